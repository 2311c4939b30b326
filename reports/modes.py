"""The report's section on natural frequencies, from stored tables only (``modes_cube``,
``modes_beam``, ``modes_pairs``: :mod:`studies.paper.modes_study`): per body a table of each model's
frequency error of the first bending, torsion and axial mode against the FEM and its lowest MAC at
each ν, a figure of those errors against ν, and a finding computed from the same numbers.

The error of a mode is ``100 (f_model / f_ref − 1)`` %, ``f_ref`` the FEM's (Hex2, mixed u–p at
ν ≥ 0.45) on the same cells and supports; a model's mode is the one its MAC pairs with the FEM's.

:func:`section` returns ``(title, intro, items)`` (items ``("table", Table)`` or
``("figure", Figure)``), or None when no modes table is stored.
"""

from __future__ import annotations

import html
from pathlib import Path

import pandas as pd

from . import palette
from .plots import Figure, nu_axis, save_figure
from .findings import number_or_none
from .tables import Table, frame_table, grade

BODIES = ("cube", "beam")
KINDS = ("bending", "torsion", "axial")
TABLES = ("modes_pairs",) + tuple(f"modes_{b}" for b in BODIES)
"""The stored tables this section shows (the build leaves them out of its other sections)."""
GRADES = (2.0, 10.0)
"""|error| (%) shown green up to the first, amber up to the second, red beyond."""
WITHIN_PCT = 5.0
"""The finding names the models whose three first modes stay within this (%) at every ν."""




def body_table(t: pd.DataFrame, body: str) -> Table:
    """The errors of the first bending, torsion and axial mode and the lowest MAC, per model and ν."""

    def cls(r, c):
        if c.endswith("_error_pct"):
            v = number_or_none(r[c])
            return grade(None if v is None else abs(v) / 100.0, tuple(g / 100.0 for g in GRADES))
        return ""

    mesh = t["mesh"].iloc[0] if len(t) else ""
    cols = {"model": "model", "nu": "ν", "fem_element": "FEM", "bending_error_pct": "1st bending (%)",
            "torsion_error_pct": "1st torsion (%)", "axial_error_pct": "1st axial (%)", "min_mac": "lowest MAC",
            "modes": "FEM modes", "model_time_s": "model eigen-solve (s)", "fem_time_s": "FEM eigen-solve (s)",
            "status": "status"}
    tab = frame_table(t, f"table_modes_{body}", f"Natural frequencies of the {mesh} {body} against the FEM",
                      "Error 100 (f_model / f_FEM − 1) % of the lowest FEM mode of each kind (layers translating "
                      "sideways: bending, or the cube's shear; turning: torsion; moving along z: axial), the model's "
                      "mode paired by MAC among its lowest 2k; empty where none of the FEM's k lowest modes is of "
                      "that kind or where the model has no counterpart of it (its best pair's MAC below 0.5). "
                      "Lowest MAC: over all k pairs (near-equal higher FEM modes mix, so it can be low "
                      "where the three named modes are well paired). Green within 2 %, amber within 10 %. FEM: Hex2 "
                      "with consistent mass on the same cells, mixed u–p for ν ≥ 0.45; model: its tangent at rest "
                      f"with its lumped masses. CSV: tables/modes_{body}.csv.", cols, cls)
    return tab  # printed (a table with a CSV link is the HTML page's only)


