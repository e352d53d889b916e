"""Slow, run by hand (``pytest -m slow tests/training``): learned coverage policies on
the paper's setting (coverage, N = 6, β = 120°) against ``random``, the safety filter
and ``pfcbf``.

Knobs (environment variables):

* ``FOV_MARL_SLOW_TIMESTEPS``: comma-separated training budgets (robot-steps), one test
  per value (default ``1000000``);
* ``FOV_MARL_SLOW_OUT``: folder for the runs and ``comparison_<T>.json`` (default: a
  pytest temporary folder);
* ``FOV_MARL_SLOW_SEEDS``: evaluation episodes (default 10, seeds 1000 + k).

Each test prints its timings and the comparison table (run with ``-s`` to see them).
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from fov_marl.infos import metrics_of  # noqa: E402
from fov_marl.training import load_policy, train  # noqa: E402

pytestmark = pytest.mark.slow

TIMESTEPS = [int(float(t)) for t in os.environ.get("FOV_MARL_SLOW_TIMESTEPS", "1e6").split(",")]
N_SEEDS = int(os.environ.get("FOV_MARL_SLOW_SEEDS", "10"))
ENV = {"n_agents": 6, "fov_deg": 120.0}


def _out(tmp_path_factory, name: str) -> Path:
    root = os.environ.get("FOV_MARL_SLOW_OUT")
    if root:
        p = Path(root) / name
        p.mkdir(parents=True, exist_ok=True)
        return p
    return tmp_path_factory.mktemp(name)


def _evaluate(make_env, factory, seeds):
    """Final η, time to η = 0.99 (s), collisions per episode (ground truth, 1000 steps)."""
    rows = []
    for seed in seeds:
        env = make_env()
        obs, _ = env.reset(seed=seed)
        policy = factory(env)
        policy.reset(seed=seed)
        t99 = None
        while env.agents:
            obs, _, _, _, infos = env.step(policy.act(obs))
            m = metrics_of(infos[env.possible_agents[0]])
            if t99 is None and m["eta"] >= 0.99:
                t99 = m["t_s"]
        rows.append(
            {
                "seed": seed,
                "final_eta": m["eta"],
                "time_to_eta_99": t99,
                "collisions": m["collisions_total"],
                "min_distance": m["min_distance_episode"],
            }
        )
    return rows


def _summary(rows):
    etas = np.array([r["final_eta"] for r in rows])
    t99 = [r["time_to_eta_99"] for r in rows if r["time_to_eta_99"] is not None]
    return {
        "final_eta_mean": float(etas.mean()),
        "final_eta_std": float(etas.std()),
        "reached_099": len(t99),
        "time_to_eta_99_mean": float(np.mean(t99)) if t99 else None,
        "collisions_total": int(sum(r["collisions"] for r in rows)),
        "min_distance": float(min(r["min_distance"] for r in rows)),
    }


@pytest.mark.parametrize("timesteps", TIMESTEPS)
def test_ppo_beats_random_on_final_eta(timesteps, tmp_path_factory):
    from fov_marl.baselines import make_policy

    out = _out(tmp_path_factory, f"ppo_{timesteps}")
    t0 = time.perf_counter()
    path = train("ppo", timesteps=timesteps, seed=0, out_dir=out, env_kwargs=ENV)
    wall = time.perf_counter() - t0
    policy = load_policy(path)
    seeds = [1000 + k for k in range(N_SEEDS)]
    learned = _evaluate(policy.make_env, policy.factory, seeds)
    rand = _evaluate(policy.make_env, lambda env: make_policy("random", env), seeds)
    res = {
        "timesteps": timesteps,
        "train_wall_s": wall,
        "samples_per_s": timesteps / wall,
        "learned": _summary(learned),
        "random": _summary(rand),
        "episodes": {"learned": learned, "random": rand},
    }
    (out / f"beats_random_{timesteps}.json").write_text(json.dumps(res, indent=2))
    print(json.dumps({k: v for k, v in res.items() if k != "episodes"}, indent=2))
    gap = res["learned"]["final_eta_mean"] - res["random"]["final_eta_mean"]
    assert gap > 0.3, f"learned final η only {gap:+.3f} above random"


@pytest.mark.parametrize("timesteps", TIMESTEPS)
def test_learned_vs_learned_filter_vs_pfcbf(timesteps, tmp_path_factory):
    """The issue's comparison over ``N_SEEDS`` seeds; the filtered policy must not collide."""
    wrappers = pytest.importorskip("fov_marl.wrappers")
    if not hasattr(wrappers, "SafetyFilterWrapper"):
        pytest.skip("SafetyFilterWrapper not built yet")
    from fov_marl.baselines import available_policies, make_policy

    out = _out(tmp_path_factory, f"compare_{timesteps}")
    seeds = [1000 + k for k in range(N_SEEDS)]
    results, timing = {}, {}
    for name, filt in (("ppo", False), ("ppo+filter", True)):
        t0 = time.perf_counter()
        path = train(
            "ppo",
            timesteps=timesteps,
            seed=0,
            out_dir=out / name.replace("+", "_"),
            env_kwargs=ENV,
            safety_filter=filt,
        )
        timing[name] = time.perf_counter() - t0
        policy = load_policy(path)
        results[name] = _evaluate(policy.make_env, policy.factory, seeds)
    plain = load_policy(out / "ppo" / "model.zip")
    results["ppo, filter at test only"] = _evaluate(
        lambda: wrappers.SafetyFilterWrapper(plain.make_env()), plain.factory, seeds
    )
    if "pfcbf" in available_policies():
        results["pfcbf"] = _evaluate(plain.make_env, lambda env: make_policy("pfcbf", env), seeds)
    summary = {k: _summary(v) for k, v in results.items()}
    res = {"timesteps": timesteps, "train_wall_s": timing, "summary": summary, "episodes": results}
    (out / f"comparison_{timesteps}.json").write_text(json.dumps(res, indent=2))
    print(json.dumps({"train_wall_s": timing, "summary": summary}, indent=2))
    assert summary["ppo+filter"]["collisions_total"] == 0
