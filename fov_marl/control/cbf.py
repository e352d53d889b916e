"""Field-of-view CBFs (Eq. 11-12), their Lie derivatives, and slack (Eq. 16-17).

Pure, vectorised NumPy functions over the ``M`` neighbours of one robot i. Every
position and velocity is in i's body frame Σ_i; the robot's input is the body-frame
velocity ``u = [vx m/s, vy m/s, ω rad/s]`` (the kinematic model of Section III-B).

Rows (Eq. 12)
=============

For a neighbour at ``ⁱp_j = (x, y)`` and ``t = tan(β/2)``, four rows, in this order
(index ``r`` = 0..3 everywhere in this package)::

    r  name          h(ⁱp_j)           unit   h ≥ 0 means
    0  right_border  t x + y           m      j on the left of the right border (y = −t x)
    1  left_border   t x − y           m      j on the right of the left border (y = t x)
    2  safety        x² + y² − D_s²    m²     j at least D_s away (hard: ε₂ = 0)
    3  range         R_d² − x² − y²    m²     j within the detection range R_d

Rows 0-1 are the paper's border rows; for β < 180° their intersection is exactly
the sector ``|atan2(y, x)| ≤ β/2``. The controller shrinks the FoV rows by a small
margin (``ControllerParams.fov_margin_m``, default 0.05 m; see :func:`fov_barrier`)
so that the discrete-time overshoot of this continuous-time CBF stays in view.

**β ≥ 180°.** The sector is then the *union* of the two half-planes, not their
intersection (it is not convex), so the two border rows would describe the wrong
set (for β = 200° their intersection is a 160° cone pointing backwards). We replace
them by one smooth angular row in slot 0::

    h₀ = x − cos(β/2) ‖p‖  = ‖p‖ (cos φ − cos(β/2)),   φ = atan2(y, x)

which is ≥ 0 exactly on the sector for every β in (0°, 360°), and mark slot 1
inactive. At β = 360° (the ideal, isotropic case) both slots are inactive: the
whole plane is visible. Inactive rows have ``h = +inf`` and zero Lie-derivative
rows, so they are satisfied for every input and pruned before any QP.

Lie derivatives (the ḣ of Eq. 11, 17)
=====================================

The relative position obeys ``ⁱṗ_j = −v_i − ω × ⁱp_j + ⁱv_j^est``, i.e.::

    ẋ = −vx + ω y + v_jx,        ẏ = −vy − ω x + v_jy

with ``ⁱv_j^est`` the neighbour's estimated world velocity expressed in Σ_i (the
tracker's motion model, Eq. 20 or Eq. 22). Hence ``ḣ = A u + drift`` with, per row::

    r  A (row of ∂ḣ/∂u = [∂/∂vx, ∂/∂vy, ∂/∂ω])       drift
    0  [−t,          −1,        t y − x]              t v_jx + v_jy
    1  [−t,          +1,        t y + x]              t v_jx − v_jy
    0' [−(1 − c x/ρ), c y/ρ,    y      ]              (1 − c x/ρ) v_jx − (c y/ρ) v_jy
    2  [−2x,         −2y,       0      ]              2 (x v_jx + y v_jy)
    3  [+2x,         +2y,       0      ]              −2 (x v_jx + y v_jy)

(0' is the angular row for β ≥ 180°, ``c = cos(β/2)``, ``ρ = ‖p‖``; its ω entry
simplifies because rotating does not change ‖p‖.) The authors' code treated the
neighbour as static (drift from ``v_i`` only); we include ``ⁱv_j^est``.

Class-K functions (Eq. 11)
==========================

``α₀ = α₁ = γ₁ h + γ₃ h³`` for the border rows (h in m: Theorem 1's linear term plus
the authors' cubic), ``α₂ = γ_s h`` (safety, m²), ``α₃ = γ_r h`` (range, m²); gains
and the reasons for the defaults in :class:`~fov_marl.control.params.ControllerParams`.

Slack and how it enters (Eq. 16-17)
===================================

``ε_r(d) = h_max,r σ(s (d − 3 D_s))`` (Eq. 16 with slope s), ``ε₂ ≡ 0``. We let ε
*shift the barrier* instead of adding it to ḣ::

    ḣ_r + α_r(h_r + ε_r) ≥ 0                  (our reading of Eq. 17)

i.e. row r becomes the CBF of the relaxed set ``{h_r ≥ −ε_r}``. Because ``h_max,r``
is the modulus of the lowest value h_r can take in the arena
(:func:`row_h_max`), ``h_r + ε_r ≥ 0`` everywhere once σ → 1: a far neighbour's set
contains every reachable configuration and, with the class-K growth, its rows are
satisfied for every admissible input and get pruned. As d → D_s, ε → 0 and the row
is the hard CBF of Eq. 11. Adding ε to ḣ as printed would mix units (h_max is a
value of h, ḣ a rate) and would not release a far neighbour's row unless
``h_max ≥ −α(h)`` over the arena, which fails for the authors' cubic α
(α(−80 m) = −5·10⁵ m/s against h_max = 80).

The paper's sigmoid is not 0 at d = D_s: ``h_max σ(−2 s D_s)`` is 2.0 m on the
border rows for β = 120° (enough to let a neighbour at the safety distance leave the
FoV). With ``slack_zero_below_ds`` (default) we use the sigmoid shifted and
rescaled to ``(σ(s(d−3D_s)) − σ₀)/(1 − σ₀)``, ``σ₀ = σ(−2 s D_s)``, clipped at 0, so
ε = 0 for d ≤ D_s, ε → h_max for d → ∞, and ε(3 D_s) = h_max (½ − σ₀)/(1 − σ₀)
(0.491 h_max with the defaults), matching the description of Fig. 3.

Recovering a neighbour's view by turning (``ControllerParams.fov_recovery_cap``)
=============================================================================

Theorem 1 (Eq. 13-15) makes a violated row attractive: ``ḣ ≥ −α(h)`` with h < 0 asks
for a positive ḣ, from *any* input. For the FoV rows that is a poor guide once the
neighbour is well out of view. The rows are linear in ⁱp_j, so moving towards a
neighbour behind the robot raises ``t x ± y`` without turning the camera towards it;
a mean beyond R_d (where the deletion of Eq. 4 puts every undetected neighbour the
robot looks for, since the FoV holds no particle of it) makes the range row drag the
robot towards it; and in the back cone the two border rows disagree on the way to
turn (one of them first decreases along the shortest turn), so the level is
infeasible and the cascade (Eq. 18) spends all inputs, translation included, on
reducing its violation. Measured with the paper's rows: four crossing robots under
Eq. 22 dragged 8-18 m off their targets for minutes by neighbours' means behind them
or just beyond R_d (seeds 1 and 2 never all arrived within 200 s, 0, 3 and 4 took
46-163 s); a coverage robot backed blind into a neighbour while "looking" for another
one's mean behind it.

Searching (Section VI-B) is what the camera does, so with ``c = fov_recovery_cap > 0``
a FoV row in *recovery* (``h_r + ε_r < 0``: the neighbour's mean outside the sector
shrunk by ε, or beyond R_d) keeps only its rotation term, demands at most what
rotation delivers, and adds the harm the desired translation v* (u*'s) would do, so
the robot turns harder when its own motion pushes j further out of view, but never
gets a translation credited::

    A_r ← [0, 0, A_r,ω],   b_r ← max(b_r, −c |A_r,ω| ω_max) + min(0, A_r,v · v*)   (r = 0, 1, 3)

In the back cone (both border rows in recovery, ω terms of opposite signs) the row
whose ω term opposes ``sign(ⁱy_j)`` is dropped, so both agree on turning towards the
side j is on. The range row has no rotation term: in recovery it is void (the robot
never chases a mean beyond R_d; rows are void by marking them inactive, h = b = +inf).
Rows that hold (``h + ε ≥ 0``, j in view) are exactly Eq. 17's and keep j in view
(forward invariance) against every input, translation included; the safety row is
never changed. V = −h still decreases (Eq. 14-15) whenever the robot turns towards j
fast enough (≥ c ω_max plus what its translation takes away). With these rows all of
crossing seeds 0-9 arrive in 35-57 s (6 robots, seeds 0-2: 40-86 s) and 20 coverage
seeds (β = 120°) keep ≥ 2.27 m.

Motion cone ("look where you go", ``ControllerParams.motion_cone``)
===================================================================

Not in the paper; see :func:`motion_cone_rows`. Off by default, also in
:class:`~fov_marl.wrappers.SafetyFilterWrapper` (whose first version's blanket cone
changed 96% of random actions; its blind travel budget bounds motion towards what the
robot cannot see instead); selectable with ``ControllerParams(motion_cone=True)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fov_marl.config import ScenarioConfig
from fov_marl.control.params import ControllerParams

__all__ = [
    "ROW_NAMES",
    "SAFETY_ROW",
    "border_mode",
    "fov_barrier",
    "fov_barrier_lie",
    "class_k",
    "row_h_max",
    "sigmoid",
    "slack",
    "CbfRows",
    "cbf_rows",
    "row_authority",
    "normalise_rows",
    "motion_cone_rows",
]

#: Names of the four rows of Eq. 12, in the order used everywhere.
ROW_NAMES: tuple[str, str, str, str] = ("right_border", "left_border", "safety", "range")
#: Index of the always-hard safety row (ε₂ = 0).
SAFETY_ROW: int = 2


def border_mode(fov_rad: float) -> str:
    """Which border rows describe the sector of amplitude β = ``fov_rad``.

    Returns:
        ``"borders"`` for β < π (Eq. 12 rows 0-1), ``"angular"`` for π ≤ β < 2π (one
        angular row in slot 0, slot 1 inactive), ``"none"`` for β ≥ 2π (both inactive).
    """
    if fov_rad >= 2.0 * math.pi:
        return "none"
    if fov_rad >= math.pi:
        return "angular"
    return "borders"


def fov_barrier(
    p_body: np.ndarray,
    fov_rad: float,
    safety_distance_m: float,
    detection_range_m: float,
    margin_m: float = 0.0,
) -> np.ndarray:
    """Barrier values h(ⁱp_j) of Eq. 12 (with the β ≥ 180° rows of the module docstring).

    With ``margin_m = m > 0`` the FoV rows describe the sector shrunk by m: border
    rows ``t x ± y − m / cos(β/2)`` (their zero set moves m inwards, since
    ``(t x ± y) cos(β/2)`` is the distance to the border line), angular row
    ``x − cos(β/2)‖p‖ − m sin(β/2)`` (≈ m from the border ray), range row
    ``(R_d − m)² − ‖p‖²``. The safety row is unchanged. m = 0 is Eq. 12 exactly.

    Args:
        p_body: ``(M, 2)`` neighbour positions in Σ_i (m).
        fov_rad: β in (0, 2π].
        safety_distance_m: D_s (m).
        detection_range_m: R_d (m).
        margin_m: m ≥ 0, inward margin of the FoV rows (m).

    Returns:
        ``(M, 4)`` h, rows ``[0 m, 1 m, safety m², range m²]``; inactive rows +inf.
    """
    p = np.asarray(p_body, dtype=np.float64)
    x, y = p[:, 0], p[:, 1]
    r2 = x * x + y * y
    h = np.empty((p.shape[0], 4))
    mode = border_mode(fov_rad)
    if mode == "borders":
        t = math.tan(0.5 * fov_rad)
        shift = margin_m / math.cos(0.5 * fov_rad)
        h[:, 0] = t * x + y - shift
        h[:, 1] = t * x - y - shift
    elif mode == "angular":
        h[:, 0] = x - math.cos(0.5 * fov_rad) * np.sqrt(r2) - margin_m * math.sin(0.5 * fov_rad)
        h[:, 1] = np.inf
    else:
        h[:, 0:2] = np.inf
    h[:, 2] = r2 - safety_distance_m**2
    h[:, 3] = (detection_range_m - margin_m) ** 2 - r2
    return h


def fov_barrier_lie(
    p_body: np.ndarray, v_est_body: np.ndarray, fov_rad: float
) -> tuple[np.ndarray, np.ndarray]:
    """Lie-derivative rows of Eq. 12: ``ḣ = A u + drift`` (table in the module docstring).

    Args:
        p_body: ``(M, 2)`` neighbour positions ⁱp_j (m).
        v_est_body: ``(M, 2)`` neighbour velocity estimates ⁱv_j^est (m/s), Eq. 20/22.
        fov_rad: β in (0, 2π].

    Returns:
        ``(A (M, 4, 3), drift (M, 4))``: A in units of h per unit of ``[vx, vy, ω]``,
        drift in units of h per second. Inactive rows are all zeros.
    """
    p = np.asarray(p_body, dtype=np.float64)
    v = np.asarray(v_est_body, dtype=np.float64)
    M = p.shape[0]
    x, y = p[:, 0], p[:, 1]
    vx, vy = v[:, 0], v[:, 1]
    A = np.zeros((M, 4, 3))
    drift = np.zeros((M, 4))
    mode = border_mode(fov_rad)
    if mode == "borders":
        t = math.tan(0.5 * fov_rad)
        A[:, 0, 0] = -t
        A[:, 0, 1] = -1.0
        A[:, 0, 2] = t * y - x
        drift[:, 0] = t * vx + vy
        A[:, 1, 0] = -t
        A[:, 1, 1] = 1.0
        A[:, 1, 2] = t * y + x
        drift[:, 1] = t * vx - vy
    elif mode == "angular":
        c = math.cos(0.5 * fov_rad)
        rho = np.maximum(np.hypot(x, y), 1e-12)
        gx = 1.0 - c * x / rho
        gy = -c * y / rho
        A[:, 0, 0] = -gx
        A[:, 0, 1] = -gy
        A[:, 0, 2] = y
        drift[:, 0] = gx * vx + gy * vy
    pv = x * vx + y * vy
    A[:, 2, 0] = -2.0 * x
    A[:, 2, 1] = -2.0 * y
    drift[:, 2] = 2.0 * pv
    A[:, 3, 0] = 2.0 * x
    A[:, 3, 1] = 2.0 * y
    drift[:, 3] = -2.0 * pv
    return A, drift


def class_k(h: np.ndarray, params: ControllerParams) -> np.ndarray:
    """Extended class-K functions α_r of Eq. 11, applied column-wise to ``(M, 4)`` values.

    ``α₀ = α₁ = γ₁ h + γ₃ h³``; ``α₂ = γ_s h``; ``α₃ = γ_r h`` (module docstring).
    +inf maps to +inf.
    """
    h = np.asarray(h, dtype=np.float64)
    out = np.empty_like(h)
    hb = h[..., 0:2]
    out[..., 0:2] = hb * (params.alpha_border_gain + params.alpha_border_cubic * hb * hb)
    out[..., 2] = params.alpha_safety_gain * h[..., 2]
    out[..., 3] = params.alpha_range_gain * h[..., 3]
    return out


def row_h_max(config: ScenarioConfig, margin_m: float = 0.0) -> np.ndarray:
    """``h_max`` of Eq. 17: modulus of the lowest value each row takes in the arena.

    A neighbour's relative position ⁱp_j can be any vector of length up to the arena
    diagonal ``ρ = L √2`` in any direction (the robot's yaw is free), so over the disk
    ``‖p‖ ≤ ρ``:

    * border rows (β < 180°): ``min(t x ± y) = −ρ √(1 + t²) = −ρ / cos(β/2)``;
    * angular row (β ≥ 180°): ``min(x − cos(β/2)‖p‖) = −ρ (1 + cos(β/2))`` (directly behind);
    * safety row: 0 (hard, ε₂ = 0 always);
    * range row: ``R_d² − ρ²`` → ``ρ² − R_d²`` (clipped at 0);

    each lowered further by the FoV margin of :func:`fov_barrier` when ``margin_m > 0``.

    The authors' [80, 80, 0, 3100] (β = 120°, L = 40 m, R_d = 10 m) used ρ = L for
    the border rows and ρ = L√2 for the range row; we use the diagonal for both,
    giving [113.1, 113.1, 0, 3100].

    Returns:
        ``(4,)`` non-negative h_max (m, m, m², m²); 0 for inactive rows.
    """
    rho = config.arena_size_m * math.sqrt(2.0)
    beta = config.fov_rad
    out = np.zeros(4)
    mode = border_mode(beta)
    if mode == "borders":
        out[0:2] = (rho + margin_m) / math.cos(0.5 * beta)
    elif mode == "angular":
        out[0] = rho * (1.0 + math.cos(0.5 * beta)) + margin_m * math.sin(0.5 * beta)
    out[3] = max(0.0, rho * rho - (config.detection_range_m - margin_m) ** 2)
    return out


def sigmoid(x: np.ndarray) -> np.ndarray:
    """Logistic function σ(x) = 1 / (1 + e^(−x)) of Eq. 16, overflow-free."""
    x = np.asarray(x, dtype=np.float64)
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def slack(
    d: np.ndarray,
    config: ScenarioConfig,
    params: ControllerParams,
    h_max: np.ndarray | None = None,
) -> np.ndarray:
    """Slack ε_r(d_ij) of Eq. 16-17, per neighbour and row.

    ``ε_r = h_max,r · σ(s (d − 3 D_s))`` with slope ``s = params.slack_slope`` and
    ``ε₂ = 0`` (the safety row is always hard). With ``params.slack_zero_below_ds``
    the sigmoid is replaced by ``max(0, (σ(s(d − 3D_s)) − σ₀) / (1 − σ₀))``,
    ``σ₀ = σ(−2 s D_s)``, which is exactly 0 at d ≤ D_s and → 1 for large d (see the
    module docstring for why).

    Args:
        d: ``(M,)`` distances d_ij from robot i to neighbour j's confidence ellipse
            (m, 0 inside; Eq. 10 or the exact distance).
        h_max: ``(4,)`` from :func:`row_h_max` (computed from ``config`` and
            ``params.fov_margin_m`` if None).

    Returns:
        ``(M, 4)`` ε in the units of each row's h (m, m, m², m²).
    """
    if h_max is None:
        h_max = row_h_max(config, params.fov_margin_m)
    d = np.asarray(d, dtype=np.float64)
    s = params.slack_slope
    ds = config.safety_distance_m
    sig = sigmoid(s * (d - 3.0 * ds))
    if params.slack_zero_below_ds:
        s0 = float(sigmoid(-2.0 * s * ds))
        sig = np.maximum(sig - s0, 0.0) / (1.0 - s0)
    eps = sig[:, None] * np.asarray(h_max, dtype=np.float64)[None, :]
    eps[:, SAFETY_ROW] = 0.0
    return eps


@dataclass(frozen=True)
class CbfRows:
    """Constraint rows ``A u + b ≥ 0`` of Eq. 17 for the ``M`` neighbours of one robot.

    Attributes:
        A: ``(M, 4, 3)`` Lie-derivative rows (units of h per unit input); FoV rows in
            recovery keep only their ω term (module docstring).
        b: ``(M, 4)`` ``drift + α(h + ε)`` (units of h per second), with the safety
            margin applied to row 2 and the recovery floor to FoV rows in recovery;
            +inf for inactive (and void) rows.
        h: ``(M, 4)`` barrier values (Eq. 12); +inf for inactive (and void) rows.
        eps: ``(M, 4)`` slack ε (Eq. 16-17).
    """

    A: np.ndarray
    b: np.ndarray
    h: np.ndarray
    eps: np.ndarray


def cbf_rows(
    p_body: np.ndarray,
    v_est_body: np.ndarray,
    d: np.ndarray,
    config: ScenarioConfig,
    params: ControllerParams,
    h_max: np.ndarray | None = None,
    v_desired_body: np.ndarray | None = None,
    detected: np.ndarray | None = None,
) -> CbfRows:
    """Assemble the rows of Eq. 17 in our reading: ``A u + drift + α(h + ε) ≥ 0``.

    FoV rows in recovery (``h + ε < 0``) are then reduced to their rotation term
    (``params.fov_recovery_cap``, module docstring; 0 keeps the paper's rows), which
    also compensates the harm the desired translation ``v_desired_body`` would do.

    h comes from :func:`fov_barrier` with ``params.fov_margin_m`` (the FoV rows keep
    the neighbour that far inside the sector, absorbing the discrete-time overshoot
    of this continuous-time CBF: with dt = 0.2 s a robot backing away and turning
    crosses the border by ~0.02° without it).

    With ``params.safety_speed_margin_mps = δv > 0`` the safety row is made robust to
    an error of norm ≤ δv in ⁱv_j^est: its drift ``2 p·v_j`` is replaced by its worst
    case ``2 p·v_j − 2 ‖p‖ δv`` (a robust CBF; the paper uses δv = 0).

    Args:
        p_body: ``(M, 2)`` ⁱp_j (m). v_est_body: ``(M, 2)`` ⁱv_j^est (m/s).
        d: ``(M,)`` ellipse distances d_ij (m).
        v_desired_body: ``(2,)`` the robot's desired planar velocity (u*'s), m/s; None
            is zero.
        detected: ``(M,)`` bool, neighbour in the camera's last report, or None.
            ``params.fov_translation`` decides which FoV rows keep their translation
            terms: ``"all"`` (the paper's Eq. 17: every row that holds), ``"seen"``
            (those of detected neighbours: a robot searches for a neighbour it does
            not see by turning, never by driving), ``"none"`` (every FoV row is in
            recovery, rotation only: the camera is kept on the neighbours by turning
            and the translation is left to u* and the collision rows). Measured
            (pfcbf, N = 6, β = 120°, seeds 0-4, mean speed over the last 50 s):
            "all" 0.044-0.066 m/s, "seen" 0.004-0.092 m/s (holding rows of seen
            neighbours at the sector's borders back the robot up), "none" below.

    Returns:
        :class:`CbfRows`.
    """
    h = fov_barrier(
        p_body,
        config.fov_rad,
        config.safety_distance_m,
        config.detection_range_m,
        params.fov_margin_m,
    )
    A, drift = fov_barrier_lie(p_body, v_est_body, config.fov_rad)
    eps = slack(d, config, params, h_max)
    b = drift + class_k(h + eps, params)
    if params.fov_recovery_cap > 0.0:
        unseen = None
        if params.fov_translation == "none":
            unseen = np.ones(h.shape[0], dtype=bool)
        elif params.fov_translation == "seen" and detected is not None:
            unseen = ~np.asarray(detected, dtype=bool).reshape(-1)
        A, b, h = _recover_by_rotation(
            A, b, h, eps, p_body, config, params.fov_recovery_cap, v_desired_body, unseen
        )
    if params.safety_speed_margin_mps > 0.0:
        p = np.asarray(p_body, dtype=np.float64)
        b[:, SAFETY_ROW] -= 2.0 * params.safety_speed_margin_mps * np.hypot(p[:, 0], p[:, 1])
    return CbfRows(A=A, b=b, h=h, eps=eps)


def _recover_by_rotation(
    A: np.ndarray,
    b: np.ndarray,
    h: np.ndarray,
    eps: np.ndarray,
    p_body: np.ndarray,
    config: ScenarioConfig,
    cap: float,
    v_desired: np.ndarray | None,
    unseen: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """FoV rows in recovery turn the camera and never drive the robot (see :func:`cbf_rows`).

    Rows 0, 1, 3 with ``h + ε < 0`` lose their translational coefficients and demand at
    most ``cap · |A_ω| ω_max``, what rotation delivers, plus the harm the desired
    translation does, ``−min(0, A_v · v*)`` (so the robot turns harder to see a
    neighbour its own motion pushes out of view). In the back cone, where both
    border rows are in recovery, the one whose ω coefficient opposes ``sign(y)`` (the
    way to turn towards j) loses its ω coefficient too. A row left without coefficients
    (the range row in recovery, that border row) is void: marked inactive like the
    unused slots of :func:`fov_barrier` (``h = b = +inf``, ``A = 0``).

    Returns:
        ``(A, b, h)``, new arrays.
    """
    with np.errstate(invalid="ignore"):
        rec = h + eps < 0.0  # inactive rows are +inf: never in recovery
    if unseen is not None:  # fov_translation: every FoV row of these neighbours
        rec |= unseen[:, None] & np.isfinite(h)
    rec[:, SAFETY_ROW] = False
    if not rec.any():
        return A, b, h
    A = A.copy()
    h = h.copy()
    if v_desired is None:
        harm = 0.0
    else:
        vd = np.asarray(v_desired, dtype=np.float64).reshape(2)
        harm = np.minimum(0.0, A[..., 0] * vd[0] + A[..., 1] * vd[1])
    A[rec, 0:2] = 0.0
    y = np.asarray(p_body, dtype=np.float64)[:, 1]
    w_border = A[:, 0:2, 2]  # a view
    w_border[(rec[:, 0] & rec[:, 1])[:, None] & (w_border * y[:, None] < 0.0)] = 0.0
    w = A[..., 2]
    b = np.where(rec, np.maximum(b, -cap * np.abs(w) * config.omega_max_radps) + harm, b)
    void = rec & (w == 0.0)
    b[void] = np.inf
    h[void] = np.inf
    return A, b, h


def row_authority(A: np.ndarray, v_max: float, omega_max: float) -> np.ndarray:
    """Largest change of ``A u`` over the admissible inputs: ``‖A[:2]‖ v_max + |A[2]| ω_max``.

    Exact maximum of ``|A u|`` over the disk ``‖v‖ ≤ v_max`` times ``|ω| ≤ ω_max``.
    A row with ``b − authority ≥ 0`` therefore holds for *every* admissible input
    (the closed-form pruning test); the polygon the QP actually uses is inscribed in
    the disk, so the test is also exact for it.

    Args:
        A: ``(..., 3)`` rows.

    Returns:
        ``(...)`` authorities (units of h per second).
    """
    A = np.asarray(A, dtype=np.float64)
    return np.hypot(A[..., 0], A[..., 1]) * v_max + np.abs(A[..., 2]) * omega_max


def normalise_rows(
    A: np.ndarray, b: np.ndarray, v_max: float, omega_max: float, clip: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scale each row by its input authority and clip its offset.

    ``Ã = A / a``, ``b̃ = clip(b / a, −C, C)`` with ``a`` = :func:`row_authority`
    (floored at 1e-12). After scaling ``|Ã u| ≤ 1`` for every admissible input, so a
    row is *possibly active* iff ``b̃ < 1``; κ of the QPs (Eq. 18-19) is then measured
    as a fraction of the row's full authority, which makes the m and m² rows
    comparable in ``‖κ‖²`` and keeps OSQP well scaled. Clipping at −C (C ≥ 2) only
    changes rows that are violated for every input by more than C − 1 authorities
    (a saturation of α); clipping at +C keeps ``b̃ ≥ 1`` rows prunable.

    Args:
        A: ``(..., 3)``; b: ``(...)``; clip: C ≥ 2.

    Returns:
        ``(Ã (..., 3), b̃ (...), a (...))``.
    """
    a = np.maximum(row_authority(A, v_max, omega_max), 1e-12)
    with np.errstate(invalid="ignore"):
        bt = np.clip(np.asarray(b, dtype=np.float64) / a, -clip, clip)
    return np.asarray(A, dtype=np.float64) / a[..., None], bt, a


def motion_cone_rows(
    fov_rad: float, blind_speed_mps: float, v_max_mps: float, half_angle_rad: float
) -> tuple[np.ndarray, np.ndarray]:
    """ "Look where you go": input rows ``G u ≥ h`` keeping fast motion where the camera looks.

    Not in the paper: an addition for collision avoidance (see the module docstring
    of :mod:`~fov_marl.control.params`, ``motion_cone``). The admissible planar
    velocities become the convex hull of the small disk ``‖v‖ ≤ v_b``
    (``v_b = blind_speed_mps``, allowed in every direction) and the full-speed cone
    ``‖v‖ ≤ v_max, |∠v| ≤ a`` around the camera axis (body x), with
    ``a = min(β/2, half_angle_rad)`` inside the camera sector F_i. A robot thus moves
    faster than v_b only towards what it sees, so two robots that cannot see each
    other close in on each other at no more than about 2 v_b.

    The hull is described by five half-planes ``n_k · v ≤ v_b`` tangent to the small
    disk, with outward unit normals at the angles ``±ψ``, ``±(ψ + π)/2`` and π,
    ``ψ = a + acos(v_b / v_max)``: the ``±ψ`` sides pass through the full-speed
    corners ``v_max (cos a, ±sin a)``; the other three close the hull behind the
    robot (the ``±ψ`` sides alone would meet ``v_b / |cos ψ|`` behind it). With
    v_b = 0.05 m/s and a = 20° the speed allowed at 30° off the axis is 0.22 m/s, at
    45° 0.11 m/s and beyond 90° about v_b. Rows are returned as ``G u ≥ h`` with ``G = −n``,
    ``h = −v_b``: ``u = 0`` always satisfies them (braking stays admissible).

    Args:
        fov_rad: β in (0, 2π]; β = 2π (isotropic camera) gives no rows.
        blind_speed_mps: v_b in [0, v_max] (m/s).
        v_max_mps: speed limit (m/s).
        half_angle_rad: half-angle of the full-speed cone, in (0, π); capped at β/2.

    Returns:
        ``(G (k, 3), h (k,))`` with ``k`` 0 or 5; ``G[:, 2] = 0``.
    """
    if fov_rad >= 2.0 * math.pi:
        return np.zeros((0, 3)), np.zeros(0)
    a = min(0.5 * fov_rad, half_angle_rad)
    vb = min(max(blind_speed_mps, 0.0), v_max_mps)
    psi = min(a + math.acos(vb / v_max_mps), math.pi)
    mid = 0.5 * (psi + math.pi)
    ang = np.array([psi, mid, math.pi, -mid, -psi])
    G = np.zeros((5, 3))
    G[:, 0] = -np.cos(ang)
    G[:, 1] = -np.sin(ang)
    return G, np.full(5, -vb)
