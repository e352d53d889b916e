"""BenchMARL task classes (imports benchmarl; use :mod:`fov_marl.integrations.benchmarl`)."""

from __future__ import annotations

import copy
import itertools
import multiprocessing as mp
import os
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from benchmarl.environments import task_config_registry, tasks
from benchmarl.environments.common import Task
from benchmarl.environments.pettingzoo.common import PettingZooClass
from benchmarl.utils import _read_yaml_config
from tensordict import TensorDictBase
from torchrl.envs import EnvBase

from fov_marl.config import ScenarioConfig, make_config
from fov_marl.integrations.common import make_parallel_env
from fov_marl.integrations.torchrl import GROUP, wrap
from fov_marl.validation import describe

__all__ = ["ENV_NAME", "FovMarlClass", "FovMarlTask", "copy_seed"]

ENV_NAME = "fov_marl"
#: Task config keys that are not scenario config fields.
WRAPPER_KEYS = ("safety_filter", "belief", "filter_kwargs", "belief_kwargs")


class FovMarlClass(PettingZooClass):
    """A fov_marl scenario as a BenchMARL task (continuous actions, global state).

    ``config`` holds scenario config fields (``n_agents``, ``fov_deg``, ``max_cycles``,
    ...; the paper's values by default) and the wrapper keys ``safety_filter``,
    ``belief`` (bools), ``filter_kwargs``, ``belief_kwargs`` (dicts). It is validated
    here, so a bad field raises ``ValueError`` naming it before any env is built.
    """

    def __init__(self, name: str, config: dict[str, Any] | None) -> None:
        if config is not None and not isinstance(config, Mapping):
            raise ValueError(f"task config must be a dict of fields, got {describe(config)}")
        super().__init__(name=name, config=dict(config or {}))
        self._check()

    @property
    def scenario(self) -> str:
        return self.name.lower()

    @property
    def scenario_config(self) -> ScenarioConfig:
        """The validated scenario config of the task's current ``config`` (read anew:
        ``task.config.update({...})``, BenchMARL's way to change a task, is seen)."""
        if "scenario" in self.config:
            given = self.config["scenario"]
            hint = f"; use FovMarlTask.{given.upper()}" if given in ("coverage", "crossing") else ""
            raise ValueError(
                f"task config: the scenario is fixed by the task ({self.name}), got "
                f"scenario={given!r}{hint}"
            )
        fields = {k: v for k, v in self.config.items() if k not in WRAPPER_KEYS}
        return make_config(scenario=self.scenario, **fields)

    def _check(self) -> None:
        """Fail here, not in a collector worker: validate and build (and discard) one env."""
        self.scenario_config  # noqa: B018 - validates the scenario fields
        make_parallel_env(self.scenario, **copy.deepcopy(self.config)).close()

    def get_env_fun(
        self, num_envs: int, continuous_actions: bool, seed: int | None, device: Any
    ) -> Callable[[], EnvBase]:
        """The env factory of BenchMARL's training and evaluation envs. Its k-th call
        (k = 0, 1, ...) builds an env whose first reset (made by TorchRL's wrapper while it
        builds the env; see :func:`fov_marl.integrations.torchrl.wrap`) uses ``seed + k``:
        the copies of a ``SerialEnv(n, make)`` (how BenchMARL batches the training env)
        start from different configurations, as the copies of a fov_marl vector env do, instead of
        all from ``seed``. In the worker processes of a ``ParallelEnv``
        (``parallel_collection=True``) each worker counts its own calls, so the seed also
        mixes in the worker's process identity (:func:`copy_seed`): distinct copies, the
        same in every run of the same script. ``seed=None`` leaves every copy to OS
        entropy."""
        if not continuous_actions:
            raise ValueError("fov_marl tasks have continuous actions only (Box(-1, 1, (3,)))")
        self._check()  # the config may have changed since the task was built
        config = copy.deepcopy(self.config)
        scenario = self.scenario
        calls = itertools.count()
        origin = os.getpid()

        def make() -> EnvBase:
            k = next(calls)
            return wrap(
                make_parallel_env(scenario, **copy.deepcopy(config)),
                seed=None if seed is None else copy_seed(seed, k, origin),
                device=device,
            )

        return make

    def supports_continuous_actions(self) -> bool:
        return True

    def supports_discrete_actions(self) -> bool:
        return False

    def has_state(self) -> bool:
        return True

    def has_render(self, env: EnvBase) -> bool:
        return False  # rendering would pull torchvision's video writer

    def max_steps(self, env: EnvBase) -> int:
        return int(self.scenario_config.max_cycles)

    @staticmethod
    def env_name() -> str:
        return ENV_NAME

    @staticmethod
    def log_info(batch: TensorDictBase) -> dict[str, float]:
        """Episode-end ground truth: mean final η (coverage), arrivals (crossing),
        collision events, over the episodes that ended in this batch."""
        done = batch.get(("next", "done"))[..., 0]
        if not bool(done.any()):
            return {}
        info = batch.get(("next", GROUP, "info"))
        out: dict[str, float] = {}
        for key, name in (
            ("metrics/eta", "final_eta"),
            ("metrics/arrived_ever", "final_arrived_ever"),
            ("metrics/collisions_total", "final_collisions_total"),
            ("metrics/safety_violations_total", "final_safety_violations_total"),
        ):
            if key in info.keys():
                out[f"collection/fov/{name}"] = float(info.get(key)[..., 0][done].float().mean())
        return out


def copy_seed(seed: int, k: int, origin_pid: int) -> int:
    """The seed of the k-th env a factory built in the process ``origin_pid`` builds:
    ``seed + k`` there; in another process (a worker of a parallel collector, which got
    a pickled copy of the factory and counts from 0 again) a seed drawn from
    ``SeedSequence(seed, spawn_key=(*identity, k))``, with ``identity`` the worker's
    ``multiprocessing`` identity (its start order under its parent: distinct per worker,
    the same in every run of the same script)."""
    if os.getpid() == origin_pid:
        return int(seed) + int(k)
    identity = tuple(getattr(mp.current_process(), "_identity", ()) or (os.getpid(),))
    state = np.random.SeedSequence(int(seed), spawn_key=(*identity, int(k))).generate_state(1)
    return int(state[0] & 0x7FFFFFFF)


class FovMarlTask(Task):
    """The fov_marl BenchMARL tasks: ``FovMarlTask.COVERAGE``, ``FovMarlTask.CROSSING``."""

    COVERAGE = None
    CROSSING = None

    @staticmethod
    def associated_class() -> type[FovMarlClass]:
        return FovMarlClass

    def get_from_yaml(self, path: str | None = None) -> FovMarlClass:
        """The task with the paper's defaults (``path=None``) or a YAML file's config."""
        if path is None:
            return self.get_task(config={})
        import yaml

        with open(path, encoding="utf-8") as f:
            raw = yaml.safe_load(f)
        if raw is not None and not isinstance(raw, dict):  # BenchMARL's reader needs a dict
            raise ValueError(f"task config {path} must be a mapping, got {describe(raw)}")
        config = _read_yaml_config(path)
        if not isinstance(config, dict):
            raise ValueError(f"task config {path} must be a mapping, got {describe(config)}")
        return self.get_task(config=config)


def register() -> None:
    """Add the tasks to BenchMARL's registries (``"fov_marl/coverage"``, ...); idempotent."""
    if FovMarlTask not in tasks:
        tasks.append(FovMarlTask)
    for task in FovMarlTask:
        task_config_registry[f"{ENV_NAME}/{task.name.lower()}"] = task


register()
