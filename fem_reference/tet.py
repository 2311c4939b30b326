"""FEM reference on tetrahedra: small-strain elasticity with scikit-fem's P1, P2 and P2–P1 elements.

On a :class:`~hybmss.tetbody.TetBody` (or a ``MeshTet``), find ``u`` with ``u = ū`` on the
supports such that for all ``v`` vanishing there

    ∫ λ div u div v + 2μ ε(u):ε(v) dx = ∫ ρ g · v dx,        ε(u) = ½(∇u + ∇uᵀ),

with ``u`` in ``ElementTetP1`` (``p1``) or the quadratic ``ElementTetP2`` (``p2``).  Near ν = ½
the mixed Taylor–Hood element (``mixed``: P2 displacement, continuous P1 pressure
``p = λ div u``) solves the symmetric saddle point

    ∫ 2μ ε(u):ε(v) dx + ∫ p div v dx = ∫ ρ g · v dx,     ∫ q div u dx − ∫ p q / λ dx = 0,

locking-free as λ → ∞ (it needs λ > 0).  A support holds the components it names of every
displacement dof whose location satisfies its predicate, at ``ū(x)``; its reaction (the force
the support exerts on the body and its torque about the support's centroid) is the residual
``r = K u − f`` (mixed: ``μ K_μ u + Bᵀ p − f``) summed over its dofs.

Refinement splits every tetrahedron into eight (``MeshTet.refined``: ``h → h/2``, the faceted
body unchanged); :func:`tet_convergence` solves on ``h, h/2, …`` and estimates the error of each
output by Richardson extrapolation (:func:`fem_reference.convergence.analyze`).
:meth:`TetSolution.sample` evaluates the displacement field at arbitrary points (the nodes of
another model's mesh) through the element containing each.

Finite strain (Neo-Hookean) is not provided here: :mod:`fem_reference.hyperelastic` is built on
the hexahedral spaces of :mod:`fem_reference.space`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import cached_property
from typing import Callable

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree
from skfem import Basis, BilinearForm, ElementTetP1, ElementTetP2, ElementVector, LinearForm, MeshTet, asm
from skfem.helpers import ddot, div, dot, sym_grad

from hybmss.result import Reaction, reaction_from_nodal
from hybmss.scene import Material

from .convergence import OutputConvergence, analyze
from .linalg import rigid_modes, solve_saddle, solve_spd

TET_FORMULATIONS = ("p1", "p2", "mixed")
EXPECTED_ORDER = {"p1": 2.0, "p2": 3.0, "mixed": 3.0}
_INTORDER = 2  # exact for the P2 stiffness, the P2–P1 coupling, the P1 mass and the P2 body load


@dataclass(frozen=True)
class Support:
    """Prescribed displacement ``ū = displacement(x)`` (x, ū: (3, k)) on the components
    ``components`` of the dofs whose location satisfies ``where(x) -> bool (k,)``."""

    name: str
    where: Callable[[np.ndarray], np.ndarray]
    displacement: Callable[[np.ndarray], np.ndarray] = field(default=lambda x: np.zeros_like(x))
    components: tuple[int, ...] = (0, 1, 2)


def clamp(name, where) -> Support:
    return Support(name, where)


def translate(name, where, d) -> Support:
    d = np.asarray(d, float)[:, None]
    return Support(name, where, lambda x: np.broadcast_to(d, x.shape).copy())


def rotate(name, where, angle: float, axis, center) -> Support:
    """Infinitesimal rotation ``ū = θ a × (x − c)`` (the rigid rotation of linear theory)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    c = np.asarray(center, float)[:, None]
    return Support(name, where, lambda x: angle * np.cross(a[:, None], x - c, axis=0))


def as_mesh(body) -> MeshTet:
    """``MeshTet`` of a :class:`~hybmss.tetbody.TetBody` (or a ``MeshTet`` as it is)."""
    if isinstance(body, MeshTet):
        return body
    return MeshTet(np.ascontiguousarray(body.X.T), np.ascontiguousarray(body.tets.T))


@dataclass
class TetSolution:
    """Nodal displacements ``U`` (n_scalar, 3) at ``basis.doflocs``, pressure ``p`` (mixed) or
    ``None``, the reactions per support, strain energy and wall time."""

    problem: "TetProblem"
    U: np.ndarray
    p: np.ndarray | None
    reactions: dict[str, Reaction]
    energy: float
    wall_time_s: float

    def sample(self, points, outside_tol: float = 1e-6) -> np.ndarray:
        """Displacement (k, 3) at ``points`` (k, 3): the element containing each point; a point
        outside the mesh by at most ``outside_tol`` × h (barycentric) is taken from the nearest
        element, farther ones raise ``ValueError`` with their count."""
        P = self.problem.probes(np.asarray(points, float), outside_tol)
        return np.asarray(P @ self.U)


