"""Per-agent ``infos`` of the fov envs and wrappers: one flat, numeric format.

Every ``infos[agent]`` returned by :meth:`reset` and :meth:`step` of the envs
(``fov_coverage_v0``, ``fov_crossing_v0``) and of the wrappers
(:class:`~fov_marl.wrappers.SafetyFilterWrapper`,
:class:`~fov_marl.wrappers.BeliefObservationWrapper`) is an :class:`AgentInfo`: a
``dict`` whose entries are all flat and numeric (Python/NumPy scalars, or fixed-shape
float32 arrays), with the **same keys at reset() and at every step()**. That is what
frameworks that infer specs from the reset infos need (TorchRL's
``PettingZooWrapper``, hence BenchMARL; RLlib and SB3 accept it too).

Keys are ``"<group>/<name>"``:

==============================  ==========  ==============================================
key                             type        meaning
==============================  ==========  ==============================================
``metrics/<name>``              scalar      the env's ground-truth metrics (evaluation only,
                                            never in observations), e.g. ``metrics/eta``,
                                            ``metrics/collisions_total``; the names are
                                            listed in each scenario module's docstring
``safety/nominal_action``       (3,) f32    the policy's action, clipped to [-1, 1]
``safety/applied_action``       (3,) f32    the action the filter sent to the env
``safety/intervened``           bool        ‖u − proj(u*)‖ above the controller's
                                            tolerance; proj maps u* into the speed
                                            polygon (``ControllerParams.n_polygon``), so
                                            a full-speed u* between two of its vertices
                                            is slowed by up to 1 − cos(π/16) = 1.9%
                                            without counting as a change
``safety/fallback``             bool        a fallback input was used
``safety/status_code``          int         QP outcome, a code of :data:`SAFETY_STATUSES`
``safety/cause_bits``           int         why the action was changed: bit ``k`` for
                                            cause ``SAFETY_CAUSES[k]`` (table below); 0
                                            when it was not
==============================  ==========  ==============================================

The ``safety/*`` entries exist only behind the safety filter; at ``reset()`` they hold
neutral values (zero actions, ``False``, status code 0 = ``"reset"``, no cause).

Intervention causes (``safety/cause_bits``; :func:`cause_names` decodes, and
:func:`safety_of` adds the names as ``causes``). A changed action gets every cause
that applies, at least one:

===  =============  ===========================================================
bit  cause          the policy's input u* (projected on the admissible set) ...
===  =============  ===========================================================
0    ``neighbour``  breaks the line of a neighbour (the collision row of its
                    belief, or of the camera's report of it)
1    ``blind``      approaches the particles of an unseen neighbour too fast
                    (the blind rows)
2    ``wall``       approaches a wall too fast
3    ``cone``       moves across the uncertain line of sight of a neighbour
                    within D_s (its bearing cone)
4    ``density``    approaches a sector where unseen neighbours are expected
5    ``last_seen``  approaches where a lost neighbour was last seen
6    ``budget``     spends more blind travel than the budget allows towards a
                    bearing the camera has not looked at
7    ``fov``        breaks none of those, but the FoV levels (Eq. 16-19) were in
                    the QP: the change keeps neighbours in view
8    ``look``       the look before the leap turned the robot (ω changed)
9    ``fallback``   the collision rows could not all be met: a fallback input
10   ``other``      none of the above (e.g. the arc guard of a turn)
===  =============  ===========================================================

Bits 0-6 are the row kinds of :mod:`fov_marl.control.safety` (``ROW_KIND_NAMES``; a
row counts when u* breaks it by more than 1e-9 m/s).

Status codes (``safety/status_code``; :func:`status_name` / :func:`status_code`
convert):

====  =====================  ====================================================
code  status                 meaning (:class:`~fov_marl.control.ControlResult`)
====  =====================  ====================================================
0     ``reset``              no step yet (the neutral value at ``reset()``)
1     ``unconstrained``      u* satisfies every row, no QP
2     ``solved``             all rows hold
3     ``relaxed``            the hierarchy had to violate some rows
4     ``degraded``           a QP failed; u is the best candidate found
5     ``invalid_input``      non-finite input, u = 0
6     ``qp_failed``          a hard level is infeasible, u = 0
7     ``safety_fallback``    the collision rows cannot all be met: safe fallback
8     ``no_neighbours``      nothing to solve: a one-robot team without wall rows
                             (``walls=False`` or ``safety_model="mean"``); with
                             the defaults a lone robot is filtered against the
                             walls and reports the statuses above
====  =====================  ====================================================

Reading infos
-------------
Use :func:`metrics_of` and :func:`safety_of`; they accept this format, a plain-``dict``
copy of it, and the former nested format (``{"metrics": {...}, "safety": {...}}``).

Deprecated: the former grouped reads ``infos[agent]["metrics"]`` /
``infos[agent]["safety"]`` (and ``.get``, ``in``) still work on an :class:`AgentInfo`
and return the group as a new nested dict (``safety`` with the ``status`` string), with
a ``DeprecationWarning``. They will be removed in a later release; a plain ``dict``
copy (``dict(info)``) has no such fallback.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

__all__ = [
    "AgentInfo",
    "METRICS_PREFIX",
    "SAFETY_KEYS",
    "SAFETY_PREFIX",
    "SAFETY_STATUSES",
    "SAFETY_CAUSES",
    "agent_infos",
    "cause_counts",
    "cause_names",
    "has_safety",
    "metrics_of",
    "reset_safety_infos",
    "safety_of",
    "set_safety_infos",
    "status_code",
    "status_name",
]

METRICS_PREFIX = "metrics/"
SAFETY_PREFIX = "safety/"

#: Status names by code (``safety/status_code``); see the module docstring's table.
SAFETY_STATUSES: tuple[str, ...] = (
    "reset",
    "unconstrained",
    "solved",
    "relaxed",
    "degraded",
    "invalid_input",
    "qp_failed",
    "safety_fallback",
    "no_neighbours",
)
_CODES = {s: i for i, s in enumerate(SAFETY_STATUSES)}

#: The flat ``safety/*`` keys, identical at reset and step.
SAFETY_KEYS: tuple[str, ...] = (
    "safety/nominal_action",
    "safety/applied_action",
    "safety/intervened",
    "safety/fallback",
    "safety/status_code",
    "safety/cause_bits",
)
#: Intervention causes by bit of ``safety/cause_bits`` (module docstring table); the
#: first seven are the row kinds (:data:`fov_marl.control.safety.ROW_KIND_NAMES` is
#: this slice, the codes ``ROW_NEIGHBOUR`` ... ``ROW_BUDGET`` index it).
SAFETY_CAUSES: tuple[str, ...] = (
    "neighbour",
    "blind",
    "wall",
    "cone",
    "density",
    "last_seen",
    "budget",
    "fov",
    "look",
    "fallback",
    "other",
)
_GROUPS = {"metrics": METRICS_PREFIX, "safety": SAFETY_PREFIX}


def status_code(status: str) -> int:
    """Code of a controller status string (module docstring table).

    Raises:
        ValueError: an unknown status (the allowed ones are listed).
    """
    try:
        return _CODES[status]
    except (KeyError, TypeError):
        raise ValueError(
            f"safety status must be one of {list(SAFETY_STATUSES)}, got {status!r}"
        ) from None


def status_name(code: int | np.integer | float) -> str:
    """Status string of a ``safety/status_code`` (floats from a tensor are accepted).

    Raises:
        ValueError: not an integer code in ``[0, len(SAFETY_STATUSES) - 1]``.
    """
    c = float(code)
    if not (c.is_integer() and 0 <= c < len(SAFETY_STATUSES)):
        raise ValueError(
            f"safety status_code must be an integer in [0, {len(SAFETY_STATUSES) - 1}], "
            f"got {code!r}"
        )
    return SAFETY_STATUSES[int(c)]


def cause_names(bits: int | np.integer | float) -> tuple[str, ...]:
    """The causes (:data:`SAFETY_CAUSES`, in bit order) of a ``safety/cause_bits`` value
    (floats from a tensor are accepted); ``()`` for 0.

    Raises:
        ValueError: not an integer in ``[0, 2^len(SAFETY_CAUSES) − 1]``.
    """
    c = float(bits)
    top = (1 << len(SAFETY_CAUSES)) - 1
    if not (c.is_integer() and 0 <= c <= top):
        raise ValueError(f"safety cause_bits must be an integer in [0, {top}], got {bits!r}")
    b = int(c)
    return tuple(name for k, name in enumerate(SAFETY_CAUSES) if b >> k & 1)


def cause_counts(bits: Any) -> np.ndarray:
    """How many of the ``safety/cause_bits`` values in ``bits`` (an iterable or array of
    integers) have each cause: ``(len(SAFETY_CAUSES),)`` int64, in bit order."""
    b = np.asarray(bits, dtype=np.int64).reshape(-1, 1)
    return ((b >> np.arange(len(SAFETY_CAUSES))) & 1).sum(axis=0)


def _group(info: Mapping[str, Any], group: str) -> dict[str, Any]:
    prefix = _GROUPS[group]
    n = len(prefix)
    out = {k[n:]: v for k, v in info.items() if isinstance(k, str) and k.startswith(prefix)}
    if group == "safety" and "status_code" in out:
        out["status"] = status_name(out["status_code"])
    if group == "safety" and "cause_bits" in out:
        out["causes"] = cause_names(out["cause_bits"])
    return out


def _has_group(info: Mapping[str, Any], group: str) -> bool:
    prefix = _GROUPS[group]
    return any(isinstance(k, str) and k.startswith(prefix) for k in info.keys())


def _warn_legacy(group: str) -> None:
    fn = "metrics_of" if group == "metrics" else "safety_of"
    warnings.warn(
        f'infos[agent]["{group}"] is deprecated: infos are flat ("{group}/<name>" keys); '
        f"use fov_marl.infos.{fn}(info)",
        DeprecationWarning,
        stacklevel=3,
    )


class AgentInfo(dict):
    """One agent's flat infos (a ``dict``; module docstring), with the deprecated
    grouped reads ``info["metrics"]`` / ``info["safety"]`` as a fallback."""

    __slots__ = ()

    def __missing__(self, key: Any) -> Any:
        if key in _GROUPS and _has_group(self, key):
            _warn_legacy(key)
            return _group(self, key)
        raise KeyError(key)

    def get(self, key: Any, default: Any = None) -> Any:
        if dict.__contains__(self, key):
            return dict.__getitem__(self, key)
        if key in _GROUPS and _has_group(self, key):
            _warn_legacy(key)
            return _group(self, key)
        return default

    def __contains__(self, key: object) -> bool:
        return dict.__contains__(self, key) or (
            isinstance(key, str) and key in _GROUPS and _has_group(self, key)
        )

    def copy(self) -> AgentInfo:
        return AgentInfo(self)


def metrics_of(info: Mapping[str, Any]) -> dict[str, Any]:
    """The metrics of one agent's info as ``{name: value}`` (e.g. ``["eta"]``).

    Accepts the flat format (an :class:`AgentInfo` or a plain-dict copy) and the former
    nested one (``info["metrics"]`` a dict); ``{}`` when there are no metrics.
    """
    nested = dict.get(info, "metrics") if isinstance(info, dict) else info.get("metrics")
    if isinstance(nested, Mapping):
        return dict(nested)
    return _group(info, "metrics")


def safety_of(info: Mapping[str, Any]) -> dict[str, Any] | None:
    """The safety filter's entries of one agent's info, or None without the filter.

    Keys: ``nominal_action``, ``applied_action``, ``intervened``, ``fallback``,
    ``status_code`` and ``status`` (its string), ``cause_bits`` and ``causes`` (their
    names, :func:`cause_names`). Accepts the flat and the former nested
    format, like :func:`metrics_of`.
    """
    nested = dict.get(info, "safety") if isinstance(info, dict) else info.get("safety")
    if isinstance(nested, Mapping):
        out = dict(nested)
        if "status" in out and "status_code" not in out:
            out["status_code"] = status_code(out["status"])
        return out
    if not _has_group(info, "safety"):
        return None
    return _group(info, "safety")


def has_safety(info: Mapping[str, Any]) -> bool:
    """True when ``info`` carries the safety filter's entries (flat or nested)."""
    return safety_of(info) is not None


