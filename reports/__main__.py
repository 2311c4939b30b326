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
    args = parser.parse_args(argv)
    import shutil
    from pathlib import Path

    from .build import build

    if args.fresh:
        shutil.rmtree(Path(args.out) / ".cache", ignore_errors=True)
    try:
        res = build(args.results, args.out, pdf=not args.no_pdf, verbose=not args.quiet)
    except FileNotFoundError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    pdf = f", {res.pdf} ({res.pages} pages)" if res.pdf else ""
    print(f"report: {res.html}{pdf}; {res.figures} figures, {len(res.tables)} tables, {res.vtu} VTU files, "
          f"{res.seconds:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
