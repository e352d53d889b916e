"""Benchmarks of the control layer: per robot-step time of Lloyd, cascade and final QP.

:func:`bench_control` runs a closed-loop coverage episode per team size with a
*synthetic* neighbour tracker (so the numbers isolate the control layer): detected
neighbours are known to 0.3 m; an undetected neighbour's estimate follows the
motion model of Eq. 20 (gain 0.5 toward q_m, as the authors) and its standard
deviation grows by 0.5 m per √step (the authors' process noise), capped at the
arena's uniform spread L/√12, giving a 95% ellipse (χ² = 5.991) whose distance
d_ij (0 inside) feeds the slack. Every robot runs its own
:class:`~fov_marl.control.controller.FovCbfController` on its own estimates; the
world is integrated exactly (:func:`~fov_marl.geometry.integrate_unicycle`).

(The safety filter over B env copies, looped against batched, is timed by
:func:`fov_marl.bench.bench_batched_filter`: it drives envs, above this layer.)

:func:`bench_lloyd_resolution` justifies the Lloyd stencil spacing: centroid error
against the polar-quadrature reference versus time.
"""

from __future__ import annotations

import math
import time

import numpy as np

from fov_marl.config import ScenarioConfig, make_config
from fov_marl.control.controller import FovCbfController
from fov_marl.control.coverage import (
    coverage_centroid_reference,
    coverage_centroids,
    coverage_desired_input,
    coverage_desired_inputs,
    lloyd_stencil,
)
from fov_marl.control.params import ControllerParams
from fov_marl.control.qp import HierarchicalQP
from fov_marl.geometry import CHI2_95_2DOF, in_fov, integrate_unicycle, world_to_body

__all__ = [
    "random_poses",
    "SyntheticTracker",
    "bench_control",
    "bench_lloyd_resolution",
    "bench_qp_backends",
]


def random_poses(
    n: int, config: ScenarioConfig, rng: np.random.Generator, min_sep: float | None = None
) -> np.ndarray:
    """``(n, 3)`` random world poses inside the arena, pairwise ≥ ``min_sep`` apart."""
    sep = config.init_min_separation_m if min_sep is None else min_sep
    L, r = config.arena_size_m, config.robot_radius_m
    pts: list[np.ndarray] = []
    while len(pts) < n:
        c = rng.uniform(r + 0.5, L - r - 0.5, 2)
        if all(np.hypot(*(c - q)) >= sep for q in pts):
            pts.append(c)
    yaw = rng.uniform(-math.pi, math.pi, n)
    return np.column_stack([np.array(pts), yaw])


class SyntheticTracker:
    """Stand-in for the particle-filter bank of every robot (see module docstring).

    Arrays are ``(N, N, ...)`` indexed ``[i, j]`` = robot i's estimate of robot j.
    """

    def __init__(self, poses: np.ndarray, config: ScenarioConfig) -> None:
        n = poses.shape[0]
        self.config = config
        self.est_world = np.broadcast_to(poses[None, :, :2], (n, n, 2)).copy()
        self.sigma = np.full((n, n), 0.3)

    def step(self, poses: np.ndarray, rng: np.random.Generator) -> None:
        """Predict every estimate with Eq. 20, then correct the detected ones."""
        cfg = self.config
        qm = np.asarray(cfg.density_mean_m)
        v = -0.5 * (self.est_world - qm)
        sp = np.hypot(v[..., 0], v[..., 1])
        v *= np.minimum(1.0, cfg.v_max_mps / np.maximum(sp, 1e-12))[..., None]
        self.est_world += cfg.dt_s * v
        self.sigma = np.minimum(np.hypot(self.sigma, 0.5), cfg.arena_size_m / math.sqrt(12.0))
        p_body = world_to_body(poses[None, :, :2], poses[:, None, :])
        seen = in_fov(p_body, cfg.fov_rad, cfg.detection_range_m)
        noisy = poses[None, :, :2] + rng.normal(0.0, 0.1, self.est_world.shape)
        self.est_world = np.where(seen[..., None], noisy, self.est_world)
        self.sigma = np.where(seen, 0.3, self.sigma)

    def estimate(self, i: int, pose_i: np.ndarray) -> tuple[np.ndarray, ...]:
        """Robot i's view: ``ids, mean_body (M, 2), v_est_body (M, 2), d (M,)``."""
        cfg = self.config
        n = self.est_world.shape[0]
        ids = np.array([j for j in range(n) if j != i], dtype=np.int64)
        mean_w = self.est_world[i, ids]
        mean_b = world_to_body(mean_w, pose_i)
        qm_b = world_to_body(np.asarray(cfg.density_mean_m), pose_i)
        v = -0.5 * (mean_b - qm_b)  # Eq. 20 in Σ_i (rotation-invariant gain)
        sp = np.hypot(v[:, 0], v[:, 1])
        v *= np.minimum(1.0, cfg.v_max_mps / np.maximum(sp, 1e-12))[:, None]
        a = math.sqrt(CHI2_95_2DOF) * self.sigma[i, ids]
        d = np.maximum(0.0, np.hypot(mean_b[:, 0], mean_b[:, 1]) - a)
        return ids, mean_b, v, d


