"""The report's section on released transients, from stored tables only (``dynamics`` and
``dynamics_traces``: :mod:`studies.paper.dynamics_study`): per body a table of each model's first
period error, damping ratio ζ, phase error, L2 trajectory error and wall time per simulated second
at each ν against the FEM's transient; a figure of the tracked point's history (model against FEM,
a panel per body at one ν); a figure of |period error| against the wall time per simulated second;
and a finding computed from the same rows on what each integrator does to frequency and damping.

The integrator's own share (columns ``integrator_period_pct``, ``integrator_zeta``) is what it does
to a linear mode of the model's measured frequency ω at its step h, ``z = ω h``: semi-implicit
Euler ``T_h/T = z / (2 arcsin(z/2))`` with no decay, backward Euler ``T_h/T = z / atan z`` and the
amplitude ``(1 + z²)^{−1/2}`` per step.

:func:`section` returns ``(title, intro, items)`` (items ``("table", Table)`` or
``("figure", Figure)``), or None when no dynamics table is stored.
"""

from __future__ import annotations

import html
import math
from pathlib import Path

import pandas as pd

from . import palette
from .plots import Figure, save_figure
from .findings import number_or_none
from .tables import Table, frame_table, grade

BODIES = ("cube", "beam")
TABLES = ("dynamics", "dynamics_traces")
"""The stored tables this section shows (the build leaves them out of its other sections)."""
GRADES = (2.0, 10.0)
"""|period error| (%) shown green up to the first, amber up to the second, red beyond."""
FAMILY_NAMES = {"symplectic": "semi-implicit (symplectic) Euler", "backward": "backward Euler",
                "other": "their own solvers"}


def _colors(models, plt) -> dict:
    """A colour per model: its stored style, else the next of matplotlib's cycle."""
    cycle = plt.rcParams["axes.prop_cycle"].by_key().get("color", ["C0"])
    out = {}
    for i, m in enumerate(models):
        out[m] = palette.color(m) if palette.family(m) != palette.OTHER else cycle[i % len(cycle)]
    return out


def body_table(t: pd.DataFrame, body: str) -> Table:
    """Period error, ζ, phase, L2 and cost per model and ν of ``body``."""

    def cls(r, c):
        if c == "period_error_pct":
            v = number_or_none(r[c])
            return grade(None if v is None else abs(v) / 100.0, tuple(g / 100.0 for g in GRADES))
        if c == "status":
            return "good" if r[c] == "ok" else "fail"
        return ""

    mesh = t["mesh"].iloc[0] if len(t) else ""
    cols = {"model": "model", "nu": "ν", "integrator": "integrator", "dt_s": "step h (s)", "substeps": "substeps",
            "omega_h": "ω h", "period_error_pct": "1st period (%)", "integrator_period_pct": "integrator alone (%)",
            "zeta": "ζ", "integrator_zeta": "ζ integrator alone", "phase_error_rad": "phase (rad)",
            "l2_error": "L2 / static", "wall_per_simulated_s": "wall / simulated s", "status": "status",
            "reason": "reason"}
    periods = int(t["phase_periods"].dropna().iloc[0]) if t["phase_periods"].notna().any() else 0
    fem = t.dropna(subset=["fem_period_error_pct"])
    fem_err = f"{fem['fem_period_error_pct'].abs().max():.2g}" if len(fem) else "?"
    return frame_table(
        t, f"table_dynamics_{body}", f"Released transients of the {mesh} {body} against the FEM's",
        "Each model released from its own static state under the load and stepped by its own integrator at the "
        "step a user would pick (0.9 of its stability limit; an engine: 1/60 s frames in substeps). 1st period: "
        "100 (T/T_FEM − 1) % of the tracked point's motion; ζ by its log decrement; phase after "
        f"{periods} periods; L2: the trajectory's RMS difference over the static deflection; integrator alone: "
        "what the scheme does to a linear mode of the model's measured frequency at its step (semi-implicit "
        "Euler z/(2 arcsin(z/2)) − 1 with no decay; backward Euler z/atan z − 1 and its amplitude (1+z²)^−½ per "
        f"step). FEM: Hex2, Newmark average acceleration, its own period error at most {fem_err} % (by halving "
        f"its step). Green within 2 %, amber within 10 %. CSV: tables/dynamics.csv.", cols, cls)


