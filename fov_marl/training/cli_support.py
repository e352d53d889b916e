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
    fov-marl train --arch set --ctde --eta-level-coef 1 --timesteps 5e6 --out runs/set
    fov-marl evaluate --policy runs/set/export --n-agents 10 --safety-filter
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import re
import sys
from pathlib import Path
from typing import Any

from fov_marl.validation import MAX_SEED

for _pkg in ("stable_baselines3", "torch"):
    if importlib.util.find_spec(_pkg) is None:
        raise ImportError(f"{_pkg} is not installed")

__all__ = ["add_train_arguments", "run_train", "parse_hyperparams"]

_DEFAULT_TIMESTEPS = 1_000_000


def _int_in(flag: str, lo: int, hi: int | None = None, *, sci: bool = False):
    """argparse type: an integer in ``[lo, hi]``; ``sci`` also takes ``1e6`` notation."""
    allowed = f"an integer in [{lo}, {hi}]" if hi is not None else f"an integer >= {lo}"

    def conv(s: str) -> int:
        text = s.strip()
        try:
            v = int(text)
        except ValueError:
            v = None
            if sci:
                try:
                    f = float(text)
                except ValueError:
                    f = math.nan
                if math.isfinite(f) and f.is_integer():
                    v = int(f)
        if v is None or v < lo or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(f"{flag} must be {allowed}, got {s!r}")
        return v

    return conv


def _real_in(flag: str, lo: float, hi: float):
    """argparse type: a finite real in ``[lo, hi]``."""

    def conv(s: str) -> float:
        try:
            v = float(s)
        except ValueError:
            v = math.nan
        if not (math.isfinite(v) and lo <= v <= hi):
            raise argparse.ArgumentTypeError(f"{flag} must be a number in [{lo}, {hi}], got {s!r}")
        return v

    return conv


def _fov(flag: str):
    def conv(s: str) -> float:
        try:
            v = float(s)
        except ValueError:
            v = math.nan
        if not (math.isfinite(v) and 0.0 < v <= 360.0):
            raise argparse.ArgumentTypeError(f"{flag} must be a number in (0, 360], got {s!r}")
        return v

    return conv


def parse_hyperparams(items: list[str] | None, flag: str = "--hp") -> dict[str, Any]:
    """``["key=value", ...]`` -> dict; values are parsed as JSON when they can be
    (``n_steps=128``, ``policy_kwargs={"net_arch": [32, 32]}``), else kept as strings.
    A key given twice keeps the last value
    (:func:`fov_marl.validation.parse_assignments`).

    Raises:
        ValueError: an item without ``=`` or with an empty key (the message names ``flag``).
    """
    from fov_marl.validation import parse_assignments

    return parse_assignments(items, flag)


