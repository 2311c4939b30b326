"""The start of the local pool's worker processes: one BLAS and OpenMP thread in each.

A sweep runs in parallel over its runs, one run per worker; a worker whose dense or sparse
solves also start one BLAS thread per core oversubscribes the machine (under load a
multithreaded dense eigen solve was 10-30x slower than a single-threaded one).  OpenBLAS, MKL and
OpenMP read their thread counts once, when the library is loaded, i.e. when numpy or scipy is
first imported: setting the variables in a process that has imported numpy changes nothing.  So
the local pool (:class:`studies.sweep.executors.LocalPool`) forks its workers from a server process
(multiprocessing's ``forkserver``) whose first import is this module: the variables are set
here, then numpy, the runner and the solvers are imported once, with them in force, and every
worker forked from the server starts with them loaded.  Dask workers get the same variables from
dask's own ``distributed.nanny.pre-spawn-environ`` setting.  The server also has the C heap keep
freed memory for the next allocation (:func:`studies.sweep.heap.keep_freed_memory`, which imports
no numpy), and the workers inherit that too.

The server and its workers end with the process that started them, however it ends (SIGKILL
included, which runs no clean-up): the server asks the kernel for SIGKILL when its parent dies
(Linux ``prctl(PR_SET_PDEATHSIG)``), and so does every worker it forks (the setting is not
inherited across ``fork``: :func:`os.register_at_fork` sets it again in each child).  A killed
``hybmss run`` then leaves no worker computing, holding memory or the caller's terminal.
"""

import ctypes
import os
import signal
import sys

from studies.sweep.heap import keep_freed_memory

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
"""The thread counts of OpenMP, OpenBLAS and MKL, each set to 1 in a worker."""

for _name in THREAD_VARIABLES:
    os.environ[_name] = "1"

PR_SET_PDEATHSIG = 1
"""``prctl`` option: the signal this process gets when its parent ends (``<linux/prctl.h>``)."""


def die_with_parent(parent: int, sig: int = signal.SIGKILL) -> bool:
    """Have the kernel send ``sig`` to this process when its parent ends; exit at once if the
    parent (pid ``parent``) has already ended.  False where ``prctl`` is not available (not
    Linux): the process then outlives a killed parent as before."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        ok = ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False
    if ok and os.getppid() != parent:  # the parent ended before the request: nobody to work for
        os._exit(1)
    return ok


def _is_server() -> bool:
    """True in multiprocessing's fork server (whose preload imports this module)."""
    main = sys.modules.get("__main__")
    return "multiprocessing.forkserver" in sys.modules and getattr(main, "__file__", None) is None \
        and sys.argv[:1] == ["-c"]


_forking_pid = os.getpid()


def _before_fork() -> None:
    global _forking_pid
    _forking_pid = os.getpid()


if _is_server():
    die_with_parent(os.getppid())
    keep_freed_memory()  # inherited by the forked workers (studies.sweep.heap)
    os.register_at_fork(before=_before_fork, after_in_child=lambda: die_with_parent(_forking_pid))

# the workers' code, loaded after the variables (numpy and scipy load their BLAS here)
import fem_reference.solve  # noqa: E402,F401
import hybmss.explicit  # noqa: E402,F401
import hybmss.solve  # noqa: E402,F401

from studies.sweep import runner  # noqa: E402,F401
