"""`fov-marl reproduce --quick`: every section and figure exists, is not blank, and the
report's numbers are the ones in results.json."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from PIL import Image

from fov_marl.cli import main
from fov_marl.report import OUTPUT_FILES

FIGURES = {
    "fig5_final_configurations.png",
    "fig6_eta.png",
    "fig6b_eta_literal.png",
    "fig_calibration.png",
    "fig7_crossing.png",
    "fig_dense_safety.png",
    "fig_cpu_vs_n.png",
}
SECTIONS = (
    "## Headline",
    "## (a) Coverage",
    "### Particle-filter calibration",
    "## (a') The literal reading",
    "## (b) Scaling",
    "## (c) Crossing",
    "## (d) Dense teams",
)


@pytest.fixture(scope="module")
def quick_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    assert main(["reproduce", "--out", str(out), "--quick", "--workers", "1"]) == 0
    md = (out / "report.md").read_text()

    def strict(name):  # standard JSON: NaN / Infinity are refused (red team 4)
        raise ValueError(f"non-standard JSON constant {name}")

    data = json.loads((out / "results.json").read_text(), parse_constant=strict)
    json.loads((out / "series.json").read_text(), parse_constant=strict)
    return out, md, data


def test_sections_figures_and_the_papers_numbers(quick_report):
    out, md, _ = quick_report
    for heading in SECTIONS:
        assert heading in md, heading
    assert "+18.6%" in md and "138.8" in md and "125.7" in md  # the paper beside ours
    assert "η / η_opt = 1" in md  # the reading of "η = 1" is stated
    assert re.search(r"\*\*(not )?significant\*\* at the 5% level", md)
    figures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    assert set(figures) == FIGURES and len(figures) == len(FIGURES)
    assert FIGURES <= set(OUTPUT_FILES)  # the CLI checks them before the runs
    for name in figures:
        with Image.open(out / name) as im:
            assert im.size[0] >= 400 and im.size[1] >= 300
            px = np.asarray(im.convert("L"), dtype=float)
        assert px.std() > 5.0, f"{name} looks blank"
    assert (out / "series.json").exists() and any((out / "cache").iterdir())


def test_results_json_records_and_clipped_intervals(quick_report):
    _, _, data = quick_report
    assert set(data) >= {"coverage", "literal", "scaling", "crossing", "dense", "calibration"}
    assert [r["n_agents"] for r in data["scaling"]] == [6, 12]
    for r in data["scaling"]:
        assert r["mean"] > 0 and set(r["stages"]) >= {"tracker", "qp"}
        # spread over episodes (null for one), never a spread over equal per-robot shares
        assert r["std_over"] == "episodes"
        assert (r["std"] is None) == (r["episodes"] == 1) and (r["std"] is None or r["std"] > 0)
        assert sum(r["stages"].values()) == pytest.approx(r["mean"], rel=0.05)
    for key in ("coverage", "literal"):
        cov = data[key]
        assert 0.9 < cov["eta_optimal"] <= 1.0
        for e in cov["episodes"]:
            assert e["eta_normalised"] == pytest.approx(e["final_eta"] / cov["eta_optimal"])
            assert "time_to_eta_norm_s" in e and e["eta_norm_threshold"] == 0.95
        for lab, s in cov["summary"].items():
            ci = s["final_eta"]["ci95"]
            assert ci is None or 0.0 <= ci[0] <= ci[1] <= 1.0, lab
        horizon = data["sizes"]["coverage_steps"] * 0.2
        for comp in cov["paired"].values():
            for m in comp.values():
                if m["ci95"] is not None and m is not comp["eta_normalised"]:
                    lo, hi = m["ci95"]
                    if m is not comp["path_length_m"]:
                        assert -horizon <= lo <= hi <= horizon
                if m["rel_ci95"] is not None:
                    assert m["rel_ci95"][0] >= -100.0
                assert m["significant"] in (True, False, None)
    for e in data["crossing"]["episodes"]:
        assert {
            "arrived",
            "time_to_arrival_s",
            "safety_violations",
            "mean_time_to_arrive_s",
        } <= set(e)
        assert e["eta_normalised"] is None
    assert data["dense"]["rows"][0]["n_agents"] == 24


def _cell(md: str, row_start: str, col: int) -> str:
    line = next(ln for ln in md.splitlines() if ln.startswith(row_start))
    return [c.strip() for c in line.strip("|").split("|")][col]


def test_report_numbers_are_traceable_to_results_json(quick_report):
    _, md, data = quick_report
    cov = data["coverage"]
    for lab in ("pfcbf 120°", "pfcbf 360°", "ideal"):
        s = cov["summary"][lab]["final_eta"]
        assert _cell(md, f"| {lab} |", 1) == f"{s['mean']:.4f} ± {s['std']:.4f}"
    c = cov["paired"]["pfcbf 120° − pfcbf 360°"]["time_to_eta_norm_s"]
    row = _cell(md, "| time increase 120° vs 360°, to 0.95", 2)
    if c["rel_pct"] is not None:
        assert row.startswith(f"{c['rel_pct']:+.1f}%")
    for r in data["scaling"]:
        assert f"| {r['n_agents']} | {r['arena_m']:.1f} |" in md
        std = "\u2013" if r["std"] is None else f"{r['std']:.3f}"  # – for one episode
        assert f"{r['mean']:.3f} ± {std}" in md
    for e in data["crossing"]["episodes"]:
        assert f"| {e['seed']} | {e['arrived']} |" in md
    d = data["dense"]["rows"][0]
    assert f"| {d['n_agents']} | {len(d['seeds'])} | {d['steps']} | {d['collisions']} |" in md
    assert math.isfinite(data["elapsed_s"]) and data["elapsed_s"] > 0
