"""Issue 12's acceptance figures in one run, with code that runs on older trees too.

Usage (from a checkout; ``PYTHONPATH`` picks the tree to measure, so two trees can be
compared back to back under the same machine load)::

    PYTHONPATH=. .venv/bin/python benchmarks/issue12_figures.py after [--ppo]
    PYTHONPATH=/path/to/old/tree .venv/bin/python benchmarks/issue12_figures.py before --ppo

Prints one dict per figure and writes ``issue12_figures_<tag>.json`` (``--out DIR``,
default the current folder): the batched env against one env (N = 6, B = 64 and 256,
exact and strip η), the batched safety filter at B N = 384 (P_T = 2000 and 500: wall
and process-CPU ms per robot-step, stages), and with ``--ppo`` PPO samples/s at the
trainer's default hyper-parameters (per-copy adapter B = 4; vector adapter B = 4, 16,
64; behind the filter at P_T = 2000 and 500). Every figure carries the 1-minute load
average. It uses only APIs that predate ``fov_marl.bench.bench_ppo`` (the particle
budget is set through ``FILTER_TRACKER_DEFAULTS``), so it measures the tree before the
speed-ups as well; ``fov-marl bench --ppo`` gives the same figures for the current tree.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("tag")
    ap.add_argument("--ppo", action="store_true")
    ap.add_argument("--out", default=".")
    args = ap.parse_args()
    out: dict = {"tag": args.tag, "start": time.strftime("%H:%M:%S"), "rows": []}

    def emit(**r):
        r["load_1min"] = round(os.getloadavg()[0], 2)
        out["rows"].append(r)
        print(r, flush=True)

    import fov_marl
    import fov_marl.wrappers.safety_filter as sf
    from fov_marl.bench import bench_batched_filter, bench_vector_env

    out["fov_marl"] = str(Path(fov_marl.__file__).parent)
    for r in bench_vector_env(((6, (64, 256)),)):
        emit(
            what="vector_env", B=r["num_envs"], eta=r["eta_method"],
            env_steps_per_s=round(r["env_steps_per_s"]),
            single=round(r["single_env_steps_per_s"]), ratio=round(r["ratio"], 2),
        )  # fmt: skip
    saved = dict(sf.FILTER_TRACKER_DEFAULTS)
    try:
        for pt in (2000, 500):
            sf.FILTER_TRACKER_DEFAULTS["n_particles_total"] = pt
            r = bench_batched_filter(n_copies=(64,), steps=10, warmup=2, looped=False)[0]
            emit(
                what="filter", B=64, robots=r["robots"], P_T=pt,
                wall_ms=round(r["batched_ms"], 4), cpu_ms=round(r["batched_cpu_ms"], 4),
                stages={k: round(v, 4) for k, v in r["batched_stage_ms"].items()},
            )  # fmt: skip
    finally:
        sf.FILTER_TRACKER_DEFAULTS.clear()
        sf.FILTER_TRACKER_DEFAULTS.update(saved)
    if args.ppo:
        import torch
        from stable_baselines3 import PPO
        from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

        from fov_marl.training.trainer import (
            _merged_hyperparams,
            _to_sb3_kwargs,
            build_env,
            make_training_vec_env,
        )
        from fov_marl.training.vec_env import ParallelEnvVecEnv

        torch.set_num_threads(1)
        hp = _merged_hyperparams("ppo", {})
        kw = _to_sb3_kwargs(hp)

        def rate(kind: str, n: int, filt: bool, pt: int | None) -> float:
            sk = {"tracker_params": {"n_particles_total": pt}} if pt else None

            def fac():
                return build_env(
                    "coverage", {"max_cycles": 500}, safety_filter=filt, safety_filter_kwargs=sk
                )

            if kind == "vector":
                _, venv = make_training_vec_env(n, fac)
            else:
                venv = VecNormalize(
                    VecMonitor(ParallelEnvVecEnv([fac for _ in range(n)])),
                    norm_obs=True, norm_reward=True, clip_obs=10.0, gamma=0.99,
                )  # fmt: skip
            m = PPO("MlpPolicy", venv, seed=0, device="cpu", **kw)
            t0 = time.perf_counter()
            m.learn(total_timesteps=kw["n_steps"] * venv.num_envs)  # one rollout + its epochs
            return m.num_timesteps / (time.perf_counter() - t0)

        cases = [
            ("per_copy", 4, False, None),
            ("vector", 4, False, None),
            ("vector", 16, False, None),
            ("vector", 64, False, None),
            ("vector", 4, True, None),
            ("vector", 16, True, None),
            ("vector", 16, True, 500),
            ("vector", 64, True, 500),
        ]
        for kind, n, filt, pt in cases:
            emit(
                what="ppo", adapter=kind, n_envs=n, filter=filt,
                P_T=(pt or 2000) if filt else None,
                samples_per_s=round(rate(kind, n, filt, pt)),
            )  # fmt: skip
    out["end"] = time.strftime("%H:%M:%S")
    path = Path(args.out) / f"issue12_figures_{args.tag}.json"
    path.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
