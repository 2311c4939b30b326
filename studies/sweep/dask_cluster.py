"""Runs of a sweep on a ``dask.distributed`` cluster (``hybmss run --executor dask``).

The executor protocol and the worker-death semantics are those of :mod:`studies.sweep.executors`.
Dask workers start with one BLAS and OpenMP thread each: dask sets ``OMP_NUM_THREADS``,
``MKL_NUM_THREADS`` and ``OPENBLAS_NUM_THREADS`` to 1 before a worker process starts
(``distributed.nanny.pre-spawn-environ``).
"""

from __future__ import annotations

import logging
import multiprocessing
import os
from typing import Callable

import dask
from distributed import Client, KilledWorker, LocalCluster, WorkerPlugin, as_completed

from studies.sweep.executors import DASK_ALLOWED_FAILURES, SweepError, WorkerDied, ignore_interrupt, kill_processes


class DaskCluster:
    """Runs on a ``dask.distributed`` cluster: the scheduler at ``scheduler`` or, without one, a
    ``LocalCluster`` of ``jobs`` single-threaded workers (all cores by default).  ``jobs`` is also
    the number of runs submitted at a time (default: the cluster's worker threads); runs are
    claimed in the store when submitted, so a second sweep on the same folder takes other runs."""

    def __init__(self, fn: Callable, jobs: int | None = None, scheduler: str | None = None):
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
