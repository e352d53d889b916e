"""The ``fov-marl`` command line: evaluate, reproduce, render, bench, train, stress.

Run ``fov-marl COMMAND --help`` for each command's options, defaults and units;
``fov-marl --version`` prints the version.

Scenario config. Every command that builds an env takes ``--config FILE.json`` (a JSON
object of :class:`~fov_marl.config.ScenarioConfig` fields, e.g. ``to_dict()`` saved with
``json.dump``) and ``--env FIELD=VALUE`` (repeatable); precedence, lowest first: the
scenario defaults, a trained model's ``config.json``, ``--config``, ``--env``, the
dedicated flags (``--n-agents``, ``--fov-deg``, ``--max-cycles``). ``evaluate`` and
``render`` take a trained model as ``--policy`` (a ``.zip`` or a run folder); evaluating
it on another scenario or team size than it was trained on is an error.

Backends. ``evaluate``, ``reproduce`` and ``stress`` take ``--backend {local,ray}`` and
``--ray-address ADDR`` (:mod:`fov_marl.backends`): the same numbers for the same seeds.
Progress bars (tqdm, else rich, else none) count simulated steps.

Errors. A user mistake (a bad flag value, an unreadable or foreign model file, an
output path that cannot be written) prints one line on stderr naming the flag or file
and what is wrong, and exits with status 2, before any work starts where it can be
checked up front (``--out`` paths, ``--policy`` files, the scenario config,
``train --hp``). Unexpected internal errors (an exception other than ``ValueError``
or ``OSError``, or one raised inside a third-party library rather than by
fov_marl's own checks) still show their traceback, so real bugs are not hidden;
``--debug`` (anywhere on the command line, or ``FOV_MARL_DEBUG=1``) shows the
traceback for user mistakes too. Ctrl-C exits with status 130 without a traceback
(``train`` first saves the model trained so far and says where).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from fov_marl.filter_options import add_filter_arguments, check_filter_config, filter_kwargs
from fov_marl.jsonio import json_text, write_json
from fov_marl.tables import format_records, format_table
from fov_marl.validation import MAX_SEED, check_out_dir, check_out_file, check_writable
from fov_marl.video import MAX_RENDER_FRAMES

__all__ = ["main", "build_parser", "format_table", "CliError"]

_PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__))


class _Parser(argparse.ArgumentParser):
    """argparse, but errors are one line (no usage dump) and exit 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        if message.rstrip().endswith("unrecognized arguments:"):  # only empty strings left
            message = message.rstrip() + " '' (an empty argument)"
        self.exit(2, f"{self.prog}: error: {_one_line(message)}\n")


class CliError(ValueError):
    """A bad argument value detected after parsing; names the flag."""


def _one_line(text: Any) -> str:
    return " ".join(str(text).split()) or "(no message)"


def _int_in(flag: str, lo: int, hi: int | None = None):
    """argparse type: an integer (decimal digits) in ``[lo, hi]``."""
    allowed = f"an integer in [{lo}, {hi}]" if hi is not None else f"an integer >= {lo}"

    def conv(s: str) -> int:
        try:
            v = int(s.strip())
        except ValueError:
            raise argparse.ArgumentTypeError(f"{flag} must be {allowed}, got {s!r}") from None
        if v < lo or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(f"{flag} must be {allowed}, got {s!r}")
        return v

    return conv


def _positive_int(flag: str, hi: int | None = None):
    return _int_in(flag, 1, hi)


def _float_in(flag: str, lo: float, hi: float, lo_open: bool = False):
    """argparse type: a finite real in ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``)."""
    b = "(" if lo_open else "["

    def conv(s: str) -> float:
        try:
            v = float(s)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{flag} must be a number in {b}{lo}, {hi}], got {s!r}"
            ) from None
        if not math.isfinite(v) or not (lo < v if lo_open else lo <= v) or v > hi:
            raise argparse.ArgumentTypeError(f"{flag} must be in {b}{lo}, {hi}], got {s!r}")
        return v

    return conv


