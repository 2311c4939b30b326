"""Effective moduli of every model against the input ones, and the E-form check."""

from __future__ import annotations

from ..data import Results
from ..tables import (Table, fmt, frame_table, grade, short_state)
from .base import Context, Section, add_tables
from .summary import claim_findings


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
            return short_state(st), "fail" if st.startswith("failed") else ""

        closer = str(r["closer"])
        if closer.startswith("undecided ("):
            closer = "undecided (" + short_state(closer[len("undecided ("):-1]) + ")"
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


def section(ctx: Context) -> Section | None:
    """Effective moduli and the E-form check, opened by the claims they decide."""
    s = Section("moduli", "Effective moduli and the E-form check",
                claim_findings(ctx.claims, "input Young's modulus", "limited to ν = 1/4", "E-form"))
    add_tables(s, moduli_table(ctx.results), eform_table(ctx.results))
    return s if s.items else None
