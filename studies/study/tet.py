"""A study body as conforming tetrahedra: ``[body] tet_sizes`` (docs/study-format.md).

A surface body (``mesh`` or ``pyvista``) with ``tet_sizes = [h, ...]`` (m, coarse to fine) is
meshed by gmsh at each target edge length (:func:`hybmss.tetbody.mesh_surface`: inverted or
degenerate tetrahedra refused with their counts).  Then

- the engines that run on a tetrahedral body (:func:`tet_engines`: the registry's engine models
  whose ``tet_body_refused`` is empty) run on the tetrahedra of every size
  (:class:`studies.sweep.tet_runs.TetEngineScene`); every other model runs on its voxels at every
  cell size, and a model that refuses tetrahedra says so in its rows' ``note``;
- ONE FEM reference per load case × material is solved on the finest tetrahedra
  (:class:`studies.sweep.tet_runs.TetReferenceScene`: P2, mixed near ν = ½; ``reference.refine``
  1, 2, 4 or ``auto``), and every model is scored against its field sampled at the model's nodes
  (:mod:`studies.study.tet_scores`).

What a tetrahedral body cannot take is refused before any work (exit 2, the key named): a box or
mask source, ``body.origin``, a nonlinear ``reference.law`` (the tetrahedral reference is
small-strain linear elasticity), ``reference.refine = 3``, gravity, tractions, released
transients and modes, a ``slide`` support (an engine's tetrahedral hold prescribes all three
components) and a region by label or patch; a support must select nodes of every tetrahedral
mesh, and the supports must hold it against the six rigid motions."""

from __future__ import annotations

import dataclasses

import numpy as np

from studies.study.errors import StudyError
from studies.study.keys import Table
from studies.study.regions import held_modes
from studies.sweep import sizing
from studies.sweep.tet_runs import TET_REFINES, NodeRegion, TetEngineScene, TetReferenceScene, TetSupport

TET_SOURCES = ("mesh", "pyvista")


def tet_engines() -> tuple[str, ...]:
    """The registered engine models that run on a tetrahedral body (``tet_body_refused`` says
    nothing: MuJoCo's box kinds and Newton's XPBD refuse one)."""
    from hybmss import models
    from hybmss.models._engine_model import EngineModel

    return tuple(n for n in models.names() if isinstance(m := models.get(n), EngineModel)
                 and not m.tet_body_refused())


def tet_refusal(name: str) -> str:
    """Why model ``name`` keeps its voxels in a tetrahedral study (``""``: it runs on the tetrahedra)."""
    from hybmss import models
    from hybmss.models._engine_model import EngineModel

    m = models.get(name)
    if not isinstance(m, EngineModel):
        return ""  # a lattice model: its voxels are its own mesh
    return m.tet_body_refused()


def read_tet_sizes(t: Table, source) -> tuple[float, ...]:
    """``tet_sizes`` of ``[body]`` (none: ``()``), coarse to fine, for a surface source."""
    if not t.has("tet_sizes"):
        return ()
    sizes = t.numbers("tet_sizes", required=True, lo=0.0, lo_open=True)
    if not sizes or sorted(sizes, reverse=True) != sizes or len(set(sizes)) != len(sizes):
        raise t.error("tet_sizes", sizes, "distinct tetrahedra edge lengths (m), coarse to fine (decreasing)")
    if source is None or source.kind not in TET_SOURCES:
        raise t.error("tet_sizes", sizes, f"tetrahedra of a surface body ({' or '.join(TET_SOURCES)}; "
                      f"not {getattr(source, 'kind', 'experiment')})")
    if t.has("origin"):
        raise t.error("origin", t.data["origin"], "no origin with tet_sizes: the tetrahedra keep the surface's "
                      "own coordinates")
    return tuple(sizes)


def mesh_tets(t: Table, source, sizes) -> tuple:
    """The :class:`hybmss.tetbody.TetBody` of every size (gmsh), refused with the mesher's reason."""
    from hybmss.tetbody import TetMeshError, mesh_surface

    import pyvista as pv

    surface = pv.read(source.path)  # read before: the body check (studies.study.body)
    if source.scale != 1.0:
        surface = surface.scale(source.scale)
    bodies = []
    for h in sizes:
        try:
            bodies.append(mesh_surface(surface, h))
        except (TetMeshError, ImportError, ValueError) as exc:
            raise t.error("tet_sizes", list(sizes), f"sizes gmsh meshes the surface at ({h:g} m: "
                          f"{' '.join(str(exc).split())})") from None
    return tuple(bodies)


