"""Batched exact solver (fov_marl.control.batch_qp) against the per-robot solver, OSQP and
a slow brute-force reference."""

from __future__ import annotations

import itertools

import numpy as np
import osqp
import pytest
import scipy.sparse as sp
from hypothesis import example, given, settings
from hypothesis import strategies as st

from fov_marl.control.batch_qp import (
    STATUS_CODES,
    BatchHierarchicalQP,
    batch_least_distance,
    batch_project_to_admissible,
)
from fov_marl.control.qp import HierarchicalQP, least_distance, project_to_admissible


def _brute_ldp(G: np.ndarray, h: np.ndarray) -> np.ndarray | None:
    """Obviously-correct reference: every active set of at most n independent rows; the
    feasible KKT point (multipliers ≥ 0) is the optimum. None if none is feasible."""
    m, n = G.shape
    best = None
    if np.all(h <= 1e-12):
        return np.zeros(n)
    for k in range(1, n + 1):
        for S in itertools.combinations(range(m), k):
            N = G[list(S)]
            gram = N @ N.T
            if np.linalg.matrix_rank(gram, tol=1e-10) < k:
                continue
            lam = np.linalg.solve(gram, h[list(S)])  # y = Nᵀ λ with N y = h_S
            if np.any(lam < -1e-9):
                continue
            y = N.T @ lam
            if np.all(G @ y >= h - 1e-7) and (best is None or y @ y < best @ best - 1e-12):
                best = y
    return best


def _osqp_ldp(G: np.ndarray, h: np.ndarray) -> np.ndarray | None:
    n = G.shape[1]
    prob = osqp.OSQP(algebra="builtin")
    prob.setup(
        sp.identity(n, format="csc"),
        np.zeros(n),
        sp.csc_matrix(G),
        h,
        np.full(h.shape, np.inf),
        eps_abs=1e-10,
        eps_rel=1e-10,
        max_iter=200000,
        polishing=True,
        verbose=False,
    )
    res = prob.solve(raise_error=False)
    if res.info.status not in ("solved", "solved inaccurate"):
        return None
    return np.asarray(res.x)


def _random_ldp(rng, R, m, n, feasible_frac=0.7):
    G = rng.normal(size=(R, m, n))
    y0 = rng.normal(size=(R, n)) * 2.0
    h = np.einsum("rmn,rn->rm", G, y0) - rng.exponential(1.0, (R, m))
    # some infeasible problems: a row and its negation both demanding a margin
    inf = (rng.random(R) > feasible_frac) & (m >= 2)
    if m >= 2:
        G[inf, 1] = -G[inf, 0]
        h[inf, 1] = -h[inf, 0] + 0.5
    return G, h, ~inf


def test_ldp_matches_brute_force_and_osqp():
    rng = np.random.default_rng(0)
    G, h, feas = _random_ldp(rng, 60, 7, 3)
    y, ok = batch_least_distance(G, h)
    np.testing.assert_array_equal(ok, feas)
    for r in range(60):
        ref = _brute_ldp(G[r], h[r])
        assert (ref is not None) == feas[r]
        if ref is None:
            continue
        np.testing.assert_allclose(y[r], ref, atol=1e-7)
        osq = _osqp_ldp(G[r], h[r])
        assert osq is not None
        np.testing.assert_allclose(y[r], osq, atol=1e-5)
        np.testing.assert_allclose(y[r], least_distance(G[r], h[r]), atol=1e-8)


@settings(max_examples=40)
@given(
    seed=st.integers(0, 2**31 - 1),
    m=st.integers(1, 12),
    n=st.integers(1, 6),
)
def test_ldp_property_matches_nnls_reduction(seed, m, n):
    rng = np.random.default_rng(seed)
    G, h, _ = _random_ldp(rng, 4, m, n)
    mask = rng.random((4, m)) < 0.8
    y, ok = batch_least_distance(G, h, mask)
    for r in range(4):
        ref = least_distance(G[r][mask[r]], h[r][mask[r]])
        assert ok[r] == (ref is not None)
        if ref is not None:
            np.testing.assert_allclose(y[r], ref, atol=1e-7)
            assert np.all(G[r][mask[r]] @ y[r] >= h[r][mask[r]] - 1e-9)