def add_train_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``fov-marl train`` options to ``parser``."""
    parser.add_argument("--algo", choices=("ppo", "sac"), default="ppo", help="SB3 algorithm")
    parser.add_argument(
        "--scenario",
        choices=("coverage", "crossing"),
        default=None,
        help="environment (default: the --config file's, else coverage)",
    )
    parser.add_argument(
        "--safety-filter",
        action="store_true",
        help="train behind SafetyFilterWrapper (the policy's actions become u*)",
    )
    from fov_marl.filter_options import add_filter_arguments

    add_filter_arguments(parser, threads=True)
    parser.add_argument(
        "--belief",
        action="store_true",
        help="append each robot's own particle-filter features (BeliefObservationWrapper)",
    )
    parser.add_argument(
        "--belief-init",
        choices=("known", "uniform"),
        default=None,
        help="with --belief: the belief trackers start at the known start poses (paper "
        "VII-B) or uniform (default: known)",
    )
    parser.add_argument(
        "--timesteps",
        type=_int_in("--timesteps", 1, 10**12, sci=True),
        default=_DEFAULT_TIMESTEPS,
        help="robot-steps (samples) to train for, in [1, 1e12]; 1e6 notation accepted. "
        "SB3 runs whole rollouts, so this is rounded up to a multiple of n_steps x n_envs x "
        "n_agents for PPO (6144 = 256 x 4 x 6 unless changed), of train_freq x n_envs x n_agents for SAC; "
        "the effective number is printed before training starts (default: 1e6)",
    )
    parser.add_argument(
        "--seed",
        type=_int_in("--seed", 0, MAX_SEED),
        default=0,
        help=f"seeds SB3 and the env copies (copy k: seed + k), in [0, {MAX_SEED}] (default: 0)",
    )
    parser.add_argument(
        "--out",
        required=True,
        help="output folder (model.zip, config.json, vecnormalize.pkl, checkpoints/, tb/); "
        "one that already holds a model is refused unless --force",
    )
    parser.add_argument(
        "--force",
        action="store_true",
        help="overwrite the model.zip and config.json already in --out (the old run's "
        "checkpoints/model_*_steps.zip and their VecNormalize files are removed; tb/ keeps "
        "its logs, one folder per run)",
    )
    parser.add_argument(
        "--n-envs",
        "--num-envs",
        dest="n_envs",
        type=_int_in("--n-envs", 1, 1024),
        default=4,
        help="env copies (each robot of each copy is one SB3 slot), in [1, 1024]",
    )
    parser.add_argument(
        "--workers",
        type=_int_in("--workers", 1, 1024),
        default=1,
        help="processes stepping the env copies and the safety filter, in [1, --n-envs] "
        "(one core each; the same numbers; not with --belief)",
    )
    parser.add_argument(
        "--n-agents",
        type=_int_in("--n-agents", 1, 256),
        default=None,
        help="robots N in [1, 256] (default: the scenario's, 6 or 4)",
    )
    parser.add_argument(
        "--fov-deg",
        type=_fov("--fov-deg"),
        default=None,
        help="camera amplitude beta in degrees, (0, 360] (default 120)",
    )
    parser.add_argument(
        "--train-max-cycles",
        type=_int_in("--train-max-cycles", 1),
        default=500,
        help="episode length while training (evaluation keeps the env's 1000)",
    )
    parser.add_argument(
        "--config",
        metavar="FILE.json",
        default=None,
        help="scenario config fields from a JSON object (e.g. ScenarioConfig.to_dict() "
        "saved with json.dump; any subset); --env and the dedicated flags override it",
    )
    parser.add_argument(
        "--env",
        action="append",
        metavar="FIELD=VALUE",
        help="any scenario config field, repeatable, VALUE parsed as JSON (e.g. --env "
        "density_sigma_m=4); overrides --config",
    )
    parser.add_argument(
        "--hp",
        action="append",
        metavar="KEY=VALUE",
        help="SB3 hyper-parameter override, repeatable (e.g. --hp n_steps=128); unknown keys "
        "and bad values are errors naming the key (see fov_marl.training.trainer.HYPERPARAM_SPECS)",
    )
    parser.add_argument(
        "--checkpoint-every",
        type=_int_in("--checkpoint-every", 0, sci=True),
        default=100_000,
        help="timesteps between checkpoints in OUT/checkpoints (0: none); Ctrl-C also "
        "saves the model trained so far",
    )
    parser.add_argument(
        "--torch-threads",
        type=_int_in("--torch-threads", 1, 1024),
        default=1,
        help="torch.set_num_threads while training (1 is fastest for these small MLPs)",
    )
    parser.add_argument(
        "--no-progress", action="store_true", help="hide SB3's progress bar (per timestep)"
    )
    parser.add_argument("--verbose", action="store_true", help="print SB3's log table")
    parser.add_argument(
        "--arch",
        choices=("mlp", "set"),
        default="mlp",
        help="policy network: mlp (flat observation, fixed N) or set (PPO: permutation-"
        "invariant, any N; exported to OUT/export for make_policy('learned', env, path=...))",
    )
    parser.add_argument(
        "--ctde",
        action="store_true",
        help="--arch set: the critic also reads the global state, agent-centric "
        "(centralised training, decentralised execution)",
    )
    parser.add_argument(
        "--eta-level-coef",
        type=_real_in("--eta-level-coef", 0.0, 1e3),
        default=0.0,
        help="weight of the per-step coverage-level reward -log10(1 - eta + 1e-4) / 4, in "
        "[0, 1000] (default 0: the env's reward only)",
    )
    parser.add_argument(
        "--intervention-coef",
        type=_real_in("--intervention-coef", 0.0, 1e3),
        default=0.0,
        help="behind --safety-filter: penalty per unit of the filter's normalised action "
        "change, in [0, 1000] (default: 0)",
    )
    parser.add_argument(
        "--blind-motion-coef",
        type=_real_in("--blind-motion-coef", 0.0, 1e3),
        default=0.0,
        help="penalty on planar speed towards directions outside the camera sector, in "
        "[0, 1000] (teaches 'look where you drive', which the safety filter rewards; "
        "default: 0)",
    )
    parser.add_argument(
        "--action-cost-coef",
        type=_real_in("--action-cost-coef", 0.0, 1e3),
        default=0.0,
        help="penalty on the action energy (|v|^2 + w^2) / 2 (normalised), in [0, 1000] "
        "(default: 0)",
    )
    parser.add_argument(
        "--fov-keep-coef",
        type=_real_in("--fov-keep-coef", 0.0, 1e3),
        default=0.0,
        help="penalty on neighbours closer than 3 D_s outside the camera sector (exact "
        "positions), in [0, 1000]: what the safety filter's FoV rows would correct "
        "(default: 0)",
    )
    parser.add_argument(
        "--init-from",
        metavar="MODEL.zip",
        default=None,
        help="start from this model's parameters (same --arch, --ctde and team size), e.g. "
        "fine-tune behind --safety-filter after training without it",
    )


def _flag_of(message: str, args: argparse.Namespace) -> str:
    """The flag a config/hyper-parameter error comes from (by the name it starts with)."""
    from fov_marl.config import ScenarioConfig
    from fov_marl.training.trainer import HYPERPARAM_SPECS

    m = re.match(r"(?:unknown )?([A-Za-z_][A-Za-z0-9_]*)", message)
    name = m.group(1) if m else ""
    if name in HYPERPARAM_SPECS.get(args.algo, {}) or message.startswith(
        f"unknown {args.algo.upper()}"
    ):
        return "--hp"
    if name == "n_agents" and args.n_agents is not None:
        return "--n-agents"
    if name == "fov_deg" and args.fov_deg is not None:
        return "--fov-deg"
    if name in ScenarioConfig.__dataclass_fields__ or message.startswith("unknown config"):
        return "--env"
    return ""


def _resolve(args: argparse.Namespace) -> tuple[str, dict[str, Any], dict[str, str]]:
    """(scenario, env_kwargs, field -> flag) from --config, --env and the dedicated flags."""
    from fov_marl.config import cli_overrides

    file_scenario, env_kwargs, sources = cli_overrides(args.config, getattr(args, "env", None))
    if file_scenario is not None and file_scenario not in ("coverage", "crossing"):
        raise ValueError(
            f"--config {args.config}: scenario must be 'coverage' or 'crossing', "
            f"got {file_scenario!r}"
        )
    if args.scenario is not None and file_scenario not in (None, args.scenario):
        raise ValueError(
            f"--scenario {args.scenario} conflicts with --config {args.config}, whose scenario "
            f"is {file_scenario!r}; give one of them"
        )
    scenario = args.scenario or file_scenario or "coverage"
    for key, flag in (("n_agents", "--n-agents"), ("fov_deg", "--fov-deg")):
        value = getattr(args, key)
        if value is None:
            continue
        if sources.get(key) == "--env" and env_kwargs[key] != value:
            raise ValueError(
                f"--env {key}={env_kwargs[key]!r} conflicts with {flag} {value}; give one of them"
            )
        env_kwargs[key] = value
        sources[key] = flag
    return scenario, env_kwargs, sources


def _check_out(args: argparse.Namespace) -> Path:
    from fov_marl.validation import check_out_dir

    out = check_out_dir("--out", args.out)
    held = [n for n in ("model.zip", "config.json") if (out / n).exists()]
    if held and not args.force:
        raise ValueError(
            f"--out {args.out} already holds a trained model ({', '.join(held)}); pass --force "
            "to overwrite it, or choose another --out"
        )
    return out


def run_train(args: argparse.Namespace) -> Path | int:
    """Run :func:`fov_marl.training.train` from parsed ``fov-marl train`` arguments.

    Every argument (``--out``, ``--config``, ``--env``, ``--hp``, the scenario config and
    the buffer sizes) is checked before training starts; the effective number of
    timesteps (whole rollouts) is printed. Returns the path of ``model.zip`` (also
    printed), or 130 when Ctrl-C stopped training (the model trained so far is saved,
    and the message says where). Invalid values raise ``ValueError`` with one clear
    message naming the flag.
    """
    from fov_marl.config import make_config, source_of_error
    from fov_marl.training.trainer import (
        checkpoint_period,
        effective_timesteps,
        train,
        validate_hyperparams,
    )
    from fov_marl.validation import ConfigError, check_writable

    out = _check_out(args)
    if args.ctde and args.arch != "set":
        raise ValueError("--ctde needs --arch set (an MLP actor would read the critic's state)")
    if args.workers > args.n_envs:
        raise ValueError(
            f"--workers {args.workers} must be at most --n-envs {args.n_envs} (each worker "
            "steps at least one env copy)"
        )
    if args.intervention_coef and not args.safety_filter:
        raise ValueError(
            f"--intervention-coef {args.intervention_coef} needs --safety-filter (it weighs "
            "the filter's action change; without the filter it would do nothing)"
        )
    if args.belief_init is not None and not args.belief:
        raise ValueError("--belief-init sets the belief trackers' start: add --belief")
    if args.arch == "set" and args.algo != "ppo":
        raise ValueError(f"--arch set needs --algo ppo, got --algo {args.algo}")
    if args.init_from is not None:
        init = Path(args.init_from)
        init = init / "model.zip" if init.is_dir() else init
        if not init.is_file():
            raise ValueError(f"--init-from {args.init_from}: no such model.zip")
    from fov_marl.filter_options import filter_kwargs

    sf_kwargs = filter_kwargs(
        args.filter_tracker,
        args.filter_controller,
        args.safety_filter,
        init=getattr(args, "filter_init", None),
        threads=getattr(args, "filter_threads", None),
    )
    scenario, env_kwargs, sources = _resolve(args)
    hyperparams = parse_hyperparams(args.hp, flag="--hp")
    try:
        validate_hyperparams(args.algo, hyperparams)
    except ConfigError as exc:
        raise ValueError(f"--hp {exc}") from None
    try:
        train_kwargs = dict(env_kwargs)
        if "max_cycles" not in train_kwargs:
            train_kwargs["max_cycles"] = args.train_max_cycles
        n_agents = make_config(scenario=scenario, **train_kwargs).n_agents
    except ConfigError as exc:
        src = source_of_error(str(exc), sources) or _flag_of(str(exc), args) or "--env"
        raise ValueError(f"{src} {exc}") from None
    # the last check, so a refused run leaves no folder behind: the files can be written
    check_writable("--out", [out / "model.zip", out / "config.json"])
    if args.force:  # the old run's checkpoints would sit beside the new run's
        for pattern in ("model_*_steps.zip", "model_vecnormalize_*_steps.pkl"):
            for stale in (out / "checkpoints").glob(pattern):
                stale.unlink()
    done_at = effective_timesteps(args.algo, args.timesteps, args.n_envs * n_agents, hyperparams)
    if done_at != args.timesteps:
        print(
            f"train: --timesteps {args.timesteps} runs {done_at} timesteps (SB3 collects whole "
            f"rollouts of {_rollout_text(args.algo, args.n_envs, n_agents, hyperparams)})",
            flush=True,
        )
    else:
        print(f"train: {done_at} timesteps", flush=True)
    slots = args.n_envs * n_agents
    period = checkpoint_period(args.checkpoint_every, slots)
    if args.checkpoint_every and period != args.checkpoint_every:
        print(
            f"train: --checkpoint-every {args.checkpoint_every} saves every {period} "
            f"timesteps (a multiple of the {slots} timesteps of one vector step)",
            flush=True,
        )
    try:
        path = train(
            args.algo,
            scenario,
            safety_filter=args.safety_filter,
            safety_filter_kwargs=sf_kwargs,
            belief=args.belief,
            belief_kwargs={"init": args.belief_init or "known"} if args.belief else None,
            timesteps=args.timesteps,
            seed=args.seed,
            out_dir=out,
            n_envs=args.n_envs,
            workers=args.workers,
            env_kwargs=env_kwargs,
            hyperparams=hyperparams,
            train_max_cycles=args.train_max_cycles,
            checkpoint_every=args.checkpoint_every,
            torch_threads=args.torch_threads,
            progress_bar=not args.no_progress,
            verbose=int(args.verbose),
            arch=args.arch,
            ctde=args.ctde,
            eta_level_coef=args.eta_level_coef,
            intervention_coef=args.intervention_coef,
            init_from=args.init_from,
            blind_motion_coef=args.blind_motion_coef,
            action_cost_coef=args.action_cost_coef,
            fov_keep_coef=args.fov_keep_coef,
        )
    except ConfigError as exc:
        flag = source_of_error(str(exc), sources) or _flag_of(str(exc), args)
        raise ValueError(f"{flag} {exc}" if flag else str(exc)) from None
    except ValueError as exc:
        if str(exc).startswith("init_from "):  # a file that is not a model of this kind
            raise ValueError(f"--init-from {str(exc)[len('init_from ') :]}") from None
        raise
    cfg = json.loads((Path(path).parent / "config.json").read_text())
    if args.arch == "set":
        from fov_marl.training.export import export_policy

        export = export_policy(path, Path(path).parent / "export")
        print(
            f"exported the actor to {export} (numpy, any team size): fov-marl evaluate "
            f"--policy {export} --n-agents N"
        )
    if cfg.get("interrupted"):
        ckpt = Path(path).parent / "checkpoints"
        extra = f"; checkpoints in {ckpt}" if ckpt.is_dir() else ""
        sys.stderr.write(
            f"fov-marl train: interrupted after {cfg['timesteps_done']} of {done_at} timesteps; "
            f'saved the model trained so far to {path} (config.json says "interrupted": '
            f"true){extra}\n"
        )
        return 130
    print(
        f"saved {path} ({cfg['timesteps_done']} timesteps in {cfg['train_wall_s']:.0f} s, "
        f"{cfg['samples_per_s']:.0f} samples/s); evaluate with: "
        f"fov-marl evaluate --policy {path}"
    )
    return Path(path)


def _rollout_text(algo: str, n_envs: int, n_agents: int, hyperparams: dict[str, Any]) -> str:
    from fov_marl.training.trainer import _merged_hyperparams

    hp = _merged_hyperparams(algo, hyperparams)
    slots = f"{n_envs} env copies x {n_agents} robots"
    if algo == "ppo":
        return f"n_steps {hp['n_steps']} x {slots} = {hp['n_steps'] * n_envs * n_agents} samples"
    freq = hp.get("train_freq", 1)
    freq = freq[0] if isinstance(freq, list | tuple) else freq
    return f"train_freq {freq} x {slots} = {freq * n_envs * n_agents} samples"
