"""Matplotlib figures for the demo and the reproduction report (Agg backend, headless)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "plot_eta_curves",
    "plot_configuration",
    "plot_trajectories",
    "plot_cpu_vs_n",
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
    """Limited-range Voronoi cells (cell ∩ sensing disk ∩ arena), drawn by contouring."""
    g = np.linspace(0, L, 400)
    X, Y = np.meshgrid(g, g)
    d2 = (X[..., None] - pos[:, 0]) ** 2 + (Y[..., None] - pos[:, 1]) ** 2
    owner = np.argmin(d2, axis=-1).astype(float)
    covered = np.min(d2, axis=-1) <= R_s**2
    owner[~covered] = -1
    ax.contour(X, Y, owner, levels=np.arange(-0.5, len(pos)), colors="k", linewidths=0.6)


def plot_configuration(
    ax, config, poses: np.ndarray, title: str = "", voronoi: bool = True
) -> None:
    """Final configuration with sensing disks and limited-range Voronoi cells (paper Fig. 5)."""
    plt = _plt()
    _density_background(ax, config)
    pos = np.asarray(poses)[:, :2]
    if voronoi and len(pos) > 1:
        _voronoi_cells(ax, pos, config.arena_size_m, config.sensing_radius_m)
    for i, p in enumerate(pos):
        ax.add_patch(plt.Circle(p, config.sensing_radius_m, fill=False, color=f"C{i % 10}", lw=1.2))
        ax.plot(*p, "o", color=f"C{i % 10}", ms=5)
        yaw = poses[i][2]
        ax.arrow(p[0], p[1], 1.5 * np.cos(yaw), 1.5 * np.sin(yaw), head_width=0.5, color="k")
    if title:
        ax.set_title(title)


def plot_trajectories(
    ax, config, traj: np.ndarray, targets: np.ndarray | None = None, title: str = ""
) -> None:
    """Ground-truth trajectories ``traj (T, N, 3)`` (paper Fig. 7 for crossing)."""
    traj = np.asarray(traj)
    if config.scenario == "coverage":
        _density_background(ax, config)
    else:
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    for i in range(traj.shape[1]):
        c = f"C{i % 10}"
        ax.plot(traj[:, i, 0], traj[:, i, 1], "-", color=c, lw=1.2)
        ax.plot(traj[0, i, 0], traj[0, i, 1], "s", color=c, ms=5)
        ax.plot(traj[-1, i, 0], traj[-1, i, 1], "o", color=c, ms=6)
        if targets is not None:
            ax.plot(*targets[i], "x", color=c, ms=9, mew=2)
    if title:
        ax.set_title(title)


def plot_eta_curves(ax, curves: dict[str, Sequence[Sequence[float]]], dt: float) -> None:
    """η(t) per condition: the mean with a min-max band (paper Fig. 6)."""
    for k, (label, series) in enumerate(curves.items()):
        T = max(len(s) for s in series)
        arr = np.array([np.pad(s, (0, T - len(s)), mode="edge") for s in series])
        t = np.arange(T) * dt
        c = f"C{k}"
        ax.plot(t, arr.mean(0), color=c, label=f"{label} (mean of {len(series)})")
        ax.fill_between(t, arr.min(0), arr.max(0), color=c, alpha=0.2)
    ax.axhline(0.99, color="gray", ls="--", lw=0.8)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("coverage efficiency η")
    ax.set_ylim(0, 1.02)
    ax.legend(loc="lower right")
    ax.grid(alpha=0.3)


def plot_cpu_vs_n(ax, rows: list[dict[str, Any]], paper: dict[int, float] | None = None) -> None:
    """Controller CPU time per robot-step vs team size (paper Table I)."""
    n = [r["n_agents"] for r in rows]
    m = [r["mean"] for r in rows]
    s = [r["std"] for r in rows]
    ax.errorbar(n, m, yerr=s, marker="o", capsize=3, label="fov_marl (this machine)")
    if paper:
        ax.plot(list(paper), list(paper.values()), "s--", label="paper Table I")
        ax.set_yscale("log")
    ax.set_xlabel("robots N")
    ax.set_ylabel("CPU ms per robot-step")
    ax.grid(alpha=0.3, which="both")
    ax.legend()


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
