"""Collision rows on the uncertainty (fov_marl.control.safety): kernels against slow
references, and the physical properties they promise (discrete time, walls, sharing)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from fov_marl.config import make_config
from fov_marl.control import ControllerParams, FovCbfController
from fov_marl.control.safety import (
    ROW_BLIND,
    ROW_BUDGET,
    ROW_CONE,
    ROW_LAST_SEEN,
    ROW_NEIGHBOUR,
    ROW_WALL,
    arc_margin,
    arc_yaw_guard,
    barrier_gain,
    bearing_cone,
    bearing_travel_floor,
    blind_representatives,
    detection_sector_rows,
    hold_band,
    neighbour_halfplanes,
    neighbour_row_offsets,
    particle_halfplane_offsets,
    risk_quantile,
    safety_rows,
    wall_clearances,
)
from fov_marl.geometry import in_fov, integrate_unicycle, world_to_body

CFG = make_config()


def _rows(**kw):
    p = ControllerParams()
    base = dict(
        mean_body=np.zeros((1, 0, 2)),
        cov_body=np.zeros((1, 0, 2, 2)),
        detected=np.zeros((1, 0), dtype=bool),
        pose_world=None,
        particles_body=None,
        particle_mass=None,
        safety_distance_m=CFG.safety_distance_m,
        v_max_mps=CFG.v_max_mps,
        omega_max_radps=CFG.omega_max_radps,
        dt_s=CFG.dt_s,
        arena_size_m=CFG.arena_size_m,
        robot_radius_m=CFG.robot_radius_m,
        safety_risk=p.safety_risk,
        safety_gain=p.safety_gain,
        responsibility=p.responsibility,
        blind_bins=p.blind_bins,
        blind_risk=p.blind_risk,
        blind_speed_mps=p.blind_speed_mps,
        walls=True,
        wall_gain=p.wall_gain,
        hold_band_m=p.safety_hold_band_m,
    )
    base.update(kw)
    return safety_rows(**base)


def test_barrier_gain_is_capped_at_one_over_dt():
    assert barrier_gain(2.5, 0.2) == 2.5  # the defaults at the paper's dt: unchanged
    assert barrier_gain(2.5, 0.5) == 2.0
    assert barrier_gain(2.5, 5.0) == pytest.approx(0.2)
    # the controller builds at every dt the env accepts (it raised beyond 0.4 s)
    for dt in (0.05, 0.5, 1.0, 5.0):
        FovCbfController(make_config(dt_s=dt), ControllerParams())


def test_arc_margin_bounds_the_exact_unicycle_displacement():
    rng = np.random.default_rng(0)
    v = rng.uniform(-1, 1, (20000, 2))
    v *= np.minimum(1.0, 1.0 / np.linalg.norm(v, axis=1))[:, None]
    w = rng.uniform(-CFG.omega_max_radps, CFG.omega_max_radps, 20000)
    new = integrate_unicycle(np.zeros((20000, 3)), v, w, CFG.dt_s)
    dev = np.linalg.norm(new[:, :2] - v * CFG.dt_s, axis=1)
    m = arc_margin(CFG.v_max_mps, CFG.omega_max_radps, CFG.dt_s)
    assert dev.max() <= m + 1e-12
    assert dev.max() > 0.95 * m  # tight
    assert m == pytest.approx(0.0299, abs=1e-3)
    assert arc_margin(1.0, 0.0, 0.2) == 0.0


@settings(max_examples=40, deadline=None)
@given(
    st.floats(2.0, 15.0),
    st.floats(-math.pi, math.pi),
    st.floats(0.05, 2.0),
    st.floats(0.05, 2.0),
    st.floats(-math.pi, math.pi),
)
def test_neighbour_line_holds_the_stated_probability(r, bearing, s1, s2, rot):
    """j ~ N(μ, Σ) lies beyond the separating line with probability 1 − δ (Monte Carlo)."""
    mu = r * np.array([math.cos(bearing), math.sin(bearing)])
    R = np.array([[math.cos(rot), -math.sin(rot)], [math.sin(rot), math.cos(rot)]])
    S = R @ np.diag([s1**2, s2**2]) @ R.T
    delta = 0.05
    n, s = neighbour_halfplanes(mu[None, None], S[None, None], risk_quantile(delta))
    x = np.random.default_rng(1).multivariate_normal(mu, S, 40000)
    frac_near = np.mean(x @ n[0, 0] < s[0, 0])
    assert abs(frac_near - delta) < 0.01
    # the line never cuts the robot's side beyond the mean's distance
    assert s[0, 0] <= r + 1e-12


def _blind_reference(p, mass, K, risk, r_cut):
    R = p.shape[0]
    rep = np.zeros((R, K, 2))
    found = np.zeros((R, K), bool)
    for i in range(R):
        for k in range(K):
            cand = []
            for q, m in zip(p[i], mass[i], strict=True):
                r = float(np.hypot(q[0], q[1]))  # the kernel's range test
                if m <= 0 or r >= r_cut:
                    continue
                b = min(int((math.atan2(q[1], q[0]) + math.pi) * K / (2 * math.pi)), K - 1)
                if b == k:
                    cand.append((r, m, q))
            cand.sort(key=lambda c: c[0])
            acc = 0.0
            for _r, m, q in cand:
                acc += m
                if acc > risk + 1e-9:
                    rep[i, k] = q
                    found[i, k] = True
                    break
    return rep, found


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 24), st.floats(0.0, 0.05))
def test_blind_representatives_match_the_reference(seed, K, risk):
    rng = np.random.default_rng(seed)
    R, P = 3, 60
    p = rng.normal(0, 4.0, (R, P, 2))
    mass = rng.choice([0.0, 1 / 30, 1 / 60], (R, P))
    rep, found = blind_representatives(p, mass, K, risk, 8.0)
    rep_r, found_r = _blind_reference(p, mass, K, risk, 8.0)
    np.testing.assert_array_equal(found, found_r)
    np.testing.assert_allclose(rep, rep_r)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.5, 20.0))
def test_blind_representatives_take_exactly_the_particles_inside_r_cut(seed, r_cut):
    """The range test is hypot(x, y) < r_cut, as with hypot over every particle: the
    squared-range prefilter that skips most of them loses no particle at the boundary
    (particles 0-2 ulp either side of r_cut, many bearings)."""
    rng = np.random.default_rng(seed)
    R, P = 2, 200
    th = rng.uniform(-math.pi, math.pi, (R, P))
    r = r_cut * (1.0 + rng.integers(-2, 3, (R, P)) * np.finfo(float).eps)
    r[:, ::3] = rng.uniform(0.0, 2.0 * r_cut, (R, (P + 2) // 3))
    p = np.stack([r * np.cos(th), r * np.sin(th)], -1)
    mass = np.full((R, P), 1 / P)
    rep, found = blind_representatives(p, mass, 16, 0.0, r_cut)
    rep_r, found_r = _blind_reference(p, mass, 16, 0.0, r_cut)
    np.testing.assert_array_equal(found, found_r)
    np.testing.assert_array_equal(rep, rep_r)


def _offsets_reference(p, counts, n, risk):
    """Slow reference: per (robot, neighbour) the (floor(δ P_j) + 1)-th smallest n·p."""
    R, M = counts.shape
    out = np.full((R, M), -np.inf)
    for r in range(R):
        start = 0
        for j in range(M):
            c = int(counts[r, j])
            if c:
                proj = sorted(float(n[r, j] @ q) for q in p[r, start : start + c])
                out[r, j] = proj[min(int(math.floor(risk * c)), c - 1)]
            start += c
    return out


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 5), st.floats(0.001, 0.49))
def test_particle_halfplane_offsets_match_the_reference(seed, M, risk):
    rng = np.random.default_rng(seed)
    R, P = 3, 40
    counts = np.stack([rng.multinomial(P, np.ones(M) / M) for _ in range(R)])
    p = rng.normal(0.0, 5.0, (R, P, 2))
    ang = rng.uniform(-math.pi, math.pi, (R, M))
    n = np.stack([np.cos(ang), np.sin(ang)], -1)
    got = particle_halfplane_offsets(p, counts, n, risk)
    np.testing.assert_allclose(got, _offsets_reference(p, counts, n, risk), rtol=0, atol=1e-12)
    # the stated chance constraint on the particles: at most a fraction δ lies nearer
    start = np.concatenate([np.zeros((R, 1), int), np.cumsum(counts, 1)[:, :-1]], 1)
    for r in range(R):
        for j in range(M):
            c = counts[r, j]
            if c:
                proj = p[r, start[r, j] : start[r, j] + c] @ n[r, j]
                assert np.mean(proj < got[r, j] - 1e-9) <= risk


def test_undetected_rows_can_use_the_particles_own_quantile():
    """A belief stretched along the line of sight: its Gaussian fit reaches the robot
    (no row), its particles stay beyond 4 m (a row at their 1% quantile); detected
    neighbours keep the Gaussian line."""
    rng = np.random.default_rng(0)
    far = np.column_stack([rng.uniform(4.0, 40.0, 200), rng.normal(0.0, 1.0, 200)])
    near = np.array([[2.5, 0.0]]) + rng.normal(0.0, 0.1, (100, 2))
    parts = np.concatenate([far, near])[None]
    counts = np.array([[200, 100]])
    mean = np.array([[far.mean(0), near.mean(0)]])
    cov = np.array([[np.cov(far.T), np.cov(near.T)]])
    det = np.array([[False, True]])
    common = dict(
        mean_body=mean,
        cov_body=cov,
        detected=det,
        particles_body=parts,
        particle_mass=np.zeros((1, 300)),
        blind_bins=0,
    )
    gauss = _rows(**common)
    pf = _rows(**common, particle_counts=counts, undetected_quantile="particles")
    n, s = neighbour_halfplanes(mean, cov, risk_quantile(0.01))
    assert s[0, 0] < 0.0  # the Gaussian band covers the robot: no row
    assert gauss.kind[0, 0] == -1
    s_pf = particle_halfplane_offsets(parts, counts, n, 0.01)[0, 0]
    assert s_pf > 3.9
    assert pf.kind[0, 0] == ROW_NEIGHBOUR
    m_arc = arc_margin(CFG.v_max_mps, CFG.omega_max_radps, CFG.dt_s)
    assert pf.h[0, 0] == pytest.approx(s_pf - CFG.safety_distance_m - m_arc)
    np.testing.assert_array_equal(pf.b[0, 1], gauss.b[0, 1])  # detected: unchanged
    with pytest.raises(ValueError, match="particle_counts"):
        _rows(**common, undetected_quantile="particles")


def test_wall_normals_point_out_of_the_arena_in_the_body_frame():
    pose = np.array([[0.6, 20.0, 0.7], [20.0, 39.2, -2.0]])
    n_body, w = wall_clearances(pose, 40.0, 0.5)
    np.testing.assert_allclose(w[0], [0.1, 38.9, 19.5, 19.5])
    np.testing.assert_allclose(w[1, 3], 0.3)
    for k in range(2):
        for j in range(4):
            # moving along n_body by the clearance reaches the projection line exactly
            step = n_body[k, j] * w[k, j]
            c, s = math.cos(pose[k, 2]), math.sin(pose[k, 2])
            world = pose[k, :2] + np.array([c * step[0] - s * step[1], s * step[0] + c * step[1]])
            on_line = [world[0] - 0.5, 39.5 - world[0], world[1] - 0.5, 39.5 - world[1]][j]
            assert on_line == pytest.approx(0.0, abs=1e-9)


def test_hold_band_is_a_dead_zone():
    h = np.array([-1.0, -0.1, 0.0, 0.1, 0.3, 0.5])
    np.testing.assert_allclose(hold_band(h, 0.3), [-1.0, -0.1, 0.0, 0.0, 0.0, 0.2])
    np.testing.assert_array_equal(hold_band(h, 0.0), h)


#: the inputs of :func:`neighbour_row_offsets` the property tests draw
_ROW_OFFSET_INPUTS = dict(
    h=st.floats(-3.0, 6.0),
    pred=st.one_of(st.none(), st.floats(-1.5, 1.5)),
    band=st.floats(0.0, 1.0),
    gain=st.floats(0.1, 5.0),
    rho=st.floats(0.05, 1.0),
)


@settings(max_examples=300, deadline=None)
@given(**_ROW_OFFSET_INPUTS)
def test_neighbour_row_offsets_keep_the_barrier_and_the_band(h, pred, band, gain, rho):
    """The row is the barrier with shared responsibility capped by the band's share:
    never more approach than the barrier allows (so h_{k+1} >= (1 - γ dt) h_k when j
    closes at what i assumes of it), none within the band, never more retreat than the
    barrier demands, and exactly the barrier without a band or below D_s."""
    hh = np.array(h)
    p = None if pred is None else np.array(pred)
    b = float(neighbour_row_offsets(hh, hold_band(hh, band), p, gain, rho))
    share = (1.0 - rho) * gain * h
    closing = share if pred is None else max(share, pred)
    barrier = gain * h - closing
    # the barrier holds: i's closing b plus j's assumed closing never exceed γ h, so
    # one step of dt <= 1/γ keeps h >= 0
    assert b + closing <= gain * h + 1e-12
    if 0.0 <= h <= band:
        assert b <= 1e-12  # no approach within the band
        assert b >= min(0.0, barrier) - 1e-12  # ... and no retreat the barrier does not ask
    if h > band:
        assert b <= rho * gain * (h - band) + 1e-12
    if band == 0.0 or h < 0.0:
        assert b == pytest.approx(barrier, abs=1e-12)


def test_neighbour_rows_in_the_band_do_not_demand_retreat_the_barrier_does_not():
    """The traced case (pfcbf N = 6, β = 120°, seed 0, robot 1, step 940): a seen
    neighbour 3 m away (h = 0.396 m) whose Eq. 20 prediction closes at 0.685 m/s. The
    barrier leaves γ h − 0.685 = 0.305 m/s; the band caps approach at ρ γ (h − b) =
    0.12 m/s. The earlier row (γ g − max((1 − ρ) γ g, p)) demanded retreat at 0.444."""
    h, p = np.array(0.396), np.array(0.685)
    g = hold_band(h, 0.3)
    b = float(neighbour_row_offsets(h, g, p, 2.5, 0.5))
    assert b == pytest.approx(0.5 * 2.5 * 0.096)
    old = float(2.5 * g - max(0.5 * 2.5 * g, p))
    assert old == pytest.approx(-0.445)
    # within the band: hold unless j's predicted closing exceeds γ h
    assert (
        float(neighbour_row_offsets(np.array(0.2), np.array(0.0), np.array(0.3), 2.5, 0.5)) == 0.0
    )
    assert float(
        neighbour_row_offsets(np.array(0.1), np.array(0.0), np.array(0.6), 2.5, 0.5)
    ) == pytest.approx(0.25 - 0.6)


def test_rows_of_a_detected_and_an_undetected_neighbour():
    """Detected: retreat when too close. Undetected: never approach, never pushed away;
    a band covering the robot gives no row."""
    mean = np.array([[[1.9, 0.0], [0.0, 1.9], [-3.0, 0.0]]])
    cov = np.zeros((1, 3, 2, 2))
    cov[0, 2] = np.eye(2) * 4.0  # wide: the band covers the robot
    det = np.array([[True, False, False]])
    rows = _rows(mean_body=mean, cov_body=cov, detected=det, blind_bins=0, walls=False)
    A, b, kind = rows.robot(0)
    assert list(kind) == [ROW_NEIGHBOUR, ROW_NEIGHBOUR]
    np.testing.assert_allclose(A[0], [-1.0, 0.0, 0.0])
    assert b[0] < 0  # 1.9 m < D_s: retreat along −x
    np.testing.assert_allclose(A[1], [0.0, -1.0, 0.0], atol=1e-12)
    assert b[1] == 0.0  # undetected, too close: hold


def test_diffuse_undetected_neighbours_leave_their_half_plane_to_the_blind_rows():
    """``lost_sigma_max_m``: an undetected neighbour whose std along the line of sight
    exceeds it gets no neighbour row; a tight undetected one and a detected one, whatever
    their spread, keep theirs."""
    mean = np.array([[[8.0, 0.0], [0.0, 3.5], [0.0, -9.0]]])
    cov = np.zeros((1, 3, 2, 2))
    cov[0, 0] = np.diag([2.5**2, 1.0])  # along the line of sight: σ_n = 2.5 m
    cov[0, 1] = np.diag([1.0, 0.3**2])  # σ_n = 0.3 m
    cov[0, 2] = np.diag([1.0, 2.6**2])  # σ_n = 2.6 m, but detected
    det = np.array([[False, False, True]])
    kw = dict(mean_body=mean, cov_body=cov, detected=det, blind_bins=0, walls=False)
    all_rows = _rows(**kw).robot(0)
    cut = _rows(lost_sigma_max_m=2.0, **kw).robot(0)
    assert len(all_rows[2]) == 3 and len(cut[2]) == 2
    np.testing.assert_allclose(cut[0][:, :2], [[0.0, -1.0], [0.0, 1.0]], atol=1e-12)
    loose = _rows(lost_sigma_max_m=2.6, **kw).robot(0)
    assert len(loose[2]) == 3


def test_blind_rows_slow_the_robot_only_towards_unseen_particles():
    """A cloud of an undetected neighbour 3 m behind: moving back is bounded, forward free."""
    rng = np.random.default_rng(0)
    cloud = rng.normal([-3.0, 0.0], 0.2, (400, 2))
    rows = _rows(
        mean_body=np.array([[[-3.0, 0.0]]]),
        cov_body=np.full((1, 1, 2, 2), 0.0) + np.eye(2) * 25.0,  # wide: no neighbour row
        detected=np.array([[False]]),
        particles_body=cloud[None],
        particle_mass=np.full((1, 400), 1 / 400),
        walls=False,
    )
    A, b, kind = rows.robot(0)
    assert set(kind.tolist()) == {ROW_BLIND}
    back = A @ np.array([-1.0, 0.0, 0.0]) + b
    ahead = A @ np.array([1.0, 0.0, 0.0]) + b
    side = A @ np.array([0.0, 1.0, 0.0]) + b
    assert back.min() < 0 and ahead.min() >= 0 and side.min() >= -0.3


def _drive(ctrl_params, start_world, u_fn, steps, neighbours_world, v_nb=(0.0, 0.0)):
    """Integrate one controlled robot against exact, possibly moving point neighbours."""
    ctrl = FovCbfController(CFG, ctrl_params)
    pose = np.array(start_world, dtype=np.float64)
    nb = np.array(neighbours_world, dtype=np.float64)
    dmin = np.inf
    poses = []
    for _ in range(steps):
        p_body = world_to_body(nb, pose)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        v_body = np.tile([c * v_nb[0] + s * v_nb[1], -s * v_nb[0] + c * v_nb[1]], (len(nb), 1))
        res = ctrl.solve(u_fn(pose), p_body, v_body, np.hypot(*p_body.T))
        pose = integrate_unicycle(pose, res.u[:2], res.u[2], CFG.dt_s)
        nb = nb + np.asarray(v_nb) * CFG.dt_s
        dmin = min(dmin, float(np.min(np.linalg.norm(nb - pose[:2], axis=1))))
        poses.append(pose.copy())
    return dmin, np.array(poses)


@settings(max_examples=25, deadline=None)
@given(
    st.floats(-math.pi, math.pi),
    st.floats(-1.0, 1.0),
    st.floats(-1.0, 1.0),
    st.floats(-1.0, 1.0),
    st.floats(2.6, 8.0),
)
def test_discrete_time_distance_never_below_ds_to_a_known_static_neighbour(yaw, vx, vy, w, dist):
    """Any constant u* (here spinning too): the exact-position rows keep D_s in discrete time."""
    u = np.array([vx, vy, w * CFG.omega_max_radps])
    dmin, _ = _drive(ControllerParams(), (20.0, 20.0, yaw), lambda _: u, 80, [(20.0 + dist, 20.0)])
    assert dmin >= CFG.safety_distance_m - 1e-9


def test_a_neighbour_predicted_to_charge_is_answered_in_full():
    """j drives at the robot at 0.8 m/s (its estimated velocity): the robot backs off and
    keeps D_s on its own, not only its share."""
    dmin, _ = _drive(
        ControllerParams(), (20.0, 20.0, 0.0), lambda _: np.zeros(3), 60, [(26.0, 20.0)], (-0.8, 0)
    )
    assert dmin >= CFG.safety_distance_m - 0.02


def test_wall_rows_stop_the_robot_at_the_wall_instead_of_sliding():
    """u* pushes 45° into the wall: the robot moves along it, never into the projection."""
    prm = ControllerParams()
    ctrl = FovCbfController(CFG, prm)
    pose = np.array([20.0, 38.0, 0.0])
    lo, hi = CFG.robot_radius_m, CFG.arena_size_m - CFG.robot_radius_m
    for _ in range(60):
        rows = _rows(pose_world=pose[None], blind_bins=0)
        u_star = np.array([0.7, 0.7, 0.0])  # body = world here (yaw 0): 45° into y = L
        res = ctrl.solve(
            u_star, np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), None, rows.robot(0)
        )
        new = integrate_unicycle(pose, res.u[:2], res.u[2], CFG.dt_s)
        assert new[1] <= hi + 1e-9 and new[0] <= hi  # the env's projection is never needed
        pose = new
    assert pose[1] > hi - 0.1  # it got to the wall
    assert pose[0] > 26.0  # and kept moving along it
    assert lo < pose[0]


def test_pair_running_the_same_rows_shares_the_budget():
    """Two controllers head-on with exact mutual positions: they meet no closer than D_s and
    each spends about half of the closing (symmetric stop)."""
    ca, cb = FovCbfController(CFG), FovCbfController(CFG)
    pa, pb = np.array([15.0, 20.0, 0.0]), np.array([25.0, 20.0, math.pi])
    fwd = np.array([1.0, 0.0, 0.0])
    for _ in range(80):
        ra = ca.solve(fwd, world_to_body(pb[None, :2], pa), np.zeros((1, 2)), np.ones(1))
        rb = cb.solve(fwd, world_to_body(pa[None, :2], pb), np.zeros((1, 2)), np.ones(1))
        pa = integrate_unicycle(pa, ra.u[:2], ra.u[2], CFG.dt_s)
        pb = integrate_unicycle(pb, rb.u[:2], rb.u[2], CFG.dt_s)
        assert np.linalg.norm(pa[:2] - pb[:2]) >= CFG.safety_distance_m
    assert abs((pa[0] - 15.0) - (25.0 - pb[0])) < 0.05
    assert np.linalg.norm(pa[:2] - pb[:2]) < CFG.safety_distance_m + 0.5  # and they got close


def test_rows_shapes_and_padding():
    rng = np.random.default_rng(2)
    R, M, P = 4, 3, 90
    rows = _rows(
        mean_body=rng.normal(0, 5, (R, M, 2)),
        cov_body=np.tile(np.eye(2) * 0.1, (R, M, 1, 1)),
        detected=rng.random((R, M)) < 0.5,
        pose_world=np.column_stack([rng.uniform(1, 39, (R, 2)), rng.uniform(-3, 3, R)]),
        particles_body=rng.normal(0, 4, (R, P, 2)),
        particle_mass=np.full((R, P), 1 / 30),
    )
    K = M + ControllerParams().blind_bins + 4
    assert rows.A.shape == (R, K, 3) and rows.b.shape == (R, K) and rows.kind.shape == (R, K)
    assert np.all(rows.A[..., 2] == 0.0)
    pad = rows.kind < 0
    assert np.all(np.isinf(rows.b[pad]))
    assert np.all(rows.kind[:, -4:] == ROW_WALL)
    real = ~pad
    np.testing.assert_allclose(np.linalg.norm(rows.A[real][:, :2], axis=1), 1.0)


def test_density_blind_rows_fire_for_many_diffuse_beliefs_only_outside_the_view():
    """23 lost neighbours with σ = 10 m clouds around the robot (a dense team): approaching
    the sectors it cannot see is forbidden; 5 such neighbours (a sparse team) add no row;
    detected neighbours and the camera's own sector never do; the count matches a Monte
    Carlo estimate of the Gaussians' mass in the slice."""
    from fov_marl.control.safety import blind_density_rows

    rng = np.random.default_rng(4)
    fov = math.radians(120.0)

    def rows(m, detected=False):
        mu = rng.normal(0.0, 6.0, (1, m, 2))
        cov = np.tile(np.eye(2) * 100.0, (1, m, 1, 1))
        det = np.full((1, m), detected)
        return blind_density_rows(mu, cov, det, 16, 0.02, 2.83, fov)

    _, b, _ = rows(23)
    th = -math.pi + (np.arange(16) + 0.5) * (2 * math.pi / 16)
    visible = np.abs(th) <= fov / 2 - math.pi / 16
    assert np.all(np.isinf(b[0, visible]))
    assert np.all(b[0, ~visible] == 0.0)
    assert np.all(np.isinf(rows(5)[1]))
    assert np.all(np.isinf(rows(23, detected=True)[1]))
    # the approximation of the expected count against Monte Carlo (one wide neighbour)
    mu = np.array([[[3.0, -2.0]]])
    cov = np.array([[[[9.0, 2.0], [2.0, 6.0]]]])
    k = 3
    x = rng.multivariate_normal(mu[0, 0], cov[0, 0], 400_000)
    ang = np.arctan2(x[:, 1], x[:, 0])
    inside = (np.hypot(x[:, 0], x[:, 1]) < 2.83) & (
        np.floor((ang + math.pi) / (2 * math.pi / 16)).astype(int) == k
    )
    for risk in (0.5 * inside.mean(), 2.0 * inside.mean()):
        _, b1, _ = blind_density_rows(mu, cov, np.zeros((1, 1), bool), 16, risk, 2.83, fov)
        assert (b1[0, k] == 0.0) == (risk < inside.mean())


