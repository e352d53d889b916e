"""Short SB3 runs: train, save, reload, evaluate; reproducibility; the CLI runner."""

from __future__ import annotations

import argparse
import csv
import json
from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

import torch  # noqa: E402
from stable_baselines3.common.logger import Logger  # noqa: E402

from fov_marl.infos import SAFETY_CAUSES, metrics_of  # noqa: E402
from fov_marl.training import load_policy, train  # noqa: E402
from fov_marl.training.cli_support import (  # noqa: E402
    add_train_arguments,
    parse_hyperparams,
    run_train,
)
from fov_marl.training.trainer import (  # noqa: E402
    DEFAULT_HYPERPARAMS,
    FovMetricsCallback,
    build_env,
)

# 2 copies x 6 robots = 12 slots; 64 steps per rollout = 768 samples; 3 rollouts.
SMALL_PPO = {"n_steps": 64, "batch_size": 256, "n_epochs": 2}
ENV = {"n_agents": 6, "eta_grid_m": 0.5}


def _safety_filter_available() -> bool:
    try:
        from fov_marl.wrappers import SafetyFilterWrapper  # noqa: F401
    except ImportError:
        return False
    return True


def _train(tmp, **kw):
    args = dict(
        algo="ppo",
        timesteps=2000,
        seed=0,
        out_dir=tmp,
        n_envs=2,
        env_kwargs=ENV,
        hyperparams=SMALL_PPO,
        train_max_cycles=60,
        checkpoint_every=1000,
        progress_bar=False,
    )
    args.update(kw)
    return train(**args)


@pytest.fixture(scope="module")
def ppo_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("ppo")
    return _train(out)


def _episode(policy, env, seed, steps):
    obs, _ = env.reset(seed=seed)
    policy.reset(seed=seed)
    acts = []
    for _ in range(steps):
        a = policy.act(obs)
        acts.append(np.stack([a[x] for x in env.possible_agents]))
        obs, _, _, _, infos = env.step(a)
    return np.stack(acts), infos


def test_ppo_run_writes_model_config_logs_and_checkpoints(ppo_run):
    out = ppo_run.parent
    assert ppo_run.name == "model.zip" and ppo_run.is_file()
    assert (out / "vecnormalize.pkl").is_file()
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["algo"] == "ppo" and cfg["scenario"] == "coverage"
    assert cfg["wrappers"] == [] and cfg["n_agents"] == 6
    assert cfg["timesteps_done"] >= 2000
    # evaluation horizon is the env's own; training used the shorter one
    assert cfg["env_kwargs"]["max_cycles"] == 1000
    assert cfg["train_env_config"]["max_cycles"] == 60
    assert cfg["env_kwargs"]["eta_grid_m"] == 0.5 and "scenario" not in cfg["env_kwargs"]
    assert cfg["hyperparams"]["n_steps"] == 64
    assert cfg["hyperparams"]["policy_kwargs"] == DEFAULT_HYPERPARAMS["ppo"]["policy_kwargs"]
    # episodes of 60 steps ended: the env metrics reached the logs
    rows = list(csv.DictReader((out / "progress.csv").open()))
    etas = [float(r["fov/final_eta"]) for r in rows if r.get("fov/final_eta")]
    assert etas and all(0.0 <= e <= 1.0 for e in etas)
    assert any(r.get("rollout/ep_rew_mean") for r in rows)
    assert any(p.name.startswith("events.out.tfevents") for p in (out / "tb").rglob("*"))
    ckpts = sorted((out / "checkpoints").glob("model_*_steps.zip"))
    assert ckpts and sorted((out / "checkpoints").glob("model_vecnormalize_*_steps.pkl"))


def test_reloaded_policy_evaluates_like_a_baseline(ppo_run):
    policy = load_policy(ppo_run)
    assert policy.algo == "ppo" and not policy.safety_filter and not policy.belief
    env = policy.make_env(max_cycles=25)
    assert env.unwrapped.config.eta_grid_m == 0.5
    acts, infos = _episode(policy, env, seed=3, steps=25)
    assert not env.agents  # the episode ran to its (overridden) horizon
    assert acts.dtype == np.float32 and acts.shape == (25, 6, 3)
    assert np.all(np.abs(acts) <= 1.0)
    assert 0.0 <= metrics_of(infos["robot_0"])["eta"] <= 1.0
    # deterministic, and observations are normalised with the saved statistics
    acts2, _ = _episode(load_policy(ppo_run.parent), env, seed=3, steps=25)
    np.testing.assert_array_equal(acts, acts2)
    obs, _ = env.reset(seed=4)
    batch = np.stack([obs[a] for a in env.possible_agents])
    ref, _ = policy.model.predict(policy._obs_norm.normalize_obs(batch), deterministic=True)
    got = policy.act(obs)
    np.testing.assert_allclose(np.stack([got[a] for a in env.possible_agents]), ref, atol=1e-6)
    raw, _ = policy.model.predict(batch, deterministic=True)
    assert not np.allclose(raw, ref)  # normalisation matters, so the check above can fail
    for bad in (-1, 1.5, "a"):  # red team 26: reset took any seed
        with pytest.raises(ValueError, match="seed"):
            policy.reset(seed=bad)


