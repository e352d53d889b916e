"""The vector env (batched core): copy k == parallel_env(seed=s+k), autoreset, spaces, errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
from fov_marl.envs.core import noise_chunk_steps
from fov_marl.infos import metrics_of
from fov_marl.validation import ConfigError

MODULES = [fov_coverage_v0, fov_crossing_v0]
ids = lambda m: m.__name__.rsplit(".", 1)[-1]  # noqa: E731


def _actions(rng: np.random.Generator, T: int, B: int, N: int) -> np.ndarray:
    return rng.uniform(-1.2, 1.2, (T, B, N, 3)).astype(np.float32)


def _compare_copies(mod, B: int, seed: int, T: int, **cfg) -> int:
    """Step a vector env and B ParallelEnvs with the same actions; return #autoresets.

    Each ParallelEnv is reset without a seed when its episode ends, which is what the
    vector env's same-step autoreset must reproduce bit for bit.
    """
    venv = mod.vector_env(num_envs=B, **cfg)
    envs = [mod.parallel_env(**cfg) for _ in range(B)]
    obs, infos = venv.reset(seed=seed)
    N = venv.n_agents
    for k, e in enumerate(envs):
        o, inf = e.reset(seed=seed + k)
        np.testing.assert_array_equal(obs[k], np.stack([o[a] for a in e.possible_agents]))
        for key, v in metrics_of(inf["robot_0"]).items():
            assert infos["metrics"][key][k] == v, key
    acts = _actions(np.random.default_rng(seed), T, B, N)
    resets = 0
    for t in range(T):
        obs, rew, term, trunc, infos = venv.step(acts[t])
        assert obs.dtype == np.float32 and obs.shape == (
            B,
            N,
            venv.single_observation_space.shape[0],
        )
        assert rew.dtype == np.float32 and rew.shape == (B, N)
        assert term.dtype == bool and trunc.dtype == bool and term.shape == (B, N)
        for k, e in enumerate(envs):
            names = e.possible_agents
            o, r, te, tr, inf = e.step(dict(zip(names, acts[t, k], strict=True)))
            last = np.stack([o[a] for a in names])
            np.testing.assert_array_equal(rew[k], np.float32([r[a] for a in names]))
            assert list(term[k]) == [te[a] for a in names]
            assert list(trunc[k]) == [tr[a] for a in names]
            for key, v in metrics_of(inf["robot_0"]).items():
                assert infos["metrics"][key][k] == v, (t, k, key)
            if not e.agents:  # finished: final obs kept, obs is the next episode's first
                resets += 1
                assert infos["_final_obs"][k]
                np.testing.assert_array_equal(infos["final_obs"][k], last)
                o, inf = e.reset()
                np.testing.assert_array_equal(obs[k], np.stack([o[a] for a in names]))
                for key, v in metrics_of(inf["robot_0"]).items():
                    assert infos["reset_metrics"][key][k] == v, key
                np.testing.assert_array_equal(venv.poses[k], e.poses)
            else:
                assert not infos["_final_obs"][k]
                assert not infos["final_obs"][k].any()
                np.testing.assert_array_equal(obs[k], last)
                np.testing.assert_array_equal(venv.poses[k], e.poses)
        np.testing.assert_array_equal(venv.state(), np.stack([e.state() for e in envs]))
    return resets


@pytest.mark.parametrize("mod", MODULES, ids=ids)
def test_copies_equal_parallel_envs_across_autoresets(mod):
    # max_cycles 23 with 60 steps: two autoresets, the second mid-chunk of the noise buffer
    resets = _compare_copies(mod, B=3, seed=11, T=60, n_agents=4, max_cycles=23)
    assert resets == 3 * 2


def test_crossing_early_terminations_at_different_steps():
    # tolerance near the start distance: copies terminate at different steps
    cfg = dict(n_agents=3, max_cycles=40, target_tolerance_m=3.4, crossing_radius_m=1.5)
    resets = _compare_copies(fov_crossing_v0, B=6, seed=0, T=30, **cfg)
    assert resets >= 6


@pytest.mark.parametrize("mod", MODULES, ids=ids)
def test_one_robot_and_full_fov(mod):
    _compare_copies(mod, B=2, seed=5, T=12, n_agents=1, max_cycles=5)
    _compare_copies(mod, B=2, seed=6, T=12, n_agents=5, fov_deg=360.0, max_cycles=8)


def test_noise_chunk_longer_than_an_episode_and_a_chunk_boundary():
    # N = 2: 64 observations per noise chunk; episodes of 70 steps cross a chunk
    assert noise_chunk_steps(2, 2) == 64
    _compare_copies(fov_coverage_v0, B=2, seed=3, T=150, n_agents=2, max_cycles=70)


def test_noise_chunks_are_bounded():
    assert noise_chunk_steps(1, 100) == 2
    assert noise_chunk_steps(4096, 6) == 18
    assert noise_chunk_steps(64, 400) == 1


def test_unseeded_reset_continues_and_reseeding_repeats():
    venv = fov_coverage_v0.vector_env(num_envs=2, n_agents=3)
    env = fov_coverage_v0.parallel_env(n_agents=3)
    venv.reset(seed=4)
    env.reset(seed=5)
    for _ in range(7):
        venv.step(np.zeros((2, 3, 3)))
        env.step({a: np.zeros(3) for a in env.agents})
    p0 = venv.poses
    venv.reset()  # mid-episode, no seed: continues each generator (mid noise chunk)
    env.reset()
    np.testing.assert_array_equal(venv.poses[1], env.poses)
    assert not np.array_equal(p0, venv.poses)
    venv.reset(seed=4)
    e0 = fov_coverage_v0.parallel_env(n_agents=3)
    e0.reset(seed=4)
    np.testing.assert_array_equal(venv.poses[0], e0.poses)
    env.reset(seed=5)
    np.testing.assert_array_equal(venv.poses[1], env.poses)


def test_reset_with_a_seed_per_copy():
    venv = fov_crossing_v0.vector_env(num_envs=3)
    obs, _ = venv.reset(seed=[7, None, 9])
    env = fov_crossing_v0.parallel_env()
    o, _ = env.reset(seed=9)
    np.testing.assert_array_equal(obs[2], np.stack([o[a] for a in env.possible_agents]))
    o, _ = env.reset(seed=7)
    np.testing.assert_array_equal(obs[0], np.stack([o[a] for a in env.possible_agents]))


@pytest.mark.parametrize("mod", MODULES, ids=ids)
def test_spaces_and_attributes(mod):
    venv = mod.vector_env(num_envs=5, n_agents=4, fov_deg=90.0)
    env = mod.parallel_env(n_agents=4, fov_deg=90.0)
    a = env.possible_agents[0]
    assert venv.num_envs == 5 and venv.n_agents == 4
    assert venv.possible_agents == env.possible_agents
    assert venv.config == env.config
    assert venv.single_observation_space == env.observation_space(a)
    assert venv.single_action_space == env.action_space(a)
    assert venv.observation_space.shape == (5, 4, 5 * 3 + 7)
    assert venv.action_space.shape == (5, 4, 3)
    obs, infos = venv.reset(seed=0)
    assert venv.observation_space.contains(obs)
    assert set(infos["metrics"]) == set(env.reset(seed=0)[1][a]["metrics"])
    for v in infos["metrics"].values():
        assert v.shape == (5,)
    p = venv.poses
    assert p.shape == (5, 4, 3) and not p.flags.writeable
    assert (venv.targets is None) == (mod is fov_coverage_v0)
    for _ in range(3):
        obs, *_ = venv.step(venv.action_space.sample())
        assert venv.observation_space.contains(obs)
    assert venv.state().shape == (5, env.state_space.shape[0])
    venv.close()


@pytest.mark.parametrize("mod", MODULES, ids=ids)
def test_autoreset_convention(mod):
    venv = mod.vector_env(num_envs=2, n_agents=3, max_cycles=4)
    venv.reset(seed=1)
    for t in range(1, 9):
        obs, rew, term, trunc, infos = venv.step(np.ones((2, 3, 3)))
        ended = t % 4 == 0
        assert trunc.all() == ended and not term.any()
        assert list(infos["_final_obs"]) == [ended, ended]
        assert ("reset_metrics" in infos) == ended
        np.testing.assert_array_equal(venv.num_steps, [0 if ended else t % 4] * 2)
        if ended:
            assert infos["final_obs"].any() and not np.array_equal(infos["final_obs"], obs)
            assert np.all(infos["reset_metrics"]["t_s"] == 0.0)
            assert np.all(infos["metrics"]["t_s"] == 4 * venv.config.dt_s)


def test_max_cycles_is_settable():
    venv = fov_coverage_v0.vector_env(num_envs=2, n_agents=2)
    venv.max_cycles = 2
    venv.reset(seed=0)
    venv.step(np.zeros((2, 2, 3)))
    *_, trunc, infos = venv.step(np.zeros((2, 2, 3)))
    assert trunc.all() and infos["_final_obs"].all()


@pytest.mark.parametrize("value", ["10", -3, 0, 2.5, True, None], ids=repr)
def test_bad_max_cycles_is_refused_before_anything_steps(value):
    """Setting ``max_cycles`` to a non-integer or < 1 is a ValueError naming it, on the
    vector env and on the ParallelEnv; the env keeps its value and steps as before (a
    string used to be accepted and the next step failed after moving the world)."""
    venv = fov_coverage_v0.vector_env(num_envs=2, n_agents=2)
    env = fov_coverage_v0.parallel_env(n_agents=2)
    for e in (venv, env):
        with pytest.raises(ValueError, match=r"max_cycles must be an integer in \[1, inf\)"):
            e.max_cycles = value
        assert e.max_cycles == 1000
    venv.max_cycles = np.int64(3)
    assert venv.max_cycles == 3 and type(venv.max_cycles) is int


@pytest.mark.parametrize(
    "num_envs", [0, -3, 2.0, "4", True, None, [2]], ids=lambda v: f"num_envs={v!r}"
)
def test_bad_num_envs(num_envs):
    with pytest.raises(ValueError, match="num_envs must be an integer in \\[1, inf\\)"):
        fov_coverage_v0.vector_env(num_envs=num_envs)


@pytest.mark.parametrize("mod", [fov_coverage_v0, fov_crossing_v0])
def test_too_many_copies_for_memory_is_a_value_error(mod):
    """Not numpy's bare MemoryError: the message names num_envs."""
    with pytest.raises(ValueError, match=r"num_envs = 1000000000000 copies of 2 robots"):
        mod.vector_env(num_envs=10**12, n_agents=2)


