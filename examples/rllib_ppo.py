"""Train one PPO policy shared by all robots on fov_coverage_v0 with RLlib, on a local Ray.

Run (from the repository root, with the ``[rllib]`` extra installed)::

    python examples/rllib_ppo.py                       # 5 iterations, N = 4, 2 CPUs
    python examples/rllib_ppo.py --iterations 50 --n-agents 6 --safety-filter
    python examples/rllib_ppo.py --iterations 1 --train-batch-size 200 --max-cycles 50

Each iteration samples ``--train-batch-size`` env steps (N agent-steps each) in the
driver process (no remote workers), runs PPO's SGD epochs, and prints the mean episode
return (summed over the team, once episodes have ended), the env steps so far and the
wall time. At the end
it saves a checkpoint when ``--out DIR`` is given and prints a JSON summary line.

The env, the shared-policy mapping and the PPO settings come from
:mod:`fov_marl.integrations.rllib` (``ppo_config``); the robots' observations are
egocentric, so one policy fits every robot. ``--safety-filter`` trains behind
:class:`fov_marl.wrappers.SafetyFilterWrapper` (slower: ~0.6 ms per robot-step).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from typing import Any


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--iterations", type=int, default=5, help="PPO iterations (default 5)")
    p.add_argument("--n-agents", type=int, default=4, help="robots (default 4)")
    p.add_argument("--max-cycles", type=int, default=200, help="episode length, steps (200)")
    p.add_argument("--scenario", choices=["coverage", "crossing"], default="coverage")
    p.add_argument("--safety-filter", action="store_true", help="train behind the filter")
    p.add_argument(
        "--train-batch-size", type=int, default=2000, help="env steps per iteration (2000)"
    )
    p.add_argument(
        "--minibatch-size", type=int, default=250, help="SGD minibatch (250; at most the batch)"
    )
    p.add_argument("--num-epochs", type=int, default=5, help="SGD epochs per iteration (5)")
    p.add_argument("--num-cpus", type=int, default=2, help="CPUs of the local Ray (2)")
    p.add_argument("--seed", type=int, default=0, help="seed (0)")
    p.add_argument("--out", default=None, help="save a checkpoint to this folder at the end")
    return p.parse_args(argv)


def _mean_return(result: dict[str, Any]) -> float:
    runners = result.get("env_runners", {})
    value = runners.get("episode_return_mean", float("nan"))
    return float(value) if value is not None else float("nan")


def main(argv: list[str] | None = None) -> dict[str, Any]:
    args = parse_args(argv)
    for name in ("iterations", "num_cpus"):
        if getattr(args, name) < 1:
            flag = "--" + name.replace("_", "-")
            sys.exit(f"rllib_ppo.py: error: {flag} must be an integer in [1, inf)")
    if args.out is not None:  # checked before training: the checkpoint comes at the end
        path = os.path.abspath(args.out)
        while not os.path.exists(path):  # the nearest part of the path that exists
            path = os.path.dirname(path)
        if not os.path.isdir(path):
            sys.exit(f"rllib_ppo.py: error: --out {args.out}: {path} is a file, not a folder")
    from fov_marl.integrations.rllib import ppo_config

    env_config = {
        "scenario": args.scenario,
        "n_agents": args.n_agents,
        "max_cycles": args.max_cycles,
        "safety_filter": args.safety_filter,
    }
    try:
        config = ppo_config(
            env_config,
            train_batch_size=args.train_batch_size,
            minibatch_size=min(args.minibatch_size, args.train_batch_size),
            num_epochs=args.num_epochs,
            seed=args.seed,
        )
    except ValueError as exc:
        sys.exit(f"rllib_ppo.py: error: {exc}")
    import ray

    ray.init(
        num_cpus=args.num_cpus,
        include_dashboard=False,
        log_to_driver=False,
        configure_logging=False,
        ignore_reinit_error=True,
    )
    t0 = time.perf_counter()
    algo = config.build_algo()
    history = []
    try:
        for it in range(1, args.iterations + 1):
            result = algo.train()
            steps = int(result.get("num_env_steps_sampled_lifetime", 0) or 0)
            ret = _mean_return(result)
            history.append(ret)
            shown = "   n/a" if math.isnan(ret) else f"{ret:8.3f}"
            print(
                f"iter {it:3d}  return {shown}  env-steps {steps:7d}  "
                f"{time.perf_counter() - t0:6.1f} s",
                flush=True,
            )
        checkpoint = None
        if args.out is not None:
            checkpoint = str(algo.save_to_path(args.out))
    finally:
        algo.stop()
        ray.shutdown()
    summary = {
        "iterations": args.iterations,
        "returns": [None if math.isnan(r) else r for r in history],
        "wall_s": round(time.perf_counter() - t0, 2),
        "checkpoint": checkpoint,
    }
    print(json.dumps(summary))
    return summary


if __name__ == "__main__":
    main()
