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

import types
import typing
from collections.abc import Mapping
from typing import Any

from fov_marl.integrations.common import require
from fov_marl.validation import (
    MAX_SEED,
    ConfigError,
    check_bool,
    check_int,
    check_out_dir,
    check_real,
    describe,
)

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

_COUNT = (1, None, False)  # an integer in [1, inf)
_UNIT = (0.0, 1.0, False)  # a real in [0, 1]
_POSITIVE = (0.0, None, True)  # a real in (0, inf)
_NON_NEGATIVE = (0.0, None, False)  # a real in [0, inf)

#: Ranges ``(lo, hi, lo_open)`` of the BenchMARL config fields where a value of the
#: right type would break a run or silently empty it (BenchMARL divides by these, takes
#: their log, counts with them). Every override is checked against the type its config
#: dataclass annotates; an integer field not listed here is a count in [0, inf), a real
#: one any finite real.
_RANGES: dict[str, tuple[float, float | None, bool]] = {
    # ExperimentConfig
    "gamma": _UNIT,
    "lr": _POSITIVE,
    "adam_eps": _NON_NEGATIVE,
    "clip_grad_val": _POSITIVE,
    "polyak_tau": _UNIT,
    "hard_target_update_frequency": _COUNT,
    "exploration_eps_init": _UNIT,
    "exploration_eps_end": _UNIT,
    "exploration_anneal_frames": _COUNT,
    "max_n_iters": _COUNT,
    "max_n_frames": _COUNT,
    "on_policy_collected_frames_per_batch": _COUNT,
    "on_policy_n_envs_per_worker": _COUNT,
    "on_policy_n_minibatch_iters": _COUNT,
    "on_policy_minibatch_size": _COUNT,
    "off_policy_collected_frames_per_batch": _COUNT,
    "off_policy_n_envs_per_worker": _COUNT,
    "off_policy_n_optimizer_steps": _COUNT,
    "off_policy_train_batch_size": _COUNT,
    "off_policy_memory_size": _COUNT,
    "off_policy_prb_alpha": _NON_NEGATIVE,
    "off_policy_prb_beta": _NON_NEGATIVE,
    "evaluation_interval": _COUNT,
    "evaluation_episodes": _COUNT,
    "keep_checkpoints_num": _COUNT,
    # algorithm configs
    "clip_epsilon": _UNIT,  # PPO clips the log-ratio to [log(1 - eps), log(1 + eps)]
    "entropy_coef": _NON_NEGATIVE,
    "critic_coef": _NON_NEGATIVE,
    "lmbda": _UNIT,
    "num_qvalue_nets": _COUNT,
    "alpha_init": _POSITIVE,
    "min_alpha": _NON_NEGATIVE,
    "max_alpha": _POSITIVE,
}

