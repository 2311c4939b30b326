"""The publication's claims judged from the stored results: each claim, its criterion, the rows it
counts, its verdict and the values behind it, written as ``tables/claims.csv`` (and the headline
comparison they rest on as ``tables/headline.csv``); the report only formats them.

Criteria (each constant below is their one home; :func:`thresholds` prints them):

- moduli: |E_eff/E − 1|, |G_eff/G − 1| ≤ 0.1 % and |ν_eff − ν| ≤ 0.001;
- volume change against FEM: |e_hybmss − e_FEM| ≤ 0.5 percentage points at d = 5 %, ≤ 2 pp at 20 %;
- near incompressibility: e ≤ 0.2 % at ν = 0.499;
- agreement with the publication's hybmss column: |e − e_[G20]| ≤ 1 pp;
- reactions (shear force, torsion torque) and beam tip deflection: within 10 % of the reference;
- middle-layer and [B09] mean differences: within a factor 2 of the publication's.

A claim without data is "not tested"; "partly reproduced": at least half of the cases meet the
criterion (:func:`count_verdict`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from studies.paper.comparisons import b09_frame, b09_models, middle_layer_frame
from studies.paper.equilibria import equilibria
from studies.sweep.results import printed_match as printed
from studies.paper.verdict import verdict
from studies.paper.values import paper_table
from studies.sweep.results import EXPERIMENT_ORDER, Results, own_study_first, run_state
from studies.sweep.store import Store

PROTOCOL_FAILURES = (
    "Two failures of the explicit protocol (dt = 1 ms, 10,000 steps, ramp 1 s, damping 2 s⁻¹) of earlier versions "
    "were the harness's, not the models': (1) the shear of the 10³ cube at 20 % diverged at step 510 for every ν "
    "on the same particle because the top plate, 1 m = two cell edges at full load, sits exactly one cell edge "
    "(0.5 m) over at t = 0.5 s, where its nodes on the x+ face met the kernel's pad nodes (points of the lattice "
    "continued beyond the grid, joined to them by springs of zero stiffness): 0 · (1 − l0/0) is not a number; the "
    "pads now sit at cell centres, out of reach of a plate moved by whole edges, and the runs come to rest. "
    "(2) Torsion at 1° never came to rest because the rest criterion measured the force residual against the "
    "plates' net force, which for a twist is second order (0.1–6 N against a couple of 490–720 N): the "
    "criterion now takes a plate's moment over its radius of gyration as well, and the same states are at rest "
    "(residual 3e-5 to 4e-5 of it on the 10³ cube). The divergence message named a step 11–150× below "
    "the stability limit as the likely cause; it now names the step only when it is above half the limit.")
"""Why the explicit protocol's shear (20 %) and torsion (1°) runs failed in earlier versions and what
changed: the report shows it with the failures."""

E_MODULI_TOL = 1e-3
NU_MODULI_TOL = 1e-3
E_FEM_PP = {0.05: 0.5, 0.20: 2.0}
INCOMPRESSIBLE_E_PCT = 0.2
PAPER_PP = 1.0
REL_PCT = 10.0
PERF_RATIO_TOL = 0.5
"""Our per-step time ratio to the baseline model counts as the publication's within ±50 %."""
SCENE_PRECISION = 1e-3
"""Relative L2 differences are printed to 0.1 %: two closer than this cannot be told apart."""

REPRODUCED, PARTLY, NOT, UNTESTED = "reproduced", "partly reproduced", "not reproduced", "not tested"


MIDDLE_LAYER_TOL = 2.0
"""A middle-layer (or [B09]) mean difference counts as reproduced within this factor of the
publication's."""

SUPPORTED, NOT_SUPPORTED = "supported", "not supported"
"""Verdicts on an interpretation of the publication (not a claim of it)."""


@dataclass
class Claim:
    """One claim: its statement, criterion, verdict and the values behind it (``evidence``); of
    a claim counted over cases, the cases counted and those within the criterion."""

    statement: str
    criterion: str
    verdict: str
    evidence: str
    counted: int | None = None
    within: int | None = None

    def row(self) -> dict:
        return {"claim": self.statement, "criterion": self.criterion, "rows_counted": self.counted,
                "rows_within": self.within, "verdict": self.verdict, "evidence": self.evidence}


