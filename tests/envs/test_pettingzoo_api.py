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
