"""``fov-marl render`` and ``fov-marl bench`` after red team 7: an ``--out`` the OS
cannot write refused up front (F3), ``--beliefs-of`` takes only the agent names, the
bench sections keep their documented sizes and the issue summaries a row per goal (F5),
the bench table flattens nested figures, and an unknown option names the command
(F11)."""

from __future__ import annotations

import os

import pytest
from test_cli import _error_line  # one exit-2, one-line check for every CLI test

import fov_marl.bench
import fov_marl.control.benchmark
import fov_marl.estimation.benchmark
import fov_marl.evaluation
from fov_marl.cli import MAX_RENDER_FRAMES, main


@pytest.fixture
def no_episode(monkeypatch):
    def no_work(*args, **kwargs):
        raise AssertionError("the episode ran before the arguments were checked")

    monkeypatch.setattr(fov_marl.evaluation, "run_episode", no_work)


RENDER = ["render", "--policy", "random", "--n-agents", "2", "--max-cycles", "4"]


# ----------------------------------------------------------------------------- F3
@pytest.mark.parametrize("out", ["/proc/episode.gif", "/sys/episode.png"])
def test_render_out_the_os_cannot_write_fails_up_front_naming_out(out, capsys, no_episode):
    """Red team 7, F3: '/proc/episode.gif: No such file or directory' after the whole
    episode, without naming --out."""
    if not os.path.isdir(os.path.dirname(out)):
        pytest.skip("needs Linux's /proc and /sys")
    err = _error_line([*RENDER, "--out", out], capsys)
    assert err.startswith("fov-marl render: error: --out") and out in err, err


def test_render_writes_into_a_new_folder(tmp_path, capsys):
    """The trial write creates the folder and leaves no file behind on an error."""
    out = tmp_path / "new" / "sub" / "e.png"
    assert main([*RENDER, "--out", str(out)]) == 0
    assert out.is_file()


# ----------------------------------------------------------------------------- F7
def test_render_frame_cap_counts_the_start_and_the_end(tmp_path, capsys, no_episode):
    """1 + ceil(steps / every) frames: the default 1000-step episode at --every 1 keeps
    1001 (allowed); 1001 steps at --every 1 keep 1002 (refused, before the episode)."""
    assert MAX_RENDER_FRAMES == 1001
    base = ["render", "--policy", "random", "--n-agents", "2", "--every", "1"]
    err = _error_line([*base, "--max-cycles", "1001", "--out", str(tmp_path / "e.gif")], capsys)
    assert "--every 1: an episode of 1001 steps keeps 1002 frames" in err
    assert "raise --every to 2" in err
    with pytest.raises(AssertionError, match="the episode ran"):  # accepted: it starts
        main([*base, "--max-cycles", "1000", "--out", str(tmp_path / "e.gif")])
    for suffix in (".png", ".mp4"):  # one frame kept; streamed
        with pytest.raises(AssertionError, match="the episode ran"):
            main([*base, "--max-cycles", "5000", "--out", str(tmp_path / f"e{suffix}")])


def test_render_gif_has_the_start_and_the_final_state(tmp_path):
    from PIL import Image

    out = tmp_path / "ep.gif"
    assert main([*RENDER[:-1], "6", "--every", "4", "--out", str(out)]) == 0
    with Image.open(out) as im:
        assert im.n_frames == 3  # t = 0, step 4, step 6


# ------------------------------------------------------------------ --beliefs-of
@pytest.mark.parametrize("value", ["robot_01", "robot_2", " robot_1", "robot_1 "])
def test_beliefs_of_takes_only_the_agent_names(value, tmp_path, capsys, no_episode):
    err = _error_line([*RENDER, "--beliefs-of", value, "--out", str(tmp_path / "e.gif")], capsys)
    assert err == (
        "fov-marl render: error: --beliefs-of must be an agent name (robot_0 ... robot_1), "
        f"'all' or 'none', got {value!r}"
    )