def thresholds() -> list[str]:
    """The thresholds of the verdicts, as printed on the summary page."""
    return [
        f"moduli: |E_eff/E − 1|, |G_eff/G − 1| ≤ {100 * E_MODULI_TOL:g} % and |ν_eff − ν| ≤ {NU_MODULI_TOL:g}",
        f"volume change against FEM: |e_hybmss − e_FEM| ≤ {E_FEM_PP[0.05]:g} pp at d = 5 %, ≤ {E_FEM_PP[0.20]:g} pp at 20 %",
        f"near incompressibility: e ≤ {INCOMPRESSIBLE_E_PCT:g} % at ν = 0.499",
        f"agreement with the publication's hybmss column: |e − e_[G20]| ≤ {PAPER_PP:g} pp",
        f"reactions (shear force, torsion torque) and beam tip deflection: within {REL_PCT:g} % of the reference",
        "'partly reproduced': at least half of the cases meet the criterion",
    ]


def e_threshold(d: float) -> float:
    """The volume-change criterion (pp) at plate displacement ``d``."""
    return E_FEM_PP[0.05] if d <= 0.05 + 1e-12 else E_FEM_PP[0.20]


# ------------------------------------------------------------------------------------ headline
def hybrid_models(results: Results) -> list[str]:
    """[G20]'s hybrid models (springs for G, volume energy for ν): its proposed one and the one
    without face diagonals, as registered."""
    return [m for m in (results.published_model(r) for r in ("proposed", "no-face-diagonals")) if m]


def headline(results: Results) -> pd.DataFrame:
    """For each experiment, ν and load: [G20]'s proposed model against FEM, and the
    publication's counterpart."""
    recs = []
    subject = results.published_model("proposed")
    pcol = results.published_name(subject)
    if subject is None:
        return pd.DataFrame()
    diffs = results.table("differences")
    for exp, pname in (("compression", "g20_table2_compression"), ("tension", "g20_table3_tension"),
                       ("shear", "g20_table4_shear"), ("torsion", "g20_table5_torsion"), ("bending", None)):
        mesh = results.primary_mesh(exp)
        if mesh is None:
            continue
        df = results.find(exp, mesh=mesh, study=exp, ok_only=False)
        if df.empty:
            df = results.find(exp, mesh=mesh, ok_only=False)
        paper = paper_table(pname) if pname else None
        if exp == "torsion":
            loads = [{"angle_deg": v} for v in sorted(df["angle_deg"].astype(float).unique())]
        elif exp == "bending":
            loads = [{"E": v} for v in sorted(df["E"].astype(float).unique(), reverse=True)]
        else:
            loads = [{"deformation": v} for v in sorted(df["deformation"].astype(float).unique())]
        nus = sorted(df["nu"].astype(float).unique())
        for load in loads:
            for nu in nus:
                rec = {"experiment": exp, "mesh": mesh, "nu": nu, **load}
                mss = own_study_first(results.find(exp, mesh=mesh, nu=nu, method=f"{subject} static", ok_only=False,
                                                   **load), exp)
                if exp == "bending":
                    ref = results.find(exp, mesh=mesh, nu=nu, method="fem-hex2-neo-hookean", **load)
                    ref = None if ref.empty else ref.iloc[0]
                else:
                    ref = results.reference(exp, mesh=mesh, nu=nu, **load)
                if mss.empty and ref is None:
                    continue
                m = mss.iloc[0] if not mss.empty else None
                rec["status"] = m["status"] if m is not None else "missing"
                rec["message"] = m["message"] if m is not None else ""
                ok = m is not None and m["status"] == "ok"
                _headline_values(rec, exp, m, ok, ref, paper, pcol, nu, load)
                rec["reference"] = ref["solver"] if ref is not None else ""
                if diffs is not None and m is not None and "mss_key" in diffs:
                    d = diffs[diffs["mss_key"] == m["key"]]
                    rec["rel_l2_pct"] = 100 * float(d["rel_l2"].iloc[0]) if len(d) else np.nan
                rec["model"] = subject
                recs.append(rec)
    return pd.DataFrame(recs)


