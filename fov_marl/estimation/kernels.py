"""Vectorised kernels of the particle-filter bank (paper Section IV-V).

Pure functions on flat particle arrays. Conventions used throughout:

* Particles are stored as separate contiguous arrays ``x, y, h`` (body frame Σ_i of the
  robot that owns the tracker: metres, metres, relative heading θ_j − θ_i in rad).
* A *block* is the contiguous run of particles of one (robot, neighbour) pair; the flat
  arrays are sorted by block. ``block_of`` (``(F,)`` int) gives each particle's block,
  ``block_start`` (``(B,)`` int) the flat index of each block's first particle. Blocks are
  never empty.
* Several robots can share the flat arrays (the batched bank): each robot owns a *row* of
  exactly ``row_len = P_T`` particles, so row ``r`` is ``[r P_T, (r + 1) P_T)``. Every
  kernel computes each block from that block's data only (cumulative sums run per row),
  so a robot gives bit-identical numbers alone or inside a bank.

Nothing here draws random numbers: draws are passed in, so the caller controls the
order of draws of each robot's Generator.

Mode mixture (``motion_model="mixture"``): each particle also carries a discrete mode
``(F,)`` int8 (:data:`MODE_STATIC`, :data:`MODE_COVERAGE`, :data:`MODE_CROSSING`,
:data:`MODE_CV`) and a velocity state ``vx, vy`` (F,) in Σ_i (m/s); see
:func:`mixture_predict`.
"""

from __future__ import annotations

import math

import numpy as np

from fov_marl.geometry import integrate_unicycle, world_to_body

__all__ = [
    "wrap",
    "in_fov_xy",
    "coverage_input",
    "crossing_input",
    "own_motion",
    "to_new_body_frame",
    "measurement_log_likelihood",
    "deletion_mask",
    "weighted_moments",
    "effective_sample_size",
    "fuse_onto_detection",
    "allocate_budget",
    "systematic_resample_indices",
    "equal_split",
    "MODE_STATIC",
    "MODE_COVERAGE",
    "MODE_CROSSING",
    "MODE_CV",
    "MODE_NAMES",
    "mode_cdf",
    "stratified_modes",
    "clip_speed",
    "fresh_velocity",
    "switch_modes",
    "mixture_predict",
    "rotate_velocity",
]

#: Mode indices of the mixture motion model (the order of ``mode_probs`` and of the
#: ``mode_prior_*`` parameters).
MODE_STATIC, MODE_COVERAGE, MODE_CROSSING, MODE_CV = 0, 1, 2, 3
#: Names of the modes, by index.
MODE_NAMES = ("static", "coverage", "crossing", "cv")

_TWO_PI = 2.0 * math.pi
_INV_TWO_PI = 1.0 / _TWO_PI


def wrap(a: np.ndarray) -> np.ndarray:
    """Wrap angles (rad) to ``[-π, π]`` with ``a − 2π rint(a / 2π)`` (faster than ``mod``).

    Differs from :func:`fov_marl.geometry.wrap_angle` only in returning ``+π`` for odd
    multiples of π that round up; every use here squares or rotates by the result.
    """
    return a - _TWO_PI * np.rint(a * _INV_TWO_PI)


def in_fov_xy(x: np.ndarray, y: np.ndarray, fov_rad: float, range_m: float) -> np.ndarray:
    """Camera sector membership F_i on separate coordinate arrays (Eq. 4's ``k ∈ F_i``).

    The same arithmetic as :func:`fov_marl.geometry.in_fov` (closed sector of amplitude
    β centred on the body x axis, radius R_d, origin excluded), on ``x`` and ``y`` arrays
    instead of a stacked ``(..., 2)`` array, so the tracker avoids a copy; the tests check
    the two agree bit for bit.

    Args:
        x, y: ``(...)`` body-frame coordinates (m).
        fov_rad: β in (0, 2π].
        range_m: R_d > 0.

    Returns:
        ``(...)`` boolean mask.
    """
    r2 = x * x + y * y
    inside = (r2 <= range_m * range_m) & (r2 > 0.0)
    if fov_rad >= _TWO_PI:
        return inside
    half = 0.5 * fov_rad
    if half <= 0.5 * math.pi:
        if half < 0.5 * math.pi:
            ang_ok = (x > 0.0) & (np.abs(y) <= np.tan(half) * x)
        else:
            ang_ok = x >= 0.0
    else:
        t = np.tan(math.pi - half)
        ang_ok = ~((x < 0.0) & (np.abs(y) < t * (-x)))
    return inside & ang_ok


