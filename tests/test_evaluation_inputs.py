"""Red team 8 (F07, F17, F20, F08): fov_marl.evaluation's arguments are checked like the
configs' (a ValueError naming the argument and its range, nothing coerced), one-robot
results give no NaN/inf in summaries or JSON, and the CPU-time split adds up behind the
safety filter too."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from fov_marl.evaluation import (
    EpisodeRecord,
    make_env,
    run_episode,
    run_episodes,
    summarize,
)

TINY = dict(n_agents=2, max_steps=3)


# ------------------------------------------------------------------ F07: run_episodes seeds
@pytest.mark.parametrize("seed", [1.7, True, "3", "x", -1, 2.0, np.float64(1.0)])
def test_run_episodes_checks_every_seed_as_run_episode_does(seed):
    """F07: 1.7 ran seed 1, True seed 1, '3' seed 3, 'x' gave a bare int() message."""
    with pytest.raises(ValueError, match=r"seeds\[1\] must be an integer in \[0, inf\)"):
        run_episodes("coverage", "random", [0, seed], max_cycles=2, n_agents=2)
    with pytest.raises(ValueError, match=r"seed must be an integer in \[0, inf\)"):
        run_episode("coverage", "random", seed, **TINY)


@pytest.mark.parametrize("seeds", [3, "12", None, {0: 1}, np.zeros((2, 1), int)])
def test_run_episodes_seeds_must_be_a_sequence(seeds):
    with pytest.raises(ValueError, match="seeds must be a"):
        run_episodes("coverage", "random", seeds, max_cycles=2, n_agents=2)


def test_run_episodes_takes_numpy_integer_seeds_as_ints():
    recs = run_episodes("coverage", "random", np.array([4, 5]), max_cycles=2, n_agents=2)
    assert [r.seed for r in recs] == [4, 5] and all(type(r.seed) is int for r in recs)
    ref = run_episode("coverage", "random", 5, n_agents=2, max_cycles=2)
    assert recs[1].eta_series == ref.eta_series and recs[1].steps == ref.steps == 2


@pytest.mark.parametrize("kw, match", [
    (dict(max_cycles="x"), r"max_cycles must be an integer"),
    (dict(max_cycles=1.5), r"max_cycles must be an integer"),
    (dict(safety_filter=1), r"safety_filter must be a bool"),
    (dict(progress="yes"), r"progress must be a bool"),
])  # fmt: skip
def test_run_episodes_other_arguments(kw, match):
    kw = {"max_cycles": 2, "n_agents": 2, **kw}
    with pytest.raises(ValueError, match=match):
        run_episodes("coverage", "random", [0], **kw)


# --------------------------------------------------------------- F17: run_episode arguments
@pytest.mark.parametrize("kw, match", [
    (dict(max_steps=1.5), r"max_steps must be an integer in \[0, inf\)"),
    (dict(max_steps=-5), r"max_steps must be an integer in \[0, inf\)"),
    (dict(max_steps="3"), r"max_steps must be an integer"),
    (dict(max_steps=True), r"max_steps must be an integer"),
    (dict(stop_at_eta="x"), r"stop_at_eta must be a real number in \[0.0, 1.0\]"),
    (dict(stop_at_eta=1.5), r"stop_at_eta must be in \[0.0, 1.0\]"),
    (dict(stop_at_eta=float("nan")), r"stop_at_eta must be finite"),
    (dict(policy=5), r"policy must be a registered policy name .* got 5"),
    (dict(policy=None), r"policy must be a registered policy name"),
    (dict(safety_filter=True, safety_filter_kwargs={"x": 1}),
     r"unknown safety_filter_kwargs \['x'\]; valid safety_filter_kwargs are .*tracker_params"),
    (dict(safety_filter=True, safety_filter_kwargs=[1]), r"safety_filter_kwargs must be a dict"),
    (dict(safety_filter_kwargs={"init": "known"}), r"need safety_filter=True"),
    (dict(safety_filter="yes"), r"safety_filter must be a bool"),
    (dict(policy_kwargs=[1]), r"policy_kwargs must be a dict"),
    (dict(policy_kwargs={"x": 1}), r"unknown option\(s\) \['x'\] for policy 'random'"),
    (dict(record_trajectory=1), r"record_trajectory must be a bool"),
    (dict(on_step=5), r"on_step must be None or a callable"),
    (dict(scenario=5), r"scenario must be one of"),
])  # fmt: skip
def test_run_episode_checks_its_arguments(kw, match):
    """F17: max_steps=1.5 ran 2 steps, -5 ran 0, the others raised TypeError."""
    kw = {"scenario": "coverage", "policy": "random", "seed": 0, **TINY, **kw}
    with pytest.raises(ValueError, match=match):
        run_episode(**kw)


def test_policy_kwargs_with_a_factory_are_refused_not_ignored():
    from fov_marl.baselines.random_policy import RandomPolicy

    with pytest.raises(ValueError, match=r"policy_kwargs \['x'\] apply to a registered"):
        run_episode("coverage", RandomPolicy, 0, policy_kwargs={"x": 1}, **TINY)


def test_a_factory_must_return_a_policy():
    with pytest.raises(ValueError, match="must return a Policy"):
        run_episode("coverage", lambda env: 5, 0, **TINY)


def test_make_env_checks_the_filter_keywords():
    with pytest.raises(ValueError, match=r"unknown safety_filter_kwargs \['foo'\]"):
        make_env("coverage", safety_filter=True, safety_filter_kwargs={"foo": 1}, n_agents=2)


def test_valid_arguments_run_as_before():
    r = run_episode("coverage", "random", np.int64(0), max_steps=np.int64(2), n_agents=2)
    assert r.steps == 2 and r.seed == 0
    assert run_episode("coverage", "random", 0, max_steps=0, n_agents=2).steps == 0
    r = run_episode("coverage", "random", None, stop_at_eta=0, **TINY)
    assert r.steps == 1  # η >= 0 after the first step


# ----------------------------------------------------------------- F20: one robot, inf
def test_a_config_whose_optimal_eta_is_zero_runs_and_reports_no_threshold():
    """Red team 29: sensing disks of 0.05 m on a 0.63 m eta grid cover no cell, so the
    optimal η is 0 and run_episode raised time_to_eta's "threshold must be in (0, 1]"
    (a valid config). The normalised fields are None, as eta_normalised already was."""
    rec = run_episode(
        "coverage", "random", 0, n_agents=2, max_steps=3, sensing_radius_m=0.05,
        density_sigma_m=1e6, eta_grid_m=0.63,
    )  # fmt: skip
    assert rec.eta_optimal == 0.0 and rec.final_eta == 0.0
    assert rec.eta_normalised is None and rec.time_to_eta_norm_s is None


def test_one_robot_summaries_have_no_nan_or_inf():
    """F20: min_distance inf gave mean inf, std nan, ci95 [nan, nan]."""
    r = run_episode("coverage", "random", 0, n_agents=1, max_steps=3)
    assert r.min_distance == math.inf  # the env's metric is unchanged
    s = summarize([r, r])["min_distance"]
    assert s == {"n": 0, "missing": 2, "mean": None, "std": None, "ci95": None,
                 "min": None, "max": None}  # fmt: skip
    json.dumps(summarize([r, r]), allow_nan=False)


def test_summaries_over_the_finite_values_only():
    two = run_episode("coverage", "random", 0, **TINY)
    one = run_episode("coverage", "random", 0, n_agents=1, max_steps=3)
    s = summarize([two, one, two])["min_distance"]
    assert s["n"] == 2 and s["missing"] == 1
    assert s["mean"] == pytest.approx(two.min_distance) and s["min"] == s["max"]
    assert s["ci95"] == [pytest.approx(two.min_distance)] * 2


def test_to_json_is_strict_json_and_round_trips():
    """F20: to_json() emitted Infinity, which strict JSON parsers reject."""
    r = run_episode("coverage", "random", 0, n_agents=1, max_steps=3)
    d = r.to_json()
    json.dumps(d, allow_nan=False)
    json.dumps(r.to_json(with_series=False), allow_nan=False)
    assert d["min_distance"] is None and d["min_distance_series"] == [None] * 4
    back = EpisodeRecord.from_json(d)
    assert back.min_distance == math.inf and back.min_distance_series == [math.inf] * 4
    two = run_episode("coverage", "random", 0, **TINY)
    assert EpisodeRecord.from_json(two.to_json()).to_json() == two.to_json()


def test_run_episodes_keeps_inf_for_a_one_robot_team():
    [rec] = run_episodes("coverage", "random", [0], n_agents=1, max_cycles=3)
    ref = run_episode("coverage", "random", 0, n_agents=1, max_cycles=3)
    assert rec.min_distance == ref.min_distance == math.inf
    assert rec.min_distance_series == ref.min_distance_series


# ----------------------------------------------------------------- F08: CPU-time split
@pytest.mark.parametrize("safety_filter", [False, True])
def test_cpu_split_adds_up_with_and_without_the_filter(safety_filter):
    """F08: behind the filter the stages and the per-robot shares left its time out
    (measured 0.86 ms of 1.82 ms per robot-step)."""
    r = run_episode("coverage", "pfcbf", 0, n_agents=2, max_steps=4, safety_filter=safety_filter)
    stages = r.cpu_ms_by_stage
    assert ("filter" in stages) is safety_filter
    assert sum(stages.values()) == pytest.approx(r.cpu_ms_per_robot_step, rel=1e-6)
    per = np.asarray(r.cpu_ms_by_robot)
    assert per.sum() / 2 == pytest.approx(r.cpu_ms_per_robot_step, rel=1e-6)
    if safety_filter:
        assert stages["filter"] > 0


def test_min_distance_interval_stays_inside_the_arena():
    """The t-interval of a few widely spread minimum distances was clipped only at 0: its
    upper end could lie beyond the arena's diagonal (no two robots are ever that far)."""
    import dataclasses

    from fov_marl.config import make_config

    r = run_episode("coverage", "random", 0, **TINY)
    L = r.max_distance_m
    cfg = make_config()
    assert L == pytest.approx(math.sqrt(2.0) * (cfg.arena_size_m - 2 * cfg.robot_radius_m))
    far = [dataclasses.replace(r, min_distance=d) for d in (0.1 * L, 0.2 * L, 0.99 * L)]
    s = summarize(far)["min_distance"]
    assert s["ci95"][1] == pytest.approx(L)  # unclipped it would be about 2.1 L
    assert s["ci95"][0] == 0.0
    # records from before the field (None): the old bound, [0, inf)
    old = [dataclasses.replace(x, max_distance_m=None) for x in far]
    assert summarize(old)["min_distance"]["ci95"][1] > 1.5 * L
    assert EpisodeRecord.from_json({**r.to_json(), "max_distance_m": None}).max_distance_m is None
