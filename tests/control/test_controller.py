"""FovCbfController: levels, pruning, fallbacks and scripted closed loops (Section VI)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fov_marl.config import make_config
from fov_marl.control import ControllerParams, FovCbfController
from fov_marl.control.qp import project_to_admissible
from fov_marl.geometry import in_fov, integrate_unicycle, rotation, world_to_body

CFG = make_config()


def _random_instance(rng, M, spread=12.0):
    p = rng.uniform(-spread, spread, (M, 2))
    r = np.hypot(p[:, 0], p[:, 1])
    p[r < 1.0] *= (1.5 / np.maximum(r[r < 1.0], 1e-3))[:, None]
    v = rng.uniform(-0.7, 0.7, (M, 2))
    d = np.maximum(0.0, np.hypot(p[:, 0], p[:, 1]) - rng.uniform(0.3, 6.0, M))
    u_star = np.array([*rng.uniform(-1, 1, 2), rng.uniform(-1.5, 1.5)])
    return u_star, p, v, d


def _admissible(u):
    return (
        math.hypot(u[0], u[1]) <= CFG.v_max_mps + 1e-9 and abs(u[2]) <= CFG.omega_max_radps + 1e-9
    )


def test_no_neighbours_returns_projected_u_star():
    ctrl = FovCbfController(CFG)
    u_star = np.array([0.6, 0.8, 2.0])
    res = ctrl.solve(u_star, np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0))
    assert res.status == "unconstrained" and not res.fallback and not res.intervened
    np.testing.assert_allclose(res.u, project_to_admissible(u_star, 1.0, 1.5, 16))
    assert res.kappa.shape == (0, 4)


@pytest.mark.parametrize("fov", [60.0, 120.0, 200.0, 360.0])
@pytest.mark.parametrize("seed", range(5))
def test_random_instances_give_finite_admissible_inputs(fov, seed):
    cfg = make_config(fov_deg=fov)
    ctrl = FovCbfController(cfg)
    rng = np.random.default_rng(seed)
    for _ in range(20):
        u_star, p, v, d = _random_instance(rng, int(rng.integers(1, 20)))
        res = ctrl.solve(u_star, p, v, d)
        assert np.all(np.isfinite(res.u)) and _admissible(res.u)
        # random neighbours may sit inside D_s on all sides: the collision rows then
        # cannot all be met and the documented safe fallback is the only fallback
        assert res.status in ("unconstrained", "solved", "relaxed", "safety_fallback")
        assert res.fallback == (res.status == "safety_fallback")
        assert res.kappa.shape == p.shape[:1] + (4,)
        assert np.all(res.kappa[~res.active] == 0)
    assert ctrl.stats["steps"] == 20
    assert ctrl.stats["fallbacks"] == ctrl.stats["safety_fallbacks"]


@pytest.mark.parametrize("seed", range(15))
def test_pruning_never_changes_the_solution(seed):
    """Rows pruned in closed form hold for every input: same u and κ with and without."""
    rng = np.random.default_rng(50 + seed)
    big = dict(max_levels=64, max_fov_neighbours=1024)
    a = FovCbfController(CFG, ControllerParams(prune=True, **big))
    b = FovCbfController(CFG, ControllerParams(prune=False, **big))
    for _ in range(10):
        u_star, p, v, d = _random_instance(rng, int(rng.integers(1, 25)), spread=25.0)
        ra, rb = a.solve(u_star, p, v, d), b.solve(u_star, p, v, d)
        assert ra.active.sum() <= rb.active.sum()
        np.testing.assert_allclose(ra.u, rb.u, atol=1e-6)
        np.testing.assert_allclose(ra.kappa, rb.kappa, atol=1e-6)


def test_levels_follow_ascending_distance_and_cap():
    ctrl = FovCbfController(CFG, ControllerParams(max_levels=2, prune=False))
    d = np.array([5.0, 1.0, 3.0, 0.5])
    active = np.ones((4, 4), dtype=bool)
    lev = ctrl.assign_levels(active, d, np.arange(4))
    np.testing.assert_array_equal(lev[:, 2], 0)  # safety rows first
    # nearest (index 3) gets level 1, the rest share the capped level 2
    np.testing.assert_array_equal(lev[[3, 1, 2, 0]][:, 0], [1, 2, 2, 2])
    paper = FovCbfController(CFG, ControllerParams(safety_first=False, max_levels=8))
    lev_p = paper.assign_levels(active, d, np.arange(4))
    np.testing.assert_array_equal(lev_p[[3, 1, 2, 0]], np.repeat([[1], [2], [3], [4]], 4, axis=1))
    hard = FovCbfController(CFG, ControllerParams(safety_hard=True))
    assert np.all(hard.assign_levels(active, d, np.arange(4))[:, 2] == -1)
    # FoV rows beyond max_fov_neighbours are left out; their safety rows stay
    few = FovCbfController(CFG, ControllerParams(max_fov_neighbours=2, prune=False))
    lev_f = few.assign_levels(active, d, np.arange(4))
    np.testing.assert_array_equal(lev_f[[2, 0]][:, [0, 1, 3]], -2)
    assert np.all(lev_f[[3, 1]][:, [0, 1, 3]] >= 1) and np.all(lev_f[:, 2] == 0)
    # ties in d are broken by id
    lev_t = paper.assign_levels(active[:2], np.array([1.0, 1.0]), np.array([7, 3]))
    np.testing.assert_array_equal(lev_t[:, 0], [2, 1])


def test_nearer_neighbour_has_priority_in_a_conflict():
    """Two neighbours behind-left and behind-right, both hard: only one can be faced."""
    ctrl = FovCbfController(CFG, ControllerParams(max_levels=8))
    p = np.array([[-4.0, 3.0], [-4.0, -3.0]])
    v = np.zeros((2, 2))
    u_star = np.zeros(3)
    res_a = ctrl.solve(u_star, p, v, np.array([0.0, 1.0]))
    res_b = ctrl.solve(u_star, p, v, np.array([1.0, 0.0]))
    # the nearer neighbour's FoV rows are violated less than the farther one's
    assert res_a.kappa[0, :2].sum() < res_a.kappa[1, :2].sum()
    assert res_b.kappa[1, :2].sum() < res_b.kappa[0, :2].sum()
    assert res_a.u[2] > 0 > res_b.u[2]  # turns left toward 0, right toward 1


@pytest.mark.parametrize("what", ["u_star", "p_body", "v_est_body", "d"])
def test_non_finite_inputs_fall_back_without_raising(what):
    ctrl = FovCbfController(CFG)
    args = {
        "u_star": np.array([0.5, 0.0, 0.0]),
        "p_body": np.array([[3.0, 0.0]]),
        "v_est_body": np.zeros((1, 2)),
        "d": np.array([1.0]),
    }
    args[what] = np.full_like(args[what], np.nan)
    res = ctrl.solve(**args)
    assert res.status == "invalid_input" and res.fallback
    np.testing.assert_array_equal(res.u, np.zeros(3))
    assert ctrl.stats["fallbacks"] == 1


def test_shape_errors_raise_value_error():
    ctrl = FovCbfController(CFG)
    with pytest.raises(ValueError, match="u_star"):
        ctrl.solve(np.zeros(2), np.zeros((1, 2)), np.zeros((1, 2)), np.zeros(1))
    with pytest.raises(ValueError, match="v_est_body"):
        ctrl.solve(np.zeros(3), np.zeros((1, 2)), np.zeros((2, 2)), np.zeros(1))
    with pytest.raises(ValueError, match="d must"):
        ctrl.solve(np.zeros(3), np.zeros((1, 2)), np.zeros((1, 2)), np.zeros(2))
    with pytest.raises(ValueError, match="ids"):
        ctrl.solve(np.zeros(3), np.zeros((1, 2)), np.zeros((1, 2)), np.zeros(1), np.zeros(3))


def _squeeze():
    """Robot between two neighbours 1.5 m away (inside D_s) closing at 1 m/s each."""
    p = np.array([[0.0, 1.5], [0.0, -1.5]])
    v = np.array([[0.0, -1.0], [0.0, 1.0]])
    return np.array([0.5, 0.0, 0.0]), p, v, np.zeros(2)


def test_infeasible_hard_safety_rows_brake_and_are_counted():
    """The paper's mean-based row 3 (``safety_model="mean"``), hard: infeasible → brake."""
    ctrl = FovCbfController(CFG, ControllerParams(safety_hard=True, safety_model="mean"))
    res = ctrl.solve(*_squeeze())
    assert res.status == "qp_failed" and res.fallback
    np.testing.assert_array_equal(res.u, np.zeros(3))
    assert ctrl.stats["fallbacks"] == 1


