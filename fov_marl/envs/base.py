"""The shared PettingZoo ``ParallelEnv`` of the two scenarios.

The scenario modules (:mod:`fov_marl.envs.fov_coverage_v0`,
:mod:`fov_marl.envs.fov_crossing_v0`) hold the user documentation; this module holds
the machinery: config, spaces, seeding, stepping, metrics, rendering.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium
import numpy as np
from pettingzoo import ParallelEnv

from fov_marl.config import ScenarioConfig, make_config
from fov_marl.envs.rendering import HumanWindow, RenderLayer, render_frame
from fov_marl.envs.world import Camera, step_poses
from fov_marl.geometry import world_to_body
from fov_marl.infos import agent_infos
from fov_marl.metrics import CoverageMetric, pairwise_distances
from fov_marl.spaces import CUE_SIZE, SLOT_SIZE, ObservationLayout, action_to_velocity
from fov_marl.validation import ConfigError, as_real_vector, check_seed, describe

__all__ = ["FovEnvBase"]


class FovEnvBase(ParallelEnv):
    """Common implementation; use the scenario modules' ``parallel_env``."""

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
        if "scenario" in config_kwargs:
            # the env fixes its scenario: the same value is accepted, another is an error
            given = config_kwargs.pop("scenario")
            if not (isinstance(given, str) and given == self.scenario):
                other = isinstance(given, str) and given in ("coverage", "crossing")
                raise ConfigError(
                    f"scenario is fixed to {self.scenario!r} by {self.metadata['name']}, got "
                    f"{describe(given)}" + (f"; use fov_{given}_v0 instead" if other else "")
                )
        self.config: ScenarioConfig = make_config(scenario=self.scenario, **config_kwargs)
        cfg = self.config
        self.render_mode = render_mode
        self.max_cycles = cfg.max_cycles
        n = cfg.n_agents
        self.possible_agents = [f"robot_{i}" for i in range(n)]
        self.agent_name_mapping = {a: i for i, a in enumerate(self.possible_agents)}
        self.agents: list[str] = []
        self.layouts = [ObservationLayout(n, i) for i in range(n)]
        self._camera = Camera(cfg)
        self._obs_space = self._make_obs_space()
        self._obs_spaces = {a: self._obs_space for a in self.possible_agents}
        self._act_spaces = {
            a: gymnasium.spaces.Box(-1.0, 1.0, (3,), np.float32) for a in self.possible_agents
        }
        self.state_space = self._make_state_space()
        self._rng: np.random.Generator | None = None
        self._poses = np.zeros((n, 3))
        self._targets: np.ndarray | None = None
        self._layers: list[RenderLayer] = []
        self._window: HumanWindow | None = None
        self._cov_metric = CoverageMetric(cfg) if self.scenario == "coverage" else None
        self.num_steps = 0

    # ----------------------------------------------------------------- spaces
    def observation_space(self, agent: str) -> gymnasium.spaces.Box:
        return self._obs_spaces[self._check_agent(agent)]

    def action_space(self, agent: str) -> gymnasium.spaces.Box:
        return self._act_spaces[self._check_agent(agent)]

    def _check_agent(self, agent: str) -> str:
        if agent not in self.agent_name_mapping:
            raise ValueError(f"unknown agent {agent!r}; agents are {self.possible_agents}")
        return agent

    def _cue_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        L = self.config.arena_size_m
        diag = L * np.sqrt(2.0)
        lo = np.array([0.0, 0.0, -1.0, -1.0, -diag, -diag, 0.0])
        hi = np.array([L, L, 1.0, 1.0, diag, diag, diag])
        return lo, hi

    def _make_obs_space(self) -> gymnasium.spaces.Box:
        n = self.config.n_agents
        b = self._camera.measure_bound_m
        slot_lo = np.array([0.0, -b, -b, -1.0, -1.0])
        slot_hi = np.array([1.0, b, b, 1.0, 1.0])
        cue_lo, cue_hi = self._cue_bounds()
        lo = np.concatenate([np.tile(slot_lo, n - 1), cue_lo]).astype(np.float32)
        hi = np.concatenate([np.tile(slot_hi, n - 1), cue_hi]).astype(np.float32)
        assert lo.size == SLOT_SIZE * (n - 1) + CUE_SIZE
        return gymnasium.spaces.Box(lo, hi, dtype=np.float32)

    def _make_state_space(self) -> gymnasium.spaces.Box:
        L = self.config.arena_size_m
        n = self.config.n_agents
        lo = np.tile([0.0, 0.0, -1.0, -1.0], n)
        hi = np.tile([L, L, 1.0, 1.0], n)
        extra_lo, extra_hi = self._state_extra_bounds()
        return gymnasium.spaces.Box(
            np.concatenate([lo, extra_lo]).astype(np.float32),
            np.concatenate([hi, extra_hi]).astype(np.float32),
            dtype=np.float32,
        )

    # -------------------------------------------------- scenario-specific hooks
    def _state_extra_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def _state_extra(self) -> np.ndarray:
        raise NotImplementedError

    def _reset_scenario(self, rng: np.random.Generator) -> np.ndarray:
        """Return start poses (N, 3) and set scenario state."""
        raise NotImplementedError

    def _goal_world(self) -> np.ndarray:
        """(N, 2) world point each robot's cue refers to (q_m or its target)."""
        raise NotImplementedError

    def _cue_scalar(self, goal_body: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _rewards_and_metrics(
        self, col_i: np.ndarray, viol_i: np.ndarray, metrics: dict[str, Any], reset: bool = False
    ) -> tuple[np.ndarray, bool]:
        """Add scenario metrics to ``metrics``; return rewards (N,) and termination.

        ``col_i``/``viol_i``: (N,) collisions / D_s violations robot i is part of.
        With ``reset=True`` only initialise the scenario's running quantities.
        """
        raise NotImplementedError

    # --------------------------------------------------------------- episode
    def reset(
        self, seed: int | None = None, options: dict | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
        seed = check_seed("seed", seed)
        if options is not None and not isinstance(options, Mapping):
            raise ValueError(f"options must be a dict or None, got {describe(options)}")
        if seed is not None or self._rng is None:
            self._rng = np.random.default_rng(seed)
        self.agents = list(self.possible_agents)
        self.num_steps = 0
        self._collisions_total = 0
        self._violations_total = 0
        self._min_distance_episode = np.inf
        try:
            self._poses = self._reset_scenario(self._rng)
        except ValueError as exc:  # random starts that do not fit: name the fields
            cfg = self.config
            raise ConfigError(
                f"reset: {exc} (n_agents = {cfg.n_agents}, arena_size_m = {cfg.arena_size_m}, "
                f"init_min_separation_m = {cfg.init_min_separation_m})"
            ) from None
        metrics = self._step_metrics_common()
        col_i, viol_i = metrics.pop("_col_i"), metrics.pop("_viol_i")
        self._rewards_and_metrics(col_i, viol_i, metrics, reset=True)
        obs = self._observe()
        infos = agent_infos(self.agents, metrics)
        if self.render_mode == "human":
            self.render()
        return obs, infos

    def step(self, actions: dict[str, Any]):
        if not self.agents:
            raise ValueError("step() called on a finished episode; call reset() first")
        act = self._validate_actions(actions)
        v, w = action_to_velocity(act, self.config.v_max_mps, self.config.omega_max_radps)
        self._poses = step_poses(self.config, self._poses, v, w)
        self.num_steps += 1

        metrics = self._step_metrics_common()
        col_i, viol_i = metrics.pop("_col_i"), metrics.pop("_viol_i")
        rew, terminate = self._rewards_and_metrics(col_i, viol_i, metrics)
        truncate = self.num_steps >= self.max_cycles
        obs = self._observe()
        agents = self.agents
        rewards = {a: float(rew[self.agent_name_mapping[a]]) for a in agents}
        terminations = {a: bool(terminate) for a in agents}
        truncations = {a: bool(truncate and not terminate) for a in agents}
        infos = agent_infos(agents, metrics)
        if terminate or truncate:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return obs, rewards, terminations, truncations, infos

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

    def _step_metrics_common(self) -> dict[str, Any]:
        cfg = self.config
        pos = self._poses[:, :2]
        n = cfg.n_agents
        if n > 1:
            d = pairwise_distances(pos)
            np.fill_diagonal(d, np.inf)
            col = d < cfg.collision_distance_m
            viol = d < cfg.safety_distance_m
            min_d = float(d.min())
        else:
            col = viol = np.zeros((1, 1), dtype=bool)
            min_d = float("inf")
        col_i, viol_i = col.sum(1), viol.sum(1)
        n_col, n_viol = int(col_i.sum() // 2), int(viol_i.sum() // 2)
        # totals count events: a pair entering contact (or D_s) counts once, however long
        if self.num_steps == 0:
            self._col_prev, self._viol_prev = np.zeros_like(col), np.zeros_like(viol)
        self._collisions_total += int(np.sum(col & ~self._col_prev) // 2)
        self._violations_total += int(np.sum(viol & ~self._viol_prev) // 2)
        self._col_prev, self._viol_prev = col, viol
        self._min_distance_episode = min(self._min_distance_episode, min_d)
        return {
            "t_s": self.num_steps * cfg.dt_s,
            "min_distance": min_d,
            "min_distance_episode": self._min_distance_episode,
            "collisions": n_col,
            "collisions_total": self._collisions_total,
            "safety_violations": n_viol,
            "safety_violations_total": self._violations_total,
            "_col_i": col_i,
            "_viol_i": viol_i,
        }

    def _observe(self) -> dict[str, np.ndarray]:
        cfg = self.config
        n = cfg.n_agents
        blocks = self._camera.neighbour_blocks(self._poses, self._rng)
        goal_body = world_to_body(self._goal_world(), self._poses)
        cue = np.empty((n, CUE_SIZE))
        cue[:, 0:2] = self._poses[:, :2]
        cue[:, 2] = np.cos(self._poses[:, 2])
        cue[:, 3] = np.sin(self._poses[:, 2])
        cue[:, 4:6] = goal_body
        cue[:, 6] = self._cue_scalar(goal_body)
        full = np.concatenate([blocks.reshape(n, -1), cue], axis=1).astype(np.float32)
        # Only float32 round-off can cross the documented bounds; keep contains() exact.
        np.clip(full, self._obs_space.low, self._obs_space.high, out=full)
        return {a: full[self.agent_name_mapping[a]].copy() for a in self.agents}

    # ----------------------------------------------------------------- state
    def state(self) -> np.ndarray:
        """Global state for centralised critics (see the module docstring)."""
        p = self._poses
        per = np.column_stack([p[:, 0], p[:, 1], np.cos(p[:, 2]), np.sin(p[:, 2])]).reshape(-1)
        s = np.concatenate([per, self._state_extra()]).astype(np.float32)
        return np.clip(s, self.state_space.low, self.state_space.high)

    @property
    def poses(self) -> np.ndarray:
        """``(N, 3)`` ground-truth world poses ``[x m, y m, yaw rad]`` (read-only copy).

        For evaluation and rendering only; never an input to a decentralised policy.
        """
        p = self._poses.copy()
        p.setflags(write=False)
        return p

    @property
    def targets(self) -> np.ndarray | None:
        """``(N, 2)`` crossing targets in the world frame (read-only copy), else None."""
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
