"""The fov-marl CLI: in-process and as a subprocess, exit codes, JSON schema, errors."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fov_marl.cli import main
from fov_marl.evaluation import run_episode

EPISODE_KEYS = {
    "seed",
    "scenario",
    "policy",
    "n_agents",
    "fov_deg",
    "steps",
    "final_eta",
    "time_to_eta_99",
    "collisions",
    "min_distance",
    "cpu_ms_per_robot_step",
}


def _eval_args(out, policy="random", extra=()):
    return [
        "evaluate",
        "--scenario",
        "coverage",
        "--policy",
        policy,
        "--n-agents",
        "3",
        "--fov-deg",
        "120",
        "--episodes",
        "2",
        "--seed",
        "5",
        "--max-cycles",
        "40",
        "--quiet",
        "--out",
        str(out),
        *extra,
    ]


def test_evaluate_in_process_matches_python_api(tmp_path, capsys):
    assert main(_eval_args(tmp_path)) == 0
    printed = capsys.readouterr().out
    assert "final_eta" in printed and "ci95_lo" in printed
    data = json.loads((tmp_path / "results.json").read_text())
    assert set(data) >= {"episodes", "summary"}
    assert len(data["episodes"]) == 2
    for k, ep in enumerate(data["episodes"]):
        assert EPISODE_KEYS <= set(ep)
        ref = run_episode("coverage", "random", 5 + k, n_agents=3, fov_deg=120.0, max_cycles=40)
        assert ep["seed"] == 5 + k
        assert ep["final_eta"] == ref.final_eta
        assert ep["collisions"] == ref.collisions
        assert ep["min_distance"] == ref.min_distance
        assert ep["steps"] == ref.steps == 40
    s = data["summary"]["final_eta"]
    assert s["n"] == 2 and s["ci95"][0] <= s["mean"] <= s["ci95"][1]


def test_evaluate_as_subprocess(tmp_path):
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    res = subprocess.run(
        [sys.executable, "-m", "fov_marl.cli", *_eval_args(tmp_path, extra=("--workers", "2"))],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    data = json.loads((tmp_path / "results.json").read_text())
    assert [e["seed"] for e in data["episodes"]] == [5, 6]
    ref = run_episode("coverage", "random", 6, n_agents=3, fov_deg=120.0, max_cycles=40)
    assert data["episodes"][1]["final_eta"] == ref.final_eta


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["evaluate", "--n-agents", "0"], "--n-agents"),
        (["evaluate", "--fov-deg", "400"], "--fov-deg"),
        (["evaluate", "--episodes", "x"], "--episodes"),
        (["evaluate", "--scenario", "maze"], "--scenario"),
        (["render", "--out", "episode.txt", "--policy", "random", "--max-cycles", "2"], "--out"),
        (["evaluate", "--policy", "nope", "--episodes", "1", "--max-cycles", "2"], "nope"),
    ],
)
def test_bad_arguments_give_one_line_naming_the_flag(argv, flag, capsys):
    with pytest.raises(SystemExit) as exc:
        code = main(argv)
        raise SystemExit(code)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert flag in err
    assert len(err.splitlines()) == 1
    assert "Traceback" not in err


@pytest.mark.parametrize("cmd", ["evaluate", "reproduce", "render", "bench", "train"])
def test_help_shows_defaults(cmd, capsys):
    with pytest.raises(SystemExit) as exc:
        main([cmd, "--help"])
    assert exc.value.code == 0
    assert "default" in capsys.readouterr().out


def test_render_writes_a_gif(tmp_path):
    out = tmp_path / "ep.gif"
    assert (
        main(
            ["render", "--policy", "random", "--max-cycles", "6", "--every", "2", "--out", str(out)]
        )
        == 0
    )
    from PIL import Image

    with Image.open(out) as im:
        assert im.n_frames == 4  # t = 0 and steps 2, 4, 6 (the final state)
        assert im.size == (640, 640)


def test_bench_json_reports_every_layer(capsys):
    assert main(["bench", "--quick", "--n-agents", "6", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    sections = {r["section"] for r in rows}
    assert {
        "env",
        "vector_env",
        "vector_filter",
        "filtered_step",
        "tracker",
        "control",
        "controller",
        "issue12",
    } <= sections
    assert sections <= {
        "env",
        "vector_env",
        "vector_filter",
        "filtered_step",
        "vmas",
        "tracker",
        "control",
        "controller",
        "issue10",
        "issue12",
    }
    # the acceptance summary: the env ratio at N = 6, B = 64 and the filter at B N = 384,
    # at the default and at the reduced particle budget; every row carries the load
    summary = [r for r in rows if r["section"] == "issue12"]
    figures = " | ".join(r["figure"] for r in summary)
    assert "N=6 B=64, eta exact" in figures and "P_T=2000" in figures and "P_T=500" in figures
    assert all(r["load_1min"] is not None for r in summary if r["measured"] is not None)
    # the PPO goals were not run (no --ppo): their rows say so
    assert [r["figure"] for r in summary if r["measured"] is None] == [
        "PPO samples/s, no filter (not run: fov-marl bench --ppo)",
        "PPO samples/s, filter (not run: fov-marl bench --ppo)",
    ]
    # the whole filtered step in 1 and 2 processes, at both particle budgets
    steps = [r for r in rows if r["section"] == "filtered_step"]
    assert {(r["workers"], r["n_particles_total"]) for r in steps} == {
        (1, 2000),
        (2, 2000),
        (1, 500),
        (2, 500),
    }
    assert all(r["wall_ms_per_robot_step"] > 0 and r["robots"] == 384 for r in steps)
    assert "P_T=2000, workers=2" in figures
    ctrl = [r for r in rows if r["section"] == "controller"]
    assert ctrl[0]["n_agents"] == 6 and ctrl[0]["ms_per_robot_step"] > 0
    assert {"tracker_ms", "lloyd_ms", "qp_ms"} <= set(ctrl[0])
    # the budget is also timed in the paper's 40 m arena after a warm-up (the packed team)
    paper = [r for r in ctrl if r["arena"] == "paper"]
    assert paper and paper[0]["arena_size_m"] == 40.0 and paper[0]["warmup_steps"] >= 10
    assert {r["arena"] for r in ctrl} == {"scaled", "paper"}
    # pfcbf's budget read from those paper-arena rows, always at N = 6 and 48
    assert [r["n_agents"] for r in paper] == [6, 48]
    i10 = [r for r in rows if r["section"] == "issue10"]
    assert [r["n_agents"] for r in i10] == [6, 48]
    for r, p in zip(i10, paper, strict=True):
        assert r["measured"] == p["ms_per_robot_step"] and r["goal"] == "<= 1 ms"
        assert r["met"] == (r["measured"] <= 1.0)
    env6 = [r for r in rows if r["section"] == "env" and r["n_agents"] == 6]
    assert env6 and env6[0]["agent_steps_per_s"] > 0


def test_issue12_summary_reads_the_ppo_rows_per_worker_count():
    """The PPO acceptance rows of ``fov-marl bench --ppo``: one per (filter, P_T, B,
    workers), the goal checked against the issue's figures."""
    from fov_marl.bench import issue12_summary

    def ppo(filt, workers, rate):
        return {
            "section": "ppo",
            "adapter": "vector",
            "n_envs": 64,
            "workers": workers,
            "safety_filter": filt,
            "n_particles_total": 2000 if filt else None,
            "samples_per_s": rate,
            "ratio": None,
            "load_1min": 0.5,
        }

    rows = [ppo(True, 1, 2410.0), ppo(True, 2, 3812.0), ppo(False, 2, 12000.0)]
    summary = {r["figure"]: r for r in issue12_summary(rows)}
    one = summary["PPO samples/s, filter P_T=2000, B=64, workers=1"]
    two = summary["PPO samples/s, filter P_T=2000, B=64, workers=2"]
    assert not one["met"] and two["met"] and two["goal"] == ">= 3000"
    assert two["vs_issue_today"] == pytest.approx(3812.0 / 1079.0)
    free = summary["PPO samples/s, no filter, B=64, workers=2"]
    assert free["met"] is False  # 12,000 < 2 x 6,087


