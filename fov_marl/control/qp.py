"""Hierarchical QP of Eq. 18-19: strict priorities by cascade, then the final projection.

The solver works on generic normalised rows ``Ã_r u + b̃_r + κ_r ≥ 0`` (see
:func:`fov_marl.control.cbf.normalise_rows`), ``u = [vx, vy, ω]`` the robot's
body-frame velocity, each row tagged with an integer priority level (smaller =
higher priority; a negative level marks a *hard* row whose κ is fixed at 0).

Admissible inputs
=================

``|ω| ≤ ω_max`` and ``‖(vx, vy)‖ ≤ v_max``. The norm bound is replaced by the regular
``n``-gon *inscribed* in the disk (``n = n_polygon``, apothem ``v_max cos(π/n)``):
every solution satisfies the true bound; at most ``1 − cos(π/n)`` of the speed is
lost (1.9% at n = 16).

Cascade (Eq. 18)
================

Levels are processed in increasing order; rows of the levels already processed
keep their κ* fixed. For level k:

1. If its rows already hold at the current candidate u_c (initially u* projected
   onto the admissible set, later the last solution, which meets every higher
   level) then κ*_k = 0 and no QP is needed.
2. Otherwise try to meet it exactly: project u* onto the higher rows (with their
   κ*) plus level k's rows with κ_k = 0. If that is feasible, κ*_k = 0 exactly and
   the new candidate is this projection. (Skipped when some row of the level has
   b̃ < −1: normalised rows satisfy ``|Ã u| ≤ 1`` on the admissible set, so such a
   row is violated by every input.)
3. Only if it is infeasible, minimise the level's violation::

       min_{u, κ_k}  ‖κ_k‖² + ρ ‖u − u*‖²
       s.t.  Ã_r u + b̃_r + κ*_r ≥ 0     rows of levels < k (κ* fixed)
             Ã_r u + b̃_r + κ_r  ≥ 0     rows of level k
             u admissible

   with a small ρ (``reg``) that makes the problem strictly convex: it selects the
   u closest to u* among the minimisers and biases κ*_k by O(ρ), only on levels
   that are infeasible anyway (step 2 keeps feasible levels exact).

κ*_r is *recomputed* from the accepted solution as ``max(0, −(Ã_r u + b̃_r))``, so the
fixed rows hold exactly at the candidate and no later level can increase them:
strict priority, up to the tolerance below. A hard level (negative level) only
gets step 1-2; if step 2 is infeasible the controller brakes.

Final QP (Eq. 19)
=================

``min ½‖u − u*‖² + ½‖κ‖²  s.t.  Ã u + b̃ + κ ≥ 0``. We insert the cascade's κ* as
fixed values (the paper: "the calculated values of minimized violations κ are then
inserted into (17)"); ½‖κ*‖² is then a constant and the problem is the projection
of u* onto ``S = {u admissible : Ã u + b̃ + κ* ≥ 0}``. Letting κ vary in ``[0, κ*]``
instead gives the same u (a smaller κ only tightens a row).

The cascade's last candidate already *is* that projection, so no separate QP is
needed: after step 2 it is the projection of u* onto a superset of S (the rows
processed so far) at which every later row holds, hence onto S; after step 3 it
minimises ``F(u) = ρ‖u − u*‖² + ‖κ_k(u)‖²`` (``κ_k(u) = max(0, −(Ã u + b̃))`` on the
level's rows) over the higher levels' set, which contains S, and every u in S has
``κ_k(u) ≤ κ*_k`` componentwise, so ``ρ‖u − u*‖² ≥ F(u_c) − ‖κ*_k‖² = ρ‖u_c − u*‖²``.
Only when a soft level's QP failed ("degraded") is the projection solved
explicitly.

Backends
========

``"nnls"`` (default): every QP above is a *least-distance program*
``min ‖y‖² s.t. G y ≥ h`` (step 2 and Eq. 19: ``y = u − u*``; step 3:
``y = [√ρ (u − u*), κ_k]``), solved exactly by Lawson & Hanson's reduction to
non-negative least squares (:func:`least_distance`, ``scipy.optimize.nnls``), an
active-set method: exact on these tiny problems (3 inputs, ≤ ~60 rows), a few µs in
the solver, and infeasibility is certified (zero residual) rather than iterated on.

``"osqp"``: two persistent ``osqp.OSQP`` objects per robot (cascade: variables
``[u, κ]``; projection: ``u``), created once with capacity for ``R`` rows and updated
in place with ``update(q, l, u, Ax)`` (``Ax`` in CSC column order, pattern fixed,
unused rows padded with zero coefficients and infinite bounds); ``warm_starting``,
``polishing``, ``algebra="builtin"``, ``verbose=False``, ``solve(raise_error=False)``;
rebuilt with double capacity when more rows arrive. **Measured drawback** (see
:func:`fov_marl.control.benchmark.bench_qp_backends`): step 3 is LP-like (the u block
only has the tiny ρ curvature and the optimum sits on a vertex of the polygon × ω
box) and relaxed levels leave thin, degenerate feasible sets, so ADMM needs
hundreds to thousands of iterations (milliseconds per hierarchy), polishing often
fails, and a few percent of solves end ``"degraded"``. Kept for comparison.

Acceptance and tolerances
=========================

Whatever the backend says, a solution is accepted only if an independent check
passes: finite, admissible (after projecting off round-off), and every fixed row
holds within ``tol_check``. Fixed rows enter each QP as
``Ã u ≥ min(−b̃ − κ*, Ã u_c) − tol_fix``, never above the candidate's own value, so
each QP is feasible by construction, and κ* absorbs the round-off of an accepted
solution. nnls: ``tol_fix = 1e-7``, ``tol_check = 1e-5``; osqp: ``1e-5``, ``1e-4``
(normalised units, fractions of a row's input authority). A lower level can raise
a higher level's κ* by at most ``tol_check`` per level.

Failure and fallback
====================

Never raises on numerical trouble. Non-finite inputs, or a *hard* level that is
infeasible or fails, return the braking input ``u = 0`` (for this kinematic model
it stops the robot at once; status ``"invalid_input"`` / ``"qp_failed"``). A soft
level whose QP fails keeps the current candidate (it meets every higher level)
and the cascade goes on; a final QP that fails returns the last cascade solution
(it meets every level with its κ*, but is not the closest to u*); both give status
``"degraded"``. Every fallback sets ``fallback=True``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import osqp
import scipy.sparse as sp
from scipy.optimize import nnls

from fov_marl.validation import check_int, check_real

__all__ = [
    "QPResult",
    "HierarchicalQP",
    "least_distance",
    "project_to_admissible",
    "polygon_normals",
]

_INF = 1e30
_BACKENDS = ("nnls", "osqp")
#: κ* above which a row counts as violated in the status ("relaxed"); below it is the
#: O(ρ) bias of the cascade regulariser and solver round-off (normalised units).
_KAPPA_REPORT = 1e-3
#: rows closer than this in every normalised coefficient count as the same constraint
_DUP_TOL = 1e-6


def polygon_normals(n: int) -> np.ndarray:
    """``(n, 2)`` outward unit normals of the regular n-gon used for ``‖v‖ ≤ v_max``."""
    ang = 2.0 * np.pi * np.arange(n) / n
    return np.stack([np.cos(ang), np.sin(ang)], -1)


def project_to_admissible(u: np.ndarray, v_max: float, omega_max: float, n: int) -> np.ndarray:
    """Euclidean projection onto the admissible set (inscribed n-gon × ``[−ω_max, ω_max]``).

    Closed form for the regular polygon: a point outside lies in the angular sector
    of the edge whose normal is nearest its bearing; project on that edge's line and
    clamp along the edge (clamping lands on the vertex when the point is in a
    vertex region).

    Args:
        u: ``(3,)`` finite ``[vx, vy, ω]``.
        v_max, omega_max: the bounds, > 0 (m/s, rad/s); n: the polygon's sides, ≥ 3.

    Returns:
        ``(3,)`` projected input.

    Raises:
        ValueError: a non-finite ``u`` or bounds out of range.
    """
    out = np.array(u, dtype=np.float64)
    if out.shape != (3,) or not (
        math.isfinite(out[0]) and math.isfinite(out[1]) and math.isfinite(out[2])
    ):
        raise ValueError(f"u must be a finite (3,) [vx, vy, omega], got {out.tolist()!r}")
    if not (0.0 < v_max < math.inf and 0.0 < omega_max < math.inf):
        raise ValueError(
            f"v_max and omega_max must be finite and > 0, got {v_max!r}, {omega_max!r}"
        )
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 3:
        raise ValueError(f"n must be an integer >= 3 (polygon sides), got {n!r}")
    return _project_admissible(out, v_max, omega_max, n)


def _project_admissible(out: np.ndarray, v_max: float, omega_max: float, n: int) -> np.ndarray:
    """:func:`project_to_admissible` in place on a fresh finite ``(3,)`` float64 ``out``,
    unchecked (:class:`HierarchicalQP` checked its bounds at construction)."""
    apothem = v_max * math.cos(math.pi / n)
    vx, vy = out[0], out[1]
    k = round(math.atan2(vy, vx) * n / (2.0 * math.pi))
    th = 2.0 * math.pi * k / n
    cn, sn = math.cos(th), math.sin(th)
    if vx * cn + vy * sn > apothem:
        half = apothem * math.tan(math.pi / n)
        tang = min(max(-vx * sn + vy * cn, -half), half)
        out[0] = apothem * cn - tang * sn
        out[1] = apothem * sn + tang * cn
    out[2] = min(max(out[2], -omega_max), omega_max)
    return out


def duplicate_rows(A: np.ndarray, b: np.ndarray, tol: float = _DUP_TOL) -> np.ndarray:
    """Rows that repeat an earlier row: ``dup[i]`` iff some ``j < i`` has
    ``max(|A_i − A_j|, |b_i − b_j|) ≤ tol`` (every coefficient within ``tol``).

    The pairs are first screened on the offsets ``b`` alone: sorted, no two neighbours
    within ``tol`` means no pair is (the common case); otherwise an ``(R, R)``
    test instead of ``(R, R, 4)`` (a short inner axis makes NumPy's reduction slow), and
    the few candidates are checked on all four. The same predicate as the dense test
    (:func:`_duplicate_rows_dense`, kept as the reference), several times faster.

    Args:
        A: ``(R, 3)``; b: ``(R,)`` (finite).

    Returns:
        ``(R,)`` bool.
    """
    dup = np.zeros(b.shape[0], dtype=bool)
    bs = np.sort(b)
    if not (bs[1:] - bs[:-1] <= tol).any():  # no two offsets within tol
        return dup
    ii, jj = np.nonzero(np.abs(b[:, None] - b[None, :]) <= tol)
    later = ii > jj
    ii, jj = ii[later], jj[later]
    if ii.size:
        close = (np.abs(A[ii] - A[jj]) <= tol).all(axis=1)
        dup[ii[close]] = True
    return dup


def _duplicate_rows_dense(A: np.ndarray, b: np.ndarray, tol: float = _DUP_TOL) -> np.ndarray:
    """Reference of :func:`duplicate_rows`: the dense ``(R, R, 4)`` comparison."""
    key = np.column_stack([A, b])
    same = np.abs(key[:, None, :] - key[None, :, :]).max(axis=2) <= tol
    return np.tril(same, -1).any(axis=1)


def least_distance(G: np.ndarray, h: np.ndarray) -> np.ndarray | None:
    """Least-distance program ``min ‖y‖² s.t. G y ≥ h`` (Lawson & Hanson, ch. 23).

    Solves the NNLS problem ``min_{z ≥ 0} ‖E z − f‖`` with ``E = [Gᵀ; hᵀ]`` and
    ``f = (0, …, 0, 1)``; with ``r = E z − f`` the solution is ``y = −r[:n] / r[n]``,
    and a zero residual means the constraints are inconsistent.

    Args:
        G: ``(m, n)``; h: ``(m,)``.

    Returns:
        ``(n,)`` solution, or None when infeasible or when NNLS did not converge.

    Raises:
        ValueError: non-finite ``G`` or ``h``.
    """
    m, n = G.shape
    if m == 0:
        return np.zeros(n)
    E = np.empty((n + 1, m))
    E[:n] = G.T
    E[n] = h
    if not np.isfinite(E).all():
        raise ValueError("G and h must be finite")
    return _ldp(E)


def _public_nnls(E: np.ndarray, f: np.ndarray, maxiter: int) -> tuple[np.ndarray, float]:
    return nnls(E, f, maxiter=maxiter)


def _direct_nnls() -> object | None:
    """SciPy's compiled NNLS without its Python wrapper (argument checks and a
    deprecation shim: ~16 µs of the ~39 µs of a call here), or None where this SciPy
    has none with the same results (checked once on a small problem; the private
    module exists from SciPy 1.15)."""
    try:
        from scipy.optimize._slsqplib import nnls as raw
    except ImportError:
        return None
    E = np.array([[1.0, 0.0, 2.0], [0.5, -1.0, 1.0], [0.0, 1.0, -1.0]])
    f = np.array([0.0, 0.0, 1.0])
    try:
        z, rnorm, _ = raw(E.copy(), f.copy(), 30)
        z_ref, r_ref = nnls(E, f, maxiter=30)
    except Exception:  # another signature: use the public function
        return None
    if not (np.array_equal(z, z_ref) and rnorm == r_ref):
        return None

    def call(E: np.ndarray, f: np.ndarray, maxiter: int) -> tuple[np.ndarray, float]:
        z, rnorm, info = raw(E, f, maxiter)
        if info == 3:
            raise RuntimeError("Maximum number of iterations reached.")
        return z, rnorm

    return call


#: NNLS on finite C-ordered float64 arrays (the only ones :func:`_ldp` builds)
_nnls = _direct_nnls() or _public_nnls


def _ldp(E: np.ndarray, maxiter: int | None = None) -> np.ndarray | None:
    """:func:`least_distance` on the stacked ``E = [Gᵀ; hᵀ]`` (``(n + 1, m)``, finite,
    C-ordered float64); ``maxiter``: NNLS iteration cap (default ``20 (m + n + 1)``)."""
    n = E.shape[0] - 1
    f = np.zeros(n + 1)
    f[n] = 1.0
    if maxiter is None:
        maxiter = 20 * (E.shape[1] + n + 1)
    try:
        z, rnorm = _nnls(E, f, maxiter)
    except RuntimeError:
        return None
    if not rnorm > 1e-10:
        return None
    r = E @ z
    r[n] -= 1.0
    if not r[n] < -1e-12:
        return None
    return r[:n] / -r[n]


@dataclass
class QPResult:
    """Outcome of :meth:`HierarchicalQP.solve`.

    Attributes:
        u: ``(3,)`` body-frame input ``[vx m/s, vy m/s, ω rad/s]``.
        kappa: ``(R,)`` minimised violations κ* per row (normalised units: fraction
            of the row's input authority), 0 for rows that hold.
        status: ``"unconstrained"`` (u* projected satisfies every row, no QP),
            ``"solved"`` (every row holds: κ* ≤ 1e-3), ``"relaxed"`` (some κ* > 1e-3),
            ``"degraded"`` (a soft level or the final QP failed; u is the best
            candidate found, it meets every level above the failure),
            ``"invalid_input"`` (non-finite data; u = 0) or ``"qp_failed"`` (a hard level
            is infeasible or failed; u = 0).
        qp_status: the backend's status of the last QP ("" if none): OSQP's status
            string, or ``"solved"`` / ``"infeasible"`` for nnls.
        fallback: True for ``"degraded"``, ``"invalid_input"`` and ``"qp_failed"``.
        n_qp: number of QPs solved.
        n_levels: number of distinct priority levels among the rows.
        t_cascade_s, t_final_s: wall time of the cascade and of the final QP.
        level_values: ``(L,)`` the distinct levels the cascade solved, ascending (rows
            repeating an earlier row are left out, so a level may be missing).
        level_start_cost: ``(L,)`` ``‖u_c − u*‖²`` of the candidate ``u_c`` with which
            the cascade reached each of those levels (NaN after a degraded level). It is
            the projection of u* onto the higher levels with their κ*, so any input that
            meets those levels with those κ* is at least this far from u*, up to the
            fixing tolerance (nnls: measured at most 1.1e-4 closer over 3,000 random
            hierarchies; OSQP's approximate solves make it only indicative):
            :meth:`~fov_marl.control.FovCbfController._yield_lost` skips a re-solve
            that cannot pay off.
    """

    u: np.ndarray
    kappa: np.ndarray
    status: str
    qp_status: str = ""
    fallback: bool = False
    n_qp: int = 0
    n_levels: int = 0
    t_cascade_s: float = 0.0
    t_final_s: float = 0.0
    levels: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    level_values: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    level_start_cost: np.ndarray = field(default_factory=lambda: np.zeros(0))


class HierarchicalQP:
    """Cascade (Eq. 18) and final QP (Eq. 19) for one robot; build once, call every step.

    Args:
        v_max: speed bound (m/s). omega_max: yaw-rate bound (rad/s).
        n_polygon: sides of the inscribed polygon (≥ 4).
        backend: ``"nnls"`` (exact active set) or ``"osqp"``.
        capacity: initial rows of the OSQP sparsity patterns.
        eps: OSQP eps_abs and eps_rel. max_iter: OSQP iteration cap.
        reg: ρ, weight of ``‖u − u*‖²`` in the cascade QPs.
    """

    def __init__(
        self,
        v_max: float,
        omega_max: float,
        n_polygon: int = 16,
        backend: str = "nnls",
        capacity: int = 16,
        eps: float = 1e-6,
        max_iter: int = 4000,
        reg: float = 1e-3,
    ) -> None:
        check_real("v_max", v_max, 0.0, math.inf, lo_open=True, hi_open=True)
        check_real("omega_max", omega_max, 0.0, math.inf, lo_open=True, hi_open=True)
        check_int("n_polygon", n_polygon, 4)
        check_real("reg", reg, 0.0, math.inf, lo_open=True, hi_open=True)
        check_real("eps", eps, 0.0, math.inf, lo_open=True, hi_open=True)
        check_int("max_iter", max_iter, 1)
        check_int("capacity", capacity, 1)
        if backend not in _BACKENDS:
            raise ValueError(f"backend must be one of {_BACKENDS}, got {backend!r}")
        self.v_max = float(v_max)
        self.omega_max = float(omega_max)
        self.n_polygon = int(n_polygon)
        self.backend = backend
        self.eps = float(eps)
        self.max_iter = int(max_iter)
        self.reg = float(reg)
        self._normals = polygon_normals(self.n_polygon)
        self._apothem = self.v_max * math.cos(math.pi / self.n_polygon)
        # admissible set as G_adm u >= h_adm
        g = np.zeros((self.n_polygon + 2, 3))
        g[: self.n_polygon, :2] = -self._normals
        g[self.n_polygon, 2] = 1.0
        g[self.n_polygon + 1, 2] = -1.0
        self._G_adm = g
        self._G_adm_T = np.ascontiguousarray(g.T)
        self._h_adm = np.concatenate(
            [np.full(self.n_polygon, -self._apothem), [-self.omega_max, -self.omega_max]]
        )
        if backend == "nnls":
            self._tol_fix, self._tol_check = 1e-7, 1e-5
        else:
            self._tol_fix, self._tol_check = 1e-5, 1e-4
        self.n_rebuilds = 0
        self.capacity = 0
        if backend == "osqp":
            self._build(max(1, int(capacity)))

    # ------------------------------------------------------------------ helpers
    def project(self, u: np.ndarray) -> np.ndarray:
        """Projection onto the admissible set (see :func:`project_to_admissible`)."""
        return _project_admissible(
            np.array(u, dtype=np.float64), self.v_max, self.omega_max, self.n_polygon
        )

    def admissible(self, u: np.ndarray, tol: float = 1e-7) -> bool:
        """Whether ``u`` satisfies the polygon and ω bounds up to ``tol``."""
        return bool(np.all(self._G_adm @ u >= self._h_adm - tol))

    def _fixed_lo(
        self, A: np.ndarray, b: np.ndarray, kappa: np.ndarray, u_c: np.ndarray
    ) -> np.ndarray:
        """Lower bounds ``Ã u ≥ lo`` of the rows whose κ* is fixed.

        ``lo = min(−b̃ − κ*, Ã u_c) − tol``: relaxed by the backend's tolerance
        and never above the candidate's own value, so the candidate ``u_c`` (which
        meets every fixed row) is strictly feasible and the next QP cannot be
        infeasible through round-off.
        """
        return np.minimum(-b - kappa, A @ u_c) - self._tol_fix

    # ------------------------------------------------------------------ solve
    def solve(
        self, A: np.ndarray, b: np.ndarray, level: np.ndarray, u_star: np.ndarray
    ) -> QPResult:
        """Solve the hierarchy for rows ``A u + b + κ ≥ 0`` grouped by ``level``.

        Args:
            A: ``(R, 3)`` normalised rows Ã. b: ``(R,)`` normalised offsets b̃.
            level: ``(R,)`` integer priorities, smaller first; negative = hard row.
            u_star: ``(3,)`` desired input ``[vx, vy, ω]``.

        Returns:
            :class:`QPResult` (never raises for non-finite data or solver failures).

        Raises:
            ValueError: inconsistent shapes.
        """
        A = np.asarray(A, dtype=np.float64).reshape(-1, 3)
        b = np.asarray(b, dtype=np.float64).reshape(-1)
        lv = np.asarray(level).reshape(-1)
        if (
            lv.dtype == bool
            or lv.dtype.kind not in "iuf"
            or (lv.dtype.kind == "f" and not (np.isfinite(lv) & (lv == np.round(lv))).all())
        ):
            raise ValueError(f"level must hold integer priorities, got {lv.tolist()!r}")
        level = lv.astype(np.int64)
        u_star = np.asarray(u_star, dtype=np.float64).reshape(-1)
        R = b.shape[0]
        if A.shape[0] != R or level.shape[0] != R or u_star.shape != (3,):
            raise ValueError(
                f"A (R, 3), b (R,), level (R,) and u_star (3,) must agree; got A {A.shape}, "
                f"b {b.shape}, level {level.shape}, u_star {u_star.shape}"
            )
        kappa = np.zeros(R)
        if not (np.isfinite(A).all() and np.isfinite(b).all() and np.isfinite(u_star).all()):
            return QPResult(np.zeros(3), kappa, "invalid_input", fallback=True, levels=level)
        u_c = self.project(u_star)
        if R == 0:
            return QPResult(u_c, kappa, "unconstrained", levels=level)
        t0 = time.perf_counter()
        tol = self._tol_check
        if (A @ u_c + b).min() >= -tol:  # u* (projected) meets every row: no QP
            kappa = np.maximum(0.0, -(A @ u_c + b))
            kappa[level < 0] = 0.0
            values = np.unique(level)
            return QPResult(
                u_c,
                kappa,
                "unconstrained",
                "",
                False,
                0,
                values.size,
                time.perf_counter() - t0,
                0.0,
                level,
                values,
                np.full(values.size, float((u_c - u_star) @ (u_c - u_star))),
            )
        # rows sorted by level: hard rows first, and the fixed rows are always a prefix
        order = np.argsort(level, kind="stable")
        As, bs, ls = A[order], b[order], level[order]
        # a row repeating an earlier (same or higher priority) row is the same constraint:
        # solve without it (duplicates make the QPs degenerate; they arise when several
        # unseen neighbours' estimates converge on the same point under Eq. 20)
        dup = duplicate_rows(As, bs)
        dup_idx = order[dup]
        if dup.any():
            keep = ~dup
            order, As, bs, ls = order[keep], As[keep], bs[keep], ls[keep]
            R = bs.shape[0]

        def expand(u: np.ndarray, ks: np.ndarray) -> np.ndarray:
            out = np.zeros(kappa.shape[0])
            out[order] = ks
            if dup_idx.size:
                out[dup_idx] = np.maximum(0.0, -(A[dup_idx] @ u + b[dup_idx]))
                out[dup_idx[level[dup_idx] < 0]] = 0.0
            return out

        brk = np.flatnonzero(ls[1:] != ls[:-1]) + 1
        starts = np.concatenate(([0], brk)).tolist()
        ends = np.append(brk, R).tolist()
        level_of_row = np.zeros(R, dtype=np.int64)
        level_of_row[brk] = 1
        level_of_row = np.cumsum(level_of_row).tolist()
        nlev = len(starts)
        values = ls[starts]
        start_cost = np.full(nlev, np.nan)
        n_hard = int(np.count_nonzero(ls < 0))
        ks = np.zeros(R)
        if self.backend == "osqp":
            self._load_rows(As)
        done = 0
        n_qp = 0
        qp_status = ""
        degraded = False
        # u_c is the projection of u* onto the rows fixed so far (then Eq. 19 needs no QP)
        is_projection = True
        while done < R:
            res = As[done:] @ u_c + bs[done:]
            bad = np.flatnonzero(res < -tol)
            stop = R if bad.size == 0 else starts[level_of_row[done + int(bad[0])]]
            if is_projection:  # every level in [done, stop] starts from u_c
                hi = nlev if stop == R else level_of_row[stop] + 1
                start_cost[level_of_row[done] : hi] = float((u_c - u_star) @ (u_c - u_star))
            # levels in [done, stop) hold at the candidate: κ* is their (round-off) violation
            lo_s = max(done, n_hard)
            if stop > lo_s:
                ks[lo_s:stop] = np.maximum(0.0, -res[lo_s - done : stop - done])
            done = stop
            if done == R:
                break
            end = ends[level_of_row[done]]
            hard = done < n_hard
            lo_fix = self._fixed_lo(As[:done], bs[:done], ks[:done], u_c)
            # (1) can this level be met exactly (κ_k = 0)? project u* with its rows hard.
            # Skipped when a row is violated by every admissible input (b̃ < −1, since
            # |Ã u| ≤ 1 on the admissible set): the level is certainly infeasible.
            u_new = None
            if hard or bs[done:end].min() >= -1.0:
                lo_try = np.concatenate([lo_fix, -bs[done:end]])
                n_qp += 1
                u_new, qp_status = self._project(As, lo_try, u_star)
                if u_new is not None:
                    u_new = self.project(u_new)  # remove round-off outside the admissible set
                    if (As[:end] @ u_new - lo_try).min() < -tol:
                        u_new = None
            if u_new is None and hard:  # a hard level that cannot be met: brake
                return QPResult(
                    np.zeros(3), expand(u_c, ks), "qp_failed", qp_status, True, n_qp, nlev,
                    time.perf_counter() - t0, 0.0, level, values, start_cost,
                )  # fmt: skip
            if u_new is None:
                # (2) infeasible: minimise the level's violation (Eq. 18)
                n_qp += 1
                u_new, qp_status = self._level(As, bs, lo_fix, done, end, u_star)
                if u_new is None and done:
                    # cannot be infeasible (κ_k is free, u_c meets the fixed rows): a
                    # degenerate, pinned feasible set defeated the solver; retry once with
                    # the fixed rows relaxed by 10 tol_fix (still far below tol_check)
                    n_qp += 1
                    u_new, qp_status = self._level(
                        As, bs, lo_fix - 10.0 * self._tol_fix, done, end, u_star
                    )
                if u_new is not None:
                    u_new = self.project(u_new)
                    if done and (As[:done] @ u_new - lo_fix).min() < -tol:
                        u_new = None
                if u_new is None:  # keep the candidate: it meets every higher level
                    degraded = True
                    u_new = u_c
                    is_projection = False
                # else: the minimiser of ρ‖u − u*‖² + ‖κ_k(u)‖² is also the projection of u*
                # onto the rows with the resulting κ* fixed (module docstring, Eq. 19)
            # κ* of this level; absorb round-off so the candidate meets every fixed row
            neg = -(As[:end] @ u_new + bs[:end])
            if end > n_hard:
                ks[n_hard:done] = np.maximum(ks[n_hard:done], neg[n_hard:done])
                lo_s = max(done, n_hard)
                ks[lo_s:end] = np.maximum(0.0, neg[lo_s:end])
            done = end
            u_c = u_new
        t1 = time.perf_counter()
        if n_qp == 0:
            return QPResult(
                u_c, expand(u_c, ks), "unconstrained", "", False, 0, nlev, t1 - t0, 0.0, level,
                values, start_cost,
            )  # fmt: skip
        if degraded:
            status = "degraded"
        else:
            status = "relaxed" if ks.max() > _KAPPA_REPORT else "solved"
        if is_projection:
            return QPResult(
                u_c, expand(u_c, ks), status, qp_status, degraded, n_qp, nlev, t1 - t0, 0.0, level,
                values, start_cost,
            )  # fmt: skip
        # final QP (Eq. 19) with every κ* fixed
        lo_fix = self._fixed_lo(As, bs, ks, u_c)
        u, qp_status = self._project(As, lo_fix, u_star)
        n_qp += 1
        t2 = time.perf_counter()
        if u is not None:
            u = self.project(u)
            if (As @ u - lo_fix).min() >= -tol:
                return QPResult(
                    u, expand(u, ks), status, qp_status, degraded, n_qp, nlev, t1 - t0, t2 - t1,
                    level, values, start_cost,
                )  # fmt: skip
        # the final QP failed: keep the last cascade solution (it meets every level)
        return QPResult(
            u_c, expand(u_c, ks), "degraded", qp_status, True, n_qp, nlev, t1 - t0, t2 - t1, level,
            values, start_cost,
        )  # fmt: skip

    # ------------------------------------------------------------------ backends
    def _project(self, A, lo, u_star):
        """Projection of u* onto ``{A[:k] u ≥ lo (k = len(lo)), u admissible}`` (Eq. 19 form).

        Returns ``(u or None, status)``; None when infeasible or failed.
        """
        if self.backend == "nnls":
            k = lo.shape[0]
            E = np.empty((4, k + self._G_adm.shape[0]))
            E[:3, :k] = A[:k].T
            E[:3, k:] = self._G_adm_T
            E[3, :k] = lo - A[:k] @ u_star
            E[3, k:] = self._h_adm - self._G_adm @ u_star
            y = _ldp(E)
            return (None, "infeasible") if y is None else (u_star + y, "solved")
        return self._project_osqp(lo, u_star)

    def _level(self, A, b, lo_fix, s, e, u_star):
        """Cascade QP (Eq. 18) of the soft rows ``[s, e)``, rows ``[0, s)`` fixed by
        ``A u ≥ lo_fix``; returns ``(u or None, status)``."""
        if self.backend == "nnls":
            return self._level_nnls(A, b, lo_fix, s, e, u_star)
        return self._level_osqp(A, b, lo_fix, s, e, u_star)

    def _level_nnls(self, A, b, lo_fix, s, e, u_star):
        # y = [sqrt(ρ)(u − u*), κ_k]: ‖y‖² = ρ‖u − u*‖² + ‖κ_k‖²; columns of E are the
        # constraints: level rows (with their κ), fixed rows, admissible set
        sc = 1.0 / math.sqrt(self.reg)
        nc = e - s
        na = self._G_adm.shape[0]
        m = nc + s + na
        E = np.zeros((4 + nc, m))
        E[:3, :nc] = A[s:e].T * sc
        E[:3, nc : nc + s] = A[:s].T * sc
        E[:3, nc + s :] = self._G_adm_T * sc
        E[3 + np.arange(nc), np.arange(nc)] = 1.0
        E[3 + nc, :nc] = -b[s:e] - A[s:e] @ u_star
        E[3 + nc, nc : nc + s] = lo_fix - A[:s] @ u_star
        E[3 + nc, nc + s :] = self._h_adm - self._G_adm @ u_star
        y = _ldp(E)
        return (None, "infeasible") if y is None else (u_star + y[:3] * sc, "solved")

    # ------------------------------------------------------------------ OSQP
    def _settings(self) -> dict:
        return dict(
            eps_abs=self.eps,
            eps_rel=self.eps,
            max_iter=self.max_iter,
            polishing=True,
            warm_starting=True,
            verbose=False,
        )

    def _build(self, R: int) -> None:
        """Create both OSQP problems with room for ``R`` rows (fixed patterns)."""
        self.capacity = R
        npoly = self.n_polygon
        nrm = self._normals
        # cascade: x = [vx, vy, ω, κ_0..κ_{R-1}]; rows: R coupling, R κ-bounds, polygon, ω
        n = 3 + R
        m = 2 * R + npoly + 1
        Pdiag = np.concatenate([np.full(3, self.reg), np.ones(R)])
        P = sp.csc_matrix((Pdiag, np.arange(n), np.arange(n + 1)), shape=(n, n))
        cpl = np.arange(R)
        poly = 2 * R + np.arange(npoly)
        wrow = 2 * R + npoly
        idx = [np.concatenate([cpl, poly]), np.concatenate([cpl, poly]), np.append(cpl, wrow)]
        dat = [
            np.concatenate([np.ones(R), nrm[:, 0]]),
            np.concatenate([np.ones(R), nrm[:, 1]]),
            np.append(np.ones(R), 1.0),
        ]
        for r in range(R):
            idx.append(np.array([r, R + r]))
            dat.append(np.ones(2))
        indptr = np.concatenate([[0], np.cumsum([len(i) for i in idx])])
        self._c_data = np.concatenate(dat)
        Acsc = sp.csc_matrix((self._c_data.copy(), np.concatenate(idx), indptr), shape=(m, n))
        self._c_pos = [indptr[k] + cpl for k in range(3)]
        self._c_l = np.full(m, -_INF)
        self._c_u = np.full(m, _INF)
        self._c_l[R : 2 * R] = 0.0
        self._c_u[R : 2 * R] = 0.0
        self._c_u[poly] = self._apothem
        self._c_l[wrow] = -self.omega_max
        self._c_u[wrow] = self.omega_max
        self._c_q = np.zeros(n)
        self._cas = osqp.OSQP(algebra="builtin")
        self._cas.setup(P, self._c_q, Acsc, self._c_l, self._c_u, **self._settings())
        # final: x = [vx, vy, ω]; rows: R coupling, polygon, ω
        m2 = R + npoly + 1
        P2 = sp.csc_matrix((np.ones(3), np.arange(3), np.arange(4)), shape=(3, 3))
        poly2 = R + np.arange(npoly)
        w2 = R + npoly
        idx2 = [np.concatenate([cpl, poly2]), np.concatenate([cpl, poly2]), np.append(cpl, w2)]
        indptr2 = np.concatenate([[0], np.cumsum([len(i) for i in idx2])])
        self._f_data = np.concatenate(dat[:3])
        A2 = sp.csc_matrix((self._f_data.copy(), np.concatenate(idx2), indptr2), shape=(m2, 3))
        self._f_pos = [indptr2[k] + cpl for k in range(3)]
        self._f_l = np.full(m2, -_INF)
        self._f_u = np.full(m2, _INF)
        self._f_u[poly2] = self._apothem
        self._f_l[w2] = -self.omega_max
        self._f_u[w2] = self.omega_max
        self._fin = osqp.OSQP(algebra="builtin")
        self._fin.setup(P2, np.zeros(3), A2, self._f_l, self._f_u, **self._settings())

    def _load_rows(self, A: np.ndarray) -> None:
        """Write the row coefficients into both patterns (padding rows get zeros)."""
        R = A.shape[0]
        if R > self.capacity:
            self.n_rebuilds += 1
            self._build(max(2 * self.capacity, R))
        Rc = self.capacity
        for data, pos in ((self._c_data, self._c_pos), (self._f_data, self._f_pos)):
            for k in range(3):
                col = np.zeros(Rc)
                col[:R] = A[:, k]
                data[pos[k]] = col
        self._cas.update(Ax=self._c_data)
        self._fin.update(Ax=self._f_data)

    def _level_osqp(self, A, b, lo_fix, s, e, u_star):
        Rc = self.capacity
        lo, hi = self._c_l, self._c_u
        lo[:Rc] = -_INF
        hi[Rc : 2 * Rc] = 0.0
        lo[:s] = lo_fix
        lo[s:e] = -b[s:e]
        hi[Rc + s : Rc + e] = _INF
        self._c_q[:3] = -self.reg * u_star
        self._cas.update(q=self._c_q, l=lo, u=hi)
        res = self._cas.solve(raise_error=False)
        x = res.x
        if x is None or not np.all(np.isfinite(x[:3])):
            return None, res.info.status
        return np.array(x[:3]), res.info.status

    def _project_osqp(self, lo_rows, u_star):
        lo = self._f_l
        lo[: self.capacity] = -_INF
        lo[: lo_rows.shape[0]] = lo_rows
        self._fin.update(q=-u_star, l=lo)
        res = self._fin.solve(raise_error=False)
        x = res.x
        if x is None or not np.all(np.isfinite(x)):
            return None, res.info.status
        return np.array(x), res.info.status
