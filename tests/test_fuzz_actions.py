"""Fuzz the actions given to both envs, their AEC versions and SafetyFilterWrapper.

One agent's action (or the whole action dict) is replaced by a fuzzed value and the
env is stepped. Outcomes (see ``tests/test_fuzz_env.py`` for the classes):

* a real numeric array-like of shape ``(3,)`` with finite entries (lists, tuples,
  int/float arrays of any width, NumPy scalars inside lists; values outside [-1, 1]
  are clipped, as the env docstring says) must step cleanly, with finite observations
  and rewards;
* anything else (strings, bytes, bools, complex, ``None``, object arrays, dicts, sets,
  another shape, NaN/inf) must raise a ``ValueError`` naming the agent (or, for a
  malformed dict, naming the actions);
* nothing may hang.

``python tests/test_fuzz_actions.py`` runs the whole sweep and prints the counts.
"""

from __future__ import annotations

import math
import re
import sys
import time
from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from test_fuzz_env import PROBLEMS, Outcome, bounded, examples

from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
from fov_marl.wrappers import SafetyFilterWrapper

TARGETS = ("coverage", "crossing", "coverage-aec", "crossing-aec", "filter")
LIMIT_S = 10.0
AGENT = "robot_1"  # the fuzzed agent: not the first, so the others' actions are fine


class _Opaque:
    def __repr__(self) -> str:
        return "<opaque>"


class _BadArray:
    """An object whose ``__array__`` raises (a broken tensor type)."""

    def __array__(self, dtype=None, copy=None):
        raise RuntimeError("broken __array__")


#: wrong values for one agent's action: each must be a ValueError naming the agent
INVALID: list[Any] = [
    "1",
    "111",
    "",
    b"abc",
    ["1", "1", "1"],
    np.array(["1", "1", "1"]),
    np.array([b"1", b"1", b"1"]),
    [1j, 0, 0],
    [1 + 0j, 0.0, 0.0],
    np.array([1, 0, 0], dtype=complex),
    np.array([0.1, 0.2, 0.3], dtype=object),
    [None, 0.0, 0.0],
    None,
    True,
    [True, False, True],
    np.array([True, False, True]),
    [True, 0.5, 0],  # red team 4: a bool among numbers (np.asarray makes it float)
    (0.1, np.bool_(False), 0.0),
    [np.array(True), 0.0, 0.0],  # red team 25: a 0-d bool array among numbers
    {"vx": 1.0, "vy": 0.0, "w": 0.0},
    {1.0, 2.0, 3.0},
    [[1.0], [0.0, 0.0], [0.0]],
    _Opaque(),
    _BadArray(),
    1.0,
    np.float32(0.5),
    [1.0, 0.0],
    [1.0, 0.0, 0.0, 0.0],
    [[1.0, 0.0, 0.0]],
    np.zeros((3, 1)),
    np.zeros(0),
    [math.nan, 0.0, 0.0],
    [0.0, math.inf, 0.0],
    np.array([0.0, 0.0, -np.inf], dtype=np.float32),
    [10**400, 0, 0],
    np.datetime64("2024-01-01"),
    [np.datetime64("2024-01-01")] * 3,
]

#: valid actions: each must step cleanly
VALID: list[Any] = [
    [0.0, 0.0, 0.0],
    (1.0, -1.0, 0.5),
    [1, 0, -1],
    np.array([0.1, 0.2, 0.3]),
    np.array([0.1, 0.2, 0.3], dtype=np.float32),
    np.array([0.1, 0.2, 0.3], dtype=np.float16),
    np.array([1, 0, -1], dtype=np.int8),
    np.array([1, 0, 1], dtype=np.uint64),
    [np.float64(0.5), np.int32(1), np.float32(-0.25)],
    [5.0, -5.0, 100.0],  # clipped to [-1, 1] (documented)
    [1e300, -1e300, 1e300],
    [5e-324, -0.0, 0.0],
    np.array([0.3, 0.2, 0.1])[::-1],  # a non-contiguous view
    np.ma.masked_array([0.1, 0.2, 0.3]),
    memoryview(np.array([0.1, 0.2, 0.3])),
]

#: malformed action dicts: (label, builder(agents) -> actions, text the message names)
DICTS = [
    ("list", lambda ag: [np.zeros(3) for _ in ag], "actions"),
    ("none", lambda ag: None, "actions"),
    ("array", lambda ag: np.zeros((len(ag), 3)), "actions"),
    ("missing", lambda ag: {a: np.zeros(3) for a in ag[1:]}, "robot_0"),
    ("extra", lambda ag: {**{a: np.zeros(3) for a in ag}, "robot_99": np.zeros(3)}, "robot_99"),
    ("int-key", lambda ag: {**{a: np.zeros(3) for a in ag}, 0: np.zeros(3)}, "0"),
]


@dataclass(frozen=True)
class Case:
    target: str
    value: Any
    expect: str  # "valid" or "invalid"
    dict_label: str = ""  # a malformed dict instead of one bad action

    def __str__(self) -> str:
        if self.dict_label:
            return f"{self.target}: actions={self.dict_label}"
        try:
            shown = repr(self.value)[:50]
        except Exception:
            shown = type(self.value).__name__
        # ids must be the same in every pytest-xdist worker: no memory addresses
        shown = re.sub(r" at 0x[0-9a-fA-F]+", "", shown)
        return f"{self.target}: {AGENT}={shown} [{self.expect}]"


