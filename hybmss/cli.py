"""The ``hybmss`` command line: mass-spring subcommands.

``info`` (lattice counts, SPEC Table 6), ``moduli`` (effective E, ν, G of a variant) and
``bench`` (speed of the explicit kernels and the static solver).  Other packages add their own
subcommands to the parser returned by :func:`build_parser` (the installed ``hybmss`` command is
assembled in :mod:`studies.cli`).  ``--json`` prints one JSON object on stdout; bad arguments
exit with status 2 and a one-line message.
"""

from __future__ import annotations

import argparse
import json
import sys

from . import models
from .scene import Body, Material, Model, parse_mesh


class CliError(Exception):
    """A bad argument: reported on one line, exit status 2."""


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line with exit status 2."""

    def error(self, message):  # one line, exit 2
        self.exit(2, f"{self.prog}: error: {message}\n")


def mesh_arg(text: str):
    try:
        return parse_mesh(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {v}")
    return v


def add_material_args(p: argparse.ArgumentParser, E=10_000.0, nu=0.25, rho=1000.0) -> None:
    p.add_argument("--E", type=float, default=E, help=f"Young's modulus, Pa (> 0; default {E:g})")
    p.add_argument("--nu", type=float, default=nu, help=f"Poisson ratio in (-1, 0.5) (default {nu:g})")
    p.add_argument("--rho", type=float, default=rho, help=f"density, kg/m^3 (>= 0; default {rho:g})")


def add_model_args(p: argparse.ArgumentParser, default="hybmss") -> None:
    p.add_argument("--model", choices=models.names(), default=default, help=f"model variant (default {default})")
    p.add_argument("--A", type=float, default=None, help="face/inner diagonal ratio kf/kc (default: variant's)")
    p.add_argument("--e-form", action="store_true", help="spring constants from [G20] eq. 5.12 (E = 5G/2)")


def emit(obj: dict, as_json: bool, table: str) -> None:
    if as_json:
        json.dump(obj, sys.stdout, indent=None, default=float)
        sys.stdout.write("\n")
    else:
        sys.stdout.write(table.rstrip() + "\n")


# ------------------------------------------------------------------------------- commands
def cmd_info(args) -> int:
    from .lattice import Lattice

    body = Body.box(*args.mesh, le=args.le)
    counts = Lattice.from_body(body).counts()
    s = counts["springs"]
    table = "\n".join([
        f"mesh {'x'.join(map(str, args.mesh))}, le = {args.le:g} m",
        f"  volumes (cells)        {counts['volumes']:>10,}",
        f"  vertices (particles)   {counts['vertices']:>10,}",
        f"  edge springs           {s['edge']:>10,}",
        f"  face-diagonal springs  {s['face_diagonal']:>10,}   (merged)",
        f"  inner-diagonal springs {s['inner_diagonal']:>10,}",
        f"  springs, total         {s['total']:>10,}",
        f"  [G20] Table 6, no FD   {counts['paper_springs_no_fd']:>10,}",
        f"  [G20] Table 6, with FD {counts['paper_springs_with_fd']:>10,}   (12 unmerged face diagonals per cell)",
    ])
    emit(counts, args.json, table)
    return 0


def cmd_moduli(args) -> int:
    from .moduli import measure_moduli

    given = {k: v for k, v in (("A", args.A), ("e_form", args.e_form or None)) if v is not None}
    model = Model(args.model, **given)  # a parameter the model does not have: exit 2
    mat = Material(args.E, args.nu, args.rho)
    m = measure_moduli(model, mat, strain=args.strain)
    G = mat.G
    table = "\n".join([
        f"model {model.variant}"
        f"{''.join(f', {k} = {v}' for k, v in model.to_dict().items() if k not in ('name', 'e_form'))}"
        f", E = {mat.E:g} Pa, nu = {mat.nu:g}",
        f"  E_eff  = {m['E_eff']:.6g} Pa   (input {mat.E:g}, rel. error {m['E_eff'] / mat.E - 1:+.2e})",
        f"  nu_eff = {m['nu_eff']:.6g}      (input {mat.nu:g}, error {m['nu_eff'] - mat.nu:+.2e})",
        f"  G_eff  = {m['G_eff']:.6g} Pa   (E/(2(1+nu)) = {G:.6g}, rel. error {m['G_eff'] / G - 1:+.2e})",
    ])
    emit(m, args.json, table)
    return 0


def cmd_bench(args) -> int:
    from .bench import format_bench, run_bench

    d = run_bench(steps=args.steps, quick=args.quick)
    emit(d, args.json, format_bench(d))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="hybmss", description="Hybrid mass-spring systems validated against finite elements.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=OneLineParser)

    q = sub.add_parser("info", help="lattice counts of a box mesh (SPEC Table 6)")
    q.add_argument("--mesh", type=mesh_arg, default=(10, 10, 10), help="NXxNYxNZ cells (default 10x10x10)")
    q.add_argument("--le", type=float, default=0.5, help="cell edge, m (default 0.5)")
    q.add_argument("--json", action="store_true")
    q.set_defaults(func=cmd_info)

    q = sub.add_parser("moduli", help="effective E, nu, G of a model variant (static homogeneous tests)")
    add_model_args(q)
    add_material_args(q)
    q.add_argument("--strain", type=float, default=1e-4, help="test strain (default 1e-4)")
    q.add_argument("--json", action="store_true")
    q.set_defaults(func=cmd_moduli)

    q = sub.add_parser("bench", help="speed of the explicit kernels and the static solver")
    q.add_argument("--steps", type=positive_int, default=10_000, help="explicit steps (default 10000)")
    q.add_argument("--quick", action="store_true", help="fewer, smaller runs")
    q.add_argument("--json", action="store_true")
    q.set_defaults(func=cmd_bench)
    return p


def run(parser: argparse.ArgumentParser, argv=None) -> int:
    """Parse and dispatch; a ``ValueError``/``CliError`` from the inputs exits 2 on one line."""
    args = parser.parse_args(argv)
    if getattr(args, "le", 1.0) is not None and getattr(args, "le", 1.0) <= 0:
        parser.exit(2, f"{parser.prog}: error: --le must be > 0 m, got {args.le}\n")
    try:
        return int(args.func(args) or 0)
    except (ValueError, CliError) as exc:
        msg = " ".join(str(exc).split())
        parser.exit(2, f"{parser.prog}: error: {msg}\n")


def main(argv=None) -> int:
    return run(build_parser(), argv)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
