"""Where the runs of a sweep are computed: in this process, on a local process pool, or on a
``dask.distributed`` cluster.

An executor only computes: it is handed ``(key, task)`` pairs and gives back each run's row and
arrays (``compute(task)``); the process that runs the sweep stores them (:mod:`studies.runner`).
Workers therefore need no shared filesystem, and a retried or duplicated task cannot corrupt a
stored result.

Worker death.  On the local pool a dead worker breaks the pool: the sweep stops with
:class:`SweepError` (finished runs are stored; rerun to resume).  On Dask the scheduler resubmits
the runs of a worker that dies (killed, out of memory) to another worker, up to its
``distributed.scheduler.allowed-failures`` setting (Dask's default: 3, so a run is tried on at most
4 workers; a cluster started here uses :data:`DASK_ALLOWED_FAILURES`); past it the run comes back as
:class:`WorkerDied` and is stored as a failed row.  Nothing here schedules, queues or retries.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import signal
import threading
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Callable

try:  # optional: pip install 'hybmss[dask]'
    from distributed import WorkerPlugin
except ImportError:  # pragma: no cover - the local executor needs no Dask
    WorkerPlugin = object

EXECUTORS = ("local", "dask")

#: worker deaths a run survives on a cluster started by the runner (the scheduler's
#: ``allowed-failures``): a run is tried on at most DASK_ALLOWED_FAILURES + 1 workers
DASK_ALLOWED_FAILURES = 3


class SweepError(RuntimeError):
    """The sweep cannot go on (a worker pool broke, workers cannot run the tasks): one line with
    the cause and the remedy.  Finished runs are stored."""


class WorkerDied:
    """Outcome of a run whose worker died more often than the scheduler allows."""

    def __init__(self, message: str):
        self.message = message


def ignore_interrupt(*_args) -> None:
    """Ignore SIGINT in a worker process: Ctrl-C (sent to the whole process group) is handled by
    the process that runs the sweep, which shuts the workers down."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def kill_processes(procs) -> None:
    for p in procs:
        if p.is_alive():
            p.kill()
    for p in procs:
        p.join(timeout=2)


# ----------------------------------------------------------------------------------- local
class InProcess:
    """One run at a time in this process (``jobs = 1``)."""

    dashboard = None

    def __init__(self, fn: Callable):
        self.fn = fn
        self.queue: list = []

    def capacity(self) -> int:
        return 1

    def submit(self, key: str, task) -> None:
        self.queue.append((key, task))

    def wait_one(self):
        key, task = self.queue.pop(0)
        return key, self.fn(task, key)

    def abandon(self) -> None:
        self.queue.clear()

    def close(self) -> None:
        self.queue.clear()


class LocalPool:
    """A pool of ``jobs`` worker processes on this machine."""

    dashboard = None

    def __init__(self, fn: Callable, jobs: int):
        self.fn, self.jobs = fn, jobs
        before = set(multiprocessing.active_children())
        self.pool = ProcessPoolExecutor(max_workers=jobs, initializer=ignore_interrupt)
        self.pool.submit(os.getpid).result()  # start the workers now (all at once with fork)
        self.procs = [p for p in multiprocessing.active_children() if p not in before]
        self.futures: dict = {}

    def capacity(self) -> int:
        return self.jobs

    def submit(self, key: str, task) -> None:
        self.futures[self.pool.submit(self.fn, task, key)] = key

    def wait_one(self):
        done, _ = wait(list(self.futures), return_when=FIRST_COMPLETED)
        fut = next(iter(done))
        key = self.futures.pop(fut)
        try:
            return key, fut.result()
        except BrokenProcessPool:
            raise SweepError("a worker process died (killed or out of memory); finished runs are "
                             "stored: rerun to resume (--executor dask resubmits the runs of a dead "
                             "worker)") from None

    def abandon(self) -> None:
        """Drop queued runs and kill the workers (their running runs are abandoned)."""
        self.futures.clear()
        self.pool.shutdown(wait=False, cancel_futures=True)
        kill_processes(self.procs)

    def close(self) -> None:
        self.pool.shutdown(wait=True)


