"""``python -m reports build --results DIR --out DIR``: the report from stored results."""

from __future__ import annotations

import argparse
import sys


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m reports", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    b = sub.add_parser("build", help="write index.html, report.pdf, figures/ and vtu/ from a results folder")
    b.add_argument("--results", default="artifacts/results", help="results folder (runs/, tables/)")
    b.add_argument("--out", default="artifacts/report", help="output folder")
    b.add_argument("--no-pdf", action="store_true", help="HTML only")
    b.add_argument("--fresh", action="store_true", help="redraw every figure and render (drop <out>/.cache)")
    b.add_argument("--quiet", action="store_true")
    b.add_argument("--debug", action="store_true", help="show a traceback when the build fails")
    args = parser.parse_args(argv)
    import shutil
    import traceback
    from pathlib import Path

    from .build import build, check_out

    try:  # exit 2: a folder that cannot be read or written, found before any work
        check_out(args.out)
        if args.fresh:
            shutil.rmtree(Path(args.out) / ".cache", ignore_errors=True)
        res = build(args.results, args.out, pdf=not args.no_pdf, verbose=not args.quiet)
    except (FileNotFoundError, NotADirectoryError, PermissionError) as exc:
        if args.debug:
            traceback.print_exc()
        print(f"error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    except Exception as exc:  # noqa: BLE001 - one line; --debug shows the traceback
        if args.debug:
            traceback.print_exc()
        print(f"failed: {type(exc).__name__}: {' '.join(str(exc).split())[:300]}", file=sys.stderr)
        return 3
    pdf = f", {res.pdf} ({res.pages} pages)" if res.pdf else ""
    damaged = sum(w.startswith("damaged run left out") for w in res.warnings)
    left = f"; {damaged} damaged run(s) left out (see the warnings)" if damaged else ""
    print(f"report: {res.html}{pdf}; {res.figures} figures, {len(res.tables)} tables, {res.vtu} VTU files, "
          f"{res.seconds:.1f} s{left}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