def _headline_values(rec: dict, exp: str, m, ok: bool, ref, paper, pcol, nu: float, load: dict) -> None:
    """Fill ``rec`` with the compared quantity of ``exp``: the model's (its run ``m``, ``ok`` if it
    reached a result), the FEM reference's, their difference and the publication's."""
    if exp in ("compression", "tension"):
        rec["quantity"], rec["unit"] = "e", "%"
        rec["mss"] = 100 * abs(m["volume_change"]) if ok else np.nan
        rec["fem"] = 100 * abs(ref["volume_change"]) if ref is not None else np.nan
        rec["err"] = rec["mss"] - rec["fem"]
        rec["err_unit"] = "pp"
        if paper is not None:
            p = paper[printed(paper["nu"], nu) & printed(paper["deformation"], load["deformation"])]
            if len(p) and pcol in p:
                rec["paper_mss"] = float(p[pcol].iloc[0])
                rec["paper_fem"] = float(p["fem_lsdyna"].iloc[0])
                rec["paper_err"] = rec["paper_mss"] - rec["paper_fem"]
    elif exp in ("shear", "torsion"):
        col = "force_x" if exp == "shear" else "torque_z"
        rec["quantity"], rec["unit"] = ("F_x", "N") if exp == "shear" else ("T_z", "N·m")
        rec["mss"] = float(m[col]) if ok else np.nan
        rec["fem"] = float(ref[col]) if ref is not None else np.nan
        rec["err"] = 100 * (rec["mss"] - rec["fem"]) / abs(rec["fem"]) if rec["fem"] else np.nan
        rec["err_unit"] = "%"
        if paper is not None:  # [G20] Tables 4, 5: ν = 1/4 only
            key = "angle_deg" if exp == "torsion" else "deformation"
            p = paper[printed(paper["nu"], nu) & printed(paper[key], load[key])]
            if len(p) and pcol in p:
                rec["paper_mss"] = float(p[pcol].iloc[0])
                rec["paper_fem"] = float(p["fem_lsdyna"].iloc[0])
                rec["paper_err"] = 100 * (rec["paper_mss"] - rec["paper_fem"]) / abs(rec["paper_fem"])
    else:
        rec["quantity"], rec["unit"] = "tip deflection", "m"
        rec["mss"] = float(m["tip_deflection"]) if ok else np.nan
        rec["fem"] = float(ref["tip_deflection"]) if ref is not None else np.nan
        # deflections point down: compare magnitudes, negative when the model deflects less
        rec["err"] = 100 * (abs(rec["mss"]) - abs(rec["fem"])) / abs(rec["fem"]) if rec["fem"] else np.nan
        rec["err_unit"] = "%"
        rec["eb"] = float(m["euler_bernoulli_tip"]) if m is not None else np.nan


# ------------------------------------------------------------------------------------ claims
def claims(results: Results, h: pd.DataFrame) -> list[Claim]:
    """The publication's claims judged from the stored results and the headline comparison ``h``
    (:func:`headline`), in the order the report prints them."""
    subject = results.published_model("proposed")
    vol = h[h["experiment"].isin(["compression", "tension"])] if not h.empty else h
    out = _moduli_claims(results) + _volume_claims(vol, subject) + _incompressible_claims(results)
    out += _paper_volume_claims(results, vol, subject) + _face_diagonal_claims(results, subject)
    out += _reaction_claims(h, subject) + _bending_claims(h, subject) + _eform_claims(results)
    out += published_claims(results)
    out += _run_claims(results)
    c = _perf_summary_claim(results.table("performance_summary"),
                            memory_bound_meshes(results.table("performance"), results.table("bandwidth")))
    if c is not None:
        out.append(c)
    return out


def _moduli_claims(results: Results) -> list[Claim]:
    """The hybrid models' effective moduli, the spring-only lattice's ν and the E-form's moduli."""
    out = []
    mod = results.table("moduli")
    hybrid = hybrid_models(results)
    subject = results.published_model("proposed")
    cf = results.published_model("springs-only")
    stmt = f"{' and '.join(hybrid)} have the input Young's modulus, Poisson's ratio and shear modulus for any ν"
    crit = f"|E_eff/E − 1|, |G_eff/G − 1| ≤ {100 * E_MODULI_TOL:g} %, |ν_eff − ν| ≤ {NU_MODULI_TOL:g}, every ν tested"
    if mod is None:
        out.append(Claim(stmt, crit, UNTESTED, "no moduli table"))
    else:
        s = mod[mod["variant"].isin(hybrid)]
        eE = float((s["E_eff_over_E"] - 1).abs().max())
        eG = float((s["G_eff_over_G"] - 1).abs().max())
        en = float((s["nu_eff"] - s["nu"]).abs().max())
        ok = eE <= E_MODULI_TOL and eG <= E_MODULI_TOL and en <= NU_MODULI_TOL
        n_ok = int((((s["E_eff_over_E"] - 1).abs() <= E_MODULI_TOL) & ((s["G_eff_over_G"] - 1).abs() <= E_MODULI_TOL)
                    & ((s["nu_eff"] - s["nu"]).abs() <= NU_MODULI_TOL)).sum())
        out.append(Claim(stmt, crit, REPRODUCED if ok else NOT,
                         f"ν ∈ {{{', '.join(f'{v:g}' for v in sorted(s['nu'].unique()))}}}: max |E_eff/E − 1| = {eE:.2g}, "
                         f"max |G_eff/G − 1| = {eG:.2g}, max |ν_eff − ν| = {en:.2g}", len(s), n_ok))
        springs = mod[mod["variant"] == cf] if cf else mod.iloc[:0]
        if len(springs):
            dev = float((springs["nu_eff"] - 0.25).abs().max())
            out.append(Claim(f"A spring-only lattice ({cf}) is limited to ν = 1/4 (the motivation of the volume term)",
                             "|ν_eff − 1/4| ≤ 0.001 for every input ν", REPRODUCED if dev <= 1e-3 else NOT,
                             f"{cf} ν_eff ∈ [{springs['nu_eff'].min():.4g}, {springs['nu_eff'].max():.4g}] for input "
                             f"ν from {springs['nu'].min():g} to {springs['nu'].max():g}", len(springs),
                             int(((springs["nu_eff"] - 0.25).abs() <= 1e-3).sum())))
        eform = mod["e_form"].fillna(False).astype(str).str.lower() == "true" if "e_form" in mod else False
        ef = mod[(mod["model"] == subject) & eform] if "model" in mod else mod.iloc[:0]
        if len(ef):
            bad = ef[((ef["E_eff_over_E"] - 1).abs() > 1e-2) | ((ef["nu_eff"] - ef["nu"]).abs() > 1e-2)]
            out.append(Claim("The E-form spring constants of [G20] eq. 5.12 give the input moduli",
                             "|E_eff/E − 1| ≤ 1 % and |ν_eff − ν| ≤ 0.01 for every ν",
                             REPRODUCED if bad.empty else NOT,
                             "wrong at ν = " + ", ".join(f"{v:g}" for v in bad["nu"]) +
                             (f" (at ν = 0: E_eff/E = {float(ef.loc[ef['nu'] == 0, 'E_eff_over_E'].iloc[0]):.3g}, "
                              f"ν_eff = {float(ef.loc[ef['nu'] == 0, 'nu_eff'].iloc[0]):.3g})"
                              if (ef["nu"] == 0).any() else "") if not bad.empty else "all ν within tolerance",
                             len(ef), len(ef) - len(bad)))
    return out


