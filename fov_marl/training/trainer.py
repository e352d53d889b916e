"""Train shared-parameter coverage policies with stable-baselines3; save, reload, act.

>>> from fov_marl.training import train, load_policy
>>> path = train("ppo", timesteps=200_000, seed=0, out_dir="runs/ppo")   # runs/ppo/model.zip
>>> policy = load_policy(path)              # reset(seed) / act(obs dict) like a baseline
>>> env = policy.make_env()                 # the scenario and wrappers it was trained with

One network is shared by every robot (:mod:`fov_marl.training.vec_env`: each agent of
each env copy is one VecEnv slot), and each robot acts on its own observation only:
training is centralised in data, execution is decentralised.

Architectures: ``arch="mlp"`` (SB3's ``MlpPolicy``, observations normalised by
``VecNormalize``, one team size) or ``arch="set"`` (PPO,
:mod:`fov_marl.training.set_policy`: permutation-invariant over neighbour slots, one set
of weights for any N, fixed feature scales instead of observation normalisation,
``ctde=True`` for a critic reading the agent-centric global state; reward shaping terms
``eta_level_coef``, ``blind_motion_coef``, ``action_cost_coef``, ``fov_keep_coef``,
``intervention_coef`` are documented in
:class:`~fov_marl.training.set_policy.CtdeVecEnvWrapper`). A set model exports with
:func:`fov_marl.training.export_policy` to the numpy policy ``make_policy("learned",
env, path=...)``; ``fov-marl train --arch set`` does it into ``OUT/export``.

Timesteps
---------
SB3 counts *samples*: one robot-step is one timestep, so ``timesteps = T`` is
``T / n_agents`` env steps spread over ``n_envs`` copies (with N = 6 and 4 copies one
vectorised step is 24 timesteps). SB3 collects whole rollouts, so a run ends at the
next multiple of the rollout size at or above ``T``: ``n_steps x n_envs x n_agents``
for PPO (256 x 4 x 6 = 6144 at the defaults: ``timesteps=1000`` runs 6144), ``train_freq
x n_envs x n_agents`` for SAC (:func:`effective_timesteps`; ``fov-marl train`` prints
it before training starts).

Default hyper-parameters and why (override any with ``hyperparams={...}``)
--------------------------------------------------------------------------
=====================  =================  =================================================
PPO                    default            reason
=====================  =================  =================================================
``n_envs``             4 copies           24 slots at N = 6: decorrelated samples, one
                                          process (the env steps at ~2400 copy-steps/s, so
                                          subprocesses would not pay on 2 cores)
``n_steps``            256                rollout of 256 × 24 = 6144 samples; ~1/2 episode
``batch_size``         512                12 minibatches per epoch
``n_epochs``           10                 SB3 / rl-zoo default for continuous control
``learning_rate``      3e-4               Adam default of PPO
``gamma``              0.99               dt = 0.2 s: horizon 1/(1−γ) = 100 steps = 20 s,
                                          the time a robot needs to cross ~half the arena;
                                          rewards are dense (Δη every step)
``gae_lambda``         0.95               standard bias/variance trade-off
``ent_coef``           0.0                Gaussian policy; exploration from log-std
``net_arch``           pi [64, 64],       observations are 32 numbers at N = 6 (57 with
                       vf [64, 64], tanh  belief features); small MLPs train fastest on CPU
``train_max_cycles``   500 (100 s)        shorter than the evaluation horizon (1000 steps):
                                          more start configurations per sample; the task
                                          is continuing, time-limit truncation bootstraps
                                          (``TimeLimit.truncated``), so the policy learns
                                          the infinite-horizon objective regardless
``normalize``          obs + reward       ``VecNormalize`` (clip 10): observations mix
                                          metres (up to 56 m) and flags; the running
                                          statistics are saved as ``vecnormalize.pkl`` and
                                          applied by :func:`load_policy`
``torch_threads``      1                  tiny MLP: a second thread costs more in
                                          synchronisation than it gains, and leaves the
                                          other core to the simulator/OS
=====================  =================  =================================================

SAC (``algo="sac"``): ``learning_rate`` 3e-4, ``buffer_size`` 300 000, ``learning_starts``
5 000, ``batch_size`` 256, ``gamma`` 0.99, ``tau`` 0.005, ``train_freq`` 1 vectorised
step (24 samples), ``gradient_steps`` 2, ``net_arch`` [128, 128] (ReLU). SAC is supported
but PPO is the recommended default on a CPU: with 24 slots SAC spends most of its
time in gradient steps.

Measured on the shared 2-core development machine (torch CPU, 1 thread)
-----------------------------------------------------------------------
Coverage, N = 6, β = 120°, PPO defaults: 5 000-7 800 samples/s (env ~0.4 ms per copy-step;
1 M timesteps in ~3.5 min). After 1 M timesteps the deterministic policy ends 1000-step
episodes at final η ≈ 0.99 with no collision (5 seeds; ``random``: η ≈ 0.29); after
200 k it reaches η ≈ 0.99 but does not hold it. With belief features (P_T = 2000):
~2 000 samples/s. ``tests/training/test_slow_training.py`` repeats the comparison.

Outputs in ``out_dir``
----------------------
=========================  ==========================================================
``model.zip``              the SB3 model (``PPO.load``/``SAC.load``)
``vecnormalize.pkl``       observation/reward normalisation statistics
``config.json``            algo, scenario, ``env_kwargs`` (every config field, evaluation
                           horizon), ``train_env_config`` (as trained), wrappers,
                           hyper-parameters, seed, timesteps, timing, versions
``checkpoints/``           ``model_<t>_steps.zip`` + ``model_vecnormalize_<t>_steps.pkl``
``tb/PPO_<k>/``            TensorBoard, one folder per run (``tensorboard --logdir
                           out_dir/tb``)
``progress.csv``           the same scalars as CSV
=========================  ==========================================================

Logged scalars: SB3's ``rollout/ep_rew_mean`` (per-robot episode return) and losses,
plus, once per finished episode of each env copy, ``fov/team_return`` (sum over
robots), ``fov/final_eta``, ``fov/collisions``, ``fov/safety_violations``,
``fov/min_distance`` (episode), crossing: ``fov/arrived``; behind the safety filter
``fov/filter_interventions`` (robot-steps where the filter changed the action, per
episode and robot) and ``fov/filter_intervention_rate``; per rollout ``fov/eta_rollout``
(mean η over all steps) and, behind the filter, ``fov/intervention_rate_rollout`` and
``fov/intervention_cause_rollout/<cause>`` (the share of robot-steps changed for each
cause of :data:`fov_marl.infos.SAFETY_CAUSES`).
"""

from __future__ import annotations

import copy
import json
import os
import pickle
import platform
import sys
import time
import warnings
import zipfile
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import stable_baselines3
import torch
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, CheckpointCallback
from stable_baselines3.common.logger import (
    CSVOutputFormat,
    HumanOutputFormat,
    Logger,
    TensorBoardOutputFormat,
)
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

from fov_marl.config import make_config
from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
from fov_marl.infos import SAFETY_CAUSES, cause_counts, metrics_of, safety_of
from fov_marl.training.vec_env import ParallelEnvVecEnv
from fov_marl.validation import (
    MAX_SEED,
    ConfigError,
    check_bool,
    check_budget,
    check_choice,
    check_int,
    check_keys,
    check_out_dir,
    check_real,
    check_seed,
    check_wrapper_kwargs,
    describe,
    is_integer,
)

