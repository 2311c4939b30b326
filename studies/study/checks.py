"""Whole-file checks of a user's study that need more than one key: what the machine can hold and
how long the runs would take (before the body is voxelized), whether the voxel body is the body
the file gave, whether the supports of a load case agree, and whether every model can run every
configuration.  Each refusal is a :class:`StudyError` naming the key to change.

The body checks compare volumes.  A closed surface encloses ``V = |Σ_t a_t · (b_t × c_t)| / 6``
(the divergence theorem over its triangles ``(a, b, c)``); a mask holds ``V = n_voxels · Π spacing``.
A voxel body of ``n`` cells of edge ``l`` has ``n l³``.  Each of its cells whose centre is on the
wrong side of the boundary lies within half a cell diagonal of it, so a body drawn faithfully
differs from the source by at most the volume of a shell of that half-thickness on each side,
``|n l³ − V| ≤ A (l + h) √3 / 2`` (``A`` the source's surface area, ``h`` the mask's largest
spacing, 0 for a surface): past it the voxels are not the body (a cell far coarser than the
image, a surface that does not bound one solid).  A closed surface that does not cross itself
has the generalized winding number ``w = Σ_t Ω_t / 4π`` equal to 0 or ±1 (one sign) at every point
off it; a winding number of 2 (overlapping shells, whose overlap the ray parity leaves out) or of
both signs (a surface turned through itself) is refused, checked at up to
:data:`WINDING_POINTS` cell centres of the grid."""

from __future__ import annotations

import math
import os

import numpy as np

from studies.sweep import sizing
from studies.study.errors import StudyError
from studies.study.tasks import timed_repeats

E_RANGE = (1e-3, 1e13)
"""Young's moduli a study accepts, Pa: from below the softest gels (about 10 Pa) to above diamond
(1.2e12 Pa).  Outside it the solvers' float64 forces, stiffnesses and time steps lose their digits
(E = 1e300 overflows a plate force to -inf)."""
RHO_MAX = 1e5
"""The largest density a study accepts, kg/m³ (osmium, the densest element: 22,590)."""
POSITION_CELLS = 1e9
"""How many cell sizes from 0 a body's coordinates may reach (float64 keeps 16 digits: 7 left of a
cell's edge)."""
WINDING_WORK = 2e6
"""Point-triangle pairs the winding-number check of a surface evaluates (nut.ply, 1,046 triangles:
1,912 points, 0.9 s at load average 7)."""
WINDING_POINTS = 20_000
"""The most grid cell centres the winding-number check evaluates (evenly drawn when there are
more, the same ones at every run)."""


# ---------------------------------------------------------------------------- memory and time
def run_estimates(shape, models, reference, materials) -> list[tuple[str, sizing.Estimate, int]]:
    """Each run a configuration of ``shape`` asks for: (the key that sets its size, its estimate,
    how many times it is solved: an untimed run and the timed repeats are counted by the caller)."""
    from studies.study.tasks import auto_refine_cap

    out = []
    for i, m in enumerate(models):
        work = sizing.model_work(dict(m.params), m.kind)
        key = f"model[{i}].solver.steps" if m.kind != "static" else "body.cell_sizes"
        out.append((key, sizing.mss(shape, m.kind, m.steps, work), 1))
    for nu in sorted({mat.nu for mat in materials}) if reference is not None else ():  # None: on tetrahedra
        refine = auto_refine_cap(shape, reference, nu) if reference.refine == "auto" else int(reference.refine)
        key = "reference.refine" if refine > 1 else "body.cell_sizes"
        out.append((key, sizing.fem(shape, reference.element, refine, reference.law, nu), 0))
    return out


