"""Desired input u* (Section VII-A, VII-D): limited-range Lloyd coverage and the crossing law.

Coverage (Cortés et al. [21], limited range)
============================================

Robot i's cell is ``V_i = {q ∈ Q : ‖q − p_i‖ ≤ R_s, ‖q − p_i‖ ≤ ‖q − p̂_j‖ ∀ j}`` with
Q the arena and p̂_j the *estimated* neighbour positions (the tracker's means).
Its centroid under the density ``φ(q) = N(q; q_m, σ² I)`` is
``c_i = ∫_{V_i} q φ / ∫_{V_i} φ`` and the desired input is::

    ⁱv* = sat_{v_max}(K_p · R(θ_i)ᵀ (c_i − p_i))          (body frame, Cortés' law)
    ω*  = sat_{ω_max}(k_ω · e · min(1, ‖ⁱg‖ / d_face)),    e = atan2(ⁱg_y, ⁱg_x)

with ``ⁱg = R(θ_i)ᵀ(c_i − p_i)`` the goal in Σ_i: ω turns the robot to face its
centroid (the paper's only change to [21]) and fades out within ``d_face`` of the
goal, where the bearing is meaningless. ``sat`` scales a vector down to the bound
(direction kept). If the cell's probability mass under φ is below
``params.lloyd_min_mass`` (or the cell is empty) the goal is q_m instead of c_i.

Quadrature
----------

A fixed stencil of lattice offsets at spacing ``h = params.lloyd_grid_m`` covering
the disk ``‖o‖ ≤ R_s + h`` is built once (cached) with the exact fraction of each
``h × h`` cell inside the disk (16 × 16 supersampling). Per robot the stencil is
shifted to p_i and each cell weighted by that disk fraction times, for every other
edge of the cell (arena walls and the Voronoi bisectors of neighbours closer than
``2 R_s + 2h``), the linear coverage ramp ``clip(½ + s/h, 0, 1)`` of its signed
distance ``s`` to that edge: an anti-aliased mask (the product handles corners
better than one ramp of the smallest distance) whose error is far below a binary
mask's. Resolution (:func:`fov_marl.control.benchmark.bench_lloyd_resolution`,
100 cells with up to 11 neighbours, error against the reference): h = 0.25 m:
mean 0.5 cm, max 3.5 cm, ~100 µs; **h = 0.4 m (default): mean 1.3 cm, p95 3.4 cm,
max 9 cm, ~80 µs**; h = 0.75 m: mean 4 cm, max 31 cm, ~70 µs. With K_p = 0.8 a 1-3 cm
centroid error is a 1-3 cm/s error in u* (v_max = 1 m/s), and below 0.4 m the time
is spent on the stencil, above it on fixed overhead, so 0.4 m is the knee. The
slow reference :func:`coverage_centroid_reference` integrates the exact convex
cell in polar coordinates. Per robot the nearest 4 neighbours are applied to the
whole stencil first; with many more, the points already outside the cell are
dropped before the rest. The batched form vectorises over robots (padding every
robot to the largest neighbour count) and falls back to one robot at a time when
that padding would exceed 4·10⁵ (robot, neighbour, point) triples (dense teams).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from fov_marl.config import ScenarioConfig
from fov_marl.control.params import ControllerParams
from fov_marl.geometry import body_to_world
from fov_marl.validation import check_budget

__all__ = [
    "DesiredInput",
    "MAX_LLOYD_STENCIL",
    "check_lloyd_stencil",
    "lloyd_radius_m",
    "lloyd_stencil",
    "coverage_centroids",
    "coverage_centroid_reference",
    "facing_omega",
    "proportional_input",
    "coverage_desired_input",
    "coverage_desired_inputs",
    "crossing_desired_input",
]


@dataclass(frozen=True)
class DesiredInput:
    """Desired input and the goal it came from.

    Attributes:
        u_star: ``(3,)`` or ``(B, 3)`` body-frame ``[vx m/s, vy m/s, ω rad/s]``.
        goal_world: ``(2,)`` or ``(B, 2)`` centroid (or q_m when the cell is empty), m.
        mass: ``()`` or ``(B,)`` probability mass of the cell under φ.
        to_density_mean: ``()`` or ``(B,)`` bool, True when the goal is q_m because the
            mass was below ``params.lloyd_min_mass``.
    """

    u_star: np.ndarray
    goal_world: np.ndarray
    mass: np.ndarray
    to_density_mean: np.ndarray


#: most lattice points a Lloyd stencil may hold (:func:`check_lloyd_stencil`); the
#: default R_s = 6 m at h = 0.4 m holds ~800, so this is ~125 times the paper's case
MAX_LLOYD_STENCIL = 100_000


def lloyd_radius_m(config: ScenarioConfig, grid_m: float) -> float:
    """Radius of the Lloyd stencil: ``min(R_s, √2 L + 2h)``.

    A robot inside the arena ``[0, L]²`` is within ``√2 L`` of every arena point, and
    a stencil point farther than ``√2 L + h`` from it is more than ``h / 2`` outside
    some wall, where the wall ramp weighs it 0: a larger disk gives the same cell.
    So a sensing radius beyond the arena (e.g. R_s = 1000 m to ask for global Lloyd
    in a 40 m arena) costs no more than ``√2 L + 2h``.

    Args:
        config: uses ``sensing_radius_m`` R_s and ``arena_size_m`` L.
        grid_m: the stencil spacing h (m).
    """
    return float(min(config.sensing_radius_m, math.sqrt(2.0) * config.arena_size_m + 2.0 * grid_m))


def lloyd_stencil_size(radius_m: float, grid_m: float) -> float:
    """Upper estimate of the points of :func:`lloyd_stencil` (``π (R/h + 1.5)²``)."""
    return math.pi * (float(radius_m) / float(grid_m) + 1.5) ** 2


def _check_stencil_size(radius_m: float, grid_m: float, sensing_radius_m: float, ctx: str) -> None:
    check_budget(
        "sensing_radius_m", sensing_radius_m, lloyd_stencil_size(radius_m, grid_m),
        MAX_LLOYD_STENCIL, "the Lloyd stencil pi (R / lloyd_grid_m + 1.5)^2, "
        "R = min(R_s, 1.414 L + 2 lloyd_grid_m)", "points per robot",
        f"lloyd_grid_m = {grid_m}{ctx}; raise lloyd_grid_m or lower sensing_radius_m",
    )  # fmt: skip


def check_lloyd_stencil(config: ScenarioConfig, params: ControllerParams) -> None:
    """Resource guard of the Lloyd quadrature: at most ``MAX_LLOYD_STENCIL`` points.

    Raises:
        ConfigError (a ``ValueError``): naming ``sensing_radius_m`` and
        ``lloyd_grid_m`` when ``π (R / h + 1.5)²`` exceeds the limit, with R from
        :func:`lloyd_radius_m` (at h = 0.4 m: R_s up to ~70 m, any R_s when the arena
        side is at most ~48 m).
    """
    h = params.lloyd_grid_m
    ctx = f", arena_size_m = {config.arena_size_m}"
    _check_stencil_size(lloyd_radius_m(config, h), h, config.sensing_radius_m, ctx)


@lru_cache(maxsize=16)
def lloyd_stencil(sensing_radius_m: float, grid_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Fixed quadrature stencil around a robot (cached, read-only arrays).

    Only the cells that straddle the circle are supersampled (16 × 16); a cell whose
    far corner is inside the disk has fraction exactly 1, one whose near corner is
    outside is dropped, so memory is O(K) for K points.

    Args:
        sensing_radius_m: R_s (m), the stencil radius (see :func:`lloyd_radius_m`).
        grid_m: lattice spacing h (m).

    Returns:
        ``(offsets (K, 2) m, disk_fraction (K,))``: lattice points whose ``h × h``
        cell meets the disk ``‖o‖ ≤ R_s`` and the fraction of that cell inside it.

    Raises:
        ConfigError: when the stencil would exceed ``MAX_LLOYD_STENCIL`` points.
    """
    h = float(grid_m)
    _check_stencil_size(sensing_radius_m, h, sensing_radius_m, "")
    n = int(math.ceil(sensing_radius_m / h)) + 1
    ax = h * np.arange(-n, n + 1)
    ox, oy = np.meshgrid(ax, ax, indexing="ij")
    off = np.stack([ox.ravel(), oy.ravel()], -1)
    dist = np.hypot(off[:, 0], off[:, 1])
    near = dist <= sensing_radius_m + h
    off, dist = off[near], dist[near]
    frac = np.ones(off.shape[0])
    # sub-cell points lie within h/√2 of the cell centre: outside this band the 256
    # samples all agree (fraction exactly 1 or 0)
    band = h * (math.sqrt(0.5) + 1e-9)
    ring = np.flatnonzero(np.abs(dist - sensing_radius_m) <= band)
    frac[dist > sensing_radius_m + band] = 0.0
    sub = (np.arange(16) + 0.5) / 16 - 0.5
    sx, sy = np.meshgrid(sub, sub, indexing="ij")
    sub = h * np.stack([sx.ravel(), sy.ravel()], -1)
    pts = off[ring, None, :] + sub[None]
    frac[ring] = np.mean(np.hypot(pts[..., 0], pts[..., 1]) <= sensing_radius_m, axis=1)
    keep = frac > 0
    off, frac = off[keep], frac[keep]
    off.setflags(write=False)
    frac.setflags(write=False)
    return off, frac