_KIND_TEXT = {bool: "a bool", int: "an integer", float: "a real number", str: "a string"}


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
        save_folder: an existing directory in which BenchMARL writes its experiment
            folder (None: the current directory).
        algorithm_overrides: a dict of fields of the algorithm config, or None.
        **experiment_overrides: ``ExperimentConfig`` fields on top of BenchMARL's
            defaults and of this function's: ``loggers=[]``, ``render=False``,
            ``create_json=False``, ``checkpoint_interval=0``, and ``max_n_frames=None``
            when ``max_n_iters`` is given (e.g. ``max_n_iters=5``,
            ``on_policy_collected_frames_per_batch=2000``). The budget ``max_n_iters`` /
            ``max_n_frames`` is a positive integer or None (no limit of that kind; not
            both None).

        Each override must have the type its BenchMARL config dataclass annotates (an
        integer for ``int``, a bool for ``bool``, None only for ``Optional`` fields) and,
        for the fields BenchMARL divides by, logs or counts with, lie in their range
        (``lr`` in (0, inf), ``gamma`` and ``clip_epsilon`` in [0, 1], batch sizes and
        budgets in [1, inf), ...).

    Raises:
        ValueError: an unknown algorithm or config field (named, with the valid ones), an
            override of the wrong type or out of its range (named, with the range),
            overrides that leave no budget, ``algorithm_overrides`` that is not a dict
            or None, or a ``save_folder`` that is not an existing directory.
        ImportError: benchmarl is not installed.
    """
    if not isinstance(algorithm, str) or algorithm not in ALGORITHMS:
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
    if save_folder is not None:
        save_folder = _existing_folder(save_folder)
    algo_class = getattr(algos, ALGORITHMS[algorithm])
    if algorithm_overrides is not None and not isinstance(algorithm_overrides, Mapping):
        raise ConfigError(
            f"algorithm_overrides must be a dict of {algo_class.__name__} fields or None, "
            f"got {describe(algorithm_overrides)}"
        )
    algo_config = algo_class.get_from_yaml()
    _apply("algorithm_overrides", algo_config, algorithm_overrides or {})
    config = ExperimentConfig.get_from_yaml()
    defaults = {"loggers": [], "render": False, "create_json": False, "checkpoint_interval": 0}
    if "max_n_iters" in experiment_overrides and "max_n_frames" not in experiment_overrides:
        defaults["max_n_frames"] = None  # one budget, not two
    _apply("experiment_overrides", config, {**defaults, **experiment_overrides})
    if config.max_n_iters is None and config.max_n_frames is None:
        raise ConfigError(
            "experiment_overrides: max_n_iters and max_n_frames are both None (no budget); "
            "give one of them as a positive integer"
        )
    if save_folder is not None:
        config.save_folder = save_folder
    return Experiment(
        task=task,
        algorithm_config=algo_config,
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=seed,
        config=config,
    )


def _existing_folder(save_folder: Any) -> str:
    """``save_folder`` as a string, or ConfigError: BenchMARL makes its experiment folder
    inside it without creating the parents."""
    folder = check_out_dir("save_folder", save_folder)
    if not folder.is_dir():
        raise ConfigError(
            f"save_folder {folder}: no such directory (BenchMARL writes its experiment "
            "folder inside an existing one)"
        )
    return str(folder)


def _apply(what: str, target: Any, overrides: Mapping[str, Any]) -> None:
    """Set the dataclass fields ``overrides`` on ``target``, each checked against the
    field's annotation (:func:`_check_field`)."""
    hints = typing.get_type_hints(type(target))
    fields = list(getattr(target, "__dataclass_fields__", {}))
    for key, value in overrides.items():
        if key not in fields:
            raise ValueError(f"{what}: unknown field {key!r}; valid fields are {sorted(fields)}")
        setattr(target, key, _check_field(f"{what}[{key!r}]", key, value, hints.get(key, Any)))


def _check_field(label: str, key: str, value: Any, hint: Any) -> Any:
    """``value`` of the config field ``key`` checked against its annotation ``hint``
    (``Optional[X]``: None or X; ``Union[float, str]``: either) and :data:`_RANGES`;
    returns it as a plain Python value. ``label`` names it in the message."""
    if typing.get_origin(hint) not in (typing.Union, types.UnionType):
        return _check_kind(label, key, value, hint, "")
    kinds = [k for k in typing.get_args(hint) if k is not type(None)]
    optional = len(kinds) < len(typing.get_args(hint))
    if value is None and optional:
        return None
    note = "(or None)" if optional else ""
    if len(kinds) == 1:
        return _check_kind(label, key, value, kinds[0], note)
    for kind in kinds:
        try:
            return _check_kind(label, key, value, kind, note)
        except ConfigError:
            pass
    allowed = " or ".join(map(_kind_text, kinds)) + (" or None" * optional)
    raise ConfigError(f"{label} must be {allowed}, got {describe(value)}")


def _check_kind(label: str, key: str, value: Any, kind: Any, note: str) -> Any:
    """``value`` checked against one annotated type ``kind`` (see :func:`_check_field`)."""
    origin = typing.get_origin(kind) or kind
    if kind is bool:
        return check_bool(label, value)
    if kind is int:
        lo, hi, _ = _RANGES.get(key, (0, None, False))
        return check_int(label, value, int(lo), None if hi is None else int(hi), note=note)
    if kind is float:
        lo, hi, lo_open = _RANGES.get(key, (None, None, False))
        return check_real(label, value, lo, hi, lo_open=lo_open, note=note)
    if origin is list:
        item = (typing.get_args(kind) or (Any,))[0]
        if isinstance(value, list | tuple) and (
            item is Any or all(isinstance(v, item) for v in value)
        ):
            return list(value)
    elif origin is dict:
        if isinstance(value, Mapping) and all(isinstance(k, str) for k in value):
            return dict(value)
    elif kind is Any or not isinstance(origin, type) or isinstance(value, origin):
        return value  # Any (or an annotation this cannot check), or of the right class
    raise ConfigError(
        f"{label} must be {_kind_text(kind)}{' ' + note if note else ''}, got {describe(value)}"
    )


def _kind_text(kind: Any) -> str:
    """``a string``, ``a list of str``, ``a dict with str keys``, ... for messages."""
    origin = typing.get_origin(kind) or kind
    if origin is list:
        item = (typing.get_args(kind) or (Any,))[0]
        return f"a list of {getattr(item, '__name__', item)}"
    if origin is dict:
        return "a dict with string keys"
    return _KIND_TEXT.get(kind, f"a {getattr(kind, '__name__', kind)}")
