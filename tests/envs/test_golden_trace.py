"""Bit-exact golden traces of both envs, recorded from the pre-batched implementation.

``golden_env_traces.json`` holds one SHA-256 digest per case of everything an episode
returns (observations, rewards, terminations, truncations, every metric, poses,
``state()``), over 200 steps of seeded random actions including truncations,
terminations and resets without a seed (which continue the generator). It was recorded
from the per-copy ParallelEnv before the envs became views of the batched core, so a
match means the refactor changed no bit. Floating-point results may legitimately
differ on another NumPy/BLAS/CPU, so the test runs only where a recording's platform
fingerprint (NumPy version, machine, OS) *and* CPU fingerprint (the SIMD features NumPy
dispatches on) match; elsewhere it skips. The CPU entered the fingerprint after the same
NumPy on an AMD EPYC gave other digests for 6 of the 9 cases, from the very code that
recorded them (presumably NumPy's SIMD loops of transcendental functions, which differ in the last bit between
instruction sets). The same SIMD features are not enough either: OpenBLAS picks its
kernels by CPU model, and an AMD EPYC of family 26 with the AVX-512 features of the
third recording got OpenBLAS's ``Haswell`` kernels and other digests for the five
coverage cases (with ``OPENBLAS_CORETYPE=SkylakeX`` it gave the third recording's, from
the reference implementation and from today's code alike). A recording may therefore
name the OpenBLAS kernel sets that reproduce it (``blas_cores``, read by
:func:`blas_core`); one that does matches only those. :mod:`tests.envs.test_vector_env` covers the batched core against
the ParallelEnv on any platform.

To add a CPU: check out the reference implementation (``650fe82``), run this module as
a script on it (``git worktree add /tmp/ref 650fe82``, then ``PYTHONPATH=/tmp/ref python
tests/envs/test_golden_trace.py``), and append its output to ``recordings``.
"""

from __future__ import annotations

import hashlib
import json
import platform
from pathlib import Path

import numpy as np
import pytest

from fov_marl.envs import fov_coverage_v0, fov_crossing_v0

try:
    from fov_marl.infos import metrics_of
except ImportError:  # the reference implementation (650fe82) nests them: infos[a]["metrics"]

    def metrics_of(info: dict) -> dict:
        return info["metrics"]


GOLDEN = Path(__file__).with_name("golden_env_traces.json")
MODULES = {"coverage": fov_coverage_v0, "crossing": fov_crossing_v0}

#: (scenario, seed, config) cases; max_cycles < 200 forces truncations and unseeded resets.
CASES: list[tuple[str, int, dict]] = [
    ("coverage", 0, dict(n_agents=1, max_cycles=70)),
    ("coverage", 1, dict(n_agents=2, fov_deg=60.0, max_cycles=70)),
    ("coverage", 2, dict(n_agents=6, max_cycles=90)),
    ("coverage", 3, dict(n_agents=13, fov_deg=360.0, max_cycles=200)),
    ("coverage", 4, dict(n_agents=6, fov_deg=200.0, max_cycles=45, sensing_radius_m=9.0)),
    ("crossing", 0, dict(n_agents=1, max_cycles=70)),
    ("crossing", 1, dict(n_agents=4, max_cycles=70)),
    ("crossing", 2, dict(n_agents=7, fov_deg=360.0, max_cycles=200)),
    # large tolerance: episodes terminate early at random steps
    (
        "crossing",
        3,
        dict(n_agents=3, max_cycles=200, target_tolerance_m=3.4, crossing_radius_m=1.5),
    ),
]


def platform_fingerprint() -> str:
    return f"numpy {np.__version__} {platform.machine()} {platform.system()}"


def cpu_fingerprint() -> str | None:
    """The CPU features NumPy dispatches on (comma-separated), or None if unknown."""
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:  # pragma: no cover - other NumPy layouts
        return None
    return ",".join(sorted(k for k, v in features.items() if v))


