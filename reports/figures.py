"""matplotlib figures of the report (Agg backend), drawn from stored results only.

- :func:`beam_deflection`: neutral axis of the clamped beam under its weight, MSS and FEM against
  Euler–Bernoulli ([G20] Fig. 5).
- :func:`cross_sections`: middle-layer cross sections, MSS over FEM, for shear (vertical section
  y = W/2, seen along y) and torsion (horizontal layer z = H/2, seen from above) ([G20] Figs 8, 10).
- :func:`volume_change`: e (%) against ν per method with the publication's values (Tables 2, 3).
- :func:`reactions`: shear force and torsion torque against ν per method (Tables 4, 5).
- :func:`differences`: relative L2 nodal difference MSS vs FEM per experiment and ν.
- :func:`generic`: performance, speed-against-error (Pareto) or stability tables, when present.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from . import findings, palette
from .data import Results, mesh_size, paper_table

def mss_methods(results: Results) -> list[str]:
    """The static methods [G20]'s figures draw over the FEM: its model without face diagonals and
    its proposed one."""
    return [f"{m} static" for m in (results.published_model(r) for r in ("no-face-diagonals", "proposed")) if m]


@dataclass
class Figure:
    id: str
    title: str
    path: Path
    caption: str



def _shared_legend(fig, axes, ncol=None, **kw):
    """One legend for a grid of axes: each label once, in order of appearance, in at most ``ncol``
    columns."""
    handles, labels = [], []
    for ax in axes.flat:
        for h, l in zip(*ax.get_legend_handles_labels()):
            if l not in labels:
                handles.append(h)
                labels.append(l)
    fig.legend(handles, labels, ncol=max(1, min(ncol or len(labels), len(labels))), frameon=False, **kw)


def nu_to_log_gap(nu):
    """−log10(½ − ν): the x coordinate of a ν axis, on which 0.45, 0.49, 0.499 and 0.4999 are one
    decade apart (a linear ν axis squeezes them into one point)."""
    return -np.log10(0.5 - np.minimum(np.asarray(nu, dtype=float), 0.5 - 1e-12))


def log_gap_to_nu(x):
    return 0.5 - 10.0 ** (-np.asarray(x, dtype=float))


LABEL_GAP_DECADES = 0.4
"""ν tick labels closer than this on the log(½ − ν) axis overlap: they are turned upright."""


def _nu_axis(ax, nus):
    """The Poisson ratios of the results on a log(½ − ν) x axis, labelled in ν."""
    ax.set_xscale("function", functions=(nu_to_log_gap, log_gap_to_nu))
    nus = sorted(set(float(v) for v in nus))
    ax.set_xlabel("ν (axis: log(½ − ν))")
    ax.set_xticks(nus)
    gaps = np.diff(nu_to_log_gap(nus)) if len(nus) > 1 else np.array([1.0])
    crowded = len(nus) > 4 or bool((gaps < LABEL_GAP_DECADES).any())
    ax.set_xticklabels([f"{v:g}" for v in nus], rotation=90 if crowded else 0, fontsize=7 if crowded else None)
    ax.xaxis.set_minor_locator(__import__("matplotlib").ticker.NullLocator())
    lo, hi = nu_to_log_gap(min(nus)), nu_to_log_gap(max(nus))
    pad = 0.06 * max(hi - lo, 0.5)
    ax.set_xlim(log_gap_to_nu(lo - pad), log_gap_to_nu(hi + pad))


ERROR_FLOOR_PCT = 1e-3
"""Relative errors below this (%) are drawn at it (triangles pointing down): exact cases (10⁻¹³ %)
would otherwise stretch a log axis over ten empty decades."""


def clipped(values, floor: float = ERROR_FLOOR_PCT):
    """(values clipped from below at ``floor``, mask of the clipped ones)."""
    v = np.asarray(values, dtype=float)
    return np.maximum(v, floor), v < floor

def _save(plt, fig, path: Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=150, bbox_inches="tight", pad_inches=0.04)
    plt.close(fig)
    return path


# ----------------------------------------------------------------------------- beam (Fig 5)
def beam_deflection(results: Results, path: Path) -> Figure | None:
    """Centre lines and Euler–Bernoulli as the studies stored them (``bending_curves``,
    ``euler_bernoulli`` tables)."""
    df = results.find("bending")
    curves, theory = results.table("bending_curves"), results.table("euler_bernoulli")
    if df.empty or curves is None:
        return None
    # the runs whose centre lines the studies stored: other studies' beams under gravity (the
    # speed-against-error study's coarse ones) have none and get no panel
    df = df[df["key"].isin(set(curves["key"]))]
    if df.empty:
        return None
    meshes = sorted(df["mesh"].astype(str).unique(), key=mesh_size)
    Es = sorted(df["E"].astype(float).unique(), reverse=True)
    methods = results.method_order(df["method"].unique())
    with palette.style() as plt:
        fig, axes = plt.subplots(len(meshes), len(Es), figsize=(3.4 * len(Es), 2.5 * len(meshes) + 0.4),
                                 squeeze=False, sharex=True)
        for i, mesh in enumerate(meshes):
            for j, E in enumerate(Es):
                ax = axes[i, j]
                sub = df[(df["mesh"] == mesh) & (df["E"] == E)]
                for m in methods:
                    s = sub[sub["method"] == m]
                    c = curves[curves["key"] == s.iloc[0]["key"]] if not s.empty else curves.iloc[:0]
                    if c.empty:
                        continue
                    ax.plot(c["z"], c["u_y"], color=palette.color(m), ls=palette.linestyle(m), marker=palette.marker(m),
                            markevery=max(1, len(c) // 8), label=m.replace(" static", ""))
                eb = theory[(theory["mesh"] == mesh) & (theory["E"] == E)] if theory is not None else None
                if eb is not None and not eb.empty:
                    ax.plot(eb["z"], eb["u_y"], color=palette.COLORS["Euler-Bernoulli"],
                            ls="-.", lw=1.2, label="Euler–Bernoulli")
                ax.set_title(f"mesh {mesh}, E = {E / 1e6:g} MPa")
                if i == len(meshes) - 1:
                    ax.set_xlabel("distance from clamp z (m)")
                if j == 0:
                    ax.set_ylabel("deflection $u_y$ (m)")
        _shared_legend(fig, axes, ncol=5, loc="lower center", bbox_to_anchor=(0.5, 1.0))
        fig.tight_layout()
        _save(plt, fig, path)
    r0 = df.iloc[0]
    return Figure("fig5", "Beam deflection under gravity (Fig. 5)", Path(path),
                  f"Clamped beam 0.4 × 0.4 × 2.4 m, ν = {r0['nu']:g}, ρ = {r0['rho']:g} kg/m³, "
                  f"g = {r0['gravity']:g} m/s², static equilibrium; vertical displacement of the centre line "
                  f"(m) against the distance from the clamped end (m). FEM: Hex2 elements on the same grid.")


# ----------------------------------------------------------------------------- cross sections (Figs 8, 10)
def _layer_grid(X: np.ndarray, P: np.ndarray, axis: int, a: int, b: int):
    """Points P of the layer ``X[:, axis] ≈ middle`` arranged as a 2D grid over axes (a, b)."""
    lev = np.unique(np.round(X[:, axis], 9))
    mid = 0.5 * (lev.min() + lev.max())
    target = lev[np.argmin(np.abs(lev - mid))]
    sel = np.flatnonzero(np.abs(X[:, axis] - target) < 1e-7)
    ua, ub = np.unique(np.round(X[sel, a], 9)), np.unique(np.round(X[sel, b], 9))
    ia = np.searchsorted(ua, np.round(X[sel, a], 9))
    ib = np.searchsorted(ub, np.round(X[sel, b], 9))
    G = np.full((len(ua), len(ub), 2), np.nan)
    G[ia, ib, 0] = P[sel, a]
    G[ia, ib, 1] = P[sel, b]
    return G, float(target)


def _draw_grid(ax, G, **kw):
    label = kw.pop("label", None)
    for k in range(G.shape[0]):
        ax.plot(G[k, :, 0], G[k, :, 1], **kw)
    for k in range(G.shape[1]):
        ax.plot(G[:, k, 0], G[:, k, 1], **kw, label=label if k == 0 else None)


def cross_sections(results: Results, experiment: str, path: Path) -> Figure | None:
    mesh = results.primary_mesh(experiment)
    if mesh is None:
        return None
    df = results.find(experiment, mesh=mesh, study=experiment)
    if df.empty:
        df = results.find(experiment, mesh=mesh)
    if experiment == "torsion":
        loads = [{"angle_deg": v} for v in sorted(df["angle_deg"].astype(float).unique())]
        axis, a, b, names = 2, 0, 1, ("x (m)", "y (m)")
    else:
        loads = [{"deformation": v} for v in sorted(df["deformation"].astype(float).unique())]
        axis, a, b, names = 1, 0, 2, ("x (m)", "z (m)")
    diffs = results.table("differences")
    with palette.style() as plt:
        nus = results.nus(experiment)
        fig, axes = plt.subplots(len(loads), len(nus), figsize=(2.4 * len(nus), 2.55 * len(loads) + 0.5), squeeze=False)
        level = None
        for i, load in enumerate(loads):
            ref = None
            for j, nu in enumerate(nus):
                ax = axes[i, j]
                ref = results.reference(experiment, mesh=mesh, nu=nu, **load)
                txt = []
                if ref is not None:
                    A = results.arrays(ref["key"])
                    G0, level = _layer_grid(A["X"], A["X"], axis, a, b)
                    _draw_grid(ax, G0, color="#c8c8c8", lw=0.7, label="undeformed")
                    G, _ = _layer_grid(A["X"], A["X"] + A["u"], axis, a, b)
                    _draw_grid(ax, G, color=palette.color(ref["solver"]), lw=1.5,
                               label=f"FEM ({ref['solver_law']})")
                for m, ls in zip(mss_methods(results), ("--", ":")):
                    s = results.find(experiment, mesh=mesh, nu=nu, method=m, **load)
                    if s.empty:
                        continue
                    B = results.arrays(s.iloc[0]["key"])
                    if "u" not in B:
                        continue
                    G, level = _layer_grid(B["X"], B["X"] + B["u"], axis, a, b)
                    _draw_grid(ax, G, color=palette.color(m), lw=1.3, ls=ls, label=m.replace(" static", ""))
                    if diffs is not None and "mss_key" in diffs:
                        d = diffs[diffs["mss_key"] == s.iloc[0]["key"]]
                        if not d.empty:
                            txt.append(f"{m.split()[0]}: {1e3 * d.iloc[0]['mid_layer_mean_m']:.3g} mm")
                if txt:
                    ax.text(0.02, 0.02, "mean |Δu|, z = H/2:\n" + "\n".join(txt), transform=ax.transAxes,
                            fontsize=6.5, va="bottom", ha="left",
                            bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="none", alpha=0.8))
                ax.autoscale_view()
                lo, hi = ax.get_ylim()
                ax.set_ylim(lo - 0.38 * (hi - lo), hi)
                ax.set_aspect("equal", adjustable="box")
                lab = f"θ = {load['angle_deg']:g}°" if "angle_deg" in load else f"d = {100 * load['deformation']:g} %"
                ax.set_title(f"ν = {nu:g}, {lab}")
                if i == len(loads) - 1:
                    ax.set_xlabel(names[0])
                if j == 0:
                    ax.set_ylabel(names[1])
        _shared_legend(fig, axes, loc="lower center", ncol=None, bbox_to_anchor=(0.5, 1.0))
        fig.tight_layout()
        _save(plt, fig, path)
    r0 = df.iloc[0]
    where = ("horizontal layer at mid-height z = H/2 seen from above" if experiment == "torsion"
             else "vertical section through the middle (y = W/2) seen along y")
    num, fid = ("10", "fig10") if experiment == "torsion" else ("8", "fig8")
    return Figure(fid, f"{experiment.capitalize()}: middle cross sections, MSS over FEM (Fig. {num})", Path(path),
                  f"{experiment.capitalize()}, mesh {mesh}, E = {r0['E']:g} Pa, static equilibrium; {where}; "
                  f"deformed positions (m), undeformed grid in grey. FEM: linear at ≤ 5 % / ≤ 5°, Neo-Hookean above. "
                  f"Boxes: mean |u_MSS − u_FEM| over the z = H/2 layer (mm), the metric of [G20] §6.")


# ----------------------------------------------------------------------------- Tables 2, 3 as plots
def _methods_in(table: pd.DataFrame) -> list[str]:
    skip = {"mesh", "nu", "deformation", "angle_deg", "E"}
    return [c for c in table.columns if c not in skip and not c.startswith("paper")]


NO_RESULT = "no result (failed or missing: see the table)"


def _mark_no_result(results: Results, ax, t: pd.DataFrame, m: str) -> None:
    """A method's ν without a value: a cross at the foot of the axis, never a borrowed value."""
    gone = t[t[m].isna()]
    # a variant the studies do not compare at a ν (the E-form at ν = 1/4) is not missing there
    gone = gone[[results.in_design(m.rsplit(" ", 1)[0], nu) for nu in gone["nu"]]] if not m.startswith("fem") else gone
    if len(gone) and t[m].notna().any():
        ax.plot(gone["nu"], [0.03] * len(gone), transform=ax.get_xaxis_transform(), ls="none", marker="x", ms=6,
                mew=1.4, color=palette.color(m), label=NO_RESULT, clip_on=False)


