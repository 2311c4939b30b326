"""The summary page: what was run, the headline table and the verdicts on the publication's claims.

The studies judge the claims and store them (:mod:`studies.paper.claims`: ``tables/headline.csv``,
``tables/claims.csv``, with their criteria); this page only formats them.  A results folder without
those tables shows no claims.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..data import (E_FEM_PP, EXPERIMENT_ORDER, NOT, PARTLY, REL_PCT, REPRODUCED, SUPPORTED, TIE_COST, TIE_PP,
                   Results, e_threshold, thresholds)
from .base import Context, Section, add_tables, escape
from ..tables import REL_DIFF_PCT, Table, fmt, grade

__all__ = ["caveats", "verdict", "verdict_sentences", "verdict_table", "claims", "claims_table", "claims_tables", "headline", "headline_table", "overview", "thresholds"]

VERDICT_CSS = {REPRODUCED: "good", PARTLY: "warn", NOT: "bad", SUPPORTED: "good"}
"""The colour class of each verdict in the claims tables."""


# ------------------------------------------------------------------------------------ overview
def overview(results: Results) -> dict:
    df = results.rows
    env = results.environment
    out = {"n_runs": int(len(df)), "env": env}
    if df.empty:
        return out
    timed = df["timing"]
    no_result = (df["status"] != "ok") & ~timed  # a timing run not at rest is what it was asked to be
    found = no_result & (df["finding"] != "")  # a finding of its study, counted apart from the failures
    out["n_ok"] = int((df["status"] == "ok").sum())
    out["n_failed"] = int((no_result & ~found).sum())
    out["n_findings"] = int(found.sum())
    out["n_timed"] = int(timed.sum())
    out["findings_by"] = [{"study": str(st), "reason": str(why), "n": int(n)} for (st, why), n in
                          df[found].groupby(["study", "finding"]).size().items()]
    out["compute_s"] = float(pd.to_numeric(df["elapsed_s"], errors="coerce").fillna(0).sum())
    studies = []
    for study, g in df.groupby("study", sort=False):
        studies.append({
            "study": study,
            "runs": len(g),
            "failed": int((no_result[g.index] & (g["finding"] == "")).sum()),
            "findings": int((no_result[g.index] & (g["finding"] != "")).sum()),
            "timed": int(timed[g.index].sum()),
            "meshes": ", ".join(sorted(g["mesh"].astype(str).unique())),
            "nus": ", ".join(f"{v:g}" for v in sorted(g["nu"].astype(float).unique())),
            "solvers": ", ".join(sorted(g["solver"].unique())),
            "models": ", ".join(sorted(g.loc[~g["is_fem"], "variant"].unique())),
            "time_s": float(pd.to_numeric(g["elapsed_s"], errors="coerce").fillna(0).sum()),
        })
    order = {s: i for i, s in enumerate(EXPERIMENT_ORDER)}
    out["studies"] = sorted(studies, key=lambda s: (order.get(s["study"], 99), s["study"]))
    return out


# ------------------------------------------------------------------------------------ headline
def headline(results: Results) -> pd.DataFrame:
    """[G20]'s proposed model against FEM and the publication's counterpart, per experiment, ν and
    load, as the studies stored it (empty if they did not)."""
    t = results.table("headline")
    return t if t is not None else pd.DataFrame()


def headline_table(h: pd.DataFrame) -> Table:
    who = str(h["model"].iloc[0]) if len(h) and "model" in h else "MSS"
    cols = ["experiment", "mesh", "ν", "load", "quantity", who, "FEM ref", f"{who} − FEM",
            f"[G20] {who}", "[G20] FEM", f"[G20] {who} − FEM", "‖Δu‖ rel. L2 (%)"]
    rows = []
    for _, r in h.iterrows():
        if "angle_deg" in r and pd.notna(r.get("angle_deg")):
            load = f"θ = {r['angle_deg']:g}°"
        elif "E" in r and pd.notna(r.get("E")):
            load = f"E = {r['E'] / 1e6:g} MPa"
        else:
            load = f"d = {100 * r['deformation']:g} %"
        unit = r["unit"]
        failed = r["status"] != "ok"
        if r["experiment"] in ("compression", "tension"):
            g = grade(r["err"], (e_threshold(r.get("deformation", 0.05)), 3 * e_threshold(r.get("deformation", 0.05))))
        else:
            g = grade(r["err"], REL_DIFF_PCT)
        rows.append([
            (r["experiment"], ""), (r["mesh"], ""), (fmt(r["nu"], 3), ""), (load, ""),
            (f"{r['quantity']} ({unit})", ""),
            (("missing" if r["status"] == "missing" else f"failed ({r['status']})") if failed else fmt(r["mss"]),
             "fail" if failed and r["status"] != "missing" else ""),
            (fmt(r["fem"]) if pd.notna(r["fem"]) else "missing", "ref"),
            (fmt(r["err"], 3, " " + r["err_unit"]), g),
            (fmt(r.get("paper_mss", np.nan), 3), "paper"),
            (fmt(r.get("paper_fem", np.nan), 3), "paper"),
            (fmt(r.get("paper_err", np.nan), 3, " " + r["err_unit"]) if pd.notna(r.get("paper_err", np.nan)) else "–",
             "paper"),
            (fmt(r.get("rel_l2_pct", np.nan), 3), grade(r.get("rel_l2_pct", np.nan), (5.0, 15.0))),
        ])
    return Table("table_headline", f"Headline: {who} against FEM, and the publication's counterpart",
                 f"{who} (static equilibrium) against the FEM reference on the same grid (linear at 5 % / 1°, "
                 "Neo-Hookean at 20 % / 45° and for the beam). Compression/tension: e = |ΔV|/V0 in %, error in "
                 f"percentage points (green ≤ {E_FEM_PP[0.05]:g} pp at 5 %, ≤ {E_FEM_PP[0.20]:g} pp at 20 %); shear: "
                 "top-plate force F_x (N); torsion: torque T_z (N·m); beam: tip deflection (m, negative = down; its "
                 "difference compares magnitudes, negative when the model deflects less); errors (model − FEM) in % of FEM "
                 f"(green ≤ {REL_PCT:g} %). [G20] columns: the publication's {who} and LS-Dyna values (Tables 2–5; "
                 "10×10×10 cube, 4×4×24 beam; Tables 4, 5 at ν = 0.25 only, torsion read as 1° and 45°). Last column: relative L2 nodal displacement difference (%).",
                 cols, rows)


# ------------------------------------------------------------------------------------ claims
def claims(results: Results) -> pd.DataFrame:
    """The claims the studies judged (``tables/claims.csv``: claim, criterion, rows counted and
    within, verdict, evidence); empty if they stored none."""
    t = results.table("claims")
    return t.fillna({"evidence": "", "criterion": ""}) if t is not None else pd.DataFrame()


CLAIMS_PER_TABLE = 8
"""Claims per printed table (a longer list is split so that no table runs over a page)."""


def claims_tables(cl: pd.DataFrame, per_table: int = CLAIMS_PER_TABLE) -> list[Table]:
    """The claims (:func:`claims`) as tables of at most ``per_table`` rows each."""
    out = []
    for i in range(0, len(cl), per_table):
        t = claims_table(cl.iloc[i:i + per_table])
        if i:
            t.id, t.title = f"table_claims_{i // per_table + 1}", t.title + " (continued)"
        out.append(t)
    return out


def claims_table(cl: pd.DataFrame) -> Table:
    rows = [[(str(c["claim"]), ""), (str(c["criterion"]), ""), (str(c["verdict"]), VERDICT_CSS.get(c["verdict"], "")),
             (str(c["evidence"]), "")] for _, c in cl.iterrows()]
    return Table("table_claims", "Claims of the publication: reproduced or not",
                 "Verdicts computed by the studies from the stored results with the stated criteria "
                 "(studies/paper/claims.py, tables/claims.csv); 'partly' = at least half of the cases meet the criterion.",
                 ["claim", "criterion", "verdict", "evidence"], rows, css="claims")


# ------------------------------------------------------------------------------------ verdict
RANK_CSS = {"best": "good", "tied with best": "good", "worse": "", "no result": "fail"}
"""The colour class of each rank of the verdict table."""


def verdict(results: Results) -> pd.DataFrame:
    """Where each model wins, as the studies stored it (``tables/verdict.csv``; empty if not)."""
    t = results.table("verdict")
    return t if t is not None else pd.DataFrame()


def _signed(v: float, unit: str) -> str:
    if unit == "count":
        return f"{v:.0f}"
    if unit == "ms/s":
        return f"{v:.3g}"
    return f"{v:+.3g}"


def _value_text(r) -> str:
    if r["state"] != "ok" or pd.isna(r["value"]):
        return str(r["state"]) if str(r["state"]) not in ("ok", "nan") else "no result"
    text = _signed(float(r["value"]), r["unit"])
    if r["unit"] == "count" and pd.notna(r.get("total", np.nan)):
        text += f" of {int(r['total'])}"
    return text


def _rank_css(r) -> str:
    """Green for the best and the tied, red for a run that failed or is missing, else none (a model
    with no dt limit has no explicit cost to rank, which is no failure)."""
    state = str(r["state"])
    if state.startswith("failed") or state == "missing":
        return "fail"
    return RANK_CSS.get(r["rank"], "") if r["rank"] != "no result" else ""


def verdict_table(v: pd.DataFrame, springs_only: str | None = None) -> Table:
    """Regimes (rows) × models (columns): each model's error or cost, the best and those tied with it green."""
    models = list(dict.fromkeys(v["method"]))
    cols = ["regime", "quantity (unit)", "scene"] + models
    rows = []
    for (regime, quantity), g in v.groupby(["regime", "quantity"], sort=False):
        unit = str(g["unit"].iloc[0])
        by = {r["method"]: r for _, r in g.iterrows()}
        row = [(regime, ""), (f"{quantity} ({unit})", ""), (str(g["scene"].iloc[0]), "")]
        for m in models:
            r = by.get(m)
            row.append(("–", "") if r is None else (_value_text(r), _rank_css(r)))
        rows.append(row)
    return Table("table_verdict", "Where each method wins",
                 "Each model's static equilibrium against the FEM reference on the same grid (signed: model − "
                 "reference, relative to the reference in % or in percentage points of e), the count of large-load "
                 "scenes without equilibrium, and the explicit cost in milliseconds of wall time per simulated second "
                 f"at the model's stable step (from single stored runs; the budget study repeats its timings). Green: the best and those tied with it (within {TIE_PP:g} % / pp of the "
                 f"best error, a factor {TIE_COST:g} of the best cost). Computed by studies/paper/verdict.py "
                 "(tables/verdict.csv)." + (f" {springs_only} has no volume term: its ν is always 1/4, so its "
                 "cost at ν = 0.499 is that of another material." if springs_only in models else ""),
                 cols, rows, css="verdict")


