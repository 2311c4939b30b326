"""studies.sweep.cost against hand-computed cases: the timing of repeats, the explicit cost at the stable
step, and the budget answer with its lead and ties (the rule: tie ⇔ lead < 1 + max spread)."""

import math

import numpy as np
import pandas as pd
import pytest

from hybmss import timing
from studies.sweep import cost
from studies.sweep.cost import NO_BUDGET, NONE_WITHIN, TIMING_NOISE, Timing, budget_answer, is_tie


# ------------------------------------------------------------------------------ timing
def test_timing_of_samples():
    t = Timing.from_samples([2.0, 2.5, 3.0, 2.2, 2.4])
    assert t.best == 2.0
    assert t.median == 2.4
    assert t.spread == pytest.approx((2.4 - 2.0) / 2.0)  # 0.2: the median's excess over the best
    assert t.repeats == 5
    assert t.as_dict("static") == {"static_s": 2.0, "static_median_s": 2.4, "static_spread": pytest.approx(0.2),
                                   "static_repeats": 5}


def test_one_disturbed_repeat_does_not_make_the_spread():
    # a first run that loaded its kernels (100x) among three: the median ignores it
    t = Timing.from_samples([1.0, 100.0, 1.1])
    assert t.best == 1.0 and t.spread == pytest.approx(0.1)
    # two repeats: the median is their mean, the spread half the relative range
    assert Timing.from_samples([2.0, 3.0]).spread == pytest.approx(0.25)


def test_one_sample_has_no_spread():
    t = Timing.from_samples([0.7])
    assert t.best == t.median == 0.7 and t.repeats == 1
    assert math.isnan(t.spread)


@pytest.mark.parametrize("bad", [[], [1.0, 0.0], [1.0, -2.0], [float("nan")], [float("inf")]])
def test_timing_refuses_non_durations(bad):
    with pytest.raises(ValueError, match="samples"):
        Timing.from_samples(bad)


def test_time_repeated_times_the_repeats_not_the_warmup(monkeypatch):
    calls = []
    clock = iter([10.0, 11.0, 20.0, 22.0, 30.0, 33.0])  # three timed calls: 1, 2, 3 s
    monkeypatch.setattr(timing.time, "perf_counter", lambda: next(clock))
    t = cost.time_repeated(lambda: calls.append(1), repeats=3, warmup=2)
    assert len(calls) == 5
    assert t.samples == (1.0, 2.0, 3.0)
    assert t.best == 1.0 and t.median == 2.0 and t.spread == 1.0


def test_time_repeated_measures_real_time():
    import time

    t = cost.time_repeated(lambda: time.sleep(0.01), repeats=2, warmup=0)
    assert t.repeats == 2 and t.best >= 0.01


# ------------------------------------------------------------------------------ explicit cost
def test_cost_per_simulated_second():
    # 50 µs per step at 1 ms: 1,000 steps per simulated second, 0.05 s
    assert cost.cost_per_simulated_second(50.0, 1e-3) == pytest.approx(0.05)
    np.testing.assert_allclose(cost.cost_per_simulated_second(np.array([50.0, 10.0]), np.array([1e-3, 1e-4])),
                               [0.05, 0.1])


def test_explicit_cost_at_the_stable_step():
    assert cost.SAFETY == 0.5
    assert cost.stable_dt(2e-3) == pytest.approx(1e-3)
    # dt_crit 2 ms -> dt 1 ms -> 1,000 steps of 50 µs
    assert cost.explicit_cost(50.0, 2e-3) == pytest.approx(0.05)
    # dt_crit 0.6 s -> dt 0.3 s: one simulated second is ceil(3.33) = 4 whole steps
    assert cost.explicit_cost(1e6, 0.6) == pytest.approx(4.0)
    # dt = 0.1 s exactly: 10 steps, not 11 (1.0 / 0.1 is 10.000000000000002 in floating point)
    assert cost.explicit_cost(1e6, 0.2) == pytest.approx(10.0)
    # ten simulated seconds at dt 1 ms: 10,000 steps of 20 µs
    assert cost.explicit_cost(20.0, 2e-3, simulated_s=10.0) == pytest.approx(0.2)


def test_explicit_cost_without_a_limit_takes_the_frame():
    assert cost.explicit_cost(1000.0, math.inf, dt_max=1 / 60) == pytest.approx(60 * 1e-3)
    # a frame larger than the stable step does not raise the step
    assert cost.stable_dt(2e-3, dt_max=1 / 60) == pytest.approx(1e-3)
    with pytest.raises(ValueError, match="dt_max"):
        cost.stable_dt(math.inf)


