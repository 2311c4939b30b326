"""The experiments of [B09] (Baudet et al. 2009) at the parameters [B09] states, every model.

- **Cantilever** 400 × 100 × 100 mm (x × y × z), E = 1000 Pa, ν = 0.3, clamped at x = 0, under
  its own weight along −z; meshes 4×1×1, 8×2×2, 16×4×4 (cubic cells of 100, 50, 25 mm).
  *Density as printed:* ρ = 0.0125 kg/m³, read literally in kg/m³, with g = 9.81 m/s² ([B09]
  prints no g).  Euler–Bernoulli then gives a tip deflection of ρ g A L⁴/(8 E I) = 0.47 mm
  (0.12 % of the length): a small-strain test, in which a linear FEM is the exact reference up to
  its own discretization error.
- **L-shape** 4000 × 4000 × 4000 mm: on the N × N × N grid of that cube (N even), the cells with
  x < 2000 mm (a column of full height) or z ≥ 2000 mm (the arm on top); the L lies in the x–z
  plane and is 4000 mm deep along y.  Meshes 2×2×2, 4×4×4, 8×8×8 are that grid (6, 48, 384
  cells).  E = 1 kPa, ν = 0.3, mass neglected (ρ = 0, no gravity); the base z = 0 clamped.
  *Load:* [B09] prints "a constant force" of "0.3 GN" on the edges orthogonal to the base; on a
  1 kPa body that is a strain of order 10⁴.  We read it as **0.3 N** in total (the prefix G
  dropped), as a uniform dead traction along −z on the arm's free end face x = 4000 mm (a face
  orthogonal to the base, 2000 × 4000 mm, so t = 0.0375 Pa): strains of order 10⁻⁵.  In that
  linear regime the error statistics below, normalized by the reference's displacements, do not
  depend on the magnitude of the force, so any small reading gives the same numbers.

Error measures, for each mesh and model, over the mesh's particles a (reported as mean, standard
deviation and maximum, in %, as [B09] prints them; [B09] does not say which normalization it
uses, so both are given):

- ``err_*_pct``: ``|u_mss(a) − u_fem(a)| / max_b |u_fem(b)|`` (normalized by the largest
  displacement; defined at every particle, the clamped ones included);
- ``rel_*_pct``: ``|u_mss(a) − u_fem(a)| / |u_fem(a)|`` at the particles that move
  (``|u_fem(a)| > 0``, the clamped ones excluded).

The FEM reference is one Hex2 linear solve on a grid twice as fine as the finest lattice
(quick mode: the finest lattice's own grid), read at every mesh's particles (the coarse grids are
subsets of the fine one); its own discretization error is estimated against the Hex2 solve on
the next coarser grid (``fem_ref_change_pct``).  A model whose static solve fails is a row with
``status`` = "failed (reason)" and no numbers.

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
from functools import partial

import numpy as np

from hybmss import models

from studies.sweep import roles

MODELS = tuple(sorted(roles.in_role("b09"), key=lambda m: models.get(m).conservative))
"""The models of the moduli and volume tables (the non-conservative first: baudet2009, hybmss)."""
def error_models() -> tuple[str, ...]:
    """Every model that takes part in the studies (:func:`studies.sweep.roles.studied`) on the
    publications' meshes, in [B09]'s two experiments: not the engines, whose parts run them on
    coarse meshes of their own (:attr:`studies.sweep.roles.Part.meshes`; [B09]'s sweep refines to
    16×4×4 and 8×8×8)."""
    return tuple(m for m in roles.studied() if not roles.part(m).meshes)
E, NU = 1000.0, 0.3
CANTILEVER_RHO, GRAVITY = 0.0125, 9.81
CANTILEVER_SIZE = (0.4, 0.1, 0.1)
CANTILEVER_CELLS = (1, 2, 4)
"""Cells across the 100 mm section: meshes 4×1×1, 8×2×2, 16×4×4."""
LSHAPE_SIDE = 4.0
LSHAPE_CELLS = (2, 4, 8)
"""Cells along each side of the 4000 mm bounding cube: meshes 2×2×2, 4×4×4, 8×8×8."""
LSHAPE_FORCE = 0.3
"""Total force (N) on the arm's free end face, along −z: the reading of the printed "0.3 GN"."""
MODULI_NUS = (0.0, 0.25, 0.3, 0.45, 0.49)


