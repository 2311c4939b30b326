"""The report's section on the engines people run (MuJoCo, Newton, PositionBasedDynamics), from
stored tables only: what each engine's parameters mean (from its source, as the model folders
``hybmss/models/mujoco``, ``newton``, ``pbd`` derive and their verification tests measure), the
closing table of the 10³ cube against the FEM (``engines_closing``, :mod:`studies.paper.engines`), the
step times as ratios to hybmss (``engines_timing``), the engines' effective moduli (rows of the
``moduli`` table) and what each cannot do.

:func:`section` returns ``(title, intro, items)`` for :func:`reports.build.build`, or None when
no engine table is stored.
"""

from __future__ import annotations

import html

import pandas as pd

from .data import ENGINE_LAWS
from .findings import number_or_none
from .tables import Table, fmt, frame_table, grade

TABLES = ("engines_closing", "engines_timing", "engines_cost")
"""The stored tables this section shows (the build leaves them out of its other sections)."""

def laws_table() -> Table:
    """What each engine model's parameters mean, from the engine's source (model docstrings)."""
    rows = [[(m, ""), (eng, ""), (law, ""), (cannot, "")] for m, (eng, law, cannot) in ENGINE_LAWS.items()]
    return Table("table_engine_laws", "The engines' laws and what each cannot do",
                 "Each engine's own code runs (its package, imported only when used); the law and the (E, ν) "
                 "mapping are derived from its source and checked by the verification tests "
                 "(tests/verification/test_engine_*.py): at strain 1e-4 on a 2×2×2 cube each engine's plate "
                 "reaction equals scikit-fem's on the very same mesh (ElementTetP1 on the engine's tetrahedra, "
                 "Hex1/Hex2 on its cells) to 1e-3, and its reactions balance the weight to 1e-3.",
                 ["model", "engine, element", "law and (E, ν) mapping", "cannot represent (refused, exit 2)"], rows)




def closing_table(t: pd.DataFrame) -> Table:
    def cls(r, c):
        if c == "status":
            return "good" if r["status"] == "ok" else "fail"
        if c in ("force_rel_error", "volume_change_rel_error"):
            return grade(number_or_none(r[c]), (0.02, 0.10))
        return ""

    cols = {"experiment": "experiment", "mesh": "mesh", "nu": "ν", "model": "model", "status": "status",
            "force_N": "plate force (N)", "force_fem_N": "FEM force (N)", "force_rel_error": "force error (–)",
            "volume_change": "ΔV/V (–)", "volume_change_fem": "FEM ΔV/V (–)",
            "volume_change_rel_error": "ΔV/V error (–)", "static_wall_s": "static wall (s)", "steps": "steps",
            "message": "why not"}
    df = t.copy()
    if "message" in df:
        df["message"] = df["message"].map(lambda m: m if isinstance(m, str) else None)
    tab = frame_table(df, "table_engines_closing", "The engines on the 10³ cube at 5 % against the FEM",
                      "Compression (F_z) and shear (F_x) of the 10×10×10 cube (E = 10⁴ Pa) at 5 %: each model's static "
                      "answer (an engine's: the rest state of its damped run in the harness's explicit loop), "
                      "against the linear FEM on the same cube (Hex2; mixed u–p Hex2×Hex1 for ν ≥ 0.45). Errors "
                      "relative to the FEM: green ≤ 2 %, amber ≤ 10 %, red beyond; the volume error is empty where "
                      "the FEM's ΔV/V is 0 (shear). hybmss and corot-hex8 for context. A model that cannot "
                      "represent the scene has a failure row with its reason; a model with no row was not run.",
                      cols, cls)
    tab.csv = "tables/engines_closing.csv"
    return tab


def timing_table(t: pd.DataFrame) -> Table:
    cols = {"model": "model", "mesh": "mesh", "nu": "ν", "steps": "steps", "s_per_step": "s per step",
            "ratio_to_hybmss": "ratio to hybmss", "engine_calls_s_per_step": "engine's own calls, s per step",
            "first_use_s": "first use (s)", "device": "device", "engine_version": "version", "load_avg": "load avg"}
    tab = frame_table(t, "table_engines_timing", "Time per explicit step against hybmss",
                      "Each model's explicit step on the compression cube in the harness's one loop (plates, damping "
                      "and checks included; the engine's own calls apart), best of three interleaved runs, as a ratio "
                      "to hybmss's (Numba, float64, one thread) measured in the same process; first use = building "
                      "and compiling the engine's model (MuJoCo's compiler, Warp's kernels: cached after the first "
                      "process). The 1-minute load average is that of each model's best run on a shared 2-core "
                      "machine: above 2, absolute times are not the code's, the ratios less so.", cols)
    tab.csv = "tables/engines_timing.csv"
    return tab


def moduli_rows(moduli: pd.DataFrame | None) -> Table | None:
    """The engines' rows of the stored ``moduli`` table."""
    if moduli is None or "model" not in moduli:
        return None
    t = moduli[moduli["model"].isin(list(ENGINE_LAWS))]
    if t.empty:
        return None

    def cls(r, c):
        if c == "status":
            return "good" if r["status"] == "ok" else "fail"
        if c == "nu_eff":
            return grade(number_or_none(r["nu_eff"]) - r["nu"] if number_or_none(r["nu_eff"]) is not None else None, (1e-3, 2e-2))
        if c in ("E_eff_over_E", "G_eff_over_G"):
            return grade(number_or_none(r[c]) - 1.0 if number_or_none(r[c]) is not None else None, (1e-3, 2e-2))
        return ""

    return frame_table(t, "table_engine_moduli", "The engines' effective moduli against the requested E, ν, G",
                       "Homogeneous uniaxial stress and simple shear at strain 1e-4 (hybmss moduli): green within "
                       "0.1 % (0.001 for ν). A refusal says which input the engine cannot represent.",
                       {"model": "model", "nu": "ν input", "E_eff_over_E": "E_eff / E (–)", "nu_eff": "ν_eff (–)",
                        "G_eff_over_G": "G_eff / G (–)", "status": "status"}, cls)


