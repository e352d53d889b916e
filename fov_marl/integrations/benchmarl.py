"""BenchMARL: the fov scenarios as BenchMARL tasks (MAPPO, IPPO, MASAC, ... out of the box).

>>> from fov_marl.integrations.benchmarl import FovMarlTask, make_experiment
>>> task = FovMarlTask.COVERAGE.get_task({"n_agents": 4, "max_cycles": 200})
>>> exp = make_experiment("mappo", task, max_n_iters=10)        # BenchMARL Experiment
>>> exp.run()

or with BenchMARL's own classes::

    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig
    from fov_marl.integrations.benchmarl import FovMarlTask

    Experiment(
        task=FovMarlTask.COVERAGE.get_from_yaml(),      # the paper's defaults
        algorithm_config=MappoConfig.get_from_yaml(),
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=0,
        config=ExperimentConfig.get_from_yaml(),
    ).run()

Tasks: ``FovMarlTask.COVERAGE`` (``fov_coverage_v0``) and ``FovMarlTask.CROSSING``
(``fov_crossing_v0``). The task config is a dict of scenario config fields
(``n_agents``, ``fov_deg``, ``max_cycles``, ...; missing ones take the paper's values)
plus ``safety_filter`` / ``belief`` (bools: wrap in
:class:`~fov_marl.wrappers.SafetyFilterWrapper` /
:class:`~fov_marl.wrappers.BeliefObservationWrapper`) and their ``filter_kwargs`` /
``belief_kwargs``. Bad fields raise ``ValueError`` naming the field when the task is
built. The env is :func:`fov_marl.integrations.torchrl.make_env`'s: one group
``"robot"``, continuous actions, global state for centralised critics (MAPPO, MASAC's
critic), infos logged as ``collection/robot/info/metrics/...``, plus episode-end
``collection/fov/final_eta`` (coverage) / ``final_arrived_ever`` (crossing) and
``final_collisions_total``.

Importing this module imports nothing heavy: benchmarl (and torch) are imported when
``FovMarlTask`` or ``make_experiment`` is first used, which also registers the tasks in
BenchMARL's registry as ``"fov_marl/coverage"`` and ``"fov_marl/crossing"``. Rendering
is off (``has_render`` False) so torchvision, which BenchMARL's video logging needs, is
never imported.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from fov_marl.integrations.common import require
from fov_marl.validation import MAX_SEED, check_int, describe

__all__ = ["ALGORITHMS", "FovMarlClass", "FovMarlTask", "make_experiment"]  # noqa: F822

#: ``make_experiment`` algorithm names -> BenchMARL config classes.
ALGORITHMS: dict[str, str] = {
    "mappo": "MappoConfig",
    "ippo": "IppoConfig",
    "masac": "MasacConfig",
    "isac": "IsacConfig",
    "maddpg": "MaddpgConfig",
    "iddpg": "IddpgConfig",
}


def __getattr__(name: str) -> Any:
    if name in ("FovMarlTask", "FovMarlClass"):
        require("benchmarl", "benchmarl")
        from fov_marl.integrations import _benchmarl_tasks

        return getattr(_benchmarl_tasks, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def make_experiment(
    algorithm: str = "mappo",
    task: Any = None,
    *,
    seed: int = 0,
    save_folder: str | None = None,
    algorithm_overrides: Mapping[str, Any] | None = None,
    **experiment_overrides: Any,
) -> Any:
    """A BenchMARL ``Experiment`` on a fov task with MLP actor and critic, on the CPU.

    Args:
        algorithm: one of :data:`ALGORITHMS` (``"mappo"``, ``"ippo"``, ``"masac"``, ...).
        task: a task built by ``FovMarlTask.X.get_task({...})``, a ``FovMarlTask`` member,
            a registry name (``"fov_marl/coverage"``, ``"fov_marl/crossing"``), or None
            for ``FovMarlTask.COVERAGE`` with the paper's defaults.
        seed: experiment seed.
        save_folder: where BenchMARL writes its folder (None: the current directory).
        algorithm_overrides: fields of the algorithm config.
        **experiment_overrides: ``ExperimentConfig`` fields on top of BenchMARL's
            defaults and of this function's: ``loggers=[]``, ``render=False``,
            ``create_json=False``, ``checkpoint_interval=0``, and ``max_n_frames=None``
            when ``max_n_iters`` is given (e.g. ``max_n_iters=5``,
            ``on_policy_collected_frames_per_batch=2000``).

    Raises:
        ValueError: an unknown algorithm or config field (named, with the valid ones).
        ImportError: benchmarl is not installed.
    """
    if algorithm not in ALGORITHMS:
        raise ValueError(f"algorithm must be one of {list(ALGORITHMS)}, got {describe(algorithm)}")
    require("benchmarl", "benchmarl")
    import benchmarl.algorithms as algos
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig

    from fov_marl.integrations._benchmarl_tasks import FovMarlClass, FovMarlTask

    seed = check_int("seed", seed, 0, MAX_SEED)
    if task is None:
        task = FovMarlTask.COVERAGE
    if isinstance(task, str):
        from benchmarl.environments import task_config_registry

        names = sorted(k for k in task_config_registry if k.startswith("fov_marl/"))
        if task not in names:
            raise ValueError(f"task must be one of {names} (or a FovMarlTask), got {task!r}")
        task = task_config_registry[task]
    if isinstance(task, FovMarlTask):
        task = task.get_from_yaml()
    if not isinstance(task, FovMarlClass):
        raise ValueError(
            "task must be None, a FovMarlTask member, a task from FovMarlTask.X.get_task({...}) "
            f"or a registry name such as 'fov_marl/coverage', got {describe(task)}"
        )
    for key, value in experiment_overrides.items():  # BenchMARL divides by these
        if key.endswith("frames_per_batch") or key.endswith("n_envs_per_worker"):
            check_int(f"experiment_overrides[{key!r}]", value, 1)
    algo_config = getattr(algos, ALGORITHMS[algorithm]).get_from_yaml()
    _apply("algorithm_overrides", algo_config, algorithm_overrides or {})
    config = ExperimentConfig.get_from_yaml()
    defaults = {"loggers": [], "render": False, "create_json": False, "checkpoint_interval": 0}
    if "max_n_iters" in experiment_overrides and "max_n_frames" not in experiment_overrides:
        defaults["max_n_frames"] = None  # one budget, not two
    _apply("experiment_overrides", config, {**defaults, **experiment_overrides})
    if save_folder is not None:
        config.save_folder = str(save_folder)
    return Experiment(
        task=task,
        algorithm_config=algo_config,
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=seed,
        config=config,
    )


def _apply(what: str, target: Any, overrides: Mapping[str, Any]) -> None:
    fields = list(getattr(target, "__dataclass_fields__", {}))
    for key, value in overrides.items():
        if key not in fields:
            raise ValueError(f"{what}: unknown field {key!r}; valid fields are {sorted(fields)}")
        setattr(target, key, value)
