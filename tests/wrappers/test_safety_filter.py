"""SafetyFilterWrapper: PettingZoo API, reporting, determinism, and no collisions under
random and adversarial policies."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from fov_marl.control import ControllerParams
from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
from fov_marl.evaluation import run_episode
from fov_marl.wrappers import SafetyFilterWrapper
from fov_marl.wrappers.safety_filter import FILTER_CONTROLLER_DEFAULTS


def test_wrapper_passes_parallel_api_test_and_keeps_spaces():
    base = fov_coverage_v0.parallel_env(n_agents=4, max_cycles=40)
    env = SafetyFilterWrapper(base)
    for a in env.possible_agents:
        assert env.observation_space(a) is base.observation_space(a)
        assert env.action_space(a) is base.action_space(a)
    parallel_api_test(env, num_cycles=50)


def test_safety_info_reports_nominal_applied_and_status():
    env = SafetyFilterWrapper(fov_coverage_v0.parallel_env(n_agents=4))
    obs, _ = env.reset(seed=0)
    acts = {a: np.array([1.0, 0.0, 0.3], dtype=np.float32) for a in env.agents}
    _, _, _, _, infos = env.step(acts)
    for a, info in infos.items():
        s = info["safety"]
        assert set(s) >= {"nominal_action", "applied_action", "intervened", "status", "fallback"}
        np.testing.assert_allclose(s["nominal_action"], acts[a])
        assert env.action_space(a).contains(s["applied_action"])
        if not s["intervened"]:  # only the speed polygon (16-gon in the disk) may shave u*
            np.testing.assert_allclose(s["applied_action"], s["nominal_action"], atol=0.02)
        assert not s["fallback"]
    assert env.last_cpu_s > 0


def test_wrapper_validates_actions_like_the_env():
    env = SafetyFilterWrapper(fov_coverage_v0.parallel_env(n_agents=3))
    env.reset(seed=0)
    good = {a: np.zeros(3) for a in env.agents}
    with pytest.raises(ValueError, match="robot_1"):
        env.step({**good, "robot_1": np.array([np.nan, 0.0, 0.0])})
    with pytest.raises(ValueError, match="robot_2"):
        env.step({**good, "robot_2": np.zeros(4)})
    with pytest.raises(ValueError, match="fov_marl environment"):
        SafetyFilterWrapper(object.__new__(type("Fake", (), {"unwrapped": property(lambda s: s)})))


def test_wrapper_is_deterministic_under_a_seed():
    kw = dict(n_agents=4, max_steps=80, record_trajectory=True, safety_filter=True)
    a = run_episode("coverage", "random", 11, **kw)
    b = run_episode("coverage", "random", 11, **kw)
    np.testing.assert_array_equal(a.trajectory, b.trajectory)
    assert a.filter_interventions == b.filter_interventions


def adversarial_factory(env):
    """Drive every robot straight at its nearest teammate at full speed (ground truth)."""

    class Adversary:
        def reset(self, seed=None):
            pass

        def act(self, obs):
            poses = env.unwrapped.poses
            out = {}
            for i, a in enumerate(env.unwrapped.possible_agents):
                d = poses[:, :2] - poses[i, :2]
                dist = np.linalg.norm(d, axis=1)
                dist[i] = np.inf
                j = int(np.argmin(dist))
                c, s = np.cos(poses[i, 2]), np.sin(poses[i, 2])
                g = np.array([c * d[j, 0] + s * d[j, 1], -s * d[j, 0] + c * d[j, 1]])
                v = g / max(np.linalg.norm(g), 1e-9)
                out[a] = np.array([v[0], v[1], 0.0], dtype=np.float32)
            return out

    return Adversary()


def _random(env):
    from fov_marl.baselines import make_policy

    return make_policy("random", env)


def _check_no_collisions(factory, n, seeds, steps, scenario="coverage"):
    for seed in seeds:
        rec = run_episode(scenario, factory, seed, n_agents=n, safety_filter=True, max_steps=steps)
        assert rec.collisions == 0, (factory.__name__, n, seed, rec)
        assert rec.qp_fallbacks is not None


@pytest.mark.parametrize("n", [4, 8])
def test_no_collisions_random_and_adversarial_quick(n):
    _check_no_collisions(_random, n, range(2), 200)
    _check_no_collisions(adversarial_factory, n, range(2), 200)


def test_unfiltered_adversary_does_collide():
    """The adversary is a real threat: without the filter it collides."""
    rec = run_episode("coverage", adversarial_factory, 0, n_agents=4, max_steps=200)
    assert rec.collisions > 0


@pytest.mark.slow
@pytest.mark.parametrize("n", [4, 8])
@pytest.mark.parametrize("factory", [_random, adversarial_factory], ids=["random", "adversarial"])
def test_no_collisions_20_episodes(n, factory):
    _check_no_collisions(factory, n, range(20), 1000)


def test_filter_controller_defaults_and_overrides():
    """The filter adds the motion cone and a 0.5 m/s safety margin to ControllerParams();
    dict overrides keep the other filter defaults, a dataclass is used as given."""
    base = fov_coverage_v0.parallel_env(n_agents=3)
    prm = SafetyFilterWrapper(base).pipeline.controller_params
    assert prm == ControllerParams(**FILTER_CONTROLLER_DEFAULTS)
    assert prm.motion_cone and prm.safety_speed_margin_mps == 0.5
    over = SafetyFilterWrapper(base, controller_params={"blind_speed_mps": 0.1})
    assert over.pipeline.controller_params.motion_cone
    assert over.pipeline.controller_params.blind_speed_mps == 0.1
    given = SafetyFilterWrapper(base, controller_params=ControllerParams())
    assert not given.pipeline.controller_params.motion_cone


def test_filter_moves_robots_fast_only_where_they_look():
    """A policy backing every robot at full speed: behind the filter a robot goes faster
    than v_b outside the ±20° cone only when a safety row needs it (cone_violation)."""
    n = 6

    def backwards(env):
        class Back:
            def reset(self, seed=None):
                pass

            def act(self, obs):
                return {a: np.array([-1.0, 0.0, 0.0], np.float32) for a in obs}

        return Back()

    env = SafetyFilterWrapper(fov_coverage_v0.parallel_env(n_agents=n))
    pol = backwards(env)
    obs, _ = env.reset(seed=3)
    prm = env.pipeline.controller_params
    cfg = env.config
    fast_blind = legit = 0
    for _ in range(60):
        obs, _, _, _, infos = env.step(pol.act(obs))
        for i, a in enumerate(env.possible_agents):
            act = infos[a]["safety"]["applied_action"]
            v = act[:2] * cfg.v_max_mps
            ang = math.degrees(math.atan2(v[1], v[0]))
            if abs(ang) > prm.cone_half_angle_deg + 10 and np.hypot(*v) > 2 * prm.blind_speed_mps:
                fast_blind += 1
                legit += env.pipeline.last_results[i].cone_violation > 0
    assert legit == fast_blind
    unfiltered = run_episode(
        "coverage", backwards, 3, n_agents=n, max_steps=5, record_trajectory=True
    )
    step = np.linalg.norm(np.diff(np.array(unfiltered.trajectory)[:, :, :2], axis=0), axis=-1)
    assert step.max() > 0.9 * cfg.v_max_mps * cfg.dt_s  # the policy itself backs off at full speed


def test_filter_on_crossing_env():
    env = SafetyFilterWrapper(fov_crossing_v0.parallel_env())
    obs, _ = env.reset(seed=0)
    for _ in range(5):
        obs, *_ = env.step({a: np.zeros(3) for a in env.agents})
    assert set(obs) == set(env.possible_agents)
