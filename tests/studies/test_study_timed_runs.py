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


@pytest.mark.parametrize("seconds, info, again", [
    (30.0, {"compile_time_s": 0.02, "warm_up_s": 0.0}, False),  # an engine's long run: its own timing
    (30.0, {"compile_time_s": 0.5}, True),                      # compile 1.7 % of it: timed again
    (30.0, {"compile_time_s": 0.0, "warm_up_s": 0.4}, True),    # the loop's warm-up call 1.3 %
    (30.0, {}, True),                                           # one-time cost not reported (Numba)
    (9.0, {"compile_time_s": 0.0}, True),                       # short: timed runs for its spread
])
def test_a_long_first_run_with_a_negligible_reported_one_time_cost_is_its_own_timing(monkeypatch, seconds, info,
                                                                                      again):
    clock = iter(k * seconds for k in range(100))
    fake = SimpleNamespace(perf_counter=lambda: next(clock))
    monkeypatch.setattr(timing, "time", fake)
    monkeypatch.setattr(tasks, "time", fake)
    calls = []

    def solve(scene, solver):
        calls.append(1)
        return SimpleNamespace(info=dict(info))

    monkeypatch.setattr(tasks, "solve_scene", solve)
    res = tasks._timed(None, None, repeats=5)
    assert (len(calls) > 1) == again
    assert res.info["time_first_run"] == (not again)
    assert res.info["time_s"] == seconds and res.info["time_repeats"] == (1 if not again else
                                                                           tasks.timed_repeats(seconds, 5))
