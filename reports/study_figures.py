"""The study sections' figures, each from stored tables only: speed against error (Pareto front,
the error budget's answers), performance against the number of volumes, stability (time step,
extreme loads), limit stretch, damping and [B09]'s experiments; :data:`STUDY_PLOTS` draw one stored
table each, :data:`STUDY_FIGURES` read several."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from . import findings, palette
from .data import TIMING_NOISE, Results, paper_table
from .plots import Figure, nu_axis, save_figure, shared_legend



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
        save_figure(plt, fig, path)
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
        shared_legend(fig, axes, loc="upper center", ncol=3, bbox_to_anchor=(0.5, 0.0), fontsize=7)
        fig.tight_layout()
        save_figure(plt, fig, path)
    return Figure("fig_performance", "Time per explicit step against the number of volumes (Figs 11, 12)", Path(path),
                  f"From tables/performance.csv: {tcol} of the timed runs divided by the step count, in ms per step "
                  f"(numba stencil kernel{_thread_styles(threads)}). Hollow circles: hybmss at ν = 1/4 "
                  "(κ = 0, no volume term). Stars: the publication's time per step (10,000 steps of the 10³ cube).")


def _thread_styles(threads: list) -> str:
    """The line style of each thread count timed (those of :func:`performance`'s lines), for a caption."""
    counts = [int(th) for th in threads if th is not None]
    words = [f"{int(th)} thread{'s' if th != 1 else ''}" for th in counts]
    if len(words) == 1:
        return f"; {words[0]}"
    return "".join(f"{'; ' if i == 0 else ', '}{style} {w}"
                   for i, (style, w) in enumerate(zip(("solid", "dashed", "dotted", "dash-dotted"), words)))


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
        shared_legend(fig, axes, loc="upper center", ncol=5, bbox_to_anchor=(0.5, 0.0))
        fig.tight_layout()
        save_figure(plt, fig, path)
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
        nu_axis(ax, df["nu"].unique())
        ax.set_ylabel("time step (s)")
        ax.legend(frameon=False, fontsize=6.5, ncol=1, loc="center left", bbox_to_anchor=(1.0, 0.5))
        fig.tight_layout()
        save_figure(plt, fig, path)
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
        handles += [plt.Line2D([], [], ls="none", marker="o", mfc="white", mec="k",
                               label=f"hollow: tie (lead < 1 + max(spread, {TIMING_NOISE:g}))"),
                    plt.Line2D([], [], ls="none", marker=".", color="#bbbbbb", label="no method meets the budget")]
        fig.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=4, frameon=False, fontsize=7)
        fig.tight_layout()
        save_figure(plt, fig, path)
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
                  "1 + the larger timing spread (median over best of the repeats), and never smaller than "
                  f"{1 + TIMING_NOISE:.2f}, the noise of two runs timed apart (only candidates whose lead is "
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
        save_figure(plt, fig, path)
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
        nu_axis(ax, t["nu"].unique())
        ax.set_ylabel("stretch L/L0 at loss of equilibrium")
        ax.legend(frameon=False, fontsize=6.5, loc="center left", bbox_to_anchor=(1.0, 0.5))
        fig.tight_layout()
        save_figure(plt, fig, path)
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
        save_figure(plt, fig, path)
    return Figure("study_damping", "Explicit protocol: distance to the static equilibrium against steps", Path(path),
                  "From tables/damping_steps.csv: relative L2 difference (%) of the explicit state (semi-implicit "
                  "Euler, mass-proportional damping) from the static equilibrium of the same scene after n steps, "
                  "measured at every checkpoint whether or not the run had come to rest.")


def b09_errors(results: Results, path: Path) -> Figure | None:
    df = results.table("b09_comparison")
    if df is None:
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
        shared_legend(fig, axes, loc="upper center", ncol=3, bbox_to_anchor=(0.5, 0.0), fontsize=7)
        fig.tight_layout()
        save_figure(plt, fig, path)
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