@dataclass(frozen=True, eq=False)
class TetProblem:
    """A tetrahedral mesh and a formulation (``p1``, ``p2``, ``mixed``); material-independent
    operators assembled lazily once."""

    mesh: MeshTet
    formulation: str = "p2"

    def __post_init__(self):
        if self.formulation not in TET_FORMULATIONS:
            raise ValueError(f"element must be one of {', '.join(TET_FORMULATIONS)}; got {self.formulation!r}")

    @cached_property
    def basis(self) -> Basis:
        """Scalar displacement basis (one row of ``U`` per dof)."""
        elem = ElementTetP1() if self.formulation == "p1" else ElementTetP2()
        return Basis(self.mesh, elem, intorder=_INTORDER)

    @cached_property
    def vbasis(self) -> Basis:
        return self.basis.with_element(ElementVector(self.basis.elem))

    @cached_property
    def pbasis(self) -> Basis:
        return self.basis.with_element(ElementTetP1())

    @cached_property
    def nullspace(self) -> np.ndarray:
        return rigid_modes(self.basis.doflocs.T)

    @cached_property
    def h(self) -> float:
        """Mean edge length."""
        p, e = self.mesh.p, self.mesh.edges
        return float(np.linalg.norm(p[:, e[0]] - p[:, e[1]], axis=0).mean())

    @cached_property
    def parts(self) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        """``(K_λ, K_μ) = (∫ div u div v, ∫ 2 ε(u):ε(v))``."""
        klam = BilinearForm(lambda u, v, w: div(u) * div(v))
        kmu = BilinearForm(lambda u, v, w: 2.0 * ddot(sym_grad(u), sym_grad(v)))
        return asm(klam, self.vbasis).tocsr(), asm(kmu, self.vbasis).tocsr()

    @cached_property
    def divergence(self) -> sp.csr_matrix:
        """``B = ∫ q div u`` (pressure rows, displacement columns)."""
        return asm(BilinearForm(lambda u, q, w: div(u) * q), self.vbasis, self.pbasis).tocsr()

    @cached_property
    def pressure_mass(self) -> sp.csr_matrix:
        return asm(BilinearForm(lambda p, q, w: p * q), self.pbasis).tocsr()

    def _prescribed(self, supports) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Prescribed vector dofs, their values, and the scalar dofs of each support."""
        x = self.basis.doflocs
        dofs, vals, nodes = [], [], {}
        for s in supports:
            sel = np.flatnonzero(np.asarray(s.where(x), bool))
            if len(sel) == 0:
                raise ValueError(f"support {s.name!r} holds no node of the mesh")
            ubar = np.asarray(s.displacement(x[:, sel]), float).reshape(3, -1)
            for c in s.components:
                dofs.append(3 * sel + c)
                vals.append(ubar[c])
            nodes[s.name] = sel
        dofs, vals = np.concatenate(dofs), np.concatenate(vals)
        dofs, first = np.unique(dofs, return_index=True)
        return dofs, vals[first], nodes

    def solve(self, material: Material, supports, gravity=(0.0, 0.0, 0.0), method: str = "direct") -> TetSolution:
        """Solve with the supports' displacements and gravity (module docstring); ``method``: the
        linear solver of :mod:`fem_reference.linalg` (``direct``: CHOLMOD when installed, else
        SuperLU; ``amg``; ``auto`` chooses by the matrix size alone)."""
        t0 = time.perf_counter()
        D, uD, nodes = self._prescribed(supports)
        b = material.rho * np.asarray(gravity, float)
        f = asm(LinearForm(lambda v, w: dot(b[:, None, None] * np.ones_like(v), v)), self.vbasis)
        Klam, Kmu = self.parts
        lam, mu = material.lam, material.G
        if self.formulation != "mixed":
            K = (lam * Klam + mu * Kmu).tocsr()
            u = solve_spd(K, f, D, uD, self.nullspace, method=method)
            r, p = K @ u - f, None
            energy = 0.5 * u @ (K @ u)
        else:
            if lam <= 0:
                raise ValueError(f"the mixed element needs lambda > 0 (nu > 0), got nu = {material.nu}")
            A, B, C = (mu * Kmu).tocsr(), self.divergence, self.pressure_mass / lam
            u, p = solve_saddle(A, B, C, f, np.zeros(B.shape[0]), D, uD, self.nullspace,
                                schur_scale=1.0 / mu + 1.0 / lam, method=method)
            r = A @ u + B.T @ p - f
            energy = 0.5 * u @ (A @ u) + 0.5 * p @ (C @ p)
        R = r.reshape(-1, 3)
        X = self.basis.doflocs.T
        reactions = {name: reaction_from_nodal(X[sel], R[sel]) for name, sel in nodes.items()}
        return TetSolution(self, u.reshape(-1, 3), p, reactions, float(energy), time.perf_counter() - t0)

    @cached_property
    def _tree(self) -> cKDTree:
        return cKDTree(self.mesh.p[:, self.mesh.t].mean(axis=1).T)

    def locate(self, points: np.ndarray, outside_tol: float = 1e-6, k: int = 16) -> np.ndarray:
        """Element of each point (k, 3): of the ``k`` nearest by centroid, the one whose smallest
        barycentric coordinate is largest (the containing element when there is one)."""
        k = min(k, self.mesh.t.shape[1])
        _, cand = self._tree.query(points, k)
        cand = cand.reshape(len(points), k)
        p, t = self.mesh.p, self.mesh.t
        v0 = p[:, t[0]][:, cand]  # (3, n, k)
        M = np.stack([p[:, t[i]][:, cand] - v0 for i in (1, 2, 3)], axis=-1)  # (3, n, k, 3)
        rhs = points.T[:, :, None] - v0
        lam = np.linalg.solve(M.transpose(1, 2, 0, 3), rhs.transpose(1, 2, 0)[..., None])[..., 0]
        bary = np.concatenate([1.0 - lam.sum(-1, keepdims=True), lam], axis=-1)  # (n, k, 4)
        worst = bary.min(-1)
        best = worst.argmax(1)
        outside = worst[np.arange(len(points)), best] < -outside_tol
        if outside.any():
            raise ValueError(f"{int(outside.sum())} of {len(points)} points lie outside the tetrahedral mesh "
                             f"(beyond {outside_tol:g} in barycentric coordinates)")
        return cand[np.arange(len(points)), best]

    def places(self, points: np.ndarray, outside_tol: float = 1e-6) -> np.ndarray:
        """Which ``points`` (k, 3) :meth:`locate` finds an element for within ``outside_tol``
        (barycentric; among the 16 tetrahedra of nearest centroid)."""
        points = np.asarray(points, float)
        p, t = self.mesh.p, self.mesh.t
        v = p[:, t[:, self.locate(points, np.inf)]].transpose(2, 1, 0)  # (k, 4, 3)
        M = np.stack([v[:, i] - v[:, 0] for i in (1, 2, 3)], axis=-1)
        lam = np.linalg.solve(M, (points - v[:, 0])[..., None])[..., 0]
        return np.minimum(1.0 - lam.sum(-1), lam.min(-1)) >= -outside_tol

    def probes(self, points: np.ndarray, outside_tol: float = 1e-6) -> sp.csr_matrix:
        """Matrix (k, n_scalar) evaluating a scalar field of :attr:`basis` at ``points`` (k, 3)."""
        cells = self.locate(points, outside_tol)
        b = self.basis
        loc = b.mapping.invF(points.T[:, :, None], tind=cells)
        phis = np.array([np.asarray(b.elem.gbasis(b.mapping, loc, j, tind=cells)[0]) for j in range(b.Nbfun)])
        rows = np.tile(np.arange(len(points)), b.Nbfun)
        cols = b.element_dofs[:, cells].ravel()
        return sp.coo_matrix((phis.ravel(), (rows, cols)), shape=(len(points), b.N)).tocsr()


def tet_convergence(
    body, formulation: str, material: Material, supports, outputs: dict[str, Callable[[TetSolution], float]],
    levels: int = 3, budget: float | None = None, gravity=(0.0, 0.0, 0.0),
    project: Callable[[MeshTet], MeshTet] | None = None,
) -> tuple[list[TetSolution], dict[str, OutputConvergence]]:
    """Solve on the body's mesh refined ``0 … levels−1`` times (``h, h/2, …``) and analyze each
    output; with ``budget``, stop at the first level from the second on at which every output's
    relative error estimate (finest) is at most ``budget``.  ``project`` maps each refined mesh to
    one whose boundary nodes lie on the true surface (default: the faceted body is kept)."""
    if levels < 2:
        raise ValueError(f"need at least two refinement levels, got {levels}")
    mesh = as_mesh(body)
    sols, conv = [], {}
    for level in range(levels):
        sols.append(TetProblem(mesh, formulation).solve(material, supports, gravity))
        if level >= 1:
            factors = [2**i for i in range(len(sols))]
            conv = {name: analyze(factors, [fn(s) for s in sols], EXPECTED_ORDER[formulation], name)
                    for name, fn in outputs.items()}
            if budget is not None and all(o.relative_error_finest <= budget for o in conv.values()):
                break
        if level + 1 < levels:
            mesh = mesh.refined() if project is None else project(mesh.refined())
    return sols, conv
