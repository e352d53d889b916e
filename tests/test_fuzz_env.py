"""Fuzz every config keyword of both envs (and the tracker parameters) as a hostile user.

Each case builds ``fov_coverage_v0`` or ``fov_crossing_v0`` with one keyword set to a
fuzzed value, then resets and steps it. The outcome must be one of

* a clean run: reset and three steps, finite observations inside their Box, finite
  rewards and state;
* a ``ValueError`` whose message names the keyword (or, for a cross-field bound, one
  of the fields that set it),

within a time bound. The oracle is this file's own table of types and of values that
must be accepted (from the docstrings of :class:`fov_marl.config.ScenarioConfig`),
not the code under test, and it classifies each case as

* ``raw``: any other exception (a traceback deep inside NumPy, a ``TypeError``);
* ``unnamed``: a ``ValueError`` that does not name the field;
* ``silent``: a wrongly typed value (str, bytes, complex, bool for a number, float
  for an integer, ...) accepted;
* ``rejected``: a value the docstrings allow was refused;
* ``hang``: the case ran past its time bound.

The normal suite runs a representative subset (a fixed sample of the sweep plus
hypothesis draws); ``-m slow`` runs the whole sweep. ``python tests/test_fuzz_env.py``
runs the whole sweep and prints the counts.
"""

from __future__ import annotations

import dataclasses
import math
import os
import signal
import sys
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from decimal import Decimal
from fractions import Fraction
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fov_marl.config import ScenarioConfig
from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
from fov_marl.estimation import TrackerParams

MODULES = {"coverage": fov_coverage_v0, "crossing": fov_crossing_v0}


def examples(n: int) -> int:
    """Hypothesis examples per property: ``n`` (time-bounded for the normal suite), or
    ``FOV_FUZZ_EXAMPLES`` for a deliberate longer search."""
    return int(os.environ.get("FOV_FUZZ_EXAMPLES", n))


CASE_TIME_LIMIT_S = 10.0
PROBLEMS = ("raw", "unnamed", "silent", "rejected", "hang")

# ------------------------------------------------------------------------------ oracle
#: kind of every ScenarioConfig field (a new field must be added here)
KINDS: dict[str, str] = {
    "scenario": "scenario",
    "n_agents": "int",
    "arena_size_m": "real",
    "fov_deg": "real",
    "detection_range_m": "real",
    "sensing_radius_m": "real",
    "safety_distance_m": "real",
    "robot_radius_m": "real",
    "v_max_mps": "real",
    "omega_max_radps": "real",
    "meas_cov_diag": "seq3",
    "meas_noise_clip_sigma": "real",
    "density_mean_m": "seq2",
    "density_sigma_m": "real",
    "dt_s": "real",
    "max_cycles": "int",
    "initial_poses": "poses",
    "init_min_separation_m": "real",
    "crossing_radius_m": "real",
    "crossing_jitter_m": "real",
    "target_tolerance_m": "real",
    "eta_grid_m": "real",
    "reward_eta_gain": "real",
    "progress_gain": "real",
    "arrival_bonus": "real",
    "collision_penalty": "real",
    "safety_penalty": "real",
}

