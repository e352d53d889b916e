"""PettingZoo ParallelEnv wrappers.

* :class:`SafetyFilterWrapper`: any policy's actions made safe by the paper's PF + FoV-CBF QP.
* :class:`BeliefObservationWrapper`: appends each robot's own particle-filter beliefs about
  its teammates to its observation (for memoryless learned policies).
"""

from fov_marl.wrappers.belief import BeliefFeaturizer, BeliefObservationWrapper
from fov_marl.wrappers.safety_filter import SafetyFilterWrapper

__all__ = ["BeliefFeaturizer", "BeliefObservationWrapper", "SafetyFilterWrapper"]
