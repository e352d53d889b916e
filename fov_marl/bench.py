"""``fov-marl bench``: timings of every layer, per robot-step, across team sizes.

Sections: ``env`` (raw env step rate, random actions, no rendering), ``vector_env``
(the batched core: B copies per call, side by side with the single env of the same N
in the same run, and the ratio; optionally ``vmas``, VMAS simple_spread on CPU when
``vmas`` is importable), ``tracker``
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

__all__ = [
    "bench_env",
    "bench_vector_env",
    "bench_vmas",
    "bench_controller",
    "run_benchmarks",
]

DEFAULT_N = (6, 9, 12, 24, 48)
#: (N, batch sizes) of the vector-env section (issue 12's acceptance figures).
VECTOR_CASES: tuple[tuple[int, tuple[int, ...]], ...] = (
    (6, (1, 64, 256)),
    (24, (64,)),
    (100, (64,)),
)


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


def _single_env_rate(n: int, steps: int, repeats: int) -> float:
    """Env-steps/s of one coverage ParallelEnv (best of ``repeats``), random actions."""
    from fov_marl.envs import fov_coverage_v0

    env = fov_coverage_v0.parallel_env(n_agents=n, max_cycles=10**9)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    acts = rng.uniform(-1, 1, (steps, n, 3)).astype(np.float32)
    names = env.possible_agents
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for k in range(steps):
            env.step(dict(zip(names, acts[k], strict=True)))
        best = min(best, time.perf_counter() - t0)
    return steps / best


def _vector_env_rate(n: int, num_envs: int, env_steps: int, repeats: int, eta_method: str) -> float:
    """Env-steps/s (copies × steps per second) of a coverage vector env, best of ``repeats``."""
    from fov_marl.envs import fov_coverage_v0

    venv = fov_coverage_v0.vector_env(
        num_envs=num_envs, n_agents=n, max_cycles=10**9, eta_method=eta_method
    )
    venv.reset(seed=0)
    steps = max(3, env_steps // num_envs)
    rng = np.random.default_rng(0)
    acts = rng.uniform(-1, 1, (min(steps, 8), num_envs, n, 3)).astype(np.float32)
    venv.step(acts[0])  # warm-up
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for k in range(steps):
            venv.step(acts[k % acts.shape[0]])
        best = min(best, time.perf_counter() - t0)
    return steps * num_envs / best


def bench_vector_env(
    cases: Sequence[tuple[int, Sequence[int]]] = VECTOR_CASES,
    quick: bool = False,
    eta_methods: Sequence[str] = ("exact", "strip"),
) -> list[dict[str, Any]]:
    """Batched coverage env against one env of the same N, measured side by side.

    For each N the single ParallelEnv is timed right before its vector envs (best of
    3 repetitions each, random actions, no rendering, the machine's load shared
    alike); ``ratio`` is the vector env's env-steps/s over the single env's.
    ``eta_method="exact"`` is bit-identical to the ParallelEnv; ``"strip"`` uses the
    cheaper training η (:class:`fov_marl.metrics.StripCoverageMetric`).
    """
    rows = []
    reps = 2 if quick else 3
    for n, batches in cases:
        single_steps = max(10, (100 if quick else 300) * 6 // max(n, 6))
        single = _single_env_rate(n, single_steps, reps)
        budget = (1500 if quick else 6000) * 6 // max(n, 6)
        for b in batches:
            for method in eta_methods:
                rate = _vector_env_rate(n, int(b), max(budget, b * 3), reps, method)
                rows.append(
                    {
                        "section": "vector_env",
                        "n_agents": n,
                        "num_envs": int(b),
                        "eta_method": method,
                        "env_steps_per_s": rate,
                        "single_env_steps_per_s": single,
                        "ratio": rate / single,
                    }
                )
    return rows


def bench_vmas(
    n_agents: int = 6, num_envs: Sequence[int] = (64, 256), steps: int = 100
) -> list[dict[str, Any]]:
    """VMAS simple_spread on CPU (one torch thread), if ``vmas`` imports; else no rows.

    VMAS is not a dependency of fov_marl; install it (it needs ``gym``) to get these rows.
    """
    try:
        import torch
        import vmas
    except Exception:  # noqa: BLE001 - vmas absent or its gym import fails
        return []
    prev = torch.get_num_threads()
    torch.set_num_threads(1)
    rows = []
    try:
        for b in num_envs:
            env = vmas.make_env(
                "simple_spread",
                num_envs=int(b),
                device="cpu",
                continuous_actions=True,
                n_agents=n_agents,
                seed=0,
            )
            env.reset()
            gen = torch.Generator().manual_seed(0)
            acts = [torch.rand(int(b), 2, generator=gen) * 2 - 1 for _ in range(n_agents)]
            env.step(acts)
            t0 = time.perf_counter()
            for _ in range(steps):
                env.step(acts)
            el = time.perf_counter() - t0
            rows.append(
                {
                    "section": "vmas",
                    "scenario": "simple_spread",
                    "n_agents": n_agents,
                    "num_envs": int(b),
                    "env_steps_per_s": steps * int(b) / el,
                }
            )
    finally:
        torch.set_num_threads(prev)
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
    # default run: the issue's figures (N = 6 at B = 1/64/256, N = 24 and 100 at B = 64);
    # with explicit team sizes: those N at B = 64
    cases = VECTOR_CASES if not n_agents else tuple((n, (64,)) for n in ns)
    rows.extend(bench_vector_env(cases, quick=quick))
    rows.extend(bench_vmas(steps=30 if quick else 100))
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


if __name__ == "__main__":  # the vector-env figures alone: python -m fov_marl.bench [--quick]
    import sys

    quick = "--quick" in sys.argv
    for r in bench_vector_env(quick=quick) + bench_vmas(steps=30 if quick else 100):
        print({k: (round(v, 2) if isinstance(v, float) else v) for k, v in r.items()})
