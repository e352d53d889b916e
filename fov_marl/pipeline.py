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

Several env copies (``n_copies = B``): one pipeline serves the ``B N`` robots of B
copies of the team at once (row ``k N + i`` is robot i of copy k): one
:class:`~fov_marl.estimation.VectorTrackerBank`, one
:class:`~fov_marl.control.batched.BatchedFovCbfController`, and the ``*_arrays`` /
:meth:`PfCbfPipeline.reset_copies` methods take ``(B, N, ...)`` arrays. Copy k's
numbers are those of a one-copy pipeline reset with copy k's seed (tested).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np

from fov_marl.config import ScenarioConfig
from fov_marl.control import (
    SAFETY_ROW,
    ControllerParams,
    ControlResult,
    FovCbfController,
    coverage_desired_inputs,
    crossing_desired_input,
)
from fov_marl.control.batch_qp import batch_project_to_admissible
from fov_marl.control.batched import (
    CONTROL_STATUSES,
    BatchControlResult,
    BatchedFovCbfController,
)
from fov_marl.control.safety import (
    SafetyRows,
    bearing_angles_body,
    bearing_travel_floor,
    bearing_travel_reset,
    bearing_travel_step,
    bearings_in_view,
    blind_travel_reset,
    blind_travel_step,
    reach_clear,
    risk_quantile,
    team_safety_rows,
    violated_kind_bits,
)
from fov_marl.estimation import TrackerParams, VectorTrackerBank
from fov_marl.estimation.tracker import check_particle_budget
from fov_marl.geometry import body_to_world, relative_pose, world_to_body, wrap_angle
from fov_marl.infos import SAFETY_CAUSES
from fov_marl.spaces import CUE_SIZE, SLOT_SIZE, ObservationLayout, velocity_to_action
from fov_marl.validation import check_int

__all__ = ["PfCbfPipeline"]

Estimates = Literal["tracker", "oracle"]
Controller = Literal["auto", "batched", "loop"]
#: the FoV rows (left, right, range) among each neighbour's four rows
_FOV_ROW_COLS = np.array([k for k in range(4) if k != SAFETY_ROW])
#: slack (m) of the look before the leap's trigger ``c ≥ look_fraction · B``: the
#: budget is booked from the float32 actions the robots applied, so a bearing the QP
#: spent exactly may read a hair below B
_LOOK_SLACK_M = 1e-6
#: ``controller="auto"`` uses the batched controller from this many env copies on: from
#: one, since its QPs are solved by the per-robot solver's NNLS (:mod:`fov_marl.control.batch_qp`)
#: and everything around them runs on the team's arrays. Measured (pfcbf, the paper's
#: 40 m arena, β = 120°, seed 0, median of steps 100-160, ms per robot-step, batched /
#: loop): N = 6 0.79 / 0.91, N = 24 0.88 / 1.18, N = 48 0.90 / 1.34; the two controllers'
#: actions agree within 1.2e-10 over whole episodes (N = 48 x 150 steps, N = 6 x 300,
#: N = 12 at 45° x 200, crossing N = 4 x 300). With the earlier lockstep active-set
#: solver the loop was as fast for one team, and this was 2.
AUTO_BATCHED_MIN_COPIES = 1


