"""Hierarchical QP (Eq. 18-19): projection, least-distance solver, cascade, final QP, failures."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.optimize import minimize

from fov_marl.control.qp import (
    HierarchicalQP,
    least_distance,
    polygon_normals,
    project_to_admissible,
)

V, W, NPOLY = 1.0, 1.5, 16
APOTHEM = V * math.cos(math.pi / NPOLY)
BACKENDS = ("nnls", "osqp")


def _adm_constraints():
    """Admissible set as scipy 'ineq' constraints (fun(u) >= 0)."""
    nrm = polygon_normals(NPOLY)
    return [
        {"type": "ineq", "fun": lambda u: APOTHEM - nrm @ u[:2],
         "jac": lambda u: -np.c_[nrm, np.zeros(NPOLY)]},
        {"type": "ineq", "fun": lambda u: np.array([W - u[2], W + u[2]]),
         "jac": lambda u: np.array([[0, 0, -1.0], [0, 0, 1.0]])},
    ]  # fmt: skip


def _slsqp_projection(u_star, A, lo):
    """Reference for Eq. 19: min ½‖u − u*‖² s.t. A u ≥ lo, admissible."""
    cons = _adm_constraints()
    if len(lo):
        cons.append({"type": "ineq", "fun": lambda u: A @ u - lo, "jac": lambda u: A})
    x0 = project_to_admissible(u_star, V, W, NPOLY)
    res = minimize(lambda u: 0.5 * np.sum((u - u_star) ** 2), x0, jac=lambda u: u - u_star,
                   constraints=cons, method="SLSQP",
                   options={"ftol": 1e-14, "maxiter": 500})  # fmt: skip
    return res.x


def _slsqp_projection_ok(u_star, A, lo):
    """SLSQP projection and whether it found a feasible point (≤ 1e-8)."""
    u = _slsqp_projection(u_star, A, lo)
    nrm = polygon_normals(NPOLY)
    ok = (A @ u - lo).min(initial=0.0) >= -1e-8 and np.all(nrm @ u[:2] <= APOTHEM + 1e-8)
    return u, bool(ok and abs(u[2]) <= W + 1e-8)


def _slsqp_cascade(A, b, level, u_star, reg):
    """Independent reference of the whole hierarchy with scipy SLSQP.

    Per level: if the level can be met with κ = 0 (projection with its rows hard is
    feasible) κ* = 0, else min ‖κ‖² + ρ‖u − u*‖² (Eq. 18); finally the projection of
    u* with every κ* fixed (Eq. 19).
    """
    kappa = np.zeros(len(b))
    fixed = np.zeros(len(b), dtype=bool)
    u_c = project_to_admissible(u_star, V, W, NPOLY)
    for lev in np.unique(level):
        rows = np.flatnonzero(level == lev)
        fx = np.flatnonzero(fixed)
        idx = np.concatenate([fx, rows])
        lo = np.concatenate([-b[fx] - kappa[fx] - 1e-7, -b[rows]])
        u_p, ok = _slsqp_projection_ok(u_star, A[idx], lo)
        if ok:
            u_c = u_p
        else:

            def obj(x):
                return np.sum(x[3:] ** 2) + reg * np.sum((x[:3] - u_star) ** 2)

            def jac(x):
                return np.concatenate([2 * reg * (x[:3] - u_star), 2 * x[3:]])

            cons = [
                {"type": "ineq", "fun": lambda x, c=c: c["fun"](x[:3])} for c in _adm_constraints()
            ]
            cons.append({"type": "ineq", "fun": lambda x, r=rows: A[r] @ x[:3] + b[r] + x[3:]})
            if fx.size:
                kfix = kappa[fx].copy()
                cons.append(
                    {
                        "type": "ineq",
                        "fun": lambda x, f=fx, k=kfix: A[f] @ x[:3] + b[f] + k + 1e-7,
                    }
                )
            x0 = np.concatenate([u_c, np.maximum(0, -(A[rows] @ u_c + b[rows]))])
            res = minimize(obj, x0, jac=jac, constraints=cons, method="SLSQP",
                           options={"ftol": 1e-15, "maxiter": 1000})  # fmt: skip
            u_c = res.x[:3]
        kappa[rows] = np.maximum(0.0, -(A[rows] @ u_c + b[rows]))
        fixed[rows] = True
    u = _slsqp_projection(u_star, A, -b - kappa - 1e-7)
    return u, kappa


def _random_rows(rng, R, feasible):
    A = rng.normal(size=(R, 3))
    A /= (np.hypot(A[:, 0], A[:, 1]) * V + np.abs(A[:, 2]) * W)[:, None]  # normalised rows
    if feasible:
        u0 = project_to_admissible(rng.uniform(-1, 1, 3) * [0.6, 0.6, 1.0], V, W, NPOLY)
        b = -A @ u0 + rng.uniform(0.0, 0.3, R)
    else:
        b = rng.uniform(-1.2, 0.5, R)
    return A, b


# --------------------------------------------------------------------------- projection
@given(st.floats(-3, 3), st.floats(-3, 3), st.floats(-4, 4))
def test_projection_onto_admissible_set_matches_slsqp(vx, vy, w):
    u = np.array([vx, vy, w])
    p = project_to_admissible(u, V, W, NPOLY)
    ref = _slsqp_projection(u, np.zeros((0, 3)), np.zeros(0))
    np.testing.assert_allclose(p, ref, atol=1e-6)
    assert np.all(polygon_normals(NPOLY) @ p[:2] <= APOTHEM + 1e-12)
    assert math.hypot(p[0], p[1]) <= V + 1e-12
    np.testing.assert_allclose(project_to_admissible(p, V, W, NPOLY), p)


# --------------------------------------------------------------------------- LDP
@pytest.mark.parametrize("seed", range(20))
def test_least_distance_matches_slsqp(seed):
    rng = np.random.default_rng(seed)
    n, m = rng.integers(2, 6), rng.integers(1, 25)
    G = rng.normal(size=(m, n))
    y0 = rng.normal(size=n)
    h = G @ y0 - rng.uniform(0, 1, m)  # feasible: y0 satisfies it
    y = least_distance(G, h)
    assert y is not None
    assert np.all(G @ y >= h - 1e-9)
    ref = minimize(lambda x: x @ x, y0, jac=lambda x: 2 * x, method="SLSQP",
                   constraints=[{"type": "ineq", "fun": lambda x: G @ x - h, "jac": lambda x: G}],
                   options={"ftol": 1e-15}).x  # fmt: skip
    np.testing.assert_allclose(y, ref, atol=1e-6)


def test_least_distance_reports_infeasible():
    G = np.array([[1.0, 0.0], [-1.0, 0.0]])
    assert least_distance(G, np.array([1.0, 0.0])) is None  # x ≥ 1 and x ≤ 0
    np.testing.assert_allclose(least_distance(G, np.array([1.0, -2.0])), [1.0, 0.0])


# --------------------------------------------------------------------------- final QP
@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed", range(25))
def test_final_qp_matches_scipy_on_feasible_instances(backend, seed):
    rng = np.random.default_rng(seed)
    R = int(rng.integers(1, 9))
    A, b = _random_rows(rng, R, feasible=True)
    u_star = rng.uniform(-1.5, 1.5, 3) * [1, 1, 1.5]
    qp = HierarchicalQP(V, W, NPOLY, backend=backend, eps=1e-6)
    res = qp.solve(A, b, np.ones(R, dtype=int), u_star)
    ref = _slsqp_projection(u_star, A, -b)
    tol = 1e-5 if backend == "nnls" else 2e-3
    np.testing.assert_allclose(res.u, ref, atol=tol)
    assert res.status in ("unconstrained", "solved") and not res.fallback
    assert np.all(A @ res.u + b >= -tol)


@pytest.mark.parametrize("seed", range(40))
def test_cascade_matches_independent_scipy_hierarchy(seed):
    """κ* per level and the final u agree with an SLSQP implementation of Eq. 18-19."""
    rng = np.random.default_rng(100 + seed)
    R = int(rng.integers(2, 9))
    A, b = _random_rows(rng, R, feasible=False)
    level = rng.integers(0, 4, R)
    u_star = rng.uniform(-1.5, 1.5, 3) * [1, 1, 1.5]
    qp = HierarchicalQP(V, W, NPOLY, reg=1e-4)
    res = qp.solve(A, b, level, u_star)
    u_ref, k_ref = _slsqp_cascade(A, b, level, u_star, 1e-4)
    assert not res.fallback
    np.testing.assert_allclose(res.kappa, k_ref, atol=1e-3)
    np.testing.assert_allclose(res.u, u_ref, atol=3e-3)


@pytest.mark.parametrize("seed", range(40))
def test_lower_levels_never_increase_a_higher_levels_violation(seed):
    """Strict priority: appending lower-priority rows leaves κ* of the higher levels alone."""
    rng = np.random.default_rng(200 + seed)
    R1, R2 = int(rng.integers(1, 5)), int(rng.integers(1, 6))
    A1, b1 = _random_rows(rng, R1, feasible=False)
    A2, b2 = _random_rows(rng, R2, feasible=False)
    lev1 = rng.integers(0, 3, R1)
    u_star = rng.uniform(-1, 1, 3)
    tol = 1e-5
    alone = HierarchicalQP(V, W, NPOLY).solve(A1, b1, lev1, u_star)
    both = HierarchicalQP(V, W, NPOLY).solve(
        np.vstack([A1, A2]),
        np.concatenate([b1, b2]),
        np.concatenate([lev1, 3 + rng.integers(0, 3, R2)]),
        u_star,
    )  # fmt: skip
    assert not alone.fallback and not both.fallback
    np.testing.assert_allclose(both.kappa[:R1], alone.kappa[:R1], atol=tol)
    # the final input still meets every higher row with its κ*
    assert np.all(A1 @ both.u + b1 + alone.kappa >= -tol)


@pytest.mark.parametrize("seed", range(40))
def test_level_start_cost_bounds_any_resolve_that_keeps_the_higher_levels(seed):
    """``QPResult.level_start_cost[k]`` (nnls): the hierarchy solved again without any
    subset of the rows of level ``level_values[k]`` and below (the lost FoV rows' yield)
    lands no closer to u* than it, up to the fixing tolerance (1e-4; measured at most
    1.1e-4 over 3,000 random hierarchies; the controller's skip margin is 1e-3)."""
    rng = np.random.default_rng(900 + seed)
    R = int(rng.integers(2, 12))
    A, b = _random_rows(rng, R, feasible=bool(rng.random() < 0.3))
    level = rng.integers(0, 5, R)
    u_star = rng.uniform(-1, 1, 3)
    qp = HierarchicalQP(V, W, NPOLY)
    res = qp.solve(A, b, level, u_star)
    assert res.level_values.shape == res.level_start_cost.shape
    assert np.all(np.diff(res.level_values) > 0)
    for k, lv in enumerate(res.level_values.tolist()):
        drop = (level >= lv) & (rng.random(R) < 0.6)
        alt = qp.solve(A[~drop], b[~drop], level[~drop], u_star)
        if alt.fallback or np.isnan(res.level_start_cost[k]):
            continue
        cost = float((alt.u - u_star) @ (alt.u - u_star))
        assert cost >= res.level_start_cost[k] - 2e-4, (k, cost, res.level_start_cost)
    # the candidate only moves away from u* level by level, and ends at the solution
    c = res.level_start_cost[~np.isnan(res.level_start_cost)]
    assert np.all(np.diff(c) >= -2e-4)
    if not res.fallback:
        assert float((res.u - u_star) @ (res.u - u_star)) >= c.max(initial=0.0) - 2e-4


def test_level_start_cost_discriminates():
    """The bound is not trivially 0: a level that pulls the input away from u* raises the
    start cost of the next one."""
    A = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    b = np.array([-0.5, 0.0])  # vx >= 0.5 (level 0), vy >= 0 (level 1)
    res = HierarchicalQP(V, W, NPOLY).solve(A, b, np.array([0, 1]), np.array([0.0, 0.0, 0.0]))
    np.testing.assert_array_equal(res.level_values, [0, 1])
    np.testing.assert_allclose(res.level_start_cost, [0.0, 0.25], atol=1e-6)


def test_priority_order_decides_who_is_served():
    """Two conflicting rows: u_x ≥ 0.5 and u_x ≤ −0.5; the higher level wins."""
    A = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    b = np.array([-0.5, -0.5])
    u_star = np.array([0.0, 0.3, 0.2])
    qp = HierarchicalQP(V, W, NPOLY)
    r1 = qp.solve(A, b, np.array([0, 1]), u_star)
    assert r1.u[0] == pytest.approx(0.5, abs=1e-6)
    np.testing.assert_allclose(r1.kappa, [0.0, 1.0], atol=1e-6)
    np.testing.assert_allclose(r1.u[1:], u_star[1:], atol=1e-6)  # free directions follow u*
    r2 = qp.solve(A, b, np.array([1, 0]), u_star)
    assert r2.u[0] == pytest.approx(-0.5, abs=1e-6)
    np.testing.assert_allclose(r2.kappa, [1.0, 0.0], atol=1e-6)
    r3 = qp.solve(A, b, np.array([0, 0]), u_star)  # same level: split the violation
    np.testing.assert_allclose(r3.kappa, [0.5, 0.5], atol=1e-4)
    assert r1.status == r2.status == r3.status == "relaxed"


@pytest.mark.parametrize("backend", BACKENDS)
def test_infeasible_hard_rows_brake_without_raising(backend):
    A = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    b = np.array([-0.5, -0.5, 0.0])
    qp = HierarchicalQP(V, W, NPOLY, backend=backend)
    res = qp.solve(A, b, np.array([-1, -1, 2]), np.array([0.3, 0.1, 0.2]))
    assert res.status == "qp_failed" and res.fallback
    np.testing.assert_array_equal(res.u, np.zeros(3))


@pytest.mark.parametrize("bad", ["A", "b", "u"])
def test_non_finite_inputs_give_invalid_input_fallback(bad):
    A = np.eye(3)
    b = np.zeros(3)
    u = np.zeros(3)
    {"A": A, "b": b, "u": u}[bad][0] = np.nan
    res = HierarchicalQP(V, W, NPOLY).solve(A, b, np.zeros(3, dtype=int), u)
    assert res.status == "invalid_input" and res.fallback
    np.testing.assert_array_equal(res.u, np.zeros(3))


def test_shape_mismatch_raises_value_error():
    with pytest.raises(ValueError, match="must agree"):
        HierarchicalQP(V, W, NPOLY).solve(np.zeros((2, 3)), np.zeros(3), np.zeros(3), np.zeros(3))


def test_unconstrained_shortcut_returns_projected_u_star_without_qp():
    A = np.array([[0.1, 0.0, 0.0]])
    b = np.array([5.0])
    u_star = np.array([2.0, 0.0, 3.0])
    res = HierarchicalQP(V, W, NPOLY).solve(A, b, np.zeros(1, dtype=int), u_star)
    assert res.status == "unconstrained" and res.n_qp == 0
    np.testing.assert_allclose(res.u, project_to_admissible(u_star, V, W, NPOLY))


def test_osqp_patterns_grow_beyond_capacity():
    rng = np.random.default_rng(5)
    A, b = _random_rows(rng, 40, feasible=True)
    qp = HierarchicalQP(V, W, NPOLY, backend="osqp", capacity=4, eps=1e-6)
    u_star = np.array([1.0, -1.0, 1.5])
    res = qp.solve(A, b, np.zeros(40, dtype=int), u_star)
    assert qp.n_rebuilds == 1 and qp.capacity >= 40
    np.testing.assert_allclose(res.u, _slsqp_projection(u_star, A, -b), atol=2e-3)
    res2 = qp.solve(A[:3], b[:3], np.zeros(3, dtype=int), u_star)  # padded rows stay inert
    np.testing.assert_allclose(res2.u, _slsqp_projection(u_star, A[:3], -b[:3]), atol=2e-3)


def test_constructor_validation():
    with pytest.raises(ValueError, match="backend"):
        HierarchicalQP(V, W, backend="x")
    with pytest.raises(ValueError, match="n_polygon"):
        HierarchicalQP(V, W, n_polygon=3)
    with pytest.raises(ValueError, match="v_max"):
        HierarchicalQP(0.0, W)


@pytest.mark.parametrize("seed", range(10))
def test_osqp_backend_agrees_with_nnls_on_hierarchies(seed):
    """The OSQP backend (kept for comparison) solves the same hierarchy, less tightly."""
    rng = np.random.default_rng(300 + seed)
    R = int(rng.integers(2, 7))
    A, b = _random_rows(rng, R, feasible=False)
    level = rng.integers(0, 3, R)
    u_star = rng.uniform(-1.0, 1.0, 3)
    r1 = HierarchicalQP(V, W, NPOLY).solve(A, b, level, u_star)
    r2 = HierarchicalQP(V, W, NPOLY, backend="osqp", eps=1e-6).solve(A, b, level, u_star)
    assert np.all(np.isfinite(r2.u))
    if r2.status != "degraded":
        np.testing.assert_allclose(r2.kappa, r1.kappa, atol=5e-2)
        assert np.all(A @ r2.u + b + r2.kappa >= -1e-3)  # its u meets every row with its κ*


@pytest.mark.parametrize("jitter", [0.0, 1e-8])
def test_duplicated_rows_across_levels_are_one_constraint(jitter):
    """Unseen neighbours whose estimates converged give (near-)identical rows: no degeneracy."""
    rng = np.random.default_rng(7)
    A1, b1 = _random_rows(rng, 2, feasible=False)
    b1 = b1 - 1.5  # certainly infeasible: step 3 with a pinned candidate
    A = np.vstack([A1, A1 + jitter, A1 - jitter, A1])
    b = np.concatenate([b1, b1 + jitter, b1, b1])
    level = np.array([1, 1, 2, 2, 3, 3, 3, 3])
    res = HierarchicalQP(V, W, NPOLY).solve(A, b, level, np.array([0.3, -0.2, 0.5]))
    alone = HierarchicalQP(V, W, NPOLY).solve(A1, b1, np.array([1, 1]), np.array([0.3, -0.2, 0.5]))
    assert not res.fallback and res.status == "relaxed"
    np.testing.assert_allclose(res.u, alone.u, atol=1e-6)
    np.testing.assert_allclose(res.kappa, np.tile(alone.kappa, 4), atol=1e-6)


def test_random_dense_hierarchies_never_fall_back():
    """Many rows and levels, conflicting: the nnls backend always returns a verified answer."""
    rng = np.random.default_rng(11)
    qp = HierarchicalQP(V, W, NPOLY)
    for _ in range(300):
        R = int(rng.integers(1, 40))
        A, b = _random_rows(rng, R, feasible=bool(rng.integers(0, 2)))
        res = qp.solve(A, b, rng.integers(0, 6, R), rng.uniform(-2, 2, 3))
        assert not res.fallback, res.status
        assert np.all(A @ res.u + b + res.kappa >= -1e-4)


@given(st.integers(0, 10_000), st.integers(1, 60))
def test_direct_nnls_gives_the_public_functions_bits(seed, m):
    """The compiled NNLS called without SciPy's wrapper (where this SciPy has it) returns
    exactly what ``scipy.optimize.nnls`` returns on the least-distance programs the
    cascade builds (``(4, m)`` and ``(4 + k, m)``), so the speed-up changes no number."""
    from scipy.optimize import nnls

    from fov_marl.control import qp

    rng = np.random.default_rng(seed)
    E = rng.normal(size=(4 + int(rng.integers(0, 4)), m))
    f = np.zeros(E.shape[0])
    f[-1] = 1.0
    maxiter = 20 * (m + E.shape[0])
    z, r = qp._nnls(E.copy(), f.copy(), maxiter)
    z_ref, r_ref = nnls(E, f, maxiter=maxiter)
    assert np.array_equal(z, z_ref) and r == r_ref


def test_least_distance_rejects_non_finite_data():
    with pytest.raises(ValueError, match="finite"):
        least_distance(np.array([[1.0, np.nan]]), np.array([0.5]))


@given(st.integers(0, 10_000), st.integers(0, 50), st.integers(0, 12))
def test_duplicate_rows_screen_matches_the_dense_comparison(seed, R, n_copies):
    """The screened duplicate test marks exactly the rows the dense ``(R, R, 4)``
    comparison marks, on rows with repeats, near-repeats (inside and just outside the
    tolerance) and ties in single coefficients (b = 0, shared columns), as the cascade's
    rows have."""
    from fov_marl.control.qp import _DUP_TOL, _duplicate_rows_dense, duplicate_rows

    rng = np.random.default_rng(seed)
    A = rng.normal(size=(R, 3)).round(int(rng.integers(0, 3)))
    b = rng.choice([0.0, -0.8, 0.3], size=R) if rng.random() < 0.5 else rng.normal(size=R)
    if R:
        src = rng.integers(0, R, n_copies)
        step = rng.choice([0.0, 0.5 * _DUP_TOL, 0.99 * _DUP_TOL, 1.01 * _DUP_TOL, 3 * _DUP_TOL])
        A = np.vstack([A, A[src] + step * rng.choice([-1.0, 1.0], (n_copies, 3))])
        b = np.concatenate([b, b[src] + step * rng.choice([-1.0, 1.0], n_copies)])
        perm = rng.permutation(b.size)
        A, b = A[perm], b[perm]
    assert np.array_equal(duplicate_rows(A, b), _duplicate_rows_dense(A, b))


def test_projection_and_hierarchy_arguments_are_checked():
    """Before: NaN gave an unrelated message, inf a NaN output, n = 0 a
    ZeroDivisionError, v_max < 0 a projection the wrong way, n_polygon = 4.5 was
    truncated, reg < 0 a math domain error and level NaN a hard row."""
    from fov_marl.control.qp import HierarchicalQP

    for u in ([np.nan, 0.0, 0.0], [np.inf, np.inf, 0.0]):
        with pytest.raises(ValueError, match="u must be a finite"):
            project_to_admissible(np.array(u), 1.0, 1.0, 16)
    with pytest.raises(ValueError, match="n must be an integer >= 3"):
        project_to_admissible(np.array([1.0, 0.0, 0.0]), 1.0, 1.0, 0)
    with pytest.raises(ValueError, match="v_max and omega_max"):
        project_to_admissible(np.array([1.0, 0.0, 0.0]), -1.0, 1.0, 16)
    for kw, name in (
        ({"n_polygon": 4.5}, "n_polygon"),
        ({"n_polygon": "8"}, "n_polygon"),
        ({"reg": -1.0}, "reg"),
        ({"eps": 0.0}, "eps"),
        ({"max_iter": 0}, "max_iter"),
    ):
        with pytest.raises(ValueError, match=name):
            HierarchicalQP(1.0, 1.0, **kw)
    with pytest.raises(ValueError, match="v_max"):
        HierarchicalQP(math.nan, 1.0)
    qp = HierarchicalQP(1.0, 1.0)
    A, b = np.array([[1.0, 0.0, 0.0]]), np.array([-0.5])
    for level in ([np.nan], [0.5], ["a"]):
        with pytest.raises(ValueError, match="level must hold integer priorities"):
            qp.solve(A, b, np.array(level), np.zeros(3))
    assert qp.solve(A, b, np.array([1.0]), np.zeros(3)).u[0] == pytest.approx(0.5)