def verdict_sentences(v: pd.DataFrame, subject: str | None) -> list[str]:
    """One sentence per regime row (best, tied, the subject's value) and one on where ``subject`` wins."""
    out, wins, losses = [], [], []
    for (regime, quantity), g in v.groupby(["regime", "quantity"], sort=False):
        unit = str(g["unit"].iloc[0])
        u = "" if unit == "count" else f" {unit}"
        good = g[g["rank"].isin(["best", "tied with best"])]
        if good.empty:
            continue
        best = ", ".join(f"{r['method']} ({_value_text(r)}{u})" for _, r in good.iterrows())
        rest = g[g["rank"] == "worse"]
        worse = ", ".join(f"{r['method']} {_value_text(r)}{u}" for _, r in rest.iterrows())
        out.append(f"<b>{regime}</b>, {quantity}: best {best}" + (f"; then {worse}" if worse else "") + ".")
        if subject is not None and subject in set(g["method"]):
            rk = g.loc[g["method"] == subject, "rank"].iloc[0]
            (wins if rk in ("best", "tied with best") else losses).append(f"{regime}: {quantity.split(',')[0]}")
    if subject is not None and (wins or losses):
        lead = (f"{subject} is best or tied in: " + "; ".join(wins) if wins else f"{subject} is best in no regime")
        lead += (". It is behind in: " + "; ".join(losses) + "." if losses else ".")
        out.insert(0, lead)
    return out


