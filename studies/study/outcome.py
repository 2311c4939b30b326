"""What a study's runs came to: a result, an expected non-answer, or a failure.

A run reaches no result when its stored row's ``status`` is not ``ok``
(:func:`studies.sweep.runner.no_result_because`).  Its kind is ``not-at-rest`` for a time-stepping run
that ended its step budget before rest (:func:`studies.sweep.outcomes.not_at_rest`), else its status
(``not-converged`` for a static solve, ``diverged``, ``unstable``, ``non-finite``, ``error``,
``not-representable``; ``missing`` when not stored).  A model's table may declare the kinds it
expects (``expect_no_result = ["not-at-rest"]``): such a run is counted apart, as a finding of the
study; any other run without result is a failure and ``hybmss study`` exits 3.  The counts here
are the ones the command prints, returns in ``--json`` and the report shows.  A released transient
(``release = true``) is a run too: its row of the stored ``dynamics_<load case>`` table without
result is a failure unless its kind is declared (:func:`studies.study.release.release_outcome`)."""

from __future__ import annotations

from pathlib import Path

from studies.sweep.outcomes import expected_not_at_rest, not_at_rest
from studies.sweep.runner import no_result_because
from studies.sweep.store import Store
from studies.study.keys import close
from studies.study.tasks import is_reference

NO_RESULT_KINDS = ("not-at-rest", "not-converged", "diverged", "unstable", "non-finite", "error",
                   "not-representable")
"""The kinds of no result a model's ``expect_no_result`` may list."""


def read_expected(t) -> tuple[str, ...]:
    """``expect_no_result`` of a ``[[model]]`` table (a :class:`studies.study.keys.Table`): a list
    of :data:`NO_RESULT_KINDS`, none by default."""
    value = t.raw("expect_no_result", [])
    if not isinstance(value, list) or not all(isinstance(v, str) and v in NO_RESULT_KINDS for v in value):
        bad = next((v for v in value if v not in NO_RESULT_KINDS), "") if isinstance(value, list) else value
        raise t.error("expect_no_result", value, f"a list of kinds of no result: {', '.join(NO_RESULT_KINDS)}"
                      f"{close(str(bad), NO_RESULT_KINDS)}")
    return tuple(dict.fromkeys(value))


def no_result_kind(row: dict | None) -> str:
    """``""`` for a result; else the kind of no result (module docstring)."""
    if no_result_because(row) == "":
        return ""
    if row is None:
        return "missing"
    return "not-at-rest" if not_at_rest(row) else str(row.get("status") or "missing")


def expectation(study):
    """``expected(task, row)`` for :meth:`studies.sweep.runner.Runner.run`: whether a run without result
    is one its model's ``expect_no_result`` declares (a reference never is); in an experiment
    study, a time-stepping run not at rest (:func:`studies.sweep.outcomes.expected_not_at_rest`)."""
    if study.experiment is not None:
        return expected_not_at_rest
    declared = {m.label: set(m.expect_no_result) for m in study.models}

    def expected(task, row) -> bool:
        kind = no_result_kind(row)
        return bool(kind) and not is_reference(task) and kind in declared.get(task.scene.label, ())

    return expected


def study_outcome(study, out) -> dict:
    """Over the study's runs (each stored run once): ``runs``, ``results``, ``failed`` and
    ``failures`` (``"<label> <cell size> m <load case>: <reason>"``), ``expected`` and
    ``expected_no_result`` (the same, for the non-answers the file declares)."""
    store = Store(Path(out))
    expected = expectation(study)
    seen: set[str] = set()
    failures, declared = [], []
    for task in study.tasks():
        key = task.key()
        if key in seen:
            continue
        seen.add(key)
        row = store.row(key) if store.has(key) else None
        why = no_result_because(row)
        if not why:
            continue
        line = f"{run_name(task)}: {why}"
        (declared if expected(task, row) else failures).append(line)
    from studies.study.release import release_outcome, released_runs  # the released transients' stored rows

    more, more_declared = release_outcome(study, out)
    failures, declared = failures + more, declared + more_declared
    runs = len(seen) + released_runs(study, out)
    return {"runs": runs, "results": runs - len(failures) - len(declared), "failed": len(failures),
            "failures": failures, "expected": len(declared), "expected_no_result": declared}


def run_name(task) -> str:
    """A run as the tables name it: its label, and in a study file its cell size and load case."""
    s = task.scene
    where = f" {s.cell_size:g} m {s.load_case}" if hasattr(s, "cell_size") and hasattr(s, "load_case") else ""
    return f"{s.label}{where}"


def outcome_line(outcome: dict) -> str:
    """The counts on one line, as the command and the report say them."""
    line = f"{outcome['results']} of {outcome['runs']} runs reached a result, {outcome['failed']} failed"
    if outcome["expected"]:
        line += f", {outcome['expected']} reached none as the study file expects"
    return line
