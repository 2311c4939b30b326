"""Numba kernel of ``xpbd-nh``: XPBD substeps with the stable Neo-Hookean constraints.

Layouts as in :mod:`hybmss._kernels` on particle arrays: ``x, v, X`` (3, n); ``winv`` (3, n) the
inverse mass per component (0 on prescribed components); tetrahedra ``tets`` (T, 4) with the
inverse rest edge matrices ``Dminv`` (T, 3, 3) and their weighted rest volumes ``Vt`` (T,).

One substep of size h (see :mod:`hybmss.models.xpbd_nh` for the method):

1. ``v ← (v + h g) / (1 + c h)``; ``x_prev = x``; ``x ← x + h v``; the plates' prescribed
   components move to ``X + u(s(t + h))`` (:func:`hybmss._kernels.apply_plates`);
2. ``iterations`` Gauss–Seidel sweeps over the tetrahedra in order, each projecting its
   deviatoric constraint ``C_D = √tr(FᵀF)`` (compliance ``1/(μ V)``) and hydrostatic one
   ``C_H = det F − γ`` (``1/(λ V)``) together (one 2×2 solve, ``coupled``) or C_D then C_H,
   with multipliers reset at the start of the substep;
3. ``v = (x − x_prev)/h``.

Precision: the state ``W`` holds float64 positions or float32 displacements (``posmode`` False,
:func:`hybmss._kernels.kernel_state`); the constraint arithmetic is float64 in both.

Speed.  A tetrahedron's projection is about 130 scalar operations with a square root and two
divisions; one at a time (:func:`project_all`) they run at the scalar peak, ~55 ns each.  The
default sweep (one coupled iteration, a lattice body) is :func:`project_cells`: the cells of a
batch share no node and take one SIMD lane each, so LLVM vectorizes the arithmetic (4 doubles per
instruction on AVX2/AVX-512), and the batches follow a level order in which every pair of cells
sharing a node keeps its order (:func:`cell_levels`).  The sweep is then the tetrahedron-by-
tetrahedron one to the last bit (a test), 3.4–3.9× faster (10³ cube, 8×8×48 beam); it also
leaves out the products with the zero entries of the corner tetrahedra's ``D_m⁻¹``
(:data:`SWEEP_PATTERNS`, :func:`lanes_source`), 14 % more.

The readable twin is :func:`hybmss.models.xpbd_nh.constraints.numpy_substep` (same order, plain Python).
"""

from __future__ import annotations

import hashlib
import math

import numpy as np
from numba import njit

from ..._kernels import apply_plates, find_bad, plate_scratch, ramp
from ..._stencil_gen import import_generated

_OPTS = dict(cache=True, error_model="numpy", fastmath=False, nogil=True)


@njit(**_OPTS)
def _gradients(x, posmode, i0, i1, i2, i3, Dm, kind, gamma, F, P, Gr):
    """C and its node gradients Gr (3, 4) of constraint ``kind`` (0: C_D, 1: C_H) of a tetrahedron
    (``F`` is left holding its deformation gradient)."""
    deformation_gradient(x, posmode, i0, i1, i2, i3, Dm, F)
    if kind == 1:
        return _hydrostatic_from(F, Dm, gamma, P, Gr)
    C = math.sqrt(F[0, 0] ** 2 + F[0, 1] ** 2 + F[0, 2] ** 2 + F[1, 0] ** 2 + F[1, 1] ** 2 + F[1, 2] ** 2
                  + F[2, 0] ** 2 + F[2, 1] ** 2 + F[2, 2] ** 2)
    for a in range(3):
        s = 0.0
        for j in range(3):
            gj = (F[a, 0] * Dm[j, 0] + F[a, 1] * Dm[j, 1] + F[a, 2] * Dm[j, 2]) / C
            Gr[a, j + 1] = gj
            s += gj
        Gr[a, 0] = -s
    return C


@njit(**_OPTS)
def deformation_gradient(x, posmode, i0, i1, i2, i3, Dm, F):
    """``F = D_s D_m⁻¹`` of a tetrahedron, in float64: ``x`` holds positions (``posmode``) or
    displacements (then ``F = I + D_u D_m⁻¹``, as ``D_X D_m⁻¹ = I``)."""
    for a in range(3):
        e1 = x[a, i1] - x[a, i0]
        e2 = x[a, i2] - x[a, i0]
        e3 = x[a, i3] - x[a, i0]
        for b in range(3):
            F[a, b] = e1 * Dm[0, b] + e2 * Dm[1, b] + e3 * Dm[2, b]
    if not posmode:
        F[0, 0] += 1.0
        F[1, 1] += 1.0
        F[2, 2] += 1.0


