"""RLlib: the fov envs as RLlib multi-agent envs, and a shared-policy PPO config.

>>> import ray
>>> from fov_marl.integrations.rllib import ppo_config
>>> ray.init(num_cpus=2)
>>> algo = ppo_config({"n_agents": 4, "max_cycles": 200}).build_algo()
>>> result = algo.train()            # one iteration; see examples/rllib_ppo.py

RLlib's ``ParallelPettingZooEnv`` wraps the fov ParallelEnvs as they are (their infos
are flat, :mod:`fov_marl.infos`). This module adds:

* :func:`make_rllib_env` ``(env_config) -> ParallelPettingZooEnv``: ``env_config`` is a
  dict with ``scenario`` (``"coverage"``/``"crossing"``), ``safety_filter``,
  ``belief``, ``filter_kwargs``, ``belief_kwargs`` and scenario config fields
  (``n_agents``, ``fov_deg``, ``max_cycles``, ...), as
  :func:`fov_marl.integrations.make_parallel_env` takes them;
* :func:`register_rllib_env` registers it with Ray Tune under ``"fov_marl"``;
* :func:`ppo_config`: a PPO config (RLlib's new API stack) with **one policy shared by
  all robots** (``"shared"``: the robots are interchangeable, their observations are
  egocentric), local sampling by default (``num_env_runners=0``), CPU only.

Ray is imported only when these functions are called.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from fov_marl.integrations.common import make_parallel_env, require
from fov_marl.validation import MAX_SEED, check_int, check_real, describe

__all__ = ["ENV_NAME", "POLICY_ID", "make_rllib_env", "ppo_config", "register_rllib_env"]

#: Name under which :func:`register_rllib_env` registers the env.
ENV_NAME = "fov_marl"
#: The one policy (RLModule) every robot uses.
POLICY_ID = "shared"


def make_rllib_env(env_config: Mapping[str, Any] | None = None) -> Any:
    """RLlib ``ParallelPettingZooEnv`` of a fov env built from ``env_config`` (module doc).

    Raises:
        ValueError: an ``env_config`` that is not a dict or None, or a bad scenario, flag
            or config field (named).
        ImportError: ray[rllib] is not installed.
    """
    env = _parallel_env(env_config)  # validate before the (slow) ray import
    require("ray.rllib", "rllib")
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

    return ParallelPettingZooEnv(env)


def _env_config(env_config: Mapping[str, Any] | None) -> dict[str, Any]:
    """A plain dict copy of ``env_config`` (None: ``{}``), or ValueError if it is no dict."""
    if env_config is not None and not isinstance(env_config, Mapping):
        raise ValueError(f"env_config must be a dict or None, got {describe(env_config)}")
    return dict(env_config or {})  # RLlib's EnvContext is a dict subclass


def _parallel_env(env_config: Mapping[str, Any] | None) -> Any:
    cfg = _env_config(env_config)
    scenario = cfg.pop("scenario", "coverage")
    return make_parallel_env(scenario, **cfg)


def register_rllib_env(name: str = ENV_NAME) -> str:
    """Register :func:`make_rllib_env` with Ray Tune under ``name``; returns ``name``."""
    require("ray.tune", "rllib")
    from ray.tune.registry import register_env

    register_env(name, make_rllib_env)
    return name


def ppo_config(
    env_config: Mapping[str, Any] | None = None,
    *,
    num_env_runners: int = 0,
    train_batch_size: int = 4000,
    minibatch_size: int = 500,
    num_epochs: int = 5,
    lr: float = 3e-4,
    gamma: float = 0.99,
    hidden: tuple[int, ...] = (128, 128),
    seed: int | None = 0,
) -> Any:
    """An RLlib ``PPOConfig`` training one shared policy on a fov env.

    Args:
        env_config: a dict or None, see :func:`make_rllib_env` (validated here by
            building one env).
        num_env_runners: remote sampling workers (0: sample in the driver).
        train_batch_size: env steps sampled per iteration (each gives N agent-steps;
            ``train_batch_size_per_learner``, RLlib counts env steps), in [1, inf).
        minibatch_size: SGD minibatch, in [1, train_batch_size].
        num_epochs: SGD passes per iteration, in [1, inf).
        lr, gamma: PPO learning rate, in (0, 10], and discount, in [0, 1].
        hidden: hidden layer sizes of the policy and value MLPs, each in [1, 65536].
        seed: RLlib's ``debugging(seed=...)``, in [0, 2^31 - 1], or None.

    Raises:
        ValueError: a bad argument (named with its range), an ``env_config`` that is not
            a dict or None, or a bad env config field.
        ImportError: ray[rllib] is not installed.
    """
    check_int("num_env_runners", num_env_runners, 0)
    check_int("train_batch_size", train_batch_size, 1)
    check_int("minibatch_size", minibatch_size, 1, train_batch_size)
    check_int("num_epochs", num_epochs, 1)
    lr = check_real("lr", lr, 0.0, 10.0, lo_open=True)
    gamma = check_real("gamma", gamma, 0.0, 1.0)
    if isinstance(hidden, str | bytes) or not isinstance(hidden, Sequence) or not hidden:
        raise ValueError(f"hidden must be a non-empty sequence of layer sizes, got {hidden!r}")
    hidden = tuple(check_int(f"hidden[{i}]", h, 1, 65536) for i, h in enumerate(hidden))
    if seed is not None:
        seed = check_int("seed", seed, 0, MAX_SEED, note="(or None)")
    env_config = _env_config(env_config)
    _parallel_env(env_config).close()  # a bad field fails here, not in a worker
    require("ray.rllib", "rllib")
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    register_rllib_env()
    return (
        PPOConfig()
        .environment(ENV_NAME, env_config=env_config)
        .framework("torch")
        .env_runners(num_env_runners=num_env_runners, num_gpus_per_env_runner=0)
        .learners(num_learners=0, num_gpus_per_learner=0)
        .multi_agent(
            policies={POLICY_ID},
            policy_mapping_fn=_shared_policy,
        )
        .rl_module(
            rl_module_spec=MultiRLModuleSpec(rl_module_specs={POLICY_ID: RLModuleSpec()}),
            model_config=DefaultModelConfig(
                fcnet_hiddens=list(hidden), fcnet_activation="tanh", vf_share_layers=False
            ),
        )
        .training(
            train_batch_size_per_learner=train_batch_size,
            minibatch_size=minibatch_size,
            num_epochs=num_epochs,
            lr=lr,
            gamma=gamma,
        )
        .debugging(seed=seed)
    )


def _shared_policy(agent_id: Any, episode: Any = None, **kwargs: Any) -> str:
    """Every robot maps to the one shared policy."""
    return POLICY_ID