def test_reload_from_checkpoint_and_as_run_episode_factory(ppo_run):
    ckpt = sorted((ppo_run.parent / "checkpoints").glob("model_*_steps.zip"))[0]
    policy = load_policy(ckpt)
    env = build_env("coverage", {**ENV, "max_cycles": 5})
    assert policy.factory(env) is policy
    acts, _ = _episode(policy, env, seed=0, steps=5)
    assert acts.shape == (5, 6, 3)
    with pytest.raises(ValueError, match="n_agents"):
        policy.bind(build_env("coverage", {"n_agents": 4}))
    with pytest.raises(ValueError, match="n_agents"):
        policy.make_env(n_agents=4)
    evaluation = pytest.importorskip("fov_marl.evaluation")
    rec = evaluation.run_episode(
        "coverage", load_policy(ppo_run).factory, 0, max_steps=10, **{**ENV, "max_cycles": 10}
    )
    assert rec.steps == 10 and rec.final_eta is not None


def test_same_seed_gives_identical_parameters(tmp_path):
    def params(run_dir, seed):
        path = _train(run_dir, timesteps=800, seed=seed, checkpoint_every=0)
        return load_policy(path).model.policy.state_dict()

    a = params(tmp_path / "a", 5)
    b = params(tmp_path / "b", 5)
    c = params(tmp_path / "c", 6)
    assert a.keys() == b.keys()
    for k in a:
        assert torch.equal(a[k], b[k]), k
    assert any(not torch.equal(a[k], c[k]) for k in a)


@pytest.mark.skipif(not _safety_filter_available(), reason="SafetyFilterWrapper not built yet")
def test_ppo_behind_the_safety_filter(tmp_path):
    path = _train(tmp_path, timesteps=1000, safety_filter=True, checkpoint_every=0)
    cfg = json.loads((tmp_path / "config.json").read_text())
    assert cfg["wrappers"] == ["safety_filter"]
    rows = list(csv.DictReader((tmp_path / "progress.csv").open()))
    assert any(r.get("fov/filter_intervention_rate") for r in rows)
    assert {f"fov/intervention_cause_rollout/{c}" for c in SAFETY_CAUSES} <= set(rows[0])
    policy = load_policy(path)
    env = policy.make_env(max_cycles=10)
    acts, infos = _episode(policy, env, seed=0, steps=10)
    assert "safety" in infos["robot_0"]
    assert acts.shape == (10, 6, 3)
    # the copies and their filters in 2 processes: the same run, parameter for parameter
    path2 = _train(
        tmp_path / "w2", timesteps=1000, safety_filter=True, checkpoint_every=0, workers=2
    )
    assert json.loads((tmp_path / "w2" / "config.json").read_text())["workers"] == 2
    a = policy.model.policy.state_dict()
    b = load_policy(path2).model.policy.state_dict()
    assert a.keys() == b.keys()
    for k in a:
        assert torch.equal(a[k], b[k]), k


def test_belief_policy_computes_the_wrapper_features_itself(tmp_path):
    """A belief policy acts on the plain env; its features equal the training wrapper's."""
    from fov_marl.wrappers.belief import BeliefObservationWrapper

    bk = {"init": "known", "tracker_params": {"n_particles_total": 300}}
    path = _train(
        tmp_path,
        timesteps=800,
        belief=True,
        belief_kwargs=bk,
        checkpoint_every=0,
        env_kwargs={"n_agents": 4, "eta_grid_m": 0.5},
    )
    policy = load_policy(path)
    assert policy.belief and policy.belief_kwargs == bk
    env = policy.make_env(max_cycles=12)
    wrapped = BeliefObservationWrapper(build_env("coverage", policy.env_kwargs), **bk)
    obs, _ = env.reset(seed=9)
    wobs, _ = wrapped.reset(seed=9)
    policy.reset(seed=9)
    agents = env.possible_agents
    for _ in range(12):
        act = policy.act(obs)
        batch = policy._obs_norm.normalize_obs(np.stack([wobs[a] for a in agents]))
        ref, _ = policy.model.predict(batch, deterministic=True)
        np.testing.assert_allclose(np.stack([act[a] for a in agents]), ref, atol=1e-6)
        obs, *_ = env.step(act)
        wobs, *_ = wrapped.step(act)
    unbound = load_policy(path)
    with pytest.raises(ValueError, match="bind"):
        unbound.act(obs)


