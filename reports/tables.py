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

from studies.sweep.results import printed_match as printed
from studies.paper.equilibria import NONUNIQUE_PCT
from studies.paper.claims import b09_normalisation, b09_particles
from studies.paper.claims import MIDDLE_LAYER_TOL, PAPER_PP, REL_PCT, e_threshold, middle_layer_frame

from . import findings
from .data import Results, paper_source, paper_table, run_state

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


MAX_COLUMNS = 14
"""Columns of a printed table at most: wider tables are split (the PDF build fails on a table
wider than its page, :mod:`reports.layout`)."""

SIGNS = ("Δ = model − reference: positive when the model's value is larger; relative differences "
         "(model − reference) / |reference| in %.")
"""The sign convention of every difference of the report (stated in the captions)."""


NONUNIQUE_NOTE = (f"‡: the explicit run of this scene came to rest more than {NONUNIQUE_PCT:g} % (relative L2 of the "
                  "nodal displacements) from this static equilibrium: the model has more than one equilibrium here, "
                  "and this value is one of them (see 'Failures and non-unique equilibria').")


def _nonunique_note(rows: list) -> str:
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


def _flagged(cell: tuple[str, str], flags: set, method: str, experiment: str, r, load: str) -> tuple[str, str]:
    """A value cell marked ‡ (and coloured) where its scene has two equilibria."""
    key = (method, experiment, str(r["mesh"]), round(float(r["nu"]), 6), round(float(r[load]), 6))
    if key not in flags or cell[1] == "fail":
        return cell
    return f"{cell[0]} ‡", "twofold"


def _split_methods(results: Results, methods: list[str]) -> tuple[list[str], list[str], list[str]]:
    """(the static methods of [G20]'s own models, the FEM methods, every other method) of a table."""
    own = _published_methods(results, methods)
    fem = [m for m in methods if m.startswith("fem")]
    return own, fem, [m for m in methods if m not in own and m not in fem]


def _reference(results: Results, experiment: str, methods: list[str], r, load: str):
    """(reference column, its value) of a row: the FEM law the studies compare the row's load with."""
    law = results.reference_law(experiment, r[load] if load == "deformation" else 0.0,
                                r[load] if load == "angle_deg" else 0.0)
    col = next((m for m in methods if law and m.startswith("fem") and m.endswith(law)), None)
    return col, (r.get(col, np.nan) if col else np.nan), law


def _load_cell(r, load: str) -> tuple[str, str]:
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


def _method_value(results: Results, experiment: str, m: str, r, load: str, law: str, cls: str = "",
                  ran: set | None = None) -> tuple[str, str]:
    """A method's value, or what the reader sees instead: not run at this load or on this mesh
    (``ran``: :func:`ran_on`), failed, missing."""
    v = r.get(m, np.nan)
    if pd.isna(v) and _not_in_design(m, law):
        return "–", ""
    if pd.isna(v) and ran is not None and (str(r["mesh"]), m) not in ran:
        return "–", ""
    if pd.isna(v):
        scene = {"mesh": r["mesh"], load: r[load], **({"nu": r["nu"]} if "nu" in r else {})}
        state = run_state(results, experiment, m, **scene)
        return (state or "missing"), "fail" if state.startswith("failed") else ""
    return fmt(v), cls


def _pp(a, b) -> float:
    """a − b in percentage points, to 0.001 pp (round-off below that reads as 0)."""
    return round(a - b, 3) if not (pd.isna(a) or pd.isna(b)) else np.nan


def _pp_cell(d: float, thresholds=E_DIFF_PP) -> tuple[str, str]:
    if pd.isna(d):
        return "–", ""
    return (f"{d:+.3g}" if d != 0 else "0"), grade(d, thresholds)


def _rel(a, b) -> float:
    """(a − b) / |b| in %."""
    return 100 * (a - b) / abs(b) if not (pd.isna(a) or pd.isna(b) or b == 0) else np.nan


def _rel_cell(d: float, thresholds=REL_DIFF_PCT) -> tuple[str, str]:
    return ("–", "") if pd.isna(d) else (f"{d:+.3g}", grade(d, thresholds))


def _chunks(items: list, size: int) -> list[list]:
    return [items[i:i + size] for i in range(0, len(items), size)] or [[]]


