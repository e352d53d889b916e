"""The paper's decentralised pipeline for a whole team: particle filters -> FoV CBFs -> QP.

One implementation serves both the scripted ``pfcbf`` baseline
(:mod:`fov_marl.baselines.pfcbf`) and :class:`fov_marl.wrappers.SafetyFilterWrapper`.
Per robot i and step, using only robot i's own data (row i of every array):

1. :meth:`PfCbfPipeline.observe`: robot i's tracker (a row of one
   :class:`~fov_marl.estimation.TrackerBank`) predicts with the action robot i applied
   and updates with robot i's observation (Eq. 1-5, Section IV-B).
2. :meth:`PfCbfPipeline.desired_inputs`: u* from limited-range Lloyd on robot i's
   estimates (coverage, Section VII-A) or the proportional law to its own target
   (crossing, VII-D); or the incoming policy action (safety filter).
3. :meth:`PfCbfPipeline.filter`: robot i's :class:`~fov_marl.control.FovCbfController`
   (Eq. 12, 16-19) turns u* into the safe input; the applied action is remembered for
   step 1 of the next step.

Estimates modes (``estimates=``):

* ``"tracker"`` (default): the particle filters (the paper's setting).
* ``"oracle"``: the paper's *ideal* comparison (isotropic sensors, ideal
  communication): robot i receives the true positions of all neighbours (a point
  "ellipse": d_ij = ‖ⁱp_j‖, neighbours treated as static in the CBF as in the
  authors' code) and the controller has no FoV rows (β = 360°, range unlimited).
  It reads ground truth by definition and needs ``poses_world`` every step.

The team arrays are batched for speed, but no number of robot i depends on another
robot's data: rows are independent (tested).
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Literal

import numpy as np

from fov_marl.config import ScenarioConfig
from fov_marl.control import (
    ControllerParams,
    ControlResult,
    FovCbfController,
    coverage_desired_inputs,
    crossing_desired_input,
)
from fov_marl.control.safety import (
    SafetyRows,
    blind_travel_reset,
    blind_travel_step,
    team_safety_rows,
)
from fov_marl.estimation import TrackerBank, TrackerParams
from fov_marl.geometry import relative_pose
from fov_marl.spaces import ObservationLayout, velocity_to_action

__all__ = ["PfCbfPipeline"]

Estimates = Literal["tracker", "oracle"]
#: the blind travel is forgotten once its direction is this far inside the view (degrees)
_LOOK_MARGIN_DEG = 10.0


class PfCbfPipeline:
    """Team-wide, row-independent PF + FoV-CBF controller (see module docstring).

    Args:
        config: the env's scenario config.
        tracker_params: particle-filter parameters (default :class:`TrackerParams()`).
        controller_params: CBF/QP/Lloyd parameters (default :class:`ControllerParams()`).
        use_cbf: False skips the QP (the ``lloyd-pf`` ablation): u = u*.
        estimates: ``"tracker"`` or ``"oracle"``.
        init: ``"known"`` (the paper's assumption, VII-B: every robot knows the
            starting positions of its neighbours) or ``"uniform"``.

    Attributes:
        last_results: the :class:`~fov_marl.control.ControlResult` of every robot at
            the last :meth:`filter` (None entries when ``use_cbf`` is False).
        last_timings: team wall-clock seconds of the last step per stage
            (``tracker``, ``lloyd``, ``qp``).
        counters: ``interventions``, ``fallbacks`` since :meth:`reset`.
    """

    def __init__(
        self,
        config: ScenarioConfig,
        *,
        tracker_params: TrackerParams | None = None,
        controller_params: ControllerParams | None = None,
        use_cbf: bool = True,
        estimates: Estimates = "tracker",
        init: Literal["known", "uniform"] = "known",
    ) -> None:
        if estimates not in ("tracker", "oracle"):
            raise ValueError(f"estimates must be 'tracker' or 'oracle', got {estimates!r}")
        if init not in ("known", "uniform"):
            raise ValueError(f"init must be 'known' or 'uniform', got {init!r}")
        self.config = config
        self.n = config.n_agents
        self.agents = [f"robot_{i}" for i in range(self.n)]
        self.layouts = [ObservationLayout(self.n, i) for i in range(self.n)]
        if tracker_params is not None and not isinstance(tracker_params, TrackerParams):
            raise ValueError(
                f"tracker_params must be a TrackerParams or None, got {type(tracker_params).__name__}"
            )
        if controller_params is not None and not isinstance(controller_params, ControllerParams):
            raise ValueError(
                "controller_params must be a ControllerParams or None, "
                f"got {type(controller_params).__name__}"
            )
        self.tracker_params = tracker_params if tracker_params is not None else TrackerParams()
        self.controller_params = (
            controller_params if controller_params is not None else ControllerParams()
        )
        self.use_cbf = use_cbf
        self.estimates = estimates
        self.init = init
        ctrl_cfg = config
        if estimates == "oracle":
            L = config.arena_size_m
            ctrl_cfg = config.replace(fov_deg=360.0, detection_range_m=2.0 * L)
        self.controllers = [
            FovCbfController(ctrl_cfg, self.controller_params) for _ in range(self.n)
        ]
        self.bank: TrackerBank | None = None
        self._applied: np.ndarray | None = None
        self._need_observe = False
        self._est: dict[str, np.ndarray] | None = None
        self._own_pose = np.zeros((self.n, 3))
        self._goal_body = np.zeros((self.n, 2))
        self.last_results: list[ControlResult | None] = [None] * self.n
        self.last_timings: dict[str, float] = {}
        self.counters = {"interventions": 0, "fallbacks": 0, "safety_fallbacks": 0}

    # ------------------------------------------------------------------ views
    @property
    def own_pose(self) -> np.ndarray:
        """``(N, 3)`` each robot's own world pose, read from its own cue."""
        return self._own_pose.copy()

    def estimates_view(self) -> dict[str, np.ndarray] | None:
        """The current per-robot estimates ``(N, N − 1, ...)`` (not copied; do not modify)."""
        return self._est if self.n > 1 else None

    # ------------------------------------------------------------------ inputs
    def _obs_matrix(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        missing = [a for a in self.agents if a not in obs]
        if missing:
            raise ValueError(
                f"the PF+CBF pipeline needs every robot's observation; missing {missing}"
            )
        return np.stack([np.asarray(obs[a], dtype=np.float64) for a in self.agents])

    def _read_cues(self, obs_m: np.ndarray) -> None:
        for i, lay in enumerate(self.layouts):
            self._own_pose[i] = lay.own_pose_world(obs_m[i])
            self._goal_body[i] = lay.goal_body(obs_m[i])

    # ------------------------------------------------------------------ episode
    def reset(
        self,
        obs: dict[str, np.ndarray],
        seed: int | None = None,
        initial_poses_world: np.ndarray | None = None,
    ) -> None:
        """Start an episode from the first observations.

        Args:
            obs: every robot's first observation.
            seed: seeds the particle filters (robot k draws from child k of
                ``SeedSequence(seed)``).
            initial_poses_world: ``(N, 3)`` true start poses, used only with
                ``init="known"`` (the paper's assumption) and ``estimates="oracle"``.
        """
        obs_m = self._obs_matrix(obs)
        self._read_cues(obs_m)
        self._applied = np.zeros((self.n, 3), dtype=np.float32)
        self._blind_travel_world = np.zeros((self.n, 2))
        self._need_observe = False
        self.counters = {"interventions": 0, "fallbacks": 0, "safety_fallbacks": 0}
        self.last_results = [None] * self.n
        if self.estimates == "tracker" and self.n > 1:
            self.bank = TrackerBank(self.config, self.tracker_params, seed=seed)
            init = initial_poses_world if self.init == "known" else None
            if self.init == "known" and init is None:
                raise ValueError(
                    "init='known' needs initial_poses_world (the team's start poses); "
                    "pass them or use init='uniform'"
                )
            t0 = time.perf_counter()
            self.bank.reset(obs_m.astype(np.float32), initial_poses_world=init)
            self.last_timings = {"tracker": time.perf_counter() - t0}
            self._est = self._bank_estimate()
            self._last_seen_world = np.full((self.n, self.n - 1, 2), np.nan)
            if init is not None:  # the start poses count as seen at t = 0
                cols = np.array([[j for j in range(self.n) if j != i] for i in range(self.n)])
                self._last_seen_world = np.asarray(init, dtype=np.float64)[cols, :2]
            self._update_last_seen()
        elif self.estimates == "oracle":
            self._oracle(initial_poses_world)

    def observe(self, obs: dict[str, np.ndarray], poses_world: np.ndarray | None = None) -> None:
        """Absorb the observations produced by the last applied actions (step 1).

        ``poses_world`` is read only in ``estimates="oracle"`` mode.
        """
        obs_m = self._obs_matrix(obs)
        self._read_cues(obs_m)
        self._blind_travel_world = blind_travel_reset(
            self._blind_travel_world,
            self._own_pose[:, 2],
            self.config.fov_rad,
            math.radians(_LOOK_MARGIN_DEG),
        )
        self.last_timings = {}
        if self.estimates == "tracker" and self.bank is not None:
            t0 = time.perf_counter()
            self.bank.step(self._applied, obs_m.astype(np.float32))
            self._est = self._bank_estimate()
            self._update_last_seen()
            self.last_timings["tracker"] = time.perf_counter() - t0
        elif self.estimates == "oracle":
            self._oracle(poses_world)

    def _update_last_seen(self) -> None:
        """Carry the detected neighbours' estimates into Σ_w as their last-seen points
        (rows of :func:`fov_marl.control.safety.last_seen_rows`)."""
        det = self._est["detected"]
        mu = self._est["mean_body"]
        th = self._own_pose[:, 2:3]
        c, s = np.cos(th), np.sin(th)
        pw = np.stack(
            [
                self._own_pose[:, 0:1] + c * mu[..., 0] - s * mu[..., 1],
                self._own_pose[:, 1:2] + s * mu[..., 0] + c * mu[..., 1],
            ],
            -1,
        )
        self._last_seen_world = np.where(det[..., None], pw, self._last_seen_world)

    def _last_seen_body(self) -> np.ndarray:
        """``(N, N − 1, 2)`` the last-seen points in each robot's Σ_i (NaN: never seen)."""
        d = self._last_seen_world - self._own_pose[:, None, :2]
        th = self._own_pose[:, 2:3]
        c, s = np.cos(th), np.sin(th)
        return np.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]], -1)

    def _bank_estimate(self) -> dict[str, np.ndarray]:
        e = self.bank.estimate()
        return {
            "ids": e.ids,
            "mean_body": e.mean_body,
            "cov_body": e.cov_body,
            "detected": e.detected,
            "counts": e.counts,
            "velocity_est_body": e.velocity_est_body,
            "ellipse_distance": e.ellipse_distance,
            "ellipse_a": e.ellipse_a,
            "ellipse_b": e.ellipse_b,
            "ellipse_psi": e.ellipse_psi,
            "time_since_seen_s": e.time_since_seen_s,
        }

    def _particles(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(p_body (N, P_T, 2), mass (N, P_T))``: every robot's particles and, for those of
        undetected neighbours, their expected-neighbour mass ``1 / P_j`` (0 otherwise)."""
        if self.bank is None or self.controller_params.blind_bins == 0:
            return None
        e = self._est
        P = int(self.tracker_params.n_particles_total)
        pts = np.empty((self.n, P, 2))
        mass = np.empty((self.n, P))
        counts = e["counts"].astype(np.float64)
        w = np.where(e["detected"], 0.0, 1.0 / np.maximum(counts, 1.0))  # (N, M)
        for k in range(self.n):
            p, owner = self.bank.particles_body(k)
            local = owner - (owner > k)  # neighbour ID -> column of robot k's arrays
            pts[k] = p
            mass[k] = w[k, local]
        return pts, mass

    def safety_rows(self) -> SafetyRows:
        """Every robot's collision rows (:mod:`fov_marl.control.safety`) from its own data."""
        cfg, par = self.config, self.controller_params
        e = self._est
        if self.n > 1:
            mean = e["mean_body"]
            cov = e.get("cov_body")
            if cov is None:  # oracle: exact positions, all "detected"
                cov = np.zeros(mean.shape + (2,))
            det = e.get("detected")
            if det is None:
                det = np.ones(mean.shape[:2], dtype=bool)
            parts = self._particles() if self.estimates == "tracker" else None
            tracked = self.estimates == "tracker" and self.bank is not None
            last = self._last_seen_body() if tracked else None
            age = e["time_since_seen_s"] if tracked else None
        else:
            last = age = None
            mean, cov, det, parts = np.zeros((1, 0, 2)), np.zeros((1, 0, 2, 2)), None, None
        return team_safety_rows(
            cfg,
            par,
            mean_body=mean,
            cov_body=cov,
            detected=det if det is not None else np.zeros((1, 0), dtype=bool),
            velocity_est_body=e["velocity_est_body"] if self.n > 1 else None,
            pose_world=self._own_pose,
            particles_body=None if parts is None else parts[0],
            particle_mass=None if parts is None else parts[1],
            fov_rad=2.0 * math.pi if self.estimates == "oracle" else cfg.fov_rad,
            last_seen_body=last,
            last_seen_age_s=age,
            blind_travel_body=None if self.estimates == "oracle" else self._blind_travel_body(),
        )

    def _blind_travel_body(self) -> np.ndarray:
        """``(N, 2)`` each robot's blind travel ``e`` in its Σ_i (m)."""
        e = self._blind_travel_world
        th = self._own_pose[:, 2]
        c, s = np.cos(th), np.sin(th)
        return np.stack([c * e[:, 0] + s * e[:, 1], -s * e[:, 0] + c * e[:, 1]], -1)

    def _oracle(self, poses_world: np.ndarray | None) -> None:
        if poses_world is None:
            raise ValueError("estimates='oracle' needs the true poses_world every step")
        rel = relative_pose(np.asarray(poses_world, dtype=np.float64))
        ids = np.array([lay.neighbour_ids for lay in self.layouts]).reshape(self.n, self.n - 1)
        rows = np.arange(self.n)[:, None]
        p = rel[rows, ids, :2]
        self._est = {
            "ids": ids,
            "mean_body": p,
            "velocity_est_body": np.zeros_like(p),
            "ellipse_distance": np.linalg.norm(p, axis=-1),
        }

    # --------------------------------------------------------------- control
    def desired_inputs(self) -> np.ndarray:
        """``(N, 3)`` u* (body-frame velocities) from each robot's own estimates and cue."""
        t0 = time.perf_counter()
        cfg, par = self.config, self.controller_params
        if cfg.scenario == "crossing":
            u = crossing_desired_input(self._goal_body, cfg, par)
        else:
            if self.n > 1:
                nb = self._est["mean_body"]
            else:
                nb = np.zeros((1, 0, 2))
            u = coverage_desired_inputs(self._own_pose, nb, None, cfg, par).u_star
        self.last_timings["lloyd"] = time.perf_counter() - t0
        return np.asarray(u, dtype=np.float64).reshape(self.n, 3)

    def _look_before_leap(self, u_star: np.ndarray) -> np.ndarray:
        """Turn a robot that has spent most of its blind travel budget towards it.

        Where ``‖e‖ ≥ ¾ B`` (:func:`fov_marl.control.safety.blind_travel_step`) and u*
        still translates along ``e``, u*'s yaw rate becomes ``sat(look_gain · φ_e)``,
        φ_e the bearing of ``e`` in Σ_i: the robot looks where it has been going, which
        releases the budget (the FoV levels, above u*, keep priority). Returns u*
        unchanged otherwise (and for the oracle, or with the budget disabled).
        """
        par = self.controller_params
        if self.estimates != "tracker" or par.blind_travel_m <= 0.0:
            return u_star
        e = self._blind_travel_body()
        r = np.hypot(e[:, 0], e[:, 1])
        along = np.einsum("ij,ij->i", e, u_star[:, :2]) > 0.0
        look = (r >= 0.75 * par.blind_travel_m) & along
        if not np.any(look):
            return u_star
        gain = par.look_gain if par.look_gain > 0.0 else 3.0
        w_max = self.config.omega_max_radps
        out = u_star.copy()
        phi = np.arctan2(e[:, 1], e[:, 0])
        out[:, 2] = np.where(look, np.clip(gain * phi, -w_max, w_max), u_star[:, 2])
        return out

    def filter(self, u_star: np.ndarray) -> np.ndarray:
        """Safe body-frame inputs ``(N, 3)`` closest to ``u_star`` (Eq. 19) per robot.

        Remembers the resulting normalised actions as the applied ones for the next
        :meth:`observe`. With ``use_cbf=False`` returns ``u_star`` (clipped by the
        action mapping).

        Returns:
            ``(N, 3)`` float32 normalised actions in ``[-1, 1]``.
        """
        cfg = self.config
        u_star = np.asarray(u_star, dtype=np.float64).reshape(self.n, 3)
        t0 = time.perf_counter()
        u_nominal = u_star
        u_star = self._look_before_leap(u_star)
        looked = u_star[:, 2] != u_nominal[:, 2]
        u = u_star.copy()
        ellipse = self.controller_params.safety_model == "ellipse"
        if self.use_cbf and (self.n > 1 or (ellipse and self.controller_params.walls)):
            if self.n > 1:
                e = self._est
            else:
                e = {
                    "mean_body": np.zeros((1, 0, 2)),
                    "velocity_est_body": np.zeros((1, 0, 2)),
                    "ellipse_distance": np.zeros((1, 0)),
                    "ids": np.zeros((1, 0), dtype=np.int64),
                }
            t_rows = time.perf_counter()
            rows = self.safety_rows() if ellipse else None
            self.last_timings["safety_rows"] = time.perf_counter() - t_rows
            for i, ctrl in enumerate(self.controllers):
                res = ctrl.solve(
                    u_star[i],
                    e["mean_body"][i],
                    e["velocity_est_body"][i],
                    e["ellipse_distance"][i],
                    e["ids"][i],
                    safety=None if rows is None else rows.robot(i),
                    detected=e["detected"][i] if "detected" in e else None,
                )
                if looked[i] and not res.intervened:  # the look turn is an intervention
                    w_nom = np.clip(u_nominal[i, 2], -cfg.omega_max_radps, cfg.omega_max_radps)
                    tol = self.controller_params.intervention_tol
                    if abs(res.u[2] - w_nom) > tol:
                        res = dataclasses.replace(res, intervened=True)
                self.last_results[i] = res
                u[i] = res.u
                self.counters["interventions"] += int(res.intervened)
                self.counters["fallbacks"] += int(res.fallback)
                self.counters["safety_fallbacks"] += int(res.status == "safety_fallback")
        self.last_timings["qp"] = time.perf_counter() - t0
        act = velocity_to_action(u[:, :2], u[:, 2], cfg.v_max_mps, cfg.omega_max_radps)
        self._applied = act
        if self.estimates == "tracker":
            v = act[:, :2].astype(np.float64) * cfg.v_max_mps
            self._blind_travel_world = blind_travel_step(
                self._blind_travel_world,
                v,
                self._own_pose[:, 2],
                cfg.dt_s,
                self.controller_params.blind_travel_memory_s,
            )
        return act