def check_size(t, grid_shape, sizes, models, reference, materials) -> None:
    """Refuse cell sizes whose grid's runs would not fit this machine's memory
    (:func:`studies.sweep.sizing.fits`), before the body is voxelized (``grid_shape(le)``: the body's grid
    at cell size ``le``, :func:`studies.study.body.grid_shape`); the message gives the memory
    needed and the cell size from which the runs fit."""
    for le in sizes:
        shape = grid_shape(le)
        worst = max((e for _, e, _ in run_estimates(shape, models, reference, materials)), key=lambda e: e.bytes)
        if sizing.fits(worst) and sizing.fits(sizing.mss(shape)):
            continue
        fit = le
        for _ in range(400):
            fit *= 1.25
            est = run_estimates(grid_shape(fit), models, reference, materials)
            if all(sizing.fits(e) for _, e, _ in est):
                break
        shown = "x".join(map(str, shape))
        raise t.error("cell_sizes", sizes, f"cell sizes whose runs fit this machine's memory: at {le:g} m the "
                      f"body's grid is {shown} cells and the {worst.what} would need about "
                      f"{sizing.size(worst.bytes)}, allowed up to {sizing.size(sizing.limit())} "
                      f"({sizing.MEMORY_FRACTION:.0%} of {sizing.size(sizing.machine_memory())}); cell sizes "
                      f"of {fit:.3g} m or more fit")


def check_time(study, top) -> None:
    """Refuse a study one of whose runs would take over :data:`studies.sweep.sizing.TIME_LIMIT_S` (a
    model run with its timed repeats), or whose runs together would take over
    :data:`studies.sweep.sizing.SWEEP_TIME_LIMIT_S` on this machine's cores (the estimates of
    ``hybmss run``, :mod:`studies.sweep.sizing`), naming the key that sets it."""
    every = []
    for vox in study.voxels:
        reference = None if study.tet_sizes else study.reference  # a tetrahedral study's: studies.study.tet
        for key, est, timed in run_estimates(vox.body.shape, study.models, reference, study.materials):
            seconds = est.seconds * (1 + timed * timed_repeats(est.seconds, study.repeats))
            every.append(sizing.Estimate(est.what, est.bytes, seconds * len(study.load_cases)))
            if seconds > sizing.TIME_LIMIT_S:
                value = _value_of(study, key, top)
                raise StudyError(key, value, f"runs of up to {sizing.duration(sizing.TIME_LIMIT_S)}: at cell size "
                                 f"{vox.le:g} m the {est.what} would take about {sizing.duration(seconds)} "
                                 f"({1 + timed * study.repeats} solves, study.repeats = "
                                 f"{study.repeats})", top.file)
    whole = sizing.sweep("study", every, os.cpu_count() or 1)
    if not sizing.in_time(whole):
        raise StudyError("body.cell_sizes", list(study.cell_sizes), f"a study whose runs take up to "
                         f"{sizing.duration(whole.limit_s)} on this machine's {os.cpu_count() or 1} cores: these "
                         f"would take about {sizing.duration(whole.seconds)} (fewer or coarser cell sizes, "
                         "materials, models or study.repeats)", top.file)


def _value_of(study, key: str, top):
    if key.startswith("model["):
        return study.models[int(key[6:key.index("]")])].steps
    if key == "reference.refine":
        return study.reference.refine
    return list(study.cell_sizes)


