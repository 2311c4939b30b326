"""Numba twins of the energies, forces and Hessian of :mod:`hybmss.forces` (the NumPy reference),
for the static and implicit Newton solvers, which evaluate them at every iteration and line-search
trial.

The Hessian is written into the data array of the fixed CSR pattern of
:func:`hybmss.forces._pattern` through its scatter map (``slots``): the 3×3 blocks of the springs'
``[[K, −K], [−K, K]]`` (rows aa, bb, ab, ba of ``slots[:4 s 9]``) and the 8×8 corner blocks of each
volume cell (``slots[4 s 9:]``, in the order (p, q, i, j)), so no COO matrix is formed and the
pattern never changes.  ``form``: 0 for the ``quadratic`` volume energy, 1 for ``squared``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .lattice import VOLUME_SIGNS

_OPTS = dict(cache=True, error_model="numpy", fastmath=False, nogil=True)

FORMS = {"quadratic": 0, "squared": 1}
_SIGNS = np.ascontiguousarray(VOLUME_SIGNS, dtype=np.float64)


@njit(**_OPTS)
def spring_energy_forces(x, a, b, k, l0, f):
    """Adds the spring forces to ``f`` (n, 3); returns the spring energy."""
    e = 0.0
    for s in range(a.shape[0]):
        i, j = a[s], b[s]
        d0 = x[j, 0] - x[i, 0]
        d1 = x[j, 1] - x[i, 1]
        d2 = x[j, 2] - x[i, 2]
        l = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        st = l - l0[s]
        e += 0.5 * k[s] * st * st
        c = k[s] * (1.0 - l0[s] / l)
        f[i, 0] += c * d0
        f[i, 1] += c * d1
        f[i, 2] += c * d2
        f[j, 0] -= c * d0
        f[j, 1] -= c * d1
        f[j, 2] -= c * d2
    return e


@njit(**_OPTS)
def _abc(x, cells, m, signs, abc):
    """Averaged edge vectors of cell m into abc (3, 3); returns V' = a · (b × c)."""
    for d in range(3):
        for i in range(3):
            abc[d, i] = 0.0
    for c in range(8):
        p = cells[m, c]
        for d in range(3):
            s = signs[c, d]
            abc[d, 0] += s * x[p, 0]
            abc[d, 1] += s * x[p, 1]
            abc[d, 2] += s * x[p, 2]
    return (abc[0, 0] * (abc[1, 1] * abc[2, 2] - abc[1, 2] * abc[2, 1])
            + abc[0, 1] * (abc[1, 2] * abc[2, 0] - abc[1, 0] * abc[2, 2])
            + abc[0, 2] * (abc[1, 0] * abc[2, 1] - abc[1, 1] * abc[2, 0]))


@njit(**_OPTS)
def cell_volumes(x, cells):
    """V' of every cell (m,)."""
    signs = _SIGNS
    abc = np.empty((3, 3))
    out = np.empty(cells.shape[0])
    for m in range(cells.shape[0]):
        out[m] = _abc(x, cells, m, signs, abc)
    return out


@njit(**_OPTS)
def _law(V, V0, kappa, form):
    """(W, W', W'') of one cell."""
    if form == 0:
        J = (V - V0) / V0
        return 0.5 * kappa * V0 * J * J, kappa * J, kappa / V0
    q = (V * V - V0 * V0) / (2.0 * V0 * V0)
    return 0.5 * kappa * V0 * q * q, kappa * q * V / V0, kappa * (V * V / V0 ** 3 + q / V0)


@njit(**_OPTS)
def _axis_gradients(abc, dV):
    """dV[d] = ∂V'/∂(axis d): b × c, c × a, a × b."""
    for d in range(3):
        u = (d + 1) % 3
        w = (d + 2) % 3
        dV[d, 0] = abc[u, 1] * abc[w, 2] - abc[u, 2] * abc[w, 1]
        dV[d, 1] = abc[u, 2] * abc[w, 0] - abc[u, 0] * abc[w, 2]
        dV[d, 2] = abc[u, 0] * abc[w, 1] - abc[u, 1] * abc[w, 0]


@njit(**_OPTS)
def volume_energy_forces(x, cells, V0, kappa, form, f):
    """Adds the volume forces to ``f`` (n, 3); returns the volume energy."""
    signs = _SIGNS
    abc = np.empty((3, 3))
    dV = np.empty((3, 3))
    e = 0.0
    for m in range(cells.shape[0]):
        V = _abc(x, cells, m, signs, abc)
        W, dW, _ = _law(V, V0[m], kappa, form)
        e += W
        _axis_gradients(abc, dV)
        for c in range(8):
            p = cells[m, c]
            for i in range(3):
                g = signs[c, 0] * dV[0, i] + signs[c, 1] * dV[1, i] + signs[c, 2] * dV[2, i]
                f[p, i] -= dW * g
    return e


