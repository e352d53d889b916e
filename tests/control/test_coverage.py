"""Desired inputs: limited-range Lloyd (Section VII-A) and the crossing law (VII-D)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fov_marl.config import make_config
from fov_marl.control import ControllerParams
from fov_marl.control.coverage import (
    MAX_LLOYD_STENCIL,
    check_lloyd_stencil,
    coverage_centroid_reference,
    coverage_centroids,
    coverage_desired_input,
    coverage_desired_inputs,
    crossing_desired_input,
    facing_omega,
    lloyd_deadband_scale,
    lloyd_radius_m,
    lloyd_stencil,
    lloyd_stencil_size,
)
from fov_marl.geometry import rotation, world_to_body

CFG = make_config()
PRM = ControllerParams()
L = CFG.arena_size_m


def _case(rng):
    p = np.clip(np.asarray(CFG.density_mean_m) + rng.normal(0, 6, 2), 0.5, L - 0.5)
    nb = p + rng.normal(0, 5, (int(rng.integers(0, 12)), 2))
    return p, nb


@pytest.mark.parametrize("h", [0.25, 0.4, 0.5])
def test_stencil_disk_fractions_sum_to_the_disk_area(h):
    off, frac = lloyd_stencil(CFG.sensing_radius_m, h)
    np.testing.assert_allclose(frac.sum() * h * h, math.pi * CFG.sensing_radius_m**2, rtol=2e-3)
    assert not off.flags.writeable


def test_reference_is_exact_on_a_lone_disk():
    """No neighbour, far from walls, φ centred on p: centroid p, mass 1 − e^{−R²/2σ²}."""
    p = np.asarray(CFG.density_mean_m)
    c, m = coverage_centroid_reference(p, np.zeros((0, 2)), CFG)
    np.testing.assert_allclose(c, p, atol=1e-9)
    np.testing.assert_allclose(m, 1 - math.exp(-(6.0**2) / (2 * 2.8**2)), rtol=1e-9)


@pytest.mark.parametrize(("h", "tol_mean", "tol_max"), [(0.25, 0.01, 0.05), (0.4, 0.02, 0.07)])
def test_centroid_matches_reference(h, tol_mean, tol_max):
    rng = np.random.default_rng(0)
    prm = ControllerParams(lloyd_grid_m=h)
    errs, merr = [], []
    for _ in range(60):
        p, nb = _case(rng)
        c, m = coverage_centroids(p[None], nb[None], None, CFG, prm)
        cr, mr = coverage_centroid_reference(p, nb, CFG)
        errs.append(np.hypot(*(c[0] - cr)))
        merr.append(abs(m[0] / mr - 1))
    assert np.mean(errs) < tol_mean and np.max(errs) < tol_max
    assert np.median(merr) < 0.01


@pytest.mark.parametrize(("B", "M"), [(7, 9), (40, 39)])  # vectorised and per-robot paths
def test_batched_equals_per_robot_and_respects_valid_mask(B, M):
    rng = np.random.default_rng(1)
    p = rng.uniform(3, 37, (B, 2))
    nb = p[:, None, :] + rng.normal(0, 4, (B, M, 2))
    valid = rng.uniform(size=(B, M)) < 0.7
    c, m = coverage_centroids(p, nb, valid, CFG, PRM)
    for i in range(B):
        ci, mi = coverage_centroids(p[i][None], nb[i][valid[i]][None], None, CFG, PRM)
        np.testing.assert_allclose(c[i], ci[0], atol=1e-12)
        np.testing.assert_allclose(m[i], mi[0], rtol=1e-12)


def test_desired_input_points_at_the_centroid_in_body_frame():
    rng = np.random.default_rng(2)
    for _ in range(20):
        p, nbw = _case(rng)
        yaw = rng.uniform(-math.pi, math.pi)
        pose = np.array([*p, yaw])
        des = coverage_desired_input(pose, world_to_body(nbw, pose), CFG, PRM)
        g_body = rotation(yaw).T @ (des.goal_world - p)
        v = des.u_star[:2]
        expect = PRM.kp_coverage * g_body * lloyd_deadband_scale(np.hypot(*g_body), PRM)
        if np.hypot(*expect) > CFG.v_max_mps:
            expect *= CFG.v_max_mps / np.hypot(*expect)
        np.testing.assert_allclose(v, expect, atol=1e-12)
        assert np.hypot(*v) <= CFG.v_max_mps + 1e-12
        bearing = math.atan2(g_body[1], g_body[0])
        if np.hypot(*g_body) > PRM.face_distance_m and abs(bearing) > 1e-6:
            assert np.sign(des.u_star[2]) == np.sign(bearing)  # turns to face the centroid
        assert abs(des.u_star[2]) <= CFG.omega_max_radps


def test_batched_desired_inputs_match_single():
    rng = np.random.default_rng(3)
    poses = np.column_stack([rng.uniform(3, 37, (5, 2)), rng.uniform(-3, 3, 5)])
    nb_body = rng.normal(0, 5, (5, 6, 2))
    batch = coverage_desired_inputs(poses, nb_body, None, CFG, PRM)
    for i in range(5):
        one = coverage_desired_input(poses[i], nb_body[i], CFG, PRM)
        np.testing.assert_allclose(batch.u_star[i], one.u_star, atol=1e-12)


def test_zero_mass_cell_heads_for_the_density_mean():
    cfg = make_config(density_sigma_m=0.5)
    pose = np.array([2.0, 2.0, 0.3])
    des = coverage_desired_input(pose, np.zeros((0, 2)), cfg, PRM)
    assert des.to_density_mean and des.mass < PRM.lloyd_min_mass
    np.testing.assert_allclose(des.goal_world, cfg.density_mean_m)
    g = rotation(0.3).T @ (np.asarray(cfg.density_mean_m) - pose[:2])
    np.testing.assert_allclose(des.u_star[:2], CFG.v_max_mps * g / np.hypot(*g), atol=1e-12)
    # with the default density the same cell has mass and is used
    des2 = coverage_desired_input(np.array([12.0, 12.0, 0.0]), np.zeros((0, 2)), CFG, PRM)
    assert not des2.to_density_mean


def test_cell_cut_by_a_neighbour_moves_away_from_it():
    p = np.asarray(CFG.density_mean_m)
    c0, _ = coverage_centroids(p[None], np.zeros((1, 0, 2)), None, CFG, PRM)
    c1, _ = coverage_centroids(p[None], (p + [2.0, 0.0])[None, None], None, CFG, PRM)
    np.testing.assert_allclose(c0[0], p, atol=1e-9)
    assert c1[0, 0] < p[0] - 0.3 and abs(c1[0, 1] - p[1]) < 1e-9


@given(
    px=st.floats(0.1, L - 0.1),
    py=st.floats(0.1, L - 0.1),
    nb=st.lists(st.tuples(st.floats(-15, 15), st.floats(-15, 15)), max_size=8),
)
def test_centroid_lies_in_the_sensing_disk_and_the_arena(px, py, nb):
    p = np.array([px, py])
    nbw = p + np.array(nb, dtype=float).reshape(-1, 2)
    c, m = coverage_centroids(p[None], nbw[None], None, CFG, PRM)
    h = PRM.lloyd_grid_m
    if not m[0] > 0:
        return  # empty cell (reported as mass 0): the desired input heads for q_m
    assert np.hypot(*(c[0] - p)) <= CFG.sensing_radius_m + h
    assert np.all(c[0] >= -h) and np.all(c[0] <= L + h)
    # and on p's side of every bisector (the cell is convex and contains p)
    for q in nbw:
        dq = q - p
        if np.hypot(*dq) > 1e-6:
            assert (c[0] - p) @ dq <= 0.5 * dq @ dq + h * np.hypot(*dq)


def test_crossing_law_and_facing_omega():
    t = np.array([3.0, 4.0])
    u = crossing_desired_input(t, CFG, PRM)
    np.testing.assert_allclose(u[:2], [0.6, 0.8])  # saturated at v_max along the target
    assert u[2] == pytest.approx(min(CFG.omega_max_radps, PRM.k_omega * math.atan2(4, 3)))
    near = crossing_desired_input(np.array([0.1, 0.1]), CFG, PRM)
    np.testing.assert_allclose(near[:2], PRM.kp_coverage * np.array([0.1, 0.1]))
    # ω fades linearly inside face_distance_m
    dist = math.hypot(0.1, 0.1)
    assert near[2] == pytest.approx(PRM.k_omega * math.pi / 4 * dist / PRM.face_distance_m)
    behind = facing_omega(np.array([[-5.0, 0.1], [-5.0, -0.1]]), CFG, PRM)
    np.testing.assert_allclose(behind, [CFG.omega_max_radps, -CFG.omega_max_radps])


def test_lloyd_dead_band_is_continuous_and_zero_near_the_centroid():
    prm = ControllerParams(lloyd_deadband_m=0.3)
    d = np.array([0.0, 0.1, 0.3, 0.31, 1.0, 5.0])
    f = lloyd_deadband_scale(d, prm)
    np.testing.assert_allclose(f[:3], 0.0)
    np.testing.assert_allclose(d[3:] * f[3:], d[3:] - 0.3)  # the error shrinks by the band
    np.testing.assert_array_equal(
        lloyd_deadband_scale(d, ControllerParams(lloyd_deadband_m=0.0)), 1.0
    )


# ------------------------------------------------------------ stencil size and range
def _stencil_reference(radius_m: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Obviously-correct stencil: every candidate cell supersampled 16 × 16."""
    n = int(math.ceil(radius_m / h)) + 1
    ax = h * np.arange(-n, n + 1)
    off = np.stack([g.ravel() for g in np.meshgrid(ax, ax, indexing="ij")], -1)
    off = off[np.hypot(off[:, 0], off[:, 1]) <= radius_m + h]
    sub = (np.arange(16) + 0.5) / 16 - 0.5
    sub = h * np.stack([g.ravel() for g in np.meshgrid(sub, sub, indexing="ij")], -1)
    pts = off[:, None, :] + sub[None]
    frac = np.mean(np.hypot(pts[..., 0], pts[..., 1]) <= radius_m, axis=1)
    return off[frac > 0], frac[frac > 0]


