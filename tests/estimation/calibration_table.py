"""Calibration table of tracker motion models across neighbour behaviours.

Usage (from the repository root)::

    .venv/bin/python -m tests.estimation.calibration_table [--models mixture static coverage]
        [--behaviours pfcbf random ...] [--seeds 10 11 12 13] [--steps 300]
        [--start cluster|random] [--workers 1]

For every (model, behaviour): the fraction of (robot, neighbour, step) samples whose
truth is inside the reported 95% ellipse, overall, per category and for the pairs within
10 m ("near"), and the mean semi-major axis over all samples and over the near pairs. See
:mod:`tests.estimation.behaviours` for the behaviours and the start poses.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor

from fov_marl.estimation import TrackerParams
from fov_marl.estimation.testing import CalibrationCounter

from .behaviours import BEHAVIOURS, behaviour_counter


def _one(args):
    model, name, steps, seed, start = args
    return behaviour_counter(name, TrackerParams(motion_model=model), steps, seed, start)


def table(models, behaviours, seeds, steps, start, workers=1) -> list[dict]:
    """Rows ``{model, behaviour, stats}`` (``stats`` from :meth:`CalibrationCounter.stats`)."""
    jobs = [(m, b, steps, s, start) for m in models for b in behaviours for s in seeds]
    if workers > 1:
        with ProcessPoolExecutor(workers) as pool:
            res = list(pool.map(_one, jobs))
    else:
        res = [_one(j) for j in jobs]
    rows = []
    for m in models:
        for b in behaviours:
            c = CalibrationCounter()
            for job, r in zip(jobs, res, strict=True):
                if job[0] == m and job[1] == b:
                    c.merge(r)
            rows.append(dict(model=m, behaviour=b, stats=c.stats()))
    return rows


def format_rows(rows: list[dict]) -> str:
    head = (
        f"{'model':9s} {'behaviour':14s} {'rate':>6s} {'det':>6s} {'recent':>6s} {'long':>6s}"
        f" {'near':>6s} {'a all':>6s} {'a near':>6s}"
    )
    lines = [head]
    for r in rows:
        st = r["stats"]
        lines.append(
            f"{r['model']:9s} {r['behaviour']:14s} {st['all']['rate']:6.3f} "
            f"{st['detected']['rate']:6.3f} {st['recent']['rate']:6.3f} {st['long']['rate']:6.3f} "
            f"{st['near']['rate']:6.3f} {st['all']['mean_a_m']:6.1f} {st['near']['mean_a_m']:6.1f}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--models", nargs="+", default=["mixture"])
    ap.add_argument("--behaviours", nargs="+", default=list(BEHAVIOURS))
    ap.add_argument("--seeds", type=int, nargs="+", default=[10, 11, 12, 13])
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--start", choices=["cluster", "random"], default="cluster")
    ap.add_argument("--workers", type=int, default=1)
    a = ap.parse_args(argv)
    rows = table(a.models, a.behaviours, a.seeds, a.steps, a.start, a.workers)
    print(format_rows(rows))


if __name__ == "__main__":
    main()
