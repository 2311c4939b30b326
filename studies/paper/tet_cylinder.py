"""The FEM reference on a tetrahedralized cylinder (R 1 cm, H 4 cm), squeezed and twisted.

A closed-surface STL of the cylinder (written from ``pyvista.Cylinder`` unless one is given) is
meshed into tetrahedra (:func:`hybmss.tetbody.mesh_surface`); the bottom face is clamped and the
top face moved: squeezed by ``δ = strain · H`` along −z, or twisted by an angle θ about the axis
(the infinitesimal rotation of linear theory).  For each ν, small-strain elasticity is solved on
the mesh refined ``levels − 1`` times (P2, or P2–P1 for ν ≥ 0.45) and the top plate's reaction
(F_z for the squeeze, T_z for the twist) is extrapolated by Richardson; its relative error
estimate and the wall times are reported beside the closed forms of a long bar,
``F = E A δ / H`` (uniaxial stress, the clamped ends make it stiffer) and ``T = G J θ / H``
(Saint-Venant torsion, exact for a circular shaft).

Run: ``python -m studies.paper.tet_cylinder [--h 0.005] [--levels 2] [--stl FILE]`` (at h 5 mm: 722 and
5776 tetrahedra, 4 s a load for P2 and 9–13 s for P2–P1; a third level, 46208 tetrahedra, takes
minutes).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time

from fem_reference.tet import as_mesh, clamp, rotate, tet_convergence, translate
from hybmss.scene import NEARLY_INCOMPRESSIBLE_NU, Material
from hybmss.tetbody import TetMeshError, mesh_surface

R, H = 0.01, 0.04


def _cylinder_stl(path: str) -> str:
    import pyvista as pv

    pv.Cylinder(center=(0, 0, H / 2), direction=(0, 0, 1), radius=R, height=H, resolution=128).save(path)
    return path


def cylinder_reference(stl: str | None = None, h: float = 0.005, levels: int = 2, nus=(0.3, 0.49),
                       E: float = 1e4, strain: float = 0.01, theta: float = 0.1) -> list[dict]:
    """One row per (ν, load): the reaction on each level, its Richardson estimate and times."""
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        body = mesh_surface(stl or _cylinder_stl(os.path.join(tmp, "cylinder.stl")), h)
        t_mesh = time.perf_counter() - t0
    z0, z1 = float(body.X[:, 2].min()), float(body.X[:, 2].max())
    tol = 1e-6 * (z1 - z0)
    bottom = clamp("bottom", lambda x: x[2] < z0 + tol)
    loads = {
        "squeeze": (translate("top", lambda x: x[2] > z1 - tol, (0.0, 0.0, -strain * (z1 - z0))),
                    lambda s: s.reactions["top"].force[2]),
        "twist": (rotate("top", lambda x: x[2] > z1 - tol, theta, (0, 0, 1), (0.0, 0.0, z1)),
                  lambda s: s.reactions["top"].torque[2]),
    }
    rows = []
    for nu in nus:
        mat = Material(E, nu, 0.0)
        form = "mixed" if nu >= NEARLY_INCOMPRESSIBLE_NU else "p2"
        closed = {"squeeze": -E * math.pi * R**2 * strain, "twist": mat.G * math.pi * R**4 / 2 * theta / H}
        for name, (top, output) in loads.items():
            t0 = time.perf_counter()
            sols, conv = tet_convergence(as_mesh(body), form, mat, [bottom, top], {name: output}, levels=levels)
            o = conv[name]
            rows.append({
                "nu": nu, "load": name, "element": form, "tets": [s.problem.mesh.t.shape[1] for s in sols],
                "values": list(o.values), "observed_order": o.observed_order, "extrapolated": o.extrapolated,
                "relative_error_finest": o.relative_error_finest,
                "relative_error_coarsest": o.relative_error_coarsest, "closed_form": closed[name],
                "solve_s": [s.wall_time_s for s in sols], "wall_s": time.perf_counter() - t0,
                "mesh_s": t_mesh, "mesh": body.summary(),
            })
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m studies.paper.tet_cylinder", description=__doc__.splitlines()[0])
    ap.add_argument("--h", type=float, default=0.005, help="target edge length (m), default 0.005")
    ap.add_argument("--levels", type=int, default=2, help="refinement levels 2 or 3, default 2")
    ap.add_argument("--stl", default=None, help="surface file (default: a pyvista cylinder R 1 cm, H 4 cm)")
    args = ap.parse_args(argv)
    if not (args.h > 0 and math.isfinite(args.h)):
        ap.exit(2, f"--h: {args.h} is not allowed; a target edge length > 0 (m)\n")
    if not 2 <= args.levels <= 3:
        ap.exit(2, f"--levels: {args.levels} is not allowed; 2 or 3\n")
    try:
        rows = cylinder_reference(args.stl, args.h, args.levels)
    except KeyboardInterrupt:
        return 130
    except (TetMeshError, ImportError, OSError) as exc:  # the surface cannot be meshed, or no mesher
        print(f"the cylinder cannot be meshed: {exc}", file=sys.stderr)
        return 3
    m = rows[0]["mesh"]
    print(f"mesh: {m['nodes']} nodes, {m['tets']} tets at h {m['h']:g} m ({rows[0]['mesh_s']:.2f} s); "
          f"volume {m['mesh_volume']:.6g} m^3, surface {m['surface_volume']:.6g} m^3 ({100 * m['volume_error']:+.2f} %)")
    for r in rows:
        order = "-" if r["observed_order"] is None else f"{r['observed_order']:.2f}"
        print(f"nu {r['nu']:<5} {r['load']:<8} {r['element']:<6} tets {r['tets']} values "
              + " ".join(f"{v:.6g}" for v in r["values"])
              + f" order {order} extrapolated {r['extrapolated']:.6g} (closed form {r['closed_form']:.6g})"
              + f" est. error finest {r['relative_error_finest']:.2e} coarsest {r['relative_error_coarsest']:.2e}"
              + f" solve {' '.join(f'{t:.2f}' for t in r['solve_s'])} s, total {r['wall_s']:.1f} s")
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
