"""Neighbour estimation: one particle filter per neighbour in the robot's body frame, with
deletion inside the camera's field of view and a fixed, re-allocated particle budget
(paper Section IV-V).

Public API::

    from fov_marl.estimation import NeighborTracker, TrackerParams, TrackerEstimate
    tracker = NeighborTracker.for_env(env, agent="robot_0", seed=0)
    tracker.reset(obs["robot_0"], initial_poses_world=env.poses)   # or None: uniform
    tracker.step(actions["robot_0"], obs["robot_0"])
    est = tracker.estimate()

    bank = TrackerBank.for_env(env, seed=0)      # all robots at once, same numbers
    bank.reset(obs, initial_poses_world=env.poses); bank.step(actions, obs)
    est_all = bank.estimate(); est_all.robot(k)
"""

from fov_marl.estimation.params import TrackerParams
from fov_marl.estimation.tracker import BankEstimate, NeighborTracker, TrackerBank, TrackerEstimate

__all__ = ["NeighborTracker", "TrackerBank", "TrackerParams", "TrackerEstimate", "BankEstimate"]
