"""Natural frequencies and mode shapes of a scene's body: small-strain FEM at rest.

Find ``ω² ≥ 0`` and ``φ ≠ 0`` vanishing on the plates' constrained dofs such that for all ``v``
vanishing there

    ∫ λ div φ div v + 2μ ε(φ):ε(v) dx = ω² ∫ ρ φ · v dx,        f = ω / (2π)  (Hz),

i.e. ``K φ = ω² M φ`` on the free dofs.  ``K = λ K_λ + μ K_μ`` is the stiffness of
:mod:`fem_reference.linear` on the same mesh (:mod:`~fem_reference.mesh`), space
(:mod:`~fem_reference.space`) and supports (:mod:`~fem_reference.dirichlet`: every component a
plate constrains is held at zero; a plate's motion, the gravity and the loads do not enter: the
body vibrates about its rest state, unstressed).  The mass is

- consistent: ``M = ρ ∫ N_a N_b dx ⊗ I₃`` (exact quadrature: degree 2 per direction for Hex1,
  4 for Hex2, within the spaces' Gauss orders 3 and 5);
- lumped: its row sums on the diagonal (positive for Hex1 and the 27-node Hex2, tensor products of
  the 1D row sums h/2, h/2 and h/6, 2h/3, h/6).

The eigenproblem is solved by ARPACK in shift-invert mode (``scipy.sparse.linalg.eigsh``,
``mode='normal'``) with a shift ``σ = −10⁻⁶ E / (ρ L²)`` (L: the body's longest side) just
below zero, so ``K − σ M`` is positive definite even when supports leave rigid motions free,
and the k eigenvalues nearest σ are the lowest.  Modes are mass-normalised (``φᵀ M φ = 1``).
``K − σM`` is factorized once by CHOLMOD (:class:`fem_reference.linalg.CholmodFactor`) in the
nested-dissection order of the mesh (:attr:`fem_reference.linear.LinearElasticity.order`), the
mixed element's saddle point below by SuperLU in the same order (:class:`~fem_reference.linalg.OrderedLU`):
on the 10×10×10 cube, Hex2 at ν = 0.25 in 3.8 s instead of 14.6 s with SuperLU's own order inside
eigsh, the mixed element at ν = 0.499 in 5.7 s instead of 39.8 s, the frequencies equal to 5e-12.

Mixed u–p element (Taylor–Hood Hex2 × Hex1, ν → ½): with ``p = λ div u`` the saddle point of
:mod:`fem_reference.linear`, ``[[μ K_μ, Bᵀ], [B, −M_p/λ]]``, has the eigenproblem

    (μ K_μ + λ Bᵀ M_p⁻¹ B) φ = ω² M φ,

the pressure condensed exactly.  The Taylor–Hood pressure is continuous, so ``M_p⁻¹`` (and the
condensed matrix) is dense: it is never formed.  Each shift-invert step solves the saddle point
system ``[[μ K_μ − σ M, Bᵀ], [B, −M_p/λ]] [φ; p] = [M x; 0]`` (one sparse LU, reused) and keeps ``φ``,
which is ``(K_cond − σ M)⁻¹ M x``.  It needs λ > 0 (ν > 0), as the static mixed solve does.

The FEM field at a lattice particle is its nodal value: every lattice particle is a vertex of the
mesh at any refinement and a Lagrange basis is interpolatory there (:func:`at_particles`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from hybmss.scene import Scene

from .dirichlet import plate_dirichlet
from .linalg import CholmodFactor, OrderedLU, _local_order, cholmod
from .linear import FORMULATIONS, LinearElasticity
from .mesh import build_mesh

MASSES = ("consistent", "lumped")
SHIFT = 1e-6
"""σ = −SHIFT · E / (ρ L²): the shift of the shift-invert iteration, just below the spectrum."""


@dataclass(frozen=True, eq=False)
class Modes:
    """The lowest natural frequencies of a body and their mass-normalised mode shapes.

    Attributes
    ----------
    freq : (k,) natural frequencies f = ω / 2π, Hz, ascending.
    shapes : (k, n_nodes, 3) nodal mode shapes (zero on the held dofs), ``φᵀ M φ = 1``.
    points : (n_nodes, 3) reference positions of the nodes.
    element, mass : the formulation and the mass matrix they come from.
    particle_nodes : node of every lattice particle (:func:`at_particles`).
    """

    freq: np.ndarray
    shapes: np.ndarray
    points: np.ndarray
    element: str
    mass: str
    refine: int
    particle_nodes: np.ndarray

    @property
    def omega2(self) -> np.ndarray:
        return (2.0 * np.pi * self.freq) ** 2


def mass_matrix(space, rho: float, lumped: bool = False) -> sp.csr_matrix:
    """The vector mass matrix ``ρ ∫ N_a N_b dx ⊗ I₃`` (dofs ``3 s + c``), or its row-sum lumping."""
    Ms = space.mass(rho)
    if lumped:
        Ms = sp.diags(np.asarray(Ms.sum(axis=1)).ravel())
    return sp.kron(Ms, sp.identity(3), format="csr")


def matrices(scene: Scene, element: str = "hex2", refine: int = 1, mass: str = "consistent"):
    """``(K, M, free, ops)`` of ``scene``'s body: the full stiffness (the mixed element: its
    ``(μ K_μ, B, M_p/λ)`` blocks as a tuple instead) and mass, the free vector dofs (bool) and the
    operators (:class:`~fem_reference.linear.LinearElasticity`)."""
    if element not in FORMULATIONS:
        raise ValueError(f"element must be one of {', '.join(FORMULATIONS)}; got {element!r}")
    if mass not in MASSES:
        raise ValueError(f"mass must be one of {', '.join(MASSES)}; got {mass!r}")
    ops = LinearElasticity(build_mesh(scene.body, refine), element)
    mat = scene.material
    Klam, Kmu = ops.parts
    M = mass_matrix(ops.space, mat.rho, lumped=mass == "lumped")
    free = np.ones(ops.space.n_vector, dtype=bool)
    free[plate_dirichlet(scene, ops.space).dofs] = False
    if element != "mixed":
        return (mat.lam * Klam + mat.G * Kmu).tocsr(), M, free, ops
    if mat.lam <= 0:
        raise ValueError(f"the mixed u-p element needs lambda > 0 (nu > 0), got nu = {mat.nu}")
    return (mat.G * Kmu, ops.divergence, ops.pressure_mass / mat.lam), M, free, ops


def shift(scene: Scene) -> float:
    """The shift σ of the shift-invert iteration (module docstring)."""
    L = max(scene.body.shape) * scene.body.le
    m = scene.material
    return -SHIFT * m.E / (max(m.rho, 1e-300) * L * L)


def _saddle_inverse(A, B, C, M, sigma: float, order: np.ndarray | None = None) -> spla.LinearOperator:
    """``x ↦ φ`` of ``[[A − σM, Bᵀ], [B, −C]] [φ; p] = [M x; 0]``: the shift-invert operator of the
    pressure-condensed eigenproblem (module docstring), factorized once in the fill-reducing
    ``order`` of its unknowns (``None``: SuperLU's own; see :class:`fem_reference.linalg.OrderedLU`)."""
    n = A.shape[0]
    S = sp.bmat([[A - sigma * M, B.T], [B, -C]], format="csr")
    lu = OrderedLU(S, order)
    zeros = np.zeros(B.shape[0])

    def solve(x):
        return lu.solve(np.concatenate([np.ravel(x), zeros]))[:n]

    return spla.LinearOperator((n, n), matvec=solve, dtype=float)


def _spd_inverse(K, M, free: np.ndarray, sigma: float, order: np.ndarray | None) -> spla.LinearOperator | None:
    """``x ↦ (K − σM)⁻¹ x`` on the free dofs by CHOLMOD's ``L Lᵀ`` in the fill-reducing ``order``
    of all dofs (``K − σM`` is positive definite for σ below the spectrum); ``None`` without
    CHOLMOD (eigsh then factorizes by SuperLU itself)."""
    if cholmod is None:
        return None
    fac = CholmodFactor(sp.csr_matrix(K - sigma * M), free, _local_order(order, free))
    fac.factorize(sp.csr_matrix(K - sigma * M))
    n = int(free.sum())
    return spla.LinearOperator((n, n), matvec=lambda x: fac.solve(np.ravel(x)), dtype=float)


def eigen(K, M, k: int, sigma: float, OPinv=None) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` eigenpairs ``(ω², φ)`` of ``K φ = ω² M φ`` nearest ``σ``, ascending, ``φᵀ M φ = 1``
    (M symmetric positive definite; ``OPinv``: ``(K − σM)⁻¹`` when K is not a matrix)."""
    n = M.shape[0]
    if not 1 <= k < n:
        raise ValueError(f"k (number of modes) must lie in [1, {n - 1}] for this body's {n} free dofs, got {k}")
    # a start vector of its own, not ARPACK's (whose generator's state persists between calls): the
    # basis of a degenerate eigenvalue then does not depend on the process's earlier solves
    v0 = np.random.default_rng(0).standard_normal(n)
    w, V = spla.eigsh(K, k=k, M=M, sigma=sigma, which="LM", mode="normal", OPinv=OPinv, tol=0.0, v0=v0)
    order = np.argsort(w)
    w, V = w[order], V[:, order]
    V = V / np.sqrt(np.einsum("ik,ik->k", V, M @ V))
    return w, V


def modes(scene: Scene, k: int = 6, element: str = "hex2", refine: int = 1, mass: str = "consistent") -> Modes:
    """The lowest ``k`` natural frequencies (Hz) and mode shapes of ``scene``'s body (module
    docstring) with the FEM ``element`` (hex1, hex2, mixed) on the grid refined ``refine`` times."""
    K, M, free, ops = matrices(scene, element, refine, mass)
    sigma = shift(scene)
    Mff = M[free][:, free].tocsc()
    if element == "mixed":
        A, B, C = K
        Aff, Bf = A[free][:, free].tocsc(), B.tocsc()[:, free]
        keep = np.concatenate([free, np.ones(C.shape[0], dtype=bool)])
        op = _saddle_inverse(Aff, Bf, C.tocsc(), Mff, sigma, _local_order(ops.order, keep))
        Clu = spla.splu(C.tocsc())
        Kop = spla.LinearOperator(Aff.shape, matvec=lambda x: Aff @ x + Bf.T @ Clu.solve(Bf @ np.ravel(x)),
                                  dtype=float)
        w, Vf = eigen(Kop, Mff, k, sigma, OPinv=op)
    else:
        Kff = K[free][:, free].tocsc()
        w, Vf = eigen(Kff, Mff, k, sigma, OPinv=_spd_inverse(K, M, free, sigma, ops.order))
    V = np.zeros((ops.space.n_vector, len(w)))
    V[free] = Vf
    freq = np.sqrt(np.clip(w, 0.0, None)) / (2.0 * np.pi)
    shapes = np.ascontiguousarray(V.T.reshape(len(w), -1, 3))
    return Modes(freq, shapes, ops.space.points, element, mass, int(refine), ops.space.particle_dofs)


def at_particles(m: Modes) -> np.ndarray:
    """(k, n_particles, 3): the mode shapes at the lattice particles (their nodal values)."""
    return m.shapes[:, m.particle_nodes, :]


def direction_share(m: Modes, axis: int, M=None) -> np.ndarray:
    """(k,) share of each mode's kinetic energy in component ``axis``: ``φ_aᵀ M φ_a / φᵀ M φ``
    with the mass ``M`` (n_vector²; ``None``: nodal sums of squares, a lumped-mass measure)."""
    out = np.empty(len(m.freq))
    for i, phi in enumerate(m.shapes):
        v = phi.ravel()
        va = np.zeros_like(phi)
        va[:, axis] = phi[:, axis]
        va = va.ravel()
        if M is None:
            out[i] = va @ va / (v @ v)
        else:
            out[i] = va @ (M @ va) / (v @ (M @ v))
    return out