@pytest.mark.parametrize("hard", [False, True])
def test_infeasible_collision_rows_take_the_safe_fallback(hard):
    """Squeezed between two neighbours inside D_s: the rows of the uncertainty cannot be met;
    the fallback closes on neither neighbour (no motion along ±y, where they are); counted.
    With the rows as hard constraints the QP has no solution: the robot stops translating
    and turns towards a neighbour."""
    ctrl = FovCbfController(CFG, ControllerParams(safety_hard=hard))
    res = ctrl.solve(*_squeeze())
    assert res.status == "safety_fallback" and res.fallback
    assert ctrl.stats["safety_fallbacks"] == 1 and ctrl.stats["fallbacks"] == 1
    assert abs(res.u[1]) < 1e-6
    if hard:
        np.testing.assert_array_equal(res.u[:2], np.zeros(2))
        assert abs(res.u[2]) == pytest.approx(CFG.omega_max_radps)  # neighbours at ±90°
    else:
        assert res.safety_violation > 0


def test_infeasible_safety_level_is_relaxed_when_soft():
    ctrl = FovCbfController(CFG, ControllerParams(safety_model="mean"))
    res = ctrl.solve(*_squeeze())
    assert res.status == "relaxed" and not res.fallback
    assert res.safety_violation > 0
    assert _admissible(res.u)