@given(radius=st.floats(0.01, 12.0), h=st.floats(0.1, 2.0))
def test_stencil_supersamples_only_the_rim_with_the_same_result(radius, h):
    """Interior cells get fraction 1 without supersampling: bit-identical to the reference."""
    off, frac = lloyd_stencil(radius, h)
    ref_off, ref_frac = _stencil_reference(radius, h)
    np.testing.assert_array_equal(off, ref_off)
    np.testing.assert_array_equal(frac, ref_frac)


def test_sensing_radius_beyond_the_arena_is_global_lloyd_at_bounded_cost():
    """Red team 3: R_s = 1000 m in the 40 m arena needed a 75 GiB stencil (MemoryError).

    The stencil radius is capped at √2 L + 2h, where a larger disk gives the same cell:
    the centroid matches the exact reference (whose disk is 1000 m) and equals the one
    of a config whose R_s is exactly at the cap.
    """
    big = make_config(sensing_radius_m=1000.0)
    h = PRM.lloyd_grid_m
    assert lloyd_radius_m(big, h) == pytest.approx(math.sqrt(2) * L + 2 * h)
    assert lloyd_radius_m(CFG, h) == CFG.sensing_radius_m  # the paper's R_s: uncapped
    at_cap = make_config(sensing_radius_m=lloyd_radius_m(big, h))
    rng = np.random.default_rng(3)
    for _ in range(6):
        p = rng.uniform(0.5, L - 0.5, 2)
        nb = rng.uniform(0.5, L - 0.5, (int(rng.integers(0, 6)), 2))
        c, m = coverage_centroids(p[None], nb[None], None, big, PRM)
        c_cap, m_cap = coverage_centroids(p[None], nb[None], None, at_cap, PRM)
        cr, mr = coverage_centroid_reference(p, nb, big)
        np.testing.assert_allclose(c[0], c_cap[0], atol=1e-9)
        assert np.hypot(*(c[0] - cr)) < 0.1 and abs(m[0] - mr) < 0.02 * mr + 1e-4
    # a corner robot still sees the whole arena: its lone cell is not cut by the cap
    corner = np.array([0.5, 0.5])
    c, m = coverage_centroids(corner[None], np.zeros((1, 0, 2)), None, big, PRM)
    np.testing.assert_allclose(
        m[0], coverage_centroid_reference(corner, np.zeros((0, 2)), big)[1], rtol=1e-3
    )


