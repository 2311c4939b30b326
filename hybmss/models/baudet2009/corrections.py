"""The cubic-cell MSS of [B09] (variant ``baudet2009``): its lateral correction forces, a
non-conservative :class:`hybmss.terms.ForceTerm`.

Springs ([B09], SPEC §4)
------------------------
Per cell, each of the 12 edges is a spring ``kx = E le (4ν+1)/(8(1+ν))`` and each of the 4 inner
diagonals ``kd = 3 E le/(8(1+ν))``; no face diagonals.  Shared edges are merged (Kirchhoff), so
the family constant of an interior edge is ``4 kx`` (:mod:`hybmss.calibrate`): every cell keeps
its own share ``kx`` and a homogeneous deformation of a body costs exactly the sum of the cells.

[B09]'s derivation, redone.  A single cube of edge l under the diagonal strain
``(ε1, ε2, ε3)`` (small strain).  The cell's springs crossing axis i are the 4 i-edges
(elongation ``l εi``) and the 4 inner diagonals (elongation ``l tr ε/√3``, axial component
``1/√3``); they pull the two i-faces together with the total normal force

    S_i = 4 kx l εi + (4/3) kd l tr ε = l² (a εi + b tr ε),
    a = E(4ν+1)/(2(1+ν)),   b = E/(2(1+ν)) = G.

Uniaxial stress along x (ε2 = ε3 = −ν ε1) gives ``S_1 = E l² ε1``: the pulled face carries
exactly E (this is how [B09] fixed kx once kd is fixed by shear: the edges carry no shear, the
inner diagonals give ``C_44 = 4 kd/(3 l) = G``).  But the lateral faces are not free:
``S_2 = S_3 = S_1 (1 − 4ν)/2 ≠ 0`` except at ν = 1/4 (springs alone obey the Cauchy relation).
[B09] cancels it with forces on the lateral faces, orthogonal to them: the lateral face must
receive the outward total force ``c S_1`` with

    c = (1 − 4ν)/2,  i.e. per vertex  c S_1/4 = −(4ν − 1) S_1/8 = −F_1 (4ν − 1)/16

where ``F_1 = 2 S_1`` is the sum over the cell's two x-faces of the normal force they carry.
That is the published ``F⊥ = −F (4ν−1)/16`` per vertex, provided F counts both faces of the
pair.  (Taking F as the force on one face, the literal formula gives half the correction needed
ν_eff is wrong: at ν = 0.3 one gets ν_eff = 0.27 and E_eff = 1.02 E.)

Definition of the elongation force F_i used here
------------------------------------------------
Inside a lattice the lateral faces of a cell carry forces too, and every axis drives a
correction on the two others.  If F_i were the force of the cell's *springs* alone, the
uniaxial test would feed the lateral spring forces ``S_2, S_3`` back as corrections on the
loaded face and E and ν would both be off (the single-cube derivation assumed the lateral
faces transmit nothing): at ν = 0.3 that gives ν_eff = 0.295 and E_eff = 0.986 E, at ν = 0.45
ν_eff = 0.388 and E_eff = 0.80 E, and at ν = 0 (c = 1/2) the lateral faces lose all stiffness.  We therefore take F_i/2 = T_i, the normal force the cell *transmits*
across its i-faces, springs and corrections together (the cell's ``σ_ii l²``):

    T_i = S_i − c Σ_{j≠i} T_j        (the corrections push the i-faces apart)
    ⇔  ((1 − c) I + c 𝟙𝟙ᵀ) T = S  ⇔  T = (S − c/(1+2c) (Σ S) 𝟙) / (1 − c),

a 3×3 linear system per cell, regular for ν ≠ 1/2 and ν ≠ −1/4.  On a free lateral face T = 0
exactly as in [B09]'s test, and for any homogeneous small strain the cell's law becomes
``σ_ii (1 − c) + c tr σ = a εi + b tr ε``, whose solution is exactly isotropic linear
elasticity: ``2μ = a/(1 − c) = E/(1+ν)``, ``λ = Eν/((1+ν)(1−2ν))``; shear is carried by the
inner diagonals with ``G = 4 kd/(3 le)``.  So E, ν *and* G are right for homogeneous states;
what the model misses is in the inhomogeneous ones (no face diagonals: hourglass modes).

Finite deformation.  ``d_i`` is the unit vector of the cell's averaged edge vector along i
(``a, b, c`` of SPEC §3, which joins the centroids of the two i-faces); S_i is the sum of the
forces of the cell's own springs (its shares ``kx``, ``kd``) on the 4 vertices of the i+ face,
projected on ``−d_i`` (tension positive).  The correction on face j± is ``±c (Σ T − T_j) d_j / 4``
on each of its 4 vertices.  Being pairs of equal and opposite forces along the line of the face
centroids, the corrections conserve linear and angular momentum and rotate with the cell
(objective); for a cube the d_i are the face normals.

Not the gradient of an energy
-----------------------------
The correction on the j-faces depends on the springs of the other axes (including the inner
diagonals' response to non-affine motions), but the j-face motion does not enter those forces
in the transposed way: the Jacobian ``∂f/∂x`` of the corrections is not symmetric, so the forces
have a non-zero curl and do work around closed loops (``tests/test_baudet.py`` measures both).
There is no potential energy: :func:`hybmss.solve.solve_static` cannot minimize one and
solves this variant in its residual mode (Newton on the force residual, see
:mod:`hybmss.solve`), with :meth:`Corrections.stiffness` as the term's Jacobian.

What the residual mode guarantees: a configuration where the total force (springs,
corrections, gravity, loads) on every free degree of freedom is below ``rtol`` times the
largest plate reaction or applied load, reached by continuation from rest over load steps.  It
does not guarantee stability (without an energy there is no minimum to certify; a dynamic run
could leave this state) nor uniqueness.  Without face diagonals the lattice has zero-stiffness
(hourglass) modes, so the Jacobian is singular and the plain Newton step can be useless along
them; the step is then retried with a Levenberg–Marquardt shift ``μ·mean(diag J)·I``
(μ = 1e-8 … 1), which only damps it: convergence is still judged on the unshifted residual.
Where such modes are loaded at second order (a clamped 4×1×1 bar under gravity), the equilibria
form a family and different load paths can end at different members (all with zero residual):
the displacement there is not determined by the model to better than that spread.  For that
bar, damped explicit dynamics (NumPy kernel) settles on the state this solver returns (to
1e-14 m, with 1 or 8 load steps); an undamped-Newton variant of the solver had stopped on
another zero-residual state 5 % away.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ...lattice import CORNERS, VOLUME_SIGNS

AXIS_SIGNS = 2.0 * CORNERS - 1.0
"""(8, 3): +1 if corner c lies on the i+ face of its cell, −1 on the i− face."""

EDGE_LO = np.array([[c for c in range(8) if not (c >> i) & 1] for i in range(3)], dtype=np.int64)
"""(3, 4): the low corner of each of the 4 cell edges along axis i (the high one is ``lo | 1<<i``)."""

DIAG_LO = np.arange(4, dtype=np.int64)
"""Inner diagonals join corner q and 7 − q, q = 0..3."""

DIAG_SIGN = np.array([[1.0 if not (q >> i) & 1 else -1.0 for i in range(3)] for q in range(4)])
"""(4, 3): +1 if diagonal q (from q to 7 − q) runs from the i− to the i+ face, else −1."""


def coefficient(nu: float) -> float:
    """c = (1 − 4ν)/2: total lateral correction per face, in units of the transmitted force."""
    return 0.5 * (1.0 - 4.0 * nu)


@dataclass(frozen=True, eq=False)
class Corrections:
    """The correction forces of one system as a non-conservative :class:`hybmss.terms.ForceTerm`:
    per-cell spring shares ``kx``, ``kd`` (N/m), rest edge ``le`` (m), coefficient ``c``, and the
    cells (m, 8) they act on.  Internal forces: they do not follow the load factor."""

    cells: np.ndarray
    kx: float
    kd: float
    le: float
    c: float

    name = "baudet2009_corrections"
    conservative = False
    scaled = False

    @classmethod
    def for_system(cls, consts, material, lattice) -> "Corrections":
        c = coefficient(material.nu)
        if abs(1.0 - c) < 1e-12 or abs(1.0 + 2.0 * c) < 1e-12:
            raise ValueError(f"baudet2009 corrections are singular at nu = {material.nu} (need nu != -1/4, 1/2)")
        return cls(lattice.cells, consts.ke / 4.0, consts.kc, lattice.body.le, c)

    def forces(self, x: np.ndarray) -> np.ndarray:
        """Correction forces (n, 3) at positions ``x`` (NumPy reference)."""
        return correction_forces(x, self.cells, self.kx, self.kd, self.le, self.c)

    def energy(self, x: np.ndarray) -> float:
        raise TypeError("the baudet2009 correction forces are not the gradient of an energy")

    def stiffness(self, x: np.ndarray) -> sp.csr_matrix:
        """``∂(−f_corr)/∂x``: minus :func:`correction_jacobian` (not symmetric)."""
        return -correction_jacobian(x, self)

    def stencil_stage(self, system):
        """Its stage in the generated stencil kernel (:class:`hybmss.models.hybmss.stepper.StencilStage`):
        :func:`hybmss.models.baudet2009._kernels.stencil_stage` on the grid layout of
        :class:`GridCorrections`, float64 only."""
        from ..hybmss.stepper import StencilStage

        return StencilStage(f"{_kernels_module()}:stencil_stage", GridCorrections.from_system(system).stage_args,
                            ("f64",))


# ------------------------------------------------------------------------- NumPy reference
def _sqrt(v):
    return np.sqrt(v)  # analytic (complex-step safe): no abs()


def cell_transmitted(xc, kx, kd, le):
    """Spring tensions ``S`` (m, 3) and unit axes ``d`` (m, 3, 3) of cells with corners ``xc``
    (m, 8, 3).  Written without ``abs`` so that it accepts complex positions (complex step)."""
    abc = np.einsum("cd,mci->mdi", VOLUME_SIGNS, xc)  # averaged edge vectors a, b, c
    d = abc / _sqrt(np.einsum("mdi,mdi->md", abc, abc))[..., None]
    S = np.zeros(xc.shape[:1] + (3,), dtype=xc.dtype)
    for i in range(3):
        lo = EDGE_LO[i]
        E = xc[:, lo | (1 << i)] - xc[:, lo]  # (m, 4, 3)
        t = kx * (1.0 - le / _sqrt(np.einsum("mei,mei->me", E, E)))
        S[:, i] += np.einsum("me,mei,mi->m", t, E, d[:, i])
    D = xc[:, 7 - DIAG_LO] - xc[:, DIAG_LO]  # (m, 4, 3)
    td = kd * (1.0 - math.sqrt(3.0) * le / _sqrt(np.einsum("mqi,mqi->mq", D, D)))
    S += np.einsum("mq,qj,mqi,mji->mj", td, DIAG_SIGN, D, d)
    return S, d


def cell_correction_forces(xc, kx, kd, le, c):
    """Correction forces (m, 8, 3) on the corners of cells ``xc`` (m, 8, 3)."""
    S, d = cell_transmitted(xc, kx, kd, le)
    T = (S - (c / (1.0 + 2.0 * c)) * S.sum(axis=1, keepdims=True)) / (1.0 - c)
    mag = 0.25 * c * (T.sum(axis=1, keepdims=True) - T)  # (m, 3): per vertex, face j
    P = mag[..., None] * d  # (m, 3 axes, 3 comps)
    return np.einsum("cj,mji->mci", AXIS_SIGNS, P)


def correction_forces(x, cells, kx, kd, le, c):
    """Correction forces (n, 3) of all ``cells`` at positions ``x`` (n, 3)."""
    fc = cell_correction_forces(np.asarray(x)[cells], kx, kd, le, c)
    f = np.zeros(np.shape(x))
    idx = cells.ravel()
    for k in range(3):
        f[:, k] = np.bincount(idx, weights=fc[..., k].ravel(), minlength=len(f))
    return f


def cell_transmitted_forces(x, corr: Corrections) -> np.ndarray:
    """Transmitted normal forces T (m, 3) per cell (N): the cell's ``σ_ii le²``."""
    S, _ = cell_transmitted(np.asarray(x)[corr.cells], corr.kx, corr.kd, corr.le)
    c = corr.c
    return (S - (c / (1.0 + 2.0 * c)) * S.sum(axis=1, keepdims=True)) / (1.0 - c)


