"""Observation and action layouts shared by the envs, trackers and policies.

This module is the single definition of what a robot observes and how an action
maps to a body-frame velocity; the environments encode with it, the neighbour
tracker and the policies decode with it. It sits beside :mod:`fov_marl.config`
(below ``estimation``/``control``/``envs`` in the import order).

Observation of robot i (float32, length ``5 * (N - 1) + 7``)
-------------------------------------------------------------

Neighbour slots, one per other robot ID in ascending order, skipping i
(slot ``k`` holds robot ``j = k if k < i else k + 1``); 5 entries each:

=====  ===================  ==========================  ===========================
entry  name                 unit / frame                when not detected
=====  ===================  ==========================  ===========================
0      detected             1.0 if j ∈ F_i else 0.0     0
1      ⁱx_j                 m, Σ_i, noisy               0
2      ⁱy_j                 m, Σ_i, noisy               0
3      cos(θ_j − θ_i)       noisy relative heading      0
4      sin(θ_j − θ_i)       noisy relative heading      0
=====  ===================  ==========================  ===========================

Then the robot's own cue (7 entries), which differs by scenario:

=====  =========================  ==========================================
entry  coverage                   crossing
=====  =========================  ==========================================
0      own x (m, Σ_w)             own x (m, Σ_w)
1      own y (m, Σ_w)             own y (m, Σ_w)
2      cos(own yaw)               cos(own yaw)
3      sin(own yaw)               sin(own yaw)
4      ⁱq_m x (m, Σ_i)            own target x (m, Σ_i)
5      ⁱq_m y (m, Σ_i)            own target y (m, Σ_i)
6      density σ (m)              distance to own target (m)
=====  =========================  ==========================================

Actions
-------

``Box(-1, 1, (3,), float32)``: ``[vx, vy, ω]`` normalised. Values outside the box
are clipped to it; the planar part is then scaled by ``v_max`` and, if its norm
exceeds ``v_max`` (diagonal commands), shrunk to norm ``v_max``; ``ω = a₂ ω_max``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "SLOT_SIZE",
    "CUE_SIZE",
    "SLOT_DETECTED",
    "SLOT_P_BODY",
    "SLOT_YAW_CS",
    "CUE_P_WORLD",
    "CUE_YAW_CS",
    "CUE_GOAL_BODY",
    "CUE_SCALAR",
    "ObservationLayout",
    "Detections",
    "action_to_velocity",
    "velocity_to_action",
]

SLOT_SIZE = 5
CUE_SIZE = 7

# The entries of the tables above, by name (the one place that says where each is):
#: slot entry 0, the detection flag (1.0 if j ∈ F_i else 0.0)
SLOT_DETECTED = 0
#: slot entries 1-2, ``ⁱp_j`` (m, Σ_i, noisy)
SLOT_P_BODY = slice(1, 3)
#: slot entries 3-4, ``(cos, sin)(θ_j − θ_i)`` (noisy)
SLOT_YAW_CS = slice(3, 5)
#: cue entries 0-1, the robot's own position (m, Σ_w)
CUE_P_WORLD = slice(0, 2)
#: cue entries 2-3, ``(cos, sin)`` of its own yaw
CUE_YAW_CS = slice(2, 4)
#: cue entries 4-5, ``ⁱq_m`` (coverage) or its own target (crossing) in Σ_i (m)
CUE_GOAL_BODY = slice(4, 6)
#: cue entry 6, the density σ (coverage) or the distance to its own target (crossing), m
CUE_SCALAR = 6


@dataclass(frozen=True)
class Detections:
    """Decoded camera detections of one robot.

    Attributes:
        ids: ``(K,)`` int robot IDs detected (ascending).
        p_body: ``(K, 2)`` measured positions in Σ_i (m).
        yaw_rel_rad: ``(K,)`` measured relative headings θ_j − θ_i (rad).
    """

    ids: np.ndarray
    p_body: np.ndarray
    yaw_rel_rad: np.ndarray


@dataclass(frozen=True)
class ObservationLayout:
    """Index arithmetic of one robot's observation vector (see module docstring)."""

    n_agents: int
    agent_index: int

    def __post_init__(self) -> None:
        if isinstance(self.n_agents, bool) or not isinstance(self.n_agents, int | np.integer):
            raise ValueError(f"n_agents must be an integer in [1, inf), got {self.n_agents!r}")
        if self.n_agents < 1:
            raise ValueError(f"n_agents must be an integer in [1, inf), got {self.n_agents!r}")
        if (
            isinstance(self.agent_index, bool)
            or not isinstance(self.agent_index, int | np.integer)
            or not 0 <= self.agent_index < self.n_agents
        ):
            raise ValueError(
                f"agent_index must be an integer in [0, {self.n_agents - 1}], "
                f"got {self.agent_index!r}"
            )

    @property
    def n_slots(self) -> int:
        """Number of neighbour slots, N − 1."""
        return self.n_agents - 1

    @property
    def size(self) -> int:
        """Length of the observation vector."""
        return SLOT_SIZE * self.n_slots + CUE_SIZE

    @property
    def neighbour_ids(self) -> np.ndarray:
        """``(N − 1,)`` robot ID held by each slot."""
        return np.array([j for j in range(self.n_agents) if j != self.agent_index], dtype=np.int64)

    @property
    def cue_slice(self) -> slice:
        """Slice of the own-cue block."""
        return slice(SLOT_SIZE * self.n_slots, self.size)

    def slots(self, obs: np.ndarray) -> np.ndarray:
        """``(..., N − 1, 5)`` view of the neighbour slots of ``obs`` ``(..., size)``."""
        obs = np.asarray(obs)
        m = self.n_slots
        return obs[..., : SLOT_SIZE * m].reshape(*obs.shape[:-1], m, SLOT_SIZE)

    def cue(self, obs: np.ndarray) -> np.ndarray:
        """``(..., 7)`` own cue of ``obs`` ``(..., size)``."""
        return np.asarray(obs)[..., self.cue_slice]

    def slot_arrays(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every slot of ``obs`` ``(..., size)`` as arrays (the batched :meth:`decode`).

        Returns:
            ``detected`` ``(..., N − 1)`` bool, ``p_body`` ``(..., N − 1, 2)`` measured
            positions in Σ_i (m) and ``yaw_rel_rad`` ``(..., N − 1)`` measured θ_j − θ_i
            (rad), float64; an undetected slot holds the env's zeros (its yaw is 0).
        """
        s = self.slots(obs).astype(np.float64)
        cs = s[..., SLOT_YAW_CS]
        return s[..., SLOT_DETECTED] > 0.5, s[..., SLOT_P_BODY], np.arctan2(cs[..., 1], cs[..., 0])

    def decode(self, obs: np.ndarray) -> Detections:
        """Detections contained in one observation vector.

        Raises:
            ValueError: ``obs`` does not have shape ``(size,)``.
        """
        obs = np.asarray(obs)
        if obs.shape != (self.size,):
            raise ValueError(
                f"observation of robot_{self.agent_index} must have shape ({self.size},), "
                f"got {obs.shape}"
            )
        det, p_body, yaw = self.slot_arrays(obs)
        return Detections(ids=self.neighbour_ids[det], p_body=p_body[det], yaw_rel_rad=yaw[det])

    def own_pose_world(self, obs: np.ndarray) -> np.ndarray:
        """``(..., 3)`` the robot's own world pose ``[x m, y m, yaw rad]`` from its cue
        (``obs`` ``(..., size)``)."""
        c = self.cue(obs).astype(np.float64)
        p, cs = c[..., CUE_P_WORLD], c[..., CUE_YAW_CS]
        return np.stack([p[..., 0], p[..., 1], np.arctan2(cs[..., 1], cs[..., 0])], -1)

    def goal_body(self, obs: np.ndarray) -> np.ndarray:
        """``(..., 2)`` q_m (coverage) or the own target (crossing) in Σ_i (m)."""
        return self.cue(obs)[..., CUE_GOAL_BODY].astype(np.float64)


def action_to_velocity(
    action: np.ndarray, v_max: float, omega_max: float
) -> tuple[np.ndarray, np.ndarray]:
    """Map normalised actions to body-frame velocities (see module docstring).

    Args:
        action: ``(..., 3)`` actions; clipped to ``[-1, 1]``.
        v_max: maximum planar speed (m/s).
        omega_max: maximum yaw rate (rad/s).

    Returns:
        ``(v_body (..., 2) m/s, omega (...) rad/s)`` with ``‖v_body‖ ≤ v_max``.
    """
    a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    v = a[..., :2] * v_max
    speed = np.linalg.norm(v, axis=-1, keepdims=True)
    v = v * np.minimum(1.0, v_max / np.maximum(speed, 1e-300))
    return v, a[..., 2] * omega_max


def velocity_to_action(v_body: np.ndarray, omega: np.ndarray, v_max: float, omega_max: float):
    """Inverse of :func:`action_to_velocity` for inputs within the limits.

    Args:
        v_body: ``(..., 2)`` m/s with ``‖v‖ ≤ v_max``.
        omega: ``(...)`` rad/s with ``|ω| ≤ ω_max``.

    Returns:
        ``(..., 3)`` float32 actions in ``[-1, 1]`` (clipped against round-off).
    """
    v_body = np.asarray(v_body, dtype=np.float64)
    a = np.concatenate(
        [v_body / v_max, (np.asarray(omega, dtype=np.float64) / omega_max)[..., None]], -1
    )
    return np.clip(a, -1.0, 1.0).astype(np.float32)