def volume_table(results: Results, name: str, experiment: str, number: int) -> Table | None:
    """[G20] Table 2 or 3 beside ours: [G20]'s own models and FEM, ours and the publication's, the
    differences and a verdict per row (the other models: :func:`competitors_volume_tables`)."""
    t = results.table(name)
    if t is None:
        return None
    t = t.sort_values(["mesh", "deformation", "nu"])
    methods = _method_cols(results, t)
    own, _, _ = _split_methods(results, methods)
    t = _own_meshes(results, t, experiment, own)
    if t.empty:
        return None
    paper_own = [m for m in own if f"paper {m.rsplit(' ', 1)[0]}" in t]
    subject = f"{results.published_model('proposed')} static"
    pfem = "paper FEM (LS-Dyna)"
    cols = ["mesh", "ν", "d (%)"]
    for m in paper_own:
        cols += [f"{_short(m)} ours", f"{_short(m)} [G20]"]
    cols += ["FEM ours", "FEM [G20]", f"Δ {_short(subject)} − FEM, ours (pp)",
             f"Δ {_short(subject)} − FEM, [G20] (pp)", f"Δ {_short(subject)} ours − [G20] (pp)", "verdict"]
    flags = nonunique_scenes(results)
    rows = []
    for _, r in t.iterrows():
        ref_col, ref, law = _reference(results, experiment, methods, r, "deformation")
        row = [(r["mesh"], ""), (fmt(r["nu"], 3), ""), _load_cell(r, "deformation")]
        for m in paper_own:
            cell = _method_value(results, experiment, m, r, "deformation", law)
            row += [_flagged(cell, flags, m, experiment, r, "deformation"),
                    (fmt(r[f"paper {m.rsplit(' ', 1)[0]}"], 3), "paper")]
        row += [(fmt(ref), "ref") if pd.notna(ref) else ("missing", ""), (fmt(r.get(pfem, np.nan), 3), "paper")]
        ours = r.get(subject, np.nan)
        theirs = r.get(f"paper {subject.rsplit(' ', 1)[0]}", np.nan)
        d_fem, d_paper_fem, d_paper = _pp(ours, ref), _pp(theirs, r.get(pfem, np.nan)), _pp(ours, theirs)
        row += [_pp_cell(d_fem, (e_threshold(r["deformation"]), 3 * e_threshold(r["deformation"]))),
                (_pp_cell(d_paper_fem)[0], "paper"), _pp_cell(d_paper)]
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
                 f"of the publication; 'as FEM' within the FEM criterion.{_nonunique_note(rows)} [G20] ran the 10×10×10 "
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
    methods = _method_cols(results, t)
    own, fem, _ = _split_methods(results, methods)
    tabulated = [m for m in own if f"paper {m.rsplit(' ', 1)[0]}" in t]  # the models of volume_table
    others = [m for m in methods if m not in tabulated and m not in fem]
    th = (E_DIFF_PP[0], E_DIFF_PP[1])
    return _competitor_tables(results, t, experiment, others, "deformation", f"table{number}_others",
                              f"Table {number}, other models: {experiment}, Δe = e_model − e_FEM (pp)",
                              f"The models of this harness that [G20]'s Table {number} does not list, against the "
                              f"same FEM reference as Table {number} (linear at 5 %, Neo-Hookean at 20 %): e as "
                              f"there (%, magnitude), Δe = e_model − e_FEM in percentage points (green |Δe| ≤ "
                              f"{th[0]:g} pp, amber ≤ {th[1]:g} pp). Values of e: tables/{name}.csv.",
                              "FEM ref e (%)", lambda v, ref: _pp_cell(_pp(v, ref), th), "(pp)")


def _competitor_tables(results: Results, t: pd.DataFrame, experiment: str, others: list[str], load: str,
                       tid: str, title: str, caption: str, ref_head: str, delta, unit: str) -> list[Table]:
    if not others:
        return []
    load_head = "θ (°)" if load == "angle_deg" else "d (%)"
    per = MAX_COLUMNS - 4
    methods = _method_cols(results, t)
    flags = nonunique_scenes(results)
    ran = ran_on(results, experiment)
    out = []
    for k, chunk in enumerate(_chunks(others, per)):
        cols = ["mesh", "ν", load_head, ref_head] + [f"{_short(m)} {unit}" for m in chunk]
        rows = []
        for _, r in t.iterrows():
            _, ref, law = _reference(results, experiment, methods, r, load)
            row = [(r["mesh"], ""), (fmt(r["nu"], 3), ""), _load_cell(r, load),
                   (fmt(ref), "ref") if pd.notna(ref) else ("missing", "")]
            for m in chunk:
                v = r.get(m, np.nan)
                cell = delta(v, ref) if pd.notna(v) else _method_value(results, experiment, m, r, load, law, ran=ran)
                row.append(_flagged(cell, flags, m, experiment, r, load))
            rows.append(row)
        suffix = f" ({k + 1} of {len(_chunks(others, per))})" if len(others) > per else ""
        out.append(Table(f"{tid}{'_' + str(k + 1) if k else ''}", title + suffix,
                         caption + " " + SIGNS + " " + OWN_MESH_NOTE + _nonunique_note(rows), cols, rows))
    return out