def correction_jacobian(x, corr: Corrections) -> sp.csr_matrix:
    """``∂f_corr/∂x`` (3n × 3n, CSR, not symmetric), exact to round-off by the complex step
    applied cell by cell (each cell's forces depend on its 8 corners only)."""
    cells = corr.cells
    xc = np.asarray(x, dtype=float)[cells]  # (m, 8, 3)
    m = len(cells)
    h = 1e-30 * corr.le
    blocks = np.empty((m, 8, 3, 8, 3))  # [cell, a, i, b, j] = ∂f_{a,i}/∂x_{b,j}
    for b in range(8):
        for j in range(3):
            z = xc.astype(complex)
            z[:, b, j] += 1j * h
            blocks[:, :, :, b, j] = cell_correction_forces(z, corr.kx, corr.kd, corr.le, corr.c).imag / h
    dof = 3 * cells[:, :, None] + np.arange(3)[None, None, :]  # (m, 8, 3)
    rows = np.broadcast_to(dof[:, :, :, None, None], blocks.shape).ravel()
    cols = np.broadcast_to(dof[:, None, None, :, :], blocks.shape).ravel()
    N = 3 * len(x)
    return sp.csr_matrix((blocks.ravel(), (rows, cols)), shape=(N, N))


# ------------------------------------------------------------------------- stencil layout
@dataclass(frozen=True, eq=False)
class GridCorrections:
    """The corrections of a system laid out on its full grid for the Numba twin
    (:mod:`hybmss.models.baudet2009._kernels`): ``flat`` (n,) grid index of each particle, ``kc`` (2, N)
    per-cell ``kx``, ``kd`` at the cell's lowest corner (0: no cell), ``coff`` (8,) corner offsets."""

    shape: tuple[int, int, int]
    flat: np.ndarray
    kc: np.ndarray
    coff: np.ndarray
    le: float
    c: float
    Xg: np.ndarray

    @classmethod
    def from_system(cls, system) -> "GridCorrections":
        corr = system.term(Corrections.name)
        if corr is None:
            raise ValueError(f"model {system.scene.model.name!r} has no baudet2009 correction forces")
        lat = system.lattice
        shape = tuple(int(n) + 1 for n in system.scene.body.shape)
        strides = np.array([shape[1] * shape[2], shape[2], 1], dtype=np.int64)
        N = int(np.prod(shape))
        flat = lat.grid @ strides
        kc = np.zeros((2, N))
        low = lat.cell_ijk @ strides
        kc[0, low] = corr.kx
        kc[1, low] = corr.kd
        gi = np.indices(shape).reshape(3, -1).astype(float)
        Xg = np.asarray(system.scene.body.origin, dtype=float)[:, None] + gi * corr.le
        return cls(shape, flat, kc, (CORNERS @ strides).astype(np.int64), corr.le, corr.c, Xg)

    def stage_args(self) -> tuple:
        """``args`` of :func:`hybmss.models.baudet2009._kernels.stencil_stage`: the grid constants
        and fresh scratch ``(kc, coff, le, c, P (3, 3, N), Fc (3, N))``."""
        N = int(np.prod(self.shape))
        return (self.kc, self.coff, float(self.le), float(self.c), np.zeros((3, 3, N)), np.zeros((3, N)))

    def forces(self, x: np.ndarray) -> np.ndarray:
        """Correction forces (n, 3) at particle positions ``x`` (n, 3), by the Numba kernel."""
        from ._kernels import correction_forces_grid

        xg = self.Xg.copy()
        xg[:, self.flat] = np.asarray(x, dtype=float).T
        F = correction_forces_grid(xg, self.kc, self.coff, self.le, self.c)
        return np.ascontiguousarray(F[:, self.flat].T)


def _kernels_module() -> str:
    """The module of the corrections' Numba kernels (named in the generated stencil's source)."""
    return __name__.rsplit(".", 1)[0] + "._kernels"
