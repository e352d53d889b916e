"""The fov-marl CLI: in-process and as a subprocess, exit codes, JSON schema, errors."""

from __future__ import annotations

import json
import os
import subprocess
import sys

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
        assert im.n_frames == 3
        assert im.size == (640, 640)


def test_bench_json_reports_every_layer(capsys):
    assert main(["bench", "--quick", "--n-agents", "6", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    sections = {r["section"] for r in rows}
    assert sections == {"env", "tracker", "control", "controller"}
    ctrl = [r for r in rows if r["section"] == "controller"]
    assert ctrl[0]["n_agents"] == 6 and ctrl[0]["ms_per_robot_step"] > 0
    assert {"tracker_ms", "lloyd_ms", "qp_ms"} <= set(ctrl[0])
    env6 = [r for r in rows if r["section"] == "env" and r["n_agents"] == 6]
    assert env6 and env6[0]["agent_steps_per_s"] > 0


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
