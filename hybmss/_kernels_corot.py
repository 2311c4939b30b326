"""Numba kernel of the corotational hexahedra (``corot-hex8``, ``corot-hex8-sri``): explicit steps.

Same layout and protocol as :mod:`hybmss._kernels` on particle arrays: ``x, v, X`` are (3, n)
positions, velocities (at half steps) and reference positions, ``invm`` (n,) 1/m, ``gacc`` (3, n)
gravity.  One step:

1. per cell: the deformation gradient at the centre ``F = (1/(4 le)) Σ_c x_c ⊗ ξ_c``, its polar
   rotation R (Newton iteration ``R ← ½ (R + R⁻ᵀ)``, :func:`polar_rotation`), the local
   displacement ``u_c = Rᵀ (x_c − x̄) − (X_c − X̄)``, ``g = K_e u`` and the forces ``−R g_c``
   added to the corners (serial scatter); ``g = K_e u`` is one matrix product over all cells;
2. ``v ← (v + dt (f/m + g)) / (1 + c dt)``, ``x ← x + dt v``;
3. plates and the divergence check of :func:`hybmss._kernels.end_of_step`.

Precision: the state ``W`` holds float64 positions or float32 displacements (``posmode`` False,
:mod:`hybmss.models._voxel_explicit`); the element arithmetic is float64 in both.

The readable twin is :mod:`hybmss.models.corot_hex8` (NumPy, vectorized over cells).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._kernels import end_of_step, plate_scratch

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


@njit(**_OPTS)
def corot_forces(x, X, posmode, cells, Ke, XI, inv4le, f, Rs, U, G):
    """Internal forces f (3, n) of the corotational hexahedra at positions x (3, n) (overwritten).

    Three passes: per cell the rotation ``Rs[e]`` and local displacement ``U[e]`` (24,); then
    ``G = U K_e`` for all cells at once (one matrix product, K_e symmetric); then the scatter of
    ``−R_e G_e`` to the corners.  ``Rs`` (m, 3, 3), ``U`` and ``G`` (m, 24) are scratch.
    ``x`` holds positions (``posmode``) or displacements from ``X`` (the float32 state: the element
    arithmetic is float64 on ``X + u``, relative positions ``(X_c − X̄) + (u_c − ū)``)."""
    n = x.shape[1]
    m = cells.shape[0]
    F = np.empty((3, 3))
    T = np.empty((3, 3))
    xl = np.empty((8, 3))
    for e in range(m):
        R = Rs[e]
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
        for a in range(3):
            for b in range(3):
                F[a, b] = 0.0
        for c in range(8):
            q = cells[e, c]
            xl[c, 0] = np.float64(x[0, q]) - xb0
            xl[c, 1] = np.float64(x[1, q]) - xb1
            xl[c, 2] = np.float64(x[2, q]) - xb2
            if not posmode:  # displacements: relative positions (X_c − X̄) + (u_c − ū)
                xl[c, 0] += X[0, q] - Xb0
                xl[c, 1] += X[1, q] - Xb1
                xl[c, 2] += X[2, q] - Xb2
            for a in range(3):
                xa = np.float64(x[a, q]) if posmode else X[a, q] + np.float64(x[a, q])
                for b in range(3):
                    F[a, b] += xa * XI[c, b]
        for a in range(3):
            for b in range(3):
                F[a, b] *= inv4le
        polar_rotation(F, R, T)
        u = U[e]
        for c in range(8):
            q = cells[e, c]
            for i in range(3):
                u[3 * c + i] = R[0, i] * xl[c, 0] + R[1, i] * xl[c, 1] + R[2, i] * xl[c, 2]
            u[3 * c] -= X[0, q] - Xb0
            u[3 * c + 1] -= X[1, q] - Xb1
            u[3 * c + 2] -= X[2, q] - Xb2
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


__all__ = ["polar_rotation", "corot_forces", "run_serial", "forces", "advance"]
