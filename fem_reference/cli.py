"""The ``fem`` subcommand: solve a simple scene with the FEM reference.

``hybmss fem --scene compression --mesh 10x10x10 --le 0.5 --E 1e4 --nu 0.25 --deformation 0.2
--element auto --law neo-hookean --refine 1 --json`` prints one JSON object
(:meth:`Result.summary` plus the scene); ``--convergence 1,2,3`` solves on those refinements
and reports each output's observed order and Richardson error estimate instead.  ``--scene-json FILE`` solves any stored Scene
(``Scene.to_dict`` format) instead.  The scenes built here are minimal loadings of a box
are the experiments of :mod:`hybmss.experiments` (the same builder as ``hybmss compare`` and the
studies, so equal arguments give the same scene); options left out take the experiment's
defaults (mesh, E, ν, d, torsion angle, gravity) and the cell edge follows from the body's size.

``register(subparsers)`` adds the subcommand to a parser (``studies.cli`` assembles the
``hybmss`` command); ``python -m fem_reference`` runs it alone.  Bad arguments exit with status 2
and a one-line message.
"""

from __future__ import annotations

import argparse
import json
import sys

from hybmss.cli import OneLineParser, mesh_arg, positive_int
from hybmss.experiments import EXPERIMENTS, SceneSpec
from hybmss.scene import Scene

SCENES = tuple(e for e in EXPERIMENTS if e != "uniaxial")


def build_scene(args):
    """The Scene described by the parsed arguments (:class:`hybmss.experiments.SceneSpec`)."""
    if args.scene_json:
        try:
            with open(args.scene_json) as fh:
                return Scene.from_dict(json.load(fh))
        except OSError as exc:
            raise ValueError(f"cannot read --scene-json: {exc.strerror}: {args.scene_json}") from None
        except (KeyError, TypeError, json.JSONDecodeError) as exc:
            raise ValueError(f"--scene-json is not a scene: {exc}") from None
    return SceneSpec.default(args.scene, mesh=args.mesh, le=args.le, E=args.E, nu=args.nu, rho=args.rho,
                             deformation=args.deformation, angle_deg=args.angle, gravity=args.gravity).build()


def format_result(res) -> str:
    lines = [
        f"{res.solver}  ({res.info['n_dofs']:,} dofs, {res.info['n_elements']:,} elements, "
        f"{res.iterations} Newton iteration(s), {res.wall_time_s:.2f} s)",
        f"  volume change  ∫det F: {100 * res.volume_change:+.4f} %   "
        f"averaged-edge (MSS formula): {100 * (res.info['volume_mss_formula'] / res.volume0 - 1):+.4f} %",
        f"  max |u| = {res.max_displacement:.6g} m   strain energy = {res.energy['strain']:.6g} J",
    ]
    for name, r in res.reactions.items():
        F = ", ".join(f"{v:.6g}" for v in r.force)
        T = ", ".join(f"{v:.6g}" for v in r.torque)
        lines.append(f"  plate {name}: F = ({F}) N   T = ({T}) N·m")
    return "\n".join(lines)


def _refinements(text: str) -> tuple[int, ...]:
    try:
        rs = tuple(int(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected refinement factors like 1,2,3, got {text!r}") from None
    if len(rs) < 2 or min(rs) < 1 or len(set(rs)) != len(rs):
        raise argparse.ArgumentTypeError(f"expected at least two distinct factors >= 1, got {text!r}")
    return rs


def cmd_fem(args) -> int:
    from .solve import solve

    scene = build_scene(args)
    if args.convergence:
        from .convergence import convergence

        study = convergence(scene, refinements=args.convergence, element=args.element, law=args.law,
                            steps=args.steps, method=args.solver)
        if args.json:
            out = study.to_dict()
            out["finest"] = study.results[-1].summary()
            out["scene"] = scene.to_dict()
            json.dump(out, sys.stdout, default=float)
            sys.stdout.write("\n")
        else:
            sys.stdout.write(format_result(study.results[-1]) + "\n" + study.table() + "\n")
        return 0
    res = solve(scene, element=args.element, law=args.law, refine=args.refine, steps=args.steps,
                method=args.solver)
    if args.json:
        out = res.summary()
        out["scene"] = scene.to_dict()
        json.dump(out, sys.stdout, default=float)
        sys.stdout.write("\n")
    else:
        sys.stdout.write(format_result(res) + "\n")
    return 0


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``fem`` subcommand to ``subparsers`` (from ``ArgumentParser.add_subparsers``)."""
    from .solve import ELEMENT_CHOICES, LAW_CHOICES

    q = subparsers.add_parser("fem", help="FEM reference (scikit-fem) of a simple scene")
    q.add_argument("--scene", choices=SCENES, default="compression", help="loading (default compression)")
    q.add_argument("--scene-json", default=None, metavar="FILE", help="solve a stored Scene (JSON) instead")
    q.add_argument("--mesh", type=mesh_arg, default=None, help="NXxNYxNZ cells (default: the experiment's)")
    q.add_argument("--le", type=float, default=None, help="cell edge, m (default: body size / mesh)")
    q.add_argument("--E", type=float, default=None, help="Young's modulus, Pa (default: the experiment's)")
    q.add_argument("--nu", type=float, default=None, help="Poisson ratio in (-1, 0.5) (default 0.25)")
    q.add_argument("--rho", type=float, default=None, help="density, kg/m^3 (default 1000)")
    q.add_argument("--deformation", "-d", type=float, default=None,
                   help="plate displacement / height d (default 0.05)")
    q.add_argument("--angle", type=float, default=None, help="torsion angle, degrees (default 1)")
    q.add_argument("--gravity", type=float, default=None, help="bending: gravity, m/s^2 (default 10)")
    q.add_argument("--element", choices=ELEMENT_CHOICES, default="auto",
                   help="hex1, hex2, mixed (Hex2 x Hex1 u-p) or auto (mixed for nu >= 0.45; default)")
    q.add_argument("--law", choices=LAW_CHOICES, default="linear", help="material law (default linear)")
    q.add_argument("--refine", type=positive_int, default=1, help="split each cell into r^3 elements")
    q.add_argument("--steps", type=positive_int, default=None, help="load steps (finite strain; default 5)")
    q.add_argument("--convergence", type=_refinements, default=None, metavar="R1,R2[,R3]",
                   help="solve on these refinements; report observed order and Richardson errors")
    q.add_argument("--solver", choices=("auto", "direct", "amg"), default="auto", help="linear solver")
    q.add_argument("--json", action="store_true", help="print one JSON object")
    q.set_defaults(func=cmd_fem)
    return q


def main(argv=None) -> int:
    """``python -m fem_reference [fem] ...``."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] != "fem":
        argv = ["fem"] + argv
    p = OneLineParser(prog="hybmss")
    sub = p.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    register(sub)
    args = p.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except ValueError as exc:
        p.exit(2, f"{p.prog}: error: {' '.join(str(exc).split())}\n")
    return 0
