"""The studies' sections (speed against error, performance, stability, damping, limit stretch,
[B09]): each study's answer in a sentence or two, its figures, a short table and its stored tables;
and the stored tables no section shows."""

from __future__ import annotations

import numpy as np
import pandas as pd

from .. import study_figures
from .. import findings
from ..data import (Results, b09_models, paper_source)
from ..tables import (Table, fmt, frame_table, grade, short_state, stored_table)
from .base import Context, Section, add_tables, fig_item


#: study sections: (id, title, figures, stored tables kept in the HTML only, collapsed)
STUDY_SECTIONS = (
    ("pareto", "Speed against error: which method for which error budget", ("study_budget", "study_budget_explicit", "study_pareto"),
     ("budget", "pareto_front", "pareto_references", "pareto")),
    ("performance", "Performance against the number of volumes (Figs 11, 12)", ("study_performance",),
     ("performance_summary", "performance", "bandwidth")),
    ("stability", "Stability: time step and extreme loads", ("study_stability_map", "study_dt_stability"),
     ("dt_stability", "stability_extreme", "stability", "stability_irregular", "stability_engines")),
    ("damping", "Damping: steps the explicit protocol needs", ("study_damping",), ("damping_steps",)),
    ("limit", "Limit stretch", ("study_limit_stretch",), ("limit_stretch",)),
    ("baudet", "[B09]'s experiments at [B09]'s parameters", ("study_b09",),
     ("baudet_cantilever", "baudet_lshape", "baudet_moduli", "baudet_volume")),
)


#: study figures printed at a third of the page height, so that a section's figures and short table share a page
HALF_FIGURES = {"study_performance", "study_stability_map", "study_dt_stability", "study_damping",
                "study_limit_stretch", "study_b09"}


def finding(sid: str, results: Results):
    """(answer in one or two sentences, short table or None) of a study section."""
    if sid == "pareto":
        return (findings.budget_sentence(findings.budget_answers(results.table("budget")))
                + study_figures.no_result_note(study_figures.no_result_count(results.table("pareto")))), None
    if sid == "performance":
        return (findings.performance_sentence(results.table("performance_summary")),
                performance_short(results))
    if sid == "stability":
        return findings.stability_sentence(results.table("stability_extreme"), results.table("dt_stability"),
                                           results.published_model("proposed")), None
    if sid == "damping":
        return findings.damping_sentence(results.table("damping_steps")), damping_short(results)
    if sid == "limit":
        return findings.limit_sentence(results.table("limit_stretch")), None
    if sid == "baudet":
        norm = results.table("b09_normalisation")
        return (findings.b09_sentence(results.table("b09_comparison")) + " "
                + b09_sd_sentence(norm if norm is not None else pd.DataFrame()), b09_table(results))
    return "", None


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


def b09_table(results: Results) -> Table | None:
    df = results.table("b09_comparison")
    if df is None:
        return None
    own = b09_models(df)
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
    paper = results.table("b09_published")
    if paper is None:
        return None
    df = results.table("b09_comparison")
    df = df if df is not None else pd.DataFrame()
    norm = results.table("b09_normalisation")
    norm = norm if norm is not None else pd.DataFrame()
    cols = ["experiment", "mesh", "N particles", "[B09] M", "[B09] SD", "[B09] MAX", "ours M", "ours SD", "ours MAX",
            "ours SD/√N × [B09] M / ours M", "that ÷ [B09] SD"]
    rows = []
    for _, p in paper.iterrows():
        row = [(findings.EXPERIMENT_NAMES.get(p["experiment"], p["experiment"]), ""), (p["mesh"], ""),
               (fmt(p["n_particles"]), "")]
        row += [(fmt(float(p[c]), 3), "paper") for c in ("mean_pct", "sd_pct", "max_pct")]
        ours = df[(df["experiment"] == p["experiment"]) & (df["mesh"] == p["mesh"]) & (df["model"] == p["model"])] \
            if not df.empty else df
        n = norm[(norm["experiment"] == p["experiment"]) & (norm["mesh"] == p["mesh"])
                 & (norm["model"] == p["model"])] if not norm.empty else norm
        if ours.empty:
            row += [("not run here", "")] + [("–", "")] * 4
        elif ours["state"].iloc[0] != "ok":
            row += [(short_state(str(ours["state"].iloc[0])), "fail")] + [("–", "")] * 4
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


def sections(ctx: Context) -> list[Section]:
    """One section per study of :data:`STUDY_SECTIONS` that stored a table: its answer, figures,
    short table and stored tables (HTML only)."""
    results = ctx.results
    present = set(results.table_names())
    out = []
    for sid, title, fig_ids, names in STUDY_SECTIONS:
        if not present & set(names):
            continue
        intro, short = finding(sid, results)
        s = Section(f"study_{sid}", title, intro)
        for fid in fig_ids:
            if fid in ctx.figs:
                item = fig_item(ctx.figs[fid])
                if fid in HALF_FIGURES:
                    item["css"] = "study"
                s.items.append(("figure", item))
        add_tables(s, short)
        if sid == "baudet":
            add_tables(s, b09_published_table(results))
        add_tables(s, *(stored_table(results, name) for name in names))
        out.append(s)
    return out


def others(ctx: Context, known: set) -> Section | None:
    """The stored tables no section shows (``known``), as stored (HTML only)."""
    names = [n for n in ctx.results.table_names() if n not in known]
    if not names:
        return None
    s = Section("study_other", "Other study tables",
                "Tables written by further studies, as stored (HTML only).", screen_only=True)
    add_tables(s, *(stored_table(ctx.results, name) for name in names))
    return s
