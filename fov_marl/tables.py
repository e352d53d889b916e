"""The one plain-text table formatter of the package (CLI tables, benchmarks, stress).

>>> print(format_table([[1, 0.5], [2, None]], ["seed", "eta"]))
seed  eta
----  ---
   1  0.5
   2    -
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

__all__ = ["format_table", "format_cell", "format_records", "flatten_record"]


def format_cell(value: Any) -> str:
    """One cell: ``None`` -> ``-``, floats with 4 significant digits (``1.235e+04``
    from 1e4 on), anything else ``str``."""
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.4g}" if abs(value) < 1e4 else f"{value:.3e}"
    return str(value)


def format_table(
    rows: Sequence[Sequence[Any]] | Sequence[Mapping[str, Any]],
    headers: Sequence[str] | Sequence[tuple[str, str]],
) -> str:
    """Right-aligned plain-text table readable in a terminal and in a log.

    Args:
        rows: one sequence of cells per row, in the order of ``headers``; or one
            mapping per row, read by key (a missing key is ``-``).
        headers: column titles; with mapping rows, either the keys themselves or
            ``(title, key)`` pairs.

    Returns:
        The header line, a dashed rule and one line per row (no trailing newline).
    """
    titles = [h[0] if isinstance(h, tuple) else h for h in headers]
    keys = [h[1] if isinstance(h, tuple) else h for h in headers]
    if rows and isinstance(rows[0], Mapping):
        cells = [[format_cell(r.get(k)) for k in keys] for r in rows]  # type: ignore[union-attr]
    else:
        cells = [[format_cell(v) for v in r] for r in rows]
    widths = [
        max(len(h), *(len(r[i]) for r in cells)) if cells else len(h) for i, h in enumerate(titles)
    ]
    line = "  ".join(h.rjust(w) for h, w in zip(titles, widths, strict=True))
    sep = "  ".join("-" * w for w in widths)
    body = ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in cells]
    return "\n".join([line, sep, *body])


def flatten_record(row: Mapping[str, Any], sep: str = ".") -> dict[str, Any]:
    """``row`` with each nested mapping spread into columns ``key.subkey`` (recursively),
    so a table cell never shows a raw dict:

    >>> flatten_record({"n": 6, "stage_ms": {"qp": 0.1, "lloyd": 0.2}})
    {'n': 6, 'stage_ms.qp': 0.1, 'stage_ms.lloyd': 0.2}
    """
    out: dict[str, Any] = {}
    for key, value in row.items():
        if isinstance(value, Mapping):
            for sub, v in flatten_record(value, sep).items():
                out[f"{key}{sep}{sub}"] = v
        else:
            out[str(key)] = value
    return out


def format_records(rows: Sequence[Mapping[str, Any]], exclude: Sequence[str] = ()) -> str:
    """:func:`format_table` of dict rows: the columns are every key of every row in the
    order first seen (``exclude`` left out), nested mappings flattened
    (:func:`flatten_record`); a key missing from a row is ``-``."""
    flat = [flatten_record(r) for r in rows]
    keys = [k for k in dict.fromkeys(k for r in flat for k in r) if k not in exclude]
    return format_table(flat, keys)
