"""fov_marl.adversaries: valid, seeded actions for every adversary; valid adversarial
starts; and the adversaries really do drive robots into each other without a filter."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fov_marl.adversaries import (
    Adversary,
    available_adversaries,
    available_starts,
    make_adversary,
    make_start_poses,
)
from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
from fov_marl.envs.fov_coverage_v0 import FovCoverageEnv
from fov_marl.infos import metrics_of
from fov_marl.wrappers import SafetyFilterWrapper

SHIPPED = {
    "straight",
    "charge_centre",
    "spin_charge",
    "chase_last_seen",
    "wait_charge",
    "head_on",
    "rush",
    "random",
}


def _rollout(env, adversary, seed: int, steps: int) -> list[dict[str, np.ndarray]]:
    """Actions of ``steps`` steps (or until the episode ends), checked for validity."""
    obs, _ = env.reset(seed=seed)
    adversary.reset(seed=seed)
    out = []
    for _ in range(steps):
        if not env.agents:
            break
        act = adversary.act(obs)
        assert set(act) == set(env.agents)
        for a, u in act.items():
            assert isinstance(u, np.ndarray) and u.dtype == np.float32 and u.shape == (3,), a
            assert np.all(np.isfinite(u)) and np.all(np.abs(u) <= 1.0), (a, u)
            assert env.action_space(a).contains(u)
        out.append(act)
        obs, *_ = env.step(act)
    return out


def test_registry_lists_the_shipped_adversaries_and_rejects_unknown_names():
    assert SHIPPED <= set(available_adversaries())
    assert available_adversaries() == sorted(available_adversaries())
    env = fov_coverage_v0.parallel_env(n_agents=2)
    for name in available_adversaries():
        assert isinstance(make_adversary(name, env), Adversary)
    with pytest.raises(ValueError, match="unknown adversary 'nope'.*straight"):
        make_adversary("nope", env)
    with pytest.raises(ValueError, match="wait_charge"):
        make_adversary("wait_charge", env, bogus=1)
    with pytest.raises(ValueError, match="wait_steps"):
        make_adversary("wait_charge", env, wait_steps=-1)
    with pytest.raises(ValueError, match="spin"):
        make_adversary("spin_charge", env, spin=2)
    with pytest.raises(ValueError, match="fov_marl environment"):
        make_adversary("straight", type("Fake", (), {"unwrapped": None})())


@pytest.mark.parametrize("name", sorted(SHIPPED | set(available_adversaries())))
def test_valid_actions_for_every_team_size_and_fov(name):
    for n in (1, 2, 6):
        for fov in (45.0, 120.0, 360.0):
            env = fov_coverage_v0.parallel_env(n_agents=n, fov_deg=fov, max_cycles=30)
            acts = _rollout(env, make_adversary(name, env), seed=3, steps=30)
            assert len(acts) == 30


def test_valid_actions_on_crossing_and_behind_the_filter():
    for name in available_adversaries():
        env = fov_crossing_v0.parallel_env(n_agents=3, fov_deg=90.0, max_cycles=15)
        _rollout(env, make_adversary(name, env), seed=1, steps=15)
    env = SafetyFilterWrapper(fov_coverage_v0.parallel_env(n_agents=3, max_cycles=10))
    for name in ("charge_centre", "chase_last_seen", "rush"):
        _rollout(env, make_adversary(name, env), seed=1, steps=10)


@pytest.mark.parametrize("name", available_adversaries())
def test_deterministic_under_a_seed(name):
    def run(seed):
        env = fov_coverage_v0.parallel_env(n_agents=4, fov_deg=90.0, max_cycles=40)
        acts = _rollout(env, make_adversary(name, env), seed=seed, steps=40)
        return np.array([[a[k] for k in sorted(a)] for a in acts])

    a, b = run(5), run(5)
    np.testing.assert_array_equal(a, b)
    if name in ("random", "spin_charge"):  # the seeded ones
        assert not np.array_equal(run(5), run(6))


@pytest.mark.parametrize("name", ["random", "straight"])
def test_reset_checks_its_seed(name):
    """Red team 26 (the policies' reset): numpy's own message, not naming ``seed``."""
    adv = make_adversary(name, fov_coverage_v0.parallel_env(n_agents=2))
    for bad in (-1, 1.5, "a"):
        with pytest.raises(ValueError, match="seed"):
            adv.reset(seed=bad)
    adv.reset(seed=None)


def test_documented_behaviours():
    cfg = fov_coverage_v0.parallel_env(n_agents=2).config
    # two robots on the x axis, 4 m apart, robot 0 facing +y (the other is to its right)
    poses = np.array([[18.0, 20.0, math.pi / 2], [22.0, 20.0, math.pi]])
    env = fov_coverage_v0.parallel_env(n_agents=2, fov_deg=120.0, initial_poses=poses)
    obs, _ = env.reset(seed=0)

    def first(name, **kw):
        adv = make_adversary(name, env, **kw)
        adv.reset(seed=0)
        return adv.act(obs)

    np.testing.assert_array_equal(first("straight")["robot_0"], [1, 0, 0])
    # head_on: sideways (body -y), no turning, full speed
    np.testing.assert_allclose(first("head_on")["robot_0"], [0, -1, 0], atol=1e-6)
    # charge_centre: towards the midpoint, turning towards it at full rate
    u = first("charge_centre")["robot_0"]
    assert u[1] < -0.9 and u[2] == -1.0 and np.hypot(u[0], u[1]) == pytest.approx(1, abs=1e-6)
    u = first("spin_charge", spin=1)["robot_0"]
    assert u[2] == 1.0 and np.hypot(u[0], u[1]) == pytest.approx(1, abs=1e-6)
    # wait_charge stands still first
    np.testing.assert_array_equal(first("wait_charge", wait_steps=3)["robot_0"], [0, 0, 0])
    # robot 1 faces robot 0 (4 m ahead): chase_last_seen drives straight at it
    u = first("chase_last_seen")["robot_1"]
    assert u[0] > 0.95 and abs(u[2]) < 0.5
    # robot 0 sees no one yet: straight ahead
    np.testing.assert_array_equal(first("chase_last_seen")["robot_0"], [1, 0, 0])
    # rush: towards q_m = (20, 20), i.e. to robot 0's right, full speed
    u = first("rush")["robot_0"]
    assert u[1] < -0.9 and cfg.density_mean_m == (20.0, 20.0)


def test_spin_charge_step_moves_straight_at_the_centroid():
    """The pre-rotation makes the integrated step move straight at the target."""
    poses = np.array([[10.0, 10.0, 0.3], [30.0, 30.0, 2.0]])
    env = fov_coverage_v0.parallel_env(n_agents=2, initial_poses=poses)
    obs, _ = env.reset(seed=0)
    adv = make_adversary("spin_charge", env, spin=1)
    adv.reset(seed=0)
    before = env.poses.copy()
    env.step(adv.act(obs))
    step = env.poses[:, :2] - before[:, :2]
    to_centre = before[:, :2].mean(0) - before[:, :2]
    cos = (
        np.sum(step * to_centre, 1)
        / np.linalg.norm(step, axis=1)
        / np.linalg.norm(to_centre, axis=1)
    )
    np.testing.assert_allclose(cos, 1.0, atol=1e-6)  # float32 actions
    # chord of an arc of angle ω dt at speed v_max: 2 sin(ω dt / 2) / ω
    np.testing.assert_allclose(np.linalg.norm(step, axis=1), 2 * math.sin(0.15) / 1.5, rtol=1e-6)


class _GuardedEnv(FovCoverageEnv):
    """Ground truth refused after reset: what an honest policy must live with."""

    guard = False

    @property
    def poses(self):
        if self.guard:
            raise AssertionError("ground truth read")
        return super().poses


@pytest.mark.parametrize("name", ["chase_last_seen", "rush", "straight", "random"])
def test_observation_only_adversaries_never_read_ground_truth(name):
    env = _GuardedEnv(n_agents=4, fov_deg=120.0, max_cycles=30)
    adv = make_adversary(name, env)
    obs, _ = env.reset(seed=2)
    adv.reset(seed=2)
    env.guard = True
    for _ in range(30):
        obs, *_ = env.step(adv.act(obs))


# -------------------------------------------------------------------- starts
def _check_start(start: str, n: int, seed: int, **kw) -> np.ndarray | None:
    env = fov_coverage_v0.parallel_env(n_agents=n)
    cfg = env.config
    poses = make_start_poses(start, cfg, np.random.default_rng(seed), **kw)
    if start == "random":
        assert poses is None
        return None
    assert poses.shape == (n, 3) and np.all(np.isfinite(poses))
    r, L = cfg.robot_radius_m, cfg.arena_size_m
    assert np.all(poses[:, :2] >= r) and np.all(poses[:, :2] <= L - r)
    assert np.all(np.abs(poses[:, 2]) <= math.pi)
    if n > 1:
        d = np.linalg.norm(poses[:, None, :2] - poses[None, :, :2], axis=-1)
        np.fill_diagonal(d, np.inf)
        assert d.min() >= cfg.collision_distance_m + 0.1 - 1e-9, (start, n, d.min())
    # the env accepts them and starts there
    env = fov_coverage_v0.parallel_env(n_agents=n, initial_poses=poses)
    env.reset(seed=0)
    np.testing.assert_allclose(env.poses[:, :2], poses[:, :2])
    again = make_start_poses(start, cfg, np.random.default_rng(seed), **kw)
    np.testing.assert_array_equal(poses, again)
    return poses


@pytest.mark.parametrize("start", available_starts())
def test_starts_are_inside_the_arena_separated_and_seeded(start):
    assert set(available_starts()) >= {"random", "clustered", "corner", "wall", "head_on_pair"}
    for n in (1, 2, 4, 8, 12, 24):
        if start == "head_on_pair" and n < 2:
            continue
        for seed in range(3):
            _check_start(start, n, seed)


def test_start_geometry():
    cfg = fov_coverage_v0.parallel_env(n_agents=24).config
    L = cfg.arena_size_m
    # clustered: inside the 6 m square around the centre; packed closer than D_s
    p = _check_start("clustered", 24, 0)
    assert np.all(np.abs(p[:, :2] - L / 2) <= 3.0)
    # corner: every robot within a few metres of one corner, facing it
    p = _check_start("corner", 12, 1)
    corners = np.array([[0, 0], [L, 0], [L, L], [0, L]], dtype=float)
    k = np.argmin(np.linalg.norm(corners - p[:, :2].mean(0), axis=1))
    assert np.all(np.linalg.norm(p[:, :2] - corners[k], axis=1) < 6.0)
    aim = np.arctan2(corners[k, 1] - p[:, 1], corners[k, 0] - p[:, 0])
    np.testing.assert_allclose(np.cos(aim - p[:, 2]), 1.0, atol=1e-9)
    # wall: one row at 0.55 m from a wall, facing it
    p = _check_start("wall", 8, 2)
    gaps = np.column_stack([p[:, 0], L - p[:, 0], p[:, 1], L - p[:, 1]])
    w = np.argmin(gaps.min(0))
    np.testing.assert_allclose(gaps[:, w], cfg.robot_radius_m + 0.05)
    out_rad = [math.pi, 0.0, -math.pi / 2, math.pi / 2][w]
    np.testing.assert_allclose(np.cos(p[:, 2] - out_rad), 1.0, atol=1e-9)
    p = _check_start("wall", 4, 2, facing="each_other")
    assert np.allclose(np.cos(p[0, 2] - p[1, 2]), -1.0)
    # head_on_pair: 2.6 m apart, facing each other; the others far away
    p = _check_start("head_on_pair", 8, 3)
    d = p[1, :2] - p[0, :2]
    assert np.hypot(*d) == pytest.approx(2.6)
    assert math.cos(math.atan2(d[1], d[0]) - p[0, 2]) == pytest.approx(1.0)
    assert math.cos(p[1, 2] - p[0, 2]) == pytest.approx(-1.0)
    assert np.all(np.linalg.norm(p[2:, :2] - L / 2, axis=1) >= 8.0)


def test_bad_starts_raise_naming_the_problem():
    cfg = fov_coverage_v0.parallel_env(n_agents=4).config
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="unknown start 'x'.*clustered"):
        make_start_poses("x", cfg, rng)
    with pytest.raises(ValueError, match="clustered.*side_m"):
        make_start_poses("clustered", cfg, rng, gap_m=1)
    with pytest.raises(ValueError, match="facing"):
        make_start_poses("wall", cfg, rng, facing="up")
    with pytest.raises(ValueError, match="side_m"):
        big = fov_coverage_v0.parallel_env(n_agents=60).config
        make_start_poses("clustered", big, rng)
    with pytest.raises(ValueError, match="n_agents >= 2"):
        make_start_poses("head_on_pair", fov_coverage_v0.parallel_env(n_agents=1).config, rng)


# --------------------------------------------------------- the adversaries bite
def _unfiltered_collisions(name: str, start: str, n: int, fov: float, steps: int, seed=0) -> int:
    cfg = fov_coverage_v0.parallel_env(n_agents=n).config
    poses = make_start_poses(start, cfg, np.random.default_rng(seed))
    env = fov_coverage_v0.parallel_env(
        n_agents=n, fov_deg=fov, initial_poses=poses, max_cycles=steps
    )
    adv = make_adversary(name, env)
    obs, infos = env.reset(seed=seed)
    adv.reset(seed=seed)
    while env.agents:
        obs, _, _, _, infos = env.step(adv.act(obs))
    return metrics_of(next(iter(infos.values())))["collisions_total"]


@pytest.mark.parametrize("name", ["straight", "head_on", "charge_centre", "chase_last_seen"])
def test_unfiltered_head_on_pair_collides(name):
    """Without a filter, the pair 2.6 m apart, facing each other, collides (within 2 s)."""
    assert _unfiltered_collisions(name, "head_on_pair", 2, 120.0, steps=10) >= 1


@pytest.mark.parametrize(
    "name,start",
    [
        ("charge_centre", "clustered"),
        ("spin_charge", "clustered"),
        ("wait_charge", "random"),
        ("rush", "random"),
        ("head_on", "wall"),
        ("wall_slide", "wall"),
    ],
)
def test_unfiltered_charges_collide(name, start):
    assert _unfiltered_collisions(name, start, 4, 120.0, steps=150) >= 1
