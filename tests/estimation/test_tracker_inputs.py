"""Tracker edge cases: a team of one (no neighbour, no particles) and bad seeds, indices,
actions and poses (a ValueError naming the argument, nothing coerced); red team 8."""

from __future__ import annotations

import numpy as np
import pytest

from fov_marl.config import make_config
from fov_marl.estimation import (
    NeighborTracker,
    TrackerBank,
    TrackerParams,
    VectorTrackerBank,
)
from fov_marl.estimation.testing import MiniWorld

from .episodes import record_episode

FAST = TrackerParams(n_particles_total=200)


# ---------------------------------------------------------------- N = 1 (F01)
def _solo(model: str) -> tuple[TrackerBank, NeighborTracker, VectorTrackerBank, np.ndarray]:
    cfg = make_config(n_agents=1)
    params = TrackerParams(motion_model=model, n_particles_total=200)
    world = MiniWorld(cfg, np.random.default_rng(0))
    obs0 = world.observe()
    obs1 = world.step(np.zeros((1, 3)))
    tr = NeighborTracker(cfg, 0, params, rng=np.random.default_rng(0))
    tr.reset(obs0[0], initial_poses_world=world.poses)
    tr.step(np.zeros(3), obs1[0])
    bank = TrackerBank(cfg, params, seed=0)
    bank.reset(obs0)
    bank.step(np.zeros((1, 3)), obs1)
    vec = VectorTrackerBank(cfg, params, n_copies=2)
    vec.reset(np.stack([obs0, obs0]), seeds=[0, 1])
    vec.step(np.zeros((2, 1, 3)), np.stack([obs1, obs1]))
    return bank, tr, vec, np.stack([obs0, obs0])


@pytest.mark.parametrize("model", ["auto", "static"])
def test_a_team_of_one_holds_no_particles(model):
    """No neighbour: every particle accessor gives an empty array of its documented dtype
    and trailing shape (was: a reshape error, AttributeError, or 2000 uninitialised
    'particles' owned by robot 0)."""
    bank, tr, vec, obs = _solo(model)
    for src in (tr, bank):
        p, owner = src.particles_body()
        assert p.shape == (0, 2) and p.dtype == np.float64
        assert owner.shape == (0,) and owner.dtype == np.int64
        h = src.particle_headings()
        assert h.shape == (0,) and h.dtype == np.float64
        m = src.particle_modes()
        assert m.shape == (0,) and m.dtype == np.int8
        v = src.particle_velocities_body()
        assert v.shape == (0, 2) and v.dtype == np.float64
    assert tr.estimate().counts.shape == (0,)
    assert bank.estimate().counts.shape == (1, 0)
    p, owner = vec.particles_all()
    assert p.shape == (2, 0, 2) and owner.shape == (2, 0) and owner.dtype == np.int64
    assert vec.positions_all().shape == (2, 0, 2)
    p, owner = vec.particles_body(1)
    assert p.shape == (0, 2) and owner.shape == (0,)
    # restarting a copy keeps working and the time of the other copy
    vec.reset_copies([0], obs, seeds=[5])
    np.testing.assert_array_equal(vec.time_s, [0.0, vec.config.dt_s])
    assert vec.particles_all()[0].shape == (2, 0, 2)


# ---------------------------------------------------------------- seeds (F10)
@pytest.mark.parametrize("seed", [-1, 1.5, "a", True, 2.0, [1, 2]])
def test_bad_seeds_name_the_seed(seed):
    ep = record_episode(n_agents=3, steps=0)
    env = _Env(ep.config)
    with pytest.raises(ValueError, match=r"seed must be an integer in \[0, inf\)"):
        NeighborTracker.for_env(env, seed=seed)
    with pytest.raises(ValueError, match=r"seed must be an integer in \[0, inf\)"):
        TrackerBank.for_env(env, seed=seed)
    with pytest.raises(ValueError, match=r"seed must be an integer in \[0, inf\)"):
        TrackerBank(ep.config, FAST, seed=seed)


def test_numpy_integer_seeds_give_the_same_numbers_as_ints():
    ep = record_episode(n_agents=3, steps=1)
    a = TrackerBank(ep.config, FAST, seed=7)
    b = TrackerBank(ep.config, FAST, seed=np.int64(7))
    for bank in (a, b):
        bank.reset(ep.obs0)
        bank.step(ep.actions[0], ep.obs[0])
    np.testing.assert_array_equal(a.particles_body(1)[0], b.particles_body(1)[0])


class _Env:
    def __init__(self, config):
        self.config = config
        self.possible_agents = [f"robot_{i}" for i in range(config.n_agents)]


