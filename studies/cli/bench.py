"""``hybmss bench``: the speed of the explicit kernels and of the static solver
(:mod:`hybmss.bench`), or of one configuration; for an engine's model, its time per step as a
ratio to hybmss's on the same cube, with the load average."""

from __future__ import annotations

import os
import time

from hybmss import models
from hybmss.scene import Material

from studies.sweep import roles
from studies.sweep import sizing
from studies.cli.common import InputError, SolveFailure, guard, mesh_flags, show, working
from studies.cli.options import Options, add_no_guard, add_scene_options, positive_int

HELP = "speed of the explicit kernels and the static solver"


def add_options(parser, opts: Options) -> None:
    """The options of ``hybmss bench``."""
    opts.add(parser, "--steps", type=positive_int, default=None,
             help="explicit steps per timed run (integer >= 1; default 10000 on 10x10x10, 1000 on 30x30x30)")
    opts.add(parser, "--quick", action="store_true", help="fewer, smaller runs (a smoke run, not a measurement)")
    add_scene_options(parser, opts, names=("model", "nu", "mesh"))
    opts.add(parser, "--threads", type=positive_int, default=None,
             help="threads of one timed configuration (integer >= 1; default 1)")
    opts.add(parser, "--precision", choices=("f64", "f32"), default=None,
             help="precision of one timed configuration (default f64)")
    add_no_guard(parser, opts)


def bench(args):
    from hybmss.bench import MAX_STEPS, MESH, MESHES, MIN_STEPS, NU, PROBE_STEPS, QUICK_MESH, QUICK_TARGET_S, \
        TARGET_S, default_variants, format_bench, run_bench, time_config

    def timed(mesh) -> sizing.Estimate:
        """One timed run: ``--steps``, or the steps that fit the target time (at least MIN_STEPS)
        after a probe, as :mod:`hybmss.bench` chooses them."""
        if args.steps:
            return sizing.mss(mesh, "explicit", args.steps)
        per_step = sizing.mss(mesh, "explicit", 1).seconds
        target = QUICK_TARGET_S if args.quick else TARGET_S
        n = min(MAX_STEPS, max(MIN_STEPS, int(target / per_step))) + PROBE_STEPS
        return sizing.mss(mesh, "explicit", n)

    one = {k: getattr(args, k, None) for k in ("model", "nu", "mesh", "threads", "precision")}
    if one["nu"] is not None:
        try:
            Material(1e4, one["nu"])
        except ValueError as exc:
            raise InputError(f"--nu = {show(one['nu'])} is not allowed: {exc}") from None
    repeats = 1 if args.quick else 3
    if any(v is not None for v in one.values()):
        mesh = one["mesh"] or MESH
        est = sizing.total("timed configuration", [timed(mesh)] * repeats)
        guard(est, mesh_flags(None, mesh) + (f" --steps {args.steps}" if args.steps else ""), timed, args)
    else:  # every variant, four configurations a mesh
        meshes = (QUICK_MESH,) if args.quick else MESHES
        n = len(default_variants()) * (1 if args.quick else 4) * repeats
        guard(sizing.total("benchmark", [timed(m) for m in meshes for _ in range(n)]),
              f"--steps {args.steps}" if args.steps else "bench", args=args)
    if one["model"] is not None and models.get(one["model"]).kernels == ("engine",):
        return _bench_engine(args, one, repeats)
    with working():
        if any(v is not None for v in one.values()):  # time one configuration
            row = time_config(model=one["model"], nu=NU if one["nu"] is None else one["nu"],
                              mesh=one["mesh"] or MESH, threads=one["threads"] or 1,
                              precision=one["precision"] or "f64", steps=args.steps, repeats=repeats)
            d = {"explicit": [row], "static": []}
        else:
            d = run_bench(steps=args.steps, quick=args.quick, static_models=roles.in_role("performance"))
    return d, format_bench(d)


def _bench_engine(args, one: dict, repeats: int):
    """``bench --model <engine>``: the engine's time per explicit step as a ratio to hybmss's on
    the same compression cube (ν = 1/4 unless ``--nu``: every engine represents it), and the wall
    time of both static answers (the engine's: the rest state of its damped run; hybmss's:
    Newton), with the 1-minute load average (:func:`studies.paper.engines.step_ratios`).  What the engine
    cannot represent, a thread count or precision it does not have, is refused before any work."""
    from hybmss.bench import MESH, QUICK_MESH, compression_scene, load_average
    from hybmss.solve import StaticSolveError, solve_static

    from studies.paper.engines import TIMED_NU, step_ratios

    name = one["model"]
    nu = TIMED_NU if one["nu"] is None else float(one["nu"])
    mesh = tuple(one["mesh"] or (QUICK_MESH if args.quick else MESH))
    spec = models.get(name)
    scene = compression_scene(name, nu, mesh=mesh)
    try:
        spec._check(scene, one["threads"] or 1, one["precision"] or spec.precisions[0])
    except ValueError as exc:
        raise InputError(f"--model = {name} is not allowed for this scene: {exc}") from None
    with working():
        rows = step_ratios([name], mesh=mesh, nu=nu, steps=args.steps, repeats=repeats,
                           target_s=0.05 if args.quick else 0.5)
        static = []
        for m in (models.default_name(), name):
            sc = compression_scene(m, nu, mesh=mesh)
            t0 = time.perf_counter()
            try:
                r = solve_static(sc)
            except StaticSolveError as exc:
                raise SolveFailure(f"{m}: static answer failed: {' '.join(str(exc).split())}") from None
            static.append({"model": m, "mesh": "x".join(map(str, mesh)), "nu": nu,
                           "wall_time_s": time.perf_counter() - t0, "solver": r.solver,
                           "steps_or_iterations": int(r.iterations), "load_avg": load_average()})
    ratio = rows[1]["ratio_to_hybmss"]
    d = {"model": name, "mesh": "x".join(map(str, mesh)), "nu": nu, "explicit": rows, "static": static,
         "step_ratio_to_hybmss": ratio, "static_ratio_to_hybmss": static[1]["wall_time_s"] / static[0]["wall_time_s"],
         "cores": os.cpu_count()}
    lines = [f"{name} against hybmss, compression cube {d['mesh']}, nu = {nu:g}",
             f"{'model':<18} {'steps':>6} {'s/step':>10} {'ratio':>8} {'engine calls s/step':>20} {'load':>5}"]
    for r in rows:
        eng = r["engine_calls_s_per_step"]
        lines.append(f"{r['model']:<18} {r['steps']:>6} {r['s_per_step']:>10.3e} {r['ratio_to_hybmss']:>8.2f} "
                     f"{(f'{eng:.3e}' if eng is not None else '-'):>20} {r['load_avg'] or float('nan'):>5.2f}")
    lines.append("static answer (wall time, s): " + ", ".join(
        f"{r['model']} {r['wall_time_s']:.3g} ({r['solver']}, {r['steps_or_iterations']} steps/iterations, "
        f"load {r['load_avg'] or float('nan'):.2f})" for r in static))
    lines.append(f"(1-min load average on {os.cpu_count()} cores: above the core count, times are not the code's)")
    return d, "\n".join(lines)
