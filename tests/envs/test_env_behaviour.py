"""Behaviour of the environments that users rely on: determinism, camera, physics, errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fov_marl.config import ConfigError
from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
from fov_marl.geometry import in_fov, relative_pose
from fov_marl.infos import metrics_of
from fov_marl.spaces import ObservationLayout

MODULES = [fov_coverage_v0, fov_crossing_v0]
ids = lambda m: m.__name__.rsplit(".", 1)[-1]  # noqa: E731


def run_episode(mod, seed, n_steps, action_seed=123, **kw):
    env = mod.parallel_env(**kw)
    obs, infos = env.reset(seed=seed)
    rng = np.random.default_rng(action_seed)
    trace = [(obs, infos)]
    for _ in range(n_steps):
        if not env.agents:
            break
        acts = {a: rng.uniform(-1, 1, 3).astype(np.float32) for a in env.agents}
        trace.append(env.step(acts))
    return trace, env


def assert_traces_equal(t1, t2):
    assert len(t1) == len(t2)
    for s1, s2 in zip(t1, t2, strict=True):
        for d1, d2 in zip(s1, s2, strict=True):
            assert d1.keys() == d2.keys()
            for k in d1:
                if isinstance(d1[k], np.ndarray):
                    np.testing.assert_array_equal(d1[k], d2[k])
                else:
                    assert d1[k] == d2[k]


@pytest.mark.parametrize("mod", MODULES, ids=ids)
def test_whole_episode_determinism(mod):
    t1, e1 = run_episode(mod, seed=7, n_steps=150, n_agents=5, max_cycles=150)
    t2, e2 = run_episode(mod, seed=7, n_steps=150, n_agents=5, max_cycles=150)
    assert_traces_equal(t1, t2)
    np.testing.assert_array_equal(e1.poses, e2.poses)
    t3, e3 = run_episode(mod, seed=8, n_steps=150, n_agents=5, max_cycles=150)
    assert not np.array_equal(e1.poses, e3.poses)
    assert any(not np.array_equal(t1[k][0]["robot_0"], t3[k][0]["robot_0"]) for k in range(len(t3)))


def test_reset_without_seed_continues_stream_and_reseeding_repeats():
    env = fov_coverage_v0.parallel_env()
    env.reset(seed=3)
    p0 = env.poses
    env.reset()
    assert not np.array_equal(p0, env.poses)
    env.reset(seed=3)
    np.testing.assert_array_equal(p0, env.poses)


@pytest.mark.parametrize("mod", MODULES, ids=ids)
@pytest.mark.parametrize("fov", [60.0, 120.0, 200.0, 360.0])
def test_camera_reports_exactly_the_robots_in_the_sector(mod, fov):
    env = mod.parallel_env(n_agents=8, fov_deg=fov, meas_cov_diag=(0.0, 0.0, 0.0))
    obs, _ = env.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(30):
        rel = relative_pose(env.poses)
        for i, a in enumerate(env.possible_agents):
            lay = ObservationLayout(8, i)
            slots = lay.slots(obs[a])
            for k, j in enumerate(lay.neighbour_ids):
                visible = in_fov(rel[i, j, :2], np.radians(fov), env.config.detection_range_m)
                assert bool(slots[k, 0]) == bool(visible)
                if visible:  # noiseless: exact relative pose
                    np.testing.assert_allclose(slots[k, 1:3], rel[i, j, :2], atol=1e-4)
                    np.testing.assert_allclose(
                        np.arctan2(slots[k, 4], slots[k, 3]), rel[i, j, 2], atol=1e-4
                    )
                else:
                    assert np.all(slots[k] == 0.0)
        obs, *_ = env.step({a: rng.uniform(-1, 1, 3) for a in env.agents})


def test_no_ground_truth_leaks_about_unseen_neighbours():
    """Moving a neighbour that robot 0 cannot see leaves robot 0's observation unchanged."""
    base = np.array([[10.0, 10.0, 0.0], [5.0, 10.0, 0.0], [30.0, 30.0, 1.0]])
    moved = base.copy()
    moved[1] = [6.0, 4.0, 2.0]  # still behind robot 0 (x < 0 in its frame)
    obs = []
    for poses in (base, moved):
        env = fov_coverage_v0.parallel_env(n_agents=3, initial_poses=poses)
        o, _ = env.reset(seed=0)
        o2, *_ = env.step({a: np.zeros(3) for a in env.agents})
        obs.append((o["robot_0"], o2["robot_0"]))
    np.testing.assert_array_equal(obs[0][0], obs[1][0])
    np.testing.assert_array_equal(obs[0][1], obs[1][1])