#: neighbours applied to the whole stencil before the dropped points are compacted away
_FIRST_CUTS = 4
#: above this many (robot, neighbour, stencil point) triples the batch is done per robot
_BATCH_WORK = 400_000


def _ramp(sd: np.ndarray, h: float) -> np.ndarray:
    """Covered fraction of an ``h × h`` cell at signed distance ``sd`` from a line (in place)."""
    sd *= 1.0 / h
    sd += 0.5
    return np.clip(sd, 0.0, 1.0, out=sd)


@lru_cache(maxsize=16)
def _stencil_with_norms(sensing_radius_m: float, grid_m: float):
    off, frac = lloyd_stencil(sensing_radius_m, grid_m)
    oo = np.sum(off * off, axis=1)
    oo.setflags(write=False)
    return off, frac, oo


def coverage_centroids(
    p_world: np.ndarray,
    neighbours_world: np.ndarray,
    valid: np.ndarray | None,
    config: ScenarioConfig,
    params: ControllerParams,
) -> tuple[np.ndarray, np.ndarray]:
    """Centroids and masses of limited-range Voronoi cells, batched over robots.

    Args:
        p_world: ``(B, 2)`` robot positions (m).
        neighbours_world: ``(B, M, 2)`` estimated neighbour positions of each robot (m).
        valid: ``(B, M)`` bool mask of real entries (None: all valid).

    Returns:
        ``(centroid (B, 2) m, mass (B,))``; mass is the probability of the cell under
        φ; an empty cell gives mass 0 and centroid NaN.
    """
    p = np.asarray(p_world, dtype=np.float64).reshape(-1, 2)
    B = p.shape[0]
    nb = np.asarray(neighbours_world, dtype=np.float64).reshape(B, -1, 2)
    h = params.lloyd_grid_m
    Rs = lloyd_radius_m(config, h)
    L = config.arena_size_m
    reach = Rs + h
    off, frac, oo = _stencil_with_norms(Rs, h)
    w = np.repeat(frac[None, :], B, axis=0)  # (B, K)
    # arena walls: only the robots whose stencil reaches a wall pay for it
    gaps = np.concatenate([p, L - p], axis=1)  # (B, 4): x, y, L - x, L - y
    if gaps.min() < reach:
        for k in range(4):
            near = np.flatnonzero(gaps[:, k] < reach)
            if near.size:
                sd = gaps[near, k, None] + (off[None, :, k % 2] if k < 2 else -off[None, :, k % 2])
                w[near] *= _ramp(sd, h)
    # Voronoi half-planes of the neighbours close enough to cut the stencil, compacted
    # per robot (nearest first) so the work is (B, k, K) with k the largest count
    delta = nb - p[:, None, :]
    dist = np.hypot(delta[..., 0], delta[..., 1])
    use = (dist > 1e-9) & (dist < 2.0 * reach)
    if valid is not None:
        use &= np.asarray(valid, dtype=bool).reshape(dist.shape)
    kmax = int(use.sum(axis=1).max(initial=0))
    if B > 1 and B * kmax * off.shape[0] > _BATCH_WORK:
        # dense teams: one robot at a time (own neighbour count and compaction) is
        # cheaper than padding every robot to the largest neighbour count
        out = [coverage_centroids(p[i : i + 1], nb[i : i + 1][:, use[i]], None, config, params)
               for i in range(B)]  # fmt: skip
        return np.concatenate([o[0] for o in out]), np.concatenate([o[1] for o in out])
    if kmax:
        if B == 1:
            sel = np.flatnonzero(use[0])
            dist, delta = dist[:, sel], delta[:, sel]
            dist_order = np.argsort(dist[0])
            dist, delta = dist[:, dist_order], delta[:, dist_order]
            ok = np.ones(dist.shape, dtype=bool)
        else:
            key = np.where(use, dist, np.inf)
            idx = np.argsort(key, axis=1)[:, :kmax]
            dist = np.take_along_axis(key, idx, axis=1)
            delta = np.take_along_axis(delta, idx[..., None], axis=1)
            ok = np.isfinite(dist)
        nhat = delta / np.where(ok, dist, 1.0)[..., None]
        half = np.where(ok, 0.5 * dist, np.inf)
        # the nearest neighbours usually shrink the cell a lot: apply them to the whole
        # stencil; with many more to come, first drop the points no robot keeps
        first = min(kmax, _FIRST_CUTS)
        w *= np.prod(_ramp(half[:, :first, None] - nhat[:, :first] @ off.T, h), axis=1)
        if kmax > first:
            keep = np.flatnonzero(np.any(w > 0, axis=0))
            if kmax > 2 * _FIRST_CUTS and keep.size < 0.5 * off.shape[0]:
                off, oo, w = off[keep], oo[keep], w[:, keep]
            sd = half[:, first:, None] - nhat[:, first:] @ off.T
            w *= np.prod(_ramp(sd, h), axis=1)
    # density: log φ(p + o) = -(‖o‖² + 2 o·(p − q_m) + ‖p − q_m‖²) / (2σ²)
    qm = np.asarray(config.density_mean_m, dtype=np.float64)
    sig2 = config.density_sigma_m**2
    a = p - qm
    expo = (oo[None, :] + 2.0 * (a @ off.T)) * (-0.5 / sig2)  # (B, K)
    mx = np.max(expo, axis=1, where=w > 0, initial=-np.inf)
    mx_safe = np.where(np.isfinite(mx), mx, 0.0)
    # points outside the cell (w = 0) may lie far above the cell's maximum (a narrow φ,
    # σ ≪ R_s): capping at 0 keeps their exp finite, so 0 · exp is 0, not 0 · inf = NaN
    e = w * np.exp(np.minimum(expo - mx_safe[:, None], 0.0))
    S = e.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cen = p + (e @ off) / S[:, None]
    log_scale = mx_safe - np.sum(a * a, axis=1) / (2.0 * sig2)
    mass = np.where(S > 0, np.exp(log_scale) * S * h * h / (2.0 * np.pi * sig2), 0.0)
    return cen, mass


