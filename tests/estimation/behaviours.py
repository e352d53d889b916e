"""Neighbour behaviours the default tracker must stay calibrated for (issue 10, item 8).

Each behaviour drives *every* robot of a team; a :class:`~fov_marl.estimation.TrackerBank`
of all robots tracks the others and a
:class:`~fov_marl.estimation.testing.CalibrationCounter` counts, for every (robot,
neighbour) pair and step, whether the truth is inside the reported 95% ellipse.

* ``pfcbf``: the paper's controller (``make_policy("pfcbf")``) in ``fov_coverage_v0``,
  the paper's setup (40 m arena, N = 6, β = 120°, random starts). The observing bank is
  separate from the policy's own trackers (it sees the same observations and actions).
* the others run in :class:`~fov_marl.estimation.testing.MiniWorld` (the env's
  kinematics, camera and noise) from a *clustered* start (:func:`clustered_poses`, a 10 m
  square around q_m: a team deployed together, in sight of each other): ``random``
  (uniform actions, the ``random`` baseline), ``smooth_random`` (OU velocity), and the
  adversaries ``straight``, ``charge_centre``, ``spin_charge``, ``chase``,
  ``wait_charge`` (see :mod:`fov_marl.estimation.testing`).

Why clustered starts: from the paper's random starts in the 40 m arena most pairs are
never within the 10 m camera range in a 60 s episode (e.g. 87% of the steps for uniform
random actions), so the rate there measures the prior of never-seen robots, not the
tracker. :func:`behaviour_counter` takes ``start="random"`` for that view too.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np

from fov_marl.config import make_config
from fov_marl.estimation import TrackerBank, TrackerParams
from fov_marl.estimation import testing as T
from fov_marl.geometry import world_to_body

MOTIONS: dict[str, Callable] = {
    "random": T.UniformRandomMotion,
    "smooth_random": T.RandomMotion,
    "straight": T.StraightMotion,
    "charge_centre": T.ChargeCentreMotion,
    "spin_charge": functools.partial(T.ChargeCentreMotion, spin=True),
    "chase": T.ChaseMotion,
    "wait_charge": T.WaitChargeMotion,
}

#: Every behaviour of the calibration tests, in table order.
BEHAVIOURS = ("pfcbf", *MOTIONS)


def pfcbf_counter(
    params: TrackerParams | None, steps: int, seed: int, n_agents: int = 6
) -> T.CalibrationCounter:
    """Calibration of an observing bank while ``pfcbf`` drives the team in the env."""
    from fov_marl.baselines import make_policy
    from fov_marl.envs import fov_coverage_v0

    env = fov_coverage_v0.parallel_env(n_agents=n_agents, max_cycles=steps + 5)
    obs, _ = env.reset(seed=seed)
    policy = make_policy("pfcbf", env)
    policy.reset(seed=seed)
    bank = TrackerBank(env.config, params, seed=seed)
    bank.reset(obs, initial_poses_world=env.poses)
    counter = T.CalibrationCounter()
    others = [[j for j in range(n_agents) if j != i] for i in range(n_agents)]
    for _ in range(steps):
        actions = policy.act(obs)
        obs, *_ = env.step(actions)
        bank.step(actions, obs)
        poses = env.poses
        truth = np.stack([world_to_body(poses[js, :2], poses[i]) for i, js in enumerate(others)])
        counter.add(bank.estimate(), truth)
    return counter


def behaviour_counter(
    name: str,
    params: TrackerParams | None = None,
    steps: int = 300,
    seed: int = 0,
    start: str = "cluster",
    n_agents: int = 6,
) -> T.CalibrationCounter:
    """One episode of behaviour ``name`` (see the module docstring), counted."""
    if name == "pfcbf":
        return pfcbf_counter(params, steps, seed, n_agents)
    cfg = make_config(n_agents=n_agents)
    starts = {"cluster": T.clustered_poses, "random": None}
    return T.calibration_counter(cfg, MOTIONS[name], params, steps, seed, start=starts[start])


def pooled(
    name: str,
    params: TrackerParams | None,
    steps: int,
    seeds,
    start: str = "cluster",
    n_agents: int = 6,
) -> dict[str, dict[str, float]]:
    """:meth:`CalibrationCounter.stats` of ``name`` pooled over ``seeds``."""
    total = T.CalibrationCounter()
    for s in seeds:
        total.merge(behaviour_counter(name, params, steps, s, start, n_agents))
    return total.stats()