def test_shard_api_and_render_with_one_process():
    """get_attr / set_attr / call / shard_starts exist with workers = 1 too (one shard),
    so code written for SubprocVectorEnv runs unchanged; render() warns and returns None
    (a vector env has no render mode) instead of an AttributeError."""
    venv = fov_crossing_v0.vector_env(num_envs=3, n_agents=2, eta_method="exact")
    venv.reset(seed=0)
    assert venv.shard_starts == (0, 3)
    assert venv.get_attr("max_cycles") == [1000]
    venv.set_attr("max_cycles", 7)
    assert venv.max_cycles == 7
    (state,) = venv.call("state")
    np.testing.assert_array_equal(state, venv.state())
    for bad in (3, None):
        with pytest.raises(ValueError, match="name must be a str"):
            venv.get_attr(bad)
    with pytest.raises(ValueError, match="max_cycles"):
        venv.set_attr("max_cycles", 0)
    with pytest.warns(UserWarning, match="does not render"):
        assert venv.render() is None
    with pytest.raises(ValueError, match="eta_method applies to the coverage scenario"):
        fov_crossing_v0.vector_env(num_envs=1, eta_method="strip")


def test_bad_config_names_the_field():
    with pytest.raises(ValueError, match="fov_deg"):
        fov_coverage_v0.vector_env(num_envs=2, fov_deg=-1.0)
    with pytest.raises(ValueError, match="no_such_field"):
        fov_crossing_v0.vector_env(num_envs=2, no_such_field=1)
    with pytest.raises(ValueError, match="scenario is fixed"):
        fov_crossing_v0.vector_env(num_envs=2, scenario="coverage")
    fov_crossing_v0.vector_env(num_envs=2, scenario="crossing")


