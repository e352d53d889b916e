"""``fov-marl train``: argument definitions and runner for the CLI.

The CLI registers the sub-command with::

    from fov_marl.training.cli_support import add_train_arguments, run_train
    add_train_arguments(subparser)
    subparser.set_defaults(func=run_train)

Importing this module does not import torch (so every ``fov-marl`` command stays fast);
it raises ``ImportError`` when the ``train`` extra (stable-baselines3, torch) is not
installed, so the CLI can say so.

Example::

    fov-marl train --algo ppo --timesteps 1000000 --seed 0 --out runs/ppo
    fov-marl train --algo ppo --safety-filter --belief --timesteps 1000000 --out runs/ppo_fb
    fov-marl evaluate --policy runs/ppo/model.zip --episodes 10
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
from pathlib import Path
from typing import Any

for _pkg in ("stable_baselines3", "torch"):
    if importlib.util.find_spec(_pkg) is None:
        raise ImportError(f"{_pkg} is not installed")

__all__ = ["add_train_arguments", "run_train", "parse_hyperparams"]

_DEFAULT_TIMESTEPS = 1_000_000


def _int_at_least(flag: str, lo: int):
    def conv(s: str) -> int:
        try:
            f = float(s)
        except ValueError:
            f = math.nan
        if not (math.isfinite(f) and f.is_integer()):
            raise argparse.ArgumentTypeError(f"{flag} must be an integer >= {lo}, got {s!r}")
        v = int(s) if s.strip().lstrip("+-").isdigit() else int(f)
        if v < lo:
            raise argparse.ArgumentTypeError(f"{flag} must be an integer >= {lo}, got {s!r}")
        return v

    return conv


def parse_hyperparams(items: list[str] | None) -> dict[str, Any]:
    """``["key=value", ...]`` -> dict; values are parsed as JSON when they can be
    (``n_steps=128``, ``policy_kwargs={"net_arch": [32, 32]}``), else kept as strings.

    Raises:
        ValueError: an item without ``=``.
    """
    out: dict[str, Any] = {}
    for item in items or []:
        if "=" not in item:
            raise ValueError(f"--hp must be KEY=VALUE, got {item!r}")
        key, value = item.split("=", 1)
        try:
            out[key.strip()] = json.loads(value)
        except json.JSONDecodeError:
            out[key.strip()] = value
    return out


def add_train_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``fov-marl train`` options to ``parser``."""
    parser.add_argument("--algo", choices=("ppo", "sac"), default="ppo", help="SB3 algorithm")
    parser.add_argument(
        "--scenario", choices=("coverage", "crossing"), default="coverage", help="environment"
    )
    parser.add_argument(
        "--safety-filter",
        action="store_true",
        help="train behind SafetyFilterWrapper (the policy's actions become u*)",
    )
    parser.add_argument(
        "--belief",
        action="store_true",
        help="append each robot's own particle-filter features (BeliefObservationWrapper)",
    )
    parser.add_argument(
        "--belief-init",
        choices=("known", "uniform"),
        default="known",
        help="belief trackers start at the known start poses (paper VII-B) or uniform",
    )
    parser.add_argument(
        "--timesteps",
        type=_int_at_least("--timesteps", 1),
        default=_DEFAULT_TIMESTEPS,
        help="robot-steps (samples) to train for; 1e6 notation accepted",
    )
    parser.add_argument(
        "--seed",
        type=_int_at_least("--seed", 0),
        default=0,
        help="seeds SB3 and the env copies (copy k: seed + k)",
    )
    parser.add_argument("--out", required=True, help="output folder (model.zip, config.json, tb/)")
    parser.add_argument("--n-envs", type=_int_at_least("--n-envs", 1), default=4, help="env copies")
    parser.add_argument(
        "--n-agents",
        type=_int_at_least("--n-agents", 1),
        default=None,
        help="robots N (default: the scenario's, 6 or 4)",
    )
    parser.add_argument(
        "--fov-deg", type=float, default=None, help="camera amplitude beta (deg; default 120)"
    )
    parser.add_argument(
        "--train-max-cycles",
        type=_int_at_least("--train-max-cycles", 1),
        default=500,
        help="episode length while training (evaluation keeps the env's 1000)",
    )
    parser.add_argument(
        "--env",
        action="append",
        metavar="FIELD=VALUE",
        help="any scenario config field, repeatable (e.g. --env density_sigma_m=4)",
    )
    parser.add_argument(
        "--hp",
        action="append",
        metavar="KEY=VALUE",
        help="SB3 hyper-parameter override, repeatable (e.g. --hp n_steps=128)",
    )
    parser.add_argument(
        "--checkpoint-every",
        type=_int_at_least("--checkpoint-every", 0),
        default=100_000,
        help="timesteps between checkpoints in OUT/checkpoints (0: none)",
    )
    parser.add_argument(
        "--torch-threads",
        type=_int_at_least("--torch-threads", 1),
        default=1,
        help="torch.set_num_threads while training (1 is fastest for these small MLPs)",
    )
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    parser.add_argument("--verbose", action="store_true", help="print SB3's log table")


def run_train(args: argparse.Namespace) -> Path:
    """Run :func:`fov_marl.training.train` from parsed ``fov-marl train`` arguments.

    Returns the path of ``model.zip`` (also printed). Invalid values raise
    ``ValueError`` with one clear message.
    """
    from fov_marl.training.trainer import train

    env_kwargs = parse_hyperparams(getattr(args, "env", None))
    if args.n_agents is not None:
        env_kwargs["n_agents"] = args.n_agents
    if args.fov_deg is not None:
        env_kwargs["fov_deg"] = args.fov_deg
    path = train(
        args.algo,
        args.scenario,
        safety_filter=args.safety_filter,
        belief=args.belief,
        belief_kwargs={"init": args.belief_init} if args.belief else None,
        timesteps=args.timesteps,
        seed=args.seed,
        out_dir=args.out,
        n_envs=args.n_envs,
        env_kwargs=env_kwargs,
        hyperparams=parse_hyperparams(args.hp),
        train_max_cycles=args.train_max_cycles,
        checkpoint_every=args.checkpoint_every,
        torch_threads=args.torch_threads,
        progress_bar=not args.no_progress,
        verbose=int(args.verbose),
    )
    cfg = json.loads((Path(path).parent / "config.json").read_text())
    print(
        f"saved {path} ({cfg['timesteps_done']} timesteps in {cfg['train_wall_s']:.0f} s, "
        f"{cfg['samples_per_s']:.0f} samples/s); evaluate with: "
        f"fov-marl evaluate --policy {path}"
    )
    return Path(path)
