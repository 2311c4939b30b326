"""The experiments' tables are built from equilibria only: a store that also holds the dynamics
study's released transients (as after ``make reproduce-paper``) still gives them when a study
that lists no experiment task (``--study performance``) rewrites them from every stored run."""

from __future__ import annotations

import pandas as pd

import studies.paper.tables as tables
from hybmss.experiments import SceneSpec
from studies.sweep.runner import Runner, SolverSpec, Task, run_tasks
from studies.sweep.store import Store


def test_a_released_transient_in_the_store_is_left_out_of_the_experiment_tables(tmp_path, monkeypatch):
    spec = SceneSpec.default("compression", mesh=(2, 2, 2), nu=0.25, deformation=0.05, model="hybmss")
    store = Store(tmp_path)
    tasks = [Task(spec, SolverSpec("static"), "compression"),
             Task(spec, SolverSpec("fem", element="hex1", law="linear"), "compression")]
    run_tasks(tasks, store, runner=Runner(jobs=1, progress=False))
    stored = tables.runs_frame(store)
    released = stored[~stored["is_fem"]].assign(experiment="released", study="dynamics", key="released-run")
    monkeypatch.setattr(tables, "runs_frame", lambda store, keys=None: pd.concat([stored, released], ignore_index=True))
    monkeypatch.setattr(tables, "moduli_table", lambda store=None, runner=None: pd.DataFrame())
    out = tables.write_tables(store)  # every stored run, as with --study performance alone
    assert "released" not in set(out["runs"]["experiment"]) and len(out["runs"]) == len(stored)
    assert len(out["differences"]) == 1  # the model against its reference