def trajectory_figure(traces: pd.DataFrame, path: Path) -> Figure | None:
    """The tracked point's displacement against time, every model and the FEM, a panel per body."""
    if traces is None or traces.empty:
        return None
    bodies = [b for b in BODIES if (traces["body"] == b).any()]
    nu = float(traces["nu"].iloc[0])
    with palette.style() as plt:
        fig, axes = plt.subplots(1, len(bodies), figsize=(4.6 * len(bodies), 3.0), squeeze=False)
        models = [m for m in dict.fromkeys(traces["model"]) if m != "fem"]
        colors = _colors(models, plt)
        for ax, body in zip(axes[0], bodies):
            t = traces[traces["body"] == body]
            for m in models:
                s = t[t["model"] == m]
                if not s.empty:
                    ax.plot(s["t_s"], 1e3 * s["u_m"], lw=0.9, color=colors[m], label=m)
            f = t[t["model"] == "fem"]
            ax.plot(f["t_s"], 1e3 * f["u_m"], lw=1.6, color=palette.COLORS["fem"], ls="--", label="FEM (Hex2, Newmark)")
            ax.set_title(f"{body} {t['mesh'].iloc[0]}, ν = {nu:g}", fontsize=9)
            ax.set_xlabel("t (s)")
            ax.set_ylabel("tracked displacement (mm)")
        handles, labels = [], []
        for ax in axes.flat:
            for h, lab in zip(*ax.get_legend_handles_labels()):
                if lab not in labels:
                    handles.append(h)
                    labels.append(lab)
        fig.legend(handles, labels, ncol=min(len(labels), 5), frameon=False, loc="lower center",
                   bbox_to_anchor=(0.5, 1.0), fontsize=7)
        fig.tight_layout()
        save_figure(plt, fig, path)
    return Figure("dynamics_trajectories", f"Released trajectories at ν = {nu:g}", path,
                  "The tracked point's displacement along the load after the release (its static deflection at "
                  "t = 0), each model with its own integrator at its user step against the FEM's transient "
                  "(dashed). A shorter period shows as a drift ahead of the FEM, numerical damping as a decay.")


def cost_figure(t: pd.DataFrame, path: Path) -> Figure | None:
    """|first period error| against wall time per simulated second, a point per model, body and ν."""
    ok = t[(t["status"] == "ok")].dropna(subset=["period_error_pct", "wall_per_simulated_s"])
    ok = ok[ok["wall_per_simulated_s"] > 0]
    if ok.empty:
        return None
    with palette.style() as plt:
        fig, ax = plt.subplots(figsize=(6.4, 3.8))
        models = list(dict.fromkeys(ok["model"]))
        colors = _colors(models, plt)
        marks = {"cube": "s", "beam": "o"}
        for m in models:
            for body in BODIES:
                s = ok[(ok["model"] == m) & (ok["body"] == body)]
                if not s.empty:
                    ax.scatter(s["wall_per_simulated_s"], s["period_error_pct"].abs().clip(lower=1e-3), s=18,
                               marker=marks[body], color=colors[m], label=m)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time per simulated second (s)")
        ax.set_ylabel("|1st period error| (%)")
        handles, labels = [], []
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
        ax.legend(handles, labels, fontsize=7, frameon=False, loc="center left", bbox_to_anchor=(1.0, 0.5))
        fig.tight_layout()
        save_figure(plt, fig, path)
    return Figure("dynamics_cost", "First period error against cost", path,
                  "|100 (T/T_FEM − 1)| % of each released run against its wall time per simulated second (the "
                  "stepping alone, one machine, one run; squares: cube, circles: beam; every ν). Down and left is "
                  "better.")


def _span(values, fmt: str) -> str:
    v = [x for x in (number_or_none(y) for y in values) if x is not None]
    if not v:
        return "?"
    lo, hi = min(v), max(v)
    return format(lo, fmt) if math.isclose(lo, hi, rel_tol=1e-9, abs_tol=1e-12) else \
        f"{format(lo, fmt)} to {format(hi, fmt)}"