def _volume_claims(vol: pd.DataFrame, subject: str | None) -> list[Claim]:
    """The volume change against the FEM at small and large deformation."""
    out = []
    for d, label in ((0.05, "small (5 %)"), (0.20, "large (20 %)")):
        sub = vol[vol["deformation"] == d] if not vol.empty else vol
        stmt = f"{subject} reproduces the FEM volume change in compression and tension at {label} deformation"
        crit = f"|e_hybmss − e_FEM| ≤ {e_threshold(d):g} pp for every ν, and every run reaches equilibrium"
        if sub.empty:
            out.append(Claim(stmt, crit, UNTESTED, "no runs"))
            continue
        failed = sub[sub["status"] != "ok"]
        within = sub[(sub["status"] == "ok") & (sub["err"].abs() <= e_threshold(d))]
        worst = sub.loc[sub["err"].abs().idxmax()] if sub["err"].notna().any() else None
        ev = f"{len(within)} of {len(sub)} cases within"
        if worst is not None:
            ev += (f"; largest |Δe| = {abs(worst['err']):.3g} pp ({worst['experiment']}, ν = {worst['nu']:g}, "
                   f"mesh {worst['mesh']})")
        if len(failed):
            ev += "; no equilibrium: " + ", ".join(f"{r['experiment']} ν = {r['nu']:g} ({r['status']})"
                                                   for _, r in failed.iterrows())
        verdict = REPRODUCED if len(within) == len(sub) else (PARTLY if len(within) >= len(sub) / 2 else NOT)
        out.append(Claim(stmt, crit, verdict, ev, len(sub), len(within)))
    return out


def _incompressible_claims(results: Results) -> list[Claim]:
    """The hybrid models' volume at ν = 0.499, over distinct runs: a timing repeat of a run (the
    speed-against-error study's, ``solver_repeat`` > 0) is the same state and is counted once."""
    out = []
    hybrid = hybrid_models(results)
    df = results.ok()
    if not df.empty and "solver_repeat" in df:
        df = df[pd.to_numeric(df["solver_repeat"], errors="coerce").fillna(0) == 0]
    if not df.empty:
        inc = df[(df["nu"].astype(float) == 0.499) & ~df["is_fem"]
                 & df["variant"].isin(hybrid)
                 & df["experiment"].isin(["compression", "tension", "shear", "torsion"])]
        if len(inc):
            e = 100 * inc["volume_change"].abs()
            worst = inc.loc[e.idxmax()]
            n_ok = int((e <= INCOMPRESSIBLE_E_PCT).sum())
            out.append(Claim(f"{' and '.join(hybrid)} preserve the volume of a nearly incompressible material (ν = 0.499)",
                             f"e ≤ {INCOMPRESSIBLE_E_PCT:g} % in every experiment and load",
                             REPRODUCED if n_ok == len(inc) else (PARTLY if n_ok >= len(inc) / 2 else NOT),
                             f"{n_ok} of {len(inc)} runs within; largest e = {e.max():.3g} % ({worst['label']})",
                             len(inc), n_ok))
    return out


