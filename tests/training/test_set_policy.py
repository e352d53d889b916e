"""The set (deep-sets) actor-critic: invariances, numpy == torch, CTDE entries, tiny runs."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

import gymnasium as gym  # noqa: E402
import torch  # noqa: E402

from fov_marl.baselines import make_policy  # noqa: E402
from fov_marl.baselines.learned import SetActorWeights  # noqa: E402
from fov_marl.config import make_config  # noqa: E402
from fov_marl.envs import fov_coverage_v0  # noqa: E402
from fov_marl.training.set_policy import (  # noqa: E402
    CtdeVecEnvWrapper,
    SetActorCriticPolicy,
    action_change,
    actor_weights,
    agent_centric_state,
    default_feature_scales,
    eta_level_reward,
)

SCALES = default_feature_scales(make_config(scenario="coverage"))


def _policy(
    ctde: bool = False, n_agents: int = 6, seed: int = 0, bounded: bool = True
) -> SetActorCriticPolicy:
    """A policy with random (not SB3-initialised) weights, so outputs are far from 0."""
    torch.manual_seed(seed)
    d = (10 if ctde else 5) * (n_agents - 1) + 7
    space = gym.spaces.Box(-1e3, 1e3, (d,), np.float32)
    pol = SetActorCriticPolicy(
        space, gym.spaces.Box(-1, 1, (3,), np.float32), lambda _: 3e-4,
        ctde=ctde, feature_scales=SCALES, hidden=16, bounded_mean=bounded,
    )  # fmt: skip
    with torch.no_grad():
        for p in pol.parameters():
            p.copy_(torch.randn_like(p) * 0.5)
    return pol


def _obs(rng: np.random.Generator, robots: int, n_agents: int) -> np.ndarray:
    """Random observations in the env's layout: detected slots with metres, others 0."""
    m = n_agents - 1
    slots = np.zeros((robots, m, 5), np.float32)
    det = rng.random((robots, m)) < 0.6
    slots[..., 0] = det
    slots[..., 1:3] = rng.uniform(-10, 10, (robots, m, 2))
    ang = rng.uniform(-np.pi, np.pi, (robots, m))
    slots[..., 3], slots[..., 4] = np.cos(ang), np.sin(ang)
    slots[~det] = 0.0
    yaw = rng.uniform(-np.pi, np.pi, robots)
    cue = np.column_stack(
        [rng.uniform(0, 40, (robots, 2)), np.cos(yaw), np.sin(yaw),
         rng.uniform(-30, 30, (robots, 2)), np.full(robots, 2.8)]
    )  # fmt: skip
    return np.concatenate([slots.reshape(robots, -1), cue], axis=1).astype(np.float32)


def _torch_mean(pol: SetActorCriticPolicy, obs: np.ndarray) -> np.ndarray:
    with torch.no_grad():
        t = torch.as_tensor(obs)
        return pol.action_net(pol.mlp_extractor.forward_actor(t)).numpy()


@pytest.mark.parametrize(
    "n_agents, bounded", [(1, True), (2, True), (4, True), (6, True), (9, True), (12, True),
                          (3, False), (12, False)]
)  # fmt: skip
def test_numpy_forward_equals_torch_actor(n_agents, bounded):
    pol = _policy(bounded=bounded)
    w, cfg = actor_weights(pol)
    obs = _obs(np.random.default_rng(n_agents), 16, n_agents)
    got = SetActorWeights(w, cfg).mean_action(obs)
    want = _torch_mean(pol, obs)
    assert np.abs(want).max() > 0.1  # not a trivially small output
    np.testing.assert_allclose(got, want, atol=1e-5, rtol=0)


def test_shuffling_neighbour_slots_leaves_the_action_unchanged():
    pol = _policy()
    np_pol = SetActorWeights(*actor_weights(pol))
    rng = np.random.default_rng(1)
    obs = _obs(rng, 8, 7)
    slots = obs[:, :30].reshape(8, 6, 5)
    perm = rng.permutation(6)
    assert not np.array_equal(perm, np.arange(6))
    shuffled = np.concatenate([slots[:, perm].reshape(8, -1), obs[:, 30:]], axis=1)
    for f in (lambda o: _torch_mean(pol, o), np_pol.mean_action):
        np.testing.assert_allclose(f(shuffled), f(obs), atol=1e-5)
    # and the slots do matter (the test can fail)
    moved = obs.copy()
    moved[:, 1:3] += 3.0 * (moved[:, 0:1] > 0)
    assert np.abs(np_pol.mean_action(moved) - np_pol.mean_action(obs)).max() > 1e-3