BIG = 1e6
#: (scenario, field) -> closed interval of values that must be accepted with every
#: other field at its default; "*" applies to both scenarios.
SAFE_REAL: dict[tuple[str, str], tuple[float, float]] = {
    ("coverage", "arena_size_m"): (10.0, 1000.0),  # 10 m: issue 15's rejected case
    ("crossing", "arena_size_m"): (25.5, 1000.0),  # crossing_radius_m 12 must fit
    ("*", "fov_deg"): (1e-3, 360.0),
    ("*", "detection_range_m"): (1e-3, BIG),
    ("coverage", "sensing_radius_m"): (1e-3, 300.0),
    ("crossing", "sensing_radius_m"): (1e-3, BIG),  # unused by crossing
    ("*", "safety_distance_m"): (1.001, BIG),
    ("*", "robot_radius_m"): (1e-3, 0.99),
    ("*", "v_max_mps"): (1e-6, BIG),
    ("*", "omega_max_radps"): (1e-6, BIG),
    ("*", "meas_noise_clip_sigma"): (1.0, 1000.0),
    ("coverage", "density_sigma_m"): (0.1, BIG),
    ("crossing", "density_sigma_m"): (1e-6, BIG),
    ("*", "dt_s"): (1e-6, 5.0),
    ("*", "init_min_separation_m"): (1.0, 5.0),
    ("coverage", "crossing_radius_m"): (1e-3, BIG),  # crossing field: free in coverage
    # N = 4, jitter 0.5: 2 R sin(pi/4) - 2 sqrt(2) 0.5 >= 1 (no two starts in collision)
    ("crossing", "crossing_radius_m"): (1.71, 19.5),
    ("coverage", "crossing_jitter_m"): (0.0, BIG),
    ("crossing", "crossing_jitter_m"): (0.0, 5.6),  # R = 12, N = 4: jitter <= 5.65
    ("*", "target_tolerance_m"): (1e-6, BIG),
    ("coverage", "eta_grid_m"): (0.01, 1.0),
    ("crossing", "eta_grid_m"): (1e-9, 1.0),
    ("*", "reward_eta_gain"): (0.0, 1e9),
    ("*", "progress_gain"): (0.0, 1e9),
    ("*", "arrival_bonus"): (0.0, 1e9),
    ("*", "collision_penalty"): (0.0, 1e9),
    ("*", "safety_penalty"): (0.0, 1e9),
}
SAFE_INT = {"n_agents": (1, 12), "max_cycles": (1, 10**12)}
SAFE_SEQ = {
    ("*", "meas_cov_diag"): (0.0, BIG),
    ("coverage", "density_mean_m"): (0.0, 40.0),
    ("crossing", "density_mean_m"): (-BIG, BIG),  # coverage field: free in crossing
}
#: fields a cross-field error about ``field`` may name instead of it
RELATED: dict[str, set[str]] = {
    "arena_size_m": {
        "robot_radius_m",
        "density_mean_m",
        "density_sigma_m",
        "crossing_radius_m",
        "crossing_jitter_m",
        "eta_grid_m",
        "init_min_separation_m",
        "sensing_radius_m",
    },
    "robot_radius_m": {"safety_distance_m", "init_min_separation_m", "crossing_radius_m"},
    "eta_grid_m": {"density_sigma_m", "sensing_radius_m"},
    "n_agents": {"sensing_radius_m", "init_min_separation_m", "crossing_radius_m"},
    "crossing_jitter_m": {"crossing_radius_m"},
}


def _safe(table: dict, scenario: str, field: str):
    return table.get((scenario, field), table.get(("*", field)))


class _Opaque:
    def __repr__(self) -> str:
        return "<opaque>"


