"""A study's released transients (``release = true`` in a load case): per material and cell size
the body held at static equilibrium under the load case's gravity and tractions, released at t = 0,
stepped by every model's own integrator and by the FEM (:mod:`studies.sweep.transients`), as the tables
``dynamics_<load case>`` and ``dynamics_budget_<load case>``.

After the release the load is gone and the supports hold what they held; each model's nodes obey
``m ẍ = f(x)`` from its own static answer, the FEM ``M ü + f_int(u) = 0`` (Newmark average
acceleration, Hex2, or Hex1 when the study's reference element is Hex1, at a step whose own period
error, checked by halving, is below :data:`FEM_PERIOD_TOL`).  A model steps at the step a user would
pick (:func:`hybmss.released.user_step`: its own integrator at 0.9 of its stability limit; an engine
at 1/60 s frames cut into its substeps, with the parameters its user picks for dynamics when the
study gives it none).  The tracked point is ``[metrics] point`` (a name of ``[metrics.points]``),
else the lattice particle of largest static displacement of the FEM.  The run lasts ``periods``
first periods of the FEM (its Rayleigh estimate; default :data:`PERIODS`) or ``release_time``
seconds; the phase error is taken after the last whole period.

Per model: its integrator, ``dt``, the period error ``100 (T/T_FEM − 1)`` %, the damping ratio ζ
(log decrement), the phase error (rad), the L2 trajectory error (relative to the static deflection
of the point) and the wall time per simulated second, beside the FEM's own period error estimate.
A model that cannot run has a row with its kind of no result and the reason (counted by
:func:`release_outcome`).  The budget table answers, per material and budget ``x`` (the study's
``budgets``), which model keeps its first period within ``x`` at the least wall time per simulated
second.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

PERIODS = 5
"""First periods a released run lasts unless the load case says otherwise."""
MAX_PERIODS = 100
MAX_RELEASE_TIME = 100.0
"""Longest ``release_time`` (s)."""
FEM_PERIOD_TOL = 1e-3
"""The FEM transient's own period error bound (checked by halving its step)."""
COLUMNS = ("model", "model_name", "cell_size_m", "E", "nu", "rho", "integrator", "dt_s", "substeps", "point",
           "period_s", "period_ref_s", "period_error_pct", "zeta", "zeta_ref", "phase_error_rad",
           "phase_periods", "l2_error", "wall_per_simulated_s", "fem_dt_s", "fem_period_error_pct",
           "fem_wall_per_simulated_s", "load_average", "status", "reason")
BUDGET_COLUMNS = ("load_case", "E", "nu", "rho", "period_budget_pct", "answer", "model", "cell_size_m", "period_error_pct",
                  "wall_per_simulated_s", "n_within", "runner_up", "lead")


@dataclass(frozen=True)
class Release:
    """``release = true`` of a load case: how long to step, ``periods`` or ``release_time`` (s)."""

    periods: int = PERIODS
    release_time: float | None = None


def read_release(t, gravity, tractions) -> Release | None:
    """``release``, ``periods`` and ``release_time`` of a ``[[load_case]]`` table: refused unless
    the load case has a load to remove (gravity or a traction); at most one of the two lengths."""
    release = t.flag("release", False)
    for key in ("periods", "release_time"):
        if t.has(key) and not release:
            raise t.error(key, t.raw(key), "only with release = true")
    if not release:
        return None
    if not any(g != 0.0 for g in gravity) and not tractions:
        raise t.error("release", True, "only for a load case with a load that can be removed: a non-zero gravity "
                      "or a traction")
    if t.has("periods") and t.has("release_time"):
        raise t.error("release_time", t.raw("release_time"), "absent when periods is given (one length of the run)")
    if t.has("release_time"):
        return Release(release_time=t.number("release_time", lo=0.0, lo_open=True, hi=MAX_RELEASE_TIME))
    return Release(periods=int(t.number("periods", PERIODS, lo=1, hi=MAX_PERIODS, integer=True)))


