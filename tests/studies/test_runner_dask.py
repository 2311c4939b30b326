"""The runner on a dask.distributed cluster (a LocalCluster of 2 single-threaded workers started
here): the same stored keys and rows as the local executor, nothing lost when a worker is
killed during a sweep, a finished sweep not recomputed, a run whose workers keep dying stored as
a failed row."""

import os
import signal
import threading
import time

import pytest

distributed = pytest.importorskip("distributed")

from studies.sweep.runner import Runner, SolverSpec, Task  # noqa: E402
from studies.sweep.scenes import SceneSpec  # noqa: E402
from studies.sweep.store import Store, dumps  # noqa: E402

TIMINGS = ("elapsed_s", "wall_time_s")


def small_tasks(mesh=(3, 3, 3)) -> list[Task]:
    tasks = []
    for nu in (0.0, 0.25):
        for d in (0.05, 0.2):
            spec = SceneSpec.default("compression", mesh=mesh, nu=nu, deformation=d)
            tasks.append(Task(spec, SolverSpec("static"), "compression"))
            tasks.append(Task(spec.replace(model="hybmss-fd"), SolverSpec("static"), "compression"))
        tasks.append(Task(spec, SolverSpec("fem", element="hex1", law="linear"), "compression"))
    return tasks


def comparable(row: dict) -> str:
    return dumps({k: v for k, v in row.items() if k not in TIMINGS})


def check_intact(store: Store, n: int) -> None:
    """n runs stored, every file parses and matches its row; no temporary or lock file left."""
    rows, damaged = store.scan()
    assert damaged == [] and len(rows) == n
    assert not list(store.runs.glob(".*.tmp")) and not list(store.locks.glob("*.lock"))


@pytest.fixture(scope="module")
def cluster():
    c = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                 dashboard_address=":0")
    client = distributed.Client(c)
    yield c, client
    client.close()
    c.close()


@pytest.mark.slow
def test_dask_and_local_store_the_same_runs(cluster, tmp_path):
    c, _ = cluster
    tasks = small_tasks()
    local, dask = Store(tmp_path / "local"), Store(tmp_path / "dask")
    Runner("local", jobs=1, progress=False).run(tasks, local)
    runner = Runner("dask", scheduler=c.scheduler_address, progress=False)
    with runner:
        runner.run(tasks, dask)
    assert runner.summary.computed == len(tasks)
    assert local.keys() == dask.keys() and len(local.keys()) == len(tasks)
    for k in local.keys():
        assert comparable(local.row(k)) == comparable(dask.row(k)), k
    check_intact(dask, len(tasks))
    # a finished sweep, run again on Dask, computes nothing
    mtimes = {p: p.stat().st_mtime_ns for p in dask.runs.iterdir()}
    again = Runner("dask", scheduler=c.scheduler_address, progress=False)
    rows = again.run(tasks, dask)
    assert (again.summary.computed, again.summary.stored) == (0, len(tasks))
    assert [r["key"] for r in rows] == [t.key() for t in tasks]
    assert {p: p.stat().st_mtime_ns for p in dask.runs.iterdir()} == mtimes


def long_run(steps: int) -> Task:
    """A damped explicit run of ``steps`` NumPy steps on a 2³ cube (nothing to compile; at rest
    after 10,000 steps): about 0.1 ms a step, so a run of known, long duration (``steps = 10**6``:
    minutes) that a kill lands in."""
    spec = SceneSpec.default("compression", mesh=(2, 2, 2), nu=0.25, deformation=0.05, damping=2.0)
    return Task(spec, SolverSpec("explicit", steps=steps, kernel="numpy"), "compression")


def worker_running(client, task: Task):
    """The worker that holds ``task``'s run, or None."""
    key = f"hybmss-run-{task.key()}"
    return next((w for w, keys in client.processing().items() if key in keys), None)


@pytest.mark.slow
def test_a_killed_worker_loses_nothing(cluster, tmp_path):
    """One worker is killed (SIGKILL) while it computes a run: the scheduler resubmits the run,
    the sweep finishes, every run is computed and stored once and every file is intact.  The run
    killed is a 10,000-step explicit run (a second or more), submitted last: the kill lands while it runs,
    after other runs are stored, whatever the machine's load."""
    c, client = cluster
    slow = long_run(10_000)
    tasks = small_tasks(mesh=(4, 4, 4)) + [slow]
    store = Store(tmp_path)
    runner = Runner("dask", scheduler=c.scheduler_address, progress=False)
    failure = []

    def sweep():
        try:
            runner.run(tasks, store)
        except BaseException as exc:  # noqa: BLE001 - reported by the test
            failure.append(exc)

    th = threading.Thread(target=sweep)
    th.start()
    killed = None
    deadline = time.monotonic() + 120
    while killed is None and th.is_alive() and time.monotonic() < deadline:
        busy = worker_running(client, slow)
        if busy and store.keys():  # some runs stored, the slow one in progress on `busy`
            pid = client.run(os.getpid, workers=[busy])[busy]
            os.kill(pid, signal.SIGKILL)
            killed = pid
        time.sleep(0.02)
    th.join(timeout=180)
    assert not th.is_alive() and not failure, failure
    assert killed is not None
    assert runner.summary.computed == len(tasks)
    rows = [store.row(t.key()) for t in tasks]
    assert all(r["status"] == "ok" for r in rows), [r["message"] for r in rows]
    check_intact(store, len(tasks))


def _allow_failures(n, dask_scheduler=None):
    old, dask_scheduler.allowed_failures = dask_scheduler.allowed_failures, n
    return old


def test_a_run_whose_workers_keep_dying_is_a_failed_row(cluster, tmp_path):
    """With no worker death allowed, a killed run comes back as a stored failed row naming the
    cause (the sweep goes on and stores it).  The run would take minutes: it cannot finish before
    the kill lands."""
    c, client = cluster
    task = long_run(10**6)
    store = Store(tmp_path)
    runner = Runner("dask", scheduler=c.scheduler_address, progress=False)
    old = client.run_on_scheduler(_allow_failures, 0)
    try:
        th = threading.Thread(target=runner.run, args=([task], store))
        th.start()
        deadline = time.monotonic() + 120
        busy = None
        while time.monotonic() < deadline and busy is None:
            busy = worker_running(client, task)
            time.sleep(0.005)
        assert busy is not None, "the run never started"
        os.kill(client.run(os.getpid, workers=[busy])[busy], signal.SIGKILL)
        th.join(timeout=180)
        assert not th.is_alive()
    finally:
        client.run_on_scheduler(_allow_failures, old)
    row = store.row(task.key())
    assert row["status"] == "error" and "KilledWorker" in row["message"] and "died" in row["message"]
    assert runner.summary.computed == 1 and runner.summary.failed == 1
    check_intact(store, 1)