def caveats(results: Results, cl: pd.DataFrame, h: pd.DataFrame) -> list[str]:
    """The reproduction's caveats a reader needs before any number: the calibration, the inferred
    torsion angles, meshes and references, from the stored claims and headline."""
    out = []
    ef = cl[cl["claim"].astype(str).str.contains("E-form", regex=False)] if not cl.empty else cl
    if not ef.empty:
        found = "; ".join(f"{c['claim'].split(' (')[0]}: {c['verdict']} ({str(c['evidence']).split(' (')[0]})"
                          for _, c in ef.iterrows())
        out.append("Calibration: this harness builds its spring constants from G = E/(2(1+ν)), which give the input "
                   "moduli at every ν; [G20] eq. 5.12 states them in terms of E (the E-form). " + found + ". Where "
                   "[G20]'s values follow the E-form, its rows of Tables 2–3 differ from ours by construction.")
    out.append("Torsion loads: [G20] labels its torsion rows 5 % and 20 % without defining d for a rotation; they "
               "are read as θ = 1° and 45° (the angles at which the published torques agree with linear torsion of a "
               "square section), an inference, not a statement of [G20].")
    if not h.empty and "mesh" in h:
        meshes = ", ".join(f"{e} {m}" for e, m in h.groupby("experiment", sort=False)["mesh"].first().items())
        out.append(f"Meshes here: {meshes}; [G20]: the 10×10×10 cube and the 4×4×24 beam. The FEM reference is "
                   "scikit-fem (Hex2 on the same grid, mixed u–p near ν = ½); [G20]'s is LS-Dyna.")
    return out