@njit(**_OPTS)
def _tet_stress(x, tets, Dminv, t, F, cof):
    """``F`` (:func:`deformation_gradient` of positions ``x`` (3, n)) and ``cof F`` of tetrahedron
    ``t``, and its ``J``, in the order of :meth:`hybmss.models.xpbd_nh.constraints.XpbdNH.forces_numpy`
    (cofactor columns ``f₁ × f₂, f₂ × f₀, f₀ × f₁``, ``J = f₀ · (f₁ × f₂)``)."""
    deformation_gradient(x, True, tets[t, 0], tets[t, 1], tets[t, 2], tets[t, 3], Dminv[t], F)
    for c in range(3):
        j, k = (c + 1) % 3, (c + 2) % 3
        cof[0, c] = F[1, j] * F[2, k] - F[2, j] * F[1, k]
        cof[1, c] = F[2, j] * F[0, k] - F[0, j] * F[2, k]
        cof[2, c] = F[0, j] * F[1, k] - F[1, j] * F[0, k]
    return F[0, 0] * cof[0, 0] + F[1, 0] * cof[1, 0] + F[2, 0] * cof[2, 0]


@njit(**_OPTS)
def term_forces(x, tets, Dminv, Vt, mu, lam, gamma):
    """``−∇E`` (n, 3) of the constraints' energy at positions ``x`` (3, n): compiled twin of
    :meth:`hybmss.models.xpbd_nh.constraints.XpbdNH.forces_numpy` (the same formulas, summed
    into the nodes in the same order), which takes 10–20× as long: the force residual the rest
    tests of an explicit run read every 0.25 s of simulated time."""
    out = np.zeros((x.shape[1], 3))
    F = np.empty((3, 3))
    cof = np.empty((3, 3))
    H = np.empty((3, 3))
    for t in range(tets.shape[0]):
        J = _tet_stress(x, tets, Dminv, t, F, cof)
        s = lam * (J - gamma)
        for a in range(3):
            p0 = mu * F[a, 0] + s * cof[a, 0]
            p1 = mu * F[a, 1] + s * cof[a, 1]
            p2 = mu * F[a, 2] + s * cof[a, 2]
            for j in range(3):
                H[a, j] = -Vt[t] * (p0 * Dminv[t, j, 0] + p1 * Dminv[t, j, 1] + p2 * Dminv[t, j, 2])
        for a in range(3):
            out[tets[t, 0], a] += -(H[a, 0] + H[a, 1] + H[a, 2])
        for j in range(3):
            for a in range(3):
                out[tets[t, j + 1], a] += H[a, j]
    return out


@njit(**_OPTS)
def term_energy(x, tets, Dminv, Vt, mu, lam, gamma):
    """The constraints' energy at positions ``x`` (3, n): compiled twin of
    :meth:`hybmss.models.xpbd_nh.constraints.XpbdNH.energy_numpy` (its ``J`` by the cofactor
    expansion of :func:`_tet_stress`, NumPy's by an LU factorization)."""
    F = np.empty((3, 3))
    cof = np.empty((3, 3))
    e = 0.0
    for t in range(tets.shape[0]):
        J = _tet_stress(x, tets, Dminv, t, F, cof)
        ff = 0.0
        for a in range(3):
            for b in range(3):
                ff += F[a, b] * F[a, b]
        psi = 0.5 * mu * (ff - 3.0) + 0.5 * lam * (J - gamma) ** 2 - 0.5 * lam * (1.0 - gamma) ** 2
        e += Vt[t] * psi
    return e


@njit(**_OPTS)
def _hydrostatic_from(F, Dm, gamma, P, Gr):
    """C_H and its gradients Gr (3, 4) from a deformation gradient F already computed (``P``
    is left holding cof F)."""
    P[0, 0] = F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]
    P[0, 1] = F[1, 2] * F[2, 0] - F[1, 0] * F[2, 2]
    P[0, 2] = F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]
    P[1, 0] = F[2, 1] * F[0, 2] - F[2, 2] * F[0, 1]
    P[1, 1] = F[2, 2] * F[0, 0] - F[2, 0] * F[0, 2]
    P[1, 2] = F[2, 0] * F[0, 1] - F[2, 1] * F[0, 0]
    P[2, 0] = F[0, 1] * F[1, 2] - F[0, 2] * F[1, 1]
    P[2, 1] = F[0, 2] * F[1, 0] - F[0, 0] * F[1, 2]
    P[2, 2] = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
    C = F[0, 0] * P[0, 0] + F[0, 1] * P[0, 1] + F[0, 2] * P[0, 2] - gamma
    for a in range(3):
        s = 0.0
        for j in range(3):
            gj = P[a, 0] * Dm[j, 0] + P[a, 1] * Dm[j, 1] + P[a, 2] * Dm[j, 2]
            Gr[a, j + 1] = gj
            s += gj
        Gr[a, 0] = -s
    return C


