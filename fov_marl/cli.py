"""The ``fov-marl`` command line: evaluate, reproduce, render, bench, train.

Run ``fov-marl COMMAND --help`` for each command's options, defaults and units.
Bad arguments print one line naming the flag and exit with status 2.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["main", "build_parser", "format_table"]


class _Parser(argparse.ArgumentParser):
    """argparse, but errors are one line (no usage dump) and exit 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message}\n")


class CliError(ValueError):
    """A bad argument value detected after parsing; names the flag."""


def _positive_int(flag: str):
    def conv(s: str) -> int:
        try:
            v = int(s)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{flag} must be a positive integer, got {s!r}"
            ) from None
        if v < 1:
            raise argparse.ArgumentTypeError(f"{flag} must be a positive integer, got {s!r}")
        return v

    return conv


def _float_in(flag: str, lo: float, hi: float, lo_open: bool = False):
    def conv(s: str) -> float:
        try:
            v = float(s)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{flag} must be a number, got {s!r}") from None
        if not (lo < v if lo_open else lo <= v) or v > hi:
            b = "(" if lo_open else "["
            raise argparse.ArgumentTypeError(f"{flag} must be in {b}{lo}, {hi}], got {s!r}")
        return v

    return conv


def format_table(rows: Sequence[Sequence[Any]], headers: Sequence[str]) -> str:
    """Plain-text table readable in a terminal and in a log."""

    def fmt(v: Any) -> str:
        if v is None:
            return "-"
        if isinstance(v, float):
            return f"{v:.4g}" if abs(v) < 1e4 else f"{v:.3e}"
        return str(v)

    cells = [[fmt(v) for v in r] for r in rows]
    widths = [
        max(len(h), *(len(r[i]) for r in cells)) if cells else len(h) for i, h in enumerate(headers)
    ]
    line = "  ".join(h.rjust(w) for h, w in zip(headers, widths, strict=True))
    sep = "  ".join("-" * w for w in widths)
    body = ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in cells]
    return "\n".join([line, sep, *body])


# ----------------------------------------------------------------- evaluate
EVAL_COLUMNS = (
    "seed",
    "steps",
    "final_eta",
    "time_to_eta_99",
    "collisions",
    "min_distance",
    "cpu_ms_per_robot_step",
)


def _is_model(policy: str) -> bool:
    return policy.endswith(".zip") or os.path.isdir(policy)


def _env_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    """Config keywords given on the command line; scenario/model defaults fill the rest."""
    kw: dict[str, Any] = {}
    for flag in ("n_agents", "fov_deg", "max_cycles"):
        if getattr(args, flag, None) is not None:
            kw[flag] = getattr(args, flag)
    if not _is_model(args.policy):
        kw.setdefault("fov_deg", 120.0)
    return kw


def _episode_job(job: dict[str, Any]) -> dict[str, Any]:
    from fov_marl.evaluation import run_episode

    policy = job.pop("policy")
    if _is_model(policy):
        from fov_marl.training import load_policy  # torch only for learned policies

        loaded = load_policy(policy)
        job = {**loaded.env_kwargs, **job}
        job["safety_filter"] = job.get("safety_filter") or loaded.safety_filter
        rec = run_episode(policy=loaded.factory, **job)
        rec.policy = str(policy)
    else:
        rec = run_episode(policy=policy, **job)
    return rec.to_json()