def test_intervened_flag():
    ctrl = FovCbfController(CFG)
    far = ctrl.solve(
        np.array([1.0, 0.0, 1.0]), np.array([[-30.0, 0.0]]), np.zeros((1, 2)), np.array([25.0])
    )
    assert not far.intervened and far.status == "unconstrained"
    near = ctrl.solve(
        np.array([1.0, 0.0, 0.0]), np.array([[2.1, 0.0]]), np.zeros((1, 2)), np.array([0.0])
    )
    assert near.intervened and near.u[0] < 0.5
    assert ctrl.stats["interventions"] == 1


def test_osqp_backend_runs_the_same_pipeline():
    rng = np.random.default_rng(3)
    a = FovCbfController(CFG)
    b = FovCbfController(CFG, ControllerParams(qp_backend="osqp"))
    for _ in range(10):
        u_star, p, v, d = _random_instance(rng, 6)
        ra, rb = a.solve(u_star, p, v, d), b.solve(u_star, p, v, d)
        assert np.all(np.isfinite(rb.u)) and _admissible(rb.u)
        if ra.status in ("unconstrained", "solved") and rb.status != "degraded":
            np.testing.assert_allclose(rb.u, ra.u, atol=1e-2)


# --------------------------------------------------------------------------- closed loops
def _run_pair(u_star_fn, pose_i, pose_j, v_j_world, ellipse_radius, steps, params=None, cfg=CFG):
    """Simulate robot i (controller) and neighbour j (constant velocity) with exact kinematics.

    The controller sees the true relative position and velocity, and d from an isotropic
    ellipse of radius ``ellipse_radius`` around j.
    """
    ctrl = FovCbfController(cfg, params)
    pose_i, pose_j = np.array(pose_i, float), np.array(pose_j, float)
    vj = np.asarray(v_j_world, float)
    log = []
    for _ in range(steps):
        p_body = world_to_body(pose_j[:2], pose_i)
        v_body = rotation(pose_i[2]).T @ vj
        d = max(0.0, math.hypot(*p_body) - ellipse_radius)
        u_star = u_star_fn(pose_i, p_body)
        res = ctrl.solve(u_star, p_body[None], v_body[None], np.array([d]))
        assert not res.fallback
        pose_i = integrate_unicycle(pose_i, res.u[:2], res.u[2], cfg.dt_s)
        pose_j = pose_j + np.append(vj * cfg.dt_s, 0.0)
        p_next = world_to_body(pose_j[:2], pose_i)
        log.append((p_next, d, res))
    return log


def _seen(log, cfg=CFG):
    return np.array(
        [bool(in_fov(p[None], cfg.fov_rad, cfg.detection_range_m)[0]) for p, _, _ in log]
    )


def test_hard_neighbour_stays_in_view_while_u_star_turns_away():
    """d = 0 (ε = 0): u* spins the robot; the border rows stop it with j still in view."""
    log = _run_pair(
        lambda *_: np.array([0.0, 0.0, 1.5]), (20, 20, 0), (22.5, 20, 0), (0, 0), 5.0, 80
    )
    assert _seen(log).all()
    bearing = math.degrees(math.atan2(log[-1][0][1], log[-1][0][0]))
    assert 40.0 < abs(bearing) <= 60.0 + 1e-6  # turned up to the border, not past it
    assert all(r.intervened for _, _, r in log[-40:])


def test_hard_neighbour_stays_in_view_while_u_star_backs_away():
    """A large ellipse keeps d = 0: backing off and turning, j stays in view and in range
    (with the paper's translating FoV rows, ``fov_translation="all"``)."""
    log = _run_pair(
        lambda *_: np.array([-1.0, 0.0, 1.0]),
        (20, 20, 0),
        (23, 20.5, 0),
        (0, 0),
        12.0,
        150,
        ControllerParams(fov_translation="all"),
    )
    assert _seen(log).all()
    assert max(math.hypot(*p) for p, _, _ in log) <= CFG.detection_range_m + 1e-6