def blas_core() -> str | None:
    """The kernel set NumPy's bundled OpenBLAS chose for this CPU (e.g. ``"Haswell"``,
    ``"SkylakeX"``), or None where it cannot be read (another BLAS, no ``/proc``)."""
    import ctypes

    try:
        with open("/proc/self/maps") as f:
            paths = sorted({ln.split()[-1] for ln in f if "openblas" in ln.lower()})
    except OSError:
        return None
    for path in paths:
        if "numpy" not in path:
            continue
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in ("scipy_openblas_get_corename64_", "openblas_get_corename64_",
                     "openblas_get_corename"):  # fmt: skip
            fn = getattr(lib, name, None)
            if fn is not None:
                fn.restype = ctypes.c_char_p
                core = fn()
                return core.decode() if core else None
    return None


def trace_digest(scenario: str, seed: int, config: dict, n_steps: int = 200) -> str:
    """SHA-256 of an episode stream of ``n_steps`` steps with automatic unseeded resets."""
    env = MODULES[scenario].parallel_env(**config)
    h = hashlib.sha256()

    def put_metrics(infos):
        for a in env.possible_agents:
            m = metrics_of(infos[a])
            h.update(repr(sorted((k, type(v).__name__, repr(v)) for k, v in m.items())).encode())

    obs, infos = env.reset(seed=seed)
    rng = np.random.default_rng(1000 + seed)
    for a in env.possible_agents:
        h.update(obs[a].tobytes())
    put_metrics(infos)
    for _ in range(n_steps):
        if not env.agents:
            obs, infos = env.reset()
            h.update(b"reset")
            for a in env.possible_agents:
                h.update(obs[a].tobytes())
            put_metrics(infos)
        acts = rng.uniform(-1.1, 1.1, (len(env.agents), 3)).astype(np.float32)
        obs, rew, term, trunc, infos = env.step(dict(zip(env.agents, acts, strict=True)))
        for a in env.possible_agents:
            h.update(obs[a].tobytes())
            h.update(np.float64(rew[a]).tobytes())
            h.update(bytes([term[a], trunc[a]]))
        put_metrics(infos)
        h.update(env.poses.tobytes())
        h.update(env.state().tobytes())
    return h.hexdigest()


def _case_id(case) -> str:
    scenario, seed, cfg = case
    return f"{scenario}-{seed}-" + "-".join(f"{k}={v}" for k, v in cfg.items())


def _load() -> dict:
    return json.loads(GOLDEN.read_text())


@pytest.mark.parametrize("case", CASES, ids=_case_id)
def test_golden_trace_is_bit_identical(case):
    plat, cpu, core = platform_fingerprint(), cpu_fingerprint(), blas_core()
    match = [
        r
        for r in _load()["recordings"]
        if r["platform"] == plat
        and cpu is not None
        and r["cpu"] == cpu
        and core in r.get("blas_cores", [core])
    ]
    if not match:
        pytest.skip(f"no golden trace recorded for {plat} on this CPU (see the module docstring)")
    assert trace_digest(*case) == match[0]["digests"][_case_id(case)]


def test_recordings_are_complete():
    for r in _load()["recordings"]:
        assert set(r["digests"]) == {_case_id(c) for c in CASES}, r["platform"]


def test_trace_digest_can_fail():
    # the digest sees a one-step difference in the actions' stream
    a = trace_digest("coverage", 0, dict(n_agents=2, max_cycles=30), n_steps=20)
    b = trace_digest("coverage", 0, dict(n_agents=2, max_cycles=30), n_steps=21)
    c = trace_digest("coverage", 1, dict(n_agents=2, max_cycles=30), n_steps=20)
    assert len({a, b, c}) == 3


if __name__ == "__main__":  # print a recording (run it from the reference implementation)
    out = {
        "platform": platform_fingerprint(),
        "cpu": cpu_fingerprint(),
        "blas_cores": [blas_core()],
        "digests": {_case_id(c): trace_digest(*c) for c in CASES},
    }
    print(json.dumps(out, indent=1))
