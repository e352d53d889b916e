"""FoV CBF rows (Eq. 12), their Lie derivatives, class-K functions and slack (Eq. 16-17)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fov_marl.config import ConfigError, make_config
from fov_marl.control.cbf import (
    SAFETY_ROW,
    border_mode,
    cbf_rows,
    class_k,
    fov_barrier,
    fov_barrier_lie,
    motion_cone_rows,
    normalise_rows,
    row_authority,
    row_h_max,
    sigmoid,
    slack,
)
from fov_marl.control.params import ControllerParams
from fov_marl.geometry import in_fov, integrate_unicycle, rotation, world_to_body

BETAS = (60.0, 120.0, 200.0, 360.0)
# the recovery-by-turning rows of ``fov_translation="all"`` (rows in view untouched)
PRM = ControllerParams(fov_translation="all")
#: the rows exactly as in the paper (Eq. 12 at the mean, α uncapped)
PAPER_ROWS = ControllerParams(fov_recovery_cap=0.0, fov_translation="all")


def _cfg(beta: float = 120.0):
    return make_config(fov_deg=beta)


def test_h_on_known_points_beta_120():
    cfg = _cfg(120.0)
    t = math.tan(math.radians(60.0))
    p = np.array([[5.0, 0.0], [0.0, 5.0], [1.0, 0.0], [12.0, 0.0], [-3.0, 4.0]])
    h = fov_barrier(p, cfg.fov_rad, 2.0, 10.0)
    expected = np.array(
        [
            [5 * t, 5 * t, 21.0, 75.0],
            [5.0, -5.0, 21.0, 75.0],
            [t, t, -3.0, 99.0],
            [12 * t, 12 * t, 140.0, -44.0],
            [-3 * t + 4, -3 * t - 4, 21.0, 75.0],
        ]
    )
    np.testing.assert_allclose(h, expected, rtol=1e-12)


@pytest.mark.parametrize("beta", BETAS)
def test_fov_margin_shrinks_the_sector_by_m(beta):
    """With margin m the FoV rows vanish m inside the border lines / range."""
    cfg = _cfg(beta)
    m = 0.3
    half = 0.5 * cfg.fov_rad
    # points m inside the right border ray (at distance 5) and the range circle
    if beta < 360:
        q = 5.0 * np.array([math.cos(-half), math.sin(-half)])
        inward = np.array([math.cos(-half + math.pi / 2), math.sin(-half + math.pi / 2)])
        h = fov_barrier((q + m * inward)[None], cfg.fov_rad, 2.0, 10.0, m)[0]
        assert abs(h[0]) < 1e-9 if beta < 180 else abs(h[0]) < 5e-3
    hr = fov_barrier(np.array([[10.0 - m, 0.0]]), cfg.fov_rad, 2.0, 10.0, m)[0]
    assert abs(hr[3]) < 1e-9
    np.testing.assert_allclose(row_h_max(cfg, m)[3], 3200 - (10 - m) ** 2)


def test_border_mode_by_beta():
    assert border_mode(math.radians(60)) == "borders"
    assert border_mode(math.radians(179.9)) == "borders"
    assert border_mode(math.radians(180)) == "angular"
    assert border_mode(math.radians(200)) == "angular"
    assert border_mode(math.radians(360)) == "none"


@pytest.mark.parametrize("beta", BETAS)
def test_inactive_rows_are_inf_with_zero_lie_rows(beta):
    cfg = _cfg(beta)
    p = np.random.default_rng(0).uniform(-10, 10, (20, 2))
    h = fov_barrier(p, cfg.fov_rad, 2.0, 10.0)
    A, drift = fov_barrier_lie(p, np.ones_like(p), cfg.fov_rad)
    n_inactive = {60.0: 0, 120.0: 0, 200.0: 1, 360.0: 2}[beta]
    inactive = np.isinf(h).all(axis=0)
    assert inactive.sum() == n_inactive
    assert np.all(A[:, inactive] == 0) and np.all(drift[:, inactive] == 0)
    assert np.all(np.isfinite(h[:, 2:]))


@pytest.mark.parametrize("beta", BETAS)
@given(
    r=st.floats(0.05, 30.0),
    phi=st.floats(-math.pi, math.pi),
)
def test_rows_nonnegative_iff_in_fov_sector(beta, r, phi):
    """h_0, h_1, h_3 ≥ 0 exactly on the camera sector F_i (geometry.in_fov); h_2 ≥ 0 iff r ≥ D_s."""
    cfg = _cfg(beta)
    half = 0.5 * cfg.fov_rad
    if beta < 360 and abs(abs(phi) - half) < 1e-6:
        return  # on the border: both answers are right up to round-off
    if abs(r - cfg.detection_range_m) < 1e-9 or abs(r - cfg.safety_distance_m) < 1e-9:
        return
    p = np.array([[r * math.cos(phi), r * math.sin(phi)]])
    h = fov_barrier(p, cfg.fov_rad, cfg.safety_distance_m, cfg.detection_range_m)[0]
    sees = bool(in_fov(p, cfg.fov_rad, cfg.detection_range_m)[0])
    assert bool(np.all(h[[0, 1, 3]] >= 0)) == sees
    assert bool(h[SAFETY_ROW] >= 0) == (r >= cfg.safety_distance_m)


def _fd_case(rng, beta):
    pose_i = np.array([*rng.uniform(5, 35, 2), rng.uniform(-math.pi, math.pi)])
    ang = rng.uniform(-math.pi, math.pi)
    pose_j = np.array(
        [*(pose_i[:2] + rng.uniform(2.5, 12) * np.array([math.cos(ang), math.sin(ang)])), 0.0]
    )
    u = np.array([*rng.uniform(-1, 1, 2), rng.uniform(-1.5, 1.5)])
    vj_world = rng.uniform(-1, 1, 2)
    return pose_i, pose_j, u, vj_world


@pytest.mark.parametrize("beta", BETAS)
@pytest.mark.parametrize("seed", range(8))
def test_lie_derivative_matches_finite_difference_of_simulated_step(beta, seed):
    """ḣ = A u + drift against a central difference of the simulated relative motion."""
    cfg = _cfg(beta)
    rng = np.random.default_rng(seed)
    pose_i, pose_j, u, vj = _fd_case(rng, beta)
    dt = 1e-5

    def h_at(t):
        pi = integrate_unicycle(pose_i, u[:2], u[2], t)
        pj = pose_j[:2] + vj * t
        pb = world_to_body(pj, pi)[None]
        return fov_barrier(pb, cfg.fov_rad, cfg.safety_distance_m, cfg.detection_range_m)[0]

    active = np.isfinite(h_at(0.0))
    fd = (h_at(dt)[active] - h_at(-dt)[active]) / (2 * dt)
    p_body = world_to_body(pose_j[:2], pose_i)[None]
    v_body = (rotation(pose_i[2]).T @ vj)[None]
    A, drift = fov_barrier_lie(p_body, v_body, cfg.fov_rad)
    pred = A[0] @ u + drift[0]
    np.testing.assert_allclose(pred[active], fd, rtol=1e-5, atol=1e-5)


def test_class_k_is_odd_and_increasing_per_row():
    h = np.linspace(-50, 50, 1001)
    H = np.repeat(h[:, None], 4, axis=1)
    a = class_k(H, PRM)
    assert np.all(np.diff(a, axis=0) > 0)
    np.testing.assert_allclose(class_k(-H, PRM), -a)
    np.testing.assert_allclose(a[:, 0], PRM.alpha_border_gain * h + PRM.alpha_border_cubic * h**3)
    np.testing.assert_allclose(a[:, 2], PRM.alpha_safety_gain * h)
    np.testing.assert_allclose(a[:, 3], PRM.alpha_range_gain * h)
    assert np.all(np.isposinf(class_k(np.full((1, 4), np.inf), PRM)))


def test_h_max_values_for_the_paper_setup():
    # β = 120°, L = 40 m, R_d = 10 m: border rows over the arena diagonal ρ = L√2
    hm = row_h_max(_cfg(120.0))
    rho = 40 * math.sqrt(2)
    np.testing.assert_allclose(hm, [2 * rho, 2 * rho, 0.0, 3100.0], rtol=1e-12)
    hm200 = row_h_max(_cfg(200.0))
    np.testing.assert_allclose(hm200, [rho * (1 + math.cos(math.radians(100))), 0, 0, 3100])
    np.testing.assert_allclose(row_h_max(_cfg(360.0)), [0, 0, 0, 3100])


@pytest.mark.parametrize("beta", BETAS)
def test_h_max_is_the_modulus_of_the_lowest_value_in_the_arena(beta):
    cfg = _cfg(beta)
    rho = cfg.arena_size_m * math.sqrt(2)
    th = np.linspace(-math.pi, math.pi, 20001)
    r = np.linspace(0, rho, 201)
    p = (r[:, None, None] * np.stack([np.cos(th), np.sin(th)], -1)[None]).reshape(-1, 2)
    h = fov_barrier(p, cfg.fov_rad, cfg.safety_distance_m, cfg.detection_range_m)
    lowest = np.where(np.isinf(h), 0.0, h).min(axis=0)
    expected = np.maximum(0.0, -lowest)
    expected[SAFETY_ROW] = 0.0  # hard row: no slack
    np.testing.assert_allclose(row_h_max(cfg), expected, rtol=1e-6, atol=1e-6)


def test_slack_values_zero_below_ds():
    cfg = _cfg(120.0)
    hm = row_h_max(cfg, PRM.fov_margin_m)
    ds = cfg.safety_distance_m
    d = np.array([0.0, ds, 3 * ds, 1e3])
    eps = slack(d, cfg, PRM)
    s0 = float(sigmoid(-2 * ds))
    np.testing.assert_allclose(eps[0], 0.0)
    np.testing.assert_allclose(eps[1], 0.0)
    np.testing.assert_allclose(eps[2], hm * (0.5 - s0) / (1 - s0))
    np.testing.assert_allclose(eps[3], hm, rtol=1e-12)
    assert np.all(eps[:, SAFETY_ROW] == 0.0)


def test_slack_values_raw_paper_formula_and_slope():
    cfg = _cfg(120.0)
    hm = row_h_max(cfg)
    ds = cfg.safety_distance_m
    raw = ControllerParams(slack_zero_below_ds=False, fov_margin_m=0.0)
    eps = slack(np.array([ds, 3 * ds, 1e3]), cfg, raw)
    np.testing.assert_allclose(eps[0], hm * (1 / (1 + math.exp(2 * ds))) * np.array([1, 1, 0, 1]))
    np.testing.assert_allclose(eps[1], hm * np.array([0.5, 0.5, 0, 0.5]))
    np.testing.assert_allclose(eps[2], hm * np.array([1, 1, 0, 1]))
    steep = ControllerParams(slack_zero_below_ds=False, slack_slope=2.0, fov_margin_m=0.0)
    e1 = slack(np.array([5.0, 7.0]), cfg, raw)[:, 0]
    e2 = slack(np.array([5.0, 7.0]), cfg, steep)[:, 0]
    assert e2[0] < e1[0] and e2[1] > e1[1]


@given(st.lists(st.floats(0, 100), min_size=2, max_size=20))
def test_slack_is_monotone_in_distance(ds):
    cfg = _cfg(120.0)
    d = np.sort(np.array(ds))
    eps = slack(d, cfg, PRM)
    assert np.all(np.diff(eps, axis=0) >= -1e-12)
    assert np.all(eps >= 0) and np.all(eps <= row_h_max(cfg, PRM.fov_margin_m) + 1e-9)


def _admissible_samples(cfg, n=4000, seed=0):
    rng = np.random.default_rng(seed)
    ang = rng.uniform(-math.pi, math.pi, n)
    rad = cfg.v_max_mps * np.sqrt(rng.uniform(0, 1, n))
    u = np.column_stack([rad * np.cos(ang), rad * np.sin(ang), rng.uniform(-1, 1, n)])
    u[:, 2] *= cfg.omega_max_radps
    corners = np.array([[cfg.v_max_mps * math.cos(a), cfg.v_max_mps * math.sin(a), w]
                        for a in np.linspace(-math.pi, math.pi, 64)
                        for w in (-cfg.omega_max_radps, cfg.omega_max_radps)])  # fmt: skip
    return np.vstack([u, corners])


@pytest.mark.parametrize("beta", BETAS)
def test_pruned_rows_hold_for_every_admissible_input(beta):
    """Closed-form pruning (b̃ ≥ 1) never drops a row some admissible input violates."""
    cfg = _cfg(beta)
    rng = np.random.default_rng(1)
    M = 400
    p = rng.uniform(-30, 30, (M, 2))
    v = rng.uniform(-1, 1, (M, 2))
    d = rng.uniform(0, 20, M)
    rows = cbf_rows(p, v, d, cfg, PRM)
    At, bt, a = normalise_rows(rows.A, rows.b, cfg.v_max_mps, cfg.omega_max_radps, 10.0)
    U = _admissible_samples(cfg)
    pruned = bt >= 1.0
    assert pruned.any() and (~pruned).any()
    vals = np.einsum("mrk,nk->mrn", rows.A, U) + rows.b[..., None]
    assert np.all(vals[pruned] >= -1e-9)
    # and the authority is the exact max of |A u|: attained up to the sampling
    act = np.isfinite(rows.h)
    best = np.abs(np.einsum("mrk,nk->mrn", rows.A, U)).max(-1)
    np.testing.assert_allclose(best[act], a[act], rtol=2e-3)


@given(r=st.floats(3.0, 45.0), phi=st.floats(-math.pi, math.pi), vx=st.floats(-1, 1),
       vy=st.floats(-1, 1))  # fmt: skip
def test_far_neighbour_fov_rows_are_released(r, phi, vx, vy):
    """With σ → 1 (d large) the border and range rows hold for every input: pruned."""
    cfg = _cfg(120.0)
    p = np.array([[r * math.cos(phi), r * math.sin(phi)]])
    rows = cbf_rows(p, np.array([[vx, vy]]), np.array([60.0]), cfg, PRM)
    _, bt, _ = normalise_rows(rows.A, rows.b, cfg.v_max_mps, cfg.omega_max_radps, 10.0)
    assert np.all(bt[0, [0, 1, 3]] >= 1.0)


def test_near_neighbour_rows_are_the_hard_cbf():
    """d ≤ D_s: ε = 0 and b = drift + α(h) (Eq. 11 unrelaxed), with the paper's rows."""
    cfg = _cfg(120.0)
    prm = PAPER_ROWS
    p = np.array([[3.0, 4.0], [-2.0, 1.0]])
    v = np.array([[0.3, -0.2], [0.0, 1.0]])
    rows = cbf_rows(p, v, np.array([0.0, 2.0]), cfg, prm)
    A, drift = fov_barrier_lie(p, v, cfg.fov_rad)
    h = fov_barrier(p, cfg.fov_rad, 2.0, 10.0, prm.fov_margin_m)
    np.testing.assert_allclose(rows.eps, 0.0)
    np.testing.assert_allclose(rows.b, drift + class_k(h, prm))
    np.testing.assert_allclose(rows.A, A)