def test_hard_neighbour_moving_is_tracked():
    """j crosses in front at 0.5 m/s with d ≈ 0: the robot turns to keep it in view."""
    log = _run_pair(lambda *_: np.zeros(3), (20, 20, 0), (24, 17, 0), (0, 0.5), 6.0, 60)
    assert _seen(log).all()


def test_far_neighbour_is_released():
    """d large (slack high): the robot spins as u* asks and j leaves the FoV."""
    log = _run_pair(
        lambda *_: np.array([0.0, 0.0, 1.5]), (20, 20, 0), (32.5, 20, 0), (0, 0), 0.5, 20
    )
    assert not _seen(log).all()
    assert not any(r.intervened for _, _, r in log)


def test_safety_distance_is_kept_driving_at_a_neighbour():
    """u* drives straight at j (static, then approaching): centres stay ≥ D_s apart."""
    for vj in ((0.0, 0.0), (-0.5, 0.0)):
        log = _run_pair(
            lambda pose, pb: np.array([1.0, 0.0, 0.0]), (10, 20, 0), (18, 20, 0), vj, 0.5, 120
        )
        dmin = min(math.hypot(*p) for p, _, _ in log)
        assert dmin >= CFG.safety_distance_m - 0.05


def test_ties_in_d_go_to_the_nearest_mean_first():
    """Several far-reaching ellipses give d = 0: the nearest mean gets the first FoV level."""
    ctrl = FovCbfController(CFG, ControllerParams(prune=False, max_levels=8))
    active = np.ones((3, 4), dtype=bool)
    lev = ctrl.assign_levels(active, np.zeros(3), np.arange(3), np.array([6.0, 2.0, 9.0]))
    np.testing.assert_array_equal(lev[:, 0], [2, 1, 3])


def test_the_previous_fov_lead_keeps_its_level_within_the_hysteresis():
    """Eq. 18 orders by d; the lead of the previous step keeps level 1 until another
    neighbour's d is more than its head start smaller."""
    ctrl = FovCbfController(CFG, ControllerParams(prune=False, max_levels=8))
    active = np.ones((2, 4), dtype=bool)
    ids = np.arange(2)
    for d1, first in ((1.2, 0), (0.9, 0), (0.6, 0), (0.4, 1)):
        d = np.array([1.0, d1])
        lev = ctrl.assign_levels(active, d, ids, None, np.array([0.5, 0.0]))
        assert lev[first, 0] == 1, (d1, lev[:, 0])
    lev = ctrl.assign_levels(active, np.array([1.0, 0.9]), ids, None)  # no head start
    assert lev[1, 0] == 1


def test_neighbour_behind_is_searched_by_turning_not_by_backing_up():
    """A hard neighbour behind (d = 0) while u* drives ahead: the default rows turn the robot
    until it sees j and never pull it back; the paper's rows back it up blind, never see j."""
    scripted = (lambda *_: np.array([1.0, 0.0, 0.0]), (10, 20, 0), (4, 20.5, 0), (0, 0), 12.0, 50)
    log = _run_pair(*scripted)
    assert _seen(log)[:25].any() and _seen(log)[-10:].all()
    assert all(r.u[0] > 0.5 for _, _, r in log[:15])  # keeps driving while it turns
    paper = _run_pair(*scripted, params=ControllerParams(fov_recovery_cap=0.0))
    assert not _seen(paper).any()
    assert min(r.u[0] for _, _, r in paper) < -0.5


def _cone_speed_limit(params, cfg=CFG):
    from fov_marl.control.cbf import motion_cone_rows

    G, h = motion_cone_rows(
        cfg.fov_rad, params.blind_speed_mps, cfg.v_max_mps, math.radians(params.cone_half_angle_deg)
    )

    def limit(v):
        return bool(np.all(G[:, :2] @ v >= h - 1e-9))

    return limit