def test_evaluate_pfcbf_with_safety_filter_flag(tmp_path):
    args = _eval_args(tmp_path, policy="pfcbf", extra=("--safety-filter",))
    assert main(args) == 0
    data = json.loads((tmp_path / "results.json").read_text())
    ep = data["episodes"][0]
    assert ep["policy"] == "pfcbf" and ep["collisions"] == 0
    assert ep["filter_interventions"] is not None and ep["cpu_ms_per_robot_step"] > 0


# ----------------------------------------------------------------------------- issue 15
def _error_line(argv, capsys) -> str:
    """Run ``main(argv)``; it must exit 2 with one error line and no traceback."""
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize(
    "argv",
    [
        ["render", "--policy", "random", "--max-cycles", "2", "--out", "{f}/x.gif"],
        ["evaluate", "--policy", "random", "--episodes", "1", "--max-cycles", "2", "--out", "{f}"],
        [
            "evaluate",
            "--policy",
            "random",
            "--episodes",
            "1",
            "--max-cycles",
            "2",
            "--out",
            "{f}/a",
        ],
        ["reproduce", "--quick", "--out", "{f}"],
        ["reproduce", "--quick", "--out", "{f}/sub"],
        ["train", "--timesteps", "8", "--out", "{f}"],
        ["train", "--timesteps", "8", "--out", "{f}/run"],
    ],
    ids=[
        "render-under-file",
        "eval-onto",
        "eval-under",
        "repro-onto",
        "repro-under",
        "train-onto",
        "train-under",
    ],
)
def test_clashing_out_paths_are_caught_before_any_work(argv, tmp_path, capsys, monkeypatch):
    import fov_marl.evaluation
    import fov_marl.report

    def no_work(*args, **kwargs):
        raise AssertionError("work started before --out was checked")

    monkeypatch.setattr(fov_marl.report, "reproduce", no_work)
    monkeypatch.setattr(fov_marl.evaluation, "run_episode", no_work)
    blocker = tmp_path / "blocker"
    blocker.write_text("a file, not a directory")
    err = _error_line([a.replace("{f}", str(blocker)) for a in argv], capsys)
    assert "--out" in err and str(blocker) in err


