"""The installed ``hybmss`` command: the mass-spring subcommands of :mod:`hybmss.cli` plus the
FEM reference and the study subcommands (which need both solvers)."""

from __future__ import annotations

import sys

from hybmss.cli import build_parser, run


def _subparsers(parser):
    for action in parser._actions:  # argparse keeps the subparsers action here
        if action.__class__.__name__ == "_SubParsersAction":
            return action
    raise RuntimeError("parser has no subcommands")


def full_parser():
    parser = build_parser()
    sub = _subparsers(parser)
    try:
        from fem_reference.cli import register as register_fem
    except ImportError:  # the FEM package is optional at the parser level
        register_fem = None
    if register_fem is not None:
        register_fem(sub)
    from .commands import register as register_studies

    register_studies(sub)
    return parser


def main(argv=None) -> int:
    return run(full_parser(), argv)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