@settings(max_examples=40)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 9), fov=st.floats(5.0, 360.0))
def test_observations_and_state_always_inside_their_box(seed, n, fov):
    for mod in MODULES:
        env = mod.parallel_env(n_agents=n, fov_deg=fov, max_cycles=20)
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        while True:
            for a, o in obs.items():
                assert env.observation_space(a).contains(o)
            assert env.state_space.contains(env.state())
            if not env.agents:
                break
            obs, *_ = env.step({a: rng.uniform(-3, 3, 3) for a in env.agents})


@pytest.mark.parametrize("sigma", [2.8, 56.0, 60.0, 1e6])
def test_density_sigma_in_the_cue_is_reported_as_configured(sigma):
    """Red team 4: σ above the arena diagonal (56.57 m) was clipped to it in the cue while
    the state reported it: the bound of that entry is max(diagonal, σ)."""
    env = fov_coverage_v0.parallel_env(n_agents=2, density_sigma_m=sigma)
    obs, _ = env.reset(seed=0)
    for a, o in obs.items():
        assert o[-1] == np.float32(sigma) == env.state()[-1]
        assert env.observation_space(a).contains(o)


def test_kinematics_exact_integration_and_speed_limit():
    env = fov_coverage_v0.parallel_env(
        n_agents=1, initial_poses=[[20.0, 20.0, 0.5]], dt_s=0.2, v_max_mps=1.0, omega_max_radps=1.0
    )
    env.reset(seed=0)
    # pure forward motion at full speed: 0.2 m along the heading
    env.step({"robot_0": np.array([1.0, 0.0, 0.0])})
    np.testing.assert_allclose(env.poses[0, :2], [20 + 0.2 * np.cos(0.5), 20 + 0.2 * np.sin(0.5)])
    # diagonal command is limited to v_max in norm
    p0 = env.poses.copy()
    env.step({"robot_0": np.array([1.0, 1.0, 0.0])})
    assert np.linalg.norm(env.poses[0, :2] - p0[0, :2]) == pytest.approx(0.2)
    # constant turn: a full circle of radius v/omega comes back to the start
    env = fov_coverage_v0.parallel_env(
        n_agents=1, initial_poses=[[20.0, 20.0, 0.0]], dt_s=0.1, omega_max_radps=1.0
    )
    env.reset(seed=0)
    steps = int(round(2 * np.pi / 0.1))
    for _ in range(steps):
        env.step({"robot_0": np.array([1.0, 0.0, 2 * np.pi / (0.1 * steps)])})
    np.testing.assert_allclose(env.poses[0, :2], [20.0, 20.0], atol=1e-9)


def test_out_of_box_actions_are_clipped_as_documented():
    mk = lambda: fov_coverage_v0.parallel_env(n_agents=1, initial_poses=[[20.0, 20.0, 0.0]])  # noqa: E731
    e1, e2 = mk(), mk()
    e1.reset(seed=0)
    e2.reset(seed=0)
    e1.step({"robot_0": np.array([5.0, 0.0, -7.0])})
    e2.step({"robot_0": np.array([1.0, 0.0, -1.0])})
    np.testing.assert_array_equal(e1.poses, e2.poses)


def test_robots_stay_inside_the_arena():
    env = fov_coverage_v0.parallel_env(n_agents=4, max_cycles=300)
    env.reset(seed=2)
    r, L = env.config.robot_radius_m, env.config.arena_size_m
    while env.agents:
        env.step({a: np.array([1.0, 0.3, 0.0]) for a in env.agents})
        assert np.all(env.poses[:, :2] >= r) and np.all(env.poses[:, :2] <= L - r)


def test_poses_are_a_read_only_copy():
    env = fov_coverage_v0.parallel_env()
    env.reset(seed=0)
    p = env.poses
    with pytest.raises(ValueError):
        p[0, 0] = 3.0
    assert env.poses is not p