def volume_change(results: Results, path: Path) -> Figure | None:
    panels = []
    for exp, name in (("compression", "table2_compression"), ("tension", "table3_tension")):
        t = results.table(name)
        if t is not None:
            mesh = results.primary_mesh(exp)
            t = t[t["mesh"] == mesh] if mesh in set(t["mesh"]) else t
            for d in sorted(t["deformation"].unique()):
                panels.append((exp, mesh, d, t[t["deformation"] == d].sort_values("nu")))
    if not panels:
        return None
    with palette.style() as plt:
        ncol = min(4, len(panels))
        nrow = int(np.ceil(len(panels) / ncol))
        fig, axes = plt.subplots(nrow, ncol, figsize=(max(4.6, 1.85 * ncol + 0.4), 2.5 * nrow + 0.4), squeeze=False)
        for ax in axes.flat[len(panels):]:
            ax.set_visible(False)
        for ax, (exp, mesh, d, t) in zip(axes.flat, panels):
            for m in _methods_in(t):
                if t[m].notna().any():
                    ax.plot(t["nu"], t[m], color=palette.color(m), marker=palette.marker(m), ls=palette.linestyle(m),
                            lw=1.0, label=m.replace(" static", ""))
                _mark_no_result(results, ax, t, m)
            # the publication's columns ("paper <model>", "paper FEM (LS-Dyna)"), in the model's own style
            for m in [c for c in t.columns if c.startswith("paper ")]:
                if t[m].notna().any():
                    base = m[len("paper "):]
                    fem = base.startswith("FEM")
                    ax.plot(t["nu"], t[m], ls="none", marker="h" if fem else palette.marker(base), mfc="none", ms=7,
                            mew=1.1, color=palette.color("fem" if fem else base), label=m.replace("paper", "[G20]"))
            ax.set_title(f"{exp}, d = {100 * d:g} %\nmesh {mesh}")
            _nu_axis(ax, sorted(t["nu"].unique()))
        for r in range(nrow):
            axes[r, 0].set_ylabel("relative volume change e (%)")
        _shared_legend(fig, axes, loc="upper center", ncol=4, bbox_to_anchor=(0.5, 0.0))
        fig.tight_layout()
        _save(plt, fig, path)
    return Figure("fig_e", "Relative volume change against ν (Tables 2, 3)", Path(path),
                  "e = |V′ − V0|/V0 (%) of the static equilibria, E = 10⁴ Pa; filled markers: this "
                  "reproduction; hollow markers: the publication's values ([G20] Tables 2, 3, 10×10×10 cube and "
                  "4×4×24 beam, LS-Dyna FEM). hybmss-cf is ν-blind (always ν = 1/4). A cross at the foot of a panel: "
                  "that method has no result at that ν (failed or missing; Tables 2, 3 give the reason).")


