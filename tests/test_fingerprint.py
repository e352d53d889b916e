"""fov_marl.fingerprint: the source fingerprint that keys reproduce's cache and stamps
stress checkpoints."""

from __future__ import annotations

import ast
import hashlib
from pathlib import Path

import pytest

import fov_marl
from fov_marl.fingerprint import code_text, source_fingerprint
from fov_marl.stress_checkpoint import NOT_EPISODE, code_id


def _reference(exclude: set[str]) -> str:
    """The obvious form: every package .py file not excluded, path then its code."""
    root = Path(fov_marl.__file__).resolve().parent
    h = hashlib.sha256()
    for p in sorted(root.rglob("*.py")):
        rel = p.relative_to(root).as_posix()
        if rel in exclude or any(rel.startswith(e) for e in exclude if e.endswith("/")):
            continue
        h.update(rel.encode() + code_text(p.read_bytes()).encode())
    return h.hexdigest()


def test_fingerprint_is_the_hash_of_the_files_it_keeps():
    assert source_fingerprint() == _reference(set())
    ex = {"report.py", "training/"}
    assert source_fingerprint(ex) == _reference(ex)
    assert source_fingerprint(ex) != source_fingerprint()
    assert source_fingerprint(["training/"]) != source_fingerprint()  # a folder left out
    assert source_fingerprint(list(ex)) == source_fingerprint(tuple(ex))  # any iterable


def test_stress_code_id_leaves_out_what_cannot_change_an_episode():
    assert code_id() == source_fingerprint(NOT_EPISODE)[:12]
    assert {"cli.py", "stress_checkpoint.py", "training/"} <= NOT_EPISODE
    assert "stress.py" not in NOT_EPISODE and "adversaries.py" not in NOT_EPISODE


def test_reproduces_cache_key_leaves_out_the_checkpoint_and_fingerprint_modules():
    """Neither decides an episode: adding them must not invalidate reproduce's caches
    (a red team found the key changed when they were added)."""
    from fov_marl import report

    assert {"stress_checkpoint.py", "fingerprint.py", "stress.py"} <= report._NOT_EPISODE
    assert report._code_fingerprint() == _reference({*report._NOT_EPISODE, "training/"})


_MODULE = '''"""A module."""

import math

GAIN = 2.5  # per second


class Barrier:
    """A class."""

    def h(self, d_m: float) -> float:
        """A method."""
        return d_m * d_m - GAIN


def closing(v: float) -> float:
    return math.sqrt(v)
'''


@pytest.mark.parametrize(
    "edited",
    [
        _MODULE.replace('"""A method."""', '"""A method, documented.\n\n        More."""'),
        _MODULE.replace("  # per second", "  # 1/s, chosen at dt = 0.2 s"),
        _MODULE.replace('    """A class."""\n\n', ""),
        _MODULE.replace(
            "return d_m * d_m - GAIN",
            "return (\n            d_m * d_m\n            - GAIN\n        )",
        ),
        _MODULE.replace("-> float:\n    return", '-> float:\n    """Added."""\n    return'),
    ],
    ids=["docstring", "comment", "docstring-removed", "format", "docstring-added"],
)
def test_docs_comments_and_formatting_keep_the_fingerprint(edited):
    """A sweep's checkpoint survives a docs-only commit (one had to be resumed from an
    old checkout after a docstring edit)."""
    assert edited != _MODULE
    assert code_text(edited) == code_text(_MODULE)


@pytest.mark.parametrize(
    "edited",
    [
        _MODULE.replace("GAIN = 2.5", "GAIN = 2.6"),
        _MODULE.replace("d_m * d_m - GAIN", "d_m * d_m + GAIN"),
        _MODULE.replace(
            "-> float:\n    return", "-> float:\n    x = 'not a docstring'\n    return"
        ),
        _MODULE.replace(
            "    return math.sqrt(v)", "    math.e\n    'a later string'\n    return math.sqrt(v)"
        ),
    ],
    ids=["constant", "operator", "assigned-string", "later-string"],
)
def test_a_code_change_changes_the_fingerprint(edited):
    assert edited != _MODULE
    assert code_text(edited) != code_text(_MODULE)


def test_every_package_file_keeps_its_code_text_when_its_docs_and_layout_change():
    """On every file of the package: blank every docstring (``ast.get_docstring``'s) and
    regenerate the source with ``ast.unparse`` (no comments, another layout); the code
    text stays the same. Dropping a statement that is not a docstring changes it."""
    root = Path(fov_marl.__file__).resolve().parent
    kinds = (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)
    for p in sorted(root.rglob("*.py")):
        source = p.read_bytes()
        tree = ast.parse(source)
        n_docs = 0
        for node in ast.walk(tree):
            if isinstance(node, kinds) and ast.get_docstring(node, clean=False) is not None:
                node.body[0].value.value = ""
                n_docs += 1
        assert code_text(ast.unparse(tree)) == code_text(source), p
        body = ast.parse(source).body
        if len(body) > n_docs and len(body) > 1:  # a module with code besides its docstring
            tree = ast.parse(source)
            tree.body = tree.body[:-1]
            assert code_text(ast.unparse(tree)) != code_text(source), p