@pytest.mark.parametrize(
    ("argv", "blocked", "says"),
    [
        (["evaluate", "--episodes", "1", "--out", "{d}"], "results.json", "--out"),
        (["reproduce", "--quick", "--out", "{d}"], "report.md", "--out"),
        (["reproduce", "--quick", "--out", "{d}"], "fig6_eta.png", "--out"),
        (["train", "--timesteps", "8", "--out", "{d}", "--force"], "config.json", "--out"),
        (["stress", "--quick", "--json", "{d}/rows.json"], "rows.json", "--json"),
    ],
    ids=["eval-results", "repro-report", "repro-figure", "train-config", "stress-json"],
)
def test_output_files_blocked_by_a_folder_fail_before_any_work(
    argv, blocked, says, tmp_path, capsys, monkeypatch
):
    """Red team 4: a folder where an output file goes ran all the work, then failed
    with a bare "Is a directory" that named no flag (train left a model without its
    config.json)."""
    import fov_marl.evaluation
    import fov_marl.report
    import fov_marl.stress

    def no_work(*args, **kwargs):
        raise AssertionError("work started before the output files were checked")

    monkeypatch.setattr(fov_marl.report, "reproduce", no_work)
    monkeypatch.setattr(fov_marl.evaluation, "run_episode", no_work)
    monkeypatch.setattr(fov_marl.stress, "run_stress", no_work)
    if argv[0] == "train":
        pytest.importorskip("stable_baselines3")
        import fov_marl.training.trainer

        monkeypatch.setattr(fov_marl.training.trainer, "train", no_work)
    (tmp_path / blocked).mkdir()
    err = _error_line([a.replace("{d}", str(tmp_path)) for a in argv], capsys)
    assert err.startswith(f"fov-marl {argv[0]}: error: {says}") and blocked in err, err


