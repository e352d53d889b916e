"""Shared pytest configuration: hypothesis profiles.

* ``default``: 100 examples per property, no deadline (shared 2-core machines make
  per-example timings meaningless; speed is checked by ``fov-marl bench``).
* ``ci`` (selected when the environment has ``CI=true``): 25 examples,
  derandomised so a CI run is reproducible, no deadline, and the ``too_slow``
  health check off for slow runners.

* ``thorough``: 2000 examples, for a deliberate search after touching geometry.

``HYPOTHESIS_PROFILE=<name>`` overrides the choice.
"""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

settings.register_profile("default", max_examples=100, deadline=None)
settings.register_profile("thorough", max_examples=2000, deadline=None)
settings.register_profile(
    "ci",
    max_examples=25,
    deadline=None,
    derandomize=True,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow],
)

_default = "ci" if os.environ.get("CI", "").lower() == "true" else "default"
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", _default))
