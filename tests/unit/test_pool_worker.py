"""A worker of the local pool runs one BLAS thread: the thread variables are in force when its
numpy and scipy load OpenBLAS (:mod:`studies.sweep.pool_worker`), whatever this process loaded."""

from __future__ import annotations

import ctypes
import os

import numpy as np
import scipy.linalg  # noqa: F401 - scipy's own OpenBLAS, loaded here as in a worker

from studies.sweep.executors import LocalPool

GETTERS = ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads", "openblas_get_num_threads64_",
           "openblas_get_num_threads")


def blas_threads() -> dict[str, int]:
    """Thread count of every OpenBLAS loaded in this process, by library file (Linux)."""
    import scipy.linalg  # noqa: F401 - as a worker's solves load it

    with open("/proc/self/maps") as fh:
        libs = sorted({line.split()[-1] for line in fh if "openblas" in line.rsplit("/", 1)[-1].lower()})
    out = {}
    for path in libs:
        lib = ctypes.CDLL(path)
        for name in GETTERS:
            if hasattr(lib, name):
                out[os.path.basename(path)] = int(getattr(lib, name)())
                break
    return out


def in_worker(task, key):
    """A pool task: the worker's BLAS thread counts and thread variables."""
    return blas_threads(), {v: os.environ.get(v) for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS")}


def test_a_pool_worker_runs_one_blas_thread():
    here = blas_threads()
    assert len(here) >= 2, here  # numpy's and scipy's: the probe sees what it checks
    pool = LocalPool(in_worker, 2)
    try:
        for k in ("a", "b"):
            pool.submit(k, None)
        outcomes = [pool.wait_one()[1] for _ in range(2)]
    finally:
        pool.close()
    for threads, env in outcomes:
        assert set(threads) >= set(here), (threads, here)  # the solvers may load one more
        assert set(threads.values()) == {1}, threads
        assert env == {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    assert np.dot(np.ones(3), np.ones(3)) == 3.0
