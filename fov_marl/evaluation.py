"""Seeded episode runs and summaries shared by the CLI, the report and the tests.

An :class:`EpisodeRecord` holds what ``results.json`` stores per episode (schema in
design.md); :func:`summarize` adds mean, std and a 95% confidence interval.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fov_marl.baselines import make_policy
from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
from fov_marl.metrics import time_to_eta

__all__ = [
    "EpisodeRecord",
    "SCENARIOS",
    "make_env",
    "run_episode",
    "summarize",
    "SUMMARY_FIELDS",
]

SCENARIOS = {"coverage": fov_coverage_v0, "crossing": fov_crossing_v0}


def make_env(scenario: str, safety_filter: bool = False, render_mode: str | None = None, **kw):
    """Build a scenario's ParallelEnv, optionally behind the SafetyFilterWrapper.

    Raises:
        ValueError: unknown scenario or invalid config keyword/value.
    """
    if scenario not in SCENARIOS:
        raise ValueError(f"scenario must be one of {sorted(SCENARIOS)}, got {scenario!r}")
    env = SCENARIOS[scenario].parallel_env(render_mode=render_mode, **kw)
    if safety_filter:
        from fov_marl.wrappers import SafetyFilterWrapper

        env = SafetyFilterWrapper(env)
    return env


@dataclass
class EpisodeRecord:
    """One evaluated episode (the per-episode record of ``results.json``).

    Times are simulated seconds; ``cpu_ms_per_robot_step`` is the wall-clock time
    of the controller (policy + safety filter, not the simulator) per robot per step.
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
    safety_fallbacks: int | None = None
    time_to_settle_s: float | None = None
    path_length_m: float | None = None
    mean_speed_last_50s: float | None = None
    eta_series: list[float] = field(default_factory=list, repr=False)
    trajectory: list[list[list[float]]] = field(default_factory=list, repr=False)

    def to_json(self, with_series: bool = True) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        if not with_series:
            d.pop("eta_series")
        d.pop("trajectory")
        return d


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
    **env_kwargs: Any,
) -> EpisodeRecord:
    """Run one seeded episode and measure it.

    Args:
        scenario: ``"coverage"`` or ``"crossing"``.
        policy: a registered name (``make_policy``) or a factory ``f(env) -> Policy``.
        seed: seeds the env (start poses, camera noise) and the policy.
        safety_filter: wrap the env in :class:`fov_marl.wrappers.SafetyFilterWrapper`.
        max_steps: stop earlier than the env's ``max_cycles``.
        record_trajectory: keep the ground-truth poses of every step.
        stop_at_eta: end the episode once η reaches this value (saves time in sweeps
            that only need the time to η = 0.99).
        on_step: called as ``on_step(env, infos)`` after every step (rendering).
        **env_kwargs: config fields for the env.
    """
    env = make_env(scenario, safety_filter=safety_filter, render_mode=render_mode, **env_kwargs)
    name = policy if isinstance(policy, str) else getattr(policy, "__name__", "custom")
    pol = (
        make_policy(policy, env, **(policy_kwargs or {}))
        if isinstance(policy, str)
        else policy(env)
    )
    cfg = env.unwrapped.config
    obs, infos = env.reset(seed=seed)
    pol.reset(seed=seed)
    n = cfg.n_agents
    dt = cfg.dt_s
    eta_series: list[float] = []
    traj: list[list[list[float]]] = []
    cpu: list[float] = []
    interventions = fallbacks = safety_fb = 0
    du_sum = 0.0
    have_filter = False
    speeds: list[float] = []
    path = 0.0
    prev_xy = env.unwrapped.poses[:, :2]
    m = infos[env.possible_agents[0]]["metrics"]
    if "eta" in m:
        eta_series.append(m["eta"])
    if record_trajectory:
        traj.append(env.unwrapped.poses.tolist())
    arrival_t = None
    steps = 0
    limit = max_steps if max_steps is not None else cfg.max_cycles
    while env.agents and steps < limit:
        t0 = time.perf_counter()
        actions = pol.act(obs)
        t_policy = time.perf_counter() - t0
        obs, _, term, trunc, infos = env.step(actions)
        steps += 1
        info0 = infos[env.possible_agents[0]]
        t_filter = 0.0
        if "safety" in info0:
            have_filter = True
            t_filter = float(getattr(env, "last_cpu_s", 0.0))
            saf = [infos[a]["safety"] for a in infos]
            interventions += sum(int(x["intervened"]) for x in saf)
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
        m = info0["metrics"]
        if "eta" in m:
            eta_series.append(m["eta"])
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
    return EpisodeRecord(
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
        safety_fallbacks=safety_fb if (have_filter or pipe is not None) else None,
        time_to_settle_s=time_to_settle(speeds, dt),
        path_length_m=path,
        mean_speed_last_50s=float(np.mean(last)) if last else None,
        eta_series=eta_series,
        trajectory=traj,
    )


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
)


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


def _stats(values: Sequence[float]) -> dict[str, Any]:
    v = np.asarray([x for x in values if x is not None], dtype=np.float64)
    out: dict[str, Any] = {"n": int(v.size), "missing": len(values) - int(v.size)}
    if v.size == 0:
        return {**out, "mean": None, "std": None, "ci95": None, "min": None, "max": None}
    mean = float(v.mean())
    std = float(v.std(ddof=1)) if v.size > 1 else 0.0
    half = _t95(v.size - 1) * std / math.sqrt(v.size) if v.size > 1 else 0.0
    return {
        **out,
        "mean": mean,
        "std": std,
        "ci95": [mean - half, mean + half],
        "min": float(v.min()),
        "max": float(v.max()),
    }


def _t95(dof: int) -> float:
    """Two-sided 95% Student-t quantile (scipy, imported lazily)."""
    from scipy.stats import t

    return float(t.ppf(0.975, dof))


def summarize(records: Sequence[EpisodeRecord]) -> dict[str, Any]:
    """Mean, std (ddof=1), 95% t-interval, min and max of every summary field.

    ``time_to_eta_99`` and ``time_to_arrival_s`` ignore episodes that never got
    there and report how many in ``missing``.
    """
    out: dict[str, Any] = {"episodes": len(records)}
    for f in SUMMARY_FIELDS:
        vals = [getattr(r, f) for r in records]
        if all(v is None for v in vals):
            continue
        out[f] = _stats(vals)
    return out