def reactions(results: Results, path: Path) -> Figure | None:
    panels = []
    for exp, name, col, unit, q in (("shear", "table4_shear", "deformation", "N", "reaction force F_x"),
                                    ("torsion", "table5_torsion", "angle_deg", "N·m", "reaction torque T_z")):
        t = results.table(name)
        if t is None:
            continue
        mesh = results.primary_mesh(exp)
        t = t[t["mesh"] == mesh] if mesh in set(t["mesh"]) else t
        for v in sorted(t[col].unique()):
            panels.append((exp, mesh, col, v, unit, q, t[t[col] == v].sort_values("nu")))
    if not panels:
        return None
    with palette.style() as plt:
        ncol = min(4, len(panels))
        nrow = int(np.ceil(len(panels) / ncol))
        fig, axes = plt.subplots(nrow, ncol, figsize=(1.85 * ncol + 0.5, 2.5 * nrow + 0.4), squeeze=False)
        for ax in axes.flat[len(panels):]:
            ax.set_visible(False)
        for ax, (exp, mesh, col, v, unit, q, t) in zip(axes.flat, panels):
            law = results.reference_law(exp, v if col == "deformation" else 0.0, v if col == "angle_deg" else 0.0)
            for m in _methods_in(t):
                if m.startswith("fem") and law != "linear" and m.endswith("linear"):
                    continue  # small-strain FEM is no reference at large load
                if t[m].notna().any():
                    ax.plot(t["nu"], t[m], color=palette.color(m), marker=palette.marker(m), ls=palette.linestyle(m),
                            lw=1.0, label=m.replace(" static", ""))
                _mark_no_result(results, ax, t, m)
            lab = f"θ = {v:g}°" if col == "angle_deg" else f"d = {100 * v:g} %"
            ax.set_title(f"{exp}, {lab}\nmesh {mesh}")
            _nu_axis(ax, sorted(t["nu"].unique()))
            ax.set_ylabel(f"{q} ({unit})")
            ax.ticklabel_format(axis="y", style="sci", scilimits=(-3, 4))
        _shared_legend(fig, axes, loc="upper center", ncol=4, bbox_to_anchor=(0.5, 0.0))
        fig.tight_layout()
        _save(plt, fig, path)
    return Figure("fig_reactions", "Top-plate reactions against ν (Tables 4, 5)", Path(path),
                  "Shear: reaction force F_x (N) on the top plate; torsion: reaction torque T_z (N·m) about the "
                  "vertical axis; E = 10⁴ Pa, static equilibria. FEM at 5 % / 1° is linear (small strain); at 20 % / 45° the "
                  "finite-strain laws (Neo-Hookean, SVK) are shown and linear FEM is left out (see Tables 4, 5). A cross "
                  "at the foot of a panel: that method has no result at that ν (failed or missing; the tables give "
                  "the reason).")


