"""Evaluate the paper's PF+CBF controller against the ideal baseline on a few seeds.

    python examples/evaluate_baseline.py

Prints one row per (policy, seed) and the mean final coverage efficiency η per policy.
"""

from __future__ import annotations

from _common import steps

from fov_marl.evaluation import run_episodes, summarize
from fov_marl.tables import format_table

SEEDS = [0, 1, 2]


def main() -> None:
    rows, means = [], []
    for policy, fov_deg in (("pfcbf", 120.0), ("ideal", 360.0)):
        records = run_episodes(
            "coverage", policy, SEEDS, n_agents=6, fov_deg=fov_deg, max_cycles=steps(400)
        )
        for r in records:
            rows.append([policy, r.seed, r.final_eta, r.eta_normalised, r.collisions])
        means.append([policy, summarize(records)["final_eta"]["mean"]])
    print(format_table(rows, ["policy", "seed", "final_eta", "eta/eta_opt", "collisions"]))
    print()
    print(format_table(means, ["policy", "mean final_eta"]))


if __name__ == "__main__":
    main()
