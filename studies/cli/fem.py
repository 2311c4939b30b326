"""``hybmss fem``: the FEM reference (scikit-fem, :func:`fem_reference.solve.solve`) of one scene,
an experiment's or a stored one, or its convergence over refinements (observed order, Richardson
errors: :func:`fem_reference.convergence.convergence`)."""

from __future__ import annotations

from hybmss.scene import plates_cross, unsupported

from studies.sweep import sizing
from studies.sweep.compare import default_law
from studies.cli.common import SCENES, SOLVER_DEFAULTS, InputError, check_result, flag, given_scene_options, guard, \
    load_scene, mesh_flags, scene_spec, working
from studies.cli.options import Options, add_fem_options, add_model_options, add_no_guard, add_scene_options, \
    positive_int, refinements

HELP = "FEM reference (scikit-fem) of one scene"


def add_options(parser, opts: Options) -> None:
    """The options of ``hybmss fem``."""
    opts.add(parser, "--scene", choices=SCENES, default=None, help="experiment (default compression)")
    opts.add(parser, "--scene-json", default=None, metavar="FILE",
             help="solve a stored Scene (Scene.to_dict JSON) instead of an experiment")
    add_scene_options(parser, opts)
    add_model_options(parser, opts)
    add_fem_options(parser, opts)
    opts.add(parser, "--load-steps", type=positive_int, default=None,
             help="load steps of the finite-strain laws (integer >= 1; default 5)")
    opts.add(parser, "--linear-solver", choices=("auto", "direct", "amg"), default="auto",
             help="linear solver (default auto: direct below a size or separator, AMG-CG above)")
    opts.add(parser, "--convergence", type=refinements, default=None, metavar="R1,R2[,R3]",
             help="solve on these refinements; report observed order and Richardson errors")
    add_no_guard(parser, opts)


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
        guard(sizing.fem(scene.body.shape, args.element, r, law, nu), mesh_flags(spec, scene.body.shape, r),
              lambda shape, r=r: sizing.fem(shape, args.element, r, law, nu), args)
    if args.scene_json:
        why = unsupported(scene) or plates_cross(scene)
        if why:
            raise InputError(f"--scene-json = {args.scene_json} is not allowed: {why}; allowed: plates that "
                             "do not cross")

    with working():
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
