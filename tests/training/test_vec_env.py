"""The parameter-sharing VecEnv adapter against SB3's VecEnv contract and against
independently stepped env copies (the reference)."""

from __future__ import annotations

import functools

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from pettingzoo import ParallelEnv  # noqa: E402
from pettingzoo.utils.wrappers import BaseParallelWrapper  # noqa: E402
from stable_baselines3.common.env_checker import check_env  # noqa: E402
from stable_baselines3.common.vec_env import (  # noqa: E402
    DummyVecEnv,
    VecCheckNan,
    VecMonitor,
    VecNormalize,
)

from fov_marl.envs import fov_coverage_v0, fov_crossing_v0  # noqa: E402
from fov_marl.infos import metrics_of  # noqa: E402
from fov_marl.training.vec_env import (  # noqa: E402
    ParallelEnvVecEnv,
    VectorEnvVecEnv,
    make_parallel_vec_env,
    make_vector_vec_env,
    wrapper_chain,
)

N = 3


def _cov(**kw):
    return fov_coverage_v0.parallel_env(**{"n_agents": N, "max_cycles": 7, **kw})


def _actions(rng, venv, scale=1.0):
    return (scale * rng.uniform(-1, 1, (venv.num_envs, 3))).astype(np.float32)


class _SingleAgentGym(gym.Env):
    """Reference: a 1-agent ParallelEnv as a gymnasium Env, for SB3's DummyVecEnv."""

    metadata = {"render_modes": []}

    def __init__(self, penv):
        self.penv = penv
        self.agent = penv.possible_agents[0]
        self.observation_space = penv.observation_space(self.agent)
        self.action_space = penv.action_space(self.agent)

    def reset(self, seed=None, options=None):
        obs, infos = self.penv.reset(seed=seed, options=options)
        return obs[self.agent], infos[self.agent]

    def step(self, action):
        obs, rew, term, trunc, infos = self.penv.step({self.agent: action})
        a = self.agent
        return obs[a], rew[a], term[a], trunc[a], infos[a]


def test_spaces_shapes_dtypes_and_slot_layout():
    venv = make_parallel_vec_env(_cov, n_envs=2, seed=0)
    env = _cov()
    assert venv.num_envs == 2 * N
    assert venv.observation_space == env.observation_space("robot_0")
    assert venv.action_space == env.action_space("robot_0")
    obs = venv.reset()
    assert obs.shape == (2 * N, env.observation_space("robot_0").shape[0])
    assert obs.dtype == np.float32
    assert all(venv.observation_space.contains(o) for o in obs)
    assert [venv.slot_to_copy_agent(s) for s in range(2 * N)] == [
        (k, f"robot_{i}") for k in range(2) for i in range(N)
    ]
    assert venv.slot(1, "robot_2") == N + 2
    rng = np.random.default_rng(0)
    obs, rew, done, infos = venv.step(_actions(rng, venv))
    assert obs.shape == (2 * N, obs.shape[1]) and obs.dtype == np.float32
    assert rew.shape == (2 * N,) and rew.dtype == np.float32
    assert done.shape == (2 * N,) and done.dtype == bool
    assert len(infos) == 2 * N
    for s, info in enumerate(infos):
        assert info["agent"] == f"robot_{s % N}"
        assert info["agent_index"] == s % N and info["env_index"] == s // N
        assert {"eta", "collisions_total"} <= set(metrics_of(info))
        assert info["TimeLimit.truncated"] is False
    assert len(venv.reset_infos) == 2 * N and "metrics" in venv.reset_infos[0]


