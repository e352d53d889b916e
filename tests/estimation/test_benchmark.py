"""The benchmark entry point runs and returns the documented rows (speed itself is not
asserted: timings belong to ``fov-marl bench``, not to unit tests)."""

from __future__ import annotations

import pytest

from fov_marl.estimation.benchmark import bench_tracker, format_table


def test_bench_tracker_rows():
    rows = bench_tracker(p_totals=(100,), n_agents=(3,), steps=2, warmup=1, repeats=1)
    assert len(rows) == 1
    r = rows[0]
    assert r["p_total"] == 100 and r["n_agents"] == 3 and r["n_neighbours"] == 2
    assert r["motion_model"] == "auto"
    assert r["single_ms_per_robot_step"] > 0 and r["bank_ms_per_robot_step"] > 0
    assert "P_T" in format_table(rows)
    with pytest.raises(ValueError, match="steps"):
        bench_tracker(steps=0)
    two = bench_tracker(
        p_totals=(100,),
        n_agents=(3,),
        steps=1,
        warmup=0,
        repeats=1,
        motion_models=("auto", "static"),
    )
    assert [r["motion_model"] for r in two] == ["auto", "static"]
