"""What the two PettingZoo wrappers refuse at construction, and what they leave alone.

Found by a red team of the wrappers: each case below used to be accepted and then
failed later with an internal error, or ran in a state its options contradict.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
from fov_marl.wrappers import BeliefObservationWrapper, SafetyFilterWrapper


def _env(n: int = 3):
    return fov_coverage_v0.parallel_env(n_agents=n, max_cycles=5)


@pytest.mark.parametrize(("init", "mode"), [("known", "uniform"), ("uniform", "known")])
def test_the_filter_refuses_an_init_mode_that_contradicts_init(init, mode):
    # known + uniform particles started the controller as if the poses were known
    # (budget unspent, last-seen points at the true starts); uniform + known failed at
    # reset() asking for initial_poses_world, which the user never passes
    with pytest.raises(ValueError, match=rf"init_mode = '{mode}' contradicts init = '{init}'"):
        SafetyFilterWrapper(_env(), init=init, tracker_params={"init_mode": mode})
    # the same mode as init, or 'auto', is accepted
    SafetyFilterWrapper(_env(), init=init, tracker_params={"init_mode": init}).reset(seed=0)
    SafetyFilterWrapper(_env(), init=init, tracker_params={"init_mode": "auto"}).reset(seed=0)


def test_the_filter_refuses_too_few_particles_before_any_reset():
    with pytest.raises(ValueError, match=r"n_particles_total must be >= .* N - 1 = 2, got 1"):
        SafetyFilterWrapper(_env(3), tracker_params={"n_particles_total": 1})
    SafetyFilterWrapper(_env(3), tracker_params={"n_particles_total": 2}).reset(seed=0)


@pytest.mark.parametrize("wrapper", [SafetyFilterWrapper, BeliefObservationWrapper])
@pytest.mark.parametrize("module", [fov_coverage_v0, fov_crossing_v0])
def test_an_aec_env_is_refused_naming_the_parallel_env(wrapper, module):
    # its .unwrapped is the ParallelEnv, so it passed, and reset() raised a TypeError
    with pytest.raises(ValueError, match="got the AEC env .*parallel_to_aec"):
        wrapper(module.env(n_agents=3))


def test_wrappers_that_change_the_observations_go_outside():
    with pytest.raises(ValueError, match=r"shape \(17,\) .* gives \(33,\).*outside"):
        SafetyFilterWrapper(BeliefObservationWrapper(_env()))
    with pytest.raises(ValueError, match=r"shape \(17,\) .* gives \(33,\)"):
        BeliefObservationWrapper(BeliefObservationWrapper(_env()))
    # the documented order works, and a wrapper that keeps the layout is accepted
    env = BeliefObservationWrapper(SafetyFilterWrapper(_env()))
    obs, _ = env.reset(seed=0)
    assert obs["robot_0"].shape == (33,)
    SafetyFilterWrapper(SafetyFilterWrapper(_env())).reset(seed=0)


def test_the_belief_wrapper_checks_its_reset_before_the_env_moves():
    env = _env()
    env.reset(seed=0)
    wrapped = BeliefObservationWrapper(env)
    with pytest.raises(ValueError, match=r"BeliefObservationWrapper.step\(\) called before"):
        wrapped.step({a: np.array([1.0, 0.0, 0.0]) for a in wrapped.agents})
    assert env.num_steps == 0


def test_the_speed_polygon_shrink_is_not_an_intervention():
    """Documented in ``safety/intervened``: u* is first mapped into the controller's
    16-sided speed polygon; a full-speed command between two vertices is slowed by
    1 − cos(π/16) and the step is still "unconstrained", not intervened."""
    env = SafetyFilterWrapper(_env(1))
    env.reset(seed=0)
    _, _, _, _, infos = env.step({"robot_0": np.array([1.0, 0.0, 0.0], np.float32)})
    info = infos["robot_0"]
    assert info["safety/applied_action"][0] == pytest.approx(math.cos(math.pi / 16), abs=1e-6)
    assert not info["safety/intervened"] and info["safety/cause_bits"] == 0


def test_a_wrapper_that_changes_one_agents_observations_is_refused():
    from pettingzoo.utils import BaseParallelWrapper

    class OneLonger(BaseParallelWrapper):
        def observation_space(self, agent):
            space = self.env.observation_space(agent)
            if agent != "robot_1":
                return space
            import gymnasium

            return gymnasium.spaces.Box(-1.0, 1.0, (space.shape[0] + 1,), np.float32)

    with pytest.raises(ValueError, match=r"gives \(18,\) for robot_1"):
        SafetyFilterWrapper(OneLonger(_env()))
