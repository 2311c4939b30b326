"""Deformed shapes rendered off-screen with pyvista (Figs 3, 4, 7, 9 of [G20]).

Each figure is a grid: rows hybmss-fd / hybmss / FEM reference, columns ν ∈ {0, 0.25, 0.499}; each
panel is the deformed lattice (displacements to scale); the MSS panels are coloured by
|u_MSS − u_FEM| (m) against the FEM panel of their column, the FEM panels by |u| (m), each with one
colour range per figure; the undeformed body is drawn as a grey outline.  Panels are rendered with a single
off-screen plotter (EGL, no display needed) and assembled with matplotlib, which draws the labels
and the shared colour bar.  Figures are cached by the keys and file times of the runs they show.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import palette
from .data import VTK_HEX_ORDER, Results

#: bump when the look of the renders changes (invalidates the cache)
RENDER_VERSION = "5"
PANEL_SIZE = (400, 350)
BEAM_PANEL_SIZE = (420, 170)
def render_rows(results: Results) -> list[str]:
    """Rows of a grid figure, as in [G20]'s: its model without face diagonals, its proposed model
    (their static methods) and the FEM."""
    mss = (results.published_model(r) for r in ("no-face-diagonals", "proposed"))
    return [f"{m} static" for m in mss if m] + ["FEM"]

FIGURE_NUMBERS = {"compression": 3, "tension": 4, "shear": 7, "torsion": 9}


@dataclass
class RenderFigure:
    """One rendered grid figure, its scene parameters and the runs it shows."""

    experiment: str
    load: str  # "d = 20 %" or "θ = 45°"
    path: Path
    mesh: str
    caption: str
    keys: list = field(default_factory=list)
    umax: float = 0.0
    dmax: float = 0.0  # largest |u_MSS − u_FEM| over the MSS panels (m)
    dmax_where: str = ""  # "<model>, ν = <nu>" of that panel


#: colour map of the MSS panels: |u_MSS − u_FEM| (m)
DIFF_CMAP = "magma_r"


def hex_grid(X: np.ndarray, u: np.ndarray, cells: np.ndarray, scalars: np.ndarray | None = None,
             name: str = "|u| (m)"):
    """pyvista UnstructuredGrid of the deformed lattice with point data ``name``: ``scalars`` (one
    value per particle), by default ``|u|``."""
    import pyvista as pv

    grid = pv.UnstructuredGrid({pv.CellType.HEXAHEDRON: np.asarray(cells)[:, VTK_HEX_ORDER]},
                               np.asarray(X + u, dtype=float))
    grid.point_data[name] = np.linalg.norm(u, axis=1) if scalars is None else np.asarray(scalars, dtype=float)
    return grid


OFF_SCREEN_WINDOW = "vtkEGLRenderWindow"
"""VTK's render window without a display.  VTK's wheels choose their window at run time, X first:
without ``DISPLAY`` the X window fails, prints a warning on the standard error ("bad X server
connection") and VTK then falls back to EGL.  Asked for EGL directly, it prints nothing."""


def off_screen_plotter(**kwargs):
    """``pyvista.Plotter(off_screen=True, **kwargs)`` on EGL when there is no display (and the
    user has not chosen a window with ``VTK_DEFAULT_OPENGL_WINDOW``)."""
    import os

    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", OFF_SCREEN_WINDOW)
    import pyvista as pv

    return pv.Plotter(off_screen=True, **kwargs)


class PanelRenderer:
    """One small off-screen pyvista plotter reused for every panel."""

    def __init__(self, size=PANEL_SIZE):
        import pyvista as pv

        self._pv = pv
        self.plotter = off_screen_plotter(window_size=list(size))
        self.plotter.set_background("white")

    def close(self):
        self.plotter.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def panel(self, X, u, cells, clim, view: dict, size=PANEL_SIZE, scalars=None, cmap=None) -> np.ndarray:
        """One panel: the deformed lattice coloured by ``scalars`` (default |u|) in ``cmap``."""
        pv, p = self._pv, self.plotter
        p.clear()
        if tuple(p.window_size) != tuple(size):
            p.window_size = list(size)
        grid = hex_grid(X, u, cells, scalars, "value")
        p.add_mesh(grid, scalars="value", clim=clim, cmap=cmap or palette.CMAP, show_edges=True,
                   edge_color="#303030", line_width=0.6, show_scalar_bar=False, lighting=True)
        lo, hi = X.min(axis=0), X.max(axis=0)
        p.add_mesh(pv.Box(bounds=(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])).outline(),
                   color="#9a9a9a", line_width=1.2)
        cam = p.camera
        cam.focal_point = view["focal"]
        cam.position = view["position"]
        cam.up = view["up"]
        p.enable_parallel_projection()
        cam.parallel_scale = view["scale"]
        p.render()
        return p.screenshot(return_img=True)