def test_stress_json_seed_and_grid_lists_are_checked(tmp_path, capsys):
    (tmp_path / "file").write_text("")
    for argv, says in [
        (["stress", "--quick", "--json", ""], "--json must be a file path"),
        (
            ["stress", "--quick", "--json", str(tmp_path / "file" / "x.json")],
            f"--json {tmp_path / 'file' / 'x.json'}: {tmp_path / 'file'} is not a directory",
        ),
        (["stress", "--quick", "--seed", "2147483648"], "--seed must be an integer in"),
        (["stress", "--adversaries", "rush,rush", "--n-agents", "2"], "rush more than once"),
    ]:
        assert says in _error_line(argv, capsys)


def test_config_file_fields_are_validated_with_the_flags_applied(tmp_path, capsys):
    """Red team 4: a --config of 3 initial_poses was refused with --n-agents 3 (the file
    was validated alone, at the default N = 6, before the flags that override it)."""
    cfg = tmp_path / "ip3.json"
    cfg.write_text(json.dumps({"initial_poses": [[5, 5, 0], [10, 10, 0], [20, 20, 0]]}))
    base = ["evaluate", "--config", str(cfg), "--episodes", "1", "--max-cycles", "3", "--quiet"]
    assert main([*base, "--n-agents", "3"]) == 0  # the file holds with the flag applied
    capsys.readouterr()
    err = _error_line(base, capsys)  # N = 6 in force: the file is named, with the length
    assert err.startswith(f"fov-marl evaluate: error: --config {cfg}: initial_poses must have")


def test_render_onto_an_existing_directory(tmp_path, capsys):
    (tmp_path / "ep.gif").mkdir()
    err = _error_line(["render", "--policy", "random", "--out", str(tmp_path / "ep.gif")], capsys)
    assert "--out" in err and "is a directory" in err


def test_hp_errors_name_the_key_and_list_the_valid_ones(tmp_path, capsys):
    base = ["train", "--timesteps", "8", "--out", str(tmp_path / "run")]
    err = _error_line([*base, "--hp", "n_steps=abc"], capsys)
    assert "--hp n_steps must be an integer" in err and "'abc'" in err
    err = _error_line([*base, "--hp", "nosuchkey=1"], capsys)
    assert "nosuchkey" in err and "n_steps" in err and "learning_rate" in err
    assert not (tmp_path / "run").exists()  # nothing was created


def test_bench_with_one_robot_is_a_clean_error(capsys):
    err = _error_line(["bench", "--quick", "--n-agents", "1"], capsys)
    assert "--n-agents" in err and "[2, 100]" in err


@pytest.mark.parametrize(
    ("content", "says"),
    [(b"", "empty"), (b"PK\x03\x04garbage", "not a zip archive"), ("foreign", "not a PPO model")],
)
def test_damaged_or_foreign_model_files_say_so(content, says, tmp_path, capsys):
    import zipfile

    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_text(
        json.dumps({"format": "fov_marl.training/1", "algo": "ppo", "scenario": "coverage",
                    "n_agents": 6, "env_kwargs": {}})
    )  # fmt: skip
    if content == "foreign":
        with zipfile.ZipFile(run / "model.zip", "w") as z:
            z.writestr("readme.txt", "some other program's zip")
    else:
        (run / "model.zip").write_bytes(content)
    err = _error_line(["evaluate", "--policy", str(run / "model.zip"), "--episodes", "1"], capsys)
    assert "--policy" in err and str(run / "model.zip") in err and says in err


def test_debug_shows_the_traceback_of_user_errors(monkeypatch):
    with pytest.raises(ValueError, match="--policy must be a registered policy"):
        main(["render", "--debug", "--policy", "nope"])
    with pytest.raises(ValueError, match="--policy"):
        main(["--debug", "evaluate", "--policy", "nope"])
    monkeypatch.setenv("FOV_MARL_DEBUG", "1")
    with pytest.raises(ValueError, match="--out"):
        main(["render", "--out", "x.txt"])


def test_interrupt_exits_130_without_traceback(monkeypatch, capsys):
    import fov_marl.evaluation

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(fov_marl.evaluation, "run_episode", interrupted)
    assert main(["evaluate", "--policy", "random", "--episodes", "1", "--quiet"]) == 130
    assert capsys.readouterr().err.strip() == "fov-marl evaluate: interrupted"


