"""The engines on the user's own body: one surface (the cylinder R 1 cm, H 4 cm of
:mod:`studies.paper.tet_cylinder`) squeezed and twisted, each model scored against one tetrahedral FEM
reference field.

- The surface is meshed into tetrahedra at the edge length ``h`` (:func:`hybmss.tetbody.mesh_surface`);
  mujoco-tet, newton-semi, newton-vbd and pbd-xpbd-fem run on exactly these tetrahedra
  (:meth:`hybmss.models._engine_model.EngineModel.solve_tets`: the rest state of the engine's
  damped run), the bottom nodes clamped and the top nodes moved.
- The reference is scikit-fem's P2 (P2–P1 for ν ≥ 0.45) on the same tetrahedra refined
  ``levels − 1`` times (:func:`fem_reference.tet.tet_convergence`, the faceted body unchanged),
  with the same displacement on the held nodes.  Its own error estimate: the reaction's
  Richardson estimate on the finest mesh, and the field's ``‖u_L − u_{L−1}‖/‖u_L‖`` at the scored
  nodes (the coarser level's change, an over-estimate of the finest level's error).  A row whose
  error is not above both estimates is flagged (``ref>err``): the reference cannot resolve it; an
  engine whose rest state's equilibrium error ``‖f_free‖/‖f_held‖`` exceeds an error it reports is
  flagged ``equil>err``.
- hybmss and corot-hex8 run on voxels of the same surface (:func:`hybmss.voxelize.voxelize`, cell
  edge ``le``), plates on the voxel body's bottom and top faces.  Their lattice nodes are scored
  where they lie in the faceted tetrahedral body (:func:`inside`) and the reference places them
  (:func:`placed`); the others (the voxel staircase reaches past the inscribed facets; a node on
  a facet whose element the reference's search misses) are left out of the field error and
  counted in the table (``outside``); the reaction is the voxel model's own.
- Errors: the field's relative L2 at the scored nodes on the reference's own displacement scale,
  ``‖u − u_ref‖₂/‖u_ref‖₂``, and the top reaction's (F_z of the squeeze, T_z of the twist)
  ``|R − R_ref|/|R_ref|``, the load's own force (torque) scale.  Wall times are each model's whole
  run (mesh and law check excluded), printed with the load average.

Run: ``python -m studies.paper.tet_compare [--h 0.005] [--le 0.0025] [--nu 0.3] [--levels 2]``.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time

import numpy as np

from fem_reference.tet import Support, as_mesh, tet_convergence
from hybmss.scene import NEARLY_INCOMPRESSIBLE_NU, Material
from hybmss.scene.boundary import Motion
from hybmss.tetbody import TetMeshError, contains, mesh_surface

from studies.paper.tet_cylinder import H, _cylinder_stl
from studies.study.tet import tet_engines



def lattice_models() -> tuple[str, ...]:
    """The registered lattice models solved by the harness's Newton (:func:`hybmss.modes.has_tangent`)."""
    from hybmss import models
    from hybmss.modes import has_tangent

    return tuple(n for n in models.names() if has_tangent(models.get(n)))


SAMPLE_TOL = 1e-6
"""Barycentric tolerance of the reference's sampling (:meth:`fem_reference.tet.TetSolution.sample`)."""


def loads(z0: float, z1: float, strain: float, theta: float) -> dict[str, Motion]:
    """The top plate's motion of each load (the bottom clamped): squeeze and twist about the axis."""
    return {"squeeze": Motion(kind="translate", displacement=(0.0, 0.0, -strain * (z1 - z0))),
            "twist": Motion(kind="rotate", angle=theta, axis=(0.0, 0.0, 1.0), center=(0.0, 0.0, z1))}


def _component(load: str, reaction) -> float:
    return float(reaction.force[2] if load == "squeeze" else reaction.torque[2])


def reference(body, mat: Material, load: str, motion: Motion, levels: int):
    """The tetrahedral FEM on ``body`` refined (module docstring): (finest, previous, estimate)."""
    z0, z1 = float(body.X[:, 2].min()), float(body.X[:, 2].max())
    tol = 1e-6 * (z1 - z0)
    supports = [Support("bottom", lambda x: x[2] < z0 + tol),
                Support("top", lambda x: x[2] > z1 - tol, lambda x: motion.displacement_at(x.T, 1.0).T)]
    form = "mixed" if mat.nu >= NEARLY_INCOMPRESSIBLE_NU else "p2"
    sols, conv = tet_convergence(as_mesh(body), form, mat, supports,
                                 {load: lambda s: _component(load, s.reactions["top"])}, levels=levels)
    return sols[-1], sols[-2], conv[load]


