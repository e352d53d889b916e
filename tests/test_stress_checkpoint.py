"""``run_stress(checkpoint=...)`` / ``fov-marl stress --checkpoint``: a stopped sweep
resumes where it stopped, runs only the missing episodes, and gives the rows of a sweep
that was never stopped; a file that is not a checkpoint of this version is refused
(naming it and the line) and never truncated."""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import re

import pytest

import fov_marl.stress as stress
from fov_marl import __version__
from fov_marl.stress import (
    CHECKPOINT_FORMAT,
    StressCase,
    add_stress_parser,
    code_id,
    run_stress,
    stored_rows,
)

CASES = [
    StressCase("head_on", 2, 45.0, "head_on_pair"),
    StressCase("charge_centre", 3, 120.0, "clustered"),
    StressCase("straight", 2, 90, "head_on_pair", filtered=False),  # int β: same key as 90.0
]
KW = {"episodes": 2, "steps": 25, "seed": 11}
_REAL_JOB = stress._job


class _Stop(Exception):
    pass


def _counting(monkeypatch, stop_after: int | None = None) -> list[int]:
    """Count the episodes run here (``_job`` calls); raise after ``stop_after`` of them."""
    calls: list[int] = []
    real = _REAL_JOB

    def job(j, **kw):
        if stop_after is not None and len(calls) == stop_after:
            raise _Stop
        calls.append(j[2])
        return real(j, **kw)

    monkeypatch.setattr(stress, "_job", job)
    return calls


def _lines(path) -> list[dict]:
    return [json.loads(t) for t in path.read_text().splitlines() if t.strip()]


def test_a_stopped_sweep_resumes_with_the_rows_of_an_unbroken_one(tmp_path, monkeypatch):
    ref = run_stress(CASES, **KW)
    ck = tmp_path / "sub" / "sweep.jsonl"
    calls = _counting(monkeypatch, stop_after=4)
    with pytest.raises(_Stop):
        run_stress(CASES, checkpoint=ck, **KW)
    assert len(calls) == 4 and len(_lines(ck)) == 4  # each episode written as it ended
    first = _lines(ck)[0]
    assert first["format"] == CHECKPOINT_FORMAT and first["version"] == __version__
    assert first["case"]["adversary"] == "head_on" and first["seed"] == 11
    # a run stopped while writing a line leaves half of it
    ck.write_text(ck.read_text() + ck.read_text().splitlines()[0][:70])
    calls = _counting(monkeypatch)
    seen = []
    rows = run_stress(CASES, checkpoint=ck, progress=lambda d, t: seen.append((d, t)), **KW)
    assert rows == ref
    assert len(calls) == 6 - 4  # only the missing episodes ran
    assert seen[0] == (4 * 25, 6 * 25) and seen[-1] == (6 * 25, 6 * 25)
    assert len(_lines(ck)) == 6  # the cut line is gone, the new ones follow
    # everything stored: nothing runs, the same rows. Episodes are stored by their own
    # seed: first seed 12 reuses episode 12 and runs only 13
    calls = _counting(monkeypatch)
    assert run_stress(CASES, checkpoint=ck, **KW) == ref and calls == []
    other = run_stress(CASES[:1], checkpoint=ck, **{**KW, "seed": 12})
    assert calls == [13] and other == run_stress(CASES[:1], **{**KW, "seed": 12})


def test_resuming_on_two_workers_gives_the_same_rows(tmp_path):
    ref = run_stress(CASES, **KW)
    ck = tmp_path / "sweep.jsonl"
    run_stress(CASES[1:2], checkpoint=ck, **KW)  # one case's episodes stored
    assert run_stress(CASES, checkpoint=ck, workers=2, **KW) == ref
    assert len(_lines(ck)) == 6


@functools.cache
def _record() -> dict:
    return stress.run_stress_episode(CASES[0], 11, 25)