def run_evaluate(args: argparse.Namespace) -> dict[str, Any]:
    from fov_marl.evaluation import EpisodeRecord, summarize

    env_kwargs = _env_kwargs(args)
    # validate the config once, here, so a bad value is one clear line
    from fov_marl.config import make_config

    make_config(scenario=args.scenario, **env_kwargs)
    jobs = [
        dict(
            scenario=args.scenario,
            policy=args.policy,
            seed=args.seed + k,
            safety_filter=args.safety_filter,
            **env_kwargs,
        )
        for k in range(args.episodes)
    ]
    t0 = time.perf_counter()
    results: list[dict[str, Any]] = []
    if args.workers > 1 and len(jobs) > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(max_workers=min(args.workers, len(jobs))) as ex:
            for k, res in enumerate(ex.map(_episode_job, jobs)):
                results.append(res)
                _progress(k + 1, len(jobs), t0, args.quiet)
    else:
        for k, job in enumerate(jobs):
            results.append(_episode_job(dict(job)))
            _progress(k + 1, len(jobs), t0, args.quiet)
    fields = {f for f in EpisodeRecord.__dataclass_fields__}
    records = [EpisodeRecord(**{k: v for k, v in r.items() if k in fields}) for r in results]
    summary = summarize(records)
    out = {
        "episodes": [r.to_json(with_series=args.save_series) for r in records],
        "summary": summary,
        "args": {k: v for k, v in vars(args).items() if k != "func"},
    }
    rows = [
        [
            r.seed,
            r.steps,
            r.final_eta,
            r.time_to_eta_99,
            r.collisions,
            r.min_distance,
            r.cpu_ms_per_robot_step,
        ]
        for r in records
    ]
    print(format_table(rows, EVAL_COLUMNS))
    srows = []
    for f in ("final_eta", "time_to_eta_99", "collisions", "min_distance", "cpu_ms_per_robot_step"):
        s = summary.get(f)
        if s and s["mean"] is not None:
            srows.append([f, s["mean"], s["std"], s["ci95"][0], s["ci95"][1], s["n"]])
    print()
    print(format_table(srows, ("metric", "mean", "std", "ci95_lo", "ci95_hi", "n")))
    if args.out:
        path = Path(args.out)
        path.mkdir(parents=True, exist_ok=True)
        (path / "results.json").write_text(json.dumps(out, indent=2))
        if not args.quiet:
            print(f"\nwrote {path / 'results.json'}")
    return out


def _progress(k: int, n: int, t0: float, quiet: bool) -> None:
    if quiet:
        return
    el = time.perf_counter() - t0
    bar = "#" * int(20 * k / n)
    sys.stderr.write(f"\r[{bar:<20}] {k}/{n} episodes, {el:.1f} s")
    if k == n:
        sys.stderr.write("\n")
    sys.stderr.flush()


# ------------------------------------------------------------------- render
def run_render(args: argparse.Namespace) -> Path:
    from fov_marl.video import render_episode

    env_kwargs = _env_kwargs(args)
    path = render_episode(
        scenario=args.scenario,
        policy=args.policy,
        seed=args.seed,
        out=Path(args.out),
        safety_filter=args.safety_filter,
        every=args.every,
        fps=args.fps,
        **env_kwargs,
    )
    print(f"wrote {path}")
    return path


# -------------------------------------------------------------------- bench
def run_bench(args: argparse.Namespace) -> list[dict[str, Any]]:
    from fov_marl.bench import run_benchmarks

    rows = run_benchmarks(quick=args.quick, n_agents=args.n_agents)
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        for section in dict.fromkeys(r["section"] for r in rows):
            sub = [r for r in rows if r["section"] == section]
            keys = [k for k in sub[0] if k != "section"]
            print(f"\n== {section} ==")
            print(format_table([[r.get(k) for k in keys] for r in sub], keys))
    return rows


# ---------------------------------------------------------------- reproduce
def run_reproduce(args: argparse.Namespace) -> Path:
    from fov_marl.report import reproduce

    path = reproduce(Path(args.out), quick=args.quick, workers=args.workers, seeds=args.seeds)
    print(f"wrote {path}")
    return path


