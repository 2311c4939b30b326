"""The experiments of [B09] (Baudet et al. 2009) as scenes, baudet2009 and hybmss side by side.

- **Cantilever** 400 × 100 × 100 mm (x × y × z), E = 1000 Pa, ν = 0.3, clamped at x = 0, under
  gravity −z; meshes 4×1×1, 8×2×2, 16×4×4 (cubic cells of 100, 50, 25 mm).  With real
  self-weight (ρ = 1000 kg/m³) a 1 kPa beam would sag ~38 m by Euler–Bernoulli, far outside small
  strain; the density is not part of the experiment as SPEC §4 states it, so we take
  ρ = 0.1 kg/m³ (tip deflection ≈ 1 % of the length), a small-strain test in which a linear FEM
  is the exact reference up to its own discretization error.
- **L-shape** (:func:`hybmss.voxelize.l_shape`): three blocks of 100 mm, a column of two and an
  arm on top, same material; the base (z = 0) clamped, a uniform dead traction
  ``t = (0, 0, −0.5) Pa`` on the arm's free end face (x = 200 mm), i.e. 5 mN downwards; meshes
  2×2×2, 4×4×4, 8×8×8 cells per block.

Error measure, for each mesh and model: ``e_a = |u_mss(a) − u_fem(a)| / max_b |u_fem(b)|`` over
the mesh's particles a, reported as mean, standard deviation and maximum (%), as [B09] does.
The FEM reference is one Hex2 linear solve on the finest lattice's grid (h = 12.5 mm; 25 mm in
quick mode), read at every mesh's particles (the coarse grids are subsets of the fine one); its
own discretization error is estimated against the next coarser Hex2 solve (``fem_ref_change``).

Also the effective moduli of baudet2009 (homogeneous uniaxial tension and simple shear,
:func:`hybmss.moduli.measure_moduli`, G from the plate reactions) for ν ∈ {0, 0.25, 0.3, 0.45,
0.49}, with hybmss for comparison.

Finally the relative volume change of both models in [G20]'s compression and tension scenes
(static), next to [G20]'s FEM values.

Tables (``Store.write_table``): ``baudet_cantilever``, ``baudet_lshape``, ``baudet_moduli``,
``baudet_volume``.
"""

from __future__ import annotations

import time

import numpy as np

MODELS = ("baudet2009", "hybmss")
E, NU = 1000.0, 0.3
CANTILEVER_RHO, GRAVITY = 0.1, 9.81
CANTILEVER_SIZE = (0.4, 0.1, 0.1)
CANTILEVER_CELLS = (1, 2, 4)
"""Cells across the 100 mm section: meshes 4×1×1, 8×2×2, 16×4×4."""
LSHAPE_BLOCK = 0.1
LSHAPE_CELLS = (2, 4, 8)
LSHAPE_TRACTION = (0.0, 0.0, -0.5)
MODULI_NUS = (0.0, 0.25, 0.3, 0.45, 0.49)


def cantilever_scene(n: int, model: str = "baudet2009"):
    """The cantilever meshed with ``4n × n × n`` cubic cells."""
    from hybmss.scene import Body, Material, Model, Motion, Plate, Region, Scene

    le = CANTILEVER_SIZE[1] / n
    return Scene(Body.box(4 * n, n, n, le), Material(E, NU, CANTILEVER_RHO), Model(model),
                 plates=(Plate("clamp", Region("x-"), Motion("clamped")),), gravity=(0.0, 0.0, -GRAVITY),
                 name=f"baudet-cantilever-{4 * n}x{n}x{n}")


def lshape_scene(n: int, model: str = "baudet2009"):
    """The L-shape with ``n × n × n`` cells per block."""
    from hybmss.scene import Load, Material, Model, Motion, Plate, Region, Scene
    from hybmss.voxelize import l_shape

    return Scene(l_shape(n, LSHAPE_BLOCK / n), Material(E, NU, 1000.0), Model(model),
                 plates=(Plate("base", Region("z-"), Motion("clamped")),),
                 loads=(Load(Region("x+"), LSHAPE_TRACTION),), name=f"baudet-lshape-{n}")


def displacement_error(X: np.ndarray, u: np.ndarray, ref_X: np.ndarray, ref_u: np.ndarray) -> dict:
    """Mean, std and max (%) of ``|u − u_ref| / max|u_ref|`` at the points ``X`` (matched in ``ref_X``)."""
    from fem_reference.mesh import match_points

    idx = match_points(ref_X, X, 1e-9 * max(1.0, float(np.abs(ref_X).max())))
    ur = ref_u[idx]
    e = np.linalg.norm(u - ur, axis=1) / np.linalg.norm(ur, axis=1).max()
    return {"err_mean_pct": 100 * float(e.mean()), "err_std_pct": 100 * float(e.std()),
            "err_max_pct": 100 * float(e.max())}


def _fem(scene):
    from fem_reference.solve import solve as fem_solve

    return fem_solve(scene, element="hex2", law="linear", refine=1)