def test_last_seen_rows_forbid_approaching_where_a_lost_neighbour_was():
    """A neighbour lost 2.8 m behind the robot: once the disk it can have reached covers
    D_s, the row forbids any speed towards the point and nothing else (moving away, or
    sideways, stays free); a point in view, beyond the radius, never seen, or of a
    detected neighbour gives no row; while the disk is small the robot may approach at
    the shared discrete-time rate."""
    from fov_marl.control.safety import last_seen_rows

    fov = math.radians(120.0)
    kw = dict(radius_m=5.0, reach_sigma_m=0.74, v_max_mps=1.0, fov_rad=fov, detection_range_m=10.0)
    c = np.array([[[-2.8, 0.0], [2.8, 0.0], [-6.0, 0.0], [np.nan, np.nan], [0.0, 3.0]]])
    det = np.array([[False, False, False, False, True]])
    n, h = last_seen_rows(c, np.full((1, 5), 1.0), det, **kw)
    assert np.isfinite(h[0]).tolist() == [True, False, False, False, False]
    np.testing.assert_allclose(n[0, 0], [-1.0, 0.0])
    np.testing.assert_allclose(h[0, 0], 2.8 - 0.74 - 1.0)

    def rows(age):
        return _rows(
            mean_body=np.array([[[20.0, 15.0]]]),  # the belief has drifted far away
            cov_body=np.tile(np.eye(2) * 4.0, (1, 1, 1, 1)),
            detected=np.zeros((1, 1), bool),
            last_seen_body=np.array([[[-2.8, 0.0]]]),
            last_seen_age_s=np.array([[age]]),
            last_seen_radius_m=5.0,
            reach_sigma_m=0.74,
            detection_range_m=10.0,
            fov_rad=fov,
        )

    late = rows(2.0)
    A, b, kind = late.robot(0)
    row = np.flatnonzero((A[:, 0] > 0.99) & (kind == ROW_LAST_SEEN))
    assert row.size == 1 and b[row[0]] == 0.0  # −vx ≤ 0: no backing towards it
    for u, ok in (([-0.5, 0.0, 0.0], False), ([0.5, 0.0, 0.0], True), ([0.0, 1.0, 0.0], True)):
        assert bool(np.all(A[row] @ np.array(u) + b[row] >= -1e-12)) == ok, u
    early = rows(0.0)
    A0, b0, k0 = early.robot(0)
    r0 = np.flatnonzero((A0[:, 0] > 0.99) & (k0 == ROW_LAST_SEEN))
    m_arc = arc_margin(CFG.v_max_mps, CFG.omega_max_radps, CFG.dt_s)
    gain = ControllerParams().responsibility * ControllerParams().safety_gain
    np.testing.assert_allclose(b0[r0[0]], gain * (2.8 - 0.74 - CFG.safety_distance_m - m_arc))