def test_fov_rows_in_view_are_the_papers():
    """Default ``fov_recovery_cap``: rows of a neighbour in view (h + ε ≥ 0) are untouched."""
    cfg = _cfg(120.0)
    p = np.array([[3.0, 0.2], [6.0, -2.0], [20.0, 5.0]])
    v = np.array([[0.3, -0.2], [0.0, 0.5], [-0.5, 0.0]])
    d = np.array([0.0, 1.0, 15.0])
    rows, paper = cbf_rows(p, v, d, cfg, PRM), cbf_rows(p, v, d, cfg, PAPER_ROWS)
    np.testing.assert_array_equal(rows.A, paper.A)
    np.testing.assert_array_equal(rows.b, paper.b)


def test_fov_recovery_turns_the_camera_and_never_drives():
    """A neighbour out of view (h + ε < 0, ε = 0 at d = 0): its border rows lose their
    translation terms and demand at most what rotation gives (``−c |A_ω| ω_max``), so
    turning towards it satisfies them; the paper's rows demand more and credit backing
    up towards the neighbour. Rows that hold and the safety row are unchanged."""
    cfg = _cfg(120.0)
    w_max = cfg.omega_max_radps
    phi = math.radians(100.0)  # 40° beyond the left border, 8 m away
    p = np.array([[8.0 * math.cos(phi), 8.0 * math.sin(phi)]])
    v, d = np.zeros((1, 2)), np.zeros(1)
    rows, paper = cbf_rows(p, v, d, cfg, PRM), cbf_rows(p, v, d, cfg, PAPER_ROWS)
    assert paper.h[0, 1] < 0 <= paper.h[0, 0]
    np.testing.assert_allclose(rows.A[0, 1, 0:2], 0.0)
    np.testing.assert_allclose(rows.A[0, 1, 2], paper.A[0, 1, 2])
    cap = -PRM.fov_recovery_cap * abs(paper.A[0, 1, 2]) * w_max
    np.testing.assert_allclose(rows.b[0, 1], cap)
    assert paper.b[0, 1] < cap  # the paper's cubic demands more than ω_max can give
    np.testing.assert_array_equal(rows.A[0, [0, 2]], paper.A[0, [0, 2]])
    np.testing.assert_array_equal(rows.b[0, [0, 2]], paper.b[0, [0, 2]])
    turn = np.array([0.0, 0.0, w_max])
    assert np.all(rows.A[0, 0:2] @ turn + rows.b[0, 0:2] >= 0.0)
    assert not np.all(paper.A[0, 0:2] @ turn + paper.b[0, 0:2] >= 0.0)