def findings(closing: pd.DataFrame | None, timing: pd.DataFrame | None) -> str:
    """The section's introduction: measured figures of the stored tables, in sentences."""
    out = ["Three engines' own code runs the same scenes, plates and materials as every other model. "
           "Defects found by measurement (each guarded by a test that fails when the model is changed to "
           "ignore it): Newton's builder Lamé parameters are not SolverSemiImplicit's (μ 25 % low as "
           "documented); SolverXPBD has no small-strain shear stiffness; pypbd's FEM constraint silently does "
           "nothing for ν < 0 or ν > 0.49 and below an absolute threshold of 1e-6; MuJoCo refuses joint "
           "damping on a flex; SolverVBD cannot hold a sliding plate. pbd-xpbd-fem's forces (its plate "
           "reactions, its rest test) are the harness's re-implementation of the library's formulas (svk_forces, "
           "checked against one projection of the engine), not the engine's: its bindings expose no force.",
           "In the tables of the five experiments the engines of the tables and bending roles have rows on "
           "coarse meshes of their own (the 5³ cube and the 2×2×12 beam; mujoco-quadratic 2³ and 1×1×6), each "
           "against the FEM solved on the same mesh (the tables of the other models, with the mesh in the row); "
           "in bending a run to rest of the cantilever under its weight takes about 3,000 engine steps (its "
           "first bending mode is slow against the cells' stable step), 5–13 s a run on the 2×2×12 beam. "
           "Their behaviour at "
           "ν = 0.499 and 20 % (rest, locking, divergence) is the stability study's table stability_engines."]
    if closing is not None and not closing.empty:
        ok = closing[(closing["status"] == "ok") & closing["engine"].astype(bool)]
        if not ok.empty and ok["force_rel_error"].notna().any():
            worst = ok.loc[ok["force_rel_error"].astype(float).idxmax()]
            best = ok.loc[ok["force_rel_error"].astype(float).idxmin()]
            out.append(f"On the {worst['mesh']} cube at 5 % the engines' plate forces are within "
                       f"{100 * float(best['force_rel_error']):.2g} % ({best['model']}, {best['experiment']}, "
                       f"ν = {best['nu']:g}) to {100 * float(worst['force_rel_error']):.2g} % ({worst['model']}, "
                       f"{worst['experiment']}, ν = {worst['nu']:g}) of the FEM.")
        top = closing[(closing["nu"] == closing["nu"].max()) & closing["engine"].astype(bool)
                      & (closing["experiment"] == "compression")]
        if not top.empty:  # locking as ν → ½: the force error of each engine at the largest ν
            out.append(f"Compression at ν = {closing['nu'].max():g}: " + ", ".join(
                f"{r['model']} " + (f"{100 * float(r['force_rel_error']):.3g} %" if r["status"] == "ok"
                                    and number_or_none(r["force_rel_error"]) is not None else str(r["status"]))
                for _, r in top.iterrows()) + " (force error against the FEM).")
        refused = closing[closing["status"] == "not-representable"]
        if not refused.empty:
            out.append("Not representable: " + "; ".join(
                f"{m} ({', '.join(sorted({f'ν = {n:g}' for n in g['nu']}))})" for m, g in refused.groupby("model"))
                + ".")
    if timing is not None and not timing.empty:
        eng = timing.iloc[1:]  # the first row is the reference model the ratios are to
        if not eng.empty:
            loads = timing["load_avg"].dropna()
            out.append("Time per step against hybmss on the " + str(timing["mesh"].iloc[0]) + " cube: " + ", ".join(
                f"{r['model']} {fmt(float(r['ratio_to_hybmss']), 3)}×" for _, r in eng.iterrows())
                + (f" (load average {loads.min():.1f}–{loads.max():.1f} on 2 cores)." if len(loads) else "."))
    return " ".join(out)


def section(results) -> tuple[str, str, list] | None:
    """``(title, intro, items)`` of the engines' section, or None without any engine table."""
    closing, timing = results.table("engines_closing"), results.table("engines_timing")
    moduli = moduli_rows(results.table("moduli"))
    if closing is None and timing is None and moduli is None:
        return None
    items = [("table", laws_table())]
    if closing is not None:
        items.append(("table", closing_table(closing)))
    if timing is not None:
        items.append(("table", timing_table(timing)))
    if moduli is not None:
        items.append(("table", moduli))
    cost = results.table("engines_cost")
    if cost is not None:
        tab = frame_table(cost, "table_engines_cost", "The engines' share of make reproduce-paper",
                          "The engine runs of the studies (their rows in the tables and the speed-against-error "
                          "study): measured on the quick reproduction, estimated for the full one from the "
                          "measured time per step and steps to rest (∝ √((λ+2μ)/μ)); times measured on a loaded "
                          "machine are brought to the reproduction's conditions by the factor between the same "
                          "non-engine runs then and now.")
        tab.csv = "tables/engines_cost.csv"
        items.append(("table", tab))
    return ("The engines people run: MuJoCo, Newton, PositionBasedDynamics", html.escape(findings(closing, timing)),
            items)
