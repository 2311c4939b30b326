"""§2: Tables 2–6 of [G20] beside ours (volume change, reaction force and torque, meshes, beam
deflection), the models [G20] does not list in tables of their own, and their figures."""

from __future__ import annotations

import math
import numpy as np
import pandas as pd

from ..data import (PAPER_PP, REL_PCT, Results, e_threshold, paper_source, paper_table, run_state)
from ..tables import (E_DIFF_PP, MAX_COLUMNS, OWN_MESH_NOTE, REL_DIFF_PCT, SIGNS, Table, chunks, flagged, fmt, grade,
                      load_cell, method_cols, method_value, nonunique_note, nonunique_scenes, pp, pp_cell, ran_on,
                      reference_column, rel, rel_cell, short_head, split_methods)
from .base import Context, Section, add_tables
from .summary import claim_findings


def volume_table(results: Results, name: str, experiment: str, number: int) -> Table | None:
    """[G20] Table 2 or 3 beside ours: [G20]'s own models and FEM, ours and the publication's, the
    differences and a verdict per row (the other models: :func:`competitors_volume_tables`)."""
    t = results.table(name)
    if t is None:
        return None
    t = t.sort_values(["mesh", "deformation", "nu"])
    methods = method_cols(results, t)
    own, _, _ = split_methods(results, methods)
    t = _own_meshes(results, t, experiment, own)
    if t.empty:
        return None
    paper_own = [m for m in own if f"paper {m.rsplit(' ', 1)[0]}" in t]
    subject = f"{results.published_model('proposed')} static"
    pfem = "paper FEM (LS-Dyna)"
    cols = ["mesh", "ν", "d (%)"]
    for m in paper_own:
        cols += [f"{short_head(results, m)} ours", f"{short_head(results, m)} [G20]"]
    cols += ["FEM ours", "FEM [G20]", f"Δ {short_head(results, subject)} − FEM, ours (pp)",
             f"Δ {short_head(results, subject)} − FEM, [G20] (pp)", f"Δ {short_head(results, subject)} ours − [G20] (pp)", "verdict"]
    flags = nonunique_scenes(results)
    rows = []
    for _, r in t.iterrows():
        ref_col, ref, law = reference_column(results, experiment, methods, r, "deformation")
        row = [(r["mesh"], ""), (fmt(r["nu"], 3), ""), load_cell(r, "deformation")]
        for m in paper_own:
            cell = method_value(results, experiment, m, r, "deformation", law)
            row += [flagged(cell, flags, m, experiment, r, "deformation"),
                    (fmt(r[f"paper {m.rsplit(' ', 1)[0]}"], 3), "paper")]
        row += [(fmt(ref), "ref") if pd.notna(ref) else ("missing", ""), (fmt(r.get(pfem, np.nan), 3), "paper")]
        ours = r.get(subject, np.nan)
        theirs = r.get(f"paper {subject.rsplit(' ', 1)[0]}", np.nan)
        d_fem, d_paper_fem, d_paper = pp(ours, ref), pp(theirs, r.get(pfem, np.nan)), pp(ours, theirs)
        row += [pp_cell(d_fem, (e_threshold(r["deformation"]), 3 * e_threshold(r["deformation"]))),
                (pp_cell(d_paper_fem)[0], "paper"), pp_cell(d_paper)]
        row.append(_volume_verdict(d_fem, d_paper, r["deformation"]))
        rows.append(row)
    src = paper_source(f"g20_table{number}_{experiment}")
    body = "10×10×10 cube of 5 m" if experiment == "compression" else "0.4 × 0.4 × 2.4 m beam"
    return Table(f"table{number}", f"Table {number} beside [G20]: {experiment}, relative volume change e (%)",
                 f"{experiment.capitalize()} of the {body}, E = 10 kPa, ρ = 1000 kg/m³, static equilibria; "
                 f"e = |V′ − V0|/V0 in % as [G20] prints it (a magnitude; FEM V′ = ∫ det F dX, linear FEM ∫ (1 + div u) dX). "
                 f"FEM ours (bold) = linear at d = 5 %, Neo-Hookean at 20 %; [G20]'s FEM is LS-Dyna. "
                 f"{SIGNS} Δ in percentage points; against FEM green within the claims' criterion "
                 f"(|Δ| ≤ {e_threshold(0.05):g} pp at 5 %, ≤ {e_threshold(0.2):g} pp at 20 %), against [G20] green "
                 f"|Δ| ≤ {E_DIFF_PP[0]:g} pp, amber ≤ {E_DIFF_PP[1]:g} pp. Verdict: 'as [G20]' within {PAPER_PP:g} pp "
                 f"of the publication; 'as FEM' within the FEM criterion.{nonunique_note(rows)} [G20] ran the 10×10×10 "
                 f"cube and the 4×4×24 / 8×8×48 beams: compare meshes before reading a Δ. Other models: the next "
                 f"table. Publication: {src}", cols, rows)


