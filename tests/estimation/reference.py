"""Slow, obviously-correct reference of one tracker step, one neighbour at a time.

It follows the paper's steps literally, through the world frame and the geometry module,
with textbook loops for the budget split and the systematic resampling. It consumes the
robot's Generator in the documented order (process noise ``(3, P_T)``, recovery draws by
ascending neighbour, ``random(M)`` offsets), so the fast tracker must reproduce it.
"""

from __future__ import annotations

import math

import numpy as np

from fov_marl.config import ScenarioConfig
from fov_marl.estimation import TrackerParams
from fov_marl.estimation import kernels as K
from fov_marl.geometry import (
    body_to_world,
    chi2_2dof,
    confidence_ellipse,
    ellipse_distance,
    in_fov,
    integrate_unicycle,
    world_to_body,
    wrap_angle,
)
from fov_marl.spaces import ObservationLayout, action_to_velocity


def neighbour_input(
    p: np.ndarray, goal: np.ndarray, model: str, k_p: float, v_max: float, standoff: float
) -> np.ndarray:
    """``(n, 2)`` u_j^est per particle, one particle at a time (Eq. 20 / 22)."""
    out = np.zeros_like(p)
    for k in range(p.shape[0]):
        if model == "coverage":
            e = p[k] - goal
            r = math.hypot(e[0], e[1])
            speed = min(max(k_p * (r - standoff), 0.0), v_max)
            out[k] = -speed * e / r if r > 0 else 0.0
        elif model == "crossing":
            r = math.hypot(p[k, 0], p[k, 1])
            out[k] = -0.5 * v_max * p[k] / r if r > 0 else 0.0
    return out


MODES = ("static", "coverage", "crossing", "cv")


def shrink(v: np.ndarray, v_max: float) -> np.ndarray:
    """``v`` scaled down to norm ``v_max`` when longer."""
    n = math.hypot(v[0], v[1])
    return v * (v_max / n) if n > v_max else v


def mixture_predict_reference(
    x, y, h, vx, vy, mode, u, noise, q, *, dt, p_switch, prior, k_p, v_max, standoff,
    sig_pos, sig_vel, forward_bias,
):  # fmt: skip
    """The mixture prediction (kernels.mixture_predict), one particle at a time, written
    from the definitions: switch with probability p to a mode drawn from the prior by
    inverse CDF of ``u / p``; the mode's velocity (static 0, Eq. 20, Eq. 22, cv random
    walk or a fresh forward-biased velocity after a switch); move with the mode's noise.

    ``noise``: ``(4, n)`` standard normals (position x, y, velocity x, y; the tracker passes
    the same pair twice, see kernels.mixture_predict); ``q``: q_m (2,).
    Returns ``(x, y, vx, vy, mode)`` as new arrays.
    """
    prior = np.asarray(prior, dtype=np.float64) / np.sum(prior)
    n = len(x)
    out = np.zeros((5, n))
    for k in range(n):
        m = int(mode[k])
        switched = u[k] < p_switch
        if switched:
            t = u[k] / p_switch
            acc = 0.0
            m = len(prior) - 1
            for j, pj in enumerate(prior):
                acc += pj
                if t < acc:
                    m = j
                    break
        p = np.array([x[k], y[k]])
        if MODES[m] == "static":
            v = np.zeros(2)
        elif MODES[m] == "coverage":
            e = p - q
            r = math.hypot(e[0], e[1])
            speed = min(max(k_p * (r - standoff), 0.0), v_max)
            v = -speed * e / r if r > 0 else np.zeros(2)
        elif MODES[m] == "crossing":
            r = math.hypot(p[0], p[1])
            v = -0.5 * v_max * p / r if r > 0 else np.zeros(2)
        elif switched:  # fresh velocity in the particle's heading frame, rotated into Σ_i
            f = shrink(v_max * np.array([forward_bias + noise[2, k], noise[3, k]]), v_max)
            c, s = math.cos(h[k]), math.sin(h[k])
            v = shrink(np.array([c * f[0] - s * f[1], s * f[0] + c * f[1]]), v_max)
        else:
            v = shrink(np.array([vx[k], vy[k]]) + sig_vel * noise[2:4, k], v_max)
        p = p + dt * v + sig_pos[m] * noise[0:2, k]
        out[:, k] = [p[0], p[1], v[0], v[1], m]
    return out[0], out[1], out[2], out[3], out[4].astype(np.int8)


