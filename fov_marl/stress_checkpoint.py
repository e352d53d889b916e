"""The file format of resumable stress sweeps (:func:`fov_marl.stress.run_stress`'s
``checkpoint``, ``fov-marl stress --checkpoint``).

A checkpoint is a JSON-lines file: one line per finished episode, holding ``format``
(:data:`CHECKPOINT_FORMAT`), ``version`` (``fov_marl.__version__``), ``code``
(:func:`code_id`), the episode's ``case`` (:meth:`~fov_marl.stress.StressCase.describe`,
``fov_deg`` a float), ``seed`` and ``steps``, and its ``record``
(:func:`~fov_marl.stress.run_stress_episode`'s dict). Lines are appended and flushed as
episodes end; a reader keys them by case, seed and steps. Every line is checked (format,
the same version and code, a record an episode can have produced); a file with any other
line is refused and never written to.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from fov_marl.fingerprint import NOT_EPISODE, source_fingerprint
from fov_marl.infos import SAFETY_CAUSES, SAFETY_STATUSES
from fov_marl.jsonio import jsonable
from fov_marl.validation import check_out_path, describe

__all__ = ["CHECKPOINT_FORMAT", "code_id"]

#: the ``format`` entry of a checkpoint line (:func:`~fov_marl.stress.run_stress`'s ``checkpoint``)
CHECKPOINT_FORMAT = "fov_marl.stress/episode-1"
#: the entries of an episode record (:func:`~fov_marl.stress.run_stress_episode`)
EPISODE_KEYS = frozenset(
    (
        "seed steps robot_steps collisions first_collision_step violation_events "
        "violation_events_after_start violation_robot_steps min_distance_m "
        "start_min_distance_m encroachment_m intervened action_change_sum fallbacks "
        "statuses cause_counts chatter_events filter_chatter_events"
    ).split()
)


def episode_id(case: Any, seed: int, steps: int) -> dict[str, Any]:
    """One episode's identity: its case's fields (``fov_deg`` a float), seed and steps."""
    d = case.describe()
    d["fov_deg"] = float(d["fov_deg"])
    return {"case": d, "seed": int(seed), "steps": int(steps)}


def _numpy_value(obj: Any) -> Any:
    """``json``'s ``default``: NumPy scalars and arrays as Python values. Non-finite
    floats are kept, so ``allow_nan=False`` refuses them (``jsonio.jsonable`` writes
    them as null: two cases differing only in inf and NaN would share a key)."""
    if isinstance(obj, np.ndarray | np.generic):
        return obj.tolist()
    raise TypeError(f"{type(obj).__name__} is not a JSON value")


def key_of(episode_id: Mapping[str, Any]) -> str:
    """The lookup key of :func:`episode_id`'s dict (or of one read back from a line)."""
    ident = {k: episode_id.get(k) for k in ("case", "seed", "steps")}
    try:
        return json.dumps(ident, sort_keys=True, allow_nan=False, default=_numpy_value)
    except (TypeError, ValueError):
        raise ValueError(
            "a checkpoint needs cases whose fields are JSON values (finite numbers, "
            f"strings, lists, mappings), got {describe(ident['case'])}"
        ) from None


def episode_key(case: Any, seed: int, steps: int) -> str:
    """The lookup key of one episode in a checkpoint."""
    return key_of(episode_id(case, seed, steps))


def code_id() -> str:
    """12 hex digits of :func:`~fov_marl.fingerprint.source_fingerprint` over the
    package's source less :data:`~fov_marl.fingerprint.NOT_EPISODE`: the code that measured a checkpoint's
    episodes (the package version alone stays the same across commits). Docstrings,
    comments and formatting do not count (:func:`~fov_marl.fingerprint.code_text`)."""
    return source_fingerprint(NOT_EPISODE)[:12]


def append_episode(sink: Any, case: Any, seed: int, steps: int, rec: dict) -> None:
    """One checkpoint line for a finished episode, flushed at once (a stopped run loses
    at most the line being written)."""
    from fov_marl import __version__

    line = {
        "format": CHECKPOINT_FORMAT,
        "version": __version__,
        "code": code_id(),
        **episode_id(case, seed, steps),
        "record": jsonable(rec),
    }
    sink.write(json.dumps(line, allow_nan=False, default=_numpy_value) + "\n")
    sink.flush()


