"""SubprocVectorEnv: the copies of a vector env split over worker processes.

The batched core, the tracker bank and the batched controller are single-threaded
NumPy: one process uses one core, however many copies it steps. ``SubprocVectorEnv``
splits B copies into W contiguous shards, builds each shard's vector env in its own
worker process and steps the shards in parallel (like Gymnasium's ``AsyncVectorEnv``
and SB3's ``SubprocVecEnv``, but one process per *shard* of copies, not per copy)::

    from functools import partial
    from fov_marl.config import make_config
    from fov_marl.envs import SubprocVectorEnv
    from fov_marl.wrappers import build_filtered_vector_env

    # each shard: a vector env behind the VectorSafetyFilterWrapper
    make = partial(build_filtered_vector_env, config=make_config(n_agents=6))
    venv = SubprocVectorEnv(make, num_envs=64, workers=2)
    obs, infos = venv.reset(seed=0)           # obs (64, N, D)
    obs, rew, term, trunc, infos = venv.step(actions)   # actions (64, N, 3)
    venv.close()

``fov_coverage_v0.vector_env(num_envs=B, workers=W)`` builds one for the raw env
(shard factory :func:`build_raw_vector_env`);
``fov-marl train --workers W`` for training (with or without ``--safety-filter``).

Shards. Shard w holds copies ``[k_w, k_{w+1})`` (``np.array_split`` sizes: they differ
by at most one); its vector env is ``make_vector(k_{w+1} − k_w)``. ``make_vector`` must be
picklable (a module-level function, or ``functools.partial`` of one with picklable
arguments): the workers are started with the ``forkserver`` method where the platform
has it (``spawn`` elsewhere), never ``fork``, so a parent that holds threads (torch) is
safe; as with every such start method, a script that creates one needs the
``if __name__ == "__main__":`` guard (the workers import the main module).

Same numbers as one process. ``reset(seed=s)`` resets shard w with ``s + k_w``, so copy
k starts from ``s + k`` as in ``make_vector(B)``; a sequence of B seeds is checked here
and sliced. The env core, the tracker bank and the batched controller compute every copy's numbers
from that copy alone (the controller solves each robot's program sliced to its own rows
and variables, never the batch's padding, and forms its products without BLAS, whose
kernels round by the matrix size), so copy k's observations, rewards, metrics and,
behind the filter, applied actions are bit-identical to those of ``make_vector(B)``
under the same actions (tested raw and filtered across automatic resets; measured over
400 steps of N = 8 in a 12 m arena, B = 6 over 3 workers, and of crossing, B = 5 over 2).

The vector API of :class:`~fov_marl.envs.vector.FovVectorEnv` (and of
:class:`~fov_marl.wrappers.VectorSafetyFilterWrapper`): ``num_envs``, ``n_agents``,
``config``, ``possible_agents``, ``single_observation_space``, ``single_action_space``,
``observation_space``, ``action_space``, ``max_cycles`` (settable: set in every shard),
``poses``, ``targets``, ``num_steps``, ``state()``, ``reset``, ``step`` (same-step
autoreset; ``infos`` arrays are the shards' concatenated along the copy axis, and
``infos["reset_metrics"]`` is present when any copy finished, holding
``infos["metrics"]`` for the copies of shards where none did, as in one process) and
``close``. ``last_cpu_s``: the filter's seconds in the last step summed over the
shards (CPU time, not wall time), where the shards have it. :meth:`get_attr`,
:meth:`set_attr` and :meth:`call` reach any other attribute, one result per shard
(``shard_starts`` says which copies each shard holds).

Errors. Actions are checked here (shape, dtype, finite) with the messages of the
vector env. A ``ValueError`` (a ``ConfigError`` stays one) or ``AttributeError`` raised
in a worker is raised again here with its message; any other exception becomes a
``RuntimeError`` carrying the worker's traceback. A ``step`` or ``reset`` that fails in
a worker leaves the other shards moved, so the env refuses to step until ``reset()``. An
argument that cannot be pickled is a ``ValueError`` before any worker sees the command.
A worker that dies makes the next call raise ``RuntimeError``. Workers ignore SIGINT:
Ctrl-C reaches the parent only. A call it interrupts leaves the pipes in order (every
message is sent and read whole, with SIGINT and SIGALRM handled right after it, and
answers carry their command's number, so the next call discards stale ones): the env
can step on or be closed (``fov-marl train`` saves its model on Ctrl-C); the shards
that had received an interrupted ``step`` have stepped. The same holds for whatever a
SIGINT or SIGALRM handler raises (an alarm-based timeout's ``TimeoutError``, any
exception): the caller gets that exception, never a "worker has exited" for it, and the
env steps on; only a worker's own failure makes it wait for ``reset()``. ``close()``
is idempotent (a handler's exception during it is raised once the workers are stopped);
the env is a context manager.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import pickle
import signal
import threading
import traceback
from collections.abc import Callable, Iterator, Sequence
from functools import partial
from multiprocessing.reduction import ForkingPickler
from typing import Any

import gymnasium
import numpy as np

from fov_marl.config import ScenarioConfig
from fov_marl.envs.vector import (
    FovVectorEnv,
    check_num_envs,
    check_vector_actions,
    vector_seeds,
    warn_no_render,
)
from fov_marl.validation import ConfigError, check_int, describe

__all__ = ["SubprocVectorEnv", "build_raw_vector_env", "make_vector_env"]

#: Seconds ``close()`` waits for a worker to exit before terminating it.
CLOSE_TIMEOUT_S = 10.0


def build_raw_vector_env(
    num_envs: int,
    *,
    config: ScenarioConfig,
    max_cycles: int | None = None,
    eta_method: str = "exact",
) -> FovVectorEnv:
    """``FovVectorEnv.from_config(config, num_envs, eta_method)`` with ``max_cycles`` set
    (None: the config's); module-level, so ``functools.partial`` of it is a picklable
    shard factory of :class:`SubprocVectorEnv`."""
    venv = FovVectorEnv.from_config(config, num_envs, eta_method=eta_method)
    if max_cycles is not None:
        venv.max_cycles = int(max_cycles)
    return venv


def make_vector_env(
    scenario: str,
    name: str,
    num_envs: int,
    config_kwargs: dict[str, Any],
    *,
    workers: int = 1,
    eta_method: str = "exact",
) -> FovVectorEnv | SubprocVectorEnv:
    """The ``vector_env`` of the scenario modules: one :class:`FovVectorEnv` for
    ``workers = 1``, else a :class:`SubprocVectorEnv` of ``workers`` shards of it (the
    config validated here, once, before any process starts)."""
    if check_int("workers", workers, 1, note="(at most num_envs)") == 1:
        return FovVectorEnv(num_envs, scenario, name, config_kwargs, eta_method=eta_method)
    probe = FovVectorEnv(1, scenario, name, config_kwargs, eta_method=eta_method)
    make = partial(build_raw_vector_env, config=probe.config, eta_method=eta_method)
    return SubprocVectorEnv(make, check_num_envs(num_envs), int(workers))


_NOT_RESET = "step() called before reset(); call reset() first"

#: worker exceptions the parent raises again as themselves (with the worker's message);
#: the first class the exception is an instance of wins, so ``ConfigError`` stays one
_RERAISED = (ConfigError, ValueError, AttributeError)


def _error(exc: BaseException) -> tuple[str, str, str, int]:
    """What the parent needs to raise it again: name, message, traceback, and the index
    in ``_RERAISED`` of the class it is raised again as (a ``ConfigError`` stays one, as
    in one process; any other ``ValueError`` becomes a ``ValueError``; an unknown
    attribute stays an ``AttributeError``), or -1."""
    kind = next((k for k, cls in enumerate(_RERAISED) if isinstance(exc, cls)), -1)
    return type(exc).__name__, str(exc), traceback.format_exc(), kind


#: what a shard's vector env must have (sent to the parent once built)
_STATIC = (
    "num_envs",
    "n_agents",
    "config",
    "possible_agents",
    "single_observation_space",
    "single_action_space",
    "max_cycles",
    "metadata",
)


def _worker(conn: Any, make_vector: Callable[[int], Any], num_envs: int) -> None:
    """A shard's process: build its vector env, then serve commands until ``close``.

    Protocol: the parent sends ``(seq, blob)``, ``blob`` the pickled ``(cmd, arg)``; the
    worker answers ``(seq, status, payload)`` for every command it receives, in order
    (its first answer, seq 0, is the shard's static attributes). A command whose blob
    cannot be unpickled here is answered with its error.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        venv = make_vector(num_envs)
        missing = [name for name in _STATIC if not hasattr(venv, name)]
        if missing:
            raise ValueError(
                f"make_vector({num_envs}) must return a vector env, got {describe(venv)} "
                f"(it has no {missing[0]!r})"
            )
        static = {name: getattr(venv, name) for name in _STATIC}
    except BaseException as exc:  # noqa: BLE001 - reported to the parent
        conn.send((0, "error", _error(exc)))
        conn.close()
        return
    static["per_copy_wrappers"] = tuple(getattr(venv, "per_copy_wrappers", ()))
    conn.send((0, "ok", static))
    while True:
        try:
            seq, blob = conn.recv()
        except (EOFError, OSError):  # the parent is gone
            break
        try:
            cmd, arg = pickle.loads(blob)
            if cmd == "step":
                out: Any = (*venv.step(arg), getattr(venv, "last_cpu_s", None))
            elif cmd == "reset":
                out = venv.reset(seed=arg[0], options=arg[1])
            elif cmd == "get":
                out = getattr(venv, arg)
            elif cmd == "call":
                name, args, kwargs = arg
                out = getattr(venv, name)(*args, **kwargs)
            elif cmd == "set":
                setattr(venv, arg[0], arg[1])
                out = None
            elif cmd == "close":
                close = getattr(venv, "close", None)
                if close is not None:
                    close()
                conn.send((seq, "ok", None))
                break
            else:
                raise ValueError(f"unknown command {cmd!r}")
            reply = ForkingPickler.dumps((seq, "ok", out))
        except BaseException as exc:  # noqa: BLE001 - reported to the parent
            reply = ForkingPickler.dumps((seq, "error", _error(exc)))
        try:
            conn.send_bytes(reply)
        except (EOFError, OSError):  # the parent is gone
            break
    conn.close()


#: signals whose Python handler may raise in the parent (Ctrl-C, alarm-based timeouts):
#: deferred while a message is on the pipe, so a message is never half sent or half read
_DEFERRED_SIGNALS = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGALRM") if hasattr(signal, name)
)


#: the attribute :func:`_run_handler` sets on an exception a signal handler raised
_FROM_SIGNAL = "_fov_marl_from_signal"


def _run_handler(handler: Callable[[int, Any], Any], signum: int, frame: Any) -> None:
    """Call a signal handler of :data:`_DEFERRED_SIGNALS`; an exception it raises is
    tagged (:func:`from_signal`) and raised on. A handler may raise anything, also an
    ``OSError`` (``TimeoutError`` is one): the tag tells it from a pipe's own error."""
    try:
        handler(signum, frame)
    except BaseException as exc:
        with contextlib.suppress(AttributeError, TypeError):  # a class with __slots__
            setattr(exc, _FROM_SIGNAL, True)
        raise


class _PipeClosed(Exception):
    """A worker's pipe is closed or broken (the worker has exited): raised only where a
    pipe is read or written, so a signal handler's ``OSError`` is never taken for it."""


#: the attribute set on the exceptions that mean a worker failed (it raised, or exited)
_FROM_WORKER = "_fov_marl_from_worker"


def _worker_failure(exc: BaseException) -> BaseException:
    """``exc``, tagged as a worker's failure (:meth:`SubprocVectorEnv._broadcast` then
    refuses to step until ``reset()``)."""
    setattr(exc, _FROM_WORKER, True)
    return exc


def from_signal(exc: BaseException) -> bool:
    """True when ``exc`` was raised by a signal handler while this module waited on or
    used a pipe (Ctrl-C, an alarm-based timeout), not by the pipe or a worker."""
    return bool(getattr(exc, _FROM_SIGNAL, False))


@contextlib.contextmanager
def _signals_tagged() -> Iterator[None]:
    """Run the block (an interruptible wait) with the Python handlers of
    :data:`_DEFERRED_SIGNALS` wrapped by :func:`_run_handler`, so an exception one of them
    raises inside the block is told from the pipe's errors. Main thread only (elsewhere
    no handler runs)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    saved: list[tuple[int, Any]] = []
    for sig in _DEFERRED_SIGNALS:
        old = signal.getsignal(sig)
        if callable(old):
            saved.append((sig, old))
            signal.signal(sig, partial(_run_handler, old))
    try:
        yield
    finally:
        for sig, old in saved:
            signal.signal(sig, old)


@contextlib.contextmanager
def _signals_deferred() -> Iterator[None]:
    """Run the block with the Python handlers of :data:`_DEFERRED_SIGNALS` held back: a
    signal that arrives meanwhile is handled (e.g. ``KeyboardInterrupt`` raised, tagged
    by :func:`_run_handler`) right after the block. Only the main thread runs Python
    signal handlers, so elsewhere nothing is deferred (nothing can interrupt the block
    there)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[tuple[int, Any]] = []
    saved: list[tuple[int, Any]] = []
    for sig in _DEFERRED_SIGNALS:
        old = signal.getsignal(sig)
        if callable(old):
            saved.append((sig, old))
            signal.signal(sig, lambda signum, frame: caught.append((signum, frame)))
    try:
        yield
    finally:
        for sig, old in saved:
            signal.signal(sig, old)
        for signum, frame in caught:
            _run_handler(dict(saved)[signum], signum, frame)


def _concat(parts: list[Any], key: str) -> Any:
    """Concatenate the shards' values of one ``infos`` entry along the copy axis."""
    if isinstance(parts[0], dict):
        return {k: _concat([p[k] for p in parts], f"{key}/{k}") for k in parts[0]}
    return np.concatenate([np.asarray(p) for p in parts], axis=0)


def merge_vector_infos(parts: list[dict[str, Any]]) -> dict[str, Any]:
    """One vector ``infos`` from the shards' (see the module docstring).

    Every entry is a ``(B_w, ...)`` array or a dict of them; ``reset_metrics`` is filled
    with ``metrics`` for shards that have none. Another entry missing from some shard
    is an error (the shards' env types differ)."""
    keys: list[str] = []
    for p in parts:
        keys.extend(k for k in p if k not in keys)
    if any("reset_metrics" in p for p in parts):
        parts = [p if "reset_metrics" in p else {**p, "reset_metrics": p["metrics"]} for p in parts]
    out: dict[str, Any] = {}
    for k in keys:
        missing = [w for w, p in enumerate(parts) if k not in p]
        if missing:
            raise RuntimeError(f"infos[{k!r}] is missing from shard(s) {missing}")
        out[k] = _concat([p[k] for p in parts], k)
    return out


class SubprocVectorEnv:
    """B copies of a vector env split over W worker processes (see the module docstring).

    Args:
        make_vector: picklable ``make_vector(n) -> vector env of n copies``.
        num_envs: B, an integer ≥ 1.
        workers: W, an integer in [1, B].
        start_method: ``"forkserver"`` or ``"spawn"`` (default: forkserver where
            available). ``"fork"`` is refused (unsafe in a threaded parent).

    Raises:
        ValueError: bad ``num_envs``, ``workers`` or ``start_method``; ``make_vector`` not
            picklable or not callable; a worker's ``ValueError`` while building its shard
            (its message).
        RuntimeError: a worker failed otherwise (with its traceback).
    """

    #: The vector env does not render (use a ParallelEnv for frames).
    render_mode: str | None = None

    def __init__(
        self,
        make_vector: Callable[[int], Any],
        num_envs: int,
        workers: int = 2,
        *,
        start_method: str | None = None,
    ) -> None:
        B = check_num_envs(num_envs)
        workers = check_int("workers", workers, 1, B, note="(at most num_envs)")
        if not callable(make_vector):
            raise ValueError(f"make_vector must be callable, got {describe(make_vector)}")
        try:
            pickle.dumps(make_vector)
        except Exception as exc:  # noqa: BLE001 - any pickling failure
            raise ValueError(
                "make_vector must be picklable (a module-level function or a "
                f"functools.partial of one): {exc}"
            ) from None
        methods = mp.get_all_start_methods()
        if start_method is None:
            start_method = "forkserver" if "forkserver" in methods else "spawn"
        if start_method not in ("forkserver", "spawn") or start_method not in methods:
            allowed = [m for m in ("forkserver", "spawn") if m in methods]
            raise ValueError(f"start_method must be one of {allowed}, got {start_method!r}")
        self._closed = True
        self._conns: list[Any] = []
        self._procs: list[Any] = []
        self.num_envs = B
        self.workers = int(workers)
        sizes = [len(a) for a in np.array_split(np.arange(B), self.workers)]
        self._starts = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        ctx = mp.get_context(start_method)
        for n in sizes:
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_worker, args=(child, make_vector, n), daemon=True)
            proc.start()
            child.close()
            self._conns.append(parent)
            self._procs.append(proc)
        # the protocol of _worker: command seq numbers sent to / answered by each worker
        # (each worker answers seq 0 once built)
        self._seq = 0
        self._sent = [0] * self.workers
        self._answered = [-1] * self.workers
        self._closed = False
        try:
            statics = self._recv_all(0)
        except BaseException:
            self.close()
            raise
        s0 = statics[0]
        for w, s in enumerate(statics):
            if s["num_envs"] != sizes[w]:
                self.close()
                raise ValueError(
                    f"make_vector({sizes[w]}) built a vector env of {s['num_envs']} copies"
                )
            if s["n_agents"] != s0["n_agents"] or s["config"] != s0["config"]:
                self.close()
                raise ValueError("make_vector built shards with different configs")
        self.config: ScenarioConfig = s0["config"]
        self.n_agents: int = int(s0["n_agents"])
        self.possible_agents: list[str] = list(s0["possible_agents"])
        self.single_observation_space = s0["single_observation_space"]
        self.single_action_space = s0["single_action_space"]
        self.metadata = dict(s0["metadata"])
        self._max_cycles = int(s0["max_cycles"])
        #: the per-copy wrappers the shards stand for (``VectorSafetyFilterWrapper``'s)
        self.per_copy_wrappers: tuple[type, ...] = tuple(s0["per_copy_wrappers"])
        low = self.single_observation_space.low
        high = self.single_observation_space.high
        shape = (B, self.n_agents, *low.shape)
        self.observation_space = gymnasium.spaces.Box(
            np.broadcast_to(low, shape), np.broadcast_to(high, shape), dtype=np.float32
        )
        self.action_space = gymnasium.spaces.Box(-1.0, 1.0, (B, self.n_agents, 3), np.float32)
        self.last_cpu_s: float | None = None
        self._needs_reset = True
        self._not_ready = _NOT_RESET

    # ------------------------------------------------------------ plumbing
    def _check_open(self) -> None:
        if self._closed:
            raise ValueError("the SubprocVectorEnv is closed")

    def _next_answer(self, w: int) -> tuple[int, str, Any]:
        """Worker w's next answer ``(seq, status, payload)``. The wait can be interrupted
        (Ctrl-C) and leaves nothing half read: the message is read with the signals
        deferred (:func:`_signals_deferred`), together with the count of answers."""
        conn = self._conns[w]
        with _signals_tagged():
            try:
                conn.poll(None)  # interruptible; consumes nothing
            except (EOFError, OSError) as exc:
                if from_signal(exc):  # e.g. a timeout's TimeoutError: the caller's
                    raise
                raise _PipeClosed from exc
        with _signals_deferred():  # no handler runs in here: an error is the pipe's
            try:
                msg = conn.recv()
            except (EOFError, OSError) as exc:
                raise _PipeClosed from exc
            self._answered[w] = msg[0]
        return msg

    def _drain(self) -> None:
        """Discard the answers of commands whose caller stopped waiting (Ctrl-C during a
        step): every worker finishes its command and answers; the next command must not
        read that stale answer (nor block on a pipe the stale answer fills)."""
        for w in range(self.workers):
            while self._answered[w] < self._sent[w]:
                try:
                    self._next_answer(w)
                except _PipeClosed:
                    break

    def _broadcast(self, cmd: str, args: list[Any]) -> list[Any]:
        """Send ``(cmd, args[w])`` to every worker w, then collect their answers.

        Every argument is pickled before anything is sent: one that cannot be is a
        ``ValueError`` and no worker sees the command. A command interrupted while it is
        sent or answered (Ctrl-C) leaves the protocol in order: the next command first
        discards the stale answers (:meth:`_drain`). The copies of the shards that had
        received an interrupted ``step`` have stepped, the others have not.
        """
        self._check_open()
        blobs = []
        for arg in args:
            with _signals_tagged():  # the whole try: every handler's exception is tagged
                try:
                    blobs.append(ForkingPickler.dumps((cmd, arg)))
                except Exception as exc:  # noqa: BLE001 - any pickling failure
                    if from_signal(exc):  # not the pickler's: a timeout's, the caller's
                        raise
                    raise ValueError(
                        f"the arguments of {cmd!r} must be picklable to reach the worker "
                        f"processes: {type(exc).__name__}: {exc}"
                    ) from None
        self._drain()
        self._seq += 1
        seq = self._seq
        try:
            for w, blob in enumerate(blobs):
                with _signals_deferred():  # no handler runs in here: an error is the pipe's
                    try:
                        self._conns[w].send((seq, bytes(blob)))
                    except OSError:
                        raise _worker_failure(
                            RuntimeError(
                                f"worker {w} of the SubprocVectorEnv has exited "
                                f"(exit code {self._procs[w].exitcode})"
                            )
                        ) from None
                    self._sent[w] = seq
            return self._recv_all(seq)
        except Exception as exc:
            if cmd in ("step", "reset") and getattr(exc, _FROM_WORKER, False):
                # a shard that failed (a finished copy that could not reset) left the
                # others moved: nothing steps on until reset(), as in FovVectorEnv. An
                # exception of a signal handler (Ctrl-C, an alarm-based timeout) is not
                # this: the protocol keeps the shards in step.
                self._needs_reset = True
                self._not_ready = f"the last {cmd}() failed in a worker; call reset()"
            raise

    def _recv_all(self, seq: int) -> list[Any]:
        """Every shard's answer to command ``seq``, in order (older answers are
        discarded); the first error is raised after all answered."""
        results: list[Any] = []
        error: BaseException | None = None
        for w in range(self.workers):
            try:
                while True:
                    got, status, payload = self._next_answer(w)
                    if got == seq:
                        break
            except _PipeClosed:
                self._answered[w] = self._sent[w]  # nothing more will come
                self._procs[w].join(timeout=1.0)
                hint = (
                    "; a script that starts workers needs the 'if __name__ == \"__main__\":' guard"
                    if seq == 0
                    else ""
                )
                error = error or RuntimeError(
                    f"worker {w} of the SubprocVectorEnv has exited "
                    f"(exit code {self._procs[w].exitcode}){hint}"
                )
                results.append(None)
                continue
            if status == "error" and error is None:
                name, msg, tb, kind = payload
                error = (
                    _RERAISED[kind](msg)
                    if kind >= 0
                    else RuntimeError(f"worker {w} raised {name}: {msg}\n{tb}")
                )
            results.append(payload)
        if error is not None:
            raise _worker_failure(error)
        return results

    def _all(self, cmd: str, arg: Any = None) -> list[Any]:
        return self._broadcast(cmd, [arg] * self.workers)

    # ------------------------------------------------------------- episode
    def reset(
        self, seed: int | Sequence[int] | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every copy (see the module docstring for the seeds)."""
        self._check_open()
        st = self._starts
        # checked here, so a bad entry is named by its copy and no shard has reset
        seeds = vector_seeds(seed, self.num_envs)  # copy k's seed, sliced per shard
        parts = self._broadcast(
            "reset", [(seeds[st[w] : st[w + 1]], options) for w in range(self.workers)]
        )
        self._needs_reset = False
        obs = np.concatenate([p[0] for p in parts], axis=0)
        return obs, merge_vector_infos([p[1] for p in parts])

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """One step of every copy in parallel (same-step autoreset; module docstring)."""
        self._check_open()
        if self._needs_reset:
            raise ValueError(self._not_ready)
        act = check_vector_actions(actions, self.num_envs, self.n_agents)
        st = self._starts
        parts = self._broadcast("step", [act[st[w] : st[w + 1]] for w in range(self.workers)])
        obs, rew, term, trunc = (np.concatenate([p[i] for p in parts]) for i in range(4))
        infos = merge_vector_infos([p[4] for p in parts])
        cpu = [p[5] for p in parts]
        self.last_cpu_s = None if any(c is None for c in cpu) else float(sum(cpu))
        return obs, rew, term, trunc, infos

    # ------------------------------------------------------------ attributes
    @property
    def max_cycles(self) -> int:
        """Steps before truncation; setting it sets it in every shard."""
        return self._max_cycles

    @max_cycles.setter
    def max_cycles(self, value: int) -> None:
        value = check_int("max_cycles", value, 1)  # checked here: no shard sees a bad one
        self._all("set", ("max_cycles", value))
        self._max_cycles = int(self.get_attr("max_cycles")[0])

    def _gather(self, name: str) -> Any:
        parts = self.get_attr(name)
        if parts[0] is None:
            return None
        out = np.concatenate([np.asarray(p) for p in parts], axis=0)
        out.setflags(write=False)
        return out

    @property
    def poses(self) -> np.ndarray:
        """``(B, N, 3)`` ground-truth world poses (read-only copy)."""
        return self._gather("poses")

    @property
    def targets(self) -> np.ndarray | None:
        """``(B, N, 2)`` crossing targets (read-only copy), else None."""
        return self._gather("targets")

    @property
    def num_steps(self) -> np.ndarray:
        """``(B,)`` steps taken in each copy's current episode."""
        return np.concatenate(self.get_attr("num_steps"))

    def state(self) -> np.ndarray:
        """``(B, S)`` float32 global states."""
        return np.concatenate(self.call("state"), axis=0)

    def get_attr(self, name: str) -> list[Any]:
        """Attribute ``name`` of every shard's vector env, one value per shard."""
        if not isinstance(name, str):
            raise ValueError(f"name must be a str, got {describe(name)}")
        return self._all("get", name)

    def set_attr(self, name: str, value: Any) -> None:
        """Set attribute ``name`` of every shard's vector env to ``value``; a property of
        this class (``max_cycles``) is set through it (validated once, here)."""
        if not isinstance(name, str):
            raise ValueError(f"name must be a str, got {describe(name)}")
        if isinstance(getattr(type(self), name, None), property):
            setattr(self, name, value)
        else:
            self._all("set", (name, value))

    @property
    def shard_starts(self) -> tuple[int, ...]:
        """``(W + 1,)`` first copy of each shard, then B: shard w holds copies
        ``[shard_starts[w], shard_starts[w + 1])``."""
        return tuple(int(k) for k in self._starts)

    def call(self, name: str, *args: Any, **kwargs: Any) -> list[Any]:
        """``shard_env.name(*args, **kwargs)`` in every shard, one result per shard."""
        if not isinstance(name, str):
            raise ValueError(f"name must be a str, got {describe(name)}")
        return self._all("call", (name, args, kwargs))

    @property
    def unwrapped(self) -> SubprocVectorEnv:
        return self

    def render(self) -> None:
        """Draws nothing (``render_mode`` None), like :meth:`FovVectorEnv.render`."""
        warn_no_render()

    # --------------------------------------------------------------- close
    @property
    def closed(self) -> bool:
        """True once :meth:`close` ran (or the workers failed to start)."""
        return self._closed

    def close(self) -> None:
        """Stop the workers (idempotent)."""
        if self._closed:
            return
        self._closed = True
        blob = bytes(ForkingPickler.dumps(("close", None)))
        # a signal handler's exception (a timeout) during the close is raised once the
        # workers are stopped and the pipes closed
        pending: BaseException | None = None
        for conn in self._conns:
            try:
                with _signals_deferred():  # no handler runs in here: an error is the pipe's
                    with contextlib.suppress(OSError):
                        conn.send((-1, blob))
            except BaseException as exc:  # a deferred handler's
                pending = pending or exc
        for conn, proc in zip(self._conns, self._procs, strict=True):
            try:  # stale answers first, then the close's (or the end of the pipe)
                while True:
                    with _signals_tagged():
                        try:
                            ready = conn.poll(CLOSE_TIMEOUT_S)
                        except (EOFError, OSError) as exc:
                            if from_signal(exc):
                                raise
                            ready = False
                    if not ready:
                        break
                    with _signals_deferred():
                        try:
                            last = conn.recv()[0] == -1
                        except (EOFError, OSError):
                            last = True
                    if last:
                        break
            except BaseException as exc:  # a signal handler's
                pending = pending or exc
            proc.join(timeout=CLOSE_TIMEOUT_S)
            if proc.is_alive():
                proc.terminate()
                proc.join(timeout=1.0)
            conn.close()
        if pending is not None:
            raise pending

    def __copy__(self) -> SubprocVectorEnv:
        raise TypeError("a SubprocVectorEnv cannot be copied: it owns its worker processes")

    def __deepcopy__(self, memo: dict) -> SubprocVectorEnv:
        raise TypeError("a SubprocVectorEnv cannot be copied: it owns its worker processes")

    def __reduce__(self) -> Any:
        raise TypeError("a SubprocVectorEnv cannot be pickled: it owns its worker processes")

    def __enter__(self) -> SubprocVectorEnv:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass

    def __repr__(self) -> str:
        return (
            f"SubprocVectorEnv({self.metadata.get('name', '?')}, num_envs={self.num_envs}, "
            f"n_agents={self.n_agents}, workers={self.workers})"
        )
