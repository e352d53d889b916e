"""SafetyFilterWrapper: PettingZoo API, reporting, determinism, and no collisions under
random and adversarial policies."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from fov_marl.control import ControllerParams
from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
from fov_marl.evaluation import run_episode
from fov_marl.infos import safety_of
from fov_marl.wrappers import SafetyFilterWrapper
from fov_marl.wrappers.safety_filter import FILTER_CONTROLLER_DEFAULTS


def test_wrapper_passes_parallel_api_test_and_keeps_spaces():
    base = fov_coverage_v0.parallel_env(n_agents=4, max_cycles=40)
    env = SafetyFilterWrapper(base)
    for a in env.possible_agents:
        assert env.observation_space(a) is base.observation_space(a)
        assert env.action_space(a) is base.action_space(a)
    parallel_api_test(env, num_cycles=50)


def test_safety_info_reports_nominal_applied_and_status():
    env = SafetyFilterWrapper(fov_coverage_v0.parallel_env(n_agents=4))
    obs, _ = env.reset(seed=0)
    acts = {a: np.array([1.0, 0.0, 0.3], dtype=np.float32) for a in env.agents}
    _, _, _, _, infos = env.step(acts)
    for a, info in infos.items():
        s = safety_of(info)
        assert set(s) >= {"nominal_action", "applied_action", "intervened", "status", "fallback"}
        np.testing.assert_allclose(s["nominal_action"], acts[a])
        assert env.action_space(a).contains(s["applied_action"])
        if not s["intervened"]:  # only the speed polygon (16-gon in the disk) may shave u*
            np.testing.assert_allclose(s["applied_action"], s["nominal_action"], atol=0.02)
        assert not s["fallback"]
    assert env.last_cpu_s > 0


def test_last_actions_are_the_steps_nominal_and_applied_actions():
    env = SafetyFilterWrapper(fov_coverage_v0.parallel_env(n_agents=3))
    env.reset(seed=0)
    assert env.last_actions is None
    acts = {a: np.array([1.5, 0.0, -0.2], dtype=np.float32) for a in env.agents}
    _, _, _, _, infos = env.step(acts)
    last = env.last_actions
    assert last.nominal.shape == last.applied.shape == (3, 3)
    assert last.nominal.dtype == last.applied.dtype == np.float32
    for a, info in infos.items():
        i = env.unwrapped.agent_name_mapping[a]
        s = safety_of(info)
        np.testing.assert_array_equal(last.nominal[i], np.float32([1.0, 0.0, -0.2]))  # clipped
        np.testing.assert_array_equal(last.applied[i], s["applied_action"])
    last.applied[:] = 9.0  # a copy: the wrapper's own record is untouched
    assert np.abs(env.last_actions.applied).max() <= 1.0
    env.reset(seed=1)
    assert env.last_actions is None


def test_wrapper_validates_actions_like_the_env():
    env = SafetyFilterWrapper(fov_coverage_v0.parallel_env(n_agents=3))
    env.reset(seed=0)
    good = {a: np.zeros(3) for a in env.agents}
    with pytest.raises(ValueError, match="robot_1"):
        env.step({**good, "robot_1": np.array([np.nan, 0.0, 0.0])})
    with pytest.raises(ValueError, match="robot_2"):
        env.step({**good, "robot_2": np.zeros(4)})
    with pytest.raises(ValueError, match="needs a fov_marl ParallelEnv"):
        SafetyFilterWrapper(object.__new__(type("Fake", (), {"unwrapped": property(lambda s: s)})))
    with pytest.raises(ValueError, match="needs a fov_marl ParallelEnv"):
        SafetyFilterWrapper(object())  # red team 4: an AttributeError on .unwrapped
    with pytest.raises(ValueError, match="got the vector env FovVectorEnv.*VectorSafety"):
        SafetyFilterWrapper(fov_coverage_v0.vector_env(num_envs=2, n_agents=2))


def test_wrapper_is_deterministic_under_a_seed():
    kw = dict(n_agents=4, max_steps=80, record_trajectory=True, safety_filter=True)
    a = run_episode("coverage", "random", 11, **kw)
    b = run_episode("coverage", "random", 11, **kw)
    np.testing.assert_array_equal(a.trajectory, b.trajectory)
    assert a.filter_interventions == b.filter_interventions


def adversarial_factory(env):
    """Drive every robot straight at its nearest teammate at full speed (ground truth)."""

    class Adversary:
        def reset(self, seed=None):
            pass

        def act(self, obs):
            poses = env.unwrapped.poses
            out = {}
            for i, a in enumerate(env.unwrapped.possible_agents):
                d = poses[:, :2] - poses[i, :2]
                dist = np.linalg.norm(d, axis=1)
                dist[i] = np.inf
                j = int(np.argmin(dist))
                c, s = np.cos(poses[i, 2]), np.sin(poses[i, 2])
                g = np.array([c * d[j, 0] + s * d[j, 1], -s * d[j, 0] + c * d[j, 1]])
                v = g / max(np.linalg.norm(g), 1e-9)
                out[a] = np.array([v[0], v[1], 0.0], dtype=np.float32)
            return out

    return Adversary()


def _random(env):
    from fov_marl.baselines import make_policy

    return make_policy("random", env)


def _check_no_collisions(factory, n, seeds, steps, scenario="coverage"):
    for seed in seeds:
        rec = run_episode(scenario, factory, seed, n_agents=n, safety_filter=True, max_steps=steps)
        assert rec.collisions == 0, (factory.__name__, n, seed, rec)
        assert rec.qp_fallbacks is not None


@pytest.mark.parametrize("n", [4, 8])
def test_no_collisions_random_and_adversarial_quick(n):
    _check_no_collisions(_random, n, range(2), 200)
    _check_no_collisions(adversarial_factory, n, range(2), 200)


def test_unfiltered_adversary_does_collide():
    """The adversary is a real threat: without the filter it collides."""
    rec = run_episode("coverage", adversarial_factory, 0, n_agents=4, max_steps=200)
    assert rec.collisions > 0


@pytest.mark.slow
@pytest.mark.parametrize("n", [4, 8])
@pytest.mark.parametrize("factory", [_random, adversarial_factory], ids=["random", "adversarial"])
def test_no_collisions_20_episodes(n, factory):
    _check_no_collisions(factory, n, range(20), 1000)


def test_filter_controller_defaults_and_overrides():
    """The filter departs from ControllerParams() only where FILTER_CONTROLLER_DEFAULTS
    says (no deadlock steering: it must not add behaviour to the policy's; the blind
    travel budget per bearing, without a leak, with the glance); dict overrides keep
    them, a dataclass is used as given."""
    base = fov_coverage_v0.parallel_env(n_agents=3)
    prm = SafetyFilterWrapper(base).pipeline.controller_params
    assert prm == ControllerParams(**FILTER_CONTROLLER_DEFAULTS)
    assert prm.deadlock_turn_deg == 0.0 and not prm.motion_cone
    assert prm.safety_model == "ellipse" and prm.walls
    assert prm.blind_travel_memory_s == math.inf and prm.look_yields_fov
    over = SafetyFilterWrapper(base, controller_params={"blind_speed_mps": 0.1})
    assert over.pipeline.controller_params.deadlock_turn_deg == 0.0
    assert over.pipeline.controller_params.blind_speed_mps == 0.1
    given = SafetyFilterWrapper(base, controller_params=ControllerParams())
    assert (
        given.pipeline.controller_params.deadlock_turn_deg == ControllerParams().deadlock_turn_deg
    )


def test_blind_travel_budget_is_half_the_margin_to_contact():
    """B = min(0.5, (D_s − 2 r) / 2) unless given: a pair that never looks closes by at
    most 2 B, less than the margin to contact from D_s. The paper's setting keeps 0.5 m."""
    from fov_marl.config import make_config
    from fov_marl.wrappers.safety_filter import filter_controller_defaults

    assert filter_controller_defaults(make_config())["blind_travel_m"] == 0.5
    tight = make_config(safety_distance_m=1.05, init_min_separation_m=1.1)
    assert filter_controller_defaults(tight)["blind_travel_m"] == pytest.approx(0.025)
    assert filter_controller_defaults(tight, {"blind_travel_m": 0.3})["blind_travel_m"] < 0.03
    env = fov_coverage_v0.parallel_env(safety_distance_m=1.05, init_min_separation_m=1.1)
    assert SafetyFilterWrapper(env).pipeline.controller_params.blind_travel_m == pytest.approx(
        0.025
    )
    over = SafetyFilterWrapper(env, controller_params={"blind_travel_m": 0.3})
    assert over.pipeline.controller_params.blind_travel_m == 0.3  # the user's value wins


