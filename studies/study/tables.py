"""The tables of a study, from its stored runs: per load case the errors of every model run
against its reference (:mod:`studies.study.metrics`), its cost beside its error, and the budget
answer (:func:`studies.sweep.cost.budget_answer`: the fastest model whose displacement field error
``u_rel_l2`` meets each budget, at its cheapest resolution within it, its lead over the next
fastest, a tie when the lead is below 1 + the larger spread or 1 +
:data:`studies.sweep.cost.TIMING_NOISE`); and the references (element,
refinement, own error estimate, time).

A run's time is its one timed solve (:func:`studies.study.tasks._single`: the run itself, or a
second solve where the worker process had one-time costs to pay first), its spread unknown; the
winner and runner-up of a budget answer whose lead is within the noise of single timings
(:data:`studies.study.tasks.RETIME_NOISE`) are timed again, the best of the study's ``repeats``
runs after an untimed one with their spread (median − best) / best (:class:`studies.sweep.cost.
Timing`), and a lead beyond that noise is no tie.  An explicit run's cost adds µs per step, its
dt_crit and the wall time of one simulated second at its dt and at the stable step."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from studies.sweep import cost
from studies.sweep.runner import no_result_because
from studies.sweep.store import Store
from studies.study.metrics import errors, support_radius
from studies.study.tasks import RETIME_NOISE, StudyScene, is_reference

BUDGET_ERROR = "u_rel_l2"
"""The error a budget bounds: the displacement field's relative L2 error against the FEM."""


def loaded_runs(study, out) -> list[dict]:
    """Every task of the study with its stored row and arrays (``None`` when not stored ok: a run
    that reached no result, e.g. an explicit run not at rest, has no field to measure); a run whose
    near tie was timed again (:func:`studies.study.tasks.near_ties`) with that timing's
    :data:`TIMING_FIELDS` in its row's ``info`` and ``time_retimed`` true."""
    store = Store(Path(out))
    runs = []
    for task in study.tasks():
        key = task.key()
        row = store.row(key) if store.has(key) else None
        ok = row is not None and row.get("status") == "ok"
        if ok and isinstance(task.scene, StudyScene) and not is_reference(task):
            again = replace(task, scene=replace(task.scene, retime=True)).key()
            timing = store.row(again) if store.has(again) else None
            if timing is not None and timing.get("status") == "ok":
                info = timing.get("info") or {}
                row = {**row, "info": {**(row.get("info") or {}), **{k: info.get(k) for k in TIMING_FIELDS},
                                       "time_retimed": True}}
        runs.append({"task": task, "key": key, "row": row, "arrays": store.arrays(key) if ok else None})
    return runs


TIMING_FIELDS = ("time_s", "time_median_s", "time_spread", "time_repeats", "time_first_run")
"""The fields of a run's ``info`` its re-timing replaces."""


def _config(task) -> tuple:
    s = task.scene
    m = s.build().material
    return (s.load_case, m.E, m.nu, m.rho, s.cell_size)


def error_rows(study, runs: list[dict]) -> list[dict]:
    refs = {_config(r["task"]): r for r in runs if is_reference(r["task"])}
    out = []
    for r in runs:
        task = r["task"]
        if is_reference(task):
            continue
        s, m = task.scene, task.scene.build().material
        row = {"load_case": s.load_case, "model": s.label, "cell_size_m": s.cell_size, "cells": s.build().body.n_cells,
               "E": m.E, "nu": m.nu, "rho": m.rho, "solver": task.solver.kind,
               "status": (r["row"] or {}).get("status", "missing"), "message": (r["row"] or {}).get("message", "")}
        ref = refs[_config(task)]
        if r["arrays"] is not None and ref["arrays"] is not None:
            plates, X = s.build().plates, r["arrays"]["X"]
            supports = {p.name: p.motion.kind for p in plates}
            radii = {p.name: support_radius(X, p.region.select(X, s.build().body), s.cell_size) for p in plates}
            row.update(errors(r, ref, study.metrics, s.cell_size, supports, radii))
        row.update(_cost(task, r["row"] or {}))
        row["failure"] = no_result_because(r["row"])
        if row["failure"]:  # the wall time of a run that reached no result is no cost of a result
            row.update({k: np.nan for k in NO_RESULT_COST if k in row})
        out.append(row)
    return out


NO_RESULT_COST = ("time_s", "time_median_s", "time_spread", "us_per_step", "wall_per_simulated_s",
                  "wall_per_simulated_s_stable")
"""The costs of a run that reached no result: not shown (NaN)."""


