"""PettingZoo environments: ``fov_coverage_v0`` and ``fov_crossing_v0``.

Each scenario module offers ``parallel_env`` (PettingZoo ParallelEnv), ``env`` (AEC)
and ``vector_env`` (B copies over arrays, :class:`FovVectorEnv`); all are views of the
one batched core in :mod:`fov_marl.envs.core`. ``vector_env(..., workers=W)`` splits
the copies over W processes (:class:`SubprocVectorEnv`).
"""

from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
from fov_marl.envs.subproc import SubprocVectorEnv, build_raw_vector_env
from fov_marl.envs.vector import FovVectorEnv

__all__ = [
    "fov_coverage_v0",
    "fov_crossing_v0",
    "FovVectorEnv",
    "SubprocVectorEnv",
    "build_raw_vector_env",
]
