"""The mode-mixture motion model (``motion_model="mixture"``, the default): kernels against
the slow reference, switching statistics, the tracker's mixture state, mode probabilities
and velocity estimate, determinism and the single-tracker / bank equality."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fov_marl.config import make_config
from fov_marl.estimation import NeighborTracker, TrackerBank, TrackerParams
from fov_marl.estimation import kernels as K
from fov_marl.estimation.testing import MiniWorld, StraightMotion

from .episodes import record_episode
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
    noise = rng.standard_normal((2, n))
    q = rng.uniform(-20, 20, 2)
    sig_pos = rng.uniform(0.0, 0.5, 4)
    kw = dict(dt=0.2, p_switch=p_switch, k_p=k_p, v_max=v_max, sig_vel=sig_vel)
    got = K.mixture_predict(
        x, y, h, v[0], v[1], mode, u, (noise[0], noise[1]), q[0], q[1],
        cdf=K.mode_cdf(prior), standoff_m=standoff, sig_pos_by_mode=sig_pos,
        forward_bias=forward_bias, **kw,
    )  # fmt: skip
    want = mixture_predict_reference(
        x, y, h, v[0], v[1], mode, u, noise[[0, 1, 0, 1]], q, prior=prior, standoff=standoff,
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


# ---------------------------------------------------------------- parameters
@pytest.mark.parametrize(
    "field,value",
    [
        ("mode_prior_static", -0.1),
        ("mode_prior_coverage", 1.5),
        ("mode_prior_crossing", float("nan")),
        ("mode_prior_cv", "0.5"),
        ("mode_switch_rate_hz", -1.0),
        ("mixture_noise_m_per_sqrt_s", float("inf")),
        ("cv_noise_m_per_sqrt_s", -0.1),
        ("cv_velocity_noise_mps_per_sqrt_s", True),
        ("cv_forward_bias", -1.0),
    ],
)
def test_bad_mixture_params_name_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        TrackerParams(**{field: value})


def test_mode_priors_must_not_all_be_zero_and_are_normalised():
    zero = dict(mode_prior_static=0, mode_prior_coverage=0, mode_prior_crossing=0)
    with pytest.raises(ValueError, match="mode_prior"):
        TrackerParams(**zero, mode_prior_cv=0.0)
    p = TrackerParams(**zero, mode_prior_cv=0.25)
    assert p.mode_prior() == (0.0, 0.0, 0.0, 1.0)
    assert abs(sum(TrackerParams().mode_prior()) - 1.0) < 1e-12
    assert TrackerParams(motion_model="mixture").motion_model == "mixture"


# ---------------------------------------------------------------- the tracker
def _run(params, ep, seed=3, agent=None):
    bank = TrackerBank(ep.config, params, seed=seed)
    bank.reset(ep.obs0, initial_poses_world=ep.poses0)
    for a, o in zip(ep.actions, ep.obs, strict=True):
        bank.step(a, o)
    return bank


@pytest.mark.parametrize("scenario", ["coverage", "crossing"])
def test_auto_is_the_mixture_in_both_scenarios(scenario):
    ep = record_episode(n_agents=4, steps=20, seed=2, scenario=scenario, crossing_radius_m=8.0)
    a = _run(TrackerParams(n_particles_total=400), ep).estimate()
    b = _run(TrackerParams(n_particles_total=400, motion_model="mixture"), ep).estimate()
    np.testing.assert_array_equal(a.mean_body, b.mean_body)
    np.testing.assert_array_equal(a.mode_probs, b.mode_probs)


def test_mixture_determinism_under_a_seed():
    ep = record_episode(n_agents=6, steps=30, seed=8)
    params = TrackerParams(n_particles_total=800)
    b1, b2, b3 = _run(params, ep, 1), _run(params, ep, 1), _run(params, ep, 2)
    for k in range(6):
        np.testing.assert_array_equal(b1.particles_body(k)[0], b2.particles_body(k)[0])
        np.testing.assert_array_equal(b1.particle_modes(k), b2.particle_modes(k))
        np.testing.assert_array_equal(
            b1.particle_velocities_body(k), b2.particle_velocities_body(k)
        )
    e1, e2 = b1.estimate(), b2.estimate()
    np.testing.assert_array_equal(e1.mode_probs, e2.mode_probs)
    np.testing.assert_array_equal(e1.velocity_est_body, e2.velocity_est_body)
    assert not np.array_equal(b1.particle_modes(0), b3.particle_modes(0))


def test_mixture_state_invariants():
    """Velocity states within v_max, valid modes, mode probabilities summing to 1, and
    every mode present in a fresh cloud in proportion to the prior."""
    ep = record_episode(n_agents=5, steps=40, seed=4)
    params = TrackerParams(n_particles_total=1000)
    bank = TrackerBank(ep.config, params, seed=0)
    bank.reset(ep.obs0, initial_poses_world=ep.poses0)
    prior = np.asarray(params.mode_prior())
    e0 = bank.estimate()
    np.testing.assert_allclose(
        e0.mode_probs, np.broadcast_to(prior, e0.mode_probs.shape), atol=0.02
    )
    for a, o in zip(ep.actions, ep.obs, strict=True):
        bank.step(a, o)
        e = bank.estimate()
        np.testing.assert_allclose(e.mode_probs.sum(-1), 1.0, atol=1e-12)
        assert np.all(e.mode_probs >= 0)
        for k in range(5):
            v = bank.particle_velocities_body(k)
            assert np.all(np.hypot(v[:, 0], v[:, 1]) <= ep.config.v_max_mps * (1 + 1e-9))
            m = bank.particle_modes(k)
            assert m.dtype == np.int8 and np.all((m >= 0) & (m < 4))
    assert np.all(np.hypot(*e.velocity_est_body.T) <= ep.config.v_max_mps * (1 + 1e-9))


def _pair_world(poses, fov_deg=360.0):
    """Two robots at ``poses`` with an isotropic camera (always in sight)."""
    cfg = make_config(n_agents=2, fov_deg=fov_deg)
    return cfg, MiniWorld(cfg, np.random.default_rng(0), poses=poses)


def test_detections_teach_the_modes_and_the_velocity():
    """A neighbour seen driving straight at full speed: the cv mode takes over and the
    mixture's mean velocity matches its velocity in Σ_i; a parked neighbour: the mean
    velocity is ~0 and the cv particles that survive are slow."""
    poses = np.array([[20.0, 20.0, 0.0], [24.0, 17.0, math.pi / 2]])  # 1 drives along +y
    cfg, world = _pair_world(poses)
    tr = NeighborTracker(cfg, 0, TrackerParams(), np.random.default_rng(0))
    tr.reset(world.observe()[0], world.poses)
    straight = StraightMotion(cfg, np.random.default_rng(0))
    for _ in range(25):  # 5 s
        a = straight(world.poses)
        a[0] = 0.0  # robot 0 stays
        obs = world.step(a)
        tr.step(a[0], obs[0])
    e = tr.estimate()
    assert e.detected[0]
    assert e.mode_probs[0].argmax() == K.MODE_CV and e.mode_probs[0, K.MODE_CV] > 0.45, e.mode_probs
    # the cv particles learnt the velocity; the mixture's mean hedges with the other modes
    np.testing.assert_allclose(e.velocity_cv_body[0], [0.0, 1.0], atol=0.25)
    v = e.velocity_est_body[0]
    assert v[1] > 0.3 and abs(v[0]) < 0.25, v

    cfg, world = _pair_world(np.array([[20.0, 20.0, 0.0], [24.0, 17.0, 0.0]]))
    tr = NeighborTracker(cfg, 0, TrackerParams(), np.random.default_rng(0))
    tr.reset(world.observe()[0], world.poses)
    for _ in range(25):
        obs = world.step(np.zeros((2, 3)))
        tr.step(np.zeros(3), obs[0])
    e = tr.estimate()
    assert np.hypot(*e.velocity_est_body[0]) < 0.25, e.velocity_est_body  # Eq. 22 hedges
    assert np.hypot(*e.velocity_cv_body[0]) < 0.25, e.velocity_cv_body
    m = tr.particle_modes()
    v = tr.particle_velocities_body()[m == K.MODE_CV]
    assert np.median(np.hypot(v[:, 0], v[:, 1])) < 0.2


def test_single_models_report_one_hot_modes_and_unchanged_velocity():
    ep = record_episode(n_agents=4, steps=10, seed=1)
    for model, k in (("static", 0), ("coverage", 1), ("crossing", 2)):
        e = _run(TrackerParams(n_particles_total=300, motion_model=model), ep).estimate()
        want = np.zeros(4)
        want[k] = 1.0
        np.testing.assert_array_equal(e.mode_probs, np.broadcast_to(want, e.mode_probs.shape))
    e = _run(TrackerParams(n_particles_total=300, motion_model="static"), ep).estimate()
    np.testing.assert_array_equal(e.velocity_est_body, 0.0)
    np.testing.assert_array_equal(e.velocity_cv_body, 0.0)
