"""TorchRL: check_env_specs and 20-step rollouts on the env and behind the safety filter."""

from __future__ import annotations

from importlib.util import find_spec

import numpy as np
import pytest

from fov_marl.envs import fov_coverage_v0
from fov_marl.infos import SAFETY_KEYS, SAFETY_STATUSES
from fov_marl.integrations.torchrl import GROUP, make_env, wrap
from fov_marl.wrappers import SafetyFilterWrapper

# find_spec, not importorskip: importing torchrl at collection costs every xdist worker
pytestmark = pytest.mark.skipif(find_spec("torchrl") is None, reason="needs torchrl")


def check_env_specs(env, seed):
    from torchrl.envs.utils import check_env_specs as check

    check(env, seed=seed)


N = 3
FAST = {"tracker_params": {"n_particles_total": 300}}


def test_plain_pettingzoo_wrapper_accepts_the_env():
    """The acceptance check as a user writes it: TorchRL's own wrapper, default env."""
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper

    env = PettingZooWrapper(fov_coverage_v0.parallel_env(), use_mask=False, seed=0)
    check_env_specs(env, seed=0)
    env = PettingZooWrapper(
        SafetyFilterWrapper(fov_coverage_v0.parallel_env(n_agents=N), **FAST),
        use_mask=False,
        seed=0,
    )
    check_env_specs(env, seed=0)


@pytest.mark.parametrize("safety_filter", [False, True])
def test_check_env_specs_and_a_20_step_rollout(safety_filter):
    import torch

    env = make_env(
        n_agents=N,
        max_cycles=8,
        seed=0,
        safety_filter=safety_filter,
        filter_kwargs=FAST if safety_filter else None,  # without the filter: an error
    )
    check_env_specs(env, seed=0)
    td = env.rollout(20, break_when_any_done=False)  # crosses two automatic resets
    assert td.batch_size == torch.Size([20])
    obs = td["next", GROUP, "observation"]
    assert obs.shape == (20, N, 5 * (N - 1) + 7) and obs.dtype == torch.float32
    assert td[GROUP, "action"].shape == (20, N, 3)
    assert td["next", GROUP, "reward"].shape == (20, N, 1)
    state_dim = fov_coverage_v0.parallel_env(n_agents=N).state_space.shape[0]
    assert td["next", "state"].shape == (20, state_dim)
    done = td["next", "done"].reshape(-1)
    assert done.nonzero().reshape(-1).tolist() == [7, 15]  # max_cycles = 8
    info = td["next", GROUP, "info"]
    eta = info["metrics/eta"]
    assert eta.shape == (20, N) and torch.all((eta >= 0) & (eta <= 1))
    t_s = info["metrics/t_s"][:, 0]
    dt = fov_coverage_v0.parallel_env().config.dt_s
    expected = (np.arange(20) % 8 + 1) * dt
    np.testing.assert_allclose(t_s.numpy(), expected, rtol=1e-6)
    keys = set(info.keys())
    assert set(SAFETY_KEYS) <= keys if safety_filter else not keys & set(SAFETY_KEYS)
    if safety_filter:
        codes = info["safety/status_code"]
        assert torch.all((codes >= 1) & (codes < len(SAFETY_STATUSES)))
        assert info["safety/applied_action"].shape == (20, N, 3)
        # the reset's neutral entries are in the root of the rollout
        assert torch.all(td[GROUP, "info", "safety/status_code"][0] == 0)


def test_seeded_rollouts_are_reproducible_and_crossing_runs():
    import torch

    a = make_env(n_agents=N, max_cycles=10, seed=4).rollout(5)
    b = make_env(n_agents=N, max_cycles=10, seed=4).rollout(5)
    c = make_env(n_agents=N, max_cycles=10, seed=5).rollout(1)
    torch.testing.assert_close(a[GROUP, "observation"][0], b[GROUP, "observation"][0])
    assert not torch.equal(a[GROUP, "observation"][0], c[GROUP, "observation"][0])
    env = make_env("crossing", n_agents=4, max_cycles=6, seed=0)
    check_env_specs(env, seed=0)
    assert "metrics/arrived" in env.rollout(6)["next", GROUP, "info"].keys()


def test_wrap_and_bad_arguments():
    env = wrap(fov_coverage_v0.parallel_env(n_agents=N), seed=1)
    assert env.group_map == {GROUP: [f"robot_{i}" for i in range(N)]}
    with pytest.raises(ValueError, match=r"scenario must be one of \['coverage', 'crossing'\]"):
        make_env("swarm")
    with pytest.raises(ValueError, match="safety_filter must be True or False"):
        make_env(safety_filter="yes")
    with pytest.raises(ValueError, match="n_agents"):
        make_env(n_agents=0)
    # red team 6: ignored without the flag, TypeError for an unknown key
    with pytest.raises(ValueError, match=r"filter_kwargs \[.*\] need safety_filter=True"):
        make_env(n_agents=2, filter_kwargs={"init": "uniform"})
    with pytest.raises(ValueError, match=r"unknown filter_kwargs \['zzz'\]"):
        make_env(n_agents=2, safety_filter=True, filter_kwargs={"zzz": 1})
    with pytest.raises(ValueError, match=r"unknown belief_kwargs \['q'\].*time_cap_s"):
        make_env(n_agents=2, belief=True, belief_kwargs={"q": 1})


def test_wrap_rejects_what_is_no_fov_parallel_env():
    """Red team 7: the AEC env gave TorchRL's 'For AEC environments you need to set
    use_mask=True', a vector env or a string 'TypeError env is not of type expected'."""
    from pettingzoo import ParallelEnv

    from fov_marl.wrappers import BeliefObservationWrapper

    class Foreign(ParallelEnv):
        possible_agents = ["a"]

    takes = r"fov_marl.integrations.torchrl.wrap takes a fov ParallelEnv \(fov_coverage_v0"
    with pytest.raises(ValueError, match=rf"{takes}.*got the AEC env FovAECEnv"):
        wrap(fov_coverage_v0.env(n_agents=2))
    with pytest.raises(ValueError, match=r"takes one fov ParallelEnv.*vector env FovVectorEnv.*"):
        wrap(fov_coverage_v0.vector_env(num_envs=2))
    with pytest.raises(ValueError, match=rf"{takes}.*got 'x' \(str\)"):
        wrap("x")
    with pytest.raises(ValueError, match=r"needs a fov_marl ParallelEnv.*\(Foreign\)"):
        wrap(Foreign())
    with pytest.raises(ValueError, match=r"device must be a torch device.*got 'gpu0' \(str\)"):
        wrap(fov_coverage_v0.parallel_env(n_agents=2), device="gpu0")
    # a wrapper that changes the observations is fine here (TorchRL reads its spaces)
    env = wrap(BeliefObservationWrapper(fov_coverage_v0.parallel_env(n_agents=2)), device=None)
    assert env.group_map == {GROUP: ["robot_0", "robot_1"]}