# ----------------------------------------------------------------- evaluate
EVAL_COLUMNS = (
    "seed",
    "steps",
    "final_eta",
    "eta_normalised",
    "time_to_eta_norm_s",
    "time_to_eta_99",
    "time_to_settle_s",
    "collisions",
    "min_distance",
    "cpu_ms_per_robot_step",
)
#: the episode table's columns per scenario (EpisodeRecord fields)
EVAL_COLUMNS_BY_SCENARIO = {
    "coverage": EVAL_COLUMNS,
    "crossing": (
        "seed",
        "steps",
        "arrived",
        "time_to_arrival_s",
        "mean_time_to_arrive_s",
        "safety_violations",
        "collisions",
        "min_distance",
        "cpu_ms_per_robot_step",
    ),
}

#: CLI flags that set scenario config fields
_CONFIG_FLAGS = {"n_agents": "--n-agents", "fov_deg": "--fov-deg", "max_cycles": "--max-cycles"}


def _shown(value: Any) -> Any:
    """An episode-table cell: a non-finite number (``min_distance`` of a one-robot team:
    no pair) shows as ``-``, as the summary leaves it out."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _is_model(policy: str) -> bool:
    from fov_marl.evaluation import is_model_path

    return is_model_path(policy)


def _check_policy(args: argparse.Namespace) -> Any | None:
    """``--policy``: a registered name (returns None) or a trained model (returns it
    loaded), checked before any episode runs."""
    policy = args.policy
    from fov_marl.evaluation import is_exported_policy

    if is_exported_policy(policy):  # an exported set policy: numpy, any N
        from fov_marl.baselines.learned import SetActorWeights

        try:
            SetActorWeights.load(policy)
        except ValueError as exc:
            raise CliError(f"--policy {_one_line(exc)}") from None
        return None
    if _is_model(policy):
        try:
            from fov_marl.training import load_policy  # torch only for learned policies
        except ImportError as exc:
            raise CliError(
                f"--policy {policy}: loading a trained model needs the 'train' extra "
                f"(pip install 'fov_marl[train]'): {exc}"
            ) from None
        try:
            loaded = load_policy(policy)
        except ValueError as exc:
            raise CliError(f"--policy {_one_line(exc)}") from None
        return loaded
    from fov_marl.baselines import available_policies

    names = available_policies()
    if policy not in names:
        raise CliError(
            f"--policy must be a registered policy {names} or the path of a trained "
            f"model.zip, got {policy!r}"
        )
    return None


def _resolve_scenario(args: argparse.Namespace, loaded: Any | None, file_scenario: Any) -> str:
    """``--scenario``, else the ``--config`` file's, else the model's, else coverage; a
    trained model evaluated on another scenario than its own is an error."""
    given = getattr(args, "scenario", None)
    if file_scenario is not None and file_scenario not in ("coverage", "crossing"):
        raise CliError(
            f"--config {args.config}: scenario must be 'coverage' or 'crossing', "
            f"got {file_scenario!r}"
        )
    if given is not None and file_scenario is not None and given != file_scenario:
        raise CliError(
            f"--scenario {given} conflicts with --config {args.config}, whose scenario is "
            f"{file_scenario!r}; give one of them"
        )
    want = given or file_scenario
    if loaded is not None and want is not None and want != loaded.scenario:
        flag = f"--scenario {want}" if given else f"--config {args.config}"
        raise CliError(
            f"{flag}: the model {args.policy} was trained on the {loaded.scenario!r} "
            f"scenario (its observations and rewards differ); evaluate it with "
            f"--scenario {loaded.scenario}"
        )
    return want or (loaded.scenario if loaded is not None else "coverage")


def _check_config(args: argparse.Namespace, loaded: Any | None) -> dict[str, Any]:
    """Resolve and validate the scenario config before any episode runs.

    Precedence, lowest first: the scenario's defaults, a model's ``config.json``,
    ``--config FILE``, ``--env FIELD=VALUE``, the dedicated flags (``--n-agents``,
    ``--fov-deg``, ``--max-cycles``). Sets ``args.scenario`` to the scenario used.

    Returns:
        The config keywords to pass on (a model's own fields excluded: the worker
        loading it adds them).
    """
    from fov_marl.config import ConfigError, cli_overrides, make_config, source_of_error

    try:
        file_scenario, kw, sources = cli_overrides(
            getattr(args, "config", None), getattr(args, "env", None)
        )
    except ConfigError as exc:
        raise CliError(_one_line(exc)) from None
    args.scenario = _resolve_scenario(args, loaded, file_scenario)
    for field_name, flag in _CONFIG_FLAGS.items():
        value = getattr(args, field_name, None)
        if value is None:
            continue
        if sources.get(field_name) == "--env" and kw[field_name] != value:
            raise CliError(
                f"--env {field_name}={kw[field_name]!r} conflicts with {flag} {value}; give "
                "one of them"
            )
        kw[field_name] = value
        sources[field_name] = f"{flag} {value}"
    if loaded is None:
        kw.setdefault("fov_deg", 120.0)
    base = dict(loaded.env_kwargs) if loaded is not None else {}
    try:
        cfg = make_config(scenario=args.scenario, **{**base, **kw})
    except ConfigError as exc:
        src = source_of_error(str(exc), sources)
        if src is None and len(sources) == 1:
            src = next(iter(sources.values()))
        if src is not None:
            raise CliError(f"{src}: {_one_line(exc)}") from None
        if loaded is not None:
            raise CliError(f"--policy {args.policy}: its config.json: {_one_line(exc)}") from None
        raise CliError(_one_line(exc)) from None
    args.resolved_config = cfg.to_dict()  # what the episodes ran on (results.json)
    if loaded is not None and cfg.n_agents != loaded.n_agents:
        src = sources.get("n_agents", "--n-agents")
        raise CliError(
            f"{src}: the model {args.policy} was trained with n_agents = "
            f"{loaded.n_agents} (its observation size depends on it)"
        )
    return kw


def _check_backend(args: argparse.Namespace) -> None:
    from fov_marl.backends import check_backend

    check_backend(args.backend, args.ray_address)


def _workers(args: argparse.Namespace) -> int:
    """``--workers``, by default 1 locally and every CPU of a local Ray."""
    if args.workers is not None:
        return args.workers
    return (os.cpu_count() or 1) if args.backend == "ray" else 1


def _filter_kwargs(args: argparse.Namespace, loaded: Any | None) -> dict[str, Any] | None:
    """``--filter-tracker`` / ``--filter-controller`` (:mod:`fov_marl.filter_options`); a
    model trained behind the filter (a ``model.zip``, ``learned``, an exported folder) runs
    behind it without ``--safety-filter``."""
    from fov_marl.evaluation import learned_filter

    on = bool(
        args.safety_filter or getattr(loaded, "safety_filter", False) or learned_filter(args.policy)
    )
    out = filter_kwargs(
        args.filter_tracker, args.filter_controller, on, init=getattr(args, "filter_init", None)
    )
    if on and getattr(args, "resolved_config", None) is not None:  # after _check_config
        from fov_marl.config import ScenarioConfig

        check_filter_config(ScenarioConfig.from_dict(args.resolved_config), out)
    return out


def run_evaluate(args: argparse.Namespace) -> dict[str, Any]:
    from fov_marl.evaluation import run_episodes, summarize

    # every check before the first episode: output folder, backend, policy, config
    out_dir = check_out_dir("--out", args.out) if args.out is not None else None
    _check_backend(args)
    loaded = _check_policy(args)
    env_kwargs = _check_config(args, loaded)
    sf_kwargs = _filter_kwargs(args, loaded)
    if out_dir is not None:  # the last check: before the episodes, not after them
        check_writable("--out", [out_dir / "results.json"])
    records = run_episodes(
        args.scenario,
        args.policy,
        [args.seed + k for k in range(args.episodes)],
        safety_filter=args.safety_filter,
        backend=args.backend,
        workers=_workers(args),
        ray_address=args.ray_address,
        progress=not args.quiet,
        safety_filter_kwargs=sf_kwargs,
        **env_kwargs,
    )
    summary = summarize(records)
    out = {
        "episodes": [r.to_json(with_series=args.save_series) for r in records],
        "summary": summary,
        "args": {k: v for k, v in vars(args).items() if k not in ("func", "resolved_config")},
        # the scenario config in force (--config file, --env, flags and a model's own
        # fields resolved) and the code that ran, so the record stands on its own
        "config": args.resolved_config,
        "fov_marl_version": _version(),
    }
    columns = EVAL_COLUMNS_BY_SCENARIO[args.scenario]
    print(format_table([[_shown(getattr(r, c)) for c in columns] for r in records], columns))
    srows = []
    for f in columns[2:]:
        s = summary.get(f)
        if s and (s["mean"] is not None or s["n"] == 0 and s["missing"]):
            lo, hi = s.get("ci95") or (None, None)  # None for a single episode
            srows.append([f, s["mean"], s["std"], lo, hi, s["n"]])  # n 0: none got there
    print()
    print(format_table(srows, ("metric", "mean", "std", "ci95_lo", "ci95_hi", "n")))
    causes = summary.get("intervention_causes")
    if causes and any(causes.values()):
        crows = sorted(([c, v] for c, v in causes.items() if v > 0), key=lambda r: -r[1])
        print()
        print(format_table(crows, ("filter changed the action for", "share of robot-steps")))
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        write_json(out_dir / "results.json", out, indent=2)
        if not args.quiet:
            print(f"\nwrote {out_dir / 'results.json'}")
    return out


# ------------------------------------------------------------------- render
RENDER_SUFFIXES = (".gif", ".mp4", ".png")


def run_render(args: argparse.Namespace) -> Path:
    from fov_marl.config import make_config
    from fov_marl.video import check_writer, frame_count, parse_beliefs_of, render_episode

    out = check_out_file("--out", args.out, RENDER_SUFFIXES)
    check_writer(out)  # .mp4 needs imageio-ffmpeg: say so before simulating
    loaded = _check_policy(args)
    env_kwargs = _check_config(args, loaded)
    base = dict(loaded.env_kwargs) if loaded is not None else {}
    cfg = make_config(scenario=args.scenario, **{**base, **env_kwargs})
    beliefs = parse_beliefs_of(args.beliefs_of, cfg.n_agents)
    sf_kwargs = _filter_kwargs(args, loaded)
    steps = cfg.max_cycles
    frames = frame_count(steps, args.every)  # t = 0, every k-th step, the final state
    if frames > MAX_RENDER_FRAMES and out.suffix.lower() == ".gif":  # kept in memory
        raise CliError(
            f"--every {args.every}: an episode of {steps} steps keeps {frames} frames in "
            f"memory (640 x 640 RGB each: the start, every {args.every}-th step and the "
            f"end); at most {MAX_RENDER_FRAMES}: raise --every to "
            f"{-(-steps // (MAX_RENDER_FRAMES - 1))}, lower --max-cycles or write a .mp4 "
            "(streamed) or a .png (the final state)"
        )
    # the last check: a trial write (a virtual or read-only file system, /proc, /sys),
    # so the episode never ends in a write error
    check_writable("--out", [out])
    path = render_episode(
        scenario=args.scenario,
        policy=args.policy,
        seed=args.seed,
        out=out,
        safety_filter=args.safety_filter,
        every=args.every,
        fps=args.fps,
        beliefs_of=beliefs,
        legend=not args.no_legend,
        safety_filter_kwargs=sf_kwargs,
        **env_kwargs,
    )
    print(f"wrote {path}")
    return path


# -------------------------------------------------------------------- bench
BENCH_MAX_AGENTS = 100


def run_bench(args: argparse.Namespace) -> list[dict[str, Any]]:
    from fov_marl.bench import run_benchmarks

    rows = run_benchmarks(quick=args.quick, n_agents=args.n_agents, ppo=args.ppo)
    if args.json:
        print(json_text(rows, indent=2))
    else:
        for section in dict.fromkeys(r["section"] for r in rows):
            sub = [r for r in rows if r["section"] == section]
            print(f"\n== {section} ==")
            # every key of the section's rows; batched_stage_ms -> batched_stage_ms.qp, ...
            print(format_records(sub, exclude=("section",)))
    return rows


# ---------------------------------------------------------------- reproduce
def run_reproduce(args: argparse.Namespace) -> Path:
    from fov_marl.report import OUTPUT_FILES, reproduce

    out = check_out_dir("--out", args.out)
    check_out_dir("--out", out / "cache")  # the run cache is a folder inside it
    check_writable("--out", [out / name for name in OUTPUT_FILES])
    _check_backend(args)
    path = reproduce(
        out,
        quick=args.quick,
        workers=_workers(args),
        seeds=args.seeds,
        backend=args.backend,
        ray_address=args.ray_address,
        progress=not args.quiet,
    )
    print(f"wrote {path}")
    return path


# -------------------------------------------------------------------- parser
class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows ``(default: X)`` once: only when the help text does not already say what
    the default is, and never for flags (``store_true``) or ``None`` defaults."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if (
            "default" in text.lower()
            or action.default in (None, False, argparse.SUPPRESS)
            or isinstance(action, argparse._StoreTrueAction | argparse._VersionAction)
        ):
            return text
        return super()._get_help_string(action)


def _version() -> str:
    from fov_marl import __version__

    return __version__


def add_env_arguments(sp: argparse.ArgumentParser) -> None:
    """``--config FILE`` and ``--env FIELD=VALUE``: scenario config fields of any command
    that builds an env."""
    sp.add_argument(
        "--config",
        metavar="FILE.json",
        default=None,
        help="scenario config fields from a JSON object (e.g. ScenarioConfig.to_dict() "
        "saved with json.dump; any subset); --env and the dedicated flags override it",
    )
    sp.add_argument(
        "--env",
        action="append",
        metavar="FIELD=VALUE",
        help="any scenario config field, repeatable, VALUE parsed as JSON (e.g. --env "
        "density_sigma_m=4 --env density_mean_m=[10,10]); overrides --config",
    )


def add_backend_arguments(sp: argparse.ArgumentParser, workers_default: Any = None) -> None:
    """``--backend {local,ray}``, ``--ray-address`` and ``--workers``."""
    sp.add_argument(
        "--backend",
        choices=("local", "ray"),
        default="local",
        help="where episodes run: local processes, or Ray tasks (the [ray] extra; a local "
        "Ray unless --ray-address); the same numbers for the same seeds",
    )
    sp.add_argument(
        "--ray-address",
        default=None,
        metavar="ADDR",
        help="an existing Ray cluster ('auto' or ray://host:10001) for --backend ray "
        "(default: start a local Ray with --workers CPUs)",
    )
    sp.add_argument(
        "--workers",
        type=_positive_int("--workers", 256),
        default=workers_default,
        help="parallel processes (local) or CPUs of a local Ray, in [1, 256] "
        + (
            f"(default: {workers_default})"
            if workers_default is not None
            else "(default: 1 local, every CPU with --backend ray)"
        ),
    )


def build_parser() -> argparse.ArgumentParser:
    fmt = _HelpFormatter
    p = _Parser(prog="fov-marl", description=__doc__, formatter_class=fmt)
    p.add_argument(
        "--version", action="version", version=f"fov-marl {_version()}", help="print the version"
    )
    p.add_argument(
        "--debug",
        action="store_true",
        help="show the traceback of every error, user mistakes included",
    )
    # --debug is accepted after the command too (default SUPPRESS keeps the top one)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--debug", action="store_true", default=argparse.SUPPRESS, help="show tracebacks"
    )
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    def scenario_args(sp: argparse.ArgumentParser, policy_default: str = "pfcbf") -> None:
        sp.add_argument(
            "--scenario",
            choices=("coverage", "crossing"),
            default=None,
            help="coverage (paper VII-A/B/C) or crossing (VII-D) (default: a model's "
            "own scenario, the --config file's, else coverage)",
        )
        sp.add_argument(
            "--policy",
            default=policy_default,
            help="registered policy (pfcbf, ideal, lloyd-pf, random, learned: the shipped "
            "size-independent model) or PATH to a trained model.zip, its run folder, or an "
            "exported set policy folder (weights.npz + config.json, any --n-agents) "
            f"(default: {policy_default})",
        )
        sp.add_argument(
            "--n-agents",
            type=_int_in("--n-agents", 1, 256),
            default=None,
            help="robots N in [1, 256] (default: 6 for coverage, 4 for crossing, or a model's "
            "training config)",
        )
        sp.add_argument(
            "--fov-deg",
            type=_float_in("--fov-deg", 0.0, 360.0, lo_open=True),
            default=None,
            help="camera FoV amplitude beta in degrees, (0, 360] (default: 120, or a model's "
            "training config)",
        )
        sp.add_argument(
            "--seed",
            type=_int_in("--seed", 0, MAX_SEED),
            default=0,
            help=f"first seed in [0, {MAX_SEED}]; episode k uses seed + k (default: 0)",
        )
        sp.add_argument(
            "--safety-filter",
            action="store_true",
            help="wrap the env in SafetyFilterWrapper (the policy's actions become u*)",
        )
        add_filter_arguments(sp)
        sp.add_argument(
            "--max-cycles",
            type=_positive_int("--max-cycles"),
            default=None,
            help="episode length in steps of dt = 0.2 s (default: the config's, 1000)",
        )
        add_env_arguments(sp)

    e = sub.add_parser(
        "evaluate",
        help="run seeded episodes, print a table, write results.json",
        formatter_class=fmt,
        parents=[common],
    )
    scenario_args(e)
    e.add_argument(
        "--episodes",
        type=_positive_int("--episodes", 10**6),
        default=5,
        help="episodes to run, an integer in [1, 1000000]",
    )
    add_backend_arguments(e)
    e.add_argument("--out", default=None, help="directory for results.json (default: none)")
    e.add_argument(
        "--save-series", action="store_true", help="store eta(t) per episode in results.json"
    )
    e.add_argument("--quiet", action="store_true", help="no progress bar")
    e.set_defaults(func=run_evaluate)

    r = sub.add_parser(
        "reproduce",
        help="the paper's Section VII experiments: report.md + figures",
        formatter_class=fmt,
        parents=[common],
    )
    r.add_argument("--out", default="report", help="output directory")
    r.add_argument(
        "--quick", action="store_true", help="every section at a tiny size (under a minute)"
    )
    add_backend_arguments(r, workers_default=min(os.cpu_count() or 1, 256))
    r.add_argument(
        "--seeds",
        type=_positive_int("--seeds", 1000),
        default=None,
        help="random starts per coverage condition, in [1, 1000] (default 20; 2 with --quick); "
        "finished runs are cached in OUT/cache, so an interrupted run resumes",
    )
    r.add_argument("--quiet", action="store_true", help="no progress bar on stderr")
    r.set_defaults(func=run_reproduce)

    d = sub.add_parser(
        "render",
        help="render one episode to .gif/.mp4/.png",
        formatter_class=fmt,
        parents=[common],
    )
    scenario_args(d)
    d.add_argument(
        "--out",
        default="episode.gif",
        help="output file: .gif, .mp4 (the [video] extra: imageio-ffmpeg) or .png (the "
        "final state)",
    )
    d.add_argument(
        "--every",
        type=_positive_int("--every"),
        default=5,
        help="draw the state every k steps: the frames are t = 0, every k-th step and "
        f"always the final state (a .gif keeps at most {MAX_RENDER_FRAMES} frames in memory; "
        "a .mp4 is streamed; a .png draws only the final state)",
    )
    d.add_argument(
        "--fps", type=_positive_int("--fps", 100), default=10, help="frames per second, [1, 100]"
    )
    d.add_argument(
        "--beliefs-of",
        default="robot_0",
        metavar="robot_k|all|none",
        help="whose particle filters to draw: one robot (an agent name, robot_0 ... "
        "robot_{N-1}), every robot, or none (PF+CBF policies and --safety-filter)",
    )
    d.add_argument("--no-legend", action="store_true", help="draw no legend")
    d.set_defaults(func=run_render)

    b = sub.add_parser(
        "bench",
        help="per robot-step timings of env, tracker, QP, Lloyd, controller",
        formatter_class=fmt,
        parents=[common],
    )
    b.add_argument("--json", action="store_true", help="print JSON instead of tables")
    b.add_argument("--quick", action="store_true", help="fewer repetitions")
    b.add_argument(
        "--ppo",
        action="store_true",
        help="also PPO samples/s (vector vs per-copy adapter, with and without the safety "
        "filter; needs the train extra; minutes)",
    )
    b.add_argument(
        "--n-agents",
        type=_int_in("--n-agents", 2, BENCH_MAX_AGENTS),
        nargs="+",
        default=None,
        help=f"team sizes of the tracker, control and controller sections, each in [2, "
        f"{BENCH_MAX_AGENTS}] (they need a neighbour); the env, vector_env, vector_filter, "
        "filtered_step and issue sections keep their own sizes (N = 6 and 48, the "
        "issues' figures; issue10's paper-arena controller rows run at N = 6 and 48 too) "
        "(default 6 9 12 24 48; the tracker 6 12 48)",
    )
    b.set_defaults(func=run_bench)

    t = sub.add_parser(
        "train",
        help="train a policy with stable-baselines3",
        formatter_class=fmt,
        parents=[common],
    )
    try:
        from fov_marl.training.cli_support import add_train_arguments, run_train

        add_train_arguments(t)
        t.set_defaults(func=run_train)
    except ImportError as exc:  # training extra not installed
        msg = f"training needs the 'train' extra (pip install 'fov_marl[train]'): {exc}"

        def _no_train(_args: argparse.Namespace) -> None:
            raise CliError(msg)

        t.set_defaults(func=_no_train)
    from fov_marl.stress import add_stress_parser

    stress = add_stress_parser(sub)
    if not any("--debug" in a.option_strings for a in stress._actions):
        stress.add_argument(
            "--debug", action="store_true", default=argparse.SUPPRESS, help="show tracebacks"
        )
    return p


def _command_parser(parser: argparse.ArgumentParser, command: str | None) -> Any:
    """The subparser of ``command`` (``fov-marl render``), else ``parser`` itself."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction) and command in action.choices:
            return action.choices[command]
    return parser


