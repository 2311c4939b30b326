"""Numba kernel of the corotational hexahedra (``corot-hex8``, ``corot-hex8-sri``): explicit steps.

Same layout and protocol as :mod:`hybmss._kernels` on particle arrays: ``x, v, X`` are (3, n)
positions, velocities (at half steps) and reference positions, ``invm`` (n,) 1/m, ``gacc`` (3, n)
gravity.  One step:

1. per cell: the deformation gradient at the centre ``F = (1/(4 le)) Σ_c x_c ⊗ ξ_c``, its polar
   rotation R (Newton iteration ``R ← ½ (R + R⁻ᵀ)``, :func:`polar_rotation`; in the kernel four
   cells at once, :func:`polar_rotation_lanes`, the same bits), the local
   displacement ``u_c = Rᵀ (x_c − x̄) − (X_c − X̄)``, ``g = K_e u`` and the forces ``−R g_c``
   added to the corners (serial scatter); ``g = K_e u`` is one matrix product over all cells;
2. ``v ← (v + dt (f/m + g)) / (1 + c dt)``, ``x ← x + dt v``;
3. plates and the divergence check of :func:`hybmss._kernels.end_of_step`.

Precision: the state ``W`` holds float64 positions or float32 displacements (``posmode`` False,
:func:`hybmss._kernels.kernel_state`); the element arithmetic is float64 in both.

The readable twin is :mod:`hybmss.models.corot_hex8` (NumPy, vectorized over cells).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..._kernels import cofactor3, end_of_step, plate_scratch

_OPTS = dict(cache=True, error_model="numpy", fastmath=False, nogil=True)

POLAR_TOL = 1e-15
"""The polar iteration stops when no entry of R changes by more than this (R is O(1))."""
POLAR_MAX_ITER = 60


@njit(**_OPTS)
def polar_rotation(F, R, T):
    """Rotation R of the polar decomposition F = R U (F 3×3, det F > 0), by Newton's iteration
    ``R ← ½ (R + cof(R)/det R)`` (cof(R)/det R = R⁻ᵀ) from R = F; ``T`` is 3×3 scratch.
    Returns the number of iterations."""
    for i in range(3):
        for j in range(3):
            R[i, j] = F[i, j]
    for it in range(POLAR_MAX_ITER):
        for i in range(3):
            i1 = (i + 1) % 3
            i2 = (i + 2) % 3
            for j in range(3):
                j1 = (j + 1) % 3
                j2 = (j + 2) % 3
                T[i, j] = R[i1, j1] * R[i2, j2] - R[i1, j2] * R[i2, j1]
        det = R[0, 0] * T[0, 0] + R[0, 1] * T[0, 1] + R[0, 2] * T[0, 2]
        change = 0.0
        for i in range(3):
            for j in range(3):
                new = 0.5 * (R[i, j] + T[i, j] / det)
                change = max(change, abs(new - R[i, j]))
                R[i, j] = new
        if change <= POLAR_TOL:
            return it + 1
    return POLAR_MAX_ITER


LANES = 4
"""Cells whose polar rotations :func:`polar_rotation_lanes` computes side by side (one AVX2
register of doubles)."""


@njit(**_OPTS)
def polar_rotation_lanes(F, R, active):
    """:func:`polar_rotation` of :data:`LANES` matrices at once, bit for bit: ``F`` and ``R``
    (3, 3, LANES), ``active`` (LANES,) bool scratch.  Every lane makes the iterations it would
    make alone (one that has converged keeps its R while the others go on), so LLVM can run the
    lanes in one SIMD register: the divisions, most of the iteration's cost, then cost a quarter.
    On the 8×8×48 beam the force stage of a step took 338 ns per cell with the scalar iteration
    (120 ns of it the rotation)."""
    for i in range(3):
        for j in range(3):
            for l in range(LANES):
                R[i, j, l] = F[i, j, l]
    for l in range(LANES):
        active[l] = True
    for _ in range(POLAR_MAX_ITER):
        for l in range(LANES):
            r00, r01, r02 = R[0, 0, l], R[0, 1, l], R[0, 2, l]
            r10, r11, r12 = R[1, 0, l], R[1, 1, l], R[1, 2, l]
            r20, r21, r22 = R[2, 0, l], R[2, 1, l], R[2, 2, l]
            t00, t01, t02, t10, t11, t12, t20, t21, t22 = cofactor3(r00, r01, r02, r10, r11, r12, r20, r21, r22)
            det = r00 * t00 + r01 * t01 + r02 * t02
            n00 = 0.5 * (r00 + t00 / det)
            n01 = 0.5 * (r01 + t01 / det)
            n02 = 0.5 * (r02 + t02 / det)
            n10 = 0.5 * (r10 + t10 / det)
            n11 = 0.5 * (r11 + t11 / det)
            n12 = 0.5 * (r12 + t12 / det)
            n20 = 0.5 * (r20 + t20 / det)
            n21 = 0.5 * (r21 + t21 / det)
            n22 = 0.5 * (r22 + t22 / det)
            change = 0.0
            change = max(change, abs(n00 - r00))
            change = max(change, abs(n01 - r01))
            change = max(change, abs(n02 - r02))
            change = max(change, abs(n10 - r10))
            change = max(change, abs(n11 - r11))
            change = max(change, abs(n12 - r12))
            change = max(change, abs(n20 - r20))
            change = max(change, abs(n21 - r21))
            change = max(change, abs(n22 - r22))
            a = active[l]
            R[0, 0, l] = n00 if a else r00
            R[0, 1, l] = n01 if a else r01
            R[0, 2, l] = n02 if a else r02
            R[1, 0, l] = n10 if a else r10
            R[1, 1, l] = n11 if a else r11
            R[1, 2, l] = n12 if a else r12
            R[2, 0, l] = n20 if a else r20
            R[2, 1, l] = n21 if a else r21
            R[2, 2, l] = n22 if a else r22
            active[l] = a and not change <= POLAR_TOL
        going = False
        for l in range(LANES):
            going = going or active[l]
        if not going:
            return


@njit(**_OPTS)
def corot_forces(x, X, posmode, cells, Ke, XI, inv4le, f, Rs, U, G):
    """Internal forces f (3, n) of the corotational hexahedra at positions x (3, n) (overwritten).

    Three passes: per cell the rotation ``Rs[e]`` and local displacement ``U[e]`` (24,), the
    rotations of :data:`LANES` cells at once (:func:`polar_rotation_lanes`; the last batch repeats
    its last cell); then ``G = U K_e`` for all cells at once (one matrix product, K_e symmetric);
    then the scatter of ``−R_e G_e`` to the corners.  ``Rs`` (m, 3, 3), ``U`` and ``G`` (m, 24)
    are scratch.  ``x`` holds positions (``posmode``) or displacements from ``X`` (the float32
    state: the element arithmetic is float64 on ``X + u``, relative positions
    ``(X_c − X̄) + (u_c − ū)``)."""
    n = x.shape[1]
    m = cells.shape[0]
    Fl = np.empty((3, 3, LANES))
    Rl = np.empty((3, 3, LANES))
    active = np.empty(LANES, dtype=np.bool_)
    xl = np.empty((LANES, 8, 3))
    Xbl = np.empty((LANES, 3))
    for e0 in range(0, m, LANES):
        for l in range(LANES):
            e = min(e0 + l, m - 1)
            xb0 = 0.0
            xb1 = 0.0
            xb2 = 0.0
            Xb0 = 0.0
            Xb1 = 0.0
            Xb2 = 0.0
            for c in range(8):
                q = cells[e, c]
                xb0 += np.float64(x[0, q])
                xb1 += np.float64(x[1, q])
                xb2 += np.float64(x[2, q])
                Xb0 += X[0, q]
                Xb1 += X[1, q]
                Xb2 += X[2, q]
            xb0 *= 0.125
            xb1 *= 0.125
            xb2 *= 0.125
            Xb0 *= 0.125
            Xb1 *= 0.125
            Xb2 *= 0.125
            Xbl[l, 0] = Xb0
            Xbl[l, 1] = Xb1
            Xbl[l, 2] = Xb2
            for a in range(3):
                for b in range(3):
                    Fl[a, b, l] = 0.0
            for c in range(8):
                q = cells[e, c]
                xl[l, c, 0] = np.float64(x[0, q]) - xb0
                xl[l, c, 1] = np.float64(x[1, q]) - xb1
                xl[l, c, 2] = np.float64(x[2, q]) - xb2
                if not posmode:  # displacements: relative positions (X_c − X̄) + (u_c − ū)
                    xl[l, c, 0] += X[0, q] - Xb0
                    xl[l, c, 1] += X[1, q] - Xb1
                    xl[l, c, 2] += X[2, q] - Xb2
                for a in range(3):
                    xa = np.float64(x[a, q]) if posmode else X[a, q] + np.float64(x[a, q])
                    for b in range(3):
                        Fl[a, b, l] += xa * XI[c, b]
            for a in range(3):
                for b in range(3):
                    Fl[a, b, l] *= inv4le
        polar_rotation_lanes(Fl, Rl, active)
        for l in range(min(LANES, m - e0)):
            e = e0 + l
            R = Rs[e]
            for i in range(3):
                for j in range(3):
                    R[i, j] = Rl[i, j, l]
            u = U[e]
            for c in range(8):
                q = cells[e, c]
                for i in range(3):
                    u[3 * c + i] = R[0, i] * xl[l, c, 0] + R[1, i] * xl[l, c, 1] + R[2, i] * xl[l, c, 2]
                u[3 * c] -= X[0, q] - Xbl[l, 0]
                u[3 * c + 1] -= X[1, q] - Xbl[l, 1]
                u[3 * c + 2] -= X[2, q] - Xbl[l, 2]
    G[:, :] = np.dot(U, Ke)
    for d in range(3):
        for q in range(n):
            f[d, q] = 0.0
    for e in range(m):
        R = Rs[e]
        g = G[e]
        for c in range(8):
            q = cells[e, c]
            g0 = g[3 * c]
            g1 = g[3 * c + 1]
            g2 = g[3 * c + 2]
            for a in range(3):
                f[a, q] -= R[a, 0] * g0 + R[a, 1] * g1 + R[a, 2] * g2


@njit(**_OPTS)
def run_serial(W, posmode, X, cells, Ke, XI, inv4le, invm, gacc, has_gravity, dt, damp, ramp_time, pl_nodes, pl_U1,
               pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis, pl_center, pl_angle, step0, nsteps, check_every,
               limit2, f):
    """Advance ``nsteps`` steps from global step ``step0`` on the state ``W`` of
    :func:`hybmss._kernels.particle_state` (``posmode``: positions, float64; else displacements
    from ``X``, float32).  Returns (steps done, bad node or −1)."""
    n = X.shape[1]
    x = W[:3 * n].reshape((3, n))
    v = W[3 * n:].reshape((3, n))
    R, u_old, u_new = plate_scratch(pl_ptr)
    m = cells.shape[0]
    Rs = np.empty((m, 3, 3))
    U = np.empty((m, 24))
    G = np.empty((m, 24))
    for it in range(nsteps):
        corot_forces(x, X, posmode, cells, Ke, XI, inv4le, f, Rs, U, G)
        for d in range(3):
            if has_gravity:
                for q in range(n):
                    v[d, q] = (v[d, q] + dt * (f[d, q] * invm[q] + gacc[d, q])) * damp
                    x[d, q] += dt * v[d, q]
            else:
                for q in range(n):
                    v[d, q] = (v[d, q] + dt * (f[d, q] * invm[q])) * damp
                    x[d, q] += dt * v[d, q]
        bad = end_of_step(W, np.int64(0), 3 * n, n, n, posmode, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis, pl_center,
                          pl_angle, step0 + it, dt, ramp_time, R, u_old, u_new, it, nsteps, check_every, limit2)
        if bad >= 0:
            return it + 1, bad
    return nsteps, -1


def forces(x, X, cells, Ke, XI, le):
    """Internal forces (n, 3) at positions ``x`` (n, 3): the kernel's force stage alone."""
    f = np.empty((3, len(x)))
    m = len(cells)
    corot_forces(np.ascontiguousarray(x.T), np.ascontiguousarray(X.T), True, cells, Ke, XI, 1.0 / (4.0 * le), f,
                 np.empty((m, 3, 3)), np.empty((m, 24)), np.empty((m, 24)))
    return f.T.copy()


def advance(W, X, cells, Ke, XI, le, invm, gacc, has_gravity, dt, damp, ramp_time, plates, step0, nsteps,
            check_every, limit2, f, posmode=True):
    """Run ``nsteps`` steps on the state ``W`` (:func:`hybmss._kernels.particle_state`; positions,
    or with ``posmode`` False float32 displacements) in place; (steps done, bad particle or −1)."""
    done, bad = run_serial(W, bool(posmode), X, cells, Ke, XI, 1.0 / (4.0 * le), invm, gacc, bool(has_gravity), float(dt),
                           float(damp), float(ramp_time), *plates.args(), np.int64(step0), np.int64(nsteps),
                           np.int64(max(1, check_every)), float(limit2), f)
    return int(done), int(bad)


__all__ = ["polar_rotation", "polar_rotation_lanes", "corot_forces", "run_serial", "forces", "advance"]
