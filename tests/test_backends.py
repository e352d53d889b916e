"""Backends (issue 13): the same numbers locally, in processes and as Ray tasks."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import pytest

import fov_marl.report  # noqa: F401  (imported before a test patches run_episode)
from fov_marl.backends import map_jobs
from fov_marl.cli import main

#: fields that measure wall-clock time, not the episode
WALL_CLOCK = {"cpu_ms_per_robot_step", "cpu_ms_per_robot_step_std", "cpu_ms_by_stage",
              "cpu_ms_by_robot"}  # fmt: skip


def _square(x: int) -> int:
    return x * x


def _mark_and_sleep(job: tuple[str, int]) -> int:
    folder, k = job
    (Path(folder) / f"started_{k}").touch()
    time.sleep(1.0)
    return k


@pytest.mark.parametrize("start", ["default", "spawn"])
def test_map_jobs_interrupted_stops_its_processes(tmp_path, monkeypatch, start):
    """Ctrl-C (here raised by ``on_result`` after the first job) stops the pool at once:
    the jobs not started never start, the running ones are killed and reaped. The pool's
    own exit used to wait for all 12 jobs and then drop their results (red team of the
    stress checkpoint: a sweep on 2 workers ran to its end after Ctrl-C and lost it).

    ``spawn`` is the start method map_jobs uses once torch is imported. There the pool's
    manager thread also reaps the killed workers, and a plain ``join`` lost that race in
    15 of 20 tries: a worker still read as alive (CI failed on it once). Three rounds."""
    import multiprocessing
    import types

    if start == "spawn":  # map_jobs picks spawn when torch is in sys.modules
        monkeypatch.setitem(sys.modules, "torch", types.ModuleType("torch"))
    for round_ in range(3 if start == "spawn" else 1):
        seen = []

        def on_result(k: int, r: int, seen: list[int] = seen) -> None:
            seen.append(k)
            raise KeyboardInterrupt

        folder = tmp_path / str(round_)
        folder.mkdir()
        jobs = [(str(folder), k) for k in range(12)]
        with pytest.raises(KeyboardInterrupt):
            map_jobs(_mark_and_sleep, jobs, workers=2, on_result=on_result)
        assert len(seen) == 1
        # 2 running + at most the 2 the workers took when the first two ended
        assert len(list(folder.glob("started_*"))) <= 4
        assert not [c for c in multiprocessing.active_children() if c.is_alive()]


def test_map_jobs_local_keeps_job_order_for_any_worker_count():
    calls = []
    out = map_jobs(_square, [3, 1, 2], on_result=lambda k, r: calls.append((k, r)))
    assert out == [9, 1, 4] and calls == [(0, 9), (1, 1), (2, 4)]
    assert map_jobs(_square, [3, 1, 2], workers=2, order=[2, 0, 1]) == [9, 1, 4]
    assert map_jobs(_square, []) == []
    with pytest.raises(ValueError, match="backend"):
        map_jobs(_square, [1], backend="dask")
    with pytest.raises(ValueError, match="workers"):
        map_jobs(_square, [1], workers=0)
    with pytest.raises(ValueError, match="needs --backend ray"):
        map_jobs(_square, [1], ray_address="auto")


def test_missing_ray_is_one_line_naming_the_extra(monkeypatch, capsys, tmp_path):
    import fov_marl.evaluation

    def no_work(*a, **k):
        raise AssertionError("ran without ray")

    monkeypatch.setattr(fov_marl.evaluation, "run_episode", no_work)
    monkeypatch.setitem(sys.modules, "ray", None)
    for argv in (
        ["evaluate", "--backend", "ray", "--policy", "random", "--episodes", "1"],
        ["stress", "--backend", "ray", "--quiet"],
        ["reproduce", "--quick", "--backend", "ray", "--out", str(tmp_path / "r")],
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "Traceback" not in err
        assert "--backend ray" in err and "fov_marl[ray]" in err


def _numbers(results: dict) -> list[dict]:
    return [{k: v for k, v in ep.items() if k not in WALL_CLOCK} for ep in results["episodes"]]


@pytest.fixture(scope="module")
def local_ray():
    ray = pytest.importorskip("ray")
    from fov_marl.backends import init_ray

    started = init_ray(num_cpus=2, include_dashboard=False)
    yield ray
    if started:
        ray.shutdown()


def test_ray_gives_the_local_numbers(local_ray, tmp_path, capsys):
    base = ["evaluate", "--policy", "pfcbf", "--n-agents", "3", "--episodes", "2", "--seed", "4",
            "--max-cycles", "25", "--quiet"]  # fmt: skip
    assert main([*base, "--out", str(tmp_path / "local")]) == 0
    assert main([*base, "--backend", "ray", "--out", str(tmp_path / "ray")]) == 0
    local, ray = (json.loads((tmp_path / d / "results.json").read_text()) for d in ("local", "ray"))
    assert [e["seed"] for e in ray["episodes"]] == [4, 5]
    assert _numbers(ray) == _numbers(local)
    assert ray["summary"]["final_eta"] == local["summary"]["final_eta"]
    assert ray["args"]["backend"] == "ray"

    # stress rows and reproduce jobs through the same map
    from fov_marl.report import Job, _run_all
    from fov_marl.stress import StressCase, run_stress

    case = [StressCase("charge_centre", 2, 120.0, "random")]
    assert run_stress(case, episodes=2, steps=15, backend="ray") == run_stress(
        case, episodes=2, steps=15
    )

    class Bar:
        n = hits = 0

        def update(self, n=1, note=None):
            self.n += n

    jobs = [Job(scenario="coverage", policy="random", seed=s, n_agents=2, max_cycles=5,
                _group="t", _label="x", _keep="final", _probe=False) for s in range(2)]  # fmt: skip
    for d in ("c1", "c2"):
        (tmp_path / d).mkdir()
    a = _run_all(jobs, 2, tmp_path / "c1", "code", Bar(), backend="ray")
    b = _run_all(jobs, 1, tmp_path / "c2", "code", Bar())
    assert [r["record"]["eta_series"] for r in a] == [r["record"]["eta_series"] for r in b]


def test_a_jobs_own_error_on_ray_is_one_line(local_ray):
    """A job's argument check (raised by fov_marl in the Ray worker) comes back as one line
    (the CLI prints it as one error line); other errors keep their traceback."""
    from fov_marl.evaluation import episode_job

    bad = {"scenario": "coverage", "policy": "random", "seed": 0, "n_agents": 2, "fov_deg": 0.0}
    with pytest.raises(ValueError, match="fov_deg") as exc:
        map_jobs(episode_job, [bad], backend="ray")
    assert "\n" not in str(exc.value) and "Traceback" not in str(exc.value)