def allocate_reference(d: np.ndarray, n_total: int, floor_: int, scale: float) -> np.ndarray:
    """Largest-remainder split with a loop (see kernels.allocate_budget)."""
    m = len(d)
    f = min(floor_, n_total // m)
    w = 1.0 / (np.asarray(d) + scale)
    quota = f + (n_total - m * f) * (w / np.sum(w))
    base = [int(math.floor(q)) for q in quota]
    rem = n_total - sum(base)
    order = sorted(range(m), key=lambda j: (-(quota[j] - math.floor(quota[j])), d[j], j))
    for j in order[:rem]:
        base[j] += 1
    return np.array(base, dtype=np.int64)


def systematic_reference(w: np.ndarray, n_new: int, u: float) -> np.ndarray:
    """Textbook systematic resampling: point t_i = (i + 1 − u)/n goes to the first particle
    whose cumulative normalised weight reaches it."""
    c = np.cumsum(w) / np.sum(w)
    c[-1] = 1.0
    out = np.empty(n_new, dtype=np.int64)
    k = 0
    for i in range(n_new):
        t = (i + 1 - u) / n_new
        while c[k] < t:
            k += 1
        out[i] = k
    return out


def uniform_outside_fov(rng, n, pose, cfg):
    lo, hi = cfg.robot_radius_m, cfg.arena_size_m - cfg.robot_radius_m
    pts: list[np.ndarray] = []
    last = None
    for _ in range(50):
        need = n - len(pts)
        uu = rng.random((2, max(2 * need, 16)))
        b = world_to_body(np.stack([lo + (hi - lo) * uu[0], lo + (hi - lo) * uu[1]], -1), pose)
        last = b
        for q in b[~in_fov(b, cfg.fov_rad, cfg.detection_range_m)][:need]:
            pts.append(q)
        if len(pts) == n:
            return np.array(pts)
    return np.concatenate([np.array(pts).reshape(-1, 2), last[: n - len(pts)]])


def disc_outside_fov(rng, n, centre, radius, pose, cfg):
    """Uniform in the disc around ``centre`` (body frame), inside the arena, outside F_i."""
    lo, hi = cfg.robot_radius_m, cfg.arena_size_m - cfg.robot_radius_m
    pts: list[np.ndarray] = []
    for _ in range(50):
        need = n - len(pts)
        uu = rng.random((2, max(2 * need, 16)))
        for k in range(uu.shape[1]):
            q = centre + radius * math.sqrt(uu[0, k]) * np.array(
                [math.cos(2 * math.pi * uu[1, k]), math.sin(2 * math.pi * uu[1, k])]
            )
            w = body_to_world(q, pose)
            inside = lo <= w[0] <= hi and lo <= w[1] <= hi
            if inside and not in_fov(q[None], cfg.fov_rad, cfg.detection_range_m)[0]:
                if len(pts) < n:
                    pts.append(q)
        if len(pts) == n:
            return np.array(pts)
    rest = uniform_outside_fov(rng, n - len(pts), pose, cfg)
    return np.concatenate([np.array(pts).reshape(-1, 2), rest])


def reference_step(
    cfg: ScenarioConfig,
    params: TrackerParams,
    agent_index: int,
    state: dict,
    action: np.ndarray,
    obs: np.ndarray,
    rng: np.random.Generator,
) -> tuple[dict, dict]:
    """One step from ``state`` (x, y, h (P,), counts (M,), pose_prev (3,), goal_prev (2,),
    optionally bias (M, 2) and bias_alarm (M,) of the bias test (zeros / False when
    absent); for the mixture also vx, vy (P,) and mode (P,)).

    Returns ``(new_state, estimate)`` with estimate keys mean, cov, a, b, psi, dist, counts,
    recovered, and for the mixture mode_probs (M, 4) and velocity (M, 2).
    """
    n_agents = cfg.n_agents
    m = n_agents - 1
    p_total = params.n_particles_total
    lay = ObservationLayout(n_agents, agent_index)
    slots = lay.slots(np.asarray(obs, dtype=np.float64)).astype(np.float64)
    pose_now = lay.own_pose_world(obs)
    model = "mixture" if params.motion_model == "auto" else params.motion_model
    mix = model == "mixture"
    prior = list(params.mode_prior())
    cdf = np.cumsum(np.asarray(prior) / np.sum(prior))
    q_mix = params.mixture_noise_m_per_sqrt_s  # static, Eq. 20 and Eq. 22 modes
    sig_mode = math.sqrt(cfg.dt_s) * np.array([q_mix, q_mix, q_mix, params.cv_noise_m_per_sqrt_s])

    def prior_modes(n):  # stratified: particle k of n takes the prior's (k + 1/2)/n quantile
        return np.array([int(np.sum(cdf[:-1] <= (k + 0.5) / n)) for k in range(n)], np.int8)

    def fresh(nz, h):  # fresh velocities along the headings (kernels.fresh_velocity)
        out = np.zeros((len(h), 2))
        for k in range(len(h)):
            f = shrink(
                cfg.v_max_mps * np.array([params.cv_forward_bias + nz[0, k], nz[1, k]]),
                cfg.v_max_mps,
            )
            c, s_ = math.cos(h[k]), math.sin(h[k])
            out[k] = [c * f[0] - s_ * f[1], s_ * f[0] + c * f[1]]
        return out

    rho = params.coverage_standoff_m
    rho = cfg.sensing_radius_m + cfg.safety_distance_m if rho is None else rho
    dt = cfg.dt_s
    r_rob, L = cfg.robot_radius_m, cfg.arena_size_m
    var = np.maximum(np.asarray(cfg.meas_cov_diag), params.min_meas_var)

    v, om = action_to_velocity(
        np.asarray(action, dtype=np.float64), cfg.v_max_mps, cfg.omega_max_radps
    )
    pose_new = integrate_unicycle(state["pose_prev"], v, om, dt)
    pose_new[:2] = np.clip(pose_new[:2], r_rob, L - r_rob)

    noise = rng.standard_normal((3, p_total))
    u_switch = rng.random(p_total) if mix else None
    sig_p = params.process_noise_m_per_sqrt_s * math.sqrt(dt)
    sig_h = params.heading_noise_rad_per_sqrt_s * math.sqrt(dt)
    counts = state["counts"]
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])

    bias = np.array(state.get("bias", np.zeros((m, 2))), dtype=np.float64)
    alarm = np.array(state.get("bias_alarm", np.zeros(m, dtype=bool)))
    sets, weights, recovered, esss, mixes = [], [], [], [], []
    for j in range(m):
        sl = slice(starts[j], starts[j] + counts[j])
        p = np.stack([state["x"][sl], state["y"][sl]], -1)
        if mix:
            px, py, vx, vy, mode = mixture_predict_reference(
                state["x"][sl], state["y"][sl], state["h"][sl], state["vx"][sl],
                state["vy"][sl], state["mode"][sl], u_switch[sl], noise[[0, 1, 0, 1], sl],
                state["goal_prev"], dt=dt, p_switch=-math.expm1(-params.mode_switch_rate_hz * dt),
                prior=prior, k_p=params.k_p, v_max=cfg.v_max_mps, standoff=rho,
                sig_pos=sig_mode, sig_vel=params.cv_velocity_noise_mps_per_sqrt_s * math.sqrt(dt),
                forward_bias=params.cv_forward_bias,
            )  # fmt: skip
            p = np.stack([px, py], -1)
            # velocities: world <- old body, then new body (rotation only)
            vel = np.stack([vx, vy], -1)
            ang = pose_new[2] - state["pose_prev"][2]
            c, s_ = math.cos(ang), math.sin(ang)
            vel = np.stack([c * vel[:, 0] + s_ * vel[:, 1], c * vel[:, 1] - s_ * vel[:, 0]], -1)
        else:
            u = neighbour_input(p, state["goal_prev"], model, params.k_p, cfg.v_max_mps, rho)
            p = p + u * dt + sig_p * noise[:2, sl].T
        p = world_to_body(body_to_world(p, state["pose_prev"]), pose_new)
        h = wrap_angle(state["h"][sl] + sig_h * noise[2, sl] - om * dt)
        if params.clamp_to_arena:
            pw = np.clip(body_to_world(p, pose_now), r_rob, L - r_rob)
            p = world_to_body(pw, pose_now)
        det = slots[j, 0] > 0.5
        if det:
            z = slots[j, 1:3]
            zh = math.atan2(slots[j, 4], slots[j, 3])
            dh = wrap_angle(h - zh)
            maha = (p[:, 0] - z[0]) ** 2 / var[0] + (p[:, 1] - z[1]) ** 2 / var[1]
            lw = -0.5 * (maha + dh**2 / var[2])
            w = np.exp(lw - lw.max())
            ess = w.sum() ** 2 / np.sum(w**2)
            gated = maha.min() > params.recovery_gate_chi2 or bool(alarm[j])
            low = ess < min(params.recovery_min_ess, 0.5 * counts[j])
            bad = gated or low
            if low and not gated and params.ess_recovery == "fuse":  # step 4, fused
                bad = False
                qx, qy = fuse_onto_detection_reference(
                    p[:, 0], p[:, 1], [counts[j]], [z[0]], [z[1]], (var[0], var[1])
                )
                p = np.stack([qx, qy], -1)
                if params.clamp_to_arena:
                    pw = np.clip(body_to_world(p, pose_now), r_rob, L - r_rob)
                    p = world_to_body(pw, pose_now)
                w = np.ones(counts[j])
                ess = float(counts[j])
            if bad:
                nz = rng.standard_normal((3, counts[j]))
                sd = np.sqrt(var)
                p = np.stack([z[0] + sd[0] * nz[0], z[1] + sd[1] * nz[1]], -1)
                if params.clamp_to_arena:
                    pw = np.clip(body_to_world(p, pose_now), r_rob, L - r_rob)
                    p = world_to_body(pw, pose_now)
                h = wrap_angle(zh + sd[2] * nz[2])
                w = np.ones(counts[j])
                ess = float(counts[j])
                if mix:
                    vel = fresh(rng.standard_normal((2, counts[j])), h)
                    mode = prior_modes(counts[j])
        else:
            gone = in_fov(p, cfg.fov_rad, cfg.detection_range_m)
            w = np.where(gone, 0.0, 1.0)
            bad = bool(gone.all())
            if bad and params.recovery_reseed == "local":
                centre = p.mean(axis=0)
                radius = np.linalg.norm(p - centre, axis=1).max() + params.recovery_local_margin_m
                p = disc_outside_fov(rng, counts[j], centre, radius, pose_now, cfg)
            elif bad:
                p = uniform_outside_fov(rng, counts[j], pose_now, cfg)
            if bad:
                h = 2 * math.pi * rng.random(counts[j]) - math.pi
                w = np.ones(counts[j])
                if mix:
                    vel = fresh(rng.standard_normal((2, counts[j])), h)
                    mode = prior_modes(counts[j])
            ess = float(np.sum(w))  # 0/1 weights: the surviving particles
        sets.append((p, h))
        if mix:
            mixes.append((vel, mode))
        weights.append(w)
        esss.append(ess)
        recovered.append(bad)

    chi2 = chi2_2dof(params.confidence)
    mean = np.array(
        [np.average(s[0], axis=0, weights=w) for s, w in zip(sets, weights, strict=True)]
    )
    cov = np.array(
        [np.cov(s[0].T, aweights=w, bias=True) for s, w in zip(sets, weights, strict=True)]
    )
    # Monte Carlo inflation of the reported covariance (mc_error_factor)
    cov = cov * (1.0 + params.mc_error_factor / np.array(esss))[:, None, None]
    a, b, psi = confidence_ellipse(cov, chi2)
    dist = np.array([ellipse_distance(np.zeros(2), mean[j], a[j], b[j], psi[j]) for j in range(m)])
    # the bias test (tracker step 4): world-frame EWMA of Σ_MEAS^{-1/2} (z − mean)
    alpha = params.recovery_bias_alpha
    if alpha > 0.0:
        sd = np.sqrt(var[:2])
        c, s_ = math.cos(pose_now[2]), math.sin(pose_now[2])
        for j in range(m):
            if recovered[j]:
                bias[j] = 0.0
            elif slots[j, 0] > 0.5:
                r = (slots[j, 1:3] - mean[j]) / sd
                r_world = np.array([c * r[0] - s_ * r[1], s_ * r[0] + c * r[1]])
                bias[j] = (1.0 - alpha) * bias[j] + alpha * r_world
            alarm[j] = float(bias[j] @ bias[j]) * (2.0 - alpha) / alpha > params.recovery_bias_chi2
    new_counts = allocate_reference(
        dist, p_total, params.min_particles_per_neighbour, params.allocation_scale_m
    )
    u_off = rng.random(m)
    xs, ys, hs, vs, ms = [], [], [], [], []
    for j in range(m):
        idx = systematic_reference(weights[j], int(new_counts[j]), float(u_off[j]))
        xs.append(sets[j][0][idx, 0])
        ys.append(sets[j][0][idx, 1])
        hs.append(sets[j][1][idx])
        if mix:
            vs.append(mixes[j][0][idx])
            ms.append(mixes[j][1][idx])
    new_state = dict(
        x=np.concatenate(xs),
        y=np.concatenate(ys),
        h=np.concatenate(hs),
        counts=new_counts,
        pose_prev=pose_now,
        goal_prev=lay.goal_body(obs),
        bias=bias,
        bias_alarm=alarm,
    )
    if mix:
        vv = np.concatenate(vs)
        new_state.update(vx=vv[:, 0], vy=vv[:, 1], mode=np.concatenate(ms))
    est = dict(
        mean=mean,
        cov=cov,
        a=a,
        b=b,
        psi=psi,
        dist=dist,
        counts=new_counts,
        recovered=np.array(recovered),
    )
    if mix:  # Eq. 20's q_m in Σ_i: the cue in coverage, from the own pose in crossing
        goal = lay.goal_body(obs)
        if cfg.scenario != "coverage":
            goal = world_to_body(np.asarray(cfg.density_mean_m, dtype=np.float64), pose_now)
        probs = np.zeros((m, 4))
        vel_est = np.zeros((m, 2))
        for j in range(m):
            w = weights[j] / np.sum(weights[j])
            vel, mode = mixes[j]
            for k in range(4):
                probs[j, k] = np.sum(w[mode == k])
            cv = mode == 3
            vel_est[j] = np.sum(w[cv, None] * vel[cv], axis=0)
            u20 = neighbour_input(mean[j : j + 1], goal, "coverage", params.k_p, cfg.v_max_mps, rho)
            u22 = neighbour_input(mean[j : j + 1], goal, "crossing", params.k_p, cfg.v_max_mps, rho)
            vel_est[j] += probs[j, 1] * u20[0] + probs[j, 2] * u22[0]
        v_cv = np.zeros((m, 2))
        for j in range(m):
            w = weights[j] / np.sum(weights[j])
            vel, mode = mixes[j]
            cv = mode == 3
            if np.any(w[cv] > 0):
                v_cv[j] = np.sum(w[cv, None] * vel[cv], axis=0) / np.sum(w[cv])
        est.update(mode_probs=probs, velocity=vel_est, velocity_cv=v_cv)
    return new_state, est


