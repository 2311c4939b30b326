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

from studies.paper import printed
from studies.claims import MIDDLE_LAYER_TOL, REL_PCT, middle_layer_frame

from . import findings
from .data import Results, paper_source, paper_table, run_state

#: |Δe| thresholds, percentage points (Tables 2, 3 against the publication and FEM)
E_DIFF_PP = (1.0, 3.0)
#: relative difference thresholds of reactions and deflections against the reference (%)
REL_DIFF_PCT = (REL_PCT, 2.5 * REL_PCT)
"""Colour grades of a relative difference (%): green within the claims' criterion
(:data:`studies.claims.REL_PCT`), amber within 2.5 times it, as the headline grades."""


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


def _method_cols(results: Results, t: pd.DataFrame, skip=("mesh", "nu", "deformation", "angle_deg", "E")) -> list[str]:
    cols = [c for c in t.columns if c not in skip and not c.startswith("paper") and c != "euler_bernoulli_tip"]
    return results.method_order(cols)


def _published_methods(results: Results, methods) -> list[str]:
    """The static methods of the models [G20] reports, in the registry's order."""
    return [f"{m} static" for m in results.published("G20")["model"] if f"{m} static" in methods]


def _short(m: str) -> str:
    return m.replace(" static", "").replace("fem-auto-", "FEM ").replace("fem-hex2-", "FEM Hex2 ")


def _not_in_design(method: str, law: str) -> bool:
    """A finite-strain FEM column at a small load, where the study runs the linear FEM only."""
    return method.startswith("fem") and law == "linear" and not method.endswith("linear")


def volume_table(results: Results, name: str, experiment: str, number: int) -> Table | None:
    t = results.table(name)
    if t is None:
        return None
    t = t.sort_values(["mesh", "deformation", "nu"])
    methods = _method_cols(results, t)
    own = [m for m in results.published("G20")["model"] if f"paper {m}" in t]
    subject = results.published_model("proposed")
    paper_cols = [f"paper {m}" for m in own] + [c for c in ("paper FEM (LS-Dyna)",) if c in t]
    cols = ["mesh", "ν", "d (%)"] + [f"{_short(m)}" for m in methods] + [c.replace("paper", "[G20]") for c in paper_cols]
    cols += [f"Δ {m} − [G20] (pp)" for m in own] + ["Δ FEM ref − [G20] FEM (pp)", f"Δ {subject} − FEM ref (pp)"]
    rows = []
    for _, r in t.iterrows():
        law = results.reference_law(experiment, r["deformation"])
        ref_col = next((m for m in methods if law and m.startswith("fem") and m.endswith(law)), None)
        ref = r.get(ref_col, np.nan) if ref_col else np.nan
        row = [(r["mesh"], ""), (fmt(r["nu"], 3), ""), (fmt(100 * r["deformation"], 3), "")]
        for m in methods:
            v = r[m]
            if pd.isna(v) and _not_in_design(m, law):
                row.append(("–", ""))
            elif pd.isna(v):
                state = run_state(results, experiment, m, mesh=r["mesh"], nu=r["nu"], deformation=r["deformation"])
                row.append((state or "missing", "fail" if state.startswith("failed") else ""))
            else:
                row.append((fmt(v), "ref" if m == ref_col else ""))
        for c in paper_cols:
            row.append((fmt(r[c], 3), "paper"))

        def delta(a, b):  # printed to 0.001 pp: round-off below that reads as 0
            d = round(a - b, 3) if not (pd.isna(a) or pd.isna(b)) else np.nan
            return (fmt(d, 3) if d != 0 else "0", grade(d, E_DIFF_PP))

        for m in own:
            row.append(delta(r.get(f"{m} static", np.nan), r.get(f"paper {m}", np.nan)))
        row.append(delta(ref, r.get("paper FEM (LS-Dyna)", np.nan)))
        row.append(delta(r.get(f"{subject} static", np.nan), ref))
        rows.append(row)
    src = paper_source(f"g20_table{number}_{experiment}")
    body = "10×10×10 cube of 5 m" if experiment == "compression" else "0.4 × 0.4 × 2.4 m beam"
    return Table(f"table{number}", f"Table {number}: {experiment}, relative volume change e (%)",
                 f"{experiment.capitalize()} of the {body}, E = 10⁴ Pa, ρ = 1000 kg/m³, static equilibria; "
                 f"e = |V′ − V0|/V0 in %, FEM e = ∫ det F. FEM ref (bold) = linear at d = 5 %, Neo-Hookean at 20 %. "
                 f"Δ in percentage points; green |Δ| ≤ {E_DIFF_PP[0]:g} pp, amber ≤ {E_DIFF_PP[1]:g} pp, red above. "
                 f"The publication ran the 10×10×10 cube / 4×4×24 and 8×8×48 beams; compare meshes before "
                 f"reading a Δ. '–': not run at this load (finite-strain FEM at 5 %). Publication: {src}", cols, rows)


