"""The runner's summary counts every run asked for, computed or stored: a time-stepping run not
at rest within its step budget (a finding of the study that chose the budget) apart from the
failures, by study and reason; a non-finite result is a failure; a run's warnings are kept in its
row, not printed; an interrupt says "interrupted" once."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
from study_files import changed, small_study, write

from studies.runner import Interrupted, Runner, Summary, Task, compute, run_tasks
from studies.store import Store
from studies.study import Study
from studies.study.tasks import StudyScene


def _cut(d):
    d["model"].append({"name": "hybmss", "label": "cut", "solver": {"kind": "explicit", "dt": 1e-4, "steps": 5}})
    d["model"].append({"name": "hybmss", "label": "heavy"})
    d["load_case"].append({"name": "heavy", "gravity": [0.0, 0.0, -1e9],
                           "support": [{"name": "bottom", "region": "z-", "motion": "clamped"}]})


def test_not_at_rest_is_counted_apart_from_failures(tmp_path):
    study = Study.from_toml(write(changed(small_study(), _cut), tmp_path / "s.toml"))
    tasks = study.tasks()  # press: 3 models + FEM; heavy: 3 models (all fail: 1e9 g) + FEM
    runner = Runner(jobs=1, progress=False)
    run_tasks(tasks, Store(tmp_path / "out"), runner=runner)
    s = runner.summary
    # heavy: the two static runs fail; the explicit ones are not at rest (press after 5 steps) or fail
    rows = [Store(tmp_path / "out").row(t.key()) for t in tasks]
    not_at_rest = sum(r["status"] == "not-converged" and r["solver"] == "mss-explicit" for r in rows)
    failed = sum(r["status"] != "ok" for r in rows) - not_at_rest
    assert not_at_rest >= 1 and failed >= 2
    assert (s.runs, s.failed, s.expected) == (len(tasks), failed, not_at_rest)
    assert s.expected_by == {"small, not at rest within its step budget": not_at_rest}
    assert f"{failed} failed, {not_at_rest} without result as expected (small, not at rest" in s.line()
    again = Runner(jobs=1, progress=False)  # all stored: the same counts
    run_tasks(tasks, Store(tmp_path / "out"), runner=again)
    assert (again.summary.stored, again.summary.failed, again.summary.expected) == (len(tasks), failed, not_at_rest)


@dataclasses.dataclass(frozen=True)
class Breaking(StudyScene):
    """A study scene whose solve warns, and whose result is made non-finite on request."""

    spoil: bool = False

    def solve(self, solver):
        res = super().solve(solver)
        for _ in range(3):
            warnings.warn("invalid value encountered in divide", RuntimeWarning)
        if self.spoil:
            res.reactions["top"] = dataclasses.replace(res.reactions["top"], force=(0.0, 0.0, -np.inf))
        return res


def test_a_non_finite_result_is_a_failure_and_warnings_stay_in_the_row(tmp_path):
    study = Study.from_toml(write(small_study(), tmp_path / "s.toml"))
    task = study.tasks()[0]
    for spoil, status in ((False, "ok"), (True, "non-finite")):
        scene = Breaking(**{f.name: getattr(task.scene, f.name) for f in dataclasses.fields(StudyScene)}, spoil=spoil)
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            row, _ = compute(Task(scene, task.solver, task.study))
        assert row["status"] == status, row.get("message")
        assert row["warnings"] == "RuntimeWarning: invalid value encountered in divide (x3)"
        assert not [w for w in seen if "invalid value" in str(w.message)]  # not passed on to be printed
    assert "reaction of top" in row["message"]
    s = Summary()
    s.count(task, row, lambda t, r: False)
    assert s.failed == 1 and s.expected == 0


def test_an_interrupt_says_interrupted_once():
    assert not str(Interrupted(Summary(computed=3))).startswith("interrupted")