def cantilever_scene(n: int, model: str | None = None):
    """The cantilever meshed with ``4n × n × n`` cubic cells (``model`` None: the registry's
    default model, e.g. for a FEM reference, which does not use it)."""
    from hybmss.scene import Body, Material, Model, Motion, Plate, Region, Scene

    le = CANTILEVER_SIZE[1] / n
    return Scene(Body.box(4 * n, n, n, le), Material(E, NU, CANTILEVER_RHO), Model(model),
                 plates=(Plate("clamp", Region("x-"), Motion("clamped")),), gravity=(0.0, 0.0, -GRAVITY),
                 name=f"baudet-cantilever-{4 * n}x{n}x{n}")


def lshape_mask(n: int) -> np.ndarray:
    """The L on the ``n × n × n`` grid of the bounding cube (``n`` even)."""
    if n < 2 or n % 2:
        raise ValueError(f"n (cells per side of the L-shape's bounding cube) must be even and >= 2, got {n}")
    mask = np.zeros((n, n, n), dtype=bool)
    mask[: n // 2, :, :] = True  # column of full height
    mask[:, :, n // 2:] = True  # arm on top
    return mask


def lshape_scene(n: int, model: str | None = None):
    """The L-shape on the ``n × n × n`` grid of its 4000 mm bounding cube (``model`` as for
    :func:`cantilever_scene`)."""
    from hybmss.scene import Body, Load, Material, Model, Motion, Plate, Region, Scene

    le = LSHAPE_SIDE / n
    end_face_area = (LSHAPE_SIDE / 2) * LSHAPE_SIDE
    return Scene(Body.from_mask(lshape_mask(n), le), Material(E, NU, 0.0), Model(model),
                 plates=(Plate("base", Region("z-"), Motion("clamped")),),
                 loads=(Load(Region("x+"), (0.0, 0.0, -LSHAPE_FORCE / end_face_area)),), name=f"baudet-lshape-{n}")


def displacement_error(X: np.ndarray, u: np.ndarray, ref_X: np.ndarray, ref_u: np.ndarray) -> dict:
    """Mean, SD and max (%) of ``|u − u_ref| / max|u_ref|`` (``err_*``) and of the nodal relative
    error ``|u − u_ref| / |u_ref|`` at the moving points (``rel_*``), at the points ``X``
    (matched in ``ref_X``)."""
    from fem_reference.mesh import match_points

    idx = match_points(ref_X, X, 1e-9 * max(1.0, float(np.abs(ref_X).max())))
    ur = ref_u[idx]
    d = np.linalg.norm(u - ur, axis=1)
    nr = np.linalg.norm(ur, axis=1)
    e = d / nr.max()
    moving = nr > 1e-12 * nr.max()
    rel = d[moving] / nr[moving]
    return {"err_mean_pct": 100 * float(e.mean()), "err_sd_pct": 100 * float(e.std()),
            "err_max_pct": 100 * float(e.max()), "rel_mean_pct": 100 * float(rel.mean()),
            "rel_sd_pct": 100 * float(rel.std()), "rel_max_pct": 100 * float(rel.max())}


def _fem(scene):
    from fem_reference.solve import solve as fem_solve

    return fem_solve(scene, element="hex2", law="linear", refine=1)


def _experiment(make, cells, ref_cells, check_cells, progress, label, models=None):
    """Rows of one experiment: every mesh of ``cells`` and model, against the Hex2 reference on
    the grid of ``ref_cells`` (and its change from the grid of ``check_cells``)."""
    import pandas as pd

    from hybmss.solve import solve_static

    models = error_models() if models is None else models
    t = time.perf_counter()
    ref = _fem(make(ref_cells))  # the FEM does not use the scene's model
    t_ref = time.perf_counter() - t
    check = _fem(make(check_cells))
    change = displacement_error(check.X, check.u, ref.X, ref.u)["err_max_pct"]
    h_ref = make(ref_cells).body.le
    rows = []
    for n in cells:
        for model in models:
            scene = make(n, model)
            row = {"mesh": "x".join(map(str, scene.body.shape)), "cells": scene.body.n_cells,
                   "le_mm": 1000 * scene.body.le, "model": model}
            try:
                r = solve_static(scene)
            except Exception as exc:  # noqa: BLE001 - a failed solve is a row, reported with its reason
                row.update({"status": f"failed ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})"})
                r = None
            if r is not None:
                row["status"] = "ok"
                row.update(displacement_error(r.X, r.u, ref.X, ref.u))
                row.update({"max_disp_mm": 1000 * r.max_displacement, "solve_time_s": r.wall_time_s})
            row.update({"fem_max_disp_mm": 1000 * float(np.linalg.norm(ref.u, axis=1).max()),
                        "fem_ref": f"hex2 h={1000 * h_ref:g} mm", "fem_ref_time_s": t_ref,
                        "fem_ref_change_pct": change})
            rows.append(row)
            if progress:
                msg = (f"error mean {row['err_mean_pct']:.2f} % SD {row['err_sd_pct']:.2f} % max "
                       f"{row['err_max_pct']:.2f} %" if r is not None else row["status"])
                print(f"{label} {row['mesh']:>8} {model:>10}: {msg}", flush=True)
    return pd.DataFrame(rows)


def cantilever_table(quick: bool = False, progress: bool = False):
    cells = CANTILEVER_CELLS[:2] if quick else CANTILEVER_CELLS
    ref = 4 if quick else 8
    return _experiment(cantilever_scene, cells, ref, ref // 2, progress, "cantilever")


def lshape_table(quick: bool = False, progress: bool = False):
    cells = LSHAPE_CELLS[:2] if quick else LSHAPE_CELLS
    ref = 8 if quick else 16
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
                         "G_from": "energy" if models.get(model).conservative else "plate reactions"})
            if progress:
                print(f"moduli {model:>10} nu={nu:<5}: E/E0 {rows[-1]['E_eff_over_E']:.6f} "
                      f"nu_eff {m['nu_eff']:.6f} G/G0 {rows[-1]['G_eff_over_G']:.6f}", flush=True)
    return pd.DataFrame(rows)


STUDY = "b09"
"""The driver study of :data:`studies.paper.reproduce.DRIVER_FILES` whose files
(``studies/data/studies/b09-volume-*.toml``) declare the volume table's runs."""
PAPER_TABLES = (("compression", "g20_table2_compression"), ("tension", "g20_table3_tension"))
"""The publication's table of volume changes of each experiment of the volume table."""


def tasks(quick: bool = False) -> list:
    """The pooled runs of :func:`run`, the volume table's (its study files': the compression and
    tension studies' own static runs, the same keys, so the reproduction's pool computes them
    once)."""
    from studies.paper.reproduce import DRIVER_STUDIES

    return DRIVER_STUDIES[STUDY](quick)


def volume_hook(h):
    """Table hook ``b09-volume`` (:class:`studies.paper.reproduce.HookInput`): :func:`volume_table`
    at the (ν, d) of each row of [G20]'s Tables 2 and 3, on the files' mesh of its experiment; a
    run the files do not give is a row ``not run``."""
    from studies.paper.values import load as load_paper

    found = {(t.scene.experiment, float(t.scene.nu), float(t.scene.deformation), t.scene.model): r
             for t, r in zip(h.tasks, h.rows) if t.solver.kind == "static"}
    pairs, rows = [], []
    for experiment, paper_name in PAPER_TABLES:
        mesh = next((c.mesh for c in h.configurations if c.experiment == experiment), None)
        if mesh is None:
            continue
        for _, p in load_paper(paper_name).iterrows():
            meta = {"experiment": experiment, "mesh": "x".join(map(str, mesh)), "nu": float(p["nu"]),
                    "d_pct": 100 * float(p["deformation"]), "paper_fem_e_pct": float(p["fem_lsdyna"])}
            for model in MODELS:
                row = found.get((experiment, float(p["nu"]), float(p["deformation"]), model))
                pairs.append(({**meta, "model": model}, None))
                rows.append(row if row is not None else {"status": "not run", "message": "not run"})
    return volume_table(pairs, rows)


def volume_table(pairs: list[tuple[dict, object]], rows: list[dict], progress: bool = False):
    """Relative volume change ``e`` (%) of the b09 models in [G20]'s compression (cube) and
    tension (beam) scenes, static, next to [G20]'s LS-Dyna values: where baudet2009's corrections,
    linear in the forces, stop standing in for a volume term at large strain and ν → ½.  ``pairs``:
    (row fields, run) of :func:`volume_hook`; ``rows``: their stored runs, in that order."""
    import pandas as pd

    table: dict = {}
    paper: dict = {}
    for (meta, _), row in zip(pairs, rows):
        m = meta["model"]
        key = (meta["experiment"], meta["nu"], meta["d_pct"])
        out = table.setdefault(key, {k: v for k, v in meta.items() if k not in ("model", "paper_fem_e_pct")})
        paper[key] = meta["paper_fem_e_pct"]
        status = row.get("status")
        if status == "ok":
            out[f"{m}_e_pct"] = 100 * abs(float(row["volume_change"]))
            out[f"{m}_state"] = "ok"
        else:  # no value: a lost equilibrium is a result (κ < 0 at ν < 1/4), named by its exception
            out[f"{m}_e_pct"] = float("nan")
            out[f"{m}_state"] = f"failed ({str(row.get('message') or '').split(':', 1)[0] or status})"
    if progress:
        for r in table.values():
            print(f"volume {r['experiment']} nu={r['nu']} d={r['d_pct']:g}%: "
                  + ", ".join(f"{m} {r[f'{m}_e_pct']:.2f}" if r[f"{m}_state"] == "ok" else f"{m} {r[f'{m}_state']}"
                              for m in MODELS), flush=True)
    return pd.DataFrame([{**r, "paper_fem_e_pct": paper[k]} for k, r in table.items()])  # paper last


TABLES = {"baudet_moduli": moduli_table, "baudet_cantilever": cantilever_table, "baudet_lshape": lshape_table}
"""The tables computed here, a process each (the volume table reads stored runs: :func:`run`)."""


def _table(job: tuple, progress: bool = False):
    name, quick = job
    return TABLES[name](quick, progress)


def calls(quick: bool = False) -> list:
    """The tables :func:`run` computes (:data:`TABLES`), as the sweep's calls
    (:class:`studies.sweep.executors.Call`), which :func:`run` then finds stored."""
    from studies.sweep.executors import Call

    return [Call("baudet_tables", _table, (n, quick)) for n in TABLES]


def run(store, quick: bool = False, jobs: int | None = None, progress: bool = True, runner=None) -> None:
    """Write ``baudet_moduli``, ``baudet_cantilever`` and ``baudet_lshape`` (computed ``jobs``
    processes at a time and kept in ``store``: :func:`studies.sweep.executors.map_stored`) and
    ``baudet_volume`` (from the stored runs of :func:`tasks`, computed by ``runner`` where
    missing) into ``store``."""
    from studies.paper.reproduce import file_study_tables
    from studies.sweep.executors import map_stored
    from studies.sweep.outcomes import expected_finding
    from studies.sweep.runner import run_tasks

    vol = tasks(quick)
    rows = run_tasks(vol, store, jobs=jobs, progress=progress, desc="b09 volume", runner=runner,
                     expected=expected_finding)
    for name, table in file_study_tables(STUDY, vol, rows, quick, store=store).items():
        store.write_table(name, table)
    fn = partial(_table, progress=progress)
    for name, df in zip(TABLES, map_stored(store, "baudet_tables", fn, [(n, quick) for n in TABLES], jobs, runner)):
        store.write_table(name, df)
