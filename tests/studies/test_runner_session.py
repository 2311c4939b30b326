"""A runner used as a context manager keeps one set of local worker processes for its session:
every sweep and every map of a study's own work (:func:`map_local`, :func:`map_stored`) is
computed by the same processes, so what one loaded serves the next; a failure kills them and the
next use starts new ones; the session's end ends them.  Outside a session each sweep or map has
processes of its own, ended with it."""

import os
import time

import pytest

from studies.sweep.executors import LocalPool, Workers, local_executor, map_local, map_stored
from studies.sweep.runner import Runner
from studies.sweep.store import Store

from test_runner_store import tiny_tasks


def pid(_item):
    """The worker's process id, after long enough for the other worker to take the next item."""
    time.sleep(0.3)
    return os.getpid()


def pid_of_run(_task, _key):
    return pid(None)


def fails(_item):
    raise ValueError("this item fails")


def test_maps_of_a_session_share_its_workers_and_its_end_ends_them(tmp_path):
    with Runner(jobs=2, progress=False) as runner:
        first = map_local(pid, range(4), workers=2, runner=runner)
        second = map_stored(Store(tmp_path), "pids", pid, list(range(4)), workers=2, runner=runner)
        procs = list(runner.local_workers().procs)
        assert len(procs) == 2 and set(first) == set(second) == {p.pid for p in procs}
        assert all(p.is_alive() for p in procs)  # kept between the maps
    assert not any(p.is_alive() for p in procs)


def test_maps_outside_a_session_start_and_end_their_own_processes():
    first = map_local(pid, range(4), workers=2)
    second = map_local(pid, range(4), workers=2)
    assert len(set(first)) == len(set(second)) == 2 and not set(first) & set(second)


def test_a_failure_kills_the_sessions_workers_and_the_next_map_starts_new_ones():
    with Runner(jobs=2, progress=False) as runner:
        before = map_local(pid, range(4), workers=2, runner=runner)
        procs = list(runner.local_workers().procs)
        with pytest.raises(ValueError, match="this item fails"):
            map_local(fails, [0, 1], workers=2, runner=runner)
        assert not any(p.is_alive() for p in procs)
        after = map_local(pid, range(4), workers=2, runner=runner)
        assert len(set(after)) == 2 and not set(after) & set(before)


def test_a_sweeps_pool_on_given_workers_leaves_them_running_until_abandoned():
    workers = Workers(2)
    try:
        pids = []
        for _ in range(2):
            pool = local_executor(pid_of_run, 2, 4, workers)
            assert isinstance(pool, LocalPool) and pool.capacity() == 2
            for k in "ab":
                pool.submit(k, None)
            pids.append({pool.wait_one()[1] for _ in "ab"})
            pool.close()
            assert all(p.is_alive() for p in workers.procs)
        assert pids[0] == pids[1] and len(pids[0]) == 2
        procs = list(workers.procs)
        pool.abandon()
        assert not any(p.is_alive() for p in procs)
    finally:
        workers.kill()


def test_a_runner_session_computes_every_sweep_on_the_same_workers(tmp_path):
    tasks = tiny_tasks()
    with Runner(jobs=2, progress=False) as runner:
        rows = runner.run(tasks[:3], Store(tmp_path / "a"))
        procs = list(runner.local_workers().procs)
        assert procs and all(p.is_alive() for p in procs)
        rows += runner.run(tasks[3:], Store(tmp_path / "b"))
        assert runner.local_workers().procs[:len(procs)] == procs and len(runner.local_workers().procs) <= 2
        assert all(p.is_alive() for p in procs)
    assert all(r["status"] == "ok" for r in rows) and runner.summary.computed == len(tasks)
    assert not any(p.is_alive() for p in procs)
