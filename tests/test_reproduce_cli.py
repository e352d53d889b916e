"""``fov-marl evaluate`` shows the columns of its scenario and stores the new record fields."""

from __future__ import annotations

import json

from fov_marl.cli import main


def _header(printed: str) -> list[str]:
    return printed.strip().splitlines()[0].split()


def test_crossing_table_shows_arrivals_not_eta(tmp_path, capsys):
    argv = ["evaluate", "--scenario", "crossing", "--policy", "random", "--episodes", "2",
            "--max-cycles", "5", "--quiet", "--out", str(tmp_path)]  # fmt: skip
    assert main(argv) == 0
    head = _header(capsys.readouterr().out)
    assert {"arrived", "time_to_arrival_s", "mean_time_to_arrive_s", "safety_violations"} <= set(
        head
    )
    assert "final_eta" not in head and "time_to_eta_99" not in head
    ep = json.loads((tmp_path / "results.json").read_text())["episodes"][0]
    assert ep["arrived_ever"] is not None and ep["eta_normalised"] is None


def test_coverage_table_shows_normalised_eta_and_settling(tmp_path, capsys):
    argv = ["evaluate", "--policy", "random", "--n-agents", "2", "--episodes", "2",
            "--max-cycles", "5", "--quiet", "--out", str(tmp_path)]  # fmt: skip
    assert main(argv) == 0
    printed = capsys.readouterr().out
    head = _header(printed)
    assert {"final_eta", "eta_normalised", "time_to_eta_norm_s", "time_to_settle_s"} <= set(head)
    assert "arrived" not in head
    data = json.loads((tmp_path / "results.json").read_text())
    for ep in data["episodes"]:
        assert 0.0 < ep["eta_optimal"] <= 1.0
        assert ep["eta_normalised"] == ep["final_eta"] / ep["eta_optimal"]
    ci = data["summary"]["final_eta"]["ci95"]
    assert 0.0 <= ci[0] <= ci[1] <= 1.0