def coverage_centroid_reference(
    p_world: np.ndarray,
    neighbours_world: np.ndarray,
    config: ScenarioConfig,
    n_theta: int = 4096,
    n_rho: int = 48,
) -> tuple[np.ndarray, float]:
    """Slow reference centroid: polar quadrature of the exact cell.

    The cell (disk ∩ arena ∩ Voronoi half-planes) is convex and contains p_i, so
    along each ray from p_i it is the segment ``[0, ρ_max(θ)]`` with ρ_max the
    nearest of R_s, the arena wall and each bisector. The integrals
    ``∫∫ φ(q) q ρ dρ dθ`` use ``n_theta`` uniform angles and Gauss-Legendre in ρ.

    Args:
        p_world: ``(2,)`` robot position, inside the arena. neighbours_world: ``(M, 2)``.

    Returns:
        ``(centroid (2,), mass)``.
    """
    p = np.asarray(p_world, dtype=np.float64)
    nb = np.asarray(neighbours_world, dtype=np.float64).reshape(-1, 2)
    L = config.arena_size_m
    th = 2.0 * np.pi * (np.arange(n_theta) + 0.5) / n_theta
    e = np.stack([np.cos(th), np.sin(th)], -1)
    rmax = np.full(n_theta, config.sensing_radius_m)
    for k in range(2):
        with np.errstate(divide="ignore"):
            t = np.where(
                e[:, k] > 0, (L - p[k]) / e[:, k], np.where(e[:, k] < 0, -p[k] / e[:, k], np.inf)
            )
        rmax = np.minimum(rmax, t)
    for j in range(nb.shape[0]):
        dlt = nb[j] - p
        dd = float(dlt @ dlt)
        if dd < 1e-18:
            continue
        proj = e @ dlt
        with np.errstate(divide="ignore"):
            t = np.where(proj > 0, 0.5 * dd / proj, np.inf)
        rmax = np.minimum(rmax, t)
    x, wl = np.polynomial.legendre.leggauss(n_rho)
    rho = 0.5 * (x[None, :] + 1.0) * rmax[:, None]  # (T, n_rho)
    wr = 0.5 * wl[None, :] * rmax[:, None]
    q = p + rho[..., None] * e[:, None, :]
    qm = np.asarray(config.density_mean_m)
    sig2 = config.density_sigma_m**2
    phi = np.exp(-np.sum((q - qm) ** 2, -1) / (2.0 * sig2)) / (2.0 * np.pi * sig2)
    wt = phi * rho * wr * (2.0 * np.pi / n_theta)
    mass = float(wt.sum())
    cen = np.einsum("tr,trc->c", wt, q) / mass
    return cen, mass


