"""Matplotlib figures for the demo and the reproduction report (Agg backend, headless).

Every function draws on axes it is given (``ax``) from plain arrays and a
:class:`~fov_marl.config.ScenarioConfig`; :mod:`fov_marl.report` lays them out. Units:
metres and simulated seconds.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "plot_eta_curves",
    "plot_eta_bands",
    "plot_configuration",
    "plot_trajectories",
    "plot_cpu_vs_n",
    "plot_calibration",
    "plot_min_distance",
    "plot_paired",
    "plot_episode_summary",
]


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _density_background(ax, config) -> None:
    L = config.arena_size_m
    x = np.linspace(0, L, 200)
    X, Y = np.meshgrid(x, x)
    qx, qy = config.density_mean_m
    phi = np.exp(-((X - qx) ** 2 + (Y - qy) ** 2) / (2 * config.density_sigma_m**2))
    ax.imshow(phi, extent=(0, L, 0, L), origin="lower", cmap="Oranges", alpha=0.6)
    ax.set_xlim(0, L)
    ax.set_ylim(0, L)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def _voronoi_cells(ax, pos: np.ndarray, L: float, R_s: float) -> None:
    """Limited-range Voronoi cells (cell ∩ sensing disk ∩ arena), drawn by contouring
    the owner index of a 400 x 400 grid (cells of robots ``(N, 2)`` m)."""
    g = np.linspace(0, L, 400)
    X, Y = np.meshgrid(g, g)
    d2 = (X[..., None] - pos[:, 0]) ** 2 + (Y[..., None] - pos[:, 1]) ** 2
    owner = np.argmin(d2, axis=-1).astype(float)
    covered = np.min(d2, axis=-1) <= R_s**2
    owner[~covered] = -1
    ax.contour(X, Y, owner, levels=np.arange(-0.5, len(pos)), colors="k", linewidths=0.6)


def plot_configuration(
    ax,
    config,
    poses: np.ndarray,
    title: str = "",
    voronoi: bool = True,
    fov: bool = True,
    zoom_m: float | None = None,
    reference: np.ndarray | None = None,
) -> None:
    """A team configuration (paper Fig. 5): density, sensing disks (radius R_s), camera
    FoV sectors (amplitude β, radius R_d, shaded), limited-range Voronoi cells, headings.

    Args:
        poses: ``(N, 3)`` world ``[x m, y m, yaw rad]``.
        zoom_m: show only ``q_m ± zoom_m`` (m); None shows the arena.
        reference: optional ``(N, 2)`` positions (m) drawn as grey dashed sensing disks,
            e.g. the configuration of the optimal η.
    """
    from matplotlib.patches import Wedge

    plt = _plt()
    _density_background(ax, config)
    poses = np.asarray(poses, dtype=np.float64)
    pos = poses[:, :2]
    if voronoi and len(pos) > 1:
        _voronoi_cells(ax, pos, config.arena_size_m, config.sensing_radius_m)
    half = 0.5 * float(config.fov_deg)
    for i, p in enumerate(pos):
        c = f"C{i % 10}"
        if fov:
            yaw = float(np.degrees(poses[i, 2]))
            w = Wedge(
                tuple(p), config.detection_range_m, yaw - half, yaw + half,
                color=c, alpha=0.12 if half < 180 else 0.05, lw=0,
            )  # fmt: skip
            ax.add_patch(w)
        ax.add_patch(plt.Circle(tuple(p), config.sensing_radius_m, fill=False, color=c, lw=1.2))
        ax.plot(*p, "o", color=c, ms=5)
        ax.arrow(
            p[0], p[1], 1.5 * np.cos(poses[i, 2]), 1.5 * np.sin(poses[i, 2]),
            head_width=0.5, color="k",
        )  # fmt: skip
    if reference is not None:
        for p in np.asarray(reference, dtype=np.float64):
            ax.add_patch(plt.Circle(tuple(p), config.sensing_radius_m, fill=False, color="0.4",
                                    ls="--", lw=0.8))  # fmt: skip
            ax.plot(*p, "+", color="0.3", ms=6)
    if zoom_m is not None:
        qx, qy = config.density_mean_m
        ax.set_xlim(qx - zoom_m, qx + zoom_m)
        ax.set_ylim(qy - zoom_m, qy + zoom_m)
    if title:
        ax.set_title(title)


def plot_trajectories(
    ax, config, traj: np.ndarray, targets: np.ndarray | None = None, title: str = ""
) -> None:
    """Ground-truth trajectories ``traj (T, N, 3)`` (paper Fig. 7 for crossing): start
    squares, end dots, targets as crosses, D_s/2 disks around the end positions."""
    traj = np.asarray(traj)
    if config.scenario == "coverage":
        _density_background(ax, config)
    else:
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    plt = _plt()
    for i in range(traj.shape[1]):
        c = f"C{i % 10}"
        ax.plot(traj[:, i, 0], traj[:, i, 1], "-", color=c, lw=1.2)
        ax.plot(traj[0, i, 0], traj[0, i, 1], "s", color=c, ms=5)
        ax.plot(traj[-1, i, 0], traj[-1, i, 1], "o", color=c, ms=6)
        ax.add_patch(
            plt.Circle(tuple(traj[-1, i, :2]), config.safety_distance_m / 2, fill=False, color=c)
        )
        if targets is not None:
            ax.plot(*np.asarray(targets)[i], "x", color=c, ms=9, mew=2)
    if title:
        ax.set_title(title)


def _stack(series: Sequence[Sequence[float]]) -> np.ndarray:
    """``(S, T)`` array of series padded at the end with their last value."""
    T = max(len(s) for s in series)
    return np.array([np.pad(np.asarray(s, float), (0, T - len(s)), mode="edge") for s in series])


def plot_eta_curves(ax, curves: dict[str, Sequence[Sequence[float]]], dt: float) -> None:
    """η(t) per condition: the mean with a min-max band (demo; the report uses
    :func:`plot_eta_bands`)."""
    for k, (label, series) in enumerate(curves.items()):
        arr = _stack(series)
        t = np.arange(arr.shape[1]) * dt
        c = f"C{k}"
        ax.plot(t, arr.mean(0), color=c, label=f"{label} (mean of {len(series)})")
        ax.fill_between(t, arr.min(0), arr.max(0), color=c, alpha=0.2)
    ax.axhline(0.99, color="gray", ls="--", lw=0.8)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("coverage efficiency η")
    ax.set_ylim(0, 1.02)
    ax.legend(loc="lower right")
    ax.grid(alpha=0.3)


def plot_eta_bands(
    ax,
    curves: Mapping[str, Sequence[Sequence[float]]],
    dt: float,
    *,
    scale: float = 1.0,
    t_max: float | None = None,
    y_min: float | None = None,
    thresholds: Sequence[tuple[float, str]] = (),
    ylabel: str = "coverage efficiency η",
) -> None:
    """η(t) per condition over seeds (paper Fig. 6): the mean line, the 25-75% band
    shaded and the 10-90% range dotted (quantiles, not ± std: η is bounded and skewed
    near its plateau); ``scale`` divides η (e.g. by the optimal η for the normalised
    panel). ``t_max`` and ``y_min`` zoom on the rise; ``thresholds`` are ``(level,
    label)`` horizontal lines."""
    for k, (label, series) in enumerate(curves.items()):
        arr = _stack(series) / scale
        t = np.arange(arr.shape[1]) * dt
        m = arr.mean(0)
        q1, q3 = np.quantile(arr, [0.25, 0.75], axis=0)
        c = f"C{k}"
        ax.plot(t, m, color=c, lw=1.6, label=f"{label} (n={len(series)})")
        ax.fill_between(t, q1, q3, color=c, alpha=0.18, lw=0)
        lo, hi = np.quantile(arr, [0.1, 0.9], axis=0)
        ax.plot(t, lo, ":", color=c, lw=0.7)
        ax.plot(t, hi, ":", color=c, lw=0.7)
    for level, text in thresholds:
        ax.axhline(level, color="gray", ls="--", lw=0.8)
        ax.annotate(text, (0.99, level), xycoords=("axes fraction", "data"), ha="right",
                    va="bottom", fontsize=7, color="gray")  # fmt: skip
    if t_max is not None:
        ax.set_xlim(0, t_max)
    if y_min is not None:
        ax.set_ylim(y_min, None)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.legend(loc="lower right", fontsize=8)
    ax.grid(alpha=0.3)


def plot_cpu_vs_n(
    ax,
    rows: list[dict[str, Any]],
    paper: dict[int, float] | None = None,
    stages: Sequence[str] = (),
) -> None:
    """Controller CPU time per robot-step vs team size (paper Table I): mean ± std over
    robots, optionally each stage of ``rows[k]["stages"]`` as a dashed line."""
    n = [r["n_agents"] for r in rows]
    ax.errorbar(
        n, [r["mean"] for r in rows], yerr=[r["std"] for r in rows], marker="o", capsize=3,
        label="fov_marl total (this machine)",
    )  # fmt: skip
    for k, st in enumerate(stages):
        ax.plot(n, [r["stages"].get(st, np.nan) for r in rows], "--", marker=".", color=f"C{k + 2}",
                label=st)  # fmt: skip
    if paper:
        ax.plot(list(paper), list(paper.values()), "s--", color="C1", label="paper Table I")
    from matplotlib.ticker import NullFormatter

    ax.set_yscale("log")
    ax.set_xscale("log")
    ax.set_xticks(n)
    ax.set_xticklabels([str(v) for v in n])
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("robots N")
    ax.set_ylabel("CPU ms per robot-step")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)


def plot_calibration(
    ax,
    t: np.ndarray,
    rates: Mapping[str, np.ndarray],
    nominal: float = 0.95,
    ax_size=None,
    size: np.ndarray | None = None,
) -> None:
    """Particle-filter calibration over time: the fraction of (robot, neighbour) pairs
    whose true position lies inside the estimated confidence ellipse, per category
    (``rates[label]`` ``(T,)``, NaN where a category is empty), against the nominal
    level; on ``ax_size`` the mean semi-major axis ``size`` (m)."""
    for k, (label, r) in enumerate(rates.items()):
        ax.plot(t, r, color=f"C{k}", lw=1.2, label=label)
    ax.axhline(nominal, color="gray", ls="--", lw=0.8, label=f"nominal {nominal:.0%}")
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("truth inside the ellipse")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    if ax_size is not None and size is not None:
        ax_size.plot(t, size, color="k", lw=1.0)
        ax_size.set_xlabel("time (s)")
        ax_size.set_ylabel("mean semi-major axis, undetected (m)")
        ax_size.grid(alpha=0.3)


def plot_min_distance(
    ax,
    curves: Mapping[str, Sequence[Sequence[float]]],
    dt: float,
    safety_distance_m: float,
    collision_distance_m: float,
) -> None:
    """Minimum pairwise distance over time for dense teams: per label, the minimum over
    seeds (solid) and the mean (dashed), with D_s and the collision distance."""
    for k, (label, series) in enumerate(curves.items()):
        arr = _stack(series)
        t = np.arange(arr.shape[1]) * dt  # sample 0 at reset
        c = f"C{k}"
        ax.plot(t, arr.min(0), color=c, lw=1.2, label=f"{label}: min over {len(series)} seeds")
        ax.plot(t, arr.mean(0), "--", color=c, lw=0.8, label=f"{label}: mean")
    ax.axhline(safety_distance_m, color="r", ls="--", lw=0.9, label=f"D_s = {safety_distance_m} m")
    ax.axhline(collision_distance_m, color="k", ls=":", lw=0.9,
               label=f"collision {collision_distance_m} m")  # fmt: skip
    ax.set_ylim(0, None)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("min pairwise distance (m)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def plot_paired(
    ax,
    values: Mapping[str, Sequence[float | None]],
    ylabel: str,
    title: str = "",
) -> None:
    """Paired per-seed values of several conditions: one grey line per seed joining its
    conditions, a dot per value (None: not reached, drawn as a hollow marker at the top),
    and the mean per condition as a black bar."""
    labels = list(values)
    arr = np.array([[np.nan if v is None else float(v) for v in values[k]] for k in labels])
    x = np.arange(len(labels))
    top = np.nanmax(arr) * 1.05 if np.isfinite(arr).any() else 1.0
    for j in range(arr.shape[1]):
        ax.plot(x, arr[:, j], "-", color="0.75", lw=0.8, zorder=1)
    for i in range(len(labels)):
        ok = np.isfinite(arr[i])
        ax.plot(np.full(ok.sum(), x[i]), arr[i, ok], "o", color=f"C{i}", ms=4, zorder=2)
        if (~ok).any():
            ax.plot(np.full((~ok).sum(), x[i]), np.full((~ok).sum(), top), "o", mfc="none",
                    color=f"C{i}", ms=5, zorder=2)  # fmt: skip
        if ok.any():
            m = float(arr[i, ok].mean())
            ax.plot([x[i] - 0.25, x[i] + 0.25], [m, m], "k-", lw=2, zorder=3)
    ax.set_xticks(x)
    ax.set_xticklabels(labels)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3, axis="y")
    if title:
        ax.set_title(title)


def plot_episode_summary(config, record, out: Path) -> Path:
    """Two panels: trajectories and final configuration, and η(t)."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(11, 5))
    traj = np.asarray(record.trajectory)
    plot_trajectories(
        axes[0], config, traj, title=f"{record.policy}, N={record.n_agents}, β={record.fov_deg:g}°"
    )
    plot_configuration(axes[0], config, traj[-1], voronoi=True)
    if record.eta_series:
        plot_eta_curves(axes[1], {record.policy: [record.eta_series]}, config.dt_s)
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