def test_motion_cone_turns_to_look_then_goes():
    """u* away from a neighbour 5 m ahead (world −x, ω* = 0): with the cone the robot first
    turns (look gain) at ≤ v_b and only then moves fast; without it, it backs off blind."""
    prm = ControllerParams(motion_cone=True)
    inside = _cone_speed_limit(prm)

    def away(pose, _):
        c, s = math.cos(pose[2]), math.sin(pose[2])
        return np.array([-c, s, 0.0])  # R(θ)ᵀ (−1, 0)

    log = _run_pair(away, (20, 20, 0), (25, 20, 0), (0, 0), 0.5, 40, prm)
    assert all(inside(r.u[:2]) for _, _, r in log)
    assert math.hypot(*log[0][2].u[:2]) <= prm.blind_speed_mps / math.cos(math.pi / 8) + 1e-9
    assert log[0][2].u[2] == pytest.approx(CFG.omega_max_radps)  # look: turn at full rate
    assert log[0][2].intervened and log[0][2].u_star[2] == 0.0  # ω* as given, changed
    assert max(math.hypot(*r.u[:2]) for _, _, r in log[-10:]) > 0.9  # then it goes
    free = _run_pair(
        lambda *_: np.array([-1.0, 0.0, 0.0]), (20, 20, 0), (25, 20, 0), (0, 0), 0.5, 3
    )
    assert free[0][2].u[0] < -0.9


def test_motion_cone_yields_to_the_safety_rows():
    """A neighbour in view closing in at 0.8 m/s (its estimated velocity): the cone level
    ranks below safety, so the robot backs off blind faster than v_b and keeps D_s."""
    prm = ControllerParams(motion_cone=True)
    log = _run_pair(lambda *_: np.zeros(3), (20, 20, 0), (23, 20, 0), (-0.8, 0), 0.5, 40, prm)
    dmin = min(math.hypot(*p) for p, _, _ in log)
    assert dmin >= CFG.safety_distance_m - 0.1
    assert max(r.cone_violation for _, _, r in log) > 0.0
    assert min(r.u[0] for _, _, r in log) < -0.5


def test_motion_cone_levels_and_reporting():
    """The cone is level 1 (FoV levels shift below it); no cone without neighbours or at 360°."""
    prm = ControllerParams(
        motion_cone=True, prune=False, safety_model="mean", fov_translation="all"
    )
    ctrl = FovCbfController(CFG, prm)
    res = ctrl.solve(
        np.array([0.0, 1.0, 0.0]), np.array([[4.0, 0.5]]), np.zeros((1, 2)), np.zeros(1)
    )
    assert res.level[0, 2] == 0 and np.all(res.level[0, [0, 1, 3]] >= 2)
    assert res.intervened and res.u[1] < 0.5 and res.u[2] > 0  # sideways: cut, turns to look
    iso = FovCbfController(make_config(fov_deg=360.0), prm)
    res = iso.solve(
        np.array([0.0, 1.0, 0.0]), np.array([[4.0, 0.5]]), np.zeros((1, 2)), np.zeros(1)
    )
    assert res.u[1] > 0.9 and res.cone_violation == 0.0


def test_default_fov_levels_turn_the_camera_and_leave_translation_to_u_star():
    """Default ``fov_translation="none"``: a hard neighbour (d = 0) while u* backs away and
    sideways: the robot backs off exactly as u* asks (the FoV levels never brake or drive
    it) and turns to keep the neighbour in view."""
    u = lambda *_: np.array([-0.1, 0.9, 0.0])  # noqa: E731
    log = _run_pair(u, (20, 20, 0), (23, 19, 0), (0, 0), 12.0, 40)
    for _, _, r in log:
        np.testing.assert_allclose(r.u[:2], [-0.1, 0.9], atol=1e-6)
    assert _seen(log).all()
    turned = sum(r.u[2] for _, _, r in log) * CFG.dt_s
    assert turned < -0.05  # it turned right, towards j (which falls behind on its right)


def _pinned_crossing_robot():
    """Crossing seed 7, robot 2 at t = 60 s: three neighbours lost 25-30 s before (means
    spread around it, inside their ellipses), backing towards its target blocked by blind
    rows; u* backs and turns right."""
    cfg = make_config(scenario="crossing", n_agents=4)
    p = np.array([[15.0, 9.0], [-5.9, 9.9], [5.5, -10.1]])
    v = -0.5 * p / np.linalg.norm(p, axis=1, keepdims=True)  # Eq. 22
    n = np.array([[-1.0, 0.0], [-0.74, -0.67], [-0.55, -0.83]])
    rows = (np.column_stack([-n, np.zeros(3)]), np.array([0.0, 0.0, 0.3]), np.ones(3, np.int8))
    return cfg, np.array([-0.81, -0.59, -1.5]), p, v, np.zeros(3), rows