#: values of the wrong type for each kind: every one must be rejected
WRONG_TYPE: dict[str, list[Any]] = {
    "real": [
        "2.5",
        "",
        b"2.5",
        np.str_("2.5"),
        2.5 + 0j,
        1j,
        np.complex128(2.5),
        True,
        False,
        np.bool_(True),
        None,
        [2.5],
        (2.5,),
        {"value": 2.5},
        {2.5},
        np.array([2.5]),
        np.array("2.5"),
        np.array(2.5 + 0j),
        _Opaque(),
        Decimal("2.5"),
        len,
    ],
    "int": [
        "6",
        b"6",
        6.0,
        np.float64(6.0),
        6.5,
        6 + 0j,
        True,
        np.bool_(False),
        None,
        [6],
        np.array([6]),
        np.array(6.0),
        Fraction(6, 1),
        _Opaque(),
    ],
    "seq2": [
        "20,20",
        b"20",
        20.0,
        None,
        [20.0],
        [20.0, 20.0, 20.0],
        ["20", "20"],
        [True, 20.0],
        [20.0 + 0j, 20.0],
        np.array(["20", "20"]),
        np.array([20 + 0j, 20]),
        np.array([True, False]),
        np.array([[20.0, 20.0]]),
        [[20.0], [20.0]],
        {20.0, 21.0},
        {"x": 20.0, "y": 20.0},
        [None, 20.0],
        np.array([20.0, None], dtype=object),
    ],
    "seq3": [
        "0.1,0.1,0.5",
        0.1,
        None,
        [0.1, 0.1],
        ["0.1", "0.1", "0.5"],
        [0.1, 0.1, True],
        [0.1, 0.1, 1j],
        np.array([0.1, 0.1, 0.5], dtype=complex),
        np.array(["0.1", "0.1", "0.5"]),
        {"x": 0.1},
        np.zeros((3, 1)),
    ],
    "poses": [
        "poses",
        5.0,
        True,
        {"robot_0": [5, 5, 0]},
        "bad-rows",  # replaced per case by string rows
        "bool-array",
        "complex-array",
        "object-array",
        "ragged",
        "nested-none",
        "wrong-cols",
        "extra-row",
        "flat",
    ],
    "scenario": [1, None, b"coverage", ["coverage"], "Coverage", "patrol", True],
}

#: edge values of the right type: either accepted (clean run) or a named ValueError
EDGE: dict[str, list[Any]] = {
    "real": [
        0,
        -0.0,
        -1,
        5e-324,
        1e-300,
        1e-9,
        0.5,
        1,
        2,
        np.float32(3.5),
        np.float16(2.0),
        np.int64(7),
        np.uint8(200),
        Fraction(7, 2),
        np.array(1.5),
        1e5,
        1e6,
        1e7,
        1e300,
        1.7976931348623157e308,
        -1e308,
        10**400,
        -(10**400),
        math.nan,
        math.inf,
        -math.inf,
        np.float64(np.nan),
    ],
    "int": [
        0,
        -1,
        1,
        2,
        3,
        12,
        255,
        256,
        257,
        10**6,
        10**18,
        2**63,
        -(2**63),
        np.int8(5),
        np.uint64(4),
        np.array(3),
    ],
    "seq2": [
        (0.0, 0.0),
        (40.0, 40.0),
        (-1.0, 20.0),
        (math.nan, 20.0),
        (math.inf, 20.0),
        np.array([20, 20], dtype=np.int32),
        np.array([20.5, 19.5], dtype=np.float32),
        [np.float64(10.0), np.int16(30)],
        (1e300, 1e300),
        (10**400, 20.0),
    ],
    "seq3": [
        (0.0, 0.0, 0.0),
        (1e6, 1e6, 1e6),
        (1e7, 0.1, 0.1),
        (-0.1, 0.1, 0.5),
        (math.nan, 0.1, 0.1),
        np.array([1, 1, 1]),
        np.array([0.2, 0.2, 0.2], dtype=np.float32),
        (1e-300, 1e-300, 1e-300),
    ],
    "poses": ["outside", "overlap", "yaw-big", "nan", "inf", "int-array", "float32-array"],
    "scenario": ["coverage", "crossing"],
}


def _poses_value(token: Any, n: int) -> Any:
    """Concrete ``initial_poses`` for the symbolic tokens above (n robots)."""
    good = [[5.0 + 3.0 * i, 5.0 + 2.0 * (i % 3), 0.1 * i] for i in range(n)]
    if not isinstance(token, str) or token == "poses":
        return token
    arr = np.array(good)
    return {
        "bad-rows": [[str(x) for x in row] for row in good],
        "bool-array": np.ones((n, 3), dtype=bool),
        "complex-array": arr.astype(complex),
        "object-array": arr.astype(object),
        "ragged": [row[:2] if i == 0 else row for i, row in enumerate(good)],
        "nested-none": [[None, 5.0, 0.0]] + good[1:],
        "wrong-cols": arr[:, :2],
        "extra-row": np.vstack([arr, [[30.0, 30.0, 0.0]]]),
        "flat": arr.reshape(-1),
        "outside": np.vstack([arr[:-1], [[45.0, 5.0, 0.0]]]),
        "overlap": np.vstack([arr[:-1], [arr[0] + [0.3, 0.0, 0.0]]]),
        "yaw-big": arr + [0.0, 0.0, 1e6],
        "nan": np.vstack([arr[:-1], [[np.nan, 5.0, 0.0]]]),
        "inf": np.vstack([arr[:-1], [[5.0, np.inf, 0.0]]]),
        "int-array": np.rint(arr).astype(np.int64),
        "float32-array": arr.astype(np.float32),
        "good": good,
    }[token]


