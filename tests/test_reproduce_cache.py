"""``fov-marl reproduce`` runs: per-(job, code) cache, resume, calibration probe, progress."""

from __future__ import annotations

import json

import numpy as np

import fov_marl.report as report
from fov_marl.backends import progress_bar
from fov_marl.report import Job, _run_all, _run_cached, plan, run_job


def _job(seed: int = 0, **kw) -> Job:
    base = dict(
        scenario="coverage", policy="random", seed=seed, n_agents=2, max_cycles=5,
        _group="t", _label="x", _keep="final", _probe=False,
    )  # fmt: skip
    base.update(kw)
    return Job(**base)


def test_cache_hits_misses_and_torn_files(tmp_path):
    job = _job()
    first, hit = _run_cached(job, tmp_path, "code-a")
    assert not hit and first["record"]["steps"] == 5 and len(first["final_poses"]) == 2
    again, hit = _run_cached(job, tmp_path, "code-a")
    assert hit and again == json.loads(json.dumps(first))
    # another code fingerprint or another argument is another entry
    _, hit = _run_cached(job, tmp_path, "code-b")
    assert not hit
    _, hit = _run_cached(_job(seed=1), tmp_path, "code-a")
    assert not hit
    assert len(list(tmp_path.glob("*.json"))) == 3
    # a torn file (interrupted write) is run again, not trusted
    path = tmp_path / f"{report._job_key(job, 'code-a')}.json"
    path.write_text('{"record": ')
    redo, hit = _run_cached(job, tmp_path, "code-a")
    assert not hit and redo["final_poses"] == first["final_poses"]  # timings differ
    assert redo["record"]["eta_series"] == first["record"]["eta_series"]


def test_an_interrupted_run_resumes_from_the_cache(tmp_path, monkeypatch):
    jobs = [_job(seed=s) for s in range(3)]
    _run_cached(jobs[0], tmp_path, "c")  # finished before the "interruption"
    calls = []
    real = report.run_job
    monkeypatch.setattr(
        report, "run_job", lambda j, on_step=None: calls.append(j["seed"]) or real(j, on_step)
    )
    bar = progress_bar(3 * 5, "test", enabled=False)
    bar.hits = 0
    out = _run_all(jobs, 1, tmp_path, "c", bar)
    assert calls == [1, 2] and bar.n == 3 * 5 and bar.hits == 1  # steps, cached ones too
    assert [r["record"]["seed"] for r in out] == [0, 1, 2]


def test_probe_records_calibration_per_step_and_leaves_the_episode_unchanged():
    # N = 6 (seed 0): neighbours are detected from the first step, so both series are
    # exercised (at N = 3 nobody is seen in 12 steps and "detected" is all NaN)
    kw = dict(policy="pfcbf", n_agents=6, max_cycles=12, fov_deg=120.0)
    probed = run_job(_job(**kw, _probe=True))
    plain = run_job(_job(**kw))
    cal = probed["calibration"]
    assert set(cal) == {"detected", "undetected", "near_undetected", "a_undetected_m"}
    assert all(len(v) == 12 for v in cal.values())
    for name in ("detected", "undetected"):
        rates = np.asarray(cal[name], float)
        assert np.isfinite(rates).sum() >= 6, (name, rates)
        finite = rates[np.isfinite(rates)]
        assert np.all((finite >= 0) & (finite <= 1)) and finite.mean() >= 0.5, (name, rates)
    # reading the estimates does not change the episode
    assert probed["record"]["eta_series"] == plain["record"]["eta_series"]
    assert probed["final_poses"] == plain["final_poses"]


def test_plan_pairs_the_conditions_and_keeps_quick_small():
    full, quick = plan(False), plan(True)
    cov = [j for j in full["parallel"] if j["_group"] == "coverage"]
    by = {}
    for j in cov:
        by.setdefault(j["_label"], []).append(j["seed"])
    assert set(by) == {"pfcbf 120°", "pfcbf 360°", "ideal"}
    assert all(v == list(range(20)) for v in by.values())  # same starts, 20 seeds
    assert list(dict.fromkeys(j["n_agents"] for j in full["serial"])) == [6, 9, 12, 24, 48, 100]
    assert {j["arena_size_m"] for j in full["serial"] if j["n_agents"] == 24} == {80.0}
    steps = sum(
        j.get("max_cycles", j.get("max_steps", 1000)) * j.get("n_agents", 4)
        for j in quick["parallel"] + quick["serial"]
    )
    assert steps < 20_000  # robot-steps: ~40 s on one core


def test_progress_counts_steps_in_process(tmp_path):
    """The bar moves once per simulated step when the runs are in this process."""
    seen = []

    class Bar:
        n, hits = 0, 0

        def update(self, n=1, note=None):
            seen.append(n)
            self.n += n

    _run_all([_job(seed=s) for s in range(2)], 1, tmp_path, "c", Bar())
    assert seen.count(1) >= 10 and sum(seen) == 10  # 2 runs x 5 steps, step by step
