"""Tables of the studies never show a value of a run that reached no result (an explicit run not
at rest, a lost equilibrium, a divergence): the stability study's tables and the verdict's
explicit cost, from rows stored the way the runner stores them."""

from __future__ import annotations

import types

import numpy as np
import pandas as pd
import pytest

from studies.paper import stability

from studies.paper import verdict
from studies.sweep.runner import SolverSpec, Task, no_result_because
from studies.sweep.scenes import SceneSpec
from studies.sweep.store import Store


def test_the_reason_of_no_result():
    assert no_result_because({"status": "ok", "message": ""}) == ""
    assert no_result_because({"status": "not-converged", "message": "", "solver": "mss-explicit",
                              "steps": 10_000}) == "not-converged: not at rest after 10000 steps"
    assert no_result_because({"status": "not-converged", "message": None, "solver": "mss-static"}) == \
        "not-converged: not converged"
    assert no_result_because({"status": "diverged", "message": "DivergenceError:  |v| >\n 1e6"}) == \
        "diverged: DivergenceError: |v| > 1e6"
    assert no_result_because(None) == "missing: not computed"


def test_the_extreme_table_shows_no_volume_change_of_a_run_not_at_rest(tmp_path):
    """Static and explicit runs of one scene, the explicit one stored not at rest with the volume
    change of its last state: only the static one's shows."""
    spec = SceneSpec.default("compression", mesh=(2, 2, 2), nu=0.25, deformation=0.2)
    tasks = [("b", Task(spec, stability.STATIC, "stability")),
             ("b", Task(spec.replace(damping=2.0), stability.PROTOCOL, "stability"))]
    rows = [{"key": "a" * 24, "status": "ok", "volume_change": -0.11, "inverted_cells": 0, "message": ""},
            {"key": "b" * 24, "status": "not-converged", "volume_change": -0.13, "inverted_cells": 0,
             "message": ""}]
    t = stability.extreme_table(Store(tmp_path), tasks, rows)
    assert list(t["status"]) == ["converged", "not-converged"]
    assert t["volume_change"].iloc[0] == -0.11 and np.isnan(t["volume_change"].iloc[1])


def _results(rows):
    return types.SimpleNamespace(rows=pd.DataFrame(rows), table=lambda name: None)


def test_the_verdict_prices_no_explicit_run_without_result():
    """a: 0.5 s for 10,000 steps = 50 µs a step; its dt_crit 4 ms gives the stable step 2 ms, so
    one simulated second costs 500 × 50 µs = 25 ms.  b diverged (after fewer steps than its
    10,000: elapsed / steps would be no time per step at all): no cost, its state says why."""
    base = {"solver": "mss-explicit", "nu": 0.25, "experiment": "compression", "mesh": "2x2x2",
            "solver_steps": 10_000, "elapsed_s": 0.5}
    rows = [{**base, "variant": "a", "status": "ok", "info": {"dt_crit": 4e-3}},
            {**base, "variant": "b", "status": "diverged", "info": {"dt_crit": 4e-3}, "elapsed_s": 0.01}]
    c = verdict.explicit_cost(_results(rows)).set_index("variant")
    assert c.loc["a", "us_per_step"] == pytest.approx(50.0) and c.loc["a", "cost"] == pytest.approx(0.025)
    assert c.loc["b", ["us_per_step", "dt_crit", "cost"]].isna().all()
    r = pd.DataFrame(verdict._cost_rows(_results(rows)))
    b = r[r["method"] == "b"]
    assert b["value"].isna().all() and (b["state"] == "failed (diverged)").all()
    a = r[r["method"] == "a"]
    assert a["value"].iloc[0] == pytest.approx(25.0) and a["state"].iloc[0] == "ok"


def test_the_verdict_prices_the_stepping_not_the_compilation():
    """A run whose elapsed time holds 3 s of kernel compilation on a cold cache (elapsed 3.5 s, of
    which the time loop took 0.5 s for 10,000 steps) costs what its stepping costs: 50 µs a step."""
    row = {"solver": "mss-explicit", "nu": 0.25, "experiment": "compression", "mesh": "2x2x2", "variant": "a",
           "status": "ok", "solver_steps": 10_000, "steps": 10_000, "elapsed_s": 3.5, "wall_time_s": 0.5,
           "info": {"dt_crit": 4e-3}}
    c = verdict.explicit_cost(_results([row])).set_index("variant")
    assert c.loc["a", "us_per_step"] == pytest.approx(50.0) and c.loc["a", "cost"] == pytest.approx(0.025)
    # two runs of the same kernel at other loads: the best time per step prices it
    slow = {**row, "elapsed_s": 1.0, "wall_time_s": 0.8}
    c = verdict.explicit_cost(_results([slow, row, slow])).set_index("variant")
    assert c.loc["a", "us_per_step"] == pytest.approx(50.0)