def test_uniform_init_counts_every_unseen_bearing_as_spent():
    """With ``init="uniform"`` the robot knows nothing of its neighbours: every bearing
    outside its view starts spent (c_k = B), the ones in view free; with the default
    ``init="known"`` nothing is spent."""
    from fov_marl.control.safety import bearing_angles_body

    env = fov_coverage_v0.parallel_env(n_agents=3)
    uni = SafetyFilterWrapper(env, init="uniform")
    uni.reset(seed=0)
    pipe = uni.pipeline
    c = pipe._bearing_travel
    B = pipe.controller_params.blind_travel_m
    ang = np.abs(bearing_angles_body(c.shape[1], pipe.own_pose[:, 2]))
    seen = ang <= env.unwrapped.config.fov_rad / 2 - math.pi / c.shape[1] + 1e-9
    assert np.all(c[seen] == 0.0) and np.all(c[~seen] == B) and seen.any() and (~seen).any()
    known = SafetyFilterWrapper(fov_coverage_v0.parallel_env(n_agents=3))
    known.reset(seed=0)
    assert np.all(known.pipeline._bearing_travel == 0.0)


def test_a_packed_neighbour_behind_spends_its_bearings_until_the_robot_looks():
    """Section 2g (``blind_travel_prespend``): robot 0 starts 1.1 m in front of robot 1,
    facing away. The known start pose (exact) has used ``(D_s − 1.1) / 2 = 0.45`` m of the
    0.5 m budget at the bearing behind it (the pair may close only to D_s − 2 B, as from
    D_s), so robot 0 may back up blind 0.05 m; without the option the unspent budget lets
    it back 0.5 m. Once the robot has turned and looked, the bearing is set from what the
    camera shows: ~1.1 m with the noise's margin (0.74 m), all of B."""
    from fov_marl.control.safety import bearing_angles_body

    poses = np.array([[20.0, 20.0, 0.0], [18.9, 20.0, 0.0], [5.0, 5.0, 0.0]])
    spent = {}
    for pre in (False, True):
        env = SafetyFilterWrapper(
            fov_coverage_v0.parallel_env(n_agents=3, initial_poses=poses, fov_deg=120.0),
            controller_params={"blind_travel_prespend": pre},
        )
        env.reset(seed=0)
        pipe = env.pipeline
        K = pipe._bearing_travel.shape[1]
        behind = int(np.argmin(np.abs(bearing_angles_body(K, np.array([math.pi]))[0])))
        spent[pre] = pipe._bearing_spent()[0, behind]
    B = env.pipeline.controller_params.blind_travel_m
    assert spent[False] == 0.0 and spent[True] == pytest.approx(0.5 * (2.0 - 1.1))
    # robot 0 turns around at ω_max, standing, until it has the neighbour in view
    stand = np.zeros(3, np.float32)
    for _ in range(15):
        env.step({"robot_0": np.array([0, 0, 1], np.float32), "robot_1": stand, "robot_2": stand})
        yaw = env.unwrapped.poses[0, 2]
        if abs(math.remainder(yaw - math.pi, 2 * math.pi)) < 0.2:
            break
    f = env.pipeline._bearing_floor[0, behind]
    # seen now, ~1.1 m away: its bearing's floor is set by the detection, not released
    assert f == B and env.pipeline._bearing_spent()[0, behind] == 0.0  # in view: no row


