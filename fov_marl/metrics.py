"""Evaluation metrics: coverage efficiency η (Eq. 21), time to η, separation, collisions.

Ground truth for evaluation only: these functions take world positions, which no
policy ever sees. NumPy only.

Coverage efficiency (Eq. 21)
----------------------------

``η = ∫_A φ(q) dq`` with ``A = ∪_i D(p_i, R_s)`` the union of the robots' sensing
disks and φ the Gaussian density of the scenario (mean q_m = ``density_mean_m``,
standard deviation σ = ``density_sigma_m``), normalised so that ``∫_Q φ = 1`` over
the arena ``Q = [0, L]²``; hence η ∈ [0, 1] and η = 1 when A ⊇ Q.

Quadrature: the midpoint rule on a uniform grid of ``n = ceil(L / eta_grid_m)``
cells per axis (cell ``h = L / n ≤ eta_grid_m``). A cell counts as covered when its
centre lies in some disk (``dx² + dy² ≤ R_s²``), and its weight is ``φ(centre) h²``,
the weights normalised to sum exactly 1 over the arena (nothing is dropped, so a
fully covered arena gives η = 1 exactly). Because φ is an isotropic Gaussian it
factorises, ``φ(x, y) ∝ g(x) g(y)``, and so do the weights, ``w[iy, ix] = wy[iy] wx[ix]``.
The covered cells of one disk in one grid row form a contiguous run of columns, so
:meth:`CoverageMetric.eta` works row by row on run endpoints: the weight of a run
is a difference of the prefix sums of ``wx`` times ``wy[row]``, and the union of
the runs of all disks in a row is taken by sorting them and clipping each against
the running maximum of the previous ends. Run ends come from the half-width
``sqrt(R_s² − dy²)``; where one lies within round-off of a cell centre it is
re-decided with the exact test ``dx² + dy² ≤ R_s²``. Per call this costs
``O(N · 2R_s/h · log)`` and never touches the full grid (at the defaults, 6 disks
are ~730 runs, the grid 160 000 cells). :func:`coverage_efficiency_reference` is
the slow, obviously-correct version (every disk against every cell) that the
tests compare it with; the two agree to round-off (~1e-15) because they apply the
same floating-point test to the same cell centres.

Midpoint-rule error: only the cells cut by a circle can be misclassified; at the
defaults they weigh ``≈ 2π R_s h φ(R_s) ≈ 8e-3`` in all for a disk on q_m, and the
errors cancel along the circle, so the measured error against the closed form of
:func:`eta_single_disk_at_mean` is ~1e-4 (see ``tests/test_metrics.py``).

Separation metrics
------------------

Pairs are unordered ``i < j``; two robots *collide* when their centre distance is
below ``2 * robot_radius_m`` (``ScenarioConfig.collision_distance_m``) and *violate
safety* when it is below D_s (``safety_distance_m``), both strict.
"""

from __future__ import annotations

import math

import numpy as np

from fov_marl.config import ScenarioConfig

__all__ = [
    "CoverageMetric",
    "coverage_efficiency_reference",
    "gaussian_mass_in_arena",
    "eta_single_disk_at_mean",
    "grid_centres",
    "pairwise_distances",
    "min_pairwise_distance",
    "collision_pairs",
    "safety_violations",
    "per_robot_counts",
    "separation_metrics",
    "time_to_eta",
]