def reference_size(body, refine: int, nu: float) -> sizing.Estimate:
    """The memory and time of the tetrahedral reference on ``body`` refined ``refine`` times in h
    (:func:`studies.sweep.sizing.fem_of`): 3 unknowns per P2 node (vertex and edge midpoint), plus a
    pressure per vertex for the mixed element, counted exactly through each split of every
    tetrahedron into eight: (V, E, F, T) -> (V + E, 2E + 3F + T, 4F + 8T, 8T)."""
    from hybmss.scene import NEARLY_INCOMPRESSIBLE_NU

    t = np.sort(np.asarray(body.tets), axis=1)
    edges = len(np.unique(t[:, [0, 0, 0, 1, 1, 2, 1, 2, 3, 2, 3, 3]].reshape(-1, 2, 6).transpose(0, 2, 1)
                          .reshape(-1, 2), axis=0))
    faces = len(np.unique(t[:, [0, 1, 2, 0, 1, 3, 0, 2, 3, 1, 2, 3]].reshape(-1, 3), axis=0))
    V, E, F, T = len(body.X), edges, faces, len(t)
    for _ in range(int(refine).bit_length() - 1):  # refine 1, 2, 4: 0, 1, 2 splits
        V, E, F, T = V + E, 2 * E + 3 * F + T, 4 * F + 8 * T, 8 * T
    pressures = V if nu >= NEARLY_INCOMPRESSIBLE_NU else 0
    return sizing.fem_of(3 * (V + E) + pressures, "hex2", "linear", "tetrahedral FEM reference")


def auto_largest(body, nu: float) -> int:
    """The finest of :data:`TET_REFINES` whose reference fits this machine's memory (the first if none
    does, which :func:`check_tet_study` refuses)."""
    return max([r for r in TET_REFINES if sizing.fits(reference_size(body, r, nu))], default=TET_REFINES[0])


def check_tet_study(study, top: Table) -> None:
    """What a tetrahedral body cannot take (module docstring), before any work."""
    ref = study.reference
    if ref.law != "linear":
        raise StudyError("reference.law", ref.law, "linear with body.tet_sizes (the tetrahedral FEM reference "
                         "is small-strain; a Neo-Hookean or SVK law needs a voxel body)", top.file)
    if ref.refine != "auto" and ref.refine not in TET_REFINES:
        raise StudyError("reference.refine", ref.refine, "1, 2, 4 or \"auto\" with body.tet_sizes (a split "
                         "tetrahedron halves h)", top.file)
    if study.metrics.modes:
        raise StudyError("metrics.modes", study.metrics.modes, "0 with body.tet_sizes (modes are computed on "
                         "voxel bodies)", top.file)
    for i, case in enumerate(study.load_cases):
        where = f"load_case[{i}]"
        if any(case.gravity):
            raise StudyError(f"{where}.gravity", list(case.gravity), "[0, 0, 0] with body.tet_sizes (the engines "
                             "on tetrahedra are loaded by their supports only)", top.file)
        if case.tractions:
            raise StudyError(f"{where}.traction", len(case.tractions), "none with body.tet_sizes", top.file)
        if case.release is not None:
            raise StudyError(f"{where}.release", True, "false with body.tet_sizes", top.file)
        for j, s in enumerate(case.supports):
            if s.motion.kind not in ("clamped", "translate", "rotate"):
                raise StudyError(f"{where}.support[{j}].motion", s.motion.kind, "clamped, translate or rotate "
                                 "with body.tet_sizes (a hold on tetrahedra prescribes all three components)",
                                 top.file)
            if s.region.label is not None or s.region.patch is not None:
                raise StudyError(f"{where}.support[{j}].region", "label/patch", "a face and/or a box with "
                                 "body.tet_sizes", top.file)
        for body in study.tet_bodies:
            _check_held(study, top, where, case, body)

    finest = study.tet_bodies[-1]  # the reference's mesh: memory last, once the rest is allowed
    for mat in study.materials:
        refine = TET_REFINES[0] if ref.refine == "auto" else ref.refine
        est = reference_size(finest, refine, mat.nu)
        if not sizing.fits(est):
            key = "reference.refine" if refine != TET_REFINES[0] else "body.tet_sizes"
            raise StudyError(key, ref.refine if key == "reference.refine" else list(study.tet_sizes),
                             f"a reference that fits this machine's memory: at h {finest.h:g} m the {est.what} "
                             f"would need about {sizing.size(est.bytes)}, allowed {sizing.size(sizing.limit())}",
                             top.file)


