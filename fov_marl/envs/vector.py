"""Vector env: B copies of a scenario stepped together over arrays (the batched core).

Build it with ``fov_coverage_v0.vector_env(num_envs=B, **config)`` or
``fov_crossing_v0.vector_env(...)``; every keyword is a
:class:`~fov_marl.config.ScenarioConfig` field, validated as by ``parallel_env``::

    venv = fov_coverage_v0.vector_env(num_envs=64, n_agents=6, fov_deg=120.0)
    obs, infos = venv.reset(seed=0)                # obs (B, N, D) float32
    obs, rew, term, trunc, infos = venv.step(actions)   # actions (B, N, 3)

==========================  ===============================================================
attribute                   meaning
==========================  ===============================================================
``num_envs``, ``n_agents``  B copies, N robots per copy
``config``                  the :class:`~fov_marl.config.ScenarioConfig` of every copy
``possible_agents``         ``["robot_0", …]``: row i of every array is ``robot_i``
``single_observation_space``  the ParallelEnv's per-agent ``Box`` ``(D,)`` float32
``single_action_space``     ``Box(-1, 1, (3,), float32)``
``observation_space``       ``Box`` ``(B, N, D)``; ``action_space`` ``Box`` ``(B, N, 3)``
``max_cycles``              steps before truncation (settable, as on the ParallelEnv)
``poses``                   ``(B, N, 3)`` world ground truth, read-only copy (evaluation)
``targets``                 ``(B, N, 2)`` crossing targets, read-only copy (else None)
==========================  ===============================================================

Seeding. ``reset(seed=s)`` seeds copy k with ``s + k``: copy k is then bit-identical,
observation by observation, reward by reward and metric by metric, to
``parallel_env(**config)`` after ``reset(seed=s + k)`` under the same actions (both are
views of one implementation, :mod:`fov_marl.envs.core`); the rewards are float32 here,
the ParallelEnv's float64 rewards rounded. ``reset()`` without a seed
continues every copy's generator, like the ParallelEnv's.

Autoreset: SAME-STEP, as SB3 and Gymnasium's ``AutoresetMode.SAME_STEP``. When copy k
ends at a step (all its robots terminate together, or it reaches ``max_cycles``), the
``obs[k]`` returned by that :meth:`~FovVectorEnv.step` is already the first observation
of its next episode (an unseeded reset, continuing the copy's generator exactly as
``ParallelEnv.reset()`` would), ``terminations[k]``/``truncations[k]`` say how the
episode ended, and

* ``infos["final_obs"]``: ``(B, N, D)`` float32, the last observation of the finished
  episode in the rows of finished copies, zeros elsewhere;
* ``infos["_final_obs"]``: ``(B,)`` bool, the copies that finished (and were reset);
* ``infos["metrics"]``: dict of ``(B,)`` arrays, the same keys as the ParallelEnv's
  ``infos[agent]["metrics"]``, for the step just taken: for a finished copy, the last
  step of its episode (final η, ``collisions_total``, ...);
* ``infos["reset_metrics"]`` (only when some copy finished): the metrics of the new
  episode's first state for finished copies (what ``ParallelEnv.reset`` would report),
  ``infos["metrics"]`` elsewhere.

``reset`` returns ``infos = {"metrics": ...}``. Rewards are float32 ``(B, N)``;
terminations and truncations bool ``(B, N)`` (equal across a copy's robots; truncation
is never set together with termination).

Actions: any real (integer or floating) array-like of shape ``(B, N, 3)`` with finite
entries, clipped to ``[-1, 1]`` and speed-limited as in the ParallelEnv; another shape,
a non-numeric, boolean or complex dtype, NaN or inf raise ``ValueError`` naming
``actions``.

Errors and closing. A :meth:`~FovVectorEnv.step` whose automatic reset fails (random
starts that do not fit, :func:`~fov_marl.envs.world.sample_initial_poses`) raises after
every copy has stepped, so the env refuses to step again until :meth:`~FovVectorEnv.reset`
(``ValueError``; a failed ``reset`` likewise). :meth:`~FovVectorEnv.close` sets
``closed``; ``reset`` and ``step`` then raise ``ValueError``, as on a closed
``SubprocVectorEnv``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium
import numpy as np

from fov_marl.config import ScenarioConfig
from fov_marl.envs.base import MAX_CYCLES, scenario_config
from fov_marl.envs.core import CORES, BatchedCore
from fov_marl.validation import check_seed, describe, holds_bool

try:  # Gymnasium >= 1.1 names the autoreset modes with an enum
    from gymnasium.vector import AutoresetMode

    _SAME_STEP: Any = AutoresetMode.SAME_STEP
except ImportError:  # pragma: no cover - Gymnasium 1.0
    _SAME_STEP = "SameStep"

__all__ = [
    "FovVectorEnv",
    "check_num_envs",
    "check_vector_actions",
    "vector_seeds",
    "warn_no_render",
]


def check_num_envs(num_envs: Any) -> int:
    """``num_envs`` as an int ≥ 1, else ``ValueError`` naming it."""
    if isinstance(num_envs, bool) or not isinstance(num_envs, int | np.integer) or num_envs < 1:
        raise ValueError(f"num_envs must be an integer in [1, inf), got {describe(num_envs)}")
    return int(num_envs)


def vector_seeds(seed: Any, num_envs: int) -> list[int | None]:
    """The seed of each of ``num_envs`` copies from a vector ``reset(seed=...)``: an int s
    gives copy k ``s + k``; a sequence of ``num_envs`` ints or None entries is checked
    entry by entry (``seed[k]`` named); None gives every copy None (continue its
    generator). Anything else raises ``ValueError``."""
    B = num_envs
    if isinstance(seed, np.ndarray) and seed.ndim == 0:  # a 0-d array: its scalar
        seed = seed.item()
    if seed is None or isinstance(seed, int | np.integer | bool):
        s = check_seed("seed", seed)
        return [None if s is None else s + k for k in range(B)]
    if isinstance(seed, Sequence | np.ndarray) and not isinstance(seed, str | bytes):
        seeds = [check_seed(f"seed[{k}]", x) for k, x in enumerate(seed)]
        if len(seeds) != B:
            raise ValueError(
                f"seed must be None, an int or a sequence of num_envs = {B} seeds, "
                f"got a sequence of {len(seeds)}"
            )
        return seeds
    raise ValueError(f"seed must be None, an int or a sequence of ints, got {seed!r}")


def check_vector_actions(actions: Any, num_envs: int, n_agents: int) -> np.ndarray:
    """``actions`` as a float64 ``(num_envs, n_agents, 3)`` array: any real (integer or
    floating) array-like of that shape with finite entries; another shape, a
    non-numeric, boolean or complex dtype, NaN or inf raise ``ValueError`` naming
    ``actions`` (and the copy and robot of a non-finite entry). Not clipped here."""
    shape = (num_envs, n_agents, 3)
    try:
        a = np.asarray(actions)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"actions must be a real array of shape {shape}: {exc}") from None
    if a.dtype == bool or a.dtype.kind not in "iuf":
        raise ValueError(
            f"actions must be a real (integer or floating) array of shape {shape}, "
            f"got dtype {a.dtype}"
        )
    if a.shape != shape:
        raise ValueError(
            f"actions must have shape (num_envs, n_agents, 3) = {shape}, got {a.shape}"
        )
    if holds_bool(actions):
        raise ValueError(f"actions must be a real array of shape {shape}, got a bool in a list")
    a = a.astype(np.float64, copy=False)
    if not np.isfinite(a).all():
        k, i = np.argwhere(~np.isfinite(a).all(axis=-1))[0]
        raise ValueError(
            f"actions must be finite, got {a[k, i].tolist()} at actions[{k}, {i}] "
            f"(copy {k}, robot_{i})"
        )
    return a


def warn_no_render() -> None:
    """The ``render()`` of the vector envs: they draw nothing (``render_mode`` None), so
    warn as Gymnasium's envs do without a render mode (the caller returns None)."""
    gymnasium.logger.warn(
        "a vector env does not render (render_mode is None); use "
        "parallel_env(render_mode='rgb_array') or `fov-marl render` for frames"
    )