def read_point(t, points, cases) -> str | None:
    """``[metrics] point``: the name of one of ``[metrics.points]``, only with a released load case."""
    if not t.has("point"):
        return None
    value = t.raw("point")
    names = [k for k, _ in points]
    if not isinstance(value, str) or value not in names:
        raise t.error("point", value, f"the name of a point of metrics.points ({', '.join(names) or 'none given'})")
    if not any(c.release for c in cases):
        raise t.error("point", value, "only with a load case that has release = true (the point a released "
                      "transient tracks)")
    return value


def _row_of(trial: dict) -> dict:
    """A table row from :func:`studies.sweep.transients.model_row`'s ``trial``."""
    err = trial.get("period_error")
    reason = trial.get("reason") or ""
    status = trial.get("status") or ("ok" if not reason else "error")
    if status == "failed" or (reason and status == "ok"):
        status = "error"  # the stepper stopped, or no period to measure
    if "nodes are not the lattice particles" in reason:
        status = "not-representable"
    return {"integrator": trial.get("integrator"), "dt_s": trial.get("dt"), "substeps": trial.get("substeps"),
            "period_s": trial.get("period"), "period_ref_s": trial.get("period_ref"),
            "period_error_pct": None if err is None else 100.0 * err, "zeta": trial.get("zeta"),
            "zeta_ref": trial.get("zeta_ref"), "phase_error_rad": trial.get("phase_error_rad"),
            "l2_error": trial.get("l2_error"),
            "wall_per_simulated_s": trial.get("wall_per_simulated_s") if not reason else None,
            "status": status, "reason": reason}


def _fem(scene, study, case, name_point):
    """The FEM reference transient of ``scene`` and its figures, or why it failed."""
    from fem_reference.transient import ReleasedFem

    from studies.sweep.transients import fem_transient, largest_static_point

    rel, ref = case.release, study.reference
    element = "hex1" if ref.element == "hex1" else "hex2"
    law = ref.law if ref.law in ("linear", "neo-hookean") else "linear"
    refine = ref.refine if isinstance(ref.refine, int) else 1
    try:
        point = name_point or largest_static_point(ReleasedFem(scene, element, law, refine))
        tr = fem_transient(scene, point, rel.periods + 0.5, FEM_PERIOD_TOL, element, law, refine,
                           t_end=rel.release_time)
    except (ValueError, RuntimeError, ArithmeticError) as exc:
        return f"the FEM transient failed ({element}, {law}): {' '.join(str(exc).split())}"
    return tr


def _phase_periods(tr, rel) -> int:
    from studies.sweep.dynamics import trajectory_oscillation

    if rel.release_time is None:
        return rel.periods
    T = trajectory_oscillation(tr).period
    return max(1, int(tr.t_end / T - 0.5))


def _case_rows(study, case, mat, le, fem_scene, runs) -> list[dict]:
    from studies.sweep.transients import model_row

    named = dict(study.metrics.points).get(study.metrics.point) if study.metrics.point else None
    by_label = {m.label: m for m in study.models}
    ref = _fem(fem_scene, study, case, named)
    load0 = os.getloadavg()[0]
    rows = []
    for label, scene in runs:
        run = by_label[label]
        head = {"model": label, "model_name": run.name, "cell_size_m": le, "E": mat.E, "nu": mat.nu, "rho": mat.rho}
        if isinstance(ref, str):
            rows.append({**head, "status": "error", "reason": ref})
            continue
        check = ref.info["dt_check"]
        n = _phase_periods(ref, case.release)
        try:
            trial = model_row(scene, scene.model if run.params else run.name, ref, ref.point, n)
        except Exception as exc:  # noqa: BLE001 - a model's own failure is its row, counted as a failure
            trial = {"status": "error", "reason": f"{type(exc).__name__}: {exc}".splitlines()[0]}
        rows.append({**head, **_row_of(trial), "point": " ".join(f"{c:.6g}" for c in ref.point),
                     "phase_periods": n, "fem_dt_s": check["dt"],
                     "fem_period_error_pct": 100.0 * check["period_error_estimate"],
                     "fem_wall_per_simulated_s": ref.wall_per_simulated_second(), "load_average": load0})
    return rows