# ---------------------------------------------------------------------------- the body
def surface_measures(vertices: np.ndarray, triangles: np.ndarray) -> tuple[float, float]:
    """Enclosed volume |Σ a·(b×c)|/6 and area of a closed triangle surface."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    volume = abs(float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum())) / 6.0
    area = float(np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()) / 2.0
    return volume, area


def mask_measures(keep: np.ndarray, spacing) -> tuple[float, float]:
    """Volume and boundary area of the voxels ``keep`` of an image with ``spacing``."""
    s = np.asarray(spacing, dtype=float)
    volume = float(keep.sum()) * float(np.prod(s))
    area = 0.0
    for d in range(3):
        padded = np.pad(keep, [(1, 1) if k == d else (0, 0) for k in range(3)])
        faces = np.count_nonzero(np.diff(padded.astype(np.int8), axis=d))
        area += faces * float(np.prod(np.delete(s, d)))
    return volume, area


def check_volume(t, sizes, vox, volume: float, area: float, spacing: float = 0.0) -> None:
    """Refuse a voxel body whose volume differs from its source's by more than the shell
    ``area (l + spacing) √3/2`` (module docstring)."""
    got = vox.body.n_cells * vox.le**3
    tol = area * (vox.le + spacing) * math.sqrt(3.0) / 2.0
    if abs(got - volume) > tol:
        raise t.error("cell_sizes", sizes, f"cell sizes whose cells draw the body: at {vox.le:g} m its "
                      f"{vox.body.n_cells} cells hold {got:.4g} m^3 where the body's source holds {volume:.4g} m^3 "
                      f"(allowed: within {tol:.3g} m^3, half a cell diagonal around its surface)")


def check_winding(t, key: str, vertices: np.ndarray, triangles: np.ndarray, le: float) -> None:
    """Refuse a surface that crosses itself: a winding number of 2 or more, or of both signs, at
    the centres of a grid of cells ``le`` over its bounding box (module docstring)."""
    from hybmss.voxelize import winding_number

    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    shape = np.maximum(1, np.ceil((hi - lo) / le - 1e-9).astype(int))
    n = int(np.prod(shape))
    k = int(min(n, WINDING_POINTS, max(1, WINDING_WORK // max(1, len(triangles)))))
    idx = np.arange(n) if k == n else np.unique(np.linspace(0, n - 1, k).astype(np.int64))
    centres = lo + (np.column_stack(np.unravel_index(idx, tuple(shape))) + 0.5) * le
    w = np.rint(winding_number(centres, vertices, triangles))
    if np.abs(w).max(initial=0) >= 2 or (w.max(initial=0) > 0 and w.min(initial=0) < 0):
        where = centres[np.argmax(np.abs(w) >= 2)] if np.abs(w).max() >= 2 else centres[np.argmin(w)]
        raise t.error(key, t.data[key], f"a closed surface that does not cross itself (its winding number "
                      f"ranges from {int(w.min())} to {int(w.max())} over its grid's cell centres: "
                      f"{int(w[np.argmin(np.abs(where - centres).sum(axis=1))])} at {np.round(where, 6).tolist()})")


def check_digits(t, key: str, vox) -> None:
    """Refuse a body whose coordinates are more than :data:`POSITION_CELLS` cell sizes from 0:
    float64 positions there keep fewer than 7 digits of a cell's edge (the lattice's springs and
    the FEM's Jacobians are differences of such positions)."""
    far = float(np.max(np.abs(np.asarray(vox.body.bounds, dtype=float))))
    if far > POSITION_CELLS * vox.le:
        raise t.error(key, t.data[key], f"a body within {POSITION_CELLS:g} cell sizes of the origin (its "
                      f"coordinates reach {far:.3g} m at cell size {vox.le:g} m: positions would lose a cell's "
                      "digits)")


def check_extent(t, sizes, image_shape, spacing) -> None:
    """Refuse a cell size larger than a mask's extent along an axis (the image would be one cell
    wide there, whatever it holds)."""
    extent = np.asarray(image_shape) * np.asarray(spacing, dtype=float)
    for le in sizes:
        if np.any(le > extent * (1 + 1e-9)):
            raise t.error("cell_sizes", sizes, f"cell sizes no larger than the mask's extent {extent.tolist()} m "
                          f"(image shape × body.spacing); {le:g} m is larger")


