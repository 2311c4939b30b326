"""CI regression on error metrics: a quick subset of the publication's scenes (coarse meshes,
small deformations) whose errors against the FEM reference must not get worse.

The baseline ``studies/data/regression_baseline.csv`` holds, per case, the MSS error metrics
measured when it was last updated; ``studies/data/regression_tolerances.csv`` holds, per metric,
how much worse a value may get (``value ≤ baseline · (1 + rtol) + atol``).  Updating the
baseline is a reviewed change with a reason::

    python -m studies.paper.regression --update --reason "why the errors changed"

which rewrites the CSV and prints the differences.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
from importlib import resources
from pathlib import Path

import numpy as np
import pandas as pd

from hybmss import models
from hybmss.experiments import SceneSpec, experiment

from studies.sweep.compare import diff_metrics
from studies.sweep.runner import run_tasks
from studies.sweep.store import Store, atomic_write_text

METRICS = ("rel_l2", "volume_err_pp", "reaction_rel_err")
STUDY = "regression"
"""The driver study of :data:`studies.paper.reproduce.DRIVER_FILES`: its files
(``studies/data/studies/regression-*.toml``) declare the cases, the models (role ``regression``,
their defaults), the reference and the table."""


def cases() -> list[SceneSpec]:
    """The cases of the study files, in their order: the 4³ cube compressed and sheared 5 % and
    twisted 1°, the 2×2×12 beam pulled 5 % (each at ν = 0, 0.25, 0.499), the beam bending at
    E = 10 MPa."""
    from studies.paper.reproduce import DRIVER_STUDIES, load_study_file
    from studies.study.experiment import configurations

    return [c for f in DRIVER_STUDIES[STUDY].files for c in configurations(load_study_file(f), False)]


def _reaction(row) -> float:
    """The experiment's answer quantity (:attr:`hybmss.experiments.Experiment.answer`)."""
    return row[experiment(row["experiment"]).answer]


def _case(spec: SceneSpec) -> SceneSpec:
    """The configuration a run of ``spec`` belongs to (its model's parameters aside)."""
    return dataclasses.replace(spec, model=models.default_name(), params=())


def table_hook(h) -> pd.DataFrame:
    """Table hook ``regression`` (:class:`studies.paper.reproduce.HookInput`): one row of error
    metrics per (case, model), each static run against the FEM run of its configuration."""
    rows = {t.key(): r for t, r in zip(h.tasks, h.rows)}
    fem = {_case(t.scene): t for t in h.tasks if t.solver.kind == "fem"}
    out = []
    for t in h.tasks:
        if t.solver.kind == "fem":
            continue
        spec, m, ft = t.scene, t.scene.model, fem[_case(t.scene)]
        rm, rf = rows[t.key()], rows[ft.key()]
        case = f"{spec.experiment} {'x'.join(map(str, spec.mesh))} nu={spec.nu:g}"
        if rm["status"] != "ok" or rf["status"] != "ok":
            out.append({"case": case, "model": m, "status": f"{rm['status']}/{rf['status']}",
                        **{k: np.nan for k in METRICS}})
            continue
        a, b = h.store.arrays(t.key()), h.store.arrays(ft.key())
        d = diff_metrics(a["X"], a["u"], b["u"])
        ref = _reaction(rf)
        out.append({
            "case": case, "model": m, "status": "ok",
            "rel_l2": d["rel_l2"],
            "volume_err_pp": 100 * abs(rm["volume_change"] - rf["volume_change"]),
            "reaction_rel_err": abs(_reaction(rm) - ref) / abs(ref) if ref else np.nan,
        })
    return pd.DataFrame(out)


def measure(store: Store | None = None, jobs: int | None = 1, progress: bool = False) -> pd.DataFrame:
    """Run the cases of the study files (each model's static run, the FEM) and return their
    table (:func:`table_hook`): one row of error metrics per (case, model)."""
    from studies.paper.reproduce import DRIVER_STUDIES, file_study_tables

    tmp = None
    if store is None:
        tmp = tempfile.TemporaryDirectory(prefix="hybmss-regression-")
        store = Store(tmp.name)
    try:
        tasks = DRIVER_STUDIES[STUDY](False)
        rows = run_tasks(tasks, store, jobs=jobs, progress=progress, desc="regression")
        return file_study_tables(STUDY, tasks, rows, False, store=store)["regression"]
    finally:
        if tmp is not None:
            tmp.cleanup()


def _data_path(name: str) -> Path:
    return Path(str(resources.files("studies").joinpath("data", name)))


def load_baseline() -> pd.DataFrame:
    return pd.read_csv(_data_path("regression_baseline.csv"), comment="#")


def load_tolerances() -> dict[str, tuple[float, float]]:
    t = pd.read_csv(_data_path("regression_tolerances.csv"), comment="#")
    return {r.metric: (float(r.rtol), float(r.atol)) for r in t.itertuples()}


def unbaselined(current: pd.DataFrame, baseline: pd.DataFrame) -> list[str]:
    """Models measured now that have no row in the baseline at all (a model added to the
    registry, or another package's): nothing to regress from until a baseline is recorded."""
    return sorted(set(current["model"]) - set(baseline["model"]))


def regressions(current: pd.DataFrame, baseline: pd.DataFrame, tolerances) -> list[str]:
    """Human-readable list of the metrics that got worse than allowed (empty: all good).  Rows of
    :func:`unbaselined` models are not compared."""
    current = current[~current["model"].isin(unbaselined(current, baseline))]
    merged = baseline.merge(current, on=["case", "model"], how="outer", suffixes=("_base", "_now"),
                            indicator="where")
    problems = []
    for r in merged.itertuples():
        if r.where != "both":
            problems.append(f"{r.case} / {r.model}: present only in the {'baseline' if r.where == 'left_only' else 'current run'}")
            continue
        if r.status_now != r.status_base:
            problems.append(f"{r.case} / {r.model}: status {r.status_base} -> {r.status_now}")
            continue
        for m in METRICS:
            base, now = getattr(r, f"{m}_base"), getattr(r, f"{m}_now")
            if np.isnan(base) and np.isnan(now):
                continue
            rtol, atol = tolerances[m]
            if not (now <= base * (1 + rtol) + atol):
                problems.append(f"{r.case} / {r.model}: {m} {now:.4g} > baseline {base:.4g} (rtol {rtol}, atol {atol})")
    return problems


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m studies.paper.regression", description=__doc__.split("\n\n")[0])
    p.add_argument("--update", action="store_true", help="rewrite the baseline (needs --reason)")
    p.add_argument("--reason", default="", help="why the baseline changes (kept in the file's header)")
    args = p.parse_args(argv)
    now = measure(progress=True)
    if args.update:
        if not args.reason.strip():
            p.error("--update needs --reason")
        header = f"# Regression baseline of MSS errors against the linear FEM (Hex2, mixed at nu >= 0.45). Reason of last update: {args.reason.strip()}\n"
        atomic_write_text(_data_path("regression_baseline.csv"), header + now.to_csv(index=False, float_format="%.6g"))
        print(now.to_string(index=False))
        return 0
    base = load_baseline()
    problems = regressions(now, base, load_tolerances())
    for m in unbaselined(now, base):
        print(f"model {m}: no baseline yet (measured, not compared; record one with --update --reason)")
    print("\n".join(problems) if problems else "no regression")
    return 1 if problems else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
