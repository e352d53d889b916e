"""Policy protocol and the registry behind :func:`make_policy`."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

import numpy as np

from fov_marl.validation import keyword_parameters

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
#: the keyword options of each registered factory (None: not known, the factory checks)
_OPTIONS: dict[str, tuple[str, ...] | None] = {}


def register_policy(
    name: str, options: Callable[..., Any] | tuple[str, ...] | None = None
) -> Callable[[Callable[..., Policy]], Callable[..., Policy]]:
    """Decorator: register a policy factory ``factory(env, **kwargs)`` under ``name``.

    ``options``: the keyword options :func:`make_policy` accepts for it, as names or as a
    callable whose keyword parameters (after the env) they are, e.g. the class the
    factory forwards ``**kwargs`` to. Default: the factory's own keyword parameters.
    """

    def deco(factory: Callable[..., Policy]) -> Callable[..., Policy]:
        _REGISTRY[name] = factory
        if options is None:
            _OPTIONS[name] = keyword_parameters(factory)
        elif callable(options):
            _OPTIONS[name] = keyword_parameters(options)
        else:
            _OPTIONS[name] = tuple(options)
        return factory

    return deco


def available_policies() -> list[str]:
    """Names accepted by :func:`make_policy`."""
    return sorted(_REGISTRY)


def make_policy(name: str, env: Any, **kwargs: Any) -> Policy:
    """Build the scripted policy ``name`` for ``env`` (a fov_marl ParallelEnv or wrapper).

    Raises:
        ValueError: unknown name or option (the message lists the valid ones).
    """
    if name not in _REGISTRY:
        raise ValueError(f"unknown policy {name!r}; available policies are {available_policies()}")
    allowed = _OPTIONS.get(name)
    if allowed is not None:
        unknown = sorted(set(kwargs) - set(allowed))
        if unknown:
            raise ValueError(
                f"unknown option(s) {unknown} for policy {name!r}; its options are "
                f"{sorted(allowed) if allowed else 'none'}"
            )
    return _REGISTRY[name](env, **kwargs)
