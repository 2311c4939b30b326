"""A sweep's calls: the studies' computations outside runs (:class:`studies.sweep.executors.Call`)
done by a local pool's workers once no run is left to hand out, each result kept where
:func:`studies.sweep.executors.map_stored` finds it; a call that raises keeps nothing and stops
nothing; a call already stored is not done again; in this process (one job) calls are left to
the studies' maps."""

from studies.sweep.executors import Call, map_stored
from studies.sweep.runner import Runner
from studies.sweep.store import Store

from test_runner_store import tiny_tasks


def square(item):
    return item * item


def not_again(item):
    raise AssertionError(f"computed again: {item!r}")


def fails(_item):
    raise ValueError("this call fails")


def touch(path):
    """A call with an effect only (``name`` None): a file written."""
    with open(path, "a") as fh:
        fh.write("x")


def logged_square(item):
    """``item = (log, n)``: n², with a line in the file ``log`` for each time it is computed."""
    log, n = item
    touch(log)
    return n * n


def test_calls_are_done_by_the_sweeps_workers_and_found_stored_by_the_maps(tmp_path):
    store = Store(tmp_path / "store")
    tasks = tiny_tasks()[:2]
    marker = tmp_path / "compiled"
    asked = []

    def calls():  # asked for once, when no run is left to hand out
        asked.append(True)
        return [Call("squares", square, i) for i in range(5)] + [Call(None, touch, str(marker))]

    with Runner(jobs=2, progress=False) as runner:
        rows = runner.run(tasks, store, calls=calls)
    assert [r["status"] for r in rows] == ["ok", "ok"]
    assert len(asked) == 1
    # the map finds every result stored: not_again would raise if it computed one
    assert map_stored(store, "squares", not_again, list(range(5)), workers=1) == [0, 1, 4, 9, 16]
    assert marker.read_text() == "x"


def test_calls_without_runs_are_done_too(tmp_path):
    store = Store(tmp_path)
    with Runner(jobs=2, progress=False) as runner:
        runner.run([], store, calls=[Call("squares", square, 7)])
    assert map_stored(store, "squares", not_again, [7], workers=1) == [49]


def test_a_call_that_raises_keeps_nothing_and_stops_nothing(tmp_path):
    store = Store(tmp_path)
    calls = [Call("bad", fails, 0), Call("squares", square, 3)]
    with Runner(jobs=2, progress=False) as runner:
        rows = runner.run(tiny_tasks()[:2], store, calls=calls)
    assert [r["status"] for r in rows] == ["ok", "ok"]
    assert store.load_computed("bad", store.computed_key("bad", 0)) == (False, None)
    assert store.load_computed("squares", store.computed_key("squares", 3)) == (True, 9)


def test_a_stored_call_is_not_done_again(tmp_path):
    store = Store(tmp_path / "store")
    log = str(tmp_path / "log")
    items = [(log, 2), (log, 3)]
    map_stored(store, "squares", logged_square, items[:1], workers=1)  # computed once, here
    with Runner(jobs=2, progress=False) as runner:
        runner.run([], store, calls=[Call("squares", logged_square, item) for item in items + items])
    assert open(log).read() == "xx"  # the stored one not again, the other once (not twice)
    assert map_stored(store, "squares", not_again, items, workers=1) == [4, 9]


def test_one_job_leaves_the_calls_to_the_maps(tmp_path):
    store = Store(tmp_path)
    Runner(jobs=1, progress=False).run(tiny_tasks()[:1], store, calls=[Call("squares", square, 4)])
    assert store.load_computed("squares", store.computed_key("squares", 4)) == (False, None)