@pytest.mark.parametrize(
    "actions, match",
    [
        (np.zeros((2, 3, 2)), "shape"),
        (np.zeros((3, 3, 3)), "shape"),
        (np.zeros((3, 3)), "shape"),
        (np.zeros(3), "shape"),
        ([[["a", "b", "c"]] * 3] * 2, "dtype"),
        (np.ones((2, 3, 3), dtype=bool), "dtype"),
        # red team 25: a copy's rows as a bool array in a list (np.asarray made them 1.0)
        ([np.ones((3, 3), dtype=bool), np.zeros((3, 3))], "bool"),
        ([[[np.array(True), 0.0, 0.0]] * 3, [[0.0] * 3] * 3], "bool"),
        (np.ones((2, 3, 3), dtype=complex), "dtype"),
        (np.full((2, 3, 3), None), "dtype"),
        ([[[0, 0]] * 3] * 2 + [[[0, 0, 0]] * 3], "actions"),
        (np.full((2, 3, 3), np.nan), "finite"),
        (np.where(np.arange(18).reshape(2, 3, 3) == 13, np.inf, 0.0), "actions\\[1, 1\\]"),
    ],
    ids=lambda v: str(getattr(v, "shape", v))[:20],
)
def test_bad_actions_name_the_field(actions, match):
    venv = fov_coverage_v0.vector_env(num_envs=2, n_agents=3)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match="actions") as exc:
        venv.step(actions)
    assert exc.match(match)


