"""The report of a user's study (``hybmss study FILE``): ``<out>/report/<name>.html`` (and a PDF
with ``pdf=True``, weasyprint), from the stored runs only.

Titled by the study; only the sections that ran: the error-against-cost chart, and per load case
the errors table, the cost table, the budget answer and the 3D views of the best and the worst
model run (finest resolution, first material) beside the FEM, coloured by |u_model − u_FEM|
(the FEM by |u|); the references.  Every model run and reference is also written as a VTU file
``vtu/<model>-<cell size>-<load case>.vtu`` with the model, the scene digest and the units as
field data and the FEM displacement and the error as point data.

``python -m reports.study FILE OUT [--quick] [--pdf]`` builds it and prints its path (what
``hybmss study`` runs after the study, in a process of its own)."""

from __future__ import annotations

import html
import re
import time
from pathlib import Path

import numpy as np

from . import palette
from .render import _view, hex_grid, off_screen_plotter
from studies.study import Study, metrics as study_metrics, outcome as study_outcome, tables as study_tables, tet_scores

from .study_modes import dynamics_html, modes_html

TEMPLATES = Path(__file__).parent / "templates"
VIEW_SIZE = (360, 300)


def build_study_report(study, out, pdf: bool = False) -> Path:
    """Write the report of ``study`` from the results folder ``out``; returns the HTML path."""
    out = Path(out)
    folder = out / "report"
    folder.mkdir(parents=True, exist_ok=True)
    tables = study.tables(out)
    runs = study_tables.loaded_runs(study, out)
    vtu = export_vtu(study, runs, out / "vtu")
    sections = [_case_section(study, case, tables, runs, folder) for case in study.load_cases]
    sections = [s for s in sections if s is not None]
    chart = error_cost_chart(study, tables, folder / "error-cost.png")
    outcome = study_outcome.study_outcome(study, out)
    outcome["line"] = study_outcome.outcome_line(outcome)
    page = _render(study, sections, chart, tables.get("reference"), len(vtu), outcome)
    path = folder / f"{study.name}.html"
    path.write_text(page)
    if pdf:
        from weasyprint import HTML

        HTML(string=page, base_url=str(folder)).write_pdf(folder / f"{study.name}.pdf")
    return path


# ---------------------------------------------------------------------------- VTU files
def file_name(model: str, cell_size: float, case: str, material: int | None = None) -> str:
    """``<model>-<cell size>-<load case>.vtu`` (a material index when the study sweeps one)."""
    safe = re.sub(r"[^A-Za-z0-9_.+-]+", "_", model)
    tail = "" if material is None else f"-m{material}"
    return f"{safe}-{cell_size * 1000:g}mm-{case}{tail}.vtu"


def export_vtu(study, runs: list[dict], folder: Path) -> list[Path]:
    from hybmss.result import Result
    folder.mkdir(parents=True, exist_ok=True)
    if study.tet_bodies:
        return export_tet_vtu(study, runs, folder)
    refs = {_config(r["task"]): r for r in runs if r["task"].solver.kind == "fem"}
    mats = list(study.materials)
    paths = []
    for r in runs:
        ref = refs.get(_config(r["task"]))
        if r["arrays"] is None or ref is None or ref["arrays"] is None:
            continue
        s = r["task"].scene
        a = r["arrays"]
        u_f = ref["arrays"]["u"][study_metrics.match_nodes(a["X"], ref["arrays"]["X"], s.cell_size)]
        res = Result(r["row"].get("solver", ""), s.build().digest(), a["X"], a["u"], np.nan, np.nan, {}, {}, 0, 0.0)
        grid = res.to_pyvista(a["cells"])
        grid.field_data["model"] = [s.label]
        grid.point_data["fem_displacement"] = u_f
        grid.point_data["error"] = a["u"] - u_f
        grid.point_data["|error|"] = np.linalg.norm(a["u"] - u_f, axis=1)
        index = mats.index(s.build().material) if len(mats) > 1 else None
        path = folder / file_name(s.label, s.cell_size, s.load_case, index)
        grid.save(path)
        paths.append(path)
    return paths


def _config(task) -> tuple:
    s = task.scene
    return (s.load_case, s.build().material, s.cell_size)