def _check_held(study, top, where, case, body) -> None:
    supports = tet_supports(case, body)
    for j, s in enumerate(supports):
        if not s.region(body.X).any():
            raise StudyError(f"{where}.support[{j}].region", str(s.region.face or [s.region.lo, s.region.hi]),
                             f"a region that selects nodes of the tetrahedra (none at h {body.h:g} m)", top.file)
    held = held_modes(body.X, [(s.region(body.X), (0, 1, 2)) for s in supports])
    if held < 6:
        raise StudyError(f"{where}.support", [s.name for s in supports], f"supports that hold the tetrahedra "
                         f"(h {body.h:g} m) against the 6 rigid motions: these stop {held} of 6", top.file)


def tet_supports(case, body) -> tuple[TetSupport, ...]:
    """The supports of a load case on a tetrahedral body: its own bounding box for a face; a
    rotation without a centre turns about the selected nodes' centroid on ``body``."""
    bounds = (tuple(map(float, body.X.min(axis=0))), tuple(map(float, body.X.max(axis=0))))
    out = []
    for s in case.supports:
        lo, hi = s.region.box if s.region.box else (None, None)
        region = NodeRegion(bounds, s.region.face, lo, hi)
        motion = s.motion
        if motion.kind == "rotate" and motion.center is None:
            sel = region(body.X)
            centre = body.X[sel].mean(axis=0) if sel.any() else body.X.mean(axis=0)
            motion = dataclasses.replace(motion, center=tuple(map(float, centre)))
        out.append(TetSupport(s.name, region, motion))
    return tuple(out)


def tet_study_tasks(study, voxel_tasks) -> list:
    """The runs of a tetrahedral study: every tetrahedral engine on the tetrahedra of each size,
    every other model on its voxels (``voxel_tasks(run, case, mat)``), then one reference per
    load case × material on the finest tetrahedra."""
    from studies.sweep.runner import SolverSpec, Task

    engines = set(tet_engines())
    finest = study.tet_bodies[-1]
    tasks, refs = [], []
    for case in study.load_cases:
        # a rotation without a centre: the same centre for every mesh (the coarsest's held nodes)
        supports = tet_supports(case, study.tet_bodies[0])
        for mat in study.materials:
            for run in study.models:
                if run.name not in engines:
                    tasks += voxel_tasks(run, case, mat)
                    continue
                for body in study.tet_bodies:
                    scene = TetEngineScene(body, mat, _on(supports, body), study.name, case.name, body.h, run.label,
                                           name=run.name)
                    tasks.append(Task(scene, SolverSpec("static"), study.name))
            ref = study.reference
            target = ref.tolerance * min(study.budgets)
            scene = TetReferenceScene(finest, mat, _on(supports, finest), study.name, case.name, finest.h, "FEM",
                                      refine=ref.refine, target=target if ref.refine == "auto" else float("inf"),
                                      largest=auto_largest(finest, mat.nu))
            refs.append(Task(scene, SolverSpec("fem", element="tet", law="linear"), study.name))
    return tasks + refs


def _on(supports, body) -> tuple[TetSupport, ...]:
    """``supports`` with their faces taken on ``body``'s own bounding box."""
    bounds = (tuple(map(float, body.X.min(axis=0))), tuple(map(float, body.X.max(axis=0))))
    return tuple(dataclasses.replace(s, region=dataclasses.replace(s.region, bounds=bounds)) for s in supports)


def tet_notes(study) -> dict[str, str]:
    """Each model's label → its note in a tetrahedral study (a model that keeps its voxels says why)."""
    return {run.label: tet_refusal(run.name) for run in study.models}


__all__ = ["tet_engines", "read_tet_sizes", "mesh_tets", "check_tet_study", "tet_study_tasks", "tet_supports",
           "tet_notes"]