def test_pipeline_carries_last_seen_points_into_the_body_frame():
    """The pipeline's last-seen point of a detected neighbour is its estimate; after the
    robot turns away, the point (in the new body frame) is where the neighbour really is
    when it stood still, within the measurement noise."""
    from fov_marl.envs import fov_coverage_v0
    from fov_marl.pipeline import PfCbfPipeline

    poses = np.array([[10.0, 10.0, 0.0], [12.8, 10.0, math.pi], [30.0, 30.0, 0.0]])
    env = fov_coverage_v0.parallel_env(n_agents=3, initial_poses=poses, fov_deg=120.0)
    obs, _ = env.reset(seed=1)
    pipe = PfCbfPipeline(env.config)
    pipe.reset(obs, seed=1, initial_poses_world=poses)
    spin = {a: np.array([0.0, 0.0, 0.0], np.float32) for a in env.agents}
    spin["robot_0"] = np.array([0.0, 0.0, 1.0], np.float32)  # turn at ω_max
    for _ in range(11):  # ~ 3.3 rad: robot 1 ends behind robot 0
        obs, *_ = env.step(spin)
        pipe._applied = np.stack([spin[a] for a in env.agents])
        pipe.observe(obs)
    assert not pipe._est["detected"][0, 0]
    last = pipe._last_seen_body()[0, 0]
    truth = world_to_body(env.poses[1, :2], env.poses[0])
    assert np.linalg.norm(last - truth) < 1.0, (last, truth)
    rows = pipe.safety_rows()
    A, b, kind = rows.robot(0)
    n = last / np.linalg.norm(last)
    towards = np.flatnonzero((kind == ROW_LAST_SEEN) & (np.abs(A[:, :2] @ n + 1.0) < 1e-9))
    assert towards.size == 1 and b[towards[0]] == 0.0


def test_blind_travel_is_the_net_displacement_since_the_robot_looked_that_way():
    """e sums the world-frame displacement (jitter cancels, moving back undoes travel),
    leaks with its time constant, and is zeroed once its direction comes into view."""
    from fov_marl.control.safety import blind_travel_reset, blind_travel_step

    yaw = np.array([0.0, math.pi / 2])
    e = np.zeros((2, 2))
    e = blind_travel_step(e, np.array([[0.0, 1.0], [1.0, 0.0]]), yaw, 0.2)
    np.testing.assert_allclose(e, [[0.0, 0.2], [0.0, 0.2]], atol=1e-12)  # both went +y
    e = blind_travel_step(e, np.array([[0.0, -1.0], [0.0, 0.0]]), yaw, 0.2)
    np.testing.assert_allclose(e[0], [0.0, 0.0], atol=1e-12)  # came back
    leaky = blind_travel_step(np.array([[1.0, 0.0]]), np.zeros((1, 2)), yaw[:1], 0.2, 10.0)
    np.testing.assert_allclose(leaky, [[math.exp(-0.02), 0.0]])
    fov = math.radians(120.0)
    e = np.array([[0.0, 1.0], [0.0, 1.0]])  # +y in the world
    out = blind_travel_reset(e, np.array([0.0, math.pi / 2]), fov, math.radians(10.0))
    np.testing.assert_allclose(out, [[0.0, 1.0], [0.0, 0.0]])  # robot 1 faces +y


def test_blind_travel_row_stops_travel_along_the_budget_only():
    """‖e‖ ≥ B: no speed along e (the robot may stop, go back, sideways); ‖e‖ < B: at most
    what is left of the budget in one step."""
    full = _rows(blind_travel_body=np.array([[0.0, 1.0]]), blind_travel_m=1.0)
    A, b, kind = full.robot(0)
    row = np.flatnonzero(np.abs(A[:, 1] + 1.0) < 1e-12)
    assert row.size == 1 and kind[row[0]] == ROW_BUDGET and b[row[0]] == 0.0
    for u, ok in (([0.0, 0.3, 0.0], False), ([0.0, -1.0, 0.0], True), ([1.0, 0.0, 1.0], True)):
        assert bool(A[row[0]] @ np.array(u) + b[row[0]] >= 0.0) == ok, u
    part = _rows(blind_travel_body=np.array([[0.0, 0.9]]), blind_travel_m=1.0)
    A, b, _ = part.robot(0)
    row = np.flatnonzero(np.abs(A[:, 1] + 1.0) < 1e-12)
    np.testing.assert_allclose(b[row[0]], 0.1 / CFG.dt_s)
    assert _rows(blind_travel_body=np.zeros((1, 2)), blind_travel_m=1.0).robot(0)[0].shape[0] == 0


# ------------------------------------------------------- blind travel per bearing (2e)
def _bearing_travel_reference(c, v_body, yaw, dt, memory_s, floor_m, omega):
    """Loop reference of bearing_travel_step: one robot, one bearing at a time; the arc
    integrated in 2000 small straight pieces."""
    lam = math.exp(-dt / memory_s) if math.isfinite(memory_s) else 1.0
    out = np.empty_like(c)
    for r in range(c.shape[0]):
        dx = dy = 0.0
        n_sub = 2000
        for i in range(n_sub):
            th = yaw[r] + omega[r] * dt * (i + 0.5) / n_sub
            cs, sn = math.cos(th), math.sin(th)
            dx += (cs * v_body[r, 0] - sn * v_body[r, 1]) * dt / n_sub
            dy += (sn * v_body[r, 0] + cs * v_body[r, 1]) * dt / n_sub
        for k in range(c.shape[1]):
            ang = 2.0 * math.pi * k / c.shape[1]
            out[r, k] = max(-floor_m, lam * c[r, k] + math.cos(ang) * dx + math.sin(ang) * dy)
    return out


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    k=st.sampled_from([4, 7, 24, 36]),
    memory_s=st.sampled_from([math.inf, 30.0, 1.0]),
    floor_m=st.sampled_from([0.0, 0.5]),
)
def test_bearing_travel_step_matches_its_loop_reference(seed, k, memory_s, floor_m):
    from fov_marl.control.safety import bearing_travel_step

    rng = np.random.default_rng(seed)
    c = rng.uniform(-0.5, 1.0, (3, k))
    v = rng.uniform(-1.0, 1.0, (3, 2))
    yaw = rng.uniform(-4.0, 4.0, 3)
    w = rng.uniform(-1.5, 1.5, 3)
    np.testing.assert_allclose(
        bearing_travel_step(c, v, yaw, 0.2, memory_s, floor_m, omega_radps=w),
        _bearing_travel_reference(c, v, yaw, 0.2, memory_s, floor_m, w),
        atol=1e-8,
    )
    np.testing.assert_allclose(  # without ω: the straight step
        bearing_travel_step(c, v, yaw, 0.2, memory_s, floor_m),
        _bearing_travel_reference(c, v, yaw, 0.2, memory_s, floor_m, np.zeros(3)),
        atol=1e-8,
    )