# ---------------------------------------------------------------------------- F11
@pytest.mark.parametrize(
    "argv",
    [
        ["evaluate", "--foo"],
        ["reproduce", "--foo"],
        ["render", "--foo"],
        ["render", "--max-cycles", "2", "--foo", "bar"],
        ["bench", "--quick", "--foo"],
        ["train", "--out", "x", "--foo"],
        ["stress", "--foo"],
        ["--debug", "render", "--foo"],
    ],
)
def test_an_unknown_option_names_the_command(argv, capsys, no_episode):
    """Red team 7, F11: 'fov-marl: error: unrecognized arguments: --foo'."""
    cmd = next(a for a in argv if not a.startswith("-"))
    extra = " ".join(argv[argv.index("--foo") :])
    err = _error_line(argv, capsys)
    assert err == f"fov-marl {cmd}: error: unrecognized arguments: {extra}"


def test_an_empty_unknown_argument_is_shown(capsys):
    err = _error_line(["bench", "--quick", ""], capsys)
    assert err == "fov-marl bench: error: unrecognized arguments: '' (an empty argument)"


# ----------------------------------------------------------------------------- F5
@pytest.fixture
def bench_calls(monkeypatch):
    """Replace every bench section by a stub that records its sizes and returns one
    row per size (no timing)."""
    calls: dict[str, list] = {}

    def stub(name, rows_of):
        def fn(*args, **kwargs):
            calls.setdefault(name, []).append({"args": args, **kwargs})
            return rows_of(**kwargs)

        return fn

    monkeypatch.setattr(
        fov_marl.bench,
        "bench_env",
        stub("env", lambda n_agents, **_: [{"section": "env", "n_agents": n} for n in n_agents]),
    )
    monkeypatch.setattr(fov_marl.bench, "bench_vector_env", stub("vector_env", lambda *a, **k: []))
    monkeypatch.setattr(fov_marl.bench, "bench_vmas", stub("vmas", lambda **k: []))
    monkeypatch.setattr(
        fov_marl.bench, "bench_batched_filter", stub("vector_filter", lambda **k: [])
    )
    monkeypatch.setattr(
        fov_marl.bench, "bench_filtered_step", stub("filtered_step", lambda **k: [])
    )

    def controller_rows(n_agents, arena="scaled", safety_models=("ellipse",), warmup=10, **_):
        return [
            {
                "section": "controller",
                "arena": arena,
                "safety_model": safety_models[0],
                "n_agents": n,
                "warmup_steps": warmup,
                "ms_per_robot_step": 0.5,
            }
            for n in n_agents
        ]

    monkeypatch.setattr(fov_marl.bench, "bench_controller", stub("controller", controller_rows))
    monkeypatch.setattr(
        fov_marl.estimation.benchmark, "bench_tracker", stub("tracker", lambda **k: [])
    )
    monkeypatch.setattr(
        fov_marl.control.benchmark, "bench_control", stub("control", lambda **k: [])
    )
    return calls


def test_bench_n_agents_leaves_the_sections_with_their_own_sizes(bench_calls):
    """Red team 7, F5: --n-agents 2 made the vector_env section N = 2 only, added N = 2
    to the env section and dropped the issue10 rows and issue12's N=6 B=64 ratio."""
    rows = fov_marl.bench.run_benchmarks(quick=True, n_agents=[2])
    assert [c["n_agents"] for c in bench_calls["env"]] == [(6, 48)]
    (vec,) = bench_calls["vector_env"]
    assert (vec["args"] or (vec.get("cases"),))[0] == fov_marl.bench.VECTOR_CASES
    assert [c["n_agents"] for c in bench_calls["tracker"]] == [(2,)]
    assert [c["n_agents"] for c in bench_calls["control"]] == [(2,)]
    paper = [c for c in bench_calls["controller"] if c.get("arena") == "paper"]
    assert [tuple(c["n_agents"]) for c in paper] == [(2, 6, 48)]
    assert {tuple(c["n_agents"]) for c in bench_calls["controller"] if "arena" not in c} == {(2,)}
    issue10 = [r for r in rows if r["section"] == "issue10"]
    assert [(r["n_agents"], r["measured"], r["met"]) for r in issue10] == [
        (6, 0.5, True),
        (48, 0.5, True),
    ]


