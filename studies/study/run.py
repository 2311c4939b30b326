"""Running a study: its tasks through :mod:`studies.runner` into a :class:`studies.store.Store`
(resumable: a stored run is not computed again; the machine's cores or a Dask cluster), then its
tables written under ``tables/``."""

from __future__ import annotations

from pathlib import Path

from ..runner import Runner, run_tasks
from ..store import Store
from .modes import modes_tables
from .tables import study_tables


def run_study(study, out, jobs=None, runner: Runner | None = None, progress: bool = True) -> dict:
    """Compute what is not stored yet, write the tables; returns what the sweep did and the
    tables' paths."""
    store = Store(Path(out))
    store.check_writable()
    tasks = study.tasks()
    rows = run_tasks(tasks, store, jobs=jobs, progress=progress, desc=study.name, runner=runner)
    failed = [r for r in rows if r.get("status") not in ("ok", "not-converged")]
    tables = study.tables(out) if study.experiment is None else {}
    tables.update(modes_tables(study))  # [metrics] modes: natural frequencies against the FEM's
    paths = {name: str(store.write_table(f"{study.name}_{name}", df)) for name, df in tables.items()}
    return {"runs": len(tasks), "failed": len(failed), "tables": paths,
            "failures": [f"{r.get('label')}: {r.get('message')}" for r in failed][:10]}


__all__ = ["run_study", "study_tables"]
