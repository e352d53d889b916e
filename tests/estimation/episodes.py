"""Shared helpers: a recorded MiniWorld episode to replay through trackers."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fov_marl.config import ScenarioConfig, make_config
from fov_marl.estimation.testing import MiniWorld, RandomMotion


@dataclass
class Episode:
    config: ScenarioConfig
    poses0: np.ndarray
    obs0: np.ndarray  # (N, D)
    actions: list[np.ndarray]  # (N, 3) per step
    obs: list[np.ndarray]  # (N, D) per step
    poses: list[np.ndarray]  # (N, 3) per step, ground truth after the step


def record_episode(n_agents=6, steps=50, seed=0, motion=RandomMotion, **cfg_kw) -> Episode:
    cfg = make_config(n_agents=n_agents, **cfg_kw)
    world = MiniWorld(cfg, np.random.default_rng(seed), poses=cfg.initial_poses)
    pol = motion(cfg, np.random.default_rng(seed + 1000))
    poses0 = world.poses.copy()
    obs0 = world.observe()
    acts, obss, poses = [], [], []
    for _ in range(steps):
        a = pol(world.poses)
        obss.append(world.step(a))
        acts.append(a)
        poses.append(world.poses.copy())
    return Episode(cfg, poses0, obs0, acts, obss, poses)