def _own_meshes(results: Results, t: pd.DataFrame, experiment: str, own: list[str]) -> pd.DataFrame:
    """The rows of ``t`` on a mesh that one of [G20]'s models ran on (not the engines' own meshes)."""
    ran = ran_on(results, experiment)
    return t[[any((str(mesh), m) in ran for m in own) for mesh in t["mesh"]]]


def _volume_verdict(d_fem: float, d_paper: float, deformation: float) -> tuple[str, str]:
    if pd.isna(d_fem) and pd.isna(d_paper):
        return "no result", "fail"
    parts = []
    if pd.notna(d_paper):
        parts.append("as [G20]" if abs(d_paper) <= PAPER_PP else "not as [G20]")
    if pd.notna(d_fem):
        parts.append("as FEM" if abs(d_fem) <= e_threshold(deformation) else "not as FEM")
    good = all(not p.startswith("not") for p in parts)
    return ", ".join(parts), "good" if good else ("bad" if all(p.startswith("not") for p in parts) else "warn")


def competitors_volume_tables(results: Results, name: str, experiment: str, number: int) -> list[Table]:
    """The models [G20] does not tabulate (competitors, variants) against the same FEM reference:
    Δe = e_model − e_FEM (pp) per row, split so that no table has more than :data:`MAX_COLUMNS`."""
    t = results.table(name)
    if t is None:
        return []
    t = t.sort_values(["mesh", "deformation", "nu"])
    methods = method_cols(results, t)
    own, fem, _ = split_methods(results, methods)
    tabulated = [m for m in own if f"paper {m.rsplit(' ', 1)[0]}" in t]  # the models of volume_table
    others = [m for m in methods if m not in tabulated and m not in fem]
    th = (E_DIFF_PP[0], E_DIFF_PP[1])
    return _competitor_tables(results, t, experiment, others, "deformation", f"table{number}_others",
                              f"Table {number}, other models: {experiment}, Δe = e_model − e_FEM (pp)",
                              f"The models of this harness that [G20]'s Table {number} does not list, against the "
                              f"same FEM reference as Table {number} (linear at 5 %, Neo-Hookean at 20 %): e as "
                              f"there (%, magnitude), Δe = e_model − e_FEM in percentage points (green |Δe| ≤ "
                              f"{th[0]:g} pp, amber ≤ {th[1]:g} pp). Values of e: tables/{name}.csv.",
                              "FEM ref e (%)", lambda v, ref: pp_cell(pp(v, ref), th), "(pp)")


def _competitor_tables(results: Results, t: pd.DataFrame, experiment: str, others: list[str], load: str,
                       tid: str, title: str, caption: str, ref_head: str, delta, unit: str) -> list[Table]:
    if not others:
        return []
    load_head = "θ (°)" if load == "angle_deg" else "d (%)"
    per = MAX_COLUMNS - 4
    methods = method_cols(results, t)
    flags = nonunique_scenes(results)
    ran = ran_on(results, experiment)
    out = []
    for k, chunk in enumerate(chunks(others, per)):
        cols = ["mesh", "ν", load_head, ref_head] + [f"{short_head(results, m)} {unit}" for m in chunk]
        rows = []
        for _, r in t.iterrows():
            _, ref, law = reference_column(results, experiment, methods, r, load)
            row = [(r["mesh"], ""), (fmt(r["nu"], 3), ""), load_cell(r, load),
                   (fmt(ref), "ref") if pd.notna(ref) else ("missing", "")]
            for m in chunk:
                v = r.get(m, np.nan)
                cell = delta(v, ref) if pd.notna(v) else method_value(results, experiment, m, r, load, law, ran=ran)
                row.append(flagged(cell, flags, m, experiment, r, load))
            rows.append(row)
        suffix = f" ({k + 1} of {len(chunks(others, per))})" if len(others) > per else ""
        out.append(Table(f"{tid}{'_' + str(k + 1) if k else ''}", title + suffix,
                         caption + " " + SIGNS + " " + OWN_MESH_NOTE + nonunique_note(rows), cols, rows))
    return out