def differences(results: Results, path: Path) -> Figure | None:
    t = results.table("differences")
    if t is None or "rel_l2" not in t:
        return None
    exps = [e for e in ("compression", "tension", "shear", "torsion") if e in set(t["experiment"])]
    if not exps:
        return None
    t = t[t["method"].str.endswith("static")]  # explicit runs: see the explicit-protocol table
    with palette.style() as plt:
        fig, axes = plt.subplots(1, len(exps), figsize=(max(4.6, 1.85 * len(exps) + 0.5), 2.6), squeeze=False,
                                 sharey=True)
        for ax, exp in zip(axes[0], exps):
            sub = t[t["experiment"] == exp].copy()
            mesh = results.primary_mesh(exp)
            if mesh in set(sub["mesh"]):
                sub = sub[sub["mesh"] == mesh]
            loadcol = "angle_deg" if exp == "torsion" else "deformation"
            loads = sorted(sub[loadcol].unique())
            for m in sorted(sub["method"].unique()):
                for v, ls in zip(loads, ("-", "--", ":", "-.")):
                    s = sub[(sub["method"] == m) & (sub[loadcol] == v)].sort_values("nu")
                    if s.empty:
                        continue
                    lab = f"θ={v:g}°" if loadcol == "angle_deg" else f"d={100 * v:g}%"
                    y, low = clipped(100 * s["rel_l2"])
                    ax.plot(s["nu"], y, color=palette.color(m), marker=palette.marker(m), ls=ls,
                            lw=1.0, label=f"{m.replace(' static', '')}, {lab}")
                    if low.any():
                        ax.plot(s["nu"][low], y[low], ls="none", marker="v", ms=6, color=palette.color(m))
            ax.set_yscale("log")
            ax.set_ylim(bottom=0.5 * ERROR_FLOOR_PCT)
            ax.set_title(f"{exp}, mesh {mesh}")
            _nu_axis(ax, sorted(sub["nu"].unique()))
        axes[0, 0].set_ylabel("‖u_MSS − u_FEM‖ / ‖u_FEM‖ (%)")
        from matplotlib.lines import Line2D

        methods = sorted(t["method"].unique())
        handles = [Line2D([], [], color=palette.color(m), marker=palette.marker(m), lw=1.0,
                          label=m.replace(" static", "")) for m in methods]
        handles += [Line2D([], [], color="k", ls="-", lw=1.0, label="small load (5 %, 1°)"),
                    Line2D([], [], color="k", ls="--", lw=1.0, label="large load (20 %, 45°)")]
        fig.legend(handles=handles, loc="upper center", ncol=3, frameon=False, bbox_to_anchor=(0.5, 0.0))
        fig.tight_layout()
        _save(plt, fig, path)
    return Figure("fig_diff", "Nodal displacement difference MSS vs FEM", Path(path),
                  "Relative L2 difference of the nodal displacements (%) of each MSS static equilibrium against its "
                  "FEM reference on the same grid (linear at ≤ 5 % / ≤ 5°, Neo-Hookean above); solid: small load, "
                  f"dashed: large load; E = 10 kPa. Differences below {ERROR_FLOOR_PCT:g} % (exact cases) are drawn at "
                  f"{ERROR_FLOOR_PCT:g} % as downward triangles. ν on a log(½ − ν) axis.")


def torsion_sweep(results: Results, path: Path) -> Figure | None:
    """Torque against angle at ν = 1/4 (study ``torsion-sweep`` with the table's angles)."""
    df = results.ok()
    if df.empty or "study" not in df or not (df["study"] == "torsion-sweep").any():
        return None
    sweep = df[df["study"] == "torsion-sweep"]
    mesh = sweep["mesh"].iloc[0]
    nu = float(sweep["nu"].iloc[0])
    sub = df[(df["experiment"] == "torsion") & (df["mesh"] == mesh) & (df["nu"] == nu)]
    with palette.style() as plt:
        fig, ax = plt.subplots(figsize=(4.6, 3.0))
        for m in sorted(sub["method"].unique(), key=lambda m: (m.startswith("fem"), m)):
            s = sub[sub["method"] == m].sort_values("angle_deg")
            if m.startswith("fem") and m.endswith("linear"):
                s = s[s["angle_deg"] <= 10.0]  # small-strain FEM only where it is a reference
            if s.empty:
                continue
            ax.plot(s["angle_deg"], s["torque_z"], color=palette.color(m), marker=palette.marker(m),
                    ls=palette.linestyle(m), label=m.replace(" static", ""))
        ax.set_xlabel("rotation of the top plate θ (°)")
        ax.set_ylabel("reaction torque $T_z$ (N·m)")
        ax.legend(frameon=False, fontsize=7.5)
        fig.tight_layout()
        _save(plt, fig, path)
    return Figure("fig_torsion_sweep", f"Torsion: torque against angle (ν = {nu:g})", Path(path),
                  f"Torsion of the 5 m cube, mesh {mesh}, E = {sub['E'].iloc[0]:g} Pa, ν = {nu:g}, static "
                  "equilibria: top-plate torque T_z (N·m) against the rotation θ (°). Linear FEM shown up to 10° only.")


# ----------------------------------------------------------------------------- optional studies
_X_PREF = ("volumes", "n_volumes", "cells", "n_cells", "particles", "n_particles", "vertices", "nu", "dt",
           "angle_deg", "steps")
_GROUP_PREF = ("variant", "model", "method", "solver", "kernel", "model")


def _numeric(df: pd.DataFrame) -> list[str]:
    return [c for c in df.columns if pd.api.types.is_numeric_dtype(df[c]) and df[c].notna().any()]