def agent_infos(agents: Sequence[str], metrics: Mapping[str, Any]) -> dict[str, AgentInfo]:
    """The env's per-agent infos: ``agent -> AgentInfo({"metrics/<name>": value})``.

    Args:
        agents: the agents to report (the live ones).
        metrics: ``{name: scalar}``, the same for every agent (ground truth).

    Raises:
        ValueError: a metric that is not a real scalar (TorchRL needs numeric entries).
    """
    flat: dict[str, Any] = {}
    for k, v in metrics.items():
        if isinstance(v, (bool, int, float, np.bool_, np.integer, np.floating)):
            flat[METRICS_PREFIX + k] = v
        else:
            raise ValueError(f"metric {k!r} must be a real scalar, got {type(v).__name__}")
    return {a: AgentInfo(flat) for a in agents}


def set_safety_infos(
    infos: Mapping[str, dict],
    agent_index: Mapping[str, int],
    nominal_action: np.ndarray,
    applied_action: np.ndarray,
    intervened: np.ndarray,
    fallback: np.ndarray,
    status: Sequence[str],
    cause_bits: np.ndarray | None = None,
) -> None:
    """Write the ``safety/*`` entries of every agent in ``infos`` (in place).

    Args:
        infos: ``agent -> info`` of the wrapped env's step.
        agent_index: ``agent -> robot index i``.
        nominal_action, applied_action: ``(N, 3)`` actions of the whole team (rows by
            robot index; stored as float32 copies).
        intervened, fallback: ``(N,)`` bool.
        status: ``N`` status strings (:data:`SAFETY_STATUSES`).
        cause_bits: ``(N,)`` integer bit masks of :data:`SAFETY_CAUSES`; None: 0.
    """
    nominal = np.asarray(nominal_action, dtype=np.float32)
    applied = np.asarray(applied_action, dtype=np.float32)
    codes = [status_code(s) for s in status]
    causes = np.zeros(len(codes), np.int64) if cause_bits is None else np.asarray(cause_bits)
    for a, info in infos.items():
        i = agent_index[a]
        info["safety/nominal_action"] = nominal[i].copy()
        info["safety/applied_action"] = applied[i].copy()
        info["safety/intervened"] = bool(intervened[i])
        info["safety/fallback"] = bool(fallback[i])
        info["safety/status_code"] = codes[i]
        info["safety/cause_bits"] = int(causes[i])


def reset_safety_infos(infos: Mapping[str, dict], action_size: int = 3) -> None:
    """Write the neutral ``safety/*`` entries of ``reset()`` (in place): zero actions,
    ``False`` flags, status code 0 (``"reset"``), no cause."""
    for info in infos.values():
        info["safety/nominal_action"] = np.zeros(action_size, np.float32)
        info["safety/applied_action"] = np.zeros(action_size, np.float32)
        info["safety/intervened"] = False
        info["safety/fallback"] = False
        info["safety/status_code"] = 0
        info["safety/cause_bits"] = 0