@pytest.mark.parametrize(
    "adversary, n, start, env_kw, tracker",
    [
        ("straight", 4, "wall", {}, {}),
        ("charge_centre", 4, "wall", {}, {}),
        ("straight", 4, "wall", {}, {"n_particles_total": 50}),
        ("head_on", 8, "random", {"safety_distance_m": 1.05, "init_min_separation_m": 1.1}, {}),
        ("wall_slide", 8, "random", {"safety_distance_m": 1.05, "init_min_separation_m": 1.1}, {}),
    ],
)
def test_uniform_init_and_a_thin_margin_do_not_collide(adversary, n, start, env_kw, tracker):
    """The red team's episodes (seed 1, or 0 with 50 particles; 200 steps): with
    ``init="uniform"`` a robot packed 1.1 m from a neighbour it had never seen backed into
    it (0.90 m, step 6; 0.21 m with 50 particles), and with D_s = 1.05 m two blind robots
    each spent the 0.5 m budget from a start outside D_s (0.795 m)."""
    from fov_marl.stress import StressCase, run_stress_episode

    filt = {"init": "uniform", **({"tracker_params": tracker} if tracker else {})}
    case = StressCase(adversary, n, 120.0, start, env_kwargs=env_kw, filter_kwargs=filt)
    row = run_stress_episode(case, 0 if tracker else 1, 200)
    assert row["collisions"] == 0, row


