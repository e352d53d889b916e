"""PettingZoo ParallelEnv wrappers.

* :class:`SafetyFilterWrapper`: any policy's actions made safe by the paper's PF + FoV-CBF QP.
* :class:`VectorSafetyFilterWrapper`: the same for every copy of a vector env (B copies at once).
* :class:`BeliefObservationWrapper`: appends each robot's own particle-filter beliefs about
  its teammates to its observation (for memoryless learned policies).
"""

from fov_marl.wrappers.belief import BeliefFeaturizer, BeliefObservationWrapper
from fov_marl.wrappers.safety_filter import SafetyFilterWrapper
from fov_marl.wrappers.vector_safety_filter import (
    VectorSafetyFilterWrapper,
    build_filtered_vector_env,
)

__all__ = [
    "BeliefFeaturizer",
    "BeliefObservationWrapper",
    "SafetyFilterWrapper",
    "VectorSafetyFilterWrapper",
    "build_filtered_vector_env",
]