# ------------------------------------------------------------------------------ cases
@dataclass(frozen=True)
class Case:
    """One fuzz case: ``MODULES[scenario].<api>(**{field: value})``."""

    scenario: str
    field: str
    value: Any
    expect: str  # "valid" (must run), "invalid" (must be rejected), "either"
    api: str = "parallel"  # or "aec"

    def kwargs(self) -> dict[str, Any]:
        if self.field == "initial_poses":
            n = 6 if self.scenario == "coverage" else 4
            return {"initial_poses": _poses_value(self.value, n)}
        return {self.field: self.value}

    def __str__(self) -> str:
        try:
            shown = repr(self.value)[:60]
        except Exception:
            shown = type(self.value).__name__
        return f"{self.scenario}.{self.api}({self.field}={shown}) [{self.expect}]"


def _valid_values(scenario: str, field: str, rng: np.random.Generator, k: int) -> list[Any]:
    kind = KINDS[field]
    if kind == "real":
        lo, hi = _safe(SAFE_REAL, scenario, field)
        vals: list[Any] = [lo, hi, 0.5 * (lo + hi)]
        if lo > 0:
            vals += list(np.exp(rng.uniform(math.log(lo), math.log(hi), k)))
        else:
            vals += list(rng.uniform(lo, hi, k))
        vals += [np.float32(np.clip(np.float32(vals[2]), lo, hi)), np.float64(vals[-1])]
        if float(lo).is_integer() or float(hi) >= 1.0:
            iv = int(math.ceil(max(lo, 1.0)))
            if iv <= hi:
                vals += [iv, np.int64(iv)]
        return [v for v in vals if lo <= float(v) <= hi]
    if kind == "int":
        lo, hi = SAFE_INT[field]
        return [
            lo,
            min(hi, lo + 1),
            np.int64(lo),
            np.int32(min(hi, 3)),
            int(rng.integers(lo, min(hi, 12) + 1)),
        ]
    if kind in ("seq2", "seq3"):
        lo, hi = _safe(SAFE_SEQ, scenario, field)
        n = 2 if kind == "seq2" else 3
        top = min(hi, 40.0) if field == "density_mean_m" else min(hi, 2.0)
        vals = [tuple(rng.uniform(max(lo, 0.0), top, n)) for _ in range(k)]
        return vals + [list(vals[0]), np.asarray(vals[0]), tuple([lo] * n)]
    if kind == "poses":
        return ["good", "int-array", "float32-array", None]
    if kind == "scenario":
        return [scenario]
    raise AssertionError(kind)


def sweep(seed: int = 0, valid_per_field: int = 4) -> list[Case]:
    """Every field of both envs x (wrong types, edge values, valid samples)."""
    rng = np.random.default_rng(seed)
    cases: list[Case] = []
    for scenario in MODULES:
        for field, kind in KINDS.items():
            for v in WRONG_TYPE[kind]:
                if kind == "scenario" and v == scenario:
                    continue
                cases.append(Case(scenario, field, v, "invalid"))
            if kind == "scenario":
                other = "crossing" if scenario == "coverage" else "coverage"
                cases.append(Case(scenario, field, other, "invalid"))
            else:
                for v in EDGE[kind]:
                    cases.append(Case(scenario, field, v, "either"))
            for v in _valid_values(scenario, field, rng, valid_per_field):
                cases.append(Case(scenario, field, v, "valid"))
    # the AEC env goes through the same checks (PettingZoo conversion)
    for scenario in MODULES:
        for field in ("fov_deg", "n_agents", "initial_poses", "meas_cov_diag"):
            kind = KINDS[field]
            cases.append(Case(scenario, field, WRONG_TYPE[kind][0], "invalid", api="aec"))
            cases.append(
                Case(scenario, field, _valid_values(scenario, field, rng, 1)[0], "valid", api="aec")
            )
    return cases


