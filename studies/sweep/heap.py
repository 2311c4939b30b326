"""The C heap of the processes that compute runs: memory freed within a run is reused, not
returned to the kernel and faulted in again.

glibc's ``malloc`` serves every request above its mmap threshold (32 MiB at most) with a fresh
``mmap`` and unmaps it on ``free``; the next request of that size touches new pages, and the
kernel zero-fills each one in a page fault.  A FEM reference allocates and frees arrays of that
size at every residual and tangent (the quadrature-point tensors and element blocks of the
Hex2 8×8×48 beam are 0.1–1 GB), so its run paid more time in the kernel than in some of its
solves: five references of the tension and bending studies on that beam took 48.0 s of wall
time, 13.2 s of it system time, with 2.29 million minor page faults.  With mmap off
(``M_MMAP_MAX = 0``: every request from the heap) and the heap never trimmed on ``free``
(``M_TRIM_THRESHOLD`` at its largest), the same five took 31.7 s, 0.0 s of system time and 3,077
faults, and peaked at 2.22 GB instead of 2.05 GB; with the heap handed back after each of them,
as a worker does (below), 36.6 s, 2.6 s and 711 k faults (each run faults its own peak in once).
Their forces agreed to 1e-15.  hybmss-fd's static solve of that beam (SuperLU factors) took 21.4 s
instead of 24.9 s; explicit runs, which allocate once, did not change.

:func:`keep_freed_memory` sets this in a process (a local pool's fork server sets it before it
forks the workers, which inherit it: :mod:`studies.sweep.pool_worker`); :func:`release_free_memory`
hands the heap's free memory back to the kernel (``malloc_trim``), which a worker does after each
run or call (:func:`then_release`): what a run freed is then available to the machine's other
processes again, as it was with mmap (the memory plans of :mod:`fem_reference.memory` read the
memory available), and a run keeps at most its own peak.  Elsewhere than glibc both do nothing.
"""

from __future__ import annotations

import ctypes
import platform
from functools import lru_cache

M_TRIM_THRESHOLD = -1
M_MMAP_MAX = -4
"""``mallopt`` parameters (``<malloc.h>``)."""
TRIM_THRESHOLD_MAX = 2**31 - 1
"""The largest ``M_TRIM_THRESHOLD`` (an ``int``): free memory at the heap's top is kept up to this."""


class _Mallinfo2(ctypes.Structure):
    """glibc's ``struct mallinfo2``."""

    _fields_ = [(name, ctypes.c_size_t) for name in
                ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks",
                 "keepcost")]


@lru_cache(maxsize=1)
def _libc():
    """glibc, or None where the C library is another (no ``mallopt``, ``malloc_trim``)."""
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return None
    try:
        libc = ctypes.CDLL(None)
    except OSError:
        return None
    if not (hasattr(libc, "mallopt") and hasattr(libc, "malloc_trim")):
        return None
    if hasattr(libc, "mallinfo2"):
        libc.mallinfo2.restype = _Mallinfo2
    return libc


def keep_freed_memory() -> bool:
    """Serve every allocation of this process (and of the processes it forks after) from the heap
    and keep what is freed there for the next one.  False where the C library is not glibc or
    refused a setting."""
    libc = _libc()
    if libc is None:
        return False
    no_mmap = libc.mallopt(M_MMAP_MAX, 0)
    no_trim = libc.mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_MAX)
    return bool(no_mmap and no_trim)


def release_free_memory() -> bool:
    """Return the heap's free memory to the kernel (``malloc_trim(0)``); whether any was returned."""
    libc = _libc()
    return bool(libc.malloc_trim(0)) if libc is not None else False


def mmapped_bytes() -> int | None:
    """Bytes this process's ``malloc`` holds in chunks of their own mmap (glibc's
    ``mallinfo2().hblkhd``): 0 under :func:`keep_freed_memory`; None where it cannot tell."""
    libc = _libc()
    if libc is None or not hasattr(libc, "mallinfo2"):
        return None
    return int(libc.mallinfo2().hblkhd)


def then_release(fn, *args):
    """``fn(*args)``, then the heap's free memory returned to the kernel (a worker's run or call:
    :class:`studies.sweep.executors.Workers`)."""
    try:
        return fn(*args)
    finally:
        release_free_memory()