@njit(**_OPTS)
def _wdot(Wl, A, B):
    """Σ_i A_iᵀ W_i B_i over the tetrahedron's nodes (``Wl`` (3, 4) their inverse masses)."""
    s = 0.0
    for k in range(4):
        for a in range(3):
            s += Wl[a, k] * A[a, k] * B[a, k]
    return s


@njit(**_OPTS)
def _move(x, tets, t, Wl, A, da, B, db):
    for k in range(4):
        q = tets[t, k]
        for a in range(3):
            x[a, q] += Wl[a, k] * (A[a, k] * da + B[a, k] * db)


@njit(**_OPTS)
def project_all(x, posmode, winv, tets, Dminv, Vt, mu, lam, gamma, h, iterations, coupled, lamb):
    """``iterations`` Gauss–Seidel sweeps (multipliers ``lamb`` (T, 2) reset first).  ``coupled``:
    both constraints of a tetrahedron in one 2×2 solve; else C_D then C_H, one after the other.
    ``x``: positions (``posmode``) or displacements (the float32 state, :func:`run`); the
    constraint arithmetic is float64 either way.  The compliances ``α̃ = 1/(μ V h²)``, ``1/(λ V h²)`` are
    products of precomputed inverses (one division per tetrahedron)."""
    F = np.empty((3, 3))
    P = np.empty((3, 3))
    GD = np.empty((3, 4))
    GH = np.empty((3, 4))
    Wl = np.empty((3, 4))
    nt = tets.shape[0]
    for t in range(nt):
        lamb[t, 0] = 0.0
        lamb[t, 1] = 0.0
    ih2 = 1.0 / (h * h)
    imu = 1.0 / mu
    ilam = 1.0 / lam
    for it in range(iterations):
        for t in range(nt):
            i0 = tets[t, 0]
            i1 = tets[t, 1]
            i2 = tets[t, 2]
            i3 = tets[t, 3]
            Dm = Dminv[t]
            iv = ih2 / Vt[t]
            aD = imu * iv
            aH = ilam * iv
            for k in range(4):
                q = tets[t, k]
                for a in range(3):
                    Wl[a, k] = winv[a, q]
            if coupled:  # one F for both constraints, written out (the hot loop)
                for a in range(3):
                    x0 = x[a, i0]
                    e1 = x[a, i1] - x0
                    e2 = x[a, i2] - x0
                    e3 = x[a, i3] - x0
                    for b in range(3):
                        F[a, b] = e1 * Dm[0, b] + e2 * Dm[1, b] + e3 * Dm[2, b]
                if not posmode:
                    F[0, 0] += 1.0
                    F[1, 1] += 1.0
                    F[2, 2] += 1.0
                s2 = 0.0
                for a in range(3):
                    for b in range(3):
                        s2 += F[a, b] * F[a, b]
                CD = math.sqrt(s2)
                ic = 1.0 / CD
                P[0, 0] = F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]
                P[0, 1] = F[1, 2] * F[2, 0] - F[1, 0] * F[2, 2]
                P[0, 2] = F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]
                P[1, 0] = F[2, 1] * F[0, 2] - F[2, 2] * F[0, 1]
                P[1, 1] = F[2, 2] * F[0, 0] - F[2, 0] * F[0, 2]
                P[1, 2] = F[2, 0] * F[0, 1] - F[2, 1] * F[0, 0]
                P[2, 0] = F[0, 1] * F[1, 2] - F[0, 2] * F[1, 1]
                P[2, 1] = F[0, 2] * F[1, 0] - F[0, 0] * F[1, 2]
                P[2, 2] = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
                CH = F[0, 0] * P[0, 0] + F[0, 1] * P[0, 1] + F[0, 2] * P[0, 2] - gamma
                a11 = aD
                a12 = 0.0
                a22 = aH
                for a in range(3):
                    sD = 0.0
                    sH = 0.0
                    for j in range(3):
                        gd = (F[a, 0] * Dm[j, 0] + F[a, 1] * Dm[j, 1] + F[a, 2] * Dm[j, 2]) * ic
                        gh = P[a, 0] * Dm[j, 0] + P[a, 1] * Dm[j, 1] + P[a, 2] * Dm[j, 2]
                        GD[a, j + 1] = gd
                        GH[a, j + 1] = gh
                        sD += gd
                        sH += gh
                    GD[a, 0] = -sD
                    GH[a, 0] = -sH
                    for k in range(4):
                        w = Wl[a, k]
                        a11 += w * GD[a, k] * GD[a, k]
                        a12 += w * GD[a, k] * GH[a, k]
                        a22 += w * GH[a, k] * GH[a, k]
                b1 = -CD - aD * lamb[t, 0]
                b2 = -CH - aH * lamb[t, 1]
                idet = 1.0 / (a11 * a22 - a12 * a12)
                d1 = (a22 * b1 - a12 * b2) * idet
                d2 = (a11 * b2 - a12 * b1) * idet
                for k in range(4):
                    q = tets[t, k]
                    for a in range(3):
                        x[a, q] += Wl[a, k] * (GD[a, k] * d1 + GH[a, k] * d2)
                lamb[t, 0] += d1
                lamb[t, 1] += d2
            else:
                CD = _gradients(x, posmode, i0, i1, i2, i3, Dm, 0, gamma, F, P, GD)
                d1 = (-CD - aD * lamb[t, 0]) / (aD + _wdot(Wl, GD, GD))
                _move(x, tets, t, Wl, GD, d1, GD, 0.0)
                lamb[t, 0] += d1
                CH = _gradients(x, posmode, i0, i1, i2, i3, Dm, 1, gamma, F, P, GH)
                d2 = (-CH - aH * lamb[t, 1]) / (aH + _wdot(Wl, GH, GH))
                _move(x, tets, t, Wl, GH, d2, GH, 0.0)
                lamb[t, 1] += d2