def test_bearing_travel_counts_the_approach_beside_the_direction_of_travel():
    """Driving forward (in view) spends the budget of the bearings beside the view
    (cos ψ of each step), undoes it driving back, builds at most F of credit, and a
    bearing is zeroed only when its whole sector (β/2 − π/K) is in view."""
    from fov_marl.control.safety import bearing_travel_reset, bearing_travel_step

    K = 24  # 15° bins
    yaw = np.array([0.0])
    c = bearing_travel_step(np.zeros((1, K)), np.array([[1.0, 0.0]]), yaw, 0.2)
    ang = 2.0 * math.pi * np.arange(K) / K
    np.testing.assert_allclose(c[0], np.maximum(0.0, 0.2 * np.cos(ang)), atol=1e-12)
    assert c[0, 2] == pytest.approx(0.2 * math.cos(math.radians(30.0)))  # beside a 45° view
    back = bearing_travel_step(c, np.array([[-1.0, 0.0]]), yaw, 0.2, floor_m=0.5)
    # forward then back: the bearings ahead are back at 0, those behind now approached
    np.testing.assert_allclose(back[0], np.maximum(0.0, -0.2 * np.cos(ang)), atol=1e-12)
    away = np.zeros((1, K))
    for _ in range(10):  # 2 m away from bearing 0
        away = bearing_travel_step(away, np.array([[-1.0, 0.0]]), yaw, 0.2, floor_m=0.5)
    assert away[0, 0] == pytest.approx(-0.5)  # at most F of credit
    # the default F = 0 (ControllerParams.blind_travel_credit_m): moving away earns none,
    # so driving back towards bearing 0 spends the budget from the first metre
    none = np.zeros((1, K))
    for _ in range(10):
        none = bearing_travel_step(none, np.array([[-1.0, 0.0]]), yaw, 0.2)
    assert none[0, 0] == 0.0
    none = bearing_travel_step(none, np.array([[1.0, 0.0]]), yaw, 0.2)
    assert none[0, 0] == pytest.approx(0.2)
    fov = math.radians(45.0)
    seen = bearing_travel_reset(np.ones((1, K)), yaw, fov, math.pi / K)
    # |bearing| <= 22.5° - 7.5° = 15°: bins 0°, ±15° only
    assert set(np.flatnonzero(seen[0] == 0.0)) == {0, 1, K - 1}
    turned = bearing_travel_reset(np.ones((1, K)), np.array([math.radians(30.0)]), fov, math.pi / K)
    assert set(np.flatnonzero(turned[0] == 0.0)) == {1, 2, 3}  # world bearings 15-45°
    # a 360° camera sees every bearing, straight behind included (no edge, no margin)
    assert not bearing_travel_reset(np.ones((2, K)), np.array([0.0, 2.0]), 2 * math.pi, 0.1).any()
    near = bearing_travel_reset(np.ones((1, K)), yaw, math.radians(359.0), math.pi / K)
    assert set(np.flatnonzero(near[0] != 0.0)) == {K // 2}  # 359°: the bin behind is not


def test_bearing_travel_rows_bind_only_near_the_budget():
    """Row k: n_k · v ≤ max(0, (B − c_k)/dt) in Σ_i, written only where B − c_k < v_max dt;
    through team_safety_rows they replace the single vector's row."""
    from fov_marl.control.safety import bearing_travel_rows, team_safety_rows

    K, B = 24, 0.5
    c = np.zeros((1, K))
    c[0, 2] = 0.45  # world bearing 30°: 0.05 m left
    c[0, 12] = 0.1  # far from spent: no row
    yaw = np.array([math.radians(30.0)])  # bearing 2 is straight ahead in Σ_i
    A, b, h = bearing_travel_rows(c, yaw, B, 0.2, 1.0)
    assert np.isfinite(b).sum() == 1 and np.isfinite(b[0, 2])
    np.testing.assert_allclose(A[0, 2], [-1.0, 0.0, 0.0], atol=1e-12)
    assert b[0, 2] == pytest.approx(0.05 / 0.2) and h[0, 2] == pytest.approx(0.05)
    c[0, 2] = 0.6  # overspent (one step): hold, never pushed back
    _, b, _ = bearing_travel_rows(c, yaw, B, 0.2, 1.0)
    assert b[0, 2] == 0.0
    par = ControllerParams(blind_travel_m=B, blind_travel_bearings=K)
    pose = np.array([[20.0, 20.0, yaw[0]]])
    common = dict(
        mean_body=np.zeros((1, 0, 2)),
        cov_body=np.zeros((1, 0, 2, 2)),
        detected=np.zeros((1, 0), dtype=bool),
        pose_world=pose,
        blind_travel_body=np.array([[0.0, 0.49]]),  # ignored with the per-bearing budget
    )
    rows = team_safety_rows(CFG, par, bearing_travel_m=c, **common)
    A, b, kind = rows.robot(0)
    budget = (kind == ROW_BUDGET) & (b == 0.0)
    assert budget.sum() == 1 and np.allclose(A[budget][0], [-1.0, 0.0, 0.0])
    vec = team_safety_rows(CFG, ControllerParams(blind_travel_m=B), bearing_travel_m=c, **common)
    A, b, kind = vec.robot(0)
    assert (kind == ROW_BUDGET).sum() == 1 and np.allclose(A[kind == ROW_BUDGET][0], [0, -1, 0])


def test_bearing_travel_rows_cover_unseen_bearings_when_one_step_exceeds_the_budget():
    """Red team 5: with v_max dt > B a bearing outside the view with c_k = 0 had no row,
    and one step carried the robot v_max dt (0.99 m at 5 m/s, dt 0.2 s) towards it.
    With β given, every bearing outside the view gets ``n_k · v ≤ (B − c_k)/dt`` when
    ``B − c_k < v_max dt``; the bearings in view (β/2 − π/K) none."""
    from fov_marl.control.safety import bearing_angles_body, bearing_travel_rows

    K, B, fov = 24, 0.5, math.radians(120.0)
    c = np.zeros((1, K))
    yaw = np.array([0.3])
    ang = bearing_angles_body(K, yaw)[0]
    in_view = np.abs(ang) <= 0.5 * fov - math.pi / K + 1e-9
    _, b, _ = bearing_travel_rows(c, yaw, B, 0.2, 5.0, fov)  # v_max dt = 1 m > B
    assert np.all(np.isfinite(b[0]) == ~in_view)
    np.testing.assert_allclose(b[0, ~in_view], B / 0.2)
    _, b_old, _ = bearing_travel_rows(c, yaw, B, 0.2, 5.0)  # without β: the old rule
    assert not np.isfinite(b_old).any()
    _, b, _ = bearing_travel_rows(c, yaw, B, 0.2, 1.0, fov)  # v_max dt = 0.2 m ≤ B
    assert not np.isfinite(b).any()  # the defaults' case: the same rows as before
    _, b, _ = bearing_travel_rows(c, yaw, B, 0.2, 5.0, 2.0 * math.pi)  # 360°: all in view
    assert not np.isfinite(b).any()


@pytest.mark.parametrize(("v_max", "dt"), [(5.0, 0.2), (1.0, 1.0), (2.0, 0.5)])
def test_filtered_robots_never_step_further_than_the_budget_into_an_unseen_bearing(v_max, dt):
    """The red team's episode (random actions, N = 3, β = 120°, 20 m arena, seed 0): no
    step moves a robot more than B (+ the arc's curvature) towards a bearing outside the
    view it had at the step's start (before: 0.71-0.995 m with B = 0.5 m), on the budget
    alone (``blind_travel_reach`` off, the default). With it (safety Section 2f)
    a longer blind step goes only where no neighbour can be: no step approaches a
    neighbour out of view and within H = D_s + 2 B + 2 v_max dt by more than B (over the
    bins' spacing, 1/cos 7.5°; at v_max dt = 1 m some blind steps are 0.56 m)."""
    assert _worst_blind_step(v_max, dt, {"blind_travel_reach": False})[0] <= 0.5 + 0.05
    _, approach = _worst_blind_step(v_max, dt, {"blind_travel_reach": True})
    assert approach <= 0.5 / math.cos(math.pi / 24) + 0.05


def test_blind_travel_bearings_validated():
    for bad in (1, 3, -1, 361, 2.5, True):
        with pytest.raises(ValueError, match="blind_travel_bearings"):
            ControllerParams(blind_travel_bearings=bad)
    assert ControllerParams(blind_travel_bearings=4).blind_travel_bearings == 4
    for bad in (-1.0, 90.5, float("nan"), "10"):
        with pytest.raises(ValueError, match="blind_travel_view_deg"):
            ControllerParams(blind_travel_view_deg=bad)
    assert ControllerParams(blind_travel_view_deg=90.0).blind_travel_view_deg == 90.0
    assert ControllerParams().blind_travel_credit_m == 0.0
    assert ControllerParams(blind_travel_credit_m=0.5).blind_travel_credit_m == 0.5
    for bad in (-0.1, 100.5, float("nan"), math.inf, "0.5", None):
        with pytest.raises(ValueError, match=r"blind_travel_credit_m .*\[0\.0, 100\.0\]"):
            ControllerParams(blind_travel_credit_m=bad)
    # the leak: (0, 1e6] s, or inf (none, the safety filter's); the same rule as the cut
    # of lost_sigma_max_m (check_real's inf_ok)
    for name in ("blind_travel_memory_s", "lost_sigma_max_m"):
        assert getattr(ControllerParams(**{name: math.inf}), name) == math.inf
        for bad in (0.0, -math.inf, float("nan"), 2e6, "30"):
            with pytest.raises(ValueError, match=rf"{name} .*\(0\.0, 1e6\] or inf"):
                ControllerParams(**{name: bad})


def test_blind_travel_vector_forgets_travel_only_inside_its_view_margin():
    """The single vector resets where its direction is within β/2 − margin of the heading:
    with the filter's 30° at β = 120°, net travel 35° off the heading is kept (it could
    approach a point just outside the view at cos 25°), 25° off it is forgotten."""
    from fov_marl.control.safety import blind_travel_reset

    e = np.array([[math.cos(math.radians(35.0)), math.sin(math.radians(35.0))],
                  [math.cos(math.radians(25.0)), -math.sin(math.radians(25.0))]])  # fmt: skip
    yaw = np.zeros(2)
    kept = blind_travel_reset(e, yaw, math.radians(120.0), math.radians(30.0))
    np.testing.assert_array_equal(kept[0], e[0])
    np.testing.assert_array_equal(kept[1], [0.0, 0.0])
    pfcbf = blind_travel_reset(e, yaw, math.radians(120.0), math.radians(10.0))
    assert not pfcbf.any()  # 10°: both forgotten
    # 360°: no edge, travel straight backwards is in view too
    back = np.array([[-1.0, 0.0], [-1.0, 0.01]])
    assert not blind_travel_reset(back, yaw, 2 * math.pi, math.radians(30.0)).any()
    assert np.array_equal(
        blind_travel_reset(back, yaw, math.radians(359.0), math.radians(30.0)), back
    )


# ------------------------------------------------------------- the bearing cone (1b)
def _spd(rng, scale):
    L = rng.normal(size=(2, 2)) * scale
    return L @ L.T + 1e-4 * np.eye(2)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.05, 8.0), st.floats(-1.0, 1.0))
def test_bearing_cone_matches_the_reference(seed, r, h):
    """``sin α = min(1, z σ_t / ‖μ‖)`` with σ_t across the line of sight, from a rotation."""
    rng = np.random.default_rng(seed)
    phi = rng.uniform(-math.pi, math.pi)
    mu = r * np.array([math.cos(phi), math.sin(phi)])
    S = _spd(rng, rng.uniform(0.01, 1.0))
    z = risk_quantile(0.01)
    sin_a, inside = bearing_cone(mu[None, None], S[None, None], np.array([[h]]), z)
    rot90 = np.array([[0.0, -1.0], [1.0, 0.0]])
    t = rot90 @ (mu / np.linalg.norm(mu))
    ref = min(1.0, z * math.sqrt(t @ S @ t) / np.linalg.norm(mu))
    assert sin_a[0, 0] == pytest.approx(ref, rel=1e-9, abs=1e-12)
    assert bool(inside[0, 0]) == (h < 0.0)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000), st.floats(1.05, 3.5), st.booleans())
def test_inside_ds_no_allowed_step_approaches_any_bearing_of_the_cone(seed, r, det):
    """Within D_s (h < 0, the row holds or retreats) every velocity a detected neighbour's
    rows allow has ``p · v ≤ 0`` for each direction p of the cone: a straight step shortens
    the distance to no bearing the neighbour may lie at. Beyond D_s, and for undetected
    neighbours, there are no cone rows."""
    rng = np.random.default_rng(seed)
    phi = rng.uniform(-math.pi, math.pi)
    n = np.array([math.cos(phi), math.sin(phi)])
    S = _spd(rng, rng.uniform(0.05, 0.4))
    cap = math.radians(45.0)
    rows = _rows(
        mean_body=(r * n)[None, None],
        cov_body=S[None, None],
        detected=np.array([[det]]),
        walls=False,
        blind_bins=0,
        bearing_cone_max_rad=cap,
    )
    keep = rows.kind[0] >= 0
    A, b, kind, h = rows.A[0][keep], rows.b[0][keep], rows.kind[0][keep], rows.h[0][keep]
    if not det or not np.any(kind == ROW_NEIGHBOUR) or h.min() >= 0.0:
        assert not np.any(kind == ROW_CONE)  # undetected or beyond D_s: none
        return
    assert np.sum(kind == ROW_CONE) == 2
    sin_a, _ = bearing_cone((r * n)[None, None], S[None, None], h[:1][None], risk_quantile(0.01))
    alpha = math.asin(min(float(sin_a[0, 0]), math.sin(cap)))
    v = rng.uniform(-1.0, 1.0, size=(4000, 2))
    u = np.concatenate([v, np.zeros((4000, 1))], 1)
    ok = (u @ A.T + b >= 0.0).all(axis=1)
    psi = phi + np.linspace(-alpha, alpha, 41)
    p = np.stack([np.cos(psi), np.sin(psi)], 1)
    if b.max() <= 0.0:
        assert (v[ok] @ p.T).max(initial=-np.inf) <= 1e-9
    # and the cone costs nothing the plain row allows when moving straight away
    away = -np.linalg.norm(b[kind == ROW_NEIGHBOUR]) / math.cos(alpha) * n - 1e-9 * n
    assert (A[:, :2] @ away + b >= -1e-9).all()


def _fallback_turn(A_xy, b, kind):
    from fov_marl.control.batched import BatchedFovCbfController

    A = np.concatenate([np.asarray(A_xy, float), np.zeros((len(b), 1))], 1)
    b, kind = np.asarray(b, float), np.asarray(kind, np.int8)
    one = FovCbfController(CFG, ControllerParams())._safe_fallback(None, A, b, kind)
    batch = BatchedFovCbfController(CFG, ControllerParams())._safe_fallback(
        np.full((1, 3), np.nan), A[None], b[None], kind[None], np.ones((1, len(b)), bool)
    )
    np.testing.assert_allclose(batch[0], one, atol=1e-12)
    assert one[:2].tolist() == [0.0, 0.0]
    return one[2]


