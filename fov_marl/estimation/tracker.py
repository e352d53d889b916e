"""Neighbour tracking with one particle filter per neighbour and a fixed budget (Section IV-V).

:class:`TrackerBank` steps the trackers of several robots at once on one set of flat
arrays (block = (robot, neighbour)); :class:`NeighborTracker` is a bank of one robot.
Each robot uses only its own data: its applied action, its own observation (camera
detections with IDs, its own pose and the mission cue) and its own ``Generator``.

One step of robot i (:meth:`TrackerBank.step`), all neighbours at once, no loop over
particles or neighbours (the only Python loops are over robots, for their own
Generators, and over the rare re-seeded neighbours):

1. prediction (Eq. 2): each particle moves by the neighbour model u_j^est plus process
   noise, in the old Σ_i. The default model (``motion_model="auto"`` = ``"mixture"``)
   is a mode mixture (:func:`~fov_marl.estimation.kernels.mixture_predict`): every
   particle carries a mode (static random walk; Eq. 20 towards q_m, saturated at v_max
   and with a standoff, :func:`~fov_marl.estimation.kernels.coverage_input`; Eq. 22,
   v_max/2 towards robot i; constant velocity with a per-particle velocity state) that
   switches with a small Markov probability per step, so the detections update the
   mode probabilities through the weights and the resampling. The paper's single
   models are ``"coverage"`` (Eq. 20), ``"crossing"`` (Eq. 22) and ``"static"``. Then
   the particle is re-expressed in the new Σ_i by the inverse of robot i's own motion
   (exact unicycle integration of the applied action, with the env's arena clamp;
   velocity states are rotated); positions are clamped to the arena (known to every
   robot) and the relative heading takes a random walk;
2. weight (Eq. 3): Gaussian likelihood of the detection, in log space;
3. deletion (Eq. 4): particles inside F_i of an undetected neighbour get weight 0;
4. recovery (a documented addition): a neighbour whose particles were all deleted is
   re-seeded outside F_i, by default (``recovery_reseed="local"``) uniform in the disc
   around the deleted cloud's mean whose radius is the cloud's extent plus
   ``recovery_local_margin_m`` (the neighbour was just where the belief put it, within
   that error, and is not where the view now looks), or (``"arena"``) uniform over the
   arena (the belief of a neighbour that slipped just out of view then spreads over
   tens of metres and it stops counting for safety: the traced N = 24 collision of
   :mod:`fov_marl.baselines.pfcbf`); a detected neighbour whose particles
   miss the detection (nearest one beyond the χ² gate, or effective sample size below
   ``min(recovery_min_ess, P_j / 2)``, or a biased cloud, below) is re-seeded from
   N(z, Σ_MEAS) (clamped to the arena), the posterior when the prior is flat on the
   likelihood's scale. Both are counted. With ``ess_recovery="fuse"`` (the safety
   filter's setting) a cloud that failed only the effective-size test is instead moved
   onto the Gaussian posterior of its own moments and the detection
   (:func:`~fov_marl.estimation.kernels.fuse_onto_detection`, clamped, counted in
   ``n_fusions``, no random draw): a narrow cloud is a prior that the weights can no
   longer represent, not a wrong one, and the re-seed trusted one detection alone
   (traced: a detection 1.2 m off, 3.8 σ, re-seeded the cloud of a neighbour 1.1 m away
   beyond the wall, the clamp put it on the robot itself, and the filter drove into the
   neighbour; stress grid, seed 17000). *Bias test*: a cloud can be confidently wrong
   without missing any single detection: constant-velocity particles that learnt a
   velocity from detection noise run on past a neighbour that has stopped, a few
   detection std each step, and the narrow cloud (std 0.12-0.2 m against Σ_MEAS's
   0.32 m) follows each detection only by a Kalman-like fraction (traced: seed 9100 of
   the stress grid, a cloud 0.7-0.9 m beyond a parked neighbour for 2 s, its 95%
   ellipse excluding the truth, and the robot, seeing it, closed to 1.977 m < D_s).
   Each detected step adds the residual ``r = Σ_MEAS^{-1/2} (z − mean)`` (x, y; the
   step-5 mean; rotated into the world frame so that the robot's own turns do not
   move it) to an exponentially weighted average ``ē ← (1 − α) ē + α r``
   (``recovery_bias_alpha`` α, 0 = off by default, 0.2 in the safety filter; undetected
   steps leave it). For a calibrated cloud r
   has per-axis variance at most 1 (``Σ_MEAS`` minus the posterior's), so ``‖ē‖²
   (2 − α) / α`` is at most χ² (2 dof) distributed; above ``recovery_bias_chi2``
   (p = 1e-3 per detected step) the next detection re-seeds the neighbour. A recovered
   neighbour's ē restarts at 0;
5. estimate (Eq. 5, normalised weighted mean; Section V Gaussian fit): mean, covariance,
   95% ellipse (Eq. 6-7) and the exact distance d_ij from robot i to it (replaces
   Eq. 8-10). The reported covariance is the weighted particle covariance times
   ``1 + κ / ESS`` (``mc_error_factor`` κ): the particle mean is itself a Monte Carlo
   estimate, and its error, accumulated over steps by resampling every step, would
   otherwise make the ellipse overconfident at P_j of a few hundred;
6. budget re-allocation (Section IV-B) by ascending d_ij
   (:func:`~fov_marl.estimation.kernels.allocate_budget`), then one systematic
   resampling of each neighbour's weighted set at its new size: this single draw is
   both the resampling step (IV-A 5) and the re-allocation's "another resampling step
   ... without modifying the current probability distribution" (IV-B); drawing once
   instead of twice gives the same distribution with less sampling noise.

The estimate describes the weighted set of step 5; the particles returned by
:meth:`TrackerBank.particles_body` are the resampled set of step 6 (same distribution).

Random draws per robot and step, in this order: ``standard_normal((3, P_T))`` process
noise (x, y, heading); recovery draws, by ascending neighbour ID; ``random(M)``
resampling offsets. The mixture adds (the single models are unchanged, bit for bit):
``random(P_T)`` for the mode switches right after the process noise (whose x, y normals
also drive the velocity noise, see
:func:`~fov_marl.estimation.kernels.mixture_predict`); each recovery draws its usual
numbers and then ``standard_normal((2, P_j))`` for fresh velocities (modes of re-seeded
particles are assigned by stratified prior quantiles, no draw); the reset draws
``standard_normal((2, P_T))`` fresh velocities after the initial cloud.

The prediction's draws are the first of a step, so a bank stepping its chunks of robots
one after the other (``n_threads=1``) draws chunk k + 1's on a helper thread while chunk
k computes (:data:`DRAW_AHEAD`; a quarter of a step at P_T = 2000 is these draws): the
same numbers as drawing inline, bit for bit.
"""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor, wait
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from fov_marl.config import ScenarioConfig
from fov_marl.estimation import kernels as K
from fov_marl.estimation.params import TrackerParams
from fov_marl.geometry import chi2_2dof, confidence_ellipse, ellipse_distance, world_to_body
from fov_marl.spaces import CUE_SIZE, SLOT_SIZE, ObservationLayout, action_to_velocity
from fov_marl.validation import ConfigError, check_int, check_seed, describe, holds_bool

__all__ = [
    "TrackerEstimate",
    "BankEstimate",
    "TrackerBank",
    "NeighborTracker",
    "VectorTrackerBank",
    "check_particle_budget",
]


@dataclass(frozen=True)
class TrackerEstimate:
    """What robot i believes about its M = N − 1 neighbours, ordered by ascending ID.

    All positions in robot i's body frame Σ_i at the time of the last observation.
    Arrays are read-only copies.

    Attributes:
        ids: ``(M,)`` int neighbour robot IDs.
        mean_body: ``(M, 2)`` estimated ⁱp_j (m), Eq. 5 (normalised weighted mean).
        cov_body: ``(M, 2, 2)`` weighted covariance (m²).
        ellipse_a, ellipse_b: ``(M,)`` semi-axes (m) of the confidence ellipse, a ≥ b.
        ellipse_psi: ``(M,)`` inclination of the major axis from the body x axis (rad).
        ellipse_distance: ``(M,)`` exact distance from robot i (origin of Σ_i) to the
            filled ellipse, 0 inside (m).
        counts: ``(M,)`` particles now held per neighbour; sums to P_T (N = 1: no
            neighbour, no particles, an empty array).
        detected: ``(M,)`` bool, detected in the last observation.
        time_since_seen_s: ``(M,)`` seconds since the last detection (since the reset
            when never detected).
        velocity_est_body: ``(M, 2)`` the neighbour model u_j^est evaluated at the mean,
            in Σ_i (m/s): Eq. 20 / Eq. 22 for those models, zeros for ``static``; for the
            ``mixture``, the mixture's mean velocity ``P_cov u_20(μ) + P_cross u_22(μ) +
            Σ_{k ∈ cv} w_k v_k / Σ_k w_k`` (mode probabilities P from ``mode_probs``,
            the constant-velocity particles' own velocities; static contributes 0).
        ess: ``(M,)`` effective sample size of the weighted set behind the estimate.
        recovered: ``(M,)`` bool, re-seeded on the last update.
        mode_probs: ``(M, 4)`` weighted fraction of the particles in each motion mode
            (order :data:`~fov_marl.estimation.kernels.MODE_NAMES`: static, coverage,
            crossing, cv) behind the estimate; one-hot for the single models.
        velocity_cv_body: ``(M, 2)`` weighted mean velocity state of the particles in the
            constant-velocity mode, in Σ_i (m/s): how the neighbour moves *if* it keeps
            the velocity the detections showed (e.g. a charger at full speed, where
            ``velocity_est_body`` is that times ``mode_probs[:, 3]`` plus the other
            modes); zeros without cv particles and for the single models.
        confidence: the ellipse's confidence level.
        time_s: simulated seconds since the reset.
    """

    ids: np.ndarray
    mean_body: np.ndarray
    cov_body: np.ndarray
    ellipse_a: np.ndarray
    ellipse_b: np.ndarray
    ellipse_psi: np.ndarray
    ellipse_distance: np.ndarray
    counts: np.ndarray
    detected: np.ndarray
    time_since_seen_s: np.ndarray
    velocity_est_body: np.ndarray
    ess: np.ndarray
    recovered: np.ndarray
    mode_probs: np.ndarray
    velocity_cv_body: np.ndarray
    confidence: float
    time_s: float


