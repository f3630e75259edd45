"""Dask clusters for campaigns: a ``LocalCluster`` on this machine (one single-threaded worker process per core)
or a client of a running scheduler.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import threading
from collections.abc import Iterator

#: Dask settings of the local cluster's workers. The statistical profiler samples the task's stack every
#: 10 ms from the worker's event loop, competing with the pass for the GIL: measured on 2 cores, 4 passes
#: of 100,000 pulses on 2 workers took 26-30 s of CPU without it, 36 s with it (19 s in one process).
WORKER_CONFIG = {"distributed.worker.profile.enabled": False}

def default_workers() -> int:
    """Workers of a local cluster by default: one per core this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None, *,
                dashboard: bool = True) -> Iterator:
    """A ``dask.distributed.Client``: of the scheduler at ``scheduler`` (``tcp://host:8786``), or of a new
    ``LocalCluster`` on this machine's loopback with ``workers`` worker processes (default: one per core)
    of one thread each, its dashboard on loopback (a free port) unless ``dashboard`` is False."""
    import dask
    from dask.distributed import Client, LocalCluster

    if scheduler:
        with Client(scheduler) as client:
            yield client
        return
    n = default_workers() if workers is None else workers
    if not (isinstance(n, int) and n >= 1):
        raise ValueError(f"workers = {workers!r}: must be an integer >= 1")
    with dask.config.set(WORKER_CONFIG), _quiet_processes():
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address="127.0.0.1:0" if dashboard else None)
    with _quiet_logs(), cluster, Client(cluster) as client:
        yield client


#: What the processes of a local cluster inherit: Dask's logs at CRITICAL only (a pass's failure is the
#: campaign's to report, in one line; the dashboard keeps the details), and no warning from multiprocessing's
#: resource tracker about the semaphores of workers killed at shutdown.
QUIET_ENVIRONMENT = {"DASK_LOGGING__DISTRIBUTED": "critical",
                     "PYTHONWARNINGS": "ignore::UserWarning:multiprocessing.resource_tracker"}


@contextlib.contextmanager
def _quiet_processes() -> Iterator:
    """Start a local cluster's processes with :data:`QUIET_ENVIRONMENT` and SIGINT ignored, which they inherit.
    Ctrl-C reaches every process of the terminal's process group: the command alone answers it (exit 130, one
    line) and closes the cluster, instead of each worker printing its KeyboardInterrupt."""
    saved_env = {key: os.environ.get(key) for key in QUIET_ENVIRONMENT}
    os.environ.update(QUIET_ENVIRONMENT)
    if saved_env["PYTHONWARNINGS"]:  # the user's filters kept, ours after them
        os.environ["PYTHONWARNINGS"] = f"{saved_env['PYTHONWARNINGS']},{QUIET_ENVIRONMENT['PYTHONWARNINGS']}"
    in_main = threading.current_thread() is threading.main_thread()
    handler = signal.signal(signal.SIGINT, signal.SIG_IGN) if in_main else None
    try:
        yield
    finally:
        if in_main:
            signal.signal(signal.SIGINT, handler)
        for key, value in saved_env.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


@contextlib.contextmanager
def _quiet_logs() -> Iterator:
    """Dask's logs in this process (the scheduler and the nannies of a local cluster) at CRITICAL only while the
    cluster runs and closes: an interrupted campaign cancels tasks in flight, which Dask would log as errors."""
    logger = logging.getLogger("distributed")
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        logger.setLevel(level)


def capped_workers(workers: int, passes: int | None = None) -> int:
    """Worker processes worth starting on this machine for ``passes`` passes: ``workers``, at most one per pass
    (a pass is one task: a worker more would idle) and one per core this process may use (each worker runs its pass
    on one thread, so a second worker on a core shares it and adds only its memory, a few hundred MB)."""
    return max(1, min(workers, default_workers(), workers if passes is None else passes))


@contextlib.contextmanager
def maybe_client(client=None, scheduler: str | None = None, workers: int | None = None,
                 dashboard: bool = True, announce: bool = False, passes: int | None = None) -> Iterator:
    """``client`` if given; else a client of ``scheduler``, or of a local cluster of ``workers`` (> 0) capped by
    ``passes`` and the cores (:func:`capped_workers`); else None (``workers`` 0 or None: run in this process).
    ``announce`` prints the dashboard address, and the cap where it lowered ``workers``."""
    if client is not None or (not scheduler and not workers):
        yield client
        return
    if not scheduler and not (isinstance(workers, int) and workers >= 1):
        raise ValueError(f"workers = {workers!r}: must be an integer >= 0 (0: in this process, without Dask)")
    local = None if scheduler else capped_workers(workers, passes)
    with dask_client(scheduler, local, dashboard=dashboard) as new:
        if announce:
            where = scheduler or f"a local cluster of {len(new.scheduler_info()['workers'])} workers"
            if local is not None and local < workers:
                where += (f" (--workers {workers} capped: {passes:,} pass{'es' * (passes != 1)}, "
                          f"{default_workers()} cores)" if passes is not None else
                          f" (--workers {workers} capped: {default_workers()} cores)")
            print(f"Dask: {where}; dashboard {new.dashboard_link}", flush=True)
        yield new
