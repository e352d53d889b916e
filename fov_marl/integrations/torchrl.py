"""TorchRL: the fov envs as TorchRL environments (``PettingZooWrapper``).

>>> from fov_marl.integrations.torchrl import make_env
>>> env = make_env("coverage", n_agents=4, seed=0)            # or safety_filter=True
>>> td = env.rollout(20)
>>> td["next", "robot", "info", "metrics/eta"].shape           # (20, 4)

TorchRL's wrapper works on a plain ``fov_coverage_v0.parallel_env()`` too; this module
only fixes the settings that fit the fov envs:

* one agent group ``"robot"`` (agents ``robot_0 … robot_{N-1}``); observations
  ``("robot", "observation")`` (N, D) float32, actions ``("robot", "action")`` (N, 3)
  in [-1, 1] (:mod:`fov_marl.spaces`), rewards ``("robot", "reward")`` (N, 1);
* ``return_state=True``: the global state ``"state"`` (``env.state()``, for centralised
  critics);
* ``use_mask=False``: every robot's episode ends at the same step (truncation after
  ``max_cycles``; crossing: termination when all arrived);
* the infos (:mod:`fov_marl.infos`: flat ``metrics/<name>`` and, behind the safety
  filter, ``safety/*``) become float32 entries of ``("robot", "info")``, shape (N,) or
  (N, 3). They are ground truth for evaluation: keep them out of policy inputs.

TorchRL's warning that it was tested with another PettingZoo version is silenced
(the fov envs pass ``check_env_specs`` with PettingZoo 1.27 and TorchRL 0.11).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

from fov_marl.integrations.common import make_parallel_env, require
from fov_marl.validation import describe, fov_parallel_base

__all__ = ["GROUP", "make_env", "wrap"]

#: The TorchRL agent group of the fov envs.
GROUP = "robot"

_WRAP = "fov_marl.integrations.torchrl.wrap"  # for the messages
_TAKES = (
    "fov ParallelEnv (fov_coverage_v0.parallel_env(...) or fov_crossing_v0.parallel_env(...), "
    "possibly wrapped)"
)


def wrap(parallel_env: Any, *, seed: int | None = None, device: Any = "cpu") -> Any:
    """TorchRL ``PettingZooWrapper`` of an existing fov ParallelEnv (or a wrapper of it).

    Args:
        parallel_env: a fov env, possibly wrapped (safety filter, belief features).
        seed: seed of the first reset (later resets continue the env's generator).
            TorchRL's wrapper makes that reset in its constructor (to read the info
            specs), so a first ``env.rollout(...)``, which resets without a seed, starts
            with the *next* episode; ``env.reset(seed=seed)`` gives exactly
            ``parallel_env.reset(seed=seed)``. Reproducible either way.
        device: torch device of the tensors (a ``torch.device`` or its name, ``"cpu"``;
            None: TorchRL's default, no device).

    Raises:
        ValueError: ``parallel_env`` is not a fov ParallelEnv or a ParallelEnv wrapper of
            one (an AEC env ``env(...)``, a vector env ``vector_env(...)``, anything else:
            the message names what was given), or ``device`` is no torch device.
        ImportError: torchrl is not installed (names the extra).
    """
    _check_parallel_env(parallel_env)
    require("torchrl", "torchrl")
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper

    device = _device(device)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="PettingZoo in TorchRL is tested")
        return PettingZooWrapper(
            parallel_env,
            return_state=True,
            use_mask=False,
            seed=seed,
            device=device,
        )


def _check_parallel_env(env: Any) -> None:
    """``env`` must be a fov ParallelEnv or a ParallelEnv wrapper of one (ValueError).

    TorchRL reads the outermost env's spaces, so, unlike the fov wrappers, any wrapper
    (one that changes the observations too) may sit on top: only the env under them
    (``env.unwrapped``) must be a fov env (:func:`~fov_marl.validation.fov_parallel_base`).
    """
    from pettingzoo import AECEnv, ParallelEnv

    if isinstance(env, AECEnv):  # TorchRL would want use_mask=True for it
        raise ValueError(
            f"{_WRAP} takes a {_TAKES}, got the AEC env {type(env).__name__}: pass the "
            "parallel_env(...) of the same scenario and config"
        )
    if hasattr(env, "num_envs"):
        raise ValueError(
            f"{_WRAP} takes one {_TAKES}, got the vector env {type(env).__name__}; for "
            "B copies batch the TorchRL envs: SerialEnv(B, lambda: make_env(...))"
        )
    if not isinstance(env, ParallelEnv):
        raise ValueError(f"{_WRAP} takes a {_TAKES}, got {describe(env)}")
    fov_parallel_base(_WRAP, getattr(env, "unwrapped", env))  # e.g. another library's env


def _device(device: Any) -> Any:
    """``torch.device(device)`` (None stays None), or a ValueError naming ``device``."""
    import torch

    if device is None:
        return None
    try:
        return torch.device(device)
    except (RuntimeError, TypeError, ValueError):
        raise ValueError(
            "device must be a torch device, its name ('cpu', 'cuda:0') or None, got "
            f"{describe(device)}"
        ) from None


def make_env(
    scenario: str = "coverage",
    *,
    safety_filter: bool = False,
    belief: bool = False,
    seed: int | None = None,
    device: Any = "cpu",
    filter_kwargs: Mapping[str, Any] | None = None,
    belief_kwargs: Mapping[str, Any] | None = None,
    **config: Any,
) -> Any:
    """A TorchRL environment of ``fov_<scenario>_v0`` (module docstring for the keys).

    Args:
        scenario: ``"coverage"`` or ``"crossing"``.
        safety_filter: put :class:`~fov_marl.wrappers.SafetyFilterWrapper` inside.
        belief: append the belief features (:class:`~fov_marl.wrappers.BeliefObservationWrapper`).
        seed: seed of the first reset, made while building the env (see :func:`wrap`:
            a first ``rollout`` starts with the next episode).
        device: torch device.
        filter_kwargs, belief_kwargs: keyword arguments of the wrappers.
        **config: scenario config fields (``n_agents``, ``fov_deg``, ``max_cycles``, ...).

    Raises:
        ValueError: a bad scenario, flag, config field or device (named).
        ImportError: torchrl is not installed.
    """
    env = make_parallel_env(
        scenario,
        safety_filter=safety_filter,
        belief=belief,
        filter_kwargs=filter_kwargs,
        belief_kwargs=belief_kwargs,
        **config,
    )
    return wrap(env, seed=seed, device=device)
