"""The publications' figures beside ours, as tables: [G20]'s middle-layer mean position differences
(shear, torsion) and [B09]'s nodal errors (cantilever, L-shape) with the particles of its lattices and
its SD read two ways.  The claims judge them (:mod:`studies.paper.claims`); the studies store them for
the report (:mod:`studies.paper.stored`)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from studies.paper.values import paper_table
from studies.sweep.results import Results, printed_match as printed, run_state



# ------------------------------------------------------------------ the publication's numbers beside ours
def middle_layer_frame(results: Results) -> pd.DataFrame:
    """[G20]'s mean position differences over the middle layer (shear, torsion at 20 %) beside
    ours for [G20]'s proposed model against the FEM reference, with the alternative definitions."""
    paper = paper_table("g20_middle_layer")
    diffs = results.table("differences")
    method = f"{results.published_model('proposed')} static"
    if paper is None:
        return pd.DataFrame()
    rows = []
    for _, p in paper.iterrows():
        exp = p["experiment"]
        mesh = results.primary_mesh(exp)
        rec = {"experiment": exp, "nu": float(p["nu"]), "mesh": mesh or "", "paper_m": float(p["mean_diff_m"]),
               "load": f"θ = {p['angle_deg']:g}°" if exp == "torsion" else f"d = {100 * p['deformation']:g} %"}
        scene = dict(mesh=mesh, nu=float(p["nu"]))
        if exp == "torsion":
            scene["angle_deg"] = float(p["angle_deg"])
        else:
            scene["deformation"] = float(p["deformation"])
        sel = pd.DataFrame()
        if diffs is not None and mesh is not None:
            m = (diffs["experiment"] == exp) & (diffs["mesh"] == mesh) & printed(diffs["nu"], p["nu"]) \
                & (diffs["method"] == method)
            m &= printed(diffs["angle_deg"], p["angle_deg"]) if exp == "torsion" else printed(diffs["deformation"], p["deformation"])
            sel = diffs[m]
        if len(sel):
            r = sel.iloc[0]
            rec.update(state="ok", reference=r["reference"], ours_m=r["mid_layer_mean_m"],
                       ours_xy_m=r.get("mid_layer_mean_xy_m", np.nan), ours_svk_m=r.get("mid_layer_mean_svk_m", np.nan),
                       n_points=r.get("mid_layer_n", np.nan))
        else:
            st = run_state(results, exp, method, printed=True, **scene) if mesh else "missing"
            if not st:
                st = "missing (no FEM reference)" if results.reference(exp, printed=True, **scene) is None else "missing"
            rec.update(state=st)
        rows.append(rec)
    return pd.DataFrame(rows)


# ------------------------------------------------------------------ [B09]
def b09_frame(cantilever: pd.DataFrame | None, lshape: pd.DataFrame | None, paper: pd.DataFrame | None) -> pd.DataFrame:
    """Rows ``experiment, mesh, model, state`` with our error statistics (``err_*``: normalized by
    the largest reference displacement; ``rel_*``: nodal relative error) and [B09]'s (``b09_*``)."""
    parts = []
    for exp, t in (("cantilever", cantilever), ("lshape", lshape)):
        if t is None:
            continue
        t = t.copy()
        t["experiment"] = exp
        if "err_std_pct" in t and "err_sd_pct" not in t:  # older result folders
            t["err_sd_pct"] = t["err_std_pct"]
        if "status" not in t:
            t["status"] = "ok"
        parts.append(t)
    if not parts:
        return pd.DataFrame()
    df = pd.concat(parts, ignore_index=True)
    df["state"] = df["status"].fillna("missing").astype(str)
    if paper is not None:  # [B09]'s figures are for its own model, named in the published table
        p = paper.rename(columns={"mean_pct": "b09_mean_pct", "sd_pct": "b09_sd_pct", "max_pct": "b09_max_pct"})
        df = df.merge(p, on=["experiment", "mesh", "model"], how="left")
    return df


def b09_particles(experiment: str, mesh: str) -> int:
    """Particles of [B09]'s lattices: the nodes of the cantilever's box grid, and of the cells of the
    L-shape's mask (the column x < n/2 and the arm z ≥ n/2 of the n³ grid, as
    :func:`studies.paper.baudet.lshape_mask`)."""
    dims = [int(v) for v in str(mesh).split("x")]
    if experiment != "lshape":
        return int(np.prod([d + 1 for d in dims]))
    n = dims[0]
    cells = np.zeros((n, n, n), dtype=bool)
    cells[: n // 2, :, :] = True
    cells[:, :, n // 2:] = True
    nodes = np.zeros((n + 1, n + 1, n + 1), dtype=bool)
    for di in (0, 1):
        for dj in (0, 1):
            for dk in (0, 1):
                nodes[di:n + di, dj:n + dj, dk:n + dk] |= cells
    return int(nodes.sum())


def b09_normalisation(df: pd.DataFrame) -> pd.DataFrame:
    """[B09]'s SD beside ours read two ways, for the rows with published values: our SD over the N
    particles, and our standard error of the mean SD/√N scaled by the ratio of the means
    (``sem_scaled_pct``: what [B09] would print if its SD were the standard error of its mean);
    ``sem_ratio``: that over [B09]'s SD (1 if the reading holds)."""
    s = df[df["state"].eq("ok") & df.get("b09_sd_pct", pd.Series(np.nan, index=df.index)).notna()].copy()
    if s.empty:
        return s
    s["n_particles"] = [b09_particles(e, m) for e, m in zip(s["experiment"], s["mesh"])]
    s["sem_pct"] = s["err_sd_pct"] / np.sqrt(s["n_particles"])
    s["sem_scaled_pct"] = s["sem_pct"] * s["b09_mean_pct"] / s["err_mean_pct"]
    s["sd_ratio"] = s["err_sd_pct"] / s["b09_sd_pct"]
    s["sem_ratio"] = s["sem_scaled_pct"] / s["b09_sd_pct"]
    return s


def b09_models(df: pd.DataFrame) -> list[str]:
    """The models [B09]'s figures are for (those rows of :func:`b09_frame` with published values)."""
    if "b09_mean_pct" not in df:
        return []
    return list(dict.fromkeys(df.loc[df["b09_mean_pct"].notna(), "model"]))
