"""Parameter-sharing adapters: env copies -> one SB3 ``VecEnv``, one slot per robot.

Two adapters with one slot layout and one info contract: :class:`VectorEnvVecEnv`
over the batched vector env (``fov_*_v0.vector_env``: all copies stepped in one call,
no per-copy objects; what :func:`fov_marl.training.trainer.make_training_vec_env`
uses for raw envs) and :class:`ParallelEnvVecEnv` over per-copy PettingZoo
``ParallelEnv`` objects (kept for wrapped envs: the safety filter and the belief
wrapper need a ParallelEnv per copy). Given the same seed both produce the same
observations, rewards, dones and infos slot by slot (tested).

Every agent of every env copy is one slot of the VecEnv, so one SB3 policy is shared
by all robots (decentralised execution: each slot sees only its own agent's
observation). With ``n`` copies of an env of ``N`` agents, ``num_envs = n * N`` and
slot ``s`` holds agent ``possible_agents[s % N]`` of copy ``s // N``:

=================  ===========================================================
slot ``s``         ``copy = s // N``, ``agent = possible_agents[s % N]``
observation        ``(n * N, obs_dim)`` float32, the agent's own observation
action             ``(n * N, act_dim)``; passed unchanged to the env, which clips
                   it as its docstring says (fov envs: to ``[-1, 1]``, then the
                   planar speed to ``v_max``)
reward             ``(n * N,)`` float32, the agent's own reward
done               ``terminated or truncated`` of the agent
=================  ===========================================================

Why not SuperSuit (design.md, "Ecosystem traps"): its copies share one RNG unless
seeded by hand, ``PPO(seed=...)`` fails on ``ConcatVecEnv`` without ``seed()``, and
time limits are not marked ``TimeLimit.truncated``. This adapter fixes all three:

* ``seed(seed)``: copy ``k`` is reset with ``seed + k`` at the next :meth:`reset`
  (``PPO(seed=...)`` calls it), so copies differ and two runs with the same seed are
  identical. Later episodes continue each copy's own generator (auto-reset passes
  no seed), so the whole run is reproducible.
* When a copy's episode ends (all its agents terminated or truncated *together*;
  an env whose agents leave one at a time raises ``ValueError``), the copy is reset
  at once and every slot of that copy reports ``done=True`` with
  ``info["terminal_observation"]`` (the last observation, float32) and
  ``info["TimeLimit.truncated"] = truncated and not terminated`` so SB3 bootstraps
  the value of time-limited (continuing) episodes. The reset's infos are in
  ``reset_infos[slot]``.
* Infos: ``infos[slot]`` is a copy of the env's ``infos[agent]`` (an
  :class:`~fov_marl.infos.AgentInfo`; for the fov envs: flat ``"metrics/<name>"``
  entries, read with :func:`fov_marl.infos.metrics_of`, and behind the safety filter
  ``"safety/*"``) plus ``"agent"`` (name), ``"agent_index"`` and ``"env_index"`` (the
  copy). At ``done`` the metrics are those of the episode's last step, so a callback
  logs episode-level values (final η, ``collisions_total``) from ``infos`` where
  ``dones`` is True; log them once per copy (``agent_index == 0``) because every
  agent of a copy carries the same team metrics.

Attribute access (``get_attr``, ``set_attr``, ``env_method``, ``env_is_wrapped``) take
*slot* indices like every SB3 VecEnv and return one entry per slot; the slots of one
copy share an env, so ``set_attr``/``env_method`` act once per distinct copy and
``env_method`` repeats that copy's result for each of its slots. ``set_attr`` sets the
attribute on the outermost env of the wrapper chain that defines it (so
``set_attr("max_cycles", 50)`` reaches the base env under PettingZoo wrappers).

All agents of all copies must share one observation space and one action space
(parameter sharing); otherwise ``ValueError``. Only ``Box`` observations are
supported; they are presented as float32.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import (
    VecEnv,
    VecEnvIndices,
    VecEnvObs,
    VecEnvStepReturn,
)

from fov_marl.infos import METRICS_PREFIX, AgentInfo, reset_safety_infos, status_code
from fov_marl.validation import check_seed

__all__ = [
    "ParallelEnvVecEnv",
    "VectorEnvVecEnv",
    "make_parallel_vec_env",
    "make_vector_vec_env",
    "wrapper_chain",
]

EnvFactory = Callable[[], Any]


def wrapper_chain(env: Any) -> list[Any]:
    """The env and every env it wraps, outermost first (follows ``.env``)."""
    chain = [env]
    seen = {id(env)}
    while True:
        inner = getattr(chain[-1], "__dict__", {}).get("env")
        if inner is None or id(inner) in seen:
            return chain
        chain.append(inner)
        seen.add(id(inner))


def _float32_box(space: gym.Space, what: str) -> gym.spaces.Box:
    if not isinstance(space, gym.spaces.Box):
        raise ValueError(f"{what} must be a gymnasium Box, got {space!r}")
    if space.dtype == np.float32:
        return space
    return gym.spaces.Box(
        space.low.astype(np.float32), space.high.astype(np.float32), dtype=np.float32
    )


def _same_box(a: gym.spaces.Box, b: gym.spaces.Box) -> bool:
    return (
        a.shape == b.shape
        and a.dtype == b.dtype
        and np.array_equal(a.low, b.low)
        and np.array_equal(a.high, b.high)
    )


class ParallelEnvVecEnv(VecEnv):
    """SB3 ``VecEnv`` over copies of a PettingZoo ``ParallelEnv``, one slot per agent.

    See the module docstring for the slot layout, seeding, truncation and info
    contract.

    Args:
        env_fns: one factory per copy, each returning a *new* ParallelEnv (or wrapper).

    Raises:
        ValueError: no factory, two factories returning the same instance, copies with
            different agents, or agents whose spaces differ.
    """

    def __init__(self, env_fns: Sequence[EnvFactory]) -> None:
        if len(env_fns) == 0:
            raise ValueError("env_fns must hold at least one env factory, got none")
        self.envs = [fn() for fn in env_fns]
        if len({id(e) for e in self.envs}) != len(self.envs):
            raise ValueError(
                "env_fns returned the same env instance twice; each factory must build a new env"
            )
        first = self.envs[0]
        self.possible_agents: list[str] = list(first.possible_agents)
        self.n_agents = len(self.possible_agents)
        self.n_copies = len(self.envs)
        if self.n_agents == 0:
            raise ValueError("the env has no possible_agents")
        obs_space = _float32_box(
            first.observation_space(self.possible_agents[0]), "observation space"
        )
        act_space = first.action_space(self.possible_agents[0])
        if not isinstance(act_space, gym.spaces.Box):
            raise ValueError(f"action space must be a gymnasium Box, got {act_space!r}")
        for k, env in enumerate(self.envs):
            if list(env.possible_agents) != self.possible_agents:
                raise ValueError(
                    f"env copy {k} has agents {list(env.possible_agents)}, "
                    f"copy 0 has {self.possible_agents}; all copies must have the same agents"
                )
            for a in self.possible_agents:
                o = _float32_box(env.observation_space(a), f"observation space of {a}")
                if not _same_box(o, obs_space):
                    raise ValueError(
                        f"observation space of {a} in copy {k} differs from that of "
                        f"{self.possible_agents[0]}; parameter sharing needs one space"
                    )
                if not _same_box(env.action_space(a), act_space):
                    raise ValueError(
                        f"action space of {a} in copy {k} differs from that of "
                        f"{self.possible_agents[0]}; parameter sharing needs one space"
                    )
        self._obs_shape = obs_space.shape
        self._act_shape = act_space.shape
        self._copy_seeds: list[int | None] = [None] * self.n_copies
        self._copy_options: list[dict[str, Any]] = [{} for _ in range(self.n_copies)]
        super().__init__(self.n_copies * self.n_agents, obs_space, act_space)
        self._obs = np.zeros((self.num_envs, *self._obs_shape), dtype=np.float32)
        self._actions: np.ndarray | None = None

    # ------------------------------------------------------------- slot maps
    def slot(self, copy: int, agent: str) -> int:
        """Slot index of ``agent`` in env copy ``copy``."""
        return copy * self.n_agents + self.possible_agents.index(agent)

    def slot_to_copy_agent(self, slot: int) -> tuple[int, str]:
        """``(copy, agent)`` held by ``slot``."""
        if not 0 <= slot < self.num_envs:
            raise ValueError(f"slot must be in [0, {self.num_envs - 1}], got {slot}")
        return slot // self.n_agents, self.possible_agents[slot % self.n_agents]

    # -------------------------------------------------------------- seeding
    def seed(self, seed: int | None = None) -> list[int | None]:
        """Seed copy ``k`` with ``seed + k`` at the next :meth:`reset`.

        ``None`` draws a fresh base seed from OS entropy.
        Returns the seed of each *slot* (the seed of its copy).
        """
        if seed is None:
            seed = int(np.random.default_rng().integers(0, np.iinfo(np.uint32).max))
        seed = check_seed("seed", seed)  # 2.5 or "x": a ValueError naming seed
        self._copy_seeds = [int(seed) + k for k in range(self.n_copies)]
        return [self._copy_seeds[s // self.n_agents] for s in range(self.num_envs)]

    def set_options(self, options: list[dict] | dict | None = None) -> None:
        """Reset options for the next :meth:`reset`: one dict for all copies or one per copy."""
        if options is None:
            options = {}
        if isinstance(options, dict):
            self._copy_options = [dict(options) for _ in range(self.n_copies)]
        else:
            options = list(options)
            if len(options) != self.n_copies:
                raise ValueError(
                    f"options must be one dict or a list of {self.n_copies} dicts (one per "
                    f"copy), got a list of {len(options)}"
                )
            self._copy_options = [dict(o) for o in options]

    def _reset_seeds(self) -> None:
        self._copy_seeds = [None] * getattr(self, "n_copies", 0)

    def _reset_options(self) -> None:
        self._copy_options = [{} for _ in range(getattr(self, "n_copies", 0))]

    # ------------------------------------------------------------ reset/step
    def _reset_copy(self, k: int, seed: int | None, options: dict | None) -> None:
        env = self.envs[k]
        obs, infos = env.reset(seed=seed, options=options or None)
        if list(env.agents) != self.possible_agents:
            raise ValueError(
                f"after reset, env copy {k} has agents {list(env.agents)}; the adapter needs "
                f"all of {self.possible_agents} alive at the start of an episode"
            )
        base = k * self.n_agents
        for i, a in enumerate(self.possible_agents):
            self._obs[base + i] = obs[a]
            info = AgentInfo(infos.get(a, {}))
            info.update(agent=a, agent_index=i, env_index=k)
            self.reset_infos[base + i] = info

    def reset(self) -> VecEnvObs:
        for k in range(self.n_copies):
            self._reset_copy(k, self._copy_seeds[k], self._copy_options[k])
        self._reset_seeds()
        self._reset_options()
        return self._obs.copy()

    def step_async(self, actions: np.ndarray) -> None:
        actions = np.asarray(actions)
        if actions.shape != (self.num_envs, *self._act_shape):
            raise ValueError(
                f"actions must have shape (num_envs, *action_shape) = "
                f"{(self.num_envs, *self._act_shape)}, got {actions.shape}"
            )
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise ValueError("step_wait() called without step_async(actions)")
        actions, self._actions = self._actions, None
        n = self.n_agents
        rewards = np.zeros(self.num_envs, dtype=np.float32)
        dones = np.zeros(self.num_envs, dtype=bool)
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for k, env in enumerate(self.envs):
            base = k * n
            act = {a: actions[base + i] for i, a in enumerate(self.possible_agents)}
            obs, rew, term, trunc, env_infos = env.step(act)
            ended = [bool(term[a] or trunc[a]) for a in self.possible_agents]
            if any(ended) and not all(ended):
                raise ValueError(
                    f"agents of env copy {k} ended at different times "
                    f"({[a for a, e in zip(self.possible_agents, ended, strict=True) if e]}); "
                    "the parameter-sharing adapter needs all agents to end together"
                )
            done = ended[0]
            for i, a in enumerate(self.possible_agents):
                s = base + i
                o = np.asarray(obs[a], dtype=np.float32)
                rewards[s] = rew[a]
                info = AgentInfo(
                    (key, (dict(v) if isinstance(v, dict) else v))
                    for key, v in env_infos.get(a, {}).items()
                )
                info.update(agent=a, agent_index=i, env_index=k)
                if done:
                    dones[s] = True
                    info["terminal_observation"] = o.copy()
                    info["TimeLimit.truncated"] = bool(trunc[a]) and not bool(term[a])
                else:
                    info["TimeLimit.truncated"] = False
                    self._obs[s] = o
                infos[s] = info
            if done:
                if env.agents:
                    raise ValueError(
                        f"env copy {k} reported the end of the episode but still has agents "
                        f"{list(env.agents)}"
                    )
                self._reset_copy(k, None, None)
        return self._obs.copy(), rewards, dones, infos

    def close(self) -> None:
        for env in self.envs:
            env.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        """One frame per env *copy* (not per slot)."""
        if self.render_mode != "rgb_array":
            warnings.warn(
                f"The render mode is {self.render_mode}, but get_images needs 'rgb_array'.",
                stacklevel=2,
            )
            return [None for _ in self.envs]
        return [env.render() for env in self.envs]

    # --------------------------------------------------- attribute access
    def _slots(self, indices: VecEnvIndices) -> list[int]:
        slots = list(self._get_indices(indices))
        for s in slots:
            if not 0 <= int(s) < self.num_envs:
                raise ValueError(f"slot index must be in [0, {self.num_envs - 1}], got {s}")
        return [int(s) for s in slots]

    def _copies(self, slots: Iterable[int]) -> list[int]:
        return list(dict.fromkeys(s // self.n_agents for s in slots))

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """``getattr(copy, attr_name)`` for each slot (PettingZoo wrappers forward)."""
        return [getattr(self.envs[s // self.n_agents], attr_name) for s in self._slots(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set ``attr_name`` once per distinct copy of ``indices`` (see module docstring)."""
        for k in self._copies(self._slots(indices)):
            chain = wrapper_chain(self.envs[k])
            target = next(
                (
                    e
                    for e in chain
                    if attr_name in getattr(e, "__dict__", {}) or hasattr(type(e), attr_name)
                ),
                chain[0],
            )
            setattr(target, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs
    ) -> list[Any]:
        """Call the method once per distinct copy; each slot gets its copy's result."""
        slots = self._slots(indices)
        results = {
            k: getattr(self.envs[k], method_name)(*method_args, **method_kwargs)
            for k in self._copies(slots)
        }
        return [results[s // self.n_agents] for s in slots]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        """Whether the copy of each slot has a ``wrapper_class`` in its wrapper chain."""
        return [
            any(isinstance(e, wrapper_class) for e in wrapper_chain(self.envs[s // self.n_agents]))
            for s in self._slots(indices)
        ]


def make_parallel_vec_env(
    env_fn: EnvFactory, n_envs: int = 1, seed: int | None = None
) -> ParallelEnvVecEnv:
    """``n_envs`` copies of ``env_fn()`` as one :class:`ParallelEnvVecEnv`.

    Args:
        env_fn: returns a new ParallelEnv on each call.
        n_envs: number of env copies, >= 1 (slots = ``n_envs * n_agents``).
        seed: if given, :meth:`ParallelEnvVecEnv.seed` is called with it.
    """
    if isinstance(n_envs, bool) or not isinstance(n_envs, int | np.integer) or n_envs < 1:
        raise ValueError(f"n_envs must be an integer in [1, inf), got {n_envs!r}")
    venv = ParallelEnvVecEnv([env_fn for _ in range(int(n_envs))])
    if seed is not None:
        venv.seed(seed)
    return venv


class VectorEnvVecEnv(VecEnv):
    """SB3 ``VecEnv`` over a batched vector env (``fov_*_v0.vector_env``), one slot per robot.

    The slot layout, seeding, truncation and info contract are those of
    :class:`ParallelEnvVecEnv` (module docstring): slot ``s`` holds robot ``s % N`` of
    copy ``s // N``; ``seed(s)`` makes copy k start from ``s + k`` at the next
    :meth:`reset`; a finished copy is reset in the same step (the vector env's
    same-step autoreset, continuing its generator) and its slots report ``done`` with
    ``terminal_observation`` and ``TimeLimit.truncated``; ``infos[slot]`` holds the flat
    ``"metrics/<name>"`` entries (the copy's metrics of that step, Python scalars; an
    :class:`~fov_marl.infos.AgentInfo`, as the per-copy adapter gives), ``"agent"``,
    ``"agent_index"`` and ``"env_index"``; reset metrics are in ``reset_infos``.

    Attribute access acts on the one vector env: ``get_attr`` returns its attribute
    once per slot, ``set_attr`` sets it (e.g. ``max_cycles``), ``env_method`` calls it
    once and repeats the result per slot. Over a :class:`~fov_marl.envs.SubprocVectorEnv`
    an attribute or method the parent does not hold (e.g. ``eta_method`` of the
    shards' envs) is reached in the shards: each slot gets its shard's value or result,
    and ``set_attr`` sets it in every shard; ``env_is_wrapped(cls)`` is True where the vector
    env stands for a per-copy wrapper ``cls`` (its ``per_copy_wrappers``: the
    :class:`~fov_marl.wrappers.VectorSafetyFilterWrapper`, in one process or in the shards
    of a :class:`~fov_marl.envs.SubprocVectorEnv`, for ``SafetyFilterWrapper``), as on the
    per-copy adapter. Behind the filter, ``reset_infos`` hold the neutral ``"safety/*"``
    entries of a reset (also after an automatic reset), as the per-copy filter gives.

    Args:
        venv: a :class:`~fov_marl.envs.vector.FovVectorEnv` (or an object with its API).
    """

    def __init__(self, venv: Any) -> None:
        for attr in ("num_envs", "n_agents", "possible_agents", "single_observation_space"):
            if not hasattr(venv, attr):
                raise ValueError(
                    f"venv must be a vector env (fov_*_v0.vector_env) with {attr!r}, "
                    f"got {type(venv).__name__}"
                )
        self.venv = venv
        self.n_copies = int(venv.num_envs)
        self.n_agents = int(venv.n_agents)
        self.possible_agents: list[str] = list(venv.possible_agents)
        obs_space = _float32_box(venv.single_observation_space, "observation space")
        act_space = venv.single_action_space
        if not isinstance(act_space, gym.spaces.Box):
            raise ValueError(f"action space must be a gymnasium Box, got {act_space!r}")
        self._obs_shape = obs_space.shape
        self._act_shape = act_space.shape
        self._base_seed: int | None = None
        self._slot_copy = np.repeat(np.arange(self.n_copies), self.n_agents)
        self._slot_agent = np.tile(np.arange(self.n_agents), self.n_copies)
        super().__init__(self.n_copies * self.n_agents, obs_space, act_space)
        self._actions: np.ndarray | None = None

    # ------------------------------------------------------------- slot maps
    def slot(self, copy: int, agent: str) -> int:
        """Slot index of ``agent`` in env copy ``copy``."""
        return copy * self.n_agents + self.possible_agents.index(agent)

    def slot_to_copy_agent(self, slot: int) -> tuple[int, str]:
        """``(copy, agent)`` held by ``slot``."""
        if not 0 <= slot < self.num_envs:
            raise ValueError(f"slot must be in [0, {self.num_envs - 1}], got {slot}")
        return slot // self.n_agents, self.possible_agents[slot % self.n_agents]

    # -------------------------------------------------------------- seeding
    def seed(self, seed: int | None = None) -> list[int | None]:
        """Seed copy ``k`` with ``seed + k`` at the next :meth:`reset` (None: OS entropy).

        Returns the seed of each *slot* (the seed of its copy).
        """
        if seed is None:
            seed = int(np.random.default_rng().integers(0, np.iinfo(np.uint32).max))
        self._base_seed = check_seed("seed", seed)  # 2.5 or "x": a ValueError naming seed
        return [self._base_seed + int(k) for k in self._slot_copy]

    # ------------------------------------------------------------ reset/step
    def _infos(self, metrics: dict[str, np.ndarray]) -> list[dict[str, Any]]:
        """One info dict per slot: the copy's metrics (Python scalars) and slot ids."""
        cols = {k: v.tolist() for k, v in metrics.items()}
        per_copy = [{k: col[c] for k, col in cols.items()} for c in range(self.n_copies)]
        agents = self.possible_agents
        flat = [{METRICS_PREFIX + k: v for k, v in m.items()} for m in per_copy]
        out = []
        for c in range(self.n_copies):
            for i in range(self.n_agents):
                info = AgentInfo(flat[c])
                info.update(agent=agents[i], agent_index=i, env_index=c)
                out.append(info)
        return out

    def _add_safety(self, infos: list[dict[str, Any]], safety: dict[str, np.ndarray]) -> None:
        """Write the ``safety/*`` entries of every slot from ``(B, N, ...)`` arrays."""
        flat = {
            k: np.asarray(v).reshape(self.num_envs, *np.shape(v)[2:]) for k, v in safety.items()
        }
        codes = [status_code(str(x)) for x in flat["status"].tolist()]
        for s, info in enumerate(infos):
            info["safety/nominal_action"] = flat["nominal_action"][s].astype(np.float32)
            info["safety/applied_action"] = flat["applied_action"][s].astype(np.float32)
            info["safety/intervened"] = bool(flat["intervened"][s])
            info["safety/fallback"] = bool(flat["fallback"][s])
            info["safety/status_code"] = codes[s]
            info["safety/cause_bits"] = int(flat["cause_bits"][s])

    def reset(self) -> VecEnvObs:
        seed, self._base_seed = self._base_seed, None
        obs, infos = self.venv.reset(seed=seed)
        self.reset_infos = self._infos(infos["metrics"])
        if "safety" in infos:  # a vector safety filter: the neutral report of a reset
            self._add_safety(self.reset_infos, infos["safety"])
        self._reset_seeds()
        self._reset_options()
        return obs.reshape(self.num_envs, *self._obs_shape).astype(np.float32, copy=False)

    def step_async(self, actions: np.ndarray) -> None:
        actions = np.asarray(actions)
        if actions.shape != (self.num_envs, *self._act_shape):
            raise ValueError(
                f"actions must have shape (num_envs, *action_shape) = "
                f"{(self.num_envs, *self._act_shape)}, got {actions.shape}"
            )
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise ValueError("step_wait() called without step_async(actions)")
        actions, self._actions = self._actions, None
        B, N = self.n_copies, self.n_agents
        obs, rew, term, trunc, vinfos = self.venv.step(actions.reshape(B, N, *self._act_shape))
        done_copy = vinfos["_final_obs"]
        dones = np.repeat(done_copy, N)
        infos = self._infos(vinfos["metrics"])
        if "safety" in vinfos:  # a vector safety filter: its per-robot report, flat
            self._add_safety(infos, vinfos["safety"])
        time_limit = (trunc & ~term).reshape(-1)
        if done_copy.any():
            final = vinfos["final_obs"].reshape(self.num_envs, *self._obs_shape)
            reset_infos = self._infos(vinfos["reset_metrics"])
            if "safety" in vinfos:  # what the per-copy filter reports at reset()
                reset_safety_infos(dict(enumerate(reset_infos)))
            for s in np.flatnonzero(dones).tolist():
                infos[s]["terminal_observation"] = final[s].astype(np.float32, copy=True)
                infos[s]["TimeLimit.truncated"] = bool(time_limit[s])
                self.reset_infos[s] = reset_infos[s]
        for s in np.flatnonzero(~dones).tolist():
            infos[s]["TimeLimit.truncated"] = False
        obs = obs.reshape(self.num_envs, *self._obs_shape).astype(np.float32, copy=False)
        return obs, rew.reshape(-1).astype(np.float32, copy=False), dones, infos

    def close(self) -> None:
        self.venv.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        """The vector env does not render: one None per copy (with a warning)."""
        warnings.warn("the vector env does not render; get_images returns None", stacklevel=2)
        return [None] * self.n_copies

    # --------------------------------------------------- attribute access
    def _slots(self, indices: VecEnvIndices) -> list[int]:
        slots = [int(s) for s in self._get_indices(indices)]
        for s in slots:
            if not 0 <= s < self.num_envs:
                raise ValueError(f"slot index must be in [0, {self.num_envs - 1}], got {s}")
        return slots

    def _in_shards(self, name: str) -> bool:
        """True when ``name`` lives only in the shards of a ``SubprocVectorEnv``."""
        return hasattr(self.venv, "shard_starts") and not hasattr(self.venv, name)

    def _per_slot(self, per_shard: list[Any], slots: list[int]) -> list[Any]:
        """Each slot's value from one value per shard."""
        starts = np.asarray(self.venv.shard_starts)
        copies = np.asarray(slots, dtype=np.int64) // self.n_agents
        shard = np.searchsorted(starts, copies, side="right") - 1
        return [per_shard[w] for w in shard.tolist()]

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The vector env's attribute, once per slot of ``indices`` (the slot's shard's
        over a ``SubprocVectorEnv`` where the parent does not hold it)."""
        slots = self._slots(indices)
        if self._in_shards(attr_name):
            return self._per_slot(self.venv.get_attr(attr_name), slots)
        value = getattr(self.venv, attr_name)
        return [value for _ in slots]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set the attribute on the vector env (shared by all copies, whatever ``indices``;
        in every shard over a ``SubprocVectorEnv`` where the parent does not hold it)."""
        self._slots(indices)
        if self._in_shards(attr_name):
            self.venv.set_attr(attr_name, value)
        else:
            setattr(self.venv, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs
    ) -> list[Any]:
        """Call the vector env's method once; each slot of ``indices`` gets the result
        (its shard's, over a ``SubprocVectorEnv`` where the parent lacks the method)."""
        slots = self._slots(indices)
        if self._in_shards(method_name):
            return self._per_slot(self.venv.call(method_name, *method_args, **method_kwargs), slots)
        result = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [result for _ in slots]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        """True per slot where the vector env stands for the per-copy ``wrapper_class``
        (its ``per_copy_wrappers``, e.g. ``SafetyFilterWrapper`` behind the filter)."""
        stands_for = getattr(self.venv, "per_copy_wrappers", ())
        wrapped = any(issubclass(c, wrapper_class) for c in stands_for)
        return [wrapped for _ in self._slots(indices)]


def make_vector_vec_env(
    scenario_module: Any, n_envs: int = 1, seed: int | None = None, **config: Any
) -> VectorEnvVecEnv:
    """``scenario_module.vector_env(num_envs=n_envs, **config)`` as a :class:`VectorEnvVecEnv`.

    Args:
        scenario_module: ``fov_coverage_v0`` or ``fov_crossing_v0``.
        n_envs: number of env copies, >= 1 (slots = ``n_envs * n_agents``).
        seed: if given, :meth:`VectorEnvVecEnv.seed` is called with it.
    """
    if isinstance(n_envs, bool) or not isinstance(n_envs, int | np.integer) or n_envs < 1:
        raise ValueError(f"n_envs must be an integer in [1, inf), got {n_envs!r}")
    venv = VectorEnvVecEnv(scenario_module.vector_env(num_envs=int(n_envs), **config))
    if seed is not None:
        venv.seed(seed)
    return venv
