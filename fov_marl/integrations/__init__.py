"""Adapters for the MARL frameworks (all optional, imported lazily).

============================================  ===========================================
module                                        what it gives
============================================  ===========================================
:mod:`fov_marl.integrations.torchrl`          ``make_env(...)``: a TorchRL
                                              ``PettingZooWrapper`` of a fov env (needs
                                              ``torchrl``)
:mod:`fov_marl.integrations.benchmarl`        ``FovMarlTask.COVERAGE`` / ``.CROSSING``:
                                              BenchMARL tasks (needs ``benchmarl``)
:mod:`fov_marl.integrations.rllib`            ``make_rllib_env`` / ``register_rllib_env``:
                                              RLlib ``ParallelPettingZooEnv`` (needs
                                              ``ray[rllib]``)
============================================  ===========================================

Importing this package (or any of the modules above) imports no framework: torch,
torchrl, benchmarl and ray are imported when a function that needs them is called
(for BenchMARL: when the task enum is first used). See ``docs/integrations.md``.
"""

from fov_marl.integrations.common import SCENARIOS, make_parallel_env

__all__ = ["SCENARIOS", "make_parallel_env"]