def _nonneg_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v >= 0


def _finite_nonneg(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and 0.0 <= v < math.inf


def record_problem(
    rec: Any, filtered: Any, seed: int, steps: int, n_agents: Any = None
) -> str | None:
    """What is wrong with a stored episode record (None when it is one
    :func:`~fov_marl.stress.run_stress_episode` can have returned for that seed and steps)."""
    if not isinstance(rec, dict) or set(rec) != EPISODE_KEYS:
        return "its record does not have the entries of an episode"
    n_steps = rec["steps"]
    if not (_nonneg_int(rec["seed"]) and rec["seed"] == seed) or not (
        _nonneg_int(n_steps) and 1 <= n_steps <= steps
    ):
        return "its record's seed or steps differ from the line's"
    counts = ("robot_steps", "collisions", "violation_events", "violation_robot_steps")
    bad = [k for k in (*counts, "chatter_events") if not _nonneg_int(rec[k])]
    after = rec["violation_events_after_start"]  # the events less those of the start
    if not (_nonneg_int(after) and ("violation_events" in bad or after <= rec["violation_events"])):
        bad.append("violation_events_after_start")
    if (
        "robot_steps" not in bad
        and _nonneg_int(n_agents)
        and rec["robot_steps"] > n_steps * n_agents
    ):
        bad.append("robot_steps")
    fcs = rec["first_collision_step"]
    if "collisions" not in bad:  # a first collision step exactly when there was one
        collided = rec["collisions"] > 0
        if fcs is None:
            fine = not collided
        else:
            fine = collided and _nonneg_int(fcs) and 1 <= fcs <= n_steps
        if not fine:
            bad.append("first_collision_step")
    for k in ("min_distance_m", "start_min_distance_m", "encroachment_m"):
        # all three None for a one-robot team (no pair), all three numbers otherwise
        if (rec[k] is None) != (rec["min_distance_m"] is None) or (
            rec[k] is not None and not _finite_nonneg(rec[k])
        ):
            bad.append(k)
    fields = ("intervened", "fallbacks", "filter_chatter_events", "action_change_sum")
    if filtered is not True:
        bad += [k for k in (*fields, "statuses", "cause_counts") if rec[k] is not None]
    else:
        bad += [k for k in fields[:3] if not _nonneg_int(rec[k])]
        if not _finite_nonneg(rec["action_change_sum"]):
            bad.append("action_change_sum")
        st = rec["statuses"]
        if not (
            isinstance(st, dict)
            and set(st) <= set(SAFETY_STATUSES)
            and all(_nonneg_int(v) for v in st.values())
        ):
            bad.append("statuses")
        cc = rec["cause_counts"]
        if not (
            isinstance(cc, list)
            and len(cc) == len(SAFETY_CAUSES)
            and all(_nonneg_int(v) for v in cc)
        ):
            bad.append("cause_counts")
    return f"its record's {', '.join(bad)} cannot be an episode's" if bad else None


def read_checkpoint(
    path: str | os.PathLike, name: str = "checkpoint"
) -> tuple[dict[str, dict[str, Any]], int, bool]:
    """The episodes of a checkpoint file (none when it does not exist).

    Every line must be an episode written by this package version and code
    (:func:`code_id`), with a record :func:`~fov_marl.stress.run_stress_episode` can have
    returned. The last line may lack its newline: when it is such an episode it counts;
    when it is the beginning of one (a run stopped while writing it, after at least one
    whole line) it is ignored. Anything else raises, so a file that is not a checkpoint (a wrong path)
    is never truncated or appended to.

    Args:
        path: the file. name: how errors name it (the CLI flag).

    Returns:
        ``({key: record}, n_bytes, add_newline)``: the bytes to keep (a cut-off last line
        is dropped), and whether a newline must be written before the next line.

    Raises:
        ValueError: naming ``name``, the file and the line that cannot be used.
    """
    from fov_marl import __version__

    if isinstance(path, bool) or not isinstance(path, str | os.PathLike) or not str(path).strip():
        raise ValueError(f"{name} must be a file path, got {describe(path)}")
    p = Path(path)
    try:
        if p.exists() and not p.is_file():
            raise ValueError(f"{name} {p}: not a regular file")
        data = p.read_bytes() if p.exists() else b""
    except OSError as exc:
        raise ValueError(f"{name} {p}: cannot read it ({exc.strerror or exc})") from None
    lines = data.split(b"\n")  # the last item: what follows the last newline
    tail = lines.pop()
    keep, add_newline = len(data), False
    if tail.strip():
        if _json_line(tail) is not None:
            lines.append(tail)  # a whole line without its newline: checked below
            add_newline = True
        else:
            # the beginning of one line (the file's last write, cut), after a whole line
            head = json.dumps({"format": CHECKPOINT_FORMAT}).encode()[:-1]  # b'{"format": "…"'
            stripped = tail.strip()
            one_start = stripped.count(b'{"format"') <= 1 and b"\r" not in stripped
            begins = stripped.startswith(head) or head.startswith(stripped)
            if not (begins and one_start and any(x.strip() for x in lines)):
                raise ValueError(
                    f"{name} {p}, line {len(lines) + 1}: not a stress episode (an unfinished line)"
                )
            keep = len(data) - len(tail)
    stored: dict[str, dict[str, Any]] = {}
    first: dict[str, int] = {}  # key -> line of its first record
    for n, raw in enumerate(lines, start=1):
        if not raw.strip():
            continue
        where = f"{name} {p}, line {n}"
        item = _json_line(raw)
        if item is None:
            raise ValueError(f"{where}: not a JSON line")
        if not (isinstance(item, dict) and item.get("format") == CHECKPOINT_FORMAT):
            raise ValueError(f"{where}: not a stress episode (format {CHECKPOINT_FORMAT!r})")
        if item.get("version") != __version__ or item.get("code") != code_id():
            raise ValueError(
                f"{where}: written by fov_marl {item.get('version')!r} with code "
                f"{item.get('code')!r}, this is {__version__!r} with code {code_id()!r}; its "
                "episodes were measured on other code, start a new file"
            )
        case, seed, steps = item.get("case"), item.get("seed"), item.get("steps")
        if not (isinstance(case, dict) and _nonneg_int(seed) and _nonneg_int(steps)):
            raise ValueError(f"{where}: not a stress episode (its case, seed or steps)")
        problem = record_problem(
            item.get("record"), case.get("filtered"), seed, steps, case.get("n_agents")
        )
        if problem is not None:
            raise ValueError(f"{where}: not a stress episode ({problem})")
        try:
            key = key_of(item)
        except ValueError:
            raise ValueError(f"{where}: not a stress episode (a non-finite case field)") from None
        if key in stored and stored[key] != item["record"]:
            raise ValueError(
                f"{where}: another record of the episode of line {first[key]} (an episode "
                "is a function of its case and seed: the file mixes runs)"
            )
        first.setdefault(key, n)
        stored[key] = item["record"]
    return stored, keep, add_newline


def _json_line(raw: bytes) -> Any:
    """The JSON value of one line, or None when it is not one (also for a number too long
    for ``int``, nesting too deep for the parser, or bytes that are not UTF-8)."""
    try:
        return json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError):  # JSONDecodeError is one
        return None


def open_checkpoint(path: str | os.PathLike) -> tuple[dict[str, dict[str, Any]], Any]:
    """:func:`read_checkpoint`, then the file opened for appending: a cut-off last line
    removed first, or a newline added after a whole last line that lacks it.

    Returns:
        ``({key: record}, text file opened for appending)``.

    Raises:
        ValueError: as :func:`read_checkpoint`, or a path that cannot be written (under
            a file that is not a directory, in a read-only folder), naming it.
    """
    code_id()  # hashed now, before the sweep: not from files edited while it runs
    stored, keep, add_newline = read_checkpoint(path)
    p = check_out_path("checkpoint", path)  # not under a file: the shared output check
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        if p.exists() and p.stat().st_size > keep:
            os.truncate(p, keep)
        sink = open(p, "a", encoding="utf-8")  # noqa: SIM115 (the caller closes it)
        if add_newline:
            sink.write("\n")
    except OSError as exc:
        raise ValueError(f"checkpoint {p}: cannot write it ({exc.strerror or exc})") from None
    return stored, sink