def generic(name: str, df: pd.DataFrame, path: Path) -> Figure | None:
    """A plot of a study table whose columns are not fixed in advance (performance, Pareto,
    stability): x is a size (volumes, cells, …) or a time for a Pareto table, y are time or error
    columns, one line per model; logarithmic axes where the values span over a decade."""
    num = _numeric(df)
    if len(num) < 2:
        return None
    group = next((g for g in _GROUP_PREF if g in df.columns and not pd.api.types.is_numeric_dtype(df[g])), None)
    is_pareto = "pareto" in name
    if is_pareto:
        x = next((c for c in num if "time" in c or c.endswith("_s")), None)
        ys = [c for c in num if c != x and ("err" in c or "l2" in c or "diff" in c)][:1]
    else:
        x = next((c for c in _X_PREF if c in num), None)
        ys = [c for c in num if c != x and ("time" in c or c.endswith("_s") or "dt" in c or "speed" in c)][:3]
        if not ys:
            ys = [c for c in num if c != x][:2]
    if x is None or not ys:
        return None
    with palette.style() as plt:
        fig, axes = plt.subplots(1, len(ys), figsize=(3.4 * len(ys) + 0.3, 2.7), squeeze=False)
        for ax, y in zip(axes[0], ys):
            groups = df.groupby(group) if group else [("all", df)]
            for gname, g in groups:
                g = g.dropna(subset=[x, y]).sort_values(x)
                if g.empty:
                    continue
                kw = dict(color=palette.color(str(gname)), marker=palette.marker(str(gname)), label=str(gname))
                if is_pareto:
                    ax.plot(g[x], g[y], ls="none", alpha=0.35, color=kw["color"], marker=kw["marker"])
                    front = g.sort_values([x, y])
                    front = front[front[y] <= front[y].cummin()]
                    ax.step(front[x], front[y], where="post", lw=1.2, **kw)
                else:
                    ax.plot(g[x], g[y], ls="-", lw=1.1, **kw)
            for col, setter in ((x, ax.set_xscale), (y, ax.set_yscale)):
                v = df[col].dropna()
                v = v[v > 0]
                if len(v) > 1 and v.max() / v.min() > 20:
                    setter("log")
            ax.set_xlabel(_unit_label(x))
            ax.set_ylabel(_unit_label(y))
        handles, labels = axes[0, 0].get_legend_handles_labels()
        if labels:
            fig.legend(handles, labels, loc="upper center", ncol=min(5, len(labels)), frameon=False,
                       bbox_to_anchor=(0.5, 0.0))
        fig.tight_layout()
        _save(plt, fig, path)
    what = "Pareto fronts (lines: non-dominated runs)" if is_pareto else f"{', '.join(ys)} against {x}"
    return Figure(f"fig_{name}", f"{name.replace('_', ' ').capitalize()}", Path(path),
                  f"From tables/{name}.csv: {what}; one colour per model (the report's palette).")


def _unit_label(col: str) -> str:
    c = col.lower()
    for suffix, unit in (("_pct", "%"), ("_ms", "ms"), ("_s", "s"), ("_m", "m")):
        if c.endswith(suffix):
            return f"{col[: -len(suffix)].replace('_', ' ')} ({unit})"
    if c == "nu":
        return "ν"
    if "rel" in c or c in ("volumes", "cells", "vertices", "particles", "steps", "n_cells", "n_volumes"):
        return f"{col.replace('_', ' ')} (–)"
    return col.replace("_", " ")


def performance(df: pd.DataFrame, path: Path) -> Figure | None:
    """[G20] Figs 11, 12: time per explicit step against the number of volumes, per variant and ν."""
    tcol = next((c for c in ("best_s", "median_s", "wall_time_s", "time_s") if c in df), None)
    if tcol is None or "volumes" not in df or "variant" not in df:
        return generic("performance", df, path)
    df = df.copy()
    steps = df["steps"] if "steps" in df else 1000
    df["per_step_ms"] = 1e3 * df[tcol] / steps
    scenes = list(df["scene"].unique()) if "scene" in df else [None]
    threads = sorted(df["threads"].unique()) if "threads" in df else [None]
    with palette.style() as plt:
        fig, axes = plt.subplots(1, len(scenes), figsize=(3.5 * len(scenes) + 0.4, 2.9), squeeze=False)
        for ax, scene in zip(axes[0], scenes):
            sub = df if scene is None else df[df["scene"] == scene]
            keys = ["variant"] + (["nu"] if "nu" in sub else [])
            for key, g in sub.groupby(keys):
                key = key if isinstance(key, tuple) else (key,)
                var = str(key[0])
                lab = var + (f", ν = {key[1]:g}" if len(key) > 1 else "")
                for th, ls in zip(threads, ("-", "--", ":", "-.")):
                    gg = g if th is None else g[g["threads"] == th]
                    gg = gg.sort_values("volumes")
                    if gg.empty:
                        continue
                    quarter = len(key) > 1 and abs(key[1] - 0.25) < 1e-9
                    ax.plot(gg["volumes"], gg["per_step_ms"], color=palette.color(var), ls=ls,
                            marker="o" if quarter else palette.marker(var), mfc="white" if quarter else None,
                            label=lab + (f", {th} thread{'s' if th != 1 else ''}" if th is not None and len(threads) > 1 else ""))
            if "paper_per_10k_steps_s" in sub:
                p = sub.dropna(subset=["paper_per_10k_steps_s"]).drop_duplicates("paper_per_10k_steps_s")
                for _, r in p.iterrows():
                    ax.plot(r["volumes"], 1e3 * r["paper_per_10k_steps_s"] / 1e4, ls="none", marker="*", ms=9,
                            color=palette.COLORS["paper"], label="[G20] (C++, 1 thread)")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("number of volumes (cells)")
            ax.set_ylabel("time per step (ms)")
            if scene is not None:
                ax.set_title(str(scene))
        _shared_legend(fig, axes, loc="upper center", ncol=3, bbox_to_anchor=(0.5, 0.0), fontsize=7)
        fig.tight_layout()
        _save(plt, fig, path)
    return Figure("fig_performance", "Time per explicit step against the number of volumes (Figs 11, 12)", Path(path),
                  f"From tables/performance.csv: {tcol} of the timed runs divided by the step count, in ms per step "
                  "(numba stencil kernel; solid 1 thread, dashed 2 threads). Hollow circles: hybmss at ν = 1/4 "
                  "(κ = 0, no volume term). Stars: the publication's time per step (10,000 steps of the 10³ cube).")


