"""Tangents, factorizations and orderings of the Newton solvers.

The energies, forces and Hessians are the Numba twins of :mod:`hybmss.forces`; the Hessian is
written into one fixed CSR pattern, and the constrained Hessian, its lower triangle and its shifts
are gathers of it on that pattern (:class:`Tangent`), explicit zeros kept, so CHOLMOD's symbolic
analysis is done once per solve.  CHOLMOD's Cholesky (and SuperLU where a matrix is not positive
definite, or in residual mode) factorize in a nested-dissection order of the lattice nodes
(:func:`grid_dissection`).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

try:  # CHOLMOD (SuiteSparse) through cvxopt's wheels: supernodal Cholesky, symbolic analysis reusable
    import cvxopt
    from cvxopt import cholmod
except ImportError:  # pragma: no cover - SuperLU's symmetric LU does everything, slower
    cvxopt = cholmod = None

from ..forces import free_pattern, hessian_pattern, stiffness
from ..lattice import box_dissection
from ..system import System


class Tangent:
    """The constrained Hessian ``H_ff`` (+ a diagonal) at one state; ``J`` the full (3n × 3n) one.

    When ``J`` is a Hessian of springs and volume cells only (no term adds stiffness) its data
    lies on the fixed pattern of :func:`hybmss.forces.free_pattern`: ``H_ff``, its lower
    triangle and their shifts ``H_ff + σ I`` are gathers of ``J.data`` with the same pattern,
    explicit zeros kept, so the Cholesky's symbolic analysis holds for all of them.  Otherwise
    (a term's own stiffness, nonsymmetric in residual mode) ``H_ff`` is sliced out of ``J``."""

    def __init__(self, J, free: np.ndarray, pat=None, diag: np.ndarray | None = None, _data=None, _csc=None):
        self.J, self.free, self.pat = J, free, pat
        if pat is not None:
            if _data is None:
                _data = J.data[pat.full_map]
                if diag is not None:
                    _data[pat.full_diag] += diag
            self._data = _data
            self._csc = None
        else:
            if _csc is None:
                _csc = J[free][:, free].tocsc()
                _csc.sort_indices()
                if diag is not None:
                    _csc.setdiag(_csc.diagonal() + diag)
            self._csc = _csc
        self.shape = (int(np.count_nonzero(free)),) * 2
        self.order = None  # a fill-reducing order of the free dofs for the Cholesky (None: CHOLMOD's own)

    def diagonal(self) -> np.ndarray:
        return self._data[self.pat.full_diag] if self.pat is not None else self._csc.diagonal()

    def shifted(self, sigma: float) -> Tangent:
        """``H_ff + σ I`` on the same pattern."""
        if self.pat is not None:
            data = self._data.copy()
            data[self.pat.full_diag] += sigma
            T = Tangent(self.J, self.free, self.pat, _data=data)
        else:
            A = self._csc.copy()
            A.setdiag(A.diagonal() + sigma)
            T = Tangent(self.J, self.free, None, _csc=A)
        T.order = self.order
        return T

    def csc(self):
        """``H_ff`` as a CSC matrix (both triangles)."""
        if self._csc is None:
            p = self.pat
            self._csc = sp.csc_matrix((self._data, p.full_indices, p.full_indptr), shape=self.shape)
        return self._csc

    def permuted(self):
        """``H_ff[order][:, order]`` as a CSC matrix with sorted indices: on the fixed pattern a
        gather of the data by a map computed once per pattern and order."""
        if self.pat is None:
            return self.csc()[self.order][:, self.order].tocsc()
        indptr, indices, src = _permuted_pattern(self.pat, np.ascontiguousarray(self.order, dtype=np.int64).tobytes())
        return sp.csc_matrix((self._data[src], indices, indptr), shape=self.shape)

    def lower(self):
        """``(key, indptr, rows, cols, data)`` of the lower triangle in CSC order; ``key`` is the
        pattern (None: compare the arrays)."""
        if self.pat is not None:
            p = self.pat
            return p, p.lower_indptr, p.lower_rows, p.lower_cols, self._data[p.lower_pos]
        L = sp.tril(self._csc, format="csc")
        L.sort_indices()
        return None, L.indptr, L.indices, None, L.data


@lru_cache(maxsize=8)
def _permuted_pattern(pat, order_bytes: bytes):
    """``(indptr, indices, src)`` of ``H_ff[order][:, order]`` (CSC, sorted) on the pattern ``pat``
    of :class:`hybmss.forces.FreePattern`: its data is ``H_ff``'s (CSC order) at ``src``."""
    order = np.frombuffer(order_bytes, dtype=np.int64)
    n = len(pat.full_indptr) - 1
    pos = sp.csc_matrix((np.arange(1, len(pat.full_indices) + 1, dtype=np.float64), pat.full_indices,
                         pat.full_indptr), shape=(n, n))
    P = pos[order][:, order].tocsc()
    P.sort_indices()
    src = P.data.astype(np.int64) - 1  # positions + 1: no stored entry is an explicit zero
    return P.indptr.copy(), P.indices.copy(), src


def grid_dissection(grid: np.ndarray, leaf: int = 16) -> np.ndarray:
    """Nested-dissection order of lattice nodes at integer ``grid`` coordinates (n, 3)
    (:func:`hybmss.lattice.box_dissection` of their bounding box).  On the 8×8×48 beam and the
    10³ cube CHOLMOD's numeric factorization in this order takes 0.55–0.65 of the time it takes
    in its own (AMD) order."""
    g = np.asarray(grid, dtype=np.int64)
    return box_dissection(g, g.min(axis=0), g.max(axis=0), step=1, leaf=leaf)


@lru_cache(maxsize=8)
def _free_order(grid_bytes: bytes, free_bytes: bytes) -> np.ndarray:
    """Fill-reducing order of the free dofs (:func:`grid_dissection` of their nodes), as indices
    into the free dofs."""
    grid = np.frombuffer(grid_bytes, dtype=np.int64).reshape(-1, 3)
    free = np.frombuffer(free_bytes, dtype=bool)
    nodes = grid_dissection(grid)
    dofs = (3 * nodes[:, None] + np.arange(3)[None, :]).reshape(-1)
    rank = np.cumsum(free) - 1
    return rank[dofs[free[dofs]]]


def tangent(S: System, x: np.ndarray, load: float, free: np.ndarray, diag: np.ndarray | None = None) -> Tangent:
    """The constrained tangent at ``x`` (:class:`Tangent`), plus ``diag`` on its diagonal."""
    J = stiffness(S, x, load)
    indptr, indices, _ = hessian_pattern(S)
    fixed_pattern = J.indices is indices or (J.indices.shape == indices.shape and np.array_equal(J.indptr, indptr)
                                             and np.array_equal(J.indices, indices))
    T = Tangent(J, free, free_pattern(S, free) if fixed_pattern and S.conservative else None, diag)
    T.order = _free_order(np.ascontiguousarray(S.lattice.grid, dtype=np.int64).tobytes(),
                          np.ascontiguousarray(free, dtype=bool).tobytes())
    return T


def factor(A, fac: Factorizer | None = None):
    """Factorization of a symmetric matrix ``A`` (CSC or :class:`Tangent`) with a ``solve`` method: CHOLMOD's Cholesky
    when ``A`` is positive definite (through ``fac``, which keeps the symbolic analysis), else
    SuperLU's LU in symmetric mode with a minimum-degree ordering of A+Aᵀ (3× faster than the
    default COLAMD on the lattice Hessians; no pivoting, so its pivots are the D of LDLᵀ)."""
    if fac is not None:
        F = fac.cholesky(A)
        if F is not None:
            return F
    return superlu_symmetric(A)


class PermutedLU:
    """A SuperLU factorization of ``A[p][:, p]`` that solves with ``A`` (its ``U`` pivots are
    those of the permuted matrix: the same inertia)."""

    def __init__(self, lu, p: np.ndarray):
        self._lu, self._p = lu, p

    @property
    def U(self):
        return self._lu.U  # built on demand: forming it costs a quarter of the factorization

    def solve(self, r: np.ndarray) -> np.ndarray:
        x = np.empty_like(r)
        x[self._p] = self._lu.solve(r[self._p])
        return x


def superlu_symmetric(A):
    """SuperLU's LU in symmetric mode (no pivoting: its pivots are the D of LDLᵀ) of ``A``; a
    :class:`Tangent` with a fill-reducing order is factorized in that order (1.2–1.8× faster on
    the cube and the beam than SuperLU's minimum degree), any other matrix in a minimum-degree
    order of A+Aᵀ."""
    if isinstance(A, Tangent):
        if A.order is not None:
            return PermutedLU(spla.splu(A.permuted(), permc_spec="NATURAL", diag_pivot_thresh=0.0,
                                         options={"SymmetricMode": True}), A.order)
        A = A.csc()
    return spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})