def bench_control(
    n_agents: tuple[int, ...] = (6, 9, 12, 24, 48),
    steps: int = 100,
    seed: int = 0,
    config: ScenarioConfig | None = None,
    params: ControllerParams | None = None,
    warmup: int = 5,
) -> list[dict]:
    """Per robot-step time of the control layer on closed-loop coverage episodes.

    Args:
        n_agents: team sizes; the paper's 40 m arena is kept, so larger teams are
            denser (more neighbours within reach of the CBF rows and the Voronoi cell).
        steps: timed control steps per team size (after ``warmup`` untimed steps).
        seed: seed of the random start poses and measurement noise.
        config, params: scenario and controller (defaults: the paper's).
        warmup: untimed steps first (stencil cache, early transients).

    Returns:
        One dict per team size: ``n_agents``, ``robot_steps``, mean per robot-step
        times in µs (``lloyd_us`` per-robot call, ``lloyd_batched_us`` one batched
        call for the team divided by N, ``rows_us`` row assembly + pruning + levels,
        ``cascade_us``, ``final_us``, ``controller_us`` = the whole
        :meth:`~fov_marl.control.controller.FovCbfController.solve`, ``total_us`` =
        Lloyd + controller), ``p50_total_us``, ``p99_total_us``, ``qp_per_step``,
        ``fallback_rate``, ``intervention_rate``, ``relaxed_rate``, and the true
        ``min_distance_m`` of the run (with the synthetic tracker: informative only).
    """
    base = config if config is not None else make_config()
    prm = params if params is not None else ControllerParams()
    out = []
    for n in n_agents:
        cfg = base.replace(n_agents=int(n))
        rng = np.random.default_rng(seed)
        poses = random_poses(int(n), cfg, rng)
        tracker = SyntheticTracker(poses, cfg)
        ctrls = [FovCbfController(cfg, prm) for _ in range(int(n))]
        acc = {k: [] for k in ("lloyd", "rows", "cascade", "final", "ctrl", "total")}
        batched = []
        n_qp = fallbacks = interventions = relaxed = 0
        dmin = np.inf
        for step in range(warmup + steps):
            tracker.step(poses, rng)
            u_all = np.zeros((int(n), 3))
            views = [tracker.estimate(i, poses[i]) for i in range(int(n))]
            nb_all = np.stack([v[1] for v in views])
            tb = time.perf_counter()
            coverage_desired_inputs(poses, nb_all, None, cfg, prm)
            if step >= warmup:
                batched.append((time.perf_counter() - tb) / int(n))
            for i in range(int(n)):
                ids, mb, vb, d = views[i]
                t0 = time.perf_counter()
                des = coverage_desired_input(poses[i], mb, cfg, prm)
                t1 = time.perf_counter()
                res = ctrls[i].solve(des.u_star, mb, vb, d, ids)
                t2 = time.perf_counter()
                u_all[i] = res.u
                if step >= warmup:
                    acc["lloyd"].append(t1 - t0)
                    acc["rows"].append(res.timings["rows"])
                    acc["cascade"].append(res.timings["cascade"])
                    acc["final"].append(res.timings["final"])
                    acc["ctrl"].append(t2 - t1)
                    acc["total"].append(t2 - t0)
                    n_qp += res.n_qp
                    fallbacks += int(res.fallback)
                    interventions += int(res.intervened)
                    relaxed += int(res.status == "relaxed")
            poses = integrate_unicycle(poses, u_all[:, :2], u_all[:, 2], cfg.dt_s)
            diff = poses[:, None, :2] - poses[None, :, :2]
            dd = np.hypot(diff[..., 0], diff[..., 1]) + np.eye(int(n)) * 1e9
            dmin = min(dmin, float(dd.min()))
        k = len(acc["total"])
        row = {"n_agents": int(n), "robot_steps": k}
        for name in ("lloyd", "rows", "cascade", "final", "ctrl", "total"):
            row[f"{'controller' if name == 'ctrl' else name}_us"] = 1e6 * float(np.mean(acc[name]))
        row["lloyd_batched_us"] = 1e6 * float(np.mean(batched))
        row["p50_total_us"] = 1e6 * float(np.percentile(acc["total"], 50))
        row["p99_total_us"] = 1e6 * float(np.percentile(acc["total"], 99))
        row["qp_per_step"] = n_qp / k
        row["fallback_rate"] = fallbacks / k
        row["intervention_rate"] = interventions / k
        row["relaxed_rate"] = relaxed / k
        row["min_distance_m"] = dmin
        out.append(row)
    return out


