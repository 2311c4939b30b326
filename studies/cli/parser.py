"""The ``hybmss`` command line: one parser for every subcommand, and its contract.

Subcommands, one module each (:data:`COMMANDS`): ``info`` (lattice counts), ``moduli``
(effective E, ν, G of a model), ``bench`` (speed of the kernels), ``fem`` (the FEM reference of
one scene), ``compare`` (one scene on the mass-spring system and the FEM, side by side),
``modes`` (a model's natural frequencies beside the FEM's), ``run`` (the publication's studies)
and ``study`` (a user's study file).  Each module has its ``HELP``, its ``add_options`` and the
function of its name, which takes the parsed arguments and returns ``(obj, text)``: the JSON
object printed by ``--json`` and the table printed otherwise.  What several share is in
:mod:`studies.cli.common` (failures, scene options, guard) and :mod:`studies.cli.options`
(options generated from the scene specification and the models' parameters).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import sys
import traceback
import warnings

from studies.sweep.store import strict
from studies.cli import bench, compare, fem, info, modes, moduli, run, study
from studies.cli.common import InputError, SolveFailure
from studies.cli.options import Options, Parser


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

COMMANDS = (info, moduli, bench, fem, compare, modes, run, study)
"""The subcommands, in the order ``hybmss --help`` lists them: each a module named as it, with its
``HELP`` (and an ``EPILOG`` before the contract), its ``add_options(parser, opts)`` and the
function of its name that does it."""


def build_parser() -> tuple[Parser, Options]:
    """The parser of every subcommand of :data:`COMMANDS`, and the options it declared."""
    opts = Options()
    common = Parser(add_help=False)
    opts.add(common, "--json", action="store_true", help="print one JSON object on stdout")
    opts.add(common, "--debug", action="store_true", help="show tracebacks and the solvers' warnings")

    p = Parser(prog="hybmss", description="Hybrid mass-spring systems validated against finite elements.",
               epilog=CONTRACT, formatter_class=argparse.RawDescriptionHelpFormatter, allow_abbrev=False)
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=Parser)
    for module in COMMANDS:
        name = module.__name__.rsplit(".", 1)[1]
        epilog = getattr(module, "EPILOG", None)
        q = sub.add_parser(name, help=module.HELP, description=module.HELP, parents=[common],
                           epilog=epilog + "\n" + CONTRACT if epilog else CONTRACT,
                           formatter_class=argparse.RawDescriptionHelpFormatter, allow_abbrev=False)
        q.set_defaults(func=getattr(module, name))
        module.add_options(q, opts)
    return p, opts


def dump(obj) -> str:
    """``obj`` as one line of strict JSON (:func:`studies.sweep.store.strict`: ``null`` for a non-finite
    number; any other object as its text)."""
    return json.dumps(strict(obj), default=str, allow_nan=False)


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


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
    from studies.sweep.heap import keep_freed_memory

    keep_freed_memory()  # runs computed in this process (one job) reuse the heap they free
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