__all__ = [
    "ALGOS",
    "SCENARIOS",
    "DEFAULT_HYPERPARAMS",
    "DEFAULT_TRAIN_MAX_CYCLES",
    "DEFAULT_N_ENVS",
    "build_env",
    "make_training_vec_env",
    "train",
    "checkpoint_period",
    "load_policy",
    "LearnedPolicy",
    "FovMetricsCallback",
    "HYPERPARAM_SPECS",
    "POLICY_KWARGS_SPECS",
    "MAX_BUFFER_BYTES",
    "validate_hyperparams",
    "effective_timesteps",
]

ALGOS = {"ppo": PPO, "sac": SAC}
SCENARIOS = {"coverage": fov_coverage_v0, "crossing": fov_crossing_v0}
DEFAULT_N_ENVS = 4
DEFAULT_TRAIN_MAX_CYCLES = 500
CONFIG_FORMAT = "fov_marl.training/1"

DEFAULT_HYPERPARAMS: dict[str, dict[str, Any]] = {
    "ppo": {
        "learning_rate": 3e-4,
        "n_steps": 256,
        "batch_size": 512,
        "n_epochs": 10,
        "gamma": 0.99,
        "gae_lambda": 0.95,
        "clip_range": 0.2,
        "ent_coef": 0.0,
        "vf_coef": 0.5,
        "max_grad_norm": 0.5,
        "policy_kwargs": {
            "net_arch": {"pi": [64, 64], "vf": [64, 64]},
            "activation_fn": "tanh",
        },
    },
    "sac": {
        "learning_rate": 3e-4,
        "buffer_size": 300_000,
        "learning_starts": 5_000,
        "batch_size": 256,
        "tau": 0.005,
        "gamma": 0.99,
        "train_freq": 1,
        "gradient_steps": 2,
        "policy_kwargs": {"net_arch": [128, 128], "activation_fn": "relu"},
    },
}

_ACTIVATIONS = {
    "tanh": torch.nn.Tanh,
    "relu": torch.nn.ReLU,
    "elu": torch.nn.ELU,
    "leaky_relu": torch.nn.LeakyReLU,
}


# ---------------------------------------------------------------- env building
def build_env(
    scenario: str = "coverage",
    env_kwargs: dict[str, Any] | None = None,
    *,
    safety_filter: bool = False,
    safety_filter_kwargs: dict[str, Any] | None = None,
    belief: bool = False,
    belief_kwargs: dict[str, Any] | None = None,
    render_mode: str | None = None,
) -> Any:
    """A scenario's ParallelEnv with the training wrappers, innermost first.

    Order: env -> :class:`~fov_marl.wrappers.SafetyFilterWrapper` (if ``safety_filter``)
    -> :class:`~fov_marl.wrappers.belief.BeliefObservationWrapper` (if ``belief``). The
    belief wrapper is outermost so the safety filter keeps receiving the env's own
    observation layout.

    Raises:
        ValueError: unknown scenario, or an invalid config keyword/value.
    """
    if scenario not in SCENARIOS:
        raise ValueError(f"scenario must be one of {sorted(SCENARIOS)}, got {scenario!r}")
    env = SCENARIOS[scenario].parallel_env(render_mode=render_mode, **(env_kwargs or {}))
    if safety_filter:
        from fov_marl.wrappers import SafetyFilterWrapper

        env = SafetyFilterWrapper(env, **(safety_filter_kwargs or {}))
    if belief:
        from fov_marl.wrappers.belief import BeliefObservationWrapper

        env = BeliefObservationWrapper(env, **(belief_kwargs or {}))
    return env


def make_training_vec_env(
    n_envs: int,
    env_factory: Callable[[], Any],
    *,
    normalize: bool = True,
    gamma: float = 0.99,
    eta_method: str = "exact",
    norm_obs: bool = True,
    wrap_adapter: Callable[[Any], Any] | None = None,
    workers: int = 1,
) -> tuple[Any, Any]:
    """``(adapter, vec_env)``: the adapter, then ``VecMonitor`` and optionally ``VecNormalize``.

    ``env_factory()`` is called once to see what it builds. A raw scenario env
    (``fov_coverage_v0``/``fov_crossing_v0`` ParallelEnv, no wrapper, no rendering) is
    replaced by the batched vector env of its config and ``max_cycles``, all copies
    stepped in one call through :class:`~fov_marl.training.vec_env.VectorEnvVecEnv`; a
    :class:`~fov_marl.wrappers.SafetyFilterWrapper` on such an env becomes one
    :class:`~fov_marl.wrappers.VectorSafetyFilterWrapper` over the vector env (same
    filter parameters; actions equal within 1e-6); anything else (the belief wrapper
    needs a ParallelEnv per copy) goes through :class:`~fov_marl.training.vec_env.ParallelEnvVecEnv` over
    ``n_envs`` factory calls (the probe is the first copy). Both adapters give the same
    slots, observations, rewards and infos for the same seed. ``eta_method="strip"``
    (vector path, coverage only) trains on the cheaper
    :class:`~fov_marl.metrics.StripCoverageMetric` η; the default keeps the exact one.
    ``wrap_adapter(adapter)``, if given, wraps the adapter below ``VecMonitor`` (the
    set policy's :class:`~fov_marl.training.set_policy.CtdeVecEnvWrapper`);
    ``norm_obs=False`` keeps ``VecNormalize`` to the rewards. ``workers = W > 1`` (vector
    paths only, ``W <= n_envs``) steps the copies in W processes
    (:class:`~fov_marl.envs.SubprocVectorEnv`: W cores, the same numbers); the per-copy
    path refuses it.
    """
    from fov_marl.envs.fov_coverage_v0 import FovCoverageEnv
    from fov_marl.envs.fov_crossing_v0 import FovCrossingEnv
    from fov_marl.training.vec_env import VectorEnvVecEnv

    if isinstance(n_envs, bool) or not isinstance(n_envs, int | np.integer) or n_envs < 1:
        raise ValueError(f"n_envs must be an integer in [1, inf), got {n_envs!r}")
    workers = check_int("workers", workers, 1, int(n_envs), note="(at most n_envs)")
    from fov_marl.envs import SubprocVectorEnv, build_raw_vector_env
    from fov_marl.wrappers import SafetyFilterWrapper, build_filtered_vector_env

    raw = (FovCoverageEnv, FovCrossingEnv)
    probe = env_factory()
    adapter: Any
    make: Callable[[int], Any] | None = None
    if type(probe) in raw and probe.render_mode is None:
        make = partial(
            build_raw_vector_env,
            config=probe.config,
            max_cycles=probe.max_cycles,
            eta_method=eta_method,
        )
    elif (
        type(probe) is SafetyFilterWrapper
        and type(probe.env) in raw
        and probe.env.render_mode is None
    ):
        # the filter over all copies at once: one tracker bank, one batched controller
        pipe = probe.pipeline
        make = partial(
            build_filtered_vector_env,
            config=probe.config,
            max_cycles=probe.env.max_cycles,
            eta_method=eta_method,
            init=pipe.init,
            tracker_params=pipe.tracker_params,
            controller_params=pipe.controller_params,
            tracker_threads=pipe.tracker_threads,
        )
    if make is not None:
        probe.close()
        vector = make(int(n_envs)) if workers == 1 else SubprocVectorEnv(make, int(n_envs), workers)
        adapter = VectorEnvVecEnv(vector)
    else:
        if workers != 1:
            raise ValueError(
                f"workers = {workers} needs a vector path (a raw scenario env, alone or "
                "behind the safety filter); this env is stepped per copy"
            )
        if eta_method != "exact":
            raise ValueError(
                f"eta_method={eta_method!r} needs a raw scenario env (no wrappers); "
                "wrapped envs use the exact eta"
            )
        first = [probe]
        adapter = ParallelEnvVecEnv(
            [lambda: first.pop() if first else env_factory() for _ in range(int(n_envs))]
        )
    venv: Any = VecMonitor(wrap_adapter(adapter) if wrap_adapter is not None else adapter)
    if normalize:
        venv = VecNormalize(
            venv, norm_obs=bool(norm_obs), norm_reward=True, clip_obs=10.0, gamma=gamma
        )
    return adapter, venv


