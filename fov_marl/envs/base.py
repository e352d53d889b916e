"""The shared PettingZoo ``ParallelEnv`` of the two scenarios: a B = 1 view of the core.

The scenario modules (:mod:`fov_marl.envs.fov_coverage_v0`,
:mod:`fov_marl.envs.fov_crossing_v0`) hold the user documentation; the dynamics,
camera, rewards and metrics live once in the batched core
(:mod:`fov_marl.envs.core`, arrays with a leading copy axis), which this class drives
with one copy; :mod:`fov_marl.envs.vector` drives it with B copies. This module holds
what is specific to the PettingZoo API: agent names, dict actions and observations,
per-agent infos, ``max_cycles``, rendering.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import gymnasium
import numpy as np
from pettingzoo import ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec_wrapper
from pettingzoo.utils.wrappers import OrderEnforcingWrapper

from fov_marl.config import ScenarioConfig, make_config
from fov_marl.envs.core import CORES, BatchedCore
from fov_marl.envs.rendering import HumanWindow, RenderLayer, render_frame
from fov_marl.infos import agent_infos
from fov_marl.spaces import ObservationLayout
from fov_marl.validation import ConfigError, as_real_vector, check_int, check_seed, describe

__all__ = [
    "FORWARDED_MAX_CYCLES",
    "MAX_CYCLES",
    "FovAECEnv",
    "FovEnvBase",
    "aec_env",
    "forward_max_cycles",
    "scenario_config",
]


def scenario_config(scenario: str, name: str, config_kwargs: dict[str, Any]) -> ScenarioConfig:
    """The validated config of an env whose scenario is fixed (``name`` for messages).

    ``scenario=`` among the keywords is accepted when it repeats the env's own scenario;
    another value is a :class:`~fov_marl.validation.ConfigError`.
    """
    config_kwargs = dict(config_kwargs)
    if "scenario" in config_kwargs:
        # the env fixes its scenario: the same value is accepted, another is an error
        given = config_kwargs.pop("scenario")
        if not (isinstance(given, str) and given == scenario):
            other = isinstance(given, str) and given in ("coverage", "crossing")
            raise ConfigError(
                f"scenario is fixed to {scenario!r} by {name}, got "
                f"{describe(given)}" + (f"; use fov_{given}_v0 instead" if other else "")
            )
    return make_config(scenario=scenario, **config_kwargs)


def metrics_row(metrics: dict[str, np.ndarray], k: int) -> dict[str, Any]:
    """Copy ``k`` of batched metrics as Python scalars (int for integer arrays, else float)."""
    return {key: v.item(k) for key, v in metrics.items()}


def _set_max_cycles(env: Any, value: int) -> None:
    env._max_cycles = check_int("max_cycles", value, 1)


#: ``max_cycles`` of the ParallelEnv and of the vector env (one definition): steps before
#: truncation (default: the config's); settable, an integer in [1, inf), else
#: ``ValueError`` naming ``max_cycles``.
MAX_CYCLES = property(
    lambda env: env._max_cycles,
    _set_max_cycles,
    doc=(
        "Steps before truncation (default: the config's ``max_cycles``); settable, an "
        "integer in [1, inf), else ``ValueError`` naming ``max_cycles``."
    ),
)


def forward_max_cycles(inner: Callable[[Any], Any]) -> property:
    """A wrapper's ``max_cycles`` that reads and sets ``inner(wrapper).max_cycles`` (a
    plain attribute of the wrapper would be silently ignored by the env it wraps)."""
    return property(
        lambda w: inner(w).max_cycles,
        lambda w, value: setattr(inner(w), "max_cycles", value),
        doc="The wrapped env's steps before truncation; setting it sets the wrapped env's.",
    )


#: ``max_cycles`` of ``SafetyFilterWrapper`` and ``BeliefObservationWrapper``: the
#: wrapped env's
FORWARDED_MAX_CYCLES = forward_max_cycles(lambda w: w.env)


class FovAECEnv(OrderEnforcingWrapper):
    """PettingZoo's AEC conversion of a fov_marl ParallelEnv (``parallel_to_aec``) whose
    ``max_cycles`` reads and sets the ParallelEnv's."""

    max_cycles = forward_max_cycles(lambda w: w.unwrapped)


def aec_env(parallel: ParallelEnv) -> FovAECEnv:
    """The AEC version of ``parallel`` (PettingZoo's conversion, order enforced)."""
    return FovAECEnv(parallel_to_aec_wrapper(parallel))


