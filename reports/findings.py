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

from .data import TIMING_NOISE, b09_models

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


def number_or_none(v) -> float | None:
    """A stored cell as a number, ``None`` where it holds none (empty, text, NaN)."""
    v = _num(v)
    return None if math.isnan(v) else v


# ------------------------------------------------------------------ speed against error
MEASURE_NAMES = {"force": "plate force or torque (beam: tip deflection)", "volume": "volume change",
                 "field": "displacement field"}
"""How a sentence names the budget study's error measures (:data:`studies.paper.pareto.MEASURES`)."""
COST_NAMES = {"static": "wall time to an equilibrium (static, implicit, FEM)",
              "explicit": "wall time per simulated second at the stable step (explicit)"}


def budget_answers(budget: pd.DataFrame | None) -> pd.DataFrame:
    """The per-configuration answers of the pareto study's stored ``budget`` table
    (:func:`studies.paper.pareto.budget_table`, :func:`studies.sweep.cost.budget_answer`): for every
    configuration, error measure, cost and budget, the fastest method within it (``method`` =
    "none" when none is), its mesh, cost and error, the runner-up, the lead and ``tie``.

    Columns: ``config, experiment, nu, measure, cost_kind, budget, method, mesh, cost, error,
    spread, runner_up, lead, tie`` (``runner_up`` = "none" and ``lead`` NaN when one method meets
    the budget; ``tie`` True, False or NaN: undetermined, a single timing)."""
    cols = ["config", "experiment", "nu", "measure", "cost_kind", "budget", "method", "mesh", "cost", "error",
            "spread", "runner_up", "lead", "tie"]
    if budget is None or not {"config", "measure", "cost_kind", "answer", "tie"} <= set(budget.columns):
        return pd.DataFrame(columns=cols)
    df = budget[budget["answer"].astype(str) == "fastest"].copy()
    df["method"] = df["method"].where(df["method"].astype(str) != "none within budget", "none")
    df["runner_up"] = df["runner_up"].fillna("").astype(str).replace("", "none")
    df["mesh"] = df["mesh"].fillna("")
    return df[cols].reset_index(drop=True)


def method_model(method: str) -> str:
    """The model (or the FEM) of a method name of the budget table: ``"corot-hex8 explicit"`` ->
    ``"corot-hex8"``, ``"fem-hex1-linear"`` -> ``"FEM Hex1"``."""
    m = str(method)
    if m.startswith("fem-"):
        return "FEM " + {"hex1": "Hex1", "hex2": "Hex2", "mixed": "mixed u–p"}.get(m.split("-")[1], m.split("-")[1])
    return m.split(" ")[0]


def _is_tie(v) -> bool | None:
    if v is None or (isinstance(v, float) and math.isnan(v)) or v is pd.NA:
        return None
    return str(v).strip().lower() in ("true", "1", "1.0")


def budget_sentence(ans: pd.DataFrame, budget: float | None = None) -> str:
    """Per cost and error measure, at the middle budget: which models are fastest in how many
    configurations (by name), how many configurations no method meets, and how many leads are
    ties (the lead smaller than the timing spread)."""
    if ans.empty:
        return "No speed-against-error table is stored (study pareto not run)."
    budgets = sorted(ans["budget"].astype(float).unique())
    b = budget if budget is not None else budgets[len(budgets) // 2]
    at = ans[ans["budget"].astype(float) == b]
    parts = []
    for kind in [k for k in COST_NAMES if k in set(at["cost_kind"])]:
        per = []
        for m in [m for m in MEASURE_NAMES if m in set(at["measure"])]:
            g = at[(at["cost_kind"] == kind) & (at["measure"] == m)]
            won = g[g["method"] != "none"]
            counts = won["method"].map(method_model).value_counts()
            names = ", ".join(f"{name} {n}" for name, n in counts.items()) or "no method"
            none = int((g["method"] == "none").sum())
            per.append(f"by {MEASURE_NAMES[m]} error: {names}" + (f", none in {none}" if none else "")
                       + f" (of {len(g)})")
        parts.append(f"Cost as {COST_NAMES[kind]}, fastest within {pct(b)}, " + "; ".join(per) + ".")
    leads = ans[ans["runner_up"] != "none"]
    ties = leads["tie"].map(_is_tie)
    n_tie, n_unknown = int((ties == True).sum()), int(ties.isna().sum())  # noqa: E712
    tie_txt = (f" Of the {len(leads)} answers with a runner-up (all budgets), {n_tie} "
               + ("is a tie" if n_tie == 1 else "are ties") + ": the lead is "
               "smaller than 1 + the larger timing spread (median over best of the repeats) or than "
               f"{1 + TIMING_NOISE:.2f} (runs timed apart)"
               + (f"; {n_unknown} are undetermined (a single timing)" if n_unknown else "") + ".")
    return " ".join(parts) + tie_txt + " The chart names the winner of each."


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


def b09_sentence(df: pd.DataFrame | None) -> str:
    if df is None or df.empty:
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
