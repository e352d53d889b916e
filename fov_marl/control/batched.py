"""The FoV-CBF controller for many robots at once: R calls of ``FovCbfController.solve`` in one.

:class:`BatchedFovCbfController` produces, for ``R`` robots, the same outputs as ``R``
independent :class:`~fov_marl.control.FovCbfController` objects (same rows, pruning,
levels, cascade, "keep right" deadlock steering, safe fallback, statuses and counters;
see :mod:`fov_marl.control.controller` for what each step does): the row assembly is
vectorised over ``(R, M)`` and the hierarchies are solved by
:class:`~fov_marl.control.batch_qp.BatchHierarchicalQP`. Nothing of robot r depends on
another robot's data (rows are independent). With ``params.qp_backend == "osqp"`` the
robots are solved one by one by per-robot controllers (OSQP keeps state per robot).

Usage::

    ctrl = BatchedFovCbfController(config, params)
    res = ctrl.solve(u_star, p_body, v_est_body, d, ids, safety=rows, detected=det)
    res.u           # (R, 3) body-frame [vx m/s, vy m/s, ω rad/s]
    res.robot(i)    # the ControlResult FovCbfController.solve would return for robot i
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from fov_marl.config import ScenarioConfig
from fov_marl.control.batch_qp import _BIG_LEVEL, STATUS_CODES, BatchHierarchicalQP, rows_dot
from fov_marl.control.cbf import (
    SAFETY_ROW,
    cbf_rows,
    fov_barrier_lie,
    normalise_rows,
    row_h_max,
)
from fov_marl.control.controller import (
    _YIELD_BOUND_TOL,
    ControlResult,
    FovCbfController,
    approaches_held_row,
    hold_cleanup,
    safe_fallback_inputs,
)
from fov_marl.control.params import STALL_FRACTION, TRANSLATES_FRACTION, ControllerParams
from fov_marl.control.safety import (
    SafetyRows,
    arc_yaw_guard,
    invalid_rows,
    safety_triple,
    team_safety_rows,
)

__all__ = ["BatchControlResult", "BatchedFovCbfController", "CONTROL_STATUSES"]

_FOV_ROWS = np.array([True, True, False, True])
_KAPPA_SAFETY = 1e-3
#: status strings of :class:`~fov_marl.control.ControlResult`, by code
CONTROL_STATUSES = STATUS_CODES + ("safety_fallback",)
_UNC, _INV, _FAIL, _SFB = 0, 4, 5, 6


def _translates(u_star: np.ndarray, v_max: float) -> np.ndarray:
    """``(R,)`` u* translates: ``‖v*‖ ≥ 0.1 v_max`` (:meth:`FovCbfController._translates`)."""
    return np.hypot(u_star[:, 0], u_star[:, 1]) >= TRANSLATES_FRACTION * v_max


def _stalled(
    u: np.ndarray, u_star: np.ndarray, v_max: float, fraction: float | np.ndarray = STALL_FRACTION
) -> np.ndarray:
    """``(R,)`` robots whose solution keeps less than ``fraction`` (a fifth, or ``(R,)``)
    of u*'s translation (``u_v · v̂* < 0.2 ‖v*‖``) while u* translates: the trigger of
    "keep right" and of the lost neighbours' yield (:meth:`FovCbfController._stalled`)."""
    vs = u_star[:, :2]
    speed = np.hypot(vs[:, 0], vs[:, 1])
    return (speed >= TRANSLATES_FRACTION * v_max) & (
        np.einsum("rk,rk->r", u[:, :2], vs) < fraction * speed * speed
    )


def _adopt(qres, alt, rows: np.ndarray, use: np.ndarray) -> None:
    """Copy the re-solved robots ``alt[use]`` into ``qres[rows]`` (in place; ``qres.u`` is
    copied first so a caller's array is never written)."""
    qres.u = qres.u.copy()
    for f in ("u", "kappa", "status", "qp_status", "fallback", "n_qp", "n_levels"):
        getattr(qres, f)[rows] = getattr(alt, f)[use]


