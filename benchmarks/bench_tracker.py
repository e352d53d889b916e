"""Neighbour-tracker speed: ms per robot-step, single NeighborTracker and batched TrackerBank.

Usage::

    .venv/bin/python benchmarks/bench_tracker.py [--p-totals 1000 2000 5000]
        [--n-agents 6 12 48] [--steps 100] [--repeats 3] [--json]
        [--models auto static]   # motion models side by side (auto = the mode mixture)
"""

from __future__ import annotations

import argparse
import json

from fov_marl.estimation.benchmark import bench_tracker, format_table


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--p-totals", type=int, nargs="+", default=[1000, 2000, 5000])
    ap.add_argument("--n-agents", type=int, nargs="+", default=[6, 12, 48])
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=3, help="report the minimum over repeats")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true", help="print JSON rows instead of a table")
    ap.add_argument(
        "--models",
        nargs="+",
        default=["auto"],
        choices=["auto", "mixture", "coverage", "crossing", "static"],
        help="TrackerParams.motion_model values to time",
    )
    args = ap.parse_args(argv)
    rows = bench_tracker(
        args.p_totals,
        args.n_agents,
        steps=args.steps,
        repeats=args.repeats,
        seed=args.seed,
        motion_models=args.models,
    )
    print(json.dumps(rows, indent=2) if args.json else format_table(rows))


if __name__ == "__main__":
    main()