def test_step_before_reset_and_bad_seed():
    venv = fov_coverage_v0.vector_env(num_envs=2)
    with pytest.raises(ValueError, match="reset"):
        venv.step(np.zeros((2, 6, 3)))
    for bad in (-1, 1.5, "3", [1, 2, 3], [1, -2], np.array(-1), np.array(1.5)):
        with pytest.raises(ValueError, match="seed"):
            venv.reset(seed=bad)
    # a 0-d integer array is its scalar (it raised TypeError)
    a, _ = venv.reset(seed=np.array(3))
    b, _ = venv.reset(seed=3)
    np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="options"):
        venv.reset(seed=0, options=[1])


def test_integer_actions_are_accepted():
    venv = fov_coverage_v0.vector_env(num_envs=2, n_agents=2)
    env = fov_coverage_v0.parallel_env(n_agents=2)
    venv.reset(seed=3)
    env.reset(seed=4)
    a = np.array([[[1, 0, -1], [0, 1, 1]]] * 2)
    venv.step(a)
    env.step({"robot_0": a[1, 0], "robot_1": a[1, 1]})
    np.testing.assert_array_equal(venv.poses[1], env.poses)


@settings(max_examples=15, deadline=None)
@given(
    mod=st.sampled_from(MODULES),
    B=st.integers(1, 4),
    n=st.integers(1, 5),
    fov=st.sampled_from([45.0, 120.0, 250.0, 360.0]),
    max_cycles=st.integers(1, 6),
    seed=st.integers(0, 2**31),
)
def test_hypothesis_copies_match(mod, B, n, fov, max_cycles, seed):
    _compare_copies(mod, B=B, seed=seed, T=8, n_agents=n, fov_deg=fov, max_cycles=max_cycles)


@pytest.mark.parametrize("steps", [0, 5, 63, 64, 65, 130])
def test_unseeded_reset_continues_the_generator_exactly(steps):
    # independent oracle: one generator drawing what the env draws, in the env's order
    from fov_marl.envs.world import sample_initial_poses

    n = 2  # 64 observations per noise chunk: steps cross chunk boundaries
    env = fov_coverage_v0.parallel_env(n_agents=n, max_cycles=1000)
    venv = fov_coverage_v0.vector_env(num_envs=2, n_agents=n, max_cycles=1000)
    env.reset(seed=21)
    venv.reset(seed=20)
    for _ in range(steps):
        env.step({a: np.zeros(3) for a in env.agents})
        venv.step(np.zeros((2, n, 3)))
    env.reset()
    venv.reset()
    rng = np.random.default_rng(21)
    sample_initial_poses(env.config, rng)
    rng.standard_normal((steps + 1) * n * n * 3)  # one observation per step and at reset
    expected = sample_initial_poses(env.config, rng)
    np.testing.assert_array_equal(env.poses, expected)
    np.testing.assert_array_equal(venv.poses[1], expected)


