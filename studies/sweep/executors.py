"""Where the runs of a sweep are computed: in this process, on a local process pool, or on a
``dask.distributed`` cluster (:mod:`studies.sweep.dask_cluster`, imported only when one is asked for:
Dask is an optional dependency and takes a second to import).

An executor only computes: it is handed ``(key, task)`` pairs and gives back each run's row and
arrays (``compute(task)``); the process that runs the sweep stores them (:mod:`studies.sweep.runner`).
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

import multiprocessing
import os
import signal
import threading
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Callable

from studies.sweep.heap import then_release
from studies.sweep.store import DamagedRun

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


@dataclass(frozen=True)
class Call:
    """A study's computation outside runs, done ahead on a sweep's idle workers
    (:meth:`studies.sweep.runner.Runner.run`, ``calls``): ``fn(item)``, its result kept in the
    store as computation ``name`` under :meth:`~studies.sweep.store.Store.computed_key` (what
    :func:`map_stored` of the same name and item finds stored), or with ``name`` None only its
    effect (a kernel compiled into the cache).  ``fn`` must be importable (a module-level function
    or a ``functools.partial`` of one)."""

    name: str | None
    fn: Callable
    item: object


class CallFailed:
    """Outcome of a :class:`Call` that raised: nothing is kept, and the study that needs the
    result computes it again in its own map (where the error is raised and reported)."""

    def __init__(self, exc: BaseException):
        self.exc = exc


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
        return key, then_release(self.fn, task, key)

    def abandon(self) -> None:
        self.queue.clear()

    def close(self) -> None:
        self.queue.clear()


WORKER_START = "studies.sweep.pool_worker"
"""The module a local pool's worker processes import first (one BLAS thread per worker)."""


def worker_context():
    """The multiprocessing context of the local pool: workers forked from a server process that
    has imported :data:`WORKER_START` (:mod:`studies.sweep.pool_worker`: the BLAS and OpenMP thread
    variables set to 1 before numpy is imported, then the runner and the solvers).  Forking
    this process instead would hand every worker the BLAS thread pool numpy started here, one
    thread per core, whatever the variables say afterwards."""
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload([WORKER_START])  # read when the server starts (once per process)
    return ctx


class Workers:
    """``jobs`` worker processes of this machine (:func:`worker_context`), started at their first
    use and kept for every later sweep and map given them: what a worker loaded for one run (its
    imports, the compiled kernels, an engine's start-up, 4 s for Newton's Warp) serves the next.
    A :class:`studies.sweep.runner.Runner` used as a context manager keeps one for its session
    (:meth:`~studies.sweep.runner.Runner.local_workers`).  :meth:`kill` (a failure, Ctrl-C) ends
    them at once; the next use starts new ones."""

    def __init__(self, jobs: int):
        self.jobs = jobs
        self._pool: ProcessPoolExecutor | None = None
        self._before: set = set()
        self.procs: list = []

    def submit(self, fn: Callable, *args):
        """``fn(*args)`` on a worker: its future."""
        if self._pool is None:
            self._before = set(multiprocessing.active_children())
            self._pool = ProcessPoolExecutor(max_workers=self.jobs, mp_context=worker_context(),
                                             initializer=ignore_interrupt)
            self.procs = []
        fut = self._pool.submit(then_release, fn, *args)  # the run's freed heap back to the machine
        # workers are started as work is submitted, up to ``jobs``
        self.procs += [p for p in multiprocessing.active_children() if p not in self._before and p not in self.procs]
        return fut

    def kill(self) -> None:
        """Drop the queued work and kill the workers (their running work is abandoned)."""
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            kill_processes(self.procs)
        self._pool, self.procs = None, []

    def close(self) -> None:
        """Let the workers finish and end them."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
        self._pool, self.procs = None, []


class LocalPool:
    """A pool of ``jobs`` worker processes on this machine: ``workers`` (:class:`Workers`, kept
    by their owner after the sweep), or its own, ended with the sweep."""

    dashboard = None
    shares_memory = True
    """Its runs share this machine's memory (the runner starts those that fit together)."""

    def __init__(self, fn: Callable, jobs: int, workers: Workers | None = None):
        self.fn, self.jobs = fn, jobs
        self.own = workers is None
        self.workers = Workers(jobs) if workers is None else workers
        self.futures: dict = {}

    def capacity(self) -> int:
        return self.jobs

    def submit(self, key: str, task) -> None:
        self.futures[self.workers.submit(self.fn, task, key)] = key

    def submit_call(self, call: Call) -> None:
        """``call.fn(call.item)`` on a worker; :meth:`wait_one` gives it back as ``(call, result)``,
        ``result`` a :class:`CallFailed` if it raised."""
        self.futures[self.workers.submit(call.fn, call.item)] = call

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
        except Exception as exc:  # noqa: BLE001 - a run's errors are rows (compute); a call's are its own
            if isinstance(key, Call):
                return key, CallFailed(exc)
            raise

    def abandon(self) -> None:
        """Drop queued runs and kill the workers (their running runs are abandoned)."""
        self.futures.clear()
        self.workers.kill()

    def close(self) -> None:
        if self.own:
            self.workers.close()


