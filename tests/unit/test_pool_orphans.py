"""A local pool's fork server and workers end with the process that started them, even when it is
killed with SIGKILL (no clean-up runs): :mod:`studies.sweep.pool_worker`'s parent-death signal."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

CHILD = textwrap.dedent("""
    import sys, time
    from studies.sweep.executors import LocalPool
    from test_pool_orphans import work

    pool = LocalPool(work, 2)
    pool.submit("a", None)
    print(*pool.wait_one()[1], flush=True)
    pool.submit("b", None)  # a worker computing when its parent is killed
    time.sleep(600)
""")


def work(task, key):
    """A pool task: "a" gives this worker's pid and its parent's (the fork server), others compute
    (sleep) for ten minutes."""
    if key == "a":
        return os.getpid(), os.getppid()
    time.sleep(600)


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split()[2] != "Z"  # a zombie has ended
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl(PR_SET_PDEATHSIG) is Linux's")
def test_a_killed_run_leaves_no_pool_processes():
    path = os.pathsep.join([str(ROOT), str(Path(__file__).parent), os.environ.get("PYTHONPATH", "")])
    env = {**os.environ, "PYTHONPATH": path}
    child = subprocess.Popen([sys.executable, "-c", CHILD], cwd=ROOT, env=env, stdout=subprocess.PIPE, text=True)
    try:
        worker, server = (int(v) for v in child.stdout.readline().split())
        assert alive(worker) and alive(server) and server != child.pid
        child.send_signal(signal.SIGKILL)
        child.wait(timeout=10)
        deadline = time.monotonic() + 10.0
        while (alive(worker) or alive(server)) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not alive(server), "the fork server outlived its killed parent"
        assert not alive(worker), "a pool worker outlived its killed parent"
    finally:
        if child.poll() is None:
            child.kill()