def test_strip_eta_method_changes_only_eta_and_the_reward():
    from fov_marl.metrics import StripCoverageMetric

    cfg = dict(n_agents=4, max_cycles=50, collision_penalty=0.0, safety_penalty=0.0)
    fast = fov_coverage_v0.vector_env(num_envs=2, eta_method="strip", **cfg)
    exact = fov_coverage_v0.vector_env(num_envs=2, **cfg)
    strip = StripCoverageMetric(fast.config)
    o1, i1 = fast.reset(seed=2)
    o2, i2 = exact.reset(seed=2)
    np.testing.assert_array_equal(o1, o2)
    eta_prev = i1["metrics"]["eta"]
    np.testing.assert_array_equal(eta_prev, strip.eta_batch(fast.poses[..., :2]))
    acts = _actions(np.random.default_rng(0), 10, 2, 4)
    for t in range(10):
        o1, r1, *_, i1 = fast.step(acts[t])
        o2, r2, *_, i2 = exact.step(acts[t])
        np.testing.assert_array_equal(o1, o2)  # same dynamics and camera stream
        eta = strip.eta_batch(fast.poses[..., :2])
        np.testing.assert_array_equal(i1["metrics"]["eta"], eta)
        assert np.abs(eta - i2["metrics"]["eta"]).max() < 4e-3
        want = np.float32(100.0 * (eta - eta_prev))[:, None]
        np.testing.assert_array_equal(r1, np.broadcast_to(want, r1.shape))
        eta_prev = eta
    with pytest.raises(ValueError, match="eta_method must be one of"):
        fov_coverage_v0.vector_env(num_envs=2, eta_method="coarse")
    with pytest.raises(ValueError, match="eta_method"):
        fov_crossing_v0.FovVectorEnv.from_config(fov_crossing_v0.parallel_env().config, 2, "strip")


def test_batched_camera_pieces_equal_the_single_ones():
    from fov_marl.envs.world import Camera
    from fov_marl.geometry import relative_pose, relative_pose_batch

    cfg = fov_coverage_v0.parallel_env(n_agents=7, fov_deg=100.0).config
    cam = Camera(cfg)
    rng = np.random.default_rng(4)
    poses = np.concatenate([rng.uniform(0, 40, (5, 7, 2)), rng.uniform(-4, 4, (5, 7, 1))], -1)
    rel_b, det_b = cam.detect_batch(poses)
    rel_all = relative_pose_batch(poses)
    noise = np.clip(rng.standard_normal((5, 7, 7, 3)), -5, 5)
    blocks = cam.neighbour_blocks_from_noise(poses, noise)
    assert blocks.shape == (5, 7, 6, 5) and det_b.any() and not det_b.all()
    for b in range(5):
        rel, det = cam.detect(poses[b])
        np.testing.assert_array_equal(rel_b[b], rel)
        np.testing.assert_array_equal(rel_all[b], relative_pose(poses[b]))
        np.testing.assert_array_equal(det_b[b], det)
        np.testing.assert_array_equal(
            blocks[b], cam.neighbour_blocks_from_noise(poses[b], noise[b])
        )


def _one_attempt_placement(config, rng):
    """The placement before restarts (reference): one sequential dart throw, or None."""
    n, L, r = config.n_agents, config.arena_size_m, config.robot_radius_m
    lo, hi = r + 0.5, L - r - 0.5
    pos = np.empty((n, 2))
    for i in range(n):
        for _ in range(100):
            cand = rng.uniform(lo, hi, size=(100, 2))
            ok = np.array(
                [all(np.hypot(*(c - pos[j])) >= config.init_min_separation_m for j in range(i))
                 for c in cand]
            )  # fmt: skip
            if ok.any():
                pos[i] = cand[np.argmax(ok)]
                break
        else:
            return None
    return np.column_stack([pos, rng.uniform(-np.pi, np.pi, size=n)])


