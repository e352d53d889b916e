"""Per-robot FoV-CBF controller: rows (Eq. 12, 17), pruning, hierarchy (Eq. 18-19).

One :class:`FovCbfController` per robot, built once and called every step::

    controller = FovCbfController(config, params)
    res = controller.solve(u_star, p_body, v_est_body, d, ids)
    res.u          # (3,) body-frame velocity [vx m/s, vy m/s, ω rad/s]

Inputs and outputs are body-frame *velocities* (not the env's normalised actions);
convert with :func:`fov_marl.spaces.velocity_to_action` (and
:func:`fov_marl.spaces.action_to_velocity` for a policy's action used as u*).

Pipeline of :meth:`FovCbfController.solve`
==========================================

0. "Look where you go" (``params.motion_cone``, not in the paper; only with
   neighbours, M > 0): when u*'s translation points outside the full-speed cone, u*'s
   yaw rate is replaced by ``look_gain`` times the bearing of that translation
   (:meth:`FovCbfController.look_where_you_go`; the cone itself is a level, step 3).
1. Rows ``A u + drift + α(h + ε) ≥ 0`` for every neighbour (:func:`~fov_marl.control.cbf.cbf_rows`);
   FoV rows of a neighbour out of view recover by turning only
   (``params.fov_recovery_cap``, see :mod:`~fov_marl.control.cbf`).
2. Normalise each row by its input authority and prune the rows that hold for every
   admissible input (``b̃ ≥ 1``, the closed form ``drift + α(h + ε) − ‖A_v‖ v_max −
   |A_ω| ω_max ≥ 0``; exact, see :func:`~fov_marl.control.cbf.row_authority`).
3. Priority levels (Eq. 18): neighbours sorted by ascending d_ij (ties: ascending
   distance to the mean ‖ⁱp_j‖, then id: several far-reaching ellipses all give
   d = 0, and the nearest of those neighbours is the one to look at), with
   hysteresis: the neighbour that led the FoV levels at the previous step ranks with
   d − ``params.priority_hysteresis_m`` (the pipeline passes it as ``priority_bonus``).
   By d alone, two unseen neighbours on opposite sides with d within the estimates'
   noise of each other swapped level 1 from step to step, and the robot turned
   ±0.8 ω_max on alternate steps (measured: settled pfcbf team, N = 6, β = 120°).
   With ``params.safety_first`` (default) level 0 holds the safety rows of *every*
   neighbour, so avoiding a collision with any neighbour outranks keeping the nearest
   one in view; level 1, 2, … hold the FoV rows (left, right, range) of the
   neighbours with a possibly active FoV row, one neighbour per level. With
   ``safety_first=False`` level k holds all four rows of the k-th neighbour (the
   paper). Only neighbours with a possibly active row get a level, and at most
   ``params.max_levels`` FoV levels exist: neighbours beyond the first
   ``max_levels − 1`` share the last one (their rows trade off in one ‖κ‖²). The FoV
   rows of neighbours ranked beyond ``params.max_fov_neighbours`` (default 8) are left
   out altogether (their safety rows stay): a robot cannot keep more neighbours in
   view, and it bounds the size of the last level's QP in dense teams.
   ``params.safety_hard`` puts the safety rows in a hard level (no κ).
   With ``params.motion_cone`` the rows of
   :func:`~fov_marl.control.cbf.motion_cone_rows` form their own level right below
   the safety rows (above every FoV level; the lowest level when ``safety_first`` is
   False and safety is soft): a robot moves faster than ``blind_speed_mps`` only
   where its camera looks, unless avoiding a collision needs it.
   The collision rows of :mod:`~fov_marl.control.safety` (``safety=``, or built from
   ``p_body`` taken as exact when not given) join the safety level; with
   ``params.safety_model == "ellipse"`` (default) they replace Eq. 12 row 3.
4. :class:`~fov_marl.control.qp.HierarchicalQP` (cascade whose last candidate is the
   Eq. 19 solution; fallbacks), in the metric ``‖Δv‖² + λ² Δω²``
   (``params.omega_weight``). If the collision rows cannot be met: the safe fallback;
   if they block u* (a symmetric encounter): "keep right" (``deadlock_turn_deg``).
   The cascade accepts the collision rows within a tolerance (κ* ≤ 1e-3); an output
   that creeps towards a row that holds or retreats within it is corrected to the
   nearest input that does not (:func:`hold_cleanup`; the safe fallback when none
   qualifies), and its yaw rate is limited so the step's arc approaches no held line
   either (``params.arc_yaw_guard``, :mod:`~fov_marl.control.safety` Section 1c).

The cost per robot is bounded independently of N: row assembly is vectorised over
neighbours (a few µs per op whatever M), and at most ``2 (max_levels + 1)`` small QPs
are solved (1-2 per level that the previous candidate violates, none when u*
already satisfies every row; 0.7-3.2 per step on average in
:func:`~fov_marl.control.benchmark.bench_control` for N = 6-48).

Fallbacks never raise: non-finite inputs → ``u = 0`` (``"invalid_input"``); a hard
level that cannot be met → ``u = 0`` (``"qp_failed"``); a solver failure on a soft
level → the best candidate so far (``"degraded"``). ``stats`` counts them.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fov_marl.config import ScenarioConfig
from fov_marl.control.cbf import (
    SAFETY_ROW,
    cbf_rows,
    motion_cone_rows,
    normalise_rows,
    row_h_max,
)
from fov_marl.control.coverage import check_lloyd_stencil
from fov_marl.control.params import STALL_FRACTION, TRANSLATES_FRACTION, ControllerParams
from fov_marl.control.qp import HierarchicalQP
from fov_marl.control.safety import (
    ROW_CONE,
    ROW_NEIGHBOUR,
    ROW_WALL,
    arc_yaw_guard,
    invalid_rows,
    safety_triple,
    team_safety_rows,
)
from fov_marl.validation import check_params, describe

__all__ = [
    "ControlResult",
    "FovCbfController",
    "approaches_held_row",
    "hold_cleanup",
    "escape_heading",
    "escape_translation",
    "safe_fallback_inputs",
]

_FOV_ROWS = np.array([True, True, False, True])
#: κ* (normalised) above which the collision rows count as not met: the safe fallback
_KAPPA_SAFETY = 1e-3
#: a hold-or-retreat collision row (b̃ ≤ 0) counts as approached below ``Ã u < −this``
#: (normalised): the safe fallback, whatever κ* (see :func:`approaches_held_row`)
APPROACH_TOL = 1e-9
#: margin ((m/s)², QP metric) by which the bound of a lost-row re-solve must exceed half
#: the current cost to skip it: the re-solve's fixed rows are relaxed by the backend's
#: fixing tolerance, which can bring it closer to u* than the bound (measured with nnls,
#: 3,000 random hierarchies: at most 1.1e-4; ``tests/control/test_qp.py``)
_YIELD_BOUND_TOL = 1e-3


def approaches_held_row(
    u: np.ndarray, A: np.ndarray, b: np.ndarray, keep: np.ndarray
) -> np.ndarray:
    """``(F,)`` bool: the input moves towards a collision row that holds or retreats.

    A row with ``b̃ ≤ 0`` is met only by an input with ``Ã u ≥ −b̃ ≥ 0``, i.e. one that
    does not approach along its direction. The cascade accepts the collision rows with
    a violation up to ``_KAPPA_SAFETY`` (its regulariser biases an infeasible level's κ by
    O(ρ)), and the unconstrained shortcut up to ``tol_check``: on a held row that is a
    creep towards the neighbour. Measured (stress, ``wait_charge``, N = 4, β = 120°, wall
    start, seed 1101): a robot backed at 0.6 mm/s into an unseen neighbour 1.1 m behind it
    (status "solved", κ* 6e-4) and the pair closed to 1.099874 m. Such inputs go to the
    nearest input that does not (:func:`hold_cleanup`), else to the safe fallback.

    Args:
        u: ``(F, 3)``; A, b, keep: ``(F, K, 3)``, ``(F, K)``, ``(F, K)`` normalised rows.
    """
    val = np.einsum("rkn,rn->rk", A, u)
    return (keep & (b <= 0.0) & (val < -APPROACH_TOL)).any(axis=1)


def hold_cleanup(
    u: np.ndarray, A: np.ndarray, b: np.ndarray, v_max: float, n_polygon: int
) -> np.ndarray | None:
    """The input nearest ``u`` that approaches no held row and makes no row worse.

    Projects the translation of ``u`` (ω kept) onto ``{Ã v ≥ lo} ∩ polygon`` with
    ``lo = min(−b̃, Ã u)`` per row (no row worse than at ``u``, met rows stay met) and
    ``lo ≥ 0`` on the rows with ``b̃ ≤ 0`` (no approach), by one least-distance program
    (:func:`~fov_marl.control.qp.least_distance`). The creeps of
    :func:`approaches_held_row` are tiny (κ* ≤ 1e-3), so the input hardly changes, and
    the FoV levels keep what they had; sending them to the safe fallback instead stopped
    and turned settled robots (pfcbf, N = 6, β = 120°, seed 0: 400 fallbacks in 2,400
    robot-steps against 36).

    Args:
        u: ``(3,)`` input; A, b: ``(K, 3)``, ``(K,)`` normalised collision rows (ω
            column 0). v_max, n_polygon: the admissible polygon (:mod:`~fov_marl.control.qp`).

    Returns:
        ``(3,)`` the corrected input, or None when no translation qualifies.
    """
    from fov_marl.control.qp import least_distance, polygon_normals

    v = u[:2]
    Av = A[:, :2]
    val = Av @ v
    lo = np.minimum(-b, val)
    lo = np.where(b <= 0.0, np.maximum(lo, 0.0), lo)
    nrm = polygon_normals(n_polygon)
    apothem = v_max * math.cos(math.pi / n_polygon)
    G = np.concatenate([Av, -nrm])
    h = np.concatenate([lo - val, -apothem + nrm @ v])
    y = least_distance(G, h)
    if y is None:
        return None
    out = np.array([v[0] + y[0], v[1] + y[1], u[2]])
    if ((Av @ out[:2]) - lo).min() < -1e-12 or (nrm @ out[:2]).max() > apothem + 1e-12:
        return None
    return out


#: directions (evenly spaced) the escaping fallback tries as its turn target
_ESCAPE_DIRECTIONS = 72
#: the escaping fallback keeps a translation of at least this fraction of v_max
_ESCAPE_MIN_FRACTION = 1e-3
#: the escape leaves a neighbour inside D_s at least this much (degrees) off "across its
#: line of sight" (:func:`escape_translation`)
_ESCAPE_BEARING_MARGIN_DEG = 10.0


def escape_translation(
    v: np.ndarray,
    A: np.ndarray,
    b: np.ndarray,
    v_max: float,
    n_polygon: int,
    widen: np.ndarray | None = None,
) -> np.ndarray:
    """The translation nearest ``v`` that makes no collision row worse than standing still.

    Projects ``v`` onto ``{w : Ã w ≥ min(−b̃, 0)} ∩ polygon`` (the rows that hold at
    standstill stay met, those that do not are not approached) by one least-distance
    program (:func:`~fov_marl.control.qp.least_distance`). ``w = 0`` is always in the
    set and is returned where the program fails numerically (a set with no interior,
    e.g. one ray between a widened row and another held row).

    The rows flagged in ``widen`` that hold or demand retreat (``b̃ ≤ 0``: a neighbour
    or its bearing cone, inside D_s) are replaced by their two copies turned by
    ±``_ESCAPE_BEARING_MARGIN_DEG``: the step must leave such a neighbour by at least that
    angle more than "not towards it". Without the margin the projection lands on the
    row's line, a step exactly across the *estimated* line of sight, and a bearing
    estimate a little off the truth turns it into an approach: measured, robots packed
    1.1 m apart along a wall (``wait_charge``, N = 4, β = 360°, seed 91000), the escape
    stepped at 0.17 m/s across a line of sight 2.6° off (its cone said 1.6°) and the
    pair closed from 1.1 m to 1.09992 m.

    Args:
        v: ``(2,)`` the translation to keep as much of as possible (m/s).
        A, b: ``(K, 3)``, ``(K,)`` normalised collision rows (their ω column unused).
        v_max, n_polygon: the admissible polygon (:mod:`~fov_marl.control.qp`).
        widen: ``(K,)`` bool, the rows to widen (None: none).

    Returns:
        ``(2,)`` the translation.
    """
    from fov_marl.control.qp import least_distance, polygon_normals

    Av = A[:, :2]
    lo = np.minimum(-b, 0.0)
    if widen is not None:
        turn = np.asarray(widen, dtype=bool) & (b <= 0.0)
        if turn.any():
            t = math.radians(_ESCAPE_BEARING_MARGIN_DEG)
            c, s_ = math.cos(t), math.sin(t)
            a = Av[turn]
            plus = np.stack([c * a[:, 0] - s_ * a[:, 1], s_ * a[:, 0] + c * a[:, 1]], -1)
            minus = np.stack([c * a[:, 0] + s_ * a[:, 1], -s_ * a[:, 0] + c * a[:, 1]], -1)
            Av = np.concatenate([Av[~turn], plus, minus])
            lo = np.concatenate([lo[~turn], np.zeros(2 * int(turn.sum()))])
    nrm = polygon_normals(n_polygon)
    apothem = v_max * math.cos(math.pi / n_polygon)
    G = np.concatenate([Av, -nrm])
    h = np.concatenate([lo - Av @ v, -apothem + nrm @ v])
    y = least_distance(G, h)
    if y is None:  # numerically inconsistent: the set has no interior near v
        return np.zeros(2)
    w = v + y
    if (Av @ w - lo).min(initial=0.0) < -1e-12 or (nrm @ w).max() > apothem + 1e-12:
        return np.zeros(2)
    return w


def escape_heading(
    v: np.ndarray, A: np.ndarray, b: np.ndarray, kind: np.ndarray, keep: np.ndarray
) -> np.ndarray:
    """``(F,)`` bearing (rad, Σ_i) of the escape direction nearest ``v``, NaN for none.

    A direction qualifies when the rows the camera cannot clear (neighbour, cone and
    wall rows) let a step along it be no worse than standing still
    (``Ã d ≥ min(−b̃, 0)``); the blind rows (particles, density, last-seen points,
    travel budget) are not asked: they lapse for the bearings the camera looks at.
    ``v`` of zero length aims at the camera's axis.

    Args:
        v: ``(F, 2)`` the wanted translations. A, b, kind, keep: ``(F, K, 3)``,
            ``(F, K)``, ``(F, K)``, ``(F, K)`` the normalised collision rows.
    """
    ang = np.linspace(-math.pi, math.pi, _ESCAPE_DIRECTIONS, endpoint=False)
    d = np.stack([np.cos(ang), np.sin(ang)], axis=-1)  # (D, 2)
    hard = keep & ((kind == ROW_NEIGHBOUR) | (kind == ROW_CONE) | (kind == ROW_WALL))
    lo = np.where(hard, np.minimum(-b, 0.0), -np.inf)  # (F, K)
    val = np.einsum("dn,fkn->fdk", d, A[..., :2])  # direction·row at unit speed
    # homogeneous in the step's length where lo = 0; the rows met at rest (lo < 0) are
    # asked at 10% of unit speed, the first step's scale
    ok = (np.where(hard[:, None, :], 0.1 * val, np.inf) >= lo[:, None, :] - 1e-12).all(axis=2)
    target = np.where(np.hypot(v[:, 0], v[:, 1]) > 0.0, np.arctan2(v[:, 1], v[:, 0]), 0.0)
    off = np.abs(np.angle(np.exp(1j * (ang[None, :] - target[:, None]))))
    best = np.argmin(np.where(ok, off, np.inf), axis=1)
    return np.where(ok.any(axis=1), ang[best], np.nan)


def safe_fallback_inputs(
    u_qp: np.ndarray,
    A: np.ndarray,
    b: np.ndarray,
    kind: np.ndarray,
    keep: np.ndarray,
    look_gain: float,
    omega_max_radps: float,
    tie_mps: float = 0.25,
    straight: bool = True,
    escape: bool = False,
    v_max_mps: float = 1.0,
    n_polygon: int = 16,
    u_star: np.ndarray | None = None,
) -> np.ndarray:
    """The safe fallback of :meth:`FovCbfController._safe_fallback` for ``F`` robots.

    Args:
        u_qp: ``(F, 3)`` the QPs' least-violation inputs (a NaN row: none).
        A, b, kind: ``(F, K, 3)``, ``(F, K)``, ``(F, K)`` the normalised collision rows.
        keep: ``(F, K)`` bool, the rows that exist (False: padding).
        look_gain: the turn gain (≤ 0: 3). omega_max_radps: the yaw-rate bound.
        tie_mps: rows within this of the smallest ``b̃`` tie as the turn target
            (``ControllerParams.fallback_tie_mps``); straight: drop ω of a kept step
            while a row holds or retreats (``fallback_straight``).
        escape: ``ControllerParams.fallback_escape``: where ``u_qp`` makes a row
            worse, the wanted input (``u_star``, else ``u_qp``) is projected
            (:func:`escape_translation`) instead of dropped, and a robot left without
            translation turns towards the escape direction nearest the wanted one
            (:func:`escape_heading`) instead of the most dangerous row.
        v_max_mps, n_polygon: the admissible polygon (with ``escape``).
        u_star: ``(F, 3)`` the desired inputs the controller was given (after its look
            where you go), or None: the escape aims at them, the least change to what
            was asked that no collision row forbids (measured: aiming at ``u_qp``, the
            hierarchy's compromise, robots packed along a wall and rushing to one
            point turned away from where they were sent, step after step).

    Returns:
        ``(F, 3)`` body-frame inputs ``[vx, vy, ω]``.
    """
    tol = APPROACH_TOL
    has = np.isfinite(u_qp).all(axis=1)
    uq = np.where(has[:, None], u_qp, 0.0)
    val = np.einsum("rkn,rn->rk", A, uq) + b
    okm = np.where(keep, val >= np.minimum(b, 0.0) - tol, True).all(axis=1) & has
    out = np.zeros((u_qp.shape[0], 3))
    out[okm] = uq[okm]
    moved = okm.copy()
    if escape:
        want = uq if u_star is None else np.where(np.isfinite(u_star), u_star, 0.0)
        for f in np.flatnonzero(~okm):  # rare: robot by robot, as hold_cleanup
            k = keep[f]
            near = (kind[f, k] == ROW_NEIGHBOUR) | (kind[f, k] == ROW_CONE)
            w = escape_translation(want[f, :2], A[f, k], b[f, k], v_max_mps, n_polygon, near)
            if math.hypot(w[0], w[1]) > _ESCAPE_MIN_FRACTION * v_max_mps:
                out[f, :2], out[f, 2] = w, want[f, 2]
                moved[f] = True
    if straight:  # a held or retreating row: a straight step, no arc
        out[moved & (keep & (b <= tol)).any(axis=1), 2] = 0.0
    nw = keep & (kind != ROW_WALL) & (kind != ROW_CONE)
    anyw = nw.any(axis=1) & ~moved
    gain = look_gain if look_gain > 0 else 3.0
    if escape and (~moved).any():
        stuck = np.flatnonzero(~moved)
        phi = escape_heading(want[stuck, :2], A[stuck], b[stuck], kind[stuck], keep[stuck])
        found = np.isfinite(phi)
        out[stuck[found], 2] = np.clip(gain * phi[found], -omega_max_radps, omega_max_radps)
        anyw[stuck[found]] = False
    if anyw.any():
        bb = np.where(nw, b, np.inf)
        phi = np.arctan2(-A[..., 1], -A[..., 0])
        near = nw & (bb <= bb.min(axis=1, keepdims=True) + tie_mps)
        k = np.argmin(np.where(near, np.abs(phi), np.inf), axis=1)
        om = np.clip(gain * phi[np.arange(u_qp.shape[0]), k], -omega_max_radps, omega_max_radps)
        out[anyw, 2] = om[anyw]
    return out


@dataclass
class ControlResult:
    """Outcome of one :meth:`FovCbfController.solve` call.

    Attributes:
        u: ``(3,)`` applied body-frame velocity ``[vx m/s, vy m/s, ω rad/s]``, always
            finite with ``‖(vx, vy)‖ ≤ v_max`` and ``|ω| ≤ ω_max``.
        u_star: ``(3,)`` the desired input as given (before the look-where-you-go
            yaw rate of step 0).
        status: ``"unconstrained"`` (u* projected on the admissible set satisfies every
            row, no QP), ``"solved"`` (all rows hold), ``"relaxed"`` (the hierarchy had
            to violate some rows, κ* > 1e-3), ``"degraded"`` (a QP failed; u is the
            best candidate found), ``"invalid_input"`` (non-finite input, u = 0),
            ``"qp_failed"`` (a hard level is infeasible, u = 0; only with the paper's
            ``safety_model="mean"``) or ``"safety_fallback"`` (the collision rows of
            :mod:`~fov_marl.control.safety` cannot all be met: the safe fallback of
            :meth:`FovCbfController._safe_fallback`); see
            :class:`~fov_marl.control.qp.QPResult`.
        fallback: True when ``u`` is a fallback input (the last three statuses).
        intervened: ``‖u − proj(u*)‖ > params.intervention_tol``, with proj the
            projection onto the admissible set (the polygon shrink alone is not an
            intervention).
        kappa: ``(M, 4)`` minimised violations κ* per neighbour and row, as a fraction
            of the row's input authority (0 for rows that hold or were pruned).
        active: ``(M, 4)`` rows that entered the QP (not pruned or left out).
        level: ``(M, 4)`` priority level of each active row (−1 hard, −2 pruned), as
            solved (with the motion cone, FoV levels are shifted below its level).
        n_levels: number of priority levels among the active rows.
        n_qp: QPs solved this step (backend ``params.qp_backend``).
        qp_status: the backend's status string of the last QP ("" if none).
        safety_violation: max κ* over the safety rows (0 when collision avoidance holds).
        cone_violation: max κ* over the motion-cone rows (0 when the robot moves
            faster than ``blind_speed_mps`` only inside the cone, or without the cone).
        yielded: the FoV rows of lost neighbours yielded this step
            (:meth:`FovCbfController._yield_lost`); the pipeline passes it back as the
            next step's ``yield_latched``.
        unblocked: "keep right" was adopted this step (:meth:`FovCbfController._unblock`);
            the pipeline passes it back as the next step's ``unblock_latched``.
        timings: seconds spent in ``rows`` (assembly, pruning, levels), ``cascade``,
            ``final`` (only after a failed level), ``total``.
    """

    u: np.ndarray
    u_star: np.ndarray
    status: str
    fallback: bool
    intervened: bool
    kappa: np.ndarray
    active: np.ndarray
    level: np.ndarray
    n_levels: int = 0
    n_qp: int = 0
    qp_status: str = ""
    safety_violation: float = 0.0
    cone_violation: float = 0.0
    yielded: bool = False
    unblocked: bool = False
    timings: dict = field(default_factory=dict)


class FovCbfController:
    """The paper's controller for one robot (Section VI), built once, called per step.

    Args:
        config: scenario (β, D_s, R_d, v_max, ω_max, arena size are used).
        params: controller knobs (defaults: :class:`ControllerParams`).

    Attributes:
        h_max: ``(4,)`` per-row saturation of the slack (:func:`~fov_marl.control.cbf.row_h_max`).
        stats: counters since construction: ``steps``, ``fallbacks``, ``qp_solves``,
            ``interventions``, ``relaxed`` (for ``infos``).
        qp: the robot's :class:`~fov_marl.control.qp.HierarchicalQP`.
    """

    def __init__(
        self, config: ScenarioConfig, params: ControllerParams | dict | None = None
    ) -> None:
        if not isinstance(config, ScenarioConfig):
            raise ValueError(
                f"config must be a ScenarioConfig (fov_marl.config.make_config), got "
                f"{describe(config)}"
            )
        self.config = config
        self.params = check_params("params", params, ControllerParams)
        if config.scenario == "coverage":
            check_lloyd_stencil(config, self.params)  # fail at construction, not mid-episode
        self.h_max = row_h_max(config, self.params.fov_margin_m)
        p = self.params
        # motion cone rows normalised like the CBF rows (authority ‖G_v‖ v_max = v_max)
        G, h = motion_cone_rows(
            config.fov_rad,
            p.blind_speed_mps,
            config.v_max_mps,
            math.radians(p.cone_half_angle_deg),
        )
        self._cone_A = G / config.v_max_mps if p.motion_cone else np.zeros((0, 3))
        self._cone_b = -h / config.v_max_mps if p.motion_cone else np.zeros(0)
        self._cone_half_angle = (
            min(0.5 * config.fov_rad, math.radians(p.cone_half_angle_deg))
            if self._cone_b.shape[0]
            else math.pi
        )
        self._w = float(p.omega_weight)
        self.qp = HierarchicalQP(
            config.v_max_mps,
            config.omega_max_radps * self._w,
            n_polygon=p.n_polygon,
            backend=p.qp_backend,
            capacity=32,
            eps=p.qp_eps,
            max_iter=p.qp_max_iter,
            reg=p.cascade_reg,
        )
        self.stats = {
            "steps": 0,
            "fallbacks": 0,
            "safety_fallbacks": 0,
            "qp_solves": 0,
            "interventions": 0,
            "relaxed": 0,
        }

    def assign_levels(
        self,
        active: np.ndarray,
        d: np.ndarray,
        ids: np.ndarray,
        r: np.ndarray | None = None,
        bonus: np.ndarray | None = None,
    ) -> np.ndarray:
        """Priority level of every row (Eq. 18), see the module docstring.

        Neighbours are ranked by ``d − bonus``: the pipeline gives the neighbour that
        led the FoV levels at the previous step a head start of
        ``params.priority_hysteresis_m`` (Eq. 18 orders by d_ij alone, which the
        estimates' noise reorders from step to step when two d_ij are close, and each
        reordering reverses the turn the FoV levels ask for).

        Args:
            active: ``(M, 4)`` rows that enter the QP.
            d: ``(M,)`` ellipse distances; ids: ``(M,)`` last tie-breakers.
            r: ``(M,)`` distances to the means, first tie-breakers (None: ids only).
            bonus: ``(M,)`` head start in d (m) or None (none).

        Returns:
            ``(M, 4)`` int levels: −2 for rows left out (pruned, or FoV rows of the
            neighbours beyond ``params.max_fov_neighbours``), −1 hard, 0 safety (with
            ``safety_first``), 1.. FoV levels.
        """
        p = self.params
        M = d.shape[0]
        level = np.full((M, 4), -2, dtype=np.int64)
        if M == 0:
            return level
        key = d if bonus is None else d - bonus
        order = np.lexsort((ids, key)) if r is None else np.lexsort((ids, r, key))
        per_nb_rows = _FOV_ROWS if p.safety_first else np.ones(4, dtype=bool)
        cand = np.any(active & per_nb_rows, axis=1)[order]
        rank = np.cumsum(cand) - 1
        nb_level = np.empty(M, dtype=np.int64)
        nb_level[order] = 1 + np.minimum(rank, p.max_levels - 1)
        level[:, :] = nb_level[:, None]
        beyond = np.empty(M, dtype=bool)
        beyond[order] = rank >= p.max_fov_neighbours
        level[beyond[:, None] & _FOV_ROWS[None, :]] = -2  # their safety rows stay
        if p.safety_hard:
            level[:, SAFETY_ROW] = -1
        elif p.safety_first:
            level[:, SAFETY_ROW] = 0
        level[~active] = -2
        return level

    def look_where_you_go(self, u_star: np.ndarray) -> np.ndarray:
        """Step 0 of :meth:`solve`: turn the camera towards a desired translation it cannot see.

        When ``‖v*‖ > blind_speed_mps`` and the bearing ``φ = atan2(v*_y, v*_x)`` lies
        outside the full-speed cone (``|φ| > a``, see
        :func:`~fov_marl.control.cbf.motion_cone_rows`), the desired yaw rate becomes
        ``sat_{ω_max}(look_gain · φ)``; otherwise u* is returned unchanged. The motion
        cone only lets the robot go where it looks; this makes it look where it wants
        to go (with ω* = 0, e.g. from a policy that never turns, a robot could
        otherwise only creep at ``blind_speed_mps`` towards a goal behind it).

        Args:
            u_star: ``(3,)`` finite desired input.

        Returns:
            ``(3,)`` desired input (a new array when changed).
        """
        p, cfg = self.params, self.config
        if math.hypot(u_star[0], u_star[1]) <= p.blind_speed_mps:
            return u_star
        phi = math.atan2(u_star[1], u_star[0])
        if abs(phi) <= self._cone_half_angle:
            return u_star
        out = np.array(u_star, dtype=np.float64)
        out[2] = min(max(p.look_gain * phi, -cfg.omega_max_radps), cfg.omega_max_radps)
        return out

    def _safety_rows(
        self,
        safety: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
        p_body: np.ndarray,
        v_est_body: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Normalised, pruned collision rows ``(Ã (K, 3), b̃ (K,), kind (K,))`` (maybe K = 0).

        ``safety``: the rows as :meth:`_parse_safety` returns them, or None. Without
        them (a controller used on its own) the neighbour rows of
        :func:`~fov_marl.control.safety.safety_rows` are built from ``p_body`` taken as
        exact positions (σ = 0), so collision avoidance never silently disappears.
        """
        p, cfg = self.params, self.config
        if p.safety_model != "ellipse" or (safety is None and p_body.shape[0] == 0):
            return np.zeros((0, 3)), np.zeros(0), np.zeros(0, dtype=np.int8)
        if safety is None:  # positions taken as exact: the neighbour rows alone
            rows = team_safety_rows(
                cfg,
                p,
                mean_body=p_body[None],
                cov_body=np.zeros((1, p_body.shape[0], 2, 2)),
                detected=np.ones((1, p_body.shape[0]), dtype=bool),
                velocity_est_body=v_est_body[None],
                blind=False,
            )
            safety = self._parse_safety(rows.robot(0))
        A, b, kind = safety
        At, bt, _ = normalise_rows(A, b, cfg.v_max_mps, cfg.omega_max_radps, p.row_clip)
        keep = bt < 1.0 if p.prune else np.isfinite(b)
        return At[keep], bt[keep], kind[keep]

    @staticmethod
    def _parse_safety(safety: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``safety`` as ``(A (K, 3) float, b (K,) float, kind (K,))``, else ``ValueError``."""
        A0, b0, kind0 = safety_triple(safety)
        try:
            A = A0.astype(np.float64).reshape(-1, 3)
            b = b0.astype(np.float64).reshape(-1)
        except (TypeError, ValueError):
            A = b = np.zeros(0)  # reported below with the shapes given
        kind = kind0.reshape(-1)
        if A.ndim != 2 or A.shape[0] != b.shape[0] or kind.shape[0] != b.shape[0]:
            raise ValueError(
                f"safety rows must be A (K, 3), b (K,), kind (K,) real arrays; got "
                f"{A0.shape}, {b0.shape}, {kind0.shape}"
            )
        return A, b, kind

    def _project(self, u: np.ndarray) -> np.ndarray:
        """Projection onto the admissible set (polygon × ω box; separable, so the ω weight
        of :meth:`_qp_solve` does not change it)."""
        w = self._w
        out = self.qp.project(np.array([u[0], u[1], u[2] * w]))
        out[2] /= w
        return out

    def _qp_solve(self, A: np.ndarray, b: np.ndarray, level: np.ndarray, u_star: np.ndarray):
        """The hierarchy in the weighted metric ``‖Δv‖² + λ² Δω²`` (λ = ``omega_weight``).

        Solved in the variable ``[vx, vy, λω]``: the ω column of the rows is divided by
        λ and the ω bound multiplied by it, so row authorities (and every normalised
        offset b̃ and κ) are unchanged; the solution is mapped back.
        """
        w = self._w
        if w == 1.0:
            return self.qp.solve(A, b, level, u_star)
        A_w = np.array(A, dtype=np.float64, copy=True)
        A_w[:, 2] /= w
        res = self.qp.solve(A_w, b, level, np.array([u_star[0], u_star[1], u_star[2] * w]))
        u = np.array(res.u, dtype=np.float64, copy=True)
        u[2] /= w
        res.u = u
        return res

    def _translates(self, u_star: np.ndarray) -> bool:
        """u* translates: ``‖v*‖ ≥ 0.1 v_max`` (``TRANSLATES_FRACTION``)."""
        return math.hypot(u_star[0], u_star[1]) >= TRANSLATES_FRACTION * self.config.v_max_mps

    def _stalled(self, u: np.ndarray, u_star: np.ndarray, fraction: float = STALL_FRACTION) -> bool:
        """The solution keeps less than ``fraction`` (a fifth) of u*'s translation
        (``u_v · v̂* < 0.2 ‖v*‖``) while u* translates: the trigger of :meth:`_unblock` and
        :meth:`_yield_lost`."""
        vs = u_star[:2]
        speed = math.hypot(vs[0], vs[1])
        return (
            speed >= TRANSLATES_FRACTION * self.config.v_max_mps
            and u[:2] @ vs < fraction * speed * speed
        )

    def _unblock(self, qres, A_q, b_q, l_q, u_star: np.ndarray, n_fov: int, latched=False):
        """Deadlock resolution ("keep right", not in the paper): ``params.deadlock_turn_deg``.

        Symmetric encounters (four robots crossing at one point, VII-D) stop every robot
        at its neighbours' barriers: each projection of u* onto the collision rows is
        ~0. When a collision row binds and the solution keeps less than a fifth of u*'s
        progress (``u_v · v̂* < 0.2 ‖v*‖``), the hierarchy is solved again for u* with
        its translation turned by ``−deadlock_turn_deg`` (to the right) and that
        solution is used if it progresses more along the turned direction. All robots
        turning the same way circulate around each other like a roundabout. Only u* is
        changed: every row still holds (the result is a solution of the same hierarchy).

        Hysteresis (``latched``: the robot kept right at the previous step): it keeps
        right while the solution for u* keeps less than ``params.deadlock_release`` (0.5)
        of u*'s progress, not 0.2. Without it a robot whose u* was small and whose
        solution kept about a fifth of it kept right on alternate steps, the turned u*
        flipping the sign of vx each time (traced: pfcbf, N = 6, β = 120°, seed 5, robot
        0, steps 758-764; over seeds 0-9, steps 200-1000, 34 of 81 period-2 flips came
        with keep-right adopted on alternate steps).
        """
        vs = u_star[:2]
        fraction = self.params.deadlock_release if latched else STALL_FRACTION
        if qres.fallback or not self._stalled(qres.u, u_star, fraction):
            return qres
        binding = (A_q[n_fov:] @ qres.u + b_q[n_fov:]) < 1e-3
        if not binding.any():
            return qres
        a = -math.radians(self.params.deadlock_turn_deg)
        c, s_ = math.cos(a), math.sin(a)
        u_turn = np.array([c * vs[0] - s_ * vs[1], s_ * vs[0] + c * vs[1], u_star[2]])
        alt = self._qp_solve(A_q, b_q, l_q, u_turn)
        if alt.fallback or alt.u[:2] @ u_turn[:2] <= qres.u[:2] @ u_turn[:2] + 1e-9:
            return qres
        return alt

    def _yield_lost(
        self,
        qres,
        A_q,
        b_q,
        l_q,
        u_star: np.ndarray,
        lost: np.ndarray,
        latched: bool = False,
        base=None,
    ):
        """Lost neighbours' FoV levels yield when they stall the robot (``params.lost_fov_yield``).

        Not in the paper. A neighbour the camera does not report keeps its FoV rows
        (Eq. 17, in recovery by turning, see :mod:`~fov_marl.control.cbf`), built on a
        belief that spreads while it is unseen. Several such neighbours around a robot
        can pin its yaw rate to ~0 while the collision rows forbid the blind
        translation u* asks for: the robot then stands still for good (crossing seed 7:
        7 m from its target, three neighbours lost 25-50 s before). When the solution
        keeps less than a fifth of u*'s translation (``u_v · v̂* < 0.2 ‖v*‖``, with
        ``‖v*‖ ≥ 0.1 v_max``; never for a fallback), the hierarchy is solved again
        without the FoV rows of the undetected neighbours (``lost``, rows of the QP), and
        that solution is used if its QP cost ``‖Δv‖² + λ² Δω²`` to u* is at most half the
        first one's. Only FoV rows are dropped: the collision rows (safety level) and the
        FoV rows of the neighbours in view are the same, so the robot is exactly as safe.

        The latch (``latched``: these rows yielded at the previous step and
        ``params.lost_fov_yield_latch``) replaces the stall test by ``‖v*‖ ≥ 0.1 v_max``.
        Without it a robot pinned by its blind rows yielded, turned towards u*, found a
        free direction, was no longer stalled, so the lost rows turned it back at ω_max,
        which pinned it again: ω flipped sign every step (settled pfcbf team, N = 6,
        β = 120°, seed 3, steps 931-941). The cost test still decides, so the latch ends
        when the rows stop costing twice the yield, when u* stops translating (the
        robot has arrived) or when no neighbour is lost.

        ``base`` (the hierarchy solved for u*, when ``qres`` is :meth:`_unblock`'s) bounds
        the re-solve from below: it keeps every level above the first lost row's, so its
        input is no closer to u* than the candidate the cascade reached that level with
        (``QPResult.level_start_cost``); when that bound exceeds half the current cost
        the re-solve is skipped (same result, fewer QPs: measured, pfcbf N = 48 in the
        40 m arena, 80% of the re-solves were not adopted). Only with the exact
        ``"nnls"`` backend: OSQP's tolerances make the bound approximate.

        Returns:
            the QP result to use (κ of the dropped rows is 0): ``qres`` itself unless
            the rows yielded.
        """
        if not lost.any() or qres.fallback:
            return qres
        if latched and self.params.lost_fov_yield_latch:
            trigger = self._translates(u_star)
        else:
            trigger = self._stalled(qres.u, u_star)
        if not trigger:
            return qres
        wt = np.array([1.0, 1.0, self._w * self._w])
        cost_cur = float(((qres.u - u_star) ** 2) @ wt)
        base = qres if base is None else base
        k = int(np.searchsorted(base.level_values, l_q[lost].min()))
        if self.params.qp_backend == "nnls" and k < base.level_start_cost.size:
            bound = base.level_start_cost[k]
            if bound - 0.5 * cost_cur > _YIELD_BOUND_TOL:  # NaN (degraded): no skip
                return qres
        keep = ~lost
        alt = self._qp_solve(A_q[keep], b_q[keep], l_q[keep], u_star)
        if alt.fallback:
            return qres
        cost_alt = float(((alt.u - u_star) ** 2) @ wt)
        if cost_alt > 0.5 * cost_cur:
            return qres
        kappa = np.zeros(b_q.shape[0])
        kappa[keep] = alt.kappa
        alt.kappa = kappa
        alt.n_qp += qres.n_qp
        return alt

    def _safe_fallback(
        self,
        u_qp: np.ndarray | None,
        A: np.ndarray,
        b: np.ndarray,
        kind: np.ndarray,
        u_star: np.ndarray | None = None,
    ) -> np.ndarray:
        """The collision rows cannot all be met: the documented safe fallback.

        The QP's least-violation input ``u_qp`` (None when the rows were hard and the
        QP had no solution) is kept if it makes no collision row worse than
        standing still does (``Ã u + b̃ ≥ min(b̃, 0)`` row by row: it retreats as well as
        it can without closing on anything else); while a row holds or retreats
        (``b̃ ≤ 0``) its yaw rate is dropped, so that the step is the straight one the rows
        were checked on (measured: robots packed 1.1 m apart along a wall, one escaping
        across its neighbour's line of sight at 0.98 m/s while turning at ω_max curved
        into it, 1.1 m to 1.089 m in one step). Otherwise the robot stops translating
        (its own motion then shortens no distance, and with shared responsibility the
        other robot of each pair keeps its share) and turns towards the most dangerous
        row that is not a wall (smallest ``b̃``) at ``look_gain`` times its bearing, so
        that the camera confirms or clears it. Rows within ``params.fallback_tie_mps`` of
        the smallest ``b̃`` tie, and the one nearest the camera's axis wins: turning
        towards it keeps it the target (measured: with the plain argmin, robots packed
        along a wall between two neighbours turned back and forth step after step as
        the two swapped on the estimate's noise). The bearing cone's rows
        (``ROW_CONE``) are not targets: their directions lie ``α`` off the line of sight.
        With ``params.fallback_escape`` (safety Section 1f) the robot instead steps the
        nearest ``u_star`` no row is worse for than standing still, else turns towards
        the escape direction nearest ``u_star``'s (:func:`safe_fallback_inputs`).
        """
        u = np.full((1, 3), np.nan) if u_qp is None else np.asarray(u_qp, np.float64)[None]
        keep = np.ones((1, b.shape[0]), dtype=bool)
        p = self.params
        return safe_fallback_inputs(
            u, A[None], b[None], kind[None], keep, p.look_gain, self.config.omega_max_radps,
            p.fallback_tie_mps, p.fallback_straight, p.fallback_escape, self.config.v_max_mps,
            p.n_polygon, None if u_star is None else np.asarray(u_star, np.float64)[None],
        )[0]  # fmt: skip

    def solve(
        self,
        u_star: np.ndarray,
        p_body: np.ndarray,
        v_est_body: np.ndarray,
        d: np.ndarray,
        ids: np.ndarray | None = None,
        safety: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
        detected: np.ndarray | None = None,
        fov_yield: np.ndarray | None = None,
        priority_bonus: np.ndarray | None = None,
        glance: bool = False,
        yield_latched: bool = False,
        unblock_latched: bool = False,
    ) -> ControlResult:
        """Safe input closest to u* (Eq. 19) under the hierarchy of Eq. 18.

        Args:
            u_star: ``(3,)`` desired body-frame velocity ``[vx m/s, vy m/s, ω rad/s]``.
            p_body: ``(M, 2)`` estimated neighbour positions ⁱp_j (m), e.g. the
                tracker's ``mean_body``.
            v_est_body: ``(M, 2)`` neighbour velocity estimates ⁱv_j^est (m/s), Eq. 20/22.
            d: ``(M,)`` distances d_ij to the neighbours' confidence ellipses (m, 0 inside).
            ids: ``(M,)`` neighbour IDs, used only to break ties in d (default: order).
            safety: the robot's collision rows ``(A (K, 3), b (K,) m/s, kind (K,))`` of
                :func:`fov_marl.control.safety.safety_rows` (``A u + b ≥ 0``). With
                ``params.safety_model == "ellipse"`` they replace Eq. 12 row 3 in the
                safety level (None: rows from ``p_body`` taken as exact); ignored with
                ``"mean"``.
            detected: ``(M,)`` bool, neighbours in the last camera report (None: all),
                for ``params.search_by_turning`` (see :func:`~fov_marl.control.cbf.cbf_rows`).
            fov_yield: ``(M,)`` bool, neighbours whose FoV rows yield when they stall
                the robot (:meth:`_yield_lost`; the pipeline passes the neighbours lost
                for at least ``params.lost_fov_age_s``); None: never.
            priority_bonus: ``(M,)`` head start in d (m) of :meth:`assign_levels`, or None.
            glance: leave every FoV row out of this step (the robot turns to look at a
                bearing its blind travel budget has nearly spent,
                ``params.look_yields_fov``); the collision rows stay, so the robot is
                exactly as safe.
            yield_latched: the lost FoV rows yielded at the previous step (that step's
                ``ControlResult.yielded``): the latch of :meth:`_yield_lost`.
            unblock_latched: the robot kept right at the previous step (that step's
                ``ControlResult.unblocked``): the hysteresis of :meth:`_unblock`.

        Returns:
            :class:`ControlResult`. Non-finite inputs and solver failures give a
            fallback result; they never raise.

        Raises:
            ValueError: shapes that do not match the documented ones.
        """
        t0 = time.perf_counter()
        cfg, p = self.config, self.params
        u_star = np.asarray(u_star, dtype=np.float64)
        p_body = np.asarray(p_body, dtype=np.float64)
        v_est_body = np.asarray(v_est_body, dtype=np.float64)
        d = np.asarray(d, dtype=np.float64)
        if u_star.shape != (3,):
            raise ValueError(f"u_star must have shape (3,) [vx, vy, omega], got {u_star.shape}")
        if p_body.ndim != 2 or p_body.shape[1] != 2:
            raise ValueError(f"p_body must have shape (M, 2), got {p_body.shape}")
        M = p_body.shape[0]
        if v_est_body.shape != (M, 2):
            raise ValueError(f"v_est_body must have shape ({M}, 2), got {v_est_body.shape}")
        if d.shape != (M,):
            raise ValueError(f"d must have shape ({M},), got {d.shape}")
        if ids is None:
            ids = np.arange(M)
        else:
            ids = np.asarray(ids)
            if ids.shape != (M,):
                raise ValueError(f"ids must have shape ({M},), got {ids.shape}")
        for name, value in (
            ("detected", detected),
            ("fov_yield", fov_yield),
            ("priority_bonus", priority_bonus),
        ):
            if value is not None and np.shape(value) != (M,):
                raise ValueError(f"{name} must have shape ({M},) or be None, got {np.shape(value)}")
        # a collision row with non-finite coefficients, b NaN or b = -inf is invalid
        # input (b = +inf: a row that never binds); before, such rows were dropped
        rows_given = None if safety is None else self._parse_safety(safety)
        bad_rows = rows_given is not None and bool(invalid_rows(*rows_given[:2]).any())
        self.stats["steps"] += 1
        kappa = np.zeros((M, 4))
        if bad_rows or not (
            np.isfinite(u_star).all()
            and np.isfinite(p_body).all()
            and np.isfinite(v_est_body).all()
            and np.isfinite(d).all()
        ):
            self.stats["fallbacks"] += 1
            return ControlResult(
                u=np.zeros(3),
                u_star=u_star,
                status="invalid_input",
                fallback=True,
                intervened=True,
                kappa=kappa,
                active=np.zeros((M, 4), dtype=bool),
                level=np.full((M, 4), -2, dtype=np.int64),
                timings={"rows": 0.0, "cascade": 0.0, "final": 0.0,
                         "total": time.perf_counter() - t0},
            )  # fmt: skip
        u_given = u_star
        n_cone = self._cone_b.shape[0] if M else 0  # alone, there is no one to run into
        if n_cone and p.look_gain > 0.0:
            u_star = self.look_where_you_go(u_star)
        rows = cbf_rows(p_body, v_est_body, d, cfg, p, self.h_max, u_star[:2], detected)
        At, bt, _ = normalise_rows(rows.A, rows.b, cfg.v_max_mps, cfg.omega_max_radps, p.row_clip)
        active = bt < 1.0 if p.prune else np.isfinite(rows.h)
        sA, sb, sk = self._safety_rows(rows_given, p_body, v_est_body)
        if p.safety_model == "ellipse":
            active[:, SAFETY_ROW] = False
        if glance:
            active[:, _FOV_ROWS] = False
        u_proj = self._project(u_star)
        st = self.stats
        if (
            not active.any()
            and sb.size == 0
            and (n_cone == 0 or (self._cone_A @ u_proj + self._cone_b).min() >= 0.0)
        ):  # every row holds for every admissible input, and u* is inside the cone
            return ControlResult(
                u=u_proj,
                u_star=u_given,
                status="unconstrained",
                fallback=False,
                intervened=False,
                kappa=kappa,
                active=active,
                level=np.full((M, 4), -2, dtype=np.int64),
                timings={"rows": time.perf_counter() - t0, "cascade": 0.0, "final": 0.0,
                         "total": time.perf_counter() - t0},
            )  # fmt: skip
        level = self.assign_levels(
            active, d, ids, np.hypot(p_body[:, 0], p_body[:, 1]), priority_bonus
        )
        active = level > -2
        jj, rr = np.nonzero(active)
        t1 = time.perf_counter()
        A_q, b_q, l_q = At[jj, rr], bt[jj, rr], level[jj, rr]
        if n_cone:
            if p.safety_first or p.safety_hard:  # right below the safety level
                level[level >= 1] += 1
                l_q = np.where(l_q >= 1, l_q + 1, l_q)
                l_cone = 1
            else:  # the paper's per-neighbour levels: below all of them
                l_cone = int(l_q.max(initial=0)) + 1
            A_q = np.concatenate([A_q, self._cone_A])
            b_q = np.concatenate([b_q, self._cone_b])
            l_q = np.concatenate([l_q, np.full(n_cone, l_cone, dtype=l_q.dtype)])
        n_fov = b_q.shape[0]
        if sb.size:
            l_s = -1 if p.safety_hard else 0
            A_q = np.concatenate([A_q, sA])
            b_q = np.concatenate([b_q, sb])
            l_q = np.concatenate([l_q, np.full(sb.size, l_s, dtype=l_q.dtype)])
        qres = self._qp_solve(A_q, b_q, l_q, u_star)
        base = qres
        yielded = False
        if sb.size and p.deadlock_turn_deg > 0.0:
            qres = self._unblock(qres, A_q, b_q, l_q, u_star, n_fov, unblock_latched)
        unblocked = qres is not base
        if fov_yield is not None:
            lost = np.zeros(b_q.shape[0], dtype=bool)
            lost[: jj.size] = np.asarray(fov_yield, dtype=bool).reshape(-1)[jj] & (rr != SAFETY_ROW)
            before = qres
            qres = self._yield_lost(qres, A_q, b_q, l_q, u_star, lost, yield_latched, base)
            yielded = qres is not before
        kappa[jj, rr] = qres.kappa[: jj.size]
        u = qres.u
        status, fallback = qres.status, qres.fallback
        safety_kappa = float(qres.kappa[n_fov:].max(initial=0.0))
        unmet = safety_kappa > _KAPPA_SAFETY or qres.status == "qp_failed"
        if (
            sb.size
            and p.hold_cleanup
            and not unmet
            and approaches_held_row(u[None], sA[None], sb[None], np.ones((1, sb.size), bool))[0]
        ):  # a creep towards a held row, within the cascade's tolerance
            fixed = hold_cleanup(u, sA, sb, cfg.v_max_mps, self.qp.n_polygon)
            unmet = fixed is None
            if fixed is not None:
                u = fixed
        if sb.size and unmet:
            u = self._safe_fallback(None if qres.status == "qp_failed" else u, sA, sb, sk, u_star)
            status, fallback = "safety_fallback", True
            st["safety_fallbacks"] += 1
        if sb.size and p.arc_yaw_guard:  # safety Section 1c: the step's arc
            keep = np.ones((1, sb.size), dtype=bool)
            u = arc_yaw_guard(
                u[None], sA[None], sb[None], sk[None], keep, cfg.dt_s,
                stop_weight=self._w if p.arc_guard_stop else None,
            )[0]  # fmt: skip
        du = u - (u_proj if u_star is u_given else self._project(u_given))
        intervened = bool(math.sqrt(float(du @ du)) > p.intervention_tol)
        st["qp_solves"] += qres.n_qp
        st["fallbacks"] += int(fallback)
        st["interventions"] += int(intervened)
        st["relaxed"] += int(qres.status == "relaxed")
        return ControlResult(
            u=u,
            u_star=u_given,
            status=status,
            fallback=fallback,
            intervened=intervened,
            kappa=kappa,
            active=active,
            level=level,
            n_levels=qres.n_levels,
            n_qp=qres.n_qp,
            qp_status=qres.qp_status,
            safety_violation=max(float(kappa[:, SAFETY_ROW].max(initial=0.0)), safety_kappa),
            cone_violation=float(qres.kappa[jj.size : n_fov].max(initial=0.0)),
            yielded=yielded,
            unblocked=unblocked,
            timings={
                "rows": t1 - t0,
                "cascade": qres.t_cascade_s,
                "final": qres.t_final_s,
                "total": time.perf_counter() - t0,
            },
        )
