"""The ``hybmss`` command line: one parser for every subcommand, and its contract.

Subcommands: ``info`` (lattice counts), ``moduli`` (effective E, ν, G of a model), ``bench``
(speed of the kernels), ``fem`` (the FEM reference of one scene), ``compare`` (one scene on the
mass-spring system and the FEM, side by side), ``modes`` (a model's natural
frequencies beside the FEM's), ``run`` (the publication's studies) and ``study``
(a user's study file).  Their
implementations are in :mod:`studies.cli.commands`.

The scene options (``--mesh``, ``--E``, ``--nu``, ``--deformation``, ``--angle-deg``, …) are
generated from the fields of :class:`studies.sweep.scenes.SceneSpec`: each parameter is declared, ranged
and defaulted once, there, and means the same in every subcommand.  Solver options take their
defaults from :class:`studies.sweep.runner.SolverSpec`.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import logging
import math
import os
import sys
import traceback
import warnings

from hybmss.experiments import DEFAULTS, SceneSpec, field_default
from hybmss.scene import NEARLY_INCOMPRESSIBLE_NU, parse_mesh

from studies.cli import commands

from studies.cli import modes as modes_command

from studies.sweep import sizing
from studies.sweep.executors import EXECUTORS
from studies.sweep.store import strict
from studies.cli.commands import MSS_SOLVERS, SCENES, SOLVER_DEFAULTS, InputError, SolveFailure, flag, model_choices, \
    model_parameters

ELEMENTS = ("hex1", "hex2", "mixed", "auto")
LAWS = ("linear", "neo-hookean", "svk")
"""The FEM reference's elements and laws (``fem_reference.solve``'s, named here so that a refused
invocation does not import scikit-fem)."""

CONTRACT = """\
exit status and output:
  0  a result; with --json exactly one JSON object on stdout (strict JSON: null, never NaN
     or Infinity).
  2  the input is not allowed: one line on stderr naming the parameter, its value and the
     allowed range, checked before any work starts (a size and time guard refuses what
     would not fit this machine's memory or would run over an hour, says how much it
     would need, and lets --no-guard insist).
  3  the input was valid but the simulation failed (diverged, lost equilibrium, Newton did
     not converge, inverted cells): one line on stderr with the cause and a likely remedy;
     with --json also one JSON object with "status" and "message" on stdout.
  130 stopped by Ctrl-C (one line saying what was kept).
  Never a traceback: --debug shows one (and the solvers' warnings).
"""


COMPARE_UNITS = """\
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

CHOICES = {"model": model_choices}
"""Allowed values of the scene's text parameters."""


# ------------------------------------------------------------------------------- value types
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


# ------------------------------------------------------------------------------- the parser
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


def build_parser() -> tuple[Parser, Options]:
    opts = Options()
    common = Parser(add_help=False)
    opts.add(common, "--json", action="store_true", help="print one JSON object on stdout")
    opts.add(common, "--debug", action="store_true", help="show tracebacks and the solvers' warnings")

    p = Parser(prog="hybmss", description="Hybrid mass-spring systems validated against finite elements.",
               epilog=CONTRACT, formatter_class=argparse.RawDescriptionHelpFormatter, allow_abbrev=False)
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=Parser)

    def command(name, help, func, experiment_default=None):
        q = sub.add_parser(name, help=help, description=help, parents=[common], epilog=CONTRACT,
                           formatter_class=argparse.RawDescriptionHelpFormatter, allow_abbrev=False)
        q.set_defaults(func=func)
        return q

    def no_guard(q):
        opts.add(q, "--no-guard", action="store_true",
                 help="run even when the estimated memory does not fit this machine or the estimated time "
                      f"is over {sizing.duration(sizing.TIME_LIMIT_S)} (a sweep of run: "
                      f"{sizing.duration(sizing.SWEEP_TIME_LIMIT_S)}; studies/sweep/sizing.py)")

    q = command("info", "lattice counts of a scene's body (SPEC Table 6)", commands.info)
    opts.add(q, "--scene", choices=SCENES, default="compression", help="scene whose body is counted "
             "(default compression)")
    add_scene_options(q, opts, names=("mesh", "le"))

    q = command("moduli", "effective E, nu, G of a model (static homogeneous tests)", commands.moduli)
    add_scene_options(q, opts, names=("model", "E", "nu", "rho"))
    add_model_options(q, opts)
    opts.add(q, "--strain", type=number, default=DEFAULTS["uniaxial"]["deformation"],
             help=f"test strain (allowed [1e-06, 0.01]; default {DEFAULTS['uniaxial']['deformation']:g})")
    no_guard(q)

    q = command("bench", "speed of the explicit kernels and the static solver", commands.bench)
    opts.add(q, "--steps", type=positive_int, default=None,
             help="explicit steps per timed run (integer >= 1; default 10000 on 10x10x10, 1000 on 30x30x30)")
    opts.add(q, "--quick", action="store_true", help="fewer, smaller runs (a smoke run, not a measurement)")
    add_scene_options(q, opts, names=("model", "nu", "mesh"))
    opts.add(q, "--threads", type=positive_int, default=None,
             help="threads of one timed configuration (integer >= 1; default 1)")
    opts.add(q, "--precision", choices=("f64", "f32"), default=None,
             help="precision of one timed configuration (default f64)")
    no_guard(q)

    q = command("fem", "FEM reference (scikit-fem) of one scene", commands.fem)
    opts.add(q, "--scene", choices=SCENES, default=None, help="experiment (default compression)")
    opts.add(q, "--scene-json", default=None, metavar="FILE",
             help="solve a stored Scene (Scene.to_dict JSON) instead of an experiment")
    add_scene_options(q, opts)
    add_model_options(q, opts)
    add_fem_options(q, opts)
    opts.add(q, "--load-steps", type=positive_int, default=None,
             help="load steps of the finite-strain laws (integer >= 1; default 5)")
    opts.add(q, "--linear-solver", choices=("auto", "direct", "amg"), default="auto",
             help="linear solver (default auto: direct below a size or separator, AMG-CG above)")
    opts.add(q, "--convergence", type=refinements, default=None, metavar="R1,R2[,R3]",
             help="solve on these refinements; report observed order and Richardson errors")
    no_guard(q)

    q = command("compare", "one scene on the mass-spring system and the FEM reference, side by side",
                commands.compare)
    q.epilog = COMPARE_UNITS + "\n" + CONTRACT
    opts.add(q, "scene", nargs="?", choices=SCENES, default=None, help="experiment (or --scene-json)")
    opts.add(q, "--scene-json", default=None, metavar="FILE",
             help="compare on a stored Scene (Scene.to_dict JSON) instead of an experiment; the FEM law "
                  "defaults to linear")
    add_scene_options(q, opts)
    add_model_options(q, opts)
    add_mss_options(q, opts)
    opts.add(q, "--load-steps", type=positive_int, default=None,
             help="load steps of the mass-spring static solver: at least N, each at most 1/N of the load "
                  "(integer >= 1; default: adaptive from one step)")
    add_fem_options(q, opts)
    no_guard(q)

    q = command("modes", "one model's lowest natural frequencies beside the FEM reference's: errors per mode "
                "and MAC", modes_command.modes)
    opts.add(q, "scene", nargs="?", choices=SCENES, default=None, help="experiment (or --scene-json)")
    opts.add(q, "--scene-json", default=None, metavar="FILE",
             help="the body and supports of a stored Scene (Scene.to_dict JSON) instead of an experiment")
    add_scene_options(q, opts)
    add_model_options(q, opts)
    opts.add(q, "-k", "--modes", dest="k", type=positive_int, default=6,
             help=f"number of modes (integer in [1, {modes_command.K_MAX}]; default 6)")
    g = q.add_argument_group("FEM reference")
    opts.add(g, "--element", "--fem", choices=ELEMENTS, default="auto",
             help=f"hex1, hex2, mixed (Hex2 x Hex1 u-p, pressure condensed) or auto (mixed for nu >= "
                  f"{NEARLY_INCOMPRESSIBLE_NU:g}, else hex2; default)")
    opts.add(g, "--refine", type=positive_int, default=None,
             help=f"split each cell into r^3 elements (integer >= 1; default {SOLVER_DEFAULTS['refine']})")
    opts.add(g, "--mass", choices=modes_command.MASSES, default="consistent",
             help="the FEM's mass matrix: consistent (default) or lumped (row sums)")
    no_guard(q)

    q = command("run", "run the publication's studies and store their results", commands.run)
    opts.add(q, "--study", action="append", default=None, choices=commands.study_names(),
             help="study name (repeatable; default: every study)")
    opts.add(q, "--all", action="store_true", help="every study of make reproduce-paper")
    opts.add(q, "--out", default="artifacts/results", help="results folder (default artifacts/results)")
    opts.add(q, "--quick", action="store_true", help="coarse meshes (the tests' mode)")
    opts.add(q, "--jobs", type=integer, default=None,
             help="parallel runs, >= 1 (default: all cores, or the Dask cluster's threads)")
    opts.add(q, "--executor", choices=EXECUTORS, default="local",
             help="local: a process pool on this machine (default); dask: a dask.distributed "
                  "cluster (--scheduler, or a local cluster of --jobs workers)")
    opts.add(q, "--scheduler", default=None, metavar="ADDRESS",
             help="address of a running dask scheduler, e.g. tcp://host:8786 (--executor dask)")
    opts.add(q, "--no-progress", action="store_true", help="no progress bar")
    no_guard(q)

    q = command("study", "answer a study file (docs/study-format.md): its models against one FEM reference, "
                "with cost, tables and a report", commands.study)
    opts.add(q, "file", metavar="FILE", help="the study file (.toml)")
    opts.add(q, "--quick", action="store_true", help="the file's [body.quick] values (a smoke run)")
    opts.add(q, "--out", default=None, metavar="DIR", help="results folder (default artifacts/studies/<name>)")
    opts.add(q, "--jobs", type=integer, default=None,
             help="parallel runs, >= 1 (default: all cores, or the Dask cluster's threads)")
    opts.add(q, "--scheduler", default=None, metavar="ADDRESS",
             help="address of a running dask scheduler, e.g. tcp://host:8786 (runs on that cluster)")
    opts.add(q, "--no-report", action="store_true", help="tables only, no report")
    opts.add(q, "--no-progress", action="store_true", help="no progress bar")
    return p, opts


