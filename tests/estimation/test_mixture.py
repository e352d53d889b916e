"""The mode-mixture motion model (``motion_model="mixture"``, the default): kernels against
the slow reference, switching statistics, the tracker's mixture state, mode probabilities
and velocity estimate, determinism and the single-tracker / bank equality."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from fov_marl.estimation import kernels as K

from .reference import mixture_predict_reference

PRIOR = (0.3, 0.2, 0.1, 0.4)


# ---------------------------------------------------------------- kernels
@settings(max_examples=150, deadline=None)
@given(
    n=st.integers(1, 60),
    seed=st.integers(0, 2**32 - 1),
    p_switch=st.sampled_from([0.0, 0.05, 0.5, 1.0]),
    prior=st.sampled_from(
        [PRIOR, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), (0.0, 1.0, 1.0, 0.0)]
    ),
    k_p=st.floats(0.0, 2.0),
    v_max=st.floats(0.1, 3.0),
    standoff=st.floats(0.0, 10.0),
    sig_vel=st.floats(0.0, 1.0),
    forward_bias=st.floats(0.0, 5.0),
)
def test_mixture_predict_matches_the_per_particle_reference(
    n, seed, p_switch, prior, k_p, v_max, standoff, sig_vel, forward_bias
):
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(-30, 30, (2, n))
    x[0] = y[0] = 0.0  # a particle at robot i's origin (Eq. 22 has no direction there)
    h = rng.uniform(-math.pi, math.pi, n)
    v = rng.uniform(-1.5, 1.5, (2, n)) * v_max
    mode = rng.integers(0, 4, n).astype(np.int8)
    u = rng.random(n)
    noise = rng.standard_normal((4, n))
    q = rng.uniform(-20, 20, 2)
    sig_pos = rng.uniform(0.0, 0.5, 4)
    kw = dict(dt=0.2, p_switch=p_switch, k_p=k_p, v_max=v_max, sig_vel=sig_vel)
    got = K.mixture_predict(
        x, y, h, v[0], v[1], mode, u, tuple(noise), q[0], q[1],
        cdf=K.mode_cdf(prior), standoff_m=standoff, sig_pos_by_mode=sig_pos,
        forward_bias=forward_bias, **kw,
    )  # fmt: skip
    want = mixture_predict_reference(
        x, y, h, v[0], v[1], mode, u, noise, q, prior=prior, standoff=standoff,
        sig_pos=sig_pos, forward_bias=forward_bias, **kw,
    )  # fmt: skip
    np.testing.assert_array_equal(got[4], want[4])
    for g, w in zip(got[:4], want[:4], strict=True):
        np.testing.assert_allclose(g, w, rtol=1e-12, atol=1e-12)
    speed = np.hypot(got[2], got[3])
    assert np.all(speed <= v_max * (1 + 1e-12))


def test_switching_statistics():
    """A fraction p switches; switched particles take modes in proportion to the prior."""
    rng = np.random.default_rng(0)
    n = 400_000
    mode = np.full(n, K.MODE_CV, dtype=np.int8)
    new, switched = K.switch_modes(mode, rng.random(n), 0.2, K.mode_cdf(PRIOR))
    assert abs(switched.mean() - 0.2) < 0.003
    np.testing.assert_array_equal(new[~switched], K.MODE_CV)
    frac = np.bincount(new[switched], minlength=4) / switched.sum()
    np.testing.assert_allclose(frac, np.asarray(PRIOR) / sum(PRIOR), atol=0.005)
    same, sw0 = K.switch_modes(mode, rng.random(n), 0.0, K.mode_cdf(PRIOR))
    assert not sw0.any() and np.array_equal(same, mode)


def test_stratified_modes_follow_the_prior_in_every_block():
    cdf = K.mode_cdf(PRIOR)
    for n in (1, 3, 7, 100, 333):
        m = K.stratified_modes(np.arange(n), np.full(n, n), cdf)
        counts = np.bincount(m, minlength=4)
        assert np.all(np.abs(counts - n * np.asarray(PRIOR)) <= 1.0)


def test_fresh_velocity_bounded_and_forward_biased():
    rng = np.random.default_rng(1)
    nx, ny = rng.standard_normal((2, 100_000))
    h = 0.7
    vx, vy = K.fresh_velocity(nx, ny, 1.5, h, 0.0)
    assert np.all(np.hypot(vx, vy) <= 1.5 + 1e-12)
    assert abs(np.mean(np.hypot(vx, vy) >= 1.5 - 1e-9) - math.exp(-0.5)) < 0.01
    assert np.hypot(vx.mean(), vy.mean()) < 0.02  # isotropic without bias
    fx, fy = K.fresh_velocity(nx, ny, 1.5, h, 3.0)
    ang = np.arctan2(fy, fx) - h
    assert np.median(np.abs(K.wrap(ang))) < 0.3  # mostly along the heading
    assert np.mean(np.hypot(fx, fy)) > 1.4


def test_rotate_velocity_is_the_frame_change_without_translation():
    vx, vy = np.array([1.0, 0.0]), np.array([0.0, 2.0])
    rx, ry = K.rotate_velocity(vx, vy, np.array([math.pi / 2, math.pi / 2]))
    np.testing.assert_allclose(rx, [0.0, 2.0], atol=1e-12)
    np.testing.assert_allclose(ry, [-1.0, 0.0], atol=1e-12)