# ------------------------------------------------------------------- callback
class FovMetricsCallback(BaseCallback):
    """Log the env's episode metrics and safety-filter interventions (``fov/*``).

    Reads the adapter's infos (see :mod:`fov_marl.training.vec_env`): when an env copy's
    episode ends, its team metrics (identical in every slot of the copy) are logged once.
    """

    _METRICS = {
        "eta": "final_eta",
        "collisions_total": "collisions",
        "safety_violations_total": "safety_violations",
        "min_distance_episode": "min_distance",
        "arrived_ever": "arrived",
    }

    def __init__(self, n_agents: int, verbose: int = 0) -> None:
        super().__init__(verbose)
        self.n_agents = n_agents
        self.episodes = 0
        self._interventions: dict[int, int] = {}
        self._steps: dict[int, int] = {}
        self.last_episode_metrics: dict[str, float] = {}
        self._roll = np.zeros(4)  # eta sum, eta count, interventions, filtered robot-steps
        self._causes = np.zeros(len(SAFETY_CAUSES))  # robot-steps changed per cause

    def _on_rollout_start(self) -> None:
        self._roll[:] = 0.0
        self._causes[:] = 0.0

    def _on_rollout_end(self) -> None:
        """Per-rollout means: ``fov/eta_rollout`` (η over every step of every copy) and,
        behind the filter, ``fov/intervention_rate_rollout`` (robot-steps changed) and
        ``fov/intervention_cause_rollout/<cause>`` (robot-steps changed for each cause
        of :data:`fov_marl.infos.SAFETY_CAUSES`)."""
        if self._roll[1]:
            self.logger.record("fov/eta_rollout", self._roll[0] / self._roll[1])
        if self._roll[3]:
            self.logger.record("fov/intervention_rate_rollout", self._roll[2] / self._roll[3])
            for name, n in zip(SAFETY_CAUSES, self._causes, strict=True):
                self.logger.record(f"fov/intervention_cause_rollout/{name}", n / self._roll[3])

    def _on_step(self) -> bool:
        infos = self.locals.get("infos", [])
        dones = self.locals.get("dones", np.zeros(len(infos), dtype=bool))
        for info in infos[:: max(self.n_agents, 1)]:  # one slot per copy: team metrics
            eta = info.get("metrics/eta")
            if eta is not None:
                self._roll[0] += float(eta)
                self._roll[1] += 1
        if infos and "safety/intervened" in infos[0]:
            self._roll[2] += sum(bool(i["safety/intervened"]) for i in infos)
            self._roll[3] += len(infos)
            self._causes += cause_counts([i.get("safety/cause_bits", 0) for i in infos])
        ended: dict[int, list[dict]] = {}
        for info, done in zip(infos, dones, strict=True):
            k = int(info.get("env_index", 0))
            safety = safety_of(info)
            if isinstance(safety, dict) and "intervened" in safety:
                self._interventions[k] = self._interventions.get(k, 0) + int(
                    bool(safety["intervened"])
                )
                self._steps[k] = self._steps.get(k, 0) + 1
            if done:
                ended.setdefault(k, []).append(info)
        for k, slot_infos in ended.items():
            self.episodes += 1
            metrics = metrics_of(slot_infos[0])
            out: dict[str, float] = {}
            for key, name in self._METRICS.items():
                if key in metrics:
                    out[name] = float(metrics[key])
            returns = [i["episode"]["r"] for i in slot_infos if "episode" in i]
            if returns:
                out["team_return"] = float(np.sum(returns))
            if k in self._steps:
                steps = max(self._steps.pop(k), 1)
                n_int = self._interventions.pop(k, 0)
                out["filter_interventions"] = n_int / self.n_agents
                out["filter_intervention_rate"] = n_int / steps
            for name, value in out.items():
                self.logger.record_mean(f"fov/{name}", value)
            self.last_episode_metrics = out
        return True


# ---------------------------------------------------------------- hyperparams
#: Resource guard: SB3's rollout (PPO) or replay (SAC) buffer may take at most this
#: many bytes (float32 observations, actions and per-sample scalars).
MAX_BUFFER_BYTES = 4 * 2**30

#: Accepted ``hyperparams`` keys per algorithm: key -> (kind, lo, hi). Kinds: "int",
#: "real", "real+" (lo open), "bool", "real|None", "policy_kwargs", "train_freq",
#: "ent_coef" (SAC: a real > 0, "auto" or "auto_<real>"), "target_entropy" ("auto" or
#: a real), "gradient_steps" (-1 or an int in [0, hi]).
HYPERPARAM_SPECS: dict[str, dict[str, tuple[str, float, float]]] = {
    "ppo": {
        "learning_rate": ("real+", 0.0, 1.0),
        "n_steps": ("int", 1, 10**6),
        "batch_size": ("int", 2, 10**6),
        "n_epochs": ("int", 1, 1000),
        "gamma": ("real", 0.0, 1.0),
        "gae_lambda": ("real", 0.0, 1.0),
        "clip_range": ("real+", 0.0, 10.0),
        "clip_range_vf": ("real|None", 0.0, 1e3),
        "normalize_advantage": ("bool", 0, 0),
        "ent_coef": ("real", 0.0, 1e3),
        "vf_coef": ("real", 0.0, 1e3),
        "max_grad_norm": ("real+", 0.0, 1e6),
        "use_sde": ("bool", 0, 0),
        "sde_sample_freq": ("int", -1, 10**6),
        "target_kl": ("real|None", 0.0, 1e3),
        "stats_window_size": ("int", 1, 10**6),
        "policy_kwargs": ("policy_kwargs", 0, 0),
    },
    "sac": {
        "learning_rate": ("real+", 0.0, 1.0),
        "buffer_size": ("int", 1, 10**8),
        "learning_starts": ("int", 0, 10**9),
        "batch_size": ("int", 1, 10**6),
        "tau": ("real+", 0.0, 1.0),
        "gamma": ("real", 0.0, 1.0),
        "train_freq": ("train_freq", 1, 10**6),
        "gradient_steps": ("gradient_steps", 0, 10**4),
        "n_steps": ("int", 1, 1000),
        "ent_coef": ("ent_coef", 0.0, 1e3),
        "target_update_interval": ("int", 1, 10**6),
        "target_entropy": ("target_entropy", -1e6, 1e6),
        "use_sde": ("bool", 0, 0),
        "sde_sample_freq": ("int", -1, 10**6),
        "use_sde_at_warmup": ("bool", 0, 0),
        "stats_window_size": ("int", 1, 10**6),
        "policy_kwargs": ("policy_kwargs", 0, 0),
    },
}
#: Accepted ``policy_kwargs`` keys per algorithm (same kinds; "net_arch": a list of at
#: most 8 layer widths in [1, 1024], or a dict of such lists with keys "pi"/"vf" (PPO)
#: or "pi"/"qf" (SAC); "activation_fn": a name of ``_ACTIVATIONS``).
POLICY_KWARGS_SPECS: dict[str, dict[str, tuple[str, float, float]]] = {
    "ppo": {
        "net_arch": ("net_arch", 1, 1024),
        "activation_fn": ("activation_fn", 0, 0),
        "ortho_init": ("bool", 0, 0),
        "log_std_init": ("real", -20.0, 20.0),
        "share_features_extractor": ("bool", 0, 0),
        "hidden": ("int", 4, 1024),
        "bounded_mean": ("bool", 0, 0),
    },
    "sac": {
        "net_arch": ("net_arch", 1, 1024),
        "activation_fn": ("activation_fn", 0, 0),
        "log_std_init": ("real", -20.0, 20.0),
        "clip_mean": ("real+", 0.0, 1e3),
        "n_critics": ("int", 1, 10),
        "share_features_extractor": ("bool", 0, 0),
    },
}
_NET_ARCH_KEYS = {"ppo": ("pi", "vf"), "sac": ("pi", "qf")}
_MAX_LAYERS = 8