def reaction_table(results: Results, name: str, experiment: str, number: int, load: str, unit: str,
                   quantity: str) -> Table | None:
    t = results.table(name)
    if t is None:
        return None
    t = t.sort_values(["mesh", load, "nu"])
    methods = _method_cols(results, t)
    compared = _published_methods(results, methods)
    paper = paper_table(f"g20_table{number}_{experiment}")
    load_head = "θ (°)" if load == "angle_deg" else "d (%)"
    cols = ["mesh", "ν", load_head] + [f"{_short(m)} ({unit})" for m in methods]
    cols += [f"{_short(m)} vs FEM ref (%)" for m in compared]
    if paper is not None:
        cols += [f"[G20] {c.replace('fem_lsdyna', 'FEM (LS-Dyna)')} ({unit})" for c in paper.columns
                 if c not in ("nu", "deformation", "angle_deg")]
    rows = []
    for _, r in t.iterrows():
        law = results.reference_law(experiment, r[load] if load == "deformation" else 0.0,
                                    r[load] if load == "angle_deg" else 0.0)
        ref_col = next((m for m in methods if law and m.startswith("fem") and m.endswith(law)), None)
        ref = r.get(ref_col, np.nan) if ref_col else np.nan
        lv = fmt(r[load], 3) if load == "angle_deg" else fmt(100 * r[load], 3)
        row = [(r["mesh"], ""), (fmt(r["nu"], 3), ""), (lv, "")]
        scene = dict(mesh=r["mesh"], nu=r["nu"], **{load: r[load]})
        for m in methods:
            if pd.isna(r[m]) and _not_in_design(m, law):
                row.append(("–", ""))
            elif pd.isna(r[m]):
                state = run_state(results, experiment, m, **scene)
                row.append((state or "missing", "fail" if state.startswith("failed") else ""))
            else:
                row.append((fmt(r[m]), "ref" if m == ref_col else ""))
        for m in compared:
            v = r.get(m, np.nan)
            rel = 100 * (v - ref) / abs(ref) if not (pd.isna(v) or pd.isna(ref) or ref == 0) else np.nan
            row.append((fmt(rel, 3), grade(rel, REL_DIFF_PCT)))
        if paper is not None:
            keycol = load if load in paper else None
            sel = paper[printed(paper["nu"], r["nu"])]
            if keycol:
                sel = sel[printed(sel[keycol], r[load])]
            for c in paper.columns:
                if c not in ("nu", "deformation", "angle_deg"):
                    row.append((fmt(sel[c].iloc[0]), "paper") if len(sel) else ("not published", ""))
        rows.append(row)
    note = (" [G20] publishes ν = 0.25 only (\"not published\" elsewhere); the table beside [G20] follows."
            if paper is not None else "")
    loadtxt = "top plate rotated by θ about the vertical axis" if load == "angle_deg" else "top plate moved along x by d·H"
    return Table(f"table{number}", f"Table {number}: {experiment}, {quantity} ({unit})",
                 f"{experiment.capitalize()} of the 5 m cube, bottom clamped, {loadtxt}; E = 10⁴ Pa, static equilibria; "
                 f"{quantity} on the top plate in {unit}. FEM ref (bold) = linear at small load (5 %, 1°), "
                 f"Neo-Hookean at large load. Relative differences: green ≤ {REL_DIFF_PCT[0]:g} %, amber ≤ "
                 f"{REL_DIFF_PCT[1]:g} %, red above. '–': not run at this load (finite-strain FEM at the small load).{note}",
                 cols, rows)


