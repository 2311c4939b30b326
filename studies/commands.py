"""Study subcommands of the ``hybmss`` command: ``compare`` and ``run``."""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time

import numpy as np

from hybmss.cli import CliError, emit, mesh_arg
from hybmss import models

from .compare import default_law, diff_metrics
from .executors import EXECUTORS, SweepError
from .runner import Runner, SolverSpec, Task, exit_now, measure, solve
from .scenes import EXPERIMENTS, SceneSpec
from .store import Store


def _spec_from_args(args) -> SceneSpec:
    over = dict(mesh=args.mesh, E=args.E, nu=args.nu, rho=args.rho, model=args.model, A=args.A,
                deformation=args.deformation, angle_deg=args.angle)
    if args.e_form:
        over["e_form"] = True
    if args.scene == "bending":
        over["gravity"] = args.gravity if args.gravity is not None else 10.0
    return SceneSpec.default(args.scene, **over)


def _side(spec: SceneSpec, result) -> dict:
    row = measure(spec, result)
    plate = "bottom" if spec.experiment == "bending" else "top"
    out = {
        "solver": result.solver,
        "volume_change": row["volume_change"],
        "max_displacement": row["max_displacement"],
        "wall_time_s": row["wall_time_s"],
        "converged": row["converged"],
    }
    if plate in result.reactions:
        out["reaction_force"] = list(result.reactions[plate].force)
        out["reaction_torque"] = list(result.reactions[plate].torque)
    if spec.experiment == "bending":
        out["tip_deflection"] = row["tip_deflection"]
    for k in ("inverted_cells", "volume_avg_edges", "volume_lnJ", "dt_crit"):
        if k in result.info:
            out[k] = result.info[k]
    return out


def cmd_compare(args) -> int:
    spec = _spec_from_args(args)
    law = args.law or default_law(spec)
    mss_solver = SolverSpec(kind=args.solver, dt=args.dt, steps=args.steps, ramp_time=args.ramp_time)
    fem_solver = SolverSpec(kind="fem", element=args.fem, law=law, refine=args.refine)
    t0 = time.perf_counter()
    mss = solve(Task(spec, mss_solver))
    fem = solve(Task(spec, fem_solver))
    d = diff_metrics(mss.X, mss.u, fem.u)
    out = {"scene": spec.to_dict(), "mss": _side(spec, mss), "fem": _side(spec, fem), "diff": d}
    if spec.experiment == "bending":
        out["euler_bernoulli_tip"] = spec.euler_bernoulli_tip()
    out["wall_time_s"] = time.perf_counter() - t0
    lines = [f"{spec.label}   (FEM: {fem.solver})",
             f"{'':24}{'MSS':>14}{'FEM':>14}"]
    lines.append(f"{'volume change (%)':24}{100 * out['mss']['volume_change']:>14.4f}{100 * out['fem']['volume_change']:>14.4f}")
    if "reaction_force" in out["mss"]:
        for i, c in enumerate("xyz"):
            lines.append(f"{'reaction F' + c + ' (N)':24}{out['mss']['reaction_force'][i]:>14.5g}{out['fem']['reaction_force'][i]:>14.5g}")
        lines.append(f"{'reaction Tz (N m)':24}{out['mss']['reaction_torque'][2]:>14.5g}{out['fem']['reaction_torque'][2]:>14.5g}")
    if spec.experiment == "bending":
        lines.append(f"{'tip deflection (m)':24}{out['mss']['tip_deflection']:>14.5g}{out['fem']['tip_deflection']:>14.5g}"
                     f"   Euler-Bernoulli {out['euler_bernoulli_tip']:.5g}")
    lines.append(f"{'max |u| (m)':24}{out['mss']['max_displacement']:>14.5g}{out['fem']['max_displacement']:>14.5g}")
    lines.append(f"{'wall time (s)':24}{out['mss']['wall_time_s']:>14.3f}{out['fem']['wall_time_s']:>14.3f}")
    lines.append(f"|u_mss - u_fem|: mean {d['mean']:.4g} m, max {d['max']:.4g} m, rel L2 {d['rel_l2']:.4g}, "
                 f"middle layer mean {d['mid_layer_mean']:.4g} m")
    emit(out, args.json, "\n".join(lines))
    return 0


