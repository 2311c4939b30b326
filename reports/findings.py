"""The answers of the study sections, computed from the stored study tables.

Each function reads one or two stored tables and returns a small frame or a sentence; the figures
(:mod:`reports.figures`) and the section texts (:mod:`reports.build`) use the same frames, so a
sentence and its picture never disagree.  A missing table gives ``None`` / an empty frame, and a
sentence says what is missing rather than printing a placeholder number.
"""

from __future__ import annotations

import math
import re

import pandas as pd

from studies.claims import b09_frame, b09_models  # noqa: F401 - the report's [B09] tables and figures read them here

STATES = ("converged", "unstable", "diverged", "inverted", "missing")
"""Outcomes of a run in the stability map, in legend order."""


def pct(v: float, digits: int = 3) -> str:
    """A fraction as a percentage for a sentence (``0.05`` -> ``"5 %"``)."""
    return f"{100 * v:.{digits}g} %"


def _num(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


# ------------------------------------------------------------------ speed against error
def budget_answers(budget: pd.DataFrame | None) -> pd.DataFrame:
    """The per-configuration rows of the pareto study's stored ``budget`` table
    (:func:`studies.pareto.budget_table`): for every configuration and error budget, the fastest
    method whose nodal error meets the budget, its time, the next fastest *other* method that
    meets it and the lead ``t_next / t_fastest``.

    Columns: ``config, experiment, budget, method, mesh, time_s, error_u, next_method,
    next_time_s, lead`` (``method`` = "none" when no candidate meets the budget; ``next_method``
    = "none" and ``lead`` NaN when only one method does)."""
    cols = ["config", "experiment", "budget", "method", "mesh", "time_s", "error_u", "next_method", "next_time_s",
            "lead"]
    if budget is None or not {"config", "method", "budget", "lead"} <= set(budget.columns):
        return pd.DataFrame(columns=cols)
    df = budget[budget["config"].astype(str) != "all configurations"].copy()
    df["method"] = df["method"].where(df["method"].astype(str) != "none within budget", "none")
    df["next_method"] = df["next_method"].fillna("none")
    df["mesh"] = df["mesh"].fillna("")
    return df[cols].reset_index(drop=True)


def budget_sentence(ans: pd.DataFrame) -> str:
    if ans.empty:
        return "No speed-against-error table is stored (study pareto not run)."
    parts, fem, none = [], [], []
    for b, g in ans.groupby("budget"):
        mss = int((~g["method"].str.startswith("fem") & (g["method"] != "none")).sum())
        parts.append(f"{mss} of {len(g)} at {pct(b)}")
        fem.append(int(g["method"].str.startswith("fem").sum()))
        none.append(int((g["method"] == "none").sum()))
    leads = ans["lead"].dropna()
    lead = (f"; the winner leads the next method by ×{leads.median():.2f} in the median "
            f"(×{leads.min():.2f}–×{leads.max():.2f})" if len(leads) else "")
    return ("A mass-spring model is the fastest method that meets the error budget in "
            + ", ".join(parts) + " of the configurations (a FEM mesh in " + "/".join(map(str, fem))
            + ", no method in " + "/".join(map(str, none)) + ")" + lead + ". The chart names the winner of each.")


# ------------------------------------------------------------------ performance
def performance_sentence(summ: pd.DataFrame | None) -> str:
    """Per-step time of each model with a published ratio, against [G20]'s baseline model (1 thread)."""
    if summ is None or not {"ratio_to_baseline", "paper_ratio_to_baseline", "baseline"} <= set(summ.columns):
        return "No performance summary is stored (study performance not run)."
    s = summ[summ["threads"] == summ["threads"].min()] if "threads" in summ else summ
    s = s.dropna(subset=["paper_ratio_to_baseline"])
    if s.empty:
        return "The performance summary has no row with a published ratio."
    base = str(s["baseline"].iloc[0])
    parts = [f"{v} ×{g['ratio_to_baseline'].min():.2g}–×{g['ratio_to_baseline'].max():.2g} "
             f"([G20]: ×{_num(g['paper_ratio_to_baseline'].iloc[0]):g})" for v, g in s.groupby("variant", sort=False)]
    txt = f"Per explicit step on one thread, relative to {base}: " + " and ".join(parts)
    if "volumes" in s:
        txt += f", over meshes of {int(s['volumes'].min())}–{int(s['volumes'].max())} volumes"
    return txt + "."


# ------------------------------------------------------------------ stability
def outcome(status: str, inverted) -> str:
    """One of :data:`STATES` for a row of the stability tables."""
    st = str(status)
    if _num(inverted) > 0 or st == "inverted":
        return "inverted"
    if st in ("converged", "ok"):
        return "converged"
    if st.startswith("diverged"):
        return "diverged"
    if st in ("nan", "", "missing"):
        return "missing"
    return "unstable"


def stability_grid(extreme: pd.DataFrame | None) -> pd.DataFrame:
    """Rows ``variant, case, solver, nu, outcome`` of the extreme-load study."""
    if extreme is None or not {"variant", "case", "nu", "status"} <= set(extreme.columns):
        return pd.DataFrame(columns=["variant", "case", "solver", "nu", "outcome"])
    df = extreme.copy()
    df["solver"] = df.get("solver", "mss-static").astype(str).str.replace("mss-", "", regex=False)
    df["outcome"] = [outcome(s, i) for s, i in zip(df["status"], df.get("inverted_cells", 0))]
    return df[["variant", "case", "solver", "nu", "outcome"]]


def stability_sentence(extreme: pd.DataFrame | None, dt: pd.DataFrame | None, model: str | None = None) -> str:
    """The explicit limit of ``model`` (the publication's proposed one) against ν, and the
    outcomes of the extreme loads."""
    parts = []
    if model is not None and dt is not None and {"nu", "variant", "dt_crit"} <= set(dt.columns):
        h = dt[dt["variant"] == model].sort_values("nu")
        h = h[h["nu"] > 0]
        if len(h) >= 2:
            a, b = h.iloc[0], h.iloc[-1]
            parts.append(f"the explicit limit dt_crit of {model} falls from {a['dt_crit']:.3g} s at ν = {a['nu']:g} to "
                         f"{b['dt_crit']:.3g} s at ν = {b['nu']:g} (×{a['dt_crit'] / b['dt_crit']:.3g} smaller)")
    g = stability_grid(extreme)
    if len(g):
        runs = []
        for solver, s in sorted(g.groupby("solver"), key=lambda kv: kv[0] != "static"):
            c = s["outcome"].value_counts()
            other = ", ".join(f"{k} {v}" for k, v in c.items() if k != "converged")
            runs.append(f"the {solver} solver converged in {int(c.get('converged', 0))} of {len(s)} runs"
                        + (f" ({other})" if other else ""))
        parts.append("under the extreme loads " + " and ".join(runs))
    if not parts:
        return "No stability table is stored (study stability not run)."
    s = "; ".join(parts)
    return s[0].upper() + s[1:] + "."


def limit_sentence(limit: pd.DataFrame | None) -> str:
    if limit is None or not {"nu", "variant", "status", "stretch_lo"} <= set(limit.columns):
        return "No limit-stretch table is stored (study stability not run)."
    sub = limit[limit.get("volume_energy", "quadratic").astype(str) == "quadratic"] if "volume_energy" in limit else limit
    lost = sub[sub["status"] != "ok"]
    held = sub[sub["status"] == "ok"]
    parts = []
    for v, g in lost.groupby("variant", sort=False):
        parts.append(f"{v} loses its equilibrium at a stretch of " + ", ".join(
            f"{r['stretch_lo']:.3g} (ν = {r['nu']:g})" for _, r in g.sort_values("nu", ascending=False).iterrows()))
    for v, g in held.groupby("variant", sort=False):
        dmax = g["d_max"].max() if "d_max" in g else math.nan
        parts.append(f"{v} holds to the largest stretch tried ({1 + dmax:.3g})")
    return ("In tension to 100 % with the quadratic volume energy, " + "; ".join(parts) +
            ". The volume term with κ < 0 (ν < 1/4) rewards dilation, so the loss of equilibrium is a limit point of "
            "the model, not a solver failure.") if parts else "The limit-stretch table has no rows."


def damping_curves(damping: pd.DataFrame | None) -> pd.DataFrame:
    """``nu, steps, error`` parsed from the ``errors`` column ("1000:3.96e-01; 2000:...")."""
    rows = []
    if damping is None or "errors" not in damping:
        return pd.DataFrame(columns=["nu", "steps", "error"])
    for _, r in damping.iterrows():
        for m in re.finditer(r"(\d+)\s*:\s*([0-9.eE+-]+)", str(r["errors"])):
            rows.append({"nu": float(r["nu"]), "steps": int(m.group(1)), "error": float(m.group(2))})
    return pd.DataFrame(rows, columns=["nu", "steps", "error"])


def damping_sentence(damping: pd.DataFrame | None) -> str:
    if damping is None or "steps_to_tol" not in damping:
        return "No damping table is stored (study stability not run)."
    c = damping["damping"].iloc[0] if "damping" in damping else math.nan
    tol = damping["tol"].iloc[0] if "tol" in damping else math.nan
    dt = damping["dt"].iloc[0] if "dt" in damping else math.nan
    def steps(v) -> str:
        v = str(v).strip()
        if v.startswith(">"):
            return f"more than {v[1:].strip()} steps (the most run)"
        if v.startswith("≤"):
            return f"at most {v[1:].strip()} steps (the first checkpoint)"
        return f"{v} steps"

    vals = [steps(v) for v in damping["steps_to_tol"]]
    if len(set(vals)) == 1:
        per = f"{vals[0]} at every ν tried ({', '.join(f'{v:g}' for v in damping['nu'])})"
    else:
        per = ", ".join(f"{v} at ν = {nu:g}" for v, nu in zip(vals, damping["nu"]))
    return (f"With mass-proportional damping c = {c:g} s⁻¹ and dt = {dt:g} s, the explicit run needs {per} to come "
            f"within {100 * tol:g} % (relative L2) of the static equilibrium for good (interpolated between the "
            "checkpoints that bracket the crossing); [G20]'s protocol reads the state after 10,000 steps.")


# ------------------------------------------------------------------ [B09]
EXPERIMENT_NAMES = {"lshape": "L-shape", "cantilever": "cantilever"}
"""Reader-facing names of [B09]'s experiments."""


def b09_sentence(df: pd.DataFrame) -> str:
    if df.empty:
        return "No [B09] table is stored (study b09 not run)."
    own = b09_models(df)
    if not own:
        return "No published [B09] values are stored beside these runs."
    name = own[0]
    parts = []
    for exp, g in df.groupby("experiment", sort=False):
        b = g[(g["model"] == name) & (g["state"] == "ok")].sort_values("cells")
        exp = EXPERIMENT_NAMES.get(exp, exp)
        if b.empty:
            parts.append(f"{exp}: {name} has no successful run")
            continue
        ours = " → ".join(f"{v:.3g}" for v in b["err_mean_pct"])
        theirs = " → ".join("missing" if pd.isna(v) else f"{v:.3g}" for v in b.get("b09_mean_pct", []))
        meshes = " → ".join(b["mesh"])
        fine = g[(g["state"] == "ok") & (g["cells"] == g["cells"].max())]
        best = fine.set_index("model")["err_mean_pct"].sort_values()
        parts.append(f"{exp} ({meshes}): {name} mean error {ours} % against [B09]'s {theirs} %; on the finest "
                     f"mesh here the lowest mean error is {best.index[0]}'s ({best.iloc[0]:.3g} %)")
    s = "; ".join(parts) + "."
    return s[0].upper() + s[1:]