def _check_hp_value(algo: str, name: str, value: Any, spec: tuple[str, float, float]) -> Any:
    kind, lo, hi = spec
    if kind == "int":
        return check_int(name, value, int(lo), int(hi))
    if kind == "real":
        return check_real(name, value, lo, hi)
    if kind == "real+":
        return check_real(name, value, lo, hi, lo_open=True)
    if kind == "real|None":
        return (
            None
            if value is None
            else check_real(name, value, lo, hi, lo_open=True, note="(or null)")
        )
    if kind == "bool":
        return check_bool(name, value)
    if kind == "gradient_steps":
        if is_integer(value) and int(value) == -1:
            return -1
        return check_int(name, value, int(lo), int(hi), note="(or -1: as many as env steps)")
    if kind == "train_freq":
        if isinstance(value, list | tuple):
            if len(value) != 2:
                raise ConfigError(
                    f"{name} must be an integer or [integer, 'step' | 'episode'], "
                    f"got {describe(value)}"
                )
            n = check_int(f"{name}[0]", value[0], int(lo), int(hi))
            unit = check_choice(f"{name}[1]", value[1], ("step", "episode"))
            return (n, unit)
        return check_int(name, value, int(lo), int(hi), note="(or [n, 'step' | 'episode'])")
    if kind == "ent_coef":
        if isinstance(value, str) and (value == "auto" or value.startswith("auto_")):
            if value != "auto":
                check_real(
                    f"{name} (auto_<initial value>)",
                    _float_or_none(value[5:]),
                    0.0,
                    hi,
                    lo_open=True,
                )
            return value
        return check_real(name, value, lo, hi, lo_open=True, note="(or 'auto', 'auto_<initial>')")
    if kind == "target_entropy":
        if isinstance(value, str) and value == "auto":
            return value
        return check_real(name, value, lo, hi, note="(or 'auto')")
    if kind == "activation_fn":
        return check_choice(name, value, sorted(_ACTIVATIONS))
    if kind == "net_arch":
        return _check_net_arch(algo, name, value, int(lo), int(hi))
    if kind == "policy_kwargs":
        if not isinstance(value, dict):
            raise ConfigError(f"{name} must be a JSON object (dict), got {describe(value)}")
        specs = POLICY_KWARGS_SPECS[algo]
        check_keys(f"{algo.upper()} policy_kwargs keys", value, specs)
        return {
            k: _check_hp_value(algo, f"policy_kwargs.{k}", v, specs[k]) for k, v in value.items()
        }
    raise AssertionError(kind)


def _float_or_none(text: str) -> Any:
    try:
        return float(text)
    except ValueError:
        return text


def _check_layers(name: str, value: Any, lo: int, hi: int) -> list[int]:
    if not isinstance(value, list | tuple) or len(value) > _MAX_LAYERS:
        raise ConfigError(
            f"{name} must be a list of at most {_MAX_LAYERS} layer widths in [{lo}, {hi}], "
            f"got {describe(value)}"
        )
    return [check_int(f"{name}[{k}]", w, lo, hi) for k, w in enumerate(value)]


def _check_net_arch(algo: str, name: str, value: Any, lo: int, hi: int) -> Any:
    if isinstance(value, dict):
        keys = _NET_ARCH_KEYS[algo]
        check_keys(f"{name} keys", value, keys)
        return {k: _check_layers(f"{name}.{k}", v, lo, hi) for k, v in value.items()}
    return _check_layers(name, value, lo, hi)


def validate_hyperparams(algo: str, hyperparams: Any) -> dict[str, Any]:
    """Check SB3 overrides for ``algo``: known keys, types and ranges (see
    :data:`HYPERPARAM_SPECS` and :data:`POLICY_KWARGS_SPECS`).

    Returns:
        The overrides with normalised values (Python numbers, tuples for ``train_freq``).

    Raises:
        ConfigError: an unknown key (the message lists the valid ones) or a bad value
            (the message names the key, the value and the allowed range).
    """
    if algo not in ALGOS:
        raise ConfigError(f"algo must be one of {sorted(ALGOS)}, got {describe(algo)}")
    if hyperparams is None:
        return {}
    if not isinstance(hyperparams, dict):
        raise ConfigError(f"hyperparams must be a dict or None, got {describe(hyperparams)}")
    specs = HYPERPARAM_SPECS[algo]
    for key in hyperparams:
        if not isinstance(key, str):
            raise ConfigError(f"hyper-parameter names must be strings, got {describe(key)}")
    check_keys(f"{algo.upper()} hyper-parameters", hyperparams, specs)
    return {k: _check_hp_value(algo, k, v, specs[k]) for k, v in hyperparams.items()}


def _check_buffer(algo: str, hp: dict[str, Any], n_slots: int, obs_dim: int, act_dim: int) -> None:
    """Resource guard on SB3's buffer (:data:`MAX_BUFFER_BYTES`) and PPO's rollout size."""
    slots = f"n_envs x n_agents = {n_slots} slots, {obs_dim} observations"
    if algo == "ppo":
        n_steps = int(hp["n_steps"])
        if n_steps * n_slots < 2:
            raise ConfigError(
                f"n_steps = {n_steps} ({slots}): PPO needs n_steps x slots >= 2; raise n_steps"
            )
        need = 4.0 * n_steps * n_slots * (obs_dim + act_dim + 6)
        check_budget(
            "n_steps", n_steps, need, MAX_BUFFER_BYTES, "the PPO rollout buffer", "bytes", slots
        )
    else:
        size = int(hp["buffer_size"])
        need = 4.0 * size * (2 * obs_dim + act_dim + 3)
        check_budget(
            "buffer_size", size, need, MAX_BUFFER_BYTES, "the SAC replay buffer", "bytes", slots
        )


def _merged_hyperparams(algo: str, overrides: dict[str, Any] | None) -> dict[str, Any]:
    hp = copy.deepcopy(DEFAULT_HYPERPARAMS[algo])
    for key, value in (overrides or {}).items():
        if key == "policy_kwargs" and isinstance(value, dict):
            hp["policy_kwargs"] = {**hp.get("policy_kwargs", {}), **value}
        else:
            hp[key] = value
    return hp


def _to_sb3_kwargs(hp: dict[str, Any]) -> dict[str, Any]:
    kw = copy.deepcopy(hp)
    pk = kw.get("policy_kwargs")
    if pk and isinstance(pk.get("activation_fn"), str):
        name = pk["activation_fn"]
        if name not in _ACTIVATIONS:
            raise ValueError(
                f"policy_kwargs.activation_fn must be one of {sorted(_ACTIVATIONS)}, got {name!r}"
            )
        pk["activation_fn"] = _ACTIVATIONS[name]
    return kw


