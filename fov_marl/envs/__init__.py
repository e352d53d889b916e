"""PettingZoo environments: ``fov_coverage_v0`` and ``fov_crossing_v0``."""

from fov_marl.envs import fov_coverage_v0, fov_crossing_v0

__all__ = ["fov_coverage_v0", "fov_crossing_v0"]
