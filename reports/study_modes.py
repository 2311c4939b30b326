"""The natural frequencies of a user's study in its report: the stored table
``tables/<study>_modes_<load case>.csv`` (:mod:`studies.study.modes`) as HTML, read only."""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np
import pandas as pd

SHOWN = ("model", "cell_size_m", "nu", "mode", "kind", "f_ref_hz", "f_model_hz", "error_pct", "mac",
         "model_time_s", "fem_time_s", "fem_element", "status", "message")
HEADERS = {"cell_size_m": "cell size (m)", "nu": "ν", "f_ref_hz": "FEM f (Hz)", "f_model_hz": "model f (Hz)",
           "error_pct": "error (%)", "mac": "MAC", "model_time_s": "model eigen-solve (s)",
           "fem_time_s": "FEM eigen-solve (s)", "fem_element": "FEM", "message": "why no error"}


def _cell(v) -> str:
    if v is None or (isinstance(v, (float, np.floating)) and not np.isfinite(v)):
        return ""
    if isinstance(v, (float, np.floating)):
        return f"{v:.4g}"
    return str(v)


def modes_html(out, study: str, case: str) -> str | None:
    """The stored modes table of load case ``case`` as an HTML table, or None when not stored."""
    path = Path(out) / "tables" / f"{study}_modes_{case}.csv"
    if not path.exists():
        return None
    df = pd.read_csv(path)
    cols = [c for c in SHOWN if c in df.columns]
    head = "".join(f"<th>{html.escape(HEADERS.get(c, c))}</th>" for c in cols)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(_cell(r[c]))}</td>" for c in cols) + "</tr>"
                   for _, r in df.iterrows())
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