def reaction_table(results: Results, name: str, experiment: str, number: int, load: str, unit: str,
                   quantity: str) -> Table | None:
    """[G20]'s own models against the FEM reference at every ν and load (the publication's values
    at ν = 1/4: :func:`published_reaction_table`; the other models: :func:`competitors_reaction_tables`)."""
    t = results.table(name)
    if t is None:
        return None
    t = t.sort_values(["mesh", load, "nu"])
    methods = _method_cols(results, t)
    own, _, _ = _split_methods(results, methods)
    t = _own_meshes(results, t, experiment, own)
    if t.empty:
        return None
    load_head = "θ (°)" if load == "angle_deg" else "d (%)"
    cols = ["mesh", "ν", load_head] + [f"{_short(m)} ({unit})" for m in own] + [f"FEM ref ({unit})"]
    cols += [f"{_short(m)} − FEM (%)" for m in own] + ["verdict"]
    flags = nonunique_scenes(results)
    rows = []
    for _, r in t.iterrows():
        _, ref, law = _reference(results, experiment, methods, r, load)
        row = [(r["mesh"], ""), (fmt(r["nu"], 3), ""), _load_cell(r, load)]
        row += [_flagged(_method_value(results, experiment, m, r, load, law), flags, m, experiment, r, load)
                for m in own]
        row.append((fmt(ref), "ref") if pd.notna(ref) else ("missing", ""))
        rels = [_rel(r.get(m, np.nan), ref) for m in own]
        row += [_rel_cell(d) for d in rels]
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
                 f"{REL_DIFF_PCT[1]:g} %, red above.{_nonunique_note(rows)} [G20]'s values (ν = 0.25 only) are in the "
                 f"table 'beside [G20]'; the other models in the table after it.", cols, rows)


def competitors_reaction_tables(results: Results, name: str, experiment: str, number: int, load: str,
                                unit: str, quantity: str) -> list[Table]:
    t = results.table(name)
    if t is None:
        return []
    t = t.sort_values(["mesh", load, "nu"])
    _, _, others = _split_methods(results, _method_cols(results, t))
    return _competitor_tables(results, t, experiment, others, load, f"table{number}_others",
                              f"Table {number}, other models: {experiment}, {quantity}, (model − FEM) / |FEM| (%)",
                              f"The models of this harness that [G20]'s Table {number} does not list, against the "
                              f"same FEM reference ({unit}): relative difference in % (green ≤ {REL_DIFF_PCT[0]:g} %, "
                              f"amber ≤ {REL_DIFF_PCT[1]:g} %). Values: tables/{name}.csv.",
                              f"FEM ref ({unit})", lambda v, ref: _rel_cell(_rel(v, ref)), "(%)")


def _deflection_rel(v, ref) -> float:
    """(|v| − |ref|) / |ref| in %: negative when the model deflects less than the reference."""
    return _rel(abs(v), abs(ref)) if not (pd.isna(v) or pd.isna(ref)) else np.nan


BENDING_SIGNS = ("Differences compare deflection magnitudes, (|model| − |reference|) / |reference| in %: negative "
                 "when the model deflects less (is stiffer).")


