"""``fov-marl bench``: timings of every layer, per robot-step, across team sizes.

Sections: ``env`` (raw env step rate, random actions, no rendering), ``vector_env``
(the batched core: B copies per call, side by side with the single env of the same N
in the same run, and the ratio; optionally ``vmas``, VMAS simple_spread on CPU when
``vmas`` is importable), ``tracker``
(particle-filter bank), ``control`` (Lloyd, cascade, final QP), ``controller``
(the full pfcbf policy step: tracker + Lloyd + cascade + final QP) and
``vector_filter`` (the safety filter and pfcbf over B copies, one pipeline per copy
against one batched pipeline, :func:`bench_batched_filter`; also at the reduced
particle budget :data:`FAST_FILTER_PARTICLES`), ``filtered_step`` (env + filter over
B = 64 copies in 1 and 2 processes, :func:`bench_filtered_step`), ``issue12`` (the
acceptance figures of the batched core side by side, from the rows of the same run: env
ratio at N = 6, B = 64; filter ms per robot-step at B N = 384; PPO samples/s; a goal
not run has its row with ``measured`` None), ``issue10`` (pfcbf's budget, ≤ 1 ms per
robot-step at N = 6-48, from the ``controller`` rows of the paper's 40 m arena after
the warm-up, always at N = 6 and 48) and, with
``ppo=True`` (``fov-marl bench --ppo``), ``ppo`` (:func:`bench_ppo`: PPO samples/s
with the default hyper-parameters, vector adapter against the per-copy adapter, with
and without the safety filter). Every number the closing notes quote comes from here.
Timings are wall-clock (best or median over repetitions) on the current machine; every
row carries ``load_1min`` (``os.getloadavg``), since the shared machines run other jobs.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = [
    "bench_env",
    "bench_vector_env",
    "bench_batched_filter",
    "bench_ppo",
    "bench_filtered_step",
    "bench_vmas",
    "bench_controller",
    "issue10_summary",
    "issue12_summary",
    "ISSUE10_N",
    "run_benchmarks",
    "FAST_FILTER_PARTICLES",
]

#: The reduced particle budget P_T of the filter rows ``n_particles_total`` (a
#: :class:`~fov_marl.estimation.TrackerParams` field, ``tracker_params=`` of the safety
#: filter wrappers; the default is 2000). At 500 the default tracker stays calibrated on
#: every behaviour of ``tests/estimation/test_mixture_calibration.py`` (truth inside the
#: 95% ellipse in 0.926-0.954 of the steps, 3 seeds x 300 steps; detected ellipses
#: a <= 0.9 m), tested in ``test_reduced_budget_is_calibrated``; at 250 it is not
#: (0.894 for ``straight``).
FAST_FILTER_PARTICLES = 500


def _load() -> float:
    try:
        return float(os.getloadavg()[0])
    except OSError:  # pragma: no cover - no load average on this platform
        return float("nan")


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
                "load_1min": _load(),
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
                        "load_1min": _load(),
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
    arena: str = "scaled",
) -> list[dict[str, Any]]:
    """Full pfcbf controller time per robot-step, with its breakdown when available.

    ``safety_models``: the collision rows to time (``"ellipse"``, the default rows of
    :mod:`fov_marl.control.safety`; ``"mean"``, the paper's Eq. 12 row 3, for the
    ablation); one row per (model, N). ``arena``: ``"scaled"`` (L = 40·√(N/6) m, at
    least 40 m: the density of the paper's N = 6 team) or ``"paper"`` (the paper's
    40 m arena at every N). The first ``warmup`` steps are untimed. The cost grows as
    the team packs and settles: measured (pfcbf, N = 24, seed 0, one free core), 0.80 ms
    per robot-step over steps 10-70 of the scaled 80 m arena, but in the 40 m arena
    1.6 ms over steps 0-100 and 2.1-2.3 ms over steps 100-600 (the cascade's QPs:
    1.1 -> 1.5-1.7 ms), so :func:`run_benchmarks` also reports the paper's arena after
    a 100-step warm-up. (Those figures predate the batched controller for one team,
    :data:`fov_marl.pipeline.AUTO_BATCHED_MIN_COPIES`: in the paper's arena after 100
    steps, N = 6 / 24 / 48, 0.79 / 0.88 / 0.90 ms against 0.91 / 1.18 / 1.34 ms with
    the per-robot loop, seed 0, steps 100-160.)
    """
    if arena not in ("scaled", "paper"):
        raise ValueError(f"arena must be 'scaled' or 'paper', got {arena!r}")
    rows = []
    for model in safety_models:
        for n in n_agents:
            rows.append(_bench_controller_one(n, steps, warmup, fov_deg, model, arena))
    return rows


def _bench_controller_one(
    n: int, steps: int, warmup: int, fov_deg: float, safety_model: str, arena: str
) -> dict[str, Any]:
    from fov_marl.baselines import make_policy
    from fov_marl.envs import fov_coverage_v0

    # "scaled": keep the density of robots comparable
    L = max(40.0, 40.0 * np.sqrt(n / 6.0)) if arena == "scaled" else 40.0
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
        "arena": arena,
        "arena_size_m": float(L),
        "warmup_steps": int(warmup),
        "n_agents": n,
        "ms_per_robot_step": 1e3 * float(np.median(team_arr)) / n,
        "std_ms": 1e3 * float(team_arr.std()) / n,
        "team_step_ms": 1e3 * float(np.median(team_arr)),
        "load_1min": _load(),
    }
    for key, v in parts.items():
        row[f"{key}_ms"] = 1e3 * float(np.median(v)) / n
    return row


def bench_batched_filter(
    n_copies: tuple[int, ...] = (1, 16, 64, 256),
    n_agents: int = 6,
    steps: int = 10,
    warmup: int = 2,
    seed: int = 0,
    scenario: str = "coverage",
    policy: str = "filter",
    looped: bool = True,
    tracker_overrides: dict[str, Any] | None = None,
    tracker_threads: int = 1,
    draw_ahead: bool = True,
) -> list[dict]:
    """Safety filter (or pfcbf) cost per robot-step, looped over copies vs batched, one run.

    For every B in ``n_copies``, B copies of an ``n_agents`` team (``B N`` robots) are
    stepped in closed loop (env stepping untimed). Each step both variants get the same
    inputs: *looped* is today's code, one :class:`~fov_marl.pipeline.PfCbfPipeline` per
    copy with one :class:`FovCbfController` per robot (``controller="loop"``); *batched*
    is one pipeline over all copies (``n_copies=B``, one
    :class:`~fov_marl.estimation.VectorTrackerBank`, the
    :class:`~fov_marl.control.batched.BatchedFovCbfController`). The batched actions drive
    the envs; ``max_action_diff`` is the largest difference between the two variants'
    actions (normalised units). Timed: ``filter`` + ``observe`` (+ ``desired_inputs``
    for pfcbf) per step.

    Args:
        n_copies: the B values. n_agents: N. steps / warmup: timed / untimed steps.
        seed: env copy k is reset with ``seed + k``; the filters are seeded the same way.
        scenario: ``"coverage"`` or ``"crossing"``.
        policy: ``"filter"`` (u* = uniform random actions, the filter's settings:
            :class:`~fov_marl.wrappers.SafetyFilterWrapper` defaults) or ``"pfcbf"``
            (u* from Lloyd / the crossing law, pfcbf's settings).
        looped: False skips the looped variant (large B).
        tracker_overrides: :class:`~fov_marl.estimation.TrackerParams` fields on top of
            the policy's settings, e.g. ``{"n_particles_total": 500}``.
        tracker_threads: the batched pipeline's ``tracker_threads`` (the looped variant
            keeps 1); the actions are the same for every count.
        draw_ahead: :data:`fov_marl.estimation.tracker.DRAW_AHEAD` for this run (serial
            chunks draw the next chunk's noise on a helper thread); False draws inline,
            the comparison. The actions are the same either way.

    Returns:
        One dict per B: ``n_copies``, ``n_agents``, ``robots`` (B N), ``robot_steps``,
        ``looped_ms`` and ``batched_ms`` (wall ms per robot-step), ``looped_cpu_ms`` /
        ``batched_cpu_ms`` (process CPU time), ``speedup`` (looped / batched, wall),
        ``batched_stage_ms`` (tracker, safety_rows, qp, lloyd per robot-step),
        ``max_action_diff``, ``n_particles_total``, ``tracker_threads``, ``draw_ahead``,
        ``load_1min``.
    """
    import fov_marl.estimation.tracker as tracker_module

    before = tracker_module.DRAW_AHEAD
    tracker_module.DRAW_AHEAD = bool(draw_ahead)
    try:
        rows = _bench_batched_filter(
            n_copies=n_copies,
            n_agents=n_agents,
            steps=steps,
            warmup=warmup,
            seed=seed,
            scenario=scenario,
            policy=policy,
            looped=looped,
            tracker_overrides=tracker_overrides,
            tracker_threads=tracker_threads,
        )
    finally:
        tracker_module.DRAW_AHEAD = before
    for r in rows:
        r["draw_ahead"] = bool(draw_ahead)
    return rows


def _bench_batched_filter(
    *, n_copies, n_agents, steps, warmup, seed, scenario, policy, looped, tracker_overrides,
    tracker_threads,
) -> list[dict]:  # fmt: skip
    """:func:`bench_batched_filter`'s body."""
    from dataclasses import replace

    from fov_marl.config import make_config
    from fov_marl.control import ControllerParams
    from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
    from fov_marl.estimation import TrackerParams
    from fov_marl.pipeline import PfCbfPipeline
    from fov_marl.spaces import action_to_velocity
    from fov_marl.wrappers.safety_filter import FILTER_TRACKER_DEFAULTS, filter_controller_params

    if scenario not in ("coverage", "crossing"):
        raise ValueError(f"scenario must be 'coverage' or 'crossing', got {scenario!r}")
    if policy not in ("filter", "pfcbf"):
        raise ValueError(f"policy must be 'filter' or 'pfcbf', got {policy!r}")
    mod = fov_coverage_v0 if scenario == "coverage" else fov_crossing_v0
    if policy == "filter":
        tp = TrackerParams(**FILTER_TRACKER_DEFAULTS)
        # the wrapper's settings for this env (one place for both wrappers and the bench)
        cp = filter_controller_params(make_config(scenario=scenario, n_agents=n_agents), None)
    else:
        tp, cp = TrackerParams(), ControllerParams()
    if tracker_overrides:
        tp = replace(tp, **tracker_overrides)
    out = []
    for B in n_copies:
        B = int(B)
        envs = [mod.parallel_env(n_agents=n_agents) for _ in range(B)]
        agents = list(envs[0].possible_agents)
        cfg = envs[0].unwrapped.config
        obs = np.stack(
            [
                np.stack([o[a] for a in agents])
                for o in (e.reset(seed=seed + k)[0] for k, e in enumerate(envs))
            ]
        ).astype(np.float32)
        poses = np.stack([e.unwrapped.poses for e in envs])
        kw = dict(tracker_params=tp, controller_params=cp)
        bat = PfCbfPipeline(
            cfg, n_copies=B, controller="batched", tracker_threads=tracker_threads, **kw
        )
        bat.reset_arrays(obs, [seed + k for k in range(B)], poses)
        loops = []
        if looped:
            for k in range(B):
                pl = PfCbfPipeline(cfg, controller="loop", **kw)
                pl.reset_arrays(obs[k : k + 1], [seed + k], poses[k : k + 1])
                loops.append(pl)
        rng = np.random.default_rng(seed)
        acc = {"looped": 0.0, "batched": 0.0, "looped_cpu": 0.0, "batched_cpu": 0.0}
        stages = {"tracker": 0.0, "safety_rows": 0.0, "qp": 0.0, "lloyd": 0.0}
        max_diff = 0.0
        timed = 0
        for step in range(warmup + steps):
            if policy == "filter":
                a = rng.uniform(-1.0, 1.0, (B * n_agents, 3))
                v, w = action_to_velocity(a, cfg.v_max_mps, cfg.omega_max_radps)
                u = np.column_stack([v, w])
            t0, c0 = time.perf_counter(), time.process_time()
            ub = bat.desired_inputs() if policy == "pfcbf" else u
            act_b = bat.filter(ub).copy()
            t1, c1 = time.perf_counter(), time.process_time()
            tb, cb = t1 - t0, c1 - c0
            st = dict(bat.last_timings)
            tl = cl = 0.0
            for k, pl in enumerate(loops):
                t0, c0 = time.perf_counter(), time.process_time()
                ul = (
                    pl.desired_inputs()
                    if policy == "pfcbf"
                    else u[k * n_agents : (k + 1) * n_agents]
                )
                act_l = pl.filter(ul)
                tl += time.perf_counter() - t0
                cl += time.process_time() - c0
                max_diff = max(
                    max_diff, float(np.abs(act_l - act_b[k * n_agents : (k + 1) * n_agents]).max())
                )
            nxt = []
            for k, e in enumerate(envs):
                o, *_ = e.step({ag: act_b[k * n_agents + i] for i, ag in enumerate(agents)})
                if not e.agents:
                    o, _ = e.reset(seed=seed + k)
                nxt.append(np.stack([o[ag] for ag in agents]))
            obs = np.stack(nxt).astype(np.float32)
            t0, c0 = time.perf_counter(), time.process_time()
            bat.observe_arrays(obs)
            tb += time.perf_counter() - t0
            cb += time.process_time() - c0
            st["tracker"] = bat.last_timings.get("tracker", 0.0)
            for k, pl in enumerate(loops):
                t0, c0 = time.perf_counter(), time.process_time()
                pl.observe_arrays(obs[k : k + 1])
                tl += time.perf_counter() - t0
                cl += time.process_time() - c0
            if step >= warmup:
                timed += 1
                acc["batched"] += tb
                acc["batched_cpu"] += cb
                acc["looped"] += tl
                acc["looped_cpu"] += cl
                for key in stages:
                    stages[key] += st.get(key, 0.0)
        rs = max(timed * B * n_agents, 1)
        sub = stages["qp"] - stages["safety_rows"]
        row = {
            "n_copies": B,
            "n_agents": n_agents,
            "robots": B * n_agents,
            "robot_steps": timed * B * n_agents,
            "policy": policy,
            "scenario": scenario,
            "batched_ms": 1e3 * acc["batched"] / rs,
            "batched_cpu_ms": 1e3 * acc["batched_cpu"] / rs,
            "looped_ms": 1e3 * acc["looped"] / rs if looped else None,
            "looped_cpu_ms": 1e3 * acc["looped_cpu"] / rs if looped else None,
            "speedup": acc["looped"] / acc["batched"] if looped and acc["batched"] > 0 else None,
            "batched_stage_ms": {
                "tracker": 1e3 * stages["tracker"] / rs,
                "safety_rows": 1e3 * stages["safety_rows"] / rs,
                "qp": 1e3 * max(sub, 0.0) / rs,
                "lloyd": 1e3 * stages["lloyd"] / rs,
            },
            "max_action_diff": max_diff if looped else None,
            "n_particles_total": int(tp.n_particles_total),
            "tracker_threads": int(tracker_threads),
            "load_1min": _load(),
        }
        out.append(row)
    return out


def bench_filtered_step(
    num_envs: int = 64,
    n_agents: int = 6,
    workers: Sequence[int] = (1, 2),
    filter_particles: Sequence[int | None] = (None, FAST_FILTER_PARTICLES),
    steps: int = 20,
    warmup: int = 5,
    seed: int = 0,
) -> list[dict[str, Any]]:
    """Wall time of a whole filtered step (env + :class:`~fov_marl.wrappers.
    VectorSafetyFilterWrapper`, uniform random actions) over B copies, in one process and
    split over W worker processes (:class:`~fov_marl.envs.SubprocVectorEnv`), one run.

    What a trainer waits for per step. Unlike :func:`bench_batched_filter` this includes
    the env step and cannot separate the filter's stages (they run in the workers).

    Returns:
        One dict per (P_T, W): ``section`` ``"filtered_step"``, ``num_envs``,
        ``n_agents``, ``robots`` (B N), ``workers``, ``n_particles_total``,
        ``wall_ms_per_robot_step`` (median step / B N), ``speedup`` (over W = 1 of the same
        P_T, None when W = 1 was not run), ``load_1min``.
    """
    from functools import partial

    from fov_marl.config import make_config
    from fov_marl.envs import SubprocVectorEnv
    from fov_marl.wrappers import build_filtered_vector_env

    cfg = make_config(n_agents=n_agents)
    rng = np.random.default_rng(seed)
    rows: list[dict[str, Any]] = []
    for p_t in filter_particles:
        tp = {"n_particles_total": int(p_t)} if p_t else None
        make = partial(build_filtered_vector_env, config=cfg, tracker_params=tp)
        base = None
        for w in workers:
            venv = make(num_envs) if int(w) == 1 else SubprocVectorEnv(make, num_envs, int(w))
            try:
                venv.reset(seed=seed)
                times = []
                for k in range(warmup + steps):
                    act = rng.uniform(-1.0, 1.0, (num_envs, n_agents, 3))
                    t0 = time.perf_counter()
                    venv.step(act)
                    if k >= warmup:
                        times.append(time.perf_counter() - t0)
            finally:
                venv.close()
            ms = 1e3 * float(np.median(times)) / (num_envs * n_agents)
            if int(w) == 1:
                base = ms
            rows.append(
                {
                    "section": "filtered_step",
                    "num_envs": int(num_envs),
                    "n_agents": int(n_agents),
                    "robots": int(num_envs * n_agents),
                    "workers": int(w),
                    "n_particles_total": int(p_t) if p_t else 2000,
                    "wall_ms_per_robot_step": ms,
                    "speedup": base / ms if base else None,
                    "load_1min": _load(),
                }
            )
    return rows


def bench_ppo(
    n_envs: Sequence[int] = (4, 16, 64),
    safety_filter: Sequence[bool] = (False, True),
    rollouts: int = 1,
    per_copy_envs: int | None = 4,
    filter_particles: Sequence[int | None] = (None, FAST_FILTER_PARTICLES),
    seed: int = 0,
    workers: Sequence[int] = (1,),
    tracker_threads: Sequence[int] = (1,),
) -> list[dict[str, Any]]:
    """PPO samples/s (SB3, the trainer's default hyper-parameters, 1 torch thread).

    For each ``n_envs`` B, the coverage env (N = 6, training horizon 500 steps) through
    the vector adapter (:class:`~fov_marl.training.vec_env.VectorEnvVecEnv`, what
    ``fov-marl train`` uses) and, for ``B = per_copy_envs``, through the per-copy adapter
    (:class:`~fov_marl.training.vec_env.ParallelEnvVecEnv` over B ParallelEnvs, each
    behind its own :class:`~fov_marl.wrappers.SafetyFilterWrapper` with the filter);
    ``ratio`` is a row's rate over the per-copy rate of the same filter setting. Behind
    the filter, each ``filter_particles`` P_T (None: the default 2000). Each row times
    ``model.learn`` over ``rollouts`` whole rollouts (``n_steps x B x N`` samples each:
    collection and the gradient epochs, as in training); ``train_share`` is the fraction
    of that time in PPO's gradient epochs (``PPO.train``), the part no env speed-up
    reduces. Each vector row is run for every ``workers`` W (``fov-marl train --workers
    W``: the copies and the filter stepped in W processes, :class:`~fov_marl.envs.
    SubprocVectorEnv`; W > B skipped); rows carry ``workers``. Behind the filter, the
    one-process vector rows are also run for every ``tracker_threads`` T > 1 (``fov-marl
    train --filter-threads T``); rows carry ``tracker_threads``.

    Needs the ``train`` extra (torch, stable-baselines3); returns no rows without it.
    """
    try:
        import torch
        from stable_baselines3 import PPO
        from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

        from fov_marl.training.trainer import (
            DEFAULT_TRAIN_MAX_CYCLES,
            _merged_hyperparams,
            _to_sb3_kwargs,
            build_env,
            make_training_vec_env,
        )
        from fov_marl.training.vec_env import ParallelEnvVecEnv
    except ImportError:
        return []
    hp = _merged_hyperparams("ppo", None)
    kw = _to_sb3_kwargs(hp)
    env_kw = {"max_cycles": DEFAULT_TRAIN_MAX_CYCLES}
    prev = torch.get_num_threads()
    torch.set_num_threads(1)

    def one(
        adapter: str, b: int, filt: bool, p_t: int | None, w: int = 1, t: int = 1
    ) -> dict[str, Any]:
        sf_kw: dict[str, Any] | None = (
            {"tracker_params": {"n_particles_total": int(p_t)}} if p_t else None
        )
        if filt and t > 1:
            sf_kw = {**(sf_kw or {}), "tracker_threads": int(t)}

        def factory() -> Any:
            return build_env("coverage", env_kw, safety_filter=filt, safety_filter_kwargs=sf_kw)

        if adapter == "vector":
            _, venv = make_training_vec_env(b, factory, gamma=float(hp["gamma"]), workers=w)
        else:
            ad = ParallelEnvVecEnv([factory for _ in range(b)])
            venv = VecNormalize(
                VecMonitor(ad), norm_obs=True, norm_reward=True, clip_obs=10.0, gamma=hp["gamma"]
            )
        model = PPO("MlpPolicy", venv, seed=seed, device="cpu", **kw)
        train_s = [0.0]
        inner = model.train

        def timed_train() -> None:
            t0 = time.perf_counter()
            inner()
            train_s[0] += time.perf_counter() - t0

        model.train = timed_train  # type: ignore[method-assign]
        t0 = time.perf_counter()
        model.learn(total_timesteps=int(hp["n_steps"]) * venv.num_envs * int(rollouts))
        wall = time.perf_counter() - t0
        venv.close()
        return {
            "section": "ppo",
            "adapter": adapter,
            "n_envs": int(b),
            "workers": int(w),
            "tracker_threads": int(t) if filt else None,
            "safety_filter": bool(filt),
            "n_particles_total": (int(p_t) if p_t else 2000) if filt else None,
            "samples": int(model.num_timesteps),
            "samples_per_s": model.num_timesteps / wall,
            "train_share": train_s[0] / wall,
            "load_1min": _load(),
        }

    rows: list[dict[str, Any]] = []
    try:
        for filt in safety_filter:
            for p_t in filter_particles if filt else (None,):
                base = None
                if per_copy_envs:
                    base = one("per_copy", int(per_copy_envs), filt, p_t)
                    base["ratio"] = 1.0
                    rows.append(base)
                # (workers, tracker threads): every W on 1 thread, then T > 1 in 1 process
                runs = [(int(w), 1) for w in workers]
                runs += [(1, int(t)) for t in (tracker_threads if filt else ()) if int(t) > 1]
                for b in n_envs:
                    for w, t in runs:
                        if w > int(b):
                            continue
                        r = one("vector", int(b), filt, p_t, w, t)
                        r["ratio"] = r["samples_per_s"] / base["samples_per_s"] if base else None
                        rows.append(r)
    finally:
        torch.set_num_threads(prev)
    return rows


#: The issue's figures for "today" (before the batched core): PPO samples/s at the
#: default hyper-parameters with and without the filter.
ISSUE12_PPO_TODAY = {"no_filter": 6087.0, "filter": 1079.0}


def _goal_row(
    section: str, name: str, measured: float | None, goal: str, met: bool | None, **extra: Any
) -> dict[str, Any]:
    """One acceptance figure of :func:`issue10_summary` / :func:`issue12_summary`."""
    row = {"section": section, "figure": name, "measured": measured, "goal": goal}
    row.update(met=met, vs_per_copy=None, vs_issue_today=None, load_1min=None)
    row.update(extra)
    return row


#: the team sizes of issue 10's budget (<= 1 ms per robot-step at N = 6-48): the ends of
#: its range, always timed in the paper's 40 m arena by :func:`run_benchmarks`
ISSUE10_N: tuple[int, ...] = (6, 48)
#: the sizes of issue 12's figures: the env ratio at N = 6, B = 64 and the filter at
#: B N = 384 (64 copies of N = 6)
ISSUE12_N, ISSUE12_B = 6, 64
ISSUE12_ROBOTS = ISSUE12_N * ISSUE12_B


def issue10_summary(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """pfcbf's speed budget (issue 10: ≤ 1 ms per robot-step at N = 6-48) from the
    ``controller`` rows of the paper's 40 m arena (the packed team, after the warm-up),
    in the row format of :func:`issue12_summary`: one row per such controller row with
    6 ≤ N ≤ 48, and one per N of :data:`ISSUE10_N` without one, with ``measured`` and
    ``met`` None (not run), so the goal is never silently missing."""
    out = [
        _goal_row(
            "issue10",
            f"pfcbf ms/robot-step, N={r['n_agents']}, 40 m arena, after {r['warmup_steps']} steps",
            r["ms_per_robot_step"],
            "<= 1 ms",
            r["ms_per_robot_step"] <= 1.0,
            n_agents=r["n_agents"],
            load_1min=r.get("load_1min"),
        )
        for r in rows
        if r.get("section") == "controller"
        and r.get("arena") == "paper"
        and r.get("safety_model") == "ellipse"
        and 6 <= r["n_agents"] <= 48
    ]
    seen = {r["n_agents"] for r in out}
    for n in ISSUE10_N:
        if n not in seen:
            out.append(
                _goal_row(
                    "issue10",
                    f"pfcbf ms/robot-step, N={n}, 40 m arena (not run)",
                    None,
                    "<= 1 ms",
                    None,
                    n_agents=n,
                )
            )
    return sorted(out, key=lambda r: r["n_agents"])


def issue12_summary(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The acceptance figures of the batched core (issue 12), side by side, from ``rows``
    of one :func:`run_benchmarks` run: one row per goal with ``measured``, ``goal`` and
    ``met``; a goal whose rows were not run still has its row, with ``measured`` and
    ``met`` None and a figure ending in ``(not run)``.

    The goals: the env-steps/s ratio at N = 6, B = 64 (each η method); the filter's ms
    per robot-step at B N = 384 (P_T = 2000 and :data:`FAST_FILTER_PARTICLES`); the
    filtered env step at B N = 384 (each P_T, 1 and 2 workers); PPO samples/s without
    and with the filter (``fov-marl bench --ppo``). Measured rows beyond those (B N =
    1536, more B or workers) are listed too.
    """
    out: list[dict[str, Any]] = []

    def add(name: str, measured: float | None, goal: str, met: bool | None, **extra: Any):
        out.append(_goal_row("issue12", name, measured, goal, met, **extra))

    def missing(name: str, goal: str) -> None:
        if not any(r["figure"] == name for r in out):
            add(f"{name} (not run)", None, goal, None)

    for r in rows:
        if (
            r["section"] == "vector_env"
            and r["n_agents"] == ISSUE12_N
            and r["num_envs"] == ISSUE12_B
        ):
            add(
                f"env-steps/s ratio, N=6 B=64, eta {r['eta_method']}",
                r["ratio"],
                ">= 8 x one env",
                r["ratio"] >= 8.0,
                load_1min=r.get("load_1min"),
            )
    for method in ("exact", "strip"):
        missing(f"env-steps/s ratio, N={ISSUE12_N} B={ISSUE12_B}, eta {method}", ">= 8 x one env")
    for r in rows:
        if (
            r["section"] == "vector_filter"
            and r["policy"] == "filter"
            and r["robots"] >= ISSUE12_ROBOTS
        ):
            threads = r.get("tracker_threads", 1)
            add(
                f"filter ms/robot-step, B*N={r['robots']}, P_T={r.get('n_particles_total')}"
                + (f", tracker threads={threads}" if threads > 1 else "")
                + ("" if r.get("draw_ahead", True) else ", draws inline (comparison)"),
                r["batched_ms"],
                "<= 0.1 ms",
                r["batched_ms"] <= 0.1,
                load_1min=r.get("load_1min"),
            )
    for p_t in (2000, FAST_FILTER_PARTICLES):
        missing(f"filter ms/robot-step, B*N={ISSUE12_ROBOTS}, P_T={p_t}", "<= 0.1 ms")
    for r in rows:
        if r["section"] == "filtered_step" and r["robots"] >= ISSUE12_ROBOTS:
            # the whole filtered step (env + filter) in wall time, W processes: what a
            # trainer waits for; the CPU time per robot-step is not reduced by W
            add(
                f"filtered env step wall ms/robot-step, B*N={r['robots']}, "
                f"P_T={r['n_particles_total']}, workers={r['workers']}",
                r["wall_ms_per_robot_step"],
                "<= 0.1 ms (filter alone, one process, in the issue)",
                r["wall_ms_per_robot_step"] <= 0.1,
                load_1min=r.get("load_1min"),
            )
    for p_t in (2000, FAST_FILTER_PARTICLES):
        for w in (1, 2):
            missing(
                f"filtered env step wall ms/robot-step, B*N={ISSUE12_ROBOTS}, P_T={p_t}, "
                f"workers={w}",
                "<= 0.1 ms (filter alone, one process, in the issue)",
            )
    ppo_seen = {False: False, True: False}
    for r in rows:
        if r["section"] == "ppo" and r["adapter"] == "vector":
            ppo_seen[bool(r["safety_filter"])] = True
            if r["safety_filter"]:
                today, goal = ISSUE12_PPO_TODAY["filter"], 3000.0
                threads = r.get("tracker_threads") or 1
                name = (
                    f"PPO samples/s, filter P_T={r['n_particles_total']}, B={r['n_envs']}, "
                    f"workers={r.get('workers', 1)}"
                    + (f", tracker threads={threads}" if threads > 1 else "")
                )
                text = ">= 3000"
            else:
                today = ISSUE12_PPO_TODAY["no_filter"]
                goal = 2.0 * today
                name = f"PPO samples/s, no filter, B={r['n_envs']}, workers={r.get('workers', 1)}"
                text = f">= 2 x {today:.0f} (issue's today)"
            add(
                name,
                r["samples_per_s"],
                text,
                r["samples_per_s"] >= goal,
                vs_per_copy=r.get("ratio"),
                vs_issue_today=r["samples_per_s"] / today,
                load_1min=r.get("load_1min"),
            )
    if not ppo_seen[False]:
        today = ISSUE12_PPO_TODAY["no_filter"]
        add(
            "PPO samples/s, no filter (not run: fov-marl bench --ppo)",
            None,
            f">= 2 x {today:.0f} (issue's today)",
            None,
        )
    if not ppo_seen[True]:
        add("PPO samples/s, filter (not run: fov-marl bench --ppo)", None, ">= 3000", None)
    return out


def run_benchmarks(
    quick: bool = False, n_agents: Sequence[int] | None = None, ppo: bool = False
) -> list[dict[str, Any]]:
    """All sections; ``quick`` uses fewer repetitions; ``ppo`` adds :func:`bench_ppo`
    (about a minute quick, several minutes otherwise) to the ``issue12`` summary.

    ``n_agents`` (default :data:`DEFAULT_N`) are the team sizes of the ``tracker``
    (default: 6, 12 and 48), ``control`` and ``controller`` sections; the other sections
    keep their own sizes whatever it is: ``env`` N = 6 and 48, ``vector_env``
    :data:`VECTOR_CASES`, ``vector_filter`` and ``filtered_step`` N = 6 (B N = 384 for
    the issue), and the paper-arena ``controller`` rows of ``issue10`` also run at
    :data:`ISSUE10_N`. ``issue10`` and ``issue12`` have a row for every goal (``measured``
    None when it was not run, e.g. PPO without ``ppo``).
    """
    ns = tuple(n_agents) if n_agents else DEFAULT_N
    rows = bench_env(n_agents=(6, 48), steps=100 if quick else 500)
    # the issue's figures (N = 6 at B = 1/64/256, N = 24 and 100 at B = 64), whatever
    # the team sizes of the other sections
    rows.extend(bench_vector_env(VECTOR_CASES, quick=quick))
    rows.extend(bench_vmas(steps=30 if quick else 100))
    for policy in ("filter", "pfcbf"):
        for r in bench_batched_filter(
            n_copies=(1, 16, 64) if quick else (1, 16, 64, 256),
            steps=3 if quick else 10,
            warmup=1 if quick else 2,
            policy=policy,
        ):
            rows.append({"section": "vector_filter", "policy": policy, **r})
    # the whole filtered step over 1 and 2 processes (SubprocVectorEnv), B N = 384
    rows.extend(bench_filtered_step(steps=5 if quick else 20, warmup=1 if quick else 5))
    # at B N = 384 (the issue's figure): the reduced particle budget, and both budgets
    # with the tracker on 2 threads (wall time; same actions)
    # (and the default budget on 1 thread with the chunks' draws inline, the comparison
    # for the draws ahead: same actions)
    for p_t, threads, ahead in (
        (2000, 1, False),
        (FAST_FILTER_PARTICLES, 1, True),
        (2000, 2, True),
        (FAST_FILTER_PARTICLES, 2, True),
    ):
        for r in bench_batched_filter(
            n_copies=(64,),
            steps=3 if quick else 10,
            warmup=1 if quick else 2,
            looped=False,
            tracker_overrides={"n_particles_total": p_t},
            tracker_threads=threads,
            draw_ahead=ahead,
        ):
            rows.append({"section": "vector_filter", "policy": "filter", **r})
    if ppo:
        rows.extend(
            bench_ppo(
                n_envs=(4, 16) if quick else (4, 16, 64),
                filter_particles=(None, FAST_FILTER_PARTICLES),
                workers=(1, 2),
                tracker_threads=(1, 2),
            )
        )
    try:
        from fov_marl.estimation.benchmark import bench_tracker

        for r in bench_tracker(
            p_totals=(1000, 2000, 5000),
            n_agents=ns if n_agents else (6, 12, 48),
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
        # the issue's budget (<= 1 ms per robot-step, N = 6-48) in the paper's 40 m arena,
        # once the team has packed (bench_controller's docstring)
        rows.extend(
            bench_controller(
                n_agents=tuple(sorted({n for n in ns if n <= 48} | set(ISSUE10_N))),
                steps=20 if quick else 60,
                warmup=10 if quick else 100,
                arena="paper",
            )
        )
    except ValueError:  # pfcbf not registered
        pass
    rows.extend(issue10_summary(rows))
    rows.extend(issue12_summary(rows))
    return rows


if __name__ == "__main__":  # the vector-env figures alone: python -m fov_marl.bench [--quick]
    import sys

    quick = "--quick" in sys.argv
    for r in bench_vector_env(quick=quick) + bench_vmas(steps=30 if quick else 100):
        print({k: (round(v, 2) if isinstance(v, float) else v) for k, v in r.items()})
