"""BeliefObservationWrapper: layout and bounds, equality with per-robot trackers fed by
hand, own data only (no ground truth after the documented start poses), determinism."""

from __future__ import annotations

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
from fov_marl.envs.fov_coverage_v0 import FovCoverageEnv
from fov_marl.estimation import NeighborTracker
from fov_marl.estimation.params import TrackerParams
from fov_marl.wrappers.belief import (
    FEATURE_NAMES,
    FEATURES_PER_NEIGHBOUR,
    BeliefFeaturizer,
    BeliefObservationWrapper,
)

N = 4
FAST = {"n_particles_total": 400}  # speed only; the layout does not depend on it


def _env(**kw):
    return fov_coverage_v0.parallel_env(**{"n_agents": N, "max_cycles": 40, **kw})


def _actions(rng, agents):
    return {a: rng.uniform(-1, 1, 3).astype(np.float32) for a in agents}


def _rollout(env, seed, steps, action_seed=0):
    rng = np.random.default_rng(action_seed)
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for _ in range(steps):
        if not env.agents:
            obs, _ = env.reset()
        else:
            obs, *_ = env.step(_actions(rng, env.agents))
        out.append(obs)
    return [np.stack([o[a] for a in env.possible_agents]) for o in out]


def test_layout_and_observations_inside_the_box():
    base = _env()
    twin = _env()  # the plain env, stepped alongside: the wrapper keeps its observation
    env = BeliefObservationWrapper(base, tracker_params=FAST)
    m = N - 1
    base_size = base.observation_space("robot_0").shape[0]
    space = env.observation_space("robot_0")
    assert space is env.observation_space("robot_3")  # same object for every call/agent
    assert space.shape == (base_size + FEATURES_PER_NEIGHBOUR * m,)
    assert space.dtype == np.float32 and len(FEATURE_NAMES) == FEATURES_PER_NEIGHBOUR
    np.testing.assert_array_equal(space.low[:base_size], base.observation_space("robot_0").low)
    d = 40.0 * np.sqrt(2.0)
    a_max = d / 2 * np.sqrt(-2 * np.log(0.05))
    feat_lo = space.low[base_size:].reshape(m, FEATURES_PER_NEIGHBOUR)
    feat_hi = space.high[base_size:].reshape(m, FEATURES_PER_NEIGHBOUR)
    np.testing.assert_allclose(feat_lo[2], [-d, -d, 0, 0, -1, -1, 0, 0], rtol=1e-6)
    np.testing.assert_allclose(feat_hi[2], [d, d, a_max, a_max, 1, 1, d, 60], rtol=1e-6)
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=1)
    plain, _ = twin.reset(seed=1)
    tss = []
    while env.agents:
        for a, o in obs.items():
            assert space.contains(o), a
            np.testing.assert_array_equal(o[:base_size], plain[a])
        act = _actions(rng, env.agents)
        obs, *_ = env.step(act)
        plain, *_ = twin.step(act)
        tss.append(obs["robot_0"][base_size + 7 :: FEATURES_PER_NEIGHBOUR])
    assert set(obs) == set(base.possible_agents)  # the last step still has observations
    assert np.max(tss) > 1.0  # some neighbour went unseen for a while: the feature moves


def test_features_equal_per_robot_trackers_fed_only_with_own_data():
    """Reference: one NeighborTracker per robot, fed by hand with that robot's own
    observation and own action, seeded like the wrapper's bank row."""
    base = _env()
    env = BeliefObservationWrapper(base, tracker_params=FAST)
    obs, _ = env.reset(seed=3)
    fz = env.featurizer
    size = base.observation_space("robot_0").shape[0]
    children = np.random.SeedSequence(fz.tracker_seed).spawn(N)
    params = TrackerParams(**FAST, ego_motion="pose", init_mode="known")
    refs = [
        NeighborTracker(base.config, i, params, np.random.default_rng(children[i]))
        for i in range(N)
    ]
    for i, a in enumerate(base.possible_agents):
        refs[i].reset(obs[a][:size], initial_poses_world=base.poses)
    rng = np.random.default_rng(1)
    for _ in range(25):
        for i, a in enumerate(base.possible_agents):
            e = refs[i].estimate()
            want = np.column_stack(
                [
                    e.mean_body,
                    e.ellipse_a,
                    e.ellipse_b,
                    np.cos(2 * e.ellipse_psi),
                    np.sin(2 * e.ellipse_psi),
                    e.ellipse_distance,
                    np.minimum(e.time_since_seen_s, 60.0),
                ]
            ).reshape(-1)
            np.testing.assert_allclose(obs[a][size:], want.astype(np.float32), rtol=1e-6, atol=1e-5)
        act = _actions(rng, env.agents)
        obs, *_ = env.step(act)
        for i, a in enumerate(base.possible_agents):
            refs[i].step(act[a], obs[a][:size])