def run_options(q: argparse.ArgumentParser) -> None:
    """The options of ``hybmss run`` (added to its parser by :func:`register`)."""
    q.add_argument("--study", action="append", default=None, help="study name (repeatable)")
    q.add_argument("--all", action="store_true", help="every study of make reproduce-paper")
    q.add_argument("--out", default="artifacts/results", help="results folder")
    q.add_argument("--quick", action="store_true", help="coarse meshes (the tests' mode)")
    q.add_argument("--jobs", type=int, default=None,
                   help="parallel runs, >= 1 (default: all cores, or the Dask cluster's threads)")
    q.add_argument("--executor", choices=EXECUTORS, default="local",
                   help="local: a process pool on this machine (default); dask: a dask.distributed "
                        "cluster (--scheduler, or a local cluster of --jobs workers)")
    q.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="address of a running dask scheduler, e.g. tcp://host:8786 (--executor dask)")
    q.add_argument("--no-progress", action="store_true")
    q.add_argument("--json", action="store_true", help="print what was run as one JSON object")


def cmd_run(args) -> int:
    """Exit 0 when the sweep finishes (failed runs are stored rows), 2 for options not allowed
    (checked before any work), 3 when the sweep cannot go on, 130 on SIGINT."""
    from .reproduce import EXTRA_STUDIES, STUDIES, run_studies

    if args.all and args.study:
        raise ValueError(f"--all and --study {','.join(args.study)} together are not allowed: "
                         "--all runs every study; give one or the other")
    if not str(args.out).strip():
        raise ValueError("--out '' is not allowed: a results folder path is required")
    unknown = [n for n in args.study or () if n not in STUDIES and n not in EXTRA_STUDIES]
    if unknown:
        raise ValueError(f"--study {unknown[0]!r} is not allowed; studies: "
                         f"{', '.join(list(STUDIES) + list(EXTRA_STUDIES))}")
    runner = Runner(args.executor, jobs=args.jobs, scheduler=args.scheduler, progress=not args.no_progress)
    Store(args.out).check_writable()
    try:
        with runner:
            run_studies(args.out, names=None if args.all else args.study, quick=args.quick, jobs=args.jobs,
                        progress=not args.no_progress, runner=runner)
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, exit_now)  # exiting; a second Ctrl-C exits at once
        s = runner.summary
        sys.stderr.write(f"interrupted: {s.computed} runs computed and stored in {args.out}, running "
                         "ones abandoned; rerun the same command to resume\n")
        return 130
    except SweepError as exc:
        msg = " ".join(str(exc).split())
        if args.json:
            emit({"status": "error", "message": msg, "out": str(args.out), **runner.summary.as_dict()}, True, "")
        sys.stderr.write(f"error: {msg}\n")
        return 3
    s = runner.summary
    out = {"status": "ok", "out": str(args.out), **s.as_dict()}
    emit(out, args.json, f"{args.out}: {s.line()}")
    return 0


def register(sub) -> None:
    """Add ``compare`` and ``run`` to the ``hybmss`` parser."""
    q = sub.add_parser("compare", help="one scene on the MSS and the FEM reference, side by side")
    q.add_argument("scene", choices=[e for e in EXPERIMENTS if e != "uniaxial"])
    q.add_argument("--mesh", type=mesh_arg, default=None, help="NXxNYxNZ cells (default: publication's)")
    q.add_argument("--model", choices=models.names(), default="hybmss")
    q.add_argument("--A", type=float, default=None)
    q.add_argument("--e-form", action="store_true", help="spring constants from [G20] eq. 5.12")
    q.add_argument("--E", type=float, default=None, help="Young's modulus, Pa (> 0)")
    q.add_argument("--nu", type=float, default=None, help="Poisson ratio in (-1, 0.5)")
    q.add_argument("--rho", type=float, default=None, help="density, kg/m^3 (>= 0)")
    q.add_argument("--deformation", type=float, default=None, help="d, fraction (0.05 = 5 %%)")
    q.add_argument("--angle", type=float, default=None, help="torsion angle, degrees")
    q.add_argument("--gravity", type=float, default=None, help="bending: g, m/s^2 (default 10)")
    q.add_argument("--solver", choices=("static", "explicit", "implicit"), default="static")
    q.add_argument("--dt", type=float, default=1e-3, help="time step of explicit/implicit, s (> 0)")
    q.add_argument("--steps", type=int, default=10_000, help="explicit/implicit steps")
    q.add_argument("--ramp-time", type=float, default=1.0, help="plate ramp duration, s")
    q.add_argument("--fem", choices=("hex1", "hex2", "mixed", "auto"), default="hex2")
    q.add_argument("--law", choices=("linear", "neo-hookean", "svk"), default=None)
    q.add_argument("--refine", type=int, default=1, help="FEM refinement factor r (cells split into r^3)")
    q.add_argument("--json", action="store_true")
    q.set_defaults(func=cmd_compare)

    q = sub.add_parser("run", help="run the publication's studies and store their results")
    run_options(q)
    q.set_defaults(func=cmd_run)
