"""fov_marl.fingerprint: the source fingerprint that keys reproduce's cache and stamps
stress checkpoints."""

from __future__ import annotations

import hashlib
from pathlib import Path

import fov_marl
from fov_marl.fingerprint import source_fingerprint
from fov_marl.stress_checkpoint import NOT_EPISODE, code_id


def _reference(exclude: set[str]) -> str:
    """The obvious form: every package .py file not excluded, path then bytes."""
    root = Path(fov_marl.__file__).resolve().parent
    h = hashlib.sha256()
    for p in sorted(root.rglob("*.py")):
        rel = p.relative_to(root).as_posix()
        if rel in exclude or any(rel.startswith(e) for e in exclude if e.endswith("/")):
            continue
        h.update(rel.encode() + p.read_bytes())
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