class FovEnvBase(ParallelEnv):
    """Common implementation; use the scenario modules' ``parallel_env``.

    A view of a :class:`~fov_marl.envs.core.BatchedCore` with one copy.
    """

    metadata: dict[str, Any] = {
        "render_modes": ["human", "rgb_array"],
        "name": "fov_base",
        "is_parallelizable": True,
        "render_fps": 5,
    }
    scenario: str = "coverage"

    def __init__(self, render_mode: str | None = None, **config_kwargs: Any) -> None:
        modes = self.metadata["render_modes"]
        if render_mode is not None and not (isinstance(render_mode, str) and render_mode in modes):
            raise ValueError(
                f"render_mode must be one of {[None, *modes]}, got {describe(render_mode)}"
            )
        self.config: ScenarioConfig = scenario_config(
            self.scenario, self.metadata["name"], config_kwargs
        )
        cfg = self.config
        self.render_mode = render_mode
        self.max_cycles = cfg.max_cycles
        n = cfg.n_agents
        self.possible_agents = [f"robot_{i}" for i in range(n)]
        self.agent_name_mapping = {a: i for i, a in enumerate(self.possible_agents)}
        self.agents: list[str] = []
        self._was_reset = False
        self.layouts = [ObservationLayout(n, i) for i in range(n)]
        self._core: BatchedCore = CORES[self.scenario](cfg, num_envs=1)
        self._obs_space = gymnasium.spaces.Box(
            self._core.obs_low, self._core.obs_high, dtype=np.float32
        )
        self._obs_spaces = {a: self._obs_space for a in self.possible_agents}
        self._act_spaces = {
            a: gymnasium.spaces.Box(-1.0, 1.0, (3,), np.float32) for a in self.possible_agents
        }
        self.state_space = gymnasium.spaces.Box(
            self._core.state_low, self._core.state_high, dtype=np.float32
        )
        self._layers: list[RenderLayer] = []
        self._window: HumanWindow | None = None

    max_cycles = MAX_CYCLES

    # ----------------------------------------------------------------- spaces
    def observation_space(self, agent: str) -> gymnasium.spaces.Box:
        return self._obs_spaces[self._check_agent(agent)]

    def action_space(self, agent: str) -> gymnasium.spaces.Box:
        return self._act_spaces[self._check_agent(agent)]

    @property
    def observation_spaces(self) -> dict[str, gymnasium.spaces.Box]:
        """``{agent: observation_space(agent)}`` (PettingZoo's attribute; a new dict of
        the same space objects on each access, so editing it changes nothing)."""
        return dict(self._obs_spaces)

    @property
    def action_spaces(self) -> dict[str, gymnasium.spaces.Box]:
        """``{agent: action_space(agent)}`` (a new dict of the same space objects)."""
        return dict(self._act_spaces)

    def _check_agent(self, agent: str) -> str:
        if agent not in self.agent_name_mapping:
            raise ValueError(f"unknown agent {agent!r}; agents are {self.possible_agents}")
        return agent

    # ------------------------------------------------------- the core's copy 0
    @property
    def num_steps(self) -> int:
        """Steps taken in the current episode."""
        return int(self._core.num_steps[0])

    @property
    def _poses(self) -> np.ndarray:
        return self._core.poses[0]

    @property
    def _targets(self) -> np.ndarray | None:
        t = self._core.targets
        return None if t is None else t[0]

    # --------------------------------------------------------------- episode
    def reset(
        self, seed: int | None = None, options: dict | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
        seed = check_seed("seed", seed)
        if options is not None and not isinstance(options, Mapping):
            raise ValueError(f"options must be a dict or None, got {describe(options)}")
        obs, metrics = self._core.reset(np.zeros(1, dtype=np.int64), [seed])
        self.agents = list(self.possible_agents)
        self._was_reset = True
        infos = self._agent_infos(metrics_row(metrics, 0))
        if self.render_mode == "human":
            self.render()
        return self._obs_dict(obs[0]), infos

    def step(self, actions: dict[str, Any]):
        if not self.agents:
            raise ValueError(
                "step() called on a finished episode; call reset() first"
                if self._was_reset
                else "step() called before reset()"
            )
        act = self._validate_actions(actions)
        obs, rew, term, metrics = self._core.step(act[None])
        terminate = bool(term[0])
        truncate = self.num_steps >= self.max_cycles
        agents = self.agents
        rewards = {a: float(rew[0, self.agent_name_mapping[a]]) for a in agents}
        terminations = {a: terminate for a in agents}
        truncations = {a: bool(truncate and not terminate) for a in agents}
        infos = self._agent_infos(metrics_row(metrics, 0))
        obs_d = self._obs_dict(obs[0])
        if terminate or truncate:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return obs_d, rewards, terminations, truncations, infos

    def _obs_dict(self, full: np.ndarray) -> dict[str, np.ndarray]:
        """``(N, D)`` float32 observations -> dict of the live agents' rows (copies)."""
        return {a: full[self.agent_name_mapping[a]].copy() for a in self.agents}

    def _agent_infos(self, metrics: dict[str, Any]) -> dict[str, dict]:
        """The per-agent infos of one step or reset: the one place they are built (flat
        ``metrics/<name>`` entries, :func:`fov_marl.infos.agent_infos`)."""
        return agent_infos(self.agents, metrics)

    def _validate_actions(self, actions: dict[str, Any]) -> np.ndarray:
        """``(N, 3)`` float64 actions of the live agents (rows of finished agents zero).

        Every live agent needs an action: an integer or floating array-like of shape
        ``(3,)`` with finite entries (values outside ``[-1, 1]`` are clipped later, as
        the module docstrings say). Strings, bools, complex numbers, object arrays,
        another shape, NaN/inf, unknown or missing agents raise ``ValueError`` naming
        the agent. :class:`~fov_marl.wrappers.SafetyFilterWrapper` calls this too.
        """
        if not isinstance(actions, Mapping):
            raise ValueError(
                f"actions must be a dict agent -> (3,) array, got {type(actions).__name__}"
            )
        extra = [a for a in actions if a not in self.agents]
        if extra:
            raise ValueError(f"actions given for unknown or finished agent(s) {extra}")
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise ValueError(f"actions missing for agent(s) {missing}")
        out = np.zeros((self.config.n_agents, 3))
        for a in self.agents:
            x = as_real_vector(a, actions[a], 3)
            if isinstance(x, str):
                raise ValueError(f"action of {a} {x}")
            out[self.agent_name_mapping[a]] = x
        finite = np.isfinite(out).all(axis=1)
        if not finite.all():
            for a in self.agents:
                i = self.agent_name_mapping[a]
                if not finite[i]:
                    raise ValueError(f"action of {a} must be finite, got {out[i].tolist()}")
        return out

    # ----------------------------------------------------------------- state
    def _check_was_reset(self, what: str) -> None:
        """Before the first ``reset()`` there are no poses: reading them is an error."""
        if not self._was_reset:
            raise ValueError(f"{what} before reset(): the env has no poses yet")

    def state(self) -> np.ndarray:
        """Global state for centralised critics (see the module docstring); ``ValueError``
        before the first ``reset()``."""
        self._check_was_reset("state() called")
        return self._core.state()[0]

    @property
    def poses(self) -> np.ndarray:
        """``(N, 3)`` ground-truth world poses ``[x m, y m, yaw rad]`` (read-only copy);
        ``ValueError`` before the first ``reset()``.

        For evaluation and rendering only; never an input to a decentralised policy.
        """
        self._check_was_reset("poses read")
        p = self._poses.copy()
        p.setflags(write=False)
        return p

    @property
    def targets(self) -> np.ndarray | None:
        """``(N, 2)`` crossing targets in the world frame (read-only copy), else None;
        ``ValueError`` before the first ``reset()``."""
        self._check_was_reset("targets read")
        if self._targets is None:
            return None
        t = self._targets.copy()
        t.setflags(write=False)
        return t

    # ------------------------------------------------------------- rendering
    def add_render_layer(self, layer: RenderLayer) -> None:
        """Register ``layer(canvas)`` to draw on every frame (see fov_marl.envs.rendering)."""
        if not callable(layer):
            raise ValueError(f"layer must be callable as layer(canvas), got {layer!r}")
        self._layers.append(layer)

    def clear_render_layers(self) -> None:
        self._layers.clear()

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gymnasium.logger.warn("render() called with render_mode=None; nothing is drawn")
            return None
        self._check_was_reset("render() called")
        caption = f"t = {self.num_steps * self.config.dt_s:6.1f} s"
        frame = render_frame(self.config, self._poses, self._targets, self._layers, caption=caption)
        if self.render_mode == "rgb_array":
            return frame
        if self._window is None:
            self._window = HumanWindow(self.metadata["name"])
        self._window.show(frame, self.metadata["render_fps"])
        return None

    def close(self) -> None:
        if self._window is not None:
            self._window.close()
            self._window = None
