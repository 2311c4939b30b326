"""One entry point: ``solve(scene, ...) -> Result``, the FEM reference of a Scene.

The mesh is the Scene's voxel body, each cell split into ``refine³`` elements; the plates give
the prescribed displacements (see :mod:`fem_reference.dirichlet`); gravity ``scene.gravity``
times ``material.rho`` is the body load.  The Result follows the MSS schema:

- ``X``, ``u``: lattice particles and the FEM displacement at them (vertex dofs);
- ``volume``: ``∫ det F dX`` for the finite-strain laws, ``∫ (1 + div u) dX`` for the linear
  law; ``info`` adds ``volume_detF`` (= ``∫ det(I + ∇u)`` also for the linear law),
  ``integral_lnJ`` (= ``∫ ln J dX``) and ``volume_mss_formula``, the averaged-edge volume
  ``Σ a·(b×c)`` of the lattice cells at the FEM particle positions (like-for-like with the MSS);
  ``cell_volumes`` are those per-cell volumes;
- ``reactions``: per plate, from the residual at its prescribed dofs;
- ``energy``: ``strain`` (``∫ ψ``, linear ``½ uᵀKu``) and ``gravity`` (``−∫ ρ g · u``);
- ``iterations``: Newton iterations (1 for a linear solve).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from hybmss.result import Result
from hybmss.scene import Scene, nearly_incompressible

from .dirichlet import plate_dirichlet
from .hyperelastic import ConvergenceError, Hyperelasticity
from .laws import LAWS
from .linear import FORMULATIONS, LinearElasticity
from .mesh import build_mesh

ELEMENT_CHOICES = ("auto",) + FORMULATIONS
LAW_CHOICES = ("linear",) + LAWS
def resolve_element(element: str, nu: float) -> str:
    """``'auto'`` → ``'mixed'`` for a nearly incompressible material
    (:func:`hybmss.scene.nearly_incompressible`, ν ≥ 0.45), else ``'hex2'``; other names are
    checked and kept."""
    if element not in ELEMENT_CHOICES:
        raise ValueError(f"element must be one of {', '.join(ELEMENT_CHOICES)}; got {element!r}")
    if element == "auto":
        return "mixed" if nearly_incompressible(nu) else "hex2"
    return element


def operators(scene: Scene, element: str = "auto", law: str = "linear", refine: int = 1):
    """The assembled-once operators for ``scene``'s body; pass them to :func:`solve` as
    ``operators=`` to reuse the assembly across materials (e.g. a sweep over ν)."""
    if law not in LAW_CHOICES:
        raise ValueError(f"law must be one of {', '.join(LAW_CHOICES)}; got {law!r}")
    element = resolve_element(element, scene.material.nu)
    fmesh = build_mesh(scene.body, refine)
    if law == "linear":
        return LinearElasticity(fmesh, element)
    return Hyperelasticity(fmesh, element, law)


def solve(
    scene: Scene,
    element: str = "auto",
    law: str = "linear",
    refine: int = 1,
    steps: int | None = None,
    method: str = "auto",
    operators=None,
    strict: bool = True,
) -> Result:
    """FEM reference solution of ``scene``.

    Parameters
    ----------
    element : ``'hex1'``, ``'hex2'``, ``'mixed'`` (Hex2 × Hex1 u–p) or ``'auto'`` (mixed for
        ν ≥ 0.45, else Hex2).
    law : ``'linear'`` (small strain), ``'neo-hookean'`` or ``'svk'`` (finite strain).
    refine : each cell of the body is split into ``refine³`` elements.
    steps : load steps of the finite-strain Newton solver (default 5; halved on failure).
    method : linear solver, ``'auto'`` (direct for small systems and, with CHOLMOD, for bodies
        whose nested-dissection separators are small; AMG-preconditioned Krylov above),
        ``'direct'`` (a factorization; SuperLU for the mixed element) or ``'amg'``.
    operators : operators from :func:`operators` to reuse (must match body, element, law, refine).
    strict : if Newton fails, raise :class:`~fem_reference.hyperelastic.ConvergenceError`;
        with ``strict=False`` return the last converged state with ``converged=False`` and
        ``info['load_factor']`` < 1 (its reactions and gravity are those of that load factor).
    """
    return _solve(scene, element, law, refine, steps, method, operators, strict)[0]


def solve_levels(scene: Scene, refinements, element: str = "auto", law: str = "linear",
                 steps: int | None = None, method: str = "auto", strict: bool = True):
    """The FEM reference of ``scene`` on each of ``refinements`` (increasing), one :class:`Result` at
    a time (a generator: stop taking them and no finer level is solved).  A finite-strain level
    starts its Newton solve from the solution of the level before, prolonged
    (:mod:`fem_reference.prolong`; ``info['started_from_refine']``); the answer does not depend on
    the start (it converges to the same tolerance), only its cost does."""
    previous = None
    for r in refinements:
        ops, start, prolong_s = None, None, 0.0
        if previous is not None and law != "linear":
            from .prolong import prolong

            t0 = time.perf_counter()
            ops = _checked_operators(scene, resolve_element(element, scene.material.nu), law, r, None)
            start = prolong(previous[0], ops, previous[1].U, previous[1].p)
            prolong_s = time.perf_counter() - t0
        res, ops, sol = _solve(scene, element, law, r, steps, method, ops, strict, start)
        if start is not None:  # the prolongation is part of the level's cost
            res.info.update(started_from_refine=previous[0].fmesh.refine, prolong_time_s=prolong_s)
            res = replace(res, wall_time_s=res.wall_time_s + prolong_s)
        previous = (ops, sol)
        yield res


def _solve(scene: Scene, element: str, law: str, refine: int, steps, method: str, operators, strict: bool,
           start=None):
    """:func:`solve`'s work: ``(Result, operators, solution)``; ``start``: the Newton solve's start
    state ``(U, p)`` at the full load."""
    t0 = time.perf_counter()
    if law not in LAW_CHOICES:
        raise ValueError(f"law must be one of {', '.join(LAW_CHOICES)}; got {law!r}")
    element = resolve_element(element, scene.material.nu)
    if int(refine) < 1:
        raise ValueError(f"refine must be an integer >= 1, got {refine!r}")
    if not scene.plates:
        raise ValueError("scene has no plate: the FEM needs prescribed displacements (rigid motions are free)")
    ops = _checked_operators(scene, element, law, refine, operators)
    space = ops.space
    dirichlet = plate_dirichlet(scene, space)
    if len(dirichlet.dofs) == 0:
        raise ValueError("the plates select no FEM node: check their regions")
    info: dict = {"element": element, "law": law, "refine": int(refine), "h": ops.fmesh.h,
                  "n_elements": int(ops.fmesh.mesh.t.shape[1]), "n_dofs": int(space.n_vector)}
    traction = None
    if scene.loads:  # dead surface tractions (Scene.loads)
        from .loads import load_vector

        traction = load_vector(scene, space)
        info["surface_load"] = [float(v) for v in traction.reshape(-1, 3).sum(axis=0)]
    sol, iterations, converged = _run(scene, ops, law, dirichlet, traction, steps, method, strict, info, start)
    if sol.p is not None:
        info["n_dofs"] += int(len(sol.p))
        info["pressure_range"] = [float(sol.p.min()), float(sol.p.max())]
    info["linear_solver"] = {"method": sol.stats.method, "iterations": sol.stats.iterations,
                             "solves": sol.stats.calls}
    return (_result(scene, ops, law, element, dirichlet, traction, sol, info, int(iterations), converged,
                    time.perf_counter() - t0), ops, sol)


def _checked_operators(scene: Scene, element: str, law: str, refine: int, ops):
    """``ops`` after checking that they fit ``scene``, ``element``, ``law`` and ``refine``, or new
    operators when ``ops`` is ``None``."""
    if ops is None:
        fmesh = build_mesh(scene.body, refine)
        return LinearElasticity(fmesh, element) if law == "linear" else Hyperelasticity(fmesh, element, law)
    if ops.fmesh.body != scene.body or ops.fmesh.refine != int(refine) or ops.formulation != element:
        raise ValueError("operators were built for another body, refinement or element")
    if (law == "linear") != isinstance(ops, LinearElasticity) or getattr(ops, "law", law) != law:
        raise ValueError("operators were built for another law")
    return ops


def _run(scene: Scene, ops, law: str, dirichlet, traction, steps, method: str, strict: bool, info: dict,
         start=None):
    """The linear solve or the Newton solve of ``scene``: ``(solution, iterations, converged)``;
    the Newton log and the load factor reached go to ``info``."""
    gravity = scene.gravity if scene.has_gravity else (0, 0, 0)
    if law == "linear":
        return ops.solve(scene.material, dirichlet, gravity, method=method, load=traction), 1, True
    load_factor, converged = 1.0, True
    try:
        sol, log = ops.solve(scene.material, dirichlet, gravity, steps=5 if steps is None else int(steps),
                             method=method, load=traction, start=start)
    except ConvergenceError as exc:
        if strict or exc.solution is None:
            raise ConvergenceError(f"{scene.name or 'scene'}: {exc}", exc.solution, exc.log,
                                   exc.load_factor) from None
        sol, log, load_factor, converged = exc.solution, exc.log, exc.load_factor, False
    info["load_factor"] = load_factor
    info["newton"] = {"steps": len(log.steps), "rejected_steps": log.rejected_steps,
                      "final_residuals": [float(r) for _, _, r in log.steps]}
    return sol, log.iterations, converged


def _result(scene: Scene, ops, law: str, element: str, dirichlet, traction, sol, info: dict,
            iterations: int, converged: bool, wall: float) -> Result:
    """The :class:`Result` of solution ``sol``: the lattice particles' displacements, volumes,
    reactions and energies (see the module's docstring)."""
    space, mat = ops.space, scene.material
    U = sol.U
    lattice = ops.fmesh.lattice
    u_p = U[space.particle_dofs]
    x_p = lattice.X + u_p
    gradu = np.moveaxis(space.grad(U), (0, 1), (-2, -1))
    J = np.linalg.det(np.eye(3) + gradu)
    V0 = scene.body.volume
    vol_detF = space.integrate(J)
    volume = V0 + space.integrate(np.trace(gradu, axis1=-2, axis2=-1)) if law == "linear" else vol_detF
    cellv = lattice.cell_volumes(x_p)
    info["volume_detF"] = float(vol_detF)
    info["integral_lnJ"] = float(space.integrate(np.log(J))) if np.all(J > 0) else float("nan")
    info["volume_mss_formula"] = float(cellv.sum())
    info["min_J"] = float(J.min())
    info["inverted_points"] = int(np.count_nonzero(J <= 0))
    s_load = info.get("load_factor", 1.0)
    body_load = s_load * mat.rho * np.asarray(scene.gravity) * V0 if scene.has_gravity else np.zeros(3)
    info["body_load"] = [float(b) for b in body_load]
    fext = space.body_load(s_load * mat.rho * np.asarray(scene.gravity)) if scene.has_gravity else None
    reactions = dirichlet.reactions(sol.r, U, x_p)
    energy = {"strain": float(sol.energy),
              "gravity": float(-(fext @ U.reshape(-1))) if fext is not None else 0.0}
    if traction is not None:
        energy["surface_load"] = float(-s_load * (traction @ U.reshape(-1)))
        info["surface_load"] = [s_load * v for v in info["surface_load"]]
    return Result(
        solver=f"fem-{element}-{law}",
        scene_digest=scene.digest(),
        X=lattice.X.copy(),
        u=u_p,
        volume=float(volume),
        volume0=float(V0),
        reactions=reactions,
        energy=energy,
        iterations=int(iterations),
        wall_time_s=wall,
        converged=converged,
        cell_volumes=cellv,
        info=info,
    )
