"""The natural frequencies and released transients of a user's study in its report: the stored
tables ``tables/<study>_modes_<load case>.csv`` (:mod:`studies.study.modes`),
``<study>_dynamics_<load case>.csv`` and ``<study>_dynamics_budget_<load case>.csv``
(:mod:`studies.study.release`) as HTML, read only."""

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


DYNAMICS_SHOWN = ("model", "cell_size_m", "nu", "integrator", "dt_s", "substeps", "period_ref_s", "period_error_pct",
                  "zeta", "phase_error_rad", "phase_periods", "l2_error", "wall_per_simulated_s",
                  "fem_period_error_pct", "status", "reason")
BUDGET_SHOWN = ("nu", "period_budget_pct", "answer", "model", "cell_size_m", "period_error_pct",
                "wall_per_simulated_s", "n_within", "runner_up", "lead")
DYNAMICS_HEADERS = {"cell_size_m": "cell size (m)", "nu": "ν", "dt_s": "Δt (s)", "period_ref_s": "FEM T₁ (s)",
                    "period_error_pct": "period error (%)", "zeta": "ζ", "phase_error_rad": "phase error (rad)",
                    "phase_periods": "after periods", "l2_error": "L2 error",
                    "wall_per_simulated_s": "wall s per simulated s", "fem_period_error_pct": "FEM's own (%)",
                    "period_budget_pct": "period budget (%)", "n_within": "models within", "reason": "why no result"}


def modes_html(out, study: str, case: str) -> str | None:
    """The stored modes table of load case ``case`` as an HTML table, or None when not stored."""
    return _stored_html(Path(out) / "tables" / f"{study}_modes_{case}.csv", SHOWN, HEADERS)


def dynamics_html(out, study: str, case: str) -> str | None:
    """The stored released-transient table of ``case`` and its budget answer as HTML, or None."""
    tables = Path(out) / "tables"
    runs = _stored_html(tables / f"{study}_dynamics_{case}.csv", DYNAMICS_SHOWN, DYNAMICS_HEADERS)
    budget = _stored_html(tables / f"{study}_dynamics_budget_{case}.csv", BUDGET_SHOWN, DYNAMICS_HEADERS)
    return None if runs is None else runs + (budget or "")


def _stored_html(path: Path, shown, headers: dict) -> str | None:
    if not path.exists():
        return None
    df = pd.read_csv(path)
    cols = [c for c in shown if c in df.columns]
    head = "".join(f"<th>{html.escape(headers.get(c, c))}</th>" for c in cols)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(_cell(r[c]))}</td>" for c in cols) + "</tr>"
                   for _, r in df.iterrows())
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