def effective_timesteps(
    algo: str, timesteps: int, n_slots: int, hyperparams: dict[str, Any] | None = None
) -> int:
    """The timesteps SB3 actually runs for ``timesteps`` requested.

    ``learn(total_timesteps=T)`` collects whole rollouts until ``T`` is reached: PPO's
    rollouts are ``n_steps`` vectorised steps of ``n_slots`` samples each (``n_slots =
    n_envs x n_agents``), SAC's ``train_freq`` steps (``[k, "episode"]``: at least one
    vectorised step per round, so the result is then a lower bound).

    Returns:
        ``ceil(T / block) * block`` with the block size above (``T`` itself when it is a
        multiple).
    """
    hp = _merged_hyperparams(algo, hyperparams)
    if algo == "ppo":
        block = int(hp["n_steps"]) * int(n_slots)
    else:
        freq = hp.get("train_freq", 1)
        k, unit = (freq[0], freq[1]) if isinstance(freq, list | tuple) else (freq, "step")
        block = int(n_slots) * (int(k) if unit == "step" else 1)
    return -(-int(timesteps) // block) * block


def _have_progress_bar() -> bool:
    """SB3's progress bar needs both tqdm and rich; without either, train without one."""
    try:
        import rich  # noqa: F401
        import tqdm  # noqa: F401
    except ImportError:
        return False
    return True


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, type):
        return x.__name__
    return x


def _next_run_dir(root: Path, prefix: str) -> Path:
    """``root/<prefix>_<k>`` with the first unused k >= 1 (as SB3 names its runs)."""
    k = 1
    while (root / f"{prefix}_{k}").exists():
        k += 1
    return root / f"{prefix}_{k}"


