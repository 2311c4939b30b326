"""Tables of the report as display structures: header, rows of cells with a CSS class.

A cell class marks what the reader should see: ``good`` / ``warn`` / ``bad`` for a difference
below / above the thresholds stated in each caption, ``fail`` for a run that did not reach a
result, ``ref`` for the FEM reference column, ``paper`` for the publication's values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .data import Results, mesh_counts, paper_source, paper_table

#: |Δe| thresholds, percentage points (Tables 2, 3 against the publication and FEM)
E_DIFF_PP = (1.0, 3.0)
#: relative difference thresholds of reactions and deflections against the reference (%)
REL_DIFF_PCT = (10.0, 25.0)


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


def _method_cols(t: pd.DataFrame, skip=("mesh", "nu", "d", "deformation", "angle_deg", "E")) -> list[str]:
    cols = [c for c in t.columns if c not in skip and not c.startswith("paper") and c != "Euler-Bernoulli"]
    order = ["hybmss static", "hybmss-fd static", "hybmss-cf static", "hybmss (E-form) static"]
    mss = [c for c in order if c in cols] + sorted(c for c in cols if c not in order and not c.startswith("fem"))
    return mss + sorted(c for c in cols if c.startswith("fem"))


def _short(m: str) -> str:
    return m.replace(" static", "").replace("fem-auto-", "FEM ").replace("fem-hex2-", "FEM Hex2 ")


def volume_table(results: Results, name: str, experiment: str, number: int) -> Table | None:
    t = results.table(name)
    if t is None:
        return None
    t = t.sort_values(["mesh", "d", "nu"])
    methods = _method_cols(t)
    paper_cols = [c for c in ("paper hybmss", "paper hybmss-fd", "paper FEM (LS-Dyna)") if c in t]
    cols = ["mesh", "ν", "d (%)"] + [f"{_short(m)}" for m in methods] + [c.replace("paper", "[G20]") for c in paper_cols]
    cols += ["Δ hybmss − [G20] (pp)", "Δ hybmss-fd − [G20] (pp)", "Δ FEM ref − [G20] FEM (pp)",
             "Δ hybmss − FEM ref (pp)"]
    rows = []
    for _, r in t.iterrows():
        law = results.reference_law(experiment, r["d"])
        ref_col = next((m for m in methods if law and m.startswith("fem") and m.endswith(law)), None)
        ref = r.get(ref_col, np.nan) if ref_col else np.nan
        row = [(r["mesh"], ""), (fmt(r["nu"], 3), ""), (fmt(100 * r["d"], 3), "")]
        for m in methods:
            v = r[m]
            failed = m in t and pd.isna(v) and _ran_and_failed(results, experiment, r, m)
            cls = "fail" if failed else ("ref" if m == ref_col else "")
            row.append(("failed" if failed else fmt(v), cls))
        for c in paper_cols:
            row.append((fmt(r[c], 3), "paper"))

        def delta(a, b):
            d = a - b if not (pd.isna(a) or pd.isna(b)) else np.nan
            return (fmt(d, 3), grade(d, E_DIFF_PP))

        row.append(delta(r.get("hybmss static", np.nan), r.get("paper hybmss", np.nan)))
        row.append(delta(r.get("hybmss-fd static", np.nan), r.get("paper hybmss-fd", np.nan)))
        row.append(delta(ref, r.get("paper FEM (LS-Dyna)", np.nan)))
        row.append(delta(r.get("hybmss static", np.nan), ref))
        rows.append(row)
    src = paper_source(f"g20_table{number}_{experiment}")
    body = "10×10×10 cube of 5 m" if experiment == "compression" else "0.4 × 0.4 × 2.4 m beam"
    return Table(f"table{number}", f"Table {number}: {experiment}, relative volume change e (%)",
                 f"{experiment.capitalize()} of the {body}, E = 10⁴ Pa, ρ = 1000 kg/m³, static equilibria; "
                 f"e = |V′ − V0|/V0 in %, FEM e = ∫ det F. FEM ref (bold) = linear at d = 5 %, Neo-Hookean at 20 %. "
                 f"Δ in percentage points; green |Δ| ≤ {E_DIFF_PP[0]:g} pp, amber ≤ {E_DIFF_PP[1]:g} pp, red above. "
                 f"The publication ran the 10×10×10 cube / 4×4×24 and 8×8×48 beams; compare meshes before "
                 f"reading a Δ. Publication: {src}", cols, rows)


def _ran_and_failed(results: Results, experiment: str, r, method: str) -> bool:
    sub = results.find(experiment, mesh=r["mesh"], nu=r["nu"], deformation=r.get("d"), method=method,
                       ok_only=False)
    return not sub.empty and (sub["status"] != "ok").all()


def reaction_table(results: Results, name: str, experiment: str, number: int, load: str, unit: str,
                   quantity: str) -> Table | None:
    t = results.table(name)
    if t is None:
        return None
    t = t.sort_values(["mesh", load, "nu"])
    methods = _method_cols(t)
    paper = paper_table(f"g20_table{number}_{experiment}")
    load_head = "θ (°)" if load == "angle_deg" else "d (%)"
    cols = ["mesh", "ν", load_head] + [f"{_short(m)} ({unit})" for m in methods]
    cols += ["hybmss vs FEM ref (%)", "hybmss-fd vs FEM ref (%)"]
    if paper is not None:
        cols += [f"[G20] {c} ({unit})" for c in paper.columns if c not in ("nu", "deformation", "angle_deg")]
    rows = []
    for _, r in t.iterrows():
        law = results.reference_law(experiment, r[load] if load == "deformation" else 0.0,
                                    r[load] if load == "angle_deg" else 0.0)
        ref_col = next((m for m in methods if law and m.startswith("fem") and m.endswith(law)), None)
        ref = r.get(ref_col, np.nan) if ref_col else np.nan
        lv = fmt(r[load], 3) if load == "angle_deg" else fmt(100 * r[load], 3)
        row = [(r["mesh"], ""), (fmt(r["nu"], 3), ""), (lv, "")]
        for m in methods:
            row.append((fmt(r[m]), "ref" if m == ref_col else ""))
        for m in ("hybmss static", "hybmss-fd static"):
            v = r.get(m, np.nan)
            rel = 100 * (v - ref) / abs(ref) if not (pd.isna(v) or pd.isna(ref) or ref == 0) else np.nan
            row.append((fmt(rel, 3), grade(rel, REL_DIFF_PCT)))
        if paper is not None:
            keycol = "deformation" if "deformation" in paper else ("angle_deg" if "angle_deg" in paper else None)
            sel = paper[np.isclose(paper["nu"], r["nu"])]
            if keycol:
                sel = sel[np.isclose(sel[keycol], r[load])]
            for c in paper.columns:
                if c not in ("nu", "deformation", "angle_deg"):
                    row.append((fmt(sel[c].iloc[0]) if len(sel) else "–", "paper"))
        rows.append(row)
    note = ("" if paper is not None else
            f" The publication's Table {number} values are not stored in studies/data "
            f"(g20_table{number}_{experiment}.csv would be shown here); the comparison is against FEM.")
    loadtxt = "top plate rotated by θ about the vertical axis" if load == "angle_deg" else "top plate moved along x by d·H"
    return Table(f"table{number}", f"Table {number}: {experiment}, {quantity} ({unit})",
                 f"{experiment.capitalize()} of the 5 m cube, bottom clamped, {loadtxt}; E = 10⁴ Pa, static equilibria; "
                 f"{quantity} on the top plate in {unit}. FEM ref (bold) = linear at small load (5 %, 1°), "
                 f"Neo-Hookean at large load. Relative differences: green ≤ {REL_DIFF_PCT[0]:g} %, amber ≤ "
                 f"{REL_DIFF_PCT[1]:g} %, red above.{note}", cols, rows)


def bending_table(results: Results) -> Table | None:
    t = results.table("bending")
    if t is None:
        return None
    methods = _method_cols(t)
    cols = ["mesh", "E (MPa)"] + [f"{_short(m)} (m)" for m in methods] + ["Euler–Bernoulli (m)",
                                                                            "hybmss vs E–B (%)", "hybmss vs FEM NH (%)"]
    rows = []
    for _, r in t.sort_values(["mesh", "E"]).iterrows():
        row = [(r["mesh"], ""), (fmt(r["E"] / 1e6, 3), "")]
        for m in methods:
            row.append((fmt(r[m]), "ref" if m.endswith("neo-hookean") else ""))
        eb = r.get("Euler-Bernoulli", np.nan)
        row.append((fmt(eb), "paper"))
        h = r.get("hybmss static", np.nan)
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
    if paper is None:
        return None
    cols = ["mesh", "[G20] volumes", "[G20] vertices", "[G20] springs (no FD)", "[G20] springs (with FD)",
            "lattice volumes", "lattice vertices", "lattice springs (no FD)", "lattice springs (with FD)"]
    rows = []
    for _, r in paper.iterrows():
        c = mesh_counts(*[int(v) for v in str(r["mesh"]).split("x")])
        row = [(r["mesh"], "")] + [(fmt(int(r[k])), "paper") for k in
                                    ("volumes", "vertices", "springs_no_fd", "springs_with_fd")]
        for k in ("volumes", "vertices", "springs_no_fd", "springs_with_fd"):
            row.append((fmt(c[k]), "good" if c[k] == int(r[k]) else "bad"))
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


def eform_table(results: Results) -> Table | None:
    t = results.table("eform_check")
    if t is None:
        return None

    def cls(r, c):
        if c == "closer":
            return {"E-form": "warn", "G-form": "good"}.get(r["closer"], "")
        return "paper" if c in ("paper_pct", "paper_hybmss_pct") else ""

    t = t.assign(d=100 * t["d"])
    if "paper_hybmss_pct" in t and "paper_pct" not in t:  # older result folders
        t = t.rename(columns={"paper_hybmss_pct": "paper_pct"}).assign(model="hybmss")
    return frame_table(t, "table_eform", "E-form check: which calibration the publication's columns match",
                       "e (%) of our static equilibria with the spring constants built from G = E/(2(1+ν)) (G-form, "
                       "this harness) and from [G20] eq. 5.12 in terms of E (E-form), against the publication's "
                       "hybmss and hybmss-fd columns (Tables 2, 3). 'closer' names the calibration nearer to the "
                       "publication; at ν = 1/4 both are identical.",
                       {"experiment": "experiment", "model": "model", "mesh": "mesh", "nu": "ν", "d": "d (%)",
                        "paper_pct": "[G20] e (%)", "G_form_pct": "G-form e (%)",
                        "E_form_pct": "E-form e (%)", "closer": "closer"}, cls)


def differences_table(results: Results) -> Table | None:
    t = results.table("differences")
    if t is None:
        return None
    t = t.copy()
    t["load"] = np.where(t["experiment"] == "torsion", t["angle_deg"].map(lambda v: f"θ = {v:g}°"),
                         (100 * t["d"]).map(lambda v: f"d = {v:g} %"))
    t.loc[t["experiment"] == "bending", "load"] = t.loc[t["experiment"] == "bending", "E"].map(
        lambda v: f"E = {v / 1e6:g} MPa")
    t["rel_l2_pct"] = 100 * t["rel_l2"]
    t["spread_pct"] = 100 * t["ref_nh_svk_rel_l2"]
    for c in ("mean_m", "max_m", "mid_layer_mean_m"):
        t[c.replace("_m", "_mm")] = 1e3 * t[c]
    order = {e: i for i, e in enumerate(("compression", "tension", "shear", "torsion", "bending"))}
    t["_exp"] = t["experiment"].map(order).fillna(99)
    t = t.sort_values(["_exp", "mesh", "d", "angle_deg", "E", "nu", "method"])

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


def failures_table(results: Results) -> Table:
    df = results.rows
    bad = df[df["status"] != "ok"] if not df.empty else df
    cols = {"label": "scene", "solver": "solver", "study": "study", "status": "status", "message": "message"}
    if bad.empty:
        return Table("table_failures", "Runs that did not reach a result", "Every stored run reached status ok.",
                     list(cols.values()), [])
    return frame_table(bad.sort_values(["study", "label"]), "table_failures", "Runs that did not reach a result",
                       f"{len(bad)} of {len(df)} stored runs have a status other than ok; they are reported, not "
                       "hidden: 'unstable' = the static equilibrium was lost (limit point, Hessian no longer positive "
                       "definite), 'diverged' = explicit integration blew up, 'error' = an exception in a solver.",
                       cols, lambda r, c: "fail" if c == "status" else "")


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


#: rows of a study table printed in the PDF (all rows stay in the HTML)
PRINT_ROWS = 30


def extra_table(results: Results, name: str) -> Table | None:
    t = results.table(name)
    if t is None:
        return None
    title = f"tables/{name}.csv"

    def cls(r, c):
        if c == "status":
            return "good" if str(r[c]) in ("ok", "converged") else "fail"
        if c == "pareto" and str(r[c]) == "True":
            return "good"
        return ""

    cap = (f"Table {name} as stored by the study: {len(t)} rows; units in the column names (_s seconds, _ms "
           f"milliseconds, _us microseconds, _m metres, _mm millimetres, _pct percent).")
    if len(t) > PRINT_ROWS:
        cap += f" The PDF prints the first {PRINT_ROWS} rows; the HTML page and the CSV hold all {len(t)}."
    tab = frame_table(t, f"table_{name}", title, cap, classes=cls)
    tab.css = "generic"
    tab.row_classes = {i: "screen-only" for i in range(PRINT_ROWS, len(t))}
    return tab


def explicit_table(results: Results) -> Table | None:
    """Each explicit run (the publication's protocol) against the static equilibrium of the same scene."""
    df = results.rows
    if df.empty or not (df["solver"] == "mss-explicit").any():
        return None
    ex = df[df["solver"] == "mss-explicit"]
    st = df[(df["solver"] == "mss-static") & (df["status"] == "ok")]
    rows = []
    keys = ["scene_experiment", "scene_mesh", "scene_model", "scene_e_form"]
    for _, r in ex.sort_values(["study", "label"]).iterrows():
        m = st
        for k in keys:
            m = m[m[k] == r[k]]
        for k in ("scene_nu", "scene_E", "scene_deformation", "scene_angle_deg"):
            m = m[np.isclose(m[k].astype(float), float(r[k]))]
        twin = m.iloc[0] if len(m) else None
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
            (r["label"], ""), (fmt(dt, 3), ""), (fmt(steps), ""), (fmt(r.get("scene_damping", np.nan), 3), ""),
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