class FovVectorEnv:
    """B copies of one scenario over arrays (see the module docstring).

    Args:
        num_envs: B, an integer ≥ 1.
        scenario: ``"coverage"`` or ``"crossing"``.
        name: the env name (``"fov_coverage_v0"``), for messages and ``metadata``.
        config_kwargs: :class:`~fov_marl.config.ScenarioConfig` fields.
        config: instead of ``config_kwargs``, an already validated config.
        eta_method: coverage only: ``"exact"`` (default; the ParallelEnv's η, so copies
            are bit-identical to it) or ``"strip"`` (the cheaper
            :class:`~fov_marl.metrics.StripCoverageMetric` for ``metrics["eta"]`` and the
            reward; copies then differ from the ParallelEnv by its documented error).

    Raises:
        ValueError: bad ``num_envs`` or config (naming the field).
    """

    #: ``autoreset_mode`` is Gymnasium's ``AutoresetMode.SAME_STEP`` (its value
    #: ``"SameStep"`` on Gymnasium 1.0, which has no enum)
    metadata: dict[str, Any] = {"render_modes": [], "autoreset_mode": _SAME_STEP}
    #: The vector env does not render (use a ParallelEnv for frames).
    render_mode: str | None = None

    def __init__(
        self,
        num_envs: int,
        scenario: str,
        name: str,
        config_kwargs: Mapping[str, Any] | None = None,
        *,
        config: ScenarioConfig | None = None,
        eta_method: str = "exact",
    ) -> None:
        B = check_num_envs(num_envs)
        if scenario not in CORES:
            raise ValueError(f"scenario must be one of {sorted(CORES)}, got {describe(scenario)}")
        if config is None:
            config = scenario_config(scenario, name, dict(config_kwargs or {}))
        elif config_kwargs:
            raise ValueError("give either config_kwargs or config, not both")
        self.config: ScenarioConfig = config
        self.metadata = {**self.metadata, "name": name}
        self.num_envs = B
        self.n_agents = N = config.n_agents
        self.max_cycles = config.max_cycles
        self.possible_agents = [f"robot_{i}" for i in range(N)]
        if scenario != "coverage" and eta_method != "exact":
            raise ValueError(
                f"eta_method applies to the coverage scenario only; {name} takes 'exact', "
                f"got {eta_method!r}"
            )
        kw = {"eta_method": eta_method} if scenario == "coverage" else {}
        try:
            self._core: BatchedCore = CORES[scenario](config, num_envs=B, **kw)
        except MemoryError as exc:
            raise ValueError(
                f"num_envs = {B} copies of {config.n_agents} robots do not fit in memory "
                f"({exc}); use fewer copies"
            ) from None
        self.eta_method = eta_method
        core = self._core
        self.single_observation_space = gymnasium.spaces.Box(
            core.obs_low, core.obs_high, dtype=np.float32
        )
        self.single_action_space = gymnasium.spaces.Box(-1.0, 1.0, (3,), np.float32)
        self.observation_space = gymnasium.spaces.Box(
            np.broadcast_to(core.obs_low, (B, N, core.obs_dim)),
            np.broadcast_to(core.obs_high, (B, N, core.obs_dim)),
            dtype=np.float32,
        )
        self.action_space = gymnasium.spaces.Box(-1.0, 1.0, (B, N, 3), np.float32)
        self._all = np.arange(B)
        self._needs_reset = True
        self._not_ready = "step() called before reset(); call reset() first"
        self._ever_reset = False  # poses, targets and state() exist after a reset()
        self.closed = False

    @classmethod
    def from_config(
        cls, config: ScenarioConfig, num_envs: int, eta_method: str = "exact"
    ) -> FovVectorEnv:
        """A vector env of an existing (validated) scenario config."""
        if not isinstance(config, ScenarioConfig):
            raise ValueError(f"config must be a ScenarioConfig, got {describe(config)}")
        name = f"fov_{config.scenario}_v0"
        return cls(num_envs, config.scenario, name, config=config, eta_method=eta_method)

    # ------------------------------------------------------------- episode
    max_cycles = MAX_CYCLES  # every copy's

    def reset(
        self, seed: int | Sequence[int] | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every copy: ``(obs (B, N, D) float32, {"metrics": dict of (B,) arrays})``.

        Args:
            seed: an int s seeds copy k with ``s + k``; a sequence of B ints (or None
                entries) seeds copies one by one; None continues every copy's generator.
            options: a dict or None (unused by these scenarios).
        """
        self._check_open()
        seeds = vector_seeds(seed, self.num_envs)
        if options is not None and not isinstance(options, Mapping):
            raise ValueError(f"options must be a dict or None, got {describe(options)}")
        self._needs_reset = True  # until every copy has reset
        self._not_ready = "the last reset() failed; call reset() again"
        self._ever_reset = True  # a failed reset leaves readable (partial) poses
        obs, metrics = self._core.reset(self._all, seeds)
        self._needs_reset = False
        return obs, {"metrics": metrics}

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """One step of every copy, with same-step autoreset (see the module docstring).

        Returns:
            ``(obs (B, N, D) float32, rewards (B, N) float32, terminations (B, N) bool,
            truncations (B, N) bool, infos)``.
        """
        self._check_open()
        if self._needs_reset:
            raise ValueError(self._not_ready)
        act = check_vector_actions(actions, self.num_envs, self.n_agents)
        core = self._core
        # every copy steps before the finished ones reset: a reset that raises leaves the
        # batch half-stepped, so nothing steps on until reset()
        self._needs_reset = True
        self._not_ready = (
            "the last step() failed (a finished copy could not reset); call reset() first"
        )
        obs, rew, term, metrics = core.step(act)
        trunc = (core.num_steps >= self.max_cycles) & ~term
        done = term | trunc
        final_obs = np.zeros_like(obs)
        infos: dict[str, Any] = {"metrics": metrics, "final_obs": final_obs, "_final_obs": done}
        if done.any():
            idx = np.flatnonzero(done)
            final_obs[idx] = obs[idx]
            new_obs, new_metrics = core.reset(idx, [None] * idx.size)
            obs[idx] = new_obs
            reset_metrics = {k: v.copy() for k, v in metrics.items()}
            for k, v in new_metrics.items():
                reset_metrics[k][idx] = v
            infos["reset_metrics"] = reset_metrics
        self._needs_reset = False
        N = self.n_agents
        terminations = np.repeat(term[:, None], N, axis=1)
        truncations = np.repeat(trunc[:, None], N, axis=1)
        return obs, rew.astype(np.float32), terminations, truncations, infos

    def _check_open(self) -> None:
        if self.closed:
            raise ValueError("the vector env is closed")

    # ------------------------------------------------------------- ground truth
    def _check_ever_reset(self, what: str) -> None:
        if not self._ever_reset:
            raise ValueError(f"{what} before reset(): the vector env has no poses yet")

    @property
    def poses(self) -> np.ndarray:
        """``(B, N, 3)`` ground-truth world poses ``[x m, y m, yaw rad]`` (read-only copy);
        ``ValueError`` before the first ``reset()``."""
        self._check_ever_reset("poses read")
        p = self._core.poses.copy()
        p.setflags(write=False)
        return p

    @property
    def targets(self) -> np.ndarray | None:
        """``(B, N, 2)`` crossing targets in the world frame (read-only copy), else None;
        ``ValueError`` before the first ``reset()``."""
        self._check_ever_reset("targets read")
        t = self._core.targets
        if t is None:
            return None
        t = t.copy()
        t.setflags(write=False)
        return t

    @property
    def num_steps(self) -> np.ndarray:
        """``(B,)`` steps taken in each copy's current episode (copy)."""
        return self._core.num_steps.copy()

    def state(self) -> np.ndarray:
        """``(B, S)`` float32 global states (each row as the ParallelEnv's ``state()``);
        ``ValueError`` before the first ``reset()``."""
        self._check_ever_reset("state() called")
        return self._core.state()

    # ------------------------------------------------------------ attributes
    # The shard API of SubprocVectorEnv, so code runs unchanged with workers = 1: this
    # env is one shard holding every copy.
    @property
    def shard_starts(self) -> tuple[int, ...]:
        """``(0, B)``: one shard holding every copy (see ``SubprocVectorEnv``)."""
        return (0, self.num_envs)

    def get_attr(self, name: str) -> list[Any]:
        """``[getattr(self, name)]``: one value per shard (here one)."""
        if not isinstance(name, str):
            raise ValueError(f"name must be a str, got {describe(name)}")
        return [getattr(self, name)]

    def set_attr(self, name: str, value: Any) -> None:
        """``setattr(self, name, value)`` (every shard's, here one)."""
        if not isinstance(name, str):
            raise ValueError(f"name must be a str, got {describe(name)}")
        setattr(self, name, value)

    def call(self, name: str, *args: Any, **kwargs: Any) -> list[Any]:
        """``[self.name(*args, **kwargs)]``: one result per shard (here one)."""
        if not isinstance(name, str):
            raise ValueError(f"name must be a str, got {describe(name)}")
        return [getattr(self, name)(*args, **kwargs)]

    def render(self) -> None:
        """The vector env draws nothing (``render_mode`` None): warns, as Gymnasium's
        envs do without a render mode, and returns None. Frames come from
        ``parallel_env(render_mode="rgb_array")`` or ``fov-marl render``."""
        warn_no_render()

    def close(self) -> None:
        """Mark the env closed (``closed`` True; nothing else to release): ``reset`` and
        ``step`` then raise ``ValueError``, as on a closed ``SubprocVectorEnv`` and
        Gymnasium's ``AsyncVectorEnv``. Closing twice is harmless."""
        self.closed = True

    def __repr__(self) -> str:
        return (
            f"FovVectorEnv({self.metadata['name']}, num_envs={self.num_envs}, "
            f"n_agents={self.n_agents})"
        )