# ------------------------------------------------------------------------------- output
def dump(obj) -> str:
    """``obj`` as one line of strict JSON (:func:`studies.sweep.store.strict`: ``null`` for a non-finite
    number; any other object as its text)."""
    return json.dumps(strict(obj), default=str, allow_nan=False)


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


# ------------------------------------------------------------------------------- main
@contextlib.contextmanager
def stdout_to_stderr(out):
    """While a command runs, what it prints (progress lines, notices) goes to stderr, so that stdout
    holds its result alone.  When ``out`` is the process's own stdout, its file descriptor is
    pointed at stderr too, so the worker processes a command starts print there as well."""
    fd = saved = None
    if out is sys.__stdout__:
        try:
            fd, err_fd = out.fileno(), sys.stderr.fileno()
            out.flush()
            saved = os.dup(fd)
            os.dup2(err_fd, fd)
        except (OSError, ValueError, AttributeError):  # no file descriptors (an embedding host)
            fd = saved = None
    try:
        with contextlib.redirect_stdout(sys.stderr):
            yield
    finally:
        if saved is not None:
            try:
                sys.stderr.flush()
            finally:
                os.dup2(saved, fd)
                os.close(saved)


class _Kept(logging.Handler):
    def __init__(self, records: list):
        super().__init__(logging.WARNING)
        self.records = records

    def emit(self, record) -> None:
        self.records.append(record)


