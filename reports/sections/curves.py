"""Cross sections, beam deflection and nodal differences (Figs 5, 8, 10): the middle layer's mean
position difference against [G20]'s, and the nodal differences of every model against the FEM."""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..data import (MIDDLE_LAYER_TOL, Results, paper_source)
from ..tables import (Table, fmt, frame_table, grade)
from .base import Context, Section, add_tables
from .summary import claim_findings


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


def middle_layer_table(results: Results) -> Table | None:
    f = results.table("middle_layer")
    if f is None:
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


def section(ctx: Context) -> Section | None:
    """Cross sections, beam deflection and nodal differences (Figs 5, 8, 10), opened by the claims they decide."""
    results = ctx.results
    s = Section("curves", "Cross sections, beam deflection and nodal differences (Figs 5, 8, 10)",
                claim_findings(ctx.claims, "middle-layer", "beam deflection", "closer to FEM than"))
    ctx.add_figures(s, "fig8", "fig10")
    add_tables(s, middle_layer_table(results))
    ctx.add_figures(s, "fig5", "fig_diff")
    add_tables(s, differences_table(results))
    return s if s.items else None