# ----------------------------------------------------------------------------- issue 13
@pytest.fixture(scope="module")
def tiny_model(tmp_path_factory):
    """A 128-timestep PPO model on 2 coverage robots (a few seconds)."""
    pytest.importorskip("stable_baselines3")
    out = tmp_path_factory.mktemp("tiny") / "run"
    argv = ["train", "--timesteps", "128", "--n-agents", "2", "--num-envs", "1",
            "--train-max-cycles", "10", "--hp", "n_steps=64", "--hp", "batch_size=64",
            "--checkpoint-every", "0", "--no-progress", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    return out


def test_render_takes_a_model_path_like_evaluate(tiny_model, tmp_path):
    for policy in (tiny_model / "model.zip", tiny_model):
        out = tmp_path / f"{policy.name}.gif"
        argv = ["render", "--policy", str(policy), "--max-cycles", "4", "--every", "2"]
        assert main([*argv, "--out", str(out)]) == 0
        from PIL import Image

        with Image.open(out) as im:
            assert im.n_frames == 3  # t = 0, steps 2 and 4


def test_a_model_on_another_scenario_is_a_one_line_error(tiny_model, capsys):
    for cmd in ("evaluate", "render"):
        argv = [cmd, "--policy", str(tiny_model / "model.zip"), "--scenario", "crossing"]
        err = _error_line([*argv, "--max-cycles", "2"], capsys)
        assert "--scenario crossing" in err and "'coverage'" in err
    # without --scenario the model's own scenario is used
    assert main(["evaluate", "--policy", str(tiny_model), "--episodes", "1",
                 "--max-cycles", "3", "--quiet"]) == 0  # fmt: skip


def _all_subparsers():
    import argparse

    from fov_marl.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return parser, sub.choices


def test_every_flag_has_help_and_its_default_is_printed_once(capsys):
    parser, commands = _all_subparsers()
    for name, sp in commands.items():
        for action in sp._actions:
            if not action.option_strings or action.help == "==SUPPRESS==":
                continue
            assert action.help and action.help.strip(), f"{name} {action.option_strings}"
        with pytest.raises(SystemExit):
            main([name, "--help"])
        text = capsys.readouterr().out
        assert "(default: None)" not in text and "(default: False)" not in text
        # one "default" per flag at most: split the help into per-flag paragraphs
        blocks, cur = [], []
        for line in text.splitlines():
            if line.startswith("  -") and cur:
                blocks.append(" ".join(cur))
                cur = []
            cur.append(line.strip())
        blocks.append(" ".join(cur))
        for block in blocks:
            assert block.lower().count("default") <= 1, f"{name}: {block}"


def test_version(capsys):
    import fov_marl

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"fov-marl {fov_marl.__version__}"
    assert fov_marl.__version__[0].isdigit()


def test_progress_is_per_step_with_tqdm(tmp_path, capsys):
    pytest.importorskip("tqdm")
    args = [a for a in _eval_args(tmp_path) if a != "--quiet"]
    assert main(args) == 0
    err = capsys.readouterr().err
    assert "80/80" in err  # 2 episodes x 40 steps, counted in steps
    assert "step" in err


def test_progress_falls_back_silently_without_tqdm_and_rich(tmp_path, capsys, monkeypatch):
    import sys

    from fov_marl.backends import progress_bar

    monkeypatch.setitem(sys.modules, "tqdm", None)
    monkeypatch.setitem(sys.modules, "rich", None)
    monkeypatch.setitem(sys.modules, "rich.progress", None)
    assert progress_bar(3, "x").backend == "none"
    args = [a for a in _eval_args(tmp_path) if a != "--quiet"]
    assert main(args) == 0
    assert capsys.readouterr().err == ""


def test_progress_uses_rich_without_tqdm(monkeypatch):
    import sys

    pytest.importorskip("rich")
    from fov_marl.backends import progress_bar

    monkeypatch.setitem(sys.modules, "tqdm", None)
    bar = progress_bar(3, "x")
    assert bar.backend == "rich"
    bar.update(3)
    bar.close()
    assert bar.n == 3


def test_one_table_formatter():
    import fov_marl.cli
    import fov_marl.stress
    from fov_marl.tables import format_table

    assert fov_marl.cli.format_table is format_table
    rows = [{"a": 1, "b": 0.123456}, {"a": 22}]
    text = format_table(rows, [("A", "a"), ("B", "b")])
    assert text.splitlines() == [" A       B", "--  ------", " 1  0.1235", "22       -"]
    assert format_table([[1, 0.123456], [22, None]], ["A", "B"]) == text
    import inspect
    import re

    src = inspect.getsource(fov_marl.stress)
    assert re.search(r"from fov_marl\.tables import [\w, ]*\bformat_table\b", src)


def test_evaluate_config_file_and_env_equal_the_python_api(tmp_path, capsys):
    from fov_marl.config import make_config

    cfg = make_config(n_agents=3, density_sigma_m=4.0, max_cycles=20).to_dict()
    (tmp_path / "cfg.json").write_text(json.dumps(cfg))
    base = ["evaluate", "--policy", "random", "--episodes", "1", "--quiet"]
    assert main([*base, "--config", str(tmp_path / "cfg.json"), "--out", str(tmp_path / "a")]) == 0
    env = ["--env", "n_agents=3", "--env", "density_sigma_m=4.0", "--env", "max_cycles=20"]
    assert main([*base, *env, "--out", str(tmp_path / "b")]) == 0
    a, b = (json.loads((tmp_path / d / "results.json").read_text()) for d in "ab")
    ref = run_episode("coverage", "random", 0, n_agents=3, density_sigma_m=4.0, max_cycles=20)
    for data in (a, b):
        ep = data["episodes"][0]
        assert ep["final_eta"] == ref.final_eta and ep["steps"] == 20 and ep["n_agents"] == 3
    # a flag overrides the file, a conflicting --env and flag is an error
    assert main([*base, "--config", str(tmp_path / "cfg.json"), "--max-cycles", "5"]) == 0
    capsys.readouterr()
    err = _error_line([*base, "--env", "max_cycles=7", "--max-cycles", "5"], capsys)
    assert "--env max_cycles=7 conflicts with --max-cycles 5" in err
    err = _error_line([*base, "--env", "density_sigma_m=-1"], capsys)
    assert err.startswith("fov-marl evaluate: error: --env") and "density_sigma_m" in err


def test_mp4_without_its_writer_fails_before_simulating(tmp_path, capsys, monkeypatch):
    import sys

    import fov_marl.evaluation

    def no_work(*args, **kwargs):
        raise AssertionError("the episode ran before the writer was checked")

    monkeypatch.setattr(fov_marl.evaluation, "run_episode", no_work)
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)
    err = _error_line(["render", "--policy", "random", "--out", str(tmp_path / "x.mp4")], capsys)
    assert "--out" in err and "[video]" in err and "imageio-ffmpeg" in err


