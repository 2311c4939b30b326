"""What a run came to, from its result or its stored row: the outputs of a result that are not
finite (such a result is no result), a run's warnings on one line (kept in its row), and whether
a run without result is a time-stepping run not at rest within its step budget (a finding of the
study that chose the budget, counted apart from the failures) or a timing run (:func:`timing_run`:
not at rest as asked, counted apart from both)."""

from __future__ import annotations

import numpy as np

from studies.sweep.roles import RELEASED_DIVERGES

TIME_STEPPING = ("mss-explicit", "mss-implicit")
"""The solver labels of the runs that stop after their step budget, at rest or not."""


def not_at_rest(row: dict | None) -> bool:
    """A time-stepping run that did not come to rest within its step budget: a finding of the
    study that chose the budget (no result, but no program failure either)."""
    return row is not None and row.get("status") == "not-converged" and row.get("solver") in TIME_STEPPING


def timing_run(row: dict | None) -> bool:
    """A run asked for its time per step alone (``solver_timing``: a candidate's short timed runs)
    that ended not at rest, as it was asked to: its state is no answer and none was sought, so it
    is counted apart, neither a result, nor a finding, nor a failure.  One that diverged is not."""
    return row is not None and bool(row.get("solver_timing")) and row.get("status") == "not-converged"


def expected_not_at_rest(task, row: dict | None) -> bool:
    """A sweep's default expectation (a user's experiment study keeps it): a run without result is
    expected when it is a time-stepping run not at rest (:func:`not_at_rest`: a run given a step
    budget on purpose); any other is a failure.  The publication's studies expect more
    (:func:`expected_finding`)."""
    return not_at_rest(row)


FINDING_CAUSES = ("limit-point", "unstable-path", "indefinite-at-rest", "implicit-step", "rest-state",
                  "diverged")
"""The causes of a failed static or implicit solve (:data:`hybmss.solve.CAUSES`) that diagnose a
loss of stability of the model at its load or step: a limit point (a κ < 0 body dilated past its
fold), an unstable path or a body indefinite at rest (the constrained Hessian is not positive
definite), an implicit step too long for Newton, a model's damped rest run that did not settle in
its time budget or left the physical range at its step.  Not among them: ``newton`` (the Hessian
stays positive definite and Newton did not converge) and ``residual`` (no certificate either way):
failures of the solver, not findings."""


def finding(row: dict | None) -> str:
    """Why a stored run of the publication's studies without result is a finding of the study, on a
    few words (``""`` for a result and for a failure of the program): a time-stepping run not at
    rest within its step budget; an explicit run that left the physical range at the study's step
    (status ``diverged``); a solve whose failure names one of :data:`FINDING_CAUSES`.  A released
    transient (experiment ``released``) diverges as a finding only where
    :data:`studies.sweep.roles.RELEASED_DIVERGES` says it does.  Everything else without result
    (an exception, a non-finite result, a scene an engine cannot represent, Newton not converging
    on a positive definite Hessian, a run missing) is a failure.  A timing run not at rest
    (:func:`timing_run`) is neither: ``""``, and counted apart by whoever counts.  Reads the row's
    fields only, so the sweep's summary and the report count alike."""
    if row is None or row.get("status") == "ok" or timing_run(row):
        return ""
    if not_at_rest(row):
        return "not at rest within its step budget"
    status = row.get("status")
    if row.get("experiment") == "released":
        nu = RELEASED_DIVERGES.get(row.get("model"))
        known = nu is not None and status == "diverged" and float(row.get("nu", -1.0)) >= nu
        return "diverged" if known else ""
    if status == "diverged":
        return "diverged"
    cause = row.get("failure_cause")
    if status == "unstable" and isinstance(cause, str) and cause in FINDING_CAUSES:
        return f"unstable, {cause}"
    return ""


def expected_finding(task, row: dict | None) -> bool:
    """The publication's studies' expectation (``expected`` of :meth:`studies.sweep.runner.Runner.run`):
    a run without result is expected when it is one of their findings (:func:`finding`)."""
    return bool(finding(row))


def non_finite(res) -> str:
    """The outputs of a result that are not finite numbers (displacements, reactions, volume
    change), named on one line; ``""`` when every one is finite.  Such a result is no result."""
    bad = []
    if not np.isfinite(np.asarray(res.u, dtype=float)).all():
        bad.append("displacements")
    for name, r in res.reactions.items():
        values = np.concatenate([np.asarray(r.force, dtype=float), np.asarray(r.torque, dtype=float)])
        if not np.isfinite(values).all():
            bad.append(f"reaction of {name}")
    if not np.isfinite(float(res.volume_change)):
        bad.append("volume change")
    return ", ".join(bad)


def warning_lines(caught) -> str:
    """The distinct warnings of a run, each with its count, on one line (``"; "`` between)."""
    counts: dict[str, int] = {}
    for w in caught:
        text = f"{w.category.__name__}: {' '.join(str(w.message).split())}"
        counts[text] = counts.get(text, 0) + 1
    return "; ".join(f"{t} (x{n})" for t, n in counts.items())