@dataclass
class BatchControlResult:
    """Outcome of :meth:`BatchedFovCbfController.solve` for ``R`` robots with ``M`` neighbours.

    The fields of :class:`~fov_marl.control.ControlResult` with a leading robot axis:
    ``u (R, 3)``, ``u_star (R, 3)``, ``status (R,)`` int codes into
    :data:`CONTROL_STATUSES` (``status_names``: the strings), ``fallback``, ``intervened``
    ``(R,)`` bool, ``kappa``, ``active``, ``level`` ``(R, M, 4)``, ``n_levels``, ``n_qp``
    ``(R,)`` int, ``qp_status (R,)`` object, ``safety_violation``, ``cone_violation`` ``(R,)``,
    ``yielded (R,)`` bool, ``unblocked (R,)`` bool, and ``timings`` (team seconds: ``rows``, ``cascade``, ``total``).
    """

    u: np.ndarray
    u_star: np.ndarray
    status: np.ndarray
    fallback: np.ndarray
    intervened: np.ndarray
    kappa: np.ndarray
    active: np.ndarray
    level: np.ndarray
    n_levels: np.ndarray
    n_qp: np.ndarray
    qp_status: np.ndarray
    safety_violation: np.ndarray
    cone_violation: np.ndarray
    yielded: np.ndarray
    unblocked: np.ndarray
    timings: dict

    @property
    def n_robots(self) -> int:
        return self.u.shape[0]

    @property
    def status_names(self) -> np.ndarray:
        """``(R,)`` object array of status strings."""
        return np.asarray(CONTROL_STATUSES, dtype=object)[self.status]

    def robot(self, i: int) -> ControlResult:
        """Robot ``i``'s :class:`~fov_marl.control.ControlResult` (timings: team shares)."""
        share = {k: v / max(self.n_robots, 1) for k, v in self.timings.items()}
        return ControlResult(
            u=self.u[i].copy(),
            u_star=self.u_star[i].copy(),
            status=CONTROL_STATUSES[int(self.status[i])],
            fallback=bool(self.fallback[i]),
            intervened=bool(self.intervened[i]),
            kappa=self.kappa[i].copy(),
            active=self.active[i].copy(),
            level=self.level[i].copy(),
            n_levels=int(self.n_levels[i]),
            n_qp=int(self.n_qp[i]),
            qp_status=str(self.qp_status[i]),
            safety_violation=float(self.safety_violation[i]),
            cone_violation=float(self.cone_violation[i]),
            yielded=bool(self.yielded[i]),
            unblocked=bool(self.unblocked[i]),
            timings=share,
        )

    @classmethod
    def from_results(cls, results: list[ControlResult], t_total: float) -> BatchControlResult:
        """Stack per-robot results (the osqp path)."""
        code = {s: k for k, s in enumerate(CONTROL_STATUSES)}
        return cls(
            u=np.stack([r.u for r in results]),
            u_star=np.stack([r.u_star for r in results]),
            status=np.array([code[r.status] for r in results], dtype=np.int64),
            fallback=np.array([r.fallback for r in results], dtype=bool),
            intervened=np.array([r.intervened for r in results], dtype=bool),
            kappa=np.stack([r.kappa for r in results]),
            active=np.stack([r.active for r in results]),
            level=np.stack([r.level for r in results]),
            n_levels=np.array([r.n_levels for r in results], dtype=np.int64),
            n_qp=np.array([r.n_qp for r in results], dtype=np.int64),
            qp_status=np.array([r.qp_status for r in results], dtype=object),
            safety_violation=np.array([r.safety_violation for r in results]),
            cone_violation=np.array([r.cone_violation for r in results]),
            yielded=np.array([r.yielded for r in results], dtype=bool),
            timings={"rows": 0.0, "cascade": 0.0, "total": t_total},
            unblocked=np.array([r.unblocked for r in results], dtype=bool),
        )