# ---------------------------------------------------------------- indices (F10)
@pytest.mark.parametrize(
    "value,match",
    [
        (3, r"agent_indices must be a sequence of distinct robot indices"),
        ("01", r"agent_indices must be a sequence"),
        (np.array(1), r"agent_indices must be a sequence"),
        ([], r"agent_indices must be a non-empty sequence"),
        ([0, 1.0], r"agent_indices\[1\] must be an integer in \[0, 2\]"),
        ([0, True], r"agent_indices\[1\] must be an integer"),
        ([0, 3], r"agent_indices\[1\] must be an integer in \[0, 2\]"),
        ([-1], r"agent_indices\[0\] must be an integer in \[0, 2\]"),
        ([[0, 1]], r"agent_indices\[0\] must be an integer"),
        ([1, 1], r"agent_indices must be distinct"),
    ],
)
def test_bad_agent_indices_name_the_field_and_range(value, match):
    cfg = make_config(n_agents=3)
    with pytest.raises(ValueError, match=match):
        TrackerBank(cfg, FAST, agent_indices=value)


def test_agent_indices_accept_ints_of_any_integer_type():
    cfg = make_config(n_agents=3)
    for value in ([2, 0], (np.int32(2), 0), np.array([2, 0], dtype=np.uint8), range(2, -1, -2)):
        bank = TrackerBank(cfg, FAST, agent_indices=value, seed=0)
        np.testing.assert_array_equal(bank.agent_indices, [2, 0])
        assert bank.agent_indices.dtype == np.int64


@pytest.mark.parametrize("rngs", [5, np.random.default_rng(0), "ab"])
def test_rngs_that_are_not_a_sequence_are_value_errors(rngs):
    cfg = make_config(n_agents=3)
    with pytest.raises(ValueError, match=r"rngs must be a sequence of 3 np.random.Generator"):
        TrackerBank(cfg, FAST, rngs=rngs)


def test_bank_estimate_robot_index_is_checked():
    ep = record_episode(n_agents=4, steps=0)
    bank = TrackerBank(ep.config, FAST, seed=0)
    bank.reset(ep.obs0)
    e = bank.estimate()
    for k in (4, 9, -1, 1.0, True, "1", None):
        with pytest.raises(ValueError, match=r"k must be an integer in \[0, 3\]"):
            e.robot(k)
    np.testing.assert_array_equal(e.robot(np.int64(3)).ids, [0, 1, 2])
    np.testing.assert_array_equal(e.robot(3).mean_body, e.mean_body[3])


# ---------------------------------------------------------------- data (F10)
@pytest.mark.parametrize(
    "value", ["abc", object(), None, [0.0, True, 0.0], np.array([1j, 0, 0]), [[0.0], [0.0, 1.0]]]
)
def test_non_numeric_actions_name_the_robot(value):
    ep = record_episode(n_agents=3, steps=1)
    bank = TrackerBank(ep.config, FAST, seed=0)
    bank.reset(ep.obs0)
    acts = {f"robot_{i}": np.zeros(3) for i in range(3)}
    acts["robot_1"] = value
    with pytest.raises(ValueError, match=r"actions\['robot_1'\] must be a \(3,\) array of real"):
        bank.step(acts, ep.obs[0])
    with pytest.raises(ValueError, match=r"actions must be a \(n_robots, 3\) = \(3, 3\) array"):
        bank.step(np.zeros((3, 3), dtype=bool), ep.obs[0])
    tr = NeighborTracker(ep.config, 0, FAST, rng=np.random.default_rng(0))
    tr.reset(ep.obs0[0])
    with pytest.raises(ValueError, match=r"own_action must be a \(3,\) array of real"):
        tr.step(value, ep.obs[0][0])


def test_mapping_actions_still_accept_lists_and_float32():
    ep = record_episode(n_agents=3, steps=1)
    a = TrackerBank(ep.config, FAST, seed=0)
    b = TrackerBank(ep.config, FAST, seed=0)
    for bank in (a, b):
        bank.reset(ep.obs0)
    act = ep.actions[0]
    a.step(act, ep.obs[0])
    b.step({f"robot_{i}": [float(x) for x in act[i]] for i in range(3)}, ep.obs[0])
    np.testing.assert_array_equal(a.particles_body(2)[0], b.particles_body(2)[0])


