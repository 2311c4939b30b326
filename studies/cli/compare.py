"""``hybmss compare``: one scene on the mass-spring system and on the FEM reference, side by side.

The mass-spring solve (static, explicit or implicit) and the FEM's go through the one solver
dispatch of the sweep (:func:`studies.sweep.solving.solve_scene`), so a row of a study and this
command answer the same scene alike.  The relative errors (fractions) compare like with like:
the volume changes ``(ΔV_mss − ΔV_fem) / |ΔV_fem|`` through the same averaged-edge volume, each plate's force
``|F_mss − F_fem| / |F_fem|``, and the displacements' relative L2 and relative max over the
lattice particles (:data:`EPILOG`)."""

from __future__ import annotations

import math
import time

from hybmss import models
from hybmss.experiments import SceneSpec
from hybmss.scene import plates_cross, unsupported

from studies.sweep import sizing
from studies.sweep.compare import default_law, diff_metrics
from studies.sweep.runner import SolverSpec
from studies.sweep.solving import default_kernel, measure, solve_scene
from studies.cli.common import SCENES, SOLVER_DEFAULTS, InputError, SolveFailure, check_newton_nu, check_result, \
    check_solver, flag, guard, mesh_flags, run_work, scene_spec, show, stored_scene, work_flags, working
from studies.cli.options import Options, add_fem_options, add_model_options, add_mss_options, add_no_guard, \
    add_scene_options, positive_int

HELP = "one scene on the mass-spring system and the FEM reference, side by side"

EPILOG = """\
units of compare:
  volume changes and relative errors are fractions in the text and in --json alike
  (dV/V0 = -0.0135 is a 1.35 % loss; a relative error 0.02 is 2 %); lengths m, forces N,
  torques N m, times s.  Two volume formulas, each named: the MSS's averaged-edge volume
  (sum over cells of a.(b x c), a, b, c the cell's averaged edge vectors), also evaluated on
  the FEM's displacements at the lattice particles, and the FEM's integral of det F (under
  --law linear the FEM's own volume is the linearized integral of 1 + div u, shown apart).  The
  relative errors compare like with like: the MSS volume change against the FEM's through the
  same averaged-edge formula (and, named apart, against its integral of det F), the plate
  forces as |F_mss - F_fem| / |F_fem|, the displacements as relative L2 and relative max
  over the lattice particles (the FEM's solution evaluated there).
"""


def add_options(parser, opts: Options) -> None:
    """The options of ``hybmss compare``."""
    opts.add(parser, "scene", nargs="?", choices=SCENES, default=None, help="experiment (or --scene-json)")
    opts.add(parser, "--scene-json", default=None, metavar="FILE",
             help="compare on a stored Scene (Scene.to_dict JSON) instead of an experiment; the FEM law "
                  "defaults to linear")
    add_scene_options(parser, opts)
    add_model_options(parser, opts)
    add_mss_options(parser, opts)
    opts.add(parser, "--load-steps", type=positive_int, default=None,
             help="load steps of the mass-spring static solver: at least N, each at most 1/N of the load "
                  "(integer >= 1; default: adaptive from one step)")
    add_fem_options(parser, opts)
    add_no_guard(parser, opts)


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
"""Units of ``compare``'s output, the same in its text and JSON (:data:`EPILOG`)."""


def _side(result, spec: SceneSpec | None, fem: bool) -> dict:
    """One solver's column: its volume change under each formula it has (named), the plate
    reactions, the scalar outputs of :func:`studies.sweep.solving.measure` for an experiment."""
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


def _fmt(v, spec: str = ".5g") -> str:
    return "—" if v is None else format(v, spec)


def compare(args):
    scene, spec = _compare_scene(args)
    model_name = spec.model if spec is not None else scene.model.name
    check_newton_nu(model_name, args.solver, spec.nu if spec is not None else scene.material.nu,
                    None if spec is not None else f"--scene-json = {args.scene_json}")
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
    mss_solver = SolverSpec(kind=args.solver, kernel=default_kernel(models.get(model_name)), **dyn)
    fem_solver = SolverSpec(kind="fem", element=args.element, law=law, refine=refine)
    work = run_work(args, args.solver)
    shape = spec.mesh if spec is not None else scene.body.shape
    nu = spec.nu if spec is not None else scene.material.nu
    steps = f" --steps {dyn['steps']}" if args.solver != "static" else ""
    guard(sizing.mss(shape, args.solver, dyn["steps"], work), mesh_flags(spec, shape) + steps + work_flags(args),
          lambda sh: sizing.mss(sh, args.solver, dyn["steps"], work), args)
    guard(sizing.fem(shape, args.element, refine, law, nu), mesh_flags(spec, shape, refine),
          lambda sh: sizing.fem(sh, args.element, refine, law, nu), args)
    if scene is None:
        scene = spec.build()
    with working():
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
