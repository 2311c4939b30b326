"""A study's model run is timed up to ``repeats`` times after an untimed run, the timed runs stopped
once they took TIMING_BUDGET_S together (studies.study.tasks._timed); the time estimate of the
study's checks (studies.study.checks) counts the same number (timed_repeats), checked against a
scripted clock."""

from types import SimpleNamespace

import pytest

from hybmss import timing
from studies.study import tasks


@pytest.mark.parametrize("seconds", (0.5, 3.0, 4.0, 9.9, 10.0, 30.0))
def test_timed_runs_stop_at_the_budget_and_the_estimate_counts_them(monkeypatch, seconds):
    clock = iter(k * seconds for k in range(100))
    monkeypatch.setattr(timing, "time", SimpleNamespace(perf_counter=lambda: next(clock)))
    calls = []

    def solve(scene, solver):
        calls.append(1)
        return SimpleNamespace(info={})

    monkeypatch.setattr(tasks, "solve_scene", solve)
    res = tasks._timed(None, None, repeats=5)
    timed = res.info["time_repeats"]
    assert len(calls) == 1 + timed  # the untimed run and the timed ones
    assert timed == tasks.timed_repeats(seconds, 5)
    expected = min(5, max(1, -(-tasks.TIMING_BUDGET_S // seconds)))  # k runs until k·seconds >= budget
    assert timed == expected and res.info["time_s"] == seconds
