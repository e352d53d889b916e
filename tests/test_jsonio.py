"""Standard JSON for every file the CLI writes, and output paths checked before work."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from fov_marl.jsonio import json_text, jsonable, write_json
from fov_marl.validation import ConfigError, check_writable


def _strict(name):
    raise ValueError(f"non-standard JSON constant {name}")


def test_non_finite_floats_become_null_and_numpy_values_plain():
    obj = {
        "min_distance": math.inf,
        "std": float("nan"),
        "ci95": (np.float64("nan"), -np.inf),
        "series": np.array([0.5, np.inf, 1.0]),
        "n": np.int64(3),
        "ok": np.bool_(True),
        "nested": [{"x": np.float32(0.25)}],
    }
    text = json_text(obj, indent=2)
    back = json.loads(text, parse_constant=_strict)
    assert back == {
        "min_distance": None,
        "std": None,
        "ci95": [None, None],
        "series": [0.5, None, 1.0],
        "n": 3,
        "ok": True,
        "nested": [{"x": 0.25}],
    }
    assert jsonable("text") == "text" and jsonable(None) is None


def test_write_json_writes_the_same_text(tmp_path):
    write_json(tmp_path / "r.json", {"a": math.nan}, indent=1)
    assert json.loads((tmp_path / "r.json").read_text(), parse_constant=_strict) == {"a": None}


def test_check_writable_creates_folders_and_refuses_what_cannot_be_written(tmp_path):
    target = tmp_path / "new" / "deeper" / "results.json"
    check_writable("--out", [target])
    assert target.parent.is_dir() and not target.exists()  # probed, not left behind
    existing = tmp_path / "keep.json"
    existing.write_text("old")
    check_writable("--json", [existing])
    assert existing.read_text() == "old"  # an existing file is left as it is
    (tmp_path / "d" / "results.json").mkdir(parents=True)
    with pytest.raises(ConfigError, match=r"^--out: .*results.json exists and is not a file"):
        check_writable("--out", [tmp_path / "d" / "results.json"])
    (tmp_path / "afile").write_text("")
    with pytest.raises(ConfigError, match=r"^--json: cannot write .*afile/x.json"):
        check_writable("--json", [tmp_path / "afile" / "x.json"])