def _constant(action):
    def factory(env):
        class Const:
            def reset(self, seed=None):
                pass

            def act(self, obs):
                return {a: np.asarray(action, np.float32) for a in obs}

        return Const()

    return factory


@pytest.mark.parametrize("fov", [45.0, 120.0, 360.0])
def test_head_on_pair_neither_collides_nor_breaks_ds(fov):
    """The first outside check's failing case: two robots 2.6 m apart facing each other, both
    commanding full speed ahead. Seen neighbours keep D_s (not only contact)."""
    poses = np.array([[18.7, 20.0, 0.0], [21.3, 20.0, math.pi]])
    for seed in range(3):
        rec = run_episode(
            "coverage",
            _constant([1.0, 0.0, 0.0]),
            seed,
            safety_filter=True,
            n_agents=2,
            fov_deg=fov,
            initial_poses=poses,
            max_steps=150,
        )
        assert rec.collisions == 0, rec
        assert rec.min_distance >= 2.0, rec
        unfiltered = run_episode(
            "coverage", _constant([1.0, 0.0, 0.0]), seed, n_agents=2, fov_deg=fov,
            initial_poses=poses, max_steps=30,
        )  # fmt: skip
        assert unfiltered.collisions > 0


@pytest.mark.parametrize("dt", [0.5, 1.0])
@pytest.mark.parametrize("fov", [45.0, 120.0])
def test_head_on_pair_at_a_coarse_control_period(dt, fov):
    """The head-on pair at dt = 0.5 and 1 s (the env accepts up to 5 s). The default gains
    (2.5 1/s, chosen at dt = 0.2 s) made the controller raise for dt > 0.4 s; they are now
    used as min(γ, 1/dt) (:func:`fov_marl.control.safety.barrier_gain`), and D_s holds at
    every sample although a robot moves up to 1 m per step."""
    poses = np.array([[18.7, 20.0, 0.0], [21.3, 20.0, math.pi]])
    for seed in range(2):
        rec = run_episode(
            "coverage", _constant([1.0, 0.0, 0.0]), seed, safety_filter=True, n_agents=2,
            fov_deg=fov, initial_poses=poses, max_steps=int(30 / dt), dt_s=dt,
        )  # fmt: skip
        assert rec.collisions == 0 and rec.min_distance >= 2.0, rec
    if fov == 120.0:  # pfcbf builds and runs there too
        rec = run_episode("coverage", "pfcbf", 0, n_agents=6, dt_s=dt, max_steps=60)
        assert rec.collisions == 0, rec