def test_matches_independently_stepped_copies_through_truncation_and_auto_reset():
    """Every slot equals the same agent of a reference copy seeded seed + k, stepped by
    hand; at the time limit: done, TimeLimit.truncated, terminal_observation, auto-reset."""
    seed, n_envs, cycles = 11, 2, 7
    venv = make_parallel_vec_env(_cov, n_envs=n_envs, seed=seed)
    refs = [_cov() for _ in range(n_envs)]
    ref_obs = [r.reset(seed=seed + k)[0] for k, r in enumerate(refs)]
    obs = venv.reset()
    rng = np.random.default_rng(1)
    for t in range(2 * cycles + 3):
        for k in range(n_envs):
            for i, a in enumerate(refs[k].possible_agents):
                np.testing.assert_array_equal(obs[k * N + i], ref_obs[k][a])
        act = _actions(rng, venv)
        obs, rew, done, infos = venv.step(act)
        for k, ref in enumerate(refs):
            o, r, te, tr, inf = ref.step(
                {a: act[k * N + i] for i, a in enumerate(ref.possible_agents)}
            )
            last = (t + 1) % cycles == 0
            for i, a in enumerate(ref.possible_agents):
                s = k * N + i
                assert rew[s] == np.float32(r[a])
                assert done[s] == last
                assert metrics_of(infos[s]) == metrics_of(inf[a])
                if last:
                    assert tr[a] and not te[a]
                    assert infos[s]["TimeLimit.truncated"] is True
                    np.testing.assert_array_equal(infos[s]["terminal_observation"], o[a])
                    assert infos[s]["terminal_observation"].dtype == np.float32
                else:
                    assert "terminal_observation" not in infos[s]
            if (t + 1) % cycles == 0:
                assert not ref.agents
                o, _ = ref.reset()  # auto-reset continues the copy's own generator
            ref_obs[k] = o


def test_matches_sb3_dummy_vec_env_on_single_agent_envs():
    """With N = 1 each copy is a plain single-agent env: the adapter must give exactly
    what SB3's own DummyVecEnv gives (obs, rewards, dones, terminal obs, truncation)."""

    def one():
        return fov_coverage_v0.parallel_env(n_agents=1, max_cycles=5)

    check_env(_SingleAgentGym(one()), warn=True)
    ours = ParallelEnvVecEnv([one, one])
    ref = DummyVecEnv([lambda: _SingleAgentGym(one()), lambda: _SingleAgentGym(one())])
    ours.seed(3)
    ref.seed(3)
    np.testing.assert_array_equal(ours.reset(), ref.reset())
    rng = np.random.default_rng(2)
    for _ in range(12):
        act = _actions(rng, ours)
        o1, r1, d1, i1 = ours.step(act)
        o2, r2, d2, i2 = ref.step(act)
        np.testing.assert_array_equal(o1, o2)
        np.testing.assert_array_equal(r1, r2)
        np.testing.assert_array_equal(d1, d2)
        for a, b in zip(i1, i2, strict=True):
            assert a["TimeLimit.truncated"] == b["TimeLimit.truncated"]
            assert ("terminal_observation" in a) == ("terminal_observation" in b)
            if "terminal_observation" in a:
                np.testing.assert_array_equal(a["terminal_observation"], b["terminal_observation"])
            assert metrics_of(a) == metrics_of(b)


def test_termination_is_not_marked_as_truncation():
    """Crossing: robots started on their targets terminate on the first step."""
    probe = fov_crossing_v0.parallel_env(n_agents=4)
    probe.reset(seed=5)
    starts = np.column_stack([probe.targets, np.zeros(4)])

    def at_target():
        return fov_crossing_v0.parallel_env(n_agents=4, initial_poses=starts, max_cycles=50)

    venv = make_parallel_vec_env(at_target, n_envs=1, seed=5)
    venv.reset()
    _, _, done, infos = venv.step(np.zeros((4, 3), np.float32))
    assert done.all()
    assert all(i["TimeLimit.truncated"] is False for i in infos)
    assert all("terminal_observation" in i for i in infos)


def test_seed_gives_distinct_copies_and_repeatable_runs():
    def run(seed):
        venv = make_parallel_vec_env(_cov, n_envs=3)
        seeds = venv.seed(seed)
        out = [venv.reset()]
        rng = np.random.default_rng(0)
        for _ in range(20):  # crosses two auto-resets
            out.append(venv.step(_actions(rng, venv))[0])
        return seeds, np.stack(out)

    seeds, a = run(7)
    assert seeds == [7] * N + [8] * N + [9] * N
    _, b = run(7)
    np.testing.assert_array_equal(a, b)
    _, c = run(8)
    # copies differ from each other; seed 8 shifts the copies by one
    own = a[0, :, -7:-5]  # own world (x, y) from the cue
    assert not np.allclose(own[:N], own[N : 2 * N])
    np.testing.assert_array_equal(c[0, :N], a[0, N : 2 * N])
    # a seed is used once: a second reset() continues the generators, it does not repeat
    venv = make_parallel_vec_env(_cov, n_envs=1, seed=7)
    first = venv.reset()
    assert not np.array_equal(first, venv.reset())


