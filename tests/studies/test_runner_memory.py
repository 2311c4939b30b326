"""A local pool starts no run whose estimated memory, with the running runs', exceeds the
machine's budget: it takes the next run that fits (studies.sweep.runner.next_fitting), so that a
second large reference waits for the first while the other worker computes the small runs, rather
than idling in the solver's memory plan; a cluster (no shared memory) starts runs in order."""

from collections import deque
from types import SimpleNamespace

import pytest

from studies.sweep import runner as R
from studies.sweep.runner import Runner, Summary, next_fitting
from studies.sweep.store import Store, code_version

GB = 1e9


def test_next_fitting_takes_the_first_run_that_fits():
    needs = {"A": 10 * GB, "B": 10 * GB, "c": 0.3 * GB, "d": 0.3 * GB}
    pending = deque([(k, None) for k in needs])
    assert next_fitting(pending, [], needs, 15 * GB)[0] == "A"
    assert next_fitting(pending, [10 * GB], needs, 15 * GB)[0] == "c"  # B waits
    assert [k for k, _ in pending] == ["B", "d"]
    assert next_fitting(pending, [10 * GB, 0.3 * GB], needs, 10.5 * GB) is None
    assert next_fitting(pending, [], needs, 1 * GB)[0] == "B"  # nothing running: any run


class FakeExecutor:
    """Two slots; every run takes one tick; records what ran beside what."""

    def __init__(self, shares_memory: bool):
        self.shares_memory = shares_memory
        self.running: list = []
        self.log: list = []

    def capacity(self) -> int:
        return 2

    def submit(self, key, task) -> None:
        self.running.append(key)
        self.log.append(tuple(sorted(self.running)))

    def wait_one(self):
        key = self.running.pop(0)
        return key, ({"status": "ok", "label": key, "env_code_version": code_version()}, None)


@pytest.mark.parametrize("shares", (True, False))
def test_a_pool_never_runs_two_runs_that_do_not_fit_together(tmp_path, monkeypatch, shares):
    needs = {"A": 10 * GB, "B": 10 * GB, "c": 0.3 * GB, "d": 0.3 * GB, "e": 0.3 * GB}
    monkeypatch.setattr(R, "expected_bytes", lambda t: needs[t])
    monkeypatch.setattr(R, "memory_budget", lambda: 15 * GB)
    ex = FakeExecutor(shares)
    todo = [(k, k) for k in needs]  # longest first, as the runner orders them
    Runner(jobs=2, progress=False)._sweep(ex, todo, Store(tmp_path), Summary(), SimpleNamespace(
        update=lambda n: None, set_postfix_str=lambda *a, **k: None), {}, {})
    together = {frozenset(r) for r in ex.log}
    assert (frozenset({"A", "B"}) in together) is not shares
    assert {k for r in ex.log for k in r} == set(needs)  # every run ran