def test_sac_short_run(tmp_path):
    path = _train(
        tmp_path,
        algo="sac",
        timesteps=600,
        hyperparams={"learning_starts": 200, "gradient_steps": 1, "batch_size": 64},
        checkpoint_every=0,
    )
    policy = load_policy(path)
    assert policy.algo == "sac"
    acts, _ = _episode(policy, policy.make_env(max_cycles=5), seed=0, steps=5)
    assert np.all(np.abs(acts) <= 1.0)


def test_invalid_arguments_raise_value_error(tmp_path):
    for kw, match in (
        ({"algo": "dqn"}, "algo"),
        ({"scenario": "maze"}, "scenario"),
        ({"timesteps": 0}, "timesteps"),
        ({"n_envs": 0}, "n_envs"),
        ({"env_kwargs": {"bogus": 1}}, "bogus"),
        ({"env_kwargs": {"fov_deg": 0.0}}, "fov_deg"),
        ({"hyperparams": {"policy_kwargs": {"activation_fn": "swish"}}}, "activation_fn"),
        ({"train_max_cycles": 0}, "train_max_cycles"),
        ({"workers": 3}, r"workers must be .*\[1, 2\]"),
        ({"workers": 2, "belief": True}, "workers = 2 needs the vector env"),
        # options of a wrapper that is off were silently ignored before
        ({"safety_filter_kwargs": {"init": "uniform"}}, r"\['init'\] need safety_filter=True"),
        ({"belief_kwargs": {"init": "uniform"}}, r"\['init'\] need belief=True"),
        (
            {"safety_filter": True, "safety_filter_kwargs": {"zzz": 1}},
            r"unknown safety_filter_kwargs \['zzz'\]; valid .*controller_params",
        ),
        ({"safety_filter_kwargs": 3}, "safety_filter_kwargs must be a dict"),
    ):
        with pytest.raises(ValueError, match=match):
            _train(tmp_path, **kw)
    with pytest.raises(ValueError, match="does not exist"):
        load_policy(tmp_path / "nothing.zip")


def test_metrics_callback_logs_episode_metrics_and_interventions():
    logger = Logger(folder=None, output_formats=[])
    cb = FovMetricsCallback(n_agents=2)
    cb.model = SimpleNamespace(logger=logger)

    def infos(done, intervened, eta=0.5):
        out = []
        for k in range(2):  # 2 copies x 2 agents
            for i in range(2):
                info = {"env_index": k, "agent_index": i, "metrics": {"eta": eta + k}}
                info["safety"] = {"intervened": intervened[i]}
                if done:
                    info["episode"] = {"r": 1.5, "l": 3}
                out.append(info)
        return out

    for step in range(3):
        done = step == 2
        cb.locals = {"infos": infos(done, [True, step == 0]), "dones": np.full(4, done)}
        cb._on_step()
    # per copy: 3 + 1 = 4 interventions in 6 robot-steps
    assert logger.name_to_value["fov/filter_intervention_rate"] == pytest.approx(4 / 6)
    assert logger.name_to_value["fov/filter_interventions"] == pytest.approx(2.0)
    assert logger.name_to_value["fov/final_eta"] == pytest.approx(1.0)  # mean of 0.5, 1.5
    assert logger.name_to_value["fov/team_return"] == pytest.approx(3.0)
    assert cb.episodes == 2


def test_metrics_callback_logs_the_share_of_each_intervention_cause():
    logger = Logger(folder=None, output_formats=[])
    cb = FovMetricsCallback(n_agents=2)
    cb.model = SimpleNamespace(logger=logger)
    budget, look, wall = 1 << 6, 1 << 8, 1 << 2
    bits = [[budget | look, 0], [wall, budget]]  # 2 steps x 2 slots
    cb._on_rollout_start()
    for step_bits in bits:
        infos = [
            {"safety/intervened": b != 0, "safety/cause_bits": b, "env_index": 0} for b in step_bits
        ]
        cb.locals = {"infos": infos, "dones": np.zeros(2, dtype=bool)}
        cb._on_step()
    cb._on_rollout_end()
    v = logger.name_to_value
    assert v["fov/intervention_rate_rollout"] == pytest.approx(3 / 4)
    assert v["fov/intervention_cause_rollout/budget"] == pytest.approx(2 / 4)
    assert v["fov/intervention_cause_rollout/look"] == pytest.approx(1 / 4)
    assert v["fov/intervention_cause_rollout/wall"] == pytest.approx(1 / 4)
    assert v["fov/intervention_cause_rollout/neighbour"] == 0.0


