"""Flat per-agent infos (fov_marl.infos): numeric entries, same keys at reset and step."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
from fov_marl.infos import (
    SAFETY_KEYS,
    SAFETY_STATUSES,
    AgentInfo,
    agent_infos,
    has_safety,
    metrics_of,
    safety_of,
    status_code,
    status_name,
)
from fov_marl.wrappers import BeliefObservationWrapper, SafetyFilterWrapper

FAST_FILTER = {"n_particles_total": 300}


def _make(kind: str, n: int = 3):
    if kind == "crossing":
        return fov_crossing_v0.parallel_env(n_agents=n, max_cycles=6)
    env = fov_coverage_v0.parallel_env(n_agents=n, max_cycles=6)
    if kind == "filter":
        return SafetyFilterWrapper(env, tracker_params=FAST_FILTER)
    if kind == "belief":
        return BeliefObservationWrapper(env, tracker_params=FAST_FILTER)
    if kind == "belief+filter":
        return BeliefObservationWrapper(
            SafetyFilterWrapper(env, tracker_params=FAST_FILTER), tracker_params=FAST_FILTER
        )
    return env


def _check_flat(info) -> None:
    assert isinstance(info, AgentInfo)
    for k, v in info.items():
        assert isinstance(k, str) and "/" in k, k
        if isinstance(v, np.ndarray):
            assert v.dtype == np.float32 and v.ndim == 1, k
        else:
            assert isinstance(v, (bool, int, float, np.bool_, np.integer, np.floating)), (k, v)


@pytest.mark.parametrize("kind", ["coverage", "crossing", "filter", "belief", "belief+filter"])
def test_infos_are_flat_numeric_with_the_same_keys_at_reset_and_step(kind):
    env = _make(kind)
    _, infos = env.reset(seed=3)
    assert set(infos) == set(env.possible_agents)
    keys = set(infos["robot_0"])
    rng = np.random.default_rng(0)
    steps = 0
    while env.agents:
        for info in infos.values():
            _check_flat(info)
            assert set(info) == keys
        acts = {a: rng.uniform(-1, 1, 3).astype(np.float32) for a in env.agents}
        _, _, _, _, infos = env.step(acts)
        steps += 1
    assert steps == 6 and set(infos) == set(env.possible_agents)
    for info in infos.values():
        assert set(info) == keys
    filtered = "filter" in kind
    assert set(SAFETY_KEYS) <= keys if filtered else not (keys & set(SAFETY_KEYS))
    assert "metrics/min_distance" in keys and "metrics/collisions_total" in keys
    assert ("metrics/eta" in keys) == (kind != "crossing")
    assert ("metrics/arrived" in keys) == (kind == "crossing")


def test_safety_entries_neutral_at_reset_and_real_after_a_step():
    env = _make("filter")
    _, infos = env.reset(seed=1)
    for info in infos.values():
        s = safety_of(info)
        assert s is not None and s["status"] == "reset" and s["status_code"] == 0
        assert not s["intervened"] and not s["fallback"]
        assert s["cause_bits"] == 0 and s["causes"] == ()
        np.testing.assert_array_equal(s["nominal_action"], np.zeros(3, np.float32))
        np.testing.assert_array_equal(s["applied_action"], np.zeros(3, np.float32))
    acts = {a: np.array([1.0, 0.0, 0.5], np.float32) for a in env.agents}
    _, _, _, _, infos = env.step(acts)
    for info in infos.values():
        s = safety_of(info)
        assert s["status"] in SAFETY_STATUSES[1:]
        assert status_code(s["status"]) == info["safety/status_code"]
        assert isinstance(info["safety/cause_bits"], int)
        assert bool(s["causes"]) == bool(s["intervened"])  # a change has a cause
        np.testing.assert_array_equal(s["nominal_action"], acts["robot_0"])
        assert s["applied_action"].shape == (3,) and s["applied_action"].dtype == np.float32
        assert np.all(np.abs(s["applied_action"]) <= 1.0 + 1e-6)


def test_metrics_of_matches_the_env_metrics_and_the_deprecated_reads():
    env = _make("coverage")
    _, infos = env.reset(seed=0)
    info = infos["robot_1"]
    m = metrics_of(info)
    assert m == {k[len("metrics/") :]: v for k, v in info.items()}
    assert 0.0 <= m["eta"] <= 1.0 and m["collisions_total"] == 0
    with pytest.warns(DeprecationWarning, match=r"metrics_of"):
        legacy = info["metrics"]
    assert legacy == m
    with pytest.warns(DeprecationWarning):
        assert info.get("metrics") == m
    assert "metrics" in info and "safety" not in info and not has_safety(info)
    assert safety_of(info) is None and info.get("safety", 7) == 7
    with pytest.raises(KeyError):
        info["safety"]
    with pytest.raises(KeyError):
        info["nope"]
    # a plain-dict copy keeps the flat keys (and metrics_of still reads it)
    plain = dict(info)
    assert metrics_of(plain) == m and "metrics" not in plain
    assert isinstance(info.copy(), AgentInfo)
    # no warning from the supported readers
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        metrics_of(info)
        safety_of(info)


def test_deprecated_safety_read_returns_the_status_string():
    env = _make("filter")
    env.reset(seed=2)
    _, _, _, _, infos = env.step({a: np.zeros(3, np.float32) for a in env.agents})
    with pytest.warns(DeprecationWarning, match=r"safety_of"):
        s = infos["robot_0"]["safety"]
    new = safety_of(infos["robot_0"])
    assert set(s) == set(new) == {k[len("safety/") :] for k in SAFETY_KEYS} | {"status", "causes"}
    assert isinstance(s["status"], str) and s["status"] == new["status"]
    np.testing.assert_array_equal(s["applied_action"], new["applied_action"])


def test_readers_accept_the_former_nested_format():
    old = {"metrics": {"eta": 0.5}, "safety": {"intervened": True, "status": "solved"}}
    assert metrics_of(old) == {"eta": 0.5}
    s = safety_of(old)
    assert s["intervened"] and s["status_code"] == SAFETY_STATUSES.index("solved")
    assert has_safety(old) and not has_safety({"metrics": {}})


def test_status_codes_round_trip_and_bad_values_raise():
    for i, s in enumerate(SAFETY_STATUSES):
        assert status_code(s) == i and status_name(i) == s and status_name(float(i)) == s
    with pytest.raises(ValueError, match="safety status must be one of"):
        status_code("exploded")
    for bad in (-1, len(SAFETY_STATUSES), 1.5, float("nan")):
        with pytest.raises(ValueError, match=r"status_code must be an integer in \[0, 8\]"):
            status_name(bad)


def test_every_controller_status_has_a_code():
    """The statuses ControlResult documents (controller.py) all map to a code."""
    import inspect

    from fov_marl.control import controller

    doc = inspect.getdoc(controller.ControlResult) or ""
    for s in ("unconstrained", "solved", "relaxed", "degraded", "invalid_input", "qp_failed"):
        assert f'"{s}"' in doc
        status_code(s)
    status_code("safety_fallback")
    status_code("no_neighbours")


def test_agent_infos_rejects_non_scalar_metrics():
    out = agent_infos(["a", "b"], {"x": 1.0, "n": 2})
    assert out["a"] == {"metrics/x": 1.0, "metrics/n": 2} and out["a"] is not out["b"]
    with pytest.raises(ValueError, match="metric 'v' must be a real scalar"):
        agent_infos(["a"], {"v": np.zeros(2)})