def test_attribute_access_and_wrappers():
    class Marker(BaseParallelWrapper):
        pass

    venv = ParallelEnvVecEnv([_cov, lambda: Marker(_cov())])
    assert venv.get_attr("max_cycles") == [7] * (2 * N)
    assert venv.get_attr("max_cycles", indices=[0, N]) == [7, 7]
    assert venv.env_is_wrapped(Marker) == [False] * N + [True] * N
    assert venv.env_is_wrapped(Marker, indices=N + 1) == [True]
    assert len(wrapper_chain(venv.envs[1])) == 2
    # set_attr reaches the base env under the wrapper, once per copy
    venv.set_attr("max_cycles", 2, indices=[N, N + 1])
    assert venv.envs[0].max_cycles == 7
    assert venv.envs[1].unwrapped.max_cycles == 2
    assert "max_cycles" not in vars(venv.envs[1])
    venv.seed(0)
    venv.reset()
    rng = np.random.default_rng(0)
    venv.step(_actions(rng, venv))
    _, _, done, _ = venv.step(_actions(rng, venv))
    assert done.tolist() == [False] * N + [True] * N
    # env_method: once per copy, result repeated for the copy's slots
    states = venv.env_method("state")
    assert len(states) == 2 * N
    assert states[0] is states[N - 1] and states[0] is not states[N]
    assert venv.env_method("state", indices=[N])[0].shape == venv.envs[1].state_space.shape
    with pytest.raises(ValueError, match="slot index"):
        venv.get_attr("max_cycles", indices=[2 * N])


def test_actions_are_passed_through_and_clipped_by_the_env():
    a = make_parallel_vec_env(_cov, n_envs=1, seed=1)
    b = make_parallel_vec_env(_cov, n_envs=1, seed=1)
    a.reset()
    b.reset()
    big = np.tile(np.array([[5.0, -7.0, 3.0]], np.float32), (N, 1))
    np.testing.assert_array_equal(a.step(big)[0], b.step(np.clip(big, -1, 1))[0])
    with pytest.raises(ValueError, match="shape"):
        a.step(np.zeros((N + 1, 3), np.float32))
    with pytest.raises(ValueError, match="finite"):
        a.step(np.full((N, 3), np.nan, np.float32))


def test_sb3_wrappers_stack_on_the_adapter():
    venv = VecNormalize(VecMonitor(VecCheckNan(make_parallel_vec_env(_cov, 2, seed=0))))
    obs = venv.reset()
    rng = np.random.default_rng(0)
    episodes = []
    for _ in range(8):
        obs, rew, done, infos = venv.step(_actions(rng, venv))
        episodes += [i["episode"] for i in infos if "episode" in i]
    assert obs.shape == (2 * N, venv.observation_space.shape[0])
    assert len(episodes) == 2 * N and all(e["l"] == 7 for e in episodes)


class _Stub(ParallelEnv):
    """Two agents; ``end_at`` steps per agent; optional odd observation space."""

    metadata = {"name": "stub"}
    render_mode = None

    def __init__(self, end_at=(3, 3), odd_space=False):
        self.possible_agents = ["a", "b"]
        self.end_at = dict(zip(self.possible_agents, end_at, strict=True))
        box = gym.spaces.Box(-1, 1, (2,), np.float32)
        self._obs = {"a": box, "b": gym.spaces.Box(-1, 1, (3,) if odd_space else (2,))}
        self._act = gym.spaces.Box(-1, 1, (1,), np.float32)

    def observation_space(self, agent):
        return self._obs[agent]

    def action_space(self, agent):
        return self._act

    def reset(self, seed=None, options=None):
        self.agents, self.t = list(self.possible_agents), 0
        return {a: np.zeros(2, np.float32) for a in self.agents}, {a: {} for a in self.agents}

    def step(self, actions):
        self.t += 1
        term = {a: self.t >= self.end_at[a] for a in self.agents}
        obs = {a: np.full(2, self.t / 10, np.float32) for a in self.agents}
        out = (obs, dict.fromkeys(self.agents, 1.0), term, dict.fromkeys(self.agents, False))
        out += ({a: {} for a in self.agents},)
        self.agents = [a for a in self.agents if not term[a]]
        return out


