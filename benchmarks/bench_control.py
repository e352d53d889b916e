"""Control-layer benchmark: per robot-step time of Lloyd, rows, cascade and final QP.

Usage::

    .venv/bin/python benchmarks/bench_control.py [--steps 100] [--n-agents 6 9 12 24 48]
                                                 [--json] [--lloyd] [--backends]

Prints a Markdown table (or JSON with ``--json``). ``--lloyd`` adds the Lloyd stencil
resolution study, ``--backends`` the nnls/osqp comparison of the hierarchical QP.
"""

from __future__ import annotations

import argparse
import json
import sys

from fov_marl.control.benchmark import bench_control, bench_lloyd_resolution, bench_qp_backends


def _table(rows: list[dict], cols: list[tuple[str, str, str]]) -> str:
    head = "| " + " | ".join(c[1] for c in cols) + " |"
    sep = "|" + "|".join("---:" for _ in cols) + "|"
    body = ["| " + " | ".join(format(r[c[0]], c[2]) for c in cols) + " |" for r in rows]
    return "\n".join([head, sep, *body])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n-agents", type=int, nargs="+", default=[6, 9, 12, 24, 48])
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--lloyd", action="store_true", help="also the Lloyd resolution study")
    ap.add_argument("--backends", action="store_true", help="also nnls vs osqp")
    a = ap.parse_args(argv)
    out = {"control": bench_control(tuple(a.n_agents), steps=a.steps, seed=a.seed)}
    if a.lloyd:
        out["lloyd_resolution"] = bench_lloyd_resolution(seed=a.seed)
    if a.backends:
        out["qp_backends"] = bench_qp_backends(seed=a.seed)
    if a.json:
        json.dump(out, sys.stdout, indent=2)
        print()
        return 0
    base = out["control"][0]["total_us"]
    for r in out["control"]:
        r["ratio"] = r["total_us"] / base
    print(
        _table(
            out["control"],
            [
                ("n_agents", "N", "d"),
                ("lloyd_us", "Lloyd µs", ".0f"),
                ("lloyd_batched_us", "Lloyd batched µs", ".0f"),
                ("rows_us", "rows µs", ".0f"),
                ("cascade_us", "cascade µs", ".0f"),
                ("final_us", "final µs", ".0f"),
                ("controller_us", "controller µs", ".0f"),
                ("total_us", "total µs", ".0f"),
                ("p50_total_us", "p50 µs", ".0f"),
                ("p99_total_us", "p99 µs", ".0f"),
                ("ratio", "÷ first N", ".2f"),
                ("qp_per_step", "QPs/step", ".2f"),
                ("relaxed_rate", "relaxed", ".2f"),
                ("fallback_rate", "fallback", ".3f"),
            ],
        )
    )
    if a.lloyd:
        print()
        print(
            _table(
                out["lloyd_resolution"],
                [
                    ("grid_m", "h m", ".2f"),
                    ("stencil_points", "points", "d"),
                    ("mean_err_m", "mean err m", ".4f"),
                    ("p95_err_m", "p95 err m", ".4f"),
                    ("max_err_m", "max err m", ".4f"),
                    ("time_us", "µs", ".0f"),
                ],
            )
        )
    if a.backends:
        print()
        print(
            _table(
                out["qp_backends"],
                [
                    ("backend", "backend", "s"),
                    ("mean_us", "mean µs", ".0f"),
                    ("p99_us", "p99 µs", ".0f"),
                    ("qp_per_case", "QPs", ".2f"),
                    ("degraded_rate", "degraded", ".3f"),
                    ("p90_du", "p90 |Δu|", ".4f"),
                    ("max_du", "max |Δu|", ".4f"),
                    ("max_dkappa", "max |Δκ|", ".4f"),
                ],
            )
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