def export_tet_vtu(study, runs: list[dict], folder: Path) -> list[Path]:
    """A tetrahedral study's runs, each on its own mesh (an engine's tetrahedra, a voxel model's
    hexahedra, the reference's finest tetrahedra) with the reference sampled at its nodes (NaN
    where a node is not scored: :mod:`studies.study.tet_scores`)."""
    import pyvista as pv

    refs, fields, paths = tet_scores.references(runs), {}, []
    mats = list(study.materials)
    for r in runs:
        ref = refs.get(tet_scores.reference_config(r["task"]))
        if r["arrays"] is None or ref is None or ref["arrays"] is None:
            continue
        s, a = r["task"].scene, r["arrays"]
        if "tets" in a:
            cells = np.hstack([np.full((len(a["tets"]), 1), 4), a["tets"]]).ravel()
            grid = pv.UnstructuredGrid(cells, np.full(len(a["tets"]), pv.CellType.TETRA, np.uint8), a["X"])
        else:
            grid = hex_grid(a["X"], np.zeros_like(a["u"]), a["cells"])  # the reference positions
        grid.point_data["displacement"] = a["u"]
        grid.field_data["model"] = [s.label]
        if r is not ref:
            u_f = tet_scores.reference_at_nodes(study, r, ref, fields)
            grid.point_data["fem_displacement"] = u_f
            grid.point_data["|error|"] = np.linalg.norm(a["u"] - u_f, axis=1)
        material = s.material if hasattr(s, "material") else s.build().material
        index = mats.index(material) if len(mats) > 1 else None
        kind = "tets" if "tets" in a else "voxels"
        path = folder / file_name(f"{s.label}-{kind}", s.cell_size, s.load_case, index)
        grid.save(path)
        paths.append(path)
    return paths


