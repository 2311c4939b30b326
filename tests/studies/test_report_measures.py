"""The measures the report's verdicts rest on, against closed forms: where a damped error crosses
its tolerance, how ties are declared, which explicit equilibria count as a second one."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest


def test_tolerance_crossing_of_an_exponential_decay_is_where_it_crosses():
    """e(n) = exp(−n / 1000) crosses 1e-3 at n = 1000 ln 1000 = 6907.76; the checkpoints only
    bracket it (6000, 7000), and log-linear interpolation is exact for an exponential."""
    from studies.paper.stability import tolerance_crossing

    ns = np.array([1000, 2000, 4000, 6000, 7000, 8000, 10_000])
    steps, bracket = tolerance_crossing(ns, np.exp(-ns / 1000.0), 1e-3)
    assert int(steps) == int(np.ceil(1000 * np.log(1000))) == 6908
    assert bracket == "6000–7000"
    assert tolerance_crossing(ns, np.full(len(ns), 1e-4), 1e-3)[0] == "≤ 1000"
    assert tolerance_crossing(ns, np.full(len(ns), 1e-2), 1e-3)[0] == "> 10000"
    # a checkpoint that is not measured (NaN: diverged) is not within: the crossing comes after it
    es = np.exp(-ns / 1000.0)
    es[-1] = np.nan
    assert tolerance_crossing(ns, es, 1e-3)[0] == "> 10000"


def test_ranks_declare_ties_by_the_stated_margins():
    from studies.paper.verdict import BEST, NO_RESULT, TIE_COST, TIE_PP, TIED, WORSE, rank

    f = pd.DataFrame({"regime": "r", "quantity": "q", "unit": "%", "scene": "s",
                      "method": ["a", "b", "c", "d"], "value": [3.8, -3.8 - 0.99 * TIE_PP, 27.0, np.nan],
                      "state": ["ok", "ok", "ok", "failed (unstable)"]})
    assert list(rank(f)["rank"]) == [BEST, TIED, WORSE, NO_RESULT]
    f = f.assign(unit="ms/s", value=[1.0, 0.99 * TIE_COST, 1.01 * TIE_COST, np.nan])
    assert list(rank(f)["rank"]) == [BEST, TIED, WORSE, NO_RESULT]


def test_relative_l2_of_two_equilibria():
    from studies.paper.equilibria import NONUNIQUE_PCT, rel_l2_pct

    b = np.ones((8, 3))
    assert rel_l2_pct(1.3 * b, b) == pytest.approx(30.0)  # 30 % apart: flagged
    assert rel_l2_pct(1.3 * b, b) > NONUNIQUE_PCT > rel_l2_pct(1.01 * b, b)
    assert np.isnan(rel_l2_pct(b[:4], b)) and np.isnan(rel_l2_pct(b, 0 * b))


def test_a_scene_with_two_equilibria_is_marked_where_its_value_is_shown():
    """The stored pairs apart (explicit at rest vs static) mark that model's cell of that scene ‡,
    and only that one; a failed cell stays a failure."""
    from reports.tables import flagged as _flagged, nonunique_scenes

    class Stored:  # the one table nonunique_scenes reads
        def table(self, name):
            return pd.DataFrame({"method": ["hybmss-fd static", "hybmss static"], "experiment": "compression",
                                 "mesh": "10x10x10", "nu": [0.499, 0.499], "deformation": 0.2, "angle_deg": 0.0,
                                 "apart": [True, False]}) if name == "equilibria" else None

    flags = nonunique_scenes(Stored())
    row = pd.Series({"mesh": "10x10x10", "nu": 0.499, "deformation": 0.2})
    assert _flagged(("0.12", ""), flags, "hybmss-fd static", "compression", row, "deformation") == ("0.12 ‡", "twofold")
    assert _flagged(("0.12", ""), flags, "hybmss static", "compression", row, "deformation") == ("0.12", "")
    other = pd.Series({"mesh": "10x10x10", "nu": 0.25, "deformation": 0.2})
    assert _flagged(("3.1", ""), flags, "hybmss-fd static", "compression", other, "deformation") == ("3.1", "")
    assert _flagged(("failed (unstable)", "fail"), flags, "hybmss-fd static", "compression", row,
                    "deformation") == ("failed (unstable)", "fail")
