"""VectorSafetyFilterWrapper: the safety filter over B env copies at once (a vector env).

Wraps any object with fov_marl's vector API (``fov_coverage_v0.vector_env`` /
``fov_crossing_v0.vector_env``: ``num_envs``, ``n_agents``, ``config``, ``poses (B, N, 3)``,
``reset(seed) -> (obs (B, N, D), infos)``, ``step(actions (B, N, 3))``, same-step
autoreset with ``infos["final_obs"]`` / ``infos["_final_obs"]``). Per copy and robot it
does exactly what :class:`~fov_marl.wrappers.SafetyFilterWrapper` does for one copy
(same pipeline, defaults and seeding), on one
:class:`~fov_marl.pipeline.PfCbfPipeline` over all ``B N`` robots: one tracker bank, one
batched controller. The actions equal those of B per-copy ``SafetyFilterWrapper`` s
within 1e-6 (tested against a reference loop of B ParallelEnvs).

Seeding: ``reset(seed=s)`` seeds copy k's filters with ``s + k`` (the seed the env copy
gets); when copy k finishes an episode (``infos["_final_obs"][k]``) its trackers restart
from the new episode's first observation with a seed drawn from ``default_rng(s + k)``,
as a per-copy wrapper does on ``reset()`` without a seed.

``infos["safety"]`` holds ``(B, N, ...)`` arrays: ``nominal_action`` (3,) float32,
``applied_action`` (3,) float32, ``intervened`` bool, ``status`` str (object array),
``fallback`` bool, ``cause_bits`` int64 (see :class:`~fov_marl.wrappers.SafetyFilterWrapper`);
``reset()`` gives the neutral report (status ``"reset"``, no cause), as the per-copy
wrapper does. ``last_cpu_s``:
seconds the filter spent on all copies in the last step.

Cost and the particle budget. The filter's cost grows about linearly with the
particles per robot, ``tracker_params={"n_particles_total": P_T}`` (default 2000): the
tracker is most of it, and its random draws alone (three normals and one uniform per
particle and step) cost ~0.05 ms per robot-step at P_T = 2000. ``fov-marl bench``
times the filter at B N = 384 at the default and at P_T = 500
(:data:`fov_marl.bench.FAST_FILTER_PARTICLES`), where the default tracker is still
calibrated on every tested behaviour (``tests/estimation/test_mixture_calibration.py``,
``test_reduced_budget_is_calibrated``); below that it is not (P_T = 250: 0.894 inside
the 95% ellipse for a robot driving straight). A smaller budget is a choice of the
user's; the default stays 2000.

Using more cores, the same numbers either way. ``tracker_threads=T`` steps the
tracker's chunks on T threads (NumPy releases the GIL in its array loops and its
Generators' fills; ``fov-marl train --filter-threads T``); the safety rows and the QPs
stay on one thread. Or split the copies over processes with
:class:`~fov_marl.envs.SubprocVectorEnv` and :func:`build_filtered_vector_env`
(``fov-marl train --safety-filter --workers W``), which parallelises the env and the
whole filter; use one or the other, not both, on a machine with few cores. PPO behind
the filter at B = 64 on the 2-core machine: 2,410 samples/s in one process, 3,812 with
2 workers (CHANGELOG); the tracker on 2 threads: CHANGELOG.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from fov_marl.config import ScenarioConfig
from fov_marl.control import ControllerParams
from fov_marl.control.batched import CONTROL_STATUSES
from fov_marl.envs.base import forward_max_cycles
from fov_marl.envs.subproc import build_raw_vector_env
from fov_marl.envs.vector import check_vector_actions, vector_seeds
from fov_marl.estimation import TrackerParams
from fov_marl.pipeline import PfCbfPipeline
from fov_marl.spaces import action_to_velocity
from fov_marl.validation import check_params, has_attribute
from fov_marl.wrappers.safety_filter import (
    FILTER_TRACKER_DEFAULTS,
    SafetyFilterWrapper,
    filter_controller_params,
)

__all__ = ["VectorSafetyFilterWrapper", "build_filtered_vector_env"]

_STATUS = np.asarray(CONTROL_STATUSES, dtype=object)


class VectorSafetyFilterWrapper:
    """Make any policy's actions safe in every copy of a vector env (module docstring).

    Args:
        venv: an object with the vector API (module docstring).
        init: ``"known"`` or ``"uniform"`` particle initialisation.
        tracker_params, controller_params: as for
            :class:`~fov_marl.wrappers.SafetyFilterWrapper` (dicts override the filter's
            defaults).
        controller: ``"auto"``, ``"batched"`` or ``"loop"`` (see
            :class:`~fov_marl.pipeline.PfCbfPipeline`).
        tracker_threads: threads that step the filters' particle filters, an int in
            ``[1, 1024]`` (default 1; module docstring). The actions are the same for
            every count.
    """

    #: The per-copy wrappers this vector wrapper stands for (SB3's ``env_is_wrapped``
    #: on a vector env's slots, :class:`~fov_marl.training.vec_env.VectorEnvVecEnv`).
    per_copy_wrappers: tuple[type, ...] = (SafetyFilterWrapper,)

    def __init__(
        self,
        venv: Any,
        *,
        init: str = "known",
        tracker_params: TrackerParams | dict | None = None,
        controller_params: ControllerParams | dict | None = None,
        controller: str = "auto",
        tracker_threads: int = 1,
    ) -> None:
        for attr in ("num_envs", "config", "reset", "step", "poses"):
            if not has_attribute(venv, attr):
                raise ValueError(
                    "VectorSafetyFilterWrapper needs a fov_marl vector env (num_envs, config, "
                    f"poses, reset, step); {type(venv).__name__} has no {attr!r}"
                )
        tracker_params = check_params(
            "tracker_params", tracker_params, TrackerParams, FILTER_TRACKER_DEFAULTS
        )
        controller_params = filter_controller_params(venv.config, controller_params)
        self.venv = venv
        self.config = venv.config
        self.num_envs = int(venv.num_envs)
        self.n_agents = int(self.config.n_agents)
        self.pipeline = PfCbfPipeline(
            self.config,
            tracker_params=tracker_params,
            controller_params=controller_params,
            init=init,  # type: ignore[arg-type]
            n_copies=self.num_envs,
            controller=controller,  # type: ignore[arg-type]
            tracker_threads=tracker_threads,
        )
        self._seed_rngs = [np.random.default_rng() for _ in range(self.num_envs)]
        self._ready = False
        self.last_cpu_s = 0.0

    def __getattr__(self, name: str) -> Any:
        # spaces, possible_agents, poses, close, render ... come from the wrapped env
        if name == "venv":
            raise AttributeError(name)
        return getattr(self.venv, name)

    @property
    def unwrapped(self) -> Any:
        return getattr(self.venv, "unwrapped", self.venv)

    max_cycles = forward_max_cycles(lambda w: w.venv)

    def reset(self, seed: Any = None, options: dict | None = None):
        """Reset the env and the filters. ``seed``: an int s (copy k and its filters from
        ``s + k``), a sequence of B ints or None entries (per copy; None continues that
        copy's generators), or None (every copy continues)."""
        obs, infos = self.venv.reset(seed=seed, options=options)
        seeds = []
        for k, s_k in enumerate(vector_seeds(seed, self.num_envs)):
            if s_k is not None:
                self._seed_rngs[k] = np.random.default_rng(s_k)
                seeds.append(s_k)
            else:
                seeds.append(int(self._seed_rngs[k].integers(2**63)))
        self.pipeline.reset_arrays(obs, seeds, np.asarray(self.venv.poses))
        self._ready = True
        infos = dict(infos)
        infos["safety"] = self.reset_safety_infos()
        return obs, infos

    def reset_safety_infos(self) -> dict[str, np.ndarray]:
        """The neutral filter report of a reset, ``(B, N, ...)`` arrays as in
        ``infos["safety"]``: zero actions, no intervention, status ``"reset"`` (what
        :class:`~fov_marl.wrappers.SafetyFilterWrapper` reports at ``reset()``)."""
        B, N = self.num_envs, self.n_agents
        return {
            "nominal_action": np.zeros((B, N, 3), np.float32),
            "applied_action": np.zeros((B, N, 3), np.float32),
            "intervened": np.zeros((B, N), dtype=bool),
            "status": np.full((B, N), "reset", dtype=object),
            "fallback": np.zeros((B, N), dtype=bool),
            "cause_bits": np.zeros((B, N), dtype=np.int64),
        }

    def _actions(self, actions: Any) -> np.ndarray:
        # the raw vector env's check (one place): dtype, shape, finite, copy and robot named
        return check_vector_actions(actions, self.num_envs, self.n_agents)

    def step(self, actions: Any):
        if not self._ready:
            raise ValueError("step() called before reset()")
        act = self._actions(actions)
        cfg = self.config
        B, N = self.num_envs, self.n_agents
        t0 = time.perf_counter()
        v, w = action_to_velocity(act.reshape(B * N, 3), cfg.v_max_mps, cfg.omega_max_radps)
        safe = self.pipeline.filter(np.column_stack([v, w])).reshape(B, N, 3)
        t_filter = time.perf_counter() - t0
        obs, rew, term, trunc, infos = self.venv.step(safe)
        t1 = time.perf_counter()
        done = np.asarray(infos.get("_final_obs", np.zeros(B, dtype=bool)), dtype=bool)
        seen = obs
        if done.any():  # the trackers of a finished copy see its last observation, then restart
            seen = np.where(done[:, None, None], infos["final_obs"], obs)
        self.pipeline.observe_arrays(seen)
        if done.any():
            k = np.flatnonzero(done)
            seeds = [int(self._seed_rngs[i].integers(2**63)) for i in k.tolist()]
            self.pipeline.reset_copies(k, obs, seeds, np.asarray(self.venv.poses))
        t_filter += time.perf_counter() - t1
        infos = dict(infos)
        infos["safety"] = self._safety_infos(act, safe)
        self.last_cpu_s = t_filter
        return obs, rew, term, trunc, infos

    def _safety_infos(self, act: np.ndarray, safe: np.ndarray) -> dict[str, np.ndarray]:
        """The per-robot filter report of this step, ``(B, N, ...)`` arrays (one place)."""
        B, N = self.num_envs, self.n_agents
        res = self.pipeline.last_batch if self.pipeline.use_cbf else None
        if res is not None:
            intervened = res.intervened.reshape(B, N).copy()
            status = _STATUS[res.status].reshape(B, N)
            fallback = res.fallback.reshape(B, N).copy()
            causes = self.pipeline.last_cause_bits.reshape(B, N).copy()
        else:
            intervened = np.zeros((B, N), dtype=bool)
            status = np.full((B, N), "no_neighbours", dtype=object)
            fallback = np.zeros((B, N), dtype=bool)
            causes = np.zeros((B, N), dtype=np.int64)
        return {
            "nominal_action": np.clip(act, -1.0, 1.0).astype(np.float32),
            "applied_action": safe.copy(),
            "intervened": intervened,
            "status": status,
            "fallback": fallback,
            "cause_bits": causes,
        }

    def close(self) -> None:
        close = getattr(self.venv, "close", None)
        if close is not None:
            close()


def build_filtered_vector_env(
    num_envs: int,
    *,
    config: ScenarioConfig,
    max_cycles: int | None = None,
    eta_method: str = "exact",
    **filter_kwargs: Any,
) -> VectorSafetyFilterWrapper:
    """A vector env of ``config`` (``max_cycles`` set unless None) behind
    ``VectorSafetyFilterWrapper(venv, **filter_kwargs)``; module-level, so
    ``functools.partial`` of it is a picklable shard factory of
    :class:`~fov_marl.envs.SubprocVectorEnv` (``fov-marl train --safety-filter
    --workers W``)."""
    venv = build_raw_vector_env(
        num_envs, config=config, max_cycles=max_cycles, eta_method=eta_method
    )
    return VectorSafetyFilterWrapper(venv, **filter_kwargs)
