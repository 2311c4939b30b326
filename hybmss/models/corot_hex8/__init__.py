"""Corotational linear hexahedra on the voxel grid: ``corot-hex8`` and ``corot-hex8-sri`` (SPEC §10).

The folder holds the whole model: this module (element, forces, tangent, the explicit stepper
:class:`CorotStepper` and both variants, ``MODELS``) and its Numba kernels
(:mod:`hybmss.models.corot_hex8._kernels`), whose NumPy twins are here.

What a real-time FEM user runs instead of a mass-spring system (SOFA ``HexahedronFEMForceField``,
method "polar"; Nesme et al. 2005), built on the MSS's grid: nodes are the lattice particles,
each active cell is one trilinear hexahedron, masses are the lumped ``ρ Vc/8`` per corner.

Element.  Natural coordinates ξ ∈ [−1, 1]³, corners ``ξ_c = 2 (di, dj, dk) − 1`` (corner order
``c = di + 2 dj + 4 dk`` of :mod:`hybmss.lattice`), ``N_c = ⅛ (1 + ξ ξ_c)(1 + η η_c)(1 + ζ ζ_c)``,
``∇_X N_c = (2/le) ∂N_c/∂ξ`` on a cube.  ``K_e = Σ_g B_gᵀ D B_g det J`` over the 2×2×2 Gauss
points ±1/√3 (weights 1, ``det J = (le/2)³``), D the isotropic Hooke matrix of (λ, μ) (Voigt
order xx, yy, zz, yz, xz, xy with engineering shears).  One K_e serves every cell of the grid.

``corot-hex8-sri``: selective reduced integration (Hughes 1980): ``D = λ m mᵀ + μ diag(2,2,2,1,1,1)``
(m = (1,1,1,0,0,0)), the μ part at the 2×2×2 points, the λ part at the centre point only (weight 8).
The λ part then constrains only the mean dilatation of a cell, which removes volumetric locking as
ν → ½ (it is the Q1/P0 element); the μ part at full order leaves no hourglass mode.

Corotation.  Per cell, the deformation gradient at the centre ``F_c = (1/(4 le)) Σ_c x_c ⊗ ξ_c``,
its polar decomposition ``F_c = R U`` (Newton's iteration ``R ← ½(R + R⁻ᵀ)``, which converges
quadratically to the orthogonal polar factor for det F > 0), the local displacement
``u_c = Rᵀ (x_c − x̄) − (X_c − X̄)`` (centroids x̄, X̄) and the element forces ``f_c = −R (K_e u)_c``.
A rigid motion gives u = 0 exactly (R is then the rotation itself); small strain reduces to linear
Hex1 FEM.

Not conservative.  ``½ uᵀ K_e u`` with u built on the polar R is not a potential of these
forces (its gradient has terms in ∂R/∂x that ``−R K_e u`` leaves out), so the term declares
``conservative = False`` and :meth:`CorotHex8.energy` reports the corotated strain energy
``Σ_e ½ u_eᵀ K_e u_e`` as a measure, not as a potential to minimize.

Tangent.  The usual one, ``Σ_e R_e K_e R_eᵀ`` (block-rotated), leaves out ∂R/∂x: Newton then
converges linearly under large rotation (the 8×8×48 cantilever at E = 2 MPa stalled after 160 s).
:meth:`CorotHex8.stiffness` adds it.  With ``F = R U``, a variation ``δR = R [ω]×`` has
``((tr U) I − U) ω = axial(Rᵀ δF − δFᵀ R) = Σ_c ξ_c × Rᵀ δx_c / (4 le)``, so ``ω = Σ_c W_c δx_c``
with ``W_c = ((tr U) I − U)⁻¹ [ξ_c]× Rᵀ / (4 le)``.  From ``f_a = −R g_a``, ``g = K_e u``,
``δu_b = [p_b]× ω + Rᵀ δx_b`` (``p_b = Rᵀ (x_b − x̄)``)::

    −∂f_a/∂x_c = R K_ac Rᵀ − R Q_a W_c,     Q_a = [g_a]× − Σ_b K_ab [p_b]×

(nonsymmetric; zero extra term at rest, where ``K_e`` annihilates the rotation field).  It is
the Jacobian of the forces to central-difference accuracy; Newton converges quadratically.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ...explicit import (DENSE_EIG_MAX, lambda_max, lanczos_start, plate_arrays, scaled_free_stiffness,
                         simulate_explicit as _simulate_explicit)
from ...lattice import CORNERS
from ...result import Result
from ...scene import Material
from ...stepper import ParticleStepper
from ...system import System
from ..base import ModelBase, Style
from ..hybmss.stepper import numpy_advance
from . import _kernels as _kernels_corot

XI = np.ascontiguousarray(2.0 * CORNERS - 1.0)
"""(8, 3) natural coordinates of the corners."""
GAUSS = XI / math.sqrt(3.0)
"""(8, 3) the 2×2×2 Gauss points ±1/√3 (weights 1)."""
KERNELS = ("numba", "numpy")


# ------------------------------------------------------------------------------ element
def shape_gradients(xi: np.ndarray, le: float) -> np.ndarray:
    """∇_X N_c (8, 3) at the natural point ``xi`` of a cube of edge ``le``."""
    xi = np.asarray(xi, dtype=float)
    g = np.empty((8, 3))
    for c in range(8):
        f = 1.0 + xi * XI[c]
        g[c, 0] = XI[c, 0] * f[1] * f[2]
        g[c, 1] = f[0] * XI[c, 1] * f[2]
        g[c, 2] = f[0] * f[1] * XI[c, 2]
    return g / 8.0 * (2.0 / le)


def strain_matrix(xi: np.ndarray, le: float) -> np.ndarray:
    """Voigt strain-displacement matrix B (6, 24) at ``xi`` (xx, yy, zz, yz, xz, xy; engineering
    shears), dofs ordered (corner, component)."""
    g = shape_gradients(xi, le)
    B = np.zeros((6, 24))
    for c in range(8):
        gx, gy, gz = g[c]
        j = 3 * c
        B[0, j], B[1, j + 1], B[2, j + 2] = gx, gy, gz
        B[3, j + 1], B[3, j + 2] = gz, gy
        B[4, j], B[4, j + 2] = gz, gx
        B[5, j], B[5, j + 1] = gy, gx
    return B


def hooke_parts() -> tuple[np.ndarray, np.ndarray]:
    """``(D_λ, D_μ)`` with ``D = λ D_λ + μ D_μ``: ``D_λ = m mᵀ``, ``D_μ = diag(2, 2, 2, 1, 1, 1)``."""
    m = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    return np.outer(m, m), np.diag([2.0, 2.0, 2.0, 1.0, 1.0, 1.0])


def element_stiffness(lam: float, mu: float, le: float, sri: bool = False) -> np.ndarray:
    """The 24×24 linear stiffness of a cubic Hex8 cell (module docstring): full 2×2×2 integration,
    or with ``sri`` the λ part at the centre point only."""
    Dl, Dm = hooke_parts()
    detJ = (0.5 * le) ** 3
    K = np.zeros((24, 24))
    for p in GAUSS:
        B = strain_matrix(p, le)
        K += B.T @ (mu * Dm + (0.0 if sri else lam) * Dl) @ B * detJ
    if sri:
        B0 = strain_matrix(np.zeros(3), le)
        K += B0.T @ (lam * Dl) @ B0 * (8.0 * detJ)
    return 0.5 * (K + K.T)


# ------------------------------------------------------------------------------ polar (NumPy twin)
def polar_rotations(F: np.ndarray) -> np.ndarray:
    """Rotations R (m, 3, 3) of the polar decompositions ``F = R U`` of (m, 3, 3) matrices with
    det F > 0: the iteration of :func:`hybmss.models.corot_hex8._kernels.polar_rotation`, vectorized (each
    matrix stops when no entry changes by more than ``POLAR_TOL``)."""
    R = np.array(F, dtype=float, copy=True)
    active = np.ones(len(R), dtype=bool)
    for _ in range(_kernels_corot.POLAR_MAX_ITER):
        A = R[active]
        cof = np.empty_like(A)
        for i in range(3):
            i1, i2 = (i + 1) % 3, (i + 2) % 3
            for j in range(3):
                j1, j2 = (j + 1) % 3, (j + 2) % 3
                cof[:, i, j] = A[:, i1, j1] * A[:, i2, j2] - A[:, i1, j2] * A[:, i2, j1]
        det = A[:, 0, 0] * cof[:, 0, 0] + A[:, 0, 1] * cof[:, 0, 1] + A[:, 0, 2] * cof[:, 0, 2]
        new = 0.5 * (A + cof / det[:, None, None])
        change = np.abs(new - A).max(axis=(1, 2))
        R[active] = new
        idx = np.flatnonzero(active)
        active[idx[change <= _kernels_corot.POLAR_TOL]] = False
        if not active.any():
            break
    return R


# ------------------------------------------------------------------------------ the force term
class CorotHex8:
    """Corotational Hex8 forces of a body (a non-conservative :class:`hybmss.terms.ForceTerm`).

    ``lattice``: the body's lattice (cells, reference positions); ``material``: E, ν give
    (λ, μ) = (``Material.lam``, ``Material.G``); ``sri``: selective reduced integration."""

    conservative = False
    scaled = False

    def __init__(self, lattice, material: Material, sri: bool = False):
        self.name = "corot-hex8-sri" if sri else "corot-hex8"
        self.sri = bool(sri)
        self.le = float(lattice.body.le)
        self.X = np.asarray(lattice.X, dtype=float)
        self.cells = np.ascontiguousarray(lattice.cells, dtype=np.int64)
        self.lam, self.mu = float(material.lam), float(material.G)
        self.Ke = np.ascontiguousarray(element_stiffness(self.lam, self.mu, self.le, self.sri))
        dof = 3 * self.cells[:, :, None] + np.arange(3)[None, None, :]
        dof = dof.reshape(len(self.cells), 24)
        self._rows = np.repeat(dof, 24, axis=1).ravel()
        self._cols = np.tile(dof, (1, 24)).ravel()

    # -- kinematics
    def deformation_gradients(self, x: np.ndarray) -> np.ndarray:
        """F at the cell centres (m, 3, 3)."""
        return np.einsum("mci,cj->mij", np.asarray(x)[self.cells], XI) / (4.0 * self.le)

    def rotations(self, x: np.ndarray) -> np.ndarray:
        return polar_rotations(self.deformation_gradients(x))

    def local_displacements(self, x: np.ndarray, R: np.ndarray | None = None) -> np.ndarray:
        """u (m, 8, 3) in the corotated frames."""
        R = self.rotations(x) if R is None else R
        xe = np.asarray(x)[self.cells]
        Xe = self.X[self.cells]
        rel = xe - xe.mean(axis=1, keepdims=True)
        return np.einsum("mai,mca->mci", R, rel) - (Xe - Xe.mean(axis=1, keepdims=True))

    # -- ForceTerm
    def forces(self, x: np.ndarray) -> np.ndarray:
        """Internal forces (n, 3), NumPy (the readable twin of the kernel's force stage)."""
        R = self.rotations(x)
        u = self.local_displacements(x, R).reshape(len(self.cells), 24)
        g = (u @ self.Ke.T).reshape(len(self.cells), 8, 3)
        fe = -np.einsum("mij,mcj->mci", R, g)
        f = np.zeros_like(np.asarray(x, dtype=float))
        np.add.at(f, self.cells.ravel(), fe.reshape(-1, 3))
        return f

    def forces_numba(self, x: np.ndarray) -> np.ndarray:
        """The same forces from the Numba kernel."""
        return _kernels_corot.forces(np.asarray(x, dtype=float), self.X, self.cells, self.Ke, XI, self.le)

    def energy(self, x: np.ndarray) -> float:
        """Corotated strain energy ``Σ_e ½ u_eᵀ K_e u_e`` (a measure; not a potential of the forces)."""
        u = self.local_displacements(x).reshape(len(self.cells), 24)
        return float(0.5 * np.einsum("mi,ij,mj->", u, self.Ke, u))

    def stiffness(self, x: np.ndarray, rotation_derivative: bool = True) -> sp.csr_matrix:
        """Tangent ``−∂f/∂x`` (3n, 3n), nonsymmetric: per cell ``R K_ac Rᵀ − R Q_a W_c``, the
        usual block-rotated ``R K Rᵀ`` plus the derivative of the polar rotation (module
        docstring, "Tangent"); ``rotation_derivative=False``: ``R K Rᵀ`` alone."""
        F = self.deformation_gradients(x)
        R = polar_rotations(F)
        m = len(self.cells)
        Ke = self.Ke.reshape(8, 3, 8, 3)
        blocks = np.einsum("mai,cidj,mbj->mcadb", R, Ke, R)  # (m, 8, 3, 8, 3): [cell, a, i, c, j]
        if rotation_derivative:
            blocks = blocks - self._rotation_part(x, F, R)
        N = 3 * len(self.X)
        return sp.csr_matrix((blocks.reshape(m, 576).ravel(), (self._rows, self._cols)), shape=(N, N))

    def _rotation_part(self, x: np.ndarray, F: np.ndarray, R: np.ndarray) -> np.ndarray:
        """``R Q_a W_c`` (m, 8, 3, 8, 3) of :meth:`stiffness` (``F``, ``R``: the cells' deformation
        gradients and rotations at ``x``)."""
        u = self.local_displacements(x, R)
        Xe = self.X[self.cells]
        p = u + (Xe - Xe.mean(axis=1, keepdims=True))  # Rᵀ (x_c − x̄)
        g = (u.reshape(len(self.cells), 24) @ self.Ke.T).reshape(-1, 8, 3)  # K u, local frame
        Ke = self.Ke.reshape(8, 3, 8, 3)
        Q = _cross_matrices(g) - np.einsum("aibk,mbkj->maij", Ke, _cross_matrices(p))
        U = np.einsum("mki,mkj->mij", R, F)
        U = 0.5 * (U + np.swapaxes(U, 1, 2))
        M = np.trace(U, axis1=1, axis2=2)[:, None, None] * np.eye(3) - U
        Minv = np.linalg.inv(M)
        W = np.einsum("mij,cjk,mlk->mcil", Minv, _cross_matrices(XI), R) / (4.0 * self.le)  # (m, 8, 3, 3)
        return np.einsum("mik,makl,mcln->maicn", R, Q, W)


def _cross_matrices(v: np.ndarray) -> np.ndarray:
    """``[v]×`` (…, 3, 3) of vectors v (…, 3): ``[v]× w = v × w``."""
    C = np.zeros(v.shape + (3,))
    C[..., 0, 1], C[..., 0, 2] = -v[..., 2], v[..., 1]
    C[..., 1, 0], C[..., 1, 2] = v[..., 2], -v[..., 0]
    C[..., 2, 0], C[..., 2, 1] = -v[..., 1], v[..., 0]
    return C


# ------------------------------------------------------------------------------ explicit dynamics
def _scaled_free_stiffness(system: System, term: CorotHex8):
    return scaled_free_stiffness(system, term.stiffness(system.X, rotation_derivative=False))


def frequency_range(system: System, term: CorotHex8) -> tuple[float, float]:
    """``(ω_min, ω_max)`` (rad/s) of ``M⁻¹K`` at rest on the free degrees of freedom (K: the linear
    Hex8 stiffness, the tangent there); ω_min = 0 if the body has a zero-energy mode."""
    A = _scaled_free_stiffness(system, term)
    if A.shape[0] == 0:
        return 0.0, 0.0
    if A.shape[0] <= DENSE_EIG_MAX:
        w = np.linalg.eigvalsh(A.toarray())
        lmin, lmax = float(w[0]), float(w[-1])
    else:
        lmax = lambda_max(A)
        lmin = float(spla.eigsh(A.tocsc(), k=1, sigma=-1e-6 * lmax, which="LM", return_eigenvectors=False,
                                v0=lanczos_start(A.shape[0]))[0])
    return math.sqrt(max(lmin, 0.0)), math.sqrt(max(lmax, 0.0))


def omega_max(system: System, term: CorotHex8) -> float:
    """``ω_max`` (rad/s) of ``M⁻¹K`` at rest on the free degrees of freedom (as
    :func:`frequency_range`, without its shift-invert solve for ω_min)."""
    A = _scaled_free_stiffness(system, term)
    return math.sqrt(max(lambda_max(A), 0.0)) if A.shape[0] else 0.0


def dt_crit(system: System, term: CorotHex8) -> float:
    """Explicit stability limit ``2/√λmax(M⁻¹K)`` with K the tangent at rest (the linear Hex8
    stiffness, exact there) on the free degrees of freedom."""
    w = omega_max(system, term)
    return 2.0 / w if w > 0 else math.inf


def numpy_step(system: System, term: CorotHex8, x, v, dt, damp, x_old, x_new):
    """One semi-implicit Euler step of the readable twin on (n, 3) arrays, in place (as
    :func:`hybmss.models.hybmss.stepper.numpy_step`)."""
    acc = term.forces(x) / system.mass[:, None]
    if system.gravity is not None:
        acc = acc + system.gravity[None, :]
    v[:] = (v + dt * acc) * damp
    x += dt * v
    fixed = system.fixed
    x[fixed] = x_new[fixed]
    v[fixed] = (x_new - x_old)[fixed] / dt


class CorotStepper(ParticleStepper):
    """The stepper (:mod:`hybmss.stepper`) of the corotational hexahedra: semi-implicit Euler with
    the element forces of ``term``, by the Numba kernel (:mod:`hybmss.models.corot_hex8._kernels`,
    float64 or float32 state, one thread) or its NumPy twin (:func:`numpy_step`)."""

    def __init__(self, system: System, term: CorotHex8, dt: float, *, ramp_time: float, kernel: str = "numba",
                 precision: str = "f64", threads: int = 1):
        super().__init__(system, term, dt, ramp_time=ramp_time, kernel=kernel, precision=precision,
                         threads=threads, kernels=KERNELS)
        self.damp = 1.0 / (1.0 + system.scene.damping * self.dt)
        if kernel == "numba":
            n = system.n
            self._f = np.empty((3, n))
            self._gacc = np.zeros((3, n))
            if system.gravity is not None:
                self._gacc[:] = system.gravity[:, None]
            self._Xg, self._invm = np.ascontiguousarray(system.X.T), 1.0 / system.mass
            self._plates = plate_arrays(system)

    def _numpy_step(self, x, v, P_old, P_new):
        X = self.system.X
        numpy_step(self.system, self.term, x, v, self.dt, self.damp, X if P_old is None else P_old,
                   X if P_new is None else P_new)

    def advance(self, step0, n, check_every, limit2):
        S, term = self.system, self.term
        if self.kernel == "numba":
            return _kernels_corot.advance(self._W, self._Xg, term.cells, term.Ke, XI, term.le, self._invm, self._gacc,
                                          S.gravity is not None, self.dt, self.damp, self.ramp_time, self._plates,
                                          step0, n, check_every, limit2, self._f, self._posmode)
        return numpy_advance(S, self._numpy_step, self._x, self._v, self.dt, self.ramp_time, step0, n, check_every,
                             limit2)


def simulate_explicit(system: System, term: CorotHex8, dt: float = 1e-3, steps: int = 10_000,
                      kernel: str = "numba", ramp_time: float = 1.0, *, check_every: int = 10,
                      record_every: int = 0, x0: np.ndarray | None = None, v0: np.ndarray | None = None,
                      dt_crit_value: float | None = None, compute_dt_crit: bool = True,
                      precision: str = "f64") -> Result:
    """The explicit run of ``system`` with the corotational forces ``term`` (:class:`CorotStepper`
    in the one loop :func:`hybmss.explicit.simulate_explicit`, whose keywords these are)."""
    stepper = CorotStepper(system, term, dt, ramp_time=ramp_time, kernel=kernel, precision=precision)
    return _simulate_explicit(system.scene, dt, steps, kernel, ramp_time, record_every=record_every, system=system,
                              x0=x0, v0=v0, dt_crit_value=dt_crit_value, compute_dt_crit=compute_dt_crit,
                              check_every=check_every, precision=precision, stepper=stepper)


# ------------------------------------------------------------------------------ the registry's model
def corot_term(system: System) -> CorotHex8:
    """The corotational term of a system built for a corot model."""
    for t in system.terms:
        if isinstance(t, CorotHex8):
            return t
    raise ValueError("the system has no corotational hexahedra (its model is not corot-hex8 or corot-hex8-sri)")


class CorotHex8Model(ModelBase):
    """``corot-hex8``: corotational linear hexahedra, full 2×2×2 integration (module docstring)."""

    name = "corot-hex8"
    label = "corotational linear Hex8 FEM, polar rotation, 2x2x2 Gauss (SOFA; Nesme 2005)"
    style = Style("#2ca02c", "s", "--")
    conservative = False
    solvers = ("static", "explicit")
    kernels = ("numba", "numpy")
    order = 20
    sri = False

    def terms(self, p, scene, lattice, consts):
        return (CorotHex8(lattice, scene.material, self.sri),)

    def dt_crit(self, system) -> float:
        return dt_crit(system, corot_term(system))

    def stepper(self, system, dt, *, ramp_time, kernel="numba", precision="f64", threads=1):
        return CorotStepper(system, corot_term(system), dt, ramp_time=ramp_time, kernel=kernel, precision=precision,
                            threads=threads)


class CorotHex8SRI(CorotHex8Model):
    """``corot-hex8-sri``: the same hexahedra with selective reduced integration (λ part of the
    Hooke matrix at the centre point only): no volumetric locking as ν → ½."""

    name = "corot-hex8-sri"
    label = "corotational linear Hex8 FEM, selective reduced integration (Hughes 1980)"
    style = Style("#17becf", "P", "--")
    order = 21
    sri = True


MODELS = (CorotHex8Model(), CorotHex8SRI())
"""The two variants of the folder (the registry takes both)."""
MODEL = MODELS[0]
