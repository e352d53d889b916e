"""Fuzz every flag of every ``fov-marl`` command, in process (``fov_marl.cli.main``).

For each command a cheap valid command line is the base; each case changes one flag
to a fuzzed value (or adds a flag, or points ``--policy`` at a damaged model file).
The outcome must be

* exit status 0 for a valid command line, or
* exit status 2 with exactly one ``fov-marl ...`` / argparse error line on stderr that
  names the flag (or the file, or the config field the flag sets), no traceback,

within a time bound. Problems are counted as in ``tests/test_fuzz_env.py``: ``raw``
(an exception escaped ``main``, or another exit status), ``unnamed`` (an error that is
not one line naming the flag), ``silent`` (a bad value ran), ``rejected`` (a valid
value was refused), ``hang``.

``reproduce`` and, in the normal suite, ``bench`` run with their work function
replaced by a stub that records the call (the real ones take minutes; every flag is
checked before the work function is called, which is what is fuzzed here); the slow
sweep also runs ``bench --quick`` for real. ``python tests/test_fuzz_cli.py`` runs the
whole sweep and prints the counts.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import io
import json
import os
import shutil
import sys
import tempfile
import time
import zipfile
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from test_fuzz_env import PROBLEMS, Outcome, bounded, examples

import fov_marl.bench
import fov_marl.report
from fov_marl.cli import build_parser, main

LIMIT_S = {"train": 60.0}
DEFAULT_LIMIT_S = 30.0
IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0


# ------------------------------------------------------------------------- workspace
_WS: Path | None = None


def workspace() -> Path:
    """Files the cases point at, built once per process (a tiny trained model too)."""
    global _WS
    if _WS is not None:
        return _WS
    ws = Path(tempfile.mkdtemp(prefix="fov_fuzz_cli_"))
    atexit.register(shutil.rmtree, ws, ignore_errors=True)
    (ws / "afile").write_text("not a directory\n")
    (ws / "existing_dir").mkdir()
    (ws / "dir.gif").mkdir()
    ro = ws / "readonly"
    ro.mkdir()
    ro.chmod(0o500)
    atexit.register(ro.chmod, 0o700)
    (ws / "empty.zip").write_bytes(b"")
    for name, text in (
        ("cfg.json", '{"density_sigma_m": 4.0}'),
        ("cfg_crossing.json", '{"scenario": "crossing"}'),
        ("badcfg.json", "{not json"),
        ("cfg_list.json", "[1, 2]"),
        ("cfg_unknown.json", '{"nosuch": 1}'),
        ("cfg_bad.json", '{"fov_deg": 400}'),
        ("cfg_badscenario.json", '{"scenario": "maze"}'),
    ):
        (ws / name).write_text(text)
    tiny = [
        "train",
        "--timesteps",
        "8",
        "--n-envs",
        "1",
        "--n-agents",
        "2",
        "--train-max-cycles",
        "4",
        "--hp",
        "n_steps=4",
        "--hp",
        "batch_size=4",
        "--checkpoint-every",
        "0",
        "--no-progress",
    ]
    with contextlib.redirect_stdout(io.StringIO()):
        assert main([*tiny, "--out", str(ws / "model")]) == 0
        assert main([*tiny, "--algo", "sac", "--out", str(ws / "sac")]) == 0
    good = ws / "model"
    cfg = json.loads((good / "config.json").read_text())

    def variant(name: str, *, model: bytes | None = None, config: object = cfg, vn=True) -> None:
        d = ws / name
        d.mkdir()
        (d / "model.zip").write_bytes(
            model if model is not None else (good / "model.zip").read_bytes()
        )
        if config is not None:
            text = config if isinstance(config, str | bytes) else json.dumps(config)
            (d / "config.json").write_bytes(text if isinstance(text, bytes) else text.encode())
        if vn is True:
            shutil.copy(good / "vecnormalize.pkl", d / "vecnormalize.pkl")
        elif vn is not None:
            (d / "vecnormalize.pkl").write_bytes(vn)

    raw = (good / "model.zip").read_bytes()
    foreign = io.BytesIO()
    with zipfile.ZipFile(foreign, "w") as z:
        z.writestr("hello.txt", "not a model")
    variant("truncated", model=raw[: len(raw) // 3])
    variant("zeros", model=bytes(len(raw)))
    variant("emptyzip", model=b"")
    variant("foreign", model=foreign.getvalue())
    variant("noconfig", config=None)
    variant("badjson", config="{not json")
    variant("binaryjson", config=b"\xff\xfe\x00garbage")
    variant("listjson", config="[1, 2, 3]")
    variant("badformat", config={**cfg, "format": "someone-else/9"})
    variant("badalgo", config={**cfg, "algo": "dqn"})
    variant("noalgo", config={k: v for k, v in cfg.items() if k != "algo"})
    variant("badenv", config={**cfg, "env_kwargs": {**cfg["env_kwargs"], "fov_deg": "wide"}})
    variant("envlist", config={**cfg, "env_kwargs": [1, 2]})
    variant(
        "wrong_n", config={**cfg, "n_agents": 3, "env_kwargs": {**cfg["env_kwargs"], "n_agents": 3}}
    )
    variant("sac_as_ppo", model=(ws / "sac" / "model.zip").read_bytes())
    variant("badvn", vn=b"garbage")
    variant("novn", vn=None)
    (ws / "nomodel").mkdir()
    shutil.copy(good / "config.json", ws / "nomodel" / "config.json")
    _WS = ws
    return ws


_COUNTER = [0]


def _fresh(kind: str) -> str:
    _COUNTER[0] += 1
    return f"{{ws}}/out/{_COUNTER[0]}{kind}"


# ------------------------------------------------------------------------- cases
@dataclass(frozen=True)
class CliCase:
    argv: tuple[str, ...]
    expect: str  # "valid", "invalid" or "either"
    names: tuple[str, ...]  # the error line must contain one of these
    stub: tuple[str, ...] = ()
    label: str = ""

    def resolved(self) -> list[str]:
        ws = str(workspace())
        return [a.replace("{ws}", ws) for a in self.argv]

    def __str__(self) -> str:
        return self.label or " ".join(self.argv)


def _base(command: str) -> list[tuple[str, object]]:
    """(flag, value) pairs of the cheap valid command line; value None: a bare flag,
    a list: several values (nargs='+')."""
    if command == "evaluate":
        return [
            ("--policy", "random"),
            ("--n-agents", "2"),
            ("--episodes", "1"),
            ("--max-cycles", "2"),
            ("--quiet", None),
            ("--out", "OUTDIR"),
        ]
    if command == "render":
        return [
            ("--policy", "random"),
            ("--n-agents", "2"),
            ("--max-cycles", "2"),
            ("--every", "1"),
            ("--out", "OUTFILE.png"),
        ]
    if command == "bench":
        return [("--quick", None), ("--json", None), ("--n-agents", ["2"])]
    if command == "reproduce":
        return [("--quick", None), ("--out", "OUTDIR"), ("--workers", "1")]
    if command == "train":
        return [
            ("--timesteps", "8"),
            ("--n-envs", "1"),
            ("--n-agents", "2"),
            ("--train-max-cycles", "4"),
            ("--hp", "n_steps=4"),
            ("--hp", "batch_size=4"),
            ("--checkpoint-every", "0"),
            ("--no-progress", None),
            ("--out", "OUTDIR"),
        ]
    if command == "stress":
        return [
            ("--adversaries", "charge_centre"),
            ("--n-agents", "2"),
            ("--fov-deg", "120"),
            ("--starts", "random"),
            ("--episodes", "1"),
            ("--steps", "2"),
            ("--quiet", None),
        ]
    raise AssertionError(command)


def _argv(command: str, pairs: list[tuple[str, object]]) -> tuple[str, ...]:
    out = [command]
    for flag, value in pairs:
        if value is None:
            out.append(flag)
        elif isinstance(value, list):
            out += [flag, *value]
        else:
            text = str(value)
            if text == "OUTDIR":
                text = _fresh("")
            elif text.startswith("OUTFILE"):
                text = _fresh(text[len("OUTFILE") :])
            out += [flag, text]
    return tuple(out)


def _with(command: str, flag: str, value: object, append: bool = False) -> tuple[str, ...]:
    pairs = _base(command)
    if append or not any(f == flag for f, _ in pairs):
        pairs.append((flag, value))
    else:
        pairs = [(f, value if f == flag else v) for f, v in pairs]
    return _argv(command, pairs)


BAD_POSITIVE_INT = ["0", "-1", "abc", "", " ", "1.5", "nan", "inf", "0x10", "1e3", "١٢x", "+-3"]
BAD_NONNEG_INT = ["-1", "abc", "", "1.5", "nan", "-0.5", "1e400"]
BAD_FOV = ["0", "-30", "360.5", "400", "nan", "inf", "-inf", "abc", "", "1e400", "0x10"]
BAD_CONFIG = [
    "{ws}/badcfg.json",
    "{ws}/cfg_list.json",
    "{ws}/cfg_unknown.json",
    "{ws}/cfg_bad.json",
    "{ws}/cfg_badscenario.json",
    "{ws}/missing.json",
    "{ws}/existing_dir",
    "",
]
BAD_ENV = [
    "density_sigma_m=abc",
    'density_sigma_m="4"',
    "nosuch=1",
    "n_agents=2.5",
    "fov_deg=400",
    "fov_deg=NaN",
    "fov_deg=true",
    "scenario=crossing",
    "initial_poses=abc",
    "initial_poses=[[1,2]]",
    "arena_size_m=1e400",
    "eta_grid_m=1e-9",
    "meas_cov_diag=[0.1,0.1]",
    'density_mean_m={"x": 1}',
    "foo",
    "=1",
]
BAD_OUT_DIR = ["{ws}/afile", "{ws}/afile/sub", "", "   ", "{ws}/bad\x00name"] + (
    [] if IS_ROOT else ["{ws}/readonly/sub"]
)
MODEL_FILES_BAD = [
    "{ws}/empty.zip",
    "{ws}/truncated/model.zip",
    "{ws}/zeros/model.zip",
    "{ws}/emptyzip",
    "{ws}/foreign/model.zip",
    "{ws}/noconfig/model.zip",
    "{ws}/badjson/model.zip",
    "{ws}/binaryjson/model.zip",
    "{ws}/listjson/model.zip",
    "{ws}/badformat/model.zip",
    "{ws}/badalgo/model.zip",
    "{ws}/noalgo/model.zip",
    "{ws}/badenv/model.zip",
    "{ws}/envlist/model.zip",
    "{ws}/wrong_n/model.zip",
    "{ws}/sac_as_ppo/model.zip",
    "{ws}/badvn/model.zip",
    "{ws}/novn/model.zip",
    "{ws}/nomodel",
    "{ws}/missing.zip",
    "{ws}/afile.zip",
]

#: --filter-tracker / --filter-controller (fov_marl.filter_options): without --safety-filter
#: every value is an error naming the flag, so a valid one is "either" there
BAD_FILTER_TRACKER = [
    "nosuch=1", "n_particles_total=0", "n_particles_total=abc", "n_particles_total=1e400",
    "foo", "=1", "motion_model=\"nope\"",
]  # fmt: skip
BAD_FILTER_CONTROLLER = ["nosuch=1", "safety_risk=0.9", "safety_risk=abc", "walls=2", "foo"]


def _filter_specs(filter_on: bool) -> dict[str, dict]:
    """Specs of both filter flags; with the filter off a valid value is "either"."""
    out = {}
    for flag, bad, ok in (
        ("--filter-tracker", BAD_FILTER_TRACKER, "n_particles_total=500"),
        ("--filter-controller", BAD_FILTER_CONTROLLER, "safety_risk=0.01"),
    ):
        valid = {"good": [ok]} if filter_on else {"good": [], "either": [ok]}
        out[flag] = {"bad": bad, **valid, "append": True}
    inits = ["known", "uniform"]
    valid = {"good": inits} if filter_on else {"good": [], "either": inits}
    out["--filter-init"] = {"bad": ["nearby", "", "KNOWN", "uniform "], **valid}
    return out


FILTER_SPECS_OFF = _filter_specs(False)
#: the shaping weights of ``train --arch set`` (all in [0, 1000])
BAD_COEF = ["-1", "abc", "", "nan", "inf", "1001", "1e400"]

#: command -> flag -> {"bad": [...], "good": [...], "either": [...], "names": (...)}
SPECS: dict[str, dict[str, dict]] = {
    "evaluate": {
        "--scenario": {
            "bad": ["maze", "", "COVERAGE", "coverage "],
            "good": ["coverage", "crossing"],
        },
        "--policy": {
            "bad": ["nope", "", "PFCBF", *MODEL_FILES_BAD],
            "good": [
                "random",
                "pfcbf",
                "ideal",
                "lloyd-pf",
                "{ws}/model",
                "{ws}/model/model.zip",
                "{ws}/sac",
            ],
        },
        "--n-agents": {
            "bad": [*BAD_POSITIVE_INT, "257", "100000000000000000000"],
            "good": ["1", "2", "3"],
            "either": ["150", "211", "256"],
            "names": ("--n-agents", "n_agents", "init_min_separation_m"),
        },
        "--fov-deg": {"bad": BAD_FOV, "good": ["90", "360", "0.001", "1e2"]},
        "--seed": {"bad": [*BAD_NONNEG_INT, "2147483648"], "good": ["0", "7", "2147483647"]},
        "--safety-filter": {"bad": ["--safety-filter=yes"], "good": [None]},
        **FILTER_SPECS_OFF,
        "--max-cycles": {"bad": BAD_POSITIVE_INT, "good": ["1", "3"]},
        "--episodes": {"bad": [*BAD_POSITIVE_INT, "1000001"], "good": ["1", "2"]},
        "--workers": {"bad": [*BAD_POSITIVE_INT, "257"], "good": ["1", "2"]},
        "--backend": {"bad": ["nope", "", "RAY"], "good": ["local"]},
        "--ray-address": {"bad": ["auto", ""], "good": []},
        "--config": {
            "bad": BAD_CONFIG,
            "good": ["{ws}/cfg.json", "{ws}/cfg_crossing.json"],
        },
        "--env": {
            "bad": BAD_ENV,
            "good": ["density_sigma_m=4", "eta_grid_m=0.5", "arena_size_m=50", "max_cycles=2"],
            "append": True,
        },
        "--out": {"bad": BAD_OUT_DIR, "good": ["{ws}/existing_dir", "OUTDIR"]},
        "--save-series": {"bad": ["--save-series=1"], "good": [None]},
        "--quiet": {"bad": ["--quiet=no"], "good": [None]},
        "--debug": {"bad": ["--debug=1"], "good": [None]},
    },
    "render": {
        "--scenario": {"bad": ["maze", ""], "good": ["coverage", "crossing"]},
        "--policy": {
            "bad": ["nope", "", "{ws}/empty.zip", "{ws}/truncated/model.zip", "{ws}/wrong_n"],
            "good": ["random", "pfcbf", "{ws}/model", "{ws}/model/model.zip"],
        },
        "--config": {"bad": BAD_CONFIG, "good": ["{ws}/cfg.json", "{ws}/cfg_crossing.json"]},
        "--env": {
            "bad": BAD_ENV,
            "good": ["density_sigma_m=4", "arena_size_m=50", "max_cycles=2"],
            "append": True,
        },
        "--beliefs-of": {
            "bad": ["robot_2", "robot_x", "", "ALL", "robot_-1", "0"],
            "good": ["robot_1", "all", "none"],
        },
        "--no-legend": {"bad": ["--no-legend=1"], "good": [None]},
        "--n-agents": {
            "bad": [*BAD_POSITIVE_INT, "257"],
            "good": ["1", "3"],
            "names": ("--n-agents", "n_agents", "init_min_separation_m"),
        },
        "--fov-deg": {"bad": BAD_FOV, "good": ["45", "360"]},
        "--seed": {"bad": BAD_NONNEG_INT, "good": ["0", "3"]},
        "--safety-filter": {"bad": ["--safety-filter=1"], "good": [None]},
        **FILTER_SPECS_OFF,
        "--max-cycles": {
            "bad": [*BAD_POSITIVE_INT, "5000"],
            "good": ["1", "3"],
            "names": ("--max-cycles", "--every"),
        },
        "--out": {
            "bad": [
                "OUTFILE.txt",
                "OUTFILE",
                "{ws}/dir.gif",
                "{ws}/afile/x.gif",
                "",
                "{ws}/bad\x00.gif",
            ]
            + ([] if IS_ROOT else ["{ws}/readonly/x.gif"]),
            "good": ["OUTFILE.png", "OUTFILE.gif", "OUTFILE.GIF", "OUTFILE.mp4"],
        },
        "--every": {"bad": BAD_POSITIVE_INT, "good": ["1", "2", "1000000"]},
        "--fps": {"bad": [*BAD_POSITIVE_INT, "101", "100000"], "good": ["1", "100"]},
        "--debug": {"bad": ["--debug=yes"], "good": [None]},
    },
    "bench": {
        "--json": {"bad": ["--json=1"], "good": [None]},
        "--quick": {"bad": ["--quick=0"], "good": [None]},
        "--ppo": {"bad": ["--ppo=1"], "good": [None]},
        "--n-agents": {
            "bad": [["1"], ["0"], ["-2"], ["101"], ["abc"], [""], ["2", "x"], ["2.5"], []],
            "good": [["2"], ["2", "3"], ["100"]],
        },
        "--debug": {"bad": ["--debug=x"], "good": [None]},
    },
    "reproduce": {
        "--out": {"bad": BAD_OUT_DIR, "good": ["OUTDIR", "{ws}/existing_dir"]},
        "--quick": {"bad": ["--quick=yes"], "good": [None]},
        "--workers": {"bad": [*BAD_POSITIVE_INT, "257"], "good": ["1", "256"]},
        "--backend": {"bad": ["nope", ""], "good": ["local"]},
        "--ray-address": {"bad": ["auto"], "good": []},
        "--seeds": {"bad": [*BAD_POSITIVE_INT, "1001"], "good": ["1", "1000"]},
        "--quiet": {"bad": ["--quiet=1"], "good": [None]},
        "--debug": {"bad": ["--debug=no"], "good": [None]},
    },
    "train": {
        "--algo": {"bad": ["dqn", "", "PPO"], "good": ["ppo", "sac"]},
        "--scenario": {"bad": ["maze", ""], "good": ["coverage", "crossing"]},
        "--safety-filter": {"bad": ["--safety-filter=1"], "good": [None]},
        **FILTER_SPECS_OFF,
        # without --safety-filter every value is an error naming the flag
        "--filter-threads": {
            "bad": ["0", "-1", "abc", "", "1.5", "1025", "1e3", "nan", "²"],
            "good": [],
            "either": ["1", "2"],
        },
        "--belief": {"bad": ["--belief=1"], "good": [None]},
        # only with --belief (alone: "add --belief"), like --filter-threads
        "--belief-init": {"bad": ["x", "", "KNOWN"], "good": [], "either": ["known", "uniform"]},
        "--timesteps": {
            "bad": ["0", "-1", "abc", "", "1.5", "nan", "inf", "1e13", "1e400"],
            "good": ["8", "1e1", "12"],
        },
        "--seed": {
            "bad": [*BAD_NONNEG_INT, "2147483648", "4294967296"],
            "good": ["0", "2147483647"],
        },
        "--out": {
            "bad": [*BAD_OUT_DIR, "{ws}/model"],  # a folder holding a model needs --force
            "good": ["OUTDIR", "{ws}/existing_dir"],
        },
        "--force": {"bad": ["--force=1"], "good": [None]},
        "--config": {"bad": BAD_CONFIG, "good": ["{ws}/cfg.json", "{ws}/cfg_crossing.json"]},
        "--n-envs": {"bad": [*BAD_POSITIVE_INT, "1025"], "good": ["1", "2"]},
        "--num-envs": {
            "bad": [*BAD_POSITIVE_INT, "1025"],
            "good": ["1", "2"],
            "names": ("--num-envs", "--n-envs"),
        },
        "--n-agents": {
            "bad": [*BAD_POSITIVE_INT, "257"],
            "good": ["1", "2", "3"],
            "names": ("--n-agents", "n_agents", "init_min_separation_m"),
        },
        "--fov-deg": {"bad": BAD_FOV, "good": ["60", "360"]},
        "--train-max-cycles": {"bad": BAD_POSITIVE_INT, "good": ["1", "4"]},
        "--env": {
            "bad": [
                "density_sigma_m=abc",
                'density_sigma_m="4"',
                "nosuch=1",
                "n_agents=2.5",
                "fov_deg=400",
                "fov_deg=NaN",
                "fov_deg=true",
                "scenario=crossing",
                "initial_poses=abc",
                "initial_poses=[[1,2]]",
                "arena_size_m=1e400",
                "eta_grid_m=1e-9",
                "meas_cov_diag=[0.1,0.1]",
                'density_mean_m={"x": 1}',
                "foo",
                "=1",
            ],
            "good": ["density_sigma_m=4", "eta_grid_m=0.5", "arena_size_m=50", "max_cycles=3"],
            "append": True,
            "names": ("--env",),
        },
        "--hp": {
            "bad": [
                "n_steps=abc",
                "nosuchkey=1",
                "n_steps",
                "=1",
                "n_steps=0",
                "n_steps=-5",
                "n_steps=2.5",
                "n_steps=true",
                "batch_size=1",
                "learning_rate=NaN",
                "learning_rate=0",
                "gamma=2",
                'gamma="0.9"',
                "ent_coef=auto",
                "policy_kwargs=abc",
                'policy_kwargs={"net_arch": "big"}',
                'policy_kwargs={"net_arch": [100000]}',
                'policy_kwargs={"net_arch": [8, 8, 8, 8, 8, 8, 8, 8, 8]}',
                'policy_kwargs={"net_arch": {"pi": [8], "qf": [8]}}',
                'policy_kwargs={"nosuch": 1}',
                'policy_kwargs={"activation_fn": "sigmoid"}',
                'policy_kwargs={"ortho_init": 1}',
                "clip_range_vf=-1",
                "target_kl=0",
                "buffer_size=10",
                "n_steps=1000001",
            ],
            "good": [
                "n_steps=8",
                "learning_rate=0.001",
                "gamma=0.9",
                'policy_kwargs={"net_arch": [8]}',
                'policy_kwargs={"net_arch": {"pi": [8], "vf": [4]}, "activation_fn": "relu"}',
                "clip_range_vf=null",
                "target_kl=0.05",
            ],
            "append": True,
            "names": ("--hp",),
        },
        "--checkpoint-every": {"bad": ["-1", "abc", "", "1.5", "nan"], "good": ["0", "4"]},
        "--torch-threads": {"bad": [*BAD_POSITIVE_INT, "1025"], "good": ["1", "2"]},
        # the base line has --n-envs 1: 2 workers is more than copies (a one-line error)
        "--workers": {
            "bad": [*BAD_POSITIVE_INT, "1025", "2"],
            "good": ["1"],
            "names": ("--workers", "workers must"),  # train()'s check names the field
        },
        "--arch": {"bad": ["cnn", "", "SET"], "good": ["mlp", "set"]},
        "--ctde": {"bad": ["--ctde=1", None], "good": [], "either": [None]},
        "--eta-level-coef": {"bad": BAD_COEF, "good": ["0", "1"]},
        "--blind-motion-coef": {"bad": BAD_COEF, "good": ["0", "0.5"]},
        "--action-cost-coef": {"bad": BAD_COEF, "good": ["0", "0.2"]},
        "--fov-keep-coef": {"bad": BAD_COEF, "good": ["0", "0.5"]},
        "--intervention-coef": {"bad": BAD_COEF, "good": ["0", "0.3"]},
        "--init-from": {
            "bad": ["{ws}/afile", "{ws}/nosuch.zip", "{ws}/empty.zip"],
            "good": ["{ws}/model/model.zip"],
            "names": ("--init-from",),
        },
        "--no-progress": {"bad": ["--no-progress=1"], "good": [None]},
        "--verbose": {"bad": ["--verbose=2"], "good": [None]},
        "--debug": {"bad": ["--debug=0"], "good": [None]},
    },
}

SPECS["stress"] = {
    # --quick filters the quick subset by the grid flags: the base grid is not in it
    "--quick": {
        "bad": ["--quick=1", "--full"],
        "good": [],
        "either": [None],
        "names": ("--quick", "--full"),
    },
    "--full": {"bad": ["--full=yes"], "good": [None]},
    "--adversaries": {
        "bad": ["nope", "", ",", "charge_centre,nope"],
        "good": ["charge_centre", "random,straight"],
    },
    "--n-agents": {
        "bad": ["0", "-1", "abc", "", "2,x", "1.5", ","],
        "good": ["2", "1,3"],
        "either": ["257"],
        "names": ("--n-agents", "n_agents"),
    },
    "--fov-deg": {"bad": ["0", "400", "nan", "abc", "", "120,inf"], "good": ["120", "45,360"]},
    "--starts": {
        "bad": ["nope", ""],
        "good": ["random", "corner", "head_on_pair"],
        "either": ["random,"],
    },
    "--scenario": {"bad": ["maze", ""], "good": ["coverage", "crossing"]},
    "--episodes": {"bad": BAD_POSITIVE_INT, "good": ["1", "2"]},
    "--steps": {"bad": BAD_POSITIVE_INT, "good": ["1", "3"]},
    "--seed": {"bad": BAD_NONNEG_INT, "good": ["0", "5"]},
    "--workers": {"bad": BAD_POSITIVE_INT, "good": ["1"]},
    "--backend": {"bad": ["nope", ""], "good": ["local"]},
    "--ray-address": {"bad": ["auto", ""], "good": []},
    "--config": {
        "bad": [*BAD_CONFIG, "{ws}/cfg_crossing.json"],  # another scenario than --scenario
        "good": ["{ws}/cfg.json"],
    },
    "--env": {
        "bad": ["n_agents=3", "nosuch=1", "foo", "safety_distance_m=-1", "scenario=crossing"],
        "good": ["safety_distance_m=2.5", "density_sigma_m=4"],
        "append": True,
    },
    "--no-filter": {"bad": ["--no-filter=1"], "good": [None]},
    # the sweep runs behind the filter: valid values are good here
    **_filter_specs(True),
    "--json": {
        "bad": ["{ws}/afile/x.json", "{ws}/existing_dir"],
        "good": ["OUTFILE.json"],
        "names": ("--json", "afile", "existing_dir"),
    },
    # a file that is not a checkpoint is refused (and left as it is), whatever it holds
    "--checkpoint": {
        "bad": [
            "{ws}/afile/x.jsonl",
            "{ws}/existing_dir",
            "{ws}/badcfg.json",
            "{ws}/cfg.json",
            "",
            "  ",
        ],
        "good": ["OUTFILE.jsonl"],
    },
    "--fail-on-collision": {"bad": ["--fail-on-collision=1"], "good": [None]},
    "--quiet": {"bad": ["--quiet=1"], "good": [None]},
    "--debug": {"bad": ["--debug=1"], "good": [None]},
}

GLOBAL_CASES = [
    CliCase((), "invalid", ("command", "required"), label="no command"),
    CliCase(("nosuch",), "invalid", ("nosuch",), label="unknown command"),
    CliCase(("--debug",), "invalid", ("command", "required"), label="--debug only"),
    CliCase(("evaluate", "--nosuch"), "invalid", ("--nosuch",), label="unknown flag"),
    CliCase(("evaluate", "--n-agents"), "invalid", ("--n-agents",), label="missing value"),
    CliCase(("train",), "invalid", ("--out",), label="train without --out"),
    CliCase(("--help",), "valid", (), label="--help"),
    CliCase(("--version",), "valid", (), label="--version"),
    CliCase(("train", "--help"), "valid", (), label="train --help"),
]


def _stub_for(command: str) -> tuple[str, ...]:
    return {"reproduce": ("reproduce",), "bench": ("bench",)}.get(command, ())


def sweep() -> list[CliCase]:
    cases = list(GLOBAL_CASES)
    for command, flags in SPECS.items():
        stub = _stub_for(command)
        cases.append(CliCase(_argv(command, _base(command)), "valid", (), stub, f"{command} base"))
        for flag, spec in flags.items():
            names = spec.get("names", (flag,))
            append = spec.get("append", False)
            for expect, values in (("invalid", spec["bad"]), ("valid", spec["good"])):
                for v in values:
                    if isinstance(v, str) and v.startswith(flag + "="):
                        argv = (*_argv(command, _base(command)), v)  # a bare flag with a value
                    else:
                        argv = _with(command, flag, v, append=append)
                    label = f"{command} {flag} {v!r} [{expect}]"
                    cases.append(CliCase(argv, expect, names, stub, label))
            for v in spec.get("either", []):
                label = f"{command} {flag} {v!r} [either]"
                argv = _with(command, flag, v) if v is not None else _with(command, flag, None)
                cases.append(CliCase(argv, "either", names, stub, label))
    # train with SB3's progress bar (the base line hides it)
    pairs = [(f, v) for f, v in _base("train") if f != "--no-progress"]
    cases.append(CliCase(_argv("train", pairs), "valid", (), (), "train with the progress bar"))
    return cases


SWEEP = sweep()
#: the real bench and worker processes, run as ``python -m fov_marl.cli`` subprocesses
#: (a deadlocked worker cannot be interrupted in process) (slow sweep only)
IN_SUBPROCESS = [
    CliCase(
        (
            "evaluate",
            "--policy",
            "random",
            "--n-agents",
            "200",
            "--episodes",
            "2",
            "--workers",
            "2",
            "--max-cycles",
            "2",
            "--quiet",
        ),
        "either",
        ("n_agents", "init_min_separation_m"),
        (),
        "evaluate: a worker's error is one line",
    ),  # fmt: skip
    CliCase(
        (
            "evaluate",
            "--policy",
            "{ws}/model",
            "--episodes",
            "2",
            "--workers",
            "2",
            "--max-cycles",
            "2",
            "--quiet",
        ),
        "valid",
        (),
        (),
        "evaluate a model in worker processes",
    ),  # fmt: skip
    CliCase(
        ("bench", "--quick", "--n-agents", "2"),
        "valid",
        (),
        (),
        "bench --quick --n-agents 2 (real)",
    ),
    CliCase(
        ("bench", "--quick", "--n-agents", "1"),
        "invalid",
        ("--n-agents",),
        (),
        "bench --quick --n-agents 1 (real)",
    ),
]


# ------------------------------------------------------------------------- running
@dataclass
class CliResult:
    rc: int | None
    stdout: str
    stderr: str
    calls: list = field(default_factory=list)


@contextlib.contextmanager
def _stubs(names: tuple[str, ...], calls: list):
    saved = []
    if "reproduce" in names:

        def fake_reproduce(out, quick=False, workers=1, seeds=None, backend="local", **kw):
            calls.append(("reproduce", out, quick, workers, seeds, backend))
            return Path(out) / "report.md"

        saved.append((fov_marl.report, "reproduce", fov_marl.report.reproduce))
        fov_marl.report.reproduce = fake_reproduce
    if "bench" in names:

        def fake_bench(quick=False, n_agents=None, ppo=False):
            calls.append(("bench", quick, n_agents) + (("ppo",) if ppo else ()))
            return [{"section": "env", "n_agents": n, "x": 1.0} for n in (n_agents or [6])]

        saved.append((fov_marl.bench, "run_benchmarks", fov_marl.bench.run_benchmarks))
        fov_marl.bench.run_benchmarks = fake_bench
    try:
        yield
    finally:
        for mod, name, fn in saved:
            setattr(mod, name, fn)


def invoke(case: CliCase) -> CliResult:
    """``main(argv)`` with captured output; exceptions propagate (they are 'raw')."""
    out, err, calls = io.StringIO(), io.StringIO(), []
    with _stubs(case.stub, calls), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main(case.resolved())
        except SystemExit as exc:  # argparse errors and --help
            rc = exc.code if isinstance(exc.code, int) else 2
    return CliResult(rc, out.getvalue(), err.getvalue(), calls)


def classify(case: CliCase, out: Outcome, res: CliResult | None) -> str | None:
    if out.kind == "hang":
        return "hang"
    ok_codes = (0, 1, 2) if "--fail-on-collision" in case.argv else (0, 2)  # 1: collided
    if out.kind != "ok" or res is None or res.rc not in ok_codes:
        return "raw"
    if "Traceback" in res.stderr:
        return "raw"
    if res.rc in (0, 1):
        return "silent" if case.expect == "invalid" else None
    if case.expect == "valid":
        return "rejected"
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("fov-marl")]
    if len(lines) != 1:
        return "unnamed"
    return None if any(n in lines[0] for n in case.names) else "unnamed"


def run_subprocess(case: CliCase, limit_s: float = 300.0):
    """The case as a real ``fov-marl`` process, killed after ``limit_s``."""
    import subprocess

    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    env.pop("FOV_MARL_DEBUG", None)
    t0 = time.perf_counter()
    try:
        p = subprocess.run(
            [sys.executable, "-m", "fov_marl.cli", *case.resolved()],
            capture_output=True,
            text=True,
            timeout=limit_s,
            env=env,
        )
    except subprocess.TimeoutExpired:
        out = Outcome("hang", f"ran past {limit_s} s", time.perf_counter() - t0)
        return classify(case, out, None), out, None
    res = CliResult(p.returncode, p.stdout, p.stderr)
    out = Outcome("ok", "", time.perf_counter() - t0)
    return classify(case, out, res), out, res


def run(case: CliCase) -> tuple[str | None, Outcome, CliResult | None]:
    if case in IN_SUBPROCESS:
        return run_subprocess(case)
    box: list[CliResult] = []
    limit = LIMIT_S.get(case.argv[0] if case.argv else "", DEFAULT_LIMIT_S)
    out = bounded(lambda: box.append(invoke(case)), limit)
    res = box[0] if box else None
    return classify(case, out, res), out, res


def _describe(problem, case, out, res) -> str:
    err = res.stderr.strip()[-300:] if res else out.message[:300]
    return f"{problem}: {case} -> rc={res.rc if res else None}: {err}"


def _assert_good(case: CliCase) -> None:
    problem, out, res = run(case)
    assert problem is None, _describe(problem, case, out, res)


# ------------------------------------------------------------------------- tests
@pytest.fixture(autouse=True, scope="module")
def _in_a_scratch_dir(tmp_path_factory):
    """Fuzzed relative paths (``--json inf``, ``--out nan``) land in a scratch folder, never
    in the checkout."""
    old = os.getcwd()
    os.chdir(tmp_path_factory.mktemp("fuzz_cwd"))
    yield
    os.chdir(old)


def test_every_flag_of_every_command_is_fuzzed():
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for command, sp in sub.choices.items():
        flags = {o for a in sp._actions for o in a.option_strings if o not in ("-h", "--help")}
        assert command in SPECS, f"command {command} has no fuzz spec"
        assert flags == set(SPECS[command]), f"{command}: {flags ^ set(SPECS[command])}"


def _subset() -> list[CliCase]:
    """Per command: the base line, every flag's first bad and first good value, every
    damaged model file, and the issue's reported cases."""
    picked, seen = [], set()
    for c in SWEEP:
        parts = c.label.split(" ", 2)
        key = (parts[0], parts[1] if len(parts) > 1 else "", c.expect)
        issue = any(
            s in c.label
            for s in ("n_steps=abc", "nosuchkey", "afile", "empty.zip", "truncated", "foreign")
        )
        if key not in seen or issue:
            seen.add(key)
            picked.append(c)
    return picked