def _experiment(make, cells, ref_cells, check_cells, progress, label):
    """Rows of one experiment: every mesh of ``cells`` and model, against the Hex2 reference on
    the grid of ``ref_cells`` (and its change from the grid of ``check_cells``)."""
    import pandas as pd

    from hybmss.solvers import solve_static

    t = time.perf_counter()
    ref = _fem(make(ref_cells, "hybmss"))
    t_ref = time.perf_counter() - t
    check = _fem(make(check_cells, "hybmss"))
    change = displacement_error(check.X, check.u, ref.X, ref.u)["err_max_pct"]
    h_ref = make(ref_cells, "hybmss").body.le
    rows = []
    for n in cells:
        for model in MODELS:
            scene = make(n, model)
            r = solve_static(scene)
            row = {"mesh": "x".join(map(str, scene.body.shape)), "cells": scene.body.n_cells,
                   "le_mm": 1000 * scene.body.le, "model": model}
            row.update(displacement_error(r.X, r.u, ref.X, ref.u))
            row.update({"max_disp_mm": 1000 * r.max_displacement,
                        "fem_max_disp_mm": 1000 * float(np.linalg.norm(ref.u, axis=1).max()),
                        "solve_time_s": r.wall_time_s, "fem_ref": f"hex2 h={1000 * h_ref:g} mm",
                        "fem_ref_time_s": t_ref, "fem_ref_change_pct": change})
            rows.append(row)
            if progress:
                print(f"{label} {row['mesh']:>8} {model:>10}: error mean {row['err_mean_pct']:.2f} % "
                      f"std {row['err_std_pct']:.2f} % max {row['err_max_pct']:.2f} %", flush=True)
    return pd.DataFrame(rows)


def cantilever_table(quick: bool = False, progress: bool = False):
    cells = CANTILEVER_CELLS[:2] if quick else CANTILEVER_CELLS
    ref = 4 if quick else 8
    return _experiment(cantilever_scene, cells, ref, ref // 2, progress, "cantilever")


def lshape_table(quick: bool = False, progress: bool = False):
    cells = LSHAPE_CELLS[:2] if quick else LSHAPE_CELLS
    ref = 4 if quick else 8
    return _experiment(lshape_scene, cells, ref, ref // 2, progress, "l-shape")


def moduli_table(quick: bool = False, progress: bool = False):
    import pandas as pd

    from hybmss.moduli import measure_moduli
    from hybmss.scene import Material, Model

    rows = []
    for model in MODELS:
        for nu in MODULI_NUS:
            mat = Material(1e4, nu)
            m = measure_moduli(Model(model), mat)
            rows.append({"model": model, "nu": nu, "E_eff_over_E": m["E_eff"] / mat.E, "nu_eff": m["nu_eff"],
                         "G_eff_over_G": m["G_eff"] / mat.G, "E_rel_err": f"{m['E_eff'] / mat.E - 1:+.1e}",
                         "nu_err": f"{m['nu_eff'] - nu:+.1e}", "G_rel_err": f"{m['G_eff'] / mat.G - 1:+.1e}",
                         "G_from": "plate reactions" if model == "baudet2009" else "energy"})
            if progress:
                print(f"moduli {model:>10} nu={nu:<5}: E/E0 {rows[-1]['E_eff_over_E']:.6f} "
                      f"nu_eff {m['nu_eff']:.6f} G/G0 {rows[-1]['G_eff_over_G']:.6f}", flush=True)
    return pd.DataFrame(rows)


def volume_table(quick: bool = False, progress: bool = False):
    """Relative volume change ``e`` (%) of baudet2009 and hybmss in [G20]'s compression (cube) and
    tension (beam) scenes, static, next to [G20]'s LS-Dyna values: where the corrections, linear
    in the forces, stop standing in for a volume term at large strain and ν → ½."""
    import pandas as pd

    from hybmss.solvers import solve_static

    from .paper import load as load_paper
    from .reproduce import beams, cube
    from .scenes import SceneSpec

    rows = []
    for experiment, mesh, paper_name in (("compression", cube(quick), "g20_table2_compression"),
                                         ("tension", beams(quick)[0], "g20_table3_tension")):
        paper = load_paper(paper_name)
        for _, p in paper.iterrows():
            spec = SceneSpec.default(experiment, mesh=mesh, nu=float(p["nu"]), deformation=float(p["deformation"]))
            row = {"experiment": experiment, "mesh": "x".join(map(str, mesh)), "nu": float(p["nu"]),
                   "d_pct": 100 * float(p["deformation"])}
            for model in MODELS:
                try:
                    r = solve_static(spec.replace(model=model).build())
                    row[f"{model}_e_pct"] = 100 * abs(r.volume_change)
                except Exception as exc:  # a lost equilibrium is a result (κ < 0 at ν < 1/4)
                    row[f"{model}_e_pct"] = float("nan")
                    row[f"{model}_note"] = type(exc).__name__
            row["paper_fem_e_pct"] = float(p["fem_lsdyna"])
            rows.append(row)
            if progress:
                print(f"volume {experiment} nu={row['nu']} d={row['d_pct']:g}%: "
                      + ", ".join(f"{m} {row[f'{m}_e_pct']:.2f}" for m in MODELS), flush=True)
    return pd.DataFrame(rows)


def run(store, quick: bool = False, jobs: int | None = None, progress: bool = True, runner=None) -> None:
    """Write ``baudet_moduli``, ``baudet_cantilever``, ``baudet_lshape`` and ``baudet_volume``
    into ``store``."""
    store.write_table("baudet_moduli", moduli_table(quick, progress))
    store.write_table("baudet_cantilever", cantilever_table(quick, progress))
    store.write_table("baudet_lshape", lshape_table(quick, progress))
    store.write_table("baudet_volume", volume_table(quick, progress))