def test_mp4_with_its_writer(tmp_path):
    pytest.importorskip("imageio_ffmpeg")
    out = tmp_path / "x.mp4"
    argv = ["render", "--policy", "random", "--max-cycles", "4", "--every", "1", "--out"]
    assert main([*argv, str(out)]) == 0
    assert out.stat().st_size > 1000


def test_pfcbf_episodes_charge_every_robot_its_share_of_the_cpu_time():
    """The per-robot CPU split (evaluation docstring) with the batched controller (the
    default: one solve for the team, equal shares) and with the per-robot loop; the
    shares add up to the team's time either way (the report's scaling table reads them)."""
    for kw in ({}, {"policy_kwargs": {"controller": "loop"}}):
        r = run_episode("coverage", "pfcbf", 0, n_agents=4, max_steps=5, **kw)
        per = np.asarray(r.cpu_ms_by_robot)
        assert per.shape == (4,) and np.isfinite(per).all() and (per > 0).all()
        assert per.sum() / 4 == pytest.approx(r.cpu_ms_per_robot_step, rel=0.05)


def test_train_intervention_coef_needs_the_filter(tmp_path, capsys):
    """Red team 4: accepted without --safety-filter, where it has nothing to weigh."""
    pytest.importorskip("stable_baselines3")
    argv = ["train", "--timesteps", "8", "--out", str(tmp_path / "r"), "--intervention-coef", "1"]
    assert "--intervention-coef 1.0 needs --safety-filter" in _error_line(argv, capsys)
    assert not (tmp_path / "r").exists()
    argv = ["train", "--timesteps", "8", "--out", str(tmp_path / "r"), "--workers", "2"]
    argv += ["--n-envs", "1"]
    assert "--workers 2 must be at most --n-envs 1" in _error_line(argv, capsys)