def _paper_volume_claims(results: Results, vol: pd.DataFrame, subject: str | None) -> list[Claim]:
    """Our volume changes against the publication's column (Tables 2, 3)."""
    out = []
    if not vol.empty and "paper_mss" in vol:
        sub = vol.dropna(subset=["paper_mss"])
        n = len(sub)
        close = sub[(sub["mss"] - sub["paper_mss"]).abs() <= PAPER_PP]
        meshes = ", ".join(sorted(sub["mesh"].unique()))
        out.append(Claim(f"Our {subject} volume changes match the publication's {results.published_name(subject)} "
                         "column (Tables 2, 3)",
                         f"|e − e_[G20]| ≤ {PAPER_PP:g} pp per row (failed runs count as mismatches)",
                         REPRODUCED if len(close) == n else (PARTLY if len(close) >= n / 2 else NOT),
                         f"{len(close)} of {n} rows within (meshes here: {meshes}; the publication: 10×10×10 cube, "
                         f"4×4×24 beam)", n, len(close)))
    return out


def _face_diagonal_claims(results: Results, subject: str | None) -> list[Claim]:
    """The proposed model closer to the FEM than the one without face diagonals."""
    out = []
    fd = results.published_model("no-face-diagonals")
    diffs = results.table("differences")
    if diffs is not None and len(diffs):
        keys = [k for k in ("experiment", "mesh", "nu", "E", "deformation", "angle_deg") if k in diffs]
        a = diffs[diffs["method"] == f"{subject} static"].set_index(keys)["rel_l2"]
        b = diffs[diffs["method"] == f"{fd} static"].set_index(keys)["rel_l2"]
        a, b = a[~a.index.duplicated()], b[~b.index.duplicated()]
        common = a.index.intersection(b.index)
        if len(common):
            # only scenes in which the two differ by more than the printed precision (0.1 %) can tell them apart
            apart = common[(a[common] - b[common]).abs() > SCENE_PRECISION]
            wins = int((a[apart] < b[apart]).sum())
            ma, mb = 100 * a[common].mean(), 100 * b[common].mean()
            out.append(Claim(f"{subject} (with face diagonals, A = 1) is closer to FEM than {fd}",
                             f"mean relative L2 nodal difference to FEM lower for {subject}, and lower in most scenes "
                             f"whose two differences differ by more than {100 * SCENE_PRECISION:g} %",
                             REPRODUCED if ma < mb and wins > len(apart) / 2 else
                             (PARTLY if ma < mb or wins > len(apart) / 2 else NOT),
                             f"mean rel. L2: {subject} {ma:.3g} %, {fd} {mb:.3g} %; {subject} closer in {wins} of "
                             f"{len(apart)} scenes that tell them apart ({len(common) - len(apart)} of {len(common)} "
                             "not counted)", len(apart), wins))
    return out


def _reaction_claims(h: pd.DataFrame, subject: str | None) -> list[Claim]:
    """The shear force and torsion torque against the FEM."""
    out = []
    for exp, q in (("shear", "shear force"), ("torsion", "torsion torque")):
        sub = h[(h["experiment"] == exp)] if not h.empty else h
        if sub.empty:
            continue
        n_ok = int((sub["err"].abs() <= REL_PCT).sum())
        worst = sub.loc[sub["err"].abs().idxmax()] if sub["err"].notna().any() else None
        ev = f"{n_ok} of {len(sub)} cases within"
        if worst is not None:
            lab = f"θ = {worst['angle_deg']:g}°" if exp == "torsion" else f"d = {100 * worst['deformation']:g} %"
            ev += f"; largest difference {worst['err']:+.3g} % (ν = {worst['nu']:g}, {lab})"
        out.append(Claim(f"{subject} reproduces the FEM {q} on the top plate", f"within {REL_PCT:g} % of FEM for every ν and load",
                         REPRODUCED if n_ok == len(sub) else (PARTLY if n_ok >= len(sub) / 2 else NOT), ev,
                         len(sub), n_ok))
    return out


def _bending_claims(h: pd.DataFrame, subject: str | None) -> list[Claim]:
    """The beam's tip deflection against Euler–Bernoulli."""
    out = []
    bend = h[h["experiment"] == "bending"] if not h.empty else h
    if not bend.empty:
        rel = 100 * (bend["mss"].abs() - bend["eb"].abs()) / bend["eb"].abs()  # negative: deflects less
        n_ok = int((rel.abs() <= REL_PCT).sum())
        out.append(Claim(f"The {subject} beam deflection under gravity follows Euler–Bernoulli (Fig. 5)",
                         f"tip deflection within {REL_PCT:g} % of Euler–Bernoulli",
                         REPRODUCED if n_ok == len(bend) else (PARTLY if n_ok else NOT),
                         "; ".join(f"mesh {r['mesh']}, E = {r['E'] / 1e6:g} MPa: {x:+.3g} %" for (_, r), x in
                                   zip(bend.iterrows(), rel)), len(bend), n_ok))
    return out


