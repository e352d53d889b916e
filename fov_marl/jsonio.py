"""Standard JSON for every file the CLI writes (one place).

Python's ``json`` writes ``NaN``, ``Infinity`` and ``-Infinity`` for non-finite floats,
which strict parsers (JavaScript's ``JSON.parse``, ``jq``, most other languages) reject.
Results hold such values legitimately: the minimum distance of a one-robot team is
``inf`` (no pair), the standard deviation of one episode is NaN. :func:`json_text` writes
them as ``null`` (the JSON for "no value"), and NumPy scalars and arrays as numbers and
lists, so ``results.json``, ``series.json`` and ``stress --json`` are standard JSON.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["jsonable", "json_text", "write_json"]


def jsonable(obj: Any) -> Any:
    """``obj`` with NumPy values as Python ones and non-finite floats as None.

    Dicts (keys kept), lists, tuples and arrays are walked; other objects are returned
    as they are (``json`` then raises for what it cannot write).
    """
    if isinstance(obj, dict):
        return {k: jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def json_text(obj: Any, indent: int | None = None) -> str:
    """Standard JSON text of ``obj`` (:func:`jsonable`; NaN and ±inf become ``null``)."""
    return json.dumps(jsonable(obj), indent=indent, allow_nan=False)


def write_json(path: str | Path, obj: Any, indent: int | None = None) -> None:
    """Write :func:`json_text` of ``obj`` to ``path`` (UTF-8)."""
    Path(path).write_text(json_text(obj, indent=indent), encoding="utf-8")