class BatchedFovCbfController:
    """``R`` :class:`~fov_marl.control.FovCbfController` s in one (see the module docstring).

    Args:
        config: scenario. params: controller knobs (default :class:`ControllerParams`).

    Attributes:
        stats: team totals since construction (same keys as ``FovCbfController.stats``).
    """

    def __init__(
        self, config: ScenarioConfig, params: ControllerParams | dict | None = None
    ) -> None:
        # the per-robot controller validates the config and parameters, holds the cone rows
        self._ref = FovCbfController(config, params)
        self.config = config
        self.params = self._ref.params
        p = self.params
        self.h_max = row_h_max(config, p.fov_margin_m)
        # the motion-cone rows exactly as the per-robot controller normalises them
        self._cone_A = self._ref._cone_A
        self._cone_b = self._ref._cone_b
        self._cone_half_angle = self._ref._cone_half_angle
        self._w = float(p.omega_weight)
        self.qp = BatchHierarchicalQP(
            config.v_max_mps, config.omega_max_radps * self._w, p.n_polygon, p.cascade_reg
        )
        self._loop: list[FovCbfController] = []
        self.stats = {k: 0 for k in self._ref.stats}

    # ------------------------------------------------------------------ helpers
    def _project(self, u: np.ndarray) -> np.ndarray:
        w = self._w
        uw = np.array(u, dtype=np.float64, copy=True)
        uw[:, 2] *= w
        out = self.qp.project(uw)
        out[:, 2] /= w
        return out

    def _qp_solve(self, A, b, level, valid, u_star):
        w = self._w
        if w == 1.0:
            return self.qp.solve(A, b, level, u_star, valid)
        A_w = np.array(A, dtype=np.float64, copy=True)
        A_w[..., 2] /= w
        us = np.array(u_star, dtype=np.float64, copy=True)
        us[:, 2] *= w
        res = self.qp.solve(A_w, b, level, us, valid)
        res.u = res.u.copy()
        res.u[:, 2] /= w
        return res

    def look_where_you_go(self, u_star: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`FovCbfController.look_where_you_go` for ``(R, 3)``; returns ``(u, changed)``."""
        p, cfg = self.params, self.config
        fast = np.hypot(u_star[:, 0], u_star[:, 1]) > p.blind_speed_mps
        phi = np.arctan2(u_star[:, 1], u_star[:, 0])
        chg = fast & (np.abs(phi) > self._cone_half_angle)
        out = u_star.copy()
        out[chg, 2] = np.clip(p.look_gain * phi[chg], -cfg.omega_max_radps, cfg.omega_max_radps)
        return out, chg

    def assign_levels(self, active, d, ids, r, bonus=None) -> np.ndarray:
        """:meth:`FovCbfController.assign_levels` for ``(R, M, 4)`` rows at once."""
        p = self.params
        R, M = d.shape
        level = np.full((R, M, 4), -2, dtype=np.int64)
        if M == 0 or R == 0:
            return level
        robot = np.repeat(np.arange(R), M)
        key = d if bonus is None else d - bonus
        order = np.lexsort((ids.reshape(-1), r.reshape(-1), key.reshape(-1), robot))
        per_nb_rows = _FOV_ROWS if p.safety_first else np.ones(4, dtype=bool)
        cand = np.any(active & per_nb_rows, axis=2).reshape(-1)[order]
        cs = np.cumsum(cand).reshape(R, M)
        base = np.concatenate([[0], cs[:-1, -1]])
        rank = (cs - base[:, None]).reshape(-1) - 1
        nb_level = np.empty(R * M, dtype=np.int64)
        nb_level[order] = 1 + np.minimum(rank, p.max_levels - 1)
        level[:] = nb_level.reshape(R, M)[..., None]
        beyond = np.empty(R * M, dtype=bool)
        beyond[order] = rank >= p.max_fov_neighbours
        level[beyond.reshape(R, M)[..., None] & _FOV_ROWS[None, None, :]] = -2
        if p.safety_hard:
            level[..., SAFETY_ROW] = -1
        elif p.safety_first:
            level[..., SAFETY_ROW] = 0
        level[~active] = -2
        return level

    def _safety(self, safety, p_body, v_est):
        """Normalised collision rows ``(A (R,K,3), b (R,K), kind (R,K), keep (R,K))`` and
        ``(R,)`` the robots given an invalid row (non-finite coefficients, b NaN or −inf:
        the invalid-input fallback; b = +inf is a row that never binds)."""
        p, cfg = self.params, self.config
        R, M = p_body.shape[:2]
        if p.safety_model != "ellipse" or (safety is None and M == 0):
            no_rows = np.zeros((R, 0, 3)), np.zeros((R, 0)), np.zeros((R, 0), np.int8), None
            return *no_rows, np.zeros(R, dtype=bool)
        if safety is None:
            safety = team_safety_rows(
                cfg,
                p,
                mean_body=p_body,
                cov_body=np.zeros((R, M, 2, 2)),
                detected=np.ones((R, M), dtype=bool),
                velocity_est_body=v_est,
                blind=False,
            )
        A, b, kind = safety_triple(safety)
        A = np.asarray(A, dtype=np.float64)
        b = np.asarray(b, dtype=np.float64)
        kind = np.asarray(kind)
        if A.ndim != 3 or A.shape[0] != R or A.shape[2] != 3 or b.shape != A.shape[:2]:
            raise ValueError(
                f"safety rows must be A (R, K, 3), b (R, K), kind (R, K) with R = {R}; got "
                f"{A.shape}, {b.shape}, {kind.shape}"
            )
        if kind.shape != b.shape:
            raise ValueError(f"safety kind must have shape {b.shape}, got {kind.shape}")
        bad = ((kind >= 0) & invalid_rows(A, b)).any(axis=1)
        At, bt, _ = normalise_rows(A, b, cfg.v_max_mps, cfg.omega_max_radps, p.row_clip)
        keep = (kind >= 0) & (bt < 1.0 if p.prune else np.isfinite(b))
        return At, bt, kind, keep, bad

    def _rows(self, p_body, v_est, d, u_star, detected):
        """cbf_rows over all robots: ``(A (R,M,4,3), b (R,M,4), h (R,M,4))``.

        ``cbf_rows`` takes one desired velocity; its recovery term ``min(0, A_v · v*)``
        is added here per robot to the rows it reduced (those whose translational
        coefficients it zeroed), exactly as ``cbf_rows`` adds it.
        """
        cfg, p = self.config, self.params
        R, M = d.shape
        pf = p_body.reshape(-1, 2)
        vf = v_est.reshape(-1, 2)
        det = None if detected is None else detected.reshape(-1)
        rows = cbf_rows(pf, vf, d.reshape(-1), cfg, p, self.h_max, None, det)
        A, b, h = rows.A, rows.b, rows.h
        if p.fov_recovery_cap > 0.0:
            A0, _ = fov_barrier_lie(pf, vf, cfg.fov_rad)
            reduced = np.any(A[..., 0:2] != A0[..., 0:2], axis=-1) & np.isfinite(b)
            if reduced.any():
                vd = np.repeat(u_star[:, :2], M, axis=0)
                harm = np.minimum(0.0, A0[..., 0] * vd[:, 0:1] + A0[..., 1] * vd[:, 1:2])
                b = np.where(reduced, b + harm, b)
        return A.reshape(R, M, 4, 3), b.reshape(R, M, 4), h.reshape(R, M, 4)

    # ------------------------------------------------------------------ solve
    def solve(
        self,
        u_star: np.ndarray,
        p_body: np.ndarray,
        v_est_body: np.ndarray,
        d: np.ndarray,
        ids: np.ndarray | None = None,
        safety: SafetyRows | tuple | None = None,
        detected: np.ndarray | None = None,
        fov_yield: np.ndarray | None = None,
        priority_bonus: np.ndarray | None = None,
        glance: np.ndarray | None = None,
        yield_latched: np.ndarray | None = None,
        unblock_latched: np.ndarray | None = None,
    ) -> BatchControlResult:
        """``FovCbfController.solve`` for every robot (arguments with a leading robot axis).

        Args:
            u_star: ``(R, 3)``; p_body, v_est_body: ``(R, M, 2)``; d: ``(R, M)``;
            ids: ``(R, M)`` tie-breakers (default ``arange(M)``); safety: the robots'
            :class:`~fov_marl.control.safety.SafetyRows` (or ``(A (R,K,3), b (R,K),
            kind (R,K))``; None: from ``p_body`` as exact); detected: ``(R, M)`` bool or None;
            fov_yield: ``(R, M)`` bool or None; priority_bonus: ``(R, M)`` m or None;
            glance, yield_latched, unblock_latched: ``(R,)`` bool or None (see
            ``FovCbfController.solve``).

        Raises:
            ValueError: shapes that do not match.
        """
        t0 = time.perf_counter()
        cfg, p = self.config, self.params
        u_star = np.asarray(u_star, dtype=np.float64)
        p_body = np.asarray(p_body, dtype=np.float64)
        v_est_body = np.asarray(v_est_body, dtype=np.float64)
        d = np.asarray(d, dtype=np.float64)
        if u_star.ndim != 2 or u_star.shape[1] != 3:
            raise ValueError(f"u_star must have shape (R, 3), got {u_star.shape}")
        R = u_star.shape[0]
        if p_body.ndim != 3 or p_body.shape[0] != R or p_body.shape[2] != 2:
            raise ValueError(f"p_body must have shape ({R}, M, 2), got {p_body.shape}")
        M = p_body.shape[1]
        if v_est_body.shape != (R, M, 2):
            raise ValueError(f"v_est_body must have shape ({R}, {M}, 2), got {v_est_body.shape}")
        if d.shape != (R, M):
            raise ValueError(f"d must have shape ({R}, {M}), got {d.shape}")
        if ids is None:
            ids = np.broadcast_to(np.arange(M), (R, M))
        else:
            ids = np.asarray(ids)
            if ids.shape != (R, M):
                raise ValueError(f"ids must have shape ({R}, {M}), got {ids.shape}")
        if detected is not None:
            detected = np.asarray(detected, dtype=bool)
            if detected.shape != (R, M):
                raise ValueError(f"detected must have shape ({R}, {M}), got {detected.shape}")
        if fov_yield is not None:
            fov_yield = np.asarray(fov_yield, dtype=bool)
            if fov_yield.shape != (R, M):
                raise ValueError(f"fov_yield must have shape ({R}, {M}), got {fov_yield.shape}")
        if glance is not None:
            glance = np.asarray(glance, dtype=bool)
            if glance.shape != (R,):
                raise ValueError(f"glance must have shape ({R},), got {glance.shape}")
        if yield_latched is not None:
            yield_latched = np.asarray(yield_latched, dtype=bool)
            if yield_latched.shape != (R,):
                raise ValueError(f"yield_latched must have shape ({R},), got {yield_latched.shape}")
        if unblock_latched is not None:
            unblock_latched = np.asarray(unblock_latched, dtype=bool)
            if unblock_latched.shape != (R,):
                raise ValueError(
                    f"unblock_latched must have shape ({R},), got {unblock_latched.shape}"
                )
        if p.qp_backend != "nnls":
            return self._solve_loop(
                u_star,
                p_body,
                v_est_body,
                d,
                ids,
                safety,
                detected,
                t0,
                fov_yield,
                glance,
                priority_bonus,
                yield_latched,
                unblock_latched,
            )
        self.stats["steps"] += R
        finite = (
            np.isfinite(u_star).all(1)
            & np.isfinite(p_body).all((1, 2))
            & np.isfinite(v_est_body).all((1, 2))
            & np.isfinite(d).all(1)
        )
        if not finite.all():  # compute on zeros, overwrite with the fallback below
            u_star_c = np.where(finite[:, None], u_star, 0.0)
            p_body = np.where(finite[:, None, None], p_body, 1.0)
            v_est_body = np.where(finite[:, None, None], v_est_body, 0.0)
            d = np.where(finite[:, None], d, 1.0)
        else:
            u_star_c = u_star
        u_given = u_star_c
        n_cone = self._cone_b.shape[0] if M else 0
        if n_cone and p.look_gain > 0.0:
            us, _ = self.look_where_you_go(u_star_c)
        else:
            us = u_star_c
        A, b, _h = self._rows(p_body, v_est_body, d, us, detected)
        At, bt, _ = normalise_rows(A, b, cfg.v_max_mps, cfg.omega_max_radps, p.row_clip)
        active = bt < 1.0 if p.prune else np.isfinite(_h)
        sA, sb, sk, skeep, bad_rows = self._safety(safety, p_body, v_est_body)
        if skeep is None:
            skeep = np.zeros(sb.shape, dtype=bool)
        if not finite.all() and sb.shape[1]:
            sA = np.where(finite[:, None, None], sA, 0.0)
            sb = np.where(finite[:, None], sb, 1.0)
            skeep = skeep & finite[:, None]
        if p.safety_model == "ellipse":
            active[..., SAFETY_ROW] = False
        if glance is not None and glance.any():
            active &= ~(glance[:, None, None] & _FOV_ROWS)
        u_proj = self._project(us)
        n_s = skeep.sum(axis=1)
        cone_ok = np.ones(R, dtype=bool)
        if n_cone:
            cone_ok = (rows_dot(u_proj, self._cone_A) + self._cone_b).min(axis=1) >= 0.0
        unc = ~active.any(axis=(1, 2)) & (n_s == 0) & cone_ok
        level_all = self.assign_levels(
            active, d, ids, np.hypot(p_body[..., 0], p_body[..., 1]), priority_bonus
        )
        level_all[unc] = -2
        active = np.where(unc[:, None, None], active, level_all > -2)
        # QP rows: active FoV rows (row-major), cone rows, kept collision rows
        t1 = time.perf_counter()
        qi = np.flatnonzero(~unc & finite)
        res_u = u_proj.copy()
        status = np.full(R, _UNC, dtype=np.int64)
        fallback = np.zeros(R, dtype=bool)
        n_qp = np.zeros(R, dtype=np.int64)
        n_lev = np.zeros(R, dtype=np.int64)
        qp_status = np.full(R, "", dtype=object)
        kappa = np.zeros((R, M, 4))
        safety_kappa = np.zeros(R)
        n_relaxed = 0
        cone_v = np.zeros(R)
        yielded = np.zeros(R, dtype=bool)
        unblocked = np.zeros(R, dtype=bool)
        level_out = level_all
        if qi.size:
            nq = qi.size
            lv = level_all[qi].reshape(nq, M * 4)
            actq = active[qi].reshape(nq, M * 4)
            Aq = At[qi].reshape(nq, M * 4, 3)
            bq = bt[qi].reshape(nq, M * 4)
            if n_cone:
                if p.safety_first or p.safety_hard:
                    lv = np.where(lv >= 1, lv + 1, lv)
                    level_out = level_all.copy()
                    sub = level_out[qi]
                    sub[sub >= 1] += 1
                    level_out[qi] = sub
                    l_cone = np.ones(nq, dtype=np.int64)
                else:
                    l_cone = np.where(actq, lv, 0).max(axis=1, initial=0) + 1
                Aq = np.concatenate([Aq, np.broadcast_to(self._cone_A, (nq, n_cone, 3))], 1)
                bq = np.concatenate([bq, np.broadcast_to(self._cone_b, (nq, n_cone))], 1)
                lv = np.concatenate([lv, np.repeat(l_cone[:, None], n_cone, 1)], 1)
                actq = np.concatenate([actq, np.ones((nq, n_cone), dtype=bool)], 1)
            n_fov_slots = Aq.shape[1]
            K = sb.shape[1]
            if K:
                l_s = -1 if p.safety_hard else 0
                Aq = np.concatenate([Aq, sA[qi]], 1)
                bq = np.concatenate([bq, sb[qi]], 1)
                lv = np.concatenate([lv, np.full((nq, K), l_s, dtype=np.int64)], 1)
                actq = np.concatenate([actq, skeep[qi]], 1)
            usq = us[qi]
            qres = self._qp_solve(Aq, bq, lv, actq, usq)
            if K and p.deadlock_turn_deg > 0.0:
                ulatch = None if unblock_latched is None else unblock_latched[qi]
                unblocked[qi] = self._unblock(
                    qres, Aq, bq, lv, actq, usq, n_fov_slots, skeep[qi], ulatch
                )
            if fov_yield is not None and fov_yield[qi].any():
                lost = np.zeros(actq.shape, dtype=bool)
                fov_slot = np.tile(_FOV_ROWS, M)  # never an Eq. 12 safety row
                lost[:, : M * 4] = np.repeat(fov_yield[qi], 4, axis=1) & actq[:, : M * 4] & fov_slot
                latch = None if yield_latched is None else yield_latched[qi]
                yielded[qi] = self._yield_lost(qres, Aq, bq, lv, actq, usq, lost, latch)
            res_u[qi] = qres.u
            kq = np.where(actq, qres.kappa, 0.0)
            kappa[qi] = kq[:, : M * 4].reshape(nq, M, 4)
            status[qi] = qres.status
            n_relaxed = int(np.count_nonzero(qres.status == 2))
            fallback[qi] = qres.fallback
            n_qp[qi] = qres.n_qp
            n_lev[qi] = qres.n_levels
            qp_status[qi] = qres.qp_status
            safety_kappa[qi] = kq[:, n_fov_slots:].max(axis=1, initial=0.0)
            cone_v[qi] = kq[:, M * 4 : n_fov_slots].max(axis=1, initial=0.0)
            if K:
                sf = (n_s[qi] > 0) & ((safety_kappa[qi] > _KAPPA_SAFETY) | (qres.status == _FAIL))
                creep = ~sf & (n_s[qi] > 0) & p.hold_cleanup
                creep &= approaches_held_row(qres.u, sA[qi], sb[qi], skeep[qi])
                for c in np.flatnonzero(creep):  # rare: robot by robot, as the loop does
                    r, kk = qi[c], skeep[qi[c]]
                    fixed = hold_cleanup(res_u[r], sA[r][kk], sb[r][kk], cfg.v_max_mps, p.n_polygon)
                    if fixed is None:
                        sf[c] = True
                    else:
                        res_u[r] = fixed
                if sf.any():
                    f = qi[sf]
                    u_qp = np.where((qres.status[sf] == _FAIL)[:, None], np.nan, qres.u[sf])
                    res_u[f] = self._safe_fallback(u_qp, sA[f], sb[f], sk[f], skeep[f], us[f])
                    status[f] = _SFB
                    fallback[f] = True
                    self.stats["safety_fallbacks"] += int(f.size)
                if p.arc_yaw_guard:  # safety Section 1c: the step's arc
                    res_u[qi] = arc_yaw_guard(
                        res_u[qi], sA[qi], sb[qi], sk[qi], skeep[qi], cfg.dt_s,
                        stop_weight=self._w if p.arc_guard_stop else None,
                    )  # fmt: skip
        t2 = time.perf_counter()
        du = res_u - self._project(u_given)
        intervened = np.sqrt(np.einsum("rk,rk->r", du, du)) > p.intervention_tol
        intervened[unc] = False
        safety_v = np.maximum(kappa[..., SAFETY_ROW].max(axis=1, initial=0.0), safety_kappa)
        # invalid inputs
        bad = ~finite | bad_rows
        if bad.any():
            res_u[bad] = 0.0
            status[bad] = _INV
            fallback[bad] = True
            intervened[bad] = True
            kappa[bad] = 0.0
            active[bad] = False
            level_out = level_out.copy() if level_out is level_all else level_out
            level_out[bad] = -2
            n_qp[bad] = 0
            n_lev[bad] = 0
            qp_status[bad] = ""
            safety_v[bad] = 0.0
            cone_v[bad] = 0.0
            yielded[bad] = False
            unblocked[bad] = False
        st = self.stats
        st["qp_solves"] += int(n_qp.sum())
        st["fallbacks"] += int(fallback.sum())
        st["interventions"] += int(np.count_nonzero(intervened & finite))
        st["relaxed"] += n_relaxed
        return BatchControlResult(
            u=res_u,
            u_star=u_star,
            status=status,
            fallback=fallback,
            intervened=intervened,
            kappa=kappa,
            active=active,
            level=level_out,
            n_levels=n_lev,
            n_qp=n_qp,
            qp_status=qp_status,
            safety_violation=safety_v,
            cone_violation=cone_v,
            yielded=yielded,
            timings={"rows": t1 - t0, "cascade": t2 - t1, "total": time.perf_counter() - t0},
            unblocked=unblocked,
        )

    def _unblock(self, qres, Aq, bq, lv, actq, usq, n_fov, skeep, latched=None) -> np.ndarray:
        """:meth:`FovCbfController._unblock` for the robots that need it (in place on qres);
        ``latched``: ``(nq,)`` bool or None, its hysteresis. Returns ``(nq,)`` bool, the
        robots that kept right."""
        vs = usq[:, :2]
        u = qres.u
        out = np.zeros(u.shape[0], dtype=bool)
        fraction = (
            STALL_FRACTION
            if latched is None
            else np.where(latched, self.params.deadlock_release, STALL_FRACTION)
        )
        cand = (
            _stalled(u, usq, self.config.v_max_mps, fraction) & ~qres.fallback & skeep.any(axis=1)
        )
        if not cand.any():
            return out
        srow = np.einsum("rkn,rn->rk", Aq[:, n_fov:], u) + bq[:, n_fov:]
        binding = ((srow < 1e-3) & actq[:, n_fov:]).any(axis=1)
        cand &= binding
        if not cand.any():
            return out
        c_i = np.flatnonzero(cand)
        a = -math.radians(self.params.deadlock_turn_deg)
        c, s_ = math.cos(a), math.sin(a)
        v = vs[c_i]
        u_turn = np.stack([c * v[:, 0] - s_ * v[:, 1], s_ * v[:, 0] + c * v[:, 1], usq[c_i, 2]], -1)
        alt = self._qp_solve(Aq[c_i], bq[c_i], lv[c_i], actq[c_i], u_turn)
        gain_alt = np.einsum("rk,rk->r", alt.u[:, :2], u_turn[:, :2])
        gain_cur = np.einsum("rk,rk->r", u[c_i, :2], u_turn[:, :2])
        use = ~alt.fallback & ~(gain_alt <= gain_cur + 1e-9)
        if not use.any():
            return out
        _adopt(qres, alt, c_i[use], use)
        out[c_i[use]] = True
        return out

    def _yield_lost(self, qres, Aq, bq, lv, actq, usq, lost, latched=None) -> np.ndarray:
        """:meth:`FovCbfController._yield_lost` for the robots that need it (in place on qres);
        returns ``(nq,)`` bool, the robots whose lost rows yielded."""
        u = qres.u
        trigger = _stalled(u, usq, self.config.v_max_mps)
        if latched is not None and self.params.lost_fov_yield_latch:
            moving = _translates(usq, self.config.v_max_mps)
            trigger = np.where(latched, moving, trigger)
        cand = trigger & ~qres.fallback & lost.any(axis=1)
        yielded = np.zeros(u.shape[0], dtype=bool)
        if not cand.any():
            return yielded
        wt = np.array([1.0, 1.0, self._w * self._w])
        c_i = np.flatnonzero(cand)
        cost_cur = rows_dot((u[c_i] - usq[c_i]) ** 2, wt)
        # the per-robot bound: the re-solve keeps every level above the first lost row's,
        # so it costs at least the candidate that reached that level (the hierarchy for
        # u*, before "keep right": _adopt leaves these fields as they were)
        first = np.where(lost[c_i], lv[c_i], _BIG_LEVEL).min(axis=1)
        ls = qres.level_sorted[c_i]
        at = ls >= first[:, None]
        j = np.argmax(at, axis=1)
        bound = np.where(at.any(axis=1), qres.level_start_cost[c_i, j], np.nan)
        skip = bound - 0.5 * cost_cur > _YIELD_BOUND_TOL  # NaN: no skip
        if skip.all():
            return yielded
        c_i, cost_cur = c_i[~skip], cost_cur[~skip]
        alt = self._qp_solve(Aq[c_i], bq[c_i], lv[c_i], actq[c_i] & ~lost[c_i], usq[c_i])
        cost_alt = rows_dot((alt.u - usq[c_i]) ** 2, wt)
        use = ~alt.fallback & (cost_alt <= 0.5 * cost_cur)
        if not use.any():
            return yielded
        alt.n_qp = alt.n_qp + qres.n_qp[c_i]
        alt.kappa = np.where(lost[c_i], 0.0, alt.kappa)
        _adopt(qres, alt, c_i[use], use)
        yielded[c_i[use]] = True
        return yielded

    def _safe_fallback(self, u_qp, A, b, kind, keep, u_star=None) -> np.ndarray:
        """:meth:`FovCbfController._safe_fallback` for ``(F,)`` robots (u_qp NaN rows: None)."""
        p = self.params
        return safe_fallback_inputs(
            u_qp, A, b, kind, keep, p.look_gain, self.config.omega_max_radps,
            p.fallback_tie_mps, p.fallback_straight, p.fallback_escape, self.config.v_max_mps,
            p.n_polygon, u_star,
        )  # fmt: skip

    def _solve_loop(
        self, u_star, p_body, v_est, d, ids, safety, detected, t0, fov_yield=None, glance=None,
        bonus=None, latched=None, unblock_latched=None,
    ):  # fmt: skip
        """One per-robot controller per robot (the osqp backend)."""
        R = u_star.shape[0]
        while len(self._loop) < R:
            self._loop.append(FovCbfController(self.config, self.params))
        if safety is not None and not isinstance(safety, SafetyRows):
            A, b, kind = safety_triple(safety)
            safety = SafetyRows(A, b, kind, np.zeros(b.shape))
        out = []
        for i in range(R):
            out.append(
                self._loop[i].solve(
                    u_star[i], p_body[i], v_est[i], d[i], ids[i],
                    safety=None if safety is None else safety.robot(i),
                    detected=None if detected is None else detected[i],
                    fov_yield=None if fov_yield is None else fov_yield[i],
                    priority_bonus=None if bonus is None else bonus[i],
                    glance=False if glance is None else bool(glance[i]),
                    yield_latched=False if latched is None else bool(latched[i]),
                    unblock_latched=False if unblock_latched is None else bool(unblock_latched[i]),
                )
            )  # fmt: skip
        for k in self.stats:
            self.stats[k] = sum(c.stats[k] for c in self._loop)
        return BatchControlResult.from_results(out, time.perf_counter() - t0)