def bending_table(results: Results) -> Table | None:
    t = results.table("bending")
    if t is None:
        return None
    methods = _method_cols(results, t)
    subject = results.published_model("proposed")
    cols = ["mesh", "E (MPa)"] + [f"{_short(m)} (m)" for m in methods] + ["Euler–Bernoulli (m)",
                                                                            f"{subject} vs E–B (%)",
                                                                            f"{subject} vs FEM NH (%)"]
    rows = []
    for _, r in t.sort_values(["mesh", "E"]).iterrows():
        row = [(r["mesh"], ""), (fmt(r["E"] / 1e6, 3), "")]
        for m in methods:
            row.append((fmt(r[m]), "ref" if m.endswith("neo-hookean") else ""))
        eb = r.get("euler_bernoulli_tip", np.nan)
        row.append((fmt(eb), "paper"))
        h = r.get(f"{subject} static", np.nan)
        fem = next((r[m] for m in methods if m.startswith("fem") and m.endswith("neo-hookean")), np.nan)
        for refv in (eb, fem):
            rel = 100 * (h - refv) / abs(refv) if not (pd.isna(h) or pd.isna(refv) or refv == 0) else np.nan
            row.append((fmt(rel, 3), grade(rel, REL_DIFF_PCT)))
        rows.append(row)
    return Table("table_bending", "Beam under gravity: tip deflection (m)",
                 "Clamped 0.4 × 0.4 × 2.4 m beam, ν = 0.25, ρ = 1000 kg/m³, g = 10 m/s², static equilibria; "
                 "vertical displacement of the free end's centre (m, negative = down). Euler–Bernoulli: "
                 "y(L) = −ρ g l h L⁴ / (8 E I). FEM: Hex2, linear and Neo-Hookean. Relative differences: green ≤ "
                 f"{REL_DIFF_PCT[0]:g} %, amber ≤ {REL_DIFF_PCT[1]:g} %, red above.", cols, rows)


def meshes_table(results: Results) -> Table | None:
    paper = paper_table("g20_table6_meshes")
    counts = results.table("lattice_counts")
    if paper is None or counts is None:
        return None
    counts = counts.set_index("mesh")
    cols = ["mesh", "[G20] volumes", "[G20] vertices", "[G20] springs (no FD)", "[G20] springs (with FD)",
            "lattice volumes", "lattice vertices", "lattice springs (no FD)", "lattice springs (with FD)"]
    rows = []
    for _, r in paper.iterrows():
        if r["mesh"] not in counts.index:
            continue
        c = counts.loc[r["mesh"]]
        row = [(r["mesh"], "")] + [(fmt(int(r[k])), "paper") for k in
                                    ("volumes", "vertices", "springs_no_fd", "springs_with_fd")]
        for k in ("volumes", "vertices", "springs_no_fd", "springs_with_fd"):
            row.append((fmt(int(c[k])), "good" if int(c[k]) == int(r[k]) else "bad"))
        rows.append(row)
    return Table("table6", "Table 6: meshes of the performance study",
                 "Counts of the lattices of the performance study: [G20] Table 6 next to the counts of this lattice "
                 "(SPEC §1: edge springs + 4 inner diagonals per cell; with FD: + 12 unmerged face diagonals per "
                 "cell). "
                 f"Green: identical. Publication: {paper_source('g20_table6_meshes')}", cols, rows)


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


def moduli_table(results: Results) -> Table | None:
    t = results.table("moduli")
    if t is None:
        return None

    def cls(r, c):
        if c == "status":
            return "good" if r["status"] == "ok" else "fail"
        if c == "nu_eff":
            return grade(r["nu_eff"] - r["nu"], (1e-3, 2e-2))
        if c in ("E_eff_over_E", "G_eff_over_G"):
            return grade(r[c] - 1.0, (1e-3, 2e-2))
        return ""

    return frame_table(t, "table_moduli", "Effective moduli (homogeneous static tests)",
                       "Uniaxial stress and simple shear of a homogeneous block (sliding plates, lateral faces free, "
                       "strain 10⁻⁴), E = 10⁴ Pa. E_eff/E and G_eff/G (–) and ν_eff (–): green within 0.1 % "
                       "(0.001 for ν), amber within 2 %, red beyond. E-form = spring constants of [G20] eq. 5.12, "
                       "which assume E = 5G/2.",
                       {"variant": "variant", "nu": "ν input", "E_eff_over_E": "E_eff / E (–)",
                        "nu_eff": "ν_eff (–)", "G_eff_over_G": "G_eff / G (–)", "status": "status"}, cls)


def _short_state(state: str) -> str:
    """"failed (unstable: StaticSolveError: ...)" -> "failed (unstable)" (the reason is in the
    failures table); other states unchanged."""
    m = re.match(r"^(.*?failed) \(([^:(),]+)", state)
    return f"{m.group(1)} ({m.group(2).strip()})" if m else state


