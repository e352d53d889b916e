"""Frames, FoV sector, confidence ellipses (Eq. 6-7), point-to-ellipse distance (Eq. 8-10)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from scipy import stats

from fov_marl.geometry import (
    CHI2_95_2DOF,
    body_to_world,
    chi2_2dof,
    confidence_ellipse,
    ellipse_distance,
    ellipse_distance_bruteforce,
    ellipse_distance_paper,
    in_fov,
    integrate_unicycle,
    relative_pose,
    rotation,
    world_to_body,
    wrap_angle,
)

finite = st.floats(min_value=-100.0, max_value=100.0, allow_nan=False, allow_infinity=False)
angle = st.floats(min_value=-10.0, max_value=10.0, allow_nan=False, allow_infinity=False)
xy = st.tuples(finite, finite)
pose = st.tuples(finite, finite, angle)


# ----------------------------------------------------------------------------- frames
@given(xy, pose)
def test_world_body_round_trip(p, ps):
    p_body = world_to_body(np.array(p), np.array(ps))
    np.testing.assert_allclose(body_to_world(p_body, np.array(ps)), p, atol=1e-9)
    # distances are preserved
    assert np.linalg.norm(p_body) == pytest.approx(math.dist(p, ps[:2]), abs=1e-9)


def test_world_to_body_known_values():
    robot = np.array([1.0, 2.0, np.pi / 2])  # facing +y
    np.testing.assert_allclose(world_to_body([1.0, 3.0], robot), [1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(world_to_body([0.0, 2.0], robot), [0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(body_to_world([2.0, 0.0], robot), [1.0, 4.0], atol=1e-12)
    np.testing.assert_allclose(rotation(np.pi / 2) @ [1.0, 0.0], [0.0, 1.0], atol=1e-12)


def test_frames_broadcast():
    rng = np.random.default_rng(0)
    poses = rng.uniform(-5, 5, (4, 1, 3))
    pts = rng.uniform(-5, 5, (1, 7, 2))
    out = world_to_body(pts, poses)
    assert out.shape == (4, 7, 2)
    np.testing.assert_allclose(out[2, 5], world_to_body(pts[0, 5], poses[2, 0]), atol=1e-12)


def test_relative_pose():
    rng = np.random.default_rng(1)
    poses = np.c_[rng.uniform(0, 40, (5, 2)), rng.uniform(-np.pi, np.pi, 5)]
    rel = relative_pose(poses)
    assert rel.shape == (5, 5, 3)
    np.testing.assert_allclose(rel[np.arange(5), np.arange(5)], 0.0, atol=1e-12)
    for i in range(5):
        for j in range(5):
            np.testing.assert_allclose(rel[i, j, :2], world_to_body(poses[j, :2], poses[i]))
            dyaw = (poses[j, 2] - poses[i, 2] + np.pi) % (2 * np.pi) - np.pi
            assert rel[i, j, 2] == pytest.approx(dyaw, abs=1e-12)
            assert -np.pi <= rel[i, j, 2] < np.pi


# ----------------------------------------------------------------------------- FoV sector
def in_fov_reference(p_body: np.ndarray, fov_rad: float, range_m: float) -> np.ndarray:
    """Slow, obviously correct: ``0 < ‖p‖ ≤ R_d`` and ``|atan2(y, x)| ≤ β/2``."""
    out = np.zeros(p_body.shape[:-1], dtype=bool)
    for k in np.ndindex(out.shape):
        x, y = p_body[k]
        r = math.hypot(x, y)
        out[k] = 0.0 < r <= range_m and abs(math.atan2(y, x)) <= fov_rad / 2
    return out


def border_margin(p_body: np.ndarray, fov_rad: float, range_m: float) -> np.ndarray:
    """Distance (rad or m) from the nearest sector border: used to skip points so close
    to an edge that round-off may put them on either side."""
    r = np.hypot(p_body[..., 0], p_body[..., 1])
    ang = np.abs(np.arctan2(p_body[..., 1], p_body[..., 0]))
    m = np.minimum(np.abs(r - range_m), r)
    if fov_rad < 2 * np.pi:
        m = np.minimum(m, np.abs(ang - fov_rad / 2))
    return m


@pytest.mark.parametrize("fov_deg", [1.0, 60.0, 90.0, 120.0, 179.0, 180.0, 181.0, 200.0, 300.0,
                                     359.0, 360.0])  # fmt: skip
def test_in_fov_matches_atan2_reference(fov_deg):
    rng = np.random.default_rng(int(fov_deg * 10))
    pts = rng.uniform(-12.0, 12.0, (4000, 2))
    beta = math.radians(fov_deg)
    keep = border_margin(pts, beta, 10.0) > 1e-9
    got = in_fov(pts, beta, 10.0)
    assert got.shape == (4000,)
    assert np.array_equal(got[keep], in_fov_reference(pts, beta, 10.0)[keep])
    assert keep.mean() > 0.99
    # the fraction inside is the sector's share of the square
    expected = (fov_deg / 360.0) * np.pi * 100.0 / 24.0**2
    assert got.mean() == pytest.approx(expected, abs=0.03)


@given(
    st.floats(min_value=0.01, max_value=360.0),
    st.lists(st.tuples(st.floats(-15, 15), st.floats(-15, 15)), min_size=1, max_size=20),
)
def test_in_fov_matches_reference_property(fov_deg, pts):
    p = np.array(pts)
    beta = math.radians(fov_deg)
    keep = border_margin(p, beta, 10.0) > 1e-9
    assert np.array_equal(in_fov(p, beta, 10.0)[keep], in_fov_reference(p, beta, 10.0)[keep])


@pytest.mark.parametrize("fov_deg", [60.0, 120.0, 180.0, 200.0, 300.0, 360.0])
def test_in_fov_borders(fov_deg):
    beta, R = math.radians(fov_deg), 10.0
    # straight ahead: at exactly the range inside, beyond it outside
    assert in_fov(np.array([R, 0.0]), beta, R)
    assert not in_fov(np.array([R * (1 + 1e-12), 0.0]), beta, R)
    assert not in_fov(np.array([0.0, 0.0]), beta, R)  # never sees itself
    # just inside / just outside the angular border, at half range
    for side in (1.0, -1.0):
        for delta, expected in ((-1e-6, True), (1e-6, fov_deg >= 360.0)):
            a = side * (beta / 2 + delta)
            p = 5.0 * np.array([math.cos(a), math.sin(a)])
            assert bool(in_fov(p, beta, R)) == expected, (fov_deg, side, delta)
    # behind the robot: only with beta > 180
    assert bool(in_fov(np.array([-5.0, 0.0]), beta, R)) == (fov_deg >= 360.0)
    assert bool(in_fov(np.array([0.0, 5.0]), beta, R)) == (fov_deg >= 180.0)


@given(
    st.floats(min_value=1.0, max_value=360.0),
    pose,
    st.tuples(finite, finite, angle),
    st.lists(xy, min_size=1, max_size=10),
)
def test_sector_membership_invariant_to_moving_everything(fov_deg, robot, motion, pts_world):
    """Rotate and translate the robot and the points together: F_i moves with them."""
    beta = math.radians(fov_deg)
    robot, p = np.array(robot), np.array(pts_world)
    tx, ty, rot = motion
    Rm = rotation(rot)
    robot2 = np.array([*(Rm @ robot[:2] + [tx, ty]), robot[2] + rot])
    p2 = p @ Rm.T + [tx, ty]
    b1, b2 = world_to_body(p, robot), world_to_body(p2, robot2)
    keep = border_margin(b1, beta, 10.0) > 1e-6
    assume(keep.any())
    assert np.array_equal(in_fov(b1, beta, 10.0)[keep], in_fov(b2, beta, 10.0)[keep])


def test_sector_turns_with_yaw():
    beta = math.radians(60.0)
    neighbour = np.array([20.0, 25.0])  # 5 m north of the robot
    facing_east = world_to_body(neighbour, np.array([20.0, 20.0, 0.0]))
    facing_north = world_to_body(neighbour, np.array([20.0, 20.0, np.pi / 2]))
    assert not in_fov(facing_east, beta, 10.0)
    assert in_fov(facing_north, beta, 10.0)


# ----------------------------------------------------------------------------- ellipses
def test_chi2_2dof():
    assert chi2_2dof(0.95) == pytest.approx(5.991464547107979, rel=1e-12)
    assert CHI2_95_2DOF == pytest.approx(chi2_2dof(0.95), rel=1e-15)
    for c in (0.5, 0.9, 0.99, 0.999):
        assert chi2_2dof(c) == pytest.approx(stats.chi2.ppf(c, df=2), rel=1e-9)
        assert 1 - math.exp(-chi2_2dof(c) / 2) == pytest.approx(c)
    for bad in (0.0, 1.0, -0.1, 1.5):
        with pytest.raises(ValueError, match="confidence"):
            chi2_2dof(bad)


def check_ellipse_against_eigh(cov: np.ndarray, chi2: float = CHI2_95_2DOF) -> None:
    a, b, psi = confidence_ellipse(cov, chi2)
    lam, vec = np.linalg.eigh(cov)
    assert a == pytest.approx(math.sqrt(chi2 * max(lam[1], 1e-12)), rel=1e-9, abs=1e-12)
    assert b == pytest.approx(math.sqrt(chi2 * max(lam[0], 1e-12)), rel=1e-7, abs=1e-9)
    assert a >= b > 0.0
    assert -np.pi / 2 < psi <= np.pi / 2
    if lam[1] - lam[0] > 1e-9 * max(lam[1], 1.0):
        major = vec[:, 1]
        # ψ is the direction of the major eigenvector, up to its sign (Eq. 7)
        assert abs(major[0] * math.sin(psi) - major[1] * math.cos(psi)) < 1e-6
    # Reconstruction: R(ψ) diag(a², b²) R(ψ)ᵀ / χ² = Σ (eigenvalues floored at 1e-12)
    Rm = rotation(psi)
    rebuilt = Rm @ np.diag([a * a, b * b]) @ Rm.T / chi2
    np.testing.assert_allclose(rebuilt, cov, atol=1e-9 * max(1.0, lam[1]) + 2e-12)


@given(
    st.floats(1e-6, 100.0),
    st.floats(1e-6, 100.0),
    st.floats(-np.pi, np.pi),
    st.floats(0.5, 0.999),
)
def test_confidence_ellipse_matches_eigh(s1, s2, theta, conf):
    Rm = rotation(theta)
    cov = Rm @ np.diag([s1, s2]) @ Rm.T
    cov = 0.5 * (cov + cov.T)
    check_ellipse_against_eigh(cov, chi2_2dof(conf))


@pytest.mark.parametrize(
    "cov",
    [
        np.zeros((2, 2)),  # all particles on one point
        np.eye(2),  # isotropic
        np.array([[1.0, 1.0], [1.0, 1.0]]),  # rank 1, along the diagonal
        np.array([[4.0, 0.0], [0.0, 0.0]]),  # rank 1, along x
        np.array([[0.0, 0.0], [0.0, 4.0]]),  # rank 1, along y
        np.array([[1e-14, 0.0], [0.0, 1e-14]]),  # below the floor
    ],
    ids=["zero", "isotropic", "rank1-diag", "rank1-x", "rank1-y", "tiny"],
)
def test_confidence_ellipse_degenerate(cov):
    check_ellipse_against_eigh(cov)


def test_confidence_ellipse_known_values_and_batch():
    a, b, psi = confidence_ellipse(np.diag([4.0, 1.0]))
    assert (a, b, psi) == pytest.approx((2 * math.sqrt(CHI2_95_2DOF), math.sqrt(CHI2_95_2DOF), 0))
    _, _, psi = confidence_ellipse(np.diag([1.0, 4.0]))
    assert psi == pytest.approx(np.pi / 2)
    _, _, psi = confidence_ellipse(np.array([[1.0, 1.0], [1.0, 1.0]]))
    assert psi == pytest.approx(np.pi / 4)
    rng = np.random.default_rng(3)
    A = rng.normal(size=(3, 4, 2, 2))
    covs = A @ np.swapaxes(A, -1, -2)
    a, b, psi = confidence_ellipse(covs)
    assert a.shape == b.shape == psi.shape == (3, 4)
    a1, b1, p1 = confidence_ellipse(covs[2, 1])
    assert (a[2, 1], b[2, 1], psi[2, 1]) == pytest.approx((a1, b1, p1))


# ----------------------------------------------------------------------------- distances
BRUTE_SAMPLES = 20_000


def brute_tolerance(a: float, b: float) -> float:
    """The sampled boundary points are at most ``2π max(a,b) / n`` apart along the arc,
    so the brute-force minimum exceeds the true distance by at most half of that."""
    return math.pi * max(a, b) / BRUTE_SAMPLES + 1e-9


ellipse_case = st.tuples(
    st.floats(0.05, 5.0),  # a
    st.floats(1.0, 20.0),  # axis ratio a / b
    st.floats(-np.pi, np.pi),  # psi
    st.tuples(st.floats(-5, 5), st.floats(-5, 5)),  # centre
    st.floats(-np.pi, np.pi),  # bearing of the query point
    st.floats(-4.0, 2.0),  # log10 of its distance from the centre in units of a
)


@given(ellipse_case, st.booleans())
def test_ellipse_distance_matches_bruteforce(case, swap):
    a, ratio, psi, c, bearing, log_r = case
    b = a / ratio
    r = a * 10.0**log_r
    p = np.asarray(c) + r * np.array([math.cos(bearing), math.sin(bearing)])
    if swap:  # the same ellipse given with the axes in the other order
        a, b, psi = b, a, psi + np.pi / 2
    exact = float(ellipse_distance(p, c, a, b, psi))
    brute = float(ellipse_distance_bruteforce(p, c, a, b, psi, n_samples=BRUTE_SAMPLES))
    assert exact >= 0.0
    assert exact <= brute + 1e-9
    assert brute - exact <= brute_tolerance(a, b)


@given(ellipse_case, st.floats(0.0, 0.999))
def test_ellipse_distance_is_zero_inside(case, s):
    a, ratio, psi, c, t, _ = case
    b = a / ratio
    local = s * np.array([a * math.cos(t), b * math.sin(t)])
    p = np.asarray(c) + rotation(psi) @ local
    assert float(ellipse_distance(p, c, a, b, psi)) == 0.0
    assert float(ellipse_distance_paper(p, c, a, b, psi)) == 0.0


def test_ellipse_distance_thin_ellipse_far_point_regression():
    """A far point near the minor axis of a thin ellipse: with the old Newton start
    (t = 0) eight steps left a 1.1 m error here."""
    a, b, psi = 4.740557076614315, 0.2588608139173182, -2.0620409574561305
    c, p = np.array([-1.31621979, -1.15245938]), np.array([-32.92112014, 12.44281466])
    brute = float(ellipse_distance_bruteforce(p, c, a, b, psi))
    assert float(ellipse_distance(p, c, a, b, psi)) == pytest.approx(brute, abs=1e-6)


def test_ellipse_distance_known_values_and_batch():
    # circle of radius 2 at (1, 1): distance = |p - c| - 2
    assert float(ellipse_distance([4.0, 1.0], [1.0, 1.0], 2.0, 2.0, 0.3)) == pytest.approx(1.0)
    # axis-aligned: along the axes the nearest point is the vertex
    assert float(ellipse_distance([5.0, 0.0], [0.0, 0.0], 3.0, 1.0, 0.0)) == pytest.approx(2.0)
    assert float(ellipse_distance([0.0, 4.0], [0.0, 0.0], 3.0, 1.0, 0.0)) == pytest.approx(3.0)
    # on the boundary
    assert float(ellipse_distance([3.0, 0.0], [0.0, 0.0], 3.0, 1.0, 0.0)) == 0.0
    # batched over ellipses and points, extreme axis ratio (degenerate covariance)
    rng = np.random.default_rng(4)
    K = 64
    a = rng.uniform(0.1, 4.0, K)
    b = a / np.exp(rng.uniform(0, np.log(1e4), K))
    psi = rng.uniform(-np.pi, np.pi, K)
    c = rng.uniform(-3, 3, (K, 2))
    p = rng.uniform(-12, 12, (K, 2))
    d = ellipse_distance(p, c, a, b, psi)
    assert d.shape == (K,)
    brute = ellipse_distance_bruteforce(p, c, a, b, psi, n_samples=BRUTE_SAMPLES)
    assert np.all(d <= brute + 1e-9)
    assert np.all(brute - d <= np.pi * a / BRUTE_SAMPLES + 1e-9)


@given(ellipse_case)
def test_paper_distance_is_an_upper_bound_exact_for_circles(case):
    a, ratio, psi, c, bearing, log_r = case
    b = a / ratio
    p = np.asarray(c) + a * 10.0**log_r * np.array([math.cos(bearing), math.sin(bearing)])
    exact = float(ellipse_distance(p, c, a, b, psi))
    assert float(ellipse_distance_paper(p, c, a, b, psi)) >= exact - 1e-9
    circle_exact = float(ellipse_distance(p, c, a, a, psi))
    assert float(ellipse_distance_paper(p, c, a, a, psi)) == pytest.approx(circle_exact, abs=1e-9)


def test_paper_distance_gap_is_as_documented():
    """The numbers in ``ellipse_distance_paper``'s docstring: gap ≤ 0.55 a for axis
    ratio ≤ 5 (and it does get above 0.5 a, so the Eq. 9 point is a real error)."""
    rng = np.random.default_rng(5)
    M = 200_000
    ratio = rng.uniform(1.0, 5.0, M)
    r = rng.uniform(0.0, 3.0, M)
    ang = rng.uniform(-np.pi, np.pi, M)
    p = r[:, None] * np.c_[np.cos(ang), np.sin(ang)]
    z = np.zeros(M)
    gap = ellipse_distance_paper(p, 0.0 * p, 1.0, 1 / ratio, z) - ellipse_distance(
        p, 0.0 * p, 1.0, 1 / ratio, z
    )
    assert gap.min() >= -1e-12
    assert 0.5 < gap.max() <= 0.55
    assert gap[ratio <= 2].max() <= 0.28


# ----------------------------------------------------------------------------- kinematics
def euler_reference(pose0, v_body, omega, dt, n_sub=20_000):
    """Forward Euler with many substeps: ``ṗ = R(θ) v``, ``θ̇ = ω``."""
    x, y, th = (float(t) for t in pose0)
    h = dt / n_sub
    ths = th + omega * h * np.arange(n_sub)
    c, s = np.cos(ths), np.sin(ths)
    x += h * np.sum(c * v_body[0] - s * v_body[1])
    y += h * np.sum(s * v_body[0] + c * v_body[1])
    return np.array([x, y, th + omega * dt])


@given(
    st.tuples(finite, finite, angle),
    st.tuples(st.floats(-1.5, 1.5), st.floats(-1.5, 1.5)),
    st.floats(-3.0, 3.0),
    st.floats(0.01, 2.0),
)
def test_integrate_unicycle_matches_fine_euler(p0, v, w, dt):
    p0, v = np.array(p0), np.array(v)
    got = integrate_unicycle(p0, v, w, dt)
    ref = euler_reference(p0, v, w, dt, n_sub=20_000)
    # Each Euler substep h errs by ≤ |v| |ω| h² / 2, so in all ≤ |v| |ω| dt² / (2 n_sub).
    tol = np.linalg.norm(v) * abs(w) * dt * dt / (2 * 20_000) + 1e-9
    assert np.linalg.norm(got[:2] - ref[:2]) <= tol
    assert got[2] == pytest.approx(float(wrap_angle(ref[2])), abs=1e-9)
    assert -np.pi <= got[2] < np.pi


def test_integrate_unicycle_straight_line_and_small_omega_limit():
    p0 = np.array([1.0, 2.0, 0.7])
    v = np.array([0.8, -0.3])
    straight = p0[:2] + rotation(0.7) @ v * 0.5
    np.testing.assert_allclose(integrate_unicycle(p0, v, 0.0, 0.5)[:2], straight, atol=1e-15)
    # continuous across the series / closed-form switch at |ω dt| = 1e-4
    for w in (1e-12, 1e-7, 1.999e-4, 2.001e-4, 1e-3):
        got = integrate_unicycle(p0, v, w, 0.5)
        np.testing.assert_allclose(got, euler_reference(p0, v, w, 0.5), atol=1e-9)
    lo = integrate_unicycle(p0, v, 2e-4 * (1 - 1e-9), 0.5)
    hi = integrate_unicycle(p0, v, 2e-4 * (1 + 1e-9), 0.5)
    np.testing.assert_allclose(lo, hi, atol=1e-12)


def test_integrate_unicycle_full_turn_and_batch():
    # a full turn with a constant body velocity draws a circle back to the start
    p0 = np.array([3.0, 4.0, 0.2])
    np.testing.assert_allclose(
        integrate_unicycle(p0, np.array([1.0, 0.5]), 2 * np.pi, 1.0),
        [3.0, 4.0, wrap_angle(0.2)],
        atol=1e-12,
    )
    rng = np.random.default_rng(6)
    poses = rng.uniform(-5, 5, (8, 3))
    v = rng.uniform(-1, 1, (8, 2))
    w = rng.uniform(-1.5, 1.5, 8)
    out = integrate_unicycle(poses, v, w, 0.2)
    assert out.shape == (8, 3)
    for k in range(8):
        np.testing.assert_allclose(out[k], integrate_unicycle(poses[k], v[k], w[k], 0.2))


# ----------------------------------------------------------------------------- angles
def test_wrap_angle():
    assert float(wrap_angle(np.pi)) == pytest.approx(-np.pi)
    assert float(wrap_angle(-np.pi)) == pytest.approx(-np.pi)
    assert float(wrap_angle(0.0)) == 0.0
    np.testing.assert_allclose(wrap_angle([3 * np.pi / 2, -3 * np.pi / 2]), [-np.pi / 2, np.pi / 2])


@given(st.floats(-1e3, 1e3), st.integers(-50, 50))
def test_wrap_angle_property(a, k):
    w = float(wrap_angle(a))
    assert -np.pi <= w < np.pi
    assert math.cos(w) == pytest.approx(math.cos(a), abs=1e-9)
    assert math.sin(w) == pytest.approx(math.sin(a), abs=1e-9)
    shifted = float(wrap_angle(a + 2 * np.pi * k))
    assert min(abs(shifted - w), 2 * np.pi - abs(shifted - w)) < 1e-9


def _ellipse_distance_all_iterations(point, center, a, b, psi, n_iter=12):
    """The Newton iteration of :func:`ellipse_distance` without its early exit."""
    d = np.asarray(point, dtype=np.float64) - np.asarray(center, dtype=np.float64)
    c, s = np.cos(psi), np.sin(psi)
    u, v = c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]
    swap = b > a
    a, b = np.where(swap, b, a), np.where(swap, a, b)
    u, v = np.abs(np.where(swap, v, u)), np.abs(np.where(swap, u, v))
    a2, b2 = a * a, b * b
    inside = (u / a) ** 2 + (v / b) ** 2 <= 1.0
    au, bv = a * u, b * v
    S = np.sqrt(au * au + bv * bv)
    lo = np.maximum(np.maximum(S - a2, bv - b2), 0.0)
    hi = np.maximum(S - b2, lo)
    t = lo
    with np.errstate(divide="ignore", invalid="ignore"):
        for _ in range(n_iter):
            qa, qb = au / (t + a2), bv / (t + b2)
            f = qa * qa + qb * qb - 1.0
            df = -2.0 * (qa * qa / (t + a2) + qb * qb / (t + b2))
            step = np.where(df < 0.0, f / df, 0.0)
            t = np.minimum(np.maximum(t - step, lo), hi)
    x, y = a2 * u / (t + a2), b2 * v / (t + b2)
    return np.where(inside, 0.0, np.hypot(u - x, v - y))


@given(seed=st.integers(0, 2**32 - 1), log_ratio=st.floats(0.0, 7.0))
def test_ellipse_distance_early_exit_is_bit_identical(seed, log_ratio):
    """The Newton loop stops once an iteration moves no t (a fixed point): the same
    numbers as all 12 iterations, for tracker-like and degenerate axis ratios."""
    rng = np.random.default_rng(seed)
    n = 64
    point, center = rng.normal(0, 6, (n, 2)), rng.normal(0, 3, (n, 2))
    a = np.exp(rng.normal(0, 1, n))
    b = a * np.exp(-rng.uniform(0, log_ratio, n))
    psi = rng.uniform(-math.pi, math.pi, n)
    np.testing.assert_array_equal(
        ellipse_distance(point, center, a, b, psi),
        _ellipse_distance_all_iterations(point, center, a, b, psi),
    )


# ---------------------------------------------------------------- red team 8: edge input
@pytest.mark.parametrize(
    ("p", "a", "b", "psi", "expected"),
    [
        ([1.0, 1.0], 2.0, 0.0, 0.0, 1.0),  # a segment
        ([1.0, 0.0], 2.0, 0.0, 0.0, 0.0),  # on the segment
        ([3.0, 4.0], 0.0, 0.0, 0.3, 5.0),  # a point
        ([0.0, 0.0], 0.0, 0.0, 0.0, 0.0),  # at the point
        ([1.0, 0.0], 1e-200, 1e-201, 0.0, 1.0),  # squares underflow
        ([3e160, 0.0], 1e160, 1e159, 0.0, 2e160),  # squares overflow
        ([0.0, 3.0], 1e-200, 0.0, 0.0, 3.0),
    ],
)
def test_ellipse_distance_of_degenerate_and_extreme_ellipses(p, a, b, psi, expected):
    """Finite input never gives NaN (before: NaN for all of these)."""
    d = ellipse_distance(np.array(p), np.zeros(2), a, b, psi)
    assert np.isfinite(d) and d == pytest.approx(expected, rel=1e-9, abs=0.0)


def test_ellipse_distance_of_a_scaled_ellipse_scales():
    """The rescue path (units of the major axis) against the ordinary one, and a mixed
    batch keeps the ordinary entries' numbers."""
    rng = np.random.default_rng(3)
    P = rng.normal(size=(50, 2)) * 3.0
    a, b, psi = rng.uniform(0.5, 3, 50), rng.uniform(0.1, 0.5, 50), rng.uniform(-3, 3, 50)
    d = ellipse_distance(P, np.zeros(2), a, b, psi)
    for s in (1e-180, 1e180):
        np.testing.assert_allclose(
            ellipse_distance(P * s, np.zeros(2), a * s, b * s, psi), d * s, rtol=1e-9
        )
    b_mixed = b.copy()
    b_mixed[::7] = 0.0
    mixed = ellipse_distance(P, np.zeros(2), a, b_mixed, psi)
    ok = b_mixed > 0
    np.testing.assert_array_equal(mixed[ok], d[ok])
    assert np.isfinite(mixed).all()


