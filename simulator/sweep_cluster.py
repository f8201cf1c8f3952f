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
import time
from collections.abc import Callable, Iterator
from typing import Any

from patterns.errors import InputError
from simulator.sweep_point import XLA_ONE_THREAD, _one_line, run_point

__all__ = ["CONNECT_TIMEOUT_S", "dask_client"]

#: Seconds to wait for a Dask scheduler given with ``scheduler``.
CONNECT_TIMEOUT_S = 3.0

#: Why spawned workers fail to start from a script, and the fix.
MAIN_GUARD = ("worker processes are spawned and import the main script, so a script that calls simulator.sweep must do so "
              "under `if __name__ == \"__main__\":`")


# ----------------------------------------------------------------------- running
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
        raise InputError(f"--scheduler {address}: not a Dask scheduler address ({' '.join(str(err).split())[:200]}); "
                         "write it as tcp://HOST:PORT, e.g. tcp://10.0.0.5:8786") from None


@contextlib.contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None) -> Iterator[Any]:
    """A Dask client: on ``scheduler`` (an existing cluster), else on a new LocalCluster of
    ``workers`` spawned single-threaded worker processes. Closed (cluster too) on exit."""
    import logging

    import dask
    from distributed import Client, LocalCluster

    config = {"distributed.worker.multiprocessing-method": "spawn", "distributed.comm.timeouts.connect": f"{CONNECT_TIMEOUT_S}s",
              "distributed.scheduler.allowed-failures": 1, "distributed.worker.daemon": True,
              "distributed.worker.profile.enabled": False,  # the statistical profiler costs ~15 % of a point; no dashboard shows it
              # Dask's default environment of a new worker, less MALLOC_TRIM_THRESHOLD_=65536: with it every large
              # array is mapped and unmapped afresh, which doubled the time of a point (measured).
              "distributed.nanny.pre-spawn-environ": {"OMP_NUM_THREADS": 1, "MKL_NUM_THREADS": 1, "OPENBLAS_NUM_THREADS": 1}}
    cluster = client = None
    with dask.config.set(config):
        try:
            if scheduler:
                _check_address(scheduler)
                try:
                    client = Client(scheduler, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
                except (OSError, TimeoutError, ValueError, TypeError) as err:
                    reason = " ".join(str(err).split())[:200] or type(err).__name__
                    raise InputError(f"--scheduler {scheduler}: cannot reach a Dask scheduler within {CONNECT_TIMEOUT_S:g} s ({reason}); "
                                     "check the address (tcp://HOST:PORT), or leave out --scheduler to start local workers") from None
            else:
                import multiprocessing

                if getattr(multiprocessing.current_process(), "_inheriting", False):
                    # A spawned worker is importing the script that called sweep(): the call lacks the main guard.
                    raise SystemExit(f"selfalign sweep: error: {MAIN_GUARD}")
                try:
                    cluster = LocalCluster(n_workers=int(workers or 1), threads_per_worker=1, processes=True, dashboard_address=None,
                                           silence_logs=logging.ERROR, env=_worker_env())
                except RuntimeError as err:
                    raise InputError(f"the local Dask workers did not start ({' '.join(str(err).split())[:120]}); {MAIN_GUARD}") from None
                client = Client(cluster, set_as_default=False)
            yield client
        finally:
            with contextlib.suppress(Exception):
                if client is not None:
                    client.close(timeout=10)
            with contextlib.suppress(Exception):
                if cluster is not None:
                    cluster.close(timeout=10)


def _run_dask(client: Any, tasks: list[dict], handle: Callable[[dict, dict], None]) -> dict:
    """Every task on ``client``'s cluster, at most two per worker thread in flight, results handled as they come."""
    from distributed import as_completed

    t0 = time.perf_counter()
    threads = max(1, sum(client.nthreads().values()))
    pending = iter(tasks)
    by_key: dict[str, dict] = {}
    ac = as_completed(loop=client.loop)

    def submit() -> None:
        t = next(pending, None)
        if t is not None:
            f = client.submit(run_point, t, pure=False)  # impure: no two points are merged
            by_key[f.key] = t
            ac.add(f)

    for _ in range(2 * threads):
        submit()
    for f in ac:
        t = by_key.pop(f.key)
        try:
            result = f.result()
        except Exception as err:  # the worker died (memory, a crash): the point's error row
            result = {"point": t["point"], "status": "error", "error": _one_line(err), "seconds": None, "summary": None}
        f.release()
        handle(t, result)
        submit()
    return {"run_s": time.perf_counter() - t0, "workers": len(client.nthreads()), "threads": threads}


def _run_here(tasks: list[dict], handle: Callable[[dict, dict], None]) -> dict:
    t0 = time.perf_counter()
    for t in tasks:
        handle(t, run_point(t))
    return {"run_s": time.perf_counter() - t0, "workers": 0, "threads": 1}