# ---------------------------------------------------------------------------- supports and models
def check_supports_agree(top, where: str, vox, X: np.ndarray, plates) -> None:
    """Refuse two supports that prescribe different displacements to a component of the same
    node (compared at full and half load), and supports that prescribe every component of every
    node (nothing is left to solve for)."""
    tol = 1e-9 * max(float(np.ptp(X, axis=0).max()), 1e-300)
    for b in range(len(plates)):
        for a in range(b):
            gap, shared = _disagreement(X, plates[a], plates[b])
            if gap > tol:
                pa, pb = plates[a][0], plates[b][0]
                raise StudyError(f"{where}.support[{b}].region", _region(pb.region), f"a region whose nodes no "
                                 f"other support moves otherwise: {shared} of the nodes of {pb.name!r} "
                                 f"({pb.motion.kind}) are also held by support[{a}] {pa.name!r} "
                                 f"({pa.motion.kind}), whose motion differs by up to {gap:.3g} m (at cell size "
                                 f"{vox.le:g} m)", top.file)
    given = np.zeros((len(X), 3), dtype=bool)
    for plate, sel in plates:
        given[sel] |= plate.motion.constrained
    if given.all():
        raise StudyError(f"{where}.support", [p.name for p, _ in plates], f"supports that leave some node free: "
                         f"these prescribe every component of all {len(X)} nodes (at cell size {vox.le:g} m), so "
                         "there is nothing to solve", top.file)


def _disagreement(X, first, second) -> tuple[float, int]:
    """The largest difference of two supports' prescribed displacements over the components both
    prescribe at the nodes both hold (full and half load), and how many nodes they share."""
    (pa, sa), (pb, sb) = first, second
    both = sa & sb
    comps = pa.motion.constrained & pb.motion.constrained
    if not both.any() or not comps.any():
        return 0.0, int(both.sum())
    gap = 0.0
    for s in (1.0, 0.5):
        ua, ub = np.zeros((len(X), 3)), np.zeros((len(X), 3))
        ua[sa] = pa.motion.displacement_at(X[sa], s)  # a rotation about its own plate's centroid
        ub[sb] = pb.motion.displacement_at(X[sb], s)
        gap = max(gap, float(np.abs(ua[both][:, comps] - ub[both][:, comps]).max()))
    return gap, int(both.sum())


def _region(region) -> str:
    parts = {"face": region.face, "box": None if region.lo is None else [list(region.lo), list(region.hi)],
             "label": "cells" if region.cells is not None else None, "patch": region.patch}
    return str({k: v for k, v in parts.items() if v is not None})


def model_refusal(scene, kind: str) -> str | None:
    """Why the model of ``scene`` refuses to run it with a ``kind`` solver, asked of the solvers'
    own checks before any work: the Newton solvers' Poisson-ratio range
    (:func:`hybmss.scene.check_nu`, for the harness's static and implicit solves), an engine's
    refusals (its ``_check``: what it cannot represent, surface loads) and the mass an explicit run
    needs.  None if it runs."""
    from hybmss.scene import check_nu

    spec = scene.model.spec
    try:
        if kind == "implicit" or (kind == "static" and spec.solve_static is None):
            check_nu(scene.material.nu)
        own = getattr(spec, "_check", None)
        if own is not None:
            own(scene)
    except ValueError as exc:
        return " ".join(str(exc).split())
    if kind == "explicit" and scene.material.rho <= 0:
        return "explicit dynamics needs rho > 0 (every particle must have mass)"
    return None


def check_models(study, top) -> None:
    """Refuse a model that cannot run a configuration of the study (:func:`model_refusal`),
    naming the key of the material or load the model refuses, else the model."""
    from hybmss.scene import Model, Scene

    vox = study.voxels[0]
    for c, case in enumerate(study.load_cases):
        plates = tuple(s.plate(vox.labels) for s in case.supports)
        loads = tuple(t.load(vox.labels) for t in case.tractions)
        for mat in study.materials:
            for i, run in enumerate(study.models):
                scene = Scene(vox.body, mat, Model(run.name, **dict(run.params)), plates, case.gravity,
                              run.damping, "check", loads)
                why = model_refusal(scene, run.kind)
                if why is None:
                    continue
                key, value = f"model[{i}].name", run.name
                if why.startswith("nu"):
                    key, value = "material.nu", mat.nu
                elif why.startswith("loads"):
                    key, value = f"load_case[{c}].traction", [list(t.traction) for t in case.tractions]
                elif "rho" in why:
                    key, value = "material.rho", mat.rho
                raise StudyError(key, value, f"what model[{i}] ({run.label}, {run.kind} solver) can run: {why}",
                                 top.file)