# ------------------------------------------------------------------------------ running
class _Timeout(BaseException):
    pass


@dataclass
class Outcome:
    kind: str  # "ok", "value_error", "exception", "hang"
    message: str
    seconds: float
    error: BaseException | None = None


def bounded(fn: Callable[[], Any], limit_s: float) -> Outcome:
    """Run ``fn`` with a wall-clock bound (SIGALRM); classify how it ended."""

    def on_alarm(signum, frame):  # pragma: no cover - only on a hang
        raise _Timeout()

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, limit_s)
    t0 = time.perf_counter()
    try:
        fn()
        out = Outcome("ok", "", 0.0)
    except _Timeout:
        out = Outcome("hang", f"ran past {limit_s} s", 0.0)
    except ValueError as exc:
        out = Outcome("value_error", str(exc), 0.0, exc)
    except Exception as exc:
        out = Outcome("exception", f"{type(exc).__name__}: {exc}", 0.0, exc)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    out.seconds = time.perf_counter() - t0
    if out.seconds > limit_s:
        out.kind = "hang"
    return out


def _check_obs(env: Any, obs: dict[str, np.ndarray]) -> None:
    for a, o in obs.items():
        assert np.all(np.isfinite(o)), f"non-finite observation of {a}"
        assert env.observation_space(a).contains(o), f"observation of {a} outside its Box"


def exercise(case: Case) -> None:
    """Build, reset and step the env of ``case``; raise on any misbehaviour."""
    mod = MODULES[case.scenario]
    rng = np.random.default_rng(1)
    if case.api == "aec":
        env = mod.env(**case.kwargs())
        env.reset(seed=0)
        for _ in env.agent_iter(max_iter=3 * len(env.possible_agents)):
            obs, rew, term, trunc, info = env.last()
            assert np.all(np.isfinite(obs)) and math.isfinite(rew)
            env.step(None if term or trunc else rng.uniform(-1, 1, 3).astype(np.float32))
        env.close()
        return
    env = mod.parallel_env(**case.kwargs())
    obs, infos = env.reset(seed=0)
    _check_obs(env, obs)
    assert np.all(np.isfinite(env.state()))
    for _ in range(3):
        if not env.agents:
            break
        acts = {a: rng.uniform(-1, 1, 3).astype(np.float32) for a in env.agents}
        obs, rew, term, trunc, infos = env.step(acts)
        _check_obs(env, obs)
        assert all(math.isfinite(r) for r in rew.values()), f"non-finite reward {rew}"
        assert np.all(np.isfinite(env.state())), "non-finite state"
    env.close()


def classify(case: Case, out: Outcome, names: set[str] | None = None) -> str | None:
    """The problem a case shows (one of PROBLEMS) or None when it behaved."""
    if out.kind == "hang":
        return "hang"
    if out.kind == "exception":
        return "raw"
    if out.kind == "ok":
        return "silent" if case.expect == "invalid" else None
    # a ValueError
    if case.expect == "valid":
        return "rejected"
    allowed = {case.field} | (names if names is not None else RELATED.get(case.field, set()))
    return None if any(n in out.message for n in allowed) else "unnamed"


def run(case: Case, limit_s: float = CASE_TIME_LIMIT_S) -> tuple[str | None, Outcome]:
    out = bounded(lambda: exercise(case), limit_s)
    return classify(case, out), out


