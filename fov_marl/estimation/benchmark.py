"""Tracker speed benchmark: milliseconds per robot-step, single tracker and batched bank.

Used by ``benchmarks/bench_tracker.py`` and (later) ``fov-marl bench``. The observations
come from :class:`fov_marl.estimation.testing.MiniWorld` (robots on smooth random
paths, the paper's camera and noise); recording them is not timed.
"""

from __future__ import annotations

import time
from collections.abc import Iterable

import numpy as np

from fov_marl.config import make_config
from fov_marl.estimation.params import TrackerParams
from fov_marl.estimation.testing import MiniWorld, RandomMotion
from fov_marl.estimation.tracker import NeighborTracker, TrackerBank

__all__ = ["bench_tracker", "format_table"]


def _record(n_agents: int, steps: int, seed: int):
    cfg = make_config(n_agents=n_agents)
    world = MiniWorld(cfg, np.random.default_rng(seed))
    pol = RandomMotion(cfg, np.random.default_rng(seed + 1))
    poses0, obs0 = world.poses.copy(), world.observe()
    acts, obs = [], []
    for _ in range(steps):
        a = pol(world.poses)
        obs.append(world.step(a))
        acts.append(a)
    return cfg, poses0, obs0, acts, obs


def _time_single(cfg, params, poses0, obs0, acts, obs, warmup, steps, seed) -> float:
    tr = NeighborTracker(cfg, 0, params, np.random.default_rng(seed))
    tr.reset(obs0[0], poses0)
    for t in range(warmup):
        tr.step(acts[t][0], obs[t][0])
    t0 = time.perf_counter()
    for t in range(warmup, warmup + steps):
        tr.step(acts[t][0], obs[t][0])
    return (time.perf_counter() - t0) / steps * 1e3


def _time_bank(cfg, params, poses0, obs0, acts, obs, warmup, steps, seed) -> float:
    b = TrackerBank(cfg, params, seed=seed)
    b.reset(obs0, poses0)
    for t in range(warmup):
        b.step(acts[t], obs[t])
    t0 = time.perf_counter()
    for t in range(warmup, warmup + steps):
        b.step(acts[t], obs[t])
    return (time.perf_counter() - t0) / steps / cfg.n_agents * 1e3


def bench_tracker(
    p_totals: Iterable[int] = (1000, 2000, 5000),
    n_agents: Iterable[int] = (6, 12, 48),
    steps: int = 100,
    warmup: int = 10,
    repeats: int = 3,
    seed: int = 0,
    single: bool = True,
    bank: bool = True,
    motion_models: Iterable[str] = ("auto",),
) -> list[dict]:
    """Time the tracker per robot-step.

    For each (P_T, N, motion model): a :class:`NeighborTracker` of robot 0 stepped alone
    (``single_ms_per_robot_step``) and a :class:`TrackerBank` of all N robots
    (``bank_ms_per_robot_step`` = bank step time / N), over ``steps`` recorded steps after
    ``warmup`` untimed ones; the minimum over ``repeats`` runs (the machine may be
    shared, and the minimum is the least disturbed).

    ``motion_models``: :class:`TrackerParams` ``motion_model`` values (``"auto"`` is the
    default mode mixture; ``"coverage"``, ``"crossing"``, ``"static"`` the paper's single
    models, for comparison).

    Returns:
        One dict per (P_T, N, model): ``p_total, n_agents, n_neighbours, motion_model,
        steps, repeats, single_ms_per_robot_step, bank_ms_per_robot_step`` (``None`` when
        skipped).

    Raises:
        ValueError: ``steps < 1``, ``warmup < 0`` or ``repeats < 1``.
    """
    if steps < 1 or warmup < 0 or repeats < 1:
        raise ValueError(
            f"steps must be >= 1, warmup >= 0 and repeats >= 1, got {steps}, {warmup}, {repeats}"
        )
    rows = []
    for n in n_agents:
        episode = _record(int(n), warmup + steps, seed)
        cfg = episode[0]
        for p_total in p_totals:
            for model in motion_models:
                params = TrackerParams(n_particles_total=int(p_total), motion_model=model)
                row: dict = {
                    "p_total": int(p_total),
                    "n_agents": int(n),
                    "n_neighbours": int(n) - 1,
                    "motion_model": str(model),
                    "steps": int(steps),
                    "repeats": int(repeats),
                    "single_ms_per_robot_step": None,
                    "bank_ms_per_robot_step": None,
                }
                args = (cfg, params, *episode[1:], warmup, steps, seed)
                if single:
                    row["single_ms_per_robot_step"] = min(
                        _time_single(*args) for _ in range(repeats)
                    )
                if bank:
                    row["bank_ms_per_robot_step"] = min(_time_bank(*args) for _ in range(repeats))
                rows.append(row)
    return rows


#: :func:`format_table` columns: (header, row key)
TABLE_COLUMNS = (
    ("P_T", "p_total"),
    ("N", "n_agents"),
    ("model", "motion_model"),
    ("single ms/robot-step", "single_ms_per_robot_step"),
    ("bank ms/robot-step", "bank_ms_per_robot_step"),
)


def format_table(rows: list[dict]) -> str:
    """Plain-text table of :func:`bench_tracker` rows, drawn by the one table formatter of
    the package, :func:`fov_marl.tables.format_table`."""
    from fov_marl.tables import format_table as _format_table

    return _format_table(rows, TABLE_COLUMNS)
