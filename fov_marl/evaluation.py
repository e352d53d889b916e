"""Seeded episode runs and summaries shared by the CLI, the report and the tests.

An :class:`EpisodeRecord` holds what ``results.json`` stores per episode (the file's
layout: ``docs/cli.md``, "results.json"); :func:`summarize` adds mean, std and a 95% confidence interval clipped to
each field's feasible range (:data:`FEASIBLE`); :func:`bootstrap_ci` and
:func:`paired_difference` give the percentile-bootstrap intervals and the paired
sign-flip test the reproduction uses.

Normalised coverage. ``eta_normalised = final_eta / optimal_eta(config)``
(:func:`fov_marl.metrics.optimal_eta`, measured by the same quadrature), and
``time_to_eta_norm_s`` is the first time η(t) reaches ``ETA_NORM_THRESHOLD`` (0.95) of
that optimum. Why 0.95 and σ = 4 m: see :mod:`fov_marl.config`.

CPU time. ``cpu_ms_per_robot_step`` is the controller's wall-clock time (policy plus
safety filter, not the simulator) per robot per step. For the PF+CBF pipeline policies
it is split per stage (``cpu_ms_by_stage``: ``tracker``, ``lloyd``, ``safety_rows``,
``qp`` from ``PfCbfPipeline.last_timings``, ``qp`` without the safety rows it contains,
``other``, the rest of ``act``, and, behind the safety filter, ``filter``: the
wrapper's own time, :attr:`SafetyFilterWrapper.last_cpu_s`, its tracker and QPs; they
add up to the total) and per robot (``cpu_ms_by_robot``): robot i is charged its own
controller's ``solve`` (timed around each call) plus an equal share of the
team-batched stages (the tracker bank, Lloyd, the safety rows, the filter), so the
per-robot values sum to the team's time. With the batched controller (the default,
``PfCbfPipeline(controller="auto")``) the QPs are solved for the whole team in one
call, so every robot gets an equal share of the whole step; pass
``controller="loop"`` to the policy to see each robot's own solve. Policies without
a PF+CBF pipeline have no split (both fields None).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fov_marl.baselines import Policy, make_policy
from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
from fov_marl.infos import SAFETY_CAUSES, cause_counts, has_safety, metrics_of, safety_of
from fov_marl.jsonio import jsonable
from fov_marl.metrics import optimal_eta, time_to_eta
from fov_marl.validation import (
    check_bool,
    check_int,
    check_real,
    check_seed,
    check_wrapper_kwargs,
    describe,
)

__all__ = [
    "EpisodeRecord",
    "SCENARIOS",
    "make_env",
    "run_episode",
    "summarize",
    "SUMMARY_FIELDS",
    "FEASIBLE",
    "REACHED_FIELDS",
    "ETA_NORM_THRESHOLD",
    "bootstrap_ci",
    "paired_difference",
    "time_to_settle",
    "episode_job",
    "run_episodes",
    "is_model_path",
    "is_exported_policy",
]

#: Normalised coverage threshold: ``time_to_eta_norm_s`` is the first time η reaches this
#: fraction of :func:`fov_marl.metrics.optimal_eta` (the choice is argued in fov_marl.config).
ETA_NORM_THRESHOLD = 0.95

SCENARIOS = {"coverage": fov_coverage_v0, "crossing": fov_crossing_v0}


def make_env(
    scenario: str,
    safety_filter: bool = False,
    render_mode: str | None = None,
    safety_filter_kwargs: dict[str, Any] | None = None,
    **kw,
):
    """Build a scenario's ParallelEnv, optionally behind the SafetyFilterWrapper.

    ``safety_filter_kwargs``: keywords of :class:`~fov_marl.wrappers.SafetyFilterWrapper`
    (e.g. ``{"tracker_params": {"n_particles_total": 500}}``), used with ``safety_filter``
    (a non-empty dict without it is an error, not ignored).

    Raises:
        ValueError: unknown scenario, invalid config keyword/value, ``safety_filter`` not
            a bool, or ``safety_filter_kwargs`` not a dict of the filter's keywords (the
            message lists them).
    """
    if not isinstance(scenario, str) or scenario not in SCENARIOS:
        raise ValueError(f"scenario must be one of {sorted(SCENARIOS)}, got {scenario!r}")
    safety_filter = check_bool("safety_filter", safety_filter)
    sf_kwargs = _check_filter_kwargs(safety_filter_kwargs, safety_filter)
    env = SCENARIOS[scenario].parallel_env(render_mode=render_mode, **kw)
    if safety_filter:
        from fov_marl.wrappers import SafetyFilterWrapper

        env = SafetyFilterWrapper(env, **sf_kwargs)
    return env


def _check_filter_kwargs(value: Any, safety_filter: bool) -> dict[str, Any]:
    """``safety_filter_kwargs``: None or a dict of :class:`SafetyFilterWrapper` keywords
    (their values are the filter's to check), non-empty only with the filter."""
    from fov_marl.wrappers import SafetyFilterWrapper

    return check_wrapper_kwargs(
        "safety_filter_kwargs", value, SafetyFilterWrapper, on=safety_filter
    )


@dataclass
class EpisodeRecord:
    """One evaluated episode (the per-episode record of ``results.json``).

    Times are simulated seconds; ``cpu_ms_per_robot_step`` is the wall-clock time
    of the controller (policy + safety filter, not the simulator) per robot per step
    (``_std`` over steps). Coverage only: ``eta_optimal`` (best η the team can reach),
    ``eta_normalised`` = ``final_eta / eta_optimal``, ``time_to_eta_norm_s`` (first time
    η ≥ ``eta_norm_threshold · eta_optimal``). Crossing only: ``arrived`` (robots within
    tolerance at the end), ``arrived_ever``, ``time_to_arrival_s`` (all arrived at once),
    ``mean_time_to_arrive_s`` (mean over the robots that arrived of their first
    arrival). ``safety_violations`` counts D_s violation events (a pair entering D_s).
    Behind the filter, ``intervention_causes`` is the share of robot-steps changed for
    each cause of :data:`fov_marl.infos.SAFETY_CAUSES` (a step may have several, so the
    shares can add up to more than ``intervention_rate``).
    ``max_distance_m`` is the largest distance two robots of the episode's arena can be
    apart, ``√2 (L − 2 r)`` (:func:`summarize` clips ``min_distance``'s interval to it;
    None in records written before it existed).
    ``eta_series`` and ``min_distance_series`` hold one value at reset and one per step
    (sample k at ``k · dt_s``). ``min_distance`` (and its series) is inf for a one-robot
    team (no pair; :meth:`to_json` writes it as None, :func:`summarize` leaves it out).
    None marks what does not apply or never happened.
    """

    seed: int
    scenario: str
    policy: str
    n_agents: int
    fov_deg: float
    safety_filter: bool
    steps: int
    final_eta: float | None
    time_to_eta_99: float | None
    collisions: int
    min_distance: float
    safety_violations: int
    cpu_ms_per_robot_step: float
    cpu_ms_per_robot_step_std: float
    arrived: int | None = None
    time_to_arrival_s: float | None = None
    filter_interventions: int | None = None
    qp_fallbacks: int | None = None
    intervention_rate: float | None = None
    mean_action_change: float | None = None
    intervention_causes: dict[str, float] | None = None
    safety_fallbacks: int | None = None
    time_to_settle_s: float | None = None
    path_length_m: float | None = None
    mean_speed_last_50s: float | None = None
    eta_optimal: float | None = None
    eta_normalised: float | None = None
    eta_norm_threshold: float | None = None
    time_to_eta_norm_s: float | None = None
    arrived_ever: int | None = None
    mean_time_to_arrive_s: float | None = None
    max_distance_m: float | None = None
    cpu_ms_by_stage: dict[str, float] | None = None
    cpu_ms_by_robot: list[float] | None = None
    eta_series: list[float] = field(default_factory=list, repr=False)
    min_distance_series: list[float] = field(default_factory=list, repr=False)
    trajectory: list[list[list[float]]] = field(default_factory=list, repr=False)

    def to_json(self, with_series: bool = True) -> dict[str, Any]:
        """Standard-JSON-ready dict of every field but ``trajectory``;
        ``with_series=False`` also drops the per-step ``eta_series`` and
        ``min_distance_series``.

        Non-finite floats become None, as :mod:`fov_marl.jsonio` writes them to files
        (``json.dumps(..., allow_nan=False)`` accepts the dict): a one-robot team's
        ``min_distance`` and ``min_distance_series`` (inf, no pair) are None.
        :meth:`from_json` reads them back as inf."""
        d = dataclasses.asdict(self)
        if not with_series:
            d.pop("eta_series")
            d.pop("min_distance_series")
        d.pop("trajectory")
        return jsonable(d)

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> EpisodeRecord:
        """The record of a :meth:`to_json` dict (keys that are not fields are ignored).

        ``min_distance`` and the entries of ``min_distance_series`` given as None (no
        pair: a one-robot team) are inf again, the value :func:`run_episode` records.
        """
        fields = set(cls.__dataclass_fields__)
        d = {k: v for k, v in data.items() if k in fields}
        if "min_distance" in d and d["min_distance"] is None:
            d["min_distance"] = math.inf
        if d.get("min_distance_series"):
            d["min_distance_series"] = [
                math.inf if x is None else x for x in d["min_distance_series"]
            ]
        return cls(**d)


def run_episode(
    scenario: str,
    policy: str | Callable[[Any], Any],
    seed: int,
    *,
    safety_filter: bool = False,
    max_steps: int | None = None,
    record_trajectory: bool = False,
    stop_at_eta: float | None = None,
    on_step: Callable[[Any, dict], None] | None = None,
    render_mode: str | None = None,
    policy_kwargs: dict[str, Any] | None = None,
    safety_filter_kwargs: dict[str, Any] | None = None,
    **env_kwargs: Any,
) -> EpisodeRecord:
    """Run one seeded episode and measure it.

    Args:
        scenario: ``"coverage"`` or ``"crossing"``.
        policy: a registered name (``make_policy``) or a factory ``f(env) -> Policy``.
        seed: seeds the env (start poses, camera noise) and the policy: None or an
            integer >= 0.
        safety_filter: wrap the env in :class:`fov_marl.wrappers.SafetyFilterWrapper`
            (a bool).
        max_steps: stop earlier than the env's ``max_cycles``: None (no earlier stop) or
            an integer >= 0 (0 runs no step: the record of the start).
        record_trajectory: keep the ground-truth poses of every step (a bool).
        stop_at_eta: None, or end the episode once η reaches this value, a real in
            [0, 1] (saves time in sweeps that only need the time to η = 0.99).
        on_step: None or a callable, called as ``on_step(env, infos)`` after every step
            (rendering).
        policy_kwargs: None or a dict of the options of a registered policy
            (``make_policy(policy, env, **policy_kwargs)``); a factory takes none.
        safety_filter_kwargs: keywords of the filter (:func:`make_env`).
        **env_kwargs: config fields for the env.

    Raises:
        ValueError: a bad argument (naming it and its allowed values), an unknown
            policy or option, or an invalid config field.
    """
    seed = check_seed("seed", seed)
    if not isinstance(policy, str) and not callable(policy):
        raise ValueError(
            "policy must be a registered policy name (fov_marl.baselines.available_policies()) "
            f"or a factory f(env) -> Policy, got {describe(policy)}"
        )
    if max_steps is not None:
        max_steps = check_int("max_steps", max_steps, 0, note="(or None: the env's max_cycles)")
    record_trajectory = check_bool("record_trajectory", record_trajectory)
    if stop_at_eta is not None:
        stop_at_eta = check_real("stop_at_eta", stop_at_eta, 0.0, 1.0, note="(or None)")
    if on_step is not None and not callable(on_step):
        raise ValueError(
            f"on_step must be None or a callable on_step(env, infos), got {describe(on_step)}"
        )
    if policy_kwargs is not None and not isinstance(policy_kwargs, Mapping):
        raise ValueError(
            f"policy_kwargs must be a dict of policy options or None, got {describe(policy_kwargs)}"
        )
    if policy_kwargs and not isinstance(policy, str):
        raise ValueError(
            f"policy_kwargs {sorted(map(str, policy_kwargs))} apply to a registered policy name; "
            f"the factory {getattr(policy, '__name__', describe(policy))} takes none "
            "(bind its options in the factory)"
        )
    env = make_env(
        scenario,
        safety_filter=safety_filter,
        render_mode=render_mode,
        safety_filter_kwargs=safety_filter_kwargs,
        **env_kwargs,
    )
    name = policy if isinstance(policy, str) else getattr(policy, "__name__", "custom")
    pol = (
        make_policy(policy, env, **(policy_kwargs or {}))
        if isinstance(policy, str)
        else policy(env)
    )
    if not isinstance(pol, Policy):
        env.close()
        raise ValueError(
            f"policy factory {name} must return a Policy (with reset(seed) and act(obs)), "
            f"got {describe(pol)}"
        )
    cfg = env.unwrapped.config
    obs, infos = env.reset(seed=seed)
    pol.reset(seed=seed)
    n = cfg.n_agents
    dt = cfg.dt_s
    solve_s = _time_controller_solves(getattr(pol, "pipeline", None), n)
    stage_s: dict[str, float] = {}
    robot_s = np.zeros(n)
    mind_series: list[float] = []
    first_arrival = np.full(n, np.nan)
    targets = getattr(env.unwrapped, "targets", None) if scenario == "crossing" else None
    eta_series: list[float] = []
    traj: list[list[list[float]]] = []
    cpu: list[float] = []
    interventions = fallbacks = safety_fb = 0
    du_sum = 0.0
    cause_n = np.zeros(len(SAFETY_CAUSES), dtype=np.int64)
    have_filter = False
    speeds: list[float] = []
    path = 0.0
    prev_xy = env.unwrapped.poses[:, :2]
    m = metrics_of(infos[env.possible_agents[0]])
    if "eta" in m:
        eta_series.append(m["eta"])
    mind_series.append(float(m["min_distance"]))
    if record_trajectory:
        traj.append(env.unwrapped.poses.tolist())
    arrival_t = None
    steps = 0
    limit = max_steps if max_steps is not None else cfg.max_cycles
    while env.agents and steps < limit:
        if solve_s is not None:
            solve_s[:] = 0.0
        t0 = time.perf_counter()
        actions = pol.act(obs)
        t_policy = time.perf_counter() - t0
        timings = getattr(pol, "last_timings", None)
        if timings:
            staged = 0.0
            for k, v in timings.items():
                stage_s[k] = stage_s.get(k, 0.0) + float(v)
                staged += float(v) if k not in _SUB_STAGES else 0.0
            stage_s["other"] = stage_s.get("other", 0.0) + max(t_policy - staged, 0.0)
        if solve_s is not None:
            robot_s += solve_s + (t_policy - float(solve_s.sum())) / n
        obs, _, term, trunc, infos = env.step(actions)
        steps += 1
        info0 = infos[env.possible_agents[0]]
        t_filter = 0.0
        if has_safety(info0):
            have_filter = True
            t_filter = float(getattr(env, "last_cpu_s", 0.0))
            if timings:
                stage_s["filter"] = stage_s.get("filter", 0.0) + t_filter
            if solve_s is not None:
                robot_s += t_filter / n  # the filter runs for the team: equal shares
            saf = [safety_of(infos[a]) for a in infos]
            interventions += sum(int(x["intervened"]) for x in saf)
            cause_n += cause_counts([x.get("cause_bits", 0) for x in saf])
            fallbacks += sum(int(x["fallback"]) for x in saf)
            safety_fb += sum(int(x["status"] == "safety_fallback") for x in saf)
            du_sum += float(
                sum(
                    np.linalg.norm(
                        np.asarray(x["applied_action"], np.float64)
                        - np.asarray(x["nominal_action"], np.float64)
                    )
                    for x in saf
                )
            )
        xy = env.unwrapped.poses[:, :2]
        step_len = np.linalg.norm(xy - prev_xy, axis=1)
        prev_xy = xy
        speeds.append(float(step_len.mean()) / dt)
        path += float(step_len.mean())
        cpu.append((t_policy + t_filter) * 1e3 / n)
        m = metrics_of(info0)
        if "eta" in m:
            eta_series.append(m["eta"])
        mind_series.append(float(m["min_distance"]))
        if targets is not None:
            here = np.linalg.norm(xy - targets, axis=1) < cfg.target_tolerance_m
            first_arrival[here & np.isnan(first_arrival)] = steps * dt
        if record_trajectory:
            traj.append(env.unwrapped.poses.tolist())
        if on_step is not None:
            on_step(env, infos)
        if scenario == "crossing" and arrival_t is None and m["arrived"] == n:
            arrival_t = steps * dt
        if stop_at_eta is not None and eta_series and eta_series[-1] >= stop_at_eta:
            break
    env.close()
    cpu_arr = np.asarray(cpu) if cpu else np.zeros(1)
    pipe = getattr(pol, "pipeline", None)
    if not have_filter and pipe is not None and hasattr(pipe, "counters"):
        safety_fb = int(pipe.counters.get("safety_fallbacks", 0))
    robot_steps = max(1, steps * n)
    last = speeds[-max(1, round(50.0 / dt)) :] if speeds else []
    eta_opt = eta_norm = t_norm = None
    if scenario == "coverage" and eta_series:
        eta_opt = optimal_eta(cfg)
        eta_norm = eta_series[-1] / eta_opt if eta_opt > 0 else None
        # η_opt = 0 (sensing disks that cover no grid cell: eta_grid_m coarser than R_s):
        # no threshold to reach, like eta_normalised
        t_norm = (
            time_to_eta(eta_series, dt, min(ETA_NORM_THRESHOLD * eta_opt, 1.0))
            if eta_opt > 0
            else None
        )
    arrived_any = ~np.isnan(first_arrival)
    return EpisodeRecord(
        max_distance_m=math.sqrt(2.0) * (cfg.arena_size_m - 2.0 * cfg.robot_radius_m),
        seed=seed,
        scenario=scenario,
        policy=name,
        n_agents=n,
        fov_deg=cfg.fov_deg,
        safety_filter=safety_filter,
        steps=steps,
        final_eta=eta_series[-1] if eta_series else None,
        time_to_eta_99=time_to_eta(eta_series, dt, 0.99) if eta_series else None,
        collisions=int(m["collisions_total"]),
        min_distance=float(m["min_distance_episode"]),
        safety_violations=int(m["safety_violations_total"]),
        cpu_ms_per_robot_step=float(cpu_arr.mean()),
        cpu_ms_per_robot_step_std=float(cpu_arr.std()),
        arrived=m.get("arrived"),
        time_to_arrival_s=arrival_t,
        filter_interventions=interventions if have_filter else None,
        qp_fallbacks=fallbacks if have_filter else None,
        intervention_rate=interventions / robot_steps if have_filter else None,
        mean_action_change=du_sum / robot_steps if have_filter else None,
        intervention_causes=(
            {c: int(k) / robot_steps for c, k in zip(SAFETY_CAUSES, cause_n, strict=True)}
            if have_filter
            else None
        ),
        safety_fallbacks=safety_fb if (have_filter or pipe is not None) else None,
        time_to_settle_s=time_to_settle(speeds, dt),
        path_length_m=path,
        mean_speed_last_50s=float(np.mean(last)) if last else None,
        eta_optimal=eta_opt,
        eta_normalised=eta_norm,
        eta_norm_threshold=ETA_NORM_THRESHOLD if eta_opt is not None else None,
        time_to_eta_norm_s=t_norm,
        arrived_ever=int(arrived_any.sum()) if targets is not None else None,
        mean_time_to_arrive_s=(
            float(first_arrival[arrived_any].mean())
            if targets is not None and arrived_any.any()
            else None
        ),
        cpu_ms_by_stage=_split_stages(stage_s, robot_steps) if stage_s else None,
        cpu_ms_by_robot=(robot_s * 1e3 / max(1, steps)).tolist() if solve_s is not None else None,
        eta_series=eta_series,
        min_distance_series=mind_series,
        trajectory=traj,
    )


def is_model_path(policy: Any) -> bool:
    """True when ``policy`` names a trained SB3 model (a ``.zip`` file or a run folder)."""
    import os

    return (
        isinstance(policy, str)
        and (policy.endswith(".zip") or os.path.isdir(policy))
        and not is_exported_policy(policy)
    )


def is_exported_policy(policy: Any) -> bool:
    """True when ``policy`` is a folder holding an exported set policy (``weights.npz``
    and ``config.json``, :mod:`fov_marl.baselines.learned`), run with numpy for any N."""
    import os

    return (
        isinstance(policy, str)
        and os.path.isfile(os.path.join(policy, "weights.npz"))
        and os.path.isfile(os.path.join(policy, "config.json"))
    )


def learned_filter(policy: Any) -> bool:
    """True when a ``--policy`` value is ``"learned"`` (the shipped model) or an exported
    folder that was trained behind the safety filter
    (:func:`fov_marl.baselines.learned.trained_filter`); False for anything else
    (scripted policies; ``model.zip`` paths, which :func:`fov_marl.training.load_policy`
    reads)."""
    from fov_marl.baselines.learned import trained_filter

    if policy == "learned":
        return trained_filter()[0]
    return is_exported_policy(policy) and trained_filter(policy)[0]


def _apply_learned_filter(job: dict[str, Any], policy: Any) -> dict[str, Any]:
    """``job`` with the safety filter switched on when ``policy`` was trained behind it.

    The filter keeps the job's options, by default the shipped filter's (the one the
    stress sweeps validate; the measurements of the README use it), not the training
    run's (the shipped model's used P_T = 500 for speed)."""
    return {**job, "safety_filter": True} if learned_filter(policy) else job


def episode_job(job: dict[str, Any], on_step: Callable[[Any, dict], None] | None = None) -> dict:
    """One episode from a picklable job, as its JSON-ready record (a backend task).

    ``job`` holds :func:`run_episode` keywords; ``job["policy"]`` is a registered name,
    the folder of an exported set policy (:func:`is_exported_policy`: the numpy
    ``learned`` policy with those weights, on the job's config) or the path of a trained
    model (loaded here, in the worker: its ``config.json`` fills the config fields the
    job does not give, and its safety filter applies). ``"learned"`` and an exported
    folder trained behind the filter run behind it too (:func:`learned_filter`).
    ``on_step`` is forwarded to :func:`run_episode` (in-process progress).
    """
    job = dict(job)
    policy = job.pop("policy")
    job = _apply_learned_filter(job, policy)
    if is_exported_policy(policy):  # numpy forward pass, any N, no torch
        rec = run_episode(policy="learned", policy_kwargs={"path": policy}, on_step=on_step, **job)
        rec.policy = str(policy)
    elif is_model_path(policy):
        from fov_marl.training import load_policy  # torch only for learned policies

        loaded = load_policy(policy)
        job = {**loaded.env_kwargs, **job}
        if loaded.safety_filter and not job.get("safety_filter_kwargs"):
            job["safety_filter_kwargs"] = loaded.safety_filter_kwargs or None  # as trained
        job["safety_filter"] = job.get("safety_filter") or loaded.safety_filter
        rec = run_episode(policy=loaded.factory, on_step=on_step, **job)
        rec.policy = str(policy)
    else:
        rec = run_episode(policy=policy, on_step=on_step, **job)
    return rec.to_json()


def run_episodes(
    scenario: str,
    policy: str,
    seeds: Sequence[int],
    *,
    safety_filter: bool = False,
    backend: str = "local",
    workers: int = 1,
    ray_address: str | None = None,
    progress: bool = False,
    safety_filter_kwargs: dict[str, Any] | None = None,
    **env_kwargs: Any,
) -> list[EpisodeRecord]:
    """Run one seeded episode per seed on a backend (:mod:`fov_marl.backends`).

    Args:
        scenario: ``"coverage"`` or ``"crossing"``.
        policy: a registered policy name or the path of a trained ``model.zip``.
        seeds: one episode per seed, records in this order: a list, tuple or 1-d array
            of seeds, each None or an integer >= 0 (as :func:`run_episode` takes it; no
            float, bool or string is converted).
        backend: ``"local"`` (this process or ``workers`` processes) or ``"ray"``.
        workers: local processes, or the CPUs of a local Ray started here.
        ray_address: an existing Ray cluster for ``backend="ray"``.
        progress: a progress bar on stderr (per simulated step in this process, per
            finished episode otherwise; tqdm or rich, nothing if neither is installed).
        safety_filter_kwargs: keywords of the filter (:func:`make_env`); None: its
            defaults (a trained model's own filter options when it was trained behind one).
        **env_kwargs: config fields.

    Returns:
        The records, in seed order; the same numbers for any backend and worker count
        (only the wall-clock ``cpu_ms_*`` fields differ).

    Raises:
        ValueError: a bad argument (naming it; a bad seed as ``seeds[k]``).
    """
    from fov_marl.backends import map_jobs, progress_bar
    from fov_marl.config import make_config

    if not isinstance(scenario, str) or scenario not in SCENARIOS:
        raise ValueError(f"scenario must be one of {sorted(SCENARIOS)}, got {scenario!r}")
    if isinstance(seeds, str | bytes | Mapping) or not isinstance(seeds, Sequence | np.ndarray):
        raise ValueError(
            f"seeds must be a list, tuple or 1-d array of seeds, got {describe(seeds)}"
        )
    if isinstance(seeds, np.ndarray) and seeds.ndim != 1:
        raise ValueError(f"seeds must be a 1-d array, got shape {seeds.shape}")
    checked = [check_seed(f"seeds[{k}]", s) for k, s in enumerate(seeds)]
    safety_filter = check_bool("safety_filter", safety_filter)
    progress = check_bool("progress", progress)
    extra = {"safety_filter_kwargs": safety_filter_kwargs} if safety_filter_kwargs else {}
    jobs = [
        dict(scenario=scenario, policy=policy, seed=s, safety_filter=safety_filter,
             **extra, **env_kwargs)
        for s in checked
    ]  # fmt: skip
    # the bar counts env steps, each episode at most ``limit`` (a model's own horizon
    # may differ: every episode then advances the bar by exactly ``limit``)
    mc = env_kwargs.get("max_cycles")
    limit = make_config(scenario=scenario, **({} if mc is None else {"max_cycles": mc})).max_cycles
    bar = progress_bar(len(jobs) * limit, "evaluate", "step", enabled=progress)
    counted = [0]

    def on_step(env: Any, infos: dict) -> None:
        if counted[0] < limit:
            counted[0] += 1
            bar.update(1)

    def on_result(k: int, res: dict[str, Any]) -> None:
        bar.update(limit - counted[0])  # the rest of this episode's budget
        counted[0] = 0

    try:
        results = map_jobs(
            episode_job,
            jobs,
            backend=backend,
            workers=workers,
            ray_address=ray_address,
            on_result=on_result,
            local_kwargs={"on_step": on_step} if progress else None,
        )
    finally:
        bar.close()
    return [EpisodeRecord.from_json(r) for r in results]


#: stages that ``PfCbfPipeline.last_timings`` times inside another: sub-stage -> parent
_SUB_STAGES = {"safety_rows": "qp"}


def _split_stages(stage_s: dict[str, float], robot_steps: int) -> dict[str, float]:
    """ms per robot-step per stage, nested stages taken out of their parent so the
    values add up to ``cpu_ms_per_robot_step`` (``qp`` = the controllers' QPs alone)."""
    out = dict(stage_s)
    for sub, parent in _SUB_STAGES.items():
        if sub in out and parent in out:
            out[parent] = max(out[parent] - out[sub], 0.0)
    return {k: v * 1e3 / robot_steps for k, v in out.items()}


def _time_controller_solves(pipeline: Any, n: int) -> np.ndarray | None:
    """Time each robot's controller ``solve`` of a PF+CBF pipeline: wraps the bound
    methods of this episode's controller instances (created with the policy, so nothing
    outlives the episode) and returns the ``(N,)`` seconds array they add to."""
    ctrls = getattr(pipeline, "controllers", None)
    if getattr(pipeline, "batched", None) is not None:
        return np.zeros(n)  # one solve for the team: every robot gets an equal share
    if not ctrls or len(ctrls) != n:
        return None
    acc = np.zeros(n)
    for i, ctrl in enumerate(ctrls):
        inner = ctrl.solve

        def timed(*args: Any, _inner: Any = inner, _i: int = i, **kw: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return _inner(*args, **kw)
            finally:
                acc[_i] += time.perf_counter() - t0

        ctrl.solve = timed
    return acc


SUMMARY_FIELDS = (
    "final_eta",
    "time_to_eta_99",
    "collisions",
    "min_distance",
    "safety_violations",
    "cpu_ms_per_robot_step",
    "steps",
    "arrived",
    "time_to_arrival_s",
    "intervention_rate",
    "mean_action_change",
    "safety_fallbacks",
    "time_to_settle_s",
    "path_length_m",
    "mean_speed_last_50s",
    "eta_normalised",
    "time_to_eta_norm_s",
    "arrived_ever",
    "mean_time_to_arrive_s",
)

_INF = math.inf
#: Feasible range ``(lo, hi)`` of every summary field; confidence intervals are clipped
#: to it (a t-interval is symmetric and can leave it for skewed or tiny samples).
#: ``arrived``/``arrived_ever`` are further capped at the team size by :func:`summarize`.
FEASIBLE: dict[str, tuple[float, float]] = {
    "final_eta": (0.0, 1.0),
    "time_to_eta_99": (0.0, _INF),
    "collisions": (0.0, _INF),
    "min_distance": (0.0, _INF),
    "safety_violations": (0.0, _INF),
    "cpu_ms_per_robot_step": (0.0, _INF),
    "steps": (0.0, _INF),
    "arrived": (0.0, _INF),
    "time_to_arrival_s": (0.0, _INF),
    "intervention_rate": (0.0, 1.0),
    "mean_action_change": (0.0, _INF),
    "safety_fallbacks": (0.0, _INF),
    "time_to_settle_s": (0.0, _INF),
    "path_length_m": (0.0, _INF),
    "mean_speed_last_50s": (0.0, _INF),
    "eta_normalised": (0.0, _INF),
    "time_to_eta_norm_s": (0.0, _INF),
    "arrived_ever": (0.0, _INF),
    "mean_time_to_arrive_s": (0.0, _INF),
}


def time_to_settle(
    speeds_mps: Sequence[float], dt_s: float, threshold: float = 0.05
) -> float | None:
    """First time after which the team's mean speed stays below ``threshold`` (m/s).

    Args:
        speeds_mps: team mean speed of every step (step k covers ``[k dt, (k + 1) dt]``).

    Returns:
        Simulated seconds ``k dt`` of the first step k from which every speed is below
        the threshold, or None when the last step is not (the team never settled).
    """
    sp = np.asarray(speeds_mps, dtype=np.float64)
    if sp.size == 0 or sp[-1] >= threshold:
        return None
    above = np.flatnonzero(sp >= threshold)
    k = 0 if above.size == 0 else int(above[-1]) + 1
    return k * dt_s


#: Fields whose None means "never got there" (not "not measured"), with the episodes they
#: apply to: when no episode got there, :func:`summarize` still reports the field with
#: ``n`` 0 and ``missing`` the episodes it applies to.
REACHED_FIELDS: dict[str, Callable[[EpisodeRecord], bool]] = {
    "time_to_eta_99": lambda r: r.scenario == "coverage",
    "time_to_eta_norm_s": lambda r: r.scenario == "coverage" and r.eta_norm_threshold is not None,
    "time_to_arrival_s": lambda r: r.scenario == "crossing",
    "time_to_settle_s": lambda r: r.steps > 0,
}


def _stats(
    values: Sequence[float], feasible: tuple[float, float] = (-_INF, _INF)
) -> dict[str, Any]:
    """n, missing, mean, std (ddof 1), 95% t-interval clipped to ``feasible``, min, max.

    Over the finite values: None, NaN and ±inf count in ``missing``. ``std`` and ``ci95``
    are None for fewer than two values (no spread can be estimated from one)."""
    v = np.asarray([x for x in values if x is not None], dtype=np.float64)
    v = v[np.isfinite(v)]
    out: dict[str, Any] = {"n": int(v.size), "missing": len(values) - int(v.size)}
    if v.size == 0:
        return {**out, "mean": None, "std": None, "ci95": None, "min": None, "max": None}
    mean = float(v.mean())
    std = float(v.std(ddof=1)) if v.size > 1 else None
    ci = None
    if std is not None:
        half = _t95(v.size - 1) * std / math.sqrt(v.size)
        lo, hi = feasible
        ci = [float(min(max(mean - half, lo), hi)), float(min(max(mean + half, lo), hi))]
    return {
        **out,
        "mean": mean,
        "std": std,
        "ci95": ci,
        "min": float(v.min()),
        "max": float(v.max()),
    }


def _t95(dof: int) -> float:
    """Two-sided 95% Student-t quantile (scipy, imported lazily)."""
    from scipy.stats import t

    return float(t.ppf(0.975, dof))


def summarize(records: Sequence[EpisodeRecord]) -> dict[str, Any]:
    """Mean, std (ddof=1), 95% t-interval, min and max of every summary field.

    The interval is clipped to the field's feasible range (:data:`FEASIBLE`; robots
    arrived also to ``[0, n_agents]``, ``min_distance`` also to the records' largest
    ``max_distance_m`` where every record has one) and is None with fewer than two values.
    ``time_to_eta_99``, ``time_to_eta_norm_s``, ``time_to_arrival_s`` and
    ``time_to_settle_s`` ignore episodes that never got there and report how many in
    ``missing``, also when none got there (``n`` 0, statistics None), for the episodes
    the field applies to (:data:`REACHED_FIELDS`); a field that applies to no episode
    (a crossing time in coverage) is left out. Likewise every statistic
    is over the finite values only: ``min_distance`` of a one-robot team is inf (no
    pair), so such episodes count in ``missing``, and with no finite value at all the
    entry's ``mean``, ``std``, ``ci95``, ``min`` and ``max`` are None (never NaN or inf).
    Behind the filter, ``intervention_causes`` maps each cause to its mean share of
    robot-steps over the episodes that report it.
    """
    out: dict[str, Any] = {"episodes": len(records)}
    n_max = max((r.n_agents for r in records), default=0)
    for f in SUMMARY_FIELDS:
        vals = [getattr(r, f) for r in records]
        if all(v is None for v in vals):
            applies = REACHED_FIELDS.get(f)
            if applies is None or not any(applies(r) for r in records):
                continue
            vals = [v for v, r in zip(vals, records, strict=True) if applies(r)]
        lo, hi = FEASIBLE.get(f, (-_INF, _INF))
        if f in ("arrived", "arrived_ever"):
            hi = min(hi, float(n_max))
        if f == "min_distance" and records and all(r.max_distance_m for r in records):
            hi = min(hi, max(float(r.max_distance_m) for r in records))
        out[f] = _stats(vals, (lo, hi))
    causes = [r.intervention_causes for r in records if r.intervention_causes is not None]
    if causes:
        out["intervention_causes"] = {
            c: float(np.mean([x.get(c, 0.0) for x in causes])) for c in SAFETY_CAUSES
        }
    return out


def bootstrap_ci(
    values: Sequence[float],
    stat: Callable[[np.ndarray], np.ndarray] | None = None,
    *,
    n_boot: int = 10_000,
    level: float = 0.95,
    feasible: tuple[float, float] = (-_INF, _INF),
    seed: int = 0,
) -> list[float] | None:
    """Percentile-bootstrap confidence interval of ``stat`` over ``values``.

    Args:
        values: ``(n,)`` observations (or ``(n, k)`` rows resampled together, e.g. the
            paired times of k conditions on one seed).
        stat: vectorised statistic mapping ``(B, n, ...)`` resamples to ``(B,)``; default
            the mean over axis 1.
        n_boot: bootstrap resamples B.
        level: coverage of the interval.
        feasible: ``(lo, hi)`` the interval is clipped to.
        seed: seeds the resampling (reproducible reports).

    Returns:
        ``[lo, hi]``, or None for fewer than two observations, or when the statistic is
        undefined (NaN) in more than 1% of the resamples (e.g. a relative change over a
        resample whose baseline mean is 0); below that, such resamples are left out
        (for that relative change they are +∞, so the upper end moves in by at most one
        percentile).
    """
    v = np.asarray(values, dtype=np.float64)
    if v.shape[0] < 2:
        return None
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, v.shape[0], size=(n_boot, v.shape[0]))
    boot = (stat or (lambda x: x.mean(axis=1)))(v[idx])
    boot = boot[~np.isnan(boot)]
    if boot.size < 0.99 * n_boot:
        return None
    a = (1.0 - level) / 2.0
    lo, hi = np.quantile(boot, [a, 1.0 - a])
    return [
        float(min(max(lo, feasible[0]), feasible[1])),
        float(min(max(hi, feasible[0]), feasible[1])),
    ]


def paired_difference(
    a: Sequence[float | None],
    b: Sequence[float | None],
    *,
    n_boot: int = 10_000,
    seed: int = 0,
    feasible_diff: tuple[float, float] = (-_INF, _INF),
) -> dict[str, Any]:
    """Paired comparison of two conditions measured on the same seeds.

    Pairs where either value is None (e.g. a threshold never reached) are dropped and
    counted in ``dropped``. Reports the mean difference ``a − b`` with a bootstrap CI
    clipped to ``feasible_diff``, the relative change ``mean(a) / mean(b) − 1`` in %
    with its bootstrap CI (resampling seeds, clipped to ``[−100, ∞)``; None when over 1%
    of the resamples have a baseline mean of 0, see :func:`bootstrap_ci`), the per-pair
    differences, and the two-sided p-value of the exact (n ≤ 16) or Monte-Carlo
    (20 000 draws) paired sign-flip permutation test of the mean difference.
    ``significant`` is True when both say so at the 5% level: p < 0.05 and the
    difference's CI excludes 0 (with very few pairs the percentile bootstrap is too
    narrow; the exact test then decides: at n = 2 the smallest p is 0.5).
    """
    pairs = [(x, y) for x, y in zip(a, b, strict=True) if x is not None and y is not None]
    out: dict[str, Any] = {"n": len(pairs), "dropped": len(a) - len(pairs)}
    if not pairs:
        return {**out, "mean_diff": None, "ci95": None, "rel_pct": None, "rel_ci95": None,
                "p_value": None, "significant": None, "diffs": []}  # fmt: skip
    x, y = (np.asarray(v, dtype=np.float64) for v in zip(*pairs, strict=True))
    d = x - y
    both = np.stack([x, y], -1)

    def rel(s: np.ndarray) -> np.ndarray:
        den = s[..., 1].mean(axis=1)
        return 100.0 * (s[..., 0].mean(axis=1) / np.where(den == 0, np.nan, den) - 1.0)

    ci = bootstrap_ci(d, n_boot=n_boot, seed=seed, feasible=feasible_diff)
    rel_ci = bootstrap_ci(both, rel, n_boot=n_boot, seed=seed + 1, feasible=(-100.0, _INF))
    p = _sign_flip_p(d, seed=seed + 2)
    my = float(y.mean())
    return {
        **out,
        "mean_diff": float(d.mean()),
        "ci95": ci,
        "rel_pct": 100.0 * (float(x.mean()) / my - 1.0) if my != 0 else None,
        "rel_ci95": rel_ci,
        "p_value": p,
        "significant": (
            None if ci is None or p is None else bool((ci[0] > 0.0 or ci[1] < 0.0) and p < 0.05)
        ),
        "diffs": d.tolist(),
    }


def _sign_flip_p(d: np.ndarray, seed: int = 0, n_mc: int = 20_000) -> float | None:
    """Two-sided p-value of the paired sign-flip test of ``mean(d) = 0``: exact over all
    2^n sign patterns for n ≤ 16, else Monte Carlo (the observed pattern included)."""
    n = d.size
    if n == 0:
        return None
    obs = abs(d.mean())
    if n <= 16:
        signs = 1 - 2 * ((np.arange(2**n)[:, None] >> np.arange(n)) & 1)
        stats = np.abs(signs @ d) / n
        return float(np.mean(stats >= obs - 1e-12))
    rng = np.random.default_rng(seed)
    signs = rng.choice(np.array([-1.0, 1.0]), size=(n_mc, n))
    stats = np.abs(signs @ d) / n
    return float((np.sum(stats >= obs - 1e-12) + 1) / (n_mc + 1))