@pytest.mark.parametrize("reach, bound", [(False, 0.64), (True, 0.54)])
def test_filter_changes_few_harmless_random_actions(reach, bound):
    """Random actions, N = 6, β = 120°, robots spread in the arena: the filter steps in
    only where a neighbour (seen, or believed) or a wall is near. The first version's
    blanket motion cone changed 96% of them. Measured here: 60.9% with the shipped 0.5 m
    blind travel budget (per bearing, no leak, no credit for backing away, the glance
    outranking the FoV levels: its turns count, and it comes early, at ¾ B, only for a
    u* that keeps its course, ``look_persistence_deg``; 68.8% with every u* early);
    50.4% with the option that clears it
    while no neighbour can be near (``blind_travel_reach``, safety Section 2f; 49.2%
    clearing per bearing, not kept); 67% per bearing with the 30 s leak and no glance,
    50% with the single vector's, 43% with the earlier 1 m; 36% with no budget at all. The
    issue's goal of 30% is not met: the blind rows bound the speed towards the nearest
    particle of a belief, and the budget binds towards neighbours unseen for a few
    seconds, see the wrapper's docstring."""
    env = SafetyFilterWrapper(
        fov_coverage_v0.parallel_env(n_agents=6, fov_deg=120.0),
        controller_params={"blind_travel_reach": reach},
    )
    rng = np.random.default_rng(0)
    changed = total = 0
    for seed in range(2):
        env.reset(seed=seed)
        for _ in range(150):
            acts = {a: rng.uniform(-1, 1, 3).astype(np.float32) for a in env.agents}
            _, _, _, _, infos = env.step(acts)
            changed += sum(bool(safety_of(i)["intervened"]) for i in infos.values())
            total += len(infos)
    assert changed / total <= bound, changed / total


def test_commanded_velocity_is_the_one_the_robot_gets_at_a_wall():
    """A policy pushing 45° into the wall: the filter's wall rows stop the push, so the env
    never projects the robot (it does not slide sideways with an unapproved velocity)."""
    from fov_marl.geometry import integrate_unicycle
    from fov_marl.spaces import action_to_velocity

    poses = np.array([[20.0, 38.5, 0.0], [5.0, 5.0, 0.0]])
    # no blind travel budget: with it the robot stops after ~0.4 m to look at the bearings
    # beside its way (toward the wall, where a neighbour 1.15 m off could hide)
    env = SafetyFilterWrapper(
        fov_coverage_v0.parallel_env(n_agents=2, initial_poses=poses),
        controller_params={"blind_travel_m": 0.0},
    )
    env.reset(seed=0)
    cfg = env.config
    for _ in range(40):
        before = env.unwrapped.poses
        _, _, _, _, infos = env.step(
            {"robot_0": np.array([0.7, 0.7, 0.0], np.float32), "robot_1": np.zeros(3, np.float32)}
        )
        v, w = action_to_velocity(safety_of(infos["robot_0"])["applied_action"], 1.0, 1.5)
        free = integrate_unicycle(
            before[0], v * cfg.v_max_mps, w / 1.5 * cfg.omega_max_radps, cfg.dt_s
        )
        np.testing.assert_allclose(env.unwrapped.poses[0], free, atol=1e-9)
    assert env.unwrapped.poses[0, 0] > 23.0  # it kept moving along the wall


def test_filter_on_crossing_env():
    env = SafetyFilterWrapper(fov_crossing_v0.parallel_env())
    obs, _ = env.reset(seed=0)
    for _ in range(5):
        obs, *_ = env.step({a: np.zeros(3) for a in env.agents})
    assert set(obs) == set(env.possible_agents)


