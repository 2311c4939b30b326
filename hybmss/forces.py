"""Energies, forces and exact Hessians in plain NumPy: the readable reference, and the totals
(:func:`energy_forces`, :func:`hessian`, :func:`stiffness`, :func:`cell_volumes`) that run their
Numba twins of :mod:`hybmss._kernels_static` by default (``kernel="numpy"``: this module's
functions; tests/test_static_kernels.py holds the two together).

Springs ([G20] eq. 5.1): energy ``½ k (l − l0)²`` with ``l = |x_b − x_a|``; force on a
``f_a = k (x_b − x_a)(1 − l0/l)``; Hessian block ``K = k [(1 − l0/l) I + (l0/l) d dᵀ]`` with
``d = (x_b − x_a)/l``, entering as ``[[K, −K], [−K, K]]``.

Volume term (SPEC §3): per cell ``V' = a · (b × c)`` with a, b, c the averaged edge vectors
``a = Σ_c s_{c,1} x_c`` (s = ±1/4), and
``W = Vc κ/2 J²``, ``J = (V' − Vc)/Vc`` (``quadratic``, [G20] eq. 5.8) or
``W = Vc κ/2 q²``, ``q = (V'² − Vc²)/(2 Vc²)`` (``squared``).
The force is the exact negative gradient ``f_c = −W'(V') ∂V'/∂x_c`` with
``∂V'/∂x_c = s_{c,1} (b×c) + s_{c,2} (c×a) + s_{c,3} (a×b)``.  [G20] eq. 5.16 prints this
gradient without the factor 1/4 of s; the exact gradient of the energy has it (tested by finite
differences), which is what makes the static and implicit solvers consistent with the energy.
The Hessian is ``W'' ∇V'∇V'ᵀ + W' ∇²V'`` where ∇²V' couples corners through the cross-product
matrices ``∂²V'/∂a∂b = −[c]×``, ``∂²V'/∂a∂c = [b]×``, ``∂²V'/∂b∂c = −[a]×``.

Gravity: energy ``−Σ m_a g · x_a``, force ``m_a g``, no Hessian.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import scipy.sparse as sp

from . import _kernels_static as _nb
from .lattice import VOLUME_SIGNS
from .system import System

KERNELS = ("numba", "numpy")
"""``kernel`` of :func:`energy_forces`, :func:`hessian` and :func:`stiffness`: the Numba twins of
:mod:`hybmss._kernels_static` (default) or the NumPy functions of this module (the reference)."""


# ------------------------------------------------------------------------------------ springs
def spring_energy_forces(x, a, b, k, l0):
    """Energy and forces (n, 3) of springs (a, b, k, l0) at positions ``x``."""
    d = x[b] - x[a]
    l = np.sqrt(np.einsum("ij,ij->i", d, d))
    stretch = l - l0
    energy = 0.5 * np.dot(k, stretch * stretch)
    fa = (k * (1.0 - l0 / l))[:, None] * d
    n = len(x)
    f = np.empty_like(x)
    for i in range(3):  # bincount: the scatter-add of np.add.at, an order of magnitude faster
        f[:, i] = np.bincount(a, fa[:, i], n) - np.bincount(b, fa[:, i], n)
    return energy, f


def spring_hessian_blocks(x, a, b, k, l0):
    """3×3 blocks K (s, 3, 3) with the spring Hessian ``[[K, −K], [−K, K]]``."""
    d = x[b] - x[a]
    l = np.sqrt(np.einsum("ij,ij->i", d, d))
    u = d / l[:, None]
    r = l0 / l
    K = (k * r)[:, None, None] * np.einsum("si,sj->sij", u, u)
    K += (k * (1.0 - r))[:, None, None] * np.eye(3)[None]
    return K


# ------------------------------------------------------------------------------------ volume
def cell_abc(x, cells):
    """Averaged edge vectors (m, 3, 3): ``abc[:, 0] = a``, ``[:, 1] = b``, ``[:, 2] = c``."""
    return np.einsum("cd,mci->mdi", VOLUME_SIGNS, x[cells])


def cell_volumes(x, cells, kernel: str = "numba"):
    """V' = a · (b × c) of every cell (m,)."""
    if kernel == "numba":
        return _nb.cell_volumes(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(cells, dtype=np.int64))
    abc = cell_abc(x, cells)
    return np.einsum("mi,mi->m", abc[:, 0], np.cross(abc[:, 1], abc[:, 2]))


