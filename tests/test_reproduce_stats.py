"""Statistics of the reproduction: clipped summary intervals, bootstrap CIs, paired tests."""

from __future__ import annotations

import numpy as np
import pytest

from fov_marl.evaluation import (
    FEASIBLE,
    SUMMARY_FIELDS,
    EpisodeRecord,
    bootstrap_ci,
    paired_difference,
    summarize,
)


def _rec(seed: int, **kw) -> EpisodeRecord:
    base = dict(
        seed=seed, scenario="coverage", policy="pfcbf", n_agents=6, fov_deg=120.0,
        safety_filter=False, steps=1000, final_eta=0.99, time_to_eta_99=10.0, collisions=0,
        min_distance=3.0, safety_violations=0, cpu_ms_per_robot_step=1.0,
        cpu_ms_per_robot_step_std=0.1,
    )  # fmt: skip
    base.update(kw)
    return EpisodeRecord(**base)


def test_every_summary_field_has_a_feasible_range():
    assert set(SUMMARY_FIELDS) <= set(FEASIBLE)
    assert FEASIBLE["final_eta"] == (0.0, 1.0)


def test_summary_intervals_are_clipped_to_feasible_ranges():
    """Two episodes far apart: the unclipped t-interval of η was [−0.09, 1.90] (issue 11)."""
    recs = [
        _rec(0, final_eta=0.95, time_to_eta_99=1.0, collisions=0, intervention_rate=0.0),
        _rec(1, final_eta=0.999, time_to_eta_99=90.0, collisions=3, intervention_rate=0.9),
    ]
    s = summarize(recs)
    lo, hi = s["final_eta"]["ci95"]
    assert 0.0 <= lo <= s["final_eta"]["mean"] <= hi <= 1.0
    assert hi == 1.0  # the raw t-interval went above 1
    assert s["time_to_eta_99"]["ci95"][0] == 0.0  # it went below 0
    assert s["collisions"]["ci95"][0] == 0.0
    assert 0.0 <= s["intervention_rate"]["ci95"][0] and s["intervention_rate"]["ci95"][1] <= 1.0


def test_summary_of_one_episode_has_no_interval_and_arrivals_are_capped():
    s = summarize([_rec(0)])
    assert s["final_eta"]["n"] == 1 and s["final_eta"]["ci95"] is None
    recs = [_rec(k, scenario="crossing", n_agents=4, arrived=a) for k, a in enumerate((4, 4, 2))]
    ci = summarize(recs)["arrived"]["ci95"]
    assert ci[1] == 4.0 and ci[0] >= 0.0


def test_summary_interval_matches_t_interval_when_inside_range():
    from scipy.stats import t

    vals = [0.5, 0.6, 0.55, 0.58]
    s = summarize([_rec(k, final_eta=v) for k, v in enumerate(vals)])
    half = t.ppf(0.975, 3) * np.std(vals, ddof=1) / 2.0
    assert s["final_eta"]["ci95"] == pytest.approx([np.mean(vals) - half, np.mean(vals) + half])


def test_bootstrap_ci_covers_the_mean_and_is_clipped():
    rng = np.random.default_rng(0)
    v = rng.normal(10.0, 2.0, 40)
    lo, hi = bootstrap_ci(v)
    assert lo < v.mean() < hi and hi - lo < 2.0
    # a percentile interval of the mean stays inside the data's range, so only bounds
    # inside that range show the clipping: [0, 3.75] unclipped here
    assert bootstrap_ci([0.0, 0.0, 0.0, 5.0]) == [0.0, 3.75]
    assert bootstrap_ci([0.0, 0.0, 0.0, 5.0], feasible=(0.5, 2.0)) == [0.5, 2.0]
    assert bootstrap_ci([0.0, 0.0, 0.0, 5.0], feasible=(-1.0, 3.0)) == [0.0, 3.0]
    assert bootstrap_ci([1.0]) is None
    # reproducible
    assert bootstrap_ci(v, seed=3) == bootstrap_ci(v, seed=3)


def test_paired_difference_detects_a_consistent_shift_and_not_noise():
    rng = np.random.default_rng(1)
    base = rng.uniform(10.0, 30.0, 20)
    slower = base * 1.2 + rng.normal(0.0, 0.5, 20)
    r = paired_difference(slower, base)
    assert r["n"] == 20 and r["significant"] is True and r["p_value"] < 0.01
    assert r["rel_pct"] == pytest.approx(20.0, abs=3.0)
    assert r["rel_ci95"][0] < r["rel_pct"] < r["rel_ci95"][1]
    noise = base + rng.normal(0.0, 3.0, 20)
    r0 = paired_difference(noise, base)
    assert r0["significant"] is False and r0["p_value"] > 0.05
    assert r0["ci95"][0] < 0.0 < r0["ci95"][1]


def test_paired_difference_drops_incomplete_pairs_and_uses_the_exact_test():
    r = paired_difference([1.0, None, 3.0, 4.0], [0.0, 2.0, 2.0, None])
    assert r["n"] == 2 and r["dropped"] == 2 and r["diffs"] == [1.0, 1.0]
    # n = 2, both differences +1: 2 of the 4 sign patterns are as extreme
    assert r["p_value"] == pytest.approx(0.5)
    assert r["significant"] is False  # CI excludes 0, but p = 0.5: too few pairs
    empty = paired_difference([None], [1.0])
    assert empty["n"] == 0 and empty["significant"] is None
    clipped = paired_difference([0.0, 0.0, 0.0], [1.0, 1.0, 0.9], feasible_diff=(-0.5, 0.5))
    assert clipped["ci95"][0] == -0.5


def test_relative_change_ci_leaves_out_resamples_with_a_zero_baseline():
    """A single 0 in the baseline made some resamples' relative change NaN, and the
    percentile of a set holding NaN is NaN: the interval read [nan, nan] (null in JSON,
    like "fewer than two pairs")."""
    many_zero = paired_difference([2, 1, 0, 3, 1, 2], [0, 0, 3, 0, 1, 2])
    assert many_zero["rel_pct"] == pytest.approx(50.0)
    assert many_zero["rel_ci95"] is None  # over 1% of the resamples undefined
    few_zero = paired_difference([12, 10.4, 9.8, 11], [0.0, 9.0, 10.2, 10.6])
    lo, hi = few_zero["rel_ci95"]
    assert np.isfinite(lo) and np.isfinite(hi) and -100.0 <= lo < hi
    assert bootstrap_ci(np.array([np.nan, 1.0, 2.0, 3.0])) is None


def test_a_time_no_episode_reached_is_reported_with_its_count():
    recs = [_rec(k, time_to_eta_99=None, time_to_settle_s=None) for k in range(3)]
    s = summarize(recs)
    for f in ("time_to_eta_99", "time_to_settle_s"):
        assert s[f]["n"] == 0 and s[f]["missing"] == 3 and s[f]["mean"] is None, s[f]
    # a field that does not apply (a crossing time in coverage) stays out
    assert "time_to_arrival_s" not in s and "arrived" not in s
    # a coverage threshold with no optimum known does not apply either
    assert "time_to_eta_norm_s" not in s
    s = summarize([_rec(k, eta_norm_threshold=0.95) for k in range(2)])
    assert s["time_to_eta_norm_s"] == {
        "n": 0, "missing": 2, "mean": None, "std": None, "ci95": None, "min": None, "max": None,
    }  # fmt: skip


def test_one_value_has_no_spread():
    s = summarize([_rec(0, final_eta=0.9)])
    assert s["final_eta"]["mean"] == 0.9 and s["final_eta"]["std"] is None
    assert s["final_eta"]["ci95"] is None