def claim_findings(cl: pd.DataFrame, *needles: str) -> str:
    """The stored claims whose statement contains one of ``needles``, as "claim: verdict (rows)."
    sentences: a section opens with its finding, not with a description."""
    if cl.empty:
        return ""
    out = []
    for _, c in cl.iterrows():
        claim = str(c["claim"])
        if any(n in claim for n in needles):
            counted = c.get("rows_counted")
            rows = (f", {int(c['rows_within'])} of {int(counted)} cases" if pd.notna(counted) and
                    pd.notna(c.get("rows_within")) else "")
            out.append(f"{claim}: <b>{c['verdict']}</b>{rows}.")
    return " ".join(out)


def section(ctx: Context) -> Section:
    """§1: the verdict first (where each method wins, in sentences and one table), the caveats of the
    reproduction, then the claims of the publication and the headline comparison."""
    results, head, claims = ctx.results, ctx.head, ctx.claims
    v = verdict(results)
    paras = verdict_sentences(v, results.published_model("proposed")) if not v.empty else []
    notes = caveats(results, claims, head)
    intro = "".join(f"<p>{p}</p>" for p in paras)
    if notes:
        intro += "<p><b>Caveats.</b></p><ul class='caveats'>" + "".join(f"<li>{escape(n)}</li>" for n in notes) + "</ul>"
    s = Section("summary", "Summary: where each method wins", intro)
    if not v.empty:
        add_tables(s, verdict_table(v, results.published_model("springs-only")))
    if not claims.empty:
        add_tables(s, *claims_tables(claims))
    if not head.empty:
        add_tables(s, headline_table(head))
    return s
