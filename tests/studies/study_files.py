"""Study files for the tests: a small valid study as a dict, and a TOML writer for it (every
table written as a [table] or [[array of tables]], which TOML reads back the same)."""

from __future__ import annotations

import copy
import json
import tomllib
from pathlib import Path


def small_study() -> dict:
    """A 2 x 2 x 4 cm block (1 cm cells) compressed by 1 % between a clamped floor and a
    translated lid, one model."""
    return {
        "study": {"name": "small", "title": "small block", "budgets": [0.05], "repeats": 1},
        "body": {"box": [0.02, 0.02, 0.04], "cell_sizes": [0.01]},
        "material": {"E": 3000.0, "nu": 0.3, "rho": 1000.0},
        "load_case": [{"name": "press", "support": [
            {"name": "bottom", "region": "z-", "motion": "clamped"},
            {"name": "top", "region": "z+", "motion": "translate", "displacement": [0.0, 0.0, -0.0004]}]}],
        "model": [{"name": "hybmss"}],
        "reference": {"element": "hex2", "law": "linear", "refine": 1},
        "metrics": {"plate_force": ["top"], "points": {"tip": [0.01, 0.01, 0.04]}},
    }


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise TypeError(f"no TOML value for {v!r}")


def _is_tables(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def _table(prefix: str, d: dict, lines: list[str]) -> None:
    for k, v in d.items():
        if not isinstance(v, dict) and not _is_tables(v):
            lines.append(f"{json.dumps(k)} = {_value(v)}")
    for k, v in d.items():
        name = f"{prefix}.{json.dumps(k)}" if prefix else json.dumps(k)
        if isinstance(v, dict):
            lines.append(f"[{name}]")
            _table(name, v, lines)
        elif _is_tables(v):
            for item in v:
                lines.append(f"[[{name}]]")
                _table(name, item, lines)


def dumps(doc: dict) -> str:
    lines: list[str] = []
    _table("", doc, lines)
    text = "\n".join(lines) + "\n"
    assert tomllib.loads(text) == doc, "the writer must read back the same document"
    return text


def write(doc: dict, path: Path) -> Path:
    path.write_text(dumps(doc))
    return path


def changed(doc: dict, edit) -> dict:
    new = copy.deepcopy(doc)
    edit(new)
    return new
