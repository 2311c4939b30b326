"""Natural frequencies of the [G20] cube and beam: every model with a tangent against the FEM.

The cube is the compression experiment's (10³ cells, clamped at z = 0 and held by its top plate;
4³ under ``quick``), the beam the bending experiment's cantilever (4×4×24, clamped at z = 0;
2×2×12 under ``quick``), each at ν ∈ {0, 0.25, 0.45, 0.499} (E and ρ of the experiment).  Small
vibrations about the rest state, ``K φ = ω² M φ``: the FEM (:func:`fem_reference.modal.modes`,
Hex2 with consistent mass, the mixed u–p element for ν ≥ 0.45 as ``element = "auto"``) and each
model's lattice (:func:`hybmss.modes.lattice_modes`: its tangent at rest, lumped masses), paired by
MAC (:mod:`studies.sweep.mode_pairs`).

Tables written into the store:

- ``modes_pairs``: per body, ν, model and FEM mode: the FEM's and the paired model mode's
  frequency, the error ``100 (f_model / f_ref − 1)`` %, the MAC, the mode's kind (bending,
  torsion, axial, other: :func:`studies.sweep.mode_pairs.mode_kinds`), the wall times of both solves;
- ``modes_cube`` and ``modes_beam``: per model and ν the error of the first bending, torsion and
  axial mode (the lowest FEM mode of each kind; empty when none is among the FEM's k lowest) and
  the lowest MAC over the k pairs.

The eigen-solves are direct calls (no stored run of the runner: a model's modes take well under a
second on these lattices, the FEM's a few seconds), computed again at each run.
"""

from __future__ import annotations

import pandas as pd

from hybmss import models
from hybmss.experiments import SceneSpec

from studies.sweep.mode_pairs import fem_modes, first_of_kinds, model_rows

NUS = (0.0, 0.25, 0.45, 0.499)
BODIES = {
    # name: (experiment, full mesh, quick mesh, FEM modes k)
    "cube": ("compression", (10, 10, 10), (4, 4, 4), 12),
    "beam": ("bending", (4, 4, 24), (2, 2, 12), 8),
}
ELEMENT = "auto"
TABLES = ("modes_pairs",) + tuple(f"modes_{b}" for b in BODIES)


def modal_models() -> tuple[str, ...]:
    """The registered models with a tangent stiffness (:func:`hybmss.modes.has_tangent`)."""
    from hybmss.modes import has_tangent

    return tuple(n for n in models.names() if has_tangent(models.get(n)))


def pair_rows(body: str, quick: bool = False, nus=NUS, names=None) -> list[dict]:
    """The rows of ``modes_pairs`` for ``body`` (a key of :data:`BODIES`)."""
    from fem_reference.solve import resolve_element

    experiment, full, small, k = BODIES[body]
    mesh = small if quick else full
    names = modal_models() if names is None else tuple(names)
    rows = []
    for nu in nus:
        spec = SceneSpec.default(experiment, mesh=mesh, nu=nu)
        fem = fem_modes(spec.build(), k, resolve_element(ELEMENT, nu))
        for name in names:
            head = {"body": body, "experiment": experiment, "mesh": "x".join(map(str, mesh)), "nu": float(nu),
                    "model": name, "fem_element": fem["element"]}
            rows += [{**head, **r} for r in model_rows(spec.replace(model=name).build(), fem)]
    return rows


def summary(pairs: pd.DataFrame) -> pd.DataFrame:
    """Per model and ν (in the rows' order): the first bending, torsion and axial mode's error and
    the lowest MAC (:func:`studies.sweep.mode_pairs.first_of_kinds`), the model's eigen-solve time."""
    out = []
    for (model, nu), grp in pairs.groupby(["model", "nu"], sort=False):
        recs = grp.to_dict("records")
        ok = [r for r in recs if r["status"] in ("ok", "unpaired")]  # a row per FEM mode
        row = {"body": recs[0]["body"], "mesh": recs[0]["mesh"], "nu": nu, "model": model,
               "fem_element": recs[0]["fem_element"], "status": "ok" if ok else recs[0]["status"]}
        row.update(first_of_kinds(ok))
        row["model_time_s"] = ok[0]["model_time_s"] if ok else None
        row["fem_time_s"] = ok[0]["fem_time_s"] if ok else None
        row["modes"] = len(ok)
        out.append(row)
    return pd.DataFrame(out)


def _pair_job(job: tuple) -> list[dict]:
    """The rows of one body at one ν (a worker's share of :func:`run`)."""
    body, quick, nu = job
    return pair_rows(body, quick, nus=(nu,))


def run(store, quick: bool = False, jobs: int | None = None, progress: bool = True, *, runner=None) -> dict:
    """Study driver (``EXTRA_STUDIES``): writes ``modes_pairs``, ``modes_cube`` and ``modes_beam``;
    each body at each ν on one of ``jobs`` processes (the rows in the order of a serial run)."""
    from studies.sweep.executors import map_local

    work = [(body, quick, nu) for body in BODIES for nu in NUS]
    done = dict(zip(work, map_local(_pair_job, work, jobs, runner)))
    tables, pairs = {}, []
    for body in BODIES:
        rows = pd.DataFrame([r for nu in NUS for r in done[(body, quick, nu)]])
        pairs.append(rows)
        tables[f"modes_{body}"] = summary(rows)
    tables["modes_pairs"] = pd.concat(pairs, ignore_index=True)
    for name, t in tables.items():
        store.write_table(name, t)
    return tables