class CholeskyFactor:
    """A CHOLMOD factor ``A = P L Lᵀ Pᵀ`` (valid until its :class:`Factorizer` factorizes again)."""

    def __init__(self, F):
        self._F = F

    def solve(self, r: np.ndarray) -> np.ndarray:
        B = cvxopt.matrix(np.asarray(r, dtype=float))
        cholmod.solve(self._F, B)
        return np.array(B).ravel()


class Factorizer:
    """Cholesky factorizations of the constrained Hessians of one solve.  The symbolic analysis
    (fill-reducing ordering, supernodes) depends on the sparsity pattern only, which is the same
    for every Newton iteration, shift and load step: it is computed once per pattern and every
    factorization after it is numeric only.  A failed factorization (``ArithmeticError``: a
    pivot ≤ 0) is CHOLMOD's proof that the matrix is not positive definite; the caller then uses
    SuperLU, and the symbolic analysis serves the next factorization.  Without cvxopt every call
    returns None."""

    def __init__(self):
        self._key = self._indptr = self._indices = None
        self._A = self._F = None
        self.numeric = self.symbolic = self.failed = 0

    def cholesky(self, A) -> CholeskyFactor | None:
        """Cholesky of ``A`` (a :class:`Tangent` or a symmetric sparse matrix), None if it is
        not positive definite."""
        if cholmod is None:
            return None
        order = None
        if isinstance(A, Tangent):
            key, indptr, rows, cols, data = A.lower()
            order = A.order
        else:
            L = sp.tril(A, format="csc")
            L.sort_indices()
            key, indptr, rows, cols, data = None, L.indptr, L.indices, None, L.data
        shape = A.shape
        same = self._F is not None and shape == self._A.size and (
            (key is not None and key is self._key) or (key is None and self._key is None and np.array_equal(
                indptr, self._indptr) and np.array_equal(rows, self._indices)))
        if not same:
            self._key, self._indptr, self._indices = key, np.array(indptr), np.array(rows)
            if cols is None:
                cols = np.repeat(np.arange(shape[1]), np.diff(indptr))
            self._A = cvxopt.spmatrix(data, np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64),
                                      shape)
            if order is not None:
                self._F = cholmod.symbolic(self._A, p=cvxopt.matrix(np.asarray(order, dtype=np.int32)), uplo="L")
            else:
                self._F = cholmod.symbolic(self._A, uplo="L")
            self.symbolic += 1
        else:
            self._A.V = cvxopt.matrix(data)
        self.numeric += 1
        try:
            cholmod.numeric(self._A, self._F)
        except ArithmeticError:  # not positive definite (the analysis stays valid for the next one)
            self.failed += 1
            return None
        return CholeskyFactor(self._F)


