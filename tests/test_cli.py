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
