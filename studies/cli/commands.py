"""What each subcommand of ``hybmss`` does (the parser is :mod:`studies.cli.parser`).

Every command takes the parsed arguments and returns ``(obj, text)``: the JSON object printed by
``--json`` and the table printed otherwise.  Inputs are checked before any work starts
(:class:`InputError`, exit 2), including the size guard of :mod:`studies.sweep.sizing`; a valid
simulation that fails raises :class:`SolveFailure` (exit 3).  The solvers are imported when a
command runs, so an invocation that is refused costs no more than importing NumPy.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import signal
import threading
import time

from hybmss import models
from hybmss.experiments import EXPERIMENTS, ParameterError, SceneSpec
from hybmss.scene import Material, Model, Scene, plates_cross, scene_dict_error, unsupported

from studies.sweep import roles

from studies.sweep import sizing
from studies.sweep.compare import default_law, diff_metrics
from studies.paper.reproduce import EXTRA_STUDIES, ON_REQUEST_STUDIES, STUDIES
from studies.sweep.runner import Runner, SolverSpec, Task, exit_now, measure, solve
from studies.sweep.store import Store

SCENES = tuple(e for e in EXPERIMENTS if e != "uniaxial")
"""Experiments the ``fem`` and ``compare`` subcommands solve (``uniaxial`` is ``moduli``'s)."""

MSS_SOLVERS = ("static", "explicit", "implicit")
SOLVER_DEFAULTS = {f.name: f.default for f in dataclasses.fields(SolverSpec)}


class InputError(ValueError):
    """Input that is not allowed (exit status 2)."""


class SolveFailure(RuntimeError):
    """A valid simulation that failed (exit status 3); the message says the cause and remedy.
    ``result``: what was done all the same (a study's counts, tables and report), the fields of
    the ``--json`` object beside ``status`` and ``message``."""

    def __init__(self, message: str, result: dict | None = None):
        super().__init__(message)
        self.result = result


def model_choices() -> tuple[str, ...]:
    """The models a user can name (the registry's, and those it lists as unavailable: naming one is
    refused with the reason and the install command)."""
    return tuple(models.names()) + tuple(models.unavailable())


def model_parameters() -> dict[str, tuple[dataclasses.Field, tuple[str, ...]]]:
    """Every registered model's parameters (:func:`hybmss.models.parameter_fields`): name → (its
    field, with ``help`` and ``choices`` metadata; the models that have it)."""
    owners = {name: tuple(m.name for m in models.all_models() if name in m.parameter_names())
              for name in models.parameter_fields()}
    return {name: (f, owners[name]) for name, f in models.parameter_fields().items()}


def study_names() -> tuple[str, ...]:
    return tuple(STUDIES) + tuple(EXTRA_STUDIES) + tuple(ON_REQUEST_STUDIES)


def flag(name: str) -> str:
    """The command-line flag of scene parameter ``name``."""
    return "--" + name.replace("_", "-")


def show(v) -> str:
    if isinstance(v, tuple):
        return "x".join(map(str, v))
    return f"{v:g}" if isinstance(v, float) else str(v)


# ------------------------------------------------------------------------------- scene options
def given_scene_options(args) -> dict:
    """The scene and model parameters set on the command line (``None`` = not given)."""
    names = [f.name for f in SceneSpec.parameters()] + list(model_parameters())
    return {n: getattr(args, n) for n in names if getattr(args, n, None) is not None}


def scene_spec(args, experiment: str, solvers: tuple[str, ...], solved: bool = True) -> SceneSpec:
    """The :class:`SceneSpec` of the options, checked (:meth:`SceneSpec.check`); refuses an option
    that this experiment and these solvers do not use (it would be silently ignored)."""
    given = given_scene_options(args)
    meta = {f.name: f.metadata for f in SceneSpec.parameters()}
    for name in given:
        if any(SceneSpec.uses(name, experiment, s) for s in solvers):
            continue
        m = meta.get(name, {"experiments": None, "solvers": MSS_SOLVERS})
        if m["experiments"] is not None and experiment not in m["experiments"]:
            why = f"{experiment} does not use it; used by: {', '.join(e for e in m['experiments'] if e in SCENES)}"
        else:
            why = (f"the {' and '.join(solvers)} solver{'s do' if len(solvers) > 1 else ' does'} not use it; "
                   f"used by: {', '.join(m['solvers'])}")
        raise InputError(f"{flag(name)} = {show(given[name])} is not allowed: {why}")
    try:
        spec = SceneSpec.default(experiment, **given)
        return spec.check(solved)
    except ParameterError as exc:
        raise InputError(f"{flag(exc.name)} = {show(exc.value)} is not allowed: "
                         f"{str(exc).split(': ', 1)[1]}") from None
    except ValueError as exc:  # a model parameter the model does not have: "model X has no parameter 'A' ..."
        text = str(exc)
        if "has no parameter '" not in text:
            raise
        name = text.split("has no parameter '", 1)[1].split("'", 1)[0]
        raise InputError(f"{flag(name)} = {show(given.get(name))} is not allowed: {text}") from None
    except TypeError as exc:  # a model parameter of the wrong kind
        raise InputError(f"model {given.get('model') or models.default_name()}: {exc}") from None


def guard(est: sizing.Estimate, what: str, estimate=None, args=None) -> None:
    """Refuse a run whose estimated memory does not fit this machine or whose estimated time is
    over :data:`studies.sweep.sizing.TIME_LIMIT_S`, unless ``args.no_guard``."""
    if getattr(args, "no_guard", False):
        return
    if not sizing.fits(est):
        raise InputError(f"{what} is too large: {sizing.refusal(est, estimate)}")
    if not sizing.in_time(est):
        raise InputError(f"{what} is too long: {sizing.refusal(est)}")


def _work_flags(args) -> str:
    """The given model options that set a run's work (:func:`_work`), as flags."""
    return "".join(f" {flag(n)} {show(getattr(args, n))}" for n in ("iterations", "substeps")
                   if getattr(args, n, None) is not None)


def _work(args, solver: str) -> float:
    """:func:`studies.sweep.sizing.model_work` of the model parameters given on the command line."""
    return sizing.model_work({n: getattr(args, n, None) for n in ("iterations", "substeps")}, solver)


def _settings(spec: SceneSpec | None, shape, refine=None) -> str:
    mesh = f"--mesh {show(tuple(shape))}"
    return mesh + (f" --refine {refine}" if refine and refine != 1 else "")


def check_result(res, what: str) -> None:
    """A result that is not what was asked (not converged, a dynamic run not at rest, non-finite
    outputs) is a failure."""
    rest = res.info.get("rest")
    if isinstance(rest, dict) and not rest.get("at_rest"):
        steps = res.info.get("steps", res.iterations)
        why = " ".join(str(rest.get("not_at_rest_because") or "").split())
        raise SolveFailure(f"the {what} ({res.solver}) is not at rest after {steps} steps: raise --steps or "
                           f"--damping" + (f" ({why})" if why else ""))
    if not res.converged:
        why = " ".join(str(res.info.get("warning") or res.info.get("message") or "did not converge").split())
        raise SolveFailure(f"the {what} ({res.solver}) did not converge: {why}; try a smaller load or a finer mesh")
    bad = [k for k in ("volume_change", "max_displacement") if not math.isfinite(float(getattr(res, k)))]
    if bad:
        raise SolveFailure(f"the {what} ({res.solver}) produced non-finite {', '.join(bad)}; "
                           "the state is degenerate: try a smaller load or a finer mesh")


# ------------------------------------------------------------------------------- info
def box_counts(shape) -> dict:
    """Lattice counts of a full box of ``nx × ny × nz`` cells in closed form (no arrays): particles
    on the grid's vertices, one spring per grid edge, two merged diagonals per grid face, four
    inner diagonals per cell; [G20] Table 6 adds 12 unmerged face diagonals per cell."""
    nx, ny, nz = (int(n) for n in shape)
    cells = nx * ny * nz
    edge = nx * (ny + 1) * (nz + 1) + (nx + 1) * ny * (nz + 1) + (nx + 1) * (ny + 1) * nz
    faces = nx * ny * (nz + 1) + nx * (ny + 1) * nz + (nx + 1) * ny * nz
    face, inner = 2 * faces, 4 * cells
    return {
        "volumes": cells,
        "vertices": (nx + 1) * (ny + 1) * (nz + 1),
        "springs": {"edge": edge, "face_diagonal": face, "inner_diagonal": inner, "total": edge + face + inner},
        "paper_springs_no_fd": edge + inner,
        "paper_springs_with_fd": edge + inner + 12 * cells,
    }


def info(args):
    spec = scene_spec(args, args.scene, ("static",), solved=False)
    counts = box_counts(spec.mesh)
    s = counts["springs"]
    mesh = show(spec.mesh)
    table = "\n".join([
        f"{spec.experiment} body, mesh {mesh}, le = {spec.cell_edge:g} m",
        f"  volumes (cells)        {counts['volumes']:>14,}",
        f"  vertices (particles)   {counts['vertices']:>14,}",
        f"  edge springs           {s['edge']:>14,}",
        f"  face-diagonal springs  {s['face_diagonal']:>14,}   (merged)",
        f"  inner-diagonal springs {s['inner_diagonal']:>14,}",
        f"  springs, total         {s['total']:>14,}",
        f"  [G20] Table 6, no FD   {counts['paper_springs_no_fd']:>14,}",
        f"  [G20] Table 6, with FD {counts['paper_springs_with_fd']:>14,}   (12 unmerged face diagonals per cell)",
    ])
    return {"mesh": mesh, "le": spec.cell_edge, **counts}, table


# ------------------------------------------------------------------------------- moduli
def moduli(args):
    from hybmss.moduli import MeasurementError, measure_moduli

    given = given_scene_options(args)
    base = SceneSpec("uniaxial")
    name = given.pop("model", base.model)
    mat_p = {k: given.pop(k, getattr(base, k)) for k in ("E", "nu", "rho")}
    try:
        model = Model(name, **given)  # a parameter the model does not have: exit 2
    except TypeError as exc:
        raise InputError(f"model {name}: {exc}") from None
    try:
        mat = Material(**mat_p)
    except ValueError as exc:  # "nu (Poisson ratio) must lie in ..."
        field = str(exc).split(" ", 1)[0]
        raise InputError(f"{flag(field)} = {show(mat_p.get(field))} is not allowed: {exc}") from None
    # two uniaxial tests of a 2³ cube and a shear test of a 3³ one
    guard(sizing.total("moduli tests", [sizing.mss((3, 3, 3), "static", work=_work(args, "static"))] * 3),
          f"--model {name}{_work_flags(args)}", args=args)
    try:
        m = measure_moduli(model, mat, strain=args.strain, judge=True)
    except MeasurementError as exc:
        raise SolveFailure(str(exc)) from None
    G = mat.G
    extra = "".join(f", {k} = {v}" for k, v in model.to_dict().items() if k != "name")
    table = "\n".join([
        f"model {model.variant}{extra}, E = {mat.E:g} Pa, nu = {mat.nu:g}",
        f"  E_eff  = {m['E_eff']:.6g} Pa   (input {mat.E:g}, rel. error {m['E_eff'] / mat.E - 1:+.2e})",
        f"  nu_eff = {m['nu_eff']:.6g}      (input {mat.nu:g}, error {m['nu_eff'] - mat.nu:+.2e})",
        f"  G_eff  = {m['G_eff']:.6g} Pa   (E/(2(1+nu)) = {G:.6g}, rel. error {m['G_eff'] / G - 1:+.2e})",
    ] + ([f"  float32 equilibrium error: E_eff +/-{m['equilibrium_error']['E_eff']:.2e}, nu_eff "
          f"+/-{m['equilibrium_error']['nu_eff']:.2e}, G_eff +/-{m['equilibrium_error']['G_eff']:.2e} (resolved from "
          f"strain {m['resolvable_strain']:.2g} on)"] if "equilibrium_error" in m else []))
    return {**model.to_dict(), "model": model.name, "variant": model.variant, "E": mat.E, "nu": mat.nu, **m}, table


# ------------------------------------------------------------------------------- bench
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
        guard(est, _settings(None, mesh) + (f" --steps {args.steps}" if args.steps else ""), timed, args)
    else:  # every variant, four configurations a mesh
        meshes = (QUICK_MESH,) if args.quick else MESHES
        n = len(default_variants()) * (1 if args.quick else 4) * repeats
        guard(sizing.total("benchmark", [timed(m) for m in meshes for _ in range(n)]),
              f"--steps {args.steps}" if args.steps else "bench", args=args)
    if one["model"] is not None and models.get(one["model"]).kernels == ("engine",):
        return _bench_engine(args, one, repeats)
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
        static.append({"model": m, "mesh": "x".join(map(str, mesh)), "nu": nu, "wall_time_s": time.perf_counter() - t0,
                       "solver": r.solver, "steps_or_iterations": int(r.iterations), "load_avg": load_average()})
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


# ------------------------------------------------------------------------------- fem
def load_scene(path: str) -> Scene:
    """The Scene stored in the JSON file ``path``, checked as thoroughly as the command-line options:
    strict JSON, every field known and of its type (:func:`hybmss.scene.scene_dict_error`), every
    value in its range (the constructors)."""
    def refuse(why: str):
        return InputError(f"--scene-json = {path} is not allowed: {' '.join(str(why).split())}; allowed: a "
                          "Scene JSON object (Scene.to_dict)")

    try:
        with open(path, "rb") as fh:
            data = json.loads(fh.read().decode("utf-8"), parse_constant=_not_strict)
    except OSError as exc:
        raise InputError(f"--scene-json = {path} is not allowed: cannot read it ({exc.strerror}); "
                         "allowed: a readable Scene JSON file") from None
    except RecursionError:
        raise refuse("nested too deeply to be a scene") from None
    except (ValueError, UnicodeDecodeError) as exc:  # JSONDecodeError and NaN/Infinity are ValueErrors
        raise refuse(f"not JSON ({exc})") from None
    if not isinstance(data, dict):
        raise refuse(f"it holds a JSON {type(data).__name__}")
    why = scene_dict_error(data)
    if why:
        raise refuse(f"not a scene ({why})")
    try:
        return Scene.from_dict(data)
    except (KeyError, TypeError, AttributeError, ValueError, RecursionError) as exc:
        what = f"missing key {exc}" if isinstance(exc, KeyError) else str(exc)
        raise refuse(f"not a scene ({what})") from None


def _not_strict(name):
    raise ValueError(f"{name} is not a number in strict JSON")


def format_fem(res) -> str:
    lines = [
        f"{res.solver}  ({res.info['n_dofs']:,} dofs, {res.info['n_elements']:,} elements, "
        f"{res.iterations} Newton iteration(s), {res.wall_time_s:.2f} s)",
        f"  volume change (fraction dV/V0)  ∫det F: {res.info['volume_detF'] / res.volume0 - 1:+.6g}   "
        f"averaged-edge (MSS formula): {res.info['volume_mss_formula'] / res.volume0 - 1:+.6g}"
        + ("" if res.volume == res.info["volume_detF"] else
           f"   ∫(1 + div u) (the linear law's own): {res.volume_change:+.6g}"),
        f"  max |u| = {res.max_displacement:.6g} m   strain energy = {res.energy['strain']:.6g} J",
    ]
    for name, r in res.reactions.items():
        F = ", ".join(f"{v:.6g}" for v in r.force)
        T = ", ".join(f"{v:.6g}" for v in r.torque)
        lines.append(f"  plate {name}: F = ({F}) N   T = ({T}) N·m")
    return "\n".join(lines)


def fem(args):
    given = given_scene_options(args)
    if args.scene_json:
        if args.scene or given:
            extra = ", ".join(["--scene"] * bool(args.scene) + [flag(n) for n in given])
            raise InputError(f"--scene-json is not allowed with {extra}: the stored scene defines them")
        scene, spec = load_scene(args.scene_json), None
    else:
        spec = scene_spec(args, args.scene or "compression", ("fem",))
        scene = spec.build()
    law = args.law or (default_law(spec) if spec else "linear")
    refine = SOLVER_DEFAULTS["refine"] if args.refine is None else args.refine
    if args.convergence and args.refine is not None:
        raise InputError(f"--refine = {args.refine} is not allowed with --convergence "
                         f"{','.join(map(str, args.convergence))}: the study sets the refinements")
    nu = scene.material.nu
    for r in args.convergence or (refine,):
        guard(sizing.fem(scene.body.shape, args.element, r, law, nu), _settings(spec, scene.body.shape, r),
              lambda shape, r=r: sizing.fem(shape, args.element, r, law, nu), args)
    if args.scene_json:
        why = unsupported(scene) or plates_cross(scene)
        if why:
            raise InputError(f"--scene-json = {args.scene_json} is not allowed: {why}; allowed: plates that "
                             "do not cross")

    from fem_reference.solve import solve as fem_solve

    if args.convergence:
        from fem_reference.convergence import convergence

        study = convergence(scene, refinements=args.convergence, element=args.element, law=law,
                            steps=args.load_steps, method=args.linear_solver)
        for res in study.results:
            check_result(res, "FEM solve")
        out = study.to_dict()
        out["finest"] = study.results[-1].summary()
        out["scene"] = scene.to_dict()
        out["scene_digest"] = scene.digest()
        return out, format_fem(study.results[-1]) + "\n" + study.table()
    res = fem_solve(scene, element=args.element, law=law, refine=refine, steps=args.load_steps,
                    method=args.linear_solver)
    check_result(res, "FEM solve")
    out = res.summary()
    out["scene"] = scene.to_dict()
    if spec is not None:
        out["spec"] = spec.to_dict()
    return out, format_fem(res)


# ------------------------------------------------------------------------------- compare
VOLUME_FORMULAS = {
    "avg_edges": "averaged-edge volume: sum over cells of a.(b x c), a, b, c the cell's averaged edge vectors "
                 "(the MSS's own volume)",
    "det_F": "integral of det(I + grad u) over the reference body (the exact volume of the FEM's field)",
    "div_u": "integral of (1 + div u) over the reference body (the linear law's linearized volume, the FEM's "
             "own volume under --law linear)",
}
"""The two volume formulas ``compare`` names (its JSON's ``volume_formulas``)."""

UNITS = {"volume_change": "fraction dV/V0", "relative errors": "fraction", "length": "m", "force": "N",
         "torque": "N m", "time": "s"}
"""Units of ``compare``'s output, the same in its text and JSON (:data:`studies.cli.parser.COMPARE_UNITS`)."""


def _side(result, spec: SceneSpec | None, fem: bool) -> dict:
    """One solver's column: its volume change under each formula it has (named), the plate
    reactions, the scalar outputs of :func:`studies.sweep.runner.measure` for an experiment."""
    avg = (result.info["volume_mss_formula"] / result.volume0 - 1.0) if fem else float(result.volume_change)
    own = "avg_edges"
    if fem:  # the linear law's volume is ∫(1 + div u), the finite-strain laws' ∫det F (fem_reference.solve)
        det_f = result.info["volume_detF"] / result.volume0 - 1.0
        own = "det_F" if float(result.volume) == float(result.info["volume_detF"]) else "div_u"
    out = {
        "solver": result.solver,
        "volume_change": float(result.volume_change),
        "volume_formula": own,
        "volume_change_avg_edges": float(avg),
        "max_displacement": float(result.max_displacement),
        "wall_time_s": float(result.wall_time_s),
        "converged": bool(result.converged),
        "reactions": {name: {"force": [float(v) for v in r.force], "torque": [float(v) for v in r.torque]}
                      for name, r in result.reactions.items()},
    }
    if fem:
        out["volume_change_det_F"] = float(det_f)
    if spec is not None:
        row = measure(spec, result)
        plate = "bottom" if spec.experiment == "bending" else "top"
        if plate in result.reactions:
            out["reaction_plate"] = plate
            out["reaction_force"] = list(result.reactions[plate].force)
            out["reaction_torque"] = list(result.reactions[plate].torque)
        if spec.experiment == "bending":
            out["tip_deflection"] = row["tip_deflection"]
    for k in ("inverted_cells", "volume_avg_edges", "volume_lnJ", "dt_crit", "at_rest", "kinetic_energy",
              "residual", "load_steps"):
        if k in result.info:
            out[k] = result.info[k]
    return out


def _relative(a: float, b: float, scale: float | None = None) -> float | None:
    """``(a − b)/|b|`` (``scale`` instead of |b| when given); ``None`` when the reference is zero
    (a relative error of nothing is no number)."""
    ref = abs(b) if scale is None else scale
    return float((a - b) / ref) if ref > 0 and math.isfinite(ref) else None


def relative_errors(mss: dict, fem: dict, u_mss, u_fem) -> dict:
    """The MSS against the FEM, relative (fractions, :data:`UNITS`): the volume change through the
    same averaged-edge formula and against the FEM's ∫det F; each plate's force ``|F_mss − F_fem|
    / |F_fem|``; the displacements' relative L2 and relative max over the lattice particles."""
    import numpy as np

    tiny = 1e-12  # a volume change below this is round-off of an isochoric state: no relative error
    dv = fem["volume_change_avg_edges"]
    out = {
        "volume_change_avg_edges": _relative(mss["volume_change_avg_edges"], dv) if abs(dv) > tiny else None,
        "volume_change_vs_det_F": (_relative(mss["volume_change_avg_edges"], fem["volume_change_det_F"])
                                   if abs(fem["volume_change_det_F"]) > tiny else None),
        "force": {},
    }
    for name, r in fem["reactions"].items():
        if name in mss["reactions"]:
            Ff, Fm = np.asarray(r["force"]), np.asarray(mss["reactions"][name]["force"])
            n = float(np.linalg.norm(Ff))
            out["force"][name] = float(np.linalg.norm(Fm - Ff) / n) if n > 0 else None
    du = np.linalg.norm(np.asarray(u_mss) - np.asarray(u_fem), axis=1)
    uf = np.linalg.norm(np.asarray(u_fem), axis=1)
    out["displacement_l2"] = float(np.sqrt((du**2).sum() / (uf**2).sum())) if uf.any() else None
    out["displacement_max"] = float(du.max() / uf.max()) if uf.any() else None
    return out


def check_solver(model_name: str, solver: str) -> None:
    """Refuse a solver kind the scene's model does not support (its ``solvers``)."""
    model = models.get(model_name)
    if not model.supports(solver):
        raise InputError(f"--solver = {solver} is not allowed: model {model.name} does not support it; "
                         f"allowed: {', '.join(model.solvers)}")


def stored_scene(args):
    """The scene of ``--scene-json``, refused beside an experiment or scene options (the stored
    scene defines them)."""
    given = given_scene_options(args)
    if args.scene or given:
        extra = ", ".join([f"the experiment {args.scene}"] * bool(args.scene) + [flag(n) for n in given])
        raise InputError(f"--scene-json is not allowed with {extra}: the stored scene defines them")
    return load_scene(args.scene_json)


def _compare_scene(args):
    """The scene of ``compare`` and its experiment spec (``None`` for ``--scene-json``), checked."""
    if args.scene_json:
        scene = stored_scene(args)
        check_solver(scene.model.name, args.solver)
        why = unsupported(scene)  # the FEM reference is a static solve, whatever the MSS solver
        if why:
            raise InputError(f"--scene-json = {args.scene_json} is not allowed: {why}")
        why = plates_cross(scene)
        if why:
            raise InputError(f"--scene-json = {args.scene_json} is not allowed: {why}; allowed: plates that "
                             "do not cross")
        return scene, None
    if not args.scene:
        raise InputError(f"compare needs an experiment ({', '.join(SCENES)}) or --scene-json FILE; none was given")
    spec = scene_spec(args, args.scene, (args.solver, "fem"))
    check_solver(spec.model, args.solver)
    return None, spec


def _static_options(args, model_name: str):
    """The static solver's options of ``--load-steps`` (None: its defaults), refused where unused."""
    n = getattr(args, "load_steps", None)
    if n is None:
        return None
    if args.solver != "static":
        raise InputError(f"--load-steps = {n} is not allowed: the {args.solver} solver does not use it; "
                         "used by: --solver static")
    model = models.get(model_name)
    if model.solve_static is not None:
        raise InputError(f"--load-steps = {n} is not allowed: model {model.name} has its own static solver, "
                         "without load steps; allowed with the models solved by the Newton load stepping")
    from hybmss.solve import StaticOptions

    return StaticOptions(initial_steps=n, max_step=1.0 / n)


def solve_scene(scene: Scene, solver: SolverSpec, static_options=None):
    """One solve of ``scene`` (:func:`studies.sweep.runner.solve` for a scene without an experiment spec;
    ``static_options`` for the MSS static solver)."""
    if solver.kind == "static":
        from hybmss.solve import solve_static

        return solve_static(scene, static_options)
    if solver.kind == "implicit":
        from hybmss.solve import ImplicitOptions, simulate_implicit

        return simulate_implicit(scene, ImplicitOptions(dt=solver.dt, steps=solver.steps, ramp_time=solver.ramp_time))
    if solver.kind == "explicit":
        from hybmss.explicit import simulate_explicit

        return simulate_explicit(scene, dt=solver.dt, steps=solver.steps, kernel=solver.kernel,
                                 ramp_time=solver.ramp_time)
    from fem_reference.solve import solve as fem_solve

    return fem_solve(scene, element=solver.element, law=solver.law, refine=solver.refine)


def _fmt(v, spec: str = ".5g") -> str:
    return "—" if v is None else format(v, spec)


def compare(args):
    scene, spec = _compare_scene(args)
    model_name = spec.model if spec is not None else scene.model.name
    dyn = {"dt": args.dt, "steps": args.steps, "ramp_time": args.ramp_time}
    if args.solver == "static":
        for name, v in dyn.items():
            if v is not None:
                raise InputError(f"{flag(name)} = {show(v)} is not allowed: the static solver does not use it; "
                                 "used by: --solver explicit, implicit")
    static_options = _static_options(args, model_name)
    dyn = {k: SOLVER_DEFAULTS[k] if v is None else v for k, v in dyn.items()}
    law = args.law or (default_law(spec) if spec is not None else "linear")
    refine = SOLVER_DEFAULTS["refine"] if args.refine is None else args.refine
    mss_solver = SolverSpec(kind=args.solver, **dyn)
    fem_solver = SolverSpec(kind="fem", element=args.element, law=law, refine=refine)
    work = _work(args, args.solver)
    shape = spec.mesh if spec is not None else scene.body.shape
    nu = spec.nu if spec is not None else scene.material.nu
    steps = f" --steps {dyn['steps']}" if args.solver != "static" else ""
    guard(sizing.mss(shape, args.solver, dyn["steps"], work), _settings(spec, shape) + steps + _work_flags(args),
          lambda sh: sizing.mss(sh, args.solver, dyn["steps"], work), args)
    guard(sizing.fem(shape, args.element, refine, law, nu), _settings(spec, shape, refine),
          lambda sh: sizing.fem(sh, args.element, refine, law, nu), args)
    if scene is None:
        scene = spec.build()
    t0 = time.perf_counter()
    mss = solve_scene(scene, mss_solver, static_options)
    check_result(mss, f"mass-spring {args.solver} solve")
    if args.solver == "static" and not scene.has_gravity and not scene.loads:
        from hybmss.moduli import EQUILIBRIUM_TOL, equilibrium_error

        err = equilibrium_error(scene, mss)  # a relaxation that stopped where it started is no answer
        if not err <= EQUILIBRIUM_TOL:
            raise SolveFailure(f"the mass-spring static solve ({mss.solver}) stopped away from equilibrium: net "
                               f"forces on free particles {100 * err:.3g} % of the plate forces (allowed <= "
                               f"{100 * EQUILIBRIUM_TOL:g} %); check the model's parameters (substeps, iterations)")
    fem_res = solve_scene(scene, fem_solver)
    check_result(fem_res, "FEM solve")
    d = diff_metrics(mss.X, mss.u, fem_res.u)
    m, f = _side(mss, spec, fem=False), _side(fem_res, spec, fem=True)
    out = {"scene": spec.to_dict() if spec is not None else scene.to_dict(), "scene_digest": scene.digest(),
           "mss": m, "fem": f, "diff": d, "relative_errors": relative_errors(m, f, mss.u, fem_res.u),
           "volume_formulas": VOLUME_FORMULAS, "units": UNITS}
    if spec is not None and spec.experiment == "bending":
        out["euler_bernoulli_tip"] = spec.euler_bernoulli_tip()
    out["wall_time_s"] = time.perf_counter() - t0
    return out, format_compare(out, spec.label if spec is not None else f"scene {scene.name or args.scene_json}",
                               fem_res.solver)


def format_compare(out: dict, label: str, fem_solver: str) -> str:
    """The text of ``compare``: the same numbers as its JSON, in the same units (fractions)."""
    m, f, e, d = out["mss"], out["fem"], out["relative_errors"], out["diff"]
    w = 34
    lines = [f"{label}   (FEM: {fem_solver}; volume changes and relative errors as fractions)",
             f"{'':{w}}{'MSS':>14}{'FEM':>14}{'rel. error':>12}",
             f"{'volume change, averaged-edge':{w}}{m['volume_change_avg_edges']:>14.6g}"
             f"{f['volume_change_avg_edges']:>14.6g}{_fmt(e['volume_change_avg_edges'], '.3g'):>12}",
             f"{'volume change, FEM ∫det F':{w}}{'':>14}{f['volume_change_det_F']:>14.6g}"
             f"{_fmt(e['volume_change_vs_det_F'], '.3g'):>12}   (MSS averaged-edge against it)"]
    if f["volume_formula"] == "div_u":
        lines.append(f"{'volume change, FEM ∫(1 + div u)':{w}}{'':>14}{f['volume_change']:>14.6g}"
                     f"{'':>12}   (the linear law's own, linearized)")
    for name, r in f["reactions"].items():
        if name not in m["reactions"]:
            continue
        rm = m["reactions"][name]
        for i, c in enumerate("xyz"):
            lines.append(f"{'plate ' + name + ' F' + c + ' (N)':{w}}{rm['force'][i]:>14.5g}{r['force'][i]:>14.5g}")
        lines.append(f"{'plate ' + name + ' Tz (N m)':{w}}{rm['torque'][2]:>14.5g}{r['torque'][2]:>14.5g}")
        lines.append(f"{'plate ' + name + ' force':{w}}{'':>28}{_fmt(e['force'].get(name), '.3g'):>12}"
                     "   (|F_mss - F_fem| / |F_fem|)")
    if "tip_deflection" in m:
        lines.append(f"{'tip deflection (m)':{w}}{m['tip_deflection']:>14.5g}{f['tip_deflection']:>14.5g}"
                     f"{'':>12}   Euler-Bernoulli {out['euler_bernoulli_tip']:.5g}")
    lines.append(f"{'max |u| (m)':{w}}{m['max_displacement']:>14.5g}{f['max_displacement']:>14.5g}"
                 f"{_fmt(e['displacement_max'], '.3g'):>12}   (max |u_mss - u_fem| / max |u_fem|)")
    lines.append(f"{'wall time (s)':{w}}{m['wall_time_s']:>14.3f}{f['wall_time_s']:>14.3f}")
    lines.append(f"|u_mss - u_fem|: mean {d['mean']:.4g} m, max {d['max']:.4g} m, rel L2 {d['rel_l2']:.4g}, "
                 f"middle layer mean {d['mid_layer_mean']:.4g} m")
    lines.append(f"scene digest {out['scene_digest']}")
    return "\n".join(lines)


# ------------------------------------------------------------------------------- run
def _terminate(signum, frame):
    raise KeyboardInterrupt("SIGTERM")


def sweep_estimate(names, quick: bool, store: Store, workers: int) -> sizing.Estimate:
    """:func:`studies.sweep.sizing.sweep` of the pooled runs of the studies ``names`` (None: all) that
    ``store`` does not hold yet, on ``workers`` workers (the extra studies' own computations, a
    few minutes, are not counted)."""
    import importlib

    from studies.paper.reproduce import tasks_for

    listed = [n for n in (names or study_names()) if n in STUDIES]
    tasks = tasks_for(listed, quick) if listed else []
    for n in (names or study_names()):
        if n in EXTRA_STUDIES:
            module = importlib.import_module(EXTRA_STUDIES[n].split(":")[0])
            tasks += module.tasks(quick) if hasattr(module, "tasks") else []
    stored = set(store.keys())
    pending = {t.key(): t for t in tasks}
    todo = [sizing.task(t.scene, t.solver) for k, t in pending.items() if k not in stored]
    return sizing.sweep(f"sweep of {len(todo)} runs not yet stored", todo, workers)


def run(args):
    """The studies into ``--out``: 0 when the sweep finishes (failed runs are stored rows), 2 for
    options not allowed (checked before any work: the folder, the executor and its scheduler),
    3 when the sweep cannot go on (:class:`studies.sweep.executors.SweepError`), 130 on SIGINT or SIGTERM
    (finished runs are kept, running ones abandoned and their workers stopped; a second Ctrl-C
    exits at once)."""
    from studies.paper.reproduce import check_study_files, run_studies

    if args.all and args.study:
        raise InputError(f"--all and --study {','.join(args.study)} together are not allowed: "
                         "--all runs every study; give one or the other")
    if not str(args.out).strip():
        raise InputError("--out '' is not allowed: a results folder path is required")
    if args.jobs is not None and args.jobs < 1:
        raise InputError(f"--jobs {args.jobs} is not allowed: an integer >= 1 (parallel runs), or none for all cores")
    if args.scheduler is not None and args.executor != "dask":
        raise InputError(f"--scheduler {args.scheduler!r} is given with --executor {args.executor}; a scheduler "
                         "address needs executor dask")
    names = None if args.all else args.study
    check_study_files(names)  # the study files' keys (StudyError: exit 2)
    if args.executor == "local" or args.scheduler is None:  # this machine's workers (a scheduler's are not known)
        workers = args.jobs or os.cpu_count() or 1
        guard(sweep_estimate(names, args.quick, Store(args.out), workers),
              f"run {'--all' if args.all or not args.study else ' '.join('--study ' + n for n in args.study)}"
              + (" --quick" if args.quick else "") + f" on {workers} worker(s)", args=args)
    runner = Runner(args.executor, jobs=args.jobs, scheduler=args.scheduler, progress=not args.no_progress)
    Store(args.out).check_writable()
    main = threading.current_thread() is threading.main_thread()
    # SIGTERM (a job scheduler, `timeout`, `kill`) stops the sweep as Ctrl-C does: no worker is
    # left computing for a process that is gone
    previous = signal.signal(signal.SIGTERM, _terminate) if main else None
    try:
        with runner:
            run_studies(args.out, names=names, quick=args.quick, jobs=args.jobs,
                        progress=not args.no_progress, runner=runner)
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, exit_now)  # exiting; a second Ctrl-C exits at once
        raise KeyboardInterrupt(f"{runner.summary.computed} runs computed and stored in {args.out}, running "
                                "ones abandoned; rerun the same command to resume") from None
    finally:
        if main:
            signal.signal(signal.SIGTERM, previous)
    s = runner.summary
    names = list(STUDIES) + list(EXTRA_STUDIES) if args.all or not args.study else list(args.study)
    return {"out": str(args.out), "studies": names, **s.as_dict()}, f"{args.out}: {s.line()}"


# ------------------------------------------------------------------------------- study
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