def eform_table(results: Results) -> Table | None:
    t = results.table("eform_check")
    if t is None:
        return None
    if "G_form_state" not in t:  # older result folders: no state columns, the values as stored
        t = t.assign(G_form_state="ok", E_form_state="ok")
    cols = ["experiment", "model", "mesh", "ν", "d (%)", "[G20] e (%)", "G-form e (%)", "E-form e (%)", "closer"]
    rows = []
    for _, r in t.iterrows():
        def val(c, state):
            st = str(state)
            if st == "ok":
                return fmt(r[c]), ""
            if st.startswith("identical"):
                return f"{fmt(r[c])} (identical at ν = 1/4)", ""
            return _short_state(st), "fail" if st.startswith("failed") else ""

        closer = str(r["closer"])
        if closer.startswith("undecided ("):
            closer = "undecided (" + _short_state(closer[len("undecided ("):-1]) + ")"
        rows.append([(r["experiment"], ""), (r["model"], ""), (r["mesh"], ""), (fmt(r["nu"], 3), ""),
                     (fmt(100 * r["deformation"], 3), ""), (fmt(r["paper_pct"], 3), "paper"),
                     val("G_form_pct", r["G_form_state"]), val("E_form_pct", r["E_form_state"]),
                     (closer, {"E-form": "warn", "G-form": "good"}.get(closer, ""))])
    return Table("table_eform", "E-form check: which calibration the publication's columns match",
                 "e (%) of our static equilibria with the spring constants built from G = E/(2(1+ν)) (G-form, this "
                 "harness) and from [G20] eq. 5.12 in terms of E (E-form), each from its own run, against the "
                 "publication's hybmss and hybmss-fd columns (Tables 2, 3). 'closer' names the calibration nearer to "
                 "the publication; 'undecided' where a run failed or is missing, 'same' where the two differ by no "
                 "more than the publication's printed precision (0.01 pp); at ν = 1/4 both are the same constants. "
                 "The reasons of failed runs are in the failures table.",
                 cols, rows)


def differences_table(results: Results) -> Table | None:
    t = results.table("differences")
    if t is None:
        return None
    t = t.copy()
    t["load"] = np.where(t["experiment"] == "torsion", t["angle_deg"].map(lambda v: f"θ = {v:g}°"),
                         (100 * t["deformation"]).map(lambda v: f"d = {v:g} %"))
    t.loc[t["experiment"] == "bending", "load"] = t.loc[t["experiment"] == "bending", "E"].map(
        lambda v: f"E = {v / 1e6:g} MPa")
    t["rel_l2_pct"] = 100 * t["rel_l2"]
    t["spread_pct"] = 100 * t["ref_nh_svk_rel_l2"]
    for c in ("mean_m", "max_m", "mid_layer_mean_m"):
        t[c.replace("_m", "_mm")] = 1e3 * t[c]
    order = {e: i for i, e in enumerate(("compression", "tension", "shear", "torsion", "bending"))}
    t["_exp"] = t["experiment"].map(order).fillna(99)
    t = t.sort_values(["_exp", "mesh", "deformation", "angle_deg", "E", "nu", "method"])

    def cls(r, c):
        if c == "rel_l2_pct":
            return grade(r[c], (5.0, 15.0))
        return ""

    tab = frame_table(t, "table_diff", "Nodal displacement difference MSS vs FEM",
                       "Every MSS static equilibrium against its FEM reference on the same grid (linear at ≤ 5 % / "
                       "≤ 5°, Neo-Hookean above), E = 10⁴ Pa: mean, max and middle-layer (z = H/2) mean of "
                       "|u_MSS − u_FEM| in mm; relative L2 ‖u_MSS − u_FEM‖/‖u_FEM‖ in % (green ≤ 5 %, amber ≤ 15 %); "
                       "NH–SVK spread: relative L2 between the two finite-strain references (%), the reference's own "
                       "model-form uncertainty.",
                       {"experiment": "experiment", "mesh": "mesh", "load": "load", "nu": "ν", "method": "method",
                        "reference": "FEM reference", "mean_mm": "mean (mm)", "max_mm": "max (mm)",
                        "mid_layer_mean_mm": "mid layer (mm)", "rel_l2_pct": "rel. L2 (%)",
                        "spread_pct": "NH–SVK spread (%)"}, cls)
    other = [i for i, k in enumerate(t["mss_key"]) if not results.is_publication_run(k)]
    if other:
        tab.row_classes = {i: "screen-only" for i in other}
        tab.caption += (f" {len(other)} rows of runs from other studies (sweeps, stress tests) are in the HTML page "
                        "only.")
    return tab


FAILURE_CHARS = 120
"""Characters of a failure message printed in the failures table."""


