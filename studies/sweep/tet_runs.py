"""Runs on a tetrahedral body (:class:`hybmss.tetbody.TetBody`): an engine stepped on the body's
own tetrahedra, and the FEM reference solved on the same tetrahedra.

Both are scene holders for :class:`studies.sweep.runner.Task` with their own ``digest`` (the
tetrahedra, the material, the supports, the model), ``solve`` and ``arrays``:

- :class:`TetEngineScene`: :meth:`hybmss.models._engine_model.EngineModel.solve_tets`, the rest
  state of the engine's damped run; its volume change is that of the deformed tetrahedra,
  ``Σ V_t(x) / Σ V_t(X) − 1``.  Timed once (the run is its own rest search).
- :class:`TetReferenceScene`: :class:`fem_reference.tet.TetProblem` (P2; the P2–P1 mixed element
  for ν ≥ :data:`hybmss.scene.NEARLY_INCOMPRESSIBLE_NU`) on the tetrahedra split ``log2(refine)``
  times (``h → h/refine``, the faceted body unchanged), or with ``auto`` on ``h, h/2, …`` until
  the Richardson estimate of its own error (expected order 3) is below its target: max |u| on
  itself, each support's force and torque norms on the load's force scale ``F_load`` and
  ``F_load R_s`` (as :func:`studies.study.tasks.reference_estimate` does for hexahedra).  Its
  stored arrays are the P2 field (mesh ``p``, ``t`` and nodal values ``U``), so a model's nodes
  are sampled where they lie (:func:`reference_solution`); its volume change is the linear
  ``∫ div u dx / V``.

A support is a :class:`NodeRegion` (a face of the body's bounding box and/or a box, picklable)
with a :class:`hybmss.scene.Motion` prescribing all three components of the nodes it selects.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import numpy as np

TET_REFINES = (1, 2, 4)
"""The reference's refinements on tetrahedra: each split of a tetrahedron into eight halves h."""
TET_EXPECTED_ORDER = 3.0
FACE_TOL = 1e-6
"""A node is on a face of the bounding box within this fraction of the body's extent."""


@dataclass(frozen=True)
class NodeRegion:
    """Nodes on a face of the body's bounding box (``face``, e.g. ``"z-"``, the body's own
    ``bounds``) and/or in the box ``lo``–``hi`` (m); called on points (n, 3) -> bool (n,)."""

    bounds: tuple[tuple[float, float, float], tuple[float, float, float]]
    face: str | None = None
    lo: tuple[float, float, float] | None = None
    hi: tuple[float, float, float] | None = None

    def __call__(self, X: np.ndarray) -> np.ndarray:
        X = np.asarray(X, float)
        lo, hi = (np.asarray(b, float) for b in self.bounds)
        tol = FACE_TOL * float((hi - lo).max())
        sel = np.ones(len(X), bool)
        if self.face is not None:
            ax = "xyz".index(self.face[0])
            target = hi[ax] if self.face[1] == "+" else lo[ax]
            sel &= np.abs(X[:, ax] - target) <= tol
        if self.lo is not None:
            sel &= np.all(X >= np.asarray(self.lo) - tol, axis=1) & np.all(X <= np.asarray(self.hi) + tol, axis=1)
        return sel

    def columns(self, x: np.ndarray) -> np.ndarray:
        """The same on points as columns (3, k) (:class:`fem_reference.tet.Support`'s ``where``)."""
        return self(np.asarray(x).T)


@dataclass(frozen=True)
class TetSupport:
    name: str
    region: NodeRegion
    motion: object  # hybmss.scene.Motion, all three components

    def describe(self) -> str:
        return repr((self.name, self.region, self.motion))


def body_digest(body) -> str:
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(body.X, float).tobytes())
    h.update(np.ascontiguousarray(body.tets, np.int64).tobytes())
    return h.hexdigest()[:24]


def _digest(*parts) -> str:
    return hashlib.sha256(repr(parts).encode()).hexdigest()[:24]


