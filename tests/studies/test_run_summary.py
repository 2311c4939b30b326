"""The runner's summary counts every run asked for, computed or stored: a time-stepping run not
at rest within its step budget (a finding of the study that chose the budget) apart from the
failures, by study and reason; a non-finite result is a failure; a run's warnings are kept in its
row, not printed; an interrupt says "interrupted" once."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
from study_files import changed, small_study, write

from studies.sweep.runner import Interrupted, Runner, Summary, Task, compute, run_tasks
from studies.sweep.store import Store
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


@dataclasses.dataclass(frozen=True)
class OutOfMemory(StudyScene):
    """A study scene whose solve runs out of memory while ``flag`` (a file) exists."""

    flag: str = ""

    def solve(self, solver):
        from pathlib import Path

        if Path(self.flag).exists():
            raise MemoryError
        return super().solve(solver)


def test_a_memory_error_is_never_stored_and_a_rerun_computes_it(tmp_path):
    study = Study.from_toml(write(small_study(), tmp_path / "s.toml"))
    task = study.tasks()[0]
    flag = tmp_path / "no-memory"
    flag.touch()
    scene = OutOfMemory(**{f.name: getattr(task.scene, f.name) for f in dataclasses.fields(StudyScene)},
                        flag=str(flag))
    tasks = [Task(scene, task.solver, task.study)]
    store = Store(tmp_path / "out")
    first = Runner(jobs=1, progress=False)
    rows = run_tasks(tasks, store, runner=first)
    assert rows[0]["status"] == "out-of-memory" and "rerun computes it again" in rows[0]["message"]
    assert not store.has(tasks[0].key())  # the machine's limit is not the scene's answer
    assert (first.summary.computed, first.summary.failed, first.summary.failed_stored) == (1, 1, 0)
    flag.unlink()  # memory enough now: the rerun computes it, not a stored failure
    again = Runner(jobs=1, progress=False)
    rows = run_tasks(tasks, store, runner=again)
    assert rows[0]["status"] == "ok" and store.has(tasks[0].key())
    assert (again.summary.computed, again.summary.stored, again.summary.failed) == (1, 0, 0)


def test_a_rerun_says_why_a_stored_failure_is_not_computed_again(tmp_path):
    study = Study.from_toml(write(changed(small_study(), _cut), tmp_path / "s.toml"))
    tasks = [t for t in study.tasks() if t.scene.load_case == "heavy" and t.solver.kind == "static"][:1]
    assert tasks
    first = Runner(jobs=1, progress=False)
    run_tasks(tasks, Store(tmp_path / "out"), runner=first)
    assert first.summary.failed == 1 and "not computed again" not in first.summary.line()
    again = Runner(jobs=1, progress=False)
    run_tasks(tasks, Store(tmp_path / "out"), runner=again)
    assert again.summary.failed == again.summary.failed_stored == 1
    assert "1 of them stored by an earlier run and not computed again" in again.summary.line()