def facing_omega(
    goal_body: np.ndarray, config: ScenarioConfig, params: ControllerParams
) -> np.ndarray:
    """Facing law: ``ω = sat(k_ω · atan2(g_y, g_x) · min(1, ‖g‖ / d_face))`` (module docstring).

    Args:
        goal_body: ``(..., 2)`` goal in Σ_i (m).

    Returns:
        ``(...)`` ω (rad/s), ``|ω| ≤ ω_max``.
    """
    g = np.asarray(goal_body, dtype=np.float64)
    dist = np.hypot(g[..., 0], g[..., 1])
    e = np.arctan2(g[..., 1], g[..., 0])
    w = params.k_omega * e * np.minimum(1.0, dist / params.face_distance_m)
    return np.clip(w, -config.omega_max_radps, config.omega_max_radps)


def proportional_input(
    goal_body: np.ndarray, config: ScenarioConfig, params: ControllerParams
) -> np.ndarray:
    """``[sat_{v_max}(K_p g), facing_omega(g)]`` for goals ``g`` in Σ_i.

    Args:
        goal_body: ``(..., 2)`` goal positions in Σ_i (m).

    Returns:
        ``(..., 3)`` body-frame input; the planar part is scaled down to norm v_max
        when longer (direction kept).
    """
    g = np.asarray(goal_body, dtype=np.float64)
    v = params.kp_coverage * g
    speed = np.hypot(v[..., 0], v[..., 1])
    scale = np.minimum(1.0, config.v_max_mps / np.maximum(speed, 1e-300))
    out = np.empty(g.shape[:-1] + (3,))
    out[..., 0:2] = v * scale[..., None]
    out[..., 2] = facing_omega(g, config, params)
    return out


