"""Learned policies with stable-baselines3: the only package of fov_marl importing torch.

>>> from fov_marl.training import train, load_policy
>>> path = train("ppo", timesteps=500_000, seed=0, out_dir="runs/ppo")
>>> policy = load_policy(path)        # reset(seed) / act(obs) like any baseline

* :mod:`fov_marl.training.vec_env`: :class:`ParallelEnvVecEnv`, the parameter-sharing
  PettingZoo -> SB3 VecEnv adapter (one slot per robot per env copy).
* :mod:`fov_marl.training.trainer`: :func:`train`, :func:`load_policy`,
  :class:`LearnedPolicy`, default hyper-parameters (documented there).
* :mod:`fov_marl.training.set_policy`: the permutation-invariant, size-independent
  actor-critic (``arch="set"``) and its CTDE critic entries.
* :mod:`fov_marl.training.export`: :func:`export_policy`, the actor as ``.npz`` for
  ``make_policy("learned", env, path=...)`` (numpy, no torch).
* :mod:`fov_marl.training.cli_support`: ``fov-marl train`` arguments and runner.

Names are imported lazily so that ``import fov_marl.training.cli_support`` (done by the
CLI for every command) does not import torch.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = [
    "ParallelEnvVecEnv",
    "make_parallel_vec_env",
    "train",
    "load_policy",
    "LearnedPolicy",
    "build_env",
    "DEFAULT_HYPERPARAMS",
    "export_policy",
    "SetActorCriticPolicy",
]

_WHERE = {
    "ParallelEnvVecEnv": "vec_env",
    "make_parallel_vec_env": "vec_env",
    "train": "trainer",
    "load_policy": "trainer",
    "LearnedPolicy": "trainer",
    "build_env": "trainer",
    "DEFAULT_HYPERPARAMS": "trainer",
    "export_policy": "export",
    "SetActorCriticPolicy": "set_policy",
}


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        module = importlib.import_module(f"fov_marl.training.{_WHERE[name]}")
        return getattr(module, name)
    raise AttributeError(f"module 'fov_marl.training' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