def test_initial_poses_are_used_and_validated():
    poses = [[5.0, 5.0, 0.0], [10.0, 5.0, 1.0]]
    env = fov_coverage_v0.parallel_env(n_agents=2, initial_poses=poses)
    env.reset(seed=0)
    np.testing.assert_allclose(env.poses, poses)
    with pytest.raises(ValueError, match="initial_poses"):
        fov_coverage_v0.parallel_env(n_agents=2, initial_poses=[[5, 5, 0], [5.5, 5, 0]])
    with pytest.raises(ValueError, match="initial_poses"):
        fov_coverage_v0.parallel_env(n_agents=2, initial_poses=[[5, 5, 0], [45, 5, 0]])
    with pytest.raises(ValueError, match="initial_poses"):
        fov_coverage_v0.parallel_env(n_agents=3, initial_poses=poses)


def test_random_starts_respect_separation():
    env = fov_coverage_v0.parallel_env(n_agents=12)
    for seed in range(5):
        env.reset(seed=seed)
        d = np.linalg.norm(env.poses[:, None, :2] - env.poses[None, :, :2], axis=-1)
        d[np.diag_indices(12)] = np.inf
        assert d.min() >= env.config.init_min_separation_m


@pytest.mark.parametrize("mod", MODULES, ids=ids)
def test_bad_actions_raise_value_error_naming_the_agent(mod):
    env = mod.parallel_env(n_agents=3)
    env.reset(seed=0)
    good = {a: np.zeros(3) for a in env.agents}
    with pytest.raises(ValueError, match="robot_1"):
        env.step({**good, "robot_1": np.zeros(2)})
    with pytest.raises(ValueError, match="robot_2"):
        env.step({**good, "robot_2": np.array([0.0, np.nan, 0.0])})
    with pytest.raises(ValueError, match="robot_0"):
        env.step({**good, "robot_0": np.array([np.inf, 0.0, 0.0])})
    with pytest.raises(ValueError, match="robot_9"):
        env.step({**good, "robot_9": np.zeros(3)})
    with pytest.raises(ValueError, match="missing"):
        env.step({"robot_0": np.zeros(3)})
    with pytest.raises(ValueError, match="robot_1"):
        env.step({**good, "robot_1": "fast"})
    with pytest.raises(ValueError, match="unknown agent"):
        env.observation_space("robot_7")
    env.step(good)  # still usable after rejected calls


@pytest.mark.parametrize("mod", MODULES, ids=ids)
def test_bad_config_raises_value_error_naming_the_field(mod):
    with pytest.raises(ValueError, match="fov_deg"):
        mod.parallel_env(fov_deg=400.0)
    with pytest.raises(ValueError, match="n_agents"):
        mod.parallel_env(n_agents=0)
    with pytest.raises(ConfigError, match="warp_speed"):
        mod.parallel_env(warp_speed=3)
    with pytest.raises(ValueError, match="render_mode"):
        mod.parallel_env(render_mode="ascii")


def test_step_after_episode_end_raises():
    env = fov_coverage_v0.parallel_env(n_agents=2, max_cycles=2)
    env.reset(seed=0)
    for _ in range(2):
        env.step({a: np.zeros(3) for a in env.agents})
    assert env.agents == []
    with pytest.raises(ValueError, match="reset"):
        env.step({})


def test_coverage_rewards_are_eta_gain_and_collision_penalty():
    poses = [[20.0, 20.0, 0.0], [21.2, 20.0, np.pi], [30.0, 30.0, 0.0]]
    env = fov_coverage_v0.parallel_env(n_agents=3, initial_poses=poses)
    _, infos = env.reset(seed=0)
    m0 = metrics_of(infos["robot_0"])
    assert m0["collisions"] == 0 and m0["safety_violations"] == 1
    # robots 0 and 1 drive into each other: 1.2 m -> 0.8 m, a collision
    fwd = np.array([1.0, 0.0, 0.0])
    _, rew, term, trunc, infos = env.step({"robot_0": fwd, "robot_1": fwd, "robot_2": np.zeros(3)})
    m = metrics_of(infos["robot_0"])
    assert m["collisions"] == 1 and m["safety_violations"] == 1
    assert m["min_distance"] == pytest.approx(0.8)
    gain = m["eta"] - m0["eta"]
    assert rew["robot_0"] == pytest.approx(100 * gain - 10.0 - 1.0)
    assert rew["robot_1"] == pytest.approx(100 * gain - 10.0 - 1.0)
    assert rew["robot_2"] == pytest.approx(100 * gain)
    # moving the far robot toward q_m raises eta and everyone gets the same gain
    _, rew, *_, infos = env.step(
        {"robot_0": -fwd, "robot_1": -fwd, "robot_2": np.array([-1.0, -1.0, 0.0])}
    )
    gain = metrics_of(infos["robot_0"])["eta"] - m["eta"]
    assert gain > 0
    assert rew["robot_2"] == pytest.approx(100 * gain)
    assert metrics_of(infos["robot_0"])["collisions_total"] == 1
    assert not any(term.values()) and not any(trunc.values())