def test_random_starts_place_every_team_the_packing_bound_allows():
    """N = 3 at 3 m in a 6 m arena fits (three corners of the 4 m square of start
    positions) and passes the config's bound, but one dart throw failed ~19% of seeds:
    a failed reset, in a vector env a failed step. Restarts place every seed, and a
    seed whose first throw succeeds keeps exactly its poses."""
    from fov_marl.config import make_config
    from fov_marl.envs.world import sample_initial_poses

    cfg = make_config(scenario="coverage", n_agents=3, arena_size_m=6.0)
    restarted = 0
    for seed in range(150):
        ref = _one_attempt_placement(cfg, np.random.default_rng(seed))
        got = sample_initial_poses(cfg, np.random.default_rng(seed))
        if ref is not None:
            np.testing.assert_array_equal(got, ref)
        else:
            restarted += 1
        d = np.hypot(*(got[:, None, :2] - got[None, :, :2]).transpose(2, 0, 1))
        assert np.all(d[~np.eye(3, dtype=bool)] >= 3.0)
        assert np.all((got[:, :2] >= 1.0) & (got[:, :2] <= 5.0))
    assert restarted >= 10  # the restarts were exercised
    # a team that cannot fit still fails, naming the fields, and promptly
    tight = make_config(scenario="coverage", n_agents=5, arena_size_m=6.0)
    with pytest.raises(ValueError, match="could not place 5 robots.*initial_poses"):
        sample_initial_poses(tight, np.random.default_rng(0))
    venv = fov_coverage_v0.vector_env(num_envs=4, n_agents=3, arena_size_m=6.0, max_cycles=2)
    venv.reset(seed=[0, 1, 2, 3])
    for _ in range(12):  # the red team's case: steps 1-3 and 8-10 raised
        venv.step(np.zeros((4, 3, 3)))


def test_a_failed_automatic_reset_stops_the_vector_env_until_reset(monkeypatch):
    import fov_marl.envs.core as core

    venv = fov_coverage_v0.vector_env(num_envs=2, n_agents=2, max_cycles=1)
    venv.reset(seed=0)

    def no_room(config, rng):
        raise ValueError("no room")

    monkeypatch.setattr(core, "sample_initial_poses", no_room)
    with pytest.raises(ConfigError, match="no room"):
        venv.step(np.zeros((2, 2, 3)))  # every copy stepped; the finished ones cannot reset
    poses, steps = venv.poses, venv.num_steps
    with pytest.raises(ValueError, match=r"last step\(\) failed"):
        venv.step(np.zeros((2, 2, 3)))
    np.testing.assert_array_equal(venv.poses, poses)  # nothing stepped on
    np.testing.assert_array_equal(venv.num_steps, steps)
    with pytest.raises(ConfigError, match="no room"):
        venv.reset(seed=0)
    with pytest.raises(ValueError, match=r"last reset\(\) failed"):
        venv.step(np.zeros((2, 2, 3)))
    monkeypatch.undo()
    obs, _ = venv.reset(seed=0)
    ref = fov_coverage_v0.vector_env(num_envs=2, n_agents=2, max_cycles=1)
    np.testing.assert_array_equal(obs, ref.reset(seed=0)[0])
    np.testing.assert_array_equal(
        venv.step(np.zeros((2, 2, 3)))[0], ref.step(np.zeros((2, 2, 3)))[0]
    )


def test_close_marks_the_vector_env_closed():
    venv = fov_crossing_v0.vector_env(num_envs=2, n_agents=2)
    venv.reset(seed=0)
    assert not venv.closed
    venv.close()
    venv.close()  # idempotent
    assert venv.closed
    with pytest.raises(ValueError, match="closed"):
        venv.step(np.zeros((2, 2, 3)))
    with pytest.raises(ValueError, match="closed"):
        venv.reset(seed=0)


def test_metadata_names_gymnasiums_autoreset_mode():
    vector = pytest.importorskip("gymnasium.vector")
    mode = fov_coverage_v0.vector_env(num_envs=1).metadata["autoreset_mode"]
    if hasattr(vector, "AutoresetMode"):
        assert mode == vector.AutoresetMode.SAME_STEP
    else:  # Gymnasium 1.0
        assert mode == "SameStep"
