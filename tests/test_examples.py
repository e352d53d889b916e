"""Every script in ``examples/`` runs, shortened, in a scratch folder (issue 13).

The TorchRL / BenchMARL / RLlib examples (``torchrl_*``, ``benchmarl_*``, ``rllib_*``) are
run by the tests of those integrations.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted(
    p
    for p in (ROOT / "examples").glob("*.py")
    if not p.name.startswith(("_", "torchrl_", "benchmarl_", "rllib_"))
)
#: what each example must print or write (so a script that silently does nothing fails)
EXPECT = {
    "evaluate_baseline.py": ("mean final_eta", None),
    "filter_random_policy.py": ("behind the safety filter", None),
    "seed_vector.py": ("95% CI", None),
    "render_episode.py": ("wrote crossing.gif", "crossing.gif"),
    "config_file.py": ("final_eta", "scenario.json"),
}


def test_every_example_has_an_expectation():
    assert EXAMPLES, "no examples found"
    assert {p.name for p in EXAMPLES} == set(EXPECT)


@pytest.mark.parametrize("script", EXAMPLES, ids=lambda p: p.name)
def test_example_runs(script, tmp_path):
    env = {
        **os.environ,
        "FOV_MARL_EXAMPLE_STEPS": "8",
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
        "MPLBACKEND": "Agg",
    }
    res = subprocess.run(
        [sys.executable, str(script)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert res.returncode == 0, res.stderr[-2000:]
    says, writes = EXPECT[script.name]
    assert says in res.stdout, res.stdout[-2000:]
    if writes is not None:
        assert (tmp_path / writes).stat().st_size > 0
    assert not list(ROOT.glob("examples/*.gif")) and not (ROOT / "scenario.json").exists()
