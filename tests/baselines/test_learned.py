"""The shipped learned policy: loads without torch, runs any N, deterministic, CLI."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from fov_marl.baselines import available_policies, make_policy
from fov_marl.baselines.learned import (
    MODEL_FORMAT,
    SetActorWeights,
    shipped_model_dir,
    trained_filter,
)
from fov_marl.envs import fov_coverage_v0
from fov_marl.evaluation import run_episode


def test_the_shipped_model_loads_and_is_small():
    d = shipped_model_dir()
    cfg = json.loads((d / "config.json").read_text())
    assert cfg["format"] == MODEL_FORMAT
    assert "command" in cfg and "training" in cfg
    assert (d / "weights.npz").stat().st_size <= 200_000
    model = SetActorWeights.load(d)
    assert model.act(np.zeros((3, 5 * 5 + 7), np.float32)).shape == (3, 3)
    assert "learned" in available_policies()


def test_make_policy_learned_needs_no_torch():
    code = (
        "import sys; from fov_marl.envs import fov_coverage_v0; "
        "from fov_marl.baselines import make_policy; "
        "env = fov_coverage_v0.parallel_env(n_agents=5); obs, _ = env.reset(seed=0); "
        "make_policy('learned', env).act(obs); "
        "assert 'torch' not in sys.modules, 'torch imported'"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.parametrize("n_agents", [4, 6, 8, 10, 12])
def test_whole_episodes_for_any_team_size_deterministic(n_agents):
    kw = dict(n_agents=n_agents, fov_deg=120.0, max_cycles=40, eta_grid_m=0.5)
    a = run_episode("coverage", "learned", 7, record_trajectory=True, **kw)
    b = run_episode("coverage", "learned", 7, record_trajectory=True, **kw)
    assert a.steps == 40
    assert a.trajectory == b.trajectory and a.eta_series == b.eta_series
    moved = np.linalg.norm(np.subtract(a.trajectory[-1], a.trajectory[0])[:, :2], axis=1)
    assert np.all(moved > 1.0)  # every robot drives (not a policy stuck at zero)


def test_actions_are_clipped_floats_for_every_agent():
    env = fov_coverage_v0.parallel_env(n_agents=6)
    obs, _ = env.reset(seed=0)
    policy = make_policy("learned", env)
    policy.reset(seed=0)
    act = policy.act(obs)
    assert set(act) == set(obs)
    for a in act.values():
        assert a.dtype == np.float32 and a.shape == (3,) and np.all(np.abs(a) <= 1.0)
    assert policy.act({}) == {}


def test_bad_model_folders_are_errors_naming_the_file(tmp_path):
    env = fov_coverage_v0.parallel_env(n_agents=4)
    with pytest.raises(ValueError, match="weights.npz does not exist|config.json does not exist"):
        make_policy("learned", env, path=tmp_path)
    shutil.copy(shipped_model_dir() / "config.json", tmp_path / "config.json")
    (tmp_path / "weights.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="weights.npz"):
        make_policy("learned", env, path=tmp_path)
    (tmp_path / "config.json").write_text(json.dumps({"format": "other"}))
    with pytest.raises(ValueError, match="format"):
        make_policy("learned", env, path=tmp_path)


def test_cli_evaluate_policy_learned(tmp_path, capsys):
    from fov_marl.cli import main

    args = ["evaluate", "--policy", "learned", "--n-agents", "5", "--episodes", "1",
            "--max-cycles", "20", "--quiet", "--out", str(tmp_path)]  # fmt: skip
    assert main(args) == 0
    res = json.loads((tmp_path / "results.json").read_text())
    assert res["episodes"][0]["policy"] == "learned" and res["episodes"][0]["n_agents"] == 5
    # trained behind the filter, it runs behind it without --safety-filter (alone it collides)
    assert res["episodes"][0]["safety_filter"] is True
    assert res["episodes"][0]["intervention_rate"] is not None


def test_trained_filter_reads_the_models_training_config(tmp_path):
    on, kw = trained_filter()  # the shipped model: trained behind the filter, P_T = 500
    assert on is True and kw == {"tracker_params": {"n_particles_total": 500}}
    d = tmp_path / "m"
    shutil.copytree(shipped_model_dir(), d)
    cfg = json.loads((d / "config.json").read_text())
    cfg["training"]["safety_filter"] = False
    (d / "config.json").write_text(json.dumps(cfg))
    assert trained_filter(d) == (False, None)
    del cfg["training"]
    (d / "config.json").write_text(json.dumps(cfg))
    assert trained_filter(d) == (False, None)
    from fov_marl.evaluation import episode_job

    rec = episode_job(dict(policy=str(d), scenario="coverage", seed=0, n_agents=3, max_steps=5))
    assert rec["safety_filter"] is False  # an export trained without it runs as asked
