"""Typed argument validation shared by every config dataclass, the envs and the CLI.

One module, one error type. Each check raises :class:`ConfigError` (a ``ValueError``)
whose message names the field, the value it got and the allowed range, e.g.
``fov_deg must be in (0.0, 360.0], got 400.0``, and returns the value normalised to a
plain Python type (``float``, ``int``, ``bool``, ``str``, a tuple of floats or a
read-only float64 array), so a NumPy scalar given by the user never leaks into a
config (and configs stay JSON-friendly).

Typing rules (the same for every field of every config):

* real: ``int``, ``float``, ``fractions.Fraction``, NumPy integer/floating scalars and
  0-d integer/floating arrays; ``bool``, ``str``, ``bytes``, ``complex`` (even with a
  zero imaginary part), ``None`` and containers are rejected; NaN and inf are rejected
  (no field takes them).
* integer: ``int``, NumPy integer scalars and 0-d integer arrays; ``bool`` and floats
  (even ``2.0``) are rejected.
* bool: ``bool`` or ``numpy.bool_``; ``0``/``1`` and strings are rejected.
* choice: a ``str`` from the listed options.
* sequence of n reals: a list, tuple or 1-d array of exactly n reals (each typed as
  above); a ``str`` is not a sequence of numbers.
* array: nested lists/tuples of reals or an integer/floating ndarray of the exact shape.

Nothing is silently clipped: out of range is an error.
"""

from __future__ import annotations

import math
import numbers
import os
from collections.abc import Collection, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "ConfigError",
    "describe",
    "fmt_number",
    "is_real",
    "is_integer",
    "check_real",
    "check_int",
    "check_bool",
    "check_choice",
    "check_real_sequence",
    "check_real_array",
    "check_keys",
    "check_seed",
    "check_budget",
    "fov_parallel_base",
    "keyword_parameters",
    "as_real_vector",
    "holds_bool",
    "check_out_dir",
    "check_writable",
    "MAX_SEED",
    "check_out_file",
    "check_out_path",
    "check_params",
    "has_attribute",
    "check_wrapper_kwargs",
]


class ConfigError(ValueError):
    """A configuration field is missing, unknown, wrongly typed or out of its range."""


_REPR_MAX = 80


def describe(value: Any) -> str:
    """``repr(value)`` shortened to ~80 characters, with the type when it is not obvious
    from the repr (``'2.5' (str)``, ``(1+0j) (complex)``, ``array([1.]) (ndarray)``)."""
    try:
        text = repr(value)
    except Exception:  # a hostile __repr__ must not replace the real error
        text = f"<{type(value).__name__} object>"
    if len(text) > _REPR_MAX:
        text = text[: _REPR_MAX - 3] + "..."
    if isinstance(value, bool | int | float) and type(value) in (bool, int, float):
        return text
    return f"{text} ({type(value).__name__})"


def is_real(value: Any) -> bool:
    """True for a real number as defined in the module docstring (finite or not)."""
    if isinstance(value, bool | np.bool_):
        return False
    if isinstance(value, numbers.Real):
        return True
    return isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iuf"


def is_integer(value: Any) -> bool:
    """True for an integer as defined in the module docstring."""
    if isinstance(value, bool | np.bool_):
        return False
    if isinstance(value, numbers.Integral):
        return True
    return isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iu"


def fmt_number(x: float) -> str:
    """A bound as people write it: ``5.0``, ``0.25``, ``1e6``, ``1e-8`` (not ``1000000.0``)."""
    if isinstance(x, float) and x != 0.0 and (abs(x) >= 1e5 or abs(x) < 1e-4):
        m, e = f"{x:.6g}".split("e") if "e" in f"{x:.6g}" else (f"{x:.6g}", "")
        return f"{m}e{int(e)}" if e else m
    return str(x)