def _view(boxes: list[tuple[np.ndarray, np.ndarray]], beam: bool, size) -> dict:
    """A common camera for all panels of a figure: parallel projection fitted to every box."""
    lo = np.min([b[0] for b in boxes], axis=0)
    hi = np.max([b[1] for b in boxes], axis=0)
    if beam:  # the beam lies along z: show it horizontally
        d, up = np.array([0.45, -1.0, 0.3]), np.array([1.0, 0.0, 0.0])
    else:
        d, up = np.array([1.0, -1.25, 0.8]), np.array([0.0, 0.0, 1.0])
    d = d / np.linalg.norm(d)
    up = up - up.dot(d) * d
    up /= np.linalg.norm(up)
    right = np.cross(d, up)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    pr, pu = corners @ right, corners @ up
    c_screen = 0.5 * (pr.min() + pr.max()) * right + 0.5 * (pu.min() + pu.max()) * up
    depth = (0.5 * (lo + hi)).dot(d) * d
    focal = c_screen + depth
    aspect = size[0] / size[1]
    scale = 1.06 * max(0.5 * (pu.max() - pu.min()), 0.5 * (pr.max() - pr.min()) / aspect)
    ext = float(np.linalg.norm(hi - lo))
    return {"focal": tuple(focal), "position": tuple(focal + 4 * ext * d), "up": tuple(up), "scale": scale}


def _select(results: Results, experiment: str, mesh: str, nu: float, load: dict, row: str):
    if row == "FEM":
        return results.reference(experiment, mesh=mesh, nu=nu, **load)
    sub = results.find(experiment, mesh=mesh, nu=nu, method=row, **load)
    if "study" in sub:
        sub = sub[sub["study"] == experiment] if (sub["study"] == experiment).any() else sub
    return None if sub.empty else sub.iloc[0]


def _loads(results: Results, experiment: str, mesh: str) -> list[dict]:
    sub = results.find(experiment, mesh=mesh, study=experiment)
    if sub.empty:
        sub = results.find(experiment, mesh=mesh)
    if experiment == "torsion":
        vals = sorted(sub["angle_deg"].astype(float).unique())
        return [{"angle_deg": v} for v in vals]
    vals = sorted(sub["deformation"].astype(float).unique())
    return [{"deformation": v} for v in vals]


def load_tag(load: dict) -> str:
    if "angle_deg" in load:
        return f"theta{load['angle_deg']:g}deg"
    return f"d{100 * load['deformation']:g}pct"


def load_label(load: dict) -> str:
    if "angle_deg" in load:
        return f"θ = {load['angle_deg']:g}°"
    return f"d = {100 * load['deformation']:g} %"