def tally(cases: list[Case], verbose: bool = False) -> tuple[Counter, list[str]]:
    counts: Counter = Counter()
    failures = []
    for case in cases:
        problem, out = run(case)
        counts[problem or "good"] += 1
        if problem:
            failures.append(f"{problem}: {case}: {out.message[:200]}")
            if verbose:
                print(failures[-1], file=sys.stderr)
    return counts, failures


def _assert_good(case: Case) -> None:
    problem, out = run(case)
    assert problem is None, f"{problem}: {case}: {out.message}"


# ------------------------------------------------------------------------------ tests
def test_every_field_has_a_kind():
    assert set(KINDS) == {f.name for f in dataclasses.fields(ScenarioConfig)}


SWEEP = sweep()
#: representative subset for the normal suite: every field's first wrong type, the
#: worst edge values, and one valid value per field and scenario
_SUBSET_EDGES = {"2.5", 1e300, 10**400, math.nan, -1, 0, 257, (math.nan, 20.0), "nan", "outside"}


def _subset() -> list[Case]:
    seen: set[tuple] = set()
    out = []
    for c in SWEEP:
        key = (c.scenario, c.field, c.expect, c.api)
        pick = key not in seen
        if c.expect == "either":
            try:
                pick = any(
                    c.value is v or (type(c.value) is type(v) and c.value == v)
                    for v in _SUBSET_EDGES
                )
            except Exception:
                pick = False
        if pick:
            seen.add(key)
            out.append(c)
    return out


SUBSET = _subset()


@pytest.mark.parametrize("case", SUBSET, ids=str)
def test_subset(case):
    _assert_good(case)


@pytest.mark.slow
@pytest.mark.parametrize("case", SWEEP, ids=str)
def test_full_sweep(case):
    _assert_good(case)


def _real_values() -> st.SearchStrategy:
    return st.one_of(
        st.floats(allow_nan=True, allow_infinity=True),
        st.integers(min_value=-(10**20), max_value=10**20),
        st.floats(width=32).map(np.float32),
        st.sampled_from(WRONG_TYPE["real"]),
    )


@settings(max_examples=examples(40), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    scenario=st.sampled_from(sorted(MODULES)),
    field=st.sampled_from(sorted(f for f, k in KINDS.items() if k == "real")),
    data=st.data(),
)
def test_hypothesis_real_fields(scenario, field, data):
    """Any value in a real field: a clean run, or a ValueError naming the field."""
    value = data.draw(_real_values(), label="value")
    lo, hi = _safe(SAFE_REAL, scenario, field)
    if not _is_real_for_oracle(value):
        expect = "invalid"
    elif math.isfinite(float(value)) and lo <= float(value) <= hi:
        expect = "valid"
    else:
        expect = "either"
    _assert_good(Case(scenario, field, value, expect))


def _is_real_for_oracle(value: Any) -> bool:
    if isinstance(value, bool | np.bool_ | str | bytes | complex | np.complexfloating):
        return False
    return isinstance(value, int | float | np.integer | np.floating | Fraction)


@settings(max_examples=examples(25), deadline=None)
@given(
    scenario=st.sampled_from(sorted(MODULES)),
    n=st.integers(1, 12),
    fov=st.floats(1e-3, 360.0),
    arena=st.floats(30.0, 200.0),
)
def test_hypothesis_valid_combinations_run(scenario, n, fov, arena):
    """Combinations inside the documented ranges are accepted and run: reset and a few
    steps of random actions, every observation finite and inside its space."""
    env = MODULES[scenario].parallel_env(n_agents=n, fov_deg=fov, arena_size_m=arena, max_cycles=4)
    assert env.config.density_mean_m == (arena / 2, arena / 2)
    assert env.config.n_agents == n and env.config.fov_deg == fov
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    steps = 0
    while env.agents:
        for a, o in obs.items():
            assert np.all(np.isfinite(o)) and env.observation_space(a).contains(o), (a, o)
        acts = {a: rng.uniform(-1.0, 1.0, 3).astype(np.float32) for a in env.agents}
        obs, rewards, _, _, _ = env.step(acts)
        assert all(np.isfinite(r) for r in rewards.values())
        steps += 1
    assert steps == 4 or scenario == "crossing"  # crossing may end when all arrive