SUBSET = _subset()


@pytest.mark.parametrize("case", SUBSET, ids=str)
def test_subset(case):
    _assert_good(case)


@pytest.mark.slow
@pytest.mark.parametrize("case", SWEEP + IN_SUBPROCESS, ids=str)
def test_full_sweep(case):
    _assert_good(case)


#: flags whose valid values set how much work runs: hypothesis keeps them small
_COUNT_FLAGS = {
    "--episodes", "--max-cycles", "--timesteps", "--n-envs", "--torch-threads", "--n-agents",
    "--workers", "--train-max-cycles", "--checkpoint-every", "--num-envs",
}  # fmt: skip


def _small_or_not_a_number(text: str) -> bool:
    try:
        return abs(float(text)) <= 8
    except (ValueError, OverflowError):
        return True


_FLAG_CHOICES = [(c, f) for c, flags in SPECS.items() for f in flags if f != "--out"]


@settings(max_examples=examples(40), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    choice=st.sampled_from(_FLAG_CHOICES),
    text=st.one_of(
        st.text(max_size=12),
        st.from_regex(r"-?[0-9]{1,3}(\.[0-9]{0,2})?(e-?[0-9])?", fullmatch=True),
        st.sampled_from(["nan", "inf", "-0", "0", "1", "2", "true", "null", "{}", "[]"]),
    ),
)
def test_hypothesis_flag_text(choice, text):
    """Any text for any flag: a clean run or one line naming the flag, never a traceback."""
    command, flag = choice
    if flag in _COUNT_FLAGS:
        assume(_small_or_not_a_number(text))
    if flag == "--policy":
        assume(not _is_path_like(text))
    spec = SPECS[command][flag]
    if spec["good"] == [None] or spec.get("either") == [None]:  # a bare flag: give it a
        argv = (*_argv(command, _base(command)), f"{flag}={text}")  # value, always an error
    elif command == "bench":
        argv = _with(command, flag, [text])
    else:
        argv = _with(command, flag, text, append=spec.get("append", False))
    case = CliCase(argv, "either", spec.get("names", (flag,)), _stub_for(command))
    _assert_good(case)