def test_lost_neighbours_fov_rows_yield_when_they_stall_the_robot():
    cfg, u, p, v, d, rows = _pinned_crossing_robot()
    det = np.zeros(3, dtype=bool)
    c = FovCbfController(cfg, ControllerParams())
    pinned = c.solve(u, p, v, d, safety=rows, detected=det)
    assert abs(pinned.u[2]) < 0.5 and pinned.u[:2] @ u[:2] < 0.2 * (u[:2] @ u[:2])
    freed = c.solve(u, p, v, d, safety=rows, detected=det, fov_yield=~det)
    np.testing.assert_allclose(freed.u, [0.0, 0.0, -1.5], atol=1e-6)  # turns as u* asks
    A, b, _ = rows
    assert np.all(A @ freed.u + b >= -1e-9)  # the collision rows still hold
    assert freed.kappa.shape == (3, 4) and freed.kappa.max() == 0.0
    # no neighbour allowed to yield: the pinned solution
    none = c.solve(u, p, v, d, safety=rows, detected=det, fov_yield=np.zeros(3, bool))
    np.testing.assert_array_equal(none.u, pinned.u)
    # not stalled (u* already met): nothing changes
    easy = np.array([0.5, 0.0, 0.0])
    a = c.solve(easy, p, v, d, safety=rows, detected=det)
    b_ = c.solve(easy, p, v, d, safety=rows, detected=det, fov_yield=~det)
    np.testing.assert_array_equal(a.u, b_.u)


def test_lost_rows_that_yielded_keep_yielding_while_u_star_translates():
    """The latch (``lost_fov_yield_latch``): the pinned crossing robot with its collision
    rows opened, so it keeps u*'s translation and is not stalled. Unlatched, the lost
    neighbours' FoV rows hold its yaw rate near 0; latched (they yielded at the previous
    step), they yield again and the robot turns as u* asks."""
    cfg, u, p, v, d, (A, _, kind) = _pinned_crossing_robot()
    rows = (A, np.array([1.0, 1.0, 1.0]), kind)  # translation free
    det = np.zeros(3, dtype=bool)
    c = FovCbfController(cfg, ControllerParams())
    free = c.solve(u, p, v, d, safety=rows, detected=det, fov_yield=~det)
    assert free.u[:2] @ u[:2] > 0.9 * (u[:2] @ u[:2])  # not stalled
    assert abs(free.u[2]) < 0.1 and not free.yielded  # the lost rows hold ω
    held = c.solve(u, p, v, d, safety=rows, detected=det, fov_yield=~det, yield_latched=True)
    assert held.yielded
    np.testing.assert_allclose(held.u[2], -1.5)
    np.testing.assert_allclose(held.u[:2], free.u[:2], atol=1e-9)
    assert np.all(A @ held.u + rows[1] >= -1e-9)
    # the stall test itself sets the flag the pipeline passes back
    pinned = c.solve(u, p, v, d, safety=(A, np.array([0.0, 0.0, 0.3]), kind), detected=det,
                     fov_yield=~det)  # fmt: skip
    assert pinned.yielded
    # the latch off: as unlatched
    off = FovCbfController(cfg, ControllerParams(lost_fov_yield_latch=False))
    r = off.solve(u, p, v, d, safety=rows, detected=det, fov_yield=~det, yield_latched=True)
    np.testing.assert_array_equal(r.u, free.u)
    assert not r.yielded
    # u* without translation (arrived): the latch ends
    still = np.array([0.0, 0.0, -1.5])
    a = c.solve(still, p, v, d, safety=rows, detected=det, fov_yield=~det)
    b = c.solve(still, p, v, d, safety=rows, detected=det, fov_yield=~det, yield_latched=True)
    np.testing.assert_array_equal(a.u, b.u)
    assert not b.yielded
    # no lost neighbour: nothing to yield
    r = c.solve(u, p, v, d, safety=rows, detected=det, fov_yield=det, yield_latched=True)
    np.testing.assert_array_equal(r.u, free.u)


def test_a_glance_leaves_the_fov_rows_out_and_keeps_the_collision_rows():
    """``glance`` (the pipeline's look before the leap with ``look_yields_fov``): a
    neighbour 2.5 m away at the right edge of the view (−55°, d = 0, so its FoV rows are
    hard) forbids turning left at ω_max; the glance turns anyway. Its collision rows stay:
    driving at it is still stopped at D_s."""
    ctrl = FovCbfController(CFG, ControllerParams())
    a = math.radians(-55.0)
    p = np.array([[2.5 * math.cos(a), 2.5 * math.sin(a)]])
    v, d = np.zeros((1, 2)), np.zeros(1)
    turn = np.array([0.0, 0.0, CFG.omega_max_radps])
    held = ctrl.solve(turn, p, v, d)
    assert held.u[2] < 0.5 * CFG.omega_max_radps and held.intervened
    looked = ctrl.solve(turn, p, v, d, glance=True)
    assert looked.u[2] == pytest.approx(CFG.omega_max_radps) and not looked.intervened
    charge = np.array([*(CFG.v_max_mps * p[0] / np.linalg.norm(p[0])), CFG.omega_max_radps])
    res = ctrl.solve(charge, p, v, d, glance=True)
    # the closing speed allowed keeps the next sample at or beyond D_s
    closing = float(res.u[:2] @ p[0]) / float(np.linalg.norm(p[0]))
    assert closing * CFG.dt_s <= 2.5 - CFG.safety_distance_m + 1e-6
    assert res.u[2] == pytest.approx(CFG.omega_max_radps, abs=1e-6)