def _eform_claims(results: Results) -> list[Claim]:
    """Which calibration the publication's volume changes follow."""
    out = []
    ef = results.table("eform_check")
    if ef is not None:
        for exp in ("compression", "tension"):
            sub = ef[ef["experiment"] == exp] if "experiment" in ef else ef
            if not len(sub):
                continue
            out.append(eform_claim(sub, "Table 2" if exp == "compression" else "Table 3", exp))
    return out


def _run_claims(results: Results) -> list[Claim]:
    """Every run of the publication's scenes reaches a result."""
    out = []
    rows = results.rows
    if not rows.empty and "study" in rows:
        rows = rows[rows["study"].isin(EXPERIMENT_ORDER)]  # the publication's studies, not the stress tests
    if not rows.empty:
        bad = rows[rows["status"] != "ok"]
        mss = rows[~rows["is_fem"]]
        nb = int((mss["status"] != "ok").sum())
        out.append(Claim("The publication's scenes run to a result for every model and ν ([G20] reports no failure)",
                         "all MSS runs reach status ok",
                         REPRODUCED if nb == 0 else NOT,
                         "all runs ok" if bad.empty else
                         f"{len(bad)} of {len(rows)} runs failed: " + "; ".join(
                             f"{r['label']} [{r['solver']}]: {r['status']}"
                             for _, r in bad.sort_values(["label", "solver"]).head(6).iterrows())
                         + (" …" if len(bad) > 6 else "") + " (see Failures)", len(mss), len(mss) - nb))
    return out


def decisive_rows(ef: pd.DataFrame) -> pd.DataFrame:
    """Rows of the E-form check that can tell the two calibrations apart: both runs reached a
    result and the two values differ by more than the publication's printed precision."""
    if "decisive" in ef:
        return ef[ef["decisive"].astype(str).str.lower() == "true"]
    return ef[ef["closer"].isin(["E-form", "G-form"])]


def eform_claim(sub: pd.DataFrame, table: str, exp: str) -> Claim:
    """Which calibration the publication's values follow, weighed over decisive rows only."""
    dec = decisive_rows(sub)
    n_e = int((dec["closer"] == "E-form").sum())
    skipped = len(sub) - len(dec)
    stmt = (f"The publication's {exp} values ({table}) were computed with the E-form constants of eq. 5.12 "
            "(an interpretation, not a claim of [G20])")
    crit = ("E-form closer to the published value in most rows that can tell the two apart (both runs ok, values "
            "differing by more than the printed 0.01 pp)")
    if dec.empty:
        return Claim(stmt, crit, UNTESTED, f"0 of {len(sub)} rows can tell the calibrations apart")
    return Claim(stmt, crit, SUPPORTED if n_e > len(dec) / 2 else NOT_SUPPORTED,
                 f"E-form closer in {n_e} of {len(dec)} decisive rows ({skipped} of {len(sub)} rows not counted: a "
                 "run failed or is missing, or the two calibrations agree to 0.01 pp)", len(dec), n_e)


def count_verdict(n_ok: int, n: int) -> str:
    """All cases meet the criterion: reproduced; at least half: partly; else not; none: not tested."""
    if n == 0:
        return UNTESTED
    return REPRODUCED if n_ok == n else (PARTLY if n_ok >= n / 2 else NOT)


