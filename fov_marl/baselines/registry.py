"""Policy protocol and the registry behind :func:`make_policy`."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["Policy", "register_policy", "make_policy", "available_policies"]


@runtime_checkable
class Policy(Protocol):
    """A team policy: one call maps every live agent's observation to its action.

    Decentralised policies compute each agent's action from that agent's own
    observation (and own past actions) only.
    """

    def reset(self, seed: int | None = None) -> None:
        """Start a new episode; same seed, same actions."""

    def act(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Actions ``(3,)`` float32 in ``[-1, 1]`` for every agent in ``obs``."""


_REGISTRY: dict[str, Callable[..., Policy]] = {}


def register_policy(name: str) -> Callable[[Callable[..., Policy]], Callable[..., Policy]]:
    """Decorator: register a policy factory ``factory(env, **kwargs)`` under ``name``."""

    def deco(factory: Callable[..., Policy]) -> Callable[..., Policy]:
        _REGISTRY[name] = factory
        return factory

    return deco


def available_policies() -> list[str]:
    """Names accepted by :func:`make_policy`."""
    return sorted(_REGISTRY)


def make_policy(name: str, env: Any, **kwargs: Any) -> Policy:
    """Build the scripted policy ``name`` for ``env`` (a fov_marl ParallelEnv or wrapper).

    Raises:
        ValueError: unknown name (the message lists the valid ones).
    """
    if name not in _REGISTRY:
        raise ValueError(f"unknown policy {name!r}; available policies are {available_policies()}")
    return _REGISTRY[name](env, **kwargs)