def test_rejects_bad_envs():
    with pytest.raises(ValueError, match="at least one"):
        ParallelEnvVecEnv([])
    env = _cov()
    with pytest.raises(ValueError, match="same env instance"):
        ParallelEnvVecEnv([lambda: env, lambda: env])
    with pytest.raises(ValueError, match="observation space of b"):
        ParallelEnvVecEnv([functools.partial(_Stub, odd_space=True)])
    with pytest.raises(ValueError, match="same agents"):
        ParallelEnvVecEnv([_cov, lambda: fov_coverage_v0.parallel_env(n_agents=N + 1)])
    with pytest.raises(ValueError, match="n_envs"):
        make_parallel_vec_env(_cov, n_envs=0)
    venv = ParallelEnvVecEnv([functools.partial(_Stub, end_at=(2, 3))])
    venv.reset()
    venv.step(np.zeros((2, 1), np.float32))
    with pytest.raises(ValueError, match="different times"):
        venv.step(np.zeros((2, 1), np.float32))


def test_stub_termination_and_seed_return():
    venv = ParallelEnvVecEnv([_Stub, _Stub])
    assert venv.seed(4) == [4, 4, 5, 5]
    venv.reset()
    for _ in range(2):
        _, rew, done, _ = venv.step(np.zeros((4, 1), np.float32))
        assert not done.any() and (rew == 1).all()
    obs, _, done, infos = venv.step(np.zeros((4, 1), np.float32))
    assert done.all() and not any(i["TimeLimit.truncated"] for i in infos)
    np.testing.assert_array_equal(infos[0]["terminal_observation"], np.full(2, 0.3, np.float32))
    np.testing.assert_array_equal(obs, np.zeros((4, 2)))  # reset observation


# ------------------------------------------------------------ the vector-env adapter
def _assert_same_step(a, b):
    for x, y in zip(a[:3], b[:3], strict=True):
        np.testing.assert_array_equal(x, y)
        assert x.dtype == y.dtype and x.shape == y.shape
    for ia, ib in zip(a[3], b[3], strict=True):
        assert list(ia) == list(ib)  # same keys in the same order
        for key in ia:
            if key == "terminal_observation":
                np.testing.assert_array_equal(ia[key], ib[key])
                assert ia[key].dtype == np.float32
            else:
                assert ia[key] == ib[key], key


@pytest.mark.parametrize(
    "mod, cfg",
    [
        (fov_coverage_v0, dict(n_agents=N, max_cycles=7)),
        # copies terminate early at different steps, and truncate
        (
            fov_crossing_v0,
            dict(n_agents=3, max_cycles=9, target_tolerance_m=3.4, crossing_radius_m=1.5),
        ),
    ],
    ids=["coverage", "crossing"],
)
def test_vector_adapter_matches_the_parallel_adapter_slot_by_slot(mod, cfg):
    n_envs = 3
    ours = make_vector_vec_env(mod, n_envs=n_envs, seed=5, **cfg)
    ref = make_parallel_vec_env(lambda: mod.parallel_env(**cfg), n_envs=n_envs, seed=5)
    assert ours.num_envs == ref.num_envs == n_envs * cfg["n_agents"]
    assert ours.observation_space == ref.observation_space
    assert ours.action_space == ref.action_space
    np.testing.assert_array_equal(ours.reset(), ref.reset())
    assert ours.reset_infos == ref.reset_infos
    assert [ours.slot_to_copy_agent(s) for s in range(ours.num_envs)] == [
        ref.slot_to_copy_agent(s) for s in range(ref.num_envs)
    ]
    rng = np.random.default_rng(3)
    dones = 0
    for _ in range(25):
        act = _actions(rng, ours, scale=1.3)
        a, b = ours.step(act), ref.step(act)
        _assert_same_step(a, b)
        assert ours.reset_infos == ref.reset_infos
        dones += int(a[2].sum())
    assert dones >= 3 * ours.num_envs
    # a later reset() without a new seed continues every copy's generator, like ref
    np.testing.assert_array_equal(ours.reset(), ref.reset())


