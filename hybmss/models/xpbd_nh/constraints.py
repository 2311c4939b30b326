"""The constraints of ``xpbd-nh`` on the voxel grid (SPEC §10): the cells' tetrahedra, the
constraint set as a force term, the particles' inverse masses and external accelerations, and the
readable NumPy twin of one substep.

Each cube is split into tetrahedra by the two complementary 5-tet splits, each tetrahedron at half
its rest volume V; per tetrahedron ``F = D_s D_m⁻¹`` and the constraints (Macklin & Müller 2021)

    C_D = √tr(FᵀF)   (compliance α_D = 1/(μ V)),     C_H = det F − γ   (α_H = 1/(λ V)),  γ = 1 + μ/λ,

which store ``V (μ/2 tr(FᵀF) + λ/2 (J − γ)²)``, with ``μ = μ₀``, ``λ = λ₀ + μ₀`` for a material of
Lamé (λ₀, μ₀).  One substep of size h (:func:`numpy_substep`)::

    v ← (v + h a) d,  x_prev ← x,  x ← x + h v,  prescribed components ← their targets
    per tetrahedron: Δλ = (−C − α̃ λ) / (Σ_i ∇_i Cᵀ W_i ∇_i C + α̃),  α̃ = α/h²,  x_i ← x_i + W_i ∇_i C Δλ
    v ← (x − x_prev) / h

The method and its measurements: :mod:`hybmss.models.xpbd_nh`.
"""

from __future__ import annotations

import math

import numpy as np

from ...lattice import CORNERS
from ...scene import Material
from ...system import System
from ...terms import DeadLoad
from . import _kernels as _kernels_xpbd

KERNELS = ("numba", "numpy")


def _split(central: tuple[int, ...]) -> list[tuple[int, ...]]:
    """A 5-tet split of the cube: the central tetrahedron on ``central`` and, at each other
    corner, the tetrahedron with its three edge neighbours."""
    tets = [tuple(central)]
    for c in range(8):
        if c in central:
            continue
        tets.append((c,) + tuple(c ^ (1 << d) for d in range(3)))
    return tets


SPLIT_A = _split((0, 3, 5, 6))
SPLIT_B = _split((1, 2, 4, 7))
CELL_TETS = np.array(SPLIT_A + SPLIT_B, dtype=np.int64)
"""(10, 4) local corners of a cell's tetrahedra: the two complementary 5-tet splits."""


def cell_tetrahedra(le: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(local corners (10, 4) positively oriented, D_m⁻¹ (10, 3, 3), weighted volumes (10,))``
    of one cell of edge ``le``: each split carries half the cell."""
    P = CORNERS * float(le)
    tets = CELL_TETS.copy()
    Dinv, V = [], []
    for t in tets:
        D = (P[t[1:]] - P[t[0]]).T
        if np.linalg.det(D) < 0:
            t[[2, 3]] = t[[3, 2]]
            D = (P[t[1:]] - P[t[0]]).T
        Dinv.append(np.linalg.inv(D))
        V.append(0.5 * np.linalg.det(D) / 6.0)
    return tets, np.array(Dinv), np.array(V)


def cell_batches(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cells of a body in batches of :data:`hybmss.models.xpbd_nh._kernels.LANES` that share no node,
    ordered so that any two cells sharing a node keep their order in ``cells`` (``bnodes``
    (nb, 8, LANES) corner nodes, pad lanes repeating the batch's first cell; ``bcount`` (nb,)
    cells per batch): the sweep of :func:`hybmss.models.xpbd_nh._kernels.project_cells` is then the
    cell-by-cell sweep, bit for bit."""
    cells = np.ascontiguousarray(cells, dtype=np.int64)
    lanes = _kernels_xpbd.LANES
    levels = _kernels_xpbd.cell_levels(cells)
    order = np.argsort(levels, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(levels[order]) != 0, True])
    groups = []
    for a, b in zip(starts[:-1], starts[1:]):
        groups += [order[i:min(i + lanes, b)] for i in range(a, b, lanes)]
    bnodes = np.empty((len(groups), 8, lanes), dtype=np.int64)
    bcount = np.empty(len(groups), dtype=np.int64)
    for k, g in enumerate(groups):
        idx = np.r_[g, np.full(lanes - len(g), g[0])]
        bnodes[k] = cells[idx].T
        bcount[k] = len(g)
    return bnodes, bcount


def xpbd_lame(material: Material) -> tuple[float, float, float]:
    """``(μ, λ, γ)`` of the constraints for a material of Lamé (λ₀, μ₀): μ = μ₀, λ = λ₀ + μ₀,
    γ = 1 + μ/λ (module docstring, "Lamé trap")."""
    mu = float(material.G)
    lam = float(material.lam) + mu
    return mu, lam, 1.0 + mu / lam