@pytest.mark.parametrize("fov_deg", [45.0, 90.0, 120.0, 360.0])
def test_blind_travel_budget_is_per_bearing_at_every_fov(fov_deg):
    """Both wrappers keep the budget per bearing (K = 24, no leak) at every β; an explicit
    ``blind_travel_bearings`` wins, the single vector then forgets travel only
    asin(2 r / D_s) = 30° inside the view (pfcbf: 10°) unless its margin is given too, and
    a dataclass is used as given."""
    from fov_marl.wrappers import VectorSafetyFilterWrapper

    env = fov_coverage_v0.parallel_env(n_agents=3, fov_deg=fov_deg)
    prm = SafetyFilterWrapper(env).pipeline.controller_params
    assert prm.blind_travel_bearings == 24 and prm.blind_travel_memory_s == math.inf
    venv = fov_coverage_v0.vector_env(num_envs=2, n_agents=3, fov_deg=fov_deg)
    vprm = VectorSafetyFilterWrapper(venv).pipeline.controller_params
    assert vprm == prm
    vec = SafetyFilterWrapper(env, controller_params={"blind_travel_bearings": 0})
    assert vec.pipeline.controller_params.blind_travel_view_deg == pytest.approx(30.0)
    kept = SafetyFilterWrapper(
        env, controller_params={"blind_travel_bearings": 0, "blind_travel_view_deg": 12.0}
    )
    assert kept.pipeline.controller_params.blind_travel_view_deg == 12.0
    forced = SafetyFilterWrapper(env, controller_params={"blind_travel_bearings": 36})
    assert forced.pipeline.controller_params.blind_travel_bearings == 36
    assert forced.pipeline.controller_params.blind_travel_view_deg == 10.0
    given = ControllerParams(blind_travel_m=0.5, blind_travel_bearings=12)
    assert SafetyFilterWrapper(env, controller_params=given).pipeline.controller_params is given


@pytest.mark.parametrize("make", ["per_copy", "vector"])
@pytest.mark.parametrize("range_m", [1.0, 2.0])
def test_filter_refuses_a_camera_that_cannot_see_to_ds(make, range_m):
    """Red team (N = 8, β = 120°, head_on, random start, seed 46000): a 1 m camera range
    (2 r) gave three collisions behind the filter, 2 m broke D_s. The filter keeps D_s only
    for neighbours it can see there: a range at or below D_s is a ValueError naming it."""
    from fov_marl.wrappers import VectorSafetyFilterWrapper

    kw = {"n_agents": 3, "detection_range_m": range_m}
    msg = rf"detection_range_m must be above safety_distance_m = 2 m .* got {range_m:g}"
    with pytest.raises(ValueError, match=msg):
        if make == "per_copy":
            SafetyFilterWrapper(fov_coverage_v0.parallel_env(**kw))
        else:
            VectorSafetyFilterWrapper(fov_coverage_v0.vector_env(num_envs=2, **kw))
    # just above D_s is accepted, and the env alone takes any range
    kw["detection_range_m"] = 2.01
    SafetyFilterWrapper(fov_coverage_v0.parallel_env(**kw))
    fov_coverage_v0.parallel_env(n_agents=3, detection_range_m=range_m)


def _pair_filter(poses, **controller_params):
    """Two robots at ``poses`` behind the filter with ``controller_params``, reset
    (seed 0); returns (env, its pipeline)."""
    env = SafetyFilterWrapper(
        fov_coverage_v0.parallel_env(n_agents=2, initial_poses=np.asarray(poses)),
        controller_params=controller_params,
    )
    env.reset(seed=0)
    return env, env.pipeline


def _drive_back(poses, reach, steps=20):
    """Robot 0 commands full speed backwards, robot 1 stands; returns (robot 0's x per
    step, robot-0 steps changed, min distance, the filter's pipeline)."""
    env, _ = _pair_filter(poses, blind_travel_reach=reach)
    xs, changed, dmin = [], 0, np.inf
    for _ in range(steps):
        _, _, _, _, infos = env.step(
            {"robot_0": np.array([-1.0, 0.0, 0.0], np.float32), "robot_1": np.zeros(3, np.float32)}
        )
        p = env.unwrapped.poses
        xs.append(p[0, 0])
        changed += bool(safety_of(infos["robot_0"])["intervened"])
        dmin = min(dmin, float(np.hypot(*(p[0, :2] - p[1, :2]))))
    return np.array(xs), changed, dmin, env.pipeline