def test_fov_recovery_behind_turns_towards_the_neighbours_side():
    """Back cone (both border rows violated): their ω terms disagree, so the row that
    would turn the robot away from j's side (sign of y) is voided; turning towards j at
    ω_max then satisfies both, turning away does not."""
    cfg = _cfg(120.0)
    w_max = cfg.omega_max_radps
    for y in (0.7, -0.7):
        p = np.array([[-6.0, y]])
        rows = cbf_rows(p, np.zeros((1, 2)), np.zeros(1), cfg, PRM)
        paper = cbf_rows(p, np.zeros((1, 2)), np.zeros(1), cfg, PAPER_ROWS)
        assert np.all(paper.h[0, 0:2] < 0)
        assert paper.A[0, 0, 2] * paper.A[0, 1, 2] < 0  # the paper's rows conflict in ω
        np.testing.assert_allclose(rows.A[0, 0:2, 0:2], 0.0)
        towards = np.array([0.0, 0.0, math.copysign(w_max, y)])
        assert np.all(rows.A[0, 0:2] @ towards + rows.b[0, 0:2] >= 0.0)
        assert not np.all(rows.A[0, 0:2] @ -towards + rows.b[0, 0:2] >= 0.0)


def test_range_row_beyond_range_is_void_inside_it_is_kept():
    """The range row of a mean beyond R_d (h + ε < 0) cannot be repaired by turning: it
    is void (A = 0, b ≥ 0) instead of pulling the robot towards the mean; within R_d it
    keeps the paper's form (it still stops the robot from backing out of range)."""
    cfg = _cfg(120.0)
    p = np.array([[10.4, 0.0], [3.0, 0.5]])
    v = np.zeros((2, 2))
    d = np.zeros(2)
    rows, paper = cbf_rows(p, v, d, cfg, PRM), cbf_rows(p, v, d, cfg, PAPER_ROWS)
    assert paper.h[0, 3] < 0 and paper.b[0, 3] < 0  # the paper: drive towards the mean
    np.testing.assert_allclose(rows.A[0, 3], 0.0)
    assert rows.b[0, 3] == np.inf and rows.h[0, 3] == np.inf  # void: pruned
    np.testing.assert_array_equal(rows.A[1, 3], paper.A[1, 3])
    np.testing.assert_array_equal(rows.b[1, 3], paper.b[1, 3])