def test_ldp_degenerate_and_empty():
    # no rows, all rows satisfied at 0, parallel duplicate rows, n = 3 rows through a point
    y, ok = batch_least_distance(np.zeros((2, 0, 3)), np.zeros((2, 0)))
    assert ok.all() and not y.any()
    G = np.array([[[1.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]])
    h = np.array([[1.0, 1.0, 2.0, -1.0, -3.0]])
    y, ok = batch_least_distance(G, h)
    assert ok[0]
    np.testing.assert_allclose(y[0], [1.0, 0.0, 0.0], atol=1e-12)
    y, ok = batch_least_distance(G, -np.abs(h) - 1.0)  # 0 is feasible
    assert ok[0] and not y.any()


def test_project_to_admissible_batched_equals_scalar():
    rng = np.random.default_rng(1)
    u = rng.normal(size=(500, 3)) * [1.5, 1.5, 3.0]
    out = batch_project_to_admissible(u, 1.0, 1.5, 16)
    ref = np.stack([project_to_admissible(x, 1.0, 1.5, 16) for x in u])
    np.testing.assert_allclose(out, ref, atol=1e-14)


def _random_hierarchy(rng, R, K):
    A = rng.normal(size=(R, K, 3))
    A /= (np.hypot(A[..., 0], A[..., 1]) + 1.5 * np.abs(A[..., 2]))[..., None]
    b = rng.uniform(-1.5, 1.2, (R, K))
    level = rng.integers(0, 4, (R, K))
    level = np.where(rng.random((R, K)) < 0.1, -1, level)  # a few hard rows
    valid = rng.random((R, K)) < 0.75
    if K >= 2:  # duplicated rows (same or lower priority)
        dup = rng.random(R) < 0.2
        A[dup, 1], b[dup, 1] = A[dup, 0], b[dup, 0]
    u_star = rng.uniform(-1.2, 1.2, (R, 3)) * [1, 1, 1.5]
    return A, b, level, valid, u_star


def _check_against_scalar(A, b, level, valid, u_star, v_max=1.0, om=1.5, atol=1e-6):
    q = HierarchicalQP(v_max, om)
    res = BatchHierarchicalQP(v_max, om).solve(A, b, level, u_star, valid)
    names = res.status_names
    for r in range(A.shape[0]):
        v = valid[r]
        s = q.solve(A[r][v], b[r][v], level[r][v], u_star[r])
        np.testing.assert_allclose(res.u[r], s.u, atol=atol, err_msg=f"robot {r}")
        np.testing.assert_allclose(res.kappa[r][v], s.kappa, atol=atol)
        assert not res.kappa[r][~v].any()
        assert names[r] == s.status, r
        assert res.fallback[r] == s.fallback
        assert res.n_qp[r] == s.n_qp
        assert res.n_levels[r] == s.n_levels
        assert res.qp_status[r] == s.qp_status
    return names


def test_hierarchy_matches_per_robot_solver_random():
    rng = np.random.default_rng(2)
    names = _check_against_scalar(*_random_hierarchy(rng, 300, 10))
    # the cases of the cascade are all exercised
    for s in ("unconstrained", "solved", "relaxed", "qp_failed"):
        assert s in set(names), s


@settings(max_examples=30)
@given(seed=st.integers(0, 2**31 - 1), K=st.integers(0, 14))
@example(seed=1771, K=12)
@example(seed=391, K=14)
def test_hierarchy_property(seed, K):
    """Random hierarchies agree within ten times the cascade's check tolerance (1e-5,
    nnls ``tol_check``). Found by hypothesis: seed 1771, K = 12, robot 2, a relaxed
    four-level hierarchy on which the two solvers' round-off relaxations of the fixed
    rows (``tol_fix`` = 1e-7 per level) compound to 2.9e-6 in u and 2.2e-6 in κ*; same
    status and QP count. And seed 391, K = 14, robot 1: a relaxed hierarchy with a hard
    row violated by 4e-7 in both and rows on four levels, where the batched solver
    leaves levels 1 and 2 violated by 7e-6 and 1e-5 more than the scalar one: 1.5e-5 in
    u, 1.0e-5 in κ*, same status. The differences are round-off and depend on the BLAS
    kernels: with OpenBLAS's Haswell kernels (``OPENBLAS_CORETYPE=Haswell``, set on some
    machines of this project) that example differs by 4.8e-5 in u and 1.1e-5 in κ*, the
    largest over seeds 0-1999 (with the SkylakeX kernels 1.5e-5), hence 1e-4. The
    recorded pfcbf problems and the 300 random ones above still agree within 1e-6."""
    rng = np.random.default_rng(seed)
    _check_against_scalar(*_random_hierarchy(rng, 6, K), atol=1e-4)


def test_hierarchy_invalid_input_and_empty():
    rng = np.random.default_rng(3)
    A, b, level, valid, u_star = _random_hierarchy(rng, 4, 6)
    A[0, 0, 1] = np.nan
    valid[0, 0] = True
    u_star[1, 2] = np.inf
    valid[2] = False
    A[3, 5] = np.nan  # a NaN in a padding row is ignored
    valid[3, 5] = False
    res = BatchHierarchicalQP(1.0, 1.5).solve(A, b, level, u_star, valid)
    assert list(res.status_names[:3]) == ["invalid_input", "invalid_input", "unconstrained"]
    assert res.fallback[:2].all() and not res.u[:2].any()
    np.testing.assert_allclose(res.u[2], project_to_admissible(u_star[2], 1.0, 1.5, 16))
    assert res.status_names[3] != "invalid_input"
    with pytest.raises(ValueError, match="must agree"):
        BatchHierarchicalQP(1.0, 1.5).solve(A[:, :, :2], b, level, u_star)
    with pytest.raises(ValueError, match="v_max"):
        BatchHierarchicalQP(0.0, 1.5)


def test_hierarchy_matches_on_recorded_problems(recorded_problems):
    """The hierarchies of a pfcbf episode (rows as the controller builds them)."""
    A, b, level, valid, u_star = recorded_problems
    names = _check_against_scalar(A, b, level, valid, u_star)
    assert {"solved", "relaxed"} <= set(names)


@pytest.fixture(scope="module")
def recorded_problems():
    """Hierarchies captured from HierarchicalQP.solve during a short pfcbf episode."""
    return _record_problems()


def _record_problems():
    from fov_marl.baselines import make_policy
    from fov_marl.envs import fov_coverage_v0

    env = fov_coverage_v0.parallel_env(n_agents=8)
    obs, _ = env.reset(seed=3)
    pol = make_policy("pfcbf", env, controller="loop")
    pol.reset(seed=3)
    calls = []
    for ctrl in pol.pipeline.controllers:
        orig = ctrl.qp.solve

        def rec(A, b, level, u_star, _orig=orig):
            calls.append((np.array(A), np.array(b), np.array(level), np.array(u_star)))
            return _orig(A, b, level, u_star)

        ctrl.qp.solve = rec
    for _ in range(25):
        act = pol.act(obs)
        obs, *_ = env.step(act)
    assert len(calls) > 20
    K = max(c[1].shape[0] for c in calls)
    R = len(calls)
    A = np.zeros((R, K, 3))
    b = np.zeros((R, K))
    level = np.zeros((R, K), dtype=np.int64)
    valid = np.zeros((R, K), dtype=bool)
    u_star = np.zeros((R, 3))
    for r, (a_, b_, l_, u_) in enumerate(calls):
        k = b_.shape[0]
        A[r, :k], b[r, :k], level[r, :k], valid[r, :k], u_star[r] = a_, b_, l_, True, u_
    return A, b, level, valid, u_star


def test_status_codes_cover_qp_result_statuses():
    assert STATUS_CODES == (
        "unconstrained", "solved", "relaxed", "degraded", "invalid_input", "qp_failed"
    )  # fmt: skip


def test_hierarchy_matches_osqp_backend_on_recorded_problems(recorded_problems):
    """Against the OSQP backend (ADMM, eps 1e-6): where OSQP does not report a failure
    the inputs agree to its accuracy."""
    A, b, level, valid, u_star = recorded_problems
    res = BatchHierarchicalQP(1.0, 1.5).solve(A, b, level, u_star, valid)
    q = HierarchicalQP(1.0, 1.5, backend="osqp", eps=1e-8, max_iter=200000)
    compared = 0
    for r in range(A.shape[0]):
        v = valid[r]
        s = q.solve(A[r][v], b[r][v], level[r][v], u_star[r])
        if s.fallback or s.status != res.status_names[r]:
            continue  # OSQP's documented degraded / borderline solves
        compared += 1
        np.testing.assert_allclose(res.u[r], s.u, atol=1e-3, err_msg=f"problem {r}")
    assert compared >= 0.9 * A.shape[0]  # measured: 78 of 78, max |du| 2.3e-4


def test_same_rows_equals_its_reference():
    from fov_marl.control.batch_qp import _DUP_TOL, _same_rows, _same_rows_reference

    rng = np.random.default_rng(3)
    for R, K in [(1, 1), (5, 7), (40, 23), (0, 4)]:
        A = rng.normal(size=(R, K, 3))
        b = rng.normal(size=(R, K))
        if R and K > 4:  # exact, near (inside and outside the tolerance) duplicates
            A[:, 2], b[:, 2] = A[:, 1], b[:, 1]
            A[:, 3], b[:, 3] = A[:, 1] + 0.5 * _DUP_TOL, b[:, 1] - 0.9 * _DUP_TOL
            A[:, 4], b[:, 4] = A[:, 1], b[:, 1] + 2.0 * _DUP_TOL
        np.testing.assert_array_equal(_same_rows(A, b), _same_rows_reference(A, b))