def _episode_line(record_change: dict | None = None, **change) -> str:
    line = {
        "format": CHECKPOINT_FORMAT,
        "version": __version__,
        "code": code_id(),
        "case": CASES[0].describe(),
        "seed": 11,
        "steps": 25,
        "record": {**_record(), **(record_change or {})},
        **change,
    }
    return json.dumps(line)


@pytest.mark.parametrize(
    "text, match",
    [
        ("{not json\n", "line 1: not a JSON line"),
        (_episode_line() + "\n[1, 2]\n", "line 2: not a stress episode"),
        (_episode_line(format="other") + "\n", "line 1: not a stress episode"),
        (_episode_line(version="0.0.1") + "\n", "written by fov_marl '0.0.1'"),
        (_episode_line(code="0123456789ab") + "\n", "with code '0123456789ab'"),
        (_episode_line(record={"seed": 1}) + "\n", "line 1: .*entries of an episode"),
        (_episode_line(seed="11") + "\n", "line 1: .*its case, seed or steps"),
        (_episode_line({"seed": 12}) + "\n", "record's seed or steps differ"),
        (_episode_line({"steps": 26}) + "\n", "record's seed or steps differ"),
        (_episode_line({"collisions": "0"}) + "\n", "record's collisions"),
        (_episode_line({"collisions": -5}) + "\n", "record's collisions"),
        (_episode_line({"min_distance_m": math.nan}) + "\n", "min_distance_m cannot"),
        (_episode_line({"encroachment_m": None}) + "\n", "encroachment_m cannot"),
        (_episode_line({"start_min_distance_m": -1.0}) + "\n", "start_min_distance_m cannot"),
        (_episode_line({"violation_events_after_start": 10**6}) + "\n", "after_start cannot"),
        (_episode_line({"cause_counts": [1]}) + "\n", "cause_counts cannot"),
        (_episode_line({"statuses": [1]}) + "\n", "statuses cannot"),
        (_episode_line({"intervened": None}) + "\n", "intervened cannot"),
        ('{"density_sigma_m": 4.0}', "line 1: not a stress episode"),  # a config file
        (_episode_line() + "\n\n" + '{"format": "other', "line 3: .*unfinished"),
        ("{", "line 1: .*unfinished"),  # the start of a line, but no episode before it
        ('\n\n{"f', "line 3: .*unfinished"),
        (_episode_line() + "\r" + _episode_line(), "line 1: .*unfinished"),  # CR, no LF
        (_episode_line() + "\n" + _episode_line() + _episode_line(), "line 2: .*unfinished"),
        (
            '{"format": "fov_marl.stress/episode-1", "n": ' + "9" * 5000 + "}\n",
            "line 1: not a JSON",
        ),
        ("[" * 100_000 + "\n", "line 1: not a JSON line"),
        (
            _episode_line(seed=11).replace('"fov_deg": 45.0', '"fov_deg": 1e999') + "\n",
            "non-finite",
        ),
        (
            _episode_line()
            + "\n"
            + _episode_line({"collisions": 1, "first_collision_step": 3})
            + "\n",
            "line 2: another record of the episode of line 1",
        ),
        (_episode_line({"seed": False}) + "\n", "seed or steps differ"),
        (_episode_line({"seed": 11.0}) + "\n", "seed or steps differ"),
        (_episode_line({"collisions": 2}) + "\n", "first_collision_step cannot"),
        (_episode_line({"collisions": 1, "first_collision_step": 99}) + "\n", "first_collision"),
        (_episode_line({"first_collision_step": 4}) + "\n", "first_collision_step cannot"),
        (_episode_line({"robot_steps": 10**9}) + "\n", "robot_steps cannot"),
        (_episode_line({"statuses": {"bogus": 7}}) + "\n", "statuses cannot"),
    ],
)
def test_a_file_that_is_not_a_checkpoint_is_refused_and_left_alone(tmp_path, text, match):
    path = tmp_path / "x.jsonl"
    path.write_bytes(text.encode())  # bytes: read_text would turn a CR into LF
    with pytest.raises(ValueError, match=match) as exc:
        run_stress(CASES, checkpoint=path, **KW)
    assert str(path) in str(exc.value)
    assert path.read_bytes() == text.encode()