def failures_table(results: Results) -> Table:
    df = results.rows
    bad = df[df["status"] != "ok"] if not df.empty else df
    cols = {"label": "scene", "solver": "solver", "study": "study", "status": "status", "message": "message"}
    if bad.empty:
        return Table("table_failures", "Runs that did not reach a result", "Every stored run reached status ok.",
                     list(cols.values()), [])
    bad = bad.sort_values(["study", "label"]).copy()
    bad["message"] = [" ".join(str(m).split())[:FAILURE_CHARS] + ("…" if len(" ".join(str(m).split())) > FAILURE_CHARS
                                                                    else "") for m in bad["message"]]
    tab = frame_table(bad, "table_failures", "Runs that did not reach a result",
                      f"{len(bad)} of {len(df)} stored runs have a status other than ok; they are reported, not "
                      "hidden: 'unstable' = the static equilibrium was lost (limit point, Hessian no longer positive "
                      "definite), 'diverged' = explicit integration blew up, 'error' = an exception in a solver. "
                      f"Messages shortened to {FAILURE_CHARS} characters (the HTML list of runs links every run).",
                      cols, lambda r, c: "fail" if c == "status" else "")
    other = [i for i, k in enumerate(bad["key"]) if not results.is_publication_run(k)]
    if other:
        tab.row_classes = {i: "screen-only" for i in other}
        tab.caption += (f" {len(other)} of these runs belong to the stress tests of other studies (stability, speed "
                        "against error), whose sections give their outcome; they are listed in the HTML page only.")
    return tab


def runs_table(results: Results, vtu_files: dict) -> Table | None:
    df = results.rows
    if df.empty:
        return None
    df = df.sort_values(["study", "label", "solver"]).copy()
    df["e_pct"] = 100 * df["volume_change"]
    cols = {"study": "study", "label": "scene", "solver": "solver", "status": "status", "e_pct": "signed e (%)",
            "max_displacement": "max |u| (m)", "elapsed_s": "time (s)", "key": "VTU"}
    tab = frame_table(df, "table_runs", "All runs",
                      "Every stored run: signed relative volume change (%), largest displacement (m), wall time (s); "
                      "the VTU link opens the deformed state (point field displacement, cell field "
                      "relative_volume_change) in ParaView.", cols,
                      lambda r, c: ("fail" if r["status"] != "ok" else "good") if c == "status" else "",
                      screen_only=True)
    kcol = list(cols).index("key")
    for i, key in enumerate(df["key"]):
        if key in vtu_files:
            tab.links[(i, kcol)] = f"vtu/{vtu_files[key]}"
            tab.rows[i][kcol] = (f"{key[:8]}.vtu", "")
        else:
            tab.rows[i][kcol] = ("–", "")
    return tab


#: rows of a table printed in the PDF: the rest stay in the HTML page (one page of A4 landscape)
PRINT_ROWS = 30
#: the same for tables whose rows carry a message of a few lines
PRINT_ROWS_LONG = {"table_failures": 16, "table_explicit": 16}


def cap_printed_rows(tab: Table, limit: int | None = None) -> Table:
    """Keep at most ``limit`` rows of ``tab`` in print (rows already screen-only do not count);
    the others are marked screen-only and the caption says so.  The default limit is
    :data:`PRINT_ROWS_LONG` for the tables listed there, else :data:`PRINT_ROWS`."""
    limit = limit if limit is not None else PRINT_ROWS_LONG.get(tab.id, PRINT_ROWS)
    printed = [i for i in range(tab.n_rows) if tab.row_classes.get(i) != "screen-only"]
    if len(printed) <= limit:
        return tab
    for i in printed[limit:]:
        tab.row_classes[i] = "screen-only"
    tab.caption += (f" The PDF prints the first {limit} of these {len(printed)} rows; the HTML page holds all"
                    + (f" (and tables/{tab.csv.split('/')[-1]})" if tab.csv else "") + ".")
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


def performance_short(results: Results) -> Table | None:
    t = results.table("performance_summary")
    if t is None or "ratio_to_baseline" not in t:
        return None
    base = str(t["baseline"].iloc[0]) if "baseline" in t and len(t) else "the baseline"
    cols = {"scene": "scene", "mesh": "mesh", "threads": "threads", "volumes": "volumes", "label": "variant",
            "per_step_us": "per step (µs)", "ratio_to_baseline": f"/ {base}",
            "paper_ratio_to_baseline": f"[G20] / {base}", "ratio_to_springs_only": "/ springs only"}
    return frame_table(t, "table_performance_short", f"Time per step relative to {base}",
                       f"Per-step time of the explicit kernel, ratio to {base} ([G20]'s baseline) and to the "
                       "springs-only lattice on the same mesh and thread count, beside [G20]'s ratios (single-thread "
                       "C++). Ratios from one run each; their noise is in tables/performance_summary.csv.", cols,
                       lambda r, c: "paper" if c.startswith("paper") else "")


