"""The report formats what the studies stored: it imports the studies in two statements only (the
stored results folder, :mod:`reports.data`; the study-file format, :mod:`reports.study`), and every
other module of :mod:`reports` reads through :mod:`reports.data`."""

from __future__ import annotations

import ast
from pathlib import Path

REPORTS = Path(__file__).resolve().parents[2] / "reports"


def _studies_imports() -> list[tuple[str, int]]:
    out = []
    for path in sorted(REPORTS.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0 else \
                [a.name for a in node.names] if isinstance(node, ast.Import) else []
            if any(n == "studies" or n.startswith("studies.") for n in names):
                out.append((path.relative_to(REPORTS).as_posix(), node.lineno))
    return out


def test_reports_import_the_studies_in_two_statements():
    found = _studies_imports()
    assert len(found) <= 2, found
    assert {f for f, _ in found} <= {"data.py", "study.py"}, found