def _fake_train(model: Path):
    """A stand-in for ``trainer.train`` that writes what ``fov-marl train`` reads after it
    (the run's config.json), so the command can succeed and its exit code be checked."""

    def fake(*args, **kwargs):
        model.parent.mkdir(parents=True, exist_ok=True)
        done = {"timesteps_done": 8, "train_wall_s": 1.0, "samples_per_s": 8.0}
        (model.parent / "config.json").write_text(json.dumps(done))
        return model

    return fake


def test_train_force_removes_the_old_runs_checkpoints(tmp_path, capsys, monkeypatch):
    """Red team 4: --force left model_96_steps.zip of the old run beside a 32-step model."""
    pytest.importorskip("stable_baselines3")
    import fov_marl.training.trainer

    out = tmp_path / "run"
    (out / "checkpoints").mkdir(parents=True)
    for name in ("model_96_steps.zip", "model_vecnormalize_96_steps.pkl", "notes.txt"):
        (out / "checkpoints" / name).write_text("old")
    (out / "model.zip").write_text("old")
    monkeypatch.setattr(fov_marl.training.trainer, "train", _fake_train(out / "model.zip"))
    assert main(["train", "--timesteps", "8", "--out", str(out), "--force"]) == 0
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == ["notes.txt"]


def test_evaluate_results_record_the_config_in_force_and_the_version(tmp_path):
    from fov_marl import __version__

    assert main(_eval_args(tmp_path, extra=("--env", "safety_distance_m=2.5"))) == 0
    data = json.loads((tmp_path / "results.json").read_text())
    assert data["fov_marl_version"] == __version__
    cfg = data["config"]
    assert cfg["n_agents"] == 3 and cfg["safety_distance_m"] == 2.5 and cfg["max_cycles"] == 40


def test_train_says_how_checkpoint_every_is_rounded(tmp_path, capsys, monkeypatch):
    """Red team 4: --checkpoint-every 5 silently saved every 4 timesteps."""
    pytest.importorskip("stable_baselines3")
    import fov_marl.training.trainer
    from fov_marl.training.trainer import checkpoint_period

    assert checkpoint_period(5, 4) == 4 and checkpoint_period(3, 4) == 4
    assert checkpoint_period(100_000, 24) == 99_984
    monkeypatch.setattr(fov_marl.training.trainer, "train", _fake_train(tmp_path / "m.zip"))
    argv = ["train", "--timesteps", "8", "--out", str(tmp_path / "r"), "--n-envs", "1"]
    assert main([*argv, "--n-agents", "2", "--checkpoint-every", "5"]) == 0
    out = capsys.readouterr().out
    assert "--checkpoint-every 5 saves every 4 timesteps" in out


def test_evaluate_one_robot_team_table_shows_no_infinite_distance(capsys):
    """A one-robot team has no pair: its min_distance is inf in the record, "-" in the
    episode table (the summary leaves it out), never "inf"."""
    args = _eval_args("unused")[:-2]  # no --out
    args[args.index("--n-agents") + 1] = "1"
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "inf" not in printed
    header, _rule, *rows = printed.split("\n\n")[0].splitlines()
    col = header.split().index("min_distance")
    assert len(rows) == 2 and all(r.split()[col] == "-" for r in rows)


def test_filter_with_a_camera_short_of_ds_is_one_line(capsys):
    err = _error_line(
        ["evaluate", "--policy", "random", "--safety-filter", "--env", "detection_range_m=2"],
        capsys,
    )
    assert "detection_range_m must be above safety_distance_m = 2 m" in err
