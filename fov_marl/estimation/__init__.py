"""Neighbour estimation: one particle filter per neighbour in the robot's body frame, with
deletion inside the camera's field of view and a fixed, re-allocated particle budget
(paper Section IV-V). The default motion model is a mode mixture (static random walk,
Eq. 20, Eq. 22, constant velocity, with Markov switching), calibrated whatever the
neighbours do; the paper's single models are ``TrackerParams(motion_model="coverage" |
"crossing" | "static")``. See :mod:`fov_marl.estimation.params`.

Public API::

    from fov_marl.estimation import NeighborTracker, TrackerParams, TrackerEstimate
    tracker = NeighborTracker.for_env(env, agent="robot_0", seed=0)
    tracker.reset(obs["robot_0"], initial_poses_world=env.poses)   # or None: uniform
    tracker.step(actions["robot_0"], obs["robot_0"])
    est = tracker.estimate()    # ellipses, d_ij, mode_probs (M, 4), velocity_est_body, ...

    bank = TrackerBank.for_env(env, seed=0)      # all robots at once, same numbers
    bank.reset(obs, initial_poses_world=env.poses); bank.step(actions, obs)
    est_all = bank.estimate(); est_all.robot(k)

    vbank = VectorTrackerBank(config, params, n_copies=B)   # B env copies, one set of arrays
    vbank.reset(obs_bnd, initial_poses_world=poses_bn3, seeds=[s + k for k in range(B)])
    vbank.step(actions_bn3, obs_bnd); vbank.reset_copies(done_mask, obs_bnd, poses_bn3, seeds)
"""

from fov_marl.estimation.params import TrackerParams
from fov_marl.estimation.tracker import (
    BankEstimate,
    NeighborTracker,
    TrackerBank,
    TrackerEstimate,
    VectorTrackerBank,
)

__all__ = [
    "NeighborTracker",
    "TrackerBank",
    "TrackerParams",
    "TrackerEstimate",
    "BankEstimate",
    "VectorTrackerBank",
]