def _row_at(deg):  # A of a row "do not approach bearing deg": [-n_x, -n_y]
    return [-math.cos(math.radians(deg)), -math.sin(math.radians(deg))]


def test_safe_fallback_turns_to_the_most_dangerous_row_nearest_the_camera_axis():
    """Two neighbours on opposite sides with nearly equal b̃: the one nearer the camera's
    axis is the target (turning keeps it so: no back-and-forth); a clearly more dangerous
    one wins whatever its bearing; wall and bearing-cone rows are never targets."""
    near_tie = _fallback_turn([_row_at(100.0), _row_at(-20.0)], [-0.50, -0.45], [0, 0])
    assert near_tie < 0.0  # towards -20°
    clear = _fallback_turn([_row_at(100.0), _row_at(-20.0)], [-1.0, -0.2], [0, 0])
    assert clear > 0.0  # towards +100°
    skip = _fallback_turn(
        [_row_at(60.0), _row_at(-150.0), _row_at(-30.0)],
        [-2.0, -3.0, -0.5],
        [ROW_CONE, ROW_WALL, ROW_NEIGHBOUR],
    )
    assert skip < 0.0  # towards -30°, the only neighbour row


def test_safe_fallback_keeps_a_retreat_as_a_straight_step():
    """The QP's input is kept when it makes no row worse than standing still; while a row
    holds or retreats (b̃ ≤ 0) its yaw rate is dropped (an arc would curve into the
    neighbour), and it is kept when every row allows motion."""
    from fov_marl.control.batched import BatchedFovCbfController

    A = np.array([[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # neighbours ahead and to the left
    u_qp = np.array([-0.3, -0.5, 1.2])
    for b, w in (([-0.2, 0.0], 0.0), ([0.4, 0.6], 1.2)):
        b = np.array(b)
        kind = np.array([ROW_NEIGHBOUR, ROW_NEIGHBOUR], np.int8)
        one = FovCbfController(CFG, ControllerParams())._safe_fallback(u_qp, A, b, kind)
        np.testing.assert_array_equal(one, [-0.3, -0.5, w])
        batch = BatchedFovCbfController(CFG, ControllerParams())._safe_fallback(
            u_qp[None], A[None], b[None], kind[None], np.ones((1, 2), bool)
        )
        np.testing.assert_array_equal(batch[0], one)


def _arc_step(u: np.ndarray) -> np.ndarray:
    """``(S, 2)`` exact displacements over dt of inputs ``(S, 3)`` from the body origin."""
    return integrate_unicycle(np.zeros((u.shape[0], 3)), u[:, :2], u[:, 2], CFG.dt_s)[:, :2]


def _guard_case(rng, k):
    """k random rows ``[−n, 0] u + b ≥ 0`` (some holding, b ≤ 0) and an input meeting
    the held ones on the straight step (up to round-off)."""
    ang = rng.uniform(-math.pi, math.pi, k)
    n = np.stack([np.cos(ang), np.sin(ang)], 1)
    A = np.zeros((1, k, 3))
    A[0, :, :2] = -n
    b = np.where(rng.random(k) < 0.7, 0.0, rng.uniform(-0.3, 0.5, k))[None]
    kind = rng.choice([ROW_NEIGHBOUR, ROW_BLIND, ROW_CONE, ROW_WALL], size=(1, k)).astype(np.int8)
    for _ in range(200):
        v = rng.uniform(-1.0, 1.0, 2)
        if (n @ v <= np.maximum(b[0], 0.0) + 1e-9).all() or rng.random() < 0.05:
            break
    u = np.array([[v[0], v[1], rng.uniform(-CFG.omega_max_radps, CFG.omega_max_radps)]])
    return n, A, b, kind, u


def _worst_excess(n, b, kind, u, turned_only=False):
    """Largest ``n · Δ_arc / dt − (max(n · v, 0) + ε)`` over the held non-wall rows;
    ``turned_only``: ``Δ_arc / dt`` without its ``sinc(φ/2) ≤ 1`` (v turned by φ/2, the
    guard's own condition, tight)."""
    held = (b[0] <= 0.0) & (kind[0] != ROW_WALL)
    if not held.any():
        return -np.inf
    d = _arc_step(u)[0] / CFG.dt_s
    if turned_only:
        t = 0.5 * u[0, 2] * CFG.dt_s
        d = np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]]) @ u[0, :2]
    a = n[held] @ u[0, :2]
    return float((n[held] @ d - (np.maximum(a, 0.0) + 1e-6)).max())


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 100_000), st.integers(1, 8))
def test_arc_yaw_guard_keeps_every_held_row_on_the_exact_arc(seed, k):
    """Section 1c against the exact unicycle step: after the guard no held row (b ≤ 0; not
    walls) is approached on the arc more than on the straight step (+ε); the translation
    is unchanged; ω keeps its sign and only shrinks; and the bound is tight: a yaw rate
    1e-6 rad/s nearer the input's breaks some held row (so the guard does not slow turns
    it need not; tight for v turned by φ/2, the arc's ``sinc(φ/2) ≤ 1`` aside)."""
    rng = np.random.default_rng(seed)
    n, A, b, kind, u = _guard_case(rng, k)
    g = arc_yaw_guard(u, A, b, kind, np.ones((1, k), bool), CFG.dt_s)
    assert g[0, :2].tolist() == u[0, :2].tolist()
    assert abs(g[0, 2]) <= abs(u[0, 2]) and g[0, 2] * u[0, 2] >= 0.0
    assert _worst_excess(n, b, kind, g) <= 1e-12
    if abs(g[0, 2]) < abs(u[0, 2]) - 1e-9:
        nearer = g.copy()
        nearer[0, 2] += math.copysign(1e-6, u[0, 2])
        assert _worst_excess(n, b, kind, nearer, turned_only=True) > 0.0


def test_arc_yaw_guard_stops_the_curve_into_a_packed_neighbour():
    """The traced dip: an unseen neighbour 1.1 m to the left, its row holds (v_y ≤ 0);
    creeping forward at 0.05 m/s while turning left at ω_max curves 1 mm towards it. The
    guard stops that turn (the creep cannot turn left at all without approaching), keeps
    the right turn and every turn in place, and ignores padding and wall rows."""
    A = np.array([[[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]])
    b = np.array([[0.0, -0.5, 0.0]])
    kind = np.array([[ROW_NEIGHBOUR, ROW_WALL, ROW_BLIND]], np.int8)
    keep = np.array([[True, True, False]])
    w = CFG.omega_max_radps
    creep = np.array([[0.05, 0.0, w]])
    assert _arc_step(creep)[0, 1] > 5e-4  # it does approach, 0.75 mm
    left = arc_yaw_guard(creep, A, b, kind, keep, CFG.dt_s)
    assert left[0, 2] == pytest.approx(0.0, abs=1e-3)
    assert _arc_step(left)[0, 1] <= 1e-6 * CFG.dt_s
    for ok in ([0.05, 0.0, -w], [0.0, 0.0, w], [0.0, -0.5, w]):
        ok = np.array([ok])
        np.testing.assert_array_equal(arc_yaw_guard(ok, A, b, kind, keep, CFG.dt_s), ok)
    alone = arc_yaw_guard(creep, A, b, kind, np.array([[False, True, False]]), CFG.dt_s)
    np.testing.assert_array_equal(alone, creep)  # the wall row and no held neighbour row


def test_controllers_apply_the_arc_guard_alike():
    """Both controllers (per robot and batched) clip the same yaw rate, and switching the
    guard off gives back the unguarded input."""
    from fov_marl.control.batched import BatchedFovCbfController

    mean = np.array([[0.0, 1.1]])
    cov = np.diag([0.01, 0.01])[None]
    rows = _rows(
        mean_body=mean[None], cov_body=cov[None], detected=np.array([[False]]),
        walls=False, blind_bins=0,
    )  # fmt: skip
    safety = rows.robot(0)
    u_star = np.array([0.05, 0.0, CFG.omega_max_radps])
    out = {}
    for guard, stop in ((True, False), (True, True), (False, True)):
        p = ControllerParams(
            arc_yaw_guard=guard, arc_guard_stop=stop, look_gain=0.0, motion_cone=False
        )
        one = FovCbfController(CFG, p).solve(
            u_star, mean, np.zeros((1, 2)), np.zeros(1), safety=safety,
            detected=np.array([False]),
        )  # fmt: skip
        many = BatchedFovCbfController(CFG, p).solve(
            u_star[None], mean[None], np.zeros((1, 1, 2)), np.zeros((1, 1)), safety=rows,
            detected=np.array([[False]]),
        )  # fmt: skip
        np.testing.assert_allclose(many.u[0], one.u, atol=1e-9)
        out[guard, stop] = one.u
    free = out[False, True]
    assert free[2] > 0.5 * CFG.omega_max_radps  # unguarded: the FoV levels turn left
    assert free[0] > 0.0  # ... while creeping forward
    slowed = out[True, False]  # the guard keeps the creep and slows the turn
    assert abs(slowed[2]) < 1e-3 and slowed[:2].tolist() == free[:2].tolist()
    stopped = out[True, True]  # the creep costs less than the turn: stop and turn
    assert stopped[:2].tolist() == [0.0, 0.0] and stopped[2] == free[2]


def test_arc_guard_stop_keeps_the_turn_when_the_creep_is_cheaper():
    """``stop_weight``: the traced stall (pfcbf, β = 45°, seed 7, robot 2): a blind row
    straight ahead holds (b = 0), the QP keeps a 0.01 m/s creep along it and the look
    turn at 1.05 rad/s; the plain guard slows that turn to ~0 and the robot neither moves
    nor looks. With the stop it turns in place. A fast crossing with a small turn keeps its
    translation (the slowed turn is the smaller change), and a row that needs a retreat
    (b < 0: standstill breaks it) never lets it stop."""
    A = np.array([[[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]])  # nothing ahead, nothing left
    kind = np.array([[ROW_BLIND, ROW_NEIGHBOUR]], np.int8)
    keep = np.ones((1, 2), bool)
    b = np.array([[0.0, 0.8]])
    creep = np.array([[0.0, -0.01, 1.05]])
    plain = arc_yaw_guard(creep, A, b, kind, keep, CFG.dt_s)
    assert abs(plain[0, 2]) < 2e-3 and plain[0, :2].tolist() == [0.0, -0.01]
    turned = arc_yaw_guard(creep, A, b, kind, keep, CFG.dt_s, stop_weight=1.0)
    assert turned[0].tolist() == [0.0, 0.0, 1.05]
    # a heavier yaw weight makes the slowed turn costlier still; a tiny one keeps the creep
    assert arc_yaw_guard(creep, A, b, kind, keep, CFG.dt_s, stop_weight=1e-3)[0].tolist() == (
        plain[0].tolist()
    )
    fast = np.array([[0.0, 0.9, -0.05]])  # sliding right across the held row, turning right
    g = arc_yaw_guard(fast, A, b, kind, keep, CFG.dt_s, stop_weight=1.0)
    assert g[0, :2].tolist() == [0.0, 0.9] and abs(g[0, 2]) < abs(fast[0, 2])
    retreat = np.array([[0.0, 0.8]]) - np.array([[0.0, 1.0]])  # the left row asks to back off
    np.testing.assert_array_equal(
        arc_yaw_guard(creep, A, retreat, kind, keep, CFG.dt_s, stop_weight=1.0),
        arc_yaw_guard(creep, A, retreat, kind, keep, CFG.dt_s),
    )


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 100_000), st.integers(1, 8), st.floats(0.1, 10.0))
def test_arc_guard_stop_is_the_cheaper_of_two_safe_inputs(seed, k, lam):
    """With ``stop_weight = λ`` the guard returns the plain guard's input or the turn in
    place ``(0, 0, ω)``: the latter only where the plain guard slowed the turn, every
    row holds at standstill, and it is strictly nearer the input in ``‖Δv‖² + λ² Δω²``.
    Either way no held row is approached on the exact arc beyond the straight step."""
    rng = np.random.default_rng(seed)
    n, A, b, kind, u = _guard_case(rng, k)
    keep = np.ones((1, k), bool)
    plain = arc_yaw_guard(u, A, b, kind, keep, CFG.dt_s)
    g = arc_yaw_guard(u, A, b, kind, keep, CFG.dt_s, stop_weight=lam)
    assert _worst_excess(n, b, kind, g) <= 1e-12
    if g.tolist() == plain.tolist():
        cheaper = u[0, 0] ** 2 + u[0, 1] ** 2 < (lam * (u[0, 2] - plain[0, 2])) ** 2
        assert not (plain[0, 2] != u[0, 2] and (b >= 0.0).all() and cheaper)
    else:
        assert g[0].tolist() == [0.0, 0.0, u[0, 2]]
        assert plain[0, 2] != u[0, 2] and (b >= 0.0).all()
        assert u[0, 0] ** 2 + u[0, 1] ** 2 < (lam * (u[0, 2] - plain[0, 2])) ** 2