def bench_lloyd_resolution(
    grids_m: tuple[float, ...] = (0.2, 0.25, 0.3, 0.4, 0.5, 0.75, 1.0),
    n_cases: int = 100,
    seed: int = 0,
    config: ScenarioConfig | None = None,
) -> list[dict]:
    """Centroid error of the stencil quadrature vs the exact reference, and its time.

    Cases: robot ~ N(q_m, 6 m) clipped to the arena, 11 neighbours ~ N(p_i, 5 m)
    (small cells near neighbours, walls, tails of φ).

    Returns:
        One dict per spacing: ``grid_m``, ``stencil_points``, ``mean_err_m``,
        ``p95_err_m``, ``max_err_m``, ``time_us`` (one robot, mean).
    """
    cfg = config if config is not None else make_config()
    rng = np.random.default_rng(seed)
    cases = []
    for _ in range(n_cases):
        p = np.clip(
            np.asarray(cfg.density_mean_m) + rng.normal(0, 6, 2), 0.5, cfg.arena_size_m - 0.5
        )
        nb = p + rng.normal(0, 5, (11, 2))
        ref, _ = coverage_centroid_reference(p, nb, cfg)
        cases.append((p, nb, ref))
    out = []
    for h in grids_m:
        prm = ControllerParams(lloyd_grid_m=float(h))
        coverage_centroids(cases[0][0][None], cases[0][1][None], None, cfg, prm)  # build stencil
        errs, ts = [], []
        for p, nb, ref in cases:
            t0 = time.perf_counter()
            c, _ = coverage_centroids(p[None], nb[None], None, cfg, prm)
            ts.append(time.perf_counter() - t0)
            errs.append(float(np.hypot(*(c[0] - ref))))
        out.append(
            {
                "grid_m": float(h),
                "stencil_points": int(lloyd_stencil(cfg.sensing_radius_m, float(h))[0].shape[0]),
                "mean_err_m": float(np.mean(errs)),
                "p95_err_m": float(np.percentile(errs, 95)),
                "max_err_m": float(np.max(errs)),
                "time_us": 1e6 * float(np.median(ts)),
            }
        )
    return out


def bench_qp_backends(n_cases: int = 200, seed: int = 0, max_rows: int = 8) -> list[dict]:
    """The nnls and osqp backends of :class:`HierarchicalQP` on random conflicting hierarchies.

    Cases: 2-``max_rows`` normalised rows with random offsets in [−1.2, 0.5] (many
    levels infeasible), 4 priority levels, u* uniform in the input box.

    Returns:
        One dict per backend: ``backend``, ``mean_us``, ``p99_us`` per hierarchy,
        ``qp_per_case``, ``degraded_rate`` (a QP failed), and the agreement with nnls
        (``max_du``, ``p90_du`` on u; ``max_dkappa`` on κ*).
    """
    rng = np.random.default_rng(seed)
    cases = []
    for _ in range(n_cases):
        R = int(rng.integers(2, max_rows + 1))
        A = rng.normal(size=(R, 3))
        A /= (np.hypot(A[:, 0], A[:, 1]) + 1.5 * np.abs(A[:, 2]))[:, None]
        b = rng.uniform(-1.2, 0.5, R)
        cases.append((A, b, rng.integers(0, 4, R), rng.uniform(-1.5, 1.5, 3) * [1, 1, 1.5]))
    results: dict[str, list] = {}
    out = []
    for backend in ("nnls", "osqp"):
        qp = HierarchicalQP(1.0, 1.5, backend=backend)
        ts, res = [], []
        for A, b, lev, us in cases:
            t0 = time.perf_counter()
            r = qp.solve(A, b, lev, us)
            ts.append(time.perf_counter() - t0)
            res.append(r)
        results[backend] = res
        du = [float(np.abs(r.u - q.u).max()) for r, q in zip(res, results["nnls"], strict=True)]
        dk = [
            float(np.abs(r.kappa - q.kappa).max())
            for r, q in zip(res, results["nnls"], strict=True)
        ]
        out.append(
            {
                "backend": backend,
                "mean_us": 1e6 * float(np.mean(ts)),
                "p99_us": 1e6 * float(np.percentile(ts, 99)),
                "qp_per_case": float(np.mean([r.n_qp for r in res])),
                "degraded_rate": float(np.mean([r.fallback for r in res])),
                "max_du": max(du),
                "p90_du": float(np.percentile(du, 90)),
                "max_dkappa": max(dk),
            }
        )
    return out
