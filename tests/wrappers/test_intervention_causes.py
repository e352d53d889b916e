"""Why the safety filter changed an action: ``safety/cause_bits`` (:mod:`fov_marl.infos`),
from :func:`fov_marl.control.safety.violated_kind_bits` and the pipeline's report."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fov_marl.control import safety as S
from fov_marl.envs import fov_coverage_v0
from fov_marl.evaluation import run_episode, summarize
from fov_marl.infos import SAFETY_CAUSES, cause_counts, cause_names, safety_of
from fov_marl.wrappers import SafetyFilterWrapper

STILL = np.zeros(3, np.float32)


def test_row_kinds_are_the_first_causes():
    codes = (
        S.ROW_NEIGHBOUR, S.ROW_BLIND, S.ROW_WALL, S.ROW_CONE,
        S.ROW_DENSITY, S.ROW_LAST_SEEN, S.ROW_BUDGET,
    )  # fmt: skip
    assert codes == tuple(range(7))
    assert SAFETY_CAUSES[:7] == S.ROW_KIND_NAMES
    assert len(set(SAFETY_CAUSES)) == len(SAFETY_CAUSES)


def test_cause_names_decode_bits_and_refuse_bad_values():
    assert cause_names(0) == ()
    assert cause_names(1 << 6 | 1 << 8) == ("budget", "look")
    assert cause_names(np.int64(1)) == ("neighbour",) == cause_names(1.0)  # tensor floats
    top = (1 << len(SAFETY_CAUSES)) - 1
    assert cause_names(top) == SAFETY_CAUSES
    for bad in (-1, top + 1, 2.5, float("nan")):
        with pytest.raises(ValueError, match="cause_bits must be an integer in"):
            cause_names(bad)


def test_cause_counts_count_each_cause_as_cause_names_decodes_it():
    rng = np.random.default_rng(5)
    bits = rng.integers(0, 1 << len(SAFETY_CAUSES), 200)
    counts = cause_counts(bits)
    want = [sum(c in cause_names(b) for b in bits) for c in SAFETY_CAUSES]
    assert counts.dtype == np.int64 and counts.tolist() == want
    assert cause_counts([]).tolist() == [0] * len(SAFETY_CAUSES)


def _reference_bits(A, b, kind, u, tol):
    """Row by row: the bit of every real row that ``u`` breaks by more than ``tol``."""
    out = np.zeros(len(u), dtype=np.int64)
    for r in range(len(u)):
        for k in range(kind.shape[1]):
            if kind[r, k] >= 0 and float(A[r, k] @ u[r]) + float(b[r, k]) < -tol:
                out[r] |= 1 << int(kind[r, k])
    return out


@settings(max_examples=60, deadline=None)
@given(
    r=st.integers(1, 4),
    k=st.integers(0, 9),
    seed=st.integers(0, 2**32 - 1),
)
def test_violated_kind_bits_matches_a_row_by_row_reference(r, k, seed):
    rng = np.random.default_rng(seed)
    A = np.zeros((r, k, 3))
    ang = rng.uniform(-math.pi, math.pi, (r, k))
    A[..., 0], A[..., 1] = -np.cos(ang), -np.sin(ang)
    b = rng.uniform(-0.5, 1.0, (r, k))
    b[rng.random((r, k)) < 0.2] = 0.0  # rows that hold
    kind = rng.integers(-1, 7, (r, k)).astype(np.int8)  # -1: padding
    b[kind < 0] = np.inf
    u = rng.uniform(-1.0, 1.0, (r, 3))
    rows = S.SafetyRows(A, b, kind, np.zeros((r, k)))
    got = S.violated_kind_bits(rows, u)
    assert got.dtype == np.int64 and got.shape == (r,)
    np.testing.assert_array_equal(got, _reference_bits(A, b, kind, u, 1e-9))
    # the standstill breaks exactly the rows with b < 0
    held = ((kind >= 0) & (b < -1e-9)).any(axis=1)
    np.testing.assert_array_equal(S.violated_kind_bits(rows, np.zeros((r, 3))) != 0, held)


def _pair(poses, acts, steps, **controller_params):
    """Two robots behind the filter; returns robot 0's (intervened, causes) per step."""
    env = SafetyFilterWrapper(
        fov_coverage_v0.parallel_env(n_agents=2, initial_poses=np.asarray(poses)),
        controller_params=controller_params or None,
    )
    env.reset(seed=0)
    out = []
    for _ in range(steps):
        _, _, _, _, infos = env.step(
            {"robot_0": np.asarray(acts[0], np.float32), "robot_1": acts[1]}
        )
        s = safety_of(infos["robot_0"])
        assert bool(s["causes"]) == bool(s["intervened"])
        out.append((bool(s["intervened"]), s["causes"]))
    return out


def _first_change(report):
    return next(c for changed, c in report if changed)


def test_head_on_pair_is_changed_for_its_neighbour():
    """The first outside check's case: both drive at each other, in view: the neighbour's
    rows change the action, not the blind travel budget."""
    poses = [[18.7, 20.0, 0.0], [21.3, 20.0, math.pi]]
    fwd = np.array([1.0, 0.0, 0.0], np.float32)
    report = _pair(poses, (fwd, fwd), 15)
    causes = {c for _, cs in report for c in cs}
    assert "neighbour" in _first_change(report)
    assert "budget" not in causes and "other" not in causes


def test_backing_blind_is_changed_for_the_budget():
    """Backing away from its only neighbour, 14 m ahead: unchanged until the blind travel
    budget (0.5 m) is spent, then changed for the budget (the look turns it too)."""
    poses = [[20.0, 20.0, 0.0], [34.0, 20.0, math.pi]]
    report = _pair(poses, ([-1.0, 0.0, 0.0], STILL), 8)
    assert not report[0][0] and not report[1][0]  # 0.4 m: within the budget
    assert "budget" in _first_change(report)
    assert all("neighbour" not in cs for _, cs in report)


def test_a_push_into_the_wall_is_changed_for_the_wall():
    poses = [[20.0, 39.0, math.pi / 2], [5.0, 5.0, 0.0]]  # facing the wall, 0.5 m off
    report = _pair(poses, ([1.0, 0.0, 0.0], STILL), 10)
    assert _first_change(report) == ("wall",)


def test_random_actions_every_change_has_a_cause_and_the_episode_reports_them():
    rec = run_episode("coverage", "random", 3, safety_filter=True, n_agents=4, max_steps=60)
    shares = rec.intervention_causes
    assert set(shares) == set(SAFETY_CAUSES)
    assert all(0.0 <= v <= 1.0 for v in shares.values())
    assert rec.intervention_rate > 0.1
    # every changed robot-step has at least one cause, and only changed ones have any
    assert max(shares.values()) <= rec.intervention_rate <= sum(shares.values()) + 1e-12
    assert shares["budget"] > 0.0 and shares["other"] == 0.0
    summary = summarize([rec, rec])
    assert summary["intervention_causes"] == pytest.approx(shares)
    plain = run_episode("coverage", "random", 3, n_agents=4, max_steps=5)
    assert plain.intervention_causes is None and "intervention_causes" not in summarize([plain])