def damping_short(results: Results) -> Table | None:
    t = results.table("damping_steps")
    if t is None:
        return None
    cols = {"nu": "ν", "damping": "c (1/s)", "dt": "dt (s)", "tol": "tolerance", "steps_to_tol": "steps to tolerance",
            "error_at_last": "rel. L2 at last step", "last_steps": "last step"}
    return frame_table(t, "table_damping_short", "Steps to the static equilibrium",
                       "Explicit semi-implicit Euler with mass-proportional damping c from rest to the static "
                       "equilibrium of the compression cube: steps until the relative L2 difference falls below the "
                       "tolerance ('> n': not reached within the n steps run).", cols)


def explicit_table(results: Results) -> Table | None:
    """Each explicit run (the publication's protocol) against the static equilibrium of the same scene."""
    df = results.rows
    if df.empty or not (df["solver"] == "mss-explicit").any():
        return None
    ex = df[df["solver"] == "mss-explicit"]
    st = df[(df["solver"] == "mss-static") & (df["status"] == "ok")]
    rows = []
    # the static twin: the same stored scene, every parameter exact, but the dynamic solvers' damping
    keys = [c for c in results.scene_columns() if c not in ("damping", "variant")]

    def cell(v):
        if isinstance(v, (list, tuple, np.ndarray)):
            return tuple(v)
        return None if pd.isna(v) else v  # a missing value matches a missing value

    def scene_of(r) -> tuple:
        return tuple(cell(r[k]) for k in keys)

    twins: dict = {}
    for _, t in st.iterrows():  # the first stored static run of each scene
        twins.setdefault(scene_of(t), t)
    for _, r in ex.sort_values(["study", "label"]).iterrows():
        twin = twins.get(scene_of(r))
        ok = r["status"] == "ok"
        rel = de = np.nan
        if ok and twin is not None:
            a, b = results.arrays(r["key"]), results.arrays(twin["key"])
            if "u" in a and "u" in b and a["u"].shape == b["u"].shape and np.linalg.norm(b["u"]) > 0:
                rel = 100 * float(np.linalg.norm(a["u"] - b["u"]) / np.linalg.norm(b["u"]))
            de = 100 * (float(r["volume_change"]) - float(twin["volume_change"]))
        info = r.get("info") if isinstance(r.get("info"), dict) else {}
        dt, steps = r.get("solver_dt", np.nan), r.get("solver_steps", np.nan)
        rows.append([
            (r["label"], ""), (fmt(dt, 3), ""), (fmt(steps), ""), (fmt(r.get("damping", np.nan), 3), ""),
            (fmt(info.get("dt_crit", r.get("dt_crit", np.nan)), 3), ""),
            (r["status"], "good" if ok else "fail"),
            (fmt(100 * abs(r["volume_change"]), 4) if ok else "–", ""),
            (fmt(100 * abs(twin["volume_change"]), 4) if twin is not None else "–", "ref"),
            (fmt(de, 3), grade(de, (0.1, 1.0))),
            (fmt(rel, 3), grade(rel, (1.0, 5.0))),
            (fmt(info.get("max_speed", np.nan), 3), ""),
            ("" if ok else " ".join(str(r["message"]).split())[:220], ""),
        ])
    other = [i for i, k in enumerate(ex.sort_values(["study", "label"])["key"]) if not results.is_publication_run(k)]
    note = (f" {len(other)} explicit runs of other studies (stability) are listed in the HTML page only."
            if other else "")
    return Table("table_explicit", "Explicit protocol against the static equilibrium",
                 "The publication's protocol: semi-implicit Euler, dt = 1 ms, 10,000 steps (10 s), plates ramped over "
                 "1 s, mass-proportional damping c (s⁻¹, not stated in [G20]); read at the end. Compared with the "
                 "static equilibrium of the same scene: e (%) of both, their difference (pp; green ≤ 0.1, amber ≤ 1) "
                 "and the relative L2 difference of the nodal displacements (%; green ≤ 1, amber ≤ 5). dt_crit (s) "
                 "at rest, largest particle speed at the end (m/s). A large difference means 10 s do not reach "
                 "equilibrium." + note,
                 ["run", "dt (s)", "steps", "c (1/s)", "dt_crit (s)", "status", "e explicit (%)", "e static (%)",
                  "Δe (pp)", "‖Δu‖ rel. L2 (%)", "max speed (m/s)", "message"], rows, css="explicit",
                 row_classes={i: "screen-only" for i in other})


# ------------------------------------------------------------------ the publication's numbers beside ours
def _value_cell(results: Results, experiment: str, method: str, value, digits: int = 4, cls: str = "",
                printed: bool = False, **scene) -> tuple[str, str]:
    if value is not None and not (isinstance(value, float) and math.isnan(value)) and not pd.isna(value):
        return fmt(value, digits), cls
    state = run_state(results, experiment, method, printed=printed, **scene)
    return (state or "missing"), "fail" if state.startswith("failed") else ""


