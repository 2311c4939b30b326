"""Which runs of the publication's studies without result are findings of their study, counted
apart from the failures of the program (studies.sweep.outcomes.finding): real solves that lose
their equilibrium at a limit point, an explicit run at a step above its critical step, an engine's
damped run that leaves the physical range, against a Newton solve that fails on a positive
definite Hessian and an exception; the sweep's summary and the report's overview count alike."""

from __future__ import annotations

import pytest

from hybmss.experiments import SceneSpec
from hybmss.explicit import dt_crit
from hybmss.solve import StaticSolveError
from reports.sections.summary import overview
from studies.sweep.outcomes import expected_finding, finding
from studies.sweep.results import Results
from studies.sweep.runner import Runner, SolverSpec, Task, failure_row, run_tasks
from studies.sweep.store import Store


def _limit_point() -> Task:
    """hybmss at ν = 0 has κ = -E/... < 0: stretched by 20 % its volume term folds (a limit point)."""
    spec = SceneSpec.default("tension", mesh=(2, 2, 12), nu=0.0, deformation=0.2, model="hybmss")
    return Task(spec, SolverSpec("static"), "t")


def _above_critical_step() -> Task:
    """The 2³ cube (cells of 2.5 m) at ν = 1/4: dt_crit is about 0.7 s; a step of 5 s diverges."""
    spec = SceneSpec.default("compression", mesh=(2, 2, 2), nu=0.25, deformation=0.05, model="hybmss")
    return Task(spec, SolverSpec("explicit", dt=5.0, steps=200, ramp_time=1.0), "t")


def test_a_limit_point_and_a_divergence_are_findings_an_exception_is_a_failure(tmp_path):
    tasks = [_limit_point(), _above_critical_step()]
    runner = Runner(jobs=1, progress=False)
    store = Store(tmp_path)
    fold, blown = run_tasks(tasks, store, runner=runner, expected=expected_finding)
    assert (fold["status"], fold["failure_cause"]) == ("unstable", "limit-point"), fold.get("message")
    assert blown["status"] == "diverged", blown.get("message")
    assert dt_crit(_above_critical_step().scene.build()) < 5.0 / 2  # the premise: far above the critical step
    assert (finding(fold), finding(blown)) == ("unstable, limit-point", "diverged")
    s = runner.summary
    assert (s.runs, s.failed, s.expected) == (2, 0, 2)
    assert s.expected_by == {"t, unstable, limit-point": 1, "t, diverged": 1}
    assert "0 failed, 2 without result as expected (t, diverged: 1; t, unstable, limit-point: 1)" in s.line()
    # the default expectation (a user's experiment study) counts both as failures
    again = Runner(jobs=1, progress=False)
    run_tasks(tasks, store, runner=again)
    assert (again.summary.failed, again.summary.expected) == (2, 0)
    # the report's overview counts as the sweep did, by study and reason
    ov = overview(Results(tmp_path))
    assert (ov["n_ok"], ov["n_failed"], ov["n_findings"]) == (0, 0, 2)
    assert {(f["study"], f["reason"], f["n"]) for f in ov["findings_by"]} == {
        ("t", "unstable, limit-point", 1), ("t", "diverged", 1)}
    assert [(x["study"], x["failed"], x["findings"]) for x in ov["studies"]] == [("t", 0, 2)]


@pytest.mark.parametrize("cause", ["newton", "residual", None])
def test_a_solver_that_does_not_diagnose_instability_fails(cause):
    """Newton failing on a positive definite Hessian, a residual solve without certificate, a solve
    error without cause: failures of the program, as is an exception or a non-finite result."""
    row = {"solver": "mss-static", **failure_row(StaticSolveError("no equilibrium", cause=cause))}
    assert row["status"] == "unstable" and finding(row) == ""
    assert finding({"solver": "mss-static", **failure_row(ValueError("bad"))}) == ""
    assert finding({"solver": "mss-static", "status": "non-finite"}) == ""
    assert finding(None) == "" and finding({"status": "ok"}) == ""


def test_a_released_run_diverges_as_a_finding_only_where_known():
    """baudet2009 diverges released at ν >= 0.45 (studies.sweep.roles.RELEASED_DIVERGES); any other
    released divergence is a failure."""
    row = {"experiment": "released", "solver": "mss-explicit", "status": "diverged"}
    assert finding({**row, "model": "baudet2009", "nu": 0.45}) == "diverged"
    assert finding({**row, "model": "baudet2009", "nu": 0.3}) == ""
    assert finding({**row, "model": "hybmss", "nu": 0.499}) == ""


