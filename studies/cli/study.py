"""``hybmss study``: a user's study file (docs/study-format.md) answered: its models against one
FEM reference, computed into a results folder (resumable), with cost, tables and a report."""

from __future__ import annotations

import time

from studies.sweep.runner import Runner
from studies.sweep.store import Store
from studies.cli.common import InputError, SolveFailure, working
from studies.cli.options import Options, integer

HELP = ("answer a study file (docs/study-format.md): its models against one FEM reference, with cost, tables "
        "and a report")


def add_options(parser, opts: Options) -> None:
    """The options of ``hybmss study``."""
    opts.add(parser, "file", metavar="FILE", help="the study file (.toml)")
    opts.add(parser, "--quick", action="store_true", help="the file's [body.quick] values (a smoke run)")
    opts.add(parser, "--out", default=None, metavar="DIR", help="results folder (default artifacts/studies/<name>)")
    opts.add(parser, "--jobs", type=integer, default=None,
             help="parallel runs, >= 1 (default: all cores, or the Dask cluster's threads)")
    opts.add(parser, "--scheduler", default=None, metavar="ADDRESS",
             help="address of a running dask scheduler, e.g. tcp://host:8786 (runs on that cluster)")
    opts.add(parser, "--no-report", action="store_true", help="tables only, no report")
    opts.add(parser, "--no-progress", action="store_true", help="no progress bar")


def study(args):
    """A study file: checked whole before any work (exit 2 naming the key, nothing written), its
    runs computed into ``--out`` (resumable), its tables and report written."""
    from studies.study import Study

    if args.jobs is not None and args.jobs < 1:
        raise InputError(f"--jobs {args.jobs} is not allowed: an integer >= 1 (parallel runs), or none for all cores")
    if args.out is not None and not str(args.out).strip():
        raise InputError("--out '' is not allowed: a results folder path is required")
    spec = Study.from_toml(args.file, quick=args.quick)
    out = args.out or f"artifacts/studies/{spec.name}"
    executor = "dask" if args.scheduler else "local"
    runner = Runner(executor, jobs=args.jobs, scheduler=args.scheduler, progress=not args.no_progress)
    Store(out).check_writable()
    t0 = time.perf_counter()
    with working():
        with runner:
            done = spec.run(out, jobs=args.jobs, runner=runner, progress=not args.no_progress)
        report = None if args.no_report or spec.experiment is not None else str(spec.report(out, pdf=True))
        tables = spec.tables(out) if spec.experiment is None else {}
    budget = [r for name, df in tables.items() if name.startswith("budget_")
              for r in df.astype(object).where(df.notna(), None).to_dict("records")]
    dynamics = _dynamics_budget(done.get("tables", {}))
    obj = {"study": spec.name, "title": spec.title, "out": str(out), "quick": args.quick,
           "summary": runner.summary.as_dict(), **done, "report": report, "budget": budget,
           "dynamics_budget": dynamics,
           "wall_time_s": time.perf_counter() - t0}
    if done.get("failed"):
        first = done["failures"][0]
        raise SolveFailure(f"{done['failed']} of {done['runs']} runs of study {spec.name} reached no result "
                           f"(first: {first}); tables{' and report' if report else ''} written in {out}; remedy: "
                           "change the failing model's solver or load, or list the kind of no result the study "
                           "expects in that model's expect_no_result (docs/study-format.md)", obj)
    return obj, _study_text(spec, out, runner.summary.line(), budget + dynamics, report, done)


def _dynamics_budget(paths: dict) -> list[dict]:
    """The rows of the written ``dynamics_budget_<case>`` tables (released transients)."""
    import pandas as pd

    frames = [pd.read_csv(p) for name, p in paths.items() if name.startswith("dynamics_budget_")]
    return [r for df in frames for r in df.astype(object).where(df.notna(), None).to_dict("records")]


def _period_line(b: dict) -> str:
    """One row of a released transient's budget table: the model that keeps its first period
    within the budget at the least wall time per simulated second, or the closest one."""
    head = f"  {b['load_case']} released: first period within {b['period_budget_pct']:g} %: "
    if b["answer"] != "fastest":
        if b["model"] is None:
            return head + "no model measured a period"
        return head + f"no model keeps it (closest: {b['model']}, {b['period_error_pct']:+.3g} %)"
    head += (f"{b['model']} at {b['cell_size_m']:g} m, {b['wall_per_simulated_s']:.3g} s per simulated s "
             f"(period {b['period_error_pct']:+.3g} %)")
    if b["runner_up"] is not None:
        head += f"; {b['lead']:.2f}x less than {b['runner_up']}"
    return head


def _budget_line(b: dict) -> str:
    """One row of a budget table on one line: the fastest model within a budget (or none), a model
    that meets no budget (its smallest error), a model without result (its reason)."""
    if "period_budget_pct" in b:
        return _period_line(b)
    if b["answer"] == "no result":
        return f"  {b['load_case']}: {b['method']} no result ({b.get('failure') or 'no run reached one'})"
    if b["answer"] != "fastest":
        err = b["error"]
        best = f"smallest error {err:.3g}" if err is not None else "no error measured"
        return f"  {b['load_case']}: {b['method']} {b['answer']} ({best})"
    head = f"  {b['load_case']}: u_rel_l2 <= {b['budget']:g}: "
    if not b["n_within"]:
        return head + "no model meets it"
    head += f"{b['method']} at {b['cell_size_m']:g} m, {b['cost']:.3g} s"
    if b["runner_up"]:
        tie = {True: "a tie", False: "not a tie"}.get(b["tie"], "tie undetermined")
        lead = f"{b['lead']:.2f}x" if b["lead"] is not None else "an unmeasured lead"
        head += f"; lead {lead} over {b['runner_up']} ({tie})"
    return head


def _study_text(spec, out, line: str, budget: list[dict], report, done: dict) -> str:
    lines = [f"{spec.title}", f"{out}: {line}"]
    lines += [_budget_line(b) for b in budget]
    lines += [f"  failed: {f}" for f in done.get("failures", [])]
    lines += [f"  no result, as expected: {f}" for f in done.get("expected_no_result", [])]
    lines.append(f"tables: {out}/tables/{spec.name}_*.csv" + (f"; report: {report}" if report else ""))
    return "\n".join(lines)