def _raised_by_fov_marl(exc: BaseException) -> bool:
    """True when ``exc`` was raised by fov_marl's own code (its argument checks), not
    inside a third-party library (then it is an unexpected error: show the traceback)."""
    cause = exc.__cause__
    if type(cause).__name__ == "_RemoteTraceback":  # from a worker process
        import re

        files = re.findall(r'File "([^"]+)"', str(cause))
        return bool(files) and os.path.abspath(files[-1]).startswith(_PACKAGE_DIR + os.sep)
    tb = exc.__traceback__
    if tb is None:
        return True
    while tb.tb_next is not None:
        tb = tb.tb_next
    return os.path.abspath(tb.tb_frame.f_code.co_filename).startswith(_PACKAGE_DIR + os.sep)


def _describe_os_error(exc: OSError) -> str:
    name = f"{exc.filename}: " if exc.filename else ""
    return f"{name}{exc.strerror or _one_line(exc)}"


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``fov-marl`` with ``argv``; returns the exit status (argparse's own errors
    and ``--help`` raise ``SystemExit``, status 2 and 0)."""
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:  # named by the command they were given to, like its other errors
        _command_parser(parser, args.command).error(f"unrecognized arguments: {' '.join(extra)}")
    debug = bool(getattr(args, "debug", False)) or bool(os.environ.get("FOV_MARL_DEBUG"))
    try:
        rc = args.func(args)
    except KeyboardInterrupt:
        if debug:
            raise
        sys.stderr.write(f"fov-marl {args.command}: interrupted\n")
        return 130
    except ValueError as exc:  # config and argument errors: one line, no traceback
        if debug or not _raised_by_fov_marl(exc):
            raise
        sys.stderr.write(f"fov-marl {args.command}: error: {_one_line(exc)}\n")
        return 2
    except OSError as exc:  # files: unreadable input, output that cannot be written
        if debug:
            raise
        sys.stderr.write(f"fov-marl {args.command}: error: {_one_line(_describe_os_error(exc))}\n")
        return 2
    return rc if type(rc) is int else 0


if __name__ == "__main__":
    raise SystemExit(main())
