"""Policy protocol and the registry behind :func:`make_policy`."""

from __future__ import annotations

from collections.abc import Callable, Collection
from typing import Any, Protocol, runtime_checkable

import numpy as np

from fov_marl.validation import describe, keyword_parameters

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
    name: str, options: Callable[..., Any] | Collection[str] | None = None
) -> Callable[[Callable[..., Policy]], Callable[..., Policy]]:
    """Decorator: register a policy factory ``factory(env, **kwargs)`` under ``name``.

    ``name``: a non-empty string (registering a name again replaces its factory).
    ``options``: the keyword options :func:`make_policy` accepts for it, as names (a
    list, tuple or set of strings) or as a callable whose keyword parameters (after the env)
    they are, e.g. the class the factory forwards ``**kwargs`` to. Default: the
    factory's own keyword parameters.

    Raises:
        ValueError: a name that is not a non-empty string, ``options`` of another kind,
            or a factory that is not callable (checked here, before the registry
            changes).
    """
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"policy name must be a non-empty string, got {describe(name)}")
    if options is None or callable(options):
        names: tuple[str, ...] | None = None
    elif isinstance(options, list | tuple | set | frozenset) and all(
        isinstance(o, str) for o in options
    ):
        names = tuple(options) if isinstance(options, list | tuple) else tuple(sorted(options))
    else:
        raise ValueError(
            f"options of policy {name!r} must be a list, tuple or set of option names (strings), "
            f"a callable or None, got {describe(options)}"
        )

    def deco(factory: Callable[..., Policy]) -> Callable[..., Policy]:
        if not callable(factory):
            raise ValueError(
                f"register_policy({name!r}) decorates a policy factory factory(env, **kwargs), "
                f"got {describe(factory)}"
            )
        if options is None:
            allowed = _keywords(name, factory)
        elif callable(options):
            allowed = _keywords(name, options)
        else:
            allowed = names
        _REGISTRY[name] = factory
        _OPTIONS[name] = allowed
        return factory

    return deco


def _keywords(name: str, fn: Callable[..., Any]) -> tuple[str, ...] | None:
    """:func:`keyword_parameters` of ``fn`` (after the env), or a ValueError naming the policy."""
    try:
        return keyword_parameters(fn)
    except (TypeError, ValueError) as exc:  # builtins without a signature
        raise ValueError(
            f"register_policy({name!r}): cannot read the keyword options of {describe(fn)} "
            f"({exc}); pass options=(names...)"
        ) from None


def available_policies() -> list[str]:
    """Names accepted by :func:`make_policy`."""
    return sorted(_REGISTRY)


def make_policy(name: str, env: Any, **kwargs: Any) -> Policy:
    """Build the scripted policy ``name`` for ``env`` (a fov_marl ParallelEnv or wrapper).

    Raises:
        ValueError: unknown name or option (the message lists the valid ones).
    """
    if not isinstance(name, str) or name not in _REGISTRY:
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