def _family_sentence(fam: str, g: pd.DataFrame) -> str:
    models = ", ".join(dict.fromkeys(g["model"]))
    name = FAMILY_NAMES[fam]
    s = f"{name[0].upper() + name[1:]} ({models}; ω h {_span(g['omega_h'], '.2g')}): "
    if fam == "symplectic":
        s += (f"ζ {_span(g['zeta'], '.1e')} (the scheme alone keeps a linear mode's amplitude: a decay beyond the FEM's own ζ is the "
              f"model's, not the scheme's), the step alone "
              f"shortens the period by {_span(-g['integrator_period_pct'], '.2g')} % of the "
              f"measured {_span(g['period_error_pct'], '+.3g')} %: the rest is the models' own stiffness")
    elif fam == "backward":
        s += (f"ζ {_span(g['zeta'], '.3g')} against the {_span(g['integrator_zeta'], '.3g')} of backward Euler's "
              f"(1 + z²)^−½ per step, which also lengthens the period by {_span(g['integrator_period_pct'], '.2g')} %; "
              f"measured {_span(g['period_error_pct'], '+.3g')} %")
    else:
        s += f"ζ {_span(g['zeta'], '.2g')}, period {_span(g['period_error_pct'], '+.3g')} %"
    return s + "."


def finding(t: pd.DataFrame) -> str:
    """Sentences from the stored rows: per integrator family what it does to period and damping
    (measured against its closed form), then per body the model closest to the FEM's first period
    at every ν and the cheapest within 2 %."""
    if t is None or t.empty or "family" not in t:
        return ""
    ok = t[t["status"] == "ok"].dropna(subset=["period_error_pct"])
    out = [_family_sentence(f, g) for f, g in ok.groupby("family", sort=False)]
    floor = "; ".join(f"{b} {_span(ok[ok['body'] == b]['zeta_ref'], '.1e')}" for b in BODIES if (ok["body"] == b).any())
    out.append(f"The FEM's own ζ (Newmark adds no damping: the floor of this measurement, from the other modes the "
               f"release excites and the samples per period): {floor}.")
    for body in BODIES:
        b = ok[ok["body"] == body]
        if b.empty:
            continue
        worst = b.groupby("model", sort=False)["period_error_pct"].apply(lambda s: s.abs().max())
        best = worst.idxmin()
        nus = ", ".join(f"{v:g}" for v in sorted(set(b["nu"])))
        s = (f"On the {b['mesh'].iloc[0]} {body} (ν = {nus}) the closest first period is {best}'s (within "
             f"{worst[best]:.2g} % at every ν of its runs)")
        within = b[b["period_error_pct"].abs() <= GRADES[0]].dropna(subset=["wall_per_simulated_s"])
        if not within.empty:
            c = within.loc[within["wall_per_simulated_s"].idxmin()]
            s += (f"; the cheapest run within {GRADES[0]:g} % is {c['model']} at ν = {c['nu']:g} "
                  f"({c['wall_per_simulated_s']:.2g} s per simulated second)")
        out.append(s + ".")
    failed = t[t["status"] != "ok"]
    if len(failed):
        out.append(f"{len(failed)} run{'s' if len(failed) > 1 else ''} without result: "
                   + "; ".join(f"{r['model']} ({r['body']}, ν = {r['nu']:g})" for _, r in failed.iterrows()) + ".")
    return " ".join(out)


def section(results, fig_dir: Path) -> tuple[str, str, list] | None:
    """``(title, intro, items)`` of the released transients' section, or None without its table."""
    t = results.table("dynamics")
    if t is None or t.empty:
        return None
    traces = results.table("dynamics_traces")
    items = []
    with palette.models(results.table("models")):
        for fig in (trajectory_figure(traces, Path(fig_dir) / "dynamics_trajectories.png"),
                    cost_figure(t, Path(fig_dir) / "dynamics_cost.png")):
            if fig is not None:
                items.append(("figure", fig))
    for body in BODIES:
        b = t[t["body"] == body]
        if not b.empty:
            items.append(("table", body_table(b.reset_index(drop=True), body)))
    intro = ("Each body held at static equilibrium under a small load, released, and stepped by every model's own "
             "integrator at the step a user would pick, against the FEM's transient of the same scene. "
             + finding(t))
    return "Released transients: period and damping against the FEM", html.escape(intro), items