def test_motion_cone_rows_shape_the_admissible_speeds():
    """Full speed within ±a of the camera axis, ~v_b beyond the tangent points
    ``ψ = a + acos(v_b / v_max)``, monotone in between (the hull's straight sides);
    u = 0 admissible; a capped at β/2; no rows for an isotropic camera."""
    vb, vmax = 0.05, 1.0

    def top_speed(G, h, ang):
        e = np.array([math.cos(ang), math.sin(ang), 0.0])
        r = G @ e
        return min([hh / rr for rr, hh in zip(r, h, strict=True) if rr < 0] + [np.inf])

    for fov, half in ((120.0, 20.0), (120.0, 80.0), (240.0, 20.0), (40.0, 60.0)):
        G, h = motion_cone_rows(math.radians(fov), vb, vmax, math.radians(half))
        a = min(fov / 2, half)
        assert G.shape == (5, 3) and np.all(G[:, 2] == 0) and np.all(h <= 0)
        assert np.all(G @ np.zeros(3) >= h)
        for sgn in (1.0, -1.0):
            assert top_speed(G, h, sgn * math.radians(a)) >= vmax - 1e-9
            psi = a + math.degrees(math.acos(vb / vmax))
            speeds = [top_speed(G, h, sgn * math.radians(x)) for x in np.linspace(a, psi, 40)]
            assert np.all(np.diff(speeds) <= 1e-9)
            for x in np.linspace(psi, 180.0, 10):
                assert top_speed(G, h, sgn * math.radians(x)) <= vb / math.cos(math.pi / 8) + 1e-9
    G, h = motion_cone_rows(2 * math.pi, vb, vmax, math.radians(20.0))
    assert G.shape == (0, 3) and h.shape == (0,)