# ---------------------------------------------------------------------------- figures
def error_cost_chart(study, tables: dict, path: Path) -> str | None:
    """Displacement field error against the best wall time, one panel per load case, one line
    per model through its resolutions; the budgets as horizontal lines."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    cases = [c.name for c in study.load_cases
             if "u_rel_l2" in tables[f"cost_{c.name}"] and tables[f"cost_{c.name}"]["u_rel_l2"].notna().any()]
    if not cases:
        return None
    with palette.style():
        fig, axes = plt.subplots(1, len(cases), figsize=(4.2 * len(cases), 3.4), squeeze=False)
        for ax, case in zip(axes[0], cases):
            df = tables[f"cost_{case}"]
            for i, (model, grp) in enumerate(df.groupby("model", sort=False)):
                grp = grp.sort_values("cell_size_m", ascending=False)
                ax.plot(grp["time_s"], grp["u_rel_l2"], marker="os^vDP*X"[i % 8], label=model)
            for b in study.budgets:
                ax.axhline(b, color=palette.COLORS["Euler-Bernoulli"], lw=0.8, ls=":")
            ax.set(xscale="log", yscale="log", xlabel="wall time (s)",
                   ylabel="displacement error, relative L2", title=case)
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.yaxis.set_minor_formatter(NullFormatter())
            ax.legend()
        fig.tight_layout()
        fig.savefig(path)
        plt.close(fig)
    return _b64(path)


def best_and_worst(df):
    """Rows of the best and the worst model run (u_rel_l2) at the finest resolution."""
    ok = df[df["u_rel_l2"].notna()] if "u_rel_l2" in df else df[:0]
    if ok.empty:
        return None
    fine = ok[ok["cell_size_m"] == ok["cell_size_m"].min()]
    return fine.loc[fine["u_rel_l2"].idxmin()], fine.loc[fine["u_rel_l2"].idxmax()]


def render_views(case: str, picks, runs: list[dict], path: Path) -> str | None:
    """FEM | best | worst, deformed to scale; the models coloured by |u_model − u_FEM| (one
    range), the FEM by |u|."""
    import pyvista as pv

    chosen = []
    for pick in picks:
        for r in runs:
            s = r["task"].scene
            if (r["arrays"] is not None and s.load_case == case and s.label == pick["model"]
                    and s.cell_size == pick["cell_size_m"] and s.build().material.nu == pick["nu"]
                    and s.build().material.E == pick["E"] and s.build().material.rho == pick["rho"]):
                chosen.append(r)
                break
    ref = next((r for r in runs if r["task"].solver.kind == "fem" and r["arrays"] is not None
                and _config(r["task"]) == _config(chosen[0]["task"])), None) if chosen else None
    if ref is None or len(chosen) < 2:
        return None
    a_f = ref["arrays"]
    grids, errs = [], []
    for r in chosen:
        a = r["arrays"]
        u_f = a_f["u"][study_metrics.match_nodes(a["X"], a_f["X"], r["task"].scene.cell_size)]
        g = hex_grid(a["X"], a["u"], a["cells"])
        g.point_data["|u - u_FEM| (m)"] = np.linalg.norm(a["u"] - u_f, axis=1)
        grids.append(g)
        errs.append(g.point_data["|u - u_FEM| (m)"].max())
    fem = hex_grid(a_f["X"], a_f["u"], a_f["cells"])
    boxes = [(g.points.min(axis=0), g.points.max(axis=0)) for g in (fem, *grids)]
    view = _view(boxes, False, VIEW_SIZE)
    p = off_screen_plotter(shape=(1, 3), window_size=[3 * VIEW_SIZE[0], VIEW_SIZE[1]])
    p.set_background("white")
    titles = ["FEM reference: |u| (m)", f"best: {chosen[0]['task'].scene.label}",
              f"worst: {chosen[1]['task'].scene.label}"]
    for k, (g, scalars) in enumerate(((fem, "|u| (m)"), (grids[0], "|u - u_FEM| (m)"), (grids[1], "|u - u_FEM| (m)"))):
        p.subplot(0, k)
        clim = None if k == 0 else [0.0, max(max(errs), 1e-300)]
        p.add_mesh(g.copy(), scalars=scalars, clim=clim, cmap=palette.CMAP, show_edges=True, edge_color="#303030",
                   line_width=0.5, scalar_bar_args={"title": scalars, "color": "black", "n_labels": 3, "fmt": "%.2g",
                                    "label_font_size": 10, "title_font_size": 11, "width": 0.7,
                                    "position_x": 0.15})
        p.add_text(titles[k], font_size=9, color="black")
        p.camera.focal_point, p.camera.position, p.camera.up = view["focal"], view["position"], view["up"]
        p.enable_parallel_projection()
        p.camera.parallel_scale = view["scale"]
    p.screenshot(str(path))
    p.close()
    return _b64(path)


def _b64(path: Path) -> str:
    import base64

    return "data:image/png;base64," + base64.b64encode(Path(path).read_bytes()).decode("ascii")


# ---------------------------------------------------------------------------- page
def _case_section(study, case, tables: dict, runs: list[dict], folder: Path) -> dict | None:
    errors = tables[f"errors_{case.name}"]
    if errors.empty or not (errors["status"] == "ok").any():
        return None
    picks = best_and_worst(errors) if not study.tet_bodies else None  # views: hexahedral meshes only
    views = render_views(case.name, picks, runs, folder / f"views-{case.name}.png") if picks else None
    return {"name": case.name, "errors": _html_table(errors.drop(columns=["message"], errors="ignore")),
            "cost": _html_table(tables[f"cost_{case.name}"]), "budget": _html_table(tables[f"budget_{case.name}"]),
            "views": views, "best": None if picks is None else picks[0]["model"],
            "worst": None if picks is None else picks[1]["model"],
            "modes": modes_html(folder.parent, study.name, case.name),
            "dynamics": dynamics_html(folder.parent, study.name, case.name)}


def _fmt(v) -> str:
    if isinstance(v, (float, np.floating)):
        return "" if not np.isfinite(v) else f"{v:.4g}"
    return "" if v is None else str(v)


def _html_table(df) -> str:
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in df.columns)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(_fmt(v))}</td>" for v in row) + "</tr>"
                   for row in df.itertuples(index=False))
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _render(study, sections, chart, reference, n_vtu: int, outcome: dict | None = None) -> str:
    import jinja2

    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES)),
                             autoescape=jinja2.select_autoescape(["html", "j2"]))
    css = (TEMPLATES / "report.css").read_text()
    return env.get_template("study.html.j2").render(
        study=study, sections=sections, chart=chart, n_vtu=n_vtu, css=css, outcome=outcome,
        timing_noise=1.0 + study_tables.cost.TIMING_NOISE, retime_noise=1.0 + study_tables.RETIME_NOISE,
        reference=None if reference is None or reference.empty else _html_table(reference),
        generated=time.strftime("%Y-%m-%d %H:%M"))


def main(argv=None) -> int:
    import argparse
    import sys

    parser = argparse.ArgumentParser(prog="python -m reports.study", description="the report of a study file")
    parser.add_argument("file")
    parser.add_argument("out")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--pdf", action="store_true")
    args = parser.parse_args(argv)
    try:
        path = build_study_report(Study.from_toml(args.file, quick=args.quick), args.out, pdf=args.pdf)
    except Exception as exc:  # noqa: BLE001 - one line for the caller
        print(f"{type(exc).__name__}: {' '.join(str(exc).split())[:300]}", file=sys.stderr)
        return 3
    print(path)
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main())