def _cost(task, row: dict) -> dict:
    """Best wall time, median and spread of the run's repeats; for an explicit run also µs per
    step, dt_crit and the wall time of one simulated second at the run's dt and at the stable step
    (:func:`studies.sweep.cost.stable_dt`)."""
    info = row.get("info", {}) or {}
    best = info.get("time_s", np.nan)
    out = {"time_s": best, "time_median_s": info.get("time_median_s", np.nan),
           "time_spread": info.get("time_spread", np.nan), "repeats": info.get("time_repeats", np.nan)}
    if task.solver.kind == "explicit":
        steps = row.get("steps") or task.solver.steps
        us = 1e6 * best / steps
        dt_crit = row.get("dt_crit", np.nan)
        out.update(us_per_step=us, dt_s=task.solver.dt, dt_crit_s=dt_crit, steps=steps,
                   wall_per_simulated_s=cost.cost_per_simulated_second(us, task.solver.dt),
                   wall_per_simulated_s_stable=cost.cost_per_simulated_second(us, cost.stable_dt(dt_crit))
                   if np.isfinite(dt_crit) else np.nan)
    return out


def budget_answer(rows: pd.DataFrame, budgets) -> pd.DataFrame:
    """Per material, :func:`studies.sweep.cost.budget_answer` of the runs (a model at several
    resolutions is one method: its cheapest run within the budget stands for it), on the
    displacement field error :data:`BUDGET_ERROR` and the best wall time."""
    keys = ["load_case", "E", "nu", "rho"]
    if rows.empty or BUDGET_ERROR not in rows:
        return pd.DataFrame()
    parts = []
    for cfg, grp in rows.groupby(keys, sort=False):
        ans = cost.budget_answer(grp, budgets, error=BUDGET_ERROR, cost="time_s", spread="time_spread",
                                 method="model", keep=("cell_size_m",),
                                 failure="failure" if "failure" in grp else None)
        # a lead beyond the noise of single timings is no tie; within it both were timed again
        ans.loc[ans["tie"].isna() & (ans["lead"] >= 1.0 + RETIME_NOISE), "tie"] = False
        for k, v in zip(keys, cfg):
            ans.insert(0, k, v)
        parts.append(ans[keys + [c for c in ans.columns if c not in keys]])
    return pd.concat(parts, ignore_index=True)


def reference_rows(runs: list[dict]) -> list[dict]:
    out = []
    for r in runs:
        if not is_reference(r["task"]):
            continue
        s, row = r["task"].scene, r["row"] or {}
        info = row.get("info", {}) or {}
        m = s.build().material
        out.append({"load_case": s.load_case, "cell_size_m": s.cell_size, "E": m.E, "nu": m.nu, "rho": m.rho,
                    "solver": row.get("solver"), "element": info.get("element"), "law": r["task"].solver.law,
                    "refine": info.get("reference_refine", info.get("refine")),
                    "error_estimate": info.get("reference_error_estimate"),
                    "error_basis": info.get("reference_error_basis"),
                    "error_target": info.get("reference_error_target"),
                    "time_s": info.get("time_s"), "status": row.get("status", "missing")})
    return out


ERROR_COLUMNS = ("model", "cell_size_m", "E", "nu", "rho", "status")
COST_COLUMNS = ("model", "cell_size_m", "solver", "time_s", "time_median_s", "time_spread", "us_per_step", "dt_s",
                "dt_crit_s", "wall_per_simulated_s", "wall_per_simulated_s_stable", BUDGET_ERROR)
COST_ONLY = COST_COLUMNS[3:-1]


def study_tables(study, out) -> dict[str, pd.DataFrame]:
    """``errors_<case>``, ``cost_<case>``, ``budget_<case>`` per load case, and ``reference``."""
    runs = loaded_runs(study, out)
    if study.tet_bodies:  # one reference on the tetrahedra (studies.study.tet_scores)
        from studies.study.tet_scores import tet_error_rows, tet_reference_rows

        rows, refs = pd.DataFrame(tet_error_rows(study, runs, _cost)), pd.DataFrame(tet_reference_rows(runs))
    else:
        rows, refs = pd.DataFrame(error_rows(study, runs)), pd.DataFrame(reference_rows(runs))
    tables = {}
    for case in study.load_cases:
        sub = rows[rows["load_case"] == case.name]
        err_cols = [c for c in sub.columns if c not in COST_ONLY and c not in
                    ("load_case", "cells", "repeats", "steps", "message", "solver", "failure")] + ["message"]
        tables[f"errors_{case.name}"] = sub[[c for c in err_cols if c in sub]].reset_index(drop=True)
        tables[f"cost_{case.name}"] = sub[[c for c in COST_COLUMNS if c in sub]].reset_index(drop=True)
        tables[f"budget_{case.name}"] = budget_answer(sub, study.budgets)
    tables["reference"] = refs
    return tables