# ------------------------------------------------------------------------------ ties
def test_tie_rule():
    assert is_tie(1.1, 0.2, 0.05) is True  # 1.1 < 1.2: the lead is within the noise
    assert is_tie(1.1, 0.05, 0.2) is True  # the larger spread counts, whichever method has it
    assert is_tie(1.1, 0.05, 0.05) is False  # 1.1 is not below 1 + max(0.05, TIMING_NOISE = 0.1)
    assert is_tie(1.09, 0.01, 0.02) is True  # within the noise of runs measured apart, whatever their spreads
    assert TIMING_NOISE == 0.10
    assert is_tie(1.5, 0.5, 0.25) is False  # exactly 1 + s: not smaller, not a tie
    assert is_tie(1.5, 0.0, 0.625) is True
    assert is_tie(3.0, math.nan, 0.1) is pd.NA  # a single timing: undetermined
    assert is_tie(math.nan, 0.1, 0.1) is False  # no runner-up


def _frame():
    return pd.DataFrame([
        # method, mesh, error, cost (best, s), spread
        ("A", "fine", 0.02, 1.0, 0.2),
        ("A", "coarse", 0.09, 0.3, 0.1),
        ("B", "fine", 0.03, 1.1, 0.05),
        ("C", "coarse", 0.08, 0.5, 0.1),
        ("D", "fine", 0.5, 0.01, 0.0),
        ("E", "fine", np.nan, 0.2, 0.1),  # failed run: no error
    ], columns=["method", "mesh", "error", "cost", "spread"])


def test_budget_answer_by_hand():
    a = budget_answer(_frame(), [0.01, 0.05, 0.10], keep=("mesh",))
    by = {r["budget"]: r for r in a[a["answer"] == "fastest"].to_dict("records")}
    # 1 %: nobody's error is that small
    assert by[0.01]["method"] == NONE_WITHIN and by[0.01]["n_within"] == 0 and by[0.01]["tie"] is False
    # 5 %: A fine (1.0 s) against B (1.1 s): lead 1.1, spreads 0.2 and 0.05 -> 1.1 < 1.2, a tie
    b5 = by[0.05]
    assert (b5["method"], b5["mesh"], b5["runner_up"], b5["runner_up_mesh"]) == ("A", "fine", "B", "fine")
    assert b5["lead"] == pytest.approx(1.1) and b5["tie"] is True and b5["n_within"] == 2
    # 10 %: A coarse (0.3 s) leads C (0.5 s) by 5/3 > 1 + 0.1; B (1.1 s) third
    b10 = by[0.10]
    assert (b10["method"], b10["mesh"], b10["runner_up"]) == ("A", "coarse", "C")
    assert b10["lead"] == pytest.approx(5 / 3) and b10["tie"] is False and b10["n_within"] == 3
    assert b10["error"] == 0.09 and b10["cost"] == 0.3 and b10["spread"] == 0.1
    # D (error 50 %) and E (failed) meet no budget, listed once each
    none = a[a["answer"] == NO_BUDGET].set_index("method")
    assert sorted(none.index) == ["D", "E"]
    assert none.loc["D", "error"] == 0.5 and none.loc["D", "cost"] == 0.01 and np.isnan(none.loc["D", "budget"])
    assert np.isnan(none.loc["E", "error"])
    assert len(a) == 3 + 2


def test_budget_answer_alone_undetermined_and_named_columns():
    df = pd.DataFrame({"m": ["X", "Y", "Y"], "e_force": [0.04, 0.03, 0.01], "t": [2.0, 9.0, 30.0],
                       "s": [0.1, np.nan, 0.2]})
    a = budget_answer(df, [0.02, 0.05], error="e_force", cost="t", spread="s", method="m").set_index("budget")
    # 2 %: Y alone (its 30 s run): no runner-up, no tie
    assert a.loc[0.02, "method"] == "Y" and a.loc[0.02, "runner_up"] == "" and not a.loc[0.02, "tie"]
    assert np.isnan(a.loc[0.02, "lead"])
    # 5 %: X (2 s) before Y's cheaper run (9 s): lead 4.5, but Y's one timing has no spread
    assert (a.loc[0.05, "method"], a.loc[0.05, "runner_up"]) == ("X", "Y")
    assert a.loc[0.05, "lead"] == pytest.approx(4.5) and a.loc[0.05, "tie"] is pd.NA
    assert str(a["tie"].dtype) == "boolean"