# -------------------------------------------------------------------- parser
def build_parser() -> argparse.ArgumentParser:
    fmt = argparse.ArgumentDefaultsHelpFormatter
    p = _Parser(prog="fov-marl", description=__doc__, formatter_class=fmt)
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    def scenario_args(sp: argparse.ArgumentParser, policy_default: str = "pfcbf") -> None:
        sp.add_argument("--scenario", choices=("coverage", "crossing"), default="coverage")
        sp.add_argument(
            "--policy",
            default=policy_default,
            help="registered policy (pfcbf, ideal, lloyd-pf, random) or PATH to a trained model.zip",
        )
        sp.add_argument(
            "--n-agents",
            type=_positive_int("--n-agents"),
            default=None,
            help="robots N (default: 6 for coverage, 4 for crossing, or a model's training config)",
        )
        sp.add_argument(
            "--fov-deg",
            type=_float_in("--fov-deg", 0.0, 360.0, lo_open=True),
            default=None,
            help="camera FoV amplitude beta in degrees, (0, 360] (default: 120, or a model's training config)",
        )
        sp.add_argument("--seed", type=int, default=0, help="first seed; episode k uses seed + k")
        sp.add_argument(
            "--safety-filter",
            action="store_true",
            help="wrap the env in SafetyFilterWrapper (the policy's actions become u*)",
        )
        sp.add_argument(
            "--max-cycles",
            type=_positive_int("--max-cycles"),
            default=None,
            help="episode length in steps of dt = 0.2 s (default: the config's, 1000)",
        )

    e = sub.add_parser(
        "evaluate",
        help="run seeded episodes, print a table, write results.json",
        formatter_class=fmt,
    )
    scenario_args(e)
    e.add_argument("--episodes", type=_positive_int("--episodes"), default=5)
    e.add_argument(
        "--workers", type=_positive_int("--workers"), default=1, help="parallel processes"
    )
    e.add_argument("--out", default=None, help="directory for results.json")
    e.add_argument(
        "--save-series", action="store_true", help="store eta(t) per episode in results.json"
    )
    e.add_argument("--quiet", action="store_true", help="no progress bar")
    e.set_defaults(func=run_evaluate)

    r = sub.add_parser(
        "reproduce",
        help="the paper's Section VII experiments: report.md + figures",
        formatter_class=fmt,
    )
    r.add_argument("--out", default="report", help="output directory")
    r.add_argument("--quick", action="store_true", help="reduced version (a few minutes)")
    r.add_argument("--workers", type=_positive_int("--workers"), default=os.cpu_count() or 1)
    r.add_argument(
        "--seeds",
        type=_positive_int("--seeds"),
        default=None,
        help="random starts per experiment (default 5; 2 with --quick)",
    )
    r.set_defaults(func=run_reproduce)

    d = sub.add_parser("render", help="render one episode to .gif/.mp4/.png", formatter_class=fmt)
    scenario_args(d)
    d.add_argument(
        "--out", default="episode.gif", help="output file (.gif, .mp4 or .png for the last frame)"
    )
    d.add_argument(
        "--every", type=_positive_int("--every"), default=5, help="keep every k-th frame"
    )
    d.add_argument("--fps", type=_positive_int("--fps"), default=10)
    d.set_defaults(func=run_render)

    b = sub.add_parser(
        "bench",
        help="per robot-step timings of env, tracker, QP, Lloyd, controller",
        formatter_class=fmt,
    )
    b.add_argument("--json", action="store_true", help="print JSON instead of tables")
    b.add_argument("--quick", action="store_true", help="fewer repetitions")
    b.add_argument(
        "--n-agents",
        type=_positive_int("--n-agents"),
        nargs="+",
        default=None,
        help="team sizes (default 6 9 12 24 48)",
    )
    b.set_defaults(func=run_bench)

    t = sub.add_parser("train", help="train a policy with stable-baselines3", formatter_class=fmt)
    try:
        from fov_marl.training.cli_support import add_train_arguments, run_train

        add_train_arguments(t)
        t.set_defaults(func=run_train)
    except ImportError as exc:  # training extra not installed
        msg = f"training needs the 'train' extra (pip install fov_marl[train]): {exc}"

        def _no_train(_args: argparse.Namespace) -> None:
            raise CliError(msg)

        t.set_defaults(func=_no_train)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        args.func(args)
    except ValueError as exc:  # config and argument errors: one line, no traceback
        if os.environ.get("FOV_MARL_DEBUG"):
            raise
        sys.stderr.write(f"fov-marl {args.command}: error: {exc}\n")
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