class _LazyResults(Sequence):
    """``last_results``: robot i's :class:`ControlResult`, built on access from the batch."""

    def __init__(self, batch: BatchControlResult | None, n: int) -> None:
        self._batch, self._n = batch, n

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, i):  # type: ignore[override]
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(self._n))]
        if not -self._n <= i < self._n:  # also ends iteration (Sequence.__iter__)
            raise IndexError(i)
        if self._batch is None:
            return None
        return self._batch.robot(int(i) % self._n)


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
        n_copies: B ≥ 1 env copies served at once (module docstring).
        controller: ``"batched"`` (:class:`~fov_marl.control.batched.BatchedFovCbfController`),
            ``"loop"`` (one :class:`~fov_marl.control.FovCbfController` per robot, e.g. to
            time each robot's own solve) or ``"auto"``: batched from
            :data:`AUTO_BATCHED_MIN_COPIES` copies on. Same actions either way (within
            1e-6, tested), but for degenerate ties: where the collision rows leave a
            point or a sliver (rows with b = 0 from several sides) the two solvers may
            settle differently, both meeting every row within 1e-3 m/s (measured: 2 of
            10,800 random robots, where round-off of 1e-16 in the fixed rows' bounds decides
            whether a level can be met exactly; ``tests/control/test_batch_controller.py``).
        tracker_threads: threads that step the tracker bank
            (:class:`~fov_marl.estimation.VectorTrackerBank`'s ``n_threads``, an int in
            ``[1, 1024]``, default 1); the same numbers for every count.

    Attributes:
        last_results: the :class:`~fov_marl.control.ControlResult` of every robot (row) at
            the last :meth:`filter` (None entries when ``use_cbf`` is False).
        last_batch: the same as one :class:`~fov_marl.control.batched.BatchControlResult`
            (None before the first filtered step).
        last_cause_bits: ``(B N,)`` int64, why :meth:`filter` changed each robot's input
            at the last step: bit ``k`` for :data:`fov_marl.infos.SAFETY_CAUSES` ``[k]``,
            0 where it did not (:meth:`_cause_bits`).
        controllers: the per-robot controllers (``controller="loop"``; empty otherwise).
        last_timings: team wall-clock seconds of the last step per stage
            (``tracker``, ``lloyd``, ``qp``).
        counters: ``interventions``, ``fallbacks``, ``safety_fallbacks`` since :meth:`reset`
            (all copies).
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
        n_copies: int = 1,
        controller: Controller = "auto",
        tracker_threads: int = 1,
    ) -> None:
        if estimates not in ("tracker", "oracle"):
            raise ValueError(f"estimates must be 'tracker' or 'oracle', got {estimates!r}")
        if init not in ("known", "uniform"):
            raise ValueError(f"init must be 'known' or 'uniform', got {init!r}")
        if controller not in ("auto", "batched", "loop"):
            raise ValueError(f"controller must be 'auto', 'batched' or 'loop', got {controller!r}")
        if isinstance(n_copies, bool) or not isinstance(n_copies, int | np.integer) or n_copies < 1:
            raise ValueError(f"n_copies must be an int >= 1, got {n_copies!r}")
        self.tracker_threads = check_int("tracker_threads", tracker_threads, 1, 1024)
        self.config = config
        self.n = config.n_agents
        self.n_copies = int(n_copies)
        self.n_rows = self.n_copies * self.n
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
        mode = self.tracker_params.init_mode
        if mode not in ("auto", init):
            # the particles would start one way and the controller's start state (blind
            # travel budget, last-seen points) the other
            raise ValueError(
                f"tracker_params.init_mode = {mode!r} contradicts init = {init!r}; set the "
                "initialisation with init= (fov-marl: --filter-init; init_mode 'auto' "
                "follows it)"
            )
        if estimates == "tracker":  # the bank's own check, here and not at reset()
            check_particle_budget(self.tracker_params, self.n)
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
        R = self.n_rows
        batched = controller == "batched" or (
            controller == "auto" and self.n_copies >= AUTO_BATCHED_MIN_COPIES
        )
        self.batched: BatchedFovCbfController | None = (
            BatchedFovCbfController(ctrl_cfg, self.controller_params) if batched else None
        )
        self.controllers = (
            []
            if batched
            else [FovCbfController(ctrl_cfg, self.controller_params) for _ in range(R)]
        )
        self.bank: VectorTrackerBank | None = None
        self._applied: np.ndarray | None = None
        self._travel_pending = False  # a filter() output not yet booked (Sections 2d-2e)
        self._est: dict[str, np.ndarray] | None = None
        self._own_pose = np.zeros((R, 3))
        self._goal_body = np.zeros((R, 2))
        m = self.n - 1
        ids = np.array([lay.neighbour_ids for lay in self.layouts]).reshape(self.n, m)
        self._ids = np.tile(ids, (self.n_copies, 1))
        self._agent_of_row = np.tile(np.arange(self.n), self.n_copies)
        self._obs_size = SLOT_SIZE * m + CUE_SIZE
        self.last_results: Sequence[ControlResult | None] = _LazyResults(None, R)
        self.last_batch: BatchControlResult | None = None
        self.last_cause_bits = np.zeros(R, dtype=np.int64)
        self.last_timings: dict[str, float] = {}
        #: last-seen points of the neighbours (world, NaN: never) and the blind travel
        #: (:mod:`fov_marl.control.safety` Sections 2c, 2d), per row
        self._last_seen_world = np.full((R, m, 2), np.nan)
        self._detection_body = np.full((R, m, 2), np.nan)
        self._blind_travel_world = np.zeros((R, 2))
        #: approach per world bearing since the camera last looked at it (Section 2e)
        self._bearing_travel = np.zeros((R, self.controller_params.blind_travel_bearings))
        #: the part of each bearing's budget the neighbours seen at its last look had
        #: used (Section 2g), kept only with ``blind_travel_prespend``
        self._bearing_floor = np.zeros_like(self._bearing_travel)
        # the look before the leap's memory: u*'s translation bearing at the last step
        # (rad, Σ_w; NaN: none), read with look_persistence_deg
        self._look_prev_world = np.full(R, np.nan)
        #: the neighbours' reachable disks (Section 2f), kept only with
        #: ``blind_travel_reach``: centre at the last detection (world, NaN: never
        #: detected) and its radius then (m); the time since is the tracker's
        par = self.controller_params
        self._reach_on = bool(
            par.blind_travel_reach and par.blind_travel_bearings > 0 and par.blind_travel_m > 0
        )
        self._reach_world = np.full((R, m, 2), np.nan)
        self._reach_base_m = np.zeros((R, m))
        #: Section 2g's floors are kept (and read) only with a budget per bearing, the
        #: tracker and a camera with bearings out of view
        self._prespend_on = bool(
            par.blind_travel_prespend
            and par.blind_travel_bearings > 0
            and par.blind_travel_m > 0
            and self.estimates == "tracker"
            and self.config.fov_rad < 2.0 * math.pi
        )
        self.counters = {"interventions": 0, "fallbacks": 0, "safety_fallbacks": 0}

    # ------------------------------------------------------------------ views
    @property
    def own_pose(self) -> np.ndarray:
        """``(B N, 3)`` each robot's own world pose, read from its own cue."""
        return self._own_pose.copy()

    def estimates_view(self) -> dict[str, np.ndarray] | None:
        """The current per-robot estimates ``(B N, N − 1, ...)`` (not copied; do not modify)."""
        return self._est if self.n > 1 else None

    # ------------------------------------------------------------------ inputs
    def _obs_matrix(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        if self.n_copies != 1:
            raise ValueError(
                f"this pipeline serves n_copies = {self.n_copies} copies: use the *_arrays methods"
            )
        missing = [a for a in self.agents if a not in obs]
        if missing:
            raise ValueError(
                f"the PF+CBF pipeline needs every robot's observation; missing {missing}"
            )
        return np.stack([np.asarray(obs[a], dtype=np.float64) for a in self.agents])

    def _obs_rows(self, obs: Any) -> np.ndarray:
        """``(B N, D)`` float64 from ``(B, N, D)`` observations."""
        arr = np.asarray(obs, dtype=np.float64)
        shape = (self.n_copies, self.n, self._obs_size)
        if arr.shape != shape:
            raise ValueError(
                f"obs must have shape (n_copies, n_agents, obs_size) = {shape}, got {arr.shape}"
            )
        return arr.reshape(self.n_rows, self._obs_size)

    def _poses(self, poses: Any, name: str) -> np.ndarray | None:
        if poses is None:
            return None
        arr = np.asarray(poses, dtype=np.float64)
        if arr.shape == (self.n, 3) and self.n_copies == 1:
            arr = arr[None]
        if arr.shape != (self.n_copies, self.n, 3):
            raise ValueError(
                f"{name} must have shape (n_agents, 3) per copy = ({self.n_copies}, {self.n}, 3), "
                f"got {np.shape(poses)}"
            )
        return arr

    def _read_cues(self, obs_m: np.ndarray, rows: np.ndarray | None = None) -> None:
        o = obs_m if rows is None else obs_m[rows]
        lay = self.layouts[0]  # the slots and the cue are where they are for every robot
        det, p_body, _ = lay.slot_arrays(o)
        # the camera's own report in Σ_i (safety Section 1d); NaN: not detected
        z = np.where(det[..., None], p_body, np.nan)
        at = slice(None) if rows is None else rows
        if rows is None:
            self._detection_body = z
        else:
            self._detection_body[rows] = z
        self._own_pose[at] = lay.own_pose_world(o)
        self._goal_body[at] = lay.goal_body(o)

    # ------------------------------------------------------------------ episode
    def reset(
        self,
        obs: dict[str, np.ndarray],
        seed: int | None = None,
        initial_poses_world: np.ndarray | None = None,
    ) -> None:
        """Start an episode from the first observations (one copy).

        Args:
            obs: every robot's first observation.
            seed: seeds the particle filters (robot k draws from child k of
                ``SeedSequence(seed)``).
            initial_poses_world: ``(N, 3)`` true start poses, used only with
                ``init="known"`` (the paper's assumption) and ``estimates="oracle"``.
        """
        obs_m = self._obs_matrix(obs)
        self.reset_arrays(
            obs_m[None], [seed], self._poses(initial_poses_world, "initial_poses_world")
        )

    def reset_arrays(
        self, obs: Any, seeds: Sequence[int | None] | None = None, initial_poses_world: Any = None
    ) -> None:
        """Start every copy: ``obs (B, N, D)``, one seed per copy, ``initial_poses_world
        (B, N, 3)`` (see :meth:`reset`)."""
        obs_m = self._obs_rows(obs)
        init_all = self._poses(initial_poses_world, "initial_poses_world")
        self._read_cues(obs_m)
        self._applied = np.zeros((self.n_rows, 3), dtype=np.float32)
        self._travel_pending = False
        self._blind_travel_world = np.zeros((self.n_rows, 2))
        self._bearing_travel = np.zeros_like(self._bearing_travel)
        self._reset_bearing_travel(np.arange(self.n_rows))
        self._fov_lead = np.full(self.n_rows, -1, dtype=np.int64)
        self._yielded = np.zeros(self.n_rows, dtype=bool)
        self._unblocked = np.zeros(self.n_rows, dtype=bool)
        self.counters = {"interventions": 0, "fallbacks": 0, "safety_fallbacks": 0}
        self.last_results = _LazyResults(None, self.n_rows)
        self.last_batch = None
        self.last_cause_bits = np.zeros(self.n_rows, dtype=np.int64)
        seeds = [None] * self.n_copies if seeds is None else list(seeds)
        if self.estimates == "tracker" and self.n > 1:
            self.bank = VectorTrackerBank(
                self.config,
                self.tracker_params,
                n_copies=self.n_copies,
                n_threads=self.tracker_threads,
            )
            init = self._known_init(init_all)
            t0 = time.perf_counter()
            self.bank.reset(
                obs_m.astype(np.float32).reshape(self.n_copies, self.n, -1),
                initial_poses_world=init,
                seeds=seeds,
            )
            self.last_timings = {"tracker": time.perf_counter() - t0}
            self._est = self._bank_estimate()
            self._reset_last_seen(np.arange(self.n_rows), init)
            self._reset_bearing_floor(np.arange(self.n_rows), init)
            self._reset_reach(np.arange(self.n_rows), init)
        elif self.estimates == "oracle":
            self._oracle(init_all)

    def _reset_bearing_travel(self, rows: np.ndarray) -> None:
        """Start the blind travel budget of ``rows`` (safety Sections 2d-2e).

        With ``init="known"`` the robot starts knowing where its neighbours are (their
        particles start on the true poses): nothing is spent. With ``init="uniform"`` it
        knows nothing, so every bearing counts as spent (``c_k = B``) until the camera has
        had it in view: the robot may not approach a bearing it has not looked at since
        the episode began. Measured before (filter, ``init="uniform"``, robots packed
        1.1 m apart along a wall, ``straight`` adversary, N = 4, seed 1): a robot in the
        safe fallback backed at 0.98 m/s into a neighbour 1.1 m behind it that it had
        never seen and for which no uniform particle lay in that sector (0.90 m at step
        6); the 0.5 m budget allowed it. The bearings in view at reset are released at
        once (:func:`~fov_marl.control.safety.bearing_travel_reset`). The single budget
        vector (``blind_travel_bearings = 0``, an ablation) has no per-bearing state and
        starts at zero either way.
        """
        self._look_prev_world[rows] = np.nan
        K = self._bearing_travel.shape[1]
        unknown = self.init == "uniform" and self.estimates == "tracker"
        spent = self.controller_params.blind_travel_m if unknown else 0.0
        self._bearing_travel[rows] = bearing_travel_reset(
            np.full((len(rows), K), spent),
            self._own_pose[rows, 2],
            self.config.fov_rad,
            math.pi / max(K, 1),
        )

    def _start_world(self, rows: np.ndarray, init: Any) -> np.ndarray:
        """``(len(rows), N − 1, 2)`` the neighbours' known start positions in Σ_w, from
        ``init (B, N, 3)``, in each row's slot order."""
        copy = rows // self.n
        return np.asarray(init, dtype=np.float64)[copy[:, None], self._ids[rows], :2]

    def _bearings_seen(self, rows: np.ndarray | slice) -> np.ndarray:
        """``(R, K)`` the budget bearings each of ``rows`` has in view now (the test of
        :func:`~fov_marl.control.safety.bearing_travel_reset`, without its 360° case)."""
        K = self._bearing_travel.shape[1]
        ang = bearing_angles_body(K, self._own_pose[rows, 2])
        return bearings_in_view(ang, self.config.fov_rad, math.pi / K)

    def _reset_bearing_floor(self, rows: np.ndarray, init: np.ndarray | None) -> None:
        """Start the floors of ``rows`` (safety Section 2g): the known start poses ``init
        (B, N, 3)`` are exact reports at t = 0, seen from every bearing; then this step's
        detections."""
        self._bearing_floor[rows] = 0.0
        if not self._prespend_on:
            return
        if init is not None:
            start_world = self._start_world(rows, init)
            start_body = world_to_body(start_world, self._own_pose[rows][:, None, :])
            par, cfg = self.controller_params, self.config
            self._bearing_floor[rows] = bearing_travel_floor(
                start_body,
                0.0,
                self._own_pose[rows, 2],
                self._bearing_floor.shape[1],
                cfg.safety_distance_m,
                par.blind_travel_m,
            )
        self._update_bearing_floor(rows)

    def _update_bearing_floor(self, rows: np.ndarray) -> None:
        """Set the floors of the bearings ``rows`` have in view from this step's detections,
        and raise those out of view that a detection's cone reaches (Section 2g)."""
        if not self._prespend_on:
            return
        par, cfg = self.controller_params, self.config
        slack = risk_quantile(par.safety_risk) * math.sqrt(max(cfg.meas_cov_diag[:2]))
        used = bearing_travel_floor(
            self._detection_body[rows],
            slack,
            self._own_pose[rows, 2],
            self._bearing_floor.shape[1],
            cfg.safety_distance_m,
            par.blind_travel_m,
        )
        seen = self._bearings_seen(rows)
        self._bearing_floor[rows] = np.where(
            seen, used, np.maximum(self._bearing_floor[rows], used)
        )

    def _bearing_spent(self) -> np.ndarray:
        """``(B N, K)`` the budget spent per bearing: ``c_k``, plus its floor (Section 2g)
        for the bearings out of view (those in view get no row from it)."""
        c = self._bearing_travel
        if not self._prespend_on:
            return c
        return c + np.where(self._bearings_seen(slice(None)), 0.0, self._bearing_floor)

    def _reset_last_seen(self, rows: np.ndarray, init: np.ndarray | None) -> None:
        """Forget the last-seen points of ``rows``; the known start poses ``init (B, N, 3)``
        count as seen at t = 0. Then take this step's detections."""
        self._last_seen_world[rows] = np.nan
        if init is not None:
            self._last_seen_world[rows] = self._start_world(rows, init)
        self._update_last_seen()

    def _update_last_seen(self) -> None:
        """Carry the detected neighbours' estimates into Σ_w as their last-seen points."""
        det = self._est["detected"]
        pw = body_to_world(self._est["mean_body"], self._own_pose[:, None, :])
        self._last_seen_world = np.where(det[..., None], pw, self._last_seen_world)

    def _reset_reach(self, rows: np.ndarray, init: np.ndarray | None) -> None:
        """Start the reachable disks of ``rows`` (safety Section 2f): the known start poses
        ``init (B, N, 3)`` are exact detections at t = 0; then this step's detections."""
        if not self._reach_on:
            return
        self._reach_world[rows] = np.nan
        self._reach_base_m[rows] = 0.0
        if init is not None:
            self._reach_world[rows] = self._start_world(rows, init)
        self._take_reach_detections(rows)
        self._clear_reached(rows)

    def _update_reach(self) -> None:
        """Age the reachable disks by one step, take this step's detections, and clear
        the budgets of the robots no neighbour can be near (safety Section 2f)."""
        if not self._reach_on:
            return
        rows = np.arange(self.n_rows)
        self._take_reach_detections(rows)
        self._clear_reached(rows)

    def _take_reach_detections(self, rows: np.ndarray) -> None:
        """Centre the disks of the neighbours ``rows`` detect now on the raw detection,
        with the radius of the env's truncated noise (``meas_noise_clip_sigma`` std on
        each axis; 1 mm for the observation's float32)."""
        cfg = self.config
        z = self._detection_body[rows]
        det = np.isfinite(z[..., 0])
        if not det.any():
            return
        zw = body_to_world(np.where(det[..., None], z, 0.0), self._own_pose[rows][:, None, :])
        r_z = cfg.meas_noise_clip_sigma * math.hypot(*cfg.meas_std[:2]) + 1e-3
        self._reach_world[rows] = np.where(det[..., None], zw, self._reach_world[rows])
        self._reach_base_m[rows] = np.where(det, r_z, self._reach_base_m[rows])

    def _clear_reached(self, rows: np.ndarray) -> np.ndarray:
        """Zero the whole budget of the ``rows`` no neighbour can be near
        (:func:`~fov_marl.control.safety.reach_clear`; called only with
        ``blind_travel_reach`` and a budget per bearing). Returns the rows zeroed."""
        par, cfg = self.controller_params, self.config
        pose = self._own_pose[rows]
        centre = world_to_body(self._reach_world[rows], pose[:, None, :])
        age = self._est["time_since_seen_s"][rows]  # the tracker's, from the same slots
        radius = self._reach_base_m[rows] + cfg.v_max_mps * age
        horizon = cfg.safety_distance_m + 2.0 * par.blind_travel_m + 2.0 * cfg.v_max_mps * cfg.dt_s
        clear = rows[reach_clear(centre, radius, horizon)]
        self._bearing_travel[clear] = 0.0
        self._bearing_floor[clear] = 0.0
        return clear

    def _last_seen_body(self) -> np.ndarray:
        """``(B N, N − 1, 2)`` the last-seen points in each robot's Σ_i (NaN: never seen)."""
        return world_to_body(self._last_seen_world, self._own_pose[:, None, :])

    def _blind_travel_body(self) -> np.ndarray:
        """``(B N, 2)`` each robot's blind travel ``e`` in its Σ_i (m)."""
        heading = np.zeros_like(self._own_pose)
        heading[:, 2] = self._own_pose[:, 2]  # a displacement: rotate only
        return world_to_body(self._blind_travel_world, heading)

    def _known_init(self, init_all: np.ndarray | None) -> np.ndarray | None:
        init = init_all if self.init == "known" else None
        if self.init == "known" and init is None:
            raise ValueError(
                "init='known' needs initial_poses_world (the team's start poses); "
                "pass them or use init='uniform'"
            )
        return init

    def reset_copies(
        self,
        copies: Any,
        obs: Any,
        seeds: Sequence[int | None] | None = None,
        initial_poses_world: Any = None,
    ) -> None:
        """Restart the copies ``copies`` (indices or ``(B,)`` bool mask) from their rows of
        ``obs (B, N, D)`` and ``initial_poses_world (B, N, 3)``, one seed per restarted copy;
        the other copies keep every number (an env copy that finished its episode)."""
        c = np.asarray(copies)
        if c.dtype == bool:
            c = np.flatnonzero(c)
        c = c.astype(np.int64).reshape(-1)
        if c.size == 0:
            return
        obs_m = self._obs_rows(obs)
        init_all = self._poses(initial_poses_world, "initial_poses_world")
        rows = (c[:, None] * self.n + np.arange(self.n)[None, :]).reshape(-1)
        self._read_cues(obs_m, rows)
        self._applied = self._applied.copy()  # the last filter() output stays the caller's
        self._applied[rows] = 0.0
        self._blind_travel_world[rows] = 0.0
        self._reset_bearing_travel(rows)
        self._fov_lead[rows] = -1
        self._yielded[rows] = False
        self._unblocked[rows] = False
        if self.estimates == "tracker" and self.n > 1:
            init = self._known_init(init_all)
            self.bank.reset_copies(
                c,
                obs_m.astype(np.float32).reshape(self.n_copies, self.n, -1),
                initial_poses_world=init,
                seeds=[None] * c.size if seeds is None else list(seeds),
            )
            self._est = self._bank_estimate()
            self._reset_last_seen(rows, init)
            self._reset_bearing_floor(rows, init)
            self._reset_reach(rows, init)
        elif self.estimates == "oracle":
            self._oracle(init_all)

    def observe(self, obs: dict[str, np.ndarray], poses_world: np.ndarray | None = None) -> None:
        """Absorb the observations produced by the last applied actions (step 1).

        ``poses_world`` is read only in ``estimates="oracle"`` mode.
        """
        obs_m = self._obs_matrix(obs)
        self.observe_arrays(obs_m[None], self._poses(poses_world, "poses_world"))

    def observe_arrays(self, obs: Any, poses_world: Any = None) -> None:
        """:meth:`observe` for every copy: ``obs (B, N, D)``, ``poses_world (B, N, 3)``."""
        obs_m = self._obs_rows(obs)
        self._book_travel()  # the step just taken, from the pose it started at
        self._read_cues(obs_m)
        if self._bearing_travel.shape[1]:  # one budget kept: per bearing (Section 2e) ...
            self._bearing_travel = bearing_travel_reset(
                self._bearing_travel,
                self._own_pose[:, 2],
                self.config.fov_rad,
                math.pi / self._bearing_travel.shape[1],  # the bin's whole sector
            )
            self._update_bearing_floor(np.arange(self.n_rows))
        else:  # ... or the single vector (Section 2d)
            self._blind_travel_world = blind_travel_reset(
                self._blind_travel_world,
                self._own_pose[:, 2],
                self.config.fov_rad,
                math.radians(self.controller_params.blind_travel_view_deg),
            )
        self.last_timings = {}
        if self.estimates == "tracker" and self.bank is not None:
            t0 = time.perf_counter()
            self.bank.step(
                self._applied.reshape(self.n_copies, self.n, 3),
                obs_m.astype(np.float32).reshape(self.n_copies, self.n, -1),
            )
            self._est = self._bank_estimate()
            self._update_last_seen()
            self._update_reach()
            self.last_timings["tracker"] = time.perf_counter() - t0
        elif self.estimates == "oracle":
            self._oracle(self._poses(poses_world, "poses_world"))

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
        """``(p_body (B N, P_T, 2), mass (B N, P_T))``: every robot's particles and, for those
        of undetected neighbours, their expected-neighbour mass ``1 / P_j`` (0 otherwise)."""
        if self.bank is None or self.controller_params.blind_bins == 0:
            return None
        e = self._est
        counts = e["counts"].astype(np.float64)
        w = np.where(e["detected"], 0.0, 1.0 / np.maximum(counts, 1.0))  # (R, M)
        pts = self.bank.positions_all()
        # a row's particles are sorted by owner, in neighbour-column order: each column's
        # mass repeated by its count (the values of a gather by owner column, faster)
        return pts, np.repeat(w.reshape(-1), e["counts"].reshape(-1)).reshape(pts.shape[:2])

    def safety_rows(self) -> SafetyRows:
        """Every robot's collision rows (:mod:`fov_marl.control.safety`) from its own data."""
        cfg, par = self.config, self.controller_params
        e = self._est
        R = self.n_rows
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
            mean, cov, det, parts = np.zeros((R, 0, 2)), np.zeros((R, 0, 2, 2)), None, None
        no_budget = not self._budget_on()
        return team_safety_rows(
            cfg,
            par,
            mean_body=mean,
            cov_body=cov,
            detected=det if det is not None else np.zeros((R, 0), dtype=bool),
            velocity_est_body=e["velocity_est_body"] if self.n > 1 else None,
            pose_world=self._own_pose,
            particles_body=None if parts is None else parts[0],
            particle_mass=None if parts is None else parts[1],
            fov_rad=2.0 * math.pi if self.estimates == "oracle" else cfg.fov_rad,
            last_seen_body=last,
            last_seen_age_s=age,
            # no budget for the oracle, nor for a one-robot team (no neighbour to meet blind)
            blind_travel_body=None if no_budget else self._blind_travel_body(),
            particle_counts=None if parts is None else e["counts"],
            bearing_travel_m=None if no_budget else self._bearing_spent(),
            detection_body=self._detection_body if self.estimates == "tracker" else None,
        )

    def _oracle(self, poses_world: np.ndarray | None) -> None:
        if poses_world is None:
            raise ValueError("estimates='oracle' needs the true poses_world every step")
        rows = np.arange(self.n)[:, None]
        ids = self._ids[: self.n]
        p = np.concatenate(
            [relative_pose(poses_world[k])[rows, ids, :2] for k in range(self.n_copies)]
        )
        self._est = {
            "ids": self._ids,
            "mean_body": p,
            "velocity_est_body": np.zeros_like(p),
            "ellipse_distance": np.linalg.norm(p, axis=-1),
        }

    # --------------------------------------------------------------- control
    def desired_inputs(self) -> np.ndarray:
        """``(B N, 3)`` u* (body-frame velocities) from each robot's own estimates and cue."""
        t0 = time.perf_counter()
        cfg, par = self.config, self.controller_params
        R = self.n_rows
        if cfg.scenario == "crossing":
            u = crossing_desired_input(self._goal_body, cfg, par)
        else:
            if self.n > 1:
                nb = self._est["mean_body"]
            else:
                nb = np.zeros((R, 0, 2))
            u = coverage_desired_inputs(self._own_pose, nb, None, cfg, par).u_star
        self.last_timings["lloyd"] = time.perf_counter() - t0
        return np.asarray(u, dtype=np.float64).reshape(R, 3)

    def _priority_bonus(self, ids: np.ndarray) -> np.ndarray | None:
        """``(B N, M)`` head start in d (m) of the neighbour that led the FoV levels at
        the previous step (``priority_hysteresis_m``; None when 0)."""
        hyst = self.controller_params.priority_hysteresis_m
        if hyst <= 0.0 or ids.shape[1] == 0:
            return None
        return np.where(ids == self._fov_lead[:, None], hyst, 0.0)

    def _update_fov_lead(self, level: np.ndarray, ids: np.ndarray) -> None:
        """Remember each robot's FoV lead: the neighbour whose FoV rows (left, right,
        range) sit on the highest-priority FoV level of this step's solve (−1: none)."""
        if ids.shape[1] == 0:
            return
        fov = level[..., _FOV_ROW_COLS]  # (R, M, 3)
        lv = np.where(fov >= 1, fov, np.iinfo(np.int64).max).min(axis=2)  # (R, M)
        col = np.argmin(lv, axis=1)
        has = lv[np.arange(lv.shape[0]), col] < np.iinfo(np.int64).max
        self._fov_lead = np.where(has, ids[np.arange(ids.shape[0]), col], -1)

    def _fov_yield(self, e: dict[str, np.ndarray]) -> np.ndarray | None:
        """``(R, M)`` neighbours whose FoV rows may yield when they stall their robot.

        Those not detected for at least ``controller_params.lost_fov_age_s`` (see
        :meth:`fov_marl.control.FovCbfController._yield_lost`); None when
        ``lost_fov_yield`` is off or without tracker estimates (oracle, belief-free).
        """
        p = self.controller_params
        age = e.get("time_since_seen_s")
        det = e.get("detected")
        if not p.lost_fov_yield or age is None or det is None:
            return None
        return ~np.asarray(det, dtype=bool) & (np.asarray(age) >= p.lost_fov_age_s)

    def _budget_on(self) -> bool:
        """Whether the blind travel budget applies (its rows and the look before the
        leap): the CBF on the particle filters' estimates (not the oracle), a budget
        B > 0, and a neighbour to meet blind (not a one-robot team)."""
        return (
            self.use_cbf
            and self.estimates == "tracker"
            and self.controller_params.blind_travel_m > 0.0
            and self.n > 1
        )

    def _look_before_leap(self, u_star: np.ndarray) -> np.ndarray:
        """Turn a robot that has spent most of its blind travel budget towards it.

        Where ``‖e‖ ≥ f B − 1 µm`` (f = ``look_fraction``, ¾ by default; with
        ``look_persistence_deg > 0``, the safety filter's 45°, only for a u* whose
        translation kept its course in Σ_w within that angle since the last step, and
        f = 1 for any other; :func:`fov_marl.control.safety.blind_travel_step`) and u*
        still translates along ``e``, u*'s yaw rate becomes ``sat(look_gain · φ_e)``,
        φ_e the bearing of ``e`` in Σ_i: the robot looks where it has been going, which
        releases the budget (the FoV levels, above u*, keep priority unless
        ``look_yields_fov``: then :meth:`filter` leaves them out of that step). With the budget
        per bearing (``blind_travel_bearings > 0``, Section 2e) ``e`` is the most-spent
        bearing ``c_k n_k`` among those u* approaches. Returns u* unchanged otherwise
        (and for the oracle, or with the budget disabled).
        """
        par = self.controller_params
        if not self._budget_on():
            return u_star
        trigger = par.look_fraction * par.blind_travel_m - _LOOK_SLACK_M
        if par.look_persistence_deg > 0.0:
            # the early look only for a u* that keeps its course (Σ_w, so the robot's own
            # turn does not count); a course that changes looks once the budget is spent
            ux, uy = u_star[:, 0], u_star[:, 1]
            course = self._own_pose[:, 2] + np.arctan2(uy, ux)
            turn = np.abs(wrap_angle(course - self._look_prev_world))  # NaN: no course yet
            steady = turn <= math.radians(par.look_persistence_deg)
            self._look_prev_world = np.where(np.hypot(ux, uy) > 0.0, course, np.nan)
            trigger = np.where(steady, trigger, par.blind_travel_m - _LOOK_SLACK_M)
        if par.blind_travel_bearings > 0:
            c = self._bearing_spent()
            ang = bearing_angles_body(c.shape[1], self._own_pose[:, 2])
            appr = np.cos(ang) * u_star[:, 0:1] + np.sin(ang) * u_star[:, 1:2] > 0.0
            row = np.arange(c.shape[0])
            k = np.argmax(np.where(appr, c, -1.0), axis=1)  # the most-spent approached
            look = appr[row, k] & (c[row, k] >= trigger)
            phi = ang[row, k]
        else:
            e = self._blind_travel_body()
            r = np.hypot(e[:, 0], e[:, 1])
            along = np.einsum("ij,ij->i", e, u_star[:, :2]) > 0.0
            look = (r >= trigger) & along
            phi = np.arctan2(e[:, 1], e[:, 0])
        if not np.any(look):
            return u_star
        gain = par.look_gain if par.look_gain > 0.0 else 3.0
        w_max = self.config.omega_max_radps
        out = u_star.copy()
        out[:, 2] = np.where(look, np.clip(gain * phi, -w_max, w_max), u_star[:, 2])
        return out

    def filter(self, u_star: np.ndarray) -> np.ndarray:
        """Safe body-frame inputs ``(B N, 3)`` closest to ``u_star`` (Eq. 19) per robot.

        Remembers the resulting normalised actions as the applied ones for the next
        :meth:`observe`. With ``use_cbf=False`` returns ``u_star`` (clipped by the
        action mapping).

        Returns:
            ``(B N, 3)`` float32 normalised actions in ``[-1, 1]``.
        """
        cfg = self.config
        R = self.n_rows
        u_star = np.asarray(u_star, dtype=np.float64).reshape(R, 3)
        t0 = time.perf_counter()
        u_nominal = u_star
        u_star = self._look_before_leap(u_star)
        looked = u_star[:, 2] != u_nominal[:, 2]
        glance = looked if self.controller_params.look_yields_fov else None
        u = u_star.copy()
        self.last_cause_bits = np.zeros(R, dtype=np.int64)
        ellipse = self.controller_params.safety_model == "ellipse"
        if self.use_cbf and (self.n > 1 or (ellipse and self.controller_params.walls)):
            if self.n > 1:
                e = self._est
            else:
                e = {
                    "mean_body": np.zeros((R, 0, 2)),
                    "velocity_est_body": np.zeros((R, 0, 2)),
                    "ellipse_distance": np.zeros((R, 0)),
                    "ids": np.zeros((R, 0), dtype=np.int64),
                }
            t_rows = time.perf_counter()
            rows = self.safety_rows() if ellipse else None
            self.last_timings["safety_rows"] = time.perf_counter() - t_rows
            det = e.get("detected")
            fov_yield = self._fov_yield(e)
            bonus = self._priority_bonus(e["ids"])
            if self.batched is not None:
                res = self.batched.solve(
                    u_star,
                    e["mean_body"],
                    e["velocity_est_body"],
                    e["ellipse_distance"],
                    e["ids"],
                    safety=rows,
                    detected=det,
                    fov_yield=fov_yield,
                    priority_bonus=bonus,
                    glance=glance,
                    yield_latched=None if fov_yield is None else self._yielded,
                    unblock_latched=self._unblocked,
                )
                results: Sequence[ControlResult | None] = _LazyResults(res, R)
            else:
                out = []
                for i, ctrl in enumerate(self.controllers):
                    out.append(
                        ctrl.solve(
                            u_star[i],
                            e["mean_body"][i],
                            e["velocity_est_body"][i],
                            e["ellipse_distance"][i],
                            e["ids"][i],
                            safety=None if rows is None else rows.robot(i),
                            detected=det[i] if det is not None else None,
                            fov_yield=None if fov_yield is None else fov_yield[i],
                            priority_bonus=None if bonus is None else bonus[i],
                            glance=glance is not None and bool(glance[i]),
                            yield_latched=fov_yield is not None and bool(self._yielded[i]),
                            unblock_latched=bool(self._unblocked[i]),
                        )
                    )
                res = BatchControlResult.from_results(out, time.perf_counter() - t_rows)
                results = out
            if np.any(looked):  # the look turn is an intervention when it changed ω
                w_nom = np.clip(u_nominal[:, 2], -cfg.omega_max_radps, cfg.omega_max_radps)
                extra = looked & ~res.intervened
                extra &= np.abs(res.u[:, 2] - w_nom) > self.controller_params.intervention_tol
                if np.any(extra):
                    res.intervened = res.intervened | extra
                    if self.batched is None:
                        results = [
                            dataclasses.replace(r, intervened=True) if extra[i] else r
                            for i, r in enumerate(out)
                        ]
                    else:
                        results = _LazyResults(res, R)
            self.last_cause_bits = self._cause_bits(u_nominal, rows, res, looked)
            self._update_fov_lead(res.level, e["ids"])
            self._yielded = res.yielded.copy()
            self._unblocked = res.unblocked.copy()
            self.last_batch = res
            self.last_results = results
            u = res.u.copy()
            self.counters["interventions"] += int(np.count_nonzero(res.intervened))
            self.counters["fallbacks"] += int(np.count_nonzero(res.fallback))
            self.counters["safety_fallbacks"] += int(
                np.count_nonzero(res.status == CONTROL_STATUSES.index("safety_fallback"))
            )
        self.last_timings["qp"] = time.perf_counter() - t0
        act = velocity_to_action(u[:, :2], u[:, 2], cfg.v_max_mps, cfg.omega_max_radps)
        self._applied = act
        self._travel_pending = True
        return act

    def _cause_bits(
        self,
        u_nominal: np.ndarray,
        rows: SafetyRows | None,
        res: BatchControlResult,
        looked: np.ndarray,
    ) -> np.ndarray:
        """Why each changed input was changed, as bits of
        :data:`fov_marl.infos.SAFETY_CAUSES` (its table; 0 for an unchanged one).

        Bits 0-6: the kinds of collision row the policy's u* (``u_nominal (R, 3)``,
        before the look, projected on the admissible set) breaks
        (:func:`~fov_marl.control.safety.violated_kind_bits`); ``fov``: none of them,
        with FoV rows in the QP; ``look``: the look before the leap changed ω;
        ``fallback``: a fallback input; ``other``: a change with none of these.
        """
        bit = {name: np.int64(1) << np.int64(k) for k, name in enumerate(SAFETY_CAUSES)}
        cfg, par = self.config, self.controller_params
        u_proj = batch_project_to_admissible(
            u_nominal, cfg.v_max_mps, cfg.omega_max_radps, par.n_polygon
        )
        out = np.zeros(len(u_nominal), dtype=np.int64)
        if rows is not None:
            out |= violated_kind_bits(rows, u_proj)
        fov = (out == 0) & np.asarray(res.active).any(axis=(1, 2))
        out |= np.where(fov, bit["fov"], 0)
        turned = looked & (np.abs(res.u[:, 2] - u_proj[:, 2]) > par.intervention_tol)
        out |= np.where(turned, bit["look"], 0)
        out |= np.where(np.asarray(res.fallback, dtype=bool), bit["fallback"], 0)
        changed = np.asarray(res.intervened, dtype=bool)
        out = np.where(changed, out, 0)
        return np.where(changed & (out == 0), bit["other"], out)

    def set_applied(self, actions: Any) -> None:
        """Replace the actions remembered as applied at the last step.

        :meth:`filter` remembers its own output as what each robot applied; the next
        :meth:`observe` moves the particles by that motion (tracker step 1) and books it
        in the blind travel budget (:mod:`fov_marl.control.safety` Sections 2d-2e). When
        something between this pipeline and the env changed the actions (a
        :class:`~fov_marl.wrappers.SafetyFilterWrapper` in front of the ``pfcbf`` policy),
        call this between the env step and :meth:`observe` with what was applied: a
        robot knows the velocity its own actuators executed.

        Args:
            actions: ``(B N, 3)`` normalised actions in ``[-1, 1]`` (rows as
                :meth:`filter` returns them).

        Raises:
            ValueError: another shape, non-finite entries or entries outside ``[-1, 1]``.
        """
        a = np.asarray(actions, dtype=np.float64)
        if a.shape != (self.n_rows, 3):
            raise ValueError(f"actions must have shape ({self.n_rows}, 3), got {a.shape}")
        if not np.isfinite(a).all() or np.abs(a).max(initial=0.0) > 1.0:
            raise ValueError("actions must be finite and in [-1, 1]")
        self._applied = a.astype(np.float32)

    def _book_travel(self) -> None:
        """Book the last step's applied translation in the blind travel budget (Sections
        2d-2e), in the frame of the pose it started from (called by :meth:`observe_arrays`
        before the new cues are read)."""
        if self.estimates != "tracker" or not self._travel_pending:
            return
        self._travel_pending = False
        cfg = self.config
        act = self._applied
        v = act[:, :2].astype(np.float64) * cfg.v_max_mps
        if self._bearing_travel.shape[1]:
            self._bearing_travel = bearing_travel_step(
                self._bearing_travel,
                v,
                self._own_pose[:, 2],
                cfg.dt_s,
                self.controller_params.blind_travel_memory_s,
                floor_m=self.controller_params.blind_travel_credit_m,
                omega_radps=act[:, 2].astype(np.float64) * cfg.omega_max_radps,
            )
        else:
            self._blind_travel_world = blind_travel_step(
                self._blind_travel_world,
                v,
                self._own_pose[:, 2],
                cfg.dt_s,
                self.controller_params.blind_travel_memory_s,
            )