def budget_table(df: pd.DataFrame, budgets, case: str) -> pd.DataFrame:
    """Per material and budget ``x``: the model whose ``|period error|`` is within ``100 x`` % at
    the least wall time per simulated second (a model at several cell sizes stands by its cheapest
    run within), the next one and the lead (its wall time over the answer's); ``none`` when no
    model keeps it (then the model of the smallest period error is named)."""
    out = []
    ok = df[(df["status"] == "ok") & df["period_error_pct"].notna() & df["wall_per_simulated_s"].notna()]
    for (E, nu, rho), grp in df.groupby(["E", "nu", "rho"], sort=False):
        g = ok[(ok["E"] == E) & (ok["nu"] == nu) & (ok["rho"] == rho)]
        for b in budgets:
            head = {"load_case": case, "E": E, "nu": nu, "rho": rho, "period_budget_pct": 100.0 * b}
            within = g[g["period_error_pct"].abs() <= 100.0 * b].sort_values("wall_per_simulated_s")
            within = within.drop_duplicates("model")
            if within.empty:
                best = g.loc[g["period_error_pct"].abs().idxmin()] if len(g) else None
                out.append({**head, "answer": "none", "n_within": 0,
                            "model": None if best is None else best["model"],
                            "cell_size_m": None if best is None else best["cell_size_m"],
                            "period_error_pct": None if best is None else best["period_error_pct"],
                            "wall_per_simulated_s": None if best is None else best["wall_per_simulated_s"]})
                continue
            first = within.iloc[0]
            second = within.iloc[1] if len(within) > 1 else None
            out.append({**head, "answer": "fastest", "model": first["model"], "cell_size_m": first["cell_size_m"],
                        "period_error_pct": first["period_error_pct"],
                        "wall_per_simulated_s": first["wall_per_simulated_s"], "n_within": len(within),
                        "runner_up": None if second is None else second["model"],
                        "lead": None if second is None else
                        second["wall_per_simulated_s"] / first["wall_per_simulated_s"]})
    return pd.DataFrame(out, columns=list(BUDGET_COLUMNS))


def dynamics_tables(study) -> dict[str, pd.DataFrame]:
    """``dynamics_<case>`` and ``dynamics_budget_<case>`` of every load case with ``release = true``."""
    if study.experiment is not None or not any(c.release for c in study.load_cases):
        return {}
    from studies.study.modes import _configs

    cases = {c.name: c for c in study.load_cases if c.release}
    rows: dict[str, list] = {name: [] for name in cases}
    for (case, mat, le), (fem_scene, runs) in _configs(study).items():
        if case in cases:
            rows[case] += _case_rows(study, cases[case], mat, le, fem_scene, runs)
    out = {}
    for name, r in rows.items():
        df = pd.DataFrame(r, columns=list(COLUMNS))
        out[f"dynamics_{name}"] = df
        out[f"dynamics_budget_{name}"] = budget_table(df, study.budgets, name)
    return out


def release_outcome(study, out) -> tuple[list[str], list[str]]:
    """The released runs without result in the stored ``dynamics_<case>`` tables: ``(failures,
    declared)`` as ``"<label> <cell size> m <case> released: <reason>"``; a run is declared when its
    model's ``expect_no_result`` lists its kind (``diverged``, ``error``, ``not-representable``)."""
    failures, declared = [], []
    expect = {m.label: set(m.expect_no_result) for m in study.models}
    for case in study.load_cases:
        path = Path(out) / "tables" / f"{study.name}_dynamics_{case.name}.csv"
        if not case.release or not path.exists():
            continue
        df = pd.read_csv(path)
        for r in df.to_dict("records"):
            if r["status"] == "ok":
                continue
            reason = r["reason"] if isinstance(r["reason"], str) and r["reason"] else r["status"]
            line = f"{r['model']} {r['cell_size_m']:g} m {case.name} released: {reason}"
            (declared if r["status"] in expect.get(r["model"], ()) else failures).append(line)
    return failures, declared


def released_runs(study, out) -> int:
    """Rows of the stored ``dynamics_<case>`` tables (each a released run)."""
    n = 0
    for case in study.load_cases:
        path = Path(out) / "tables" / f"{study.name}_dynamics_{case.name}.csv"
        if case.release and path.exists():
            n += len(pd.read_csv(path))
    return n


