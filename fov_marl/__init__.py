"""fov_marl: limited field-of-view, communication-denied robot teams.

PettingZoo environments (:mod:`fov_marl.envs`), the paper's particle-filter + FoV-CBF
controller (:mod:`fov_marl.baselines`, :mod:`fov_marl.pipeline`), the
:class:`~fov_marl.wrappers.SafetyFilterWrapper`, stable-baselines3 training
(:mod:`fov_marl.training`) and the ``fov-marl`` command line (:mod:`fov_marl.cli`).
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

try:
    __version__: str = version("fov_marl")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"

__all__ = ["__version__"]