def test_vector_adapter_termination_is_not_truncation():
    probe = fov_crossing_v0.parallel_env(n_agents=4)
    probe.reset(seed=5)
    starts = np.column_stack([probe.targets, np.zeros(4)])
    venv = make_vector_vec_env(
        fov_crossing_v0, n_envs=1, seed=5, n_agents=4, initial_poses=starts, max_cycles=50
    )
    venv.reset()
    _, _, done, infos = venv.step(np.zeros((4, 3), np.float32))
    assert done.all()
    assert all(i["TimeLimit.truncated"] is False for i in infos)
    assert all("terminal_observation" in i for i in infos)


def test_vector_adapter_seeding_attributes_and_errors():
    venv = make_vector_vec_env(fov_coverage_v0, n_envs=3, n_agents=N, max_cycles=7)
    assert venv.seed(7) == [7] * N + [8] * N + [9] * N
    for bad in (2.5, "x", -1, True):  # red team 6: 2.5 became 2, "x" an int() error
        with pytest.raises(ValueError, match="seed must be an integer"):
            venv.seed(bad)
    first = venv.reset()
    assert not np.array_equal(first, venv.reset())  # a seed is used once
    assert venv.get_attr("max_cycles", indices=[0, N]) == [7, 7]
    assert venv.get_attr("render_mode") == [None] * (3 * N)
    venv.set_attr("max_cycles", 2)
    assert venv.venv.max_cycles == 2
    assert venv.env_is_wrapped(VecMonitor) == [False] * (3 * N)
    states = venv.env_method("state", indices=[0, 1])
    assert states[0].shape == (3, venv.venv.state().shape[1]) and states[0] is states[1]
    with pytest.raises(ValueError, match="slot index"):
        venv.get_attr("max_cycles", indices=[3 * N])
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((N, 3), np.float32))
    with pytest.raises(ValueError, match="finite"):
        venv.step(np.full((3 * N, 3), np.nan, np.float32))
    with pytest.raises(ValueError, match="n_envs"):
        make_vector_vec_env(fov_coverage_v0, n_envs=0)
    with pytest.raises(ValueError, match="vector env"):
        VectorEnvVecEnv(_cov())
    # SB3 wrappers stack on it
    wrapped = VecNormalize(
        VecMonitor(
            VecCheckNan(make_vector_vec_env(fov_coverage_v0, 2, seed=0, n_agents=N, max_cycles=7))
        )
    )
    wrapped.reset()
    rng = np.random.default_rng(0)
    episodes = []
    for _ in range(8):
        *_, infos = wrapped.step(_actions(rng, wrapped))
        episodes += [i["episode"] for i in infos if "episode" in i]
    assert len(episodes) == 2 * N and all(e["l"] == 7 for e in episodes)


def test_make_training_vec_env_picks_the_adapter():
    from fov_marl.training.trainer import build_env, make_training_vec_env

    adapter, venv = make_training_vec_env(2, lambda: build_env("coverage", {"n_agents": N}))
    assert isinstance(adapter, VectorEnvVecEnv) and adapter.num_envs == 2 * N
    assert isinstance(venv, VecNormalize)
    adapter, _ = make_training_vec_env(
        2, lambda: build_env("crossing", {"n_agents": N, "max_cycles": 11}), normalize=False
    )
    assert isinstance(adapter, VectorEnvVecEnv) and adapter.venv.max_cycles == 11
    from fov_marl.wrappers import VectorSafetyFilterWrapper

    adapter, _ = make_training_vec_env(
        2, lambda: build_env("coverage", {"n_agents": N}, safety_filter=True), normalize=False
    )
    assert isinstance(adapter, VectorEnvVecEnv)
    assert isinstance(adapter.venv, VectorSafetyFilterWrapper)
    assert adapter.venv.pipeline.tracker_threads == 1
    # --filter-threads: the per-copy wrapper's tracker_threads reaches the vector filter
    adapter, _ = make_training_vec_env(
        2,
        lambda: build_env(
            "coverage", {"n_agents": N}, safety_filter=True,
            safety_filter_kwargs={"tracker_threads": 2},
        ),
        normalize=False,
    )  # fmt: skip
    assert adapter.venv.pipeline.tracker_threads == 2
    built = []

    def wrapped():
        built.append(build_env("coverage", {"n_agents": N}, belief=True))
        return built[-1]

    adapter, _ = make_training_vec_env(2, wrapped, normalize=False)
    assert isinstance(adapter, ParallelEnvVecEnv)
    assert len(built) == 2 and adapter.envs == built  # the probe is the first copy
    with pytest.raises(ValueError, match="eta_method"):
        make_training_vec_env(2, wrapped, eta_method="strip")
    adapter, _ = make_training_vec_env(
        1, lambda: build_env("coverage", {"n_agents": N}), eta_method="strip"
    )
    assert adapter.venv.eta_method == "strip"