@pytest.mark.parametrize("controller", ["loop", "batched"])
def test_yield_resolve_skipped_by_the_bound_gives_the_same_actions(monkeypatch, controller):
    """The lost rows' re-solve is skipped when the cascade's bound shows it cannot halve
    the cost (``QPResult.level_start_cost``, ``BatchQPResult.level_start_cost``): a pfcbf
    team (N = 24, 40 m arena, seed 0, 120 steps) acts exactly as with every re-solve
    done, with fewer hierarchy solves (measured, loop: 4,526 against 5,223), in the
    per-robot and in the batched controller."""
    from fov_marl.baselines import make_policy
    from fov_marl.control import batch_qp as bqp_mod
    from fov_marl.control import batched as batched_mod
    from fov_marl.control import controller as ctrl_mod
    from fov_marl.envs import fov_coverage_v0

    solves = []
    if controller == "loop":
        solve = FovCbfController._qp_solve

        def counted(self, *args):
            solves.append(1)
            return solve(self, *args)

        monkeypatch.setattr(FovCbfController, "_qp_solve", counted)
    else:  # robots' hierarchies solved
        bsolve = bqp_mod.BatchHierarchicalQP.solve

        def bcounted(self, A, *args, **kw):
            solves.append(A.shape[0])
            return bsolve(self, A, *args, **kw)

        monkeypatch.setattr(bqp_mod.BatchHierarchicalQP, "solve", bcounted)

    def episode():
        solves.clear()
        env = fov_coverage_v0.parallel_env(n_agents=24, max_cycles=120)
        pol = make_policy("pfcbf", env, controller=controller)
        obs, _ = env.reset(seed=0)
        pol.reset(seed=0)
        acts = []
        while env.agents:
            a = pol.act(obs)
            acts.append(np.stack([a[k] for k in env.possible_agents]))
            obs, *_ = env.step(a)
        return np.asarray(acts), sum(solves)

    fast, n_fast = episode()
    monkeypatch.setattr(ctrl_mod, "_YIELD_BOUND_TOL", math.inf)  # never skip
    monkeypatch.setattr(batched_mod, "_YIELD_BOUND_TOL", math.inf)
    slow, n_slow = episode()
    if controller == "loop":
        np.testing.assert_array_equal(fast, slow)
    else:  # the re-solve's batch (and so its padding) differs: round-off of 1e-22 m/s
        np.testing.assert_allclose(fast, slow, rtol=0.0, atol=1e-12)
    assert n_fast < 0.95 * n_slow, (n_fast, n_slow)


def _keep_right_case():
    """u* = 0.5 m/s forward, one collision row ``vx ≤ 0.15`` (binding): the solution
    keeps 0.3 of u*'s progress, between the stall test's 0.2 and the release's 0.5."""
    cfg = make_config()
    u = np.array([0.5, 0.0, 0.0])
    none2 = np.zeros((0, 2))
    rows = (np.array([[-1.0, 0.0, 0.0]]), np.array([0.15]), np.zeros(1, np.int8))
    return cfg, u, (none2, none2, np.zeros(0)), rows


