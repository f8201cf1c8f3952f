"""Where a sweep's points run: a Dask client, and the loops that run tasks and hand back results.

Owns :func:`dask_client` (a new :class:`~distributed.LocalCluster` of spawned
single-threaded worker processes, or an existing scheduler, checked and reached within
a few seconds; closed on exit), the workers' environment (XLA on one thread), the
main-guard message, ``_run_dask`` (every task submitted impure, at most two per worker
thread in flight, results handled as they come; a dead worker is the point's error row)
and ``_run_here`` (every task in this process, without Dask). ``dask`` and
``distributed`` are imported only when a cluster is made.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from typing import Any, cast

from foundation import InputError, require
from simulator.sweep._point import XLA_ONE_THREAD, _one_line, run_point
from simulator.sweep._task import PointTask

__all__ = ["CONNECT_TIMEOUT_S", "check_where", "dask_client", "run_tasks", "start_workers"]

#: Seconds to wait for a Dask scheduler given with ``scheduler``.
CONNECT_TIMEOUT_S = 3.0

#: Memory one local worker process is given (MiB): the imports (about 0.4 GB) and one point's
#: landscape, which a point keeps under 320 MB by coarsening, with their temporaries.
WORKER_MEMORY_MB = 1024

#: The end of a task iterator (None there means "nothing now").
_END = object()

#: Why spawned workers fail to start from a script, and the fix.
MAIN_GUARD = (
    "worker processes are spawned and import the main script, so a script that calls simulator.run_sweep must do so "
    'under `if __name__ == "__main__":`'
)


# ----------------------------------------------------------------------- running
def worker_cap(
    requested: int,
    points: int,
    point_bytes: float | None = None,
    budget_bytes: float | None = None,
) -> tuple[int, str | None]:
    """(local workers to start, a note when fewer than ``requested``): at most one per core
    (each is single-threaded), one per point to run, and as many as the memory holds
    together: each worker priced at ``point_bytes`` (the largest point's peak with the
    worker's imports, :func:`simulator.sweep.point_bytes`; None: :data:`WORKER_MEMORY_MB`),
    their sum within the memory available now and within ``budget_bytes`` (the sweep's
    memory budget, for all its workers together). At least one: a point that fits its own
    budget runs, one at a time."""
    from foundation import MB, available_memory_bytes, fmt_bytes

    cores = os.cpu_count() or 1
    each = float(point_bytes) if point_bytes else WORKER_MEMORY_MB * MB
    avail = available_memory_bytes()
    room = min(avail, budget_bytes) if budget_bytes else avail
    by_memory = max(1, int(room // each))
    n = max(1, min(requested, cores, by_memory, max(points, 1)))
    if n >= requested or requested <= min(
        cores, by_memory
    ):  # only the points bound it: nothing to say
        return n, None
    if cores <= by_memory:
        why = f"{cores} core{'s' if cores != 1 else ''}"
    elif point_bytes:
        where = (
            f"the memory budget of {fmt_bytes(budget_bytes)}"
            if budget_bytes and budget_bytes <= avail
            else f"the memory available ({fmt_bytes(avail)})"
        )
        why = (
            f"{where} for all the workers together, and a point may hold about {fmt_bytes(each)} "
            f"(its landscape and assessment, with a worker's imports), so it holds {by_memory}"
        )
    else:
        why = f"the memory available ({avail / 2**30:.1f} GB) holds {by_memory} workers of {WORKER_MEMORY_MB / 1024:g} GB"
    return (
        n,
        f"--workers {requested} capped at {n}: this machine has {why}; more workers would only wait for each other"
        if not point_bytes or cores <= by_memory
        else f"--workers {requested} capped at {n}: {why}; raise [scene] memory_budget_mb or use a coarser resolution_um to run more at once",
    )


def _worker_env() -> dict[str, str]:
    flags = os.environ.get("XLA_FLAGS", "")
    if XLA_ONE_THREAD not in flags:
        flags = f"{flags} {XLA_ONE_THREAD}".strip()
    return {"XLA_FLAGS": flags, "XLA_PYTHON_CLIENT_PREALLOCATE": "false", "OMP_NUM_THREADS": "1"}


def _check_address(address: str) -> None:
    """A scheduler address Dask can parse (scheme://HOST:PORT), else one line; nothing is contacted."""
    from distributed.comm.addressing import parse_address, parse_host_port
    from distributed.comm.registry import get_backend

    try:
        scheme, loc = parse_address(address)
        get_backend(scheme)
        if scheme in ("tcp", "tls"):
            parse_host_port(loc)
    except (ValueError, TypeError) as err:
        raise InputError(
            f"--scheduler {address}: not a Dask scheduler address ({' '.join(str(err).split())[:200]}); "
            "write it as tcp://HOST:PORT, e.g. tcp://10.0.0.5:8786"
        ) from None


@contextlib.contextmanager
def _sigint_blocked() -> Iterator[None]:
    """Ctrl-C kept from the local workers: SIGINT ignored (and held in this thread) while they start.

    Ctrl-C goes to the whole foreground process group: workers that took it would each print
    a KeyboardInterrupt traceback; this process closes them itself. An ignored signal stays
    ignored across the exec that spawns a worker (a blocked one does not: spawn clears the
    mask), so the workers started here never see it. Meanwhile SIGINT is also blocked in this
    thread (and in the threads made meanwhile, which keep it blocked): on Linux a blocked
    signal is held even while ignored, so a Ctrl-C pressed during the start is delivered
    here, as KeyboardInterrupt, when this returns. Only in the main thread (signal handlers).
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread() or not hasattr(
        signal, "pthread_sigmask"
    ):
        yield
        return
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    old_handler = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old_handler)
        signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)


def release_semaphores() -> None:
    """Unlink and unregister this process's multiprocessing semaphores (the cluster's queues and locks).

    For a process about to end with ``os._exit`` (SIGTERM): the resource tracker would otherwise
    remove them itself and warn on stderr about "leaked semaphore objects".
    """
    import gc

    try:
        import _multiprocessing
        from multiprocessing import resource_tracker, synchronize
    except ImportError:
        return
    for obj in gc.get_objects():
        if isinstance(obj, synchronize.SemLock):
            name = getattr(getattr(obj, "_semlock", None), "name", None)
            if name:
                with contextlib.suppress(Exception):
                    _multiprocessing.sem_unlink(name)
                with contextlib.suppress(Exception):
                    resource_tracker.unregister(name, "semaphore")


def _handshake(address: str, timeout_s: float = CONNECT_TIMEOUT_S) -> None:
    """Connect to the scheduler and have it answer one request, all within ``timeout_s``, else one line.

    ``Client(address, timeout=...)`` bounds the TCP connect but not the handshake that follows
    (distributed reads the peer's handshake without a timeout): a listener that accepts and never
    answers would keep it waiting as long as the connection stays open. This probe runs in its own
    event loop, on its own thread (a caller's running loop is left alone), under one deadline.
    """
    import asyncio
    import threading

    from distributed.comm.core import connect
    from distributed.security import Security

    tls = Security().get_connection_args(
        "client"
    )  # as Client() connects: the TLS settings of the Dask config

    async def probe() -> None:
        # connect's own message (refused, unreachable) comes within the deadline
        comm = await connect(address, timeout=round(0.8 * timeout_s, 3), **tls)
        try:
            await comm.write({"op": "identity", "reply": True})
            reply = await comm.read()
        finally:
            comm.abort()
        if not isinstance(reply, dict) or reply.get("type") != "Scheduler":
            raise OSError(f"the peer answered, but is not a Dask scheduler ({str(reply)[:80]})")

    async def bounded() -> None:
        await asyncio.wait_for(probe(), timeout_s)

    outcome: list[BaseException | None] = []

    def run() -> None:
        try:
            asyncio.run(bounded())
            outcome.append(None)
        except BaseException as err:  # noqa: BLE001 - handed to the caller's thread
            outcome.append(err)

    # A daemon thread: were the probe ever to outlive its deadline, it would not hold up the exit.
    t = threading.Thread(target=run, name="selfalign-handshake", daemon=True)
    t.start()
    t.join(timeout_s + 5)
    err = outcome[0] if outcome else TimeoutError()
    if isinstance(err, OSError | TimeoutError | ValueError | TypeError):
        reason = " ".join(str(err).split())[:200] or "no answer to the handshake"
        raise InputError(
            f"--scheduler {address}: cannot reach a Dask scheduler within {timeout_s:g} s ({reason}); "
            "check the address (tcp://HOST:PORT), or leave out --scheduler to start local workers"
        ) from None
    if err is not None:
        raise err


@contextlib.contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None) -> Iterator[Any]:
    """A Dask client: on ``scheduler`` (an existing cluster), else on a new LocalCluster of
    ``workers`` spawned single-threaded worker processes. Closed (cluster too) on exit."""
    import logging

    import dask.config
    from distributed import Client, LocalCluster

    config = {
        "distributed.worker.multiprocessing-method": "spawn",
        "distributed.comm.timeouts.connect": f"{CONNECT_TIMEOUT_S}s",
        "distributed.scheduler.allowed-failures": 1,
        "distributed.worker.daemon": True,
        "distributed.worker.profile.enabled": False,  # the statistical profiler costs ~15 % of a point; no dashboard shows it
        # Dask's default environment of a new worker, less MALLOC_TRIM_THRESHOLD_=65536: with it every large
        # array is mapped and unmapped afresh, which doubled the time of a point (measured).
        "distributed.nanny.pre-spawn-environ": {
            "OMP_NUM_THREADS": 1,
            "MKL_NUM_THREADS": 1,
            "OPENBLAS_NUM_THREADS": 1,
        },
    }
    cluster = client = None
    with dask.config.set(config):
        try:
            if scheduler:
                _check_address(scheduler)
                _handshake(scheduler)  # the whole handshake within CONNECT_TIMEOUT_S
                try:
                    client = Client(scheduler, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
                except (OSError, TimeoutError, ValueError, TypeError) as err:
                    reason = " ".join(str(err).split())[:200] or type(err).__name__
                    raise InputError(
                        f"--scheduler {scheduler}: cannot reach a Dask scheduler within {CONNECT_TIMEOUT_S:g} s ({reason}); "
                        "check the address (tcp://HOST:PORT), or leave out --scheduler to start local workers"
                    ) from None
            else:
                import multiprocessing

                if getattr(multiprocessing.current_process(), "_inheriting", False):
                    # A spawned worker is importing the script that called run_sweep(): the call lacks the main guard.
                    raise SystemExit(f"selfalign sweep: error: {MAIN_GUARD}")
                with (
                    _sigint_blocked()
                ):  # the workers, their threads and every later worker inherit it
                    try:
                        cluster = LocalCluster(
                            n_workers=int(workers or 1),
                            threads_per_worker=1,
                            processes=True,
                            dashboard_address=None,  # pyright: ignore[reportArgumentType]  (None: no dashboard; the stub says str)
                            # The scheduler's HTTP server (health routes) starts even without a
                            # dashboard, on port 8787 unless told: a second cluster on the machine
                            # (two sweeps, parallel tests) then warns that the port is taken. A
                            # free port of the loopback interface, chosen by the system, instead.
                            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                            silence_logs=logging.ERROR,
                            env=_worker_env(),
                        )
                    except RuntimeError as err:
                        raise InputError(
                            f"the local Dask workers did not start ({' '.join(str(err).split())[:120]}); {MAIN_GUARD}"
                        ) from None
                    client = Client(cluster, set_as_default=False)
            yield client
        finally:
            with contextlib.suppress(Exception):
                if client is not None:
                    client.close(timeout=10)
            with contextlib.suppress(Exception):
                if cluster is not None:
                    cluster.close(timeout=10)


def check_where(workers: int | None, scheduler: str | None) -> None:
    """``workers`` a whole number from 0 and not given with ``scheduler`` (InputError otherwise)."""
    if workers is not None:
        require(
            isinstance(workers, int) and not isinstance(workers, bool) and 0 <= workers <= 4096,
            f"--workers must be a whole number >= 0, got {workers!r}",
        )
        require(
            not scheduler,
            "give --workers or --scheduler, not both (the cluster at --scheduler has its own workers)",
        )


def start_workers(
    stack: contextlib.ExitStack,
    workers: int | None,
    scheduler: str | None,
    points: int,
    price: Callable[[], tuple[float | None, float | None]] | None = None,
) -> tuple[Any, float, str]:
    """Where ``points`` points run, started once for a sweep and a search alike: on the cluster
    at ``scheduler``, else on local workers (``workers``, default one per core, capped by
    :func:`worker_cap`, whose note is printed when ``workers`` was given; ``price()``: the
    largest point's peak bytes and the budget of all the workers, asked only when workers
    start), else in this process (no points to run, or ``workers`` 0). The client enters
    ``stack`` (closed with it). Returns the client (None: this process), the seconds its
    start took, and where the points run in words."""
    n_workers, capped = (
        (None, None)
        if scheduler
        else worker_cap(
            workers or os.cpu_count() or 1,
            points,
            *(price() if price is not None and points and workers != 0 else (None, None)),
        )
    )
    if capped and workers and points:
        print(f"note: {capped}", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    client = (
        stack.enter_context(dask_client(n_workers, scheduler)) if points and workers != 0 else None
    )
    where = (
        f"the Dask cluster at {scheduler}"
        if scheduler
        else "this process"
        if client is None
        else f"{n_workers} local Dask workers"
    )
    return client, time.perf_counter() - t0, where


def run_tasks(
    client: Any,
    tasks: Iterable[PointTask | None],
    handle: Callable[[PointTask, dict], None],
    per_thread: int = 2,
) -> dict:
    """Run every task of ``tasks`` (:func:`run_point`'s, one point each) and hand each result to
    ``handle(task, result)`` as it comes, in this thread.

    On ``client``'s cluster (None: one after another in this process), at most ``per_thread``
    tasks per worker thread in flight. ``tasks`` is read lazily, when a slot frees, after the
    result before it was handled: it may be a generator that decides the next point from the
    results so far (a search's ask and tell). Such a generator may yield None for "nothing
    to run until a running task finishes" (only while one runs): the slot waits for the next
    result. Returns the run's seconds, workers and threads.
    """
    if client is None:
        return _run_here(tasks, handle)
    return _run_dask(client, tasks, handle, per_thread)


def _run_dask(
    client: Any,
    tasks: Iterable[PointTask | None],
    handle: Callable[[PointTask, dict], None],
    per_thread: int = 2,
) -> dict:
    """Every task on ``client``'s cluster, at most ``per_thread`` per worker thread in flight, results handled as they come."""
    from distributed import as_completed

    t0 = time.perf_counter()
    threads = max(1, sum(client.nthreads().values()))
    capacity = max(1, per_thread) * threads
    pending = iter(tasks)
    by_key: dict[str, PointTask] = {}  # the tasks in flight
    ac = as_completed(loop=client.loop)
    ended = False

    def fill() -> None:
        """Submit tasks until ``capacity`` are in flight, the tasks end, or one is None (nothing now)."""
        nonlocal ended
        while not ended and len(by_key) < capacity:
            t = next(pending, _END)
            if t is _END:
                ended = True
            elif t is None:
                return
            else:
                f = client.submit(run_point, t, pure=False)  # impure: no two points are merged
                by_key[f.key] = cast(PointTask, t)  # neither _END nor None: a task
                ac.add(f)

    fill()
    for f in ac:
        t = by_key.pop(f.key)
        try:
            result = f.result()
        except Exception as err:  # the worker died (memory, a crash): the point's error row
            result = {
                "point": t.point,
                "status": "error",
                "error": _one_line(err),
                "seconds": None,
                "summary": None,
            }
        f.release()
        handle(t, result)
        fill()
    return {
        "run_s": time.perf_counter() - t0,
        "workers": len(client.nthreads()),
        "threads": threads,
    }


def _run_here(tasks: Iterable[PointTask | None], handle: Callable[[PointTask, dict], None]) -> dict:
    t0 = time.perf_counter()
    for t in tasks:
        if t is not None:  # None: nothing to run now (nothing is in flight here: ask again)
            handle(t, run_point(t))
    return {"run_s": time.perf_counter() - t0, "workers": 0, "threads": 1}