def published_claims(results: Results) -> list[Claim]:
    """One claim per published figure beside ours: [G20] Tables 4, 5, the middle-layer mean
    differences, and [B09]'s error figures."""
    out = []
    own = results.published("G20")
    for number, exp, col, q in ((4, "shear", "force_x", "shear force"), (5, "torsion", "torque_z", "torsion torque")):
        paper = paper_table(f"g20_table{number}_{exp}")
        mesh = results.primary_mesh(exp)
        named = [(r.name, r.model) for r in own.itertuples() if paper is not None and r.name in paper.columns]
        stmt = (f"Our {' and '.join(m for _, m in named) or 'models'} give [G20]'s {q} on the top plate "
                f"(Table {number}, ν = 0.25)")
        crit = f"within {REL_PCT:g} % of the published value in every row (failed or missing runs count as misses)"
        if paper is None or mesh is None:
            out.append(Claim(stmt, crit, UNTESTED, "no published values or no runs"))
            continue
        n = n_ok = 0
        ev = []
        for _, p in paper.iterrows():
            scene = dict(mesh=mesh, nu=float(p["nu"]))
            scene.update(angle_deg=float(p["angle_deg"])) if exp == "torsion" else scene.update(
                deformation=float(p["deformation"]))
            for name, model in named:
                n += 1
                m = results.find(exp, method=f"{model} static", printed=True, **scene)
                if m.empty:
                    ev.append(f"{model} {p['deformation'] * 100:g} %: "
                              + (run_state(results, exp, f"{model} static", printed=True, **scene) or "missing"))
                    continue
                rel = 100 * (float(m[col].iloc[0]) - float(p[name])) / abs(float(p[name]))
                n_ok += abs(rel) <= REL_PCT
                ev.append(f"{model} {p['deformation'] * 100:g} %: {rel:+.3g} %")
        out.append(Claim(stmt, crit, count_verdict(n_ok, n),
                         f"{n_ok} of {n} within (mesh {mesh}; [G20]: 10×10×10): " + ", ".join(ev), n, int(n_ok)))

    ml = middle_layer_frame(results)
    stmt = f"Our {results.published_model('proposed')} middle-layer mean position difference to FEM is [G20]'s (Figs 8, 10, 20 %)"
    crit = f"within a factor {MIDDLE_LAYER_TOL:g} of the published value, 3D mean, in every row"
    if ml.empty:
        out.append(Claim(stmt, crit, UNTESTED, "no published values stored"))
    else:
        good = ml[ml["state"] == "ok"]
        ratio = good["ours_m"] / good["paper_m"] if len(good) else pd.Series(dtype=float)
        n_ok = int(((ratio >= 1 / MIDDLE_LAYER_TOL) & (ratio <= MIDDLE_LAYER_TOL)).sum())
        ev = f"{n_ok} of {len(ml)} rows within"
        if len(good):
            ev += f"; ours / [G20] from ×{ratio.min():.2g} to ×{ratio.max():.2g}"
        if len(good) < len(ml):
            ev += "; " + ", ".join(f"{r['experiment']} ν = {r['nu']:g}: {r['state']}"
                                   for _, r in ml[ml["state"] != "ok"].iterrows())
        out.append(Claim(stmt, crit, count_verdict(n_ok, len(ml)) if len(good) else UNTESTED, ev, len(ml), n_ok))

    b = b09_frame(results.table("baudet_cantilever"), results.table("baudet_lshape"), paper_table("b09_errors"))
    stmt = "Our baudet2009 nodal error against FEM is [B09]'s (mean error of the cantilever and L-shape figures)"
    crit = f"mean error within a factor {MIDDLE_LAYER_TOL:g} of [B09]'s on every mesh run"
    if b.empty or "b09_mean_pct" not in b:
        out.append(Claim(stmt, crit, UNTESTED, "no [B09] experiments stored"))
    else:
        s = b[b["model"].isin(b09_models(b))]
        good = s[s["state"] == "ok"]
        ratio = good["err_mean_pct"] / good["b09_mean_pct"] if len(good) else pd.Series(dtype=float)
        n_ok = int(((ratio >= 1 / MIDDLE_LAYER_TOL) & (ratio <= MIDDLE_LAYER_TOL)).sum())
        ev = f"{n_ok} of {len(s)} meshes within: " + ", ".join(
            f"{r['experiment']} {r['mesh']} ×{r['err_mean_pct'] / r['b09_mean_pct']:.3g}" if r["state"] == "ok"
            else f"{r['experiment']} {r['mesh']} {r['state']}" for _, r in s.iterrows())
        out.append(Claim(stmt, crit, count_verdict(n_ok, len(s)), ev, len(s), n_ok))
        conv = []
        for exp, g in good.groupby("experiment"):
            g = g.sort_values("cells")
            conv.append((exp, bool((np.diff(g["err_mean_pct"].to_numpy()) < 0).all()) and len(g) > 1))
        out.append(Claim("The baudet2009 error falls as the mesh is refined ([B09]'s figures)",
                         "mean error decreases from each mesh to the next finer one, in both experiments",
                         count_verdict(sum(c for _, c in conv), len(conv)),
                         ", ".join(f"{e}: {'falls' if c else 'does not fall'}" for e, c in conv) or "no runs",
                         len(conv), sum(c for _, c in conv)))
    return out