# ------------------------------------------------------------------------------ cells in SIMD lanes
LANES = 4
"""Cells projected side by side (one SIMD lane each): one AVX2 register of doubles.  Eight (two
registers) hold twice the values live through a tetrahedron's projection and spill them: on the
8×8×48 beam at ν = 0.499 (Zen 3) a sweep took 0.78 ms with 8 lanes and 0.69 ms with 4, the same
bits."""

SLOTS = 48
"""Rows of the lane buffer: the 8 corners' positions (3 each), then their inverse masses."""

SWEEP_TETS = ((0, 3, 6, 5), (1, 0, 5, 3), (2, 3, 6, 0), (4, 5, 0, 6), (7, 6, 3, 5),
              (1, 2, 4, 7), (0, 1, 2, 4), (3, 2, 1, 7), (5, 4, 7, 1), (6, 7, 4, 2))
"""Local corners of a cell's ten tetrahedra in sweep order, positively oriented: the literal
twin of :func:`hybmss.models.xpbd_nh.constraints.cell_tetrahedra` (a test keeps them equal)."""

SWEEP_PATTERNS = (0, 2, 2, 2, 2, 0, 1, 1, 1, 1)
"""Which entries of each tetrahedron's ``D_m⁻¹`` (sweep order) are non-zero: 0 all (the central
tetrahedra, on face diagonals); 1 the diagonal (corner tetrahedra with their edges along x, y, z);
2 ``d00, d12, d21`` (edges along x, z, y).  A test derives the patterns from
:func:`hybmss.models.xpbd_nh.constraints.cell_tetrahedra`."""

# The lane sweep is written out as source (:func:`lanes_source`) and compiled as one function.
# Written as functions that Numba inlines (``inline="always"``), the same arithmetic took 34 s to
# compile, most of it the inlining (each call site runs the callee through Numba's front end
# again); left to LLVM to inline, 10 s, but a step of the 8×8×48 beam took 1.06–1.10× as long.
# Written out: 12.7 s, the same bits (a test), and a step as fast as with Numba's inlining
# (minimum of 30 and 40 alternations in one process: 1.011× and 1.008×; medians 0.97× and 1.00×).