def test_safety_speed_margin_tightens_only_the_safety_row():
    cfg = _cfg(120.0)
    p = np.array([[3.0, 4.0]])
    v = np.zeros((1, 2))
    r0 = cbf_rows(p, v, np.array([1.0]), cfg, PRM)
    r1 = cbf_rows(
        p,
        v,
        np.array([1.0]),
        cfg,
        ControllerParams(safety_speed_margin_mps=0.5, fov_translation="all"),
    )
    np.testing.assert_allclose(r0.b[0, SAFETY_ROW] - r1.b[0, SAFETY_ROW], 2 * 5.0 * 0.5)
    np.testing.assert_allclose(r0.b[0, [0, 1, 3]], r1.b[0, [0, 1, 3]])


def test_row_authority_closed_form():
    A = np.array([[3.0, 4.0, -2.0]])
    np.testing.assert_allclose(row_authority(A, 1.0, 1.5), [5.0 + 3.0])


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("alpha_safety_gain", 0.0),
        ("alpha_range_gain", -1.0),
        ("alpha_border_gain", float("nan")),
        ("slack_slope", 0.0),
        ("max_levels", 0),
        ("max_levels", 2.5),
        ("n_polygon", 3),
        ("qp_backend", "cvxpy"),
        ("row_clip", 1.0),
        ("cascade_reg", 0.0),
        ("lloyd_grid_m", 0.0),
        ("lloyd_min_mass", 1.0),
        ("safety_first", 1),
        ("lost_sigma_max_m", 0.0),
        ("lost_sigma_max_m", float("nan")),
        ("lost_fov_age_s", -1.0),
        ("lost_fov_yield", 1),
        ("lost_fov_yield_latch", 1),
        ("hold_band_barrier", 1),
        ("deadlock_release", 0.1),
        ("deadlock_release", 1.5),
        ("priority_hysteresis_m", -0.1),
        ("priority_hysteresis_m", float("nan")),
        ("undetected_quantile", "median"),
        ("bearing_cone_max_deg", -1.0),
        ("bearing_cone_max_deg", 85.0),
        ("fallback_tie_mps", -0.1),
        ("fallback_tie_mps", float("nan")),
        ("fallback_straight", 1),
    ],
)
def test_controller_params_validation_names_field(field, value):
    with pytest.raises(ConfigError, match=field):
        ControllerParams(**{field: value})