# ---------------------------------------------------------------------- train
def checkpoint_period(checkpoint_every: int, slots: int) -> int:
    """Timesteps between checkpoints: ``checkpoint_every`` rounded down to a multiple of
    ``slots`` (the timesteps of one vector step), at least one vector step."""
    return max(int(checkpoint_every) // int(slots), 1) * int(slots)


def train(
    algo: str = "ppo",
    scenario: str = "coverage",
    *,
    safety_filter: bool = False,
    belief: bool = False,
    timesteps: int = 1_000_000,
    seed: int = 0,
    out_dir: str | os.PathLike = "runs/train",
    n_envs: int = DEFAULT_N_ENVS,
    env_kwargs: dict[str, Any] | None = None,
    hyperparams: dict[str, Any] | None = None,
    train_max_cycles: int | None = DEFAULT_TRAIN_MAX_CYCLES,
    normalize: bool = True,
    checkpoint_every: int = 100_000,
    progress_bar: bool = True,
    torch_threads: int = 1,
    safety_filter_kwargs: dict[str, Any] | None = None,
    belief_kwargs: dict[str, Any] | None = None,
    verbose: int = 0,
    arch: str = "mlp",
    ctde: bool = False,
    eta_level_coef: float = 0.0,
    intervention_coef: float = 0.0,
    init_from: str | os.PathLike | None = None,
    blind_motion_coef: float = 0.0,
    action_cost_coef: float = 0.0,
    fov_keep_coef: float = 0.0,
    workers: int = 1,
) -> Path:
    """Train one shared policy for all robots and save it; return ``out_dir/model.zip``.

    Args:
        algo: ``"ppo"`` or ``"sac"``.
        scenario: ``"coverage"`` or ``"crossing"``.
        safety_filter: train behind :class:`fov_marl.wrappers.SafetyFilterWrapper`.
        belief: add :class:`fov_marl.wrappers.belief.BeliefObservationWrapper` features.
        timesteps: robot-steps (samples) to train for, in [1, 1e12] (see module
            docstring); SB3 runs whole rollouts, so the run ends at
            :func:`effective_timesteps` (``config.json``: ``timesteps_done``).
        seed: seeds SB3 (python, numpy, torch) and the env copies (copy k: seed + k), in
            [0, 2**31 - 1] (SB3 seeds NumPy's legacy generator).
        out_dir: output folder (created; existing files are overwritten: ``fov-marl
            train`` refuses a folder holding a model unless ``--force``); an existing
            non-directory, a path under one or an unwritable parent is an error before
            anything runs.
        n_envs: env copies, in [1, 1024].
        workers: processes stepping the env copies (and the filter), in [1, n_envs]
            (:class:`~fov_marl.envs.SubprocVectorEnv`; the same numbers as 1). Needs the
            vector path: not with ``belief``.
        env_kwargs: scenario config fields (:class:`fov_marl.config.ScenarioConfig`).
        hyperparams: SB3 keyword overrides; ``policy_kwargs`` is merged with the default,
            ``activation_fn`` given by name (``"tanh"``, ``"relu"``, ...). Keys, types
            and ranges are checked by :func:`validate_hyperparams` (the accepted keys are
            :data:`HYPERPARAM_SPECS`), and the rollout (PPO) or replay (SAC) buffer must
            fit in :data:`MAX_BUFFER_BYTES` (4 GiB).
        train_max_cycles: episode length while training when ``env_kwargs`` has no
            ``max_cycles``; ``None`` keeps the env's. The saved evaluation config keeps
            the env's own horizon (default 1000 steps).
        normalize: wrap in ``VecNormalize`` (observations and rewards).
        checkpoint_every: save a checkpoint every this many timesteps (0: never),
            rounded down to a multiple of the SB3 slots (``n_envs`` × N timesteps per
            vector step; at least one vector step): :func:`checkpoint_period`.
        progress_bar: show SB3's tqdm/rich progress bar (per timestep); silently none
            when tqdm or rich is not installed.
        torch_threads: ``torch.set_num_threads`` during training (restored after), in
            [1, 1024].
        safety_filter_kwargs: keywords of ``SafetyFilterWrapper``.
        belief_kwargs: keywords of ``BeliefObservationWrapper``.
        verbose: SB3 verbosity (1 prints the log table to stdout).
        arch: ``"mlp"`` (SB3's ``MlpPolicy`` over the flat observation, fixed N) or
            ``"set"`` (PPO only: :class:`~fov_marl.training.set_policy.SetActorCriticPolicy`,
            permutation-invariant and size-independent, exportable for
            ``make_policy("learned", env, path=...)``; observations are not normalised,
            rewards are). ``policy_kwargs={"hidden": k}`` sets its width (64).
        ctde: ``arch="set"`` only: the critic also reads the global state, agent-centric
            (:class:`~fov_marl.training.set_policy.CtdeVecEnvWrapper`).
        eta_level_coef: weight of the coverage-level reward term, in [0, 1000]
            (:class:`~fov_marl.training.set_policy.CtdeVecEnvWrapper`; 0: the env's reward).
        intervention_coef: weight of the penalty on the filter's action change, in
            [0, 1000] (behind the safety filter).
        blind_motion_coef: weight of the penalty on driving outside the camera's sector,
            in [0, 1000] (no filter needed).
        action_cost_coef: weight of the action energy cost, in [0, 1000].
        fov_keep_coef: weight of the penalty on neighbours closer than 3 D_s outside the
            camera sector, in [0, 1000] (exact positions; no filter needed).
        init_from: a ``model.zip`` of the same architecture and spaces whose parameters
            start this run (fine-tuning, e.g. behind the filter after pre-training
            without it).

    Returns:
        Path of the saved ``model.zip``. Ctrl-C stops training early and still saves
        (``config.json`` then says ``"interrupted": true``).

    Raises:
        ValueError: unknown algo/scenario, bad numbers, invalid config fields, unknown or
            invalid hyper-parameters, an unusable ``out_dir`` (all checked before any
            work; :class:`~fov_marl.validation.ConfigError` names the argument).
    """
    # Every argument is checked before any work (and before out_dir is created).
    algo = check_choice("algo", algo, sorted(ALGOS))
    scenario = check_choice("scenario", scenario, sorted(SCENARIOS))
    timesteps = check_int("timesteps", timesteps, 1, 10**12)
    n_envs = check_int("n_envs", n_envs, 1, 1024)
    workers = check_int("workers", workers, 1, int(n_envs), note="(at most n_envs)")
    checkpoint_every = check_int("checkpoint_every", checkpoint_every, 0)
    torch_threads = check_int("torch_threads", torch_threads, 1, 1024)
    seed = check_int("seed", seed, 0, MAX_SEED)
    verbose = check_int("verbose", verbose, 0, 2)
    safety_filter = check_bool("safety_filter", safety_filter)
    belief = check_bool("belief", belief)
    if workers > 1 and belief:
        raise ConfigError(
            f"workers = {workers} needs the vector env; with belief the copies are stepped "
            "one by one (use workers = 1)"
        )
    normalize = check_bool("normalize", normalize)
    arch = check_choice("arch", arch, ("mlp", "set"))
    ctde = check_bool("ctde", ctde)
    if arch == "set" and algo != "ppo":
        raise ConfigError(f"arch 'set' needs algo 'ppo', got algo {algo!r}")
    if ctde and arch != "set":
        raise ConfigError("ctde needs arch 'set' (the MLP actor would read the critic's state)")
    eta_level_coef = check_real("eta_level_coef", eta_level_coef, 0.0, 1e3)
    intervention_coef = check_real("intervention_coef", intervention_coef, 0.0, 1e3)
    blind_motion_coef = check_real("blind_motion_coef", blind_motion_coef, 0.0, 1e3)
    action_cost_coef = check_real("action_cost_coef", action_cost_coef, 0.0, 1e3)
    fov_keep_coef = check_real("fov_keep_coef", fov_keep_coef, 0.0, 1e3)
    if init_from is not None:
        init_path = Path(init_from)
        if init_path.is_dir():
            init_path = init_path / "model.zip"
        if not init_path.is_file():
            raise ConfigError(f"init_from must be an existing model.zip, got {str(init_from)!r}")
        init_from = init_path
    progress_bar = check_bool("progress_bar", progress_bar) and _have_progress_bar()
    if train_max_cycles is not None:
        train_max_cycles = check_int("train_max_cycles", train_max_cycles, 1, note="(or None)")
    out = check_out_dir("out_dir", out_dir)
    overrides = validate_hyperparams(algo, hyperparams)
    if env_kwargs is not None and not isinstance(env_kwargs, dict):
        raise ConfigError(f"env_kwargs must be a dict or None, got {describe(env_kwargs)}")
    from fov_marl.wrappers import SafetyFilterWrapper
    from fov_marl.wrappers.belief import BeliefObservationWrapper

    safety_filter_kwargs = check_wrapper_kwargs(
        "safety_filter_kwargs", safety_filter_kwargs, SafetyFilterWrapper, on=bool(safety_filter)
    )
    belief_kwargs = check_wrapper_kwargs(
        "belief_kwargs", belief_kwargs, BeliefObservationWrapper, on=bool(belief), switch="belief"
    )

    env_kwargs = dict(env_kwargs or {})
    train_kwargs = dict(env_kwargs)
    if "max_cycles" not in env_kwargs and train_max_cycles is not None:
        train_kwargs["max_cycles"] = int(train_max_cycles)
    wrap = {
        "safety_filter": bool(safety_filter),
        "safety_filter_kwargs": dict(safety_filter_kwargs or {}),
        "belief": bool(belief),
        "belief_kwargs": dict(belief_kwargs or {}),
    }
    # Validate config fields and wrappers now, with a clear error, before SB3 starts.
    probe = build_env(scenario, train_kwargs, **wrap)
    train_config = probe.unwrapped.config
    eval_config = train_config.replace(
        max_cycles=env_kwargs.get("max_cycles", make_config(scenario=scenario).max_cycles)
    )
    n_agents = len(probe.possible_agents)
    agent0 = probe.possible_agents[0]
    obs_dim = int(np.prod(probe.observation_space(agent0).shape))
    act_dim = int(np.prod(probe.action_space(agent0).shape))
    probe.close()
    if ctde:
        obs_dim += 5 * (n_agents - 1)

    hp = _merged_hyperparams(algo, overrides)
    _check_buffer(algo, hp, int(n_envs) * n_agents, obs_dim, act_dim)
    sb3_kwargs = _to_sb3_kwargs(hp)
    policy_class: Any = "MlpPolicy"
    wrap_adapter = None
    feature_scales = None
    if arch == "set":
        from fov_marl.training.set_policy import SetActorCriticPolicy, default_feature_scales

        policy_class = SetActorCriticPolicy
        feature_scales = default_feature_scales(train_config)
        pk = dict(sb3_kwargs.get("policy_kwargs") or {})
        pk.pop("net_arch", None)
        pk.pop("activation_fn", None)
        pk.setdefault("bounded_mean", True)
        pk.update(ctde=ctde, feature_scales=feature_scales)
        sb3_kwargs["policy_kwargs"] = pk
    shaping = (
        eta_level_coef,
        intervention_coef,
        blind_motion_coef,
        action_cost_coef,
        fov_keep_coef,
    )
    if ctde or any(shaping):
        from fov_marl.training.set_policy import CtdeVecEnvWrapper

        def wrap_adapter(adapter: Any) -> Any:
            return CtdeVecEnvWrapper(
                adapter,
                n_agents,
                ctde=ctde,
                eta_level_coef=eta_level_coef,
                intervention_coef=intervention_coef,
                blind_motion_coef=blind_motion_coef,
                fov_deg=train_config.fov_deg,
                action_cost_coef=action_cost_coef,
                fov_keep_coef=fov_keep_coef,
                keep_distance_m=3.0 * train_config.safety_distance_m,
            )

    out.mkdir(parents=True, exist_ok=True)

    prev_threads = torch.get_num_threads()
    torch.set_num_threads(int(torch_threads))
    try:

        def factory() -> Any:
            return build_env(scenario, train_kwargs, **wrap)

        _, venv = make_training_vec_env(
            int(n_envs),
            factory,
            normalize=normalize,
            gamma=float(hp.get("gamma", 0.99)),
            norm_obs=arch == "mlp",
            wrap_adapter=wrap_adapter,
            workers=int(workers),
        )
        model: BaseAlgorithm = ALGOS[algo](
            policy_class, venv, seed=int(seed), device="cpu", verbose=verbose, **sb3_kwargs
        )
        if init_from is not None:
            try:
                model.set_parameters(str(init_from), exact_match=True, device="cpu")
            except _LOAD_ERRORS as exc:
                this_run = {
                    "algo": algo,
                    "arch": arch,
                    "ctde": bool(ctde),
                    "belief": bool(belief),
                    "n_agents": n_agents,
                    "hyperparams.policy_kwargs": _jsonable(hp.get("policy_kwargs")),
                }
                raise ValueError(
                    f"init_from {init_from}: not a model of this architecture and these "
                    f"spaces ({_init_mismatch(init_from, this_run, exc)})"
                ) from None
        formats: list[Any] = [
            TensorBoardOutputFormat(str(_next_run_dir(out / "tb", algo.upper()))),
            CSVOutputFormat(str(out / "progress.csv")),
        ]
        if verbose:
            formats.append(HumanOutputFormat(sys.stdout))
        logger = Logger(folder=str(out), output_formats=formats)
        model.set_logger(logger)
        metrics_cb = FovMetricsCallback(n_agents)
        callbacks: list[BaseCallback] = [metrics_cb]
        if checkpoint_every:
            callbacks.append(
                CheckpointCallback(
                    save_freq=checkpoint_period(checkpoint_every, venv.num_envs) // venv.num_envs,
                    save_path=str(out / "checkpoints"),
                    name_prefix="model",
                    save_vecnormalize=normalize,
                )
            )
        t0 = time.perf_counter()
        interrupted = False
        try:
            with warnings.catch_warnings():
                # SB3's bar is tqdm.rich, which warns that it is experimental
                warnings.filterwarnings("ignore", message=".*rich is experimental.*")
                # the whole rollouts SB3 runs anyway (the same training: the learning
                # rate and clip range are constants), so its progress bar ends at 100%
                model.learn(
                    total_timesteps=effective_timesteps(algo, timesteps, venv.num_envs, hp),
                    callback=CallbackList(callbacks),
                    progress_bar=progress_bar,
                )
        except KeyboardInterrupt:  # Ctrl-C: keep what was learned so far
            interrupted = True
        wall = time.perf_counter() - t0
        model_path = out / "model.zip"
        model.save(str(model_path))
        if normalize:
            venv.save(str(out / "vecnormalize.pkl"))
        logger.close()
        venv.close()
    finally:
        torch.set_num_threads(prev_threads)

    eval_kwargs = eval_config.to_dict()
    eval_kwargs.pop("scenario")
    if eval_kwargs.get("initial_poses") is None:
        eval_kwargs.pop("initial_poses", None)
    train_env_config = train_config.to_dict()
    config = {
        "format": CONFIG_FORMAT,
        "algo": algo,
        "scenario": scenario,
        "env_kwargs": eval_kwargs,
        "train_env_config": train_env_config,
        "n_agents": n_agents,
        "wrappers": [w for w in ("safety_filter", "belief") if wrap[w]],
        **wrap,
        "normalize": bool(normalize),
        "arch": arch,
        "ctde": bool(ctde),
        "eta_level_coef": float(eta_level_coef),
        "intervention_coef": float(intervention_coef),
        "blind_motion_coef": float(blind_motion_coef),
        "action_cost_coef": float(action_cost_coef),
        "fov_keep_coef": float(fov_keep_coef),
        "init_from": None if init_from is None else str(init_from),
        "feature_scales": feature_scales,
        "hyperparams": _jsonable(hp),
        "seed": int(seed),
        "timesteps": int(timesteps),
        "timesteps_done": int(model.num_timesteps),
        "interrupted": interrupted,
        "n_envs": int(n_envs),
        "workers": int(workers),
        "torch_threads": int(torch_threads),
        "train_wall_s": wall,
        "samples_per_s": model.num_timesteps / max(wall, 1e-9),
        "episodes": metrics_cb.episodes,
        "last_episode_metrics": metrics_cb.last_episode_metrics,
        "versions": {
            "stable_baselines3": stable_baselines3.__version__,
            "torch": torch.__version__,
            "numpy": np.__version__,
            "python": platform.python_version(),
        },
    }
    (out / "config.json").write_text(json.dumps(_jsonable(config), indent=2) + "\n")
    return model_path


# ------------------------------------------------------------------ reloading
class LearnedPolicy:
    """A trained shared policy, used like a baseline: ``reset(seed)``, ``act(obs)``.

    ``act`` takes the observations the *evaluation env* emits, i.e. the scenario env
    behind the safety filter if the policy was trained with it
    (:meth:`make_env` builds that env). A policy trained with belief features computes
    them itself (:class:`fov_marl.wrappers.belief.BeliefFeaturizer`, fed with each
    robot's own observations only, as the training wrapper was), so ``act`` still
    takes the env's plain observations; with the wrapper's default ``init="known"``
    it reads the start poses from the env given to :meth:`bind` (the paper's
    assumption, VII-B).

    Actions are deterministic (the mean of the policy's Gaussian), float32 in
    ``[-1, 1]``.

    Attributes:
        algo: ``"ppo"`` or ``"sac"``.
        scenario: the scenario it was trained on.
        env_kwargs: the evaluation config fields (``config.json``'s ``env_kwargs``).
        safety_filter: trained behind :class:`~fov_marl.wrappers.SafetyFilterWrapper`.
        safety_filter_kwargs: the wrapper's keywords.
        belief: uses belief features (computed by the policy itself).
        belief_kwargs: the belief wrapper's keywords.
        n_agents: the team size (the observation size depends on it).
        config: the whole ``config.json``.
        model: the stable-baselines3 model.
    """

    def __init__(self, model: BaseAlgorithm, config: dict[str, Any], obs_norm: Any | None):
        self.model = model
        self.config = config
        self.algo: str = config["algo"]
        self.scenario: str = config["scenario"]
        self.env_kwargs: dict[str, Any] = dict(config["env_kwargs"])
        self.safety_filter: bool = bool(config.get("safety_filter", False))
        self.safety_filter_kwargs: dict[str, Any] = dict(config.get("safety_filter_kwargs", {}))
        self.belief: bool = bool(config.get("belief", False))
        self.belief_kwargs: dict[str, Any] = dict(config.get("belief_kwargs", {}))
        self.n_agents: int = int(config["n_agents"])
        self._obs_norm = obs_norm
        self._env: Any | None = None
        self._featurizer: Any | None = None
        self._seed: int | None = None
        self._needs_reset = True
        self._last_actions: dict[str, np.ndarray] | None = None

    def make_env(self, render_mode: str | None = None, **overrides: Any) -> Any:
        """The evaluation env: scenario + ``env_kwargs`` (+ safety filter), no belief wrapper.

        ``overrides`` change config fields (e.g. ``max_cycles``); changing ``n_agents``
        raises ``ValueError`` because the observation size depends on it.
        """
        if "n_agents" in overrides and not (
            is_integer(overrides["n_agents"]) and int(overrides["n_agents"]) == self.n_agents
        ):
            raise ValueError(
                f"n_agents must be {self.n_agents} (the policy's observation size depends on "
                f"it), got {overrides['n_agents']}"
            )
        env = build_env(
            self.scenario,
            {**self.env_kwargs, **overrides},
            safety_filter=self.safety_filter,
            safety_filter_kwargs=self.safety_filter_kwargs,
            render_mode=render_mode,
        )
        self.bind(env)
        return env

    def bind(self, env: Any) -> LearnedPolicy:
        """Attach the evaluation env (needed for belief features); returns ``self``.

        Usable as a policy factory: ``run_episode(..., policy=learned.bind, ...)``.

        Raises:
            ValueError: the env's agents or observation size differ from the training env's.
        """
        agents = list(env.possible_agents)
        if len(agents) != self.n_agents:
            raise ValueError(
                f"env has {len(agents)} agents; this policy was trained with n_agents = "
                f"{self.n_agents}"
            )
        self._env = env
        self._featurizer = None
        self._needs_reset = True
        return self

    def factory(self, env: Any) -> LearnedPolicy:
        """Policy factory ``f(env) -> Policy`` for :func:`fov_marl.evaluation.run_episode`
        (same as :meth:`bind`)."""
        return self.bind(env)

    @property
    def name(self) -> str:
        """``"<algo>[+filter][+belief]"``, for tables."""
        return self.algo + "+filter" * self.safety_filter + "+belief" * self.belief

    def reset(self, seed: int | None = None) -> None:
        """Start an episode; belief trackers are re-seeded from ``seed`` at the next ``act``."""
        self._seed = check_seed("seed", seed)
        self._needs_reset = True
        self._last_actions = None

    def _features(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        if not self.belief:
            return obs
        from fov_marl.wrappers.belief import BeliefFeaturizer

        if self._env is None:
            self._env = self._private_env()
        if self._featurizer is None:
            self._featurizer = BeliefFeaturizer(self._env, **self.belief_kwargs)
        if self._needs_reset or self._last_actions is None:
            self._featurizer.reset(obs, seed=self._seed)
        else:
            self._featurizer.step(self._last_actions, obs)
        return self._featurizer.augment(obs)

    def _private_env(self) -> Any:
        """An env of the training config, to size the trackers when :meth:`bind` was not
        called; it is never stepped, so it cannot provide start poses."""
        if self.belief_kwargs.get("init", "known") == "known":
            raise ValueError(
                "this policy uses belief features initialised at the known start poses "
                "(init='known'); call policy.bind(env) with the evaluation env first"
            )
        return build_env(self.scenario, self.env_kwargs, safety_filter=False)

    def act(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Deterministic actions ``(3,)`` float32 for every agent in ``obs``."""
        feats = self._features(obs)
        self._needs_reset = False
        agents = [a for a in feats]
        if not agents:
            return {}
        batch = np.stack([np.asarray(feats[a], dtype=np.float32) for a in agents])
        if self.config.get("ctde", False):  # the critic's entries: never read by the actor
            batch = np.concatenate(
                [batch, np.zeros((len(batch), 5 * (self.n_agents - 1)), np.float32)], axis=1
            )
        if self._obs_norm is not None:
            batch = self._obs_norm.normalize_obs(batch).astype(np.float32)
        actions, _ = self.model.predict(batch, deterministic=True)
        actions = np.clip(np.asarray(actions, dtype=np.float32), -1.0, 1.0)
        out = {a: actions[i].copy() for i, a in enumerate(agents)}
        self._last_actions = out
        return out


def _find_config(model_path: Path) -> Path:
    for d in (model_path.parent, model_path.parent.parent):
        if (d / "config.json").is_file():
            return d / "config.json"
    raise ValueError(
        f"{model_path}: no config.json beside it or in its parent folder (a model saved by "
        "`fov-marl train` has one)"
    )


def _find_vecnormalize(model_path: Path) -> Path | None:
    if model_path.name == "model.zip":
        p = model_path.parent / "vecnormalize.pkl"
        return p if p.is_file() else None
    # checkpoint: checkpoints/model_<t>_steps.zip -> model_vecnormalize_<t>_steps.pkl
    stem = model_path.stem
    if stem.startswith("model_"):
        p = model_path.parent / f"model_vecnormalize_{stem[len('model_') :]}.pkl"
        if p.is_file():
            return p
    return None


def _read_config(path: Path) -> dict[str, Any]:
    """``config.json`` written by :func:`train`, checked field by field."""
    try:
        config = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: not a readable JSON file ({_reason(exc)})") from None
    if not isinstance(config, dict):
        raise ValueError(f"{path}: must hold a JSON object, got {type(config).__name__}")
    if config.get("format") != CONFIG_FORMAT:
        raise ValueError(
            f"{path}: format must be {CONFIG_FORMAT!r} (written by `fov-marl train`), "
            f"got {config.get('format')!r}"
        )
    try:
        check_choice("algo", config.get("algo"), sorted(ALGOS))
        check_choice("scenario", config.get("scenario"), sorted(SCENARIOS))
        check_int("n_agents", config.get("n_agents"), 1, 256)
        for key in ("env_kwargs", "safety_filter_kwargs", "belief_kwargs"):
            if not isinstance(config.get(key, {}), dict):
                raise ConfigError(f"{key} must be a JSON object, got {describe(config[key])}")
        for key in ("safety_filter", "belief", "normalize"):
            check_bool(key, config.get(key, False))
    except ConfigError as exc:
        raise ValueError(f"{path}: {exc}") from None
    return config


def _init_mismatch(init_from: Path, this_run: dict[str, Any], exc: BaseException) -> str:
    """Why ``init_from`` does not fit this run, short: the settings that differ, read from
    the ``config.json`` saved beside it (``n_agents`` only where the MLP's input size
    depends on it), else the loader's message cut to 200 characters."""
    try:
        saved = json.loads((init_from.parent / "config.json").read_text())
    except (OSError, ValueError):
        saved = None
    if isinstance(saved, dict):
        saved_hp = saved.get("hyperparams")
        saved = {
            **saved,
            "hyperparams.policy_kwargs": (
                saved_hp.get("policy_kwargs") if isinstance(saved_hp, dict) else None
            ),
        }
        skip = {"n_agents"} if this_run.get("arch") == "set" else set()
        diff = [
            f"{key} {saved[key]!r} there, {value!r} here"
            for key, value in this_run.items()
            if key in saved and key not in skip and saved[key] != value
        ]
        if diff:
            return "; ".join(diff)
    text = _reason(exc)
    return text if len(text) <= 200 else text[:197] + "..."


def _reason(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


#: what loading a damaged or foreign file raises inside SB3, torch, zipfile or pickle
_LOAD_ERRORS = (
    AssertionError,
    AttributeError,
    EOFError,
    ImportError,
    IndexError,
    KeyError,
    OSError,
    RuntimeError,
    TypeError,
    ValueError,
    pickle.UnpicklingError,
    zipfile.BadZipFile,
)


def load_policy(path: str | os.PathLike, env: Any | None = None) -> LearnedPolicy:
    """Load ``model.zip`` (or a run folder, or a checkpoint) saved by :func:`train`.

    Args:
        path: ``DIR/model.zip``, ``DIR``, or ``DIR/checkpoints/model_<t>_steps.zip``.
        env: optional evaluation env to :meth:`LearnedPolicy.bind`.

    Raises:
        ValueError: a missing file, a config written by an unknown format, or a file
            that is not what :func:`train` saved (truncated, empty, corrupt, another
            program's zip, a model whose spaces differ from its config's env); the
            message names the file and says what is wrong.
    """
    p = Path(path)
    if p.is_dir():
        p = p / "model.zip"
    if not p.is_file():
        raise ValueError(f"policy file {p} does not exist")
    if not zipfile.is_zipfile(p):
        size = p.stat().st_size
        what = "empty" if size == 0 else f"not a zip archive ({size} bytes; truncated or corrupt?)"
        raise ValueError(f"{p}: {what}; expected a model.zip saved by `fov-marl train`")
    config = _read_config(_find_config(p))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # SB3 warns about version mismatches
            model = ALGOS[config["algo"]].load(str(p), device="cpu")
    except _LOAD_ERRORS as exc:
        raise ValueError(
            f"{p}: not a {config['algo'].upper()} model saved by `fov-marl train` ({_reason(exc)})"
        ) from None
    obs_norm = None
    if config.get("normalize", False):
        vn_path = _find_vecnormalize(p)
        if vn_path is None:
            raise ValueError(f"the policy was trained with normalisation but no stats beside {p}")
        try:
            with open(vn_path, "rb") as f:
                obs_norm = pickle.load(f)
        except _LOAD_ERRORS as exc:
            raise ValueError(f"{vn_path}: not normalisation statistics ({_reason(exc)})") from None
        if not callable(getattr(obs_norm, "normalize_obs", None)):
            raise ValueError(
                f"{vn_path}: not normalisation statistics (a {type(obs_norm).__name__})"
            )
        obs_norm.training = False
        obs_norm.norm_reward = False
    policy = LearnedPolicy(model, config, obs_norm)
    _check_model_spaces(policy, p)
    if env is not None:
        policy.bind(env)
    return policy


def _check_model_spaces(policy: LearnedPolicy, path: Path) -> None:
    """The model's observation/action sizes must match the env its config describes."""
    try:
        env = build_env(
            policy.scenario,
            policy.env_kwargs,
            safety_filter=False,
            belief=policy.belief,
            belief_kwargs=policy.belief_kwargs,
        )
    except ValueError as exc:
        raise ValueError(f"{path}: its config.json does not describe a valid env ({exc})") from None
    agent = env.possible_agents[0]
    want_obs = tuple(env.observation_space(agent).shape)
    if policy.config.get("ctde", False):
        want_obs = (want_obs[0] + 5 * (policy.n_agents - 1),)
    want_act = tuple(env.action_space(agent).shape)
    env.close()
    got_obs = tuple(getattr(policy.model.observation_space, "shape", ()) or ())
    got_act = tuple(getattr(policy.model.action_space, "shape", ()) or ())
    if got_obs != want_obs or got_act != want_act:
        raise ValueError(
            f"{path}: the model takes observations of shape {got_obs} and gives actions of "
            f"shape {got_act}, but its config.json describes an env with {want_obs} and "
            f"{want_act}"
        )