def render_figures(results: Results, out_dir: Path, cache_dir: Path | None = None) -> list[RenderFigure]:
    """Every grid figure the results allow (one per experiment and load level)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    figs: list[RenderFigure] = []
    renderer = None
    try:
        for experiment in FIGURE_NUMBERS:
            mesh = results.primary_mesh(experiment)
            if mesh is None:
                continue
            for load in _loads(results, experiment, mesh):
                panels = {}
                for r, row in enumerate(render_rows(results)):
                    for c, nu in enumerate(results.nus(experiment)[:3]):
                        sel = _select(results, experiment, mesh, nu, load, row)
                        if sel is not None and "u" in results.arrays(sel["key"]):
                            panels[(r, c)] = sel
                if not panels:
                    continue
                tag = f"{experiment}_{mesh}_{load_tag(load)}"
                name = f"render_{tag}.png"
                path = out_dir / name
                sig = hashlib.sha256(json.dumps(
                    [RENDER_VERSION, tag] + sorted((str(k), s["key"], results.npz_mtime(s["key"]))
                                                   for k, s in panels.items())).encode()).hexdigest()[:20]
                cached = Path(cache_dir) / f"{sig}.png" if cache_dir else None
                umax = max(float(np.linalg.norm(results.arrays(s["key"])["u"], axis=1).max())
                           for s in panels.values())
                if cached is not None and cached.exists():
                    shutil.copyfile(cached, path)
                else:
                    if renderer is None:
                        renderer = PanelRenderer()
                    _compose(results, renderer, experiment, mesh, load, panels, umax, path)
                    if cached is not None:
                        cached.parent.mkdir(parents=True, exist_ok=True)
                        shutil.copyfile(path, cached)
                dmax, where = _largest_difference(results, experiment, panels)
                figs.append(RenderFigure(experiment, load_label(load), path, mesh,
                                         _caption(results, experiment, mesh, load, panels, umax),
                                         [s["key"] for s in panels.values()], umax, dmax, where))
    finally:
        if renderer is not None:
            renderer.close()
    return figs


def _caption(results, experiment, mesh, load, panels, umax) -> str:
    any_row = next(iter(panels.values()))
    fem = [s for (r, _), s in panels.items() if render_rows(results)[r] == "FEM"]
    law = results.reference_law(experiment, load.get("deformation", 0.0), load.get("angle_deg", 0.0))
    femtxt = f"FEM: {fem[0]['solver']} ({law})" if fem else "FEM: no reference stored"
    missing = 9 - len(panels)
    miss = f"; {missing} panel(s) empty (run missing or failed, see the failures table)" if missing else ""
    return (f"{experiment.capitalize()}, mesh {mesh}, E = {any_row['E']:g} Pa, ρ = {any_row['rho']:g} kg/m³, "
            f"{load_label(load)}; static equilibrium (MSS: Newton), {femtxt}. Deformed shapes to scale. Colour of "
            f"the MSS rows: |u_MSS − u_FEM| (m) per particle against the FEM panel of the same column (one range for "
            f"the figure, upper colour bar); colour of the FEM row: its displacement magnitude |u| (m), 0–{umax:.3g} m "
            f"(lower colour bar). Grey box: undeformed body{miss}.")


def _failed(results, experiment, mesh, load) -> dict:
    """Status of runs that exist but failed, per panel position."""
    out = {}
    for r, row in enumerate(render_rows(results)):
        if row == "FEM":
            continue
        for c, nu in enumerate(results.nus(experiment)[:3]):
            sub = results.find(experiment, mesh=mesh, nu=nu, method=row, ok_only=False, **load)
            sub = sub[sub["status"] != "ok"]
            if not sub.empty:
                out[(r, c)] = f"{sub.iloc[0]['status']}\n(see failures)"
    return out


def model_differences(results: Results, panels: dict) -> dict:
    """|u_MSS − u_FEM| per particle of each MSS panel whose column has a FEM panel on the same grid."""
    rows = render_rows(results)
    fem_row = len(rows) - 1
    out = {}
    for (r, c), s in panels.items():
        if r == fem_row or (fem_row, c) not in panels:
            continue
        u, uf = results.arrays(s["key"])["u"], results.arrays(panels[(fem_row, c)]["key"])["u"]
        if u.shape == uf.shape:
            out[(r, c)] = np.linalg.norm(u - uf, axis=1)
    return out


def _largest_difference(results: Results, experiment: str, panels: dict) -> tuple[float, str]:
    """(largest |u_MSS − u_FEM| over the figure's MSS panels (m), "<model>, ν = <nu>" of its panel)."""
    diffs = model_differences(results, panels)
    if not diffs:
        return 0.0, ""
    (r, c), d = max(diffs.items(), key=lambda kv: float(kv[1].max()))
    model = render_rows(results)[r].replace(" static", "")
    return float(d.max()), f"{model}, ν = {results.nus(experiment)[c]:g}"


def largest_differences_sentence(figs: list, n: int = 3) -> str:
    """The figures whose MSS panels depart most from the FEM (relative to the FEM's largest |u|)."""
    ranked = sorted((f for f in figs if f.dmax > 0 and f.umax > 0), key=lambda f: f.dmax / f.umax, reverse=True)
    if not ranked:
        return "No render has an MSS panel beside a FEM panel of the same grid."
    parts = [f"{f.experiment} at {f.load}: {f.dmax_where}, {f.dmax:.3g} m ({100 * f.dmax / f.umax:.3g} % of the "
             f"figure's largest displacement |u|)" for f in ranked[:n]]
    return ("The MSS panels are coloured by their distance to the FEM panel of the same column, |u_MSS − u_FEM|, "
            "the FEM row by its displacement |u|. Largest distances: " + "; ".join(parts) + ".")


def _compose(results, renderer, experiment, mesh, load, panels, umax, path):
    failed = _failed(results, experiment, mesh, load)
    beam = experiment in ("tension", "bending")
    boxes = []
    for s in panels.values():
        a = results.arrays(s["key"])
        x = a["X"] + a["u"]
        boxes += [(x.min(axis=0), x.max(axis=0)), (a["X"].min(axis=0), a["X"].max(axis=0))]
    size = BEAM_PANEL_SIZE if beam else PANEL_SIZE
    view = _view(boxes, beam, size)
    clim = (0.0, umax if umax > 0 else 1.0)
    diffs = model_differences(results, panels)
    dmax = max((float(d.max()) for d in diffs.values()), default=0.0)
    dlim = (0.0, dmax if dmax > 0 else 1.0)
    images = {}
    for (r, c), s in panels.items():
        a = results.arrays(s["key"])
        if (r, c) in diffs:
            images[(r, c)] = renderer.panel(a["X"], a["u"], a["cells"], dlim, view, size, diffs[(r, c)], DIFF_CMAP)
        else:
            images[(r, c)] = renderer.panel(a["X"], a["u"], a["cells"], clim, view, size)

    with palette.style() as plt:
        import matplotlib as mpl

        w, h = size
        fig_w = 7.0
        fig_h = 0.83 * fig_w * h / w + 0.45
        fig, axes = plt.subplots(3, 3, figsize=(fig_w, fig_h),
                                 gridspec_kw=dict(wspace=0.02, hspace=0.06, left=0.07, right=0.885,
                                                  top=1 - 0.3 / fig_h, bottom=0.01))
        for r in range(3):
            for c in range(3):
                ax = axes[r, c]
                ax.set_axis_off()
                if (r, c) in images:
                    ax.imshow(images[(r, c)])
                else:
                    ax.imshow(np.full((h, w, 3), 245, dtype=np.uint8))
                    ax.text(0.5, 0.5, failed.get((r, c), "no run stored"), ha="center", va="center",
                            transform=ax.transAxes, color="#a00", fontsize=8)
                if r == 0 and c < len(results.nus(experiment)):
                    ax.set_title(f"ν = {results.nus(experiment)[c]:g}")
            label = render_rows(results)[r].replace(" static", "")
            fam = "fem-linear" if label == "FEM" else label
            axes[r, 0].text(-0.04, 0.5, label, rotation=90, ha="right", va="center", transform=axes[r, 0].transAxes,
                            color=palette.color(fam), fontsize=9.5, fontweight="bold")
        fem_row = len(render_rows(results)) - 1
        if diffs:  # MSS rows: |u_MSS − u_FEM|; the FEM row: |u|
            bars = [([0.905, 0.08 + 0.8 * (1 - fem_row / 3) + 0.02, 0.022, 0.8 * fem_row / 3 - 0.04], dlim, DIFF_CMAP,
                     "|u_MSS − u_FEM| (m)"),
                    ([0.905, 0.08, 0.022, 0.8 / 3 - 0.02], clim, palette.CMAP, "FEM |u| (m)")]
        else:
            bars = [([0.905, 0.08, 0.022, 0.8], clim, palette.CMAP, "|u| (m)")]
        for rect, lim, cmap, label in bars:
            sm = mpl.cm.ScalarMappable(norm=mpl.colors.Normalize(*lim), cmap=cmap)
            cb = fig.colorbar(sm, cax=fig.add_axes(rect))
            cb.set_label(label, fontsize=8)
            cb.ax.tick_params(labelsize=7)
        fig.savefig(path, dpi=130)
        plt.close(fig)