def reaction_table(results: Results, name: str, experiment: str, number: int, load: str, unit: str,
                   quantity: str) -> Table | None:
    """[G20]'s own models against the FEM reference at every ν and load (the publication's values
    at ν = 1/4: :func:`published_reaction_table`; the other models: :func:`competitors_reaction_tables`)."""
    t = results.table(name)
    if t is None:
        return None
    t = t.sort_values(["mesh", load, "nu"])
    methods = method_cols(results, t)
    own, _, _ = split_methods(results, methods)
    t = _own_meshes(results, t, experiment, own)
    if t.empty:
        return None
    load_head = "θ (°)" if load == "angle_deg" else "d (%)"
    cols = ["mesh", "ν", load_head] + [f"{short_head(results, m)} ({unit})" for m in own] + [f"FEM ref ({unit})"]
    cols += [f"{short_head(results, m)} − FEM (%)" for m in own] + ["verdict"]
    flags = nonunique_scenes(results)
    rows = []
    for _, r in t.iterrows():
        _, ref, law = reference_column(results, experiment, methods, r, load)
        row = [(r["mesh"], ""), (fmt(r["nu"], 3), ""), load_cell(r, load)]
        row += [flagged(method_value(results, experiment, m, r, load, law), flags, m, experiment, r, load)
                for m in own]
        row.append((fmt(ref), "ref") if pd.notna(ref) else ("missing", ""))
        rels = [rel(r.get(m, np.nan), ref) for m in own]
        row += [rel_cell(d) for d in rels]
        within = [abs(d) <= REL_PCT for d in rels if pd.notna(d)]
        row.append(("no result", "fail") if not within else
                   (f"{sum(within)} of {len(own)} within {REL_PCT:g} %",
                    "good" if all(within) and len(within) == len(own) else ("warn" if any(within) else "bad")))
        rows.append(row)
    loadtxt = "top plate rotated by θ about the vertical axis" if load == "angle_deg" else "top plate moved along x by d·H"
    return Table(f"table{number}", f"Table {number}: {experiment}, {quantity} ({unit}), [G20]'s models against FEM",
                 f"{experiment.capitalize()} of the 5 m cube, bottom clamped, {loadtxt}; E = 10 kPa, static equilibria; "
                 f"{quantity} on the top plate in {unit}. FEM ref (bold) = linear at small load (5 %, 1°), "
                 f"Neo-Hookean at large load. {SIGNS} Green ≤ {REL_DIFF_PCT[0]:g} %, amber ≤ "
                 f"{REL_DIFF_PCT[1]:g} %, red above.{nonunique_note(rows)} [G20]'s values (ν = 0.25 only) are in the "
                 f"table 'beside [G20]'; the other models in the table after it.", cols, rows)


def competitors_reaction_tables(results: Results, name: str, experiment: str, number: int, load: str,
                                unit: str, quantity: str) -> list[Table]:
    t = results.table(name)
    if t is None:
        return []
    t = t.sort_values(["mesh", load, "nu"])
    _, _, others = split_methods(results, method_cols(results, t))
    return _competitor_tables(results, t, experiment, others, load, f"table{number}_others",
                              f"Table {number}, other models: {experiment}, {quantity}, (model − FEM) / |FEM| (%)",
                              f"The models of this harness that [G20]'s Table {number} does not list, against the "
                              f"same FEM reference ({unit}): relative difference in % (green ≤ {REL_DIFF_PCT[0]:g} %, "
                              f"amber ≤ {REL_DIFF_PCT[1]:g} %). Values: tables/{name}.csv.",
                              f"FEM ref ({unit})", lambda v, ref: rel_cell(rel(v, ref)), "(%)")


def _deflection_rel(v, ref) -> float:
    """(|v| − |ref|) / |ref| in %: negative when the model deflects less than the reference."""
    return rel(abs(v), abs(ref)) if not (pd.isna(v) or pd.isna(ref)) else np.nan


BENDING_SIGNS = ("Differences compare deflection magnitudes, (|model| − |reference|) / |reference| in %: negative "
                 "when the model deflects less (is stiffer).")


