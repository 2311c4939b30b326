"""The options of the ``hybmss`` subcommands that several of them take, and the parser's parts.

The scene options (``--mesh``, ``--E``, ``--nu``, ``--deformation``, ``--angle-deg``, …) are
generated from the fields of :class:`studies.sweep.scenes.SceneSpec`: each parameter is declared,
ranged and defaulted once, there, and means the same in every subcommand; the model options from
the registered models' parameters.  Solver options take their defaults from
:class:`studies.sweep.runner.SolverSpec`.  A value of the wrong kind is refused by its type
(:func:`number`, :func:`mesh_arg`, …) with one line naming it (:class:`Parser`: exit 2).
"""

from __future__ import annotations

import argparse
import dataclasses
import math

from hybmss.experiments import DEFAULTS, SceneSpec, field_default
from hybmss.scene import NEARLY_INCOMPRESSIBLE_NU, parse_mesh

from studies.sweep import sizing
from studies.cli.common import MSS_SOLVERS, SCENES, SOLVER_DEFAULTS, InputError, flag, model_choices, \
    model_parameters


ELEMENTS = ("hex1", "hex2", "mixed", "auto")
LAWS = ("linear", "neo-hookean", "svk")
"""The FEM reference's elements and laws (``fem_reference.solve``'s, named here so that a refused
invocation does not import scikit-fem)."""

CHOICES = {"model": model_choices}
"""Allowed values of the scene's text parameters."""


def number(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return v


def positive_number(text: str) -> float:
    v = number(text)
    if v <= 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}")
    return v


def non_negative_number(text: str) -> float:
    v = number(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}")
    return v


def positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}")
    return v


def integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


