"""Tables of the report as display structures: header, rows of cells with a CSS class.

A cell class marks what the reader should see: ``good`` / ``warn`` / ``bad`` for a difference
below / above the thresholds stated in each caption, ``fail`` for a run that did not reach a
result, ``ref`` for the FEM reference column, ``paper`` for the publication's values.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .data import NONUNIQUE_PCT, REL_PCT, Results, run_state

#: |Δe| thresholds, percentage points (Tables 2, 3 against the publication and FEM)
E_DIFF_PP = (1.0, 3.0)
#: relative difference thresholds of reactions and deflections against the reference (%)
REL_DIFF_PCT = (REL_PCT, 2.5 * REL_PCT)
"""Colour grades of a relative difference (%): green within the claims' criterion
(:data:`studies.paper.claims.REL_PCT`), amber within 2.5 times it, as the headline grades."""


@dataclass
class Table:
    id: str
    title: str
    caption: str
    columns: list
    rows: list = field(default_factory=list)  # list of list of (text, css class)
    screen_only: bool = False
    links: dict = field(default_factory=dict)  # (row, col) -> href
    row_classes: dict = field(default_factory=dict)  # row -> css class
    css: str = ""
    csv: str = ""  # link to the stored CSV the table shows (HTML)
    print_note: str = ""  # printed instead of a table kept out of the PDF

    @property
    def n_rows(self) -> int:
        return len(self.rows)


def fmt(v, digits: int = 4, unit: str = "") -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return f"{v}{unit}"
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if v == 0:
            return f"0{unit}"
        if abs(v) >= 1e7 or abs(v) < 1e-3:
            return f"{v:.{digits - 1}e}{unit}"
        if abs(v) >= 10 ** digits:
            return f"{v:.0f}{unit}"
        return f"{v:.{digits}g}{unit}"
    return f"{v}{unit}"


def grade(value, thresholds) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    a = abs(value)
    return "good" if a <= thresholds[0] else ("warn" if a <= thresholds[1] else "bad")


def method_cols(results: Results, t: pd.DataFrame, skip=("mesh", "nu", "deformation", "angle_deg", "E")) -> list[str]:
    cols = [c for c in t.columns if c not in skip and not c.startswith("paper") and c != "euler_bernoulli_tip"]
    return results.method_order(cols)


def published_methods(results: Results, methods) -> list[str]:
    """The static methods of the models [G20] reports, in the registry's order."""
    return [f"{m} static" for m in results.published("G20")["model"] if f"{m} static" in methods]


#: the FEM elements a column head names briefly (any other FEM column is headed by its method)
SHORT_ELEMENTS = {"auto": "", "hex2": "Hex2 "}


def short_head(results: Results, m: str) -> str:
    """A method's column head: a model's static method by its variant, the FEM by its element
    (the automatic one unnamed) and law."""
    i = results.method(m)
    if i["is_fem"] and i["solver_element"] in SHORT_ELEMENTS:
        refine = f" r{i['solver_refine']}" if int(i["solver_refine"]) != 1 else ""
        return f"FEM {SHORT_ELEMENTS[i['solver_element']]}{i['solver_law']}{refine}"
    return i["variant"] if i["solver_kind"] == "static" and not i["is_fem"] else m


def not_in_design(results: Results, method: str, law: str) -> bool:
    """A finite-strain FEM column at a small load, where the study runs the linear FEM only."""
    return results.is_fem(method) and law == "linear" and not results.fem_with_law([method], "linear")


MAX_COLUMNS = 14
"""Columns of a printed table at most: wider tables are split (the PDF build fails on a table
wider than its page, :mod:`reports.layout`)."""

SIGNS = ("Δ = model − reference: positive when the model's value is larger; relative differences "
         "(model − reference) / |reference| in %.")
"""The sign convention of every difference of the report (stated in the captions)."""


NONUNIQUE_NOTE = (f"‡: the explicit run of this scene came to rest more than {NONUNIQUE_PCT:g} % (relative L2 of the "
                  "nodal displacements) from this static equilibrium: the model has more than one equilibrium here, "
                  "and this value is one of them (see 'Failures and non-unique equilibria').")