def figure(tables: dict, path: Path) -> Figure | None:
    """Error of the first bending, torsion and axial mode against ν per model, a row per body."""
    bodies = [b for b in BODIES if tables.get(b) is not None and not tables[b].empty]
    if not bodies:
        return None
    with palette.style() as plt:
        fig, axes = plt.subplots(len(bodies), 3, figsize=(9.0, 2.6 * len(bodies)), squeeze=False, sharex=True)
        models = list(dict.fromkeys(m for b in bodies for m in tables[b]["model"]))
        colors = plt.rcParams["axes.prop_cycle"].by_key().get("color", ["C0"])
        marks = "osD^v<>ph*"
        for i, body in enumerate(bodies):
            t = tables[body]
            for j, kind in enumerate(KINDS):
                ax = axes[i, j]
                for n, m in enumerate(models):
                    sub = t[t["model"] == m].dropna(subset=[f"{kind}_error_pct"])
                    if not sub.empty:
                        ax.plot(sub["nu"], sub[f"{kind}_error_pct"], marker=marks[n % len(marks)], ms=4,
                                color=colors[n % len(colors)], label=m)
                ax.axhline(0.0, color="0.5", lw=0.6)
                nu_axis(ax, t["nu"])
                ax.set_title(f"{body} {t['mesh'].iloc[0]}: 1st {kind}", fontsize=9)
                if j == 0:
                    ax.set_ylabel("f_model / f_FEM − 1 (%)")
                if i < len(bodies) - 1:
                    ax.set_xlabel("")
        handles, labels = axes[0, 0].get_legend_handles_labels()
        fig.legend(handles, labels, ncol=min(len(labels), 6), frameon=False, loc="lower center",
                   bbox_to_anchor=(0.5, 1.0))
        fig.tight_layout()
        save_figure(plt, fig, path)
    return Figure("modes_error", "Frequency error against ν", path,
                  "Error of each model's first bending, torsion and axial frequency against the FEM's on the same "
                  "cells, per ν (axis log(½ − ν)); a missing point: no FEM mode of that kind among the k lowest, "
                  "or no counterpart of it among the model's "
                  "lowest 2k (MAC below 0.5).")


def _worst(t: pd.DataFrame, m: str) -> tuple[float | None, float | None, str | None]:
    """(largest |error| %, its ν, its kind) of model ``m`` over the three kinds and every ν."""
    best = (None, None, None)
    for _, r in t[t["model"] == m].iterrows():
        for kind in KINDS:
            v = number_or_none(r[f"{kind}_error_pct"])
            if v is not None and (best[0] is None or abs(v) > abs(best[0])):
                best = (v, float(r["nu"]), kind)
    return best


def finding(tables: dict) -> str:
    """Sentences from the stored numbers: per body the models within :data:`WITHIN_PCT` at every ν,
    the best and the worst model (largest |error| of its three first modes over ν) and where."""
    out = []
    for body in BODIES:
        t = tables.get(body)
        if t is None or t.empty:
            continue
        worst = {m: _worst(t, m) for m in dict.fromkeys(t["model"]) if _worst(t, m)[0] is not None}
        if not worst:
            continue
        mesh = t["mesh"].iloc[0]
        nus = ", ".join(f"{v:g}" for v in sorted(set(t["nu"])))
        within = [m for m, (v, *_) in worst.items() if abs(v) <= WITHIN_PCT]
        order = sorted(worst, key=lambda m: abs(worst[m][0]))
        b, w = order[0], order[-1]
        s = f"On the {mesh} {body} (ν = {nus}), "
        s += (f"{', '.join(within)} keep{'s' if len(within) == 1 else ''} the first bending, torsion and axial "
              f"frequencies within {WITHIN_PCT:g} % of the FEM's at every ν; " if within else
              f"no model keeps the first bending, torsion and axial frequencies within {WITHIN_PCT:g} % at every ν; ")
        s += (f"the closest is {b} (at most {abs(worst[b][0]):.3g} %, its {worst[b][2]} mode at ν = {worst[b][1]:g}), "
              f"the farthest {w} ({worst[w][0]:+.3g} %, its {worst[w][2]} mode at ν = {worst[w][1]:g}).")
        out.append(s)
    return " ".join(out)


def section(results, fig_dir: Path) -> tuple[str, str, list] | None:
    """``(title, intro, items)`` of the natural frequencies' section, or None without its tables."""
    tables = {b: results.table(f"modes_{b}") for b in BODIES}
    if all(t is None for t in tables.values()):
        return None
    items = []
    fig = figure(tables, Path(fig_dir) / "modes_error.png")
    if fig is not None:
        items.append(("figure", fig))
    for body in BODIES:
        if tables[body] is not None and not tables[body].empty:
            items.append(("table", body_table(tables[body], body)))
    pairs = results.table("modes_pairs")
    if pairs is not None:
        tab = frame_table(pairs, "table_modes_pairs", "Every mode pair",
                          "Each FEM mode, its kind and the model's mode paired with it by MAC: frequencies (Hz), "
                          "error (%), MAC, wall time of each eigen-solve.", screen_only=True)
        tab.csv = "tables/modes_pairs.csv"
        items.append(("table", tab))
    intro = ("Small vibrations about the rest state, K φ = ω² M φ: each model's tangent at rest with its lumped "
             "masses against the FEM on the same cells and supports. " + finding(tables))
    return "Natural frequencies and mode shapes against the FEM", html.escape(intro), items
