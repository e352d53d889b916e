"""``fov-marl bench``: timings of every layer, per robot-step, across team sizes.

Sections: ``env`` (raw env step rate, random actions, no rendering), ``tracker``
(particle-filter bank), ``control`` (Lloyd, cascade, final QP) and ``controller``
(the full pfcbf policy step: tracker + Lloyd + cascade + final QP). Every number
the closing notes quote comes from here. Timings are wall-clock medians over
repetitions on the current machine.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["bench_env", "bench_controller", "run_benchmarks"]

DEFAULT_N = (6, 9, 12, 24, 48)


def bench_env(n_agents: Sequence[int] = (6, 48), steps: int = 300) -> list[dict[str, Any]]:
    """Raw env step rate with random actions and no rendering."""
    from fov_marl.envs import fov_coverage_v0

    rows = []
    for n in n_agents:
        env = fov_coverage_v0.parallel_env(n_agents=n, max_cycles=steps + 10)
        env.reset(seed=0)
        rng = np.random.default_rng(0)
        acts = [rng.uniform(-1, 1, (n, 3)).astype(np.float32) for _ in range(steps)]
        names = env.possible_agents
        t0 = time.perf_counter()
        for k in range(steps):
            env.step(dict(zip(names, acts[k], strict=True)))
        el = time.perf_counter() - t0
        rows.append(
            {
                "section": "env",
                "n_agents": n,
                "env_steps_per_s": steps / el,
                "agent_steps_per_s": steps * n / el,
                "ms_per_env_step": 1e3 * el / steps,
            }
        )
    return rows


def bench_controller(
    n_agents: Sequence[int] = DEFAULT_N,
    steps: int = 60,
    warmup: int = 10,
    fov_deg: float = 120.0,
    safety_models: Sequence[str] = ("ellipse",),
) -> list[dict[str, Any]]:
    """Full pfcbf controller time per robot-step, with its breakdown when available.

    ``safety_models``: the collision rows to time (``"ellipse"``, the default rows of
    :mod:`fov_marl.control.safety`; ``"mean"``, the paper's Eq. 12 row 3, for the
    ablation); one row per (model, N).
    """
    rows = []
    for model in safety_models:
        for n in n_agents:
            rows.append(_bench_controller_one(n, steps, warmup, fov_deg, model))
    return rows


def _bench_controller_one(
    n: int, steps: int, warmup: int, fov_deg: float, safety_model: str
) -> dict[str, Any]:
    from fov_marl.baselines import make_policy
    from fov_marl.envs import fov_coverage_v0

    L = max(40.0, 40.0 * np.sqrt(n / 6.0))  # keep the density of robots comparable
    env = fov_coverage_v0.parallel_env(
        n_agents=n,
        fov_deg=fov_deg,
        arena_size_m=L,
        density_mean_m=(L / 2, L / 2),
        max_cycles=steps + warmup + 5,
    )
    obs, _ = env.reset(seed=0)
    pol = make_policy("pfcbf", env, controller_params={"safety_model": safety_model})
    pol.reset(seed=0)
    team = []
    parts: dict[str, list[float]] = {}
    for k in range(steps + warmup):
        t0 = time.perf_counter()
        act = pol.act(obs)
        el = time.perf_counter() - t0
        if k >= warmup:
            team.append(el)
            for key, v in getattr(pol, "last_timings", {}).items():
                parts.setdefault(key, []).append(v)
        obs, *_ = env.step(act)
    team_arr = np.asarray(team)
    row = {
        "section": "controller",
        "safety_model": safety_model,
        "n_agents": n,
        "ms_per_robot_step": 1e3 * float(np.median(team_arr)) / n,
        "std_ms": 1e3 * float(team_arr.std()) / n,
        "team_step_ms": 1e3 * float(np.median(team_arr)),
    }
    for key, v in parts.items():
        row[f"{key}_ms"] = 1e3 * float(np.median(v)) / n
    return row


def run_benchmarks(
    quick: bool = False, n_agents: Sequence[int] | None = None
) -> list[dict[str, Any]]:
    """All sections; ``quick`` uses fewer repetitions."""
    ns = tuple(n_agents) if n_agents else DEFAULT_N
    rows = bench_env(n_agents=sorted({6, 48, *ns}), steps=100 if quick else 500)
    try:
        from fov_marl.estimation.benchmark import bench_tracker

        for r in bench_tracker(
            p_totals=(1000, 2000, 5000),
            n_agents=sorted({6, 12, 48} & set(ns)) or ns,
            steps=20 if quick else 100,
            repeats=1 if quick else 3,
        ):
            rows.append({"section": "tracker", **r})
    except ImportError:
        pass
    try:
        from fov_marl.control.benchmark import bench_control

        for r in bench_control(n_agents=ns, steps=20 if quick else 100):
            rows.append({"section": "control", **r})
    except ImportError:
        pass
    try:
        big = () if n_agents else (200,)  # the issue's team-step target at N = 200
        rows.extend(bench_controller(n_agents=ns + big, steps=20 if quick else 60))
        rows.extend(
            bench_controller(n_agents=ns, steps=20 if quick else 60, safety_models=("mean",))
        )
    except ValueError:  # pfcbf not registered
        pass
    return rows