def _make(target: str):
    scenario = target.split("-")[0] if target != "filter" else "coverage"
    mod = fov_coverage_v0 if scenario == "coverage" else fov_crossing_v0
    if target.endswith("-aec"):
        return mod.env(n_agents=3, max_cycles=20)
    env = mod.parallel_env(n_agents=3, max_cycles=20)
    if target == "filter":
        return SafetyFilterWrapper(env, tracker_params={"n_particles_total": 60})
    return env


def exercise(case: Case) -> None:
    env = _make(case.target)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    if case.target.endswith("-aec"):
        if case.dict_label:
            return  # AEC takes one action at a time: no dict
        for _ in range(2 * len(env.possible_agents)):
            agent = env.agent_selection
            obs, rew, term, trunc, _ = env.last()
            assert np.all(np.isfinite(obs)) and math.isfinite(rew)
            act = case.value if agent == AGENT else rng.uniform(-1, 1, 3).astype(np.float32)
            env.step(None if term or trunc else act)
        return
    agents = list(env.agents)
    if case.dict_label:
        builder = next(b for label, b, _ in DICTS if label == case.dict_label)
        env.step(builder(agents))
        return
    for _ in range(2):
        acts = {a: rng.uniform(-1, 1, 3).astype(np.float32) for a in env.agents}
        acts[AGENT] = case.value
        obs, rew, term, trunc, infos = env.step(acts)
        for a, o in obs.items():
            assert np.all(np.isfinite(o)) and env.observation_space(a).contains(o)
        assert all(math.isfinite(r) for r in rew.values())


def classify(case: Case, out: Outcome) -> str | None:
    if out.kind == "hang":
        return "hang"
    if out.kind == "exception":
        return "raw"
    if out.kind == "ok":
        if case.target.endswith("-aec") and case.dict_label:
            return None
        return "silent" if case.expect == "invalid" else None
    if case.expect == "valid":
        return "rejected"
    want = next((w for label, _, w in DICTS if label == case.dict_label), AGENT)
    return None if want in out.message else "unnamed"


def run(case: Case) -> tuple[str | None, Outcome]:
    out = bounded(lambda: exercise(case), LIMIT_S)
    return classify(case, out), out


def sweep() -> list[Case]:
    cases = []
    for t in TARGETS:
        cases += [Case(t, v, "invalid") for v in INVALID]
        cases += [Case(t, v, "valid") for v in VALID]
        if not t.endswith("-aec"):
            cases += [Case(t, None, "invalid", label) for label, _, _ in DICTS]
    return cases


SWEEP = sweep()
SUBSET = [c for c in SWEEP if c.target in ("coverage", "coverage-aec")] + [
    c for c in SWEEP if c.target == "filter" and (c.dict_label or c.value is INVALID[0])
]


def _assert_good(case: Case) -> None:
    problem, out = run(case)
    assert problem is None, f"{problem}: {case}: {out.message}"


@pytest.mark.parametrize("case", SUBSET, ids=str)
def test_subset(case):
    _assert_good(case)


@pytest.mark.slow
@pytest.mark.parametrize("case", SWEEP, ids=str)
def test_full_sweep(case):
    _assert_good(case)


@settings(max_examples=examples(30), deadline=None)
@given(
    target=st.sampled_from(["coverage", "crossing"]),
    arr=hnp.arrays(
        dtype=st.one_of(
            hnp.floating_dtypes(), hnp.integer_dtypes(), hnp.complex_number_dtypes(),
            hnp.boolean_dtypes(), hnp.unicode_string_dtypes(max_len=3),
        ),
        shape=hnp.array_shapes(min_dims=0, max_dims=2, min_side=0, max_side=4),
    ),
)  # fmt: skip
def test_hypothesis_arrays(target, arr):
    """Any dtype and shape: real (3,) finite arrays step, everything else is named."""
    ok = arr.dtype.kind in "iuf" and arr.shape == (3,)
    if ok:
        with np.errstate(all="ignore"):
            ok = bool(np.all(np.isfinite(arr.astype(np.float64))))
    _assert_good(Case(target, arr, "valid" if ok else "invalid"))


def test_the_harness_can_fail():
    case = Case("coverage", "1", "invalid")
    assert classify(case, Outcome("ok", "", 0.0)) == "silent"
    assert classify(case, Outcome("exception", "TypeError", 0.0)) == "raw"
    assert classify(case, Outcome("value_error", "bad action", 0.0)) == "unnamed"
    assert classify(Case("coverage", [0, 0, 0], "valid"), Outcome("value_error", "", 0)) == (
        "rejected"
    )


def main() -> int:
    t0 = time.perf_counter()
    counts: Counter = Counter()
    for case in SWEEP:
        problem, out = run(case)
        counts[problem or "good"] += 1
        if problem:
            print(f"{problem}: {case}: {out.message[:200]}", file=sys.stderr)
    print(
        f"actions: {len(SWEEP)} cases, "
        + ", ".join(f"{counts[p]} {p}" for p in PROBLEMS)
        + f" ({time.perf_counter() - t0:.1f} s)"
    )
    return int(any(counts[p] for p in PROBLEMS))


if __name__ == "__main__":
    raise SystemExit(main())
