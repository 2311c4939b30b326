"""The memory that the large factorizations of this machine's processes have planned.

A large factorization (:func:`fem_reference.linalg.solve_saddle`'s Schur elimination above
CHOLMOD's fixed limit) is admitted by the memory its solve will peak at against the memory
available when it starts.  Two processes that start such a solve at the same moment (the two
workers of a study, each on a reference of 10 GB) both see the memory free and both go on: the
cylinder study peaked at 21.9 of 23 GB, and on a smaller machine the kernel would kill one.  So
each admitted solve writes what it plans to use into a ledger shared by the machine's processes
(:func:`ledger_dir`: one file a plan, named by the process id), and a solve counts, besides the
memory available, what the others planned and have not yet allocated (their plan less their
resident memory, :func:`others`), and waits while it would fit once those plans end rather than
fall back to a solver ten times slower (:func:`admit`).  A plan whose process has ended is
ignored and removed.

A plan lasts as long as the factor it was made for: :func:`plan` returns a :class:`Plan` that
removes its file when released or garbage-collected (the factor's cache is dropped at the end of
the Newton solve).
"""

from __future__ import annotations

import os
import tempfile
import time
import weakref
from itertools import count

WAIT_POLL_S = 1.0
"""Seconds between two looks at the ledger while a solve waits for another's plan to end."""

_serial = count()


def ledger_dir() -> str:
    """The folder of the plans: ``$HYBMSS_MEMORY_LEDGER``, else ``hybmss-memory-<uid>`` in the
    system's temporary folder (one machine, one ledger)."""
    d = os.environ.get("HYBMSS_MEMORY_LEDGER") or os.path.join(
        tempfile.gettempdir(), f"hybmss-memory-{os.getuid() if hasattr(os, 'getuid') else 0}")
    os.makedirs(d, exist_ok=True)
    return d


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # pragma: no cover - another user's process
        return True
    return True


def resident(pid: int) -> float:
    """Resident memory of process ``pid`` (bytes; 0 where ``/proc`` does not say)."""
    try:
        with open(f"/proc/{pid}/statm") as fh:
            return float(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0.0


def others(folder: str | None = None) -> list[tuple[float, float]]:
    """``(planned, resident)`` bytes of each other live process with plans in the ledger (its plans
    summed).  The files of ended processes are removed."""
    folder = ledger_dir() if folder is None else folder
    planned: dict[int, float] = {}
    for name in os.listdir(folder):
        try:
            pid = int(name.split("-")[0])
        except ValueError:
            continue
        if pid == os.getpid():
            continue
        path = os.path.join(folder, name)
        if not _alive(pid):  # its plans, and a plan it was writing when it ended
            _remove(path)
            continue
        if not name.endswith(".plan"):
            continue
        try:
            with open(path) as fh:
                planned[pid] = planned.get(pid, 0.0) + float(fh.read())
        except (OSError, ValueError):
            continue
    return [(b, resident(pid)) for pid, b in planned.items()]


class Plan:
    """A planned peak of ``nbytes`` in the ledger until :meth:`release` (or garbage collection)."""

    def __init__(self, nbytes: float, folder: str | None = None):
        folder = ledger_dir() if folder is None else folder
        self.path = os.path.join(folder, f"{os.getpid()}-{next(_serial)}.plan")
        tmp = self.path + ".tmp"
        with open(tmp, "w") as fh:
            fh.write(repr(float(nbytes)))
        os.replace(tmp, self.path)
        self._finalizer = weakref.finalize(self, _remove, self.path)

    def release(self) -> None:
        self._finalizer()


def _remove(path: str) -> None:
    try:
        os.remove(path)
    except OSError:
        pass


def admit(nbytes: float, available, fraction: float, folder: str | None = None, wait: bool = True,
          sleep=time.sleep) -> Plan | None:
    """A :class:`Plan` of ``nbytes`` when they fit within ``fraction`` of the memory ``available()``
    less what the other processes planned and have not allocated yet.  While they would fit once
    the others' plans end (their allocated share returned), wait (``wait``; a look every
    :data:`WAIT_POLL_S`); ``None`` when they would not fit even then."""
    while True:
        free = available()
        plans = others(folder)
        pending = sum(max(0.0, p - r) for p, r in plans)
        held = sum(min(p, r) for p, r in plans)
        if nbytes <= fraction * (free - pending):
            return Plan(nbytes, folder)
        if not wait or nbytes > fraction * (free + held):
            return None
        sleep(WAIT_POLL_S)
