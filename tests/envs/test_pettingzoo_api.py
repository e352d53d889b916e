"""PettingZoo's own API tests on both environments, across team sizes and FoV amplitudes."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from pettingzoo.test import (
    api_test,
    max_cycles_test,
    parallel_api_test,
    parallel_seed_test,
    render_test,
    seed_test,
)
from pettingzoo.test.state_test import state_test

from fov_marl.envs import fov_coverage_v0, fov_crossing_v0

MODULES = [fov_coverage_v0, fov_crossing_v0]
N_AGENTS = [1, 2, 6, 12]
FOVS = [60.0, 120.0, 360.0]


def _small(mod, n, fov, **kw):
    # crossing needs a radius that fits; keep episodes short so the suite stays fast
    return dict(n_agents=n, fov_deg=fov, max_cycles=kw.pop("max_cycles", 60), **kw)


@pytest.mark.parametrize("mod", MODULES, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
@pytest.mark.parametrize("n", N_AGENTS)
@pytest.mark.parametrize("fov", FOVS)
def test_parallel_api(mod, n, fov):
    env = mod.parallel_env(**_small(mod, n, fov))
    parallel_api_test(env, num_cycles=80)


@pytest.mark.parametrize("mod", MODULES, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
@pytest.mark.parametrize("n", N_AGENTS)
@pytest.mark.parametrize("fov", FOVS)
def test_aec_api(mod, n, fov):
    api_test(mod.env(**_small(mod, n, fov)), num_cycles=40)


@pytest.mark.parametrize("mod", MODULES, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
@pytest.mark.parametrize("n", N_AGENTS)
@pytest.mark.parametrize("fov", FOVS)
def test_seed(mod, n, fov):
    seed_test(functools.partial(mod.env, **_small(mod, n, fov)), num_cycles=20)
    parallel_seed_test(functools.partial(mod.parallel_env, **_small(mod, n, fov)), num_cycles=20)


@pytest.mark.parametrize("mod", MODULES, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
def test_max_cycles(mod):
    max_cycles_test(mod)


@pytest.mark.parametrize("mod", MODULES, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
@pytest.mark.parametrize("n", N_AGENTS)
@pytest.mark.parametrize("fov", FOVS)
def test_render(mod, n, fov):
    render_test(functools.partial(mod.env, **_small(mod, n, fov)))


@pytest.mark.parametrize("mod", MODULES, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
@pytest.mark.parametrize("n", N_AGENTS)
@pytest.mark.parametrize("fov", FOVS)
def test_state(mod, n, fov):
    state_test(mod.env(**_small(mod, n, fov)), mod.parallel_env(**_small(mod, n, fov)))


@pytest.mark.parametrize("mod", MODULES, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
def test_spaces_are_cached_objects(mod):
    env = mod.parallel_env()
    a = env.possible_agents[0]
    assert env.observation_space(a) is env.observation_space(a)
    assert env.action_space(a) is env.action_space(a)
    assert env.action_space(a).shape == (3,)
    assert env.observation_space(a).shape == (5 * (env.config.n_agents - 1) + 7,)
    assert np.all(env.action_space(a).low == -1) and np.all(env.action_space(a).high == 1)


@pytest.mark.parametrize("mod", MODULES, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
def test_space_dicts_are_pettingzoo_attributes(mod):
    """``observation_spaces`` / ``action_spaces`` (PettingZoo's documented attributes):
    the spaces of the methods, in a dict whose edits change nothing; the belief wrapper
    gives its augmented spaces, the filter forwards the env's."""
    from fov_marl.wrappers import BeliefObservationWrapper, SafetyFilterWrapper

    env = mod.parallel_env(n_agents=3)
    for a in env.possible_agents:
        assert env.observation_spaces[a] is env.observation_space(a)
        assert env.action_spaces[a] is env.action_space(a)
    env.observation_spaces.clear()
    assert set(env.observation_spaces) == set(env.possible_agents)
    filt = SafetyFilterWrapper(mod.parallel_env(n_agents=3))
    assert filt.observation_spaces["robot_0"].shape == env.observation_space("robot_0").shape
    bel = BeliefObservationWrapper(mod.parallel_env(n_agents=3))
    assert bel.observation_spaces["robot_0"] is bel.observation_space("robot_0")
    assert bel.observation_spaces["robot_0"].shape != env.observation_space("robot_0").shape


def _episode_length(env, limit: int = 50) -> int:
    env.reset(seed=0)
    steps = 0
    while env.agents and steps < limit:
        env.step({a: np.zeros(3, np.float32) for a in env.agents})
        steps += 1
    return steps


@pytest.mark.parametrize("mod", MODULES, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
def test_max_cycles_set_on_a_wrapper_or_the_aec_env_truncates(mod):
    """Red team 4: ``max_cycles`` set on SafetyFilterWrapper, BeliefObservationWrapper or
    the AEC env was stored on the wrapper and ignored (episodes ran on to 1000)."""
    from fov_marl.wrappers import BeliefObservationWrapper, SafetyFilterWrapper

    filt = SafetyFilterWrapper(mod.parallel_env(n_agents=2))
    bel = BeliefObservationWrapper(SafetyFilterWrapper(mod.parallel_env(n_agents=2)))
    for wrapped in (filt, bel):
        wrapped.max_cycles = 3
        assert wrapped.unwrapped.max_cycles == 3 == wrapped.max_cycles
        assert _episode_length(wrapped) == 3
        with pytest.raises(ValueError, match="max_cycles"):
            wrapped.max_cycles = 0
    aec = mod.env(n_agents=2)
    aec.max_cycles = 3
    assert aec.unwrapped.max_cycles == 3
    aec.reset(seed=0)
    turns = 0
    for _ in aec.agent_iter(100):
        *_, term, trunc, _ = aec.last()
        aec.step(None if term or trunc else np.zeros(3, np.float32))
        turns += 1
    assert turns == 3 * 2 + 2  # 3 steps of 2 agents, then each agent's final turn
    with pytest.raises(ValueError, match="max_cycles"):
        aec.max_cycles = 1.5


@pytest.mark.parametrize("mod", MODULES, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
def test_ground_truth_before_reset_is_an_error(mod):
    """Red team 26: before reset() state(), poses and an rgb_array render() gave every
    robot the pose (0, 0, 0), overlapping outside the arena; the vector env too."""
    from fov_marl.wrappers import SafetyFilterWrapper

    env = mod.parallel_env(n_agents=2, render_mode="rgb_array")
    venv = mod.vector_env(num_envs=2, n_agents=2)
    for e in (env, SafetyFilterWrapper(mod.parallel_env(n_agents=2)), venv):
        for read in (lambda e: e.state(), lambda e: e.poses, lambda e: e.targets):
            with pytest.raises(ValueError, match=r"before reset\(\)"):
                read(e)
    with pytest.raises(ValueError, match=r"render\(\) called before reset\(\)"):
        env.render()
    env.reset(seed=0)
    venv.reset(seed=0)
    assert env.poses.shape == (2, 3) and venv.poses.shape == (2, 2, 3)
    assert env.render().ndim == 3 and env.state().shape == venv.state()[0].shape
    np.testing.assert_array_equal(env.state(), venv.state()[0])


@pytest.mark.parametrize("mod", MODULES, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
def test_step_messages_say_before_reset_or_finished(mod):
    from fov_marl.wrappers import SafetyFilterWrapper

    for env in (mod.parallel_env(n_agents=2, max_cycles=1),
                SafetyFilterWrapper(mod.parallel_env(n_agents=2, max_cycles=1))):  # fmt: skip
        with pytest.raises(ValueError, match=r"before reset\(\)"):
            env.step({})
        assert _episode_length(env) == 1
        with pytest.raises(ValueError, match="finished episode"):
            env.step({a: np.zeros(3) for a in env.possible_agents})