# --------------------------------------------------------------------------- input checks
def _positions(positions_world: np.ndarray, name: str = "positions_world") -> np.ndarray:
    """``(N, 2)`` finite float64 view/copy of ``positions_world`` or ValueError."""
    p = np.asarray(positions_world, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"{name} must have shape (N, 2) [x m, y m], got shape {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"{name} must be finite, got NaN or inf")
    return p


def grid_centres(arena_size_m: float, cell_m: float) -> tuple[np.ndarray, float]:
    """Cell centres of the quadrature grid along one axis of ``[0, L]``.

    Args:
        arena_size_m: L > 0 (m).
        cell_m: requested cell size > 0 (m); the actual one is ``L / ceil(L / cell_m)``
            so that the cells tile the arena exactly.

    Returns:
        ``(centres (n,) m, h m)`` with ``centres[k] = (k + 0.5) h``.
    """
    if not (math.isfinite(cell_m) and cell_m > 0.0):
        raise ValueError(f"cell_m must be in (0, inf) m, got {cell_m!r}")
    if not (math.isfinite(arena_size_m) and arena_size_m > 0.0):
        raise ValueError(f"arena_size_m must be in (0, inf) m, got {arena_size_m!r}")
    n = max(1, math.ceil(arena_size_m / cell_m - 1e-9))
    h = arena_size_m / n
    return (np.arange(n, dtype=np.float64) + 0.5) * h, h


def _axis_weights(centres: np.ndarray, mean: float, sigma: float) -> np.ndarray:
    """Unnormalised 1-D Gaussian factor ``g(c) = exp(-(c - μ)² / 2σ²)`` at the centres."""
    return np.exp(-0.5 * ((centres - mean) / sigma) ** 2)


# --------------------------------------------------------------------------- coverage η
class CoverageMetric:
    """Coverage efficiency η (Eq. 21) of one scenario, fast enough for every env step.

    The grid and its weights are built once from the config; :meth:`eta` then costs
    ``O(N · 2R_s/h)`` (see the module docstring for the method). Measured on the
    shared 2-core development machine at the defaults (h = 0.1 m, R_s = 6 m; best of
    30 rounds of 20 calls, robots uniform in the arena): 48 µs for N = 1, 66 µs for
    N = 6, 86 µs for N = 12, 0.34 ms for N = 48, 1.9 ms for N = 200. The slow
    reference takes ~9 ms at N = 6.

    Args:
        config: the scenario; uses ``arena_size_m``, ``sensing_radius_m``,
            ``density_mean_m``, ``density_sigma_m`` and ``eta_grid_m``.
        cell_m: override of ``config.eta_grid_m`` (m), e.g. for a finer reference.

    Attributes:
        centres_m: ``(n,)`` cell-centre coordinates along each axis (m).
        cell_m: actual cell size h (m).
        sensing_radius_m: R_s (m).
    """

    def __init__(self, config: ScenarioConfig | None = None, cell_m: float | None = None) -> None:
        cfg = ScenarioConfig() if config is None else config
        self.arena_size_m = float(cfg.arena_size_m)
        self.sensing_radius_m = float(cfg.sensing_radius_m)
        self.centres_m, self.cell_m = grid_centres(
            self.arena_size_m, float(cfg.eta_grid_m if cell_m is None else cell_m)
        )
        n = self.centres_m.size
        self.n_cells = n
        mx, my = cfg.density_mean_m
        sigma = float(cfg.density_sigma_m)
        gx = _axis_weights(self.centres_m, mx, sigma)
        gy = _axis_weights(self.centres_m, my, sigma)
        # w[iy, ix] = wy[iy] * wx[ix], sum over the arena exactly 1 (up to round-off).
        self._wx = gx / gx.sum()
        self._wy = gy / gy.sum()
        self._cum_wx = np.concatenate([[0.0], np.cumsum(self._wx)])  # (n + 1,)
        # centres_padded[k + 1] = centre of column k, for k in [-1, n]
        self._centres_padded = np.concatenate([[-np.inf], self.centres_m, [np.inf]])
        R = self.sensing_radius_m
        self._r2 = R * R
        # Rows whose centre can lie within R of a disk centre: at most floor(2R/h) + 1;
        # one more on each side absorbs round-off in the first row's index.
        self._row_offsets = np.arange(math.floor(2.0 * R / self.cell_m) + 3)

    @property
    def cell_weights(self) -> np.ndarray:
        """``(n, n)`` normalised cell weights ``φ(centre) h²``, indexed ``[iy, ix]`` (sum 1)."""
        return np.outer(self._wy, self._wx)

    def eta(self, positions_world: np.ndarray) -> float:
        """Coverage efficiency η (Eq. 21) of robots at ``positions_world``.

        Args:
            positions_world: ``(N, 2)`` world positions ``[x m, y m]`` of the sensing
                disks' centres; ``N = 0`` gives 0. Disks may stick out of the arena
                or lie outside it entirely; only their part inside counts.

        Returns:
            η in ``[0, 1]`` (clipped against round-off of ~1e-15).

        Raises:
            ValueError: wrong shape, NaN or inf.
        """
        p = _positions(positions_world)
        if p.shape[0] == 0:
            return 0.0
        n, h, c = self.n_cells, self.cell_m, self.centres_m
        R, r2 = self.sensing_radius_m, self._r2
        # Disks farther than R outside the arena stay outside after this clip; it only
        # keeps the integer cell indices below from overflowing for huge coordinates.
        p = np.clip(p, -R - 2.0 * h, self.arena_size_m + R + 2.0 * h)
        x, y = p[:, 0:1], p[:, 1:2]  # (N, 1)
        # Candidate rows of each disk: (N, m).
        k0 = np.ceil((y - R) / h - 0.5).astype(np.int64) - 1
        rows = np.maximum(k0, 0) + self._row_offsets
        rows_c = np.minimum(rows, n - 1)
        dy = c[rows_c] - y
        dy2 = dy * dy
        valid = (rows < n) & (dy2 <= r2)
        if not valid.any():
            return 0.0
        rows, dy2 = rows[valid], dy2[valid]
        xr = np.broadcast_to(x, valid.shape)[valid]
        half = np.sqrt(r2 - dy2)
        # Column run [s, e) of cells with (c - x)² + dy² <= R², first estimated from the
        # half-width, then corrected by one cell with the exact test used by the reference.
        us = (xr - half) / h - 0.5  # first covered column is ceil(us)
        ue = (xr + half) / h - 0.5  # last covered column is floor(ue)
        s = np.clip(np.ceil(us).astype(np.int64), 0, n)
        e = np.clip(np.floor(ue).astype(np.int64) + 1, 0, n)
        # Where a run end lies within round-off of a cell centre, the sqrt estimate and
        # the reference's test dx² + dy² <= R² may disagree: redo those with that test.
        # Round-off in R² - dy² - dx² (a few ulp of R²) moves the end by ~ulp(R²)/(2 half).
        tol = 1e-9 + 1e-14 * r2 / (h * half + 1e-300)
        amb = (np.abs(us - np.rint(us)) <= tol) | (np.abs(ue - np.rint(ue)) <= tol)
        if amb.any():
            k = np.flatnonzero(amb)
            s[k], e[k] = self._exact_run_ends(s[k], e[k], xr[k], dy2[k])
        keep = e > s
        if not keep.any():
            return 0.0
        rows, s, e = rows[keep], s[keep], e[keep]
        # Union of runs per row: sort by (row, s) with one integer key, then clip each
        # run's start against the running maximum of the previous ends of its row.
        stride = n + 2
        ks = rows * stride + s
        order = np.argsort(ks, kind="stable")
        ks, ke, rows = ks[order], (rows * stride + e)[order], rows[order]
        prev_end = np.empty_like(ke)
        prev_end[0] = -1
        np.maximum.accumulate(ke[:-1], out=prev_end[1:])
        start = np.maximum(ks, prev_end)
        base = rows * stride
        run = np.where(
            ke > start, self._cum_wx[ke - base] - self._cum_wx[np.minimum(start, ke) - base], 0.0
        )
        total = float(np.dot(self._wy[rows], run))
        return min(max(total, 0.0), 1.0)

    __call__ = eta

    def _exact_run_ends(
        self, s: np.ndarray, e: np.ndarray, xr: np.ndarray, dy2: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Correct run ends ``[s, e)`` (each off by at most one cell) with the exact test."""
        K = s.size
        # centres_padded[k + 1] is column k's centre; columns -1 and n are ±inf (outside).
        dx = self._centres_padded[np.concatenate([s, s + 1, e, e + 1])].reshape(4, K) - xr
        ins = dx * dx + dy2 <= self._r2  # cells s-1, s, e-1, e
        s = np.where(ins[0], s - 1, np.where(ins[1], s, s + 1))
        e = np.where(ins[3], e + 1, np.where(ins[2], e, e - 1))
        return s, e


def coverage_efficiency_reference(
    positions_world: np.ndarray, config: ScenarioConfig, cell_m: float | None = None
) -> float:
    """Slow reference for :meth:`CoverageMetric.eta`: every disk against every cell.

    Builds the full ``(n, n)`` grid of normalised weights ``φ(centre) h²`` and the
    full ``(N, n, n)`` coverage test; obviously correct and ``O(N · n²)``.

    Args:
        positions_world: ``(N, 2)`` disk centres (m).
        config: the scenario (arena, R_s, density, ``eta_grid_m``).
        cell_m: grid cell (m), default ``config.eta_grid_m``; a finer one gives a
            more accurate η.

    Returns:
        η (Eq. 21) in ``[0, 1]``.
    """
    p = _positions(positions_world)
    c, _ = grid_centres(float(config.arena_size_m), float(cell_m or config.eta_grid_m))
    mx, my = config.density_mean_m
    sigma = float(config.density_sigma_m)
    X, Y = np.meshgrid(c, c)  # [iy, ix]
    w = np.exp(-0.5 * (((X - mx) / sigma) ** 2 + ((Y - my) / sigma) ** 2))
    w /= w.sum()
    R = float(config.sensing_radius_m)
    covered = np.zeros(w.shape, dtype=bool)
    for x, y in p:
        dx, dy = X - x, Y - y
        covered |= dx * dx + dy * dy <= R * R
    return float(min(max(w[covered].sum(), 0.0), 1.0))


def gaussian_mass_in_arena(config: ScenarioConfig) -> float:
    """Mass Z of the unnormalised density (a unit-mass isotropic Gaussian) inside the arena.

    ``Z = Π_{k∈{x,y}} [Φ((L − μ_k)/σ) − Φ(−μ_k/σ)]`` with Φ the standard normal CDF,
    written with ``erf``.
    """
    L, sigma = float(config.arena_size_m), float(config.density_sigma_m)
    s = sigma * math.sqrt(2.0)
    z = 1.0
    for mu in config.density_mean_m:
        z *= 0.5 * (math.erf((L - mu) / s) + math.erf(mu / s))
    return z


def eta_single_disk_at_mean(config: ScenarioConfig) -> float:
    """Exact η (Eq. 21) of one sensing disk centred on the density mean q_m.

    The mass of an isotropic Gaussian within radius R of its mean is
    ``1 − exp(−R² / 2σ²)`` (Rayleigh CDF); normalising over the arena divides by
    :func:`gaussian_mass_in_arena`. Used to check the quadrature.

    Raises:
        ValueError: the disk around q_m is not entirely inside the arena (the
            closed form would count mass outside it).
    """
    R, sigma, L = (
        float(config.sensing_radius_m),
        float(config.density_sigma_m),
        float(config.arena_size_m),
    )
    mx, my = config.density_mean_m
    if min(mx, my, L - mx, L - my) < R:
        raise ValueError(
            f"sensing disk of radius {R} m around density_mean_m {config.density_mean_m} must "
            f"lie inside the arena [0, {L}]^2 for the closed form"
        )
    return (1.0 - math.exp(-(R * R) / (2.0 * sigma * sigma))) / gaussian_mass_in_arena(config)


# --------------------------------------------------------------------------- separation
def pairwise_distances(positions_world: np.ndarray) -> np.ndarray:
    """``(N, N)`` Euclidean centre distances (m) of ``(N, 2)`` positions; diagonal 0."""
    p = _positions(positions_world)
    d = p[:, None, :] - p[None, :, :]
    return np.sqrt(np.einsum("ijk,ijk->ij", d, d))


def min_pairwise_distance(positions_world: np.ndarray) -> float:
    """Smallest centre distance between two distinct robots (m); ``inf`` when N < 2."""
    d = pairwise_distances(positions_world)
    if d.shape[0] < 2:
        return math.inf
    iu = np.triu_indices(d.shape[0], k=1)
    return float(d[iu].min())


def _pairs_below(positions_world: np.ndarray, distance_m: float, name: str) -> np.ndarray:
    if not (math.isfinite(distance_m) and distance_m >= 0.0):
        raise ValueError(f"{name} must be in [0, inf) m, got {distance_m!r}")
    d = pairwise_distances(positions_world)
    i, j = np.nonzero(np.triu(d < distance_m, k=1))
    return np.stack([i, j], axis=-1).astype(np.int64)


def collision_pairs(positions_world: np.ndarray, collision_distance: float) -> np.ndarray:
    """Pairs of robots in collision: centre distance strictly below ``collision_distance``.

    Args:
        positions_world: ``(N, 2)`` world positions (m).
        collision_distance: two robot radii, ``config.collision_distance_m`` (m).

    Returns:
        ``(K, 2)`` int pairs ``[i, j]`` with ``i < j``, sorted lexicographically.
    """
    return _pairs_below(positions_world, collision_distance, "collision_distance")


def safety_violations(positions_world: np.ndarray, safety_distance: float) -> np.ndarray:
    """Pairs of robots closer than the safety distance D_s (strictly), as :func:`collision_pairs`.

    Args:
        positions_world: ``(N, 2)`` world positions (m).
        safety_distance: D_s, ``config.safety_distance_m`` (m).

    Returns:
        ``(K, 2)`` int pairs ``[i, j]`` with ``i < j``.
    """
    return _pairs_below(positions_world, safety_distance, "safety_distance")


def per_robot_counts(pairs: np.ndarray, n_agents: int) -> np.ndarray:
    """``(N,)`` int: how many of ``pairs`` (``(K, 2)``) each robot is part of."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if pairs.size and (pairs.min() < 0 or pairs.max() >= n_agents):
        raise ValueError(f"pairs must hold robot indices in [0, {n_agents - 1}]")
    return np.bincount(pairs.ravel(), minlength=n_agents).astype(np.int64)


def separation_metrics(
    positions_world: np.ndarray, collision_distance: float, safety_distance: float
) -> dict[str, object]:
    """All separation metrics of one step, for ``infos[agent]["metrics"]``.

    Args:
        positions_world: ``(N, 2)`` world positions (m).
        collision_distance: two robot radii (m).
        safety_distance: D_s (m).

    Returns:
        dict with ``min_distance`` (float m, inf when N < 2), ``collisions`` and
        ``safety_violations`` (int numbers of pairs), ``collisions_per_robot`` and
        ``safety_violations_per_robot`` (``(N,)`` int arrays).
    """
    p = _positions(positions_world)
    n = p.shape[0]
    col = collision_pairs(p, collision_distance)
    saf = safety_violations(p, safety_distance)
    return {
        "min_distance": min_pairwise_distance(p),
        "collisions": int(col.shape[0]),
        "safety_violations": int(saf.shape[0]),
        "collisions_per_robot": per_robot_counts(col, n),
        "safety_violations_per_robot": per_robot_counts(saf, n),
    }


# --------------------------------------------------------------------------- time to η
def time_to_eta(
    eta_series: np.ndarray, dt: float, threshold: float = 0.99, t0: float = 0.0
) -> float | None:
    """First simulated time at which η reaches ``threshold`` (paper VII-B: η = 0.99).

    Args:
        eta_series: ``(T,)`` η samples, ``eta_series[k]`` taken at time ``t0 + k dt``.
            With η recorded after every env step (not at reset), pass ``t0 = dt``.
        dt: sampling period (s), > 0.
        threshold: η level, in (0, 1].
        t0: time of the first sample (s).

    Returns:
        ``t0 + k dt`` (s) for the first ``k`` with ``eta_series[k] >= threshold``, or
        ``None`` if it is never reached.
    """
    if not (math.isfinite(dt) and dt > 0.0):
        raise ValueError(f"dt must be in (0, inf) s, got {dt!r}")
    if not 0.0 < threshold <= 1.0:
        raise ValueError(f"threshold must be in (0, 1], got {threshold!r}")
    eta = np.asarray(eta_series, dtype=np.float64).reshape(-1)
    hit = np.flatnonzero(eta >= threshold)
    if hit.size == 0:
        return None
    return float(t0 + hit[0] * dt)
