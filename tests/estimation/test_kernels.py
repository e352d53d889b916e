"""Kernels of the particle-filter bank against the geometry module and slow references."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from fov_marl.estimation import kernels as K
from fov_marl.geometry import body_to_world, in_fov, integrate_unicycle, world_to_body, wrap_angle

from .reference import allocate_reference, systematic_reference

finite = st.floats(-60.0, 60.0, allow_nan=False, allow_infinity=False)
points = hnp.arrays(np.float64, st.tuples(st.integers(1, 40), st.just(2)), elements=finite)


@settings(max_examples=200, deadline=None)
@given(
    p=points,
    fov_deg=st.sampled_from([1.0, 60.0, 90.0, 120.0, 179.0, 180.0, 181.0, 270.0, 359.0, 360.0])
    | st.floats(0.5, 360.0),
    range_m=st.floats(0.1, 50.0),
)
def test_in_fov_xy_matches_geometry(p, fov_deg, range_m):
    fov = math.radians(fov_deg)
    # include points exactly on the borders and at the origin
    half = 0.5 * fov
    border = range_m * np.array(
        [[math.cos(half), math.sin(half)], [math.cos(half), -math.sin(half)]]
    )
    p = np.concatenate([p, border, [[0.0, 0.0], [range_m, 0.0]]])
    np.testing.assert_array_equal(
        K.in_fov_xy(p[:, 0], p[:, 1], fov, range_m), in_fov(p, fov, range_m)
    )


@settings(max_examples=200, deadline=None)
@given(
    p=points,
    pose0=hnp.arrays(np.float64, 3, elements=st.floats(-20, 60)),
    v=hnp.arrays(np.float64, 2, elements=st.floats(-1.5, 1.5)),
    om=st.floats(-2.0, 2.0),
    dt=st.floats(0.01, 1.0),
    clamp=st.booleans(),
)
def test_own_motion_and_frame_change_match_the_world(p, pose0, v, om, dt, clamp):
    """Eq. 2 ego part: re-expressing through (d, dyaw) equals going through Σ_w."""
    lo, hi = (0.5, 39.5) if clamp else (None, None)
    d, dyaw = K.own_motion(pose0[None], v[None], np.array([om]), dt, lo, hi)
    pose1 = integrate_unicycle(pose0, v, om, dt)
    if clamp:
        pose1[:2] = np.clip(pose1[:2], lo, hi)
    h = np.linspace(-3, 3, p.shape[0])
    x1, y1, h1 = K.to_new_body_frame(p[:, 0], p[:, 1], h, d[0, 0], d[0, 1], dyaw[0])
    want = world_to_body(body_to_world(p, pose0), pose1)
    np.testing.assert_allclose(np.stack([x1, y1], -1), want, atol=1e-9)
    np.testing.assert_allclose(wrap_angle(h1 - (h - om * dt)), 0.0, atol=1e-12)
    assert np.all(np.abs(h1) <= math.pi)


@settings(max_examples=200, deadline=None)
@given(
    p=points,
    q=hnp.arrays(np.float64, 2, elements=st.floats(-30, 30)),
    k_p=st.floats(0.0, 3.0),
    v_max=st.floats(0.1, 3.0),
    rho=st.floats(0.0, 10.0),
)
def test_coverage_input_eq20_saturated(p, q, k_p, v_max, rho):
    ux, uy = K.coverage_input(p[:, 0], p[:, 1], q[0], q[1], k_p, v_max, rho)
    u = np.stack([ux, uy], -1)
    e = p - q
    r = np.linalg.norm(e, axis=1)
    speed = np.linalg.norm(u, axis=1)
    assert np.all(speed <= v_max * (1 + 1e-12))
    np.testing.assert_allclose(speed, np.clip(k_p * (r - rho), 0.0, v_max), atol=1e-9)
    # direction: towards q_m (non-positive projection on p - q_m)
    assert np.all(np.sum(u * e, axis=1) <= 1e-12)
    if rho == 0.0:
        unsat = k_p * r <= v_max
        np.testing.assert_allclose(u[unsat], -k_p * e[unsat], atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(p=points, v_max=st.floats(0.1, 3.0))
def test_crossing_input_eq22(p, v_max):
    ux, uy = K.crossing_input(p[:, 0], p[:, 1], v_max)
    u = np.stack([ux, uy], -1)
    r = np.linalg.norm(p, axis=1)
    ok = r > 1e-6
    np.testing.assert_allclose(np.linalg.norm(u[ok], axis=1), 0.5 * v_max, rtol=1e-9)
    np.testing.assert_allclose(u[ok], -0.5 * v_max * p[ok] / r[ok, None], atol=1e-9)
    assert np.all(np.isfinite(u))


def test_crossing_input_at_origin_is_zero():
    ux, uy = K.crossing_input(np.zeros(1), np.zeros(1), 1.0)
    assert ux[0] == 0.0 and uy[0] == 0.0


def test_measurement_log_likelihood_is_gaussian():
    rng = np.random.default_rng(0)
    dx, dy, dh = rng.normal(size=(3, 50))
    var = (0.1, 0.2, 0.5)
    lw, maha = K.measurement_log_likelihood(dx, dy, dh, tuple(1 / v for v in var))
    from scipy.stats import multivariate_normal

    ref = multivariate_normal(np.zeros(3), np.diag(var)).logpdf(np.stack([dx, dy, dh], -1))
    np.testing.assert_allclose(lw - lw[0], ref - ref[0], atol=1e-10)
    np.testing.assert_allclose(maha, dx**2 / 0.1 + dy**2 / 0.2)


# ---------------------------------------------------------------- budget split (IV-B)
d_rows = hnp.arrays(
    np.float64,
    st.tuples(st.integers(1, 4), st.integers(1, 60)),
    elements=st.one_of(st.just(0.0), st.floats(0.0, 80.0)),
)


@settings(max_examples=300, deadline=None)
@given(
    d=d_rows, n_total=st.integers(1, 20000), floor_=st.integers(1, 200), scale=st.floats(0.1, 10.0)
)
def test_allocate_budget_properties(d, n_total, floor_, scale):
    m = d.shape[1]
    if n_total < m:
        with pytest.raises(ValueError, match="n_particles_total"):
            K.allocate_budget(d, n_total, floor_, scale)
        return
    c = K.allocate_budget(d, n_total, floor_, scale)
    assert c.dtype == np.int64
    np.testing.assert_array_equal(c.sum(axis=1), n_total)
    assert np.all(c >= min(floor_, n_total // m))
    # monotone: strictly closer never gets fewer
    for row_d, row_c in zip(d, c, strict=True):
        closer = row_d[:, None] < row_d[None, :]
        assert not np.any(closer & (row_c[:, None] < row_c[None, :]))
        np.testing.assert_array_equal(row_c, allocate_reference(row_d, n_total, floor_, scale))


def test_allocate_budget_ties_and_nonfinite():
    d = np.array([[0.0, 0.0, 0.0], [np.inf, np.nan, 1.0]])
    c = K.allocate_budget(d, 1000, 20, 2.0)
    np.testing.assert_array_equal(c.sum(1), 1000)
    assert c[0].max() - c[0].min() <= 1
    assert c[1, 2] == c[1].max()


def test_allocate_budget_closer_gets_more_substantially():
    c = K.allocate_budget(np.array([[0.0, 5.0, 30.0]]), 2000, 20, 2.0)[0]
    assert c[0] > c[1] > c[2] >= 20


# ---------------------------------------------------------------- systematic resampling
def _blocks(rng, n_rows, m, row_len):
    counts = np.stack(
        [np.bincount(rng.integers(0, m, row_len), minlength=m) for _ in range(n_rows)]
    )
    counts[counts == 0] = 1
    for r in range(n_rows):  # keep row sums at row_len
        while counts[r].sum() > row_len:
            counts[r, np.argmax(counts[r])] -= 1
        counts[r, 0] += row_len - counts[r].sum()
    c = counts.reshape(-1)
    start = np.concatenate([[0], np.cumsum(c)[:-1]])
    block_of = np.repeat(np.arange(c.size), c)
    return counts, c, start, block_of


@pytest.mark.parametrize("seed", range(8))
def test_systematic_resampling_matches_textbook_loop(seed):
    rng = np.random.default_rng(seed)
    n_rows, m, row_len = 3, 7, 400
    counts, c, start, block_of = _blocks(rng, n_rows, m, row_len)
    w = rng.exponential(size=n_rows * row_len) ** 3
    w[rng.random(w.size) < 0.3] = 0.0  # deleted particles
    for b in range(c.size):  # at least one positive weight per block
        w[start[b] + rng.integers(c[b])] = rng.random() + 0.1
    n_new = np.concatenate(
        [K.allocate_budget(rng.random((1, m)) * 20, row_len, 5, 2.0)[0] for _ in range(n_rows)]
    )
    u = rng.random(c.size)
    idx = K.systematic_resample_indices(w, row_len, block_of, start, c, n_new, u)
    want = np.concatenate(
        [
            start[b] + systematic_reference(w[start[b] : start[b] + c[b]], int(n_new[b]), u[b])
            for b in range(c.size)
        ]
    )
    np.testing.assert_array_equal(idx, want)
    assert np.all(w[idx] > 0)
    np.testing.assert_array_equal(np.bincount(block_of[idx], minlength=c.size), n_new)


def test_systematic_resampling_roundoff_guards():
    """u just below 1 and weights whose cumulative sum does not end exactly at the total."""
    row_len = 1000
    w = np.full(row_len, 0.1)
    block_of = np.repeat([0, 1], [300, 700])
    start = np.array([0, 300])
    blen = np.array([300, 700])
    for u in (0.0, np.nextafter(1.0, 0.0)):
        idx = K.systematic_resample_indices(
            w, row_len, block_of, start, blen, np.array([999, 1]), np.array([u, u])
        )
        np.testing.assert_array_equal(np.bincount(block_of[idx], minlength=2), [999, 1])
        assert idx.size == row_len


def test_systematic_resampling_equal_weights_same_size_is_identity():
    row_len = 50
    block_of = np.repeat([0, 1], [20, 30])
    idx = K.systematic_resample_indices(
        np.ones(row_len),
        row_len,
        block_of,
        np.array([0, 20]),
        np.array([20, 30]),
        np.array([20, 30]),
        np.array([0.3, 0.9]),
    )
    np.testing.assert_array_equal(idx, np.arange(row_len))


@settings(max_examples=100, deadline=None)
@given(
    w=hnp.arrays(np.float64, st.integers(1, 60), elements=st.floats(0.0, 1e6)),
    n_new=st.integers(1, 200),
    u=st.floats(0.0, 1.0, exclude_max=True),
)
def test_systematic_resampling_single_block_property(w, n_new, u):
    if not np.any(w > 0):
        w = w.copy()
        w[0] = 1.0
    idx = K.systematic_resample_indices(
        w,
        w.size,
        np.zeros(w.size, dtype=np.int64),
        np.array([0]),
        np.array([w.size]),
        np.array([n_new]),
        np.array([u]),
    )
    # the row length is the old size; only the block's new size matters here
    assert idx.size == n_new
    assert np.all(np.diff(idx) >= 0)
    assert np.all(w[idx] > 0)
    # each particle's copies are within 1 of its expected share
    expect = n_new * w / w.sum()
    got = np.bincount(idx, minlength=w.size)
    assert np.all(np.abs(got - expect) < 1.0 + 1e-9)


def test_weighted_moments_match_numpy():
    rng = np.random.default_rng(3)
    c = np.array([5, 40, 1, 54])
    start = np.concatenate([[0], np.cumsum(c)[:-1]])
    block_of = np.repeat(np.arange(4), c)
    x, y = rng.normal(10, 3, (2, c.sum()))
    w = rng.random(c.sum())
    sw, mean, cov = K.weighted_moments(x, y, w, block_of, start)
    for b in range(4):
        sl = slice(start[b], start[b] + c[b])
        p = np.stack([x[sl], y[sl]], -1)
        np.testing.assert_allclose(mean[b], np.average(p, axis=0, weights=w[sl]), rtol=1e-12)
        np.testing.assert_allclose(
            cov[b], np.cov(p.T, aweights=w[sl], bias=True).reshape(2, 2), atol=1e-12
        )
    ess = K.effective_sample_size(np.ones(c.sum()), start)
    np.testing.assert_allclose(ess, c)


def test_wrap_range_and_equivalence():
    a = np.linspace(-20, 20, 10001)
    wa = K.wrap(a)
    assert np.all(np.abs(wa) <= math.pi)
    np.testing.assert_allclose(np.cos(wa), np.cos(a), atol=1e-12)
    np.testing.assert_allclose(np.sin(wa), np.sin(a), atol=1e-12)


@settings(max_examples=120, deadline=None)
@given(
    sizes=st.lists(st.integers(1, 40), min_size=1, max_size=5),
    seed=st.integers(0, 2**31 - 1),
    spread=st.floats(1e-3, 20.0),
    var=st.tuples(st.floats(1e-3, 2.0), st.floats(1e-3, 2.0)),
)
def test_fuse_onto_detection_is_the_gaussian_posterior(sizes, seed, spread, var):
    """Each moved cloud has exactly the posterior's moments of (its own moments + 1e-6 I)
    and N(z, R), and matches the block-by-block information-form reference."""
    from .reference import fuse_onto_detection_reference

    rng = np.random.default_rng(seed)
    n = np.array(sizes)
    F = int(n.sum())
    x = rng.normal(3.0, spread, F) * rng.uniform(0.2, 1.0)
    y = rng.normal(-1.0, spread, F) + 0.5 * x  # correlated clouds
    zx, zy = rng.normal(0.0, 5.0, n.size), rng.normal(0.0, 5.0, n.size)
    fx, fy = K.fuse_onto_detection(x, y, n, zx, zy, var)
    rx, ry = fuse_onto_detection_reference(x, y, n, zx, zy, var)
    scale = 1.0 + np.abs(np.concatenate([x, y, zx, zy])).max()
    np.testing.assert_allclose(fx, rx, atol=1e-9 * scale)
    np.testing.assert_allclose(fy, ry, atol=1e-9 * scale)
    R_inv = np.diag([1.0 / var[0], 1.0 / var[1]])
    s = 0
    for b, nb in enumerate(n.tolist()):
        p = np.stack([x[s : s + nb], y[s : s + nb]], -1)
        q = np.stack([fx[s : s + nb], fy[s : s + nb]], -1)
        mu = p.mean(0)
        C = (p - mu).T @ (p - mu) / nb + 1e-6 * np.eye(2)
        C_post = np.linalg.inv(np.linalg.inv(C) + R_inv)
        mu_post = C_post @ (np.linalg.solve(C, mu) + R_inv @ np.array([zx[b], zy[b]]))
        np.testing.assert_allclose(q.mean(0), mu_post, atol=1e-8 * scale)
        # the covariance: the particles' own, mapped by T = L' L^-1 (the 1e-6 floor is
        # part of C, not of the particles)
        cq = (q - q.mean(0)).T @ (q - q.mean(0)) / nb
        cp = (p - mu).T @ (p - mu) / nb
        T = np.linalg.cholesky(C_post) @ np.linalg.inv(np.linalg.cholesky(C))
        np.testing.assert_allclose(cq, T @ cp @ T.T, atol=1e-9 * scale**2)
        np.testing.assert_allclose(T @ C @ T.T, C_post, rtol=1e-7, atol=1e-12 * scale**2)
        s += nb


def test_fuse_onto_detection_narrow_cloud_barely_moves_wide_cloud_jumps():
    """A cloud narrow against Σ_MEAS keeps most of its place (the traced outlier: 0.1 m
    std, detection 1.3 m off); a wide one lands on the detection with Σ_MEAS's scale."""
    rng = np.random.default_rng(0)
    narrow_x, narrow_y = rng.normal(0.0, 0.1, 300), rng.normal(1.3, 0.25, 300)
    fx, fy = K.fuse_onto_detection(narrow_x, narrow_y, np.array([300]), np.array([-0.5]),
                                   np.array([0.0]), (0.1, 0.1))  # fmt: skip
    assert 0.6 < fy.mean() < 1.0 and fy.std() < 0.25  # between, nearer the prior in x
    wide_x, wide_y = rng.normal(0.0, 10.0, 300), rng.normal(0.0, 10.0, 300)
    fx, fy = K.fuse_onto_detection(wide_x, wide_y, np.array([300]), np.array([4.0]),
                                   np.array([-2.0]), (0.1, 0.1))  # fmt: skip
    assert abs(fx.mean() - 4.0) < 0.01 and abs(fy.mean() + 2.0) < 0.01
    assert 0.25 < fx.std() < 0.35 and 0.25 < fy.std() < 0.35