@pytest.mark.parametrize(
    ("cov", "a", "b"),
    [
        (np.diag([1e8, 1e-8]), math.sqrt(CHI2_95_2DOF * 1e8), math.sqrt(CHI2_95_2DOF * 1e-8)),
        (np.diag([1e150, 1.0]), math.sqrt(CHI2_95_2DOF * 1e150), math.sqrt(CHI2_95_2DOF)),
        (np.diag([1e200, 1.0]), math.sqrt(CHI2_95_2DOF * 1e200), math.sqrt(CHI2_95_2DOF)),
    ],
)
def test_confidence_ellipse_of_very_elongated_covariances(cov, a, b):
    """Before: the minor axis lost to cancellation (22% too long at diag(1e8, 1e-8), a
    million times too short at diag(1e150, 1)) and the major one inf at 1e160."""
    ga, gb, psi = confidence_ellipse(cov)
    assert ga == pytest.approx(a, rel=1e-12) and gb == pytest.approx(b, rel=1e-9)
    assert psi == pytest.approx(0.0)


def test_wrap_angle_never_returns_plus_pi():
    x = -math.pi - np.linspace(0.0, 1e-15, 41)
    w = wrap_angle(x)
    assert (w < math.pi).all() and (w >= -math.pi).all()
    yaw = integrate_unicycle(np.array([0.0, 0.0, -math.pi]), np.zeros(2), -3e-15, 1.0)[2]
    assert -math.pi <= yaw < math.pi


def test_integrate_unicycle_broadcasts_omega_and_in_fov_checks_its_sector():
    out = integrate_unicycle(np.zeros(3), np.array([1.0, 0.0]), np.linspace(0.0, 1.0, 5), 0.1)
    assert out.shape == (5, 3)
    for k, w in enumerate(np.linspace(0.0, 1.0, 5)):
        np.testing.assert_array_equal(
            out[k], integrate_unicycle(np.zeros(3), np.array([1.0, 0.0]), w, 0.1)
        )
    pts = np.array([[1.0, 0.0], [-1.0, 0.0]])
    for fov, rng in ((math.nan, 5.0), (0.0, 5.0), (-1.0, 5.0), (1.0, -5.0), (1.0, math.nan)):
        with pytest.raises(ValueError, match="fov_rad must be > 0 and range_m > 0"):
            in_fov(pts, fov, rng)
