"""The ``random`` baseline: uniform actions in the action box."""

from __future__ import annotations

from typing import Any

import numpy as np

from fov_marl.baselines.registry import register_policy
from fov_marl.validation import check_seed

__all__ = ["RandomPolicy"]


class RandomPolicy:
    """Independent uniform actions in ``[-1, 1]³`` per agent, from a seeded generator."""

    def __init__(self, env: Any) -> None:
        self.possible_agents = list(env.possible_agents)
        self._rng = np.random.default_rng()

    def reset(self, seed: int | None = None) -> None:
        self._rng = np.random.default_rng(check_seed("seed", seed))

    def act(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {
            a: self._rng.uniform(-1.0, 1.0, 3).astype(np.float32)
            for a in self.possible_agents
            if a in obs
        }


@register_policy("random")
def _make_random(env: Any) -> RandomPolicy:
    return RandomPolicy(env)