@pytest.mark.parametrize("value", ["abc", [["a", 0, 0]] * 3, np.ones((3, 3), dtype=bool), {}])
def test_non_numeric_initial_poses_name_the_argument(value):
    ep = record_episode(n_agents=3, steps=0)
    tr = NeighborTracker(ep.config, 0, FAST, rng=np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"initial_poses_world must be a \(n_agents, 3\)"):
        tr.reset(ep.obs0[0], initial_poses_world=value)
    vec = VectorTrackerBank(ep.config, FAST, n_copies=1)
    with pytest.raises(ValueError, match=r"initial_poses_world must be a \(n_copies, n_agents"):
        vec.reset(ep.obs0[None], initial_poses_world=value)


def test_non_numeric_observations_name_the_argument():
    ep = record_episode(n_agents=3, steps=0)
    tr = NeighborTracker(ep.config, 0, FAST, rng=np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"obs must be a \(17,\) array of real numbers"):
        tr.reset("abc")
    bank = TrackerBank(ep.config, FAST, seed=0)
    obs = {f"robot_{i}": ep.obs0[i] for i in range(3)}
    obs["robot_2"] = object()
    with pytest.raises(ValueError, match=r"obs\['robot_2'\] must be a \(17,\) array"):
        bank.reset(obs)
    vec = VectorTrackerBank(ep.config, FAST, n_copies=1)
    with pytest.raises(ValueError, match=r"obs must be a \(1, 3, 17\) array"):
        vec.reset([[object()]])


# ---------------------------------------------------------------- vector seeds (F10)
@pytest.mark.parametrize(
    "seeds,match",
    [
        (5, r"seeds must be a sequence of 2 seeds"),
        ("ab", r"seeds must be a sequence of 2 seeds"),
        ([-1, 0], r"seeds\[0\] must be an integer in \[0, inf\)"),
        ([0, 1.5], r"seeds\[1\] must be an integer in \[0, inf\)"),
        ([0, True], r"seeds\[1\] must be an integer"),
        ([0], r"seeds must hold 2 seeds"),
    ],
)
def test_vector_bank_bad_seeds(seeds, match):
    ep = record_episode(n_agents=3, steps=0)
    vec = VectorTrackerBank(ep.config, FAST, n_copies=2)
    obs = np.stack([ep.obs0, ep.obs0])
    with pytest.raises(ValueError, match=match):
        vec.reset(obs, seeds=seeds)


# ---------------------------------------------------------------- reset_copies (F11)
def _vec_after_two_steps() -> tuple[VectorTrackerBank, np.ndarray, np.ndarray]:
    ep = record_episode(n_agents=3, steps=2)
    vec = VectorTrackerBank(ep.config, FAST, n_copies=2)
    vec.reset(np.stack([ep.obs0, ep.obs0]), seeds=[10, 11])
    for t in range(2):
        vec.step(np.stack([ep.actions[t]] * 2), np.stack([ep.obs[t]] * 2))
    return vec, np.stack([ep.obs0, ep.obs0]), vec.positions_all()


@pytest.mark.parametrize(
    "copies",
    [[0.7], 0.7, [1.0], ["a"], "a", None, [0, True], [True], [2], [-1], [0, 0], [[0]], object()],
)
def test_reset_copies_rejects_non_indices_and_restarts_nothing(copies):
    vec, obs, before = _vec_after_two_steps()
    time_before = vec.time_s
    with pytest.raises(ValueError, match=r"copies must be distinct copy indices \(integers in"):
        vec.reset_copies(copies, obs, seeds=[3])
    np.testing.assert_array_equal(vec.time_s, time_before)
    np.testing.assert_array_equal(vec.positions_all(), before)


def test_reset_copies_mask_of_the_wrong_shape():
    vec, obs, _ = _vec_after_two_steps()
    with pytest.raises(ValueError, match=r"the mask has shape \(3,\)"):
        vec.reset_copies([True, False, True], obs)


def test_reset_copies_valid_forms_agree():
    """An int, a list, an integer array and a bool mask restart the same copy with the
    same numbers; an empty selection restarts nothing."""
    results = []
    for copies in (1, [1], np.array([1], dtype=np.uint16), np.array([False, True])):
        vec, obs, before = _vec_after_two_steps()
        vec.reset_copies(copies, obs, seeds=[3])
        np.testing.assert_array_equal(vec.time_s, [2 * vec.config.dt_s, 0.0])
        after = vec.positions_all()
        np.testing.assert_array_equal(after[:3], before[:3])
        results.append(after)
    for r in results[1:]:
        np.testing.assert_array_equal(r, results[0])
    for empty in ([], np.zeros(0, dtype=np.int64), np.zeros(2, dtype=bool)):
        vec, obs, before = _vec_after_two_steps()
        vec.reset_copies(empty, obs)
        np.testing.assert_array_equal(vec.positions_all(), before)