def test_filtered_vector_adapter_matches_per_copy_filters_slot_by_slot():
    """Training behind the filter: one VectorSafetyFilterWrapper over the vector env gives
    the per-copy SafetyFilterWrappers' observations, rewards, dones and safety reports
    (actions within 1e-6, so observations within float32 round-off) across auto-resets."""
    from fov_marl.infos import metrics_of, safety_of
    from fov_marl.training.trainer import build_env, make_training_vec_env

    cfg = {"n_agents": N, "max_cycles": 9, "arena_size_m": 10.0, "density_mean_m": (5.0, 5.0)}
    ours, _ = make_training_vec_env(
        3, lambda: build_env("coverage", cfg, safety_filter=True), normalize=False
    )
    ref = make_parallel_vec_env(lambda: build_env("coverage", cfg, safety_filter=True), 3)
    ours.seed(11)
    ref.seed(11)
    np.testing.assert_allclose(ours.reset(), ref.reset(), atol=1e-5)

    def same_reset_infos():  # the neutral safety/* of a reset too (they were missing)
        for x, y in zip(ours.reset_infos, ref.reset_infos, strict=True):
            assert set(x) == set(y)
            sx, sy = safety_of(x), safety_of(y)
            assert sx.keys() == sy.keys() and sx["status"] == "reset"
            for key in sx:
                np.testing.assert_array_equal(np.asarray(sx[key]), np.asarray(sy[key]))

    same_reset_infos()
    from fov_marl.wrappers import SafetyFilterWrapper

    assert ours.env_is_wrapped(SafetyFilterWrapper) == ref.env_is_wrapped(SafetyFilterWrapper)
    assert all(ours.env_is_wrapped(SafetyFilterWrapper))
    rng = np.random.default_rng(2)
    dones = changed = 0
    for _ in range(20):
        act = _actions(rng, ours, scale=1.0)
        oa, ra, da, ia = ours.step(act)
        ob, rb, db, ib = ref.step(act)
        np.testing.assert_allclose(oa, ob, atol=1e-4)
        np.testing.assert_allclose(ra, rb, atol=1e-4)
        np.testing.assert_array_equal(da, db)
        for x, y in zip(ia, ib, strict=True):
            sx, sy = safety_of(x), safety_of(y)
            np.testing.assert_allclose(sx["applied_action"], sy["applied_action"], atol=1e-5)
            assert sx["intervened"] == sy["intervened"] and sx["status"] == sy["status"]
            assert metrics_of(x)["collisions_total"] == metrics_of(y)["collisions_total"]
            changed += int(sx["intervened"])
        dones += int(da.sum())
        if da.any():
            same_reset_infos()
    assert dones >= 2 * ours.num_envs and changed > 0