def pareto(df: pd.DataFrame, path: Path) -> Figure | None:
    """Speed against error: every candidate (time, nodal error) per configuration, front as a step line."""
    if not {"time_s", "error_u"} <= set(df.columns):
        return generic("pareto", df, path)
    if "role" in df:
        df = df[df["role"] == "candidate"] if (df["role"] == "candidate").any() else df
    failed = no_result_count(df)
    if "at_rest" in df:  # a run that reached no result is no point, whatever a column holds
        df = df[df["at_rest"].astype(str).str.lower().isin(("true", "1", "1.0"))]
    df = df.dropna(subset=["time_s", "error_u"])
    df = df[(df["time_s"] > 0) & (df["error_u"] > 0)]
    if df.empty:
        return None
    from matplotlib.ticker import NullFormatter

    configs = list(dict.fromkeys(df["config"])) if "config" in df else [None]
    shown = configs[:12]
    ncol = min(4, len(shown))
    nrow = int(np.ceil(len(shown) / ncol))
    with palette.style() as plt:
        fig, axes = plt.subplots(nrow, ncol, figsize=(2.1 * ncol + 0.5, 2.05 * nrow + 0.5), squeeze=False)
        for ax in axes.flat[len(shown):]:
            ax.set_visible(False)
        for ax, cfg in zip(axes.flat, shown):
            sub = df if cfg is None else df[df["config"] == cfg]
            for var, g in sub.groupby("variant" if "variant" in sub else (lambda i: "all")):
                fam = "fem-linear" if str(var) == "fem" else str(var)
                ax.plot(g["time_s"], g["error_u"], ls="none", color=palette.color(fam), marker=palette.marker(fam),
                        alpha=0.8, label=str(var))
            front = sub[sub["pareto"].astype(bool)] if "pareto" in sub else sub
            front = front.sort_values("time_s")
            front = front[front["error_u"] <= front["error_u"].cummin()]
            ax.step(front["time_s"], front["error_u"], where="post", color="k", lw=0.9, label="Pareto front")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_title(str(cfg) if cfg is not None else "", fontsize=7.5)
            ax.tick_params(labelsize=6.5)
            ax.yaxis.set_minor_formatter(NullFormatter())
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.set_xlabel("wall time (s)", fontsize=7.5)
        for r in range(nrow):
            axes[r, 0].set_ylabel("nodal error (rel. L2)")
        _shared_legend(fig, axes, loc="upper center", ncol=5, bbox_to_anchor=(0.5, 0.0))
        fig.tight_layout()
        _save(plt, fig, path)
    more = f" (first {len(shown)} of {len(configs)} configurations; all in the table)" if len(configs) > len(shown) else ""
    return Figure("fig_pareto", "Speed against error: Pareto fronts", Path(path),
                  "From tables/pareto.csv: wall time (s) and relative L2 nodal error against the converged reference "
                  f"of every candidate (MSS solvers and FEM meshes), one panel per configuration{more}; black step "
                  "line: the non-dominated candidates." + no_result_note(failed))


def no_result_count(df: pd.DataFrame | None) -> tuple[int, int]:
    """(candidates that reached no result, candidates) of the pareto table: ``at_rest`` False (an
    explicit run not at rest, a static solve not converged, a failed run; column ``failure``)."""
    if df is None or df.empty or "at_rest" not in df:
        return 0, 0 if df is None else len(df)
    if "role" in df and (df["role"] == "candidate").any():
        df = df[df["role"] == "candidate"]
    ok = df["at_rest"].astype(str).str.lower().isin(("true", "1", "1.0"))
    return int((~ok).sum()), len(df)


def no_result_note(counts: tuple[int, int]) -> str:
    n, total = counts
    if not n:
        return ""
    return (f" {n} of {total} candidate runs reached no result (an explicit run not at rest, a static solve "
            "not converged, or a failed run: tables/pareto.csv, columns at_rest and failure); they are no "
            "point here and win no budget.")


def stable_label(g: pd.DataFrame) -> str:
    """What a variant's dt_stable bars are: the bisected limit, or (notes "no stability limit") the
    step of one stable run, a lower bound."""
    notes = g["note"].fillna("").astype(str) if "note" in g else pd.Series([], dtype=str)
    if len(notes) and notes.str.startswith("no stability limit").all():
        return "stable at 20 dt_crit (no limit)"
    return "largest stable dt"


def dt_stability(df: pd.DataFrame, path: Path) -> Figure | None:
    if not {"nu", "variant", "dt_crit"} <= set(df.columns):
        return generic("dt_stability", df, path)
    with palette.style() as plt:
        fig, ax = plt.subplots(figsize=(4.8, 3.0))
        for var, g in df.groupby("variant"):
            g = g.sort_values("nu")
            ax.plot(g["nu"], g["dt_crit"], color=palette.color(var), marker=palette.marker(var), label=f"{var}: dt_crit")
            if "dt_stable" in g:
                ax.plot(g["nu"], g["dt_stable"], color=palette.color(var), ls="none", marker="_", ms=12, mew=2,
                        label=f"{var}: {stable_label(g)}")
        ax.set_yscale("log")
        _nu_axis(ax, df["nu"].unique())
        ax.set_ylabel("time step (s)")
        ax.legend(frameon=False, fontsize=6.5, ncol=1, loc="center left", bbox_to_anchor=(1.0, 0.5))
        fig.tight_layout()
        _save(plt, fig, path)
    return Figure("fig_dt_stability", "Explicit stability limit against ν", Path(path),
                  "From tables/dt_stability.csv: dt_crit = 2/√λmax(M⁻¹K) (s, lines) and the largest dt that runs the "
                  "compression scene without divergence, found by bisection (s, bars), per variant; a model with "
                  "no explicit limit (xpbd-nh) shows the step of its one stable run at 20 dt_crit, a lower bound.")


STATE_COLORS = {"converged": "#4daf4a", "unstable": "#ff7f00", "diverged": "#e41a1c", "inverted": "#984ea3",
                "missing": "#d9d9d9"}