@dataclass(frozen=True)
class BankEstimate:
    """The estimates of all robots of a bank: :class:`TrackerEstimate`'s array fields with a
    leading robot axis ``(R, M, ...)``; ``agent_indices (R,)`` the robots, ``time_s``."""

    agent_indices: np.ndarray
    ids: np.ndarray
    mean_body: np.ndarray
    cov_body: np.ndarray
    ellipse_a: np.ndarray
    ellipse_b: np.ndarray
    ellipse_psi: np.ndarray
    ellipse_distance: np.ndarray
    counts: np.ndarray
    detected: np.ndarray
    time_since_seen_s: np.ndarray
    velocity_est_body: np.ndarray
    ess: np.ndarray
    recovered: np.ndarray
    mode_probs: np.ndarray
    velocity_cv_body: np.ndarray
    confidence: float
    time_s: float

    def robot(self, k: int) -> TrackerEstimate:
        """The :class:`TrackerEstimate` of the bank's ``k``-th robot (row k).

        Raises:
            ValueError: ``k`` not an integer in ``[0, R − 1]`` (no negative indexing).
        """
        k = check_int("k", k, 0, int(self.agent_indices.shape[0]) - 1, note="(a robot row)")
        kw = {}
        for f in fields(TrackerEstimate):
            v = getattr(self, f.name)
            kw[f.name] = _ro(v[k]) if isinstance(v, np.ndarray) else v
        return TrackerEstimate(**kw)