def _is_path_like(text: str) -> bool:
    return text.endswith(".zip") or os.path.isdir(text)


def test_stubbed_work_gets_the_parsed_flags():
    case = CliCase(
        ("reproduce", "--quick", "--out", _fresh(""), "--seeds", "3"), "valid", (), ("reproduce",)
    )
    res = invoke(case)
    assert res.rc == 0, res.stderr
    name, out, quick, workers, seeds, backend = res.calls[0]
    assert (name, quick, seeds, backend) == ("reproduce", True, 3, "local") and workers >= 1
    res = invoke(CliCase(("bench", "--n-agents", "2", "5"), "valid", (), ("bench",)))
    assert res.rc == 0 and res.calls == [("bench", False, [2, 5])]


def test_user_errors_raise_with_debug():
    with pytest.raises(ValueError, match="--policy"):
        main(["--debug", "evaluate", "--policy", "nope", "--episodes", "1"])
    with pytest.raises(ValueError, match="--out"):
        main(["render", "--debug", "--out", "x.txt"])


def test_internal_errors_keep_their_traceback(monkeypatch):
    """An error raised outside fov_marl's own checks is not turned into one line."""
    import numpy as np

    import fov_marl.evaluation

    def broken(*args, **kwargs):
        return np.add(np.zeros(2), np.zeros(3))  # ValueError raised inside NumPy

    monkeypatch.setattr(fov_marl.evaluation, "run_episode", broken)
    with pytest.raises(ValueError, match="broadcast"):
        main(["evaluate", "--policy", "random", "--episodes", "1", "--quiet"])

    def bug(*args, **kwargs):
        raise KeyError("internal")

    monkeypatch.setattr(fov_marl.evaluation, "run_episode", bug)
    with pytest.raises(KeyError):
        main(["evaluate", "--policy", "random", "--episodes", "1", "--quiet"])


