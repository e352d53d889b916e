"""The one place the integrations build a fov env (with its optional wrappers)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from fov_marl.validation import check_wrapper_kwargs, describe

__all__ = ["SCENARIOS", "make_parallel_env", "require"]

#: Scenario names accepted by the integrations.
SCENARIOS: tuple[str, ...] = ("coverage", "crossing")


def make_parallel_env(
    scenario: str = "coverage",
    *,
    safety_filter: bool = False,
    belief: bool = False,
    filter_kwargs: Mapping[str, Any] | None = None,
    belief_kwargs: Mapping[str, Any] | None = None,
    render_mode: str | None = None,
    **config: Any,
) -> Any:
    """A fov PettingZoo ``ParallelEnv``, optionally wrapped.

    Args:
        scenario: ``"coverage"`` (``fov_coverage_v0``) or ``"crossing"``
            (``fov_crossing_v0``).
        safety_filter: wrap in :class:`~fov_marl.wrappers.SafetyFilterWrapper`.
        belief: wrap (outermost) in :class:`~fov_marl.wrappers.BeliefObservationWrapper`.
        filter_kwargs, belief_kwargs: keyword arguments of those wrappers.
        render_mode: ``None``, ``"rgb_array"`` or ``"human"``.
        **config: scenario config fields (``n_agents``, ``fov_deg``, ``max_cycles``, ...).

    Raises:
        ValueError: an unknown scenario, a non-bool flag, non-dict wrapper kwargs,
            wrapper kwargs with their wrapper off, an unknown wrapper keyword (the message
            lists the valid ones), or a bad config field (named by the env).
    """
    from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
    from fov_marl.wrappers import BeliefObservationWrapper, SafetyFilterWrapper

    if scenario not in SCENARIOS:
        raise ValueError(f"scenario must be one of {list(SCENARIOS)}, got {describe(scenario)}")
    for name, flag in (("safety_filter", safety_filter), ("belief", belief)):
        if not isinstance(flag, bool):
            raise ValueError(f"{name} must be True or False, got {describe(flag)}")
    filter_kwargs = check_wrapper_kwargs(
        "filter_kwargs", filter_kwargs, SafetyFilterWrapper, on=safety_filter
    )
    belief_kwargs = check_wrapper_kwargs(
        "belief_kwargs", belief_kwargs, BeliefObservationWrapper, on=belief, switch="belief"
    )
    module = fov_coverage_v0 if scenario == "coverage" else fov_crossing_v0
    env = module.parallel_env(render_mode=render_mode, **config)
    if safety_filter:
        env = SafetyFilterWrapper(env, **filter_kwargs)
    if belief:
        env = BeliefObservationWrapper(env, **belief_kwargs)
    return env


def require(module: str, extra: str) -> Any:
    """Import an optional dependency, or raise ImportError naming the extra to install."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise ImportError(
            f"{module} is needed for this integration: pip install 'fov-marl[{extra}]' ({exc})"
        ) from exc
