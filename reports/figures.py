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

from pathlib import Path

import numpy as np
import pandas as pd

from . import palette
from .data import Results, mesh_size
from .plots import ERROR_FLOOR_PCT, Figure, clipped, nu_axis, save_figure, shared_legend
from .study_figures import STUDY_FIGURES

def mss_methods(results: Results) -> list[str]:
    """The static methods [G20]'s figures draw over the FEM: its model without face diagonals and
    its proposed one."""
    return [f"{m} static" for m in (results.published_model(r) for r in ("no-face-diagonals", "proposed")) if m]


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
        shared_legend(fig, axes, ncol=5, loc="lower center", bbox_to_anchor=(0.5, 1.0))
        fig.tight_layout()
        save_figure(plt, fig, path)
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
        shared_legend(fig, axes, loc="lower center", ncol=None, bbox_to_anchor=(0.5, 1.0))
        fig.tight_layout()
        save_figure(plt, fig, path)
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
    gone = gone[[results.in_design(results.variant(m), nu) for nu in gone["nu"]]] if not results.is_fem(m) else gone
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
            nu_axis(ax, sorted(t["nu"].unique()))
        for r in range(nrow):
            axes[r, 0].set_ylabel("relative volume change e (%)")
        shared_legend(fig, axes, loc="upper center", ncol=4, bbox_to_anchor=(0.5, 0.0))
        fig.tight_layout()
        save_figure(plt, fig, path)
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
                if law != "linear" and results.fem_with_law([m], "linear"):
                    continue  # small-strain FEM is no reference at large load
                if t[m].notna().any():
                    ax.plot(t["nu"], t[m], color=palette.color(m), marker=palette.marker(m), ls=palette.linestyle(m),
                            lw=1.0, label=m.replace(" static", ""))
                _mark_no_result(results, ax, t, m)
            lab = f"θ = {v:g}°" if col == "angle_deg" else f"d = {100 * v:g} %"
            ax.set_title(f"{exp}, {lab}\nmesh {mesh}")
            nu_axis(ax, sorted(t["nu"].unique()))
            ax.set_ylabel(f"{q} ({unit})")
            ax.ticklabel_format(axis="y", style="sci", scilimits=(-3, 4))
        shared_legend(fig, axes, loc="upper center", ncol=4, bbox_to_anchor=(0.5, 0.0))
        fig.tight_layout()
        save_figure(plt, fig, path)
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
    t = t[[results.method(m)["solver_kind"] == "static" for m in t["method"]]]  # explicit runs: see the explicit-protocol table
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
            nu_axis(ax, sorted(sub["nu"].unique()))
        axes[0, 0].set_ylabel("‖u_MSS − u_FEM‖ / ‖u_FEM‖ (%)")
        from matplotlib.lines import Line2D

        methods = sorted(t["method"].unique())
        handles = [Line2D([], [], color=palette.color(m), marker=palette.marker(m), lw=1.0,
                          label=m.replace(" static", "")) for m in methods]
        handles += [Line2D([], [], color="k", ls="-", lw=1.0, label="small load (5 %, 1°)"),
                    Line2D([], [], color="k", ls="--", lw=1.0, label="large load (20 %, 45°)")]
        fig.legend(handles=handles, loc="upper center", ncol=3, frameon=False, bbox_to_anchor=(0.5, 0.0))
        fig.tight_layout()
        save_figure(plt, fig, path)
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
        for m in sorted(sub["method"].unique(), key=lambda m: (results.is_fem(m), m)):
            s = sub[sub["method"] == m].sort_values("angle_deg")
            if results.fem_with_law([m], "linear"):
                s = s[s["angle_deg"] <= 10.0]  # small-strain FEM only where it is a reference
            if s.empty:
                continue
            ax.plot(s["angle_deg"], s["torque_z"], color=palette.color(m), marker=palette.marker(m),
                    ls=palette.linestyle(m), label=m.replace(" static", ""))
        ax.set_xlabel("rotation of the top plate θ (°)")
        ax.set_ylabel("reaction torque $T_z$ (N·m)")
        ax.legend(frameon=False, fontsize=7.5)
        fig.tight_layout()
        save_figure(plt, fig, path)
    return Figure("fig_torsion_sweep", f"Torsion: torque against angle (ν = {nu:g})", Path(path),
                  f"Torsion of the 5 m cube, mesh {mesh}, E = {sub['E'].iloc[0]:g} Pa, ν = {nu:g}, static "
                  "equilibria: top-plate torque T_z (N·m) against the rotation θ (°). Linear FEM shown up to 10° only.")


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