def test_keep_right_has_hysteresis():
    """``deadlock_release``: a robot that kept right at the previous step keeps right
    until its solution for u* keeps half of u*'s progress; a first keep-right needs
    less than a fifth. Without it a robot near the threshold kept right on alternate
    steps and vx flipped sign (pfcbf, seed 5, robot 0, steps 758-764)."""
    cfg, u, (p, v, d), rows = _keep_right_case()
    c = FovCbfController(cfg, ControllerParams())
    fresh = c.solve(u, p, v, d, safety=rows)
    np.testing.assert_allclose(fresh.u, [0.15, 0.0, 0.0], atol=1e-6)  # 0.3 of u*: not stalled
    assert not fresh.unblocked
    held = c.solve(u, p, v, d, safety=rows, unblock_latched=True)
    assert held.unblocked
    assert held.u[1] < -0.3  # turned right (−60°), the row still holds
    assert held.u[0] <= 0.15 + 1e-6
    # a first keep-right still needs the stall test: a tighter row (0.05 of u*)
    tight = (rows[0], np.array([0.01]), rows[2])
    first = c.solve(u, p, v, d, safety=tight)
    assert first.unblocked and first.u[1] < -0.3
    # no hysteresis (release = the stall test's 0.2): latched is as unlatched
    off = FovCbfController(cfg, ControllerParams(deadlock_release=0.2))
    r = off.solve(u, p, v, d, safety=rows, unblock_latched=True)
    np.testing.assert_array_equal(r.u, fresh.u)
    assert not r.unblocked
    # u* that no longer translates ends it
    still = np.array([0.04, 0.0, 0.0])
    r = c.solve(still, p, v, d, safety=rows, unblock_latched=True)
    assert not r.unblocked
    # released once the solution keeps half of u*'s progress
    loose = (rows[0], np.array([0.3]), rows[2])
    r = c.solve(u, p, v, d, safety=loose, unblock_latched=True)
    assert not r.unblocked
    np.testing.assert_allclose(r.u, [0.3, 0.0, 0.0], atol=1e-6)


# ---------------------------------------------------------------- red team 8: bad input
def _one_neighbour_ahead():
    cfg = make_config(scenario="coverage", n_agents=2)
    p = np.array([[1.5, 0.0]])
    return cfg, p, np.zeros((1, 2)), np.array([1.0])


@pytest.mark.parametrize("b_bad", [np.nan, -np.inf])
def test_a_non_finite_collision_row_is_invalid_input_not_dropped(b_bad):
    """A NaN (or −inf) collision row given through ``safety=`` used to be dropped: the
    robot drove at full speed at the neighbour it guarded ("unconstrained"). It is now
    the invalid-input fallback (u = 0), in both controllers; b = +inf stays a row that
    never binds."""
    from fov_marl.control.batched import BatchedFovCbfController

    cfg, p, v, d = _one_neighbour_ahead()
    u_star = np.array([1.0, 0.0, 0.0])
    A, kind = np.array([[-1.0, 0.0, 0.0]]), np.zeros(1, dtype=np.int8)
    ctl = FovCbfController(cfg)
    held = ctl.solve(u_star, p, v, d, safety=(A, np.array([0.0]), kind))
    assert held.status == "solved" and held.u[0] <= 1e-9
    bad = ctl.solve(u_star, p, v, d, safety=(A, np.array([b_bad]), kind))
    assert bad.status == "invalid_input" and bad.fallback
    np.testing.assert_array_equal(bad.u, 0.0)
    nan_a = ctl.solve(u_star, p, v, d, safety=(A * np.nan, np.array([0.0]), kind))
    assert nan_a.status == "invalid_input"
    free = ctl.solve(u_star, p, v, d, safety=(A, np.array([np.inf]), kind))
    assert free.status == "unconstrained"
    # the batched controller: only the robot with the bad row falls back
    bat = BatchedFovCbfController(cfg)
    b2 = np.array([[0.0], [b_bad]])
    res = bat.solve(
        np.tile(u_star, (2, 1)), np.tile(p, (2, 1, 1)), np.zeros((2, 1, 2)), np.ones((2, 1)),
        safety=(np.tile(A, (2, 1, 1)), b2, np.zeros((2, 1), dtype=np.int8)),
    )  # fmt: skip
    assert list(res.status_names) == ["solved", "invalid_input"]
    np.testing.assert_array_equal(res.u[1], 0.0)


def test_controller_arguments_are_checked():
    cfg, p, v, d = _one_neighbour_ahead()
    with pytest.raises(ValueError, match="config must be a ScenarioConfig"):
        FovCbfController(None)
    assert FovCbfController(cfg, {"omega_weight": 2.0}).params.omega_weight == 2.0
    with pytest.raises(ValueError, match="params fields"):
        FovCbfController(cfg, {"no_such_field": 1})
    ctl = FovCbfController(cfg)
    u = np.array([1.0, 0.0, 0.0])
    for name in ("detected", "fov_yield", "priority_bonus"):
        with pytest.raises(ValueError, match=rf"{name} must have shape \(1,\)"):
            ctl.solve(u, p, v, d, **{name: [True, False]})
    with pytest.raises(ValueError, match="safety must be a SafetyRows or a tuple"):
        ctl.solve(u, p, v, d, safety=(np.zeros((1, 3)), np.zeros(1)))
    with pytest.raises(ValueError, match="safety A must be a real array"):
        ctl.solve(u, p, v, d, safety=(None, None, None))