def _volume_law(V, V0, kappa, form):
    """W, W'(V), W''(V) per cell for the volume-energy ``form``."""
    if form == "quadratic":
        J = (V - V0) / V0
        return 0.5 * kappa * V0 * J * J, kappa * J, np.full_like(V, kappa) / V0
    if form == "squared":
        q = (V * V - V0 * V0) / (2.0 * V0 * V0)
        W = 0.5 * kappa * V0 * q * q
        dW = kappa * q * V / V0
        d2W = kappa * (V * V / V0**3 + q / V0)
        return W, dW, d2W
    raise ValueError(f"unknown volume energy {form!r}")


def volume_gradients(abc):
    """∂V'/∂x_c for every cell corner: (m, 8, 3)."""
    a, b, c = abc[:, 0], abc[:, 1], abc[:, 2]
    dV = np.stack([np.cross(b, c), np.cross(c, a), np.cross(a, b)], axis=1)  # (m, 3 axes, 3)
    return np.einsum("cd,mdi->mci", VOLUME_SIGNS, dV)


def volume_energy_forces(x, cells, V0, kappa, form="quadratic"):
    abc = cell_abc(x, cells)
    V = np.einsum("mi,mi->m", abc[:, 0], np.cross(abc[:, 1], abc[:, 2]))
    W, dW, _ = _volume_law(V, V0, kappa, form)
    g = volume_gradients(abc)  # (m, 8, 3)
    fc = (-dW[:, None, None] * g).reshape(-1, 3)
    idx = cells.ravel()
    f = np.empty_like(x)
    for i in range(3):
        f[:, i] = np.bincount(idx, fc[:, i], len(x))
    return float(W.sum()), f