def budget_chart(results: Results, path: Path, kind: str = "static") -> Figure | None:
    """The budget answer of one cost (``static``: time to an equilibrium; ``explicit``: per simulated
    second), a figure each so that each fills a page: one panel per error measure (force, volume,
    field); in a panel, configurations down and budgets across, each cell the winner's marker in its
    model's colour (hollow: a tie; grey dot: no method meets the budget) and its lead over the
    runner-up."""
    ans = findings.budget_answers(results.table("budget"))
    if ans.empty or kind not in set(ans["cost_kind"]):
        return None
    configs = list(dict.fromkeys(ans["config"]))
    budgets = sorted(ans["budget"].astype(float).unique())
    kinds = [kind]
    measures = [m for m in findings.MEASURE_NAMES if m in set(ans["measure"])]
    short = {"force": "force", "volume": "volume change", "field": "field (nodal L2)"}
    kind_title = {"static": "time to equilibrium", "explicit": "per simulated s, explicit"}
    with palette.style() as plt:
        fig, axes = plt.subplots(len(kinds), len(measures), squeeze=False, sharey=True,
                                 figsize=(2.35 * len(measures) + 1.6, (0.17 * len(configs) + 0.7) * len(kinds) + 0.9))
        seen = {}
        for i, kind in enumerate(kinds):
            for j, m in enumerate(measures):
                ax = axes[i, j]
                sub = ans[(ans["cost_kind"] == kind) & (ans["measure"] == m)]
                for r in sub.itertuples():
                    y = configs.index(r.config)
                    x = budgets.index(float(r.budget))
                    if r.method == "none":
                        ax.plot(x, y, ls="none", marker=".", color="#bbbbbb", ms=3)
                        continue
                    model = findings.method_model(r.method)
                    if model.startswith("FEM"):  # the palette's FEM styles are by law: one entry per law
                        law = str(r.method).split("-", 2)[-1]
                        model = f"FEM, {law} law (the table names the element)"
                    tie = findings._is_tie(r.tie)
                    c = palette.color(r.method)
                    h, = ax.plot(x - 0.18, y, ls="none", marker=palette.marker(r.method), ms=5.5, mec=c,
                                 mfc="white" if tie else c, mew=1.0)
                    seen.setdefault(model, (c, palette.marker(r.method)))
                    lead = "" if pd.isna(r.lead) else ("tie" if tie else f"×{r.lead:.2g}" + ("?" if tie is None else ""))
                    ax.text(x + 0.02, y, lead, fontsize=5.5, va="center", ha="left")
                ax.set_xlim(-0.5, len(budgets) - 0.3)
                ax.set_ylim(len(configs) - 0.5, -0.5)
                ax.set_xticks(range(len(budgets)))
                ax.set_xticklabels([f"≤ {100 * b:g} %" for b in budgets], fontsize=7)
                ax.set_yticks(range(len(configs)))
                ax.set_yticklabels(configs, fontsize=6)
                ax.grid(True, axis="y", alpha=0.25)
                ax.grid(False, axis="x")
                ax.set_title(f"{short[m]} error\n{kind_title.get(kind, kind)}", fontsize=7.5)
        handles = [plt.Line2D([], [], ls="none", marker=mk, color=c, label=name) for name, (c, mk) in seen.items()]
        handles += [plt.Line2D([], [], ls="none", marker="o", mfc="white", mec="k", label="hollow: tie (lead < 1 + spread)"),
                    plt.Line2D([], [], ls="none", marker=".", color="#bbbbbb", label="no method meets the budget")]
        fig.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=4, frameon=False, fontsize=7)
        fig.tight_layout()
        _save(plt, fig, path)
    cost_text = {"static": "wall time to an equilibrium (static, implicit and FEM solves, engines' runs to rest)",
                 "explicit": "wall time per simulated second at half the explicit limit dt_crit (explicit runs)"}
    return Figure("study_budget" + ("" if kind == "static" else f"_{kind}"),
                  f"Which method for which error budget: {kind_title.get(kind, kind)}", Path(path),
                  "From tables/budget.csv (the pareto study): for each configuration (rows), error budget (columns "
                  "of a panel) and error measure against the converged reference (panels: plate force or "
                  "torque, the beam's tip deflection; volume change in units of the imposed strain; relative L2 "
                  f"of the nodal displacement), at the cost {cost_text.get(kind, kind)}: the fastest method within the budget "
                  "(marker and colour of its model; the table names its solver and mesh) and its lead = cost of "
                  "the next fastest other method / its cost. Hollow marker, 'tie': the lead is smaller than "
                  "1 + the larger timing spread (median over best of the repeats; only candidates whose lead is "
                  "within the assumed timing noise are repeated, and a lead beyond it is no tie)."
                  + no_result_note(no_result_count(results.table("pareto"))))


def stability_map(results: Results, path: Path) -> Figure | None:
    """One panel per model: ν × load, each cell coloured by the run's outcome (static, explicit)."""
    g = findings.stability_grid(results.table("stability_extreme"))
    if g.empty:
        return None
    variants = list(dict.fromkeys(g["variant"]))
    loads = [(c, s) for c in dict.fromkeys(g["case"]) for s in sorted(g.loc[g["case"] == c, "solver"].unique())]
    nus = sorted(g["nu"].unique())
    with palette.style() as plt:
        fig, axes = plt.subplots(1, len(variants), figsize=(2.0 * len(variants) + 1.6, 0.32 * len(loads) + 1.3),
                                 squeeze=False, sharey=True)
        for ax, var in zip(axes[0], variants):
            sub = g[g["variant"] == var]
            for i, (case, solver) in enumerate(loads):
                for j, nu in enumerate(nus):
                    m = sub[(sub["case"] == case) & (sub["solver"] == solver) & (sub["nu"] == nu)]
                    st = m["outcome"].iloc[0] if len(m) else "missing"
                    ax.add_patch(plt.Rectangle((j, i), 0.95, 0.9, color=STATE_COLORS[st], lw=0))
            ax.set_xlim(0, len(nus))
            ax.set_ylim(len(loads), 0)
            ax.set_xticks([j + 0.47 for j in range(len(nus))])
            ax.set_xticklabels([f"{v:g}" for v in nus])
            ax.set_xlabel("ν")
            ax.set_title(var)
            ax.grid(False)
            ax.tick_params(length=0)
            for sp in ax.spines.values():
                sp.set_visible(False)
        axes[0, 0].set_yticks([i + 0.45 for i in range(len(loads))])
        axes[0, 0].set_yticklabels([f"{c}, {s}" for c, s in loads], fontsize=7)
        handles = [plt.Rectangle((0, 0), 1, 1, color=STATE_COLORS[k]) for k in findings.STATES]
        fig.legend(handles, findings.STATES, ncol=len(handles), frameon=False, loc="upper center",
                   bbox_to_anchor=(0.5, 0.0), fontsize=7)
        fig.tight_layout()
        _save(plt, fig, path)
    return Figure("study_stability_map", "Stability map per model", Path(path),
                  "From tables/stability_extreme.csv: each run of the extreme-load study by model (panels), load and "
                  "solver (rows) and ν (columns), coloured by outcome: converged; unstable (static equilibrium lost "
                  "at a limit point); diverged (explicit integration blew up); inverted (a cell's volume turned "
                  "negative); missing (not run).")