def test_ppo_on_the_vector_adapter_equals_ppo_on_the_parallel_adapter():
    """A few hundred PPO steps: the same seed gives the same policy with either adapter."""
    import torch
    from stable_baselines3 import PPO

    def train(venv):
        model = PPO(
            "MlpPolicy",
            venv,
            n_steps=32,
            batch_size=48,
            n_epochs=2,
            seed=3,
            device="cpu",
            policy_kwargs={"net_arch": [16]},
        )
        model.learn(total_timesteps=4 * 32 * venv.num_envs)
        return model, torch.nn.utils.parameters_to_vector(model.policy.parameters()).detach()

    cfg = dict(n_agents=N, max_cycles=20)
    prev = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        m1, p1 = train(VecMonitor(make_vector_vec_env(fov_coverage_v0, 2, **cfg)))
        m2, p2 = train(
            VecMonitor(make_parallel_vec_env(lambda: fov_coverage_v0.parallel_env(**cfg), 2))
        )
    finally:
        torch.set_num_threads(prev)
    assert m1.num_timesteps == m2.num_timesteps == 4 * 32 * 2 * N
    assert torch.equal(p1, p2)
    p0 = torch.nn.utils.parameters_to_vector(
        PPO(
            "MlpPolicy",
            make_vector_vec_env(fov_coverage_v0, 2, **cfg),
            seed=3,
            device="cpu",
            policy_kwargs={"net_arch": [16]},
        ).policy.parameters()
    ).detach()
    assert not torch.equal(p0, p1)  # it did learn (the parameters moved)
    assert len(m1.ep_info_buffer) == len(m2.ep_info_buffer) > 0


def test_training_vec_env_with_workers_equals_one_process_slot_by_slot():
    """``workers=2`` (SubprocVectorEnv shards, behind the filter) gives the one-process
    adapter's observations, rewards, dones and infos bit for bit, across auto-resets;
    ``set_attr("max_cycles")`` reaches the envs behind the filter, attributes and
    methods only the shards hold are reached per shard; the per-copy path and
    ``workers > n_envs`` are refused."""
    from fov_marl.envs import SubprocVectorEnv
    from fov_marl.training.trainer import build_env, make_training_vec_env

    cfg = {"n_agents": N, "max_cycles": 6}
    sf = {"tracker_params": {"n_particles_total": 200}}

    def factory():
        return build_env("coverage", cfg, safety_filter=True, safety_filter_kwargs=sf)

    one, _ = make_training_vec_env(3, factory, normalize=False)
    two, _ = make_training_vec_env(3, factory, normalize=False, workers=2)
    try:
        assert isinstance(two.venv, SubprocVectorEnv) and two.venv.workers == 2
        one.seed(4)
        two.seed(4)
        np.testing.assert_array_equal(one.reset(), two.reset())
        rng = np.random.default_rng(0)
        dones = 0
        for _ in range(14):
            act = _actions(rng, one, scale=1.0)
            oa, ra, da, ia = one.step(act)
            ob, rb, db, ib = two.step(act)
            np.testing.assert_array_equal(oa, ob)
            np.testing.assert_array_equal(ra, rb)
            np.testing.assert_array_equal(da, db)
            for x, y in zip(ia, ib, strict=True):
                assert set(x) == set(y)
                for k in x:
                    np.testing.assert_array_equal(x[k], y[k], err_msg=k)
            dones += int(da.sum())
        assert dones >= 2 * one.num_envs
        assert two.get_attr("max_cycles") == [6] * two.num_envs
        # attributes and methods only the shards hold (red team 3: AttributeError)
        assert two.get_attr("eta_method") == one.get_attr("eta_method") == ["exact"] * 3 * N
        assert two.venv.shard_starts == (0, 2, 3)
        sh = two.env_method("reset_safety_infos", indices=[0, 2 * N])
        ref = one.env_method("reset_safety_infos", indices=[0, 2 * N])
        assert sh[0]["intervened"].shape == (2, N)  # shard 0 holds copies 0 and 1
        assert sh[1]["intervened"].shape == (1, N)  # shard 1 holds copy 2
        assert ref[0]["intervened"].shape == (3, N)
        two.set_attr("eta_method", "exact")  # set in every shard
        with pytest.raises(AttributeError):
            two.get_attr("no_such_attribute")
        for adapter in (one, two):
            adapter.set_attr("max_cycles", 2)
            adapter.reset()
            adapter.step(np.zeros((adapter.num_envs, 3), np.float32))
            _, _, d, _ = adapter.step(np.zeros((adapter.num_envs, 3), np.float32))
            assert d.all()
    finally:
        two.close()
    with pytest.raises(ValueError, match="workers"):
        make_training_vec_env(2, factory, workers=3)
    with pytest.raises(ValueError, match="per copy"):
        make_training_vec_env(2, lambda: build_env("coverage", cfg, belief=True), workers=2)
