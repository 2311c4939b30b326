"""The start of the local pool's worker processes: one BLAS and OpenMP thread in each.

A sweep runs in parallel over its runs, one run per worker; a worker whose dense or sparse
solves also start one BLAS thread per core oversubscribes the machine (under load a
multithreaded dense eigen solve was 10-30x slower than a single-threaded one).  OpenBLAS, MKL and
OpenMP read their thread counts once, when the library is loaded, i.e. when numpy or scipy is
first imported: setting the variables in a process that has imported numpy changes nothing.  So
the local pool (:class:`studies.executors.LocalPool`) forks its workers from a server process
(multiprocessing's ``forkserver``) whose first import is this module: the variables are set
here, then numpy, the runner and the solvers are imported once, with them in force, and every
worker forked from the server starts with them loaded.  Dask workers get the same variables from
dask's own ``distributed.nanny.pre-spawn-environ`` setting.
"""

import os

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
"""The thread counts of OpenMP, OpenBLAS and MKL, each set to 1 in a worker."""

for _name in THREAD_VARIABLES:
    os.environ[_name] = "1"

# the workers' code, loaded after the variables (numpy and scipy load their BLAS here)
import fem_reference.solve  # noqa: E402,F401
import hybmss.explicit  # noqa: E402,F401
import hybmss.solvers  # noqa: E402,F401

from . import runner  # noqa: E402,F401
