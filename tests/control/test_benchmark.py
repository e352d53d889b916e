"""Smoke tests of the control benchmarks (speed itself is not asserted here)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

from fov_marl.control.benchmark import bench_control, bench_lloyd_resolution, bench_qp_backends


def test_bench_control_reports_every_team_size():
    rows = bench_control(n_agents=(3, 5), steps=2, warmup=1)
    assert [r["n_agents"] for r in rows] == [3, 5]
    for r in rows:
        assert r["robot_steps"] == 2 * r["n_agents"]
        for k in ("lloyd_us", "rows_us", "cascade_us", "final_us", "controller_us", "total_us"):
            assert r[k] >= 0
        assert r["total_us"] >= r["controller_us"]
        assert 0 <= r["fallback_rate"] <= 1


def test_bench_lloyd_resolution_and_backends_run():
    res = bench_lloyd_resolution(grids_m=(0.5, 1.0), n_cases=3)
    assert [r["grid_m"] for r in res] == [0.5, 1.0]
    qp = bench_qp_backends(n_cases=5)
    assert {r["backend"] for r in qp} == {"nnls", "osqp"}
    assert qp[0]["max_du"] == 0.0  # nnls compared with itself


def test_benchmark_script_runs(capsys):
    path = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_control.py"
    spec = importlib.util.spec_from_file_location("bench_control_script", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.main(["--n-agents", "3", "--steps", "1"]) == 0
    assert "| N |" in capsys.readouterr().out
