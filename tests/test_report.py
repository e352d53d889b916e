"""`fov-marl reproduce --quick`: every section and every figure it names exists and is not blank."""

from __future__ import annotations

import json
import re

import numpy as np
from PIL import Image

from fov_marl.cli import main


def test_reproduce_quick_writes_report_with_all_sections_and_figures(tmp_path):
    out = tmp_path / "report"
    assert main(["reproduce", "--out", str(out), "--quick", "--workers", "1", "--seeds", "1"]) == 0
    md = (out / "report.md").read_text()
    for heading in ("## Headline", "## (a) Coverage", "## (b) Scaling", "## (c) Crossing"):
        assert heading in md
    assert "+18.6%" in md and "138.8" in md  # the paper's numbers beside ours
    figures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    assert set(figures) == {
        "eta_curves.png",
        "final_configurations.png",
        "cpu_vs_n.png",
        "crossing_trajectories.png",
    }
    for name in figures:
        with Image.open(out / name) as im:
            assert im.size[0] >= 400 and im.size[1] >= 300
            px = np.asarray(im.convert("L"), dtype=float)
        assert px.std() > 5.0, f"{name} looks blank"
    data = json.loads((out / "results.json").read_text())
    assert set(data) >= {"coverage", "scaling", "crossing"}
    assert [r["n_agents"] for r in data["scaling"]] == [6, 12]
