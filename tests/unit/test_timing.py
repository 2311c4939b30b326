"""hybmss.timing against a scripted clock (every duration, hence best, median and spread, known
exactly), against sleeps of known length, and its users: the static rows of hybmss.bench keep
one untimed warm-up and the best of the repeats; studies.sweep.cost still gives the same names."""

import math
import time
from types import SimpleNamespace

import pytest

from hybmss import bench, timing
from hybmss.timing import Timing, time_repeated


def _script(monkeypatch, readings, log=None):
    """Make hybmss.timing read its clock from ``readings`` (each reading logged as "clock")."""
    it = iter(readings)

    def perf_counter():
        if log is not None:
            log.append("clock")
        return next(it)

    monkeypatch.setattr(timing, "time", SimpleNamespace(perf_counter=perf_counter))


def test_durations_best_median_and_spread_of_a_scripted_clock(monkeypatch):
    # four timed calls of 3, 1, 2 and 5 s: best 1, median (2 + 3) / 2 = 2.5, spread (2.5 - 1) / 1
    _script(monkeypatch, [0.0, 3.0, 10.0, 11.0, 20.0, 22.0, 30.0, 35.0])
    t = time_repeated(lambda: None, repeats=4, warmup=0)
    assert t.samples == (3.0, 1.0, 2.0, 5.0)
    assert t.repeats == 4
    assert t.best == 1.0
    assert t.median == 2.5
    assert t.spread == 1.5
    assert t.as_dict("solve") == {"solve_s": 1.0, "solve_median_s": 2.5, "solve_spread": 1.5, "solve_repeats": 4}


def test_an_odd_number_of_repeats_has_the_middle_duration_as_median(monkeypatch):
    _script(monkeypatch, [0.0, 4.0, 4.0, 5.0, 5.0, 7.0])  # 4, 1, 2 s
    t = time_repeated(lambda: None, repeats=3, warmup=0)
    assert (t.best, t.median, t.spread) == (1.0, 2.0, 1.0)


def test_one_repeat_has_no_spread(monkeypatch):
    _script(monkeypatch, [1.0, 1.25])
    t = time_repeated(lambda: None, repeats=1, warmup=0)
    assert t.samples == (0.25,) and t.best == t.median == 0.25
    assert math.isnan(t.spread)


def test_warm_up_calls_are_not_timed(monkeypatch):
    log = []
    _script(monkeypatch, [0.0, 1.0, 2.0, 4.0], log)
    t = time_repeated(lambda: log.append("call"), repeats=2, warmup=3)
    # the clock is first read after the three warm-up calls, then around each timed call
    assert log == ["call"] * 3 + ["clock", "call", "clock"] * 2
    assert t.samples == (1.0, 2.0)


def test_the_defaults_are_one_warm_up_and_five_repeats(monkeypatch):
    log = []
    _script(monkeypatch, [float(k) for k in range(10)], log)
    t = time_repeated(lambda: log.append("call"))
    assert log == ["call"] + ["clock", "call", "clock"] * 5
    assert t.repeats == 5


@pytest.mark.parametrize("repeats,warmup", [(0, 1), (-1, 0), (3, -1)])
def test_bad_arguments_are_refused_before_any_call(repeats, warmup):
    calls = []
    with pytest.raises(ValueError, match="repeats"):
        time_repeated(lambda: calls.append(1), repeats=repeats, warmup=warmup)
    assert calls == []


@pytest.mark.parametrize("budget,timed", [(2.5, 3), (3.0, 3), (0.5, 1), (100.0, 5), (None, 5)])
def test_a_time_budget_stops_the_timed_calls(monkeypatch, budget, timed):
    # scripted clock: every timed call lasts 1 s; stop once the durations sum to the budget
    log = []
    _script(monkeypatch, [float(k) for k in range(20)], log)
    t = time_repeated(lambda: log.append("call"), repeats=5, warmup=1, budget_s=budget)
    assert t.repeats == timed and t.samples == (1.0,) * timed
    assert log.count("call") == 1 + timed


@pytest.mark.parametrize("budget", (0.0, -1.0, float("nan")))
def test_a_budget_that_is_no_time_is_refused(budget):
    with pytest.raises(ValueError, match="budget_s"):
        time_repeated(lambda: None, repeats=2, budget_s=budget)


def test_a_clock_that_does_not_advance_is_no_duration(monkeypatch):
    _script(monkeypatch, [2.0, 2.0])
    with pytest.raises(ValueError, match="samples"):
        time_repeated(lambda: None, repeats=1, warmup=0)


def test_sleeps_of_known_length():
    # the real clock: a timed call lasts at least its sleep (the warm-up's long sleep is not timed)
    sleeps = iter([0.2, 0.005, 0.03])
    t0 = time.perf_counter()
    t = time_repeated(lambda: time.sleep(next(sleeps)), repeats=2, warmup=1)
    total = time.perf_counter() - t0
    assert t.samples[0] >= 0.005 and t.samples[1] >= 0.03
    assert sum(t.samples) < total - 0.2 + 1e-9  # the warm-up's 0.2 s is outside the samples


def test_the_sweep_names_are_these():
    from studies.sweep import cost

    assert cost.Timing is Timing and cost.time_repeated is time_repeated


def test_static_rows_are_the_best_of_the_repeats_after_one_warm_up(monkeypatch):
    calls = []

    def solve_static(scene, system=None):
        calls.append(scene)
        return SimpleNamespace(iterations=len(calls), info={"load_steps": 10 * len(calls)})

    monkeypatch.setattr(bench, "compression_scene", lambda model, nu, mesh, d: (model, nu, d))
    monkeypatch.setattr(bench, "build", lambda scene: None)
    monkeypatch.setattr(bench, "solve_static", solve_static)
    # three cases of three repeats: 0.5, 0.25, 2; 3, 1, 4; 1, 1, 0.75 s
    durations = [0.5, 0.25, 2.0, 3.0, 1.0, 4.0, 1.0, 1.0, 0.75]
    readings = [x for k, d in enumerate(durations) for x in (10.0 * k, 10.0 * k + d)]
    _script(monkeypatch, readings)
    rows = bench.static_bench(repeats=3, mesh=(2, 2, 2), names=["m"])
    assert [r["wall_time_s"] for r in rows] == [0.25, 1.0, 0.75]
    assert len(calls) == 3 * (1 + 3)  # one untimed warm-up and three timed solves per case
    assert calls == [("m", 0.25, 0.05)] * 4 + [("m", 0.499, 0.05)] * 4 + [("m", 0.25, 0.20)] * 4
    # the counts are those of the last solve of each case
    assert [r["newton_iterations"] for r in rows] == [4, 8, 12]
    assert [r["load_steps"] for r in rows] == [40, 80, 120]
