"""Command-line options of the safety filter: ``--filter-tracker``, ``--filter-controller``
and ``--filter-init``.

Shared by ``fov-marl evaluate``, ``render`` and ``train``. Each flag is repeatable as
``FIELD=VALUE`` (VALUE parsed as JSON) and sets one field of the filter's
:class:`~fov_marl.estimation.TrackerParams` / :class:`~fov_marl.control.ControllerParams`,
on top of the filter's own defaults
(:data:`~fov_marl.wrappers.safety_filter.FILTER_TRACKER_DEFAULTS`,
:data:`~fov_marl.wrappers.safety_filter.FILTER_CONTROLLER_DEFAULTS`)::

    fov-marl train --safety-filter --filter-tracker n_particles_total=500 ...
    fov-marl evaluate --safety-filter --filter-controller safety_risk=0.01 ...
    fov-marl stress --filter-init uniform ...

``--filter-threads T`` (``fov-marl train`` only, where one process filters B env copies
at once) steps the filter's particle filters on T threads (``tracker_threads`` of the
wrappers): the same actions, less wall time from about 10^5 particles on (``fov-marl
bench``). Leave 1 with ``--workers W > 1``, which already gives every core a process.

``--filter-init`` picks the filter's particle initialisation (``init`` of
:class:`~fov_marl.wrappers.SafetyFilterWrapper`): ``known`` (default, the paper's
assumption: the team's start poses) or ``uniform`` (nothing known; every bearing then
counts as unseen until the camera has looked at it).

(P_T = 500 makes the filter about 3x faster and stays calibrated:
``tests/estimation/test_mixture_calibration.py``, ``fov-marl bench``.) The result is the
``safety_filter_kwargs`` of :func:`fov_marl.evaluation.run_episodes` and
:func:`fov_marl.training.train`. Every value is checked before anything runs. An
unknown field, a value out of range, or a flag given without ``--safety-filter`` is a
one-line error naming the flag.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from typing import Any

__all__ = ["INITS", "add_filter_arguments", "check_filter_config", "filter_kwargs"]

_FLAGS = (
    ("--filter-tracker", "filter_tracker", "tracker_params", "TrackerParams"),
    ("--filter-controller", "filter_controller", "controller_params", "ControllerParams"),
)
_EXAMPLE = {"--filter-tracker": "n_particles_total=500", "--filter-controller": "safety_risk=0.01"}
#: ``--filter-init`` values (``SafetyFilterWrapper(init=...)``).
INITS = ("known", "uniform")


def add_filter_arguments(
    parser: argparse.ArgumentParser, when: str = "with --safety-filter", threads: bool = False
) -> None:
    """Add ``--filter-tracker`` and ``--filter-controller`` (repeatable), ``--filter-init``
    and, with ``threads``, ``--filter-threads`` to ``parser``; ``when`` says in the help
    when the filter runs."""
    for flag, dest, _, cls in _FLAGS:
        parser.add_argument(
            flag,
            dest=dest,
            action="append",
            metavar="FIELD=VALUE",
            help=f"{when}: a field of the filter's {cls}, repeatable, VALUE "
            f"parsed as JSON (e.g. {_EXAMPLE[flag]}), on top of the filter's defaults",
        )
    parser.add_argument(
        "--filter-init",
        dest="filter_init",
        choices=INITS,
        default=None,
        help=f"{when}: the filter's particle initialisation: known (the team's start "
        "poses, the paper's assumption) or uniform (nothing known) (default: known)",
    )
    if threads:
        parser.add_argument(
            "--filter-threads",
            dest="filter_threads",
            type=str,
            default=None,
            metavar="T",
            help=f"{when}: threads that step the filter's particle filters, an integer in "
            "[1, 1024]; the same actions, less wall time for many env copies in one "
            "process (default: 1)",
        )


def filter_kwargs(
    tracker_items: Sequence[str] | None,
    controller_items: Sequence[str] | None,
    safety_filter: bool,
    off_hint: str = "add --safety-filter",
    init: str | None = None,
    threads: str | int | None = None,
) -> dict[str, Any] | None:
    """The ``SafetyFilterWrapper`` keywords of the flags' items, validated.

    Args:
        init: ``--filter-init`` (``"known"``, ``"uniform"`` or None: not given).
        threads: ``--filter-threads`` (its text, or an int; None: not given), the
            wrappers' ``tracker_threads``.

    Returns:
        ``{"tracker_params": {...}, "controller_params": {...}, "init": ...,
        "tracker_threads": ...}`` (only the given ones), or None when no flag was given.

    Raises:
        ValueError: an item that is not ``FIELD=VALUE``, an unknown field, a bad value
            (the message starts with the flag and names the field), an unknown ``init``,
            or any flag without ``safety_filter`` (the message ends with ``off_hint``).
    """
    from fov_marl.control import ControllerParams
    from fov_marl.estimation import TrackerParams
    from fov_marl.validation import check_params, parse_assignments
    from fov_marl.wrappers.safety_filter import (
        FILTER_CONTROLLER_DEFAULTS,
        FILTER_TRACKER_DEFAULTS,
    )

    classes = {
        "tracker_params": (TrackerParams, FILTER_TRACKER_DEFAULTS),
        "controller_params": (ControllerParams, FILTER_CONTROLLER_DEFAULTS),
    }
    out: dict[str, Any] = {}
    for (flag, _, key, _), items in zip(_FLAGS, (tracker_items, controller_items), strict=True):
        if not items:
            continue
        if not safety_filter:
            raise ValueError(f"{flag} sets the safety filter's options: {off_hint}")
        try:
            fields = parse_assignments(items, flag)
            cls, defaults = classes[key]
            check_params(key, fields, cls, defaults)
        except ValueError as exc:  # ConfigError, or a dataclass's own check
            msg = str(exc)
            raise ValueError(msg if msg.startswith(flag) else f"{flag} {msg}") from None
        out[key] = fields
    if init is not None:
        if not safety_filter:
            raise ValueError(f"--filter-init sets the safety filter's options: {off_hint}")
        if init not in INITS:
            raise ValueError(f"--filter-init must be one of {list(INITS)}, got {init!r}")
        out["init"] = init
    if threads is not None:
        if not safety_filter:
            raise ValueError(f"--filter-threads sets the safety filter's options: {off_hint}")
        text = str(threads).strip()
        if not (text.isascii() and text.isdigit()) or not 1 <= int(text) <= 1024:
            raise ValueError(f"--filter-threads must be an integer in [1, 1024], got {threads!r}")
        out["tracker_threads"] = int(text)
    return out or None


def check_filter_config(config: Any, sf_kwargs: Mapping[str, Any] | None) -> None:
    """Check, before any episode, that the safety filter accepts the env of ``config``
    (a :class:`~fov_marl.config.ScenarioConfig`) with the options ``sf_kwargs``
    (:func:`filter_kwargs`): e.g. a camera range at or below D_s is refused
    (:func:`~fov_marl.wrappers.safety_filter.filter_controller_params`)."""
    from fov_marl.wrappers.safety_filter import filter_controller_params

    filter_controller_params(config, (sf_kwargs or {}).get("controller_params"))