def test_a_robots_features_depend_only_on_its_own_observations():
    """Replacing the other robots' observations by another episode's leaves robot 0's
    features unchanged: no row reads another robot's data."""
    env = _env()
    other = _env()
    rng = np.random.default_rng(2)
    obs, _ = env.reset(seed=5)
    obs_other, _ = other.reset(seed=6)
    fa = BeliefFeaturizer(env, init="uniform", tracker_params=FAST)
    fb = BeliefFeaturizer(env, init="uniform", tracker_params=FAST)
    mixed = lambda o, x: {a: (o[a] if a == "robot_0" else x[a]) for a in o}  # noqa: E731
    ra, rb = fa.reset(obs, seed=0), fb.reset(mixed(obs, obs_other), seed=0)
    np.testing.assert_array_equal(ra[0], rb[0])
    for _ in range(20):
        act = _actions(rng, env.agents)
        act_other = _actions(rng, env.agents)
        obs, *_ = env.step(act)
        obs_other, *_ = other.step(act)
        ra = fa.step(act, obs)
        rb = fb.step(mixed(act, act_other), mixed(obs, obs_other))
        np.testing.assert_array_equal(ra[0], rb[0])
        assert not np.array_equal(ra[1:], rb[1:])  # the swap did change the others


class _GuardedEnv(FovCoverageEnv):
    """Ground truth raises once ``forbid`` is set."""

    forbid = False

    @property
    def poses(self):
        if self.forbid:
            raise AssertionError("ground-truth poses read")
        return super().poses

    def state(self):
        if self.forbid:
            raise AssertionError("state() read")
        return super().state()


@pytest.mark.parametrize("init", ["known", "uniform"])
def test_no_ground_truth_after_the_documented_start_poses(init):
    base = _GuardedEnv(n_agents=N, max_cycles=15)
    env = BeliefObservationWrapper(base, init=init, tracker_params=FAST)
    base.forbid = init == "uniform"  # uniform: not even at reset
    env.reset(seed=0)
    base.forbid = True
    rng = np.random.default_rng(0)
    while env.agents:
        env.step(_actions(rng, env.agents))
    # an unseeded (auto-)reset: the known init reads the start poses, and only there
    if init == "known":
        with pytest.raises(AssertionError, match="poses"):
            env.reset()
    else:
        env.reset()


def test_known_start_poses_give_tight_initial_ellipses():
    env = BeliefObservationWrapper(_env(), init="known", tracker_params=FAST)
    obs, _ = env.reset(seed=4)
    size = _env().observation_space("robot_0").shape[0]
    f = obs["robot_0"][size:].reshape(N - 1, FEATURES_PER_NEIGHBOUR)
    assert np.all(f[:, 2] < 1.0)  # semi-axis from the 0.1 m start spread
    env_u = BeliefObservationWrapper(_env(), init="uniform", tracker_params=FAST)
    obs_u, _ = env_u.reset(seed=4)
    fu = obs_u["robot_0"][size:].reshape(N - 1, FEATURES_PER_NEIGHBOUR)
    det = obs_u["robot_0"][0 : 5 * (N - 1) : 5] > 0.5
    assert np.all(fu[~det, 2] > 10.0)  # unseen neighbours: arena-wide uncertainty


def test_deterministic_and_seed_dependent_through_auto_reset():
    def run(seed):
        return _rollout(BeliefObservationWrapper(_env(), tracker_params=FAST), seed, 90)

    a, b, c = run(7), run(7), run(8)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a[45], c[45])
    # the tracker seed stream does not depend on the env's own generator
    env = BeliefObservationWrapper(_env(), tracker_params=FAST)
    env.reset(seed=7)
    s1 = env.featurizer.tracker_seed
    env.reset()
    assert env.featurizer.tracker_seed != s1