def inside(body, points: np.ndarray) -> np.ndarray:
    """Which points lie in the tetrahedra of ``body`` (:func:`hybmss.tetbody.contains`)."""
    return contains(body, points)


def placed(solution, points: np.ndarray) -> np.ndarray:
    """Which points the reference ``solution`` finds an element for within :data:`SAMPLE_TOL`
    (:meth:`fem_reference.tet.TetProblem.places`)."""
    return solution.problem.places(points, SAMPLE_TOL)


def score(ref, prev, conv, X: np.ndarray, u: np.ndarray, R: float) -> dict:
    """Field and reaction errors of a model's nodes ``X`` (displacements ``u``) and reaction ``R``."""
    ur, up = ref.sample(X, SAMPLE_TOL), prev.sample(X, SAMPLE_TOL)
    scale = float(np.linalg.norm(ur))
    R_ref = float(conv.values[-1])
    return {"field": float(np.linalg.norm(u - ur)) / scale, "reaction": abs(R - R_ref) / abs(R_ref),
            "ref_field": float(np.linalg.norm(ur - up)) / scale, "ref_reaction": float(conv.relative_error_finest)}


def engine_rows(body, mat, load, motion, ref, prev, conv, engines) -> list[dict]:
    from hybmss.models import get
    from hybmss.models._engine_tet import TetHold

    z0, z1 = float(body.X[:, 2].min()), float(body.X[:, 2].max())
    tol = 1e-6 * (z1 - z0)
    holds = [TetHold("bottom", lambda X: X[:, 2] < z0 + tol, Motion(kind="clamped")),
             TetHold("top", lambda X: X[:, 2] > z1 - tol, motion)]
    rows = []
    for name in engines:
        row = {"model": name, "mesh": f"tets {body.n_tets}", "nodes": body.n_nodes, "outside": 0}
        try:
            r = get(name).solve_tets(body, mat, holds)
        except (ValueError, ArithmeticError, RuntimeError) as exc:  # refused, diverged, reset by the engine
            rows.append({**row, "failed": str(exc).splitlines()[0]})
            continue
        rows.append({**row, **score(ref, prev, conv, r.X, r.u, _component(load, r.reactions["top"])),
                     "converged": r.converged, "equilibrium": r.equilibrium_error, "wall_s": r.wall_time_s})
    return rows


def voxel_rows(body, surface, mat, load, strain, theta, le, ref, prev, conv, models) -> list[dict]:
    from hybmss import Model, Plate, Region, Scene
    from hybmss.solve import solve_static
    from hybmss.voxelize import voxelize

    vox = voxelize(surface, le)
    lo, hi = (np.asarray(b, float) for b in vox.bounds)
    motion = loads(lo[2], hi[2], strain, theta)[load]
    rows = []
    for name in models:
        scene = Scene(body=vox, material=mat, model=Model(name),
                      plates=(Plate("bottom", Region("z-")), Plate("top", Region("z+"), motion)))
        t0 = time.perf_counter()
        try:
            r = solve_static(scene)
        except (ValueError, ArithmeticError, RuntimeError) as exc:
            rows.append({"model": name, "mesh": f"voxels {int(vox.mask.sum())}", "failed": str(exc).splitlines()[0]})
            continue
        wall = time.perf_counter() - t0
        ok = inside(body, r.X)
        ok[ok] = placed(ref, r.X[ok]) & placed(prev, r.X[ok])
        rows.append({"model": name, "mesh": f"voxels {int(vox.mask.sum())}", "nodes": int(ok.sum()),
                     "outside": int((~ok).sum()), "converged": bool(r.converged), "equilibrium": None,
                     **score(ref, prev, conv, r.X[ok], r.u[ok], _component(load, r.reactions["top"])),
                     "wall_s": wall})
    return rows


