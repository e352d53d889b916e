"""Where episodes run: one place for the map-over-episodes logic of ``evaluate``,
``reproduce`` and ``stress``.

:func:`map_jobs` applies a module-level function to a list of jobs (each job is one
seeded episode, or a cached run) and returns the results in job order, on one of
these backends:

=========  =================================================================================
backend    how
=========  =================================================================================
``local``  this process (``workers=1``), or a ``concurrent.futures.ProcessPoolExecutor``
           of ``workers`` processes (``spawn`` when torch is already loaded: forking a
           process with torch's threads can deadlock)
``ray``    one Ray task per job (``ray.remote(num_cpus=1)``): a local Ray started here
           when none is running (``num_cpus=workers``, no dashboard; shut down after),
           or an existing cluster with ``ray_address`` (``"auto"`` or
           ``"ray://host:10001"``; every node needs fov_marl installed)
=========  =================================================================================

Every job is a deterministic function of its own arguments (its seed included), so
the numbers do not depend on the backend or the number of workers; only wall-clock
fields (``cpu_ms_*``, ``wall_s``) differ. Ray is imported lazily: the core package does
not need it, and a missing ``ray`` is a one-line ``ValueError`` naming the ``[ray]``
extra.

:func:`progress_bar` is the progress display shared by the commands: tqdm, else
rich, else nothing (both ship with the ``train`` extra).
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

__all__ = [
    "BACKENDS",
    "map_jobs",
    "init_ray",
    "check_backend",
    "progress_bar",
    "Progress",
    "RAY_EXTRA_HINT",
]

BACKENDS = ("local", "ray")
RAY_EXTRA_HINT = "pip install 'fov_marl[ray]'"
_PACKAGE_PARENT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _import_ray() -> Any:
    try:
        import ray
    except ImportError as exc:
        raise ValueError(
            f"--backend ray needs Ray, which is not installed ({RAY_EXTRA_HINT}): {exc}"
        ) from None
    return ray


def check_backend(backend: str, ray_address: str | None = None) -> None:
    """Check a backend name (and that Ray imports for ``"ray"``) before any work.

    Raises:
        ValueError: unknown backend, ``ray_address`` without ``backend="ray"``, or Ray
            not installed (the message names the ``[ray]`` extra).
    """
    if backend not in BACKENDS:
        raise ValueError(f"--backend must be one of {list(BACKENDS)}, got {backend!r}")
    if ray_address is not None and backend != "ray":
        raise ValueError(f"--ray-address {ray_address} needs --backend ray")
    if ray_address is not None and not str(ray_address).strip():
        raise ValueError("--ray-address must be 'auto' or a cluster address, got ''")
    if backend == "ray":
        _import_ray()


def init_ray(address: str | None = None, num_cpus: int | None = None, **kwargs: Any) -> bool:
    """Connect to Ray, unless it is already initialised; returns True when this call
    started (or connected) it, so the caller shuts it down.

    Without ``address`` a local Ray starts with ``num_cpus`` CPUs and no dashboard, its
    workers importing fov_marl from the same folder as this process (``PYTHONPATH``
    in the runtime env). With ``address`` it connects to that cluster (whose nodes
    must have fov_marl installed). Extra ``kwargs`` go to ``ray.init``.
    """
    ray = _import_ray()
    if ray.is_initialized():
        return False
    kw: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False, **kwargs}
    if address is None:
        if num_cpus is not None:
            kw.setdefault("num_cpus", int(num_cpus))
        path = os.pathsep.join(p for p in (_PACKAGE_PARENT, os.environ.get("PYTHONPATH")) if p)
        kw.setdefault("runtime_env", {"env_vars": {"PYTHONPATH": path}})
    else:
        kw.pop("include_dashboard")
        kw["address"] = address
    ray.init(**kw)
    return True


def map_jobs(
    fn: Callable[[Any], Any],
    jobs: Sequence[Any],
    *,
    backend: str = "local",
    workers: int = 1,
    ray_address: str | None = None,
    on_result: Callable[[int, Any], None] | None = None,
    local_kwargs: dict[str, Any] | None = None,
    order: Sequence[int] | None = None,
) -> list[Any]:
    """``[fn(job) for job in jobs]`` on a backend (module docstring); results in job order.

    Args:
        fn: a module-level function (it is pickled by reference for other processes).
        jobs: its arguments, one per call (picklable).
        backend: ``"local"`` or ``"ray"``.
        workers: local processes (1: this process), or the CPUs of a local Ray started
            here.
        ray_address: an existing Ray cluster (``backend="ray"`` only).
        on_result: called as ``on_result(index, result)`` as each job finishes (any
            order), in this process: progress bars, caches.
        local_kwargs: keywords given to ``fn`` only when it runs in this process
            (``backend="local"``, ``workers=1``): callbacks that cannot cross processes,
            such as a per-step progress hook.
        order: submission order (indices into ``jobs``), e.g. the longest jobs first;
            default the job order. The results do not depend on it.

    A ``KeyboardInterrupt`` (or a job's error) with local processes cancels the jobs not
    started and kills the running ones before it propagates: the jobs that finished
    before it have reached ``on_result``, no other job does.

    Raises:
        ValueError: a bad backend or argument, or Ray missing (see :func:`check_backend`).
    """
    check_backend(backend, ray_address)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    n = len(jobs)
    idx = list(range(n)) if order is None else [int(k) for k in order]
    if sorted(idx) != list(range(n)):
        raise ValueError("order must be a permutation of the job indices")
    results: list[Any] = [None] * n

    def done(k: int, res: Any) -> None:
        results[k] = res
        if on_result is not None:
            on_result(k, res)

    if n == 0:
        return results
    if backend == "ray":
        _map_ray(fn, jobs, idx, workers, ray_address, done)
    elif workers > 1 and n > 1:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        ctx = multiprocessing.get_context("spawn") if "torch" in sys.modules else None
        ex = ProcessPoolExecutor(max_workers=min(workers, n), mp_context=ctx)
        try:
            futs = {ex.submit(fn, jobs[k]): k for k in idx}
            for f in as_completed(futs):
                done(futs[f], f.result())
        except BaseException:
            _stop_pool(ex)
            raise
        ex.shutdown()
    else:
        for k in idx:
            done(k, fn(jobs[k], **(local_kwargs or {})))
    return results


def _stop_pool(ex: Any) -> None:
    """Stop a process pool at once (Ctrl-C, or a job's error): the jobs not started are
    cancelled and the running ones killed. ``ProcessPoolExecutor``'s own exit waits for
    every submitted job, so a Ctrl-C ran the rest of a sweep and then discarded it."""
    # no public API kills a pool's workers; _processes is there from Python 3.8 to 3.14
    # (shutdown() sets it to None, so it is read first)
    procs = list((getattr(ex, "_processes", None) or {}).values())
    manager = getattr(ex, "_executor_manager_thread", None)
    ex.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        if proc.is_alive():
            proc.terminate()
    # The pool's manager thread reaps the killed workers too; a join here can lose that
    # race and return while the process still reads as alive (waitpid already taken), so
    # wait for the manager thread, then for every exit code to be set.
    deadline = time.monotonic() + 10.0
    if manager is not None:
        manager.join(timeout=5.0)
    for proc in procs:
        proc.join(timeout=max(0.0, deadline - time.monotonic()))
        while proc.exitcode is None and time.monotonic() < deadline:
            time.sleep(0.01)


def _map_ray(
    fn: Callable[[Any], Any],
    jobs: Sequence[Any],
    idx: list[int],
    workers: int,
    address: str | None,
    done: Callable[[int, Any], None],
) -> None:
    ray = _import_ray()
    started = init_ray(address, num_cpus=workers if address is None else None)
    try:
        task = ray.remote(num_cpus=1)(fn)
        refs = {task.remote(jobs[k]): k for k in idx}
        pending = list(refs)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for r in ready:
                try:
                    res = ray.get(r)
                except ray.exceptions.RayTaskError as exc:
                    if _raised_by_fov_marl_check(exc):  # a job's own argument check
                        raise ValueError(_last_line(_message(exc.cause))) from None
                    raise
                done(refs[r], res)
    finally:
        if started:
            ray.shutdown()


def _raised_by_fov_marl_check(exc: Any) -> bool:
    """A Ray task's ``ValueError`` raised by fov_marl's own code (the innermost frame of
    its traceback lies in the package), not inside a library (then: a real bug)."""
    import re

    cause = getattr(exc, "cause", None)
    if not isinstance(cause, ValueError):
        return False
    files = re.findall(r'File "([^"]+)"', str(exc))  # str: Ray's remote traceback
    pkg = os.path.join(_PACKAGE_PARENT, "fov_marl") + os.sep
    return bool(files) and os.path.abspath(files[-1]).startswith(pkg)


def _message(cause: BaseException) -> str:
    """The exception's own message (``args[0]``), not Ray's traceback-laden ``str``."""
    args = getattr(cause, "args", ())
    return str(args[0]) if args else str(cause)


def _last_line(text: str) -> str:
    lines = [ln for ln in text.strip().splitlines() if ln.strip()]
    return " ".join(lines[-1].split()) if lines else "(no message)"


class Progress:
    """A progress display: ``update(n)`` advances it, ``close()`` ends it.

    Backed by tqdm when installed, else rich, else nothing (``enabled=False`` too).
    """

    def __init__(self, total: int, desc: str, unit: str, enabled: bool = True) -> None:
        self.total, self.n = int(total), 0
        self._tqdm = self._rich = self._task = None
        if not enabled:
            return
        try:
            from tqdm import tqdm

            self._tqdm = tqdm(total=self.total, desc=desc, unit=unit, file=sys.stderr)
            return
        except ImportError:
            pass
        try:
            from rich.progress import Progress as RichProgress

            self._rich = RichProgress(transient=False)
            self._rich.start()
            self._task = self._rich.add_task(desc, total=self.total)
        except ImportError:
            self._rich = None

    @property
    def backend(self) -> str:
        """``"tqdm"``, ``"rich"`` or ``"none"``."""
        return "tqdm" if self._tqdm is not None else "rich" if self._rich is not None else "none"

    def update(self, n: int = 1, note: str | None = None) -> None:
        """Advance by ``n`` units (``note``: a short postfix, tqdm only)."""
        self.n += int(n)
        if self._tqdm is not None:
            if note is not None:
                self._tqdm.set_postfix_str(note, refresh=False)
            self._tqdm.update(int(n))
        elif self._rich is not None:
            self._rich.update(self._task, advance=int(n))

    def close(self) -> None:
        if self._tqdm is not None:
            self._tqdm.close()
            self._tqdm = None
        if self._rich is not None:
            self._rich.stop()
            self._rich = None

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def progress_bar(total: int, desc: str, unit: str = "step", enabled: bool = True) -> Progress:
    """A :class:`Progress` of ``total`` units (tqdm, rich or nothing)."""
    return Progress(total, desc, unit, enabled)
