"""Numba twin of the [B09] correction forces (:mod:`hybmss.models.baudet2009.corrections`), in the
stencil layout of :mod:`hybmss._stencil_gen`, and their stage in the generated stencil kernel
(:func:`stencil_stage`).

Arrays live on the full ``(nx+1)(ny+1)(nz+1)`` grid, flattened in C order: ``x`` (3, N)
positions; ``kc`` (2, N) the spring shares ``kx``, ``kd`` of the cell whose lowest corner is p
(both 0 where there is no cell: voxel masks and the wrap-around of the flattening); ``coff``
(8,) flat offsets of the corners ``c = di + 2 dj + 4 dk``.  Two stages, as for the volume term:

1. :func:`corrections_stage`, per cell p: averaged edge vectors and their unit axes d_j, the
   tensions S_i of the cell's own springs, the transmitted forces ``T = M⁻¹ S`` and the
   per-vertex correction ``P[j, :, p] = c (Σ T − T_j)/4 · d_j`` of the face pair j;
2. :func:`corrections_accumulate`, per node q: ``F[:, q] = Σ_c Σ_j ±P[j, :, q − coff_c]``
   (+ on the j+ face of the cell, − on the j− face), unit-stride loops over nodes.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_OPTS = dict(cache=True, error_model="numpy", fastmath=False, nogil=True)


@njit(**_OPTS)
def corrections_stage(x, kc, coff, le, c, P, lo, hi):
    """Stage 1 on the cells with lowest corner p in [lo, hi): fills ``P`` (3, 3, N)."""
    N = x.shape[1]
    end = min(hi, N - coff[7])
    xs = np.empty((8, 3))
    d = np.empty((3, 3))
    S = np.empty(3)
    T = np.empty(3)
    r3 = math.sqrt(3.0) * le
    cc = c / (1.0 + 2.0 * c)
    ic = 1.0 / (1.0 - c)
    for p in range(lo, end):
        kx = kc[0, p]
        kd = kc[1, p]
        if kx == 0.0 and kd == 0.0:
            for j in range(3):
                for i in range(3):
                    P[j, i, p] = 0.0
            continue
        for cn in range(8):
            q = p + coff[cn]
            for i in range(3):
                xs[cn, i] = x[i, q]
        for j in range(3):  # averaged edge vector along j and its direction
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            for cn in range(8):
                sg = 0.25 if (cn >> j) & 1 else -0.25
                s0 += sg * xs[cn, 0]
                s1 += sg * xs[cn, 1]
                s2 += sg * xs[cn, 2]
            n = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
            d[j, 0] = s0 / n
            d[j, 1] = s1 / n
            d[j, 2] = s2 / n
            S[j] = 0.0
        for i in range(3):  # the 4 edges along i
            bit = 1 << i
            for cn in range(8):
                if cn & bit:
                    continue
                e0 = xs[cn | bit, 0] - xs[cn, 0]
                e1 = xs[cn | bit, 1] - xs[cn, 1]
                e2 = xs[cn | bit, 2] - xs[cn, 2]
                t = kx * (1.0 - le / math.sqrt(e0 * e0 + e1 * e1 + e2 * e2))
                S[i] += t * (e0 * d[i, 0] + e1 * d[i, 1] + e2 * d[i, 2])
        for q in range(4):  # inner diagonals q -> 7 - q
            D0 = xs[7 - q, 0] - xs[q, 0]
            D1 = xs[7 - q, 1] - xs[q, 1]
            D2 = xs[7 - q, 2] - xs[q, 2]
            t = kd * (1.0 - r3 / math.sqrt(D0 * D0 + D1 * D1 + D2 * D2))
            for i in range(3):
                sg = -1.0 if (q >> i) & 1 else 1.0
                S[i] += sg * t * (D0 * d[i, 0] + D1 * d[i, 1] + D2 * d[i, 2])
        sumS = S[0] + S[1] + S[2]
        for i in range(3):
            T[i] = (S[i] - cc * sumS) * ic
        sumT = T[0] + T[1] + T[2]
        for j in range(3):
            m = 0.25 * c * (sumT - T[j])
            for i in range(3):
                P[j, i, p] = m * d[j, i]


@njit(**_OPTS)
def corrections_accumulate(P, coff, F, lo, hi):
    """Stage 2 on the nodes [lo, hi): ``F[:, q] = Σ_c Σ_j ±P[j, :, q − coff_c]`` (overwritten)."""
    for dd in range(3):
        f = F[dd, lo:hi]
        for i in range(hi - lo):
            f[i] = 0.0
        for cn in range(8):
            o = coff[cn]
            start = max(lo, o)
            if start >= hi:
                continue
            ff = F[dd, start:hi]
            for j in range(3):
                g = P[j, dd, start - o:hi - o]
                if (cn >> j) & 1:
                    for i in range(hi - start):
                        ff[i] += g[i]
                else:
                    for i in range(hi - start):
                        ff[i] -= g[i]


def correction_forces_grid(x, kc, coff, le, c, P=None, F=None):
    """Correction forces (3, N) on the grid positions ``x`` (3, N)."""
    N = x.shape[1]
    P = np.zeros((3, 3, N)) if P is None else P
    F = np.zeros((3, N)) if F is None else F
    corrections_stage(x, kc, coff, float(le), float(c), P, 0, N)
    corrections_accumulate(P, coff, F, 0, N)
    return F


@njit(**_OPTS)
def stencil_stage(W, xb, feb, L, N, F0, args):
    """The stage of the corrections in the generated stencil kernel (:mod:`hybmss._stencil_gen`):
    external-force rows at ``feb`` = ``F0`` (dead loads, (3, N)) + the corrections at the
    positions of the rows at ``xb``.  ``args``: ``(kc, coff, le, c, P, Fc)`` of
    :meth:`hybmss.models.baudet2009.corrections.GridCorrections.stage_args`."""
    kc, coff, le, c, P, Fc = args
    x = W[xb:xb + 3 * L].reshape((3, L))[:, :N]
    corrections_stage(x, kc, coff, le, c, P, 0, N)
    corrections_accumulate(P, coff, Fc, 0, N)
    for d in range(3):
        for q in range(N):
            W[feb + d * L + q] = F0[d, q] + Fc[d, q]
