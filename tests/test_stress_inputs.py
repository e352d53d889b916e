"""Red team 8 (F15, F20): fov_marl.stress refuses bad cases and arguments with a
ValueError naming them (never a TypeError), and a one-robot case reports no inf."""

from __future__ import annotations

import json
import math

import pytest

from fov_marl.stress import StressCase, format_stress_table, run_stress, run_stress_episode

OK = ("straight", 2, 90.0)


@pytest.mark.parametrize("case, match", [
    ({"adversary": "straight", "n_agents": 2, "fov_deg": 90.0, "foo": 1},
     r"unknown stress case fields \['foo'\]; valid stress case fields are"),
    ({"adversary": "straight", "fov_deg": 90.0}, r"missing \['n_agents'\]"),
    (("straight", 2, 90.0, "random", True, "coverage", {}, {}, {}, {}, "x"),
     r"a stress case tuple holds 3 to 10 fields .* got 11"),
    (("straight", 2), r"a stress case tuple holds 3 to 10 fields .* got 2"),
    (5, r"a stress case must be a StressCase, tuple or dict"),
    ("straight", r"a stress case must be a StressCase, tuple or dict"),
])  # fmt: skip
def test_bad_cases_are_value_errors(case, match):
    """F15: unknown/missing dict keys and an 11-field tuple raised TypeError."""
    with pytest.raises(ValueError, match=match):
        run_stress([case], episodes=1, steps=1)


@pytest.mark.parametrize("kw, match", [
    (dict(filter_kwargs={"x": 1}), r"unknown filter_kwargs \['x'\]; valid filter_kwargs are"),
    (dict(filter_kwargs={"init": "known"}, filtered=False), r"need filtered=True"),
    (dict(n_agents="3", start="head_on_pair"), r"n_agents must be an integer"),
    (dict(n_agents=2.0), r"n_agents must be an integer"),
    (dict(fov_deg="90"), r"fov_deg must be a real number"),
    (dict(env_kwargs=None), r"env_kwargs must be a mapping, got None"),
    (dict(start_kwargs=[("a", 1)]), r"start_kwargs must be a mapping"),
    (dict(adversary_kwargs={1: 2}), r"adversary_kwargs keys must be strings"),
    (dict(adversary=["straight"]), r"adversary must be one of"),
    (dict(start=None), r"start must be one of"),
    (dict(n_agents=1, start="head_on_pair"), r"'head_on_pair' needs n_agents >= 2"),
])  # fmt: skip
def test_bad_case_fields_are_value_errors(kw, match):
    """F15: StressCase(n_agents='3', start='head_on_pair') and env_kwargs=None raised
    TypeError; unknown filter_kwargs only failed inside the episode, as a TypeError."""
    fields = {"adversary": "straight", "n_agents": 2, "fov_deg": 90.0, **kw}
    with pytest.raises(ValueError, match=match):
        StressCase(**fields)


@pytest.mark.parametrize("cases", [StressCase(*OK), {"adversary": "straight", "n_agents": 2,
                                                    "fov_deg": 90.0}, 5, None])  # fmt: skip
def test_cases_must_be_a_list(cases):
    """F15: a bare StressCase raised "'StressCase' object is not iterable"."""
    with pytest.raises(ValueError, match="cases must be a list of cases"):
        run_stress(cases, episodes=1, steps=1)


def test_progress_must_be_callable():
    with pytest.raises(ValueError, match="progress must be None or a callable"):
        run_stress([OK], episodes=1, steps=1, progress=5)


@pytest.mark.parametrize("seed", [-1, 1.5, None, "3", True])
def test_run_stress_episode_checks_its_seed(seed):
    """F15: -1 gave a numpy error, 1.5 and None a TypeError."""
    with pytest.raises(ValueError, match=r"seed must be an integer in \[0, inf\)"):
        run_stress_episode(StressCase(*OK), seed, 2)


@pytest.mark.parametrize("steps", [0, 1.5, "2"])
def test_run_stress_episode_checks_its_steps(steps):
    with pytest.raises(ValueError, match=r"steps must be an integer in \[1, inf\)"):
        run_stress_episode(StressCase(*OK), 0, steps)