def fuse_onto_detection_reference(
    x: np.ndarray,
    y: np.ndarray,
    block_len: np.ndarray,
    zx: np.ndarray,
    zy: np.ndarray,
    meas_var: tuple[float, float],
) -> tuple[np.ndarray, np.ndarray]:
    """Slow reference of :func:`fov_marl.estimation.kernels.fuse_onto_detection`: block by block, the textbook
    information form of the posterior, ``C' = (C⁻¹ + R⁻¹)⁻¹``, ``μ' = C' (C⁻¹ μ + R⁻¹ z)``."""
    xo, yo = np.empty_like(x), np.empty_like(y)
    R_inv = np.diag([1.0 / meas_var[0], 1.0 / meas_var[1]])
    s = 0
    for b, nb in enumerate(np.asarray(block_len).tolist()):
        p = np.stack([x[s : s + nb], y[s : s + nb]], -1)
        mu = p.mean(axis=0)
        C = (p - mu).T @ (p - mu) / nb + K._FUSE_COV_FLOOR * np.eye(2)
        C_post = np.linalg.inv(np.linalg.inv(C) + R_inv)
        mu_post = C_post @ (np.linalg.solve(C, mu) + R_inv @ np.array([zx[b], zy[b]]))
        T = np.linalg.cholesky(C_post) @ np.linalg.inv(np.linalg.cholesky(C))
        q = mu_post + (p - mu) @ T.T
        xo[s : s + nb], yo[s : s + nb] = q[:, 0], q[:, 1]
        s += nb
    return xo, yo