class XpbdNH:
    """The constraints of a body.  As a :class:`hybmss.terms.ForceTerm` it is the energy the
    constraints store, ``Σ_t V_t (μ/2 (tr FᵀF − 3) + λ/2 (J − γ)² − λ/2 (1 − γ)²)`` (zero at rest),
    with its exact forces; reactions and moduli are read from these forces at the rest state.
    No stiffness: the model is explicit only."""

    name = "xpbd-nh"
    conservative = True
    scaled = False

    def __init__(self, lattice, material: Material):
        self.le = float(lattice.body.le)
        self.X = np.asarray(lattice.X, dtype=float)
        local, Dinv, V = cell_tetrahedra(self.le)
        cells = np.asarray(lattice.cells, dtype=np.int64)
        m = len(cells)
        self.tets = np.ascontiguousarray(cells[:, local].reshape(-1, 4))
        self.Dminv = np.ascontiguousarray(np.tile(Dinv, (m, 1, 1)))
        self.Vt = np.ascontiguousarray(np.tile(V, m))
        self.mu, self.lam, self.gamma = xpbd_lame(material)
        self.cells = cells
        self._batches = None

    def batches(self) -> tuple[np.ndarray, np.ndarray]:
        """:func:`cell_batches` of the body's cells (computed once)."""
        if self._batches is None:
            self._batches = cell_batches(self.cells)
        return self._batches

    def deformation_gradients(self, x: np.ndarray) -> np.ndarray:
        xt = np.asarray(x)[self.tets]
        Ds = np.swapaxes(xt[:, 1:] - xt[:, :1], 1, 2)
        return Ds @ self.Dminv

    def energy(self, x: np.ndarray) -> float:
        """The constraints' energy, compiled (:func:`hybmss.models.xpbd_nh._kernels.term_energy`;
        its twin :meth:`energy_numpy`)."""
        return float(_kernels_xpbd.term_energy(_rows(x), self.tets, self.Dminv, self.Vt, self.mu, self.lam,
                                               self.gamma))

    def forces(self, x: np.ndarray) -> np.ndarray:
        """``−∇E`` (n, 3), compiled (:func:`hybmss.models.xpbd_nh._kernels.term_forces`; its twin
        :meth:`forces_numpy`)."""
        return _kernels_xpbd.term_forces(_rows(x), self.tets, self.Dminv, self.Vt, self.mu, self.lam, self.gamma)

    def energy_numpy(self, x: np.ndarray) -> float:
        """The energy with NumPy: the readable twin of :meth:`energy`."""
        F = self.deformation_gradients(x)
        J = np.linalg.det(F)
        psi = (0.5 * self.mu * (np.einsum("tij,tij->t", F, F) - 3.0) + 0.5 * self.lam * (J - self.gamma) ** 2
               - 0.5 * self.lam * (1.0 - self.gamma) ** 2)
        return float(np.dot(self.Vt, psi))

    def forces_numpy(self, x: np.ndarray) -> np.ndarray:
        """``−∇E`` (n, 3) with NumPy, the readable twin of :meth:`forces`: per tetrahedron
        ``P = μ F + λ (J − γ) cof F``, node forces ``−V P D_m⁻ᵀ`` (node 0: minus their sum).  ``cof F`` by columns, ``(f₁ × f₂, f₂ × f₀,
        f₀ × f₁)`` of F's columns ``f_j``, and ``J = f₀ · (f₁ × f₂)``."""
        F = self.deformation_gradients(x)
        f0, f1, f2 = F[:, :, 0], F[:, :, 1], F[:, :, 2]
        cof = np.stack([np.cross(f1, f2), np.cross(f2, f0), np.cross(f0, f1)], axis=2)
        J = np.einsum("ti,ti->t", f0, cof[:, :, 0])
        P = self.mu * F + (self.lam * (J - self.gamma))[:, None, None] * cof
        H = -self.Vt[:, None, None] * (P @ np.swapaxes(self.Dminv, 1, 2))  # column j: node j+1
        fe = np.concatenate([-H.sum(axis=2)[:, None, :], np.swapaxes(H, 1, 2)], axis=1)  # (T, 4, 3)
        x = np.asarray(x, dtype=float)
        idx, fe = self.tets.ravel(), fe.reshape(-1, 3)
        return np.stack([np.bincount(idx, weights=fe[:, a], minlength=len(x)) for a in range(3)], axis=1)

    def stiffness(self, x: np.ndarray):
        raise NotImplementedError("xpbd-nh is explicit only: it has no static tangent")