def map_local(fn: Callable, items: list, workers: int | None = None, runner=None) -> list:
    """``[fn(i) for i in items]`` on up to ``workers`` processes of this machine (all cores by
    default; :func:`worker_context`), in order: for the work of a study that is not a stored run
    (compiling kernels; :func:`map_stored` keeps the results).  ``fn`` must be importable (a
    module-level function).  Ctrl-C (or an exception in ``fn``) kills the workers at once.
    ``runner``: a :class:`studies.sweep.runner.Runner` whose session's workers compute instead
    (:meth:`~studies.sweep.runner.Runner.local_workers`; none: processes of this call's own)."""
    items = list(items)
    out: list = [None] * len(items)

    def keep(i, result):
        out[i] = result

    _map(fn, items, list(range(len(items))), workers, keep, _shared(runner))
    return out


def _shared(runner) -> Workers | None:
    return runner.local_workers() if runner is not None else None


def map_stored(store, name: str, fn: Callable, items: list, workers: int | None = None, runner=None) -> list:
    """:func:`map_local` for the results a study computes outside runs (a bisection, a table of
    its own): the result of each item is kept in ``store`` (a :class:`studies.sweep.store.Store`) as
    computation ``name`` as soon as it is done (:meth:`~studies.sweep.store.Store.save_computed`, keyed by
    the item and the code version), and an item whose result is stored is not computed again, so
    an interrupted study resumes and a finished one costs nothing when run again.  A damaged
    stored result is moved aside and computed again.  Results come back as stored (the same
    values, NumPy scalars made plain, tuples lists).  ``store`` None: :func:`map_local`;
    ``runner``: as there."""
    if store is None:
        return map_local(fn, items, workers, runner)
    items = list(items)
    store.remove_orphans()
    keys = [store.computed_key(name, item) for item in items]
    out: list = [None] * len(items)
    todo = []
    for i, key in enumerate(keys):
        try:
            found, result = store.load_computed(name, key)
        except DamagedRun as exc:
            store.quarantine(exc)
            print(f"{name}: damaged stored result moved aside, computing it again ({exc.reason})", flush=True)
            found = False
        if found:
            out[i] = result
        else:
            todo.append(i)

    def keep(i, result):
        out[i] = store.save_computed(name, keys[i], result)

    _map(fn, items, todo, workers, keep, _shared(runner))
    return out


def _map(fn: Callable, items: list, todo: list, workers: int | None, done: Callable,
         shared: Workers | None = None) -> None:
    """``done(i, fn(items[i]))`` for each ``i`` of ``todo``, on up to ``workers`` processes (in this
    one for a single worker), or on the ``shared`` workers, each as soon as it finishes.  On an
    exception or Ctrl-C the queued items are dropped and the workers killed before it is raised."""
    if not todo:
        return
    n = min(workers or os.cpu_count() or 1, len(todo))
    if shared is None and n <= 1:
        for i in todo:
            done(i, fn(items[i]))
        return
    pool = Workers(n) if shared is None else shared
    try:
        futures = {pool.submit(fn, items[i]): i for i in todo}
        pending = set(futures)
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in sorted(finished, key=futures.get):
                try:
                    result = fut.result()
                except BrokenProcessPool:
                    raise SweepError("a worker process died (killed or out of memory): rerun (stored "
                                     "results are kept)") from None
                done(futures[fut], result)
    except BaseException:
        pool.kill()
        raise
    if shared is None:
        pool.close()


def local_executor(fn: Callable, jobs: int | None, todo: int, workers: Workers | None = None):
    """The executor of a sweep of ``todo`` runs on this machine: the ``workers`` given (kept after
    the sweep), else in this process for one job, else a pool of ``jobs`` workers (all cores by
    default) of the sweep's own."""
    if workers is not None:
        return LocalPool(fn, min(workers.jobs, max(todo, 1)), workers)
    n = min(jobs or os.cpu_count() or 1, max(todo, 1))
    return InProcess(fn) if n == 1 else LocalPool(fn, n)