def _skew(v):
    """Cross-product matrices [v]× of (m, 3) vectors: (m, 3, 3)."""
    S = np.zeros(v.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S


def volume_hessian_blocks(x, cells, V0, kappa, form="quadratic"):
    """Per-cell Hessian blocks (m, 8, 8, 3, 3) of the volume energy."""
    abc = cell_abc(x, cells)
    V = np.einsum("mi,mi->m", abc[:, 0], np.cross(abc[:, 1], abc[:, 2]))
    _, dW, d2W = _volume_law(V, V0, kappa, form)
    g = volume_gradients(abc)
    m = len(cells)
    H = (d2W[:, None, None, None, None] * g[:, :, None, :, None]) * g[:, None, :, None, :]
    a, b, c = abc[:, 0], abc[:, 1], abc[:, 2]
    M = np.zeros((m, 3, 3, 3, 3))  # M[m, d, e] = ∂²V/∂(axis d)∂(axis e)
    M[:, 0, 1], M[:, 0, 2], M[:, 1, 2] = -_skew(c), _skew(b), -_skew(a)
    M[:, 1, 0] = np.swapaxes(M[:, 0, 1], -1, -2)
    M[:, 2, 0] = np.swapaxes(M[:, 0, 2], -1, -2)
    M[:, 2, 1] = np.swapaxes(M[:, 1, 2], -1, -2)
    # Σ_de s_pd s_qe M_de as one matrix product: (64, 9) @ (m, 9, 9) -> (m, 64, 9)
    M = M.reshape(m, 9, 9) * dW[:, None, None]  # rows (d, e), columns (i, j)
    Hv = (_SIGN_PAIRS @ M).reshape(m, 8, 8, 3, 3)
    H += Hv
    return H


_SIGN_PAIRS = np.einsum("pd,qe->pqde", VOLUME_SIGNS, VOLUME_SIGNS).reshape(64, 9)


# ------------------------------------------------------------------------------------ totals
def energy_forces(system: System, x: np.ndarray, load: float = 1.0, kernel: str = "numba"):
    """Total energy and forces at load factor ``load``: springs + volume + ``load`` · gravity +
    every term of ``system.terms`` (a ``scaled`` term times ``load``).

    Returns ``(energy, forces, parts)``: ``parts`` holds each energy (``springs``, ``volume``,
    ``gravity`` and each conservative term under its name) and ``energy`` is their sum; a
    non-conservative term adds forces only, so ``energy`` is then not a potential of them.
    """
    if kernel == "numba":
        x = np.ascontiguousarray(x, dtype=float)
        f = np.zeros_like(x)
        parts = {"springs": _nb.spring_energy_forces(x, system.spring_a, system.spring_b, system.spring_k,
                                                     system.spring_l0, f)}
        if system.has_volume:
            parts["volume"] = _nb.volume_energy_forces(x, system.vol_cells, system.vol_V0, system.kappa,
                                                       _nb.FORMS.get(system.volume_energy, 0), f)
    else:
        e_s, f = spring_energy_forces(x, system.spring_a, system.spring_b, system.spring_k, system.spring_l0)
        parts = {"springs": e_s}
        if system.has_volume:
            e_v, f_v = volume_energy_forces(x, system.vol_cells, system.vol_V0, system.kappa, system.volume_energy)
            f += f_v
            parts["volume"] = e_v
    if system.gravity is not None:
        parts["gravity"] = -load * float(np.dot(system.mass, x @ system.gravity))
        f += load * (system.mass[:, None] * system.gravity[None, :])
    for t in system.terms:
        w = load if t.scaled else 1.0
        f += w * t.forces(x)
        if t.conservative:
            parts[t.name] = w * t.energy(x)
    return sum(parts.values()), f, parts


def internal_forces(system: System, x: np.ndarray) -> np.ndarray:
    """Every force but gravity: springs + volume + the terms (dead loads and corrections)."""
    _, f, _ = energy_forces(system, x)
    if system.gravity is not None:
        f -= system.mass[:, None] * system.gravity[None, :]
    return f


def stiffness(system: System, x: np.ndarray, load: float = 1.0, kernel: str = "numba") -> sp.csr_matrix:
    """``∂(−forces)/∂x`` of :func:`energy_forces` at load factor ``load``: the exact Hessian of the
    springs and volume energy plus each term's stiffness (symmetric iff every term is conservative).
    Without a term of nonzero stiffness the matrix has the fixed pattern of :func:`hessian`."""
    H = hessian(system, x, kernel)
    for t in system.terms:
        w = load if t.scaled else 1.0
        if w != 0.0:
            K = t.stiffness(x)
            if K.nnz:
                H = H + (w * K if w != 1.0 else K)
    return H.tocsr()


@lru_cache(maxsize=8)
def _pattern(n, a_bytes, b_bytes, cells_bytes):
    """CSR pattern of the Hessian and the map from COO entries to CSR slots.

    The pattern is made of 3×3 blocks: the node pairs (springs (a,a), (b,b), (a,b), (b,a), then
    the 8×8 corner pairs of every volume cell, the order :func:`hessian` lists its blocks in) are
    sorted once at the node level, and the slot of entry (i, j) of the block of pair q in row a is
    ``9 P_a + 3 i deg(a) + 3 (q − P_a) + j`` (P_a pairs in rows before a, deg(a) in row a)."""
    a = np.frombuffer(a_bytes, dtype=np.int64)
    b = np.frombuffer(b_bytes, dtype=np.int64)
    cells = np.frombuffer(cells_bytes, dtype=np.int64).reshape(-1, 8)
    rows = [a, b, a, b]
    cols = [a, b, b, a]
    if len(cells):
        rows.append(np.broadcast_to(cells[:, :, None], (len(cells), 8, 8)).reshape(-1))
        cols.append(np.broadcast_to(cells[:, None, :], (len(cells), 8, 8)).reshape(-1))
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    uniq, q = np.unique(rows * n + cols, return_inverse=True)
    r, c = np.divmod(uniq, n)
    deg = np.bincount(r, minlength=n)
    P = np.concatenate(([0], np.cumsum(deg)[:-1]))
    ra = r[q]
    base = 9 * P[ra] + 3 * (q - P[ra])  # slot of (i, j) = (0, 0) of each COO block
    ij = np.arange(3)
    inv = (base[:, None, None] + 3 * ij[None, :, None] * deg[ra][:, None, None] + ij[None, None, :]).reshape(-1)
    # dof-level rows: row 3a + i starts at 9 P_a + 3 i deg(a); its columns are 3c + j per neighbour c
    indptr = np.empty(3 * n + 1, dtype=np.int64)
    indptr[:-1] = (9 * P[:, None] + 3 * ij[None, :] * deg[:, None]).reshape(-1)
    indptr[-1] = 9 * len(uniq)
    # entry (i, j) of the block of node pair t (row r_t, column c_t) sits at slot
    # 9 P_r + 3 i deg(r) + 3 (t − P_r) + j and holds column 3 c_t + j
    t = np.arange(len(uniq))
    slot0 = 9 * P[r] + 3 * (t - P[r])
    slots = slot0[:, None, None] + 3 * ij[None, :, None] * deg[r][:, None, None] + ij[None, None, :]
    indices = np.empty(9 * len(uniq), dtype=np.int64)
    indices[slots.reshape(-1)] = np.broadcast_to(3 * c[:, None, None] + ij[None, None, :], slots.shape).reshape(-1)
    idx = np.int32 if len(indices) < 2**31 - 1 else np.int64  # scipy's own index type: no copy per matrix
    return indptr.astype(idx), indices.astype(idx), inv


def hessian_pattern(system: System):
    """``(indptr, indices, slots)`` of the Hessian's fixed CSR pattern (:func:`_pattern`), shared by
    every Hessian of ``system``'s springs and cells."""
    return _pattern(*_pattern_key(system))


def _pattern_key(system: System) -> tuple:
    cells = system.vol_cells if system.has_volume else np.zeros((0, 8), dtype=np.int64)
    return (system.n, system.spring_a.tobytes(), system.spring_b.tobytes(), np.ascontiguousarray(cells).tobytes())


@lru_cache(maxsize=8)
def _free_pattern(key, free_bytes):
    indptr, indices, _ = _pattern(*key)
    return FreePattern(indptr, indices, np.frombuffer(free_bytes, dtype=bool))


def free_pattern(system: System, free: np.ndarray) -> "FreePattern":
    """The :class:`FreePattern` of ``system``'s Hessian pattern and the free dofs ``free`` (3n,)."""
    return _free_pattern(_pattern_key(system), np.ascontiguousarray(free, dtype=bool).tobytes())


class FreePattern:
    """Where the constrained Hessian ``H_ff`` (rows and columns of the free dofs) lies in the data
    of the Hessian's fixed CSR pattern: ``full_map`` selects the data of ``H_ff`` in CSR order
    (which, the pattern being symmetric, is also its CSC: ``full_indptr``, ``full_indices``),
    ``lower_pos`` the entries of its lower triangle among those, in CSC order (``lower_indptr``,
    ``lower_rows``, ``lower_cols``); ``full_diag`` the diagonal's positions.  Every dof has its
    diagonal entry (each particle has a spring), so a shift ``H_ff + σ I`` changes values only."""

    def __init__(self, indptr: np.ndarray, indices: np.ndarray, free: np.ndarray):
        N = len(indptr) - 1
        rows = np.repeat(np.arange(N), np.diff(indptr))
        rank = np.cumsum(free) - 1
        self.full_map = np.flatnonzero(free[rows] & free[indices])
        r, c = rank[rows[self.full_map]], rank[indices[self.full_map]]
        self.n = n = int(np.count_nonzero(free))
        self.full_indptr = np.concatenate(([0], np.cumsum(np.bincount(r, minlength=n)))).astype(indices.dtype)
        self.full_indices = c.astype(indices.dtype)
        self.full_diag = np.flatnonzero(r == c)
        low = c >= r
        self.lower_pos = np.flatnonzero(low)
        self.lower_indptr = np.concatenate(([0], np.cumsum(np.bincount(r[low], minlength=n))))
        self.lower_rows, self.lower_cols = c[low].astype(np.int64), r[low].astype(np.int64)
        if len(self.full_diag) != n:
            raise ValueError("the Hessian pattern lacks a diagonal entry of a free dof")


def hessian(system: System, x: np.ndarray, kernel: str = "numba") -> sp.csr_matrix:
    """Exact Hessian (3n × 3n, CSR) of the total energy at ``x``, on the pattern of
    :func:`hessian_pattern` (explicit zeros kept)."""
    n = system.n
    indptr, indices, inv = hessian_pattern(system)
    if kernel == "numba":
        data = np.empty(len(indices))
        _nb.hessian_data(np.ascontiguousarray(x, dtype=float), system.spring_a, system.spring_b, system.spring_k,
                         system.spring_l0, system.vol_cells, system.vol_V0, system.kappa,
                         _nb.FORMS.get(system.volume_energy, 0), inv, data)
        return sp.csr_matrix((data, indices, indptr), shape=(3 * n, 3 * n))
    cells = system.vol_cells if system.has_volume else np.zeros((0, 8), dtype=np.int64)
    K = spring_hessian_blocks(x, system.spring_a, system.spring_b, system.spring_k, system.spring_l0)
    parts = [K.reshape(-1), K.reshape(-1), -K.reshape(-1), -K.reshape(-1)]
    if len(cells):
        H = volume_hessian_blocks(x, cells, system.vol_V0, system.kappa, system.volume_energy)
        parts.append(H.reshape(-1))
    data = np.bincount(inv, weights=np.concatenate(parts), minlength=len(indices))
    return sp.csr_matrix((data, indices, indptr), shape=(3 * n, 3 * n))