# ------------------------------------------------------------------------------------ dask
class DaskCluster:
    """Runs on a ``dask.distributed`` cluster: the scheduler at ``scheduler`` or, without one, a
    ``LocalCluster`` of ``jobs`` single-threaded workers (all cores by default).  ``jobs`` is also
    the number of runs submitted at a time (default: the cluster's worker threads); runs are
    claimed in the store when submitted, so a second sweep on the same folder takes other runs."""

    def __init__(self, fn: Callable, jobs: int | None = None, scheduler: str | None = None):
        import dask
        from distributed import Client, LocalCluster, as_completed

        self.fn, self.jobs, self.cluster = fn, jobs, None
        if scheduler:
            try:
                self.client = Client(scheduler, timeout="10s")
            except (OSError, TimeoutError, ValueError, TypeError) as exc:
                raise ValueError(f"scheduler {scheduler!r}: cannot connect "
                                 f"({type(exc).__name__}: {' '.join(str(exc).split())[:160]}); the "
                                 "address of a running dask scheduler, e.g. tcp://host:8786, is "
                                 "required") from None
        else:
            with dask.config.set({"distributed.scheduler.allowed-failures": DASK_ALLOWED_FAILURES}):
                self.cluster = LocalCluster(n_workers=jobs or os.cpu_count() or 1, threads_per_worker=1,
                                            processes=True, silence_logs=logging.CRITICAL,
                                            dashboard_address=":0")
            self.client = Client(self.cluster)
            self.client.register_plugin(_IgnoreInterrupt(), name="hybmss-ignore-interrupt")
        services = self.client.scheduler_info().get("services", {})
        self.dashboard = self.client.dashboard_link if "dashboard" in services else None
        self.completed = as_completed()
        self.futures: dict = {}

    def capacity(self) -> int:
        if self.jobs:
            return self.jobs
        return max(1, sum(self.client.nthreads().values()))

    def submit(self, key: str, task) -> None:
        fut = self.client.submit(self.fn, task, key, key=f"hybmss-run-{key}", pure=False)
        self.futures[fut] = key
        self.completed.add(fut)

    def wait_one(self):
        from distributed import KilledWorker

        fut = next(self.completed)
        key = self.futures.pop(fut)
        try:
            if fut.status == "error":
                exc = fut.exception()
                if isinstance(exc, KilledWorker):
                    return key, WorkerDied(
                        f"KilledWorker: the run's worker died (killed or out of memory) on "
                        f"{exc.allowed_failures + 1} attempts (the scheduler's allowed-failures is "
                        f"{exc.allowed_failures})")
                raise SweepError(f"run {key} failed on a worker outside its solver "
                                 f"({type(exc).__name__}: {' '.join(str(exc).split())[:200]}); every "
                                 "worker needs hybmss installed at the same version (README)")
            if fut.status == "cancelled":
                raise SweepError(f"run {key} was cancelled by the dask scheduler; rerun to resume")
            return key, fut.result()
        finally:
            fut.release()

    def abandon(self) -> None:
        """Cancel every submitted run and shut a cluster started here down."""
        futs = list(self.futures)
        self.futures.clear()
        try:
            if futs:
                self.client.cancel(futs, force=True)
        finally:
            self.close(fast=True)

    def close(self, fast: bool = False) -> None:
        """Close the client and a cluster started here (``fast``: short timeouts, then the
        worker processes that are left are killed)."""
        procs = []
        if self.cluster is not None:
            procs = [p for p in multiprocessing.active_children()
                     if p.name.startswith("Dask Worker process")]
        timeout = 1 if fast else 10
        try:
            self.client.close(timeout=timeout)
        except Exception:  # noqa: BLE001 - a client that cannot close cleanly is dropped
            pass
        if self.cluster is not None:
            try:
                self.cluster.close(timeout=timeout)
            except Exception:  # noqa: BLE001 - workers busy in a run: killed below
                pass
            kill_processes(procs)
            self.cluster.shutdown_on_close = False  # closed here; nothing left for exit time


class _IgnoreInterrupt(WorkerPlugin):
    """Worker plugin: SIGINT ignored in the workers of a cluster started by the runner."""

    def setup(self, worker):
        ignore_interrupt()


def make_executor(kind: str, fn: Callable, jobs: int | None, scheduler: str | None, todo: int):
    """The executor for a sweep of ``todo`` runs."""
    if kind == "dask":
        return DaskCluster(fn, jobs, scheduler)
    n = min(jobs or os.cpu_count() or 1, max(todo, 1))
    return InProcess(fn) if n == 1 else LocalPool(fn, n)