def bending_table(results: Results) -> Table | None:
    """[G20]'s own models against the finite-strain FEM and Euler–Bernoulli (the others:
    :func:`bending_others_tables`)."""
    t = results.table("bending")
    if t is None:
        return None
    methods = _method_cols(results, t)
    own, fem, _ = _split_methods(results, methods)
    t = _own_meshes(results, t, "bending", own)
    if t.empty:
        return None
    ran = ran_on(results, "bending")
    nh = next((m for m in fem if m.endswith("neo-hookean")), None)
    cols = ["mesh", "E (MPa)"] + [f"{_short(m)} (m)" for m in own + fem] + ["Euler–Bernoulli (m)"]
    cols += [f"{_short(m)} vs FEM NH (%)" for m in own] + [f"{_short(m)} vs E–B (%)" for m in own]
    rows = []
    for _, r in t.sort_values(["mesh", "E"]).iterrows():
        row = [(r["mesh"], ""), (fmt(r["E"] / 1e6, 3), "")]
        row += [(fmt(r[m]), "ref" if m == nh else "") if pd.notna(r[m]) else
                _method_value(results, "bending", m, r, "E", "", ran=ran) for m in own + fem]
        eb = r.get("euler_bernoulli_tip", np.nan)
        row.append((fmt(eb), "paper"))
        ref = r.get(nh, np.nan) if nh else np.nan
        row += [_rel_cell(_deflection_rel(r.get(m, np.nan), ref)) for m in own]
        row += [_rel_cell(_deflection_rel(r.get(m, np.nan), eb)) for m in own]
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
    methods = _method_cols(results, t)
    _, fem, others = _split_methods(results, methods)
    nh = next((m for m in fem if m.endswith("neo-hookean")), None)
    if not others or nh is None:
        return []
    ran = ran_on(results, "bending")
    out = []
    chunks = _chunks(others, MAX_COLUMNS - 3)
    for k, chunk in enumerate(chunks):
        cols = ["mesh", "E (MPa)", "FEM NH (m)"] + [f"{_short(m)} (%)" for m in chunk]
        rows = []
        for _, r in t.sort_values(["mesh", "E"]).iterrows():
            row = [(r["mesh"], ""), (fmt(r["E"] / 1e6, 3), ""), (fmt(r[nh]), "ref")]
            row += [_rel_cell(_deflection_rel(r[m], r[nh])) if pd.notna(r[m]) else
                    _method_value(results, "bending", m, r, "E", "", ran=ran) for m in chunk]
            rows.append(row)
        out.append(Table(f"table_bending_others{'_' + str(k + 1) if k else ''}",
                         "Beam under gravity, other models: tip deflection against FEM NH (%)"
                         + (f" ({k + 1} of {len(chunks)})" if len(chunks) > 1 else ""),
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
    failed = df["status"] != "ok"  # a run that did not reach a result shows no value
    df.loc[failed, ["e_pct", "max_displacement", "elapsed_s"]] = np.nan
    cols = {"study": "study", "label": "scene", "solver": "solver", "status": "status", "e_pct": "signed e (%)",
            "max_displacement": "max |u| (m)", "elapsed_s": "time (s)", "key": "VTU"}
    tab = frame_table(df, "table_runs", "All runs",
                      "Every stored run: signed relative volume change (V′ − V0)/V0 (%), largest displacement (m), "
                      "wall time (s); '–' (and no VTU) for a run that did not reach a result (its status says "
                      "why); the VTU link opens the deformed state (point field displacement, cell field "
                      "relative_volume_change) in ParaView.", cols,
                      lambda r, c: ("fail" if r["status"] != "ok" else "good") if c == "status" else "",
                      screen_only=True)
    kcol = list(cols).index("key")
    for i, (key, no_result) in enumerate(zip(df["key"], failed)):
        if key in vtu_files and not no_result:  # the state of a run not at rest is no result either
            tab.links[(i, kcol)] = f"vtu/{vtu_files[key]}"
            tab.rows[i][kcol] = (f"{key[:8]}.vtu", "")
        else:
            tab.rows[i][kcol] = ("–", "")
    return tab


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
    t = t.copy()
    for c in ("tol", "error_at_last"):
        if c in t:
            t[c] = 100 * pd.to_numeric(t[c], errors="coerce")
    cols = {"nu": "ν", "damping": "c (1/s)", "dt": "dt (s)", "tol": "tolerance (%)",
            "steps_to_tol": "steps to tolerance", "crossing_between": "between checkpoints",
            "error_at_last": "rel. L2 at last checkpoint (%)", "last_steps": "last checkpoint (steps)"}
    return frame_table(t, "table_damping_short", "Steps to the static equilibrium",
                       "Explicit semi-implicit Euler with mass-proportional damping c from rest to the static "
                       "equilibrium of the compression cube, runs cut at checkpoints of n steps (a run cut before "
                       "rest is measured all the same): steps at which the relative L2 difference ‖u_n − u_static‖ / "
                       "‖u_static‖ crosses the tolerance for good, interpolated log-linearly between the two "
                       "checkpoints that bracket it ('≤ n': within at the first checkpoint; '> n': not reached within "
                       "the n steps run).", cols)


def equilibria_frame(results: Results) -> pd.DataFrame:
    """The explicit runs beside their static twins as the studies stored them
    (``tables/equilibria.csv``), or computed from the runs for a folder stored without it."""
    t = results.table("equilibria")
    if t is None:
        from studies.paper.equilibria import equilibria

        t = equilibria(results)
    return t


def _explicit_state(r) -> tuple[str, str]:
    if r["status"] != "ok":
        return r["status"], "fail"
    if str(r["apart"]).lower() == "true":
        return "two equilibria ‡", "twofold"
    return "ok", "good"


def explicit_table(results: Results) -> Table | None:
    """Each explicit run (the publication's protocol) against the static equilibrium of the same
    scene; a run that did not come to rest shows no value, a pair apart is flagged."""
    eq = equilibria_frame(results)
    if eq.empty:
        return None
    rows = []
    for _, r in eq.iterrows():
        ok = r["status"] == "ok"
        rows.append([
            (r["label"], ""), (fmt(r["dt"], 3), ""), (fmt(r["steps"]), ""), (fmt(r["damping"], 3), ""),
            (fmt(r["dt_crit"], 3), ""), _explicit_state(r),
            (fmt(r["e_explicit_pct"], 4) if ok else "–", ""),
            (fmt(r["e_static_pct"], 4), "ref") if pd.notna(r["e_static_pct"]) else ("–", ""),
            _pp_cell(r["de_pp"] if ok else np.nan, (0.1, 1.0)),
            ((fmt(r["rel_l2_pct"], 3), grade(r["rel_l2_pct"], (1.0, NONUNIQUE_PCT))) if ok else ("–", "")),
            (fmt(r["max_speed"], 3) if ok else "–", ""),
            ("" if ok or pd.isna(r["message"]) else str(r["message"])[:220], ""),
        ])
    other = [i for i, k in enumerate(eq["explicit_key"]) if not results.is_publication_run(k)]
    note = (f" {len(other)} explicit runs of other studies (stability, speed against error) are listed in the HTML "
            "page only." if other else "")
    return Table("table_explicit", "Explicit protocol against the static equilibrium",
                 "The publication's protocol: semi-implicit Euler, dt = 1 ms, 10,000 steps (10 s), plates ramped over "
                 "1 s, mass-proportional damping c (s⁻¹, not stated in [G20]); read at the end. A run that did not "
                 "come to rest (status not-converged, diverged) shows no value: it is no result. Compared with the "
                 "static equilibrium of the same scene: e (%) of both, Δe = e_explicit − e_static (pp; green ≤ 0.1, "
                 "amber ≤ 1) and ‖u_explicit − u_static‖ / ‖u_static‖ (%; green ≤ 1, amber ≤ "
                 f"{NONUNIQUE_PCT:g}). Above {NONUNIQUE_PCT:g} % with the explicit run at rest, both are equilibria of "
                 "one scene: 'two equilibria ‡' (non-unique). dt_crit (s) at rest, largest particle speed at the end "
                 "(m/s)." + note,
                 ["run", "dt (s)", "steps", "c (1/s)", "dt_crit (s)", "status", "e explicit (%)", "e static (%)",
                  "Δe (pp)", "‖Δu‖ rel. L2 (%)", "max speed (m/s)", "message"], rows, css="explicit",
                 row_classes={i: "screen-only" for i in other})


def _apart_counts(results: Results, eq: pd.DataFrame) -> str:
    """"k of the n explicit runs at rest …: model: scenes, range" for one group of explicit runs."""
    rest = eq[eq["status"] == "ok"]
    apart = rest[rest["apart"].astype(str).str.lower() == "true"]
    if apart.empty:
        return f"none of the {len(rest)} explicit runs that came to rest"
    per = "; ".join(f"{v} {len(g)} ({g['rel_l2_pct'].min():.3g}–{g['rel_l2_pct'].max():.3g} % apart)"
                    for v, g in apart.groupby("variant"))
    return f"{len(apart)} of the {len(rest)} explicit runs that came to rest ({per})"


def nonunique_sentence(results: Results) -> str:
    """How many explicit runs at rest are apart from their static equilibria, in the publication's
    scenes and in the other studies' stress tests, and which models."""
    eq = equilibria_frame(results)
    if eq.empty:
        return ""
    own = eq["explicit_key"].map(results.is_publication_run).astype(bool)
    parts = []
    if own.any():
        parts.append(f"in the publication's scenes, {_apart_counts(results, eq[own])}")
    if (~own).any():
        parts.append(f"in the other studies (extreme loads, speed against error), {_apart_counts(results, eq[~own])}")
    apart = eq[(eq["status"] == "ok") & (eq["apart"].astype(str).str.lower() == "true")]
    fd = results.published_model("no-face-diagonals")
    hourglass = (f" {fd} has no face diagonals: its cubic lattice has zero-energy (hourglass-like) modes, the zig-zag "
                 "surfaces of its renders." if fd in set(apart["variant"]) else "")
    return ("Non-unique equilibria: an explicit run that came to rest more than "
            f"{NONUNIQUE_PCT:g} % (relative L2 of the nodal displacements) from the static equilibrium of the same "
            "scene found a second equilibrium, and neither value is the model's answer (Tables 2–5 mark such scenes "
            "‡). Found " + "; ".join(parts) + "." + hourglass)


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


def b09_published_table(results: Results) -> Table | None:
    """[B09]'s whole published table (both experiments, every mesh) beside ours for its own model,
    with the reading of its SD as the standard error of the mean."""
    paper = paper_table("b09_errors")
    if paper is None:
        return None
    df = findings.b09_frame(results.table("baudet_cantilever"), results.table("baudet_lshape"), paper)
    norm = b09_normalisation(df) if not df.empty else pd.DataFrame()
    cols = ["experiment", "mesh", "N particles", "[B09] M", "[B09] SD", "[B09] MAX", "ours M", "ours SD", "ours MAX",
            "ours SD/√N × [B09] M / ours M", "that ÷ [B09] SD"]
    rows = []
    for _, p in paper.iterrows():
        row = [(findings.EXPERIMENT_NAMES.get(p["experiment"], p["experiment"]), ""), (p["mesh"], ""),
               (fmt(b09_particles(p["experiment"], p["mesh"])), "")]
        row += [(fmt(float(p[c]), 3), "paper") for c in ("mean_pct", "sd_pct", "max_pct")]
        ours = df[(df["experiment"] == p["experiment"]) & (df["mesh"] == p["mesh"]) & (df["model"] == p["model"])] \
            if not df.empty else df
        n = norm[(norm["experiment"] == p["experiment"]) & (norm["mesh"] == p["mesh"])
                 & (norm["model"] == p["model"])] if not norm.empty else norm
        if ours.empty:
            row += [("not run here", "")] + [("–", "")] * 4
        elif ours["state"].iloc[0] != "ok":
            row += [(_short_state(str(ours["state"].iloc[0])), "fail")] + [("–", "")] * 4
        else:
            o = ours.iloc[0]
            row += [(fmt(o[c], 3), "") for c in ("err_mean_pct", "err_sd_pct", "err_max_pct")]
            if n.empty:
                row += [("–", "")] * 2
            else:
                q = n.iloc[0]
                row += [(fmt(q["sem_scaled_pct"], 3), ""), (f"×{q['sem_ratio']:.3g}", grade(q["sem_ratio"] - 1, (0.15, 0.35)))]
        rows.append(row)
    return Table("table_b09_published", f"[B09]'s published errors ({', '.join(dict.fromkeys(paper['model']))}) and "
                 "its standard deviation", "[B09]'s table whole: both experiments, every mesh, mean (M), standard "
                 "deviation (SD) and maximum (MAX) of the nodal displacement error in % as printed, beside ours for "
                 "the same model (|u_MSS − u_FEM| / max|u_FEM| over the N particles, %). " + b09_sd_sentence(norm) + " The last two columns: our SD/√N scaled by the ratio of the means (to "
                 "compare the normalisations, not our accuracy) and its ratio to [B09]'s SD; near 1 supports that "
                 "reading (green within 15 %, amber within 35 %). Where a mesh was not run (a shorter reproduction), "
                 f"the row says so. {paper_source('b09_errors')}", cols, rows)


def b09_sd_sentence(norm: pd.DataFrame) -> str:
    """Our SD against [B09]'s, and our means against [B09]'s, over the rows run (from the data)."""
    if norm.empty:
        return "No mesh of [B09]'s table was run here."
    m = norm["err_mean_pct"] / norm["b09_mean_pct"]
    return (f"Our SD is ×{norm['sd_ratio'].min():.3g}–×{norm['sd_ratio'].max():.3g} [B09]'s while our means are "
            f"×{m.min():.3g}–×{m.max():.3g} theirs: [B09]'s SD is not the spread of the error over the particles; "
            f"read as the standard error of the mean, ours matches it to ×{norm['sem_ratio'].min():.3g}–"
            f"×{norm['sem_ratio'].max():.3g}.")