def test_filter_lets_a_robot_back_away_where_no_neighbour_can_be():
    """Safety Section 2f: robot 0 backs away from its only neighbour, 14 m ahead (beyond
    R_d, known start). That neighbour can be nowhere within H = D_s + 2 B + 2 v_max dt of
    it, so every bearing counts as looked at: the filter changes none of its 20 steps
    (4 m back). Without the rule the 0.5 m budget turns it round to look after 0.4 m."""
    poses = np.array([[20.0, 20.0, 0.0], [34.0, 20.0, math.pi]])
    xs, changed, _, pipe = _drive_back(poses, reach=True)
    assert changed == 0 and 20.0 - xs[-1] > 3.9  # 0.98 m/s: the env's unicycle
    assert np.all(pipe._bearing_travel == 0.0)
    xs_off, changed_off, _, pipe_off = _drive_back(poses, reach=False)
    assert changed_off > 10 and 20.0 - xs_off[-1] < 1.0
    assert pipe_off._bearing_travel.max() > 0.0


def test_filter_still_budgets_a_robot_whose_neighbour_can_be_near():
    """The same robot with its neighbour 3.5 m behind it, unseen (each faces away): the
    neighbour's reachable disk is within H, so the budget counts as without the rule
    (the same approach per bearing after a step); the pair never comes within D_s. And a
    neighbour 14 m away whose disk has grown to H (10.2 s unseen at 1 m/s, the robot
    standing) stops clearing the budget."""
    poses = np.array([[20.0, 20.0, 0.0], [16.5, 20.0, math.pi]])
    _, _, dmin, _ = _drive_back(poses, reach=True, steps=40)
    assert dmin >= 2.0
    (x1,), _, _, pipe = _drive_back(poses, reach=True, steps=1)
    _, _, _, pipe_off = _drive_back(poses, reach=False, steps=1)
    c = pipe._bearing_travel[0]
    np.testing.assert_array_equal(c, pipe_off._bearing_travel[0])
    assert c.max() == pytest.approx(20.0 - x1, abs=1e-3) and c.max() > 0.1
    # the far neighbour, unseen (robot 1 faces away, beyond R_d): clear until its disk,
    # growing at v_max from the known start, reaches H = 2 + 1 + 0.4 = 3.4 m
    env, pipe = _pair_filter([[20.0, 20.0, 0.0], [34.0, 20.0, 0.0]], blind_travel_reach=True)
    spin = {"robot_0": np.array([0.0, 0.0, 0.0], np.float32), "robot_1": np.zeros(3, np.float32)}
    cleared = []
    for _ in range(60):
        pipe._bearing_travel[0] = 0.3  # as if spent: the rule zeroes it while it holds
        env.step(spin)
        cleared.append(bool(np.all(pipe._bearing_travel[0] == 0.0)))
    first_kept = cleared.index(False)
    assert all(cleared[:first_kept]) and not any(cleared[first_kept:])
    assert (first_kept + 1) * 0.2 == pytest.approx(14.0 - 3.4, abs=0.21)


