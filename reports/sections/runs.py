"""All runs and their VTU files (HTML only)."""

from __future__ import annotations

import numpy as np

from ..data import Results
from ..tables import Table, frame_table
from .base import Context, Section


def runs_table(results: Results, vtu_files: dict) -> Table | None:
    df = results.rows
    if df.empty:
        return None
    df = df.sort_values(["study", "label", "solver"]).copy()
    df["e_pct"] = 100 * df["volume_change"]
    failed = df["status"] != "ok"  # a run that did not reach a result shows no value
    df.loc[failed, ["e_pct", "max_displacement"]] = np.nan
    df.loc[failed & ~df["timing"], "elapsed_s"] = np.nan  # a timing run's time is what it was asked for
    df["status"] = df["status"].where(~df["timing"], "timing run")
    cols = {"study": "study", "label": "scene", "solver": "solver", "status": "status", "e_pct": "signed e (%)",
            "max_displacement": "max |u| (m)", "elapsed_s": "time (s)", "key": "VTU"}
    tab = frame_table(df, "table_runs", "All runs",
                      "Every stored run: signed relative volume change (V′ − V0)/V0 (%), largest displacement (m), "
                      "wall time (s); '–' (and no VTU) for a run that did not reach a result (its status says "
                      "why); a timing run (a short explicit run timing a candidate's steps, not at rest as asked) "
                      "shows its time only; the VTU link opens the deformed state (point field displacement, cell "
                      "field relative_volume_change) in ParaView.", cols,
                      lambda r, c: ("" if r["status"] == "timing run" else "fail" if r["status"] != "ok" else "good")
                      if c == "status" else "",
                      screen_only=True)
    kcol = list(cols).index("key")
    for i, (key, no_result) in enumerate(zip(df["key"], failed)):
        if key in vtu_files and not no_result:  # the state of a run not at rest is no result either
            tab.links[(i, kcol)] = f"vtu/{vtu_files[key]}"
            tab.rows[i][kcol] = (f"{key[:8]}.vtu", "")
        else:
            tab.rows[i][kcol] = ("–", "")
    return tab


def section(ctx: Context) -> Section | None:
    """Every run and its VTU file (HTML only)."""
    t = runs_table(ctx.results, ctx.vtu_files)
    if t is None:
        return None
    return Section("runs", "All runs and VTU files",
                   "Deformed states as VTU (open in ParaView, Warp By Vector on 'displacement'): "
                   "<code>vtu/&lt;key&gt;.vtu</code> next to this page. This list is not printed.",
                   [("table", t)], screen_only=True)