def _ro(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


def _resolve_agent(env: Any, agent: str | int) -> int:
    agents = list(getattr(env, "possible_agents", []))
    if isinstance(agent, int | np.integer) and not isinstance(agent, bool):
        idx = int(agent)
        if not 0 <= idx < max(len(agents), 1):
            raise ValueError(f"agent must be in [0, {len(agents) - 1}], got {agent!r}")
        return idx
    if agent not in agents:
        raise ValueError(f"agent must be one of {agents}, got {agent!r}")
    return agents.index(agent)


def _real_data(name: str, value: Any, shape_text: str) -> np.ndarray:
    """``np.asarray(value)`` when it holds integer or floating data, else a ``ValueError``
    naming ``name`` and the expected shape (str, bytes, bool, complex, object data and
    what NumPy cannot convert; nothing is coerced). The shape is left to the caller."""
    raw = None
    if not isinstance(value, str | bytes | bytearray):
        try:
            raw = np.asarray(value)
        except Exception:  # ragged lists, objects whose __array__ fails
            raw = None
    if raw is None or raw.dtype.kind not in "iuf" or holds_bool(value):
        raise ConfigError(
            f"{name} must be a {shape_text} array of real numbers, got {describe(value)}"
        )
    return raw


def _items(name: str, value: Any, what: str) -> list[Any]:
    """``list(value)`` for a sequence (not a str), else a ``ValueError`` naming ``name``
    and ``what`` it must hold."""
    if not isinstance(value, str | bytes | bytearray):
        try:
            return list(value)
        except TypeError:  # not iterable (an int, a Generator, a 0-d array)
            pass
    raise ConfigError(f"{name} must be a sequence of {what}, got {describe(value)}")


def _env_config(env: Any) -> ScenarioConfig:
    cfg = getattr(env, "config", None)
    if cfg is None and hasattr(env, "unwrapped"):
        cfg = getattr(env.unwrapped, "config", None)
    if not isinstance(cfg, ScenarioConfig):
        raise ValueError(f"env must expose a ScenarioConfig as env.config, got {cfg!r}")
    return cfg


class _BankCore:
    """The computation for a contiguous group of robots (rows); see :class:`TrackerBank`.

    Inputs are validated by :class:`TrackerBank`; every array here has a leading row axis.
    """

    def __init__(
        self,
        config: ScenarioConfig,
        params: TrackerParams,
        agent_indices: np.ndarray,
        rngs: list[np.random.Generator],
        copy_index: np.ndarray | None = None,
    ) -> None:
        n = config.n_agents
        m = n - 1
        self.config = config
        self.params = params
        self.agent_indices = agent_indices
        self._rngs = list(rngs)
        self._R = agent_indices.size
        # env copy of each row (a vector bank); neighbour IDs are within the copy
        self._copy = (
            np.zeros(self._R, dtype=np.int64) if copy_index is None else np.asarray(copy_index)
        )
        self._M = m
        # particles held per row: P_T, or none without a neighbour (N = 1)
        self._P = int(params.n_particles_total) if m else 0
        lays = [ObservationLayout(n, int(a)) for a in agent_indices]
        self._layout = ObservationLayout(n, 0)  # decodes every row: slots need only N
        self._ids = np.stack([lay.neighbour_ids for lay in lays]).reshape(self._R, m)
        model = params.motion_model
        self._model = "mixture" if model == "auto" else model
        self._mix = self._model == "mixture"
        self._chi2 = chi2_2dof(params.confidence)
        var = np.maximum(np.asarray(config.meas_cov_diag, dtype=np.float64), params.min_meas_var)
        self._meas_std = np.sqrt(var)
        self._meas_var = (float(var[0]), float(var[1]))
        self._inv_var = tuple(float(v) for v in 1.0 / var)
        r = config.robot_radius_m
        self._lo, self._hi = r, config.arena_size_m - r
        self._fov = config.fov_rad
        self._range = config.detection_range_m
        self._dt = config.dt_s
        self._vmax = float(config.v_max_mps)
        self._q_m = np.asarray(config.density_mean_m, dtype=np.float64)
        rho = params.coverage_standoff_m
        self._standoff = float(
            config.sensing_radius_m + config.safety_distance_m if rho is None else rho
        )
        self._sig_p = params.process_noise_m_per_sqrt_s * math.sqrt(self._dt)
        self._sig_h = params.heading_noise_rad_per_sqrt_s * math.sqrt(self._dt)
        self._noise = np.empty((self._R, 3, self._P))
        if self._mix:
            self._uni = np.empty((self._R, self._P))
            self._cdf = K.mode_cdf(params.mode_prior())
            self._p_switch = -math.expm1(-params.mode_switch_rate_hz * self._dt)
            q_mix = params.mixture_noise_m_per_sqrt_s
            self._sig_mode = math.sqrt(self._dt) * np.array(
                [q_mix, q_mix, q_mix, params.cv_noise_m_per_sqrt_s]
            )
            self._sig_v = params.cv_velocity_noise_mps_per_sqrt_s * math.sqrt(self._dt)
        self._u = np.empty((self._R, m))
        self._block_ids = np.arange(self._R * m)
        self._origin = np.zeros(2)
        self.initialised = False
        self.n_recoveries_detection = np.zeros(self._R, dtype=np.int64)
        self.n_fusions = np.zeros(self._R, dtype=np.int64)
        self.n_recoveries_deleted = np.zeros(self._R, dtype=np.int64)

    def _parse(self, obs: np.ndarray):
        lay = self._layout
        det, z, zh = lay.slot_arrays(obs)
        pose = lay.own_pose_world(obs)
        if self.config.scenario == "coverage":
            goal = lay.goal_body(obs)
        else:
            goal = world_to_body(self._q_m[None, :], pose)
        return det, z[..., 0], z[..., 1], zh, pose, goal

    def reset(self, obs_arr: np.ndarray, init: np.ndarray | None) -> None:
        """Eq. 1 (``init`` (N, 3) or, per copy, (B, N, 3) known world poses, or None:
        uniform), then the first update."""
        det, zx, zy, zh, pose, goal = self._parse(obs_arr)
        R, M, P = self._R, self._M, self._P
        self._counts = np.tile(K.equal_split(P, M), (R, 1)) if M else np.zeros((R, 0), np.int64)
        self._set_blocks()
        self._x = np.empty((R, P))
        self._y = np.empty((R, P))
        self._h = np.empty((R, P))
        if M:
            if init is not None:
                init_r = (init[None] if init.ndim == 2 else init)[self._copy[:, None], self._ids]
                rel = world_to_body(init_r[..., :2], pose[:, None, :])  # (R, M, 2)
                rel_h = K.wrap(init_r[..., 2] - pose[:, None, 2])
                gl = self._gid.reshape(R, P) - (np.arange(R) * M)[:, None]
                for k, g in enumerate(self._rngs):
                    nz = g.standard_normal((3, P))
                    self._x[k] = rel[k, gl[k], 0] + self.params.init_spread_m * nz[0]
                    self._y[k] = rel[k, gl[k], 1] + self.params.init_spread_m * nz[1]
                    self._h[k] = K.wrap(
                        rel_h[k, gl[k]] + self.params.init_heading_spread_rad * nz[2]
                    )
            else:
                span = self._hi - self._lo
                for k, g in enumerate(self._rngs):
                    uu = g.random((3, P))
                    wx = self._lo + span * uu[0]
                    wy = self._lo + span * uu[1]
                    b = world_to_body(np.stack([wx, wy], -1), pose[k])
                    self._x[k] = b[:, 0]
                    self._y[k] = b[:, 1]
                    self._h[k] = 2.0 * math.pi * uu[2] - math.pi
            if self._mix:
                self._vx = np.empty((R, P))
                self._vy = np.empty((R, P))
                for k, g in enumerate(self._rngs):
                    nv = g.standard_normal((2, P))
                    self._vx[k], self._vy[k] = K.fresh_velocity(
                        nv[0], nv[1], self._vmax, self._h[k], self.params.cv_forward_bias
                    )
                local = np.arange(R * P) - self._starts[self._gid]
                self._mode = K.stratified_modes(
                    local, self._block_len[self._gid], self._cdf
                ).reshape(R, P)
        elif self._mix:  # no neighbour (N = 1): empty per-particle states (P = 0)
            self._vx = np.empty((R, 0))
            self._vy = np.empty((R, 0))
            self._mode = np.empty((R, 0), dtype=np.int8)
        self._tss = np.zeros((R, M))
        self._time = np.zeros(R)
        self.n_recoveries_detection[:] = 0
        self.n_fusions[:] = 0
        self.n_recoveries_deleted[:] = 0
        self._bias = np.zeros((R, M, 2))
        self._bias_alarm = np.zeros((R, M), dtype=bool)
        self.initialised = True
        self._update(det, zx, zy, zh, pose)
        self._pose_prev = pose
        self._goal_prev = goal

    def _set_blocks(self) -> None:
        c = self._counts.reshape(-1)
        self._block_len = c
        self._gid = np.repeat(self._block_ids, c)
        starts = np.empty_like(c)
        if c.size:
            starts[0] = 0
            np.cumsum(c[:-1], out=starts[1:])
        self._starts = starts

    def step(self, act: np.ndarray, obs_arr: np.ndarray, drawn: bool = False) -> None:
        """Predict (Eq. 2) with the rows' actions, then update with their observations.

        ``drawn``: :meth:`draw_step_noise` has already made this step's prediction draws
        (on a helper thread, :func:`_step_cores_serial`); the numbers are the same either way.
        """
        det, zx, zy, zh, pose, goal = self._parse(obs_arr)
        if self._M:
            self._predict(act, pose, drawn)
        self._tss += self._dt
        self._time += self._dt
        self._update(det, zx, zy, zh, pose)
        self._pose_prev = pose
        self._goal_prev = goal

    def draw_step_noise(self) -> None:
        """The prediction's draws of one step, each row from its own Generator: the first
        draws of a step (module docstring), so they may be made before :meth:`step` (on
        another thread, while other rows compute) without changing a number."""
        if not self._M:
            return
        for k, g in enumerate(self._rngs):
            g.standard_normal(out=self._noise[k])
            if self._mix:
                g.random(out=self._uni[k])

    def _predict(self, act: np.ndarray, pose_now: np.ndarray, drawn: bool = False) -> None:
        """Eq. 2: neighbour model + process noise in the old Σ_i, then the inverse own motion."""
        cfg, p = self.config, self.params
        dt = self._dt
        if p.ego_motion == "action":
            v, om = action_to_velocity(act, cfg.v_max_mps, cfg.omega_max_radps)
            d_body, dyaw = K.own_motion(self._pose_prev, v, om, dt, self._lo, self._hi)
        else:
            d_body = world_to_body(pose_now[:, :2], self._pose_prev)
            dyaw = K.wrap(pose_now[:, 2] - self._pose_prev[:, 2])
        if not drawn:
            self.draw_step_noise()
        x, y, h = self._x, self._y, self._h
        if self._mix:
            self._predict_mixture(d_body, dyaw, pose_now)
            return
        if self._model == "coverage":
            q = self._goal_prev
            ux, uy = K.coverage_input(
                x, y, q[:, 0:1], q[:, 1:2], p.k_p, cfg.v_max_mps, self._standoff
            )
        elif self._model == "crossing":
            ux, uy = K.crossing_input(x, y, cfg.v_max_mps)
        else:
            ux = uy = None
        nz = self._noise
        if ux is None:
            xo = x + self._sig_p * nz[:, 0]
            yo = y + self._sig_p * nz[:, 1]
        else:
            xo = x + dt * ux + self._sig_p * nz[:, 0]
            yo = y + dt * uy + self._sig_p * nz[:, 1]
        ho = h + self._sig_h * nz[:, 2]
        x, y, h = K.to_new_body_frame(xo, yo, ho, d_body[:, 0:1], d_body[:, 1:2], dyaw[:, None])
        if p.clamp_to_arena:
            x, y = self._clamp(x, y, pose_now[:, 0:1], pose_now[:, 1:2], pose_now[:, 2:3])
        self._x, self._y, self._h = x, y, h

    def _predict_mixture(self, d_body, dyaw, pose_now) -> None:
        """Eq. 2 with the mode mixture (:func:`~fov_marl.estimation.kernels.mixture_predict`)
        in the old Σ_i, then the inverse own motion (positions, headings, velocities)."""
        p = self.params
        nz = self._noise
        q = self._goal_prev
        xo, yo, vx, vy, mode = K.mixture_predict(
            self._x,
            self._y,
            self._h,
            self._vx,
            self._vy,
            self._mode,
            self._uni,
            (nz[:, 0], nz[:, 1]),
            q[:, 0:1],
            q[:, 1:2],
            dt=self._dt,
            p_switch=self._p_switch,
            cdf=self._cdf,
            k_p=p.k_p,
            v_max=self._vmax,
            standoff_m=self._standoff,
            sig_pos_by_mode=self._sig_mode,
            sig_vel=self._sig_v,
            forward_bias=p.cv_forward_bias,
        )
        ho = self._h + self._sig_h * nz[:, 2]
        dy = dyaw[:, None]
        x, y, h = K.to_new_body_frame(xo, yo, ho, d_body[:, 0:1], d_body[:, 1:2], dy)
        if p.clamp_to_arena:
            x, y = self._clamp(x, y, pose_now[:, 0:1], pose_now[:, 1:2], pose_now[:, 2:3])
        self._x, self._y, self._h = x, y, h
        self._vx, self._vy = K.rotate_velocity(vx, vy, dy)
        self._mode = mode

    def _clamp(self, x, y, px, py, yaw):
        """Clamp body-frame positions to the arena ``[r, L − r]^2`` (via Σ_w, own pose)."""
        c = np.cos(yaw)
        s = np.sin(yaw)
        lo, hi = self._lo, self._hi
        # in place, in the same order of operations as
        # wx = min(max(px + c x − s y, lo), hi) − px  (and wy), then R(yaw)ᵀ (wx, wy)
        wx = c * x
        wx += px
        wx -= s * y
        np.maximum(wx, lo, out=wx)
        np.minimum(wx, hi, out=wx)
        wx -= px
        wy = s * x
        wy += py
        wy += c * y
        np.maximum(wy, lo, out=wy)
        np.minimum(wy, hi, out=wy)
        wy -= py
        bx = c * wx
        bx += s * wy
        by = c * wy
        by -= s * wx
        return bx, by

    # ------------------------------------------------------------------ update
    def _update(self, det, zx, zy, zh, pose) -> None:
        """Eq. 3-5, recovery, Section V estimate, IV-B re-allocation and resampling."""
        R, M, P = self._R, self._M, self._P
        self._tss[det] = 0.0
        self._det = det.copy()
        if M == 0:
            self._store_empty()
            return
        x = self._x.reshape(-1)
        y = self._y.reshape(-1)
        h = self._h.reshape(-1)
        gid, starts, blen = self._gid, self._starts, self._block_len
        det_f = det.reshape(-1)
        # per-particle copies of per-block values by np.repeat over the contiguous
        # blocks: the numbers of a gather by gid, several times faster
        det_p = np.repeat(det_f, blen)
        if det_f.any():
            dx = x - np.repeat(zx.reshape(-1), blen)
            dy = y - np.repeat(zy.reshape(-1), blen)
            dh = K.wrap(h - np.repeat(zh.reshape(-1), blen))
            lw_det, maha = K.measurement_log_likelihood(dx, dy, dh, self._inv_var)
            lw = np.where(det_p, lw_det, 0.0)
            maha_min = np.minimum.reduceat(maha, starts)
        else:
            lw = np.zeros(x.shape[0])
            maha_min = np.zeros(R * M)
        lw[K.deletion_mask(x, y, det_p, self._fov, self._range)] = -np.inf
        lw_max = np.maximum.reduceat(lw, starts)
        dead = lw_max == -np.inf
        shift = np.where(dead, 0.0, lw_max)
        lw -= np.repeat(shift, blen)
        w = np.exp(lw, out=lw)
        sw = np.add.reduceat(w, starts)
        sw2 = np.add.reduceat(w * w, starts)
        ess = np.divide(sw * sw, sw2, out=np.zeros_like(sw), where=~dead)
        thr = np.minimum(self.params.recovery_min_ess, 0.5 * blen)
        alarm = self._bias_alarm.reshape(-1)
        gated = (maha_min > self.params.recovery_gate_chi2) | alarm
        if self.params.ess_recovery == "fuse":  # a collapsed set that passed the gates
            fuse = det_f & (ess < thr) & ~gated
            rec_det = det_f & gated
        else:
            fuse = None
            rec_det = det_f & (gated | (ess < thr))
        rec = rec_det | dead
        if rec.any():
            self._recover_all(np.flatnonzero(rec), det_f, x, y, h, w, zx, zy, zh, pose)
            ess = np.where(rec, blen.astype(np.float64), ess)
        if fuse is not None and fuse.any():
            self._fuse_detected(np.flatnonzero(fuse), x, y, w, zx, zy, pose)
            ess = np.where(fuse, blen.astype(np.float64), ess)
        sw, mean, cov = K.weighted_moments(x, y, w, gid, starts, blen)
        if self._mix:
            mode = self._mode.reshape(-1)
            vx = self._vx.reshape(-1)
            vy = self._vy.reshape(-1)
            probs = np.bincount(gid * 4 + mode, weights=w, minlength=4 * R * M).reshape(-1, 4)
            probs /= sw[:, None]
            w_cv = w * (mode == K.MODE_CV)
            v_cv = np.stack(
                [np.add.reduceat(w_cv * vx, starts) / sw, np.add.reduceat(w_cv * vy, starts) / sw],
                -1,
            )
        if self.params.mc_error_factor > 0.0:
            cov *= (1.0 + self.params.mc_error_factor / ess)[:, None, None]
        a, b, psi = confidence_ellipse(cov, self._chi2)
        dist = ellipse_distance(self._origin, mean, a, b, psi)
        if self.params.recovery_bias_alpha > 0.0:
            self._bias_test(det, rec.reshape(R, M), zx, zy, mean.reshape(R, M, 2), pose)
        mean_r = mean.reshape(R, M, 2)
        d_r = dist.reshape(R, M)
        counts = K.allocate_budget(
            d_r, P, self.params.min_particles_per_neighbour, self.params.allocation_scale_m
        )
        for k, g in enumerate(self._rngs):
            self._u[k] = g.random(M)
        idx = K.systematic_resample_indices(
            w, P, gid, starts, blen, counts.reshape(-1), self._u.reshape(-1)
        )
        self._x = np.take(x, idx).reshape(R, P)
        self._y = np.take(y, idx).reshape(R, P)
        self._h = np.take(h, idx).reshape(R, P)
        if self._mix:
            self._mode = np.take(mode, idx).reshape(R, P)
            self._vx = np.take(vx, idx).reshape(R, P)
            self._vy = np.take(vy, idx).reshape(R, P)
            self._mode_probs = probs.reshape(R, M, 4)
            self._v_cv = v_cv.reshape(R, M, 2)
        self._counts = counts
        self._set_blocks()
        self._est = dict(
            mean_body=mean_r,
            cov_body=cov.reshape(R, M, 2, 2),
            ellipse_a=a.reshape(R, M),
            ellipse_b=b.reshape(R, M),
            ellipse_psi=psi.reshape(R, M),
            ellipse_distance=d_r,
            ess=ess.reshape(R, M),
            recovered=rec.reshape(R, M),
            mode_probs=self._mode_probs if self._mix else self._one_hot(),
            velocity_cv_body=self._velocity_cv() if self._mix else np.zeros((R, M, 2)),
        )

    def _bias_test(self, det, rec, zx, zy, mean, pose) -> None:
        """The bias test of step 4 (module docstring): update ē with this step's
        residuals (detected, not re-seeded) and set the alarms read by the next update.
        ``det``, ``rec``: ``(R, M)``; ``zx``, ``zy``: ``(R, M)``; ``mean``: ``(R, M, 2)``
        body frame; ``pose``: ``(R, 3)`` world."""
        alpha = self.params.recovery_bias_alpha
        rx = (zx - mean[..., 0]) / self._meas_std[0]
        ry = (zy - mean[..., 1]) / self._meas_std[1]
        c = np.cos(pose[:, 2])[:, None]
        s = np.sin(pose[:, 2])[:, None]
        r = np.stack([c * rx - s * ry, s * rx + c * ry], -1)
        upd = det & ~rec
        self._bias = np.where(upd[..., None], (1.0 - alpha) * self._bias + alpha * r, self._bias)
        self._bias[rec] = 0.0
        stat = np.einsum("rmk,rmk->rm", self._bias, self._bias) * ((2.0 - alpha) / alpha)
        self._bias_alarm = stat > self.params.recovery_bias_chi2

    def _store_empty(self) -> None:
        R = self._R
        self._est = dict(
            mean_body=np.zeros((R, 0, 2)),
            cov_body=np.zeros((R, 0, 2, 2)),
            ellipse_a=np.zeros((R, 0)),
            ellipse_b=np.zeros((R, 0)),
            ellipse_psi=np.zeros((R, 0)),
            ellipse_distance=np.zeros((R, 0)),
            ess=np.zeros((R, 0)),
            recovered=np.zeros((R, 0), dtype=bool),
            mode_probs=np.zeros((R, 0, 4)),
            velocity_cv_body=np.zeros((R, 0, 2)),
        )

    def _velocity_cv(self) -> np.ndarray:
        """``(R, M, 2)`` mean velocity of the cv particles (0 where there are none)."""
        p_cv = self._mode_probs[..., K.MODE_CV : K.MODE_CV + 1]
        return np.divide(self._v_cv, p_cv, out=np.zeros_like(self._v_cv), where=p_cv > 0)

    def _one_hot(self) -> np.ndarray:
        """``(R, M, 4)`` mode probabilities of a single-model tracker."""
        out = np.zeros((self._R, self._M, 4))
        out[..., K.MODE_NAMES.index(self._model)] = 1.0
        return out

    def _recover_all(self, blocks, det_f, x, y, h, w, zx, zy, zh, pose) -> None:
        """Re-seed ``blocks`` (ascending flat block indices) in place (module docstring,
        step 4). The robots whose re-seeds are all around detections (the common case:
        ~2 per robot-step at N = 48) are done at once, one draw per robot of all its
        blocks' normals (the same numbers as :meth:`_recover` block by block: a
        Generator's normals are drawn in sequence); a robot with a deleted block goes
        block by block, keeping its draw order."""
        M = self._M
        rows = blocks // M
        slow = np.isin(rows, rows[~det_f[blocks]])
        for b in blocks[slow]:
            self._recover(b, bool(det_f[b]), x, y, h, w, zx, zy, zh, pose)
        fast = blocks[~slow]
        if fast.size:
            self._reseed_detected(fast, x, y, h, w, zx, zy, zh, pose)

    def _reseed_detected(self, fast, x, y, h, w, zx, zy, zh, pose) -> None:
        """Re-seed the detected blocks ``fast`` (ascending) from N(z, Σ_MEAS): per robot one
        draw of ``(3 + 2 mixture) P_j`` normals per block, in block order."""
        rows = fast // self._M
        n, loc, idx = self._block_particles(fast)
        per = 5 if self._mix else 3  # normals per particle: x, y, h (+ 2 velocity)
        draws = []
        for k in np.unique(rows).tolist():
            draws.append(self._rngs[k].standard_normal(per * int(n[rows == k].sum())))
        flat = np.concatenate(draws)
        off = np.zeros(fast.size, dtype=np.int64)  # each block's offset in ``flat``
        np.cumsum(per * n[:-1], out=off[1:])
        nb = np.repeat(n, n)
        base = np.repeat(off, n) + loc
        sd = self._meas_std
        k_p = np.repeat(rows, n)
        bx = np.repeat(zx.reshape(-1)[fast], n) + sd[0] * flat[base]
        by = np.repeat(zy.reshape(-1)[fast], n) + sd[1] * flat[base + nb]
        if self.params.clamp_to_arena:
            bx, by = self._clamp(bx, by, pose[k_p, 0], pose[k_p, 1], pose[k_p, 2])
        x[idx] = bx
        y[idx] = by
        hn = K.wrap(np.repeat(zh.reshape(-1)[fast], n) + sd[2] * flat[base + 2 * nb])
        h[idx] = hn
        if self._mix:
            vx, vy = K.fresh_velocity(
                flat[base + 3 * nb], flat[base + 4 * nb], self._vmax, hn,
                self.params.cv_forward_bias,
            )  # fmt: skip
            self._vx.reshape(-1)[idx] = vx
            self._vy.reshape(-1)[idx] = vy
            self._mode.reshape(-1)[idx] = K.stratified_modes(loc, nb, self._cdf)
        np.add.at(self.n_recoveries_detection, rows, 1)
        w[idx] = 1.0

    def _block_particles(self, blocks: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(n (k,), loc (Σn,), idx (Σn,))`` of the flat ``blocks``: their sizes, each
        particle's index within its block, and the particles' flat indices."""
        n = self._block_len[blocks]
        loc = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
        return n, loc, np.repeat(self._starts[blocks], n) + loc

    def _fuse_detected(self, blocks, x, y, w, zx, zy, pose) -> None:
        """``ess_recovery="fuse"`` (step 4): map the clouds of the detected ``blocks``
        (flat block indices) onto the Gaussian posterior of their moments and the
        detection (:func:`~fov_marl.estimation.kernels.fuse_onto_detection`), clamp them
        to the arena, weights 1. No random draw; headings, modes and velocities kept."""
        n, _, idx = self._block_particles(blocks)
        bx, by = K.fuse_onto_detection(
            x[idx], y[idx], n, zx.reshape(-1)[blocks], zy.reshape(-1)[blocks], self._meas_var
        )
        if self.params.clamp_to_arena:
            k_p = np.repeat(blocks // self._M, n)
            bx, by = self._clamp(bx, by, pose[k_p, 0], pose[k_p, 1], pose[k_p, 2])
        x[idx] = bx
        y[idx] = by
        w[idx] = 1.0
        np.add.at(self.n_fusions, blocks // self._M, 1)

    def _recover(self, b, detected, x, y, h, w, zx, zy, zh, pose) -> None:
        """Re-seed block ``b`` in place (see module docstring, step 4); weights become 1."""
        k, j = divmod(int(b), self._M)
        g = self._rngs[k]
        s = int(self._starts[b])
        n = int(self._block_len[b])
        e = s + n
        if detected:
            self._reseed_detected(np.array([b]), x, y, h, w, zx, zy, zh, pose)
            return
        if self.params.recovery_reseed == "local":
            cx, cy = float(x[s:e].mean()), float(y[s:e].mean())
            spread = float(np.sqrt(np.max((x[s:e] - cx) ** 2 + (y[s:e] - cy) ** 2)))
            radius = spread + self.params.recovery_local_margin_m
            bx, by = self._disc_outside_fov(g, n, cx, cy, radius, pose[k])
        else:
            bx, by = self._uniform_outside_fov(g, n, pose[k])
        x[s:e] = bx
        y[s:e] = by
        h[s:e] = 2.0 * math.pi * g.random(n) - math.pi
        self._recover_mixture(g, k, s, e)
        self.n_recoveries_deleted[k] += 1
        w[s:e] = 1.0

    def _recover_mixture(self, g: np.random.Generator, k: int, s: int, e: int) -> None:
        """Mixture state of a re-seeded block (flat slice ``[s, e)`` of row ``k``'s chunk):
        stratified prior modes, fresh velocities from ``standard_normal((2, n))``."""
        if not self._mix:
            return
        n = e - s
        nv = g.standard_normal((2, n))
        vx, vy = K.fresh_velocity(
            nv[0], nv[1], self._vmax, self._h.reshape(-1)[s:e], self.params.cv_forward_bias
        )
        self._vx.reshape(-1)[s:e] = vx
        self._vy.reshape(-1)[s:e] = vy
        self._mode.reshape(-1)[s:e] = K.stratified_modes(np.arange(n), np.full(n, n), self._cdf)

    def _disc_outside_fov(
        self, g: np.random.Generator, n: int, cx: float, cy: float, radius: float, pose
    ) -> tuple[np.ndarray, np.ndarray]:
        """``n`` points uniform in the disc of ``radius`` around ``(cx, cy)`` (Σ_i) that lie
        inside the arena ``[r, L − r]^2`` and outside F_i (``recovery_reseed="local"``).

        Rejection sampling in rounds of ``random((2, max(2 need, 16)))`` (radius by the
        square root of the first row, angle from the second); after 50 rounds (only when
        the disc lies almost wholly in F_i or beyond the walls) the rest come from
        :meth:`_uniform_outside_fov`.
        """
        out_x = np.empty(n)
        out_y = np.empty(n)
        got = 0
        c, s = math.cos(pose[2]), math.sin(pose[2])
        for _ in range(50):
            need = n - got
            uu = g.random((2, max(2 * need, 16)))
            rr = radius * np.sqrt(uu[0])
            th = 2.0 * math.pi * uu[1]
            bx = cx + rr * np.cos(th)
            by = cy + rr * np.sin(th)
            wx = pose[0] + c * bx - s * by
            wy = pose[1] + s * bx + c * by
            ok = ~K.in_fov_xy(bx, by, self._fov, self._range)
            ok &= (wx >= self._lo) & (wx <= self._hi) & (wy >= self._lo) & (wy <= self._hi)
            bx, by = bx[ok][:need], by[ok][:need]
            out_x[got : got + bx.size] = bx
            out_y[got : got + by.size] = by
            got += bx.size
            if got == n:
                return out_x, out_y
        out_x[got:], out_y[got:] = self._uniform_outside_fov(g, n - got, pose)
        return out_x, out_y

    def _uniform_outside_fov(self, g: np.random.Generator, n: int, pose: np.ndarray):
        """``n`` points uniform over the arena ``[r, L − r]^2`` outside F_i, in Σ_i.

        Rejection sampling; after 50 rounds (only when F_i covers nearly the whole arena)
        the remaining points are taken from the last round regardless of F_i.
        """
        span = self._hi - self._lo
        out_x = np.empty(n)
        out_y = np.empty(n)
        got = 0
        for _ in range(50):
            need = n - got
            kk = max(2 * need, 16)
            uu = g.random((2, kk))
            b = world_to_body(
                np.stack([self._lo + span * uu[0], self._lo + span * uu[1]], -1), pose
            )
            ok = ~K.in_fov_xy(b[:, 0], b[:, 1], self._fov, self._range)
            bx, by = b[ok, 0][:need], b[ok, 1][:need]
            out_x[got : got + bx.size] = bx
            out_y[got : got + by.size] = by
            got += bx.size
            if got == n:
                return out_x, out_y
        out_x[got:] = b[: n - got, 0]
        out_y[got:] = b[: n - got, 1]
        return out_x, out_y

    def _velocity_est(self) -> np.ndarray:
        """``(R, M, 2)`` u_j^est (Eq. 20 / 22) at the means, in the current Σ_i."""
        mean = self._est["mean_body"]
        if self._M == 0 or self._model == "static":
            return np.zeros(mean.shape)
        if self._mix:
            q = self._goal_prev
            ax, ay = K.coverage_input(
                mean[..., 0],
                mean[..., 1],
                q[:, 0:1],
                q[:, 1:2],
                self.params.k_p,
                self._vmax,
                self._standoff,
            )
            bx, by = K.crossing_input(mean[..., 0], mean[..., 1], self._vmax)
            pr = self._est["mode_probs"]
            v = self._v_cv.copy()
            v[..., 0] += pr[..., K.MODE_COVERAGE] * ax + pr[..., K.MODE_CROSSING] * bx
            v[..., 1] += pr[..., K.MODE_COVERAGE] * ay + pr[..., K.MODE_CROSSING] * by
            return v
        if self._model == "coverage":
            q = self._goal_prev
            vx, vy = K.coverage_input(
                mean[..., 0],
                mean[..., 1],
                q[:, 0:1],
                q[:, 1:2],
                self.params.k_p,
                self.config.v_max_mps,
                self._standoff,
            )
        else:
            vx, vy = K.crossing_input(mean[..., 0], mean[..., 1], self.config.v_max_mps)
        return np.stack([vx, vy], -1)

    def estimate_arrays(self) -> dict:
        """Per-row estimate arrays (not copied)."""
        return dict(
            velocity_est_body=self._velocity_est(),
            ids=self._ids,
            counts=self._counts,
            detected=self._det,
            time_since_seen_s=self._tss,
            time_s=self._time,
            **self._est,
        )

    def particles_all(self) -> tuple[np.ndarray, np.ndarray]:
        """``(p_body (R, P, 2), owner (R, P) neighbour ID)`` of every row (new arrays)."""
        p = np.stack([self._x, self._y], -1)
        if not self._M:
            return p, np.zeros((self._R, self._P), dtype=np.int64)
        # blocks are contiguous and in neighbour order: each ID repeated by its count
        owner = np.repeat(self._ids.reshape(-1), self._counts.reshape(-1))
        return p, owner.reshape(self._R, self._P)

    #: per-row state (leading row axis) replaced by :meth:`splice`
    _ROW_STATE = (
        "_x", "_y", "_h", "_counts", "_tss", "_time", "_pose_prev", "_goal_prev", "_det",
        "n_recoveries_detection", "n_recoveries_deleted", "n_fusions", "_mode", "_vx", "_vy",
        "_mode_probs", "_v_cv", "_bias", "_bias_alarm",
    )  # fmt: skip

    def splice(self, rows: np.ndarray, other: _BankCore) -> None:
        """Replace rows ``rows`` by the rows of ``other`` (a core of those robots, reset on
        its own): state, estimate and Generators; the other rows keep every number."""
        for name in self._ROW_STATE:
            if hasattr(other, name):
                getattr(self, name)[rows] = getattr(other, name)
        for key, val in other._est.items():
            self._est[key][rows] = val
        for j, r in enumerate(np.asarray(rows).tolist()):
            self._rngs[r] = other._rngs[j]
        self._set_blocks()

    def particles_body(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        p = np.stack([self._x[k], self._y[k]], -1)
        local = self._gid.reshape(self._R, self._P)[k] - k * self._M
        return p, self._ids[k][local]

    def particle_headings(self, k: int) -> np.ndarray:
        return self._h[k].copy()

    def particle_modes(self, k: int) -> np.ndarray:
        if self._mix:
            return self._mode[k].copy()
        return np.full(self._P, K.MODE_NAMES.index(self._model), dtype=np.int8)

    def particle_velocities(self, k: int) -> np.ndarray:
        if self._mix:
            return np.stack([self._vx[k], self._vy[k]], -1)
        return np.zeros((self._P, 2))


#: Robots per computation chunk are chosen so a chunk holds about this many particles:
#: the per-particle temporaries then stay in cache (2x faster than one chunk at
#: P_T = 2000, N = 48), while each chunk pays the fixed cost of its small per-block arrays.
#: 131072 (was 32768) measured in one run, ``bench_batched_filter`` batched filter ms per
#: robot-step at B N = 384, 3 repeats: P_T = 500 0.120-0.142 -> 0.103-0.107 (one chunk:
#: 0.103-0.109), P_T = 2000 0.332-0.360 -> 0.290-0.317 (one chunk: 0.317-0.360); N = 48,
#: B = 8: P_T = 2000 tracker 0.307 -> 0.266-0.272; no case slower. Chunking changes no number.
CHUNK_PARTICLES = 131072

#: Thread pools shared by the banks, one per (process, thread count), created on first
#: use. A bank holds only its count, so it stays picklable and copyable; the process id
#: in the key gives a forked child (``multiprocessing``'s default start on Linux) pools of
#: its own instead of the parent's, whose threads do not exist in the child.
_POOLS: dict[tuple[int, int], ThreadPoolExecutor] = {}
_POOLS_LOCK = threading.Lock()


def check_particle_budget(params: TrackerParams, n_agents: int) -> None:
    """``ValueError`` unless ``params.n_particles_total`` gives every one of the
    ``n_agents − 1`` neighbours a particle (what a bank of that team needs)."""
    m = int(n_agents) - 1
    if params.n_particles_total < m:
        raise ValueError(
            f"n_particles_total must be >= the number of neighbours N - 1 = {m}, "
            f"got {params.n_particles_total}"
        )


def _pool(n_threads: int) -> ThreadPoolExecutor:
    key = (os.getpid(), n_threads)
    with _POOLS_LOCK:
        pool = _POOLS.get(key)
        if pool is None:
            pool = _POOLS[key] = ThreadPoolExecutor(n_threads, thread_name_prefix="fov_marl-pf")
        return pool


def _check_threads(n_threads: Any) -> int:
    """``n_threads``: an int in ``[1, 1024]`` (a ``ValueError`` naming it otherwise)."""
    return check_int("n_threads", n_threads, 1, 1024)


def _chunk_bounds(n_rows: int, n_particles: int, n_threads: int) -> list[tuple[int, int]]:
    """Row ranges ``[(start, end), ...]`` of the computation chunks: about
    :data:`CHUNK_PARTICLES` particles each; with threads, a multiple of ``n_threads``
    chunks of equal size (where there are that many rows), so that every thread has the
    same work (measured, tracker alone, B N = 384, P_T = 500, 2 threads: 2 chunks 0.057
    ms per robot-step, 3 chunks 0.071, serial 0.093)."""
    per = max(1, CHUNK_PARTICLES // max(1, n_particles))
    if n_threads > 1:
        n_chunks = -(-n_rows // per)
        n_chunks = min(n_rows, -(-n_chunks // n_threads) * n_threads)
        per = -(-n_rows // n_chunks)
    return [(s, min(s + per, n_rows)) for s in range(0, n_rows, per)]


def _step_cores(cores, bounds, act: np.ndarray, obs_arr: np.ndarray, n_threads: int) -> None:
    """Step every chunk, on ``n_threads`` threads when there are several chunks.

    The chunks share no array and no Generator (each row draws from its own), so the
    order in which the threads run them changes no number: threaded and serial steps are
    bit-identical (tested). NumPy releases the GIL inside its array loops and its
    Generators' fills, which is where a step spends its time.
    """
    if len(cores) == 1:
        cores[0].step(act, obs_arr)
        return
    if n_threads == 1:
        _step_cores_serial(cores, bounds, act, obs_arr)
        return
    pool = _pool(n_threads)
    futures = [
        pool.submit(core.step, act[s:e], obs_arr[s:e])
        for core, (s, e) in zip(cores, bounds, strict=True)
    ]
    for f in futures:
        f.result()  # a chunk's exception is raised here


#: Serial chunks draw the next chunk's prediction noise on a helper thread while the
#: current chunk computes (:func:`_step_cores_serial`); False draws inline (the same
#: numbers; the benchmark's comparison,
#: ``fov_marl.bench.bench_batched_filter(draw_ahead=False)``).
DRAW_AHEAD = True


def _step_cores_serial(cores, bounds, act: np.ndarray, obs_arr: np.ndarray) -> None:
    """Step the chunks one after the other on this thread; with :data:`DRAW_AHEAD`, chunk
    k + 1's prediction draws (:meth:`_BankCore.draw_step_noise`, a quarter of a step's
    time at P_T = 2000, in NumPy's Generator fills, which release the GIL) are made on a
    helper thread while chunk k computes. Each chunk draws from its own rows' Generators
    only, and those draws are the first of its step, so the numbers are those of inline
    draws (tested). The helper has finished before this returns, also when a chunk
    raises."""
    if not DRAW_AHEAD:
        for core, (s, e) in zip(cores, bounds, strict=True):
            core.step(act[s:e], obs_arr[s:e])
        return
    helper = _pool(1)
    ahead = None
    try:
        for i, (core, (s, e)) in enumerate(zip(cores, bounds, strict=True)):
            if ahead is not None:
                ahead.result()
            ahead = helper.submit(cores[i + 1].draw_step_noise) if i + 1 < len(cores) else None
            core.step(act[s:e], obs_arr[s:e], drawn=i > 0)
    finally:
        if ahead is not None:
            wait([ahead])  # no draw outlives the step; a chunk's exception propagates


class TrackerBank:
    """The particle-filter banks of several robots, stepped together (see module docstring).

    Robot ``k`` of the bank (row k) is robot ``agent_indices[k]`` of the team and draws
    only from ``rngs[k]``; its numbers are bit-identical to a :class:`NeighborTracker` of
    that robot with the same Generator. Internally the robots are processed in chunks of
    about :data:`CHUNK_PARTICLES` particles (one flat array per chunk, owner = (robot,
    neighbour)); chunking changes no number.

    Args:
        config: the scenario.
        params: tracker parameters (default :class:`TrackerParams()`).
        agent_indices: team indices of the robots in the bank (default: all N, in order),
            distinct integers in ``[0, N − 1]``.
        rngs: one ``np.random.Generator`` per robot of the bank. Default: spawned from
            ``np.random.SeedSequence(seed)``, child ``k`` for row ``k``.
        seed: ``None`` or an integer ≥ 0; used only when ``rngs`` is None (checked always).
        n_threads: threads that step the chunks (an int in ``[1, 1024]``, default 1); the
            rows are then split into equal chunks, a multiple of that many. The numbers
            are the same for every count (tested). Threads pay off from about 10^5
            particles in the bank (:func:`fov_marl.bench.bench_batched_filter`'s
            ``tracker_threads``); leave 1 where the process already runs one bank per
            core (``SubprocVectorEnv`` workers). With 1 and several chunks, a helper
            thread draws the next chunk's noise ahead (:data:`DRAW_AHEAD`, same numbers).

    Raises:
        ValueError: bad ``config``, ``params``, ``agent_indices``, ``rngs``, ``seed``,
            ``n_threads``, or ``n_particles_total < N − 1``.
    """

    def __init__(
        self,
        config: ScenarioConfig,
        params: TrackerParams | None = None,
        *,
        agent_indices: Sequence[int] | None = None,
        rngs: Sequence[np.random.Generator] | None = None,
        seed: int | None = None,
        n_threads: int = 1,
    ) -> None:
        if not isinstance(config, ScenarioConfig):
            raise ValueError(f"config must be a ScenarioConfig, got {type(config).__name__}")
        params = TrackerParams() if params is None else params
        if not isinstance(params, TrackerParams):
            raise ValueError(f"params must be a TrackerParams, got {type(params).__name__}")
        n = config.n_agents
        seed = check_seed("seed", seed)
        if agent_indices is None:
            agent_indices = range(n)
        what = f"distinct robot indices (integers in [0, {n - 1}])"
        items = _items("agent_indices", agent_indices, what)
        if not items:
            raise ConfigError(f"agent_indices must be a non-empty sequence of {what}, got []")
        idx = np.array(
            [check_int(f"agent_indices[{k}]", a, 0, n - 1) for k, a in enumerate(items)],
            dtype=np.int64,
        )
        if np.unique(idx).size != idx.size:
            raise ConfigError(f"agent_indices must be {what}, got {idx.tolist()}")
        if rngs is None:
            rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(idx.size)]
        rngs = _items("rngs", rngs, f"{idx.size} np.random.Generator objects (one per robot)")
        if len(rngs) != idx.size or not all(isinstance(g, np.random.Generator) for g in rngs):
            raise ValueError(
                f"rngs must be {idx.size} np.random.Generator objects (one per robot), "
                f"got {len(rngs)} objects"
            )
        m = n - 1
        check_particle_budget(params, n)
        self.config = config
        self.params = params
        self.agent_indices = idx.astype(np.int64)
        self._R = idx.size
        self._M = m
        self._P = int(params.n_particles_total)
        self._obs_size = SLOT_SIZE * m + CUE_SIZE
        self.n_threads = _check_threads(n_threads)
        self._bounds = _chunk_bounds(self._R, self._P, self.n_threads)
        self._cores = [
            _BankCore(config, params, self.agent_indices[s:e], rngs[s:e]) for s, e in self._bounds
        ]
        self._initialised = False

    # ------------------------------------------------------------------ construction
    @classmethod
    def for_env(
        cls,
        env: Any,
        seed: int | None = 0,
        agents: Sequence[str | int] | None = None,
        **param_overrides: Any,
    ) -> TrackerBank:
        """Bank for the robots ``agents`` (default all) of a PettingZoo env with ``.config``.

        Robot k's Generator is ``default_rng(SeedSequence(seed).spawn(R)[k])`` (``seed``:
        None or an integer ≥ 0).
        ``param_overrides`` are fields of :class:`TrackerParams`.
        """
        cfg = _env_config(env)
        if agents is None:
            idx = list(range(cfg.n_agents))
        else:
            idx = [_resolve_agent(env, a) for a in agents]
        return cls(cfg, _params(param_overrides), agent_indices=idx, seed=seed)

    # ------------------------------------------------------------------ properties
    @property
    def n_robots(self) -> int:
        """Robots in the bank, R."""
        return self._R

    @property
    def n_neighbours(self) -> int:
        """Neighbours per robot, M = N − 1."""
        return self._M

    @property
    def neighbour_ids(self) -> np.ndarray:
        """``(R, M)`` neighbour IDs per robot (ascending)."""
        return np.concatenate([c._ids for c in self._cores])

    @property
    def n_recoveries_detection(self) -> np.ndarray:
        """``(R,)`` re-seeds around a detection the particles missed, per robot."""
        return np.concatenate([c.n_recoveries_detection for c in self._cores])

    @property
    def n_recoveries_deleted(self) -> np.ndarray:
        """``(R,)`` re-seeds after every particle was deleted inside F_i, per robot."""
        return np.concatenate([c.n_recoveries_deleted for c in self._cores])

    @property
    def n_recoveries(self) -> np.ndarray:
        """``(R,)`` re-seeds so far per robot (both kinds)."""
        return self.n_recoveries_detection + self.n_recoveries_deleted

    @property
    def n_fusions(self) -> np.ndarray:
        """``(R,)`` collapsed clouds fused onto a detection (``ess_recovery="fuse"``)."""
        return np.concatenate([c.n_fusions for c in self._cores])

    @property
    def initialised(self) -> bool:
        """Whether :meth:`reset` (explicit or implicit) has run."""
        return self._initialised

    # ------------------------------------------------------------------ input checks
    def _obs_array(self, obs: Any, name: str = "obs") -> np.ndarray:
        if isinstance(obs, Mapping):
            rows = []
            for a in self.agent_indices:
                key = f"robot_{a}"
                if key not in obs:
                    raise ValueError(f"{name} must hold an observation for {key!r}")
                rows.append(_real_data(f"{name}[{key!r}]", obs[key], f"({self._obs_size},)"))
            try:
                arr = np.stack(rows).astype(np.float64)
            except ValueError:
                raise ValueError(
                    f"{name}: every observation must have shape ({self._obs_size},)"
                ) from None
        else:
            _real_data(name, obs, f"(n_robots, obs_size) = ({self._R}, {self._obs_size})")
            arr = np.asarray(obs, dtype=np.float64)
        if arr.shape != (self._R, self._obs_size):
            raise ValueError(
                f"{name} must have shape (n_robots, obs_size) = ({self._R}, {self._obs_size}), "
                f"got {arr.shape}"
            )
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be finite, got NaN or inf")
        return arr

    def _action_array(self, actions: Any, name: str = "actions") -> np.ndarray:
        if isinstance(actions, Mapping):
            rows = []
            for a in self.agent_indices:
                key = f"robot_{a}"
                if key not in actions:
                    raise ValueError(f"{name} must hold an action for {key!r}")
                _real_data(f"{name}[{key!r}]", actions[key], "(3,)")
                rows.append(np.asarray(actions[key], dtype=np.float64).reshape(-1))
            try:
                arr = np.stack(rows)
            except ValueError:
                raise ValueError(f"{name}: every action must have shape (3,)") from None
        else:
            _real_data(name, actions, f"(n_robots, 3) = ({self._R}, 3)")
            arr = np.asarray(actions, dtype=np.float64)
        if arr.shape != (self._R, 3):
            raise ValueError(
                f"{name} must have shape (n_robots, 3) = ({self._R}, 3), got {arr.shape}"
            )
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be finite, got NaN or inf")
        return arr

    # ------------------------------------------------------------------ reset / step
    def reset(self, obs: Any, initial_poses_world: np.ndarray | None = None) -> None:
        """Initialise every filter (Eq. 1) and absorb the first observation.

        Args:
            obs: ``(R, obs_size)`` array, or a mapping ``"robot_<i>" -> (obs_size,)``.
            initial_poses_world: ``(N, 3)`` known world start poses of the whole team
                (the paper's assumption): each neighbour's particles start at its
                relative pose plus N(0, init_spread²). ``None``: uniform over the arena
                (and the first update deletes those inside F_i). ``init_mode`` can force
                either.

        Raises:
            ValueError: bad shapes or non-finite values (naming the argument);
                ``init_mode="known"`` without ``initial_poses_world``.
        """
        obs_arr = self._obs_array(obs)
        mode = self.params.init_mode
        known = initial_poses_world is not None if mode == "auto" else mode == "known"
        init = None
        if known:
            if initial_poses_world is None:
                raise ValueError("initial_poses_world is required when init_mode='known'")
            n = self.config.n_agents
            _real_data("initial_poses_world", initial_poses_world, f"(n_agents, 3) = ({n}, 3)")
            init = np.asarray(initial_poses_world, dtype=np.float64)
            if init.shape != (n, 3):
                raise ValueError(
                    f"initial_poses_world must have shape (n_agents, 3) = ({n}, 3), "
                    f"got {init.shape}"
                )
            if not np.all(np.isfinite(init)):
                raise ValueError("initial_poses_world must be finite, got NaN or inf")
        for core, (s, e) in zip(self._cores, self._bounds, strict=True):
            core.reset(obs_arr[s:e], init)
        self._initialised = True

    def step(self, actions: Any, obs: Any) -> None:
        """One filter step of every robot: predict, weight, delete, resample, re-allocate.

        Args:
            actions: ``(R, 3)`` normalised actions each robot applied on the step that
                produced ``obs`` (mapped with :func:`fov_marl.spaces.action_to_velocity`,
                which clips like the env), or a mapping ``"robot_<i>" -> (3,)``.
            obs: the observations that step produced, as in :meth:`reset`.

        Before the first :meth:`reset`, this resets with ``obs`` (uniform or per
        ``init_mode``) and ignores ``actions``.

        Raises:
            ValueError: bad shapes or non-finite values, naming the argument.
        """
        act = self._action_array(actions)
        obs_arr = self._obs_array(obs)
        if not self._initialised:
            self.reset(obs_arr)
            return
        _step_cores(self._cores, self._bounds, act, obs_arr, self.n_threads)

    # ------------------------------------------------------------------ outputs
    def _check_init(self) -> None:
        if not self._initialised:
            raise ValueError("the tracker has no estimate yet: call reset(obs) or step() first")

    def estimate(self) -> BankEstimate:
        """All robots' estimates (copies); ``.robot(k)`` gives one :class:`TrackerEstimate`."""
        self._check_init()
        parts = [c.estimate_arrays() for c in self._cores]
        arrays = {k: _ro(np.concatenate([p[k] for p in parts])) for k in parts[0] if k != "time_s"}
        return BankEstimate(
            agent_indices=_ro(self.agent_indices),
            confidence=float(self.params.confidence),
            time_s=float(parts[0]["time_s"][0]),
            **arrays,
        )

    def _locate(self, k: int) -> tuple[_BankCore, int]:
        self._check_init()
        if isinstance(k, bool) or not isinstance(k, int | np.integer) or not 0 <= k < self._R:
            raise ValueError(f"k must be an int in [0, {self._R - 1}], got {k!r}")
        for core, (s, e) in zip(self._cores, self._bounds, strict=True):
            if s <= k < e:
                return core, int(k) - s
        raise AssertionError("unreachable")  # pragma: no cover

    def particles_body(self, k: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Particles of the bank's ``k``-th robot, for drawing.

        Returns:
            ``(p_body (P_T, 2) m in Σ_i, owner (P_T,) int neighbour ID)``, flat, sorted by
            owner; copies. With no neighbour (N = 1) there are no particles: ``(0, 2)``
            and ``(0,)`` (likewise for the other ``particle_*`` accessors).
        """
        core, j = self._locate(k)
        return core.particles_body(j)

    def particle_headings(self, k: int = 0) -> np.ndarray:
        """``(P_T,)`` relative headings θ_j − θ_i (rad) of the ``k``-th robot's particles."""
        core, j = self._locate(k)
        return core.particle_headings(j)

    def particle_modes(self, k: int = 0) -> np.ndarray:
        """``(P_T,)`` int8 motion modes (:data:`~fov_marl.estimation.kernels.MODE_NAMES`
        indices) of the ``k``-th robot's particles; constant for the single models."""
        core, j = self._locate(k)
        return core.particle_modes(j)

    def particle_velocities_body(self, k: int = 0) -> np.ndarray:
        """``(P_T, 2)`` velocity states in Σ_i (m/s) of the ``k``-th robot's particles: the
        velocity each moved with on the last prediction (mixture); zeros for the single
        models, which keep no velocity state."""
        core, j = self._locate(k)
        return core.particle_velocities(j)


def _params(overrides: Mapping[str, Any], base: TrackerParams | None = None) -> TrackerParams:
    valid = {f.name for f in fields(TrackerParams)}
    unknown = sorted(set(overrides) - valid)
    if unknown:
        raise ValueError(f"unknown TrackerParams field(s) {unknown}; valid: {sorted(valid)}")
    return replace(base or TrackerParams(), **overrides)


class NeighborTracker:
    """One robot's particle-filter bank: a :class:`TrackerBank` of that robot alone.

    Args:
        config: the scenario.
        agent_index: robot i's index in the team.
        params: tracker parameters (default :class:`TrackerParams()`).
        rng: this robot's Generator (default ``np.random.default_rng()``, unseeded).

    Example::

        tracker = NeighborTracker.for_env(env, agent="robot_0", seed=0)
        tracker.reset(obs["robot_0"], initial_poses_world=env.poses)
        tracker.step(actions["robot_0"], obs["robot_0"])
        est = tracker.estimate()
    """

    def __init__(
        self,
        config: ScenarioConfig,
        agent_index: int = 0,
        params: TrackerParams | None = None,
        rng: np.random.Generator | None = None,
    ) -> None:
        if isinstance(agent_index, bool) or not isinstance(agent_index, int | np.integer):
            raise ValueError(f"agent_index must be an int, got {agent_index!r}")
        if rng is None:
            rng = np.random.default_rng()
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a np.random.Generator, got {type(rng).__name__}")
        self._bank = TrackerBank(config, params, agent_indices=[int(agent_index)], rngs=[rng])
        self.agent_index = int(agent_index)
        self._obs_size = self._bank._obs_size

    @classmethod
    def for_env(
        cls, env: Any, agent: str | int = "robot_0", seed: int | None = 0, **param_overrides: Any
    ) -> NeighborTracker:
        """Tracker of ``agent`` for a PettingZoo env exposing ``.config`` and
        ``.possible_agents``; ``rng = default_rng(seed)`` (``seed``: None or an integer
        ≥ 0); ``param_overrides`` are :class:`TrackerParams` fields."""
        seed = check_seed("seed", seed)
        cfg = _env_config(env)
        idx = _resolve_agent(env, agent)
        return cls(cfg, idx, _params(param_overrides), np.random.default_rng(seed))

    @property
    def config(self) -> ScenarioConfig:
        return self._bank.config

    @property
    def params(self) -> TrackerParams:
        return self._bank.params

    @property
    def neighbour_ids(self) -> np.ndarray:
        """``(M,)`` neighbour IDs, ascending."""
        return self._bank.neighbour_ids[0]

    @property
    def n_recoveries(self) -> int:
        """Re-seeds so far (both kinds)."""
        return int(self._bank.n_recoveries[0])

    @property
    def n_recoveries_detection(self) -> int:
        """Re-seeds around a detection the particles missed."""
        return int(self._bank.n_recoveries_detection[0])

    @property
    def n_recoveries_deleted(self) -> int:
        """Re-seeds after every particle was deleted inside F_i."""
        return int(self._bank.n_recoveries_deleted[0])

    @property
    def n_fusions(self) -> int:
        """Collapsed clouds fused onto a detection (``ess_recovery="fuse"``)."""
        return int(self._bank.n_fusions[0])

    @property
    def initialised(self) -> bool:
        return self._bank.initialised

    def _obs(self, obs: Any) -> np.ndarray:
        _real_data("obs", obs, f"({self._obs_size},)")
        arr = np.asarray(obs, dtype=np.float64)
        if arr.shape != (self._obs_size,):
            raise ValueError(
                f"obs of robot_{self.agent_index} must have shape ({self._obs_size},), "
                f"got {arr.shape}"
            )
        return arr[None]

    def reset(self, obs: np.ndarray, initial_poses_world: np.ndarray | None = None) -> None:
        """Initialise (Eq. 1) from this robot's first observation; see
        :meth:`TrackerBank.reset`."""
        self._bank.reset(self._obs(obs), initial_poses_world)

    def step(self, own_action: np.ndarray, obs: np.ndarray) -> None:
        """One filter step; ``own_action`` ``(3,)`` normalised, ``obs`` ``(obs_size,)``.
        See :meth:`TrackerBank.step`."""
        _real_data("own_action", own_action, "(3,)")
        act = np.asarray(own_action, dtype=np.float64)
        if act.shape != (3,):
            raise ValueError(f"own_action must have shape (3,), got {act.shape}")
        if not np.all(np.isfinite(act)):
            raise ValueError("own_action must be finite, got NaN or inf")
        self._bank.step(act[None], self._obs(obs))

    def estimate(self) -> TrackerEstimate:
        """The current :class:`TrackerEstimate`."""
        return self._bank.estimate().robot(0)

    def particles_body(self) -> tuple[np.ndarray, np.ndarray]:
        """``(p_body (P_T, 2), owner (P_T,) neighbour ID)``; see :meth:`TrackerBank.particles_body`."""
        return self._bank.particles_body(0)

    def particle_headings(self) -> np.ndarray:
        """``(P_T,)`` relative headings of the particles (rad); ``(0,)`` for N = 1."""
        return self._bank.particle_headings(0)

    def particle_modes(self) -> np.ndarray:
        """``(P_T,)`` int8 motion modes; see :meth:`TrackerBank.particle_modes`."""
        return self._bank.particle_modes(0)

    def particle_velocities_body(self) -> np.ndarray:
        """``(P_T, 2)`` velocity states (m/s); see
        :meth:`TrackerBank.particle_velocities_body`."""
        return self._bank.particle_velocities_body(0)


class VectorTrackerBank:
    """The tracker banks of ``B`` env copies of an ``N``-robot team in one set of arrays.

    Row ``k N + i`` is robot i of copy k; its neighbour IDs are those of copy k, and it
    draws only from its own Generator: child i of ``SeedSequence(seeds[k])``, exactly as
    ``TrackerBank(config, params, seed=seeds[k])`` for copy k alone. Every number of
    copy k is therefore bit-identical to that separate bank under the same inputs
    (tested), and :meth:`reset_copies` restarts some copies without touching the others
    (an env copy that finished its episode).

    Args:
        config: the scenario (N robots per copy).
        params: tracker parameters (default :class:`TrackerParams()`).
        n_copies: B ≥ 1.
        n_threads: threads that step the chunks (see :class:`TrackerBank`; default 1).

    Raises:
        ValueError: bad ``config``, ``params``, ``n_copies``, ``n_threads``, or
            ``n_particles_total < N − 1``.
    """

    def __init__(
        self,
        config: ScenarioConfig,
        params: TrackerParams | None = None,
        *,
        n_copies: int,
        n_threads: int = 1,
    ) -> None:
        if isinstance(n_copies, bool) or not isinstance(n_copies, int | np.integer):
            raise ValueError(f"n_copies must be an int >= 1, got {n_copies!r}")
        if n_copies < 1:
            raise ValueError(f"n_copies must be an int >= 1, got {n_copies}")
        # validates config / params and gives the layout of one copy
        one = TrackerBank(config, params, rngs=None, seed=0)
        self.config = config
        self.params = one.params
        self.n_copies = int(n_copies)
        self.n_agents = config.n_agents
        N, B = self.n_agents, self.n_copies
        self._R = B * N
        self._M = one._M
        self._P = one._P
        self._obs_size = one._obs_size
        self.agent_indices = np.tile(np.arange(N, dtype=np.int64), B)
        self.copy_index = np.repeat(np.arange(B, dtype=np.int64), N)
        self.n_threads = _check_threads(n_threads)
        self._bounds = _chunk_bounds(self._R, self._P, self.n_threads)
        self._cores: list[_BankCore] = []
        self._initialised = False

    # ------------------------------------------------------------------ helpers
    def _copy_rngs(self, seed: int | None) -> list[np.random.Generator]:
        return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(self.n_agents)]

    def _seeds(self, seeds: Any, n: int) -> list[int | None]:
        """``seeds``: None or ``n`` seeds (each None or an integer ≥ 0), one per copy."""
        if seeds is None:
            return [None] * n
        out = _items("seeds", seeds, f"{n} seeds (one per copy: integers >= 0 or None) or None")
        if len(out) != n:
            raise ValueError(f"seeds must hold {n} seeds (one per copy), got {len(out)}")
        return [check_seed(f"seeds[{k}]", s) for k, s in enumerate(out)]

    def _array(self, x: Any, name: str, tail: tuple[int, ...]) -> np.ndarray:
        B, N = self.n_copies, self.n_agents
        _real_data(name, x, str((B, N) + tail))
        arr = np.asarray(x, dtype=np.float64)
        if arr.shape == (B * N,) + tail:
            arr = arr.reshape((B, N) + tail)
        if arr.shape != (B, N) + tail:
            raise ValueError(f"{name} must have shape {(B, N) + tail}, got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be finite, got NaN or inf")
        return arr.reshape((B * N,) + tail)

    def _init(self, initial_poses_world: Any) -> np.ndarray | None:
        mode = self.params.init_mode
        known = initial_poses_world is not None if mode == "auto" else mode == "known"
        if not known:
            return None
        if initial_poses_world is None:
            raise ValueError("initial_poses_world is required when init_mode='known'")
        B, N = self.n_copies, self.n_agents
        shape_text = f"(n_copies, n_agents, 3) = ({B}, {N}, 3)"
        _real_data("initial_poses_world", initial_poses_world, shape_text)
        init = np.asarray(initial_poses_world, dtype=np.float64)
        if init.shape != (B, N, 3):
            raise ValueError(
                f"initial_poses_world must have shape (n_copies, n_agents, 3) = ({B}, {N}, 3), "
                f"got {init.shape}"
            )
        if not np.all(np.isfinite(init)):
            raise ValueError("initial_poses_world must be finite, got NaN or inf")
        return init

    # ------------------------------------------------------------------ reset / step
    def reset(self, obs: Any, initial_poses_world: Any = None, seeds: Any = None) -> None:
        """Start every copy: obs ``(B, N, obs_size)``, ``initial_poses_world (B, N, 3)`` or
        None, ``seeds`` one per copy (None: fresh entropy for every copy)."""
        obs_arr = self._array(obs, "obs", (self._obs_size,))
        init = self._init(initial_poses_world)
        rngs: list[np.random.Generator] = []
        for s in self._seeds(seeds, self.n_copies):
            rngs += self._copy_rngs(s)
        self._cores = [
            _BankCore(
                self.config, self.params, self.agent_indices[s:e], rngs[s:e], self.copy_index[s:e]
            )
            for s, e in self._bounds
        ]
        for core, (s, e) in zip(self._cores, self._bounds, strict=True):
            core.reset(obs_arr[s:e], init)
        self._initialised = True

    def reset_copies(
        self, copies: Any, obs: Any, initial_poses_world: Any = None, seeds: Any = None
    ) -> None:
        """Restart the copies ``copies`` (one index or a sequence of distinct indices, integers
        in ``[0, B − 1]``, or a ``(B,)`` bool mask) from their rows of ``obs (B, N,
        obs_size)`` (and of ``initial_poses_world (B, N, 3)``), with one seed per restarted
        copy; every other copy keeps all its numbers.

        Raises:
            ValueError: before :meth:`reset`; ``copies`` neither integer indices in range
                (a float, even ``1.0``, is not an index) nor a ``(B,)`` bool mask; repeated
                indices; bad ``obs``, ``initial_poses_world`` or ``seeds``.
        """
        if not self._initialised:
            raise ValueError("reset_copies() called before reset()")
        c = self._copy_indices(copies)
        if c.size == 0:
            return
        seeds_l = self._seeds(seeds, c.size)
        obs_arr = self._array(obs, "obs", (self._obs_size,))
        init = self._init(initial_poses_world)
        new_rng: dict[int, np.random.Generator] = {}
        for k, s in zip(c.tolist(), seeds_l, strict=True):
            for i, g in enumerate(self._copy_rngs(s)):
                new_rng[k * self.n_agents + i] = g
        for core, (s, e) in zip(self._cores, self._bounds, strict=True):
            rows = np.flatnonzero(np.isin(self.copy_index[s:e], c))
            if rows.size == 0:
                continue
            g_rows = s + rows
            tmp = _BankCore(
                self.config,
                self.params,
                self.agent_indices[g_rows],
                [new_rng[int(r)] for r in g_rows],
                self.copy_index[g_rows],
            )
            tmp.reset(obs_arr[g_rows], init)
            core.splice(rows, tmp)

    def _copy_indices(self, copies: Any) -> np.ndarray:
        """``copies`` of :meth:`reset_copies` as an int64 vector of distinct indices."""
        B = self.n_copies
        what = (
            f"copies must be distinct copy indices (integers in [0, {B - 1}]) or a ({B},) bool mask"
        )
        try:
            c = np.asarray(copies)
        except Exception:  # ragged lists, objects whose __array__ fails
            raise ConfigError(f"{what}, got {describe(copies)}") from None
        if c.ndim > 1:
            raise ConfigError(f"{what}, got an array of shape {c.shape}")
        if c.dtype == bool:
            if c.shape != (B,):
                raise ConfigError(f"{what}; the mask has shape {c.shape}")
            return np.flatnonzero(c)
        if c.size == 0:  # no copy (``[]`` is a float array)
            return np.zeros(0, dtype=np.int64)
        # str, None, floats (0.7 is no index), complex, objects, bools mixed with ints
        if c.dtype.kind not in "iu" or holds_bool(copies):
            raise ConfigError(f"{what}, got {describe(copies)}")
        out = c.astype(np.int64).reshape(-1)
        if np.any((out < 0) | (out >= B)) or np.unique(out).size != out.size:
            raise ConfigError(f"{what}, got {describe(copies)}")
        return out

    def step(self, actions: Any, obs: Any) -> None:
        """One filter step of every robot of every copy: ``actions (B, N, 3)`` applied
        (normalised), ``obs (B, N, obs_size)`` they produced (see :meth:`TrackerBank.step`)."""
        if not self._initialised:
            raise ValueError("step() called before reset()")
        act = self._array(actions, "actions", (3,))
        obs_arr = self._array(obs, "obs", (self._obs_size,))
        _step_cores(self._cores, self._bounds, act, obs_arr, self.n_threads)

    # ------------------------------------------------------------------ outputs
    @property
    def initialised(self) -> bool:
        return self._initialised

    @property
    def time_s(self) -> np.ndarray:
        """``(B,)`` simulated seconds since each copy's last reset."""
        self._check()
        t = np.concatenate([c._time for c in self._cores])
        return t.reshape(self.n_copies, self.n_agents)[:, 0].copy()

    def _check(self) -> None:
        if not self._initialised:
            raise ValueError("the tracker has no estimate yet: call reset(obs) first")

    def estimate(self) -> BankEstimate:
        """The estimates of all ``B N`` rows (row ``k N + i``: robot i of copy k), as a
        :class:`BankEstimate` (``time_s``: copy 0's; per copy: :attr:`time_s`)."""
        self._check()
        parts = [c.estimate_arrays() for c in self._cores]
        arrays = {k: _ro(np.concatenate([p[k] for p in parts])) for k in parts[0] if k != "time_s"}
        return BankEstimate(
            agent_indices=_ro(self.agent_indices),
            confidence=float(self.params.confidence),
            time_s=float(parts[0]["time_s"][0]),
            **arrays,
        )

    def positions_all(self) -> np.ndarray:
        """``p_body (B N, P_T, 2)`` m of every row, sorted by owner within a row (a new
        array; :meth:`particles_all` without the owners, which the safety rows do not need:
        a row's blocks follow its neighbour columns, ``estimate().counts`` long each).
        With no neighbour (N = 1) there are no particles: ``(B N, 0, 2)``."""
        self._check()
        R, P = self._R, (self._P if self._M else 0)
        pts = np.empty((R, P, 2))
        for core, (s, e) in zip(self._cores, self._bounds, strict=True):
            pts[s:e, :, 0] = core._x
            pts[s:e, :, 1] = core._y
        return pts

    def particles_all(self) -> tuple[np.ndarray, np.ndarray]:
        """``(p_body (B N, P_T, 2) m, owner (B N, P_T) neighbour ID)`` of every row, sorted
        by owner within a row (new arrays); ``(B N, 0, 2)`` and ``(B N, 0)`` for N = 1."""
        pts = self.positions_all()
        R, P = self._R, self._P
        if not self._M:
            return pts, np.zeros((R, 0), dtype=np.int64)
        # blocks are contiguous and in neighbour order: each ID repeated by its count
        ids = np.concatenate([c._ids for c in self._cores])
        counts = np.concatenate([c._counts for c in self._cores])
        return pts, np.repeat(ids.reshape(-1), counts.reshape(-1)).reshape(R, P)

    def particles_body(self, row: int) -> tuple[np.ndarray, np.ndarray]:
        """``(p_body (P_T, 2), owner (P_T,))`` of row ``row`` (see :meth:`TrackerBank.particles_body`)."""
        self._check()
        if isinstance(row, bool) or not isinstance(row, int | np.integer) or not 0 <= row < self._R:
            raise ValueError(f"row must be an int in [0, {self._R - 1}], got {row!r}")
        for core, (s, e) in zip(self._cores, self._bounds, strict=True):
            if s <= row < e:
                return core.particles_body(int(row) - s)
        raise AssertionError("unreachable")  # pragma: no cover