def coverage_desired_inputs(
    poses_world: np.ndarray,
    neighbours_body: np.ndarray,
    valid: np.ndarray | None,
    config: ScenarioConfig,
    params: ControllerParams,
) -> DesiredInput:
    """Lloyd desired inputs of B robots at once (module docstring).

    Args:
        poses_world: ``(B, 3)`` own world poses ``[x m, y m, yaw rad]``.
        neighbours_body: ``(B, M, 2)`` estimated neighbour positions in each robot's
            own frame Σ_i (m), e.g. the trackers' ``mean_body`` (padded).
        valid: ``(B, M)`` mask of real entries, or None.

    Returns:
        :class:`DesiredInput` with ``(B, ...)`` arrays.
    """
    poses = np.asarray(poses_world, dtype=np.float64).reshape(-1, 3)
    nb_body = np.asarray(neighbours_body, dtype=np.float64).reshape(poses.shape[0], -1, 2)
    nb_world = body_to_world(nb_body, poses[:, None, :])
    cen, mass = coverage_centroids(poses[:, :2], nb_world, valid, config, params)
    empty = ~(mass > params.lloyd_min_mass) | ~np.all(np.isfinite(cen), axis=1)
    goal = np.where(empty[:, None], np.asarray(config.density_mean_m)[None, :], cen)
    d = goal - poses[:, :2]
    d = d * lloyd_deadband_scale(np.hypot(d[:, 0], d[:, 1]), params)[:, None]
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    g_body = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], -1)
    return DesiredInput(proportional_input(g_body, config, params), goal, mass, empty)