def nonunique_note(rows: list) -> str:
    """The ‡ note, for a table that has a flagged cell."""
    return " " + NONUNIQUE_NOTE if any(c[1] == "twofold" for row in rows for c in row) else ""


def nonunique_scenes(results: Results) -> set:
    """(method, experiment, mesh, ν, load) of the scenes with two equilibria (``tables/equilibria.csv``)."""
    t = results.table("equilibria")
    if t is None or "apart" not in t:
        return set()
    t = t[t["apart"].astype(str).str.lower() == "true"]
    out = set()
    for _, r in t.iterrows():
        load = float(r["angle_deg"]) if r["experiment"] == "torsion" else float(r["deformation"])
        out.add((r["method"], r["experiment"], str(r["mesh"]), round(float(r["nu"]), 6), round(load, 6)))
    return out


def flagged(cell: tuple[str, str], flags: set, method: str, experiment: str, r, load: str) -> tuple[str, str]:
    """A value cell marked ‡ (and coloured) where its scene has two equilibria."""
    key = (method, experiment, str(r["mesh"]), round(float(r["nu"]), 6), round(float(r[load]), 6))
    if key not in flags or cell[1] == "fail":
        return cell
    return f"{cell[0]} ‡", "twofold"


def split_methods(results: Results, methods: list[str]) -> tuple[list[str], list[str], list[str]]:
    """(the static methods of [G20]'s own models, the FEM methods, every other method) of a table."""
    own = published_methods(results, methods)
    fem = [m for m in methods if results.is_fem(m)]
    return own, fem, [m for m in methods if m not in own and m not in fem]


def reference_column(results: Results, experiment: str, methods: list[str], r, load: str):
    """(reference column, its value) of a row: the FEM law the studies compare the row's load with."""
    law = results.reference_law(experiment, r[load] if load == "deformation" else 0.0,
                                r[load] if load == "angle_deg" else 0.0)
    col = results.fem_with_law(methods, law)
    return col, (r.get(col, np.nan) if col else np.nan), law


def load_cell(r, load: str) -> tuple[str, str]:
    return (fmt(r[load], 3), "") if load == "angle_deg" else (fmt(100 * r[load], 3), "")


def ran_on(results: Results, experiment: str) -> set:
    """(mesh, method) of every stored run of ``experiment``'s own study (of any study where it has
    none), whatever its status: a method without
    a run on a mesh does not run there by design (the engines run on coarse meshes of their own,
    the other models on the publication's), which a table says with "–", not "missing"."""
    rows = results.find(experiment, study=experiment, ok_only=False)  # the experiment's own study's runs
    if rows.empty:  # a folder whose runs another study stored
        rows = results.find(experiment, ok_only=False)
    if rows.empty:
        return set()
    return set(zip(rows["mesh"].astype(str), rows["method"]))


OWN_MESH_NOTE = ("A model runs on the meshes of its rows only: the engines (MuJoCo, Newton) on coarse meshes of "
                 "their own, each row against the FEM on that same mesh; – where a model has no run on a row's mesh.")


def method_value(results: Results, experiment: str, m: str, r, load: str, law: str, cls: str = "",
                  ran: set | None = None) -> tuple[str, str]:
    """A method's value, or what the reader sees instead: not run at this load or on this mesh
    (``ran``: :func:`ran_on`), failed, missing."""
    v = r.get(m, np.nan)
    if pd.isna(v) and not_in_design(results, m, law):
        return "–", ""
    if pd.isna(v) and ran is not None and (str(r["mesh"]), m) not in ran:
        return "–", ""
    if pd.isna(v):
        scene = {"mesh": r["mesh"], load: r[load], **({"nu": r["nu"]} if "nu" in r else {})}
        state = run_state(results, experiment, m, **scene)
        return (state or "missing"), "fail" if state.startswith("failed") else ""
    return fmt(v), cls


def pp(a, b) -> float:
    """a − b in percentage points, to 0.001 pp (round-off below that reads as 0)."""
    return round(a - b, 3) if not (pd.isna(a) or pd.isna(b)) else np.nan