def test_the_harness_can_fail():
    bad = CliCase(("evaluate",), "invalid", ("--n-agents",))
    ok = Outcome("ok", "", 0.0)
    assert classify(bad, ok, CliResult(0, "", "")) == "silent"
    assert classify(bad, ok, CliResult(1, "", "")) == "raw"
    assert classify(bad, ok, CliResult(2, "", "Traceback (most recent call last):\n")) == "raw"
    assert classify(bad, ok, CliResult(2, "", "fov-marl evaluate: error: bad value\n")) == "unnamed"
    assert (
        classify(bad, ok, CliResult(2, "", "fov-marl x: a --n-agents\nfov-marl x: b\n"))
        == "unnamed"
    )
    assert classify(bad, Outcome("exception", "TypeError", 0.0), None) == "raw"
    assert classify(bad, Outcome("hang", "", 99.0), None) == "hang"
    good = CliCase(("evaluate",), "valid", ())
    assert classify(good, ok, CliResult(2, "", "fov-marl evaluate: error: x\n")) == "rejected"
    assert classify(bad, ok, CliResult(2, "", "fov-marl evaluate: error: --n-agents 0\n")) is None


def main_sweep() -> int:
    t0 = time.perf_counter()
    counts: Counter = Counter()
    for case in SWEEP + IN_SUBPROCESS:
        problem, out, res = run(case)
        counts[problem or "good"] += 1
        if problem:
            print(_describe(problem, case, out, res), file=sys.stderr)
    print(
        f"CLI: {len(SWEEP) + len(IN_SUBPROCESS)} cases, "
        + ", ".join(f"{counts[p]} {p}" for p in PROBLEMS)
        + f" ({time.perf_counter() - t0:.1f} s)"
    )
    return int(any(counts[p] for p in PROBLEMS))


if __name__ == "__main__":
    raise SystemExit(main_sweep())