def memory_bound_meshes(perf: pd.DataFrame | None, bandwidth: pd.DataFrame | None) -> tuple[dict, float | None]:
    """``({mesh: MiB a step}, last-level cache MiB)``: the timed meshes whose step streams more
    bytes than the machine's last-level cache (``bytes_per_step`` of the performance table, its
    largest one-thread variant, against ``llc_MB`` of the bandwidth table, both as the
    performance study stored them).  Their time is set by DRAM traffic, which this machine shares:
    on the 16×16×96 beam hybmss-cf took 1,231–1,652 µs a step for eight round-robin rounds and
    734–917 µs for the next four, within one process, while hybmss-fd stayed at 486–675 µs.
    ``({}, None)`` when either figure is not stored."""
    if perf is None or bandwidth is None or "llc_MB" not in bandwidth or "bytes_per_step" not in perf:
        return {}, None
    llc = pd.to_numeric(bandwidth["llc_MB"], errors="coerce").max()
    if not np.isfinite(llc):
        return {}, None
    one = perf[perf["threads"] == perf["threads"].min()] if "threads" in perf else perf
    mb = one.groupby("mesh")["bytes_per_step"].max() / 2**20
    return {str(m): float(v) for m, v in mb.items() if v > llc}, float(llc)


def _perf_summary_claim(summ: pd.DataFrame | None, bound: tuple[dict, float | None] = ({}, None)) -> Claim | None:
    """[G20]'s per-step time ratios to its baseline model against ours (1 thread), from the
    performance study's summary (which joined the publication's ratios by its names).  The meshes
    of ``bound`` (:func:`memory_bound_meshes`) are not counted: their ratios are shown apart."""
    if summ is None or not {"paper_ratio_to_baseline", "ratio_to_baseline", "baseline"} <= set(summ.columns):
        return None
    s = summ[summ["threads"] == summ["threads"].min()] if "threads" in summ else summ
    s = s.dropna(subset=["paper_ratio_to_baseline"])
    heavy, llc = bound
    apart = s[s["mesh"].astype(str).isin(heavy)]
    s = s[~s["mesh"].astype(str).isin(heavy)]
    if s.empty:
        return None
    base = str(s["baseline"].iloc[0])
    ok, ev, stated, n_ok = True, [], [], 0
    for variant, g in s.groupby("variant", sort=False):
        r, th = g["ratio_to_baseline"].astype(float), float(g["paper_ratio_to_baseline"].iloc[0])
        ok = ok and bool((r / th - 1).abs().max() <= PERF_RATIO_TOL)
        n_ok += int(((r / th - 1).abs() <= PERF_RATIO_TOL).sum())
        ev.append(f"{variant} / {base} per step: {r.min():.3g}–{r.max():.3g} (publication {th:g})")
        stated.append(f"{variant} about {th:g}×")
    crit = f"every mesh's ratio within ±{100 * PERF_RATIO_TOL:g} % of the publication's (1 thread)"
    if not apart.empty:
        crit += f"; meshes whose step streams more than the {llc:.3g} MiB last-level cache not counted"
        meshes = ", ".join(f"{m} ({heavy[m]:.0f} MiB a step)" for m in dict.fromkeys(apart["mesh"].astype(str)))
        ranges = "; ".join(f"{v} {g['ratio_to_baseline'].min():.3g}–{g['ratio_to_baseline'].max():.3g}"
                           for v, g in apart.groupby("variant", sort=False))
        ev.append(f"not counted, bound by DRAM traffic the machine shares: {meshes}: {ranges}")
    return Claim(f"Per step, {' and '.join(stated)} the time of {base}", crit,
                 REPRODUCED if ok else NOT,
                 "; ".join(ev) + "; the publication's C++ and this numba kernel differ, so only ratios compare",
                 len(s), n_ok)


# ------------------------------------------------------------------ the stored verdicts
CLAIMS_COLUMNS = ["claim", "criterion", "rows_counted", "rows_within", "verdict", "evidence"]


def judge(results: Results) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The headline comparison and the claims (one row each, :data:`CLAIMS_COLUMNS`) of a results
    folder: the moduli alone when no run is stored, nothing without either."""
    h = headline(results)
    if h.empty and results.table("moduli") is None:
        return h, pd.DataFrame(columns=CLAIMS_COLUMNS)
    return h, pd.DataFrame([c.row() for c in claims(results, h)], columns=CLAIMS_COLUMNS)


def write_claims(store: Store) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Judge the results in ``store`` (every stored run of this code version and the tables the
    studies wrote, as the report reads them) and store ``tables/headline.csv`` and
    ``tables/claims.csv``; run after every study's tables are written."""
    results = Results(store.root)
    h, c = judge(results)
    eq = equilibria(results)
    if not eq.empty:
        store.write_table("equilibria", eq)
    v = verdict(results)
    if not v.empty:
        store.write_table("verdict", v)
    if not h.empty:
        store.write_table("headline", h)
    if not c.empty:
        store.write_table("claims", c)
    return h, c