def test_an_engines_damped_run_that_diverges_names_its_cause():
    """mujoco-tet's damped rest run of the stretched 2×2×12 beam leaves the physical range at its
    step (as in the tension study): the error names the cause, so the run is a finding."""
    pytest.importorskip("mujoco")
    from hybmss.models import get

    spec = SceneSpec.default("tension", mesh=(2, 2, 12), nu=0.25, deformation=0.2, model="mujoco-tet")
    with pytest.raises(StaticSolveError) as e:
        get("mujoco-tet").solve_static(spec.build())
    assert e.value.cause == "diverged" and e.value.step > 0, str(e.value)
    assert finding({"solver": "mss-static", **failure_row(e.value)}) == "unstable, diverged"


def test_a_timing_run_not_at_rest_is_counted_apart_from_findings_and_failures(tmp_path):
    """The speed-against-error study times an explicit candidate by short runs of a fixed number of
    steps (pareto.repeat_pairs): not at rest, as asked.  Such a run is neither a result, nor a
    finding (the budget study's 'not at rest within its step budget' of a candidate), nor a failure;
    the same run without the timing flag, not at rest after the same steps, is a finding."""
    from reports.sections.failures import failures_table
    from studies.paper import pareto

    spec = SceneSpec.default("compression", mesh=(2, 2, 2), nu=0.25, deformation=0.05, model="hybmss",
                             damping=2.0)
    short = SolverSpec("explicit", dt=1e-3, steps=20, ramp_time=1.0)
    timing = Task(spec, SolverSpec("explicit", dt=1e-3, steps=20, ramp_time=1.0, timing=True), "pareto")
    budget = Task(spec, short, "pareto")
    assert timing.key() != budget.key()
    runner = Runner(jobs=1, progress=False)
    t_row, b_row = run_tasks([timing, budget], Store(tmp_path), runner=runner, expected=expected_finding)
    assert t_row["status"] == b_row["status"] == "not-converged"  # 20 ms of a 1 s ramp: not at rest
    assert (finding(t_row), finding(b_row)) == ("", "not at rest within its step budget")
    s = runner.summary
    assert (s.runs, s.failed, s.expected, s.timed) == (2, 0, 1, 1)
    assert s.expected_by == {"pareto, not at rest within its step budget": 1}
    assert "0 failed, 1 without result as expected (pareto, not at rest within its step budget: 1), " \
           "1 timing runs" in s.line()
    res = Results(tmp_path)
    ov = overview(res)
    assert (ov["n_ok"], ov["n_failed"], ov["n_findings"], ov["n_timed"]) == (0, 0, 1, 1)
    assert [(x["study"], x["failed"], x["findings"], x["timed"]) for x in ov["studies"]] == [("pareto", 0, 1, 1)]
    tab = failures_table(res)
    assert len(tab.rows) == 1 and "Not listed: 1 timing runs" in tab.caption
    # the list of runs: the timing run shows its time (its answer) and no state; the other, neither
    from reports.sections.runs import runs_table

    listed = {row[3][0]: row for row in runs_table(res, {}).rows}  # by the status column's text
    assert set(listed) == {"timing run", "not-converged"}
    assert listed["timing run"][6][0] not in ("", "–") and listed["timing run"][4][0] in ("", "–")
    assert listed["not-converged"][6][0] in ("", "–")
    # the study's own timing runs carry the flag where their state is no answer: explicit ones
    meta, cand = {"config": "c", "role": "candidate"}, Task(spec, pareto.PROTOCOL, "pareto")
    assert {t.solver.timing for _, t in pareto.repeat_pairs(meta, cand, "quick")} == {True}
    static = Task(spec.replace(damping=0.0), pareto.STATIC, "pareto")
    assert {t.solver.timing for _, t in pareto.repeat_pairs(meta, static, "quick")} == {False}
    with pytest.raises(ValueError, match="timing"):
        SolverSpec("static", timing=True)
    with pytest.raises(ValueError, match="timing"):
        SolverSpec("explicit", until_rest=True, timing=True)
