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

__all__ = ["format_table", "format_cell"]


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