def test_cli_runner(tmp_path, capsys):
    parser = argparse.ArgumentParser()
    add_train_arguments(parser)
    args = parser.parse_args(
        [
            "--timesteps",
            "1e3",
            "--out",
            str(tmp_path),
            "--n-envs",
            "1",
            "--n-agents",
            "3",
            "--env",
            "eta_grid_m=0.5",
            "--hp",
            "n_steps=64",
            "--hp",
            "batch_size=64",
            "--hp",
            'policy_kwargs={"net_arch": [16]}',
            "--no-progress",
            "--checkpoint-every",
            "0",
        ]
    )
    assert args.timesteps == 1000
    path = run_train(args)
    assert "fov-marl evaluate --policy" in capsys.readouterr().out
    cfg = json.loads((path.parent / "config.json").read_text())
    assert cfg["env_kwargs"]["n_agents"] == 3 and cfg["env_kwargs"]["eta_grid_m"] == 0.5
    assert cfg["hyperparams"]["policy_kwargs"]["net_arch"] == [16]
    with pytest.raises(SystemExit):
        parser.parse_args(["--out", "x", "--timesteps", "2.5"])
    assert parse_hyperparams(["gamma=0.995", "note=abc"]) == {"gamma": 0.995, "note": "abc"}
    with pytest.raises(ValueError, match="KEY=VALUE"):
        parse_hyperparams(["gamma"])


# ------------------------------------------------------------------- issue 13: CLI
TINY_CLI = [
    "train",
    "--n-agents",
    "2",
    "--num-envs",
    "1",
    "--train-max-cycles",
    "10",
    "--hp",
    "n_steps=64",
    "--hp",
    "batch_size=64",
    "--checkpoint-every",
    "0",
    "--no-progress",
]


def test_timesteps_rounding_is_printed_and_matches_what_ran(tmp_path, capsys, monkeypatch):
    from stable_baselines3 import PPO

    from fov_marl.cli import main
    from fov_marl.training.trainer import effective_timesteps

    asked = []
    learn = PPO.learn

    def spy(self, total_timesteps, *args, **kwargs):
        asked.append(total_timesteps)
        return learn(self, total_timesteps, *args, **kwargs)

    monkeypatch.setattr(PPO, "learn", spy)

    # whole PPO rollouts of n_steps 64 x 1 copy x 2 robots = 128 samples
    assert effective_timesteps("ppo", 1000, 2, {"n_steps": 64}) == 1024
    assert effective_timesteps("ppo", 1024, 2, {"n_steps": 64}) == 1024
    assert effective_timesteps("ppo", 1000, 24) == 6144  # the defaults: 256 x 4 x 6
    assert effective_timesteps("sac", 1000, 12) == 1008
    assert main([*TINY_CLI, "--timesteps", "1000", "--out", str(tmp_path / "r")]) == 0
    out = capsys.readouterr().out
    assert "--timesteps 1000 runs 1024 timesteps" in out and "n_steps 64" in out
    cfg = json.loads((tmp_path / "r" / "config.json").read_text())
    assert cfg["timesteps_done"] == 1024 and cfg["n_envs"] == 1  # --num-envs is --n-envs
    # SB3 is told what it runs, so its progress bar ends at 1024/1024, not 1024/1000
    assert asked == [1024]