# ---------------------------------------------------------------- tracker parameters
def _tracker_kinds() -> dict[str, str]:
    kinds = {}
    for f in dataclasses.fields(TrackerParams):
        d = f.default
        kinds[f.name] = (
            "bool" if isinstance(d, bool) else "int" if isinstance(d, int) else
            "choice" if isinstance(d, str) else "real"
        )  # fmt: skip
    return kinds


TRACKER_KINDS = _tracker_kinds()
_BOOL_WRONG = [1, 0, "True", "false", None, 1.0, np.int64(1), [True]]


def tracker_cases() -> list[tuple[str, Any, str]]:
    """(field, value, expect) for every TrackerParams field."""
    out = []
    for name, kind in TRACKER_KINDS.items():
        default = getattr(TrackerParams(), name)
        out.append((name, default, "valid"))
        wrong = {
            "bool": _BOOL_WRONG,
            "int": WRONG_TYPE["int"],
            "real": WRONG_TYPE["real"],
            "choice": [1, None, b"auto", ["auto"], "AUTO", "nonsense", True],
        }[kind]
        for v in wrong:
            if name == "coverage_standoff_m" and v is None:
                continue  # None is its documented "default from the config"
            out.append((name, v, "invalid"))
        if kind in ("int", "real"):
            for v in EDGE[kind]:
                out.append((name, v, "either"))
    return out


TRACKER_CASES = tracker_cases()


def _tracker_problem(name: str, value: Any, expect: str) -> tuple[str | None, Outcome]:
    out = bounded(lambda: TrackerParams(**{name: value}), 5.0)
    return classify(Case("coverage", name, value, expect), out, names=set()), out


@pytest.mark.parametrize(("name", "value", "expect"), TRACKER_CASES, ids=str)
def test_tracker_params(name, value, expect):
    problem, out = _tracker_problem(name, value, expect)
    assert problem is None, f"{problem}: TrackerParams({name}={value!r}): {out.message}"


def test_the_harness_can_fail():
    """Each problem class is detected (so a passing sweep means something)."""
    case = Case("coverage", "fov_deg", "2.5", "invalid")
    assert classify(case, bounded(lambda: None, 1.0)) == "silent"
    assert classify(case, bounded(lambda: np.add("a", 1), 1.0)) == "raw"
    assert classify(case, bounded(lambda: int("x"), 1.0)) == "unnamed"
    assert classify(case, bounded(lambda: time.sleep(2.0), 0.2)) == "hang"
    valid = Case("coverage", "fov_deg", 90.0, "valid")
    assert classify(valid, bounded(lambda: float("x"), 1.0)) == "rejected"
    assert classify(case, bounded(lambda: float("fov_deg"), 1.0)) is None


def main() -> int:
    """Full sweep with counts (the numbers quoted in issue 15's closing note)."""
    t0 = time.perf_counter()
    counts, failures = tally(SWEEP, verbose=True)
    tcounts: Counter = Counter()
    for name, value, expect in TRACKER_CASES:
        problem, out = _tracker_problem(name, value, expect)
        tcounts[problem or "good"] += 1
        if problem:
            print(f"{problem}: TrackerParams({name}={value!r}): {out.message}", file=sys.stderr)
    print(
        f"env keywords: {len(SWEEP)} cases, "
        + ", ".join(f"{counts[p]} {p}" for p in PROBLEMS)
        + f"; tracker params: {len(TRACKER_CASES)} cases, "
        + ", ".join(f"{tcounts[p]} {p}" for p in PROBLEMS)
        + f" ({time.perf_counter() - t0:.1f} s)"
    )
    return int(bool(failures) or any(tcounts[p] for p in PROBLEMS))


if __name__ == "__main__":
    raise SystemExit(main())