def test_hold_cleanup_removes_a_creep_and_keeps_the_rest():
    """A held row (neighbour ahead, b̃ = 0) crept on at 1 mm/s within the cascade's
    tolerance: the clean-up removes the creep, keeps the sideways motion and ω, and keeps
    a met row met; with a retreat it cannot keep (a neighbour behind asking to move
    forward while the one ahead holds) it gives None (the safe fallback)."""
    from fov_marl.control.controller import approaches_held_row, hold_cleanup

    A = np.array([[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # do not approach +x; +y bounded
    b = np.array([0.0, 0.8])
    u = np.array([0.001, 0.5, 0.3])
    assert approaches_held_row(u[None], A[None], b[None], np.ones((1, 2), bool))[0]
    out = hold_cleanup(u, A, b, CFG.v_max_mps, 16)
    np.testing.assert_allclose(out, [0.0, 0.5, 0.3], atol=1e-12)
    assert not approaches_held_row(out[None], A[None], b[None], np.ones((1, 2), bool))[0]
    A2 = np.array([[-1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    b2 = np.array([0.0, -0.2])  # the same direction: hold, and retreat 0.2 (met by u)
    u2 = np.array([0.0, 0.0, 0.0])
    assert not approaches_held_row(u2[None], A2[None], b2[None], np.ones((1, 2), bool))[0]
    A3 = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])  # ahead holds, behind wants +x
    b3 = np.array([0.0, -0.3])
    u3 = np.array([0.01, 0.0, 0.0])  # retreats from behind, creeps into the one ahead
    assert hold_cleanup(u3, A3, b3, CFG.v_max_mps, 16) is None


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 100_000), st.integers(1, 8))
def test_hold_cleanup_never_approaches_and_never_worsens(seed, k):
    """Random rows and a near-feasible input: the clean-up's input (when there is one)
    approaches no row with b̃ ≤ 0, makes no row worse than the input did, stays in the
    polygon and keeps ω."""
    from fov_marl.control.controller import APPROACH_TOL, hold_cleanup

    rng = np.random.default_rng(seed)
    ang = rng.uniform(-math.pi, math.pi, k)
    A = np.zeros((k, 3))
    A[:, 0], A[:, 1] = -np.cos(ang), -np.sin(ang)
    b = np.where(rng.random(k) < 0.6, 0.0, rng.uniform(-0.3, 0.6, k))
    u = np.array([*rng.uniform(-0.7, 0.7, 2), rng.uniform(-1.5, 1.5)])
    out = hold_cleanup(u, A, b, 1.0, 16)
    if out is None:
        return
    val, val0 = A @ out, A @ u
    assert out[2] == u[2]
    assert (val[b <= 0.0] >= -APPROACH_TOL).all()
    assert (val >= np.minimum(-b, val0) - 1e-12).all()
    assert np.hypot(out[0], out[1]) <= 1.0 + 1e-12


def test_single_vector_budget_caps_unseen_directions_when_one_step_exceeds_it():
    """The single-vector budget (blind_travel_bearings = 0) had the per-bearing budget's
    gap: with v_max dt > B and a zero vector nothing bounded a blind step. Behind the
    filter with that budget no step moves more than B towards an unseen direction."""
    assert _worst_blind_step(5.0, 0.2, {"blind_travel_bearings": 0})[0] <= 0.5 + 0.05


def _worst_blind_step(
    v_max: float, dt: float, controller_params: dict | None = None
) -> tuple[float, float]:
    """Random actions behind the filter (N = 3, β = 120°, 20 m arena, seed 0, 150 steps):
    the longest step (m) a robot made towards a direction outside the view it had at the
    step's start, and the most a step approached a neighbour outside that view and
    within H = D_s + 2 B + 2 v_max dt (safety Section 2f)."""
    from fov_marl.envs import fov_coverage_v0
    from fov_marl.wrappers import SafetyFilterWrapper

    n, fov = 3, 120.0
    base = fov_coverage_v0.parallel_env(
        n_agents=n, fov_deg=fov, v_max_mps=v_max, dt_s=dt, arena_size_m=20.0, max_cycles=150
    )
    env = SafetyFilterWrapper(base, controller_params=controller_params)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    cfg = base.config
    horizon = cfg.safety_distance_m + 2.0 * 0.5 + 2.0 * v_max * dt
    worst = approach = 0.0
    for _ in range(150):
        before = base.poses.copy()
        act = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
        env.step({a: act[i] for i, a in enumerate(env.possible_agents)})
        d = base.poses[:, :2] - before[:, :2]
        off = np.abs((np.arctan2(d[:, 1], d[:, 0]) - before[:, 2] + np.pi) % (2 * np.pi) - np.pi)
        blind = off > math.radians(fov / 2)
        if blind.any():
            worst = max(worst, float(np.hypot(d[blind, 0], d[blind, 1]).max()))
        for i in range(n):
            for j in range(n):
                rel = before[j, :2] - before[i, :2]
                r = float(np.hypot(*rel))
                bearing = math.atan2(rel[1], rel[0]) - before[i, 2]
                unseen = abs(math.remainder(bearing, 2.0 * math.pi)) > math.radians(fov / 2)
                if i != j and unseen and r <= horizon:
                    approach = max(approach, float(d[i] @ rel) / r)
    return worst, approach


def test_detection_rows_are_the_chance_constraint_of_the_raw_detection():
    """Section 1d: n = z/‖z‖, s = ‖z‖ − z_δ σ_z with σ_z² = nᵀ Σ_MEAS n; no row (s = +inf)
    for a neighbour not detected (NaN) or a detection at the robot's centre."""
    from fov_marl.control.safety import detection_rows

    cov = np.diag([0.1, 0.4])
    zq = risk_quantile(0.01)
    z = np.array([[[3.0, 0.0], [0.0, -2.0], [np.nan, np.nan], [0.0, 0.0], [3.0, 4.0]]])
    n, s = detection_rows(z, cov, zq)
    assert np.isfinite(s[0]).tolist() == [True, True, False, False, True]
    np.testing.assert_allclose(n[0, 0], [1.0, 0.0])
    np.testing.assert_allclose(n[0, 1], [0.0, -1.0])
    np.testing.assert_allclose(s[0, 0], 3.0 - zq * math.sqrt(0.1))
    np.testing.assert_allclose(s[0, 1], 2.0 - zq * math.sqrt(0.4))
    np.testing.assert_allclose(s[0, 4], 5.0 - zq * math.sqrt(0.36 * 0.1 + 0.64 * 0.4))
    assert not n[0, 2:4].any()


def test_detection_rows_bound_the_approach_to_what_the_camera_sees_and_never_push():
    """A detected neighbour whose posterior has drifted through the robot (mean behind it,
    the red-team case) while the camera sees it 1.1 m ahead: the posterior's row asks for
    a retreat *forward*, the detection's row forbids any forward speed, so no input
    approaches the camera's neighbour. Beyond D_s + z σ the detection row allows the
    shared barrier's approach; it never demands a retreat (b ≥ 0)."""
    cov_meas = np.diag([0.5, 0.5])
    kw = dict(
        mean_body=np.array([[[-0.08, 0.0]]]),
        cov_body=np.tile(np.diag([0.2, 0.03]), (1, 1, 1, 1)),
        detected=np.ones((1, 1), bool),
        meas_cov_xy=cov_meas,
    )
    without = _rows(**kw)
    A0, b0, k0 = without.robot(0)
    post = np.flatnonzero(k0 == ROW_NEIGHBOUR)
    assert post.size == 1 and A0[post[0], 0] > 0.99 and b0[post[0]] < 0.0  # retreat forward
    rows = _rows(detection_body=np.array([[[1.1, 0.0]]]), **kw)
    A, b, kind = rows.robot(0)
    det = np.flatnonzero((kind == ROW_NEIGHBOUR) & (A[:, 0] < -0.99))
    assert det.size == 1 and b[det[0]] == 0.0
    for u in ([0.5, 0.0, 0.0], [1.0, 0.3, 0.0], [0.0, 0.0, 1.0], [-0.5, 0.0, 0.0]):
        ok = bool(A[det[0]] @ np.array(u) + b[det[0]] >= -1e-12)
        assert ok == (u[0] <= 0.0), u
    m_arc = arc_margin(CFG.v_max_mps, CFG.omega_max_radps, CFG.dt_s)
    p = ControllerParams()
    far = _rows(detection_body=np.array([[[6.0, 0.0]]]), **kw)
    A2, b2, k2 = far.robot(0)
    d2 = np.flatnonzero((k2 == ROW_NEIGHBOUR) & (A2[:, 0] < -0.99))
    s = 6.0 - risk_quantile(p.safety_risk) * math.sqrt(0.5)
    gain = p.responsibility * p.safety_gain
    np.testing.assert_allclose(b2[d2[0]], gain * (s - CFG.safety_distance_m - m_arc))
    none = _rows(detection_body=np.full((1, 1, 2), np.nan), **kw)
    assert none.robot(0)[2].size == without.robot(0)[2].size


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000), st.floats(1.05, 3.2), st.floats(-50.0, 50.0))
def test_the_detection_cone_covers_what_the_camera_sees_whatever_the_posterior(seed, r, off_deg):
    """Section 1d: a detected neighbour whose posterior sits ``off_deg`` off the camera's
    bearing (the packed-corner case: 0.70 m and 37° off, outside its own cone). Where the
    detection's barrier and the posterior's are both negative (within D_s, where the
    posterior's cone applies), every velocity the rows allow has ``p · v ≤ 0`` for each
    direction p of the detection's cone (α_z from Σ_MEAS, capped at 45°); elsewhere there
    are no such rows, and none with ``detection_cone=False``. The cone's rows never push
    (b = 0 where they exist)."""
    rng = np.random.default_rng(seed)
    phi = rng.uniform(-math.pi, math.pi)
    psi_mu = phi + math.radians(off_deg)
    cov_meas = np.diag([0.1, 0.1])
    zq = risk_quantile(0.01)
    cap = math.radians(45.0)
    kw = dict(
        mean_body=(r * np.array([math.cos(psi_mu), math.sin(psi_mu)]))[None, None],
        cov_body=_spd(rng, 0.1)[None, None],
        detected=np.ones((1, 1), bool),
        walls=False,
        blind_bins=0,
        bearing_cone_max_rad=cap,
        detection_body=(r * np.array([math.cos(phi), math.sin(phi)]))[None, None],
        meas_cov_xy=cov_meas,
    )
    rows = _rows(**kw)
    off = _rows(detection_cone=False, **kw)
    keep = rows.kind[0] >= 0
    A, b, kind = rows.A[0][keep], rows.b[0][keep], rows.kind[0][keep]
    m_arc = arc_margin(CFG.v_max_mps, CFG.omega_max_radps, CFG.dt_s)
    h_z = r - zq * math.sqrt(0.1) - CFG.safety_distance_m - m_arc
    h_post = off.h[0][0]  # the posterior's row comes first
    n_cone = np.sum(kind == ROW_CONE) - np.sum(off.kind[0] == ROW_CONE)
    inside = h_z < 0.0 and h_post < 0.0
    assert n_cone == (2 if inside else 0)
    if not inside:
        return
    cones = (kind == ROW_CONE) & np.isclose(b, 0.0)
    assert np.sum(cones) >= 2
    alpha = math.asin(min(zq * math.sqrt(0.1) / r, math.sin(cap)))
    v = rng.uniform(-1.0, 1.0, size=(4000, 2))
    u = np.concatenate([v, np.zeros((4000, 1))], 1)
    ok = (u @ A.T + b >= -1e-12).all(axis=1)
    p = np.stack([np.cos(phi + np.linspace(-alpha, alpha, 41)),
                  np.sin(phi + np.linspace(-alpha, alpha, 41))], 1)  # fmt: skip
    if ok.any():
        assert (v[ok] @ p.T).max() <= 1e-9


