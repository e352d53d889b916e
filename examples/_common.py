"""Shared by the examples: how long to run (``FOV_MARL_EXAMPLE_STEPS`` shortens them)."""

from __future__ import annotations

import os


def steps(default: int) -> int:
    """Episode length: ``default``, or ``FOV_MARL_EXAMPLE_STEPS`` when set (the test suite
    sets it to a few steps so every example runs in seconds)."""
    value = os.environ.get("FOV_MARL_EXAMPLE_STEPS")
    return int(value) if value else default