def _ratio_cell(ours, theirs, thresholds=REL_DIFF_PCT) -> tuple[str, str]:
    if pd.isna(ours) or pd.isna(theirs) or theirs == 0:
        return "–", ""
    rel = 100 * (ours - theirs) / abs(theirs)
    return f"{rel:+.3g} %", grade(rel, thresholds)


def published_reaction_table(results: Results, number: int) -> Table | None:
    """[G20] Table 4 (shear force) or 5 (torsion torque): each of its models (by the names of its
    columns) and FEM, ours beside the publication's, at ν = 1/4 and the publication's two loads."""
    experiment, col, unit, quantity = (("shear", "force_x", "N", "reaction force F_x") if number == 4 else
                                       ("torsion", "torque_z", "N·m", "reaction torque T_z"))
    paper = paper_table(f"g20_table{number}_{experiment}")
    mesh = results.primary_mesh(experiment)
    if paper is None or mesh is None:
        return None
    own = {r.name: r.model for r in results.published("G20").itertuples()}
    columns = [(f"{own[c]} static", own[c], c) for c in paper.columns if c in own] + [("FEM", "FEM", "fem_lsdyna")]
    cols = ["mesh", "ν", "[G20] load", "load here"]
    for _, who, _ in columns:
        cols += [f"{who} ours ({unit})", f"{who} [G20] ({unit})", f"{who} ours vs [G20]"]
    rows = []
    for _, p in paper.iterrows():
        scene = dict(mesh=mesh, nu=float(p["nu"]))
        if experiment == "torsion":
            scene["angle_deg"] = float(p["angle_deg"])
            load_here = f"θ = {p['angle_deg']:g}°"
        else:
            scene["deformation"] = float(p["deformation"])
            load_here = f"d = {100 * p['deformation']:g} %"
        row = [(mesh, ""), (fmt(p["nu"], 3), ""), (f"{100 * p['deformation']:g} %", "paper"), (load_here, "")]
        for who, _, pcol in columns:
            if who == "FEM":
                ref = results.reference(experiment, printed=True, **scene)
                v = float(ref[col]) if ref is not None else np.nan
                cell = (fmt(v), "ref") if ref is not None else ("missing", "")
            else:
                m = results.find(experiment, method=who, printed=True, **scene)
                v = float(m[col].iloc[0]) if len(m) and col in m else np.nan
                cell = _value_cell(results, experiment, who, v, printed=True, **scene)
            row += [cell, (fmt(float(p[pcol])), "paper"), _ratio_cell(v, float(p[pcol]))]
        rows.append(row)
    conv = ("Torsion load: [G20] labels its rows 5 % and 20 % without defining d for torsion; this table reads them "
            "as θ = 1° and 45°, the angles at which the published torques agree with linear torsion of a square "
            "section (0.1406 G a⁴ θ / H = 1227 N·m at 1°, [G20] 1277–1306); the reading θ = d·√2 rad (4.05°, 16.2°) "
            "would give about 4,970 and 19,900 N·m. " if experiment == "torsion" else "")
    return Table(f"table{number}_g20", f"Table {number} beside [G20]: {experiment}, {quantity} ({unit}), ν = 0.25",
                 f"{experiment.capitalize()} of the 5 m cube, E = 10⁴ Pa, ν = 0.25, static equilibria on the {mesh} "
                 f"lattice ([G20]: 10×10×10). {conv}FEM here: the reference of this harness (scikit-fem, linear at the "
                 f"small load, Neo-Hookean at the large one); [G20]: LS-Dyna. 'ours vs [G20]': relative difference, "
                 f"green ≤ {REL_DIFF_PCT[0]:g} %, amber ≤ {REL_DIFF_PCT[1]:g} %, red above. Publication: "
                 f"{paper_source(f'g20_table{number}_{experiment}')}", cols, rows)


