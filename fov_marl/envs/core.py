"""The batched core: B copies of one scenario stepped together over ``(B, N)`` arrays.

One implementation serves one env copy and many (VMAS-style): the PettingZoo
``ParallelEnv`` of each scenario (:mod:`fov_marl.envs.base`) is a view of a core with
B = 1, and :mod:`fov_marl.envs.vector` exposes B copies. Every per-step quantity is
an array with a leading copy axis: poses ``(B, N, 3)`` world ``[x m, y m, yaw rad]``,
observations ``(B, N, D)``, rewards ``(B, N)``, metrics ``(B,)``.

Randomness. Copy k owns its own ``np.random.Generator`` (seeded by ``reset``), so
copy k of a core is bit-identical to a B = 1 core seeded the same way. The camera
draws ``N·N·3`` clipped standard normals per observation; to avoid one generator
call per copy per step, each copy draws the noise of the next ``K`` observations in
one call (``K`` from :func:`noise_chunk_steps`; the values are the same as ``K``
separate draws). When an episode ends before its chunk is used up (a reset, seeded
or not), the generator is rewound to where the unbuffered draws would have left it
(its state is restored and exactly the consumed normals are drawn again), so a reset
without a seed continues the stream exactly as one draw per step would. The only
per-copy Python work on the step path is that refill (once every ``K`` steps per copy)
and one ``np.dot`` per copy in the exact η (see :meth:`CoverageMetric.eta_batch`);
resets draw each copy's start poses in a loop over the copies being reset (the
dart throwing of :func:`~fov_marl.envs.world.sample_initial_poses` is per team).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from fov_marl.config import ScenarioConfig
from fov_marl.envs.world import Camera, crossing_layout, sample_initial_poses, step_poses
from fov_marl.geometry import world_to_body
from fov_marl.metrics import CoverageMetric, StripCoverageMetric, pairwise_distances_batch
from fov_marl.spaces import (
    CUE_GOAL_BODY,
    CUE_P_WORLD,
    CUE_SCALAR,
    CUE_SIZE,
    CUE_YAW_CS,
    SLOT_SIZE,
    action_to_velocity,
)
from fov_marl.validation import ConfigError

__all__ = ["BatchedCore", "CoverageCore", "CrossingCore", "noise_chunk_steps", "CORES"]

#: Upper bound on the per-copy noise buffer (float64 entries) and on all copies together.
_CHUNK_ENTRIES_PER_COPY = 1 << 16
_CHUNK_ENTRIES_TOTAL = 8_000_000
_MAX_CHUNK_STEPS = 64


def noise_chunk_steps(num_envs: int, n_agents: int) -> int:
    """Observations of camera noise each copy draws per generator call (1 to 64)."""
    per_step = max(n_agents * n_agents * 3, 1)
    k = min(_CHUNK_ENTRIES_PER_COPY // per_step, _CHUNK_ENTRIES_TOTAL // (per_step * num_envs))
    return int(min(max(k, 1), _MAX_CHUNK_STEPS))


class BatchedCore:
    """State and dynamics of ``num_envs`` copies of one scenario (see the module docstring).

    Not a user-facing env: it validates nothing about actions (its callers do) and
    knows no agent names. Subclasses implement the scenario hooks.

    Args:
        config: the validated scenario config (shared by all copies).
        num_envs: B ≥ 1.

    Attributes:
        poses: ``(B, N, 3)`` world poses ``[x m, y m, yaw rad]``.
        targets: ``(B, N, 2)`` world targets (crossing) or None.
        num_steps: ``(B,)`` steps taken in each copy's current episode.
    """

    scenario: str = ""
    #: Metric keys in the order of the ParallelEnv's ``infos[agent]["metrics"]``.
    metric_keys: tuple[str, ...] = ()

    def __init__(self, config: ScenarioConfig, num_envs: int) -> None:
        self.config = config
        self.num_envs = B = int(num_envs)
        self.n_agents = N = config.n_agents
        self.camera = Camera(config)
        self.obs_low, self.obs_high = self._obs_bounds()
        self.obs_dim = int(self.obs_low.size)
        self.state_low, self.state_high = self._state_bounds()
        self.poses = np.zeros((B, N, 3))
        self.targets: np.ndarray | None = None
        self.num_steps = np.zeros(B, dtype=np.int64)
        self._collisions_total = np.zeros(B, dtype=np.int64)
        self._violations_total = np.zeros(B, dtype=np.int64)
        self._min_distance_episode = np.full(B, np.inf)
        self._col_prev = np.zeros((B, N, N), dtype=bool)
        self._viol_prev = np.zeros((B, N, N), dtype=bool)
        self._diag = np.arange(N)
        self._all = np.arange(B)
        # per-copy generators and camera-noise chunks
        self.rngs: list[np.random.Generator | None] = [None] * B
        self._chunk = noise_chunk_steps(B, N)
        self._noise = np.zeros((B, self._chunk, N, N, 3))
        self._noise_pos = np.full(B, self._chunk, dtype=np.int64)  # == chunk: empty
        self._noise_state: list[dict[str, Any] | None] = [None] * B
        self._clip = float(config.meas_noise_clip_sigma)

    # ------------------------------------------------------------- bounds
    def _obs_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        n = self.n_agents
        b = self.camera.measure_bound_m
        slot_lo = np.array([0.0, -b, -b, -1.0, -1.0])
        slot_hi = np.array([1.0, b, b, 1.0, 1.0])
        L = self.config.arena_size_m
        diag = L * np.sqrt(2.0)
        cue_lo = np.array([0.0, 0.0, -1.0, -1.0, -diag, -diag, 0.0])
        cue_hi = np.array([L, L, 1.0, 1.0, diag, diag, self._cue_scalar_high()])
        lo = np.concatenate([np.tile(slot_lo, n - 1), cue_lo]).astype(np.float32)
        hi = np.concatenate([np.tile(slot_hi, n - 1), cue_hi]).astype(np.float32)
        assert lo.size == SLOT_SIZE * (n - 1) + CUE_SIZE
        return lo, hi

    def _state_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        L = self.config.arena_size_m
        n = self.n_agents
        lo = np.tile([0.0, 0.0, -1.0, -1.0], n)
        hi = np.tile([L, L, 1.0, 1.0], n)
        extra_lo, extra_hi = self._state_extra_bounds()
        return (
            np.concatenate([lo, extra_lo]).astype(np.float32),
            np.concatenate([hi, extra_hi]).astype(np.float32),
        )

    # -------------------------------------------------- scenario-specific hooks
    def _state_extra_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def _state_extra(self) -> np.ndarray:
        """``(B, S_extra)`` scenario part of the global state."""
        raise NotImplementedError

    def _reset_copy(self, k: int, rng: np.random.Generator) -> None:
        """Set ``poses[k]`` (and scenario state of copy k) from ``rng``."""
        raise NotImplementedError

    def _goal_world(self, idx: Any) -> np.ndarray:
        """``(b, N, 2)`` world point each robot's cue refers to (q_m or its target)."""
        raise NotImplementedError

    def _cue_scalar(self, goal_body: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _cue_scalar_high(self) -> float:
        """Upper bound of the cue's last entry (m): the arena diagonal by default."""
        return self.config.arena_size_m * math.sqrt(2.0)

    def _rewards_and_metrics(
        self, idx: Any, col_i: np.ndarray, viol_i: np.ndarray, metrics: dict, reset: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        """Add scenario metrics; return rewards ``(b, N)`` and termination ``(b,)``."""
        raise NotImplementedError

    # ------------------------------------------------------------ episode
    def reset(
        self, idx: np.ndarray, seeds: Sequence[int | None]
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Start a new episode in copies ``idx``.

        Args:
            idx: ``(b,)`` int copy indices (distinct).
            seeds: one per index: an int re-seeds that copy's generator; None continues
                it (a fresh, OS-seeded generator if the copy has none yet).

        Returns:
            ``(obs (b, N, D) float32, metrics dict of (b,) arrays)``.

        Raises:
            ConfigError: random starts that do not fit the arena (naming the fields).
        """
        idx = np.asarray(idx, dtype=np.int64)
        for k, seed in zip(idx.tolist(), seeds, strict=True):
            rng = self.rngs[k]
            if seed is not None or rng is None:
                rng = self.rngs[k] = np.random.default_rng(seed)
                self._noise_state[k] = None
            else:
                self._rewind_noise(k)
            self._noise_pos[k] = self._chunk
            try:
                self._reset_copy(k, rng)
            except ValueError as exc:  # random starts that do not fit: name the fields
                cfg = self.config
                raise ConfigError(
                    f"reset: {exc} (n_agents = {cfg.n_agents}, arena_size_m = "
                    f"{cfg.arena_size_m}, init_min_separation_m = {cfg.init_min_separation_m})"
                ) from None
            self._refill_noise(k)
        self.num_steps[idx] = 0
        self._collisions_total[idx] = 0
        self._violations_total[idx] = 0
        self._min_distance_episode[idx] = np.inf
        self._col_prev[idx] = False
        self._viol_prev[idx] = False
        metrics, col_i, viol_i = self._common_metrics(idx)
        self._rewards_and_metrics(idx, col_i, viol_i, metrics, reset=True)
        return self._observe(idx), metrics

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Advance every copy by one step.

        Args:
            actions: ``(B, N, 3)`` float64 normalised actions (clipped here, as
                :func:`fov_marl.spaces.action_to_velocity` says).

        Returns:
            ``(obs (B, N, D) float32, rewards (B, N) float64, terminated (B,) bool,
            metrics dict of (B,) arrays)``. Truncation is the caller's (``max_cycles``).
        """
        cfg = self.config
        v, w = action_to_velocity(actions, cfg.v_max_mps, cfg.omega_max_radps)
        self.poses = step_poses(cfg, self.poses, v, w)
        self.num_steps += 1
        idx = slice(None)
        metrics, col_i, viol_i = self._common_metrics(idx)
        rew, term = self._rewards_and_metrics(idx, col_i, viol_i, metrics, reset=False)
        return self._observe(idx), rew, term, metrics

    # ------------------------------------------------------------- camera noise
    def _refill_noise(self, k: int) -> None:
        rng = self.rngs[k]
        self._noise_state[k] = rng.bit_generator.state
        buf = self._noise[k]
        rng.standard_normal(out=buf.reshape(-1))
        np.clip(buf, -self._clip, self._clip, out=buf)
        self._noise_pos[k] = 0

    def _rewind_noise(self, k: int) -> None:
        """Put copy k's generator where one draw per observation would have left it."""
        state = self._noise_state[k]
        used = int(self._noise_pos[k])
        if state is None or used >= self._chunk:
            return
        rng = self.rngs[k]
        rng.bit_generator.state = state
        if used:
            rng.standard_normal(used * self.n_agents * self.n_agents * 3)
        self._noise_state[k] = None

    def _take_noise(self, idx: Any) -> np.ndarray:
        """``(b, N, N, 3)`` clipped standard normals of the next observation of ``idx``."""
        ks = self._all[idx]
        empty = self._noise_pos[ks] >= self._chunk
        if empty.any():
            for k in ks[empty].tolist():
                self._refill_noise(k)
        pos = self._noise_pos[ks]
        noise = self._noise[ks, pos]
        self._noise_pos[ks] = pos + 1
        return noise

    # ------------------------------------------------------------- metrics
    def _common_metrics(self, idx: Any) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
        cfg = self.config
        pos = self.poses[idx, :, :2]
        b, n = pos.shape[0], self.n_agents
        if n > 1:
            d = pairwise_distances_batch(pos)
            d[:, self._diag, self._diag] = np.inf
            col = d < cfg.collision_distance_m
            viol = d < cfg.safety_distance_m
            min_d = d.min(axis=(1, 2))
        else:
            col = viol = np.zeros((b, 1, 1), dtype=bool)
            min_d = np.full(b, np.inf)
        col_i, viol_i = col.sum(2), viol.sum(2)
        n_col, n_viol = col_i.sum(1) // 2, viol_i.sum(1) // 2
        # totals count events: a pair entering contact (or D_s) counts once, however long
        self._collisions_total[idx] += np.sum(col & ~self._col_prev[idx], axis=(1, 2)) // 2
        self._violations_total[idx] += np.sum(viol & ~self._viol_prev[idx], axis=(1, 2)) // 2
        self._col_prev[idx], self._viol_prev[idx] = col, viol
        self._min_distance_episode[idx] = np.minimum(self._min_distance_episode[idx], min_d)
        metrics = {
            "t_s": self.num_steps[idx] * cfg.dt_s,
            "min_distance": min_d,
            "min_distance_episode": self._min_distance_episode[idx].copy(),
            "collisions": n_col,
            "collisions_total": self._collisions_total[idx].copy(),
            "safety_violations": n_viol,
            "safety_violations_total": self._violations_total[idx].copy(),
        }
        return metrics, col_i, viol_i

    # ------------------------------------------------------------- observations
    def _observe(self, idx: Any) -> np.ndarray:
        poses = self.poses[idx]
        b, n = poses.shape[0], self.n_agents
        blocks = self.camera.neighbour_blocks_from_noise(poses, self._take_noise(idx))
        goal_body = world_to_body(self._goal_world(idx), poses)
        cue = np.empty((b, n, CUE_SIZE))
        cue[..., CUE_P_WORLD] = poses[..., :2]
        cue[..., CUE_YAW_CS] = np.stack([np.cos(poses[..., 2]), np.sin(poses[..., 2])], -1)
        cue[..., CUE_GOAL_BODY] = goal_body
        cue[..., CUE_SCALAR] = self._cue_scalar(goal_body)
        full = np.concatenate([blocks.reshape(b, n, -1), cue], axis=-1).astype(np.float32)
        # Only float32 round-off can cross the documented bounds; keep contains() exact.
        np.clip(full, self.obs_low, self.obs_high, out=full)
        return full

    def state(self) -> np.ndarray:
        """``(B, S)`` float32 global states for centralised critics."""
        p = self.poses
        per = np.stack([p[..., 0], p[..., 1], np.cos(p[..., 2]), np.sin(p[..., 2])], -1)
        s = np.concatenate([per.reshape(self.num_envs, -1), self._state_extra()], axis=1)
        return np.clip(s.astype(np.float32), self.state_low, self.state_high)


class CoverageCore(BatchedCore):
    """fov_coverage_v0 (see that module's docstring for rewards and metrics)."""

    scenario = "coverage"
    metric_keys = (
        "t_s",
        "min_distance",
        "min_distance_episode",
        "collisions",
        "collisions_total",
        "safety_violations",
        "safety_violations_total",
        "eta",
    )

    #: η methods: ``"exact"`` (the 0.1 m grid quadrature of :class:`CoverageMetric`,
    #: the evaluation metric) or ``"strip"`` (:class:`StripCoverageMetric`, cheaper, for
    #: training rewards).
    ETA_METHODS = ("exact", "strip")

    def __init__(self, config: ScenarioConfig, num_envs: int, eta_method: str = "exact") -> None:
        super().__init__(config, num_envs)
        if eta_method not in self.ETA_METHODS:
            raise ValueError(
                f"eta_method must be one of {list(self.ETA_METHODS)}, got {eta_method!r}"
            )
        self.eta_method = eta_method
        self.cov_metric = CoverageMetric(config)
        if eta_method == "strip":
            self._eta = StripCoverageMetric(config)._eta_batch
        else:
            self._eta = functools.partial(self.cov_metric._eta_batch, exact_sum=True)
        self._eta_prev = np.zeros(self.num_envs)
        self._goal = np.broadcast_to(np.asarray(config.density_mean_m, dtype=np.float64), (2,))

    def _state_extra_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        L = self.config.arena_size_m
        return np.zeros(3), np.array([L, L, max(L, self.config.density_sigma_m)])

    def _state_extra(self) -> np.ndarray:
        extra = np.array([*self.config.density_mean_m, self.config.density_sigma_m])
        return np.broadcast_to(extra, (self.num_envs, 3))

    def _reset_copy(self, k: int, rng: np.random.Generator) -> None:
        if self.config.initial_poses is not None:
            self.poses[k] = np.array(self.config.initial_poses, dtype=np.float64)
        else:
            self.poses[k] = sample_initial_poses(self.config, rng)

    def _goal_world(self, idx: Any) -> np.ndarray:
        return np.broadcast_to(self._goal, (self.poses[idx].shape[0], self.n_agents, 2))

    def _cue_scalar(self, goal_body: np.ndarray) -> np.ndarray:
        return np.full(goal_body.shape[:-1], self.config.density_sigma_m)

    def _cue_scalar_high(self) -> float:
        # σ may exceed the diagonal (a nearly flat density): the observation reports it
        # as it is, like the state (the clip to the bounds must not change it)
        return max(super()._cue_scalar_high(), self.config.density_sigma_m)

    def _rewards_and_metrics(
        self, idx: Any, col_i: np.ndarray, viol_i: np.ndarray, metrics: dict, reset: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        cfg = self.config
        eta = self._eta(self.poses[idx, :, :2])
        metrics["eta"] = eta
        b = eta.shape[0]
        if reset:
            self._eta_prev[idx] = eta
            return np.zeros((b, self.n_agents)), np.zeros(b, dtype=bool)
        gain = eta - self._eta_prev[idx]
        self._eta_prev[idx] = eta
        rew = (
            cfg.reward_eta_gain * gain[:, None]
            - cfg.collision_penalty * col_i
            - cfg.safety_penalty * viol_i
        )
        return rew.astype(np.float64), np.zeros(b, dtype=bool)


class CrossingCore(BatchedCore):
    """fov_crossing_v0 (see that module's docstring for rewards and metrics)."""

    scenario = "crossing"
    metric_keys = (
        "t_s",
        "min_distance",
        "min_distance_episode",
        "collisions",
        "collisions_total",
        "safety_violations",
        "safety_violations_total",
        "arrived",
        "arrived_ever",
        "mean_distance_to_target",
        "max_distance_to_target",
    )

    def __init__(self, config: ScenarioConfig, num_envs: int) -> None:
        super().__init__(config, num_envs)
        B, N = self.num_envs, self.n_agents
        self.targets = np.zeros((B, N, 2))
        self._dist_prev = np.zeros((B, N))
        self._arrived_ever = np.zeros((B, N), dtype=bool)

    def _state_extra_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        n, L = self.config.n_agents, self.config.arena_size_m
        return np.zeros(2 * n), np.full(2 * n, L)

    def _state_extra(self) -> np.ndarray:
        return self.targets.reshape(self.num_envs, -1)

    def _reset_copy(self, k: int, rng: np.random.Generator) -> None:
        starts, targets = crossing_layout(self.config, rng)
        self.targets[k] = targets
        if self.config.initial_poses is not None:
            starts = np.array(self.config.initial_poses, dtype=np.float64)
        self.poses[k] = starts

    def _goal_world(self, idx: Any) -> np.ndarray:
        return self.targets[idx]

    def _cue_scalar(self, goal_body: np.ndarray) -> np.ndarray:
        return np.linalg.norm(goal_body, axis=-1)

    def _rewards_and_metrics(
        self, idx: Any, col_i: np.ndarray, viol_i: np.ndarray, metrics: dict, reset: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        cfg = self.config
        dist = np.linalg.norm(self.targets[idx] - self.poses[idx, :, :2], axis=-1)
        here = dist < cfg.target_tolerance_m
        if reset:
            self._dist_prev[idx] = dist
            self._arrived_ever[idx] = here
            rew = np.zeros(dist.shape)
            term = np.zeros(dist.shape[0], dtype=bool)
        else:
            ever = self._arrived_ever[idx]
            first = here & ~ever
            ever = ever | here
            self._arrived_ever[idx] = ever
            rew = (
                cfg.progress_gain * (self._dist_prev[idx] - dist)
                + cfg.arrival_bonus * first
                - cfg.collision_penalty * col_i
                - cfg.safety_penalty * viol_i
            )
            self._dist_prev[idx] = dist
            term = here.all(axis=-1)
        metrics["arrived"] = here.sum(axis=-1)
        metrics["arrived_ever"] = self._arrived_ever[idx].sum(axis=-1)
        metrics["mean_distance_to_target"] = dist.mean(axis=-1)
        metrics["max_distance_to_target"] = dist.max(axis=-1)
        return rew.astype(np.float64), term


#: scenario name -> core class
CORES: dict[str, type[BatchedCore]] = {"coverage": CoverageCore, "crossing": CrossingCore}