def compare(surface=None, h: float = 0.005, le: float = 0.0025, nus=(0.3,), strain: float = 0.01,
            theta: float = 0.01, levels: int = 2, engines=None, voxel_models=None) -> list[dict]:
    """One row per (ν, load, model): errors against the tetrahedral reference, wall times
    (``engines``: default :func:`tet_engines`; ``voxel_models``: default :func:`lattice_models`)."""
    engines = tet_engines() if engines is None else tuple(engines)
    voxel_models = lattice_models() if voxel_models is None else tuple(voxel_models)
    with tempfile.TemporaryDirectory() as tmp:
        surface = surface or _cylinder_stl(os.path.join(tmp, "cylinder.stl"))
        body = mesh_surface(surface, h)
        z0, z1 = float(body.X[:, 2].min()), float(body.X[:, 2].max())
        rows = []
        for nu in nus:
            mat = Material(1e4, nu, 1000.0)
            for load, motion in loads(z0, z1, strain, theta).items():
                t0 = time.perf_counter()
                ref, prev, conv = reference(body, mat, load, motion, levels)
                head = {"nu": nu, "load": load, "ref_tets": int(ref.problem.mesh.t.shape[1]),
                        "ref_s": time.perf_counter() - t0}
                for row in (engine_rows(body, mat, load, motion, ref, prev, conv, engines)
                            + voxel_rows(body, surface, mat, load, strain, theta, le, ref, prev, conv, voxel_models)):
                    rows.append({**head, **row})
    return rows


def _fmt(v, spec=".2e") -> str:
    return "-" if v is None else format(v, spec)


def table(rows: list[dict]) -> str:
    out = [f"{'nu':<5} {'load':<8} {'model':<13} {'mesh':<13} {'scored':>6} {'outside':>7} {'field':>9} "
           f"{'reaction':>9} {'ref field':>9} {'ref reac':>9} {'equil':>9} {'wall s':>7}  note"]
    for r in rows:
        if "failed" in r:
            out.append(f"{r['nu']:<5} {r['load']:<8} {r['model']:<13} {r['mesh']:<13} failed: {r['failed']}")
            continue
        flag = [] if r["converged"] else ["not at rest"]
        if not (r["field"] > r["ref_field"] and r["reaction"] > r["ref_reaction"]):
            flag.append("ref>err")
        if r["equilibrium"] is not None and r["equilibrium"] > min(r["field"], r["reaction"]):
            flag.append("equil>err")
        out.append(f"{r['nu']:<5} {r['load']:<8} {r['model']:<13} {r['mesh']:<13} {r['nodes']:>6} {r['outside']:>7} "
                   f"{_fmt(r['field'])} {_fmt(r['reaction'])} {_fmt(r['ref_field'])} {_fmt(r['ref_reaction'])} "
                   f"{_fmt(r['equilibrium'])} {r['wall_s']:>7.2f}  {', '.join(flag)}")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m studies.paper.tet_compare", description=__doc__.splitlines()[0])
    ap.add_argument("--h", type=float, default=0.005, help="tetrahedra edge length (m), default 0.005")
    ap.add_argument("--le", type=float, default=0.0025, help="voxel edge (m), default 0.0025")
    ap.add_argument("--nu", type=float, action="append", help="Poisson ratio in [0, 0.49] (repeatable), default 0.3")
    ap.add_argument("--levels", type=int, default=2, help="reference levels 2 or 3, default 2")
    ap.add_argument("--stl", default=None, help="surface file (default: a pyvista cylinder R 1 cm, H 4 cm)")
    args = ap.parse_args(argv)
    for key, v, lo, hi in (("--h", args.h, 1e-3, H / 2), ("--le", args.le, 1e-3, H / 4)):
        if not (math.isfinite(v) and lo <= v <= hi):
            ap.exit(2, f"{key}: {v} is not allowed; a length in [{lo:g}, {hi:g}] m\n")
    nus = tuple(args.nu or (0.3,))
    for nu in nus:
        if not 0.0 <= nu <= 0.49:
            ap.exit(2, f"--nu: {nu} is not allowed; in [0, 0.49] (pbd-xpbd-fem's range)\n")
    if not 2 <= args.levels <= 3:
        ap.exit(2, f"--levels: {args.levels} is not allowed; 2 or 3\n")
    try:
        t0 = time.perf_counter()
        rows = compare(args.stl, args.h, args.le, nus, levels=args.levels)
    except KeyboardInterrupt:
        return 130
    except (TetMeshError, ImportError, OSError) as exc:
        print(f"the surface cannot be meshed: {exc}", file=sys.stderr)
        return 3
    print(table(rows))
    print(f"total {time.perf_counter() - t0:.1f} s; load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    bad = sum(1 for r in rows if "failed" in r or not r["converged"])
    if bad:
        print(f"{bad} of {len(rows)} runs failed or did not come to rest (see the table); a finer --h or --le "
              "changes the step and the rest test", file=sys.stderr)
        return 3
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