def limit_stretch(results: Results, path: Path) -> Figure | None:
    t = results.table("limit_stretch")
    if t is None or not {"nu", "variant", "stretch_lo", "status"} <= set(t.columns):
        return None
    with palette.style() as plt:
        fig, ax = plt.subplots(figsize=(4.8, 2.9))
        energies = list(dict.fromkeys(t["volume_energy"])) if "volume_energy" in t else [None]
        for (var, en), g in t.groupby(["variant", "volume_energy"] if "volume_energy" in t else ["variant", "variant"]):
            g = g.sort_values("nu")
            ls = "-" if en == energies[0] else ":"
            has_volume = bool(g["volume_term"].astype(str).str.lower().eq("true").any()) if "volume_term" in g else True
            lab = var + (f", {en} volume energy" if "volume_energy" in t and has_volume else "")
            held = g["status"] == "ok"
            ax.plot(g["nu"], g["stretch_lo"], color=palette.color(var), marker=palette.marker(var), ls=ls, label=lab)
            if held.any():
                ax.plot(g.loc[held, "nu"], g.loc[held, "stretch_lo"], ls="none", marker="^", ms=8,
                        color=palette.color(var), mfc="white")
        _nu_axis(ax, t["nu"].unique())
        ax.set_ylabel("stretch L/L0 at loss of equilibrium")
        ax.legend(frameon=False, fontsize=6.5, loc="center left", bbox_to_anchor=(1.0, 0.5))
        fig.tight_layout()
        _save(plt, fig, path)
    return Figure("study_limit_stretch", "Limit stretch against ν", Path(path),
                  "From tables/limit_stretch.csv: tension of the beam to 100 %, static solver with load stepping; the "
                  "last stretch L/L0 at which the equilibrium exists, per model and volume energy. Hollow triangles: "
                  "the equilibrium held up to the largest stretch tried (a lower bound).")


def damping(results: Results, path: Path) -> Figure | None:
    c = findings.damping_curves(results.table("damping_steps"))
    if c.empty:
        return None
    with palette.style() as plt:
        fig, ax = plt.subplots(figsize=(4.2, 2.7))
        for nu, g in c.groupby("nu"):
            ax.plot(g["steps"], 100 * g["error"], marker="o", label=f"ν = {nu:g}")
        t = results.table("damping_steps")
        if "tol" in t:
            ax.axhline(100 * float(t["tol"].iloc[0]), color="k", lw=0.8, ls="--", label="tolerance")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("explicit steps (dt = 1 ms)")
        ax.set_ylabel("‖u − u_static‖ / ‖u_static‖ (%)")
        ax.legend(frameon=False, fontsize=7)
        fig.tight_layout()
        _save(plt, fig, path)
    return Figure("study_damping", "Explicit protocol: distance to the static equilibrium against steps", Path(path),
                  "From tables/damping_steps.csv: relative L2 difference (%) of the explicit state (semi-implicit "
                  "Euler, mass-proportional damping) from the static equilibrium of the same scene after n steps, "
                  "measured at every checkpoint whether or not the run had come to rest.")


def b09_errors(results: Results, path: Path) -> Figure | None:
    df = findings.b09_frame(results.table("baudet_cantilever"), results.table("baudet_lshape"),
                            paper_table("b09_errors"))
    if df.empty:
        return None
    exps = list(dict.fromkeys(df["experiment"]))
    with palette.style() as plt:
        fig, axes = plt.subplots(1, len(exps), figsize=(3.4 * len(exps) + 0.6, 2.8), squeeze=False)
        for ax, exp in zip(axes[0], exps):
            g = df[df["experiment"] == exp]
            for model, m in g[g["state"] == "ok"].groupby("model", sort=False):
                m = m.sort_values("cells")
                ax.plot(m["cells"], m["err_mean_pct"], color=palette.color(model), marker=palette.marker(model),
                        label=f"{model} (ours, mean)")
            p = paper_table("b09_errors")
            if p is not None:
                p = p[p["experiment"] == exp]
                cells = [int(np.prod([int(v) for v in str(ms).split("x")])) for ms in p["mesh"]]
                if exp == "lshape":  # the L occupies 3/4 of its bounding grid
                    cells = [3 * c // 4 for c in cells]
                ax.plot(cells, p["mean_pct"], ls="none", marker="*", ms=9, color=palette.COLORS["paper"],
                        label="[B09] baudet2009, mean")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("cells")
            ax.set_ylabel("mean nodal error (%)")
            ax.set_title(findings.EXPERIMENT_NAMES.get(exp, exp))
        _shared_legend(fig, axes, loc="upper center", ncol=3, bbox_to_anchor=(0.5, 0.0), fontsize=7)
        fig.tight_layout()
        _save(plt, fig, path)
    return Figure("study_b09", "[B09]'s experiments: mean nodal error against the number of cells", Path(path),
                  "From tables/baudet_cantilever.csv and baudet_lshape.csv: mean over the particles of |u_MSS − u_FEM| "
                  "/ max|u_FEM| (%) per model against a Hex2 reference, at [B09]'s stated parameters; stars: "
                  "[B09]'s printed means for its own model.")


STUDY_PLOTS = {"performance": performance, "pareto": pareto, "dt_stability": dt_stability}
"""Plots of one stored study table each (table name -> function of the table)."""

def budget_chart_explicit(results: Results, path: Path) -> Figure | None:
    """:func:`budget_chart` of the explicit cost (per simulated second at ½ dt_crit)."""
    return budget_chart(results, path, kind="explicit")


STUDY_FIGURES = {"budget": budget_chart, "budget_explicit": budget_chart_explicit, "stability_map": stability_map, "limit_stretch": limit_stretch,
                 "damping": damping, "b09": b09_errors}
"""Figures of the study sections that read several tables (id -> function of the results)."""


def all_figures(results: Results, out_dir: Path, warnings: list | None = None) -> dict[str, Figure]:
    """Every figure the results allow; a figure that fails is reported in ``warnings``, not raised."""
    out_dir = Path(out_dir)
    figs = {}
    jobs = [(volume_change, (results, out_dir / "volume_change.png")),
            (reactions, (results, out_dir / "reactions.png")),
            (torsion_sweep, (results, out_dir / "torsion_sweep.png")),
            (differences, (results, out_dir / "differences.png")),
            (beam_deflection, (results, out_dir / "fig5_beam.png")),
            (cross_sections, (results, "shear", out_dir / "fig8_shear_sections.png")),
            (cross_sections, (results, "torsion", out_dir / "fig10_torsion_sections.png"))]
    jobs += [(fn, (results, out_dir / f"study_{name}.png")) for name, fn in STUDY_FIGURES.items()]
    for fn, args in jobs:
        try:
            f = fn(*args)
        except Exception as exc:  # noqa: BLE001 - one broken figure must not hide the others
            if warnings is None:
                raise
            warnings.append(f"figure {Path(args[-1]).name} not drawn: {type(exc).__name__}: {exc}")
            continue
        if f is not None:
            figs[f.id] = f
    return figs
