"""Argument validation shared by every config dataclass.

Each check raises :class:`ConfigError` (a ``ValueError``) whose message names the
field and the allowed range, e.g. ``fov_deg must be in (0.0, 360.0], got 400.0``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["ConfigError", "check_real", "check_int", "check_bool"]


class ConfigError(ValueError):
    """A configuration field is missing, unknown or out of its allowed range."""


def _interval(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    lo_b = "(" if lo_open or lo is None else "["
    hi_b = ")" if hi_open or hi is None else "]"
    return f"{lo_b}{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}{hi_b}"


def check_real(
    name: str,
    value: Any,
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
) -> None:
    """``value`` must be a finite real (not a bool) inside the interval."""
    allowed = _interval(lo, hi, lo_open, hi_open)
    if isinstance(value, bool | np.bool_):
        raise ConfigError(f"{name} must be a real number in {allowed}, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a real number in {allowed}, got {value!r}") from None
    if not math.isfinite(v):
        raise ConfigError(f"{name} must be finite and in {allowed}, got {value!r}")
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise ConfigError(f"{name} must be in {allowed}, got {value!r}")
    if hi is not None and (v > hi or (hi_open and v == hi)):
        raise ConfigError(f"{name} must be in {allowed}, got {value!r}")


def check_int(name: str, value: Any, lo: int, hi: int | None = None) -> None:
    """``value`` must be an integer (not a bool) in ``[lo, hi]``."""
    allowed = f"[{lo}, inf)" if hi is None else f"[{lo}, {hi}]"
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer):
        raise ConfigError(f"{name} must be an integer in {allowed}, got {value!r}")
    if value < lo or (hi is not None and value > hi):
        raise ConfigError(f"{name} must be an integer in {allowed}, got {value!r}")


def check_bool(name: str, value: Any) -> None:
    """``value`` must be a bool."""
    if not isinstance(value, bool | np.bool_):
        raise ConfigError(f"{name} must be a bool, got {value!r}")