def _interval(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    lo_b = "(" if lo_open or lo is None else "["
    hi_b = ")" if hi_open or hi is None else "]"
    lo_t = "-inf" if lo is None else fmt_number(lo)
    hi_t = "inf" if hi is None else fmt_number(hi)
    return f"{lo_b}{lo_t}, {hi_t}{hi_b}"


def check_real(
    name: str,
    value: Any,
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
    note: str = "",
    inf_ok: bool = False,
) -> float:
    """``value`` must be a finite real (see the module docstring) inside the interval.

    Args:
        name: field name used in the message.
        lo, hi: bounds (None: unbounded on that side).
        lo_open, hi_open: exclude the bound itself.
        note: appended to the message after the range (e.g. which fields set a bound).
        inf_ok: ``+inf`` is accepted too (a switch-off value; the message says "or inf").

    Returns:
        ``float(value)``.
    """
    allowed = _interval(lo, hi, lo_open, hi_open) + (" or inf" if inf_ok else "")
    allowed += f" {note}" if note else ""
    if not is_real(value):
        raise ConfigError(f"{name} must be a real number in {allowed}, got {describe(value)}")
    try:
        v = float(value)
    except OverflowError:
        v = math.inf if value > 0 else -math.inf
    if inf_ok and v == math.inf:
        return v
    if not math.isfinite(v):
        raise ConfigError(f"{name} must be finite and in {allowed}, got {describe(value)}")
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise ConfigError(f"{name} must be in {allowed}, got {describe(value)}")
    if hi is not None and (v > hi or (hi_open and v == hi)):
        raise ConfigError(f"{name} must be in {allowed}, got {describe(value)}")
    return v + 0.0  # -0.0 -> 0.0 (NumPy's uniform(0.0, -0.0) is an error)


def check_int(name: str, value: Any, lo: int, hi: int | None = None, *, note: str = "") -> int:
    """``value`` must be an integer (not a bool, not a float) in ``[lo, hi]``.

    Returns:
        ``int(value)``.
    """
    allowed = (f"[{lo}, inf)" if hi is None else f"[{lo}, {hi}]") + (f" {note}" if note else "")
    if not is_integer(value):
        raise ConfigError(f"{name} must be an integer in {allowed}, got {describe(value)}")
    v = int(value)
    if v < lo or (hi is not None and v > hi):
        raise ConfigError(f"{name} must be an integer in {allowed}, got {describe(value)}")
    return v


def check_bool(name: str, value: Any) -> bool:
    """``value`` must be a bool (``True``/``False`` or ``numpy.bool_``).

    Returns:
        ``bool(value)``.
    """
    if not isinstance(value, bool | np.bool_):
        raise ConfigError(f"{name} must be a bool (True or False), got {describe(value)}")
    return bool(value)


def check_choice(name: str, value: Any, choices: Sequence[str]) -> str:
    """``value`` must be one of the strings ``choices``.

    Returns:
        ``str(value)``.
    """
    if not isinstance(value, str) or value not in choices:
        raise ConfigError(f"{name} must be one of {tuple(choices)}, got {describe(value)}")
    return str(value)


def _is_sequence(value: Any) -> bool:
    if isinstance(value, str | bytes | bytearray):
        return False
    return isinstance(value, list | tuple | np.ndarray)


def check_real_sequence(
    name: str,
    value: Any,
    n: int,
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
    labels: Sequence[str] | None = None,
    note: str = "",
) -> tuple[float, ...]:
    """``value`` must be a list, tuple or 1-d array of ``n`` finite reals in the interval.

    Element k is reported as ``name[labels[k]]`` (or ``name[k]``).

    Returns:
        A tuple of ``n`` Python floats.
    """
    what = f"{name} must be a sequence of {n} real numbers"
    if not _is_sequence(value):
        raise ConfigError(f"{what}, got {describe(value)}")
    if isinstance(value, np.ndarray):
        if value.ndim != 1 or value.dtype.kind not in "iuf":
            raise ConfigError(
                f"{what} (a 1-d integer or floating array), got an array of shape "
                f"{value.shape} and dtype {value.dtype}"
            )
    if len(value) != n:
        raise ConfigError(f"{what}, got {len(value)}: {describe(value)}")
    out = []
    for k, x in enumerate(value):
        label = labels[k] if labels is not None else str(k)
        out.append(
            check_real(f"{name}[{label}]", x, lo, hi, lo_open=lo_open, hi_open=hi_open, note=note)
        )
    return tuple(out)


def _nested_reals(value: Any, shape: tuple[int, ...], path: str, name: str, text: str) -> None:
    """Check that nested lists/tuples/arrays hold reals with exactly ``shape``."""
    if not shape:
        if not is_real(value):
            raise ConfigError(f"{name}{path} must be a real number, got {describe(value)}")
        return
    if not _is_sequence(value) or (isinstance(value, np.ndarray) and value.ndim == 0):
        raise ConfigError(
            f"{name}{path} must be a sequence of length {shape[0]} ({name} has shape {text}), "
            f"got {describe(value)}"
        )
    if len(value) != shape[0]:
        raise ConfigError(
            f"{name}{path} must have length {shape[0]} ({name} has shape {text}), "
            f"got length {len(value)}"
        )
    for k, x in enumerate(value):
        _nested_reals(x, shape[1:], f"{path}[{k}]", name, text)


def check_real_array(
    name: str, value: Any, shape: tuple[int, ...], shape_text: str = ""
) -> np.ndarray:
    """``value`` must be an array of finite reals of exactly ``shape``.

    Accepted: an ndarray of integer or floating dtype, or nested lists/tuples whose
    leaves are reals (module docstring). Rejected: strings, bools, complex, object
    arrays, ragged nesting, a wrong shape, NaN or inf.

    Args:
        shape_text: how the shape is stated in messages (default ``str(shape)``).

    Returns:
        A new float64 array of ``shape`` (writable; the caller may freeze it).
    """
    text = shape_text or str(shape)
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "iuf":
            raise ConfigError(
                f"{name} must be an integer or floating array of shape {text}, "
                f"got dtype {value.dtype}"
            )
        if value.shape != shape:
            raise ConfigError(f"{name} must have shape {text}, got shape {value.shape}")
    elif not _is_sequence(value):
        raise ConfigError(
            f"{name} must be an array of shape {text} (an ndarray or nested lists), "
            f"got {describe(value)}"
        )
    else:
        _nested_reals(value, shape, "", name, text)
    try:
        arr = np.array(value, dtype=np.float64)
    except OverflowError:
        raise ConfigError(f"{name} must be finite, got an entry beyond float64's range") from None
    if not np.all(np.isfinite(arr)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise ConfigError(f"{name} must be finite, got {arr[bad]} at index {list(bad)}")
    return arr


def check_keys(what: str, given: Iterable[Any], valid: Collection[str]) -> None:
    """Every key of ``given`` must be one of ``valid`` (the message lists them)."""
    unknown = [k for k in given if k not in valid]
    if unknown:
        shown = sorted(repr(k) if not isinstance(k, str) else k for k in unknown)
        raise ConfigError(f"unknown {what} {shown}; valid {what} are {sorted(valid)}")


def check_seed(name: str, value: Any) -> int | None:
    """A seed: ``None`` or a non-negative integer (what ``numpy.random.default_rng``
    takes).

    Returns:
        ``None`` or ``int(value)``.
    """
    if value is None:
        return None
    return check_int(name, value, 0, note="(or None)")


def check_params(
    name: str, value: Any, cls: type, defaults: Mapping[str, Any] | None = None
) -> Any:
    """Options given as a params dataclass, a dict of its fields, or None.

    ``None`` gives ``cls(**defaults)``; an instance of ``cls`` is returned as is; a dict
    must use only ``cls``'s field names (the message lists them) and is applied on top of
    ``defaults``. Anything else is an error naming ``name``. The dataclass validates the
    values itself.
    """
    base = dict(defaults or {})
    if value is None:
        return cls(**base)
    if isinstance(value, cls):
        return value
    if not isinstance(value, Mapping):
        raise ConfigError(
            f"{name} must be a {cls.__name__}, a dict of its fields or None, got {describe(value)}"
        )
    fields = getattr(cls, "__dataclass_fields__", {})
    check_keys(f"{name} fields", value, fields)
    return cls(**{**base, **value})


def keyword_parameters(fn: Any, skip: int = 1) -> tuple[str, ...] | None:
    """The parameter names of ``fn`` after its first ``skip`` (e.g. ``self`` and the env),
    or None when it takes ``**kwargs`` (then only ``fn`` knows what it accepts): what
    :func:`check_keys` checks a dict of keyword options against."""
    import inspect

    params = list(inspect.signature(fn).parameters.values())[skip:]
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
        return None
    return tuple(p.name for p in params if p.kind is not inspect.Parameter.VAR_POSITIONAL)


def check_wrapper_kwargs(
    name: str, value: Any, cls: type, *, on: bool = True, switch: str = "safety_filter"
) -> dict[str, Any]:
    """Keyword options of a wrapper given as a dict, e.g. ``safety_filter_kwargs``.

    ``value`` must be None or a dict whose keys are parameters of ``cls.__init__`` after
    ``self`` and the env (the message lists them; their values are the wrapper's to
    check), and may be non-empty only while the wrapper is on (``on``): options of a
    wrapper that is off would be silently ignored, so they are an error naming
    ``switch``.

    Returns:
        A plain dict of the options (``{}`` for None).
    """
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ConfigError(
            f"{name} must be a dict of {cls.__name__} keywords or None, got {describe(value)}"
        )
    valid = keyword_parameters(cls.__init__, skip=2)
    if valid is not None:
        check_keys(name, value, valid)
    if value and not on:
        raise ConfigError(
            f"{name} {sorted(map(str, value))} need {switch}=True (they configure "
            f"{cls.__name__}, which is off)"
        )
    return dict(value)


def has_attribute(obj: Any, name: str) -> bool:
    """``hasattr`` that counts an attribute refusing to be read yet as present: a
    property raising ``ValueError`` (an env's ``poses`` before ``reset()``) exists."""
    try:
        getattr(obj, name)
    except AttributeError:
        return False
    except ValueError:
        return True
    return True


def fov_parallel_base(name: str, env: Any, vector_hint: str = "") -> Any:
    """The fov_marl ParallelEnv under ``env`` (``env.unwrapped``), or a ``ValueError``.

    For wrappers that take one ParallelEnv (``name`` for the message): a vector env (it
    has ``num_envs``), an AEC env (``env(...)``, whose ``unwrapped`` is the ParallelEnv
    but whose ``reset`` and ``step`` are turn by turn), anything without ``.config`` and
    ``.poses``, and a wrapper that changes the env's observations (the wrappers read the
    env's own layout: ``BeliefObservationWrapper`` goes outside them) are refused, naming
    what was given; ``vector_hint`` ends the vector env's message (what to use instead).
    """
    from pettingzoo import AECEnv

    base = getattr(env, "unwrapped", None)
    if hasattr(env, "num_envs") or hasattr(base, "num_envs"):
        raise ValueError(
            f"{name} wraps one fov_marl ParallelEnv (parallel_env(...)), got the vector env "
            f"{type(env).__name__}" + (f"; {vector_hint}" if vector_hint else "")
        )
    if isinstance(env, AECEnv):
        raise ValueError(
            f"{name} wraps a ParallelEnv (fov_coverage_v0.parallel_env(...) or "
            f"fov_crossing_v0.parallel_env(...)), got the AEC env {type(env).__name__}; wrap "
            "the ParallelEnv and convert the wrapper (pettingzoo.utils.parallel_to_aec)"
        )
    if base is None or not hasattr(base, "config") or not has_attribute(base, "poses"):
        raise ValueError(
            f"{name} needs a fov_marl ParallelEnv (fov_coverage_v0.parallel_env(...) or "
            f"fov_crossing_v0.parallel_env(...), possibly wrapped), got {describe(env)}"
        )
    for agent in base.possible_agents if env is not base else ():
        own, got = base.observation_space(agent).shape, env.observation_space(agent).shape
        if got != own:
            raise ValueError(
                f"{name} reads the env's own observations, shape {own} per agent, but "
                f"{type(env).__name__} gives {got} for {agent}: apply wrappers that change "
                f"the observations (BeliefObservationWrapper) outside {name}"
            )
    return base


def check_budget(
    name: str, value: Any, need: float, limit: float, what: str, unit: str, context: str = ""
) -> None:
    """Resource guard: ``need`` (what ``name = value`` would cost) must not exceed ``limit``.

    The message names the field, its value, what it costs and the stated limit, e.g.
    ``eta_grid_m = 1e-05 (arena_size_m = 40.0): the eta quadrature grid would need
    4e+06 cells per axis, more than the limit of 20000``.
    """
    if not need <= limit:  # also catches NaN
        ctx = f" ({context})" if context else ""
        raise ConfigError(
            f"{name} = {describe(value)}{ctx}: {what} would need {need:.6g} {unit}, more than "
            f"the limit of {limit:g}"
        )


def as_real_vector(name: str, value: Any, n: int) -> np.ndarray | str:
    """``value`` as a float64 vector of length ``n``, or the text of what is wrong.

    Used on hot paths (actions, every step): it returns an error description instead
    of raising, so the caller can name the agent. Accepted: an integer or floating
    array (any array-like: list, tuple, ndarray, tensors with ``__array__``) of shape
    ``(n,)``; rejected: str/bytes/bool/complex/object data, another shape. Finiteness
    is left to the caller (one vectorised check for the whole team).
    """
    if isinstance(value, str | bytes | bytearray):
        return f"must be a ({n},) array of real numbers, got {describe(value)}"
    try:
        x = np.asarray(value)
    except Exception as exc:  # ragged lists, objects whose __array__ fails
        return f"must be a ({n},) array of real numbers, got {describe(value)} ({exc})"
    if x.dtype.kind not in "iuf":
        if x.dtype.kind == "c":
            kind = "complex numbers"
        elif x.dtype.kind == "b":
            kind = "bools"
        elif x.dtype.kind in "USa":
            kind = "strings"
        else:
            kind = f"dtype {x.dtype}"
        return f"must be a ({n},) array of real numbers, got {kind}: {describe(value)}"
    if x.shape != (n,):
        return f"must have shape ({n},), got shape {x.shape}"
    if holds_bool(value):
        return f"must be a ({n},) array of real numbers, got a bool in {describe(value)}"
    return x.astype(np.float64, copy=False)


def holds_bool(value: Any) -> bool:
    """True when a list or tuple (nested) holds a ``bool`` / ``np.bool_`` element or a
    boolean array (``[np.ones((2, 3), bool), np.zeros((2, 3))]``, ``[np.array(True), 0, 0]``).

    ``np.asarray([True, 0.5, 0])`` is a float array: the bools of a mixed sequence
    would pass a dtype check. An array is not walked (its dtype says it): only its dtype
    is read, at the top level or as an element of a sequence.
    """
    if not isinstance(value, list | tuple):
        return False
    return any(
        isinstance(e, bool | np.bool_)
        or (isinstance(e, np.ndarray) and e.dtype.kind == "b")
        or (isinstance(e, list | tuple) and holds_bool(e))
        for e in value
    )


# ------------------------------------------------------------------------ output paths
def _path_reason(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    return " ".join(str(exc).split())


def _check_parent_writable(name: str, text: str, p: Path) -> None:
    anc = p
    while not os.path.lexists(anc) and anc.parent != anc:
        anc = anc.parent
    if not anc.is_dir():
        raise ConfigError(f"{name} {text}: {anc} is not a directory")
    if not os.access(anc, os.W_OK | os.X_OK):
        raise ConfigError(f"{name} {text}: {anc} is not writable")


def check_out_dir(name: str, value: str | os.PathLike) -> Path:
    """``value`` must be an output directory that exists or can be created: not empty,
    not an existing non-directory, not under a non-directory, writable. Checked before
    any work starts (nothing is created here).

    Returns:
        ``Path(value)``.
    """
    if not isinstance(value, str | os.PathLike):
        raise ConfigError(f"{name} must be a directory path, got {describe(value)}")
    text = os.fspath(value)
    if not isinstance(text, str) or not text.strip():
        raise ConfigError(f"{name} must be a directory path, got {describe(value)}")
    if "\x00" in text:
        raise ConfigError(f"{name} {text!r}: a path cannot contain a NUL byte")
    try:
        p = Path(text)
        if os.path.lexists(p) and not p.is_dir():
            raise ConfigError(f"{name} {text}: exists and is not a directory")
        _check_parent_writable(name, text, p)
    except ConfigError:
        raise
    except (OSError, ValueError) as exc:  # NUL bytes, names too long, loops
        raise ConfigError(f"{name} {text!r}: not a usable path ({_path_reason(exc)})") from None
    return p


def check_out_file(name: str, value: str | os.PathLike, suffixes: Sequence[str]) -> Path:
    """``value`` must be a writable output file path ending in one of ``suffixes``:
    not empty, not an existing directory, not under a non-directory. An existing file
    is overwritten. (:func:`check_out_path` with the suffix check.)

    Returns:
        ``Path(value)``.
    """
    return check_out_path(name, value, suffixes)


def check_out_path(
    name: str, value: str | os.PathLike, suffixes: Sequence[str] | None = None
) -> Path:
    """``value`` must be a writable output file path: not empty, not an existing
    directory, not under a non-directory (the message names the component that is not a
    directory), in a writable folder, and ending in one of ``suffixes`` unless that is
    None (any name, e.g. a file that is appended to). Nothing is created here.

    Returns:
        ``Path(value)``.
    """
    if not isinstance(value, str | os.PathLike):
        raise ConfigError(f"{name} must be a file path, got {describe(value)}")
    text = os.fspath(value)
    if not isinstance(text, str) or not text.strip():
        raise ConfigError(f"{name} must be a file path, got {describe(value)}")
    if "\x00" in text:
        raise ConfigError(f"{name} {text!r}: a path cannot contain a NUL byte")
    try:
        p = Path(text)
        if suffixes is not None and p.suffix.lower() not in suffixes:
            raise ConfigError(f"{name} must end in {', '.join(suffixes)}, got {text!r}")
        if p.is_dir():
            raise ConfigError(f"{name} {text}: is a directory")
        if os.path.lexists(p) and not os.access(p, os.W_OK):
            raise ConfigError(f"{name} {text}: exists and is not writable")
        _check_parent_writable(name, text, p.parent)
    except ConfigError:
        raise
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{name} {text!r}: not a usable path ({_path_reason(exc)})") from None
    return p


#: largest seed the CLI accepts (stable-baselines3 seeds NumPy's legacy generator, which
#: needs < 2**32; episode or copy k then uses seed + k)
MAX_SEED = 2**31 - 1


def check_writable(name: str, paths: Sequence[str | os.PathLike]) -> None:
    """Before any work: each path can be written now. Its folder is created (with its
    parents), the file opened for appending and, when it did not exist, removed again,
    so a run never ends in a write error after its work (a folder where the file should
    be, a read-only or virtual file system). Existing files are left as they are.

    Raises:
        ConfigError: naming ``name`` (the flag) and the path that cannot be written.
    """
    for path in paths:
        p = Path(path)
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
            existed = os.path.lexists(p)
            if existed and not p.is_file():
                raise ConfigError(f"{name}: {p} exists and is not a file")
            with open(p, "a", encoding="utf-8"):
                pass
            if not existed:
                p.unlink()
        except ConfigError:
            raise
        except (OSError, ValueError) as exc:
            raise ConfigError(f"{name}: cannot write {p} ({_path_reason(exc)})") from None


def parse_assignments(items: Sequence[str] | None, flag: str) -> dict[str, Any]:
    """``["key=value", ...]`` (a repeatable CLI flag) -> dict; values are parsed as JSON
    when they can be (``n_steps=128``, ``density_mean_m=[10, 10]``,
    ``policy_kwargs={"net_arch": [32, 32]}``), else kept as strings. A key given twice
    keeps the last value.

    Raises:
        ConfigError: an item without ``=`` or with an empty key (the message names
            ``flag``).
    """
    import json

    out: dict[str, Any] = {}
    for item in items or []:
        if "=" not in item:
            raise ConfigError(f"{flag} must be KEY=VALUE, got {item!r}")
        key, value = item.split("=", 1)
        key = key.strip()
        if not key:
            raise ConfigError(f"{flag} must be KEY=VALUE with a non-empty KEY, got {item!r}")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out