def coverage_input(
    x: np.ndarray,
    y: np.ndarray,
    qx: np.ndarray,
    qy: np.ndarray,
    k_p: float,
    v_max: float,
    standoff_m: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Coverage neighbour model, Eq. 20: ``ⁱu_j^est = −K_p (ⁱp_j − ⁱq_m)``, saturated.

    Two documented additions: the input is scaled down to norm ``v_max`` where it is
    larger (the robots cannot go faster), and with ``standoff_m = ρ > 0`` the pull stops
    at distance ρ from q_m: ``u = −K_p (1 − ρ/‖p − q_m‖)₊ (p − q_m)`` (coverage robots
    spread around the peak instead of converging on it; with ρ = 0 this is Eq. 20).

    Args:
        x, y: ``(...)`` particle positions in Σ_i (m).
        qx, qy: q_m in Σ_i (m), broadcast against ``x``.
        k_p: K_p (1/s).
        v_max: speed limit (m/s).
        standoff_m: ρ ≥ 0 (m).

    Returns:
        ``(ux, uy)`` velocities in Σ_i (m/s), each shaped like ``x``.
    """
    ex = x - qx
    ey = y - qy
    r = np.sqrt(ex * ex + ey * ey)
    # ‖u‖ = min(K_p (r − ρ)₊, v_max), direction −(p − q_m)/r
    speed = np.minimum(np.maximum(k_p * (r - standoff_m), 0.0), v_max)
    f = speed / np.maximum(r, 1e-300)
    return -f * ex, -f * ey


def crossing_input(x: np.ndarray, y: np.ndarray, v_max: float) -> tuple[np.ndarray, np.ndarray]:
    """Worst-case neighbour model, Eq. 22: ``−(v_max / 2) ⁱp_j / ‖ⁱp_j‖`` (towards robot i).

    A particle exactly at the origin gets zero input (no direction).

    Args:
        x, y: ``(...)`` particle positions in Σ_i (m).
        v_max: speed limit (m/s).

    Returns:
        ``(ux, uy)`` in Σ_i (m/s).
    """
    r = np.sqrt(x * x + y * y)
    s = -0.5 * v_max / np.maximum(r, 1e-9)
    return s * x, s * y


def mode_cdf(prior: np.ndarray) -> np.ndarray:
    """``(4,)`` cumulative mode distribution from non-negative prior weights (normalised;
    the last entry is exactly 1, so a uniform in [0, 1) always finds a mode)."""
    p = np.asarray(prior, dtype=np.float64)
    c = np.cumsum(p / p.sum())
    c[-1] = 1.0
    return c


def stratified_modes(local_index: np.ndarray, block_len: np.ndarray, cdf: np.ndarray) -> np.ndarray:
    """Deterministic mode assignment of a fresh cloud: the k-th of n particles of a block
    gets the mode whose cumulative prior first exceeds ``(k + ½) / n`` (every block holds
    each mode in proportion to the prior, to within one particle; no random draws).

    Args:
        local_index: ``(F,)`` index k of each particle inside its block.
        block_len: ``(F,)`` size n of each particle's block.
        cdf: ``(4,)`` from :func:`mode_cdf`.

    Returns:
        ``(F,)`` int8 modes.
    """
    q = (np.asarray(local_index, dtype=np.float64) + 0.5) / np.asarray(block_len)
    return np.searchsorted(cdf, q, side="right").astype(np.int8)


def clip_speed(vx: np.ndarray, vy: np.ndarray, v_max: float) -> tuple[np.ndarray, np.ndarray]:
    """Scale ``(vx, vy)`` down to norm ``v_max`` where it is longer (like the env's action
    mapping)."""
    f = _speed_factor(vx, vy, v_max)
    return vx * f, vy * f


def _speed_factor(vx: np.ndarray, vy: np.ndarray, v_max: float) -> np.ndarray:
    """``min(1, v_max / ‖v‖)`` (1 at v = 0)."""
    f = vx * vx
    f += vy * vy
    f += 1e-300  # no division by zero; sqrt(1e-300) = 1e-150 keeps f = 1 below
    np.sqrt(f, out=f)
    np.divide(v_max, f, out=f)
    np.minimum(f, 1.0, out=f)
    return f


def fresh_velocity(
    nx: np.ndarray,
    ny: np.ndarray,
    v_max: float,
    h: np.ndarray | float = 0.0,
    forward_bias: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """A velocity drawn afresh for the constant-velocity mode.

    In the particle's own heading frame ``v = v_max (b + n_x, n_y)`` with ``n`` a standard
    normal pair and ``b`` the forward bias, shrunk to norm v_max, then rotated by the
    particle's relative heading ``h`` into Σ_i. ``b = 0``: a uniform direction, full speed
    with probability ``e^{−1/2} ≈ 0.61``; larger ``b``: mostly forward at full speed
    (robots drive where they look).
    """
    fx, fy = clip_speed(v_max * (forward_bias + nx), v_max * ny, v_max)
    c, s = np.cos(h), np.sin(h)
    return c * fx - s * fy, s * fx + c * fy


def switch_modes(
    mode: np.ndarray, u: np.ndarray, p_switch: float, cdf: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Markov mode switching of the mixture (one uniform per particle).

    With probability ``p_switch`` a particle's mode is redrawn from the prior (it may
    redraw the same mode): ``P(m → m') = (1 − p) δ_{mm'} + p π_{m'}``. The uniform ``u``
    decides both: ``u < p`` switches, and then ``u / p`` (uniform in [0, 1) given the
    switch) picks the new mode by inverse CDF.

    Args:
        mode: ``(...)`` int8 modes; u: ``(...)`` uniforms in [0, 1).
        p_switch: per-step probability in [0, 1].
        cdf: ``(4,)`` cumulative prior.

    Returns:
        ``(new_mode (...) int8, switched (...) bool)``.
    """
    switched = u < p_switch
    new = mode.copy()
    idx = np.flatnonzero(switched)
    if idx.size:
        ix = np.unravel_index(idx, switched.shape)
        new[ix] = np.searchsorted(cdf, u[ix] / p_switch, side="right")
    return new, switched


def mixture_predict(
    x: np.ndarray,
    y: np.ndarray,
    h: np.ndarray,
    vx: np.ndarray,
    vy: np.ndarray,
    mode: np.ndarray,
    u_switch: np.ndarray,
    noise: tuple[np.ndarray, np.ndarray],
    qx: np.ndarray,
    qy: np.ndarray,
    *,
    dt: float,
    p_switch: float,
    cdf: np.ndarray,
    k_p: float,
    v_max: float,
    standoff_m: float,
    sig_pos_by_mode: np.ndarray,
    sig_vel: float,
    forward_bias: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One prediction step (Eq. 2, neighbour part) of the mode-mixture motion model.

    Per particle, in the old Σ_i: (1) the mode switches (:func:`switch_modes`); (2) the
    particle's velocity over the step is its mode's:

    * ``static``: 0 (a random walk: position noise only);
    * ``coverage``: Eq. 20 with standoff and saturation (:func:`coverage_input`);
    * ``crossing``: Eq. 22, ``v_max / 2`` towards robot i (:func:`crossing_input`);
    * ``cv``: the particle's velocity state plus a random walk, ``v + σ_v n_v`` shrunk
      to norm v_max; a particle that has just switched (into ``cv``, possibly from
      ``cv``) takes a fresh velocity instead, mostly along its heading ``h``
      (:func:`fresh_velocity` with ``forward_bias``): a robot that changes behaviour
      may start in any direction, most likely ahead;

    (3) it moves ``p + dt v + σ_pos[mode] n``; (4) its velocity state becomes the
    velocity it moved with (only ``cv`` particles read it back: a switch into ``cv``
    draws afresh).

    One standard normal pair ``n`` per particle drives both its position noise and its
    velocity noise (``n_v = n`` above): for ``cv`` that is the white-acceleration
    constant-velocity model, one noise per axis moving velocity and position together
    (``p' = p + dt v + (dt σ_v + σ_pos) n``); it saves two draws per particle per step,
    the largest cost of the mixture.

    Only particles in the coverage / crossing modes evaluate Eq. 20 / 22, and only the
    (rare) fresh ones draw a fresh velocity; everything else is computed for all
    particles at once. Tested against a one-particle-at-a-time reference
    (``tests/estimation/reference.py``).

    Args:
        x, y, vx, vy: ``(...)`` positions (m) and velocity states (m/s) in the old Σ_i.
        h: ``(...)`` relative headings (rad), for the direction of fresh velocities.
        mode: ``(...)`` int8 modes; u_switch: ``(...)`` uniforms in [0, 1).
        noise: two ``(...)`` standard normals ``(n_x, n_y)``.
        qx, qy: q_m in the old Σ_i, broadcast against ``x``.
        dt: step (s); p_switch: per-step switching probability; cdf: ``(4,)`` prior.
        k_p, standoff_m: Eq. 20's gain (1/s) and standoff ρ (m); v_max: speed limit (m/s).
        sig_pos_by_mode: ``(4,)`` per-step position noise std per axis of each mode (m).
        sig_vel: per-step velocity random-walk std per axis of the ``cv`` mode (m/s).
        forward_bias: ``b`` of :func:`fresh_velocity`.

    Returns:
        ``(x', y', vx', vy', mode')`` in the old Σ_i.
    """
    n_px, n_py = noise
    n_vx, n_vy = noise
    mode, switched = switch_modes(mode, u_switch, p_switch, cdf)
    # cv (computed for every particle, zeroed for the others): velocity random walk
    is_cv = mode == MODE_CV
    ux = n_vx * sig_vel
    ux += vx
    uy = n_vy * sig_vel
    uy += vy
    f = _speed_factor(ux, uy, v_max)
    f *= is_cv
    ux *= f
    uy *= f
    # the rarer modes and the fresh velocities on their particles only (flat indices of
    # the subset: the work is proportional to the subset, not to the whole array)
    shape = x.shape

    def subset(mask):
        idx = np.flatnonzero(mask)
        return np.unravel_index(idx, shape) if idx.size else None

    sel = subset(switched & is_cv)
    if sel is not None:
        ux[sel], uy[sel] = fresh_velocity(
            n_vx[sel], n_vy[sel], v_max, np.broadcast_to(h, shape)[sel], forward_bias
        )
    sel = subset(mode == MODE_COVERAGE)
    if sel is not None:
        ux[sel], uy[sel] = coverage_input(
            x[sel],
            y[sel],
            np.broadcast_to(qx, shape)[sel],
            np.broadcast_to(qy, shape)[sel],
            k_p,
            v_max,
            standoff_m,
        )
    sel = subset(mode == MODE_CROSSING)
    if sel is not None:
        ux[sel], uy[sel] = crossing_input(x[sel], y[sel], v_max)
    sig = np.take(sig_pos_by_mode, mode)
    xo = sig * n_px
    xo += x
    xo += dt * ux
    yo = sig * n_py
    yo += y
    yo += dt * uy
    return xo, yo, ux, uy, mode


def rotate_velocity(
    vx: np.ndarray, vy: np.ndarray, dyaw: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Re-express velocities after Σ_i turned by ``dyaw``: ``R(dyaw)ᵀ v`` (no translation;
    the velocity part of :func:`to_new_body_frame`)."""
    c, s = np.cos(dyaw), np.sin(dyaw)
    return c * vx + s * vy, c * vy - s * vx


def own_motion(
    pose_prev_world: np.ndarray,
    v_body: np.ndarray,
    omega: np.ndarray,
    dt: float,
    lo_m: float | None = None,
    hi_m: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Own motion of Σ_i over one step, as the env integrates it (Eq. 2, ego part).

    Exact unicycle integration of the constant body input (the env's
    :func:`fov_marl.geometry.integrate_unicycle`), then the position clamp to
    ``[lo_m, hi_m]^2`` (the arena shrunk by one robot radius), when given.

    Args:
        pose_prev_world: ``(R, 3)`` world pose at the start of the step.
        v_body: ``(R, 2)`` body velocity (m/s).
        omega: ``(R,)`` yaw rate (rad/s).
        dt: step (s).
        lo_m, hi_m: clamp bounds (m), or ``None`` for no clamp.

    Returns:
        ``(d_body (R, 2), dyaw (R,))``: the displacement of the origin of Σ_i expressed in
        the *old* Σ_i (m), and the yaw change (rad).
    """
    new = integrate_unicycle(pose_prev_world, v_body, omega, dt)
    if lo_m is not None and hi_m is not None:
        new[:, :2] = np.clip(new[:, :2], lo_m, hi_m)
    d_body = world_to_body(new[:, :2], pose_prev_world)
    return d_body, np.asarray(omega, dtype=np.float64) * dt


def to_new_body_frame(
    x: np.ndarray,
    y: np.ndarray,
    h: np.ndarray,
    d_x: np.ndarray,
    d_y: np.ndarray,
    dyaw: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Re-express particles after Σ_i moved by ``(d, dyaw)`` (Eq. 2, inverse own motion).

    ``ⁱp' = R(dyaw)ᵀ (ⁱp − d)`` and ``h' = wrap(h − dyaw)``.

    Args:
        x, y, h: ``(...)`` particles in the old Σ_i.
        d_x, d_y, dyaw: displacement of Σ_i in the old Σ_i and yaw change, broadcast.

    Returns:
        ``(x', y', h')`` in the new Σ_i.
    """
    c, s = np.cos(dyaw), np.sin(dyaw)
    xr = x - d_x
    yr = y - d_y
    return c * xr + s * yr, c * yr - s * xr, wrap(h - dyaw)


def measurement_log_likelihood(
    dx: np.ndarray, dy: np.ndarray, dh: np.ndarray, inv_var: tuple[float, float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian log-likelihood of a detection, Eq. 3, up to a constant.

    ``log w = −½ (dx²/σx² + dy²/σy² + dh²/σθ²)`` with Σ_MEAS = diag(σx², σy², σθ²) (the
    config's ``meas_cov_diag`` are variances) and ``dh`` the wrapped heading difference.

    Args:
        dx, dy: ``(...)`` particle minus measured position (m).
        dh: ``(...)`` wrapped heading difference (rad).
        inv_var: ``(1/σx², 1/σy², 1/σθ²)``.

    Returns:
        ``(log_w, maha_pos)``: the log-weights and the squared Mahalanobis distance of the
        position part alone (used by the recovery gate).
    """
    maha_pos = dx * dx * inv_var[0] + dy * dy * inv_var[1]
    return -0.5 * (maha_pos + dh * dh * inv_var[2]), maha_pos


def deletion_mask(
    x: np.ndarray, y: np.ndarray, detected: np.ndarray, fov_rad: float, range_m: float
) -> np.ndarray:
    """Particles deleted by Eq. 4: inside F_i while their neighbour is undetected.

    Args:
        x, y: ``(...)`` particle positions in Σ_i.
        detected: ``(...)`` whether each particle's neighbour was detected.

    Returns:
        ``(...)`` boolean mask of particles whose weight is set to 0.
    """
    return ~detected & in_fov_xy(x, y, fov_rad, range_m)


def weighted_moments(
    x: np.ndarray,
    y: np.ndarray,
    w: np.ndarray,
    block_of: np.ndarray | None,
    block_start: np.ndarray,
    block_len: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-block weighted mean and covariance (Eq. 5 and Section V's Gaussian fit).

    Eq. 5 as printed, ``Σ_k w_k χ_k / w_k``, would be the plain sum of the particles; it
    is read as the normalised weighted mean ``Σ_k w_k χ_k / Σ_k w_k``. The covariance is
    the weighted (maximum-likelihood) one, ``Σ_k w_k (χ_k − μ)(χ_k − μ)ᵀ / Σ_k w_k``,
    computed in two passes (centred) for accuracy.

    Args:
        x, y: ``(F,)`` positions; w: ``(F,)`` non-negative weights, positive sum per block.
        block_of: ``(F,)`` block of each particle (None when ``block_len`` is given);
            block_start: ``(B,)``.
        block_len: ``(B,)`` block sizes, optional: per-particle copies of the block
            means are then made with ``np.repeat`` (the same numbers as the gather by
            ``block_of``, several times faster).

    Returns:
        ``(sum_w (B,), mean (B, 2), cov (B, 2, 2))``.
    """
    sw = np.add.reduceat(w, block_start)

    def block_mean(v: np.ndarray) -> np.ndarray:  # Σ_block v / Σ_block w
        out = np.add.reduceat(v, block_start)
        out /= sw
        return out

    t = w * x
    mx = block_mean(t)
    np.multiply(w, y, out=t)
    my = block_mean(t)
    if block_len is None:
        ex = x - mx[block_of]
        ey = y - my[block_of]
    else:
        ex = x - np.repeat(mx, block_len)
        ey = y - np.repeat(my, block_len)
    wex = np.multiply(w, ex, out=t)
    u = wex * ex
    cxx = block_mean(u)
    np.multiply(wex, ey, out=u)
    cxy = block_mean(u)
    np.multiply(w, ey, out=u)
    u *= ey
    cyy = block_mean(u)
    mean = np.stack([mx, my], -1)
    cov = np.empty((sw.shape[0], 2, 2))
    cov[:, 0, 0] = cxx
    cov[:, 0, 1] = cxy
    cov[:, 1, 0] = cxy
    cov[:, 1, 1] = cyy
    return sw, mean, cov


def effective_sample_size(w: np.ndarray, block_start: np.ndarray) -> np.ndarray:
    """Per-block effective sample size ``(Σ w)² / Σ w²`` (``(B,)``)."""
    sw = np.add.reduceat(w, block_start)
    sw2 = np.add.reduceat(w * w, block_start)
    return sw * sw / sw2


#: floor (m²) added to a cloud's covariance before :func:`fuse_onto_detection` factors it:
#: a cloud resampled onto a few particles can be (nearly) a point
_FUSE_COV_FLOOR = 1e-6


def fuse_onto_detection(
    x: np.ndarray,
    y: np.ndarray,
    block_len: np.ndarray,
    zx: np.ndarray,
    zy: np.ndarray,
    meas_var: tuple[float, float],
) -> tuple[np.ndarray, np.ndarray]:
    """Move each equally weighted cloud onto the Gaussian posterior of it and a detection.

    Tracker step 4, ``ess_recovery="fuse"``. A cloud whose weighted set collapsed under a
    detection (effective size below the threshold) is a prior that the particle weights
    can no longer represent, not necessarily a wrong one: a narrow cloud (std 0.1 m) and a
    detection 3.8 σ of Σ_MEAS away (p ≈ 7e-4 per detection, tens of times per episode in a
    team of 12) leave a handful of particles. Re-seeding from N(z, Σ_MEAS) then trusts
    that one detection alone (traced: a cloud 1.2 m from the truth, clamped onto the
    robot's own position by the wall, and a collision). Here each block's moments
    ``(μ, C)`` (equal weights: the set was resampled at the previous step; C + 1e-6 I)
    are fused with ``N(z, R)``, ``R = diag(meas_var)`` (Kalman form):

        ``S = C + R,  K = C S⁻¹,  μ' = μ + K (z − μ),  C' = C − K C``

    and every particle is mapped by the affine ``p' = μ' + L' L⁻¹ (p − μ)`` (L, L' the
    Cholesky factors of C, C'), which gives the cloud exactly the posterior's mean and
    covariance and keeps its shape (and each particle's own heading, mode and velocity).
    For a cloud wide against R the result is N(z, R)'s scale around z, as a re-seed; for
    a narrow one it barely moves. Positions only, in the observer's body frame.

    Args:
        x, y: ``(F,)`` positions of the blocks' particles, block after block (m).
        block_len: ``(B,)`` particles per block (each ≥ 1; sums to F).
        zx, zy: ``(B,)`` the detections (m). meas_var: Σ_MEAS's x and y variances (m²).

    Returns:
        ``(x', y')`` ``(F,)`` the moved particles.
    """
    n = np.asarray(block_len, dtype=np.int64)
    starts = np.zeros(n.size, dtype=np.int64)
    np.cumsum(n[:-1], out=starts[1:])
    _, m, C = weighted_moments(x, y, np.ones(x.shape[0]), None, starts, n)
    C[:, 0, 0] += _FUSE_COV_FLOOR
    C[:, 1, 1] += _FUSE_COV_FLOOR
    ex = x - np.repeat(m[:, 0], n)
    ey = y - np.repeat(m[:, 1], n)
    S = C.copy()
    S[:, 0, 0] += meas_var[0]
    S[:, 1, 1] += meas_var[1]
    K_gain = C @ np.linalg.inv(S)
    r = np.stack([zx, zy], -1) - m
    mu = m + np.einsum("bij,bj->bi", K_gain, r)
    C_post = C - K_gain @ C
    C_post = 0.5 * (C_post + np.swapaxes(C_post, 1, 2))
    T = np.linalg.cholesky(C_post) @ np.linalg.inv(np.linalg.cholesky(C))
    Tr = np.repeat(T, n, axis=0)
    xn = np.repeat(mu[:, 0], n) + Tr[:, 0, 0] * ex + Tr[:, 0, 1] * ey
    yn = np.repeat(mu[:, 1], n) + Tr[:, 1, 0] * ex + Tr[:, 1, 1] * ey
    return xn, yn


def equal_split(n_total: int, n_blocks: int) -> np.ndarray:
    """``(n_blocks,)`` counts summing to ``n_total``, the extra ones to the first blocks."""
    base, extra = divmod(int(n_total), int(n_blocks))
    out = np.full(n_blocks, base, dtype=np.int64)
    out[:extra] += 1
    return out


def allocate_budget(
    d_m: np.ndarray, n_total: int, min_per_block: int, scale_m: float
) -> np.ndarray:
    """Split a fixed budget P_T across neighbours by importance (Section IV-B).

    Importance is the distance d_ij to the neighbour's ellipse (Eq. 10, closer is more
    important). Each neighbour first gets the floor ``f = min(min_per_block, P_T // M)``;
    the rest, ``P_T − M f``, is split in proportion to ``w_j = 1 / (d_ij + scale_m)``
    and rounded by largest remainder (ties: smaller d, then lower slot), so

    * the counts sum to exactly P_T (the authors' integer division lost particles),
    * every count is at least ``f ≥ 1``,
    * a neighbour never gets fewer particles than one with a strictly larger d.

    Args:
        d_m: ``(R, M)`` distances d_ij ≥ 0 per robot and neighbour (m); non-finite
            values are treated as very far.
        n_total: P_T ≥ M.
        min_per_block: requested floor ≥ 1.
        scale_m: ``s > 0`` (m).

    Returns:
        ``(R, M)`` int64 counts, each row summing to ``n_total``.

    Raises:
        ValueError: ``n_total < M``, naming ``n_particles_total``.
    """
    d = np.asarray(d_m, dtype=np.float64)
    n_rows, m = d.shape
    if n_total < m:
        raise ValueError(
            f"n_particles_total must be >= the number of neighbours ({m}), got {n_total}"
        )
    if m == 0:
        return np.zeros((n_rows, 0), dtype=np.int64)
    d = np.where(np.isfinite(d), np.maximum(d, 0.0), 1e12)
    f = min(int(min_per_block), int(n_total) // m)
    w = 1.0 / (d + scale_m)
    quota = f + (n_total - m * f) * (w / w.sum(axis=1, keepdims=True))
    base = np.floor(quota)
    frac = quota - base
    counts = base.astype(np.int64)
    rem = n_total - counts.sum(axis=1)
    # np.lexsort is stable: equal (frac, d) keep ascending slot order.
    order = np.lexsort((d, -frac), axis=-1)
    counts[np.arange(n_rows)[:, None], order] += np.arange(m)[None, :] < rem[:, None]
    return counts


def systematic_resample_indices(
    w: np.ndarray,
    row_len: int,
    block_of: np.ndarray,
    block_start: np.ndarray,
    block_len: np.ndarray,
    n_new: np.ndarray,
    u: np.ndarray,
) -> np.ndarray:
    """Systematic resampling of every block at once, each at its new size (IV-A 5, IV-B).

    For a block with normalised cumulative weights ``C_k`` (``C_{−1} = 0``), new size
    ``n`` and one uniform ``u ∈ [0, 1)``, particle k is copied
    ``⌊n C_k + u⌋ − ⌊n C_{k−1} + u⌋`` times, i.e. once for each of the evenly spaced
    points ``t_i = (i + 1 − u) / n``, i = 0..n−1, with ``C_{k−1} < t_i ≤ C_k``: the
    systematic scheme (offset ``1 − u ∈ (0, 1]``). One cumulative sum runs along each row
    (robot), and each block's sum is measured from its own start, so no block depends on
    another.

    Round-off guards: the last ``C_k`` of each block is exactly 1 (a number divided by
    itself) and ``⌊n C_k + u⌋`` is capped at n (``n + u`` can round up to ``n + 1``), so
    each block gets exactly ``n`` copies; zero-weight (deleted) particles never get one.
    Re-drawing at a new size this way is the budget re-allocation's "resampling without
    modifying the distribution".

    Args:
        w: ``(F,)`` weights ≥ 0 with a positive sum in every block, ``F = R row_len``.
        row_len: particles per row (P_T).
        block_of: ``(F,)``; block_start, block_len: ``(B,)``.
        n_new: ``(B,)`` int new block sizes, each row summing to ``row_len``.
        u: ``(B,)`` uniforms in [0, 1).

    Returns:
        ``(F,)`` int indices into the flat arrays; the new blocks are contiguous and in
        the same block order.
    """
    f = w.shape[0]
    cs = np.cumsum(w.reshape(-1, row_len), axis=1).reshape(f)
    off = cs[block_start - 1]
    off[block_start % row_len == 0] = 0.0
    total = cs[block_start + block_len - 1] - off
    # per-particle copies of per-block values: np.repeat (blocks are contiguous), the
    # same numbers as a gather by block_of
    c = np.subtract(cs, np.repeat(off, block_len), out=cs)
    c /= np.repeat(total, block_len)
    np.maximum(c, 0.0, out=c)
    n_p = np.repeat(n_new.astype(np.float64), block_len)
    c *= n_p
    c += np.repeat(u, block_len)
    fl = np.floor(c, out=c)
    np.minimum(fl, n_p, out=fl)
    prev = n_p  # reused
    prev[1:] = fl[:-1]
    prev[block_start] = 0.0
    fl -= prev
    return np.repeat(np.arange(f), fl.astype(np.int64))