def pp_cell(d: float, thresholds=E_DIFF_PP) -> tuple[str, str]:
    if pd.isna(d):
        return "–", ""
    return (f"{d:+.3g}" if d != 0 else "0"), grade(d, thresholds)


def rel(a, b) -> float:
    """(a − b) / |b| in %."""
    return 100 * (a - b) / abs(b) if not (pd.isna(a) or pd.isna(b) or b == 0) else np.nan


def rel_cell(d: float, thresholds=REL_DIFF_PCT) -> tuple[str, str]:
    return ("–", "") if pd.isna(d) else (f"{d:+.3g}", grade(d, thresholds))


def chunks(items: list, size: int) -> list[list]:
    return [items[i:i + size] for i in range(0, len(items), size)] or [[]]


def frame_table(df: pd.DataFrame, tid: str, title: str, caption: str, columns: dict | None = None,
                classes=None, screen_only=False) -> Table:
    """A plain table of a DataFrame: ``columns`` maps column -> header (with unit)."""
    columns = columns or {c: c for c in df.columns}
    cols = [c for c in columns if c in df.columns]
    rows = []
    for i, (_, r) in enumerate(df.iterrows()):
        row = []
        for c in cols:
            cls = classes(r, c) if classes else ""
            row.append((fmt(r[c]), cls or ""))
        rows.append(row)
    return Table(tid, title, caption, [columns[c] for c in cols], rows, screen_only=screen_only)


def short_state(state: str) -> str:
    """"failed (unstable: StaticSolveError: ...)" -> "failed (unstable)" (the reason is in the
    failures table); other states unchanged."""
    m = re.match(r"^(.*?failed) \(([^:(),]+)", state)
    return f"{m.group(1)} ({m.group(2).strip()})" if m else state


#: rows of a table printed in the PDF: a longer table is a dump, kept to the HTML page and its CSV
PRINT_ROWS = 30
#: the same for tables whose rows carry a message of a few lines
PRINT_ROWS_LONG = {"table_failures": 16, "table_explicit": 16}


def cap_printed_rows(tab: Table, limit: int | None = None) -> Table:
    """A table of more than ``limit`` printed rows (rows already screen-only do not count) is not
    printed at all: the PDF says where it is (the HTML page, its CSV) instead of printing its first
    rows. The default limit is :data:`PRINT_ROWS_LONG` for the tables listed there, else
    :data:`PRINT_ROWS`."""
    limit = limit if limit is not None else PRINT_ROWS_LONG.get(tab.id, PRINT_ROWS)
    printed = [i for i in range(tab.n_rows) if tab.row_classes.get(i) != "screen-only"]
    if tab.screen_only or (0 < len(printed) <= limit) or tab.n_rows == 0:
        return tab
    if not printed:  # every row is of another study: no empty table in print
        tab.screen_only = True
        tab.print_note = f"its {tab.n_rows} rows belong to other studies' sections: in the HTML page (index.html) only."
        return tab
    tab.screen_only = True
    where = f"tables/{tab.csv.split('/')[-1]}" if tab.csv else "the report's tables/ folder"
    tab.print_note = (f"{len(printed)} rows, longer than a page: in the HTML page (index.html) and as CSV in "
                      f"{where}, not printed here.")
    return tab


def stored_table(results: Results, name: str) -> Table | None:
    """A study's table as stored, for the HTML page only (collapsed, with a link to its CSV)."""
    t = results.table(name)
    if t is None:
        return None

    def cls(r, c):
        if c == "status":
            return "good" if str(r[c]) in ("ok", "converged") else "fail"
        if c == "pareto" and str(r[c]) == "True":
            return "good"
        return ""

    cap = (f"{len(t)} rows as stored by the study; units in the column names (_s seconds, _ms milliseconds, _us "
           "microseconds, _m metres, _mm millimetres, _pct percent). Empty cells: the quantity does not apply to the "
           "row or was not measured.")
    tab = frame_table(t, f"table_{name}", f"tables/{name}.csv", cap, classes=cls, screen_only=True)
    tab.css = "generic"
    tab.csv = f"tables/{name}.csv"
    return tab