def test_pettingzoo_api_and_crossing():
    env = BeliefObservationWrapper(_env(max_cycles=20), tracker_params=FAST)
    parallel_api_test(env, num_cycles=25)
    cross = BeliefObservationWrapper(
        fov_crossing_v0.parallel_env(n_agents=N, max_cycles=10), tracker_params=FAST
    )
    obs, _ = cross.reset(seed=0)
    assert all(cross.observation_space(a).contains(o) for a, o in obs.items())


def test_invalid_arguments():
    with pytest.raises(ValueError, match="init"):
        BeliefObservationWrapper(_env(), init="exact")
    with pytest.raises(ValueError, match="time_cap_s"):
        BeliefObservationWrapper(_env(), time_cap_s=0.0)
    with pytest.raises(ValueError, match="bogus"):
        BeliefObservationWrapper(_env(), tracker_params={"bogus": 1})
    with pytest.raises(ValueError, match="init="):
        BeliefObservationWrapper(_env(), tracker_params={"init_mode": "uniform"})
    with pytest.raises(ValueError, match="before reset"):
        BeliefFeaturizer(_env()).features()
    with pytest.raises(ValueError, match="needs a fov_marl ParallelEnv"):
        BeliefObservationWrapper(object())  # red team 4: an AttributeError
    with pytest.raises(ValueError, match="got the vector env"):
        BeliefObservationWrapper(fov_coverage_v0.vector_env(num_envs=2, n_agents=2))


def test_tracker_budget_is_checked_against_the_team_at_construction():
    """Red team 8: n_particles_total < N - 1 was accepted here and raised only at reset(),
    after the wrapped env had been reset."""
    with pytest.raises(ValueError, match=r"n_particles_total must be >= .* N - 1 = 3, got 2"):
        BeliefObservationWrapper(_env(), tracker_params={"n_particles_total": 2})
    with pytest.raises(ValueError, match=r"n_particles_total must be >= .* N - 1 = 3, got 2"):
        BeliefFeaturizer(_env(), tracker_params={"n_particles_total": 2})
    w = BeliefObservationWrapper(_env(), tracker_params={"n_particles_total": N - 1})
    obs, _ = w.reset(seed=0)  # the smallest budget runs: one particle per neighbour
    assert w.featurizer.bank.estimate().counts.sum(axis=1).tolist() == [N - 1] * N
    assert obs["robot_0"].shape == w.observation_space("robot_0").shape


def test_behind_the_safety_filter():
    wrappers = pytest.importorskip("fov_marl.wrappers")
    if not hasattr(wrappers, "SafetyFilterWrapper"):
        pytest.skip("SafetyFilterWrapper not built yet")
    env = BeliefObservationWrapper(
        wrappers.SafetyFilterWrapper(_env(max_cycles=10)), tracker_params=FAST
    )
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    while env.agents:
        obs, *_ = env.step(_actions(rng, env.agents))
        assert all(env.observation_space(a).contains(o) for a, o in obs.items())


def test_featurizer_checks_its_seed_and_actions():
    """Called directly (the learned policy computes its own features), a bad seed or
    action was numpy's message or a KeyError; the numbers of valid calls are unchanged."""
    from fov_marl.envs import fov_coverage_v0
    from fov_marl.wrappers.belief import BeliefFeaturizer

    env = fov_coverage_v0.parallel_env(n_agents=3, max_cycles=5)
    obs, _ = env.reset(seed=0)
    feat = BeliefFeaturizer(env, tracker_params={"n_particles_total": 60})
    for bad in (-1, 1.5, "a"):
        with pytest.raises(ValueError, match="seed"):
            feat.reset(obs, seed=bad)
    f0 = feat.reset(obs, seed=3)
    act = {a: np.array([0.5, 0.0, 0.1]) for a in env.agents}
    obs2, *_ = env.step(act)
    with pytest.raises(ValueError, match="actions must be a dict"):
        feat.step(np.zeros((3, 3)), obs2)
    with pytest.raises(ValueError, match="robot_2"):
        feat.step({a: act[a] for a in env.agents[:2]}, obs2)
    with pytest.raises(ValueError, match="robot_1"):
        feat.step({**act, "robot_1": "abc"}, obs2)
    f1 = feat.step(act, obs2)
    # the same episode again, actions as lists: the same features
    obs, _ = env.reset(seed=0)
    again = BeliefFeaturizer(env, tracker_params={"n_particles_total": 60})
    np.testing.assert_array_equal(again.reset(obs, seed=3), f0)
    obs2, *_ = env.step(act)
    np.testing.assert_array_equal(again.step({a: list(v) for a, v in act.items()}, obs2), f1)