def test_detection_rows_are_the_filters_and_not_pfcbfs():
    """``detection_rows`` is on in the safety filter (FILTER_CONTROLLER_DEFAULTS), off in
    ControllerParams (pfcbf), and the pipeline passes the camera's report: a seen
    neighbour 2.5 m ahead gives one more neighbour row with it on, at the detection's
    bearing, and none with it off; a non-bool is refused."""
    from fov_marl.envs import fov_coverage_v0
    from fov_marl.pipeline import PfCbfPipeline
    from fov_marl.validation import ConfigError
    from fov_marl.wrappers.safety_filter import FILTER_CONTROLLER_DEFAULTS

    assert FILTER_CONTROLLER_DEFAULTS["detection_rows"] is True
    assert ControllerParams().detection_rows is False
    with pytest.raises(ConfigError, match="detection_rows"):
        ControllerParams(detection_rows=1)
    poses = np.array([[10.0, 10.0, 0.0], [12.5, 10.0, math.pi], [30.0, 30.0, 0.0]])
    env = fov_coverage_v0.parallel_env(n_agents=3, initial_poses=poses, fov_deg=120.0)
    obs, _ = env.reset(seed=1)
    counts = []
    for on in (False, True):
        pipe = PfCbfPipeline(env.config, controller_params=ControllerParams(detection_rows=on))
        pipe.reset(obs, seed=1, initial_poses_world=poses)
        assert pipe._est["detected"][0, 0]
        z = obs["robot_0"][1:3].astype(np.float64)  # robot 1's slot: [det, x, y, cos, sin]
        np.testing.assert_allclose(pipe._detection_body[0, 0], z)
        assert np.isnan(pipe._detection_body[0, 1]).all()  # robot 2: not seen
        A, b, kind = pipe.safety_rows().robot(0)
        nz = z / np.linalg.norm(z)
        counts.append(int(np.sum((kind == ROW_NEIGHBOUR) & (np.abs(A[:, :2] @ nz + 1.0) < 1e-9))))
    assert counts == [0, 1]


def test_last_seen_release_disk_needs_the_points_uncertainty_in_view():
    """``release="disk"`` (the filter's): a last-seen point 0.8 m ahead at −6° inside a
    45° view is released by ``"point"`` but kept while its disk of radius z σ_meas
    (0.74 m) reaches outside the view's sector; a point 6 m dead ahead is released by
    both, one at 9.5 m (disk beyond the 10 m range) only by ``"point"``; a bad value is
    refused, here and in ControllerParams."""
    from fov_marl.control.safety import last_seen_rows
    from fov_marl.validation import ConfigError

    fov = math.radians(45.0)
    ang = math.radians(-6.0)
    c = np.array([[[0.8 * math.cos(ang), 0.8 * math.sin(ang)], [6.0, 0.0], [9.5, 0.0]]])
    kw = dict(radius_m=20.0, reach_sigma_m=0.74, v_max_mps=1.0, fov_rad=fov, detection_range_m=10.0)
    args = (c, np.full((1, 3), 1.0), np.zeros((1, 3), bool))
    _, h_point = last_seen_rows(*args, **kw)
    _, h_disk = last_seen_rows(*args, release="disk", **kw)
    assert np.isfinite(h_point[0]).tolist() == [False, False, False]
    assert np.isfinite(h_disk[0]).tolist() == [True, False, True]
    with pytest.raises(ValueError, match="release"):
        last_seen_rows(*args, release="bearing", **kw)
    with pytest.raises(ConfigError, match="last_seen_release"):
        ControllerParams(last_seen_release="bearing")
    from fov_marl.wrappers.safety_filter import FILTER_CONTROLLER_DEFAULTS

    assert FILTER_CONTROLLER_DEFAULTS["last_seen_release"] == "disk"
    assert ControllerParams().last_seen_release == "point"


def _reach_clear_reference(centre, radius, horizon):
    """Loop reference of :func:`reach_clear` (safety Section 2f)."""
    R, M = radius.shape
    out = np.ones(R, dtype=bool)
    for r in range(R):
        for j in range(M):
            cx, cy, rad = centre[r, j, 0], centre[r, j, 1], radius[r, j]
            if not (math.isfinite(cx) and math.isfinite(cy)):
                out[r] = False  # never detected: it may be anywhere
            elif math.hypot(cx, cy) - rad <= horizon:
                out[r] = False  # it may be within H
    return out


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), m=st.integers(0, 4))
def test_reach_clear_matches_its_loop_reference(seed, m):
    from fov_marl.control.safety import reach_clear

    rng = np.random.default_rng(seed)
    centre = rng.uniform(-12.0, 12.0, (5, m, 2))
    radius = rng.uniform(0.0, 6.0, (5, m))
    centre[rng.random((5, m)) < 0.1] = np.nan  # never detected
    got = reach_clear(centre, radius, 3.4)
    np.testing.assert_array_equal(got, _reach_clear_reference(centre, radius, 3.4))


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_reach_clear_only_where_no_reachable_point_is_within_the_horizon(seed):
    """A robot is cleared only if no point of any neighbour's disk lies within H of it."""
    from fov_marl.control.safety import reach_clear

    rng = np.random.default_rng(seed)
    H = 3.4
    centre = rng.uniform(-9.0, 9.0, (1, 3, 2))
    radius = rng.uniform(0.0, 4.0, (1, 3))
    if not reach_clear(centre, radius, H)[0]:
        return
    for j in range(3):
        for _ in range(200):
            rho, phi = radius[0, j] * math.sqrt(rng.random()), rng.uniform(-math.pi, math.pi)
            p = centre[0, j] + rho * np.array([math.cos(phi), math.sin(phi)])
            assert np.hypot(*p) > H


def test_reach_clear_cases():
    """No neighbour: clear; one never detected: not; a disk whose edge is beyond H: clear;
    within H, or around the robot: not."""
    from fov_marl.control.safety import reach_clear

    H = 3.4
    assert reach_clear(np.zeros((1, 0, 2)), np.zeros((1, 0)), H).all()
    assert not reach_clear(np.full((1, 1, 2), np.nan), np.zeros((1, 1)), H).any()
    c = np.array([[[10.0, 0.0]], [[10.0, 0.0]], [[10.0, 0.0]], [[0.0, -10.0]]])
    r = np.array([[6.5], [6.7], [12.0], [6.0]])  # edges 3.5, 3.3, inside, 4.0
    np.testing.assert_array_equal(reach_clear(c, r, H), [True, False, False, True])
    two = np.array([[[10.0, 0.0], [0.0, 3.0]]])  # one far, one near
    assert not reach_clear(two, np.zeros((1, 2)), H)[0]


@settings(max_examples=60, deadline=None)
@given(
    st.floats(-6.0, 6.0),
    st.floats(-6.0, 6.0),
    st.floats(10.0, 360.0),
    st.floats(0.2, 3.6),
    st.integers(0, 10_000),
)
def test_detection_sector_rows_flag_the_reports_the_camera_could_not_make(
    zx, zy, beta_deg, clip, seed
):
    """Section 1e: a report is flagged exactly when it lies outside the camera sector (β <
    360°); the clearance is a lower bound on the range of every true position the camera
    could have reported it from (in the sector, within the clip box of the report)."""
    assume(math.hypot(zx, zy) > 1e-6)  # the camera never reports a neighbour at the centre
    fov = math.radians(beta_deg)
    z = np.array([[[zx, zy]]])
    n, clear, outside = detection_sector_rows(z, fov, 4.0, (clip, clip))
    flagged = bool(outside[0, 0])
    if beta_deg >= 360.0:
        assert not flagged
    else:
        assert flagged == (not bool(in_fov(z[0, 0], fov, 4.0)))
    assert n.shape == (3, 2)
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0)
    if not flagged:
        assert clear[0, 0] == math.inf
        return
    rng = np.random.default_rng(seed)
    q = z[0, 0] + rng.uniform(-clip, clip, size=(4000, 2))
    q = q[in_fov(q, fov, 4.0)]
    if q.size:
        assert np.hypot(q[:, 0], q[:, 1]).min() >= clear[0, 0] - 1e-12


def test_detection_sector_rows_keep_a_packed_robot_out_of_the_sector():
    """The harsh env's collision, reconstructed: the camera reports the neighbour 1.05 m
    *behind* the robot (0.71 m noise per axis, clipped at 3.5 m; β = 120°, R_d = 4 m) and
    the posterior follows it. Without the option the posterior's row demands a retreat
    forward and allows the full-speed step into the neighbour, which stands 1.27 m
    ahead; with it no row pushes, and no allowed velocity approaches any bearing of the
    sector (where the camera must have seen it): with the posterior's own row (no
    approach towards the report) the robot may only stand. A report inside the sector
    changes nothing."""
    clip = 5.0 * math.sqrt(0.5)
    kw = dict(
        mean_body=np.array([[[-0.381, -0.144]]]),
        cov_body=np.array([[[[0.312, 0.027], [0.027, 0.076]]]]),
        detected=np.ones((1, 1), bool),
        meas_cov_xy=np.diag([0.5, 0.5]),
        fov_rad=math.radians(120.0),
        detection_range_m=4.0,
        meas_clip_xy_m=(clip, clip),
        bearing_cone_max_rad=math.radians(45.0),
    )
    report = np.array([[[-1.047, -0.395]]])
    forward = np.array([1.0, 0.0, 0.0])
    off = _rows(detection_body=report, **kw)
    A0, b0, k0 = off.robot(0)
    # a retreat from the report is demanded, and the step into the neighbour passes the
    # safe fallback's test (no row worse than standing still: A u + b >= min(b, 0))
    assert b0[k0 == ROW_NEIGHBOUR].min() < 0.0
    assert (A0 @ forward + b0 >= np.minimum(b0, 0.0) - 1e-12).all()
    on = _rows(detection_body=report, detection_sector=True, **kw)
    A, b, kind = on.robot(0)
    assert (b[kind == ROW_NEIGHBOUR] >= 0.0).all()
    assert not (A @ forward + b >= np.minimum(b, 0.0) - 1e-12).all()
    v = np.random.default_rng(0).uniform(-1.0, 1.0, size=(4000, 2))
    u = np.concatenate([v, np.zeros((4000, 1))], 1)
    ok = (u @ A.T + b >= -1e-12).all(axis=1)
    assert (b >= 0.0).all()  # standing still is allowed: the robot stops and turns
    th = np.linspace(-math.pi / 3, math.pi / 3, 61)
    assert (v[ok] @ np.stack([np.cos(th), np.sin(th)]) <= 1e-9).all()
    inside = np.array([[[1.2, 0.1]]])
    same = _rows(detection_body=inside, **kw)
    with_opt = _rows(detection_body=inside, detection_sector=True, **kw)
    for a, c in zip(same.robot(0), with_opt.robot(0), strict=True):
        np.testing.assert_array_equal(a, c)


def _bearing_travel_floor_reference(near, slack, yaw, k, d_s, budget):
    """Section 2g one neighbour and one bearing at a time."""
    R, M = near.shape[:2]
    out = np.zeros((R, k))
    for r in range(R):
        for j in range(M):
            x, y = near[r, j]
            if not (math.isfinite(x) and math.isfinite(y)):
                continue
            d = math.hypot(x, y)
            used = min(max(0.5 * (d_s - (d - slack[r, j])), 0.0), budget)
            cone = math.asin(slack[r, j] / d) if d > slack[r, j] else math.pi
            cone += math.pi / k
            for b in range(k):
                ang = 2.0 * math.pi * b / k - yaw[r]
                off = abs((ang - math.atan2(y, x) + math.pi) % (2.0 * math.pi) - math.pi)
                if off <= cone + 1e-9:
                    out[r, b] = max(out[r, b], used)
    return out


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.sampled_from([4, 12, 24, 36]), st.integers(0, 4))
def test_bearing_travel_floor_matches_its_loop_reference(seed, k, m):
    rng = np.random.default_rng(seed)
    near = rng.uniform(-4.0, 4.0, size=(3, m, 2))
    near[rng.random((3, m)) < 0.3] = np.nan
    slack = rng.choice([0.0, 0.3, 0.75, 5.0], size=(3, m))
    yaw = rng.uniform(-math.pi, math.pi, 3)
    got = bearing_travel_floor(near, slack, yaw, k, 2.0, 0.5)
    assert got.shape == (3, k)
    np.testing.assert_allclose(got, _bearing_travel_floor_reference(near, slack, yaw, k, 2.0, 0.5))