@pytest.mark.parametrize("path", ["", "  ", 3, True])
def test_the_checkpoint_must_be_a_path(path):
    with pytest.raises(ValueError, match="checkpoint must be a file path"):
        run_stress(CASES, checkpoint=path, **KW)


def test_cases_that_are_not_json_cannot_be_checkpointed(tmp_path):
    case = StressCase("head_on", 2, 45.0, "head_on_pair", adversary_kwargs={"speed": {1, 2}})
    with pytest.raises(ValueError, match="JSON values"):
        run_stress([case], checkpoint=tmp_path / "x.jsonl", **KW)


def _cmd(argv: str):
    p = argparse.ArgumentParser(prog="fov-marl")
    sub = p.add_subparsers(dest="command", required=True)
    add_stress_parser(sub)
    args = p.parse_args(["stress", *argv.split()])
    return args.func(args)


def test_the_cli_resumes_and_names_the_flag(tmp_path, capsys):
    ck = tmp_path / "grid.jsonl"
    argv = (
        "--adversaries head_on,straight --n-agents 2 --fov-deg 120 --starts head_on_pair "
        f"--episodes 2 --steps 12 --seed 5 --quiet --checkpoint {ck}"
    )
    out = tmp_path / "rows.json"
    assert _cmd(f"{argv} --json {out}") == 0
    first = capsys.readouterr().out
    assert len(_lines(ck)) == 4 and json.loads(out.read_text())["episodes_from_checkpoint"] == 0
    assert _cmd(f"{argv} --json {out}") == 0
    again = capsys.readouterr().out
    assert again == first and len(_lines(ck)) == 4
    assert json.loads(out.read_text())["episodes_from_checkpoint"] == 4
    assert _cmd(argv.replace(" --quiet", "")) == 0
    assert f"4 of 4 episodes read from {ck}" in capsys.readouterr().err
    bad = tmp_path / "cfg.json"
    bad.write_text("{not json\n")
    with pytest.raises(ValueError, match="--checkpoint .*line 1"):
        _cmd(argv.replace(str(ck), str(bad)))
    with pytest.raises(ValueError, match="--checkpoint"):
        _cmd(argv.replace(str(ck), str(tmp_path)))  # a folder
    link = tmp_path / "link.jsonl"
    link.symlink_to(ck)
    before = ck.read_text()
    hard = tmp_path / "hard.json"
    os.link(ck, hard)
    for same in (ck, link, hard):  # --json would overwrite the checkpoint
        with pytest.raises(ValueError, match="--json and --checkpoint must be different"):
            _cmd(f"{argv} --json {same}")
    assert ck.read_text() == before


def test_python_m_stress_stopped_exits_130(monkeypatch, capsys):
    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(stress, "cmd_stress", interrupted)
    monkeypatch.delenv("FOV_MARL_DEBUG", raising=False)
    assert stress.main(["--quick"]) == 130
    assert "interrupted" in capsys.readouterr().err


def test_stored_rows_are_the_rows_of_the_episodes_stored_so_far(tmp_path, monkeypatch):
    ref = run_stress(CASES, **KW)
    ck = tmp_path / "sweep.jsonl"
    assert stored_rows(CASES, checkpoint=ck, **KW) == ([], 0)
    _counting(monkeypatch, stop_after=3)
    with pytest.raises(_Stop):
        run_stress(CASES, checkpoint=ck, **KW)
    rows, n = stored_rows(CASES, checkpoint=ck, **KW)
    assert n == 3 and [r["episodes"] for r in rows] == [2, 1]
    monkeypatch.setattr(stress, "_job", _REAL_JOB)
    assert rows[0] == ref[0]  # a complete case: its final row
    assert rows[1] == run_stress(CASES[1:2], **{**KW, "episodes": 1})[0]
    run_stress(CASES, checkpoint=ck, **KW)
    assert stored_rows(CASES, checkpoint=ck, **KW) == (ref, 6)


