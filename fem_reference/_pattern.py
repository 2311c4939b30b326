"""The CSR pattern of a vector-space matrix from its scalar element-to-dof map, compiled by Numba.

:meth:`fem_reference.space.Space._block_pattern` computes the same arrays with NumPy (its
readable twin, tested against this): the scalar pattern by a sort of all ``nn² · ne`` element
entries, then the vector pattern by index arithmetic on arrays of ``9 nn² ne`` entries (the Hex2
8×8×48 beam: 2.2e6 and 2.0e7, 3.0 s).  Here each scalar row gathers the dofs of the elements
around its node and keeps those few sorted (at most 125 distinct in Hex2), and the vector arrays
are written entry by entry.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_OPTS = dict(cache=True, error_model="numpy", nogil=True)


@njit(**_OPTS)
def _node_elements(e, N):
    """Elements around each scalar dof: ``(start (N+1,), elements)``, a CSR map."""
    nn, ne = e.shape
    start = np.zeros(N + 1, dtype=np.int64)
    for el in range(ne):
        for n in range(nn):
            start[e[n, el] + 1] += 1
    for a in range(N):
        start[a + 1] += start[a]
    fill = np.empty(N, dtype=np.int64)
    for a in range(N):
        fill[a] = start[a]
    elems = np.empty(start[N], dtype=np.int64)
    for el in range(ne):
        for n in range(nn):
            a = e[n, el]
            elems[fill[a]] = el
            fill[a] += 1
    return start, elems


@njit(**_OPTS)
def _row_columns(e, a, start, elems, buf):
    """The sorted distinct scalar dofs coupled to ``a`` (written to the front of ``buf``); their
    count.  Insertion into the sorted front, skipping those already there: a row has at most
    125 (Hex2) of the few hundred candidates, and plain loops compile in a fraction of the time
    of ``np.sort``."""
    nn = e.shape[0]
    d = 0
    for j in range(start[a], start[a + 1]):
        el = elems[j]
        for m in range(nn):
            b = e[m, el]
            lo = _lower_bound(buf, d, b)
            if lo < d and buf[lo] == b:
                continue
            for t in range(d, lo, -1):
                buf[t] = buf[t - 1]
            buf[lo] = b
            d += 1
    return d


@njit(**_OPTS)
def _lower_bound(v, n, x):
    """First index of the sorted ``v[:n]`` whose entry is not below ``x``."""
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) >> 1
        if v[mid] < x:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(**_OPTS)
def scalar_pattern(e, N):
    """``(ptr (N+1,), cols)``: the sorted columns of each scalar row (``e`` (nn, ne) int64)."""
    nn = e.shape[0]
    start, elems = _node_elements(e, N)
    most = 0
    for a in range(N):
        most = max(most, start[a + 1] - start[a])
    buf = np.empty(max(1, most * nn), dtype=np.int64)
    ptr = np.zeros(N + 1, dtype=np.int64)
    for a in range(N):
        ptr[a + 1] = ptr[a] + _row_columns(e, a, start, elems, buf)
    cols = np.empty(ptr[N], dtype=np.int64)
    for a in range(N):
        d = _row_columns(e, a, start, elems, buf)
        for j in range(d):
            cols[ptr[a] + j] = buf[j]
    return ptr, cols


@njit(**_OPTS)
def block_pattern(e, N):
    """``(indptr, indices, position)`` of the vector matrix whose element blocks are ordered
    ``K[n, m, e, i, k]`` (:meth:`fem_reference.space.Space._block_pattern`)."""
    nn, ne = e.shape
    ptr, cols = scalar_pattern(e, N)
    indptr = np.empty(3 * N + 1, dtype=np.int64)
    indices = np.empty(9 * ptr[N], dtype=np.int32)
    for a in range(N):
        deg = ptr[a + 1] - ptr[a]
        for i in range(3):
            row = 9 * ptr[a] + 3 * i * deg
            indptr[3 * a + i] = row
            for r in range(deg):
                b = cols[ptr[a] + r]
                for k in range(3):
                    indices[row + 3 * r + k] = 3 * b + k
    indptr[3 * N] = 9 * ptr[N]
    position = np.empty(nn * nn * ne * 9, dtype=np.intp)
    q = 0
    for n in range(nn):
        for m in range(nn):
            for el in range(ne):
                a = e[n, el]
                deg = ptr[a + 1] - ptr[a]
                r = _lower_bound(cols[ptr[a]:], deg, e[m, el])
                base = 9 * ptr[a] + 3 * r
                for i in range(3):
                    for k in range(3):
                        position[q] = base + 3 * i * deg + k
                        q += 1
    return indptr, indices, position