@dataclass(frozen=True, eq=False)
class _TetScene:
    body: object  # hybmss.tetbody.TetBody
    material: object
    supports: tuple[TetSupport, ...]
    study: str
    load_case: str
    cell_size: float  # the tetrahedra's target edge length h
    label: str

    experiment = "study"

    @property
    def nu(self) -> float:
        return self.material.nu

    @property
    def mesh(self) -> tuple[int, int, int]:
        return (self.body.n_tets, 1, 1)

    def expected_cost(self, solver) -> float:
        return float(self.body.n_tets) * (30.0 if solver.kind == "fem" else 10.0)

    def _base_dict(self) -> dict:
        m = self.material
        return {"experiment": "study", "load_case": self.load_case, "cell_size": self.cell_size,
                "mesh": f"tets {self.body.n_tets}", "cells": self.body.n_tets, "E": m.E, "nu": m.nu,
                "rho": m.rho, "variant": self.label}


@dataclass(frozen=True, eq=False)
class TetEngineScene(_TetScene):
    """An engine model (registry ``name``) on the body's tetrahedra (module docstring)."""

    name: str = ""

    @property
    def model(self) -> str:
        return self.name

    def digest(self) -> str:
        m = self.material
        return _digest("tet-engine", body_digest(self.body), m.E, m.nu, m.rho, self.name,
                       [s.describe() for s in self.supports])

    def to_dict(self) -> dict:
        return {**self._base_dict(), "model": self.name, "repeats": 1}

    def solve(self, solver):
        from hybmss import models
        from hybmss.models._engine_tet import TetHold
        from hybmss.result import Result
        from hybmss.tetbody import signed_volumes

        holds = [TetHold(s.name, s.region, s.motion) for s in self.supports]
        rest = models.get(self.name).solve_tets(self.body, self.material, holds)
        tets = np.asarray(self.body.tets)
        V0 = float(signed_volumes(rest.X, tets).sum())
        V = float(signed_volumes(rest.X + rest.u, tets).sum())
        info = {k: v for k, v in rest.info.items() if isinstance(v, (int, float, str, bool))}
        info.update(equilibrium_error=float(rest.equilibrium_error), steps=int(rest.steps), dt=float(rest.dt),
                    time_s=float(rest.wall_time_s), time_repeats=1, tets=int(len(tets)))
        warnings = rest.info.get("engine_warnings") or []
        if warnings:
            info["warning"] = " | ".join(map(str, warnings))[:500]
        res = Result(f"engine-tets-{self.name}", self.digest(), rest.X, rest.u, V, V0, dict(rest.reactions), {},
                     int(rest.steps), float(rest.wall_time_s), bool(rest.converged), None, info)
        _reaction_info(res)
        return res

    def arrays(self, res) -> dict:
        return {"X": res.X, "u": res.u, "tets": np.asarray(self.body.tets)}