def test_bench_default_sizes(bench_calls):
    fov_marl.bench.run_benchmarks(quick=True)
    assert [c["n_agents"] for c in bench_calls["env"]] == [(6, 48)]
    assert [c["n_agents"] for c in bench_calls["tracker"]] == [(6, 12, 48)]
    paper = [c for c in bench_calls["controller"] if c.get("arena") == "paper"]
    assert [tuple(c["n_agents"]) for c in paper] == [(6, 9, 12, 24, 48)]


def test_issue_summaries_have_a_row_per_goal_when_nothing_ran():
    """issue12_summary's docstring: a row per goal, met = None when its rows were not
    run (they were left out)."""
    from fov_marl.bench import issue10_summary, issue12_summary

    i10 = issue10_summary([])
    assert [r["n_agents"] for r in i10] == [6, 48]
    assert all(r["measured"] is None and r["met"] is None and r["goal"] for r in i10)
    i12 = issue12_summary([])
    figures = [r["figure"] for r in i12]
    assert figures == [
        "env-steps/s ratio, N=6 B=64, eta exact (not run)",
        "env-steps/s ratio, N=6 B=64, eta strip (not run)",
        "filter ms/robot-step, B*N=384, P_T=2000 (not run)",
        "filter ms/robot-step, B*N=384, P_T=500 (not run)",
        "filtered env step wall ms/robot-step, B*N=384, P_T=2000, workers=1 (not run)",
        "filtered env step wall ms/robot-step, B*N=384, P_T=2000, workers=2 (not run)",
        "filtered env step wall ms/robot-step, B*N=384, P_T=500, workers=1 (not run)",
        "filtered env step wall ms/robot-step, B*N=384, P_T=500, workers=2 (not run)",
        "PPO samples/s, no filter (not run: fov-marl bench --ppo)",
        "PPO samples/s, filter (not run: fov-marl bench --ppo)",
    ]
    assert all(r["measured"] is None and r["met"] is None and r["goal"] for r in i12)
    # a measured goal replaces its placeholder; the others stay
    ratio = {
        "section": "vector_env",
        "n_agents": 6,
        "num_envs": 64,
        "eta_method": "exact",
        "ratio": 9.0,
    }
    i12 = issue12_summary([ratio])
    assert len(i12) == 10
    assert i12[0]["figure"] == "env-steps/s ratio, N=6 B=64, eta exact"
    assert i12[0]["measured"] == 9.0 and i12[0]["met"] is True
    assert i12[1]["measured"] is None


# ------------------------------------------------------------------- bench table
def test_bench_table_flattens_the_stage_times(monkeypatch, capsys):
    rows = [
        {
            "section": "vector_filter",
            "n_copies": 1,
            "batched_ms": 0.05,
            "batched_stage_ms": {"tracker": 0.01, "qp": 0.02},
        },
        {"section": "vector_filter", "n_copies": 64, "batched_ms": 0.04, "extra": 3},
        {"section": "env", "n_agents": 6},
    ]
    monkeypatch.setattr(fov_marl.bench, "run_benchmarks", lambda **kw: rows)
    assert main(["bench", "--quick"]) == 0
    out = capsys.readouterr().out
    assert "{" not in out and "'tracker'" not in out
    block = out.split("== vector_filter ==")[1].split("== env ==")[0].strip().splitlines()
    assert block[0].split() == [
        "n_copies",
        "batched_ms",
        "batched_stage_ms.tracker",
        "batched_stage_ms.qp",
        "extra",
    ]
    assert block[2].split() == ["1", "0.05", "0.01", "0.02", "-"]
    assert block[3].split() == ["64", "0.04", "-", "-", "3"]


def test_flatten_record():
    from fov_marl.tables import flatten_record, format_records

    assert flatten_record({"a": 1, "b": {"c": 2, "d": {"e": 3}}}) == {"a": 1, "b.c": 2, "b.d.e": 3}
    assert format_records([{"s": "x", "a": 1}, {"s": "x", "b": 2.5}], exclude=("s",)) == (
        "a    b\n-  ---\n1    -\n-  2.5"
    )