def test_valid_cases_still_run():
    rows = run_stress(
        [OK, ("straight", 2, 90.0, "random", True, "coverage", {}, {"init": "known"})],
        episodes=1,
        steps=2,
    )
    assert [r["steps"] for r in rows] == [2, 2]
    assert all(r["min_distance_m"] > 0 for r in rows)


def test_a_one_robot_case_reports_no_inf():
    """F20: min_distance_m was inf (the env's metric for a team without a pair)."""
    ep = run_stress_episode(StressCase("straight", 1, 120.0), 0, 2)
    assert ep["min_distance_m"] is None and ep["steps"] == 2
    [row] = run_stress([("straight", 1, 120.0)], episodes=2, steps=2)
    assert row["min_distance_m"] is None
    json.dumps(row, allow_nan=False)
    assert "min_d_m" in format_stress_table([row])
    both = run_stress([("straight", 2, 120.0)], episodes=1, steps=2)[0]["min_distance_m"]
    assert math.isfinite(both)


def test_a_filtered_case_whose_camera_cannot_see_to_ds_is_refused():
    """The filter refuses a camera range at or below D_s; a stress case says so when it is
    built (before any episode), and an unfiltered case takes the range."""
    from fov_marl.stress import StressCase

    with pytest.raises(ValueError, match="detection_range_m must be above safety_distance_m"):
        StressCase("head_on", 8, 120.0, env_kwargs={"detection_range_m": 1.0})
    StressCase("head_on", 8, 120.0, filtered=False, env_kwargs={"detection_range_m": 1.0})


# ------------------------------------------------------ the CLI names the flag and range
def _cli_error(argv: list[str], capsys) -> str:
    """``fov-marl stress ARGV`` must exit 2 with one error line, before any episode."""
    from test_cli import _error_line  # one exit-2, one-line check for every CLI test

    return _error_line(["stress", "--quiet", *argv], capsys)


@pytest.mark.parametrize("value", ["300", "257", "2,300", "0", "-1", "abc"])
def test_cli_n_agents_out_of_range_names_the_flag_and_range(value, capsys, monkeypatch):
    """Red team: ``--n-agents 300`` said "n_agents must be an integer in [1, 256]" without
    naming --n-agents."""
    import fov_marl.stress

    monkeypatch.setattr(fov_marl.stress, "run_stress", None)  # no episode may start
    err = _cli_error(["--n-agents", value], capsys)
    assert "--n-agents" in err and "[1, 256]" in err, err


def test_cli_help_gives_the_n_agents_range(capsys):
    from fov_marl.cli import main

    with pytest.raises(SystemExit):
        main(["stress", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "--n-agents N_AGENTS team sizes, comma-separated integers in [1, 256]" in help_text


@pytest.mark.parametrize("flag, name", [("--json", "x.json"), ("--checkpoint", "x.jsonl")])
@pytest.mark.parametrize("depth", [(), ("sub",)])
def test_cli_output_under_a_file_says_it_is_not_a_directory(
    flag, name, depth, tmp_path, capsys, monkeypatch
):
    """Red team: a PATH under a regular file said "cannot write PATH (File exists)"; the
    shared output check (as ``evaluate --out``) names the component that is no folder."""
    import fov_marl.stress

    monkeypatch.setattr(fov_marl.stress, "run_stress", None)  # no episode may start
    afile = tmp_path / "afile"
    afile.write_text("keep")
    path = afile.joinpath(*depth, name)
    err = _cli_error([flag, str(path)], capsys)
    assert err == f"fov-marl stress: error: {flag} {path}: {afile} is not a directory"
    assert afile.read_text() == "keep"


@pytest.mark.parametrize("flag", ["--json", "--checkpoint"])
def test_cli_output_that_is_a_folder_is_refused_naming_the_flag(flag, tmp_path, capsys):
    err = _cli_error([flag, str(tmp_path)], capsys)
    assert err == f"fov-marl stress: error: {flag} {tmp_path}: is a directory"