@settings(max_examples=80, deadline=None)
@given(
    st.floats(-3.5, 3.5),
    st.floats(-3.5, 3.5),
    st.floats(0.0, 1.7),
    st.floats(-math.pi, math.pi),
    st.sampled_from([12, 24]),
    st.integers(0, 10_000),
)
def test_bearing_travel_floor_covers_every_position_the_report_allows(zx, zy, slack, yaw, k, seed):
    """Section 2g's guarantee: for every position ``p`` within ``slack`` of the report, the
    bearing nearest to p's (the bin whose row bounds the approach towards p) keeps at least
    ``clip((D_s − ‖p‖) / 2, 0, B)``, so the pair's blind closing from ``‖p‖`` stays within
    ``2 B − (D_s − ‖p‖)`` (to ``D_s − 2 B`` as from D_s)."""
    assume(math.hypot(zx, zy) > 1e-3)
    f = bearing_travel_floor(np.array([[[zx, zy]]]), slack, np.array([yaw]), k, 2.0, 0.5)[0]
    rng = np.random.default_rng(seed)
    r = slack * np.sqrt(rng.random(200))
    th = rng.uniform(-math.pi, math.pi, 200)
    p = np.array([zx, zy]) + np.stack([r * np.cos(th), r * np.sin(th)], -1)
    d = np.hypot(p[:, 0], p[:, 1])
    psi_world = np.arctan2(p[:, 1], p[:, 0]) + yaw
    nearest = np.round(psi_world / (2.0 * math.pi / k)).astype(int) % k
    need = np.clip(0.5 * (2.0 - d), 0.0, 0.5)
    assert np.all(f[nearest] >= need - 1e-9)


def test_bearing_travel_floor_is_zero_beyond_d_s_and_spends_all_of_a_packed_bearing():
    """A neighbour whose whole noise disk lies beyond D_s has used nothing; one reported
    1.1 m away with the default noise margin (z_δ σ = 0.74 m) has used all of B, within its
    cone of bearings (asin(0.74 / 1.1) = 42°, plus half a bin) and nowhere else."""
    slack = risk_quantile(0.01) * math.sqrt(0.1)
    far = bearing_travel_floor(
        np.array([[[0.0, 2.0 + slack + 0.01]]]), slack, np.zeros(1), 24, 2.0, 0.5
    )
    assert np.all(far == 0.0)
    f = bearing_travel_floor(np.array([[[-1.1, 0.0]]]), slack, np.zeros(1), 24, 2.0, 0.5)[0]
    ang = np.degrees(2.0 * math.pi * np.arange(24) / 24)
    behind = np.abs(((ang - 180.0) + 180.0) % 360.0 - 180.0)
    half = math.degrees(math.asin(slack / 1.1)) + 7.5
    np.testing.assert_array_equal(f, np.where(behind <= half + 1e-6, 0.5, 0.0))


# ------------------------------------------------ packed robots: cap and escape (1f)
@settings(max_examples=300, deadline=None)
@given(**_ROW_OFFSET_INPUTS, cap=st.floats(0.01, 2.0))
def test_recovery_cap_only_bounds_the_retreat_below_ds(h, pred, band, gain, rho, cap):
    """The cap r replaces γ h by max(γ h, −r): unchanged at and above D_s and wherever
    γ |h| ≤ r; below D_s the row still never allows an approach j's assumed closing
    does not leave (h does not decrease) and demands at most what the uncapped barrier
    demands."""
    hh = np.array(h)
    p = None if pred is None else np.array(pred)
    g = hold_band(hh, band)
    free = float(neighbour_row_offsets(hh, g, p, gain, rho))
    capped = float(neighbour_row_offsets(hh, g, p, gain, rho, cap))
    if h >= 0.0 or gain * h >= -cap:
        assert capped == pytest.approx(free, abs=1e-12)
        return
    assert capped >= free - 1e-12  # never more retreat than the uncapped row
    gh = max(gain * h, -cap)
    closing = (1.0 - rho) * gh if pred is None else max((1.0 - rho) * gh, pred)
    assert capped + closing <= 1e-12  # i plus j's assumed closing: no approach below D_s
    if pred is None:  # j takes its share: i retreats at its share of the cap
        assert capped == pytest.approx(-rho * cap, abs=1e-12)


def test_recovery_cap_reaches_the_rows_through_the_params():
    """A detected neighbour 1.1 m ahead (inside D_s): the uncapped row demands ~2 m/s
    of retreat (more than v_max), the capped one r ρ."""
    mean = np.array([[[1.1, 0.0]]])
    cov = np.array([[np.eye(2) * 0.01]])
    kw = dict(
        mean_body=mean, cov_body=cov, detected=np.array([[True]]), pose_world=None,
        particles_body=None, particle_mass=None, safety_distance_m=2.0, v_max_mps=1.0,
        omega_max_radps=1.5, dt_s=0.2, arena_size_m=40.0, robot_radius_m=0.5,
        safety_risk=0.01, safety_gain=2.5, responsibility=0.5, blind_bins=0,
        blind_risk=0.0, blind_speed_mps=0.05, walls=False, wall_gain=2.5,
    )  # fmt: skip
    free = safety_rows(**kw)
    capped = safety_rows(**kw, recovery_mps=0.25)
    nb = free.kind[0] == ROW_NEIGHBOUR
    assert free.b[0][nb].min() < -1.0
    np.testing.assert_allclose(capped.b[0][nb], -0.125, atol=1e-12)
    with pytest.raises(ValueError, match="safety_recovery_mps"):
        ControllerParams(safety_recovery_mps=0.0)
    with pytest.raises(ValueError, match="safety_recovery_mps"):
        ControllerParams(safety_recovery_mps=float("nan"))
    assert ControllerParams(safety_recovery_mps=math.inf).safety_recovery_mps == math.inf


def _random_rows(rng, k):
    ang = rng.uniform(-math.pi, math.pi, k)
    A = np.zeros((k, 3))
    A[:, 0], A[:, 1] = np.cos(ang), np.sin(ang)
    b = rng.uniform(-1.5, 1.0, k)
    return A, b


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), k=st.integers(1, 8))
def test_escape_translation_is_the_nearest_step_no_worse_than_standing_still(seed, k):
    """Against a brute-force reference: the result meets every row as well as standstill
    does (Ã w ≥ min(−b̃, 0)), leaves every widened held row by the margin angle
    (Ã w ≥ sin(10°) ‖w‖), lies in the polygon, and no sampled point that does all this
    is nearer the wanted translation."""
    from fov_marl.control.controller import escape_translation
    from fov_marl.control.qp import polygon_normals

    rng = np.random.default_rng(seed)
    A, b = _random_rows(rng, k)
    widen = rng.random(k) < 0.5
    v = rng.uniform(-1.0, 1.0, 2)
    w = escape_translation(v, A, b, 1.0, 16, widen)
    lo = np.minimum(-b, 0.0)
    margin = math.sin(math.radians(10.0))
    held = widen & (b <= 0.0)

    def ok(p: np.ndarray, tol: float) -> np.ndarray:
        val = p @ A[:, :2].T  # (S, K)
        norm = np.linalg.norm(p, axis=-1)[:, None]
        need = np.where(held[None], margin * norm, lo[None])
        return (val >= need - tol).all(axis=1)

    assert ok(w[None], 1e-9)[0]
    nrm, apothem = polygon_normals(16), math.cos(math.pi / 16)
    assert (nrm @ w).max() <= apothem + 1e-9
    g = np.linspace(-1.0, 1.0, 161)
    pts = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    fine = ok(pts, 0.0) & ((pts @ nrm.T) <= apothem).all(axis=1)
    best = np.linalg.norm(pts[fine] - v, axis=1).min()
    assert np.linalg.norm(w - v) <= best + 1e-9


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), k=st.integers(1, 8))
def test_escape_heading_matches_a_loop_reference(seed, k):
    """The heading is the tried direction nearest the wanted translation among those the
    neighbour, cone and wall rows allow (blind rows are not asked), NaN when none is."""
    from fov_marl.control.controller import escape_heading

    rng = np.random.default_rng(seed)
    A, b = _random_rows(rng, k)
    kind = rng.choice([ROW_NEIGHBOUR, ROW_CONE, ROW_WALL, 1, 4, 5, 6], k).astype(np.int8)
    v = rng.uniform(-1.0, 1.0, 2)
    got = escape_heading(v[None], A[None], b[None], kind[None], np.ones((1, k), bool))[0]
    best, best_off = math.nan, math.inf
    for j in range(72):
        a = -math.pi + 2.0 * math.pi * j / 72
        d = np.array([math.cos(a), math.sin(a)])
        fine = all(
            0.1 * (A[r, :2] @ d) >= min(-b[r], 0.0) - 1e-12
            for r in range(k)
            if kind[r] in (ROW_NEIGHBOUR, ROW_CONE, ROW_WALL)
        )
        off = abs(math.remainder(a - math.atan2(v[1], v[0]), 2.0 * math.pi))
        if fine and off < best_off - 1e-12:
            best, best_off = a, off
    if math.isnan(best):
        assert math.isnan(got)
    else:
        assert got == pytest.approx(best, abs=1e-9)


def test_escaping_fallback_steps_out_instead_of_stopping():
    """A robot with neighbours ahead and to its left inside D_s (retreat demanded at
    more than it can do) and a wall on its right: the plain fallback stops it, the
    escaping one steps back-right, approaching none of the three and straight; with no
    free step it turns towards the escape direction nearest the QP's, not towards the
    most dangerous row; the loop and the batched controller agree."""
    from fov_marl.control.batched import BatchedFovCbfController

    A = np.array([[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 1.0, 0.0]])
    b = np.array([-2.0, -2.0, 0.3])
    kind = np.array([ROW_NEIGHBOUR, ROW_NEIGHBOUR, ROW_WALL], np.int8)
    u_qp = np.array([-0.8, -0.6, 0.7])  # the least-violation input overshoots the wall row
    plain = FovCbfController(CFG, ControllerParams())._safe_fallback(u_qp, A, b, kind)
    assert plain[:2].tolist() == [0.0, 0.0]
    par = ControllerParams(fallback_escape=True)
    esc = FovCbfController(CFG, par)._safe_fallback(u_qp, A, b, kind)
    assert esc[0] < -0.5 and esc[1] < 0.0 and esc[2] == 0.0
    assert (A[:, :2] @ esc[:2] - np.minimum(-b, 0.0)).min() >= -1e-9
    batch = BatchedFovCbfController(CFG, par)._safe_fallback(
        u_qp[None], A[None], b[None], kind[None], np.ones((1, 3), bool)
    )
    np.testing.assert_allclose(batch[0], esc, atol=1e-12)
    # the wall now at rest on the right (b̃ = 0): no translation qualifies but the
    # back-left bearings, and u_qp asks for back-right; blind rows behind do not count
    A2 = np.concatenate([A, [[1.0, 0.0, 0.0]]])
    b2 = np.array([-2.0, 0.0, 0.0, 0.0])
    kind2 = np.array([ROW_NEIGHBOUR, ROW_NEIGHBOUR, ROW_WALL, 6], np.int8)
    out = FovCbfController(CFG, par)._safe_fallback(np.array([-0.8, -0.6, 0.0]), A2, b2, kind2)
    assert out[:2].tolist() == [0.0, 0.0]
    assert out[2] < 0.0  # turns towards the back (−180°), not the neighbour ahead (0°)


def test_escape_translation_stands_still_where_the_program_fails():
    """The traced hypothesis case (seed 26590): a held row and a widened one leave
    (nearly) one ray, the least-distance program reports the rows inconsistent, and the
    step is standstill, which meets every row."""
    from fov_marl.control.controller import escape_translation

    rng = np.random.default_rng(26590)
    A, b = _random_rows(rng, 2)
    widen = rng.random(2) < 0.5
    v = rng.uniform(-1.0, 1.0, 2)
    assert widen.tolist() == [False, True] and (b <= 0.0).all()
    w = escape_translation(v, A, b, 1.0, 16, widen)
    assert w.tolist() == [0.0, 0.0]


def test_escaping_fallback_aims_at_what_was_asked():
    """Given the desired input, the escape projects it (not the QP's compromise): a robot
    asked to go right and a little forward with a neighbour ahead inside D_s, the QP's
    input approaching it, steps right and 10° back, approaching nothing."""
    A = np.array([[-1.0, 0.0, 0.0]])  # neighbour ahead, retreat demanded
    b = np.array([-2.0])
    kind = np.array([ROW_NEIGHBOUR], np.int8)
    u_qp = np.array([-0.9, 0.4, 0.0])  # the hierarchy's compromise: makes nothing worse
    u_star = np.array([0.3, -1.0, 0.2])
    ctrl = FovCbfController(CFG, ControllerParams(fallback_escape=True))
    kept = ctrl._safe_fallback(u_qp, A, b, kind, u_star)
    np.testing.assert_array_equal(kept, [-0.9, 0.4, 0.0])  # a u_qp that qualifies is kept
    worse = np.array([0.5, 0.4, 0.0])  # approaches the neighbour
    out = ctrl._safe_fallback(worse, A, b, kind, u_star)
    assert out[1] < -0.8 and out[2] == 0.0
    # not straight across the estimated line of sight: 10° away from the neighbour
    speed = math.hypot(out[0], out[1])
    assert -out[0] == pytest.approx(math.sin(math.radians(10.0)) * speed, abs=1e-9)