def mesh_arg(text: str):
    try:
        return parse_mesh(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected three integers >= 1 as NXxNYxNZ (e.g. 10x10x10), got {text!r}") from None


def refinements(text: str) -> tuple[int, ...]:
    try:
        rs = tuple(int(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected refinement factors like 1,2,3, got {text!r}") from None
    if len(rs) < 2 or min(rs) < 1 or len(set(rs)) != len(rs):
        raise argparse.ArgumentTypeError(f"expected at least two distinct factors >= 1, got {text!r}")
    return rs


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors raise :class:`InputError` (one line, exit 2)."""

    def error(self, message):
        raise InputError(message)


class Options:
    """The options declared so far, by flag: which take a value, so that ``--E -1e4`` reads
    ``-1e4`` as the value of ``--E`` rather than as an unknown option."""

    def __init__(self):
        self.valued: set[str] = set()
        self.flags: set[str] = set()

    def add(self, parser, *flags, **kw):
        action = parser.add_argument(*flags, **kw)
        self.flags.update(action.option_strings)  # with the --no-X of a BooleanOptionalAction
        if kw.get("action") in (None, "store", "append"):
            self.valued.update(flags)
        return action

    def join_values(self, argv: list[str]) -> list[str]:
        """``[--E, -1e4]`` → ``[--E=-1e4]`` for options that take a value."""
        out, i = [], 0
        while i < len(argv):
            tok = argv[i]
            if tok == "--":
                out.extend(argv[i:])
                break
            nxt = argv[i + 1] if i + 1 < len(argv) else None
            if tok in self.valued and nxt is not None and nxt.startswith("-") and nxt not in self.flags:
                out.append(f"{tok}={nxt}")
                i += 2
                continue
            out.append(tok)
            i += 1
        return out


def _default_text(f: dataclasses.Field) -> str:
    per = {ex: d[f.name] for ex, d in DEFAULTS.items() if f.name in d and ex != "uniaxial"
           and SceneSpec.uses(f.name, ex)}
    if per and len(set(map(str, per.values()))) > 1:
        show = {ex: ("x".join(map(str, v)) if isinstance(v, tuple) else f"{v:g}") for ex, v in per.items()}
        return "default: " + ", ".join(f"{ex} {v}" for ex, v in show.items())
    v = next(iter(per.values())) if per else field_default(f)
    if isinstance(v, tuple):
        v = "x".join(map(str, v))
    return "" if v is None or v is False else f"default: {v:g}" if isinstance(v, float) else f"default: {v}"


def add_scene_options(parser, opts: Options, names=None) -> None:
    """One option per :class:`SceneSpec` parameter (or those in ``names``), default ``None``
    (the experiment's own value)."""
    group = parser.add_argument_group("scene parameters")
    for f in SceneSpec.parameters():
        if names is not None and f.name not in names:
            continue
        meta = f.metadata
        rng = meta["ranges"]
        bits = [meta["help"]]
        if meta["unit"]:
            bits.append(meta["unit"])
        if isinstance(rng, dict):
            bits.append("allowed " + ", ".join(f"{ex} {r}" for ex, r in rng.items() if ex in SCENES))
        elif rng is not None:
            bits.append(f"allowed {rng}")
        if meta["experiments"] is not None:
            bits.append("used by " + ", ".join(e for e in meta["experiments"] if e in SCENES))
        if meta["solvers"] is not None:
            bits.append("solvers " + ", ".join(meta["solvers"]))
        dflt = _default_text(f)
        if dflt:
            bits.append(dflt)
        text = "; ".join(bits).replace("%", "%%")
        flags = (flag(f.name), *meta["flags"])
        if f.type == "bool":
            opts.add(group, *flags, dest=f.name, action="store_const", const=True, default=None, help=text)
        elif f.name in CHOICES:
            opts.add(group, *flags, dest=f.name, choices=CHOICES[f.name](), default=None, help=text)
        elif f.name == "mesh":
            opts.add(group, *flags, dest=f.name, type=mesh_arg, default=None, metavar="NXxNYxNZ", help=text)
        else:
            opts.add(group, *flags, dest=f.name, type=number, default=None, help=text)


def add_model_options(parser, opts: Options) -> None:
    """One option per parameter of the registered models (default ``None``: the model's own)."""
    group = parser.add_argument_group("model parameters (of the models that declare them)")
    for name, (f, owners) in model_parameters().items():
        default = f.default if f.default is not dataclasses.MISSING else None
        doc = f.metadata.get("help", name)
        doc = f"{doc}; parameter of {', '.join(owners)} (default: the model's)".replace("%", "%%")
        kw = dict(dest=name, default=None, help=doc)
        if isinstance(default, bool):  # --X sets it, --no-X clears it, neither: the model's default
            opts.add(group, flag(name), action=argparse.BooleanOptionalAction, **kw)
        elif f.metadata.get("choices"):
            opts.add(group, flag(name), choices=tuple(f.metadata["choices"]), **kw)
        elif isinstance(default, (int, float)):
            opts.add(group, flag(name), type=number, **kw)
        else:
            opts.add(group, flag(name), **kw)


def add_fem_options(parser, opts: Options) -> None:
    from_spec = SOLVER_DEFAULTS
    g = parser.add_argument_group("FEM reference")
    opts.add(g, "--element", "--fem", choices=ELEMENTS, default="auto",
             help=f"hex1, hex2, mixed (Hex2 x Hex1 u-p) or auto (mixed for nu >= {NEARLY_INCOMPRESSIBLE_NU:g}, "
                  "else hex2; default)")
    opts.add(g, "--law", choices=LAWS, default=None,
             help="material law (default: linear up to 5 %% / 5 degrees, neo-hookean above and for bending)")
    opts.add(g, "--refine", type=positive_int, default=None,
             help=f"split each cell into r^3 elements (integer >= 1; default {from_spec['refine']})")


def add_mss_options(parser, opts: Options) -> None:
    d = SOLVER_DEFAULTS
    g = parser.add_argument_group("mass-spring solver")
    opts.add(g, "--solver", choices=MSS_SOLVERS, default="static", help="static (Newton, default), explicit "
             "(symplectic Euler) or implicit (backward Euler to rest)")
    opts.add(g, "--dt", type=positive_number, default=None,
             help=f"time step of explicit/implicit, s (> 0; default {d['dt']:g})")
    opts.add(g, "--steps", type=positive_int, default=None,
             help=f"steps of explicit/implicit (integer >= 1; default {d['steps']})")
    opts.add(g, "--ramp-time", type=non_negative_number, default=None,
             help=f"plate ramp duration of explicit/implicit, s (>= 0; default {d['ramp_time']:g})")


def add_no_guard(parser, opts: Options) -> None:
    """``--no-guard``: run what the size and time guard (:func:`studies.cli.common.guard`) refuses."""
    opts.add(parser, "--no-guard", action="store_true",
             help="run even when the estimated memory does not fit this machine or the estimated time "
                  f"is over {sizing.duration(sizing.TIME_LIMIT_S)} (a sweep of run: "
                  f"{sizing.duration(sizing.SWEEP_TIME_LIMIT_S)}; studies/sweep/sizing.py)")
