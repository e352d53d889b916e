"""Fingerprints of the package's Python source: the code that measured cached episodes.

``fov-marl reproduce`` keys its cached runs on one (:mod:`fov_marl.report`) and
``fov-marl stress --checkpoint`` stamps every stored episode with one
(:mod:`fov_marl.stress_checkpoint`), so neither reuses an episode measured by other
code. The package version alone stays the same across commits. Each caller leaves out
the files that cannot change its episodes (the report, plots, the CLI), so editing
those keeps the caches.

A file counts by its code, not its text (:func:`code_text`): its syntax tree with the
docstrings of the module, classes and functions left out, so comments, docstrings and
formatting (``ruff format``) can be edited without invalidating a sweep's checkpoint
or reproduce's cache (no episode reads a docstring; only the CLI's help does). Any other
change, down to one constant, changes the fingerprint. Syntax trees are dumped
differently by each Python minor version, so a checkpoint resumes under the Python
version that wrote it.
"""

from __future__ import annotations

import ast
import hashlib
from collections.abc import Iterable
from pathlib import Path

__all__ = ["NOT_EPISODE", "code_text", "source_fingerprint"]

#: Files that cannot change any episode (reports, plots, the CLI, benchmarks, the
#: caches' own modules, training), left out by every caller; a caller adds its own
#: (``reproduce`` also leaves out ``stress.py``).
NOT_EPISODE: frozenset[str] = frozenset(
    (
        "report.py plots.py cli.py demo.py video.py bench.py backends.py tables.py "
        "stress_checkpoint.py fingerprint.py training/"
    ).split()
)

_MEMO: dict[frozenset[str], str] = {}
#: the nodes that may open with a docstring (``ast.get_docstring`` accepts these only)
_HAS_DOCSTRING = (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)


def code_text(source: str | bytes) -> str:
    """The code of one Python file, for the fingerprint: ``ast.dump`` of its syntax tree
    (no line or column numbers, so no formatting or comments) with every docstring left
    out (the first statement of the module, a class or a function when it is a string
    constant).

    Raises:
        SyntaxError: ``source`` is not Python.
    """
    tree = ast.parse(source)
    for node in ast.walk(tree):
        if isinstance(node, _HAS_DOCSTRING) and ast.get_docstring(node, clean=False) is not None:
            node.body = node.body[1:]
    return ast.dump(tree)


def source_fingerprint(exclude: Iterable[str] = ()) -> str:
    """SHA-256 (hex) of the package's ``*.py`` files: each file's path relative to the
    package (``/``-separated) then its code (:func:`code_text`: no docstrings, comments
    or formatting), in path order.

    Args:
        exclude: files to leave out, as relative paths (``"report.py"``), or folders as
            prefixes ending in ``/`` (``"training/"``).

    Returns:
        64 hex digits; computed once per process for each ``exclude`` (the source the
        process started from, not files edited while it runs).
    """
    key = frozenset(exclude)
    if key not in _MEMO:
        root = Path(__file__).resolve().parent
        folders = tuple(e for e in key if e.endswith("/"))
        h = hashlib.sha256()
        for p in sorted(root.rglob("*.py")):
            rel = p.relative_to(root).as_posix()
            if rel in key or rel.startswith(folders):
                continue
            h.update(rel.encode())
            h.update(code_text(p.read_bytes()).encode())
        _MEMO[key] = h.hexdigest()
    return _MEMO[key]
