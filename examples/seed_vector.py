"""A vector of seeds on a backend: the same numbers in this process, in worker processes
or on Ray (``--backend ray``, the ``[ray]`` extra).

    python examples/seed_vector.py [--backend ray] [--workers 2]

Prints per-seed final η and the 95% confidence interval of its mean.
"""

from __future__ import annotations

import argparse

from _common import steps

from fov_marl.evaluation import run_episodes, summarize


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--backend", choices=("local", "ray"), default="local")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seeds", type=int, default=4)
    args = parser.parse_args()
    records = run_episodes(
        "coverage",
        "lloyd-pf",
        range(args.seeds),
        n_agents=4,
        max_cycles=steps(300),
        backend=args.backend,
        workers=args.workers,
    )
    for r in records:
        print(f"seed {r.seed}: final eta {r.final_eta:.3f}, min distance {r.min_distance:.2f} m")
    s = summarize(records)["final_eta"]
    print(f"mean {s['mean']:.3f}, 95% CI {s['ci95']}")


if __name__ == "__main__":
    main()
