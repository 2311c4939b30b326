"""The C heap of the processes that compute runs (:mod:`studies.sweep.heap`): a large array is
served from the heap (not a fresh mmap whose pages the kernel faults in again at every
allocation), what a run frees goes back to the machine after it, and a local pool's workers
inherit the setting from their fork server."""

import ast
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from studies.sweep import heap
from studies.sweep.executors import Workers

pytestmark = pytest.mark.skipif(heap.mmapped_bytes() is None, reason="glibc's malloc only")

MB = 2**20
HERE = os.path.dirname(os.path.abspath(__file__))


def resident_bytes() -> int:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def _in_fresh_process(code: str) -> dict:
    """``code`` run by a new interpreter (the heap's settings are the process's): the dict it prints."""
    src = "import numpy as np\nfrom studies.sweep import heap\nfrom test_heap import resident_bytes, MB\n" + textwrap.dedent(code)
    out = subprocess.run([sys.executable, "-c", src], capture_output=True, text=True, check=True,
                         cwd=HERE, env={**os.environ, "PYTHONPATH": os.path.dirname(os.path.dirname(HERE))})
    return ast.literal_eval(out.stdout.strip().splitlines()[-1])


def test_glibc_maps_a_large_array_of_its_own_and_the_setting_takes_it_from_the_heap():
    got = _in_fresh_process("""
        m0 = heap.mmapped_bytes()
        a = np.ones(64 * MB // 8)
        before = heap.mmapped_bytes() - m0
        del a
        kept = heap.keep_freed_memory()
        m0 = heap.mmapped_bytes()
        b = np.ones(64 * MB // 8)
        print(dict(before=before, kept=kept, after=heap.mmapped_bytes() - m0))
    """)
    assert got["before"] >= 64 * MB  # what the setting is for: glibc's own choice for 64 MiB
    assert got["kept"] and got["after"] == 0


def test_the_heap_keeps_what_is_freed_until_it_is_released():
    got = _in_fresh_process("""
        heap.keep_freed_memory()
        base = resident_bytes()
        a = np.ones(256 * MB // 8)
        del a
        kept = resident_bytes() - base
        heap.release_free_memory()
        print(dict(kept=kept, after=resident_bytes() - base))
    """)
    assert got["kept"] >= 250 * MB  # freed, still this process's: the next array takes it
    assert got["after"] <= 16 * MB  # released: the machine's again


def _allocate(n_mb: int) -> dict:
    m0 = heap.mmapped_bytes()
    a = np.ones(n_mb * MB // 8)
    return {"mmapped": heap.mmapped_bytes() - m0, "resident": resident_bytes(), "sum": float(a.sum())}


def _resident(_item) -> int:
    return resident_bytes()


def test_a_pool_worker_takes_large_arrays_from_the_heap_and_releases_it_after_each_call():
    workers = Workers(1)
    try:
        during = workers.submit(_allocate, 256).result()
        after = workers.submit(_resident, None).result()
    finally:
        workers.close()
    assert during["sum"] == 256 * MB // 8
    assert during["mmapped"] == 0  # the fork server's setting, inherited
    assert during["resident"] - after >= 200 * MB  # the call's freed heap went back after it