@dataclass(frozen=True, eq=False)
class TetReferenceScene(_TetScene):
    """The FEM on the body's tetrahedra: ``refine`` in :data:`TET_REFINES`, or ``auto`` with
    ``target`` (module docstring)."""

    refine: int | str = 1
    target: float = math.inf
    largest: int = TET_REFINES[-1]
    """The finest refinement ``auto`` may reach (the finest that fits the machine's memory)."""

    model = "fem-tet"

    @property
    def key_extra(self) -> dict:
        auto = self.refine == "auto"
        return {"refine": self.refine, "target": self.target if auto else None, "largest": self.largest if auto else None}

    def digest(self) -> str:
        m = self.material
        return _digest("tet-fem", body_digest(self.body), m.E, m.nu, m.rho,
                       [s.describe() for s in self.supports])

    def to_dict(self) -> dict:
        return {**self._base_dict(), "model": "fem-tet", "repeats": 1}

    @property
    def formulation(self) -> str:
        from hybmss.scene import NEARLY_INCOMPRESSIBLE_NU

        return "mixed" if self.material.nu >= NEARLY_INCOMPRESSIBLE_NU else "p2"

    def fem_supports(self):
        from fem_reference.tet import Support

        return [Support(s.name, s.region.columns, _MotionField(s.motion)) for s in self.supports]

    def solve(self, solver):
        from fem_reference.tet import TetProblem, as_mesh

        mesh, sols = as_mesh(self.body), []
        refines = [r for r in TET_REFINES if r <= (self.largest if self.refine == "auto" else self.refine)]
        estimate = math.nan
        for i, r in enumerate(refines):
            if i:
                mesh = mesh.refined()
            sols.append(TetProblem(mesh, self.formulation).solve(self.material, self.fem_supports()))
            if len(sols) >= 2:
                estimate = self.estimate(sols, refines[: len(sols)])
                if self.refine == "auto" and estimate <= self.target:
                    break
        return self._result(sols[-1], refines[len(sols) - 1], estimate, sum(s.wall_time_s for s in sols))

    def estimate(self, sols, refines) -> float:
        """The largest Richardson estimate of the finest solution's error (module docstring)."""
        from fem_reference.convergence import analyze

        def err(q) -> float:
            return analyze(refines, [q(s) for s in sols], TET_EXPECTED_ORDER).error_finest

        last = sols[-1]
        radii = {s.name: support_radius(last, s) for s in self.supports}
        force = max([0.0] + [max(_norm(last.reactions[n].force), _norm(last.reactions[n].torque) / R)
                             for n, R in radii.items()])
        out = [analyze(refines, [float(np.linalg.norm(s.U, axis=1).max()) for s in sols],
                       TET_EXPECTED_ORDER).relative_error_finest]
        for n, R in radii.items():
            if force > 0:
                out.append(err(lambda s, n=n: _norm(s.reactions[n].force)) / force)
                out.append(err(lambda s, n=n: _norm(s.reactions[n].torque)) / (force * R))
        return float(max(out)) if np.isfinite(out).all() else math.inf

    def _result(self, sol, refine: int, estimate: float, wall: float):
        from hybmss.result import Result
        from skfem import Functional
        from skfem.helpers import div

        prob = sol.problem
        nodal = prob.basis.nodal_dofs[0]
        X, u = prob.mesh.p.T.copy(), sol.U[nodal]
        V0 = float(Functional(lambda w: 1.0 + 0.0 * w.x[0]).assemble(prob.basis))
        dV = float(Functional(lambda w: div(w["u"])).assemble(prob.vbasis, u=prob.vbasis.interpolate(sol.U.ravel())))
        info = {"element": f"tet-{sol.problem.formulation}", "reference_refine": int(refine), "refine": int(refine),
                "reference_error_estimate": float(estimate), "reference_error_target": float(self.target),
                "tets": int(prob.mesh.t.shape[1]), "time_s": float(wall), "time_repeats": 1}
        res = Result(f"fem-tet-{prob.formulation}", self.digest(), X, u, V0 + dV, V0, dict(sol.reactions),
                     {"strain": sol.energy}, 1, float(wall), True, None, info)
        _reaction_info(res)
        info["field"] = (prob.mesh.t.T.copy(), sol.U)  # not a scalar: kept off the row, stored as arrays
        return res

    def arrays(self, res) -> dict:
        tets, U = res.info["field"]
        return {"X": res.X, "u": res.u, "tets": tets, "U": U}


@dataclass(frozen=True)
class _MotionField:
    """``ū(x)`` of a motion at full load on points as columns (3, k) (picklable)."""

    motion: object

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(self.motion.displacement_at(np.asarray(x).T, 1.0), float).T


def reference_solution(arrays: dict, formulation: str):
    """The stored P2 field of a :class:`TetReferenceScene` as a
    :class:`fem_reference.tet.TetSolution` (for :meth:`~fem_reference.tet.TetSolution.sample`)."""
    from fem_reference.tet import TetProblem, TetSolution
    from skfem import MeshTet

    mesh = MeshTet(np.ascontiguousarray(arrays["X"].T), np.ascontiguousarray(arrays["tets"].T))
    return TetSolution(TetProblem(mesh, formulation), np.asarray(arrays["U"]), None, {}, 0.0, 0.0)


def support_radius(sol, support: TetSupport) -> float:
    """The lever arm of a support's torque: the largest distance of its vertices from their
    centroid (the reference mesh's vertices it selects)."""
    P = sol.problem.mesh.p.T
    P = P[support.region(P)]
    if len(P) == 0:
        return sol.problem.h
    r = float(np.linalg.norm(P - P.mean(axis=0), axis=1).max())
    return r if r > 0 else sol.problem.h


def _norm(v) -> float:
    return float(np.linalg.norm(np.asarray(v, float)))


def _reaction_info(res) -> None:
    for name, r in res.reactions.items():
        for c, v in zip("xyz", r.force):
            res.info[f"reaction_{name}_f{c}"] = float(v)
        for c, v in zip("xyz", r.torque):
            res.info[f"reaction_{name}_t{c}"] = float(v)