def test_controller_params_border_class_k_must_not_vanish():
    with pytest.raises(ConfigError, match="alpha_border"):
        ControllerParams(alpha_border_gain=0.0, alpha_border_cubic=0.0)
    ControllerParams(alpha_border_gain=0.0, alpha_border_cubic=1.0)  # the authors' pure cubic


@pytest.mark.parametrize("mode", ["none", "seen"])
def test_fov_translation_none_and_seen_keep_only_rotation_terms(mode):
    """``fov_translation="none"`` (default): every FoV row of every neighbour is reduced to
    its rotation term; ``"seen"``: those of undetected neighbours only. The safety row is
    never touched."""
    cfg = _cfg(120.0)
    p = np.array([[3.0, 0.2], [6.0, -2.0], [-4.0, 3.0]])
    v = np.zeros((3, 2))
    d = np.array([0.0, 1.0, 0.5])
    det = np.array([True, False, False])
    rows = cbf_rows(p, v, d, cfg, ControllerParams(fov_translation=mode), detected=det)
    full = cbf_rows(p, v, d, cfg, PRM, detected=det)
    fov = [0, 1, 3]
    reduced = np.ones(3, bool) if mode == "none" else ~det
    assert np.all(rows.A[reduced][:, fov, 0:2] == 0.0)
    if mode == "seen":
        np.testing.assert_array_equal(rows.A[0], full.A[0])
    np.testing.assert_array_equal(rows.A[:, 2], full.A[:, 2])
    np.testing.assert_array_equal(rows.b[:, 2], full.b[:, 2])