def _rows(x: np.ndarray) -> np.ndarray:
    """Positions (n, 3) as the kernels' (3, n) float64 rows."""
    return np.ascontiguousarray(np.asarray(x, dtype=float).T)


# ------------------------------------------------------------------------------ NumPy twin
def _constraint(F: np.ndarray, kind: int, gamma: float) -> tuple[float, np.ndarray]:
    """C and ∂C/∂F of the deviatoric (0) or hydrostatic (1) constraint."""
    if kind == 0:
        C = math.sqrt(float(np.sum(F * F)))
        return C, F / C
    cof = np.empty((3, 3))
    for a in range(3):
        a1, a2 = (a + 1) % 3, (a + 2) % 3
        for b in range(3):
            b1, b2 = (b + 1) % 3, (b + 2) % 3
            cof[a, b] = F[a1, b1] * F[a2, b2] - F[a1, b2] * F[a2, b1]
    return float(np.sum(F[0] * cof[0])) - gamma, cof


def _tet_constraint(term: XpbdNH, x: np.ndarray, t: int, kind: int) -> tuple[float, np.ndarray]:
    """C and its node gradients (4, 3) of constraint ``kind`` of tetrahedron ``t``."""
    xt = x[term.tets[t]]
    F = (xt[1:] - xt[0]).T @ term.Dminv[t]
    C, dC = _constraint(F, kind, term.gamma)
    G = dC @ term.Dminv[t].T  # column j: gradient at node j+1
    return C, np.vstack([-G.sum(axis=1), G.T])


def numpy_substep(term: XpbdNH, x, v, winv, h, damp, iterations, accel, set_plates, coupled=True):
    """One substep of the readable twin on (n, 3) arrays, in place (module docstring).
    ``accel``: (n, 3) external acceleration of the particles (:func:`external_acceleration`) or
    None.  ``set_plates(x)`` moves the prescribed components to their targets at t + h."""
    if accel is not None:
        v += h * accel
    v *= damp
    x_prev = x.copy()
    x += h * v
    set_plates(x)
    lamb = np.zeros((len(term.tets), 2))
    for _ in range(iterations):
        for t, nodes in enumerate(term.tets):
            w = winv[nodes]
            alpha = 1.0 / (np.array([term.mu, term.lam]) * term.Vt[t] * h * h)
            if coupled:  # both constraints of the tetrahedron in one 2×2 solve
                CD, gD = _tet_constraint(term, x, t, 0)
                CH, gH = _tet_constraint(term, x, t, 1)
                A = np.array([[alpha[0] + np.sum(w * gD * gD), np.sum(w * gD * gH)],
                              [np.sum(w * gH * gD), alpha[1] + np.sum(w * gH * gH)]])
                b = np.array([-CD, -CH]) - alpha * lamb[t]
                det = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
                d = np.array([A[1, 1] * b[0] - A[0, 1] * b[1], A[0, 0] * b[1] - A[0, 1] * b[0]]) / det
                x[nodes] += w * (gD * d[0] + gH * d[1])
                lamb[t] += d
            else:  # C_D, then C_H at the updated positions
                for kind in (0, 1):
                    C, g = _tet_constraint(term, x, t, kind)
                    d = (-C - alpha[kind] * lamb[t, kind]) / (float(np.sum(w * g * g)) + alpha[kind])
                    x[nodes] += w * g * d
                    lamb[t, kind] += d
    v[:] = (x - x_prev) / h



# ------------------------------------------------------------------------------ the particles
def inverse_masses(system: System) -> np.ndarray:
    """(n, 3) 1/m per component, 0 on prescribed components."""
    w = np.repeat((1.0 / system.mass)[:, None], 3, axis=1)
    w[system.fixed] = 0.0
    return w


def external_acceleration(system: System) -> np.ndarray | None:
    """(n, 3) acceleration of the particles by their external loads: gravity and the surface
    loads (``Scene.loads``, constant nodal forces over the particle masses, applied whole as the
    mass-spring explicit run applies them); ``None`` without any.  A substep damps it with the
    velocity (``v ← (v + h a)/(1 + c h)``), so a rest state feels ``a/(1 + c h)``."""
    loads = [t.f for t in system.terms if isinstance(t, DeadLoad) and np.any(t.f)]
    if system.gravity is None and not loads:
        return None
    a = np.zeros((system.n, 3))
    if system.gravity is not None:
        a[:] = system.gravity[None, :]
    for f in loads:
        a += f / system.mass[:, None]
    return a