def test_init_from_a_model_that_does_not_fit_names_what_differs(tmp_path, capsys):
    """One short line: the settings that differ (read from the config.json beside the
    model), or, for a bare model.zip, the loader's message cut short (it listed every
    parameter name of the network)."""
    import shutil

    from fov_marl.cli import main

    assert main([*TINY_CLI, "--timesteps", "128", "--out", str(tmp_path / "mlp")]) == 0
    capsys.readouterr()
    run = [*TINY_CLI, "--timesteps", "128", "--init-from", str(tmp_path / "mlp" / "model.zip")]
    for extra, says in (
        (["--arch", "set"], "arch 'mlp' there, 'set' here"),
        (["--belief"], "belief False there, True here"),
        (["--n-agents", "3"], "n_agents 2 there, 3 here"),
    ):
        assert main([*run, *extra, "--out", str(tmp_path / "b")]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "--init-from" in err and says in err, err
        assert len(err) < 250, err
    (tmp_path / "bare").mkdir()
    shutil.copy(tmp_path / "mlp" / "model.zip", tmp_path / "bare" / "model.zip")
    bare = [*TINY_CLI, "--timesteps", "128", "--init-from", str(tmp_path / "bare" / "model.zip")]
    assert main([*bare, "--arch", "set", "--out", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "RuntimeError" in err and err.endswith("...)"), err
    assert len(err) < 450, err


def test_out_holding_a_model_needs_force(tmp_path, capsys):
    from fov_marl.cli import main

    run = [*TINY_CLI, "--timesteps", "128", "--out", str(tmp_path)]
    assert main(run) == 0
    first = (tmp_path / "model.zip").read_bytes()
    capsys.readouterr()
    assert main([*run, "--seed", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--out" in err and "--force" in err
    assert (tmp_path / "model.zip").read_bytes() == first  # untouched
    assert main([*run, "--seed", "1", "--force"]) == 0
    assert json.loads((tmp_path / "config.json").read_text())["seed"] == 1


def test_ctrl_c_saves_says_where_and_exits_130(tmp_path):
    """A real SIGINT while SB3 learns: the model so far is saved and the exit status is 130."""
    import os
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "run"
    argv = [*TINY_CLI, "--timesteps", "1e9", "--out", str(out), "--checkpoint-every", "128"]
    # PYTHONFAULTHANDLER: a child that does not exit after SIGINT is aborted below and
    # dumps every thread's stack into the failure message. preexec_fn: a shell starts a
    # background job with SIGINT ignored and a child inherits SIG_IGN, so Python would
    # never raise KeyboardInterrupt in it (`make test` run in the background: the child
    # trained on for 300 s)
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "PYTHONFAULTHANDLER": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "fov_marl.cli", *argv],
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        line = proc.stdout.readline()  # "train: ... timesteps", printed before learn()
        assert "timesteps" in line, line + proc.stderr.read()
        t0 = time.monotonic()  # a first checkpoint: inside model.learn (generous: under
        # a loaded CI machine the first 128 steps took over 90 s)
        while not list(out.glob("checkpoints/*.zip")) and time.monotonic() - t0 < 300:
            assert proc.poll() is None, proc.stderr.read()
            time.sleep(0.1)
        assert list(out.glob("checkpoints/*.zip")), "no checkpoint within 300 s"
        proc.send_signal(signal.SIGINT)
        try:
            _, err = proc.communicate(timeout=300)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGABRT)
            _, err = proc.communicate(timeout=60)
            pytest.fail(f"no exit within 300 s of SIGINT; the child's stacks:\n{err[-6000:]}")
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "interrupted" in err and "saved" in err and str(out / "model.zip") in err
    assert "Traceback" not in err
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["interrupted"] is True and 0 < cfg["timesteps_done"] < 10**9
    assert load_policy(out / "model.zip").n_agents == 2


def test_train_config_file_and_env(tmp_path, capsys):
    from fov_marl.cli import main

    cfg_file = tmp_path / "cfg.json"
    cfg_file.write_text(json.dumps({"scenario": "crossing", "crossing_radius_m": 10.0}))
    argv = [*TINY_CLI, "--timesteps", "128", "--config", str(cfg_file)]
    assert main([*argv, "--env", "target_tolerance_m=0.7", "--out", str(tmp_path / "a")]) == 0
    cfg = json.loads((tmp_path / "a" / "config.json").read_text())
    assert cfg["scenario"] == "crossing"
    assert cfg["env_kwargs"]["crossing_radius_m"] == 10.0
    assert cfg["env_kwargs"]["target_tolerance_m"] == 0.7
    capsys.readouterr()
    assert main([*argv, "--scenario", "coverage", "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert "--scenario coverage conflicts with --config" in err and len(err.splitlines()) == 1


def test_no_progress_bar_without_tqdm_or_rich(tmp_path, monkeypatch):
    import sys

    from stable_baselines3 import PPO

    seen = []
    real = PPO.learn

    def learn(self, *args, **kwargs):
        seen.append(kwargs["progress_bar"])
        return real(self, *args, **kwargs)

    monkeypatch.setattr(PPO, "learn", learn)
    small = dict(timesteps=64, n_envs=1, env_kwargs={"n_agents": 2}, checkpoint_every=0,
                 hyperparams={"n_steps": 32, "batch_size": 32}, progress_bar=True)  # fmt: skip
    assert _train(tmp_path / "a", **small).exists()
    monkeypatch.setitem(sys.modules, "rich", None)  # import rich -> ImportError
    assert _train(tmp_path / "b", **small).exists()
    assert seen == [True, False]