@njit(**_OPTS)
def hessian_data(x, a, b, k, l0, cells, V0, kappa, form, slots, data):
    """The Hessian's CSR data (the pattern of ``slots``) at ``x``, written into ``data``."""
    data[:] = 0.0
    ns = a.shape[0]
    K = np.empty(9)
    for s in range(ns):
        i, j = a[s], b[s]
        d0 = x[j, 0] - x[i, 0]
        d1 = x[j, 1] - x[i, 1]
        d2 = x[j, 2] - x[i, 2]
        l = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        u0, u1, u2 = d0 / l, d1 / l, d2 / l
        r = l0[s] / l
        kr = k[s] * r
        k1 = k[s] * (1.0 - r)
        K[0] = kr * (u0 * u0) + k1
        K[1] = kr * (u0 * u1)
        K[2] = kr * (u0 * u2)
        K[3] = kr * (u1 * u0)
        K[4] = kr * (u1 * u1) + k1
        K[5] = kr * (u1 * u2)
        K[6] = kr * (u2 * u0)
        K[7] = kr * (u2 * u1)
        K[8] = kr * (u2 * u2) + k1
        for t in range(9):
            data[slots[9 * s + t]] += K[t]
            data[slots[9 * (ns + s) + t]] += K[t]
            data[slots[9 * (2 * ns + s) + t]] -= K[t]
            data[slots[9 * (3 * ns + s) + t]] -= K[t]
    if cells.shape[0] == 0:
        return
    signs = _SIGNS
    base0 = 36 * ns
    abc = np.empty((3, 3))
    dV = np.empty((3, 3))
    g = np.empty((8, 3))
    M = np.zeros((3, 3, 3, 3))  # M[d, e] = ∂²V'/∂(axis d)∂(axis e) (3×3 in i, j), times W'
    N = np.empty((3, 8, 3, 3))  # N[d, q] = Σ_e s_qe M[d, e]
    for m in range(cells.shape[0]):
        V = _abc(x, cells, m, signs, abc)
        _, dW, d2W = _law(V, V0[m], kappa, form)
        _axis_gradients(abc, dV)
        for c in range(8):
            for i in range(3):
                g[c, i] = signs[c, 0] * dV[0, i] + signs[c, 1] * dV[1, i] + signs[c, 2] * dV[2, i]
        # ∂²V/∂a∂b = −[c]×, ∂²V/∂a∂c = [b]×, ∂²V/∂b∂c = −[a]× (and their transposes)
        for d in range(3):
            e_ = (d + 1) % 3
            w = (d + 2) % 3  # ∂²V/∂(axis d)∂(axis e_) = −[axis w]× for (d, e_) cyclic
            v0, v1, v2 = -dW * abc[w, 0], -dW * abc[w, 1], -dW * abc[w, 2]
            # S = [v]×: S01 = −v2, S02 = v1, S10 = v2, S12 = −v0, S20 = −v1, S21 = v0
            M[d, e_, 0, 0] = 0.0
            M[d, e_, 0, 1] = -v2
            M[d, e_, 0, 2] = v1
            M[d, e_, 1, 0] = v2
            M[d, e_, 1, 1] = 0.0
            M[d, e_, 1, 2] = -v0
            M[d, e_, 2, 0] = -v1
            M[d, e_, 2, 1] = v0
            M[d, e_, 2, 2] = 0.0
            for i in range(3):
                for j in range(3):
                    M[e_, d, i, j] = M[d, e_, j, i]
        for d in range(3):
            for q in range(8):
                for i in range(3):
                    for j in range(3):
                        N[d, q, i, j] = signs[q, 0] * M[d, 0, i, j] + signs[q, 1] * M[d, 1, i, j] \
                            + signs[q, 2] * M[d, 2, i, j]
        base = base0 + 576 * m
        for p in range(8):
            for q in range(8):
                o = base + 72 * p + 9 * q
                for i in range(3):
                    for j in range(3):
                        h = d2W * g[p, i] * g[q, j] + signs[p, 0] * N[0, q, i, j] \
                            + signs[p, 1] * N[1, q, i, j] + signs[p, 2] * N[2, q, i, j]
                        data[slots[o + 3 * i + j]] += h
