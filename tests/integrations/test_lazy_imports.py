"""The core never imports the optional engines (torch, torchrl, benchmarl, ray)."""

from __future__ import annotations

import subprocess
import sys

CORE = [
    "fov_marl",
    "fov_marl.infos",
    "fov_marl.envs",
    "fov_marl.envs.fov_coverage_v0",
    "fov_marl.envs.fov_crossing_v0",
    "fov_marl.wrappers",
    "fov_marl.baselines",
    "fov_marl.evaluation",
    "fov_marl.stress",
    "fov_marl.integrations",
    "fov_marl.integrations.torchrl",
    "fov_marl.integrations.benchmarl",
    "fov_marl.integrations.rllib",
]
HEAVY = ["torch", "torchrl", "tensordict", "benchmarl", "ray", "torchvision"]


def test_core_imports_no_optional_engine():
    code = (
        "import importlib, sys\n"
        f"for m in {CORE!r}: importlib.import_module(m)\n"
        f"print([m for m in {HEAVY!r} if m in sys.modules])\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert out.stdout.strip() == "[]", out.stdout + out.stderr
