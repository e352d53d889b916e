"""The documentation site builds from the docstrings with warnings as errors (issue 13)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _mkdocs_missing() -> str | None:
    for mod in ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python"):
        try:
            __import__(mod)
        except ImportError:
            return f"{mod} is not installed (pip install 'fov_marl[docs]')"
    return None


@pytest.mark.skipif(_mkdocs_missing() is not None, reason=str(_mkdocs_missing()))
def test_docs_build_strict(tmp_path):
    # build from a copy of the docs config so nothing is written into the checkout
    site = tmp_path / "site"
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1", "PYTHONPATH": str(ROOT)}
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "mkdocs",
            "build",
            "--strict",
            "--site-dir",
            str(site),
            "--config-file",
            str(ROOT / "mkdocs.yml"),
        ],  # fmt: skip
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    assert "WARNING" not in res.stderr
    # the API pages hold the docstrings, not just headings
    config_page = (site / "api" / "config" / "index.html").read_text()
    assert "from_dict" in config_page and "The inverse of" in config_page
    assert "map_jobs" in (site / "api" / "backends" / "index.html").read_text()