def test_lloyd_stencil_budget_names_the_field_at_construction():
    """A stencil over MAX_LLOYD_STENCIL points is a ValueError naming sensing_radius_m
    (and the knob that fixes it) when the controller is built, not a MemoryError mid-run."""
    from fov_marl.control import FovCbfController
    from fov_marl.control.batched import BatchedFovCbfController

    cfg = make_config(arena_size_m=400.0, sensing_radius_m=150.0)
    assert lloyd_stencil_size(lloyd_radius_m(cfg, 0.4), 0.4) > MAX_LLOYD_STENCIL
    for build in (FovCbfController, BatchedFovCbfController):
        with pytest.raises(ValueError, match=r"^sensing_radius_m = 150\.0 .*lloyd_grid_m"):
            build(cfg, PRM)
    with pytest.raises(ValueError, match="sensing_radius_m"):
        lloyd_stencil(150.0, 0.4)
    # the fix the message names works: a coarser grid fits
    FovCbfController(cfg, ControllerParams(lloyd_grid_m=1.0))
    check_lloyd_stencil(make_config(sensing_radius_m=3000.0), PRM)  # capped by the arena
    # crossing never builds a Lloyd stencil
    FovCbfController(make_config(scenario="crossing", arena_size_m=400.0, sensing_radius_m=1e6))


@pytest.mark.parametrize("sigma", [0.1, 0.15, 0.2])
def test_narrow_density_gives_finite_centroids(sigma):
    """Red team 3: σ ≤ 0.2 m gave NaN centroids (0 · exp overflow at points outside the
    cell lying far above the cell's maximum of log φ). The cell x ≥ 25.6 m is 5.6 m
    from q_m = (20, 20); its centroid is its point nearest q_m, on the bisector."""
    cfg = make_config(density_sigma_m=sigma)
    p, nb = np.array([[26.1, 20.0]]), np.array([[[25.1, 20.0]]])
    c, m = coverage_centroids(p, nb, None, cfg, PRM)
    assert np.all(np.isfinite(c)) and np.isfinite(m[0]) and m[0] >= 0.0
    np.testing.assert_allclose(c[0], [25.6 + 0.1, 20.0], atol=0.15)  # within the ramp h/2