def test_undetected_slots_have_no_effect_whatever_they_hold():
    pol = _policy()
    np_pol = SetActorWeights(*actor_weights(pol))
    rng = np.random.default_rng(2)
    obs = _obs(rng, 8, 6)
    slots = obs[:, :25].reshape(8, 5, 5).copy()
    undetected = slots[..., 0] == 0
    assert undetected.any()
    junk = rng.normal(size=slots.shape) * 20
    junk[..., 0] = 0.0
    slots[undetected] = junk[undetected]
    garbled = np.concatenate([slots.reshape(8, -1), obs[:, 25:]], axis=1)
    np.testing.assert_allclose(np_pol.mean_action(garbled), np_pol.mean_action(obs), atol=1e-9)
    np.testing.assert_allclose(_torch_mean(pol, garbled), _torch_mean(pol, obs), atol=1e-5)


def test_same_weights_any_team_size_and_padding_changes_nothing():
    np_pol = SetActorWeights(*actor_weights(_policy()))
    rng = np.random.default_rng(3)
    for n in range(4, 13):
        obs = _obs(rng, n, n)
        a = np_pol.act(obs)
        assert a.shape == (n, 3) and np.all(np.abs(a) <= 1.0)
        # one more robot, never detected: an all-zero slot -> the same action
        padded = np.concatenate([obs[:, : 5 * (n - 1)], np.zeros((n, 5)), obs[:, 5 * (n - 1) :]], 1)
        np.testing.assert_allclose(np_pol.mean_action(padded), np_pol.mean_action(obs), atol=1e-9)
    with pytest.raises(ValueError, match="observation length"):
        np_pol.act(np.zeros((2, 11), np.float32))


def test_the_actor_never_reads_the_ctde_entries_and_the_critic_does():
    pol = _policy(ctde=True)
    rng = np.random.default_rng(4)
    own = _obs(rng, 6, 6)
    state = rng.normal(size=(6, 25)).astype(np.float32) * 10
    state[:, ::5] = 1.0
    a = np.concatenate([own, state], 1)
    b = np.concatenate([own, state * 1.7], 1)
    np.testing.assert_allclose(_torch_mean(pol, a), _torch_mean(pol, b), atol=0)
    with torch.no_grad():
        va = pol.predict_values(torch.as_tensor(a)).numpy()
        vb = pol.predict_values(torch.as_tensor(b)).numpy()
    assert np.abs(va - vb).max() > 1e-4
    # and the exported actor equals the torch actor on the own observation
    np.testing.assert_allclose(
        SetActorWeights(*actor_weights(pol)).mean_action(own), _torch_mean(pol, a), atol=1e-5
    )


def test_agent_centric_state_is_env_state_seen_from_each_robot():
    venv = fov_coverage_v0.vector_env(num_envs=2, n_agents=5)
    obs, _ = venv.reset(seed=3)
    st = agent_centric_state(obs).reshape(2, 5, 4, 5)
    poses = np.asarray(venv.poses, dtype=np.float64)
    for b in range(2):
        for i in range(5):
            others = [k for k in range(5) if k != i]
            d = poses[b, others, :2] - poses[b, i, :2]
            c, s = np.cos(poses[b, i, 2]), np.sin(poses[b, i, 2])
            body = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
            dyaw = poses[b, others, 2] - poses[b, i, 2]
            np.testing.assert_allclose(st[b, i, :, 0], 1.0)
            np.testing.assert_allclose(st[b, i, :, 1:3], body, atol=1e-3)
            np.testing.assert_allclose(st[b, i, :, 3], np.cos(dyaw), atol=1e-5)
            np.testing.assert_allclose(st[b, i, :, 4], np.sin(dyaw), atol=1e-5)


def test_ctde_wrapper_augments_observations_terminal_ones_and_shapes_rewards():
    from fov_marl.training.vec_env import make_vector_vec_env

    base = make_vector_vec_env(fov_coverage_v0, n_envs=2, seed=0, n_agents=4, max_cycles=3)
    w = CtdeVecEnvWrapper(base, 4, ctde=True, eta_level_coef=2.0)
    obs = w.reset()
    assert obs.shape == (8, 22 + 15) and w.observation_space.shape == (37,)
    act = np.zeros((8, 3), np.float32)
    for _ in range(2):
        w.step_async(act)
        obs, rew, dones, infos = w.step_wait()
    w.step_async(act)
    obs, rew, dones, infos = w.step_wait()
    assert dones.all()
    for info in infos:
        assert info["terminal_observation"].shape == (37,)
        assert info["terminal_observation"][22] == 1.0  # a present critic entry
    eta = np.array([i["metrics/eta"] for i in infos])
    raw = rew - 2.0 * eta_level_reward(eta)  # static robots: no eta gain, no penalty
    np.testing.assert_allclose(raw, 0.0, atol=1e-5)
    assert np.all(rew > 0.005)
    np.testing.assert_allclose(eta_level_reward(np.array([0.99, 1.0])), [0.5, 1.0], atol=2e-3)