def test_the_cli_stopped_prints_what_it_stored(tmp_path, capsys, monkeypatch):
    ck = tmp_path / "grid.jsonl"
    argv = (
        "--adversaries head_on,straight --n-agents 2 --fov-deg 120 --starts head_on_pair "
        f"--episodes 2 --steps 12 --seed 5 --quiet --checkpoint {ck}"
    )
    assert _cmd(argv.replace("head_on,straight", "straight")) == 0  # one case stored
    capsys.readouterr()

    def interrupted(*a, **kw):
        raise KeyboardInterrupt

    monkeypatch.setattr(stress, "run_stress", interrupted)
    with pytest.raises(KeyboardInterrupt):
        _cmd(argv)
    out, err = capsys.readouterr()
    assert "straight" in out and "head_on " not in out
    assert f"stopped: 2 of 4 episodes are in {ck}" in err
    with pytest.raises(KeyboardInterrupt):  # without a checkpoint: nothing to show
        _cmd(argv.replace(f" --checkpoint {ck}", ""))
    assert capsys.readouterr() == ("", "")
    with pytest.raises(KeyboardInterrupt):
        _cmd(argv.replace(str(ck), str(tmp_path / "new.jsonl")))
    out, err = capsys.readouterr()
    assert out == "" and "stopped: no episode of this sweep is in" in err


def test_identical_duplicate_lines_are_one_episode(tmp_path):
    path = tmp_path / "x.jsonl"
    path.write_text((_episode_line() + "\n") * 2)  # two sweeps wrote the same episode
    rows, n = stored_rows(CASES[:1], checkpoint=path, **{**KW, "episodes": 1})
    assert n == 1 and rows == run_stress(CASES[:1], **{**KW, "episodes": 1})


@pytest.mark.parametrize(
    "kw, name", [({"episodes": 0}, "episodes"), ({"steps": "3"}, "steps"), ({"seed": -1}, "seed")]
)
def test_stored_rows_checks_its_arguments(tmp_path, kw, name):
    with pytest.raises(ValueError, match=name):
        stored_rows(CASES, checkpoint=tmp_path / "x.jsonl", **{**KW, **kw})


def test_a_whole_last_line_without_its_newline_counts(tmp_path, monkeypatch):
    ck = tmp_path / "x.jsonl"
    ck.write_text(_episode_line())  # as an editor may save it
    calls = _counting(monkeypatch)
    rows = run_stress(CASES[:1], checkpoint=ck, **KW)
    assert calls == [12] and rows == run_stress(CASES[:1], **KW)
    assert len(_lines(ck)) == 2 and ck.read_text().endswith("}\n")


def test_non_finite_case_fields_cannot_be_checkpointed_and_create_no_file(tmp_path):
    for bad in (math.inf, math.nan, -math.inf):
        case = StressCase("charge_centre", 2, 120.0, "clustered", start_kwargs={"side_m": bad})
        with pytest.raises(ValueError, match="finite numbers"):
            run_stress([case], checkpoint=tmp_path / "sub" / "x.jsonl", **KW)
    assert not (tmp_path / "sub").exists()


def test_a_checkpoint_must_be_a_regular_file(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    for path in (fifo, tmp_path):
        with pytest.raises(ValueError, match="not a regular file"):
            run_stress(CASES, checkpoint=path, **KW)


@pytest.mark.parametrize("depth", [(), ("sub",)])
def test_a_checkpoint_under_a_file_says_it_is_not_a_directory(tmp_path, monkeypatch, depth):
    """Red team: a checkpoint path under a regular file said "cannot write it (File
    exists)"; the shared output check names the component that is no folder, before any
    episode runs, and leaves the file as it is."""
    calls = _counting(monkeypatch)
    afile = tmp_path / "afile"
    afile.write_text("keep")
    path = afile.joinpath(*depth, "x.jsonl")
    with pytest.raises(ValueError, match=f"^{re.escape(f'checkpoint {path}: {afile}')} is not a"):
        run_stress(CASES[:1], checkpoint=path, **KW)
    assert calls == [] and afile.read_text() == "keep"