def factor_general(A):
    """Sparse LU with partial pivoting of a nonsymmetric Jacobian (residual mode): a
    :class:`Tangent` in its nested-dissection order (4× faster than COLAMD on the 10³ cube of
    baudet2009, half the fill), any other matrix in COLAMD's."""
    if isinstance(A, Tangent):
        if A.order is not None:
            return PermutedLU(spla.splu(A.permuted(), permc_spec="NATURAL"), A.order)
        A = A.csc()
    return spla.splu(A)



def positive_definite(T: Tangent, fac: Factorizer) -> bool:
    """Whether ``T`` is positive definite: its Cholesky factorization succeeds, or (without
    CHOLMOD) every pivot of its symmetric LU without pivoting is positive (Sylvester's law)."""
    if cholmod is not None:
        return fac.cholesky(T) is not None
    try:
        with np.errstate(all="ignore"):
            pivots = superlu_symmetric(T).U.diagonal()
    except RuntimeError:
        return False
    return bool(np.all(np.isfinite(pivots)) and pivots.min() > 0.0)


def not_definite(Hff: Tangent, shift: float, fac: Factorizer) -> bool:
    """Whether ``Hff + shift·I`` is not positive definite (:func:`positive_definite`)."""
    return not positive_definite(Hff.shifted(shift) if shift != 0.0 else Hff, fac)
