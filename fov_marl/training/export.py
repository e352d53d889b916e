"""Export a trained set policy's actor for the numpy forward pass (no torch at run time).

>>> from fov_marl.training import export_policy
>>> export_policy("runs/set/model.zip", "runs/set/export")     # weights.npz + config.json
>>> policy = make_policy("learned", env, path="runs/set/export")   # any N

The folder layout is :mod:`fov_marl.baselines.learned`'s. ``config.json`` holds the
actor's ``format``, ``arch`` and ``feature_scales`` plus ``training``: the run's own
``config.json`` (scenario, hyper-parameters, seed, timesteps, wall time, ...).
"""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3 import PPO

from fov_marl.training.set_policy import SetActorCriticPolicy, actor_weights

__all__ = ["export_policy"]


def export_policy(
    model_zip: str | os.PathLike, out_dir: str | os.PathLike, extra: dict[str, Any] | None = None
) -> Path:
    """Write ``out_dir/weights.npz`` and ``out_dir/config.json``; return ``out_dir``.

    Args:
        model_zip: a ``model.zip`` (or its run folder) trained with ``arch="set"``.
        out_dir: destination folder (created).
        extra: more entries for ``config.json`` (e.g. ``command``, ``evaluation``).

    Raises:
        ValueError: the file is missing or is not a set-architecture PPO model.
    """
    p = Path(model_zip)
    if p.is_dir():
        p = p / "model.zip"
    if not p.is_file():
        raise ValueError(f"model_zip {p} does not exist")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = PPO.load(str(p), device="cpu")
    except Exception as exc:  # noqa: BLE001 - SB3/zip/pickle raise many kinds
        raise ValueError(f"{p}: not a PPO model saved by `fov-marl train` ({exc})") from None
    if not isinstance(model.policy, SetActorCriticPolicy):
        raise ValueError(
            f"{p}: a {type(model.policy).__name__}; only arch 'set' models export "
            "(fov-marl train --arch set)"
        )
    weights, config = actor_weights(model.policy)
    run_cfg = p.parent / "config.json"
    if run_cfg.is_file():
        config["training"] = json.loads(run_cfg.read_text(encoding="utf-8"))
    config.update(extra or {})
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out / "weights.npz", **weights)
    (out / "config.json").write_text(json.dumps(config, indent=2) + "\n", encoding="utf-8")
    return out