def lloyd_deadband_scale(dist_m: np.ndarray, params: ControllerParams) -> np.ndarray:
    """Shrinkage of the Lloyd error by the dead band δ = ``params.lloyd_deadband_m``.

    The goal error ``e = c − p`` becomes ``e · max(0, 1 − δ / ‖e‖)``: continuous, 0
    within δ of the centroid, ``‖e‖ − δ`` long outside. Not in the paper: the
    centroid is computed on the neighbours' *estimates*, whose noise (σ ≈ 0.3 m for a
    seen neighbour under Σ_MEAS) moves it by ~0.1-0.2 m from step to step; without the
    band a team at 120° never settles (measured, N = 6: mean speed over the last 50 s
    0.10-0.22 m/s, against 0.00 for the ``ideal`` baseline). δ = 0 is the paper's law.

    Args:
        dist_m: ``(...)`` ‖e‖ (m).

    Returns:
        ``(...)`` factors in [0, 1].
    """
    d = np.asarray(dist_m, dtype=np.float64)
    band = params.lloyd_deadband_m
    if band <= 0.0:
        return np.ones_like(d)
    return np.maximum(0.0, 1.0 - band / np.maximum(d, 1e-300))


def coverage_desired_input(
    pose_world: np.ndarray,
    neighbours_body: np.ndarray,
    config: ScenarioConfig,
    params: ControllerParams,
) -> DesiredInput:
    """Lloyd desired input of one robot (Section VII-A).

    Same result as :func:`coverage_desired_inputs` with B = 1, with less overhead.

    Args:
        pose_world: ``(3,)`` own world pose ``[x m, y m, yaw rad]``.
        neighbours_body: ``(M, 2)`` estimated neighbour positions in Σ_i (m).

    Returns:
        :class:`DesiredInput` with ``u_star (3,)``, ``goal_world (2,)``, scalar mass.
    """
    x, y, yaw = (float(v) for v in np.asarray(pose_world, dtype=np.float64).reshape(3))
    c, s = math.cos(yaw), math.sin(yaw)
    nb = np.asarray(neighbours_body, dtype=np.float64).reshape(-1, 2)
    nb_world = np.empty_like(nb)
    nb_world[:, 0] = x + c * nb[:, 0] - s * nb[:, 1]
    nb_world[:, 1] = y + s * nb[:, 0] + c * nb[:, 1]
    p = np.array([[x, y]])
    cen, mass = coverage_centroids(p, nb_world[None], None, config, params)
    m = float(mass[0])
    empty = not (m > params.lloyd_min_mass) or not bool(np.all(np.isfinite(cen)))
    goal = np.asarray(config.density_mean_m, dtype=np.float64) if empty else cen[0]
    dx, dy = goal[0] - x, goal[1] - y
    f = float(lloyd_deadband_scale(math.hypot(dx, dy), params))
    dx, dy = f * dx, f * dy
    gx, gy = c * dx + s * dy, -s * dx + c * dy
    # proportional_input for one goal, in scalar arithmetic (same formulas)
    dist = math.hypot(gx, gy)
    k = params.kp_coverage * min(1.0, config.v_max_mps / max(params.kp_coverage * dist, 1e-300))
    w = params.k_omega * math.atan2(gy, gx) * min(1.0, dist / params.face_distance_m)
    w = min(max(w, -config.omega_max_radps), config.omega_max_radps)
    u = np.array([k * gx, k * gy, w])
    return DesiredInput(u, goal, np.float64(m), np.bool_(empty))


def crossing_desired_input(
    target_body: np.ndarray, config: ScenarioConfig, params: ControllerParams
) -> np.ndarray:
    """Crossing scenario (Section VII-D): proportional law to the own target.

    ``u* = [sat_{v_max}(K_p ⁱt), facing_omega(ⁱt)]`` with ⁱt the target in Σ_i.

    Args:
        target_body: ``(2,)`` (or ``(..., 2)``) target in Σ_i (m).

    Returns:
        ``(3,)`` (or ``(..., 3)``) body-frame input.
    """
    return proportional_input(target_body, config, params)