@pytest.mark.parametrize("fov", [45.0, 120.0, 360.0])
def test_a_lone_robot_is_changed_only_by_the_walls(fov):
    """A one-robot team has no neighbour to meet blind: no budget rows, no look turn
    (red team 26: at 120° the budget and the look had cut a sideways drive in mid-arena
    from 0.98 to 0.08 m/s from the third step). It drives 15 steps sideways untouched;
    on towards the wall, the wall rows still slow it there (r = 0.5 m)."""
    env = SafetyFilterWrapper(
        fov_coverage_v0.parallel_env(
            n_agents=1, fov_deg=fov, max_cycles=80, initial_poses=[[20.0, 30.0, 0.0]]
        )
    )
    env.reset(seed=0)
    side = {"robot_0": np.array([0.0, 1.0, 0.0], np.float32)}
    for _ in range(15):
        _, _, _, _, infos = env.step(side)
        s = safety_of(infos["robot_0"])
        assert not s["intervened"] and s["causes"] == (), s
    assert env.unwrapped.poses[0, 1] > 30.0 + 15 * 0.2 * 0.98 - 1e-6
    walled = []
    for _ in range(50):  # 6.6 m to the wall at y = 39.5, 34 steps at 0.98 m/s
        _, _, _, _, infos = env.step(side)
        walled.append(safety_of(infos["robot_0"])["causes"])
    assert ("wall",) in walled
    assert env.unwrapped.poses[0, 1] <= 40.0 - 0.5 + 1e-9


def _look_pipe(persistence_deg: float):
    """A two-robot filter whose robot 0 has spent 0.4 m (80% of B) along every bearing."""
    env, pipe = _pair_filter(
        [[20.0, 20.0, 0.3], [30.0, 30.0, 0.0]], look_persistence_deg=persistence_deg
    )
    pipe._bearing_travel[:] = 0.4
    return env, pipe


def _looks(pipe, u_star_body) -> bool:
    """Whether the look before the leap changes robot 0's yaw rate for this u*."""
    u = np.array([u_star_body, [0.0, 0.0, 0.0]], dtype=np.float64)
    return bool(pipe._look_before_leap(u)[0, 2] != 0.0)


def test_the_early_look_waits_for_a_steady_course():
    """``look_persistence_deg`` (the filter's 45°): at 80% of the budget spent the look
    turns a robot whose u* keeps its course in Σ_w (within 45° of the last step's), not
    one whose u* changes course (a random action); once a bearing is spent it looks
    whatever the course. With 0 (pfcbf's) it looks early every time. Reset forgets the
    course."""
    env, pipe = _look_pipe(45.0)
    back = [-1.0, 0.0, 0.0]
    side = [0.0, -1.0, 0.0]
    assert not _looks(pipe, back)  # no course yet: waits for the spent budget
    assert _looks(pipe, back)  # the same course: the early look
    assert not _looks(pipe, side)  # 90° off the last course
    assert not _looks(pipe, back)
    assert _looks(pipe, [-1.0, 0.5, 0.0])  # 26.6° off the last course: steady
    # the robot's own yaw does not count: a body-frame u* turned with the robot keeps its
    # course in Σ_w
    pipe._own_pose[0, 2] += 0.5
    c, s = math.cos(-0.5), math.sin(-0.5)
    turned = [c * -1.0 - s * 0.5, s * -1.0 + c * 0.5, 0.0]  # [-1, 0.5] seen from the turn
    assert _looks(pipe, turned)
    pipe._own_pose[0, 2] += 1.0  # the same body-frame u* after a 57° turn: a new course
    assert not _looks(pipe, turned)
    pipe._bearing_travel[:] = 0.5  # spent: the look comes whatever the course
    assert _looks(pipe, side) and _looks(pipe, back)
    env.reset(seed=0)
    assert np.all(np.isnan(pipe._look_prev_world))
    _, pipe0 = _look_pipe(0.0)
    assert _looks(pipe0, back) and _looks(pipe0, side)
    with pytest.raises(
        ValueError, match=r"look_persistence_deg must be in \[0.0, 180.0\], got 200"
    ):
        SafetyFilterWrapper(
            fov_coverage_v0.parallel_env(n_agents=2),
            controller_params={"look_persistence_deg": 200.0},
        )
    with pytest.raises(ValueError, match=r"look_fraction must be in \(0.0, 1.0\]"):
        SafetyFilterWrapper(
            fov_coverage_v0.parallel_env(n_agents=2), controller_params={"look_fraction": 0.0}
        )