def middle_layer_table(results: Results) -> Table | None:
    f = middle_layer_frame(results)
    if f.empty:
        return None
    cols = ["experiment", "load", "ν", "mesh", "[G20] (m)", "ours 3D (m)", "ours / [G20]", "ours in-plane x–y (m)",
            "ours 3D vs SVK (m)", "layer points"]
    rows = []
    for _, r in f.iterrows():
        row = [(r["experiment"], ""), (r["load"], ""), (fmt(r["nu"], 3), ""), (r["mesh"], ""),
               (fmt(r["paper_m"], 3), "paper")]
        if r["state"] == "ok":
            ratio = r["ours_m"] / r["paper_m"]
            ok = 1 / MIDDLE_LAYER_TOL <= ratio <= MIDDLE_LAYER_TOL
            row += [(fmt(r["ours_m"], 3), ""), (f"×{ratio:.3g}", "good" if ok else "bad"),
                    (fmt(r["ours_xy_m"], 3), ""), (fmt(r["ours_svk_m"], 3) if pd.notna(r["ours_svk_m"]) else "missing", ""),
                    (fmt(int(r["n_points"])) if pd.notna(r["n_points"]) else "missing", "")]
        else:
            cls = "fail" if str(r["state"]).startswith("failed") else ""
            row += [(r["state"], cls)] + [("–", "")] * 4
        rows.append(row)
    who = results.published_model("proposed")
    return Table("table_middle_layer", f"Mean position difference over the middle layer, {who} vs FEM (Figs 8, 10)",
                 "Shear and torsion of the 5 m cube at the load [G20] labels 20 % (torsion read as θ = 45°, see Table 5). "
                 "Middle layer: the particles of the lattice plane nearest to mid-height z = H/2 (z = 2.5 m), taken in "
                 f"the rest configuration. Ours 3D: mean over those particles of |x_{who} − x_FEM| (Euclidean, m) "
                 "against the Neo-Hookean reference (the default); [G20] does not say which distance, so two "
                 "alternatives follow: the in-plane (x, y) distance only, as a top view of the layer shows it, and the "
                 "3D mean against the St Venant–Kirchhoff reference. 'ours / [G20]': green within a factor "
                 f"{MIDDLE_LAYER_TOL:g}. [G20]'s cube has 10×10×10 cells; compare meshes before reading a ratio. "
                 f"Publication: {paper_source('g20_middle_layer')}", cols, rows)


def b09_table(results: Results) -> Table | None:
    df = findings.b09_frame(results.table("baudet_cantilever"), results.table("baudet_lshape"),
                            paper_table("b09_errors"))
    if df.empty:
        return None
    own = findings.b09_models(df)
    cols = ["experiment", "mesh", "model", "[B09] M", "[B09] SD", "[B09] MAX", "ours M", "ours SD", "ours MAX",
            "ours M / [B09] M", "nodal rel. M", "nodal rel. SD", "nodal rel. MAX"]
    rows = []
    for _, r in df.iterrows():
        is_b09 = r["model"] in own
        row = [(findings.EXPERIMENT_NAMES.get(r["experiment"], r["experiment"]), ""), (r["mesh"], ""), (r["model"], "")]
        for c in ("b09_mean_pct", "b09_sd_pct", "b09_max_pct"):
            v = r.get(c, np.nan)
            row.append((fmt(v, 3), "paper") if is_b09 and pd.notna(v) else ("–" if not is_b09 else "missing", ""))
        if r["state"] == "ok":
            row += [(fmt(r[c], 3), "") for c in ("err_mean_pct", "err_sd_pct", "err_max_pct")]
            pm = r.get("b09_mean_pct", np.nan)
            row.append((f"×{r['err_mean_pct'] / pm:.3g}", "") if is_b09 and pd.notna(pm) else ("–", ""))
            row += [(fmt(r.get(c, np.nan), 3), "") for c in ("rel_mean_pct", "rel_sd_pct", "rel_max_pct")]
        else:
            row += [(r["state"], "fail")] + [("–", "")] * 6
        rows.append(row)
    src = paper_source("b09_errors")
    return Table("table_b09", "[B09]'s experiments at [B09]'s parameters: nodal displacement error (%)",
                 "Cantilever 400 × 100 × 100 mm, E = 1000 Pa, ν = 0.3, clamped at x = 0, own weight with ρ = 0.0125 "
                 "kg/m³ as printed (read in kg/m³, g = 9.81 m/s²; tip deflection 0.47 mm). L-shape in a 4000 mm cube "
                 "(column and arm 2000 mm thick, 4000 mm deep), E = 1 kPa, ν = 0.3, mass neglected, base clamped, the "
                 "printed \"0.3 GN\" read as 0.3 N in total along −z on the arm's free end face (as printed, a strain "
                 "of order 10⁴; in the linear regime the normalized errors do not depend on the force). Every model "
                 "against a Hex2 linear FEM on a finer grid. Ours M, SD, MAX: mean, standard deviation and maximum over "
                 "the particles of |u_MSS − u_FEM| / max|u_FEM| (%); nodal rel.: |u_MSS − u_FEM| / |u_FEM| at the "
                 "particles that move (%). [B09]'s values are for its own model (" + ", ".join(own) + ") and do not say which "
                 f"normalization they use. {src}", cols, rows)
