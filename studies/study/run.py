"""Running a study: its tasks through :mod:`studies.sweep.runner` into a :class:`studies.sweep.store.Store`
(resumable: a stored run is not computed again; the machine's cores or a Dask cluster), then its
tables written under ``tables/``."""

from __future__ import annotations

from pathlib import Path

from studies.sweep.runner import Runner, run_tasks
from studies.sweep.store import Store
from studies.study.modes import modes_tables
from studies.study.outcome import expectation, study_outcome
from studies.study.release import dynamics_tables
from studies.study.tables import study_tables
from studies.study.tasks import given_predictions, near_ties, predictor_sweeps


def run_study(study, out, jobs=None, runner: Runner | None = None, progress: bool = True) -> dict:
    """Compute what is not stored yet, time again the runs of the budget answers' near ties
    (:func:`studies.study.tasks.near_ties`), write the tables; returns the tables' paths and what the
    runs came to (:func:`studies.study.outcome.study_outcome`: the runs without result that were
    not expected are ``failed``, each in ``failures``)."""
    store = Store(Path(out))
    store.check_writable()
    tasks = study.tasks()
    for step in predictor_sweeps(tasks):  # the coarser references that predict the finer ones
        keys = {t.key() for t in step}
        step = [t for t in tasks if t.key() in keys]  # with the predictions of the steps before
        rows = run_tasks(step, store, jobs=jobs, progress=progress, desc=f"{study.name} (coarser references)",
                         runner=runner, expected=expectation(study))
        tasks = given_predictions(tasks, {t.key(): row for t, row in zip(step, rows)})
    run_tasks(tasks, store, jobs=jobs, progress=progress, desc=study.name, runner=runner,
              expected=expectation(study))
    tables = study.tables(out) if study.experiment is None else {}
    done: set[str] = set()
    while study.experiment is None:  # re-time the near ties (a new best may make a new pair)
        again = near_ties(tasks, [df for name, df in tables.items() if name.startswith("budget_")], done)
        if not again:
            break
        done |= {t.key() for t in again}
        run_tasks(again, store, jobs=jobs, progress=progress, desc=f"{study.name} (near ties timed again)",
                  runner=runner)
        tables = study.tables(out)
    tables.update(modes_tables(study))  # [metrics] modes: natural frequencies against the FEM's
    tables.update(dynamics_tables(study))  # release = true: released transients against the FEM's
    paths = {name: str(store.write_table(f"{study.name}_{name}", df)) for name, df in tables.items()}
    return {**study_outcome(study, out), "tables": paths}


__all__ = ["run_study", "study_tables"]
