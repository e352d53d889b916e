"""Train MAPPO (or IPPO, MASAC, ...) with BenchMARL on fov_coverage_v0, on the CPU.

Run (with the ``[benchmarl]`` extra)::

    python examples/benchmarl_mappo.py                          # 10 iterations, N = 4
    python examples/benchmarl_mappo.py --algorithm masac --iterations 20
    python examples/benchmarl_mappo.py --iterations 1 --frames 200 --max-cycles 50

One import gives the task (:class:`fov_marl.integrations.benchmarl.FovMarlTask`) and
an ``Experiment`` with MLP actor and critic (``make_experiment``); BenchMARL logs to CSV
under ``--out`` (default ``benchmarl_runs/``), including ``collection/fov/final_eta``.
Prints a JSON summary line at the end.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any


def main(argv: list[str] | None = None) -> dict[str, Any]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--algorithm", default="mappo", help="mappo, ippo, masac, ... (mappo)")
    p.add_argument("--iterations", type=int, default=10, help="iterations (default 10)")
    p.add_argument("--frames", type=int, default=2000, help="env steps per iteration (2000)")
    p.add_argument("--n-agents", type=int, default=4, help="robots (default 4)")
    p.add_argument("--max-cycles", type=int, default=200, help="episode length (200)")
    p.add_argument("--safety-filter", action="store_true", help="train behind the filter")
    p.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    p.add_argument("--out", default="benchmarl_runs", help="BenchMARL's save folder")
    args = p.parse_args(argv)
    for name in ("iterations", "frames"):
        if getattr(args, name) < 1:
            sys.exit(f"benchmarl_mappo.py: error: --{name} must be an integer in [1, inf)")

    from pathlib import Path

    from fov_marl.integrations.benchmarl import FovMarlTask, make_experiment

    on = {
        "on_policy_collected_frames_per_batch": args.frames,
        "on_policy_n_envs_per_worker": 2,
        "on_policy_minibatch_size": max(args.frames // 4, 1),
        "on_policy_n_minibatch_iters": 4,
    }
    off = {
        "off_policy_collected_frames_per_batch": args.frames,
        "off_policy_n_envs_per_worker": 2,
        "off_policy_n_optimizer_steps": max(args.frames // 20, 1),
        "off_policy_train_batch_size": 128,
        "off_policy_memory_size": 100_000,
    }
    try:
        task = FovMarlTask.COVERAGE.get_task(
            {
                "n_agents": args.n_agents,
                "max_cycles": args.max_cycles,
                "safety_filter": args.safety_filter,
            }
        )
        Path(args.out).mkdir(parents=True, exist_ok=True)
        exp = make_experiment(
            args.algorithm,
            task,
            seed=args.seed,
            save_folder=str(Path(args.out).resolve()),
            max_n_iters=args.iterations,
            evaluation=False,
            loggers=["csv"],
            **on,
            **off,
        )
    except FileExistsError:
        sys.exit(f"benchmarl_mappo.py: error: --out {args.out} is a file, not a folder")
    except (ValueError, OSError) as exc:
        sys.exit(f"benchmarl_mappo.py: error: {exc}")
    t0 = time.perf_counter()
    exp.run()
    summary = {
        "algorithm": args.algorithm,
        "iterations": exp.n_iters_performed,
        "frames": exp.total_frames,
        "wall_s": round(time.perf_counter() - t0, 2),
        "folder": str(exp.folder_name),
    }
    print(json.dumps(summary))
    return summary


if __name__ == "__main__":
    main()