@contextlib.contextmanager
def libraries_logged(records: list):
    """While a command runs without ``--debug``, the libraries' log records of level WARNING and
    above (VTK's through pyvista, on a file it cannot read) are kept in ``records`` instead of
    printed: the command's stderr stays one line.  A root handler of its own also stops
    ``logging.error`` from installing one that prints."""
    root = logging.getLogger()
    handler = _Kept(records)
    root.addHandler(handler)
    try:
        yield
    finally:
        root.removeHandler(handler)


OUT_OF_MEMORY = {None: "a coarser mesh or a smaller --refine",
                 "study": "larger cell sizes (body.cell_sizes) or a smaller reference.refine in the study file"}
"""The remedy for a command that ran out of memory (``study`` has no ``--mesh`` nor ``--refine``)."""


def _command(argv) -> str | None:
    """The subcommand named in ``argv`` (its first word that is not an option)."""
    return next((a for a in argv if not a.startswith("-")), None)


def _flag_in(argv, name: str) -> bool:
    head = argv[:argv.index("--")] if "--" in argv else argv
    return name in head


def main(argv=None) -> int:
    """Run the ``hybmss`` command; returns the exit status (0, 2 or 3)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    as_json, debug = _flag_in(argv, "--json"), _flag_in(argv, "--debug")
    out, err = sys.stdout, sys.stderr

    def fail(status: int, kind: str, message: str, result: dict | None = None) -> int:
        message = _one_line(message)
        err.write(f"hybmss: {kind}: {message}\n")
        if as_json:
            kind_ = {2: "invalid", 3: "failed"}.get(status, "interrupted")
            out.write(dump({"status": kind_, "message": message, **(result or {})}) + "\n")
        return status

    caught: list = []
    logged: list = []
    try:
        parser, opts = build_parser()
        args = parser.parse_args(opts.join_values(argv))
        with stdout_to_stderr(out):
            if debug:
                obj, text = args.func(args)
            else:
                with warnings.catch_warnings(record=True) as caught, libraries_logged(logged):
                    warnings.simplefilter("default")
                    obj, text = args.func(args)
    except SystemExit as exc:  # --help
        return int(exc.code or 0)
    except (InputError, ValueError) as exc:
        if debug:
            traceback.print_exc()
        return fail(2, "error", str(exc))
    except KeyboardInterrupt as exc:  # 130, the shell's status for SIGINT; the message says what was kept
        return fail(130, "interrupted", str(exc) or "stopped by Ctrl-C; stored results are kept")
    except MemoryError:
        if debug:
            traceback.print_exc()
        return fail(3, "failed", f"out of memory; use {OUT_OF_MEMORY.get(_command(argv), OUT_OF_MEMORY[None])}")
    except Exception as exc:  # noqa: BLE001 - every failure is one line; --debug shows the traceback
        if debug:
            traceback.print_exc()
        msg = str(exc) if isinstance(exc, SolveFailure) else f"{type(exc).__name__}: {exc}"
        return fail(3, "failed", msg, getattr(exc, "result", None))
    notes = sorted({_one_line(f"{w.category.__name__}: {w.message}") for w in caught}
                   | {_one_line(f"{r.levelname} {r.name}: {r.getMessage()}") for r in logged})
    if as_json:
        obj = {"status": "ok", **obj}
        if notes:
            obj["warnings"] = notes
        out.write(dump(obj) + "\n")
    else:
        out.write(text.rstrip() + "\n")
        if notes:
            err.write(f"hybmss: note: {len(notes)} warning(s) from the solvers (first: {notes[0][:120]}); "
                      "--debug shows them\n")
    out.flush()
    return 0


if __name__ == "__main__":  # pragma: no cover
    os.environ.setdefault("MPLBACKEND", "Agg")
    sys.exit(main())