def bending_table(results: Results) -> Table | None:
    """[G20]'s own models against the finite-strain FEM and Euler–Bernoulli (the others:
    :func:`bending_others_tables`)."""
    t = results.table("bending")
    if t is None:
        return None
    methods = method_cols(results, t)
    own, fem, _ = split_methods(results, methods)
    t = _own_meshes(results, t, "bending", own)
    if t.empty:
        return None
    ran = ran_on(results, "bending")
    nh = results.fem_with_law(fem, "neo-hookean")
    cols = ["mesh", "E (MPa)"] + [f"{short_head(results, m)} (m)" for m in own + fem] + ["Euler–Bernoulli (m)"]
    cols += [f"{short_head(results, m)} vs FEM NH (%)" for m in own] + [f"{short_head(results, m)} vs E–B (%)" for m in own]
    rows = []
    for _, r in t.sort_values(["mesh", "E"]).iterrows():
        row = [(r["mesh"], ""), (fmt(r["E"] / 1e6, 3), "")]
        row += [(fmt(r[m]), "ref" if m == nh else "") if pd.notna(r[m]) else
                method_value(results, "bending", m, r, "E", "", ran=ran) for m in own + fem]
        eb = r.get("euler_bernoulli_tip", np.nan)
        row.append((fmt(eb), "paper"))
        ref = r.get(nh, np.nan) if nh else np.nan
        row += [rel_cell(_deflection_rel(r.get(m, np.nan), ref)) for m in own]
        row += [rel_cell(_deflection_rel(r.get(m, np.nan), eb)) for m in own]
        rows.append(row)
    return Table("table_bending", "Beam under gravity: tip deflection (m)",
                 "Clamped 0.4 × 0.4 × 2.4 m beam, ν = 0.25, ρ = 1000 kg/m³, g = 10 m/s², static equilibria; "
                 "vertical displacement of the free end's centre (m, negative = down). Euler–Bernoulli: "
                 "y(L) = −ρ g l h L⁴ / (8 E I). FEM: Hex2, linear and Neo-Hookean (NH, the reference). "
                 f"{BENDING_SIGNS} Green ≤ {REL_DIFF_PCT[0]:g} %, amber ≤ {REL_DIFF_PCT[1]:g} %, red above. "
                 "Other models: the next table.", cols, rows)


def bending_others_tables(results: Results) -> list[Table]:
    t = results.table("bending")
    if t is None:
        return []
    methods = method_cols(results, t)
    _, fem, others = split_methods(results, methods)
    nh = results.fem_with_law(fem, "neo-hookean")
    if not others or nh is None:
        return []
    ran = ran_on(results, "bending")
    out = []
    parts = chunks(others, MAX_COLUMNS - 3)
    for k, chunk in enumerate(parts):
        cols = ["mesh", "E (MPa)", "FEM NH (m)"] + [f"{short_head(results, m)} (%)" for m in chunk]
        rows = []
        for _, r in t.sort_values(["mesh", "E"]).iterrows():
            row = [(r["mesh"], ""), (fmt(r["E"] / 1e6, 3), ""), (fmt(r[nh]), "ref")]
            row += [rel_cell(_deflection_rel(r[m], r[nh])) if pd.notna(r[m]) else
                    method_value(results, "bending", m, r, "E", "", ran=ran) for m in chunk]
            rows.append(row)
        out.append(Table(f"table_bending_others{'_' + str(k + 1) if k else ''}",
                         "Beam under gravity, other models: tip deflection against FEM NH (%)"
                         + (f" ({k + 1} of {len(parts)})" if len(parts) > 1 else ""),
                         f"The beam of the previous table; each other model's tip deflection against the Neo-Hookean "
                         f"FEM of the same mesh. {BENDING_SIGNS} {OWN_MESH_NOTE} Values: tables/bending.csv.",
                         cols, rows))
    return out


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


def section(ctx: Context) -> Section:
    """Tables 2–6: each "[G20] beside ours" (at most :data:`reports.tables.MAX_COLUMNS` columns),
    the models [G20] does not list in tables of their own, and their figures; opened by the claims
    they decide."""
    results = ctx.results
    s = Section("tables", "Tables 2–6 of the publication, reproduced",
                claim_findings(ctx.claims, "Tables 2, 3", "(Table 4", "(Table 5", "FEM shear force",
                               "FEM torsion torque", "FEM volume change"))
    for name, exp, number in (("table2_compression", "compression", 2), ("table3_tension", "tension", 3)):
        add_tables(s, volume_table(results, name, exp, number), *competitors_volume_tables(results, name, exp, number))
    ctx.add_figures(s, "fig_e")
    for name, exp, number, load, unit, q in (
            ("table4_shear", "shear", 4, "deformation", "N", "reaction force F_x"),
            ("table5_torsion", "torsion", 5, "angle_deg", "N·m", "reaction torque T_z")):
        add_tables(s, reaction_table(results, name, exp, number, load, unit, q),
                   published_reaction_table(results, number),
                   *competitors_reaction_tables(results, name, exp, number, load, unit, q))
    ctx.add_figures(s, "fig_reactions", "fig_torsion_sweep")
    add_tables(s, meshes_table(results), bending_table(results), *bending_others_tables(results))
    return s
