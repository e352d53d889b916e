"""Belief features: each robot's own neighbour tracker, appended to its observation.

A memoryless policy sees only what the camera reports *now*; a neighbour behind the
robot is all zeros. :class:`BeliefObservationWrapper` gives every robot i its own
particle-filter bank (:class:`fov_marl.estimation.TrackerBank`, one row per robot, each
row fed only with robot i's own observation and its own motion, each with its own
Generator) and appends, per neighbour, the Gaussian fit of the filter (Section V): the
95% confidence ellipse, the distance d_ij to it, and how long ago j was seen.

>>> from fov_marl.envs import fov_coverage_v0
>>> from fov_marl.wrappers.belief import BeliefObservationWrapper
>>> env = BeliefObservationWrapper(fov_coverage_v0.parallel_env(n_agents=6))
>>> obs, infos = env.reset(seed=0)          # obs["robot_0"].shape == (32 + 5 * 8,)

Observation (float32, length ``5 (N − 1) + 7 + 8 (N − 1)``)
----------------------------------------------------------
The wrapped env's observation unchanged (:mod:`fov_marl.spaces`: camera slots, own
cue), then 8 features per neighbour, neighbours in the same ascending-ID order as the
camera slots (block ``k`` is robot ``j = k if k < i else k + 1``). Entry
``o + 8k + f`` with ``o = 5 (N − 1) + 7``:

=====  ==================  ===========  ============================================  =====================
f      feature             unit/frame   meaning                                       bounds
=====  ==================  ===========  ============================================  =====================
0      ``mean_x``          m, Σ_i       ⁱp̂_j x: centre of the ellipse (Eq. 5)         ±D
1      ``mean_y``          m, Σ_i       ⁱp̂_j y                                        ±D
2      ``ellipse_a``       m            major semi-axis √(χ² λ₁) (Eq. 7)              [0, A]
3      ``ellipse_b``       m            minor semi-axis √(χ² λ₂)                      [0, A]
4      ``cos_2psi``        —            cos 2ψ, ψ the major axis' angle from the      [−1, 1]
                                        body x axis (2ψ: an ellipse is π-periodic)
5      ``sin_2psi``        —            sin 2ψ                                        [−1, 1]
6      ``distance``        m            d_ij, exact distance from robot i to the      [0, D]
                                        filled ellipse, 0 inside (replaces Eq. 8-10)
7      ``time_since_seen`` s            since j was last detected (since the reset    [0, ``time_cap_s``]
                                        if never), clipped at ``time_cap_s``
=====  ==================  ===========  ============================================  =====================

D = L√2 (the arena diagonal, L = ``arena_size_m``; particles are clamped to the arena,
so no relative position is longer) and A = (D / 2)·√χ², χ² = 5.991 at 95% (a
distribution on a set of diameter D has a variance ≤ D²/4 in every direction). Values
are clipped to these bounds, which only float32 round-off can cross with the default
tracker (``clamp_to_arena=True``).

What the trackers use
---------------------
* Robot i's row sees only ``obs[robot_i]`` (its camera detections with IDs and its own
  cue) and its own motion; never another robot's observation, ``env.state()`` or
  ``env.poses`` — with one documented exception:
* ``init="known"`` (default): at ``reset`` every robot's filters start around the
  neighbours' start poses ``env.unwrapped.poses`` — the paper's assumption ("We assumed
  every robot knows the starting position of each one of its neighbors", Section
  VII-B, Eq. 1). ``init="uniform"``: uniform over the arena, no ground truth at all.
* Own motion (Eq. 2's re-expression in the new Σ_i) comes by default from the robot's
  own pose in consecutive observations (``ego_motion="pose"``), i.e. the motion
  actually *applied*. Behind :class:`~fov_marl.wrappers.SafetyFilterWrapper` (this
  wrapper goes outside it, so the filter keeps its own observation layout) the
  action this wrapper receives is the policy's command, not what the filter applied;
  the pose-based ego motion is exact in both cases. ``tracker_params={"ego_motion":
  "action"}`` uses the received action instead (as the tracker's default does).
* Neighbour motion model: the tracker's (Eq. 20 coverage, Eq. 22 crossing).

Seeding: ``reset(seed=s)`` seeds ``default_rng(s)``, from which each episode's tracker
seed is drawn (:attr:`BeliefFeaturizer.tracker_seed`); later unseeded resets continue
that generator, so a run is reproducible from its first seed. The env's own generator is
not touched. The features of a policy evaluated without this wrapper
(:class:`BeliefFeaturizer` inside :class:`fov_marl.training.LearnedPolicy`) are
identical for the same seed.

Cost: about 0.4 ms per robot-step with the default P_T = 2000 (the tracker's speed);
``tracker_params={"n_particles_total": 500}`` halves it for faster training.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import gymnasium
import numpy as np
from pettingzoo.utils.wrappers import BaseParallelWrapper

from fov_marl.envs.base import FORWARDED_MAX_CYCLES
from fov_marl.estimation import TrackerBank
from fov_marl.estimation.params import TrackerParams
from fov_marl.estimation.tracker import check_particle_budget
from fov_marl.geometry import chi2_2dof
from fov_marl.validation import (
    ConfigError,
    check_keys,
    check_real,
    check_seed,
    describe,
    fov_parallel_base,
)

__all__ = [
    "FEATURE_NAMES",
    "FEATURES_PER_NEIGHBOUR",
    "BeliefFeaturizer",
    "BeliefObservationWrapper",
]

FEATURE_NAMES = (
    "mean_x",
    "mean_y",
    "ellipse_a",
    "ellipse_b",
    "cos_2psi",
    "sin_2psi",
    "distance",
    "time_since_seen",
)
FEATURES_PER_NEIGHBOUR = len(FEATURE_NAMES)
_INITS = ("known", "uniform")
_DEFAULT_TRACKER = {"ego_motion": "pose"}


class BeliefFeaturizer:
    """The team's trackers and their features, without being an env wrapper.

    Used by :class:`BeliefObservationWrapper` and by a trained policy evaluated on the
    plain env; both give the same numbers for the same seed.

    Args:
        env: the fov env or a wrapper of it (``env.unwrapped.config`` sizes the trackers;
            ``env.unwrapped.poses`` is read at :meth:`reset` when ``init="known"``).
        init: ``"known"`` (start poses, the paper's assumption) or ``"uniform"``.
        tracker_params: :class:`~fov_marl.estimation.params.TrackerParams` fields;
            default ``{"ego_motion": "pose"}`` (see the module docstring).
        time_cap_s: clip of ``time_since_seen``, in (0, inf) s.

    Raises:
        ValueError: bad ``init``, ``time_cap_s`` or tracker parameters (also those the
            team rules out: ``n_particles_total < N − 1``), here, before any reset.
    """

    def __init__(
        self,
        env: Any,
        init: str = "known",
        tracker_params: Mapping[str, Any] | None = None,
        time_cap_s: float = 60.0,
    ) -> None:
        if init not in _INITS:
            raise ValueError(f"init must be one of {_INITS}, got {init!r}")
        cap = check_real("time_cap_s", time_cap_s, 0.0, 1e9, lo_open=True)
        if tracker_params is not None and not isinstance(tracker_params, Mapping):
            raise ConfigError(
                "tracker_params must be a dict of TrackerParams fields or None, "
                f"got {describe(tracker_params)}"
            )
        params = {**_DEFAULT_TRACKER, **dict(tracker_params or {})}
        if "init_mode" in params:
            raise ValueError("set the initialisation with init=, not tracker_params['init_mode']")
        check_keys("tracker_params fields", params, TrackerParams.__dataclass_fields__)
        self.env = env
        self.config = fov_parallel_base("BeliefObservationWrapper", env).config
        self.init = init
        self.time_cap_s = cap
        self.tracker_params = TrackerParams(**params, init_mode=init)
        self._param_overrides = {**params, "init_mode": init}
        self.possible_agents = list(env.possible_agents)
        n = self.config.n_agents
        if len(self.possible_agents) != n:
            raise ValueError(f"env has {len(self.possible_agents)} agents, its config {n}")
        # the bank's own check against the team now, not at the first reset()
        check_particle_budget(self.tracker_params, n)
        self.n_neighbours = n - 1
        self.size = FEATURES_PER_NEIGHBOUR * self.n_neighbours
        d = self.config.arena_size_m * math.sqrt(2.0)
        a = 0.5 * d * math.sqrt(chi2_2dof(self.tracker_params.confidence))
        lo1 = np.array([-d, -d, 0.0, 0.0, -1.0, -1.0, 0.0, 0.0])
        hi1 = np.array([d, d, a, a, 1.0, 1.0, d, cap])
        self.low = np.tile(lo1, self.n_neighbours).astype(np.float32)
        self.high = np.tile(hi1, self.n_neighbours).astype(np.float32)
        self.bank: TrackerBank | None = None
        self.tracker_seed: int | None = None
        self._seed_rng: np.random.Generator | None = None

    # ------------------------------------------------------------------ episode
    def reset(self, obs: Mapping[str, np.ndarray], seed: int | None = None) -> np.ndarray:
        """New trackers for a new episode from the first observations; returns features.

        Args:
            obs: ``agent -> observation`` of every robot (the env's layout).
            seed: seeds the generator the tracker seeds are drawn from (see module).
        """
        seed = check_seed("seed", seed)
        if seed is not None or self._seed_rng is None:
            self._seed_rng = np.random.default_rng(seed)
        self.tracker_seed = int(self._seed_rng.integers(0, 2**63 - 1))
        self.bank = TrackerBank.for_env(
            self.env.unwrapped, seed=self.tracker_seed, **self._param_overrides
        )
        poses = np.asarray(self.env.unwrapped.poses) if self.init == "known" else None
        self.bank.reset(self._obs(obs), initial_poses_world=poses)
        return self.features()

    def step(self, actions: Mapping[str, np.ndarray], obs: Mapping[str, np.ndarray]) -> np.ndarray:
        """One tracker step per robot with its own action and its new observation."""
        if self.bank is None:
            raise ValueError("BeliefFeaturizer.step() called before reset()")
        if not isinstance(actions, Mapping):
            raise ValueError(
                f"actions must be a dict agent -> (3,) action, got {describe(actions)}"
            )
        # the bank checks each robot's action (present, real, finite, (3,)), naming it
        self.bank.step(actions, self._obs(obs))
        return self.features()

    def _obs(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        missing = [a for a in self.possible_agents if a not in obs]
        if missing:
            raise ValueError(f"observations missing for agent(s) {missing}")
        return np.stack([np.asarray(obs[a], dtype=np.float64) for a in self.possible_agents])

    # ------------------------------------------------------------------ outputs
    def features(self) -> np.ndarray:
        """``(N, 8 (N − 1))`` float32 features of every robot (module docstring table)."""
        if self.bank is None:
            raise ValueError("BeliefFeaturizer.features() called before reset()")
        e = self.bank.estimate()
        n, m = self.config.n_agents, self.n_neighbours
        f = np.empty((n, m, FEATURES_PER_NEIGHBOUR))
        f[..., 0:2] = e.mean_body
        f[..., 2] = e.ellipse_a
        f[..., 3] = e.ellipse_b
        f[..., 4] = np.cos(2.0 * e.ellipse_psi)
        f[..., 5] = np.sin(2.0 * e.ellipse_psi)
        f[..., 6] = e.ellipse_distance
        f[..., 7] = e.time_since_seen_s
        out = f.reshape(n, m * FEATURES_PER_NEIGHBOUR).astype(np.float32)
        np.clip(out, self.low, self.high, out=out)
        return out

    def augment(self, obs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """``agent -> concat(obs[agent], features of agent)`` for the agents in ``obs``."""
        feats = self.features()
        idx = {a: i for i, a in enumerate(self.possible_agents)}
        return {
            a: np.concatenate([np.asarray(o, dtype=np.float32), feats[idx[a]]])
            for a, o in obs.items()
        }


class BeliefObservationWrapper(BaseParallelWrapper):
    """PettingZoo ParallelEnv wrapper appending each robot's tracker features (module doc).

    Args:
        env: a fov env (``fov_coverage_v0``/``fov_crossing_v0``) or a wrapper of it whose
            observations keep the env's layout (e.g. the safety filter).
        init: ``"known"`` (default, the paper's VII-B assumption) or ``"uniform"``.
        tracker_params: :class:`~fov_marl.estimation.params.TrackerParams` overrides.
        time_cap_s: clip of ``time_since_seen`` (s).

    Attributes:
        featurizer: the :class:`BeliefFeaturizer` (its ``bank`` holds the trackers).
    """

    def __init__(
        self,
        env: Any,
        init: str = "known",
        tracker_params: Mapping[str, Any] | None = None,
        time_cap_s: float = 60.0,
    ) -> None:
        super().__init__(env)
        self.featurizer = BeliefFeaturizer(env, init, tracker_params, time_cap_s)
        base = env.observation_space(env.possible_agents[0])
        if not isinstance(base, gymnasium.spaces.Box) or base.shape is None:
            raise ValueError(f"the wrapped env must have Box observations, got {base!r}")
        space = gymnasium.spaces.Box(
            np.concatenate([base.low, self.featurizer.low]).astype(np.float32),
            np.concatenate([base.high, self.featurizer.high]).astype(np.float32),
            dtype=np.float32,
        )
        self._obs_spaces = {a: space for a in env.possible_agents}
        self.base_obs_size = int(base.shape[0])

    max_cycles = FORWARDED_MAX_CYCLES

    @property
    def observation_spaces(self) -> dict[str, gymnasium.spaces.Box]:
        """``{agent: observation_space(agent)}``: the belief-augmented spaces."""
        return dict(self._obs_spaces)

    def observation_space(self, agent: str) -> gymnasium.spaces.Box:
        if agent not in self._obs_spaces:
            raise ValueError(f"unknown agent {agent!r}; agents are {list(self._obs_spaces)}")
        return self._obs_spaces[agent]

    def reset(self, seed: int | None = None, options: dict | None = None):
        obs, infos = self.env.reset(seed=seed, options=options)
        self.featurizer.reset(obs, seed=seed)
        return self.featurizer.augment(obs), infos

    def step(self, actions: dict[str, Any]):
        if self.featurizer.bank is None:  # before the env moves, as the safety filter does
            raise ValueError("BeliefObservationWrapper.step() called before reset()")
        obs, rewards, terms, truncs, infos = self.env.step(actions)
        if obs:
            self.featurizer.step(actions, obs)
            obs = self.featurizer.augment(obs)
        return obs, rewards, terms, truncs, infos