def _dot(k: int, pattern: int, a: tuple, d: tuple) -> str:
    """``a0 d0 + a1 d1 + a2 d2`` for row or column ``k`` of a ``D_m⁻¹`` of zero pattern ``pattern``,
    without the terms that pattern makes zero.  The same bits: for finite ``a``, ``a · 0`` is ±0,
    and adding ±0 to the other terms changes at most the sign of an exact zero, which no later
    operation of the projection tells apart."""
    nz = None if pattern == 0 else (k if pattern == 1 or k == 0 else 3 - k)
    if nz is None:
        return f"{a[0]} * {d[0]} + {a[1]} * {d[1]} + {a[2]} * {d[2]}"
    return f"{a[nz]} * {d[nz]}"


def _tetrahedron(out: list, ind: str, t: int, corners: tuple, pattern: int) -> None:
    """The projection of tetrahedron ``t`` of every lane's cell (the coupled branch of
    ``project_all`` for one iteration, multipliers at 0), appended to ``out``.  ``one``: 1 on
    displacements (``F = I + D_u D_m⁻¹``), 0 on positions (adding 0 to F's diagonal, ≈ 1, leaves
    it unchanged: one loop serves both states)."""
    L = LANES
    p = [3 * c * L for c in corners]  # row of component x of each corner's position
    q = [v + 24 * L for v in p]  # and of its inverse mass
    D = [[f"d{i}{j}" for j in range(3)] for i in range(3)]

    def line(text: str, extra: int = 0):
        out.append(ind + "    " * extra + text)

    line(f"# tetrahedron {t}: corners {corners}, pattern {pattern}")
    line(", ".join(D[0] + D[1] + D[2]) + " = " + ", ".join(f"Dm[{t}, {i}, {j}]" for i in range(3) for j in range(3)))
    line(f"aDt = aD[{t}]")
    line(f"aHt = aH[{t}]")
    line(f"for l in range({L}):")
    for a in range(3):  # F = D_s D_m⁻¹, row a from the edges of component a
        r = [v + a * L for v in p]
        line(f"x0 = B[{r[0]} + l]", 1)
        line(f"e1 = B[{r[1]} + l] - x0", 1)
        line(f"e2 = B[{r[2]} + l] - x0", 1)
        line(f"e3 = B[{r[3]} + l] - x0", 1)
        for b in range(3):
            line(f"F{a}{b} = " + _dot(b, pattern, ("e1", "e2", "e3"), (D[0][b], D[1][b], D[2][b])), 1)
    for a in range(3):
        line(f"F{a}{a} += one", 1)
    line("s2 = 0.0", 1)
    for a in range(3):
        for b in range(3):
            line(f"s2 += F{a}{b} * F{a}{b}", 1)
    line("CD = math.sqrt(s2)", 1)
    line("ic = 1.0 / CD", 1)
    for i in range(3):  # cof F (hybmss._kernels.cofactor3)
        for j in range(3):
            i1, i2, j1, j2 = (i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3
            line(f"P{i}{j} = F{i1}{j1} * F{i2}{j2} - F{i1}{j2} * F{i2}{j1}", 1)
    line("CH = F00 * P00 + F01 * P01 + F02 * P02 - gamma", 1)
    for a, comp in enumerate("xyz"):  # the gradients of C_D (g) and C_H (h) at the corners
        line(f"w0{comp}, w1{comp}, w2{comp}, w3{comp} = " + ", ".join(f"B[{v + a * L} + l]" for v in q), 1)
    sums = ("aDt", "0.0", "aHt")
    for a, comp in enumerate("xyz"):
        f = (f"F{a}0", f"F{a}1", f"F{a}2")
        P = (f"P{a}0", f"P{a}1", f"P{a}2")
        for j in range(3):
            line(f"g{j + 1}{comp} = ({_dot(j, pattern, f, tuple(D[j]))}) * ic", 1)
            line(f"h{j + 1}{comp} = {_dot(j, pattern, P, tuple(D[j]))}", 1)
        line(f"g0{comp} = -(((0.0 + g1{comp}) + g2{comp}) + g3{comp})", 1)
        line(f"h0{comp} = -(((0.0 + h1{comp}) + h2{comp}) + h3{comp})", 1)
        for k in range(4):  # the Gram sums, corner after corner
            w, g, h = f"w{k}{comp}", f"g{k}{comp}", f"h{k}{comp}"
            line(f"a11, a12, a22 = {sums[0]} + {w} * {g} * {g}, {sums[1]} + {w} * {g} * {h}, "
                 f"{sums[2]} + {w} * {h} * {h}", 1)
            sums = ("a11", "a12", "a22")
    line("b1 = -CD - aDt * 0.0", 1)  # multipliers start the substep at 0: b = −C − α̃ · 0
    line("b2 = -CH - aHt * 0.0", 1)
    line("idet = 1.0 / (a11 * a22 - a12 * a12)", 1)
    line("d1 = (a22 * b1 - a12 * b2) * idet", 1)
    line("d2 = (a11 * b2 - a12 * b1) * idet", 1)
    for k in range(4):  # each corner moved by W (∇C_D d1 + ∇C_H d2)
        for a, comp in enumerate("xyz"):
            line(f"B[{p[k] + a * L} + l] += w{k}{comp} * (g{k}{comp} * d1 + h{k}{comp} * d2)", 1)


def lanes_source() -> str:
    """Python source of the module holding :func:`project_cells` (the docstring of the module)."""
    L = LANES
    out = [
        '"""Generated by hybmss.models.xpbd_nh._kernels.lanes_source: the lane sweep of xpbd-nh."""',
        "import math",
        "import numpy as np",
        "from numba import njit",
        "",
        "",
        "@njit(cache=True, error_model='numpy', fastmath=False, nogil=True)",
        "def project_cells(x, posmode, winv, bnodes, bcount, Dm, Vt, mu, lam, gamma, h, B):",
        f'    """{PROJECT_CELLS_DOC}"""',
        "    ih2 = 1.0 / (h * h)",
        "    imu = 1.0 / mu",
        "    ilam = 1.0 / lam",
        "    aD = np.empty(10)",
        "    aH = np.empty(10)",
        "    for t in range(10):",
        "        iv = ih2 / Vt[t]",
        "        aD[t] = imu * iv",
        "        aH[t] = ilam * iv",
        "    one = 0.0 if posmode else 1.0",
        "    for b in range(bnodes.shape[0]):",
        "        for c in range(8):",
        f"            for l in range({L}):",
        "                q = bnodes[b, c, l]",
        f"                B[3 * c * {L} + l] = x[0, q]",
        f"                B[(3 * c + 1) * {L} + l] = x[1, q]",
        f"                B[(3 * c + 2) * {L} + l] = x[2, q]",
        f"                B[(24 + 3 * c) * {L} + l] = winv[0, q]",
        f"                B[(25 + 3 * c) * {L} + l] = winv[1, q]",
        f"                B[(26 + 3 * c) * {L} + l] = winv[2, q]",
    ]
    for t, (corners, pattern) in enumerate(zip(SWEEP_TETS, SWEEP_PATTERNS)):
        _tetrahedron(out, "        ", t, corners, pattern)
    out += [
        "        for c in range(8):",
        "            for l in range(bcount[b]):",
        "                q = bnodes[b, c, l]",
        f"                x[0, q] = B[3 * c * {L} + l]",
        f"                x[1, q] = B[(3 * c + 1) * {L} + l]",
        f"                x[2, q] = B[(3 * c + 2) * {L} + l]",
    ]
    return "\n".join(out) + "\n"


PROJECT_CELLS_DOC = """One coupled Gauss–Seidel sweep (:func:`project_all`, ``iterations = 1``), bit for bit, with
    the cells of a batch in SIMD lanes.  ``bnodes`` (nb, 8, LANES): the corner nodes of the cells
    of each batch (lanes past ``bcount[b]`` repeat a cell of it and are not written back); the
    cells of a batch share no node and the batches follow :func:`cell_batches`, so every pair of
    tetrahedra that share a node is projected in the order of :func:`project_all`.  ``Dm``
    (10, 3, 3), ``Vt`` (10,): one cell's tetrahedra (the same in every cell); ``B`` a scratch of
    ``SLOTS · LANES``.  Generated (:func:`lanes_source`)."""


def _lanes_module():
    """The generated module of :func:`project_cells`, from the kernel cache (its name hashes its source)."""
    src = lanes_source()
    return import_generated("hybmss_xpbd_lanes_" + hashlib.sha1(src.encode()).hexdigest()[:20], src)


project_cells = _lanes_module().project_cells


@njit(**_OPTS)
def cell_levels(cells):
    """Sweep level of each cell (rows of ``cells`` (m, 8): corner nodes, in sweep order): one more
    than the highest level of an earlier cell it shares a node with.  Cells of one level share
    no node, and every pair that does is ordered as in the sweep."""
    n = 0
    for i in range(cells.shape[0]):
        for c in range(8):
            n = max(n, cells[i, c] + 1)
    node_level = np.zeros(n, dtype=np.int64)
    out = np.empty(cells.shape[0], dtype=np.int64)
    for i in range(cells.shape[0]):
        lv = 0
        for c in range(8):
            lv = max(lv, node_level[cells[i, c]])
        out[i] = lv
        for c in range(8):
            node_level[cells[i, c]] = lv + 1
    return out


@njit(**_OPTS)
def moved_since(x, xcheck):
    """Largest component change of ``x`` (3, n) since ``xcheck``, which then takes ``x``'s values."""
    moved = 0.0
    for d in range(3):
        for q in range(x.shape[1]):
            moved = max(moved, abs(x[d, q] - xcheck[d, q]))
            xcheck[d, q] = x[d, q]
    return moved


@njit(**_OPTS)
def checked(W, base, posmode, X, limit2, x, xcheck, resting, rest_disp):
    """The check of :func:`run` and ``relax`` every ``check_every`` substeps (iterations): ``(bad
    node or −1, 1 if at rest else 0)``.  A diverged node first; then, once ``resting`` (past the
    end of the ramp, at a whole check interval), at rest when no node of ``x`` (3, n) moved more
    than ``rest_disp`` since ``xcheck``; ``xcheck`` takes ``x``'s values either way."""
    n = X.shape[1]
    bad = find_bad(W, base, n, n, posmode, X, limit2)
    if bad >= 0:
        return bad, 0
    if resting:
        return -1, 1 if moved_since(x, xcheck) <= rest_disp else 0
    xcheck[:, :] = x
    return -1, 0


def uses_cells(bnodes: np.ndarray, iterations: int, coupled: bool) -> bool:
    """Whether a sweep is :func:`project_cells` (a lattice body's cells in batches, one coupled
    iteration) rather than :func:`project_all`."""
    return bnodes.shape[0] > 0 and iterations == 1 and bool(coupled)


def _kernels(cells: bool):
    """``run`` and ``relax`` with the sweep :func:`project_cells` (``cells``) or
    :func:`project_all`: ``cells`` is a constant of each, so each compiles the one sweep it calls
    (the other, compiled and linked into it for nothing, cost 6 s of a process's first run).
    Choose them with :func:`uses_cells` (:func:`stepping`)."""

    @njit(**_OPTS)
    def run(W, posmode, X, winv, tets, Dminv, Vt, mu, lam, gamma, gacc, has_gravity, h, damp, ramp_time, pl_nodes,
            pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis, pl_center, pl_angle, sub0, nsub, iterations,
            coupled, check_every, limit2, rest_after, rest_disp, xprev, lamb, bnodes, bcount, B):
        """Advance ``nsub`` substeps from global substep ``sub0``.  Every ``check_every`` substeps: a
        diverged node stops the run; after substep ``rest_after`` (the end of the ramp; −1: never) the
        run also stops once no node moved more than ``rest_disp`` over the last ``check_every``
        substeps.  ``W``: the state of :func:`hybmss._kernels.particle_state`.  Returns (substeps
        done, bad node or −1, 1 if at rest else 0).

        ``posmode``: ``W`` holds positions (float64).  Else it holds float32 displacements from ``X``
        and velocities: each substep runs on a float64 copy of the state and is rounded back at its
        end, so that the velocity ``(x − x_prev)/h`` is not the rounding of x divided by h (which
        would feed ~ulp(u)/h of noise into the motion every substep).  ``xprev`` (3, n) float64."""
        n = X.shape[1]
        Wk = np.empty(W.shape[0])
        for i in range(W.shape[0]):
            Wk[i] = W[i]
        x = Wk[:3 * n].reshape((3, n))
        v = Wk[3 * n:].reshape((3, n))
        R, u_old, u_new = plate_scratch(pl_ptr)
        xcheck = x.copy()
        done = nsub
        bad = -1
        rest = 0
        for k in range(nsub):
            step = sub0 + k
            for d in range(3):
                for q in range(n):
                    if has_gravity:
                        v[d, q] = (v[d, q] + h * gacc[d, q]) * damp
                    else:
                        v[d, q] = v[d, q] * damp
                    xprev[d, q] = x[d, q]
                    x[d, q] += h * v[d, q]
            if pl_ptr.shape[0] > 1:
                apply_plates(Wk, np.int64(0), 3 * n, n, posmode, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis,
                             pl_center, pl_angle, ramp(step * h, ramp_time), ramp((step + 1) * h, ramp_time), h, R,
                             u_old, u_new, 0, n)
            if cells:
                project_cells(x, posmode, winv, bnodes, bcount, Dminv, Vt, mu, lam, gamma, h, B)
            else:
                project_all(x, posmode, winv, tets, Dminv, Vt, mu, lam, gamma, h, iterations, coupled, lamb)
            for d in range(3):
                for q in range(n):
                    v[d, q] = (x[d, q] - xprev[d, q]) / h
            if not posmode:  # the stored state is float32
                for i in range(W.shape[0]):
                    W[i] = Wk[i]
                    Wk[i] = W[i]
            if (k + 1) % check_every == 0 or k == nsub - 1:
                resting = rest_after >= 0 and step + 1 >= rest_after and (k + 1) % check_every == 0
                bad, rest = checked(Wk, np.int64(0), posmode, X, limit2, x, xcheck, resting, rest_disp)
                if bad >= 0 or rest:
                    done = k + 1
                    break
        if posmode:
            for i in range(W.shape[0]):
                W[i] = Wk[i]
        return done, bad, rest


    @njit(**_OPTS)
    def relax(W, X, winv, tets, Dminv, Vt, mu, lam, gamma, gdisp, has_gravity, h, over, beta, H, ramp_time, pl_nodes,
              pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis, pl_center, pl_angle, k0, nk, iterations, coupled,
              check_every, limit2, rest_after, rest_disp, xprev, y, lamb, bnodes, bcount, B):
        """``nk`` iterations, from iteration ``k0``, of the relaxation to the rest state of the substep
        ``h`` (:func:`hybmss.models.xpbd_nh.relax.relax_static`), float64 positions ``W[:3n]``::

            y = x + β (x − x_prev);  z = y + gdisp  (gdisp = damp h² g on free components)
            prescribed components of z at the load s((k + 1) H);  p = project_h(z)
            x_new = y + over · (p − y)  on free components (p on prescribed ones)

        A fixed point (x = x_prev) has ``project_h(x + gdisp) = x``: the rest state of the XPBD
        substep, whatever ``over`` and ``β``.  Checks as in :func:`run`, every ``check_every``
        iterations.  ``W`` (6n,): positions, then a scratch for the plates' velocities.  Returns
        (iterations done, bad node or −1, 1 if at rest else 0)."""
        n = X.shape[1]
        x = W[:3 * n].reshape((3, n))
        # positions, as run-time values: a literal True or 0 would compile the callees (the sweep
        # takes 22 s) a second time, for this caller alone
        posmode = np.bool_(True)
        base = np.int64(0)
        R, u_old, u_new = plate_scratch(pl_ptr)
        xcheck = x.copy()
        done = nk
        bad = -1
        rest = 0
        for k in range(nk):
            it = k0 + k
            for d in range(3):
                for q in range(n):
                    yq = x[d, q] + beta * (x[d, q] - xprev[d, q])
                    xprev[d, q] = x[d, q]
                    y[d, q] = yq
                    x[d, q] = yq + gdisp[d, q] if has_gravity else yq
            if pl_ptr.shape[0] > 1:
                apply_plates(W, base, 3 * n, n, posmode, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis,
                             pl_center, pl_angle, ramp(it * H, ramp_time), ramp((it + 1) * H, ramp_time), H, R,
                             u_old, u_new, 0, n)
            if cells:
                project_cells(x, posmode, winv, bnodes, bcount, Dminv, Vt, mu, lam, gamma, h, B)
            else:
                project_all(x, posmode, winv, tets, Dminv, Vt, mu, lam, gamma, h, iterations, coupled, lamb)
            for d in range(3):
                for q in range(n):
                    if winv[d, q] != 0.0:
                        x[d, q] = y[d, q] + over * (x[d, q] - y[d, q])
            if (k + 1) % check_every == 0 or k == nk - 1:
                resting = rest_after >= 0 and it + 1 >= rest_after and (k + 1) % check_every == 0
                bad, rest = checked(W, base, posmode, X, limit2, x, xcheck, resting, rest_disp)
                if bad >= 0 or rest:
                    done = k + 1
                    break
        return done, bad, rest

    return run, relax


_STEPPING = {cells: _kernels(cells) for cells in (True, False)}


def stepping(bnodes: np.ndarray, iterations: int, coupled: bool):
    """``(run, relax)`` for a body's batches ``bnodes`` and a sweep of ``iterations`` iterations,
    ``coupled`` or not (:func:`uses_cells`)."""
    return _STEPPING[uses_cells(bnodes, iterations, coupled)]