def test_crossing_paths_intersect_and_episode_terminates_on_arrival():
    env = fov_crossing_v0.parallel_env(n_agents=4)
    obs, _ = env.reset(seed=0)
    starts, targets = env.poses[:, :2], env.targets
    centre = np.array([20.0, 20.0])
    for s, t in zip(starts, targets, strict=True):  # every path passes close to the centre
        d = t - s
        u = np.clip(np.dot(centre - s, d) / np.dot(d, d), 0, 1)
        assert np.linalg.norm(s + u * d - centre) < 1.5
    # a perfect (unsafe) proportional controller drives straight to the targets
    total = {a: 0.0 for a in env.agents}
    while env.agents:
        acts = {}
        for i, a in enumerate(env.agents):
            tb = ObservationLayout(4, i).goal_body(obs[a])
            acts[a] = np.array([*np.clip(tb / 0.2, -1, 1), 0.0])
        obs, rew, term, trunc, infos = env.step(acts)
        for a in rew:
            total[a] += rew[a]
    assert all(term.values()) and not any(trunc.values())
    assert metrics_of(infos["robot_0"])["arrived"] == 4
    assert env.num_steps < 200
    # paths cross at the centre: the unsafe controller collides, and it is counted
    assert metrics_of(infos["robot_0"])["collisions_total"] > 0


def test_rendering_frames_and_layers():
    env = fov_crossing_v0.parallel_env(render_mode="rgb_array")
    env.reset(seed=0)
    calls = []
    env.add_render_layer(lambda canvas: calls.append(canvas.scale))
    frame = env.render()
    assert frame.shape == (640, 640, 3) and frame.dtype == np.uint8
    assert frame.std() > 10  # not blank
    assert calls and calls[0] > 0
    env2 = fov_coverage_v0.parallel_env(render_mode=None)
    env2.reset(seed=0)
    assert env2.render() is None
    with pytest.raises(ValueError):
        env.add_render_layer("not callable")


def test_collision_totals_count_events_not_steps():
    poses = [[20.0, 20.0, 0.0], [21.2, 20.0, np.pi]]
    env = fov_coverage_v0.parallel_env(n_agents=2, initial_poses=poses)
    env.reset(seed=0)
    fwd, stop = np.array([1.0, 0.0, 0.0]), np.zeros(3)
    env.step({"robot_0": fwd, "robot_1": fwd})  # 0.8 m: contact begins
    for _ in range(3):  # stays in contact: still one event
        *_, infos = env.step({"robot_0": stop, "robot_1": stop})
        assert metrics_of(infos["robot_0"])["collisions"] == 1
        assert metrics_of(infos["robot_0"])["collisions_total"] == 1
    env.step({"robot_0": -fwd, "robot_1": -fwd})  # apart
    *_, infos = env.step({"robot_0": fwd, "robot_1": fwd})  # second contact
    assert metrics_of(infos["robot_0"])["collisions_total"] == 2


@settings(max_examples=30)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(2, 10),
    fov=st.floats(1.0, 360.0),
    range_m=st.floats(1.0, 30.0),
)
def test_camera_never_reports_a_neighbour_outside_the_sector(seed, n, fov, range_m):
    env = fov_coverage_v0.parallel_env(n_agents=n, fov_deg=fov, detection_range_m=range_m)
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    for _ in range(5):
        rel = relative_pose(env.poses)
        for i, a in enumerate(env.possible_agents):
            lay = ObservationLayout(n, i)
            det = lay.slots(obs[a])[:, 0] > 0.5
            truth = in_fov(rel[i, lay.neighbour_ids, :2], np.radians(fov), range_m)
            assert not np.any(det & ~truth)  # never outside F_i
            assert np.array_equal(det, truth)  # and everything inside is reported
        obs, *_ = env.step({a: rng.uniform(-1, 1, 3) for a in env.agents})