def test_action_change_ignores_the_envs_own_speed_limit():
    nom = np.array([[1.0, 1.0, 0.5], [0.2, 0.0, 0.0]])
    app = np.array([[np.sqrt(0.5), np.sqrt(0.5), 0.5], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(action_change(nom, app), [0.0, 0.2], atol=1e-12)


def test_cli_train_set_ctde_tiny_run_exports_and_loads(tmp_path, capsys):
    from fov_marl.cli import main
    from fov_marl.training import load_policy

    out = tmp_path / "run"
    code = main(
        ["train", "--arch", "set", "--ctde", "--eta-level-coef", "1", "--timesteps", "3000",
         "--n-envs", "2", "--n-agents", "4", "--train-max-cycles", "40", "--out", str(out),
         "--no-progress", "--checkpoint-every", "0",
         "--hp", "n_steps=64", "--hp", "batch_size=256", "--hp", "n_epochs=2",
         "--hp", 'policy_kwargs={"hidden": 16}']
    )  # fmt: skip
    assert code in (0, None) or str(code).endswith("model.zip")
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["arch"] == "set" and cfg["ctde"] is True and cfg["timesteps_done"] >= 3000
    assert (out / "export" / "weights.npz").is_file()
    tb = list((out / "tb").rglob("events.out.tfevents*"))
    assert tb
    # the SB3 model (fixed N) and the exported actor (any N) act the same at N = 4
    loaded = load_policy(out)
    env = loaded.make_env()
    obs, _ = env.reset(seed=0)
    loaded.reset(seed=0)
    a_sb3 = loaded.act(obs)
    learned = make_policy("learned", env, path=out / "export")
    a_np = learned.act(obs)
    for agent in obs:
        np.testing.assert_allclose(a_np[agent], a_sb3[agent], atol=1e-5)
    # the export runs another team size
    env8 = fov_coverage_v0.parallel_env(n_agents=8, max_cycles=5)
    obs8, _ = env8.reset(seed=1)
    assert len(make_policy("learned", env8, path=out / "export").act(obs8)) == 8
    # and evaluates from the CLI
    assert main(["evaluate", "--policy", str(out / "export"), "--n-agents", "5",
                 "--episodes", "1", "--max-cycles", "5", "--quiet"]) == 0  # fmt: skip


def test_bad_set_options_are_errors_naming_them(tmp_path):
    from fov_marl.training import train

    with pytest.raises(ValueError, match="ctde needs arch 'set'"):
        train(ctde=True, out_dir=tmp_path / "a", timesteps=10)
    with pytest.raises(ValueError, match="arch 'set' needs algo 'ppo'"):
        train(algo="sac", arch="set", out_dir=tmp_path / "b", timesteps=10)
    with pytest.raises(ValueError, match="eta_level_coef"):
        train(arch="set", eta_level_coef=-1.0, out_dir=tmp_path / "c", timesteps=10)
    with pytest.raises(ValueError, match="init_from"):
        train(arch="set", init_from=tmp_path / "none.zip", out_dir=tmp_path / "d", timesteps=10)


def test_shaping_terms_on_known_cases():
    from fov_marl.training.set_policy import action_energy, blind_motion, fov_keep_cost

    half = np.deg2rad(60.0)
    act = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(blind_motion(act, half), [0.0, 1 / 6, 2 / 3, 0.0], atol=1e-12)
    np.testing.assert_allclose(action_energy(act), [0.5, 0.5, 1.0, 0.0], atol=1e-12)
    # ahead (in view), behind and close, behind but far, absent: only the second costs
    e = np.array([[[1, 3, 0, 1, 0], [1, -3, 0, 1, 0], [1, -30, 0, 1, 0], [0, -3, 0, 0, 0]]], float)
    np.testing.assert_allclose(fov_keep_cost(e, half, 6.0), [2 / 3], atol=1e-12)
