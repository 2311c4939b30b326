"""Sparse linear solves with prescribed (Dirichlet) dofs.

Two kinds of systems occur:

- symmetric positive definite ``K u = f`` (displacement formulations, linear or the
  finite-strain tangent at a stable state);
- symmetric saddle-point systems of the mixed u–p formulation,
  ``[[A, Bᵀ], [B, −C]] [u; p] = [f; g]`` with ``A`` the displacement block and ``C ≥ 0``
  the (scaled) pressure mass matrix.

``method='auto'`` factorizes directly while the reduced matrix has at most :data:`DIRECT_MAX_NNZ`
non-zeros (CHOLMOD's supernodal Cholesky through cvxopt, or SuperLU without it:
:data:`DIRECT_MAX_NNZ_SUPERLU`), or :data:`DIRECT_MAX_NNZ_SADDLE` for the saddle point, otherwise
it iterates: conjugate gradients preconditioned with
smoothed-aggregation algebraic multigrid (pyamg) whose near-null space holds the six rigid-body
modes; MINRES with the block-diagonal preconditioner ``diag(AMG(A), S⁻¹)``,
``S = M_p (1/μ_s + 1/λ)`` (a spectrally equivalent Schur complement) for the saddle point.

SPD systems are factorized by CHOLMOD (supernodal ``L Lᵀ``, BLAS-3 on the supernodes) when cvxopt
is installed: on the Hex2 tangents of the publication's meshes it is 2–3× faster than SuperLU or
AMG-CG (10×10×10 cube, 27.8k dofs: 1.05 s against 2.7 s SuperLU and 2.6 s AMG-CG to 1e-11;
8×8×48 beam, 84k dofs: 5.5 s against 11.8 s AMG-CG), and its triangular solves (22 ms on the cube)
make chord steps almost free.  Its symbolic analysis and the map from the matrix's stored entries
to the factorized lower triangle are kept in the caller's ``cache`` and reused while the sparsity
pattern and the prescribed dofs stay the same (every Newton iteration and load step of a solve);
a Newton iteration after the first solves its tangent by CG preconditioned with the last factor
while that takes at most :data:`REUSE_MAXITER` iterations, and factorizes afresh past them (Hex2
neo-Hookean, 20 % tension of the 8×8×48 beam: 12 CG iterations in all instead of two more
factorizations, 31.1 → 18.7 s of CPU).
A matrix that is not positive definite (a pivot ≤ 0) falls back to SuperLU's symmetric-mode LU;
in a Newton step (``descent``) it is first factorized shifted, ``K + μ·mean|diag K|·I`` with the
smallest μ of :data:`TANGENT_SHIFTS` that is positive definite (a descent direction of the
potential energy).
The saddle point stays on SuperLU: CHOLMOD's supernodal kernel is ``L Lᵀ`` only, and its simplicial
``L D Lᵀ`` was 4× slower than SuperLU on the mixed 10×10×10 cube.

Fill-reducing order of the direct factorizations: the callers pass ``order``, a permutation of the
unknowns from :func:`nested_dissection` of the mesh's nodes (the voxel grid is cut recursively
along its longest extent by a plane of element faces, whose nodes come last).  SuperLU then keeps
that order (``permc_spec='NATURAL'``).  On the publication's meshes it halves the factorization
time against SuperLU's own minimum degree ordering (mixed u–p on the 10×10×10 cube: 3.9 s against
8.4 s of CPU, 30 M against 43 M non-zeros in the factors).  Without ``order`` SuperLU orders by
minimum degree on ``AᵀA + A`` as before; any symmetric order gives the same solution to round-off
(both systems are symmetric quasi-definite: an LDLᵀ factorization exists for every order).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .ordering import dof_order, nested_dissection, separator_dofs, unknown_order  # noqa: F401 - imported from here too

try:  # CHOLMOD (SuiteSparse) through cvxopt's wheels: supernodal Cholesky, reusable symbolic analysis
    import cvxopt
    from cvxopt import cholmod
except ImportError:  # pragma: no cover - SuperLU and AMG-CG do everything, slower
    cvxopt = cholmod = None

DIRECT_MAX_NNZ_SUPERLU = 4_000_000
"""Largest reduced SPD matrix (non-zeros) that ``method='auto'`` factorizes with SuperLU (about
50k Hex1 dofs; on the 10×10×10 cube, 27k Hex2 dofs and 4.8M non-zeros, SuperLU took 9–12 s in
minimum degree order and AMG-CG 2.3 s)."""

DIRECT_MAX_NNZ_CHOLMOD = 40_000_000
"""Largest reduced SPD matrix that ``method='auto'`` factorizes with CHOLMOD (the 8×8×48 beam in
Hex2 has 14.6M non-zeros and its factorization peaks at about 2 GB)."""

DIRECT_MAX_SEPARATOR = 2_000
"""Largest first separator (dofs, :func:`separator_dofs`) of the nested-dissection order with which
``method='auto'`` factorizes with CHOLMOD: the dense factorization of the top separators dominates a
3D factorization, so the slender bodies and the 10×10×10 cube factorize fast and a thick body does
not.  Measured numeric factorizations against AMG-CG (whole solve) in one run: 10×10×10 cube in Hex2,
1,323 separator dofs, 1.05 s against 2.6 s; 8×8×48 beam, 867 dofs, 5.5 s against 11.8 s; the [B09]
L-shape on 16³ cells, 3,267 dofs, 14.9 s against 19 s (AMG is kept there)."""

REUSE_MAXITER = 12
"""Newton iterations after the first solve their tangent by CG preconditioned with the last CHOLMOD
factor of the same pattern; past this many CG iterations the tangent is factorized afresh (a
factorization costs about 50 preconditioned iterations on the publication's meshes)."""

TANGENT_SHIFTS = (1e-3, 1e-2, 1e-1, 1.0)
"""Shifts μ (of the mean diagonal) tried, smallest first, on a displacement tangent that is not
positive definite (:func:`_shifted_factor`) before SuperLU's LDLᵀ of the tangent itself.  Far from
equilibrium a near-incompressible body's tangent has hundreds of negative pivots (571 of 10,752 on
the 15³ Hex1 cube twisted 45° at ν = 0.499), and SuperLU factorizes in 20× CHOLMOD's time
(0.42 s against 0.022 s there; 10.7 s against 2 s on the 8×8×48 Hex2 beam)."""

SCHUR_RTOL = 1e-13
"""Relative tolerance of the CG on the pressure Schur complement (:class:`SchurSolve`) of a
stand-alone solve, and the tightest one inside Newton (which asks for less far from the solution:
``schur_rtol`` of :func:`solve_saddle`)."""
SCHUR_MAXITER = 300
"""Its iteration limit; past it the saddle point is factorized by SuperLU."""

DIRECT_MAX_NNZ = DIRECT_MAX_NNZ_SUPERLU
"""Largest reduced SPD matrix (non-zeros) that ``method='auto'`` factorizes directly when no
separator size is known (without CHOLMOD, or without a nested-dissection order)."""

DIRECT_MAX_NNZ_SADDLE = 20_000_000
"""Largest saddle-point matrix that ``method='auto'`` factorizes directly.  Higher than for SPD
systems: block-preconditioned MINRES needs hundreds of iterations at ν → ½ (measured: 654
iterations, 241 s, against 14 s for the factorization on the 10×10×10 cube, 29k dofs)."""

SCHUR_BYTES_PER_NNZ = 175.0
"""Peak memory of a Newton solve with the Schur elimination of a saddle point above
:data:`DIRECT_MAX_NNZ_CHOLMOD`, per non-zero of its displacement block: the mixed twist of the
1,600-cell cylinder at refine 2 (330,723 displacement dofs, 60.1M non-zeros, first separator 4,083
dofs) peaked at 10.5 GB (9.0 GB for the assembly and one factorization alone), its numeric
factorization 57 s; the same reference took 2,190 s with block-preconditioned MINRES."""

AVAILABLE_FRACTION = 0.8
"""Share of the memory available at the time of a solve that a Schur elimination may plan to use."""


def available_memory() -> float:
    """Physical memory available now (bytes; ``inf`` where the system does not say)."""
    import os

    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_AVPHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
        return float("inf")


def _schur_fits(nnz: int, cache: dict | None = None) -> bool:
    """A saddle point's displacement block of ``nnz`` non-zeros may be factorized for the Schur
    elimination: within :data:`DIRECT_MAX_NNZ_CHOLMOD`, or its measured peak
    (:data:`SCHUR_BYTES_PER_NNZ`) within :data:`AVAILABLE_FRACTION` of the memory available now
    less what other processes' large factorizations planned and have not allocated yet
    (:func:`fem_reference.memory.admit`, which waits while it would fit once they end).  The plan is
    kept in ``cache["memory_plan"]`` for as long as the cache (the factor's lifetime)."""
    if nnz <= DIRECT_MAX_NNZ_CHOLMOD:
        return True
    from .memory import admit

    plan = admit(nnz * SCHUR_BYTES_PER_NNZ, available_memory, AVAILABLE_FRACTION)
    if plan is not None and cache is not None:
        old = cache.pop("memory_plan", None)
        cache["memory_plan"] = plan
        if old is not None:
            old.release()
    return plan is not None


def _holds_factor(cache: dict | None, A: sp.csr_matrix, free: np.ndarray) -> bool:
    """``cache`` holds the CHOLMOD factor of a matrix of ``A``'s pattern (an earlier Newton
    iteration's): its memory is this solve's already, admitted when it was made."""
    fac = cache.get("cholmod") if cache is not None else None
    if not isinstance(fac, CholmodFactor):
        return False
    return fac.matches(A if A.has_sorted_indices else A.sorted_indices(), free)


METHODS = ("auto", "direct", "amg")


@dataclass
class SolveStats:
    """What a linear solve did (kept in :attr:`Result.info`)."""

    method: str = ""
    iterations: int = 0
    calls: int = 0
    details: list = field(default_factory=list)

    def add(self, method: str, iterations: int) -> None:
        self.method = method
        self.iterations += int(iterations)
        self.calls += 1


def rigid_modes(points: np.ndarray) -> np.ndarray:
    """(3 n, 6) translations and infinitesimal rotations of nodes ``points`` (n, 3), interleaved dofs."""
    n = len(points)
    B = np.zeros((n, 3, 6))
    c = points - points.mean(axis=0)
    for i in range(3):
        B[:, i, i] = 1.0
    x, y, z = c[:, 0], c[:, 1], c[:, 2]
    B[:, 0, 3], B[:, 1, 3] = -y, x
    B[:, 1, 4], B[:, 2, 4] = -z, y
    B[:, 2, 5], B[:, 0, 5] = -x, z
    return B.reshape(3 * n, 6)


class OrderedLU:
    """SuperLU factorization (diagonal pivots) of a symmetric matrix ``A`` in the order ``perm``
    (``None``: SuperLU's minimum degree order); :meth:`solve` takes and returns vectors in the
    original order, :attr:`lu` solves in the permuted one.

    ``permuted=True``: ``A`` is already ``A[perm][:, perm]``.  A symmetric CSR matrix is passed to
    SuperLU as CSC without conversion (its CSR arrays are the CSC arrays of ``Aᵀ = A``)."""

    def __init__(self, A: sp.spmatrix, perm: np.ndarray | None, permuted: bool = False):
        self.perm = perm
        Ap = sp.csr_matrix(A if (perm is None or permuted) else A[perm][:, perm])
        Ap = sp.csc_matrix((Ap.data, Ap.indices, Ap.indptr), shape=Ap.shape)
        self.lu = spla.splu(Ap, permc_spec="MMD_AT_PLUS_A" if perm is None else "NATURAL",
                            diag_pivot_thresh=0.0, options=dict(SymmetricMode=True))

    def solve(self, b: np.ndarray) -> np.ndarray:
        if self.perm is None:
            return self.lu.solve(b)
        x = np.empty_like(b)
        x[self.perm] = self.lu.solve(b[self.perm])
        return x


class CholmodFactor:
    """CHOLMOD's ``L Lᵀ`` of the free block ``K[free][:, free]`` of a symmetric matrix, in the
    fill-reducing order ``perm`` (``None``: CHOLMOD's own).  :meth:`factorize` takes the whole
    matrix; while its sparsity pattern is the one of the first call (compared entry by entry),
    it only gathers the stored values of the triangle through a precomputed map and
    refactorizes numerically.  :meth:`solve` takes and returns free-dof vectors.  A factorization
    of a matrix that is not positive definite raises ``ArithmeticError``."""

    def __init__(self, K: sp.csr_matrix, free: np.ndarray, perm: np.ndarray | None):
        self.indptr, self.indices = K.indptr.copy(), K.indices.copy()
        self.free = free.copy()
        # The upper triangle of the free block in CSR is the lower triangle in CSC (the pattern is
        # symmetric), and K's sorted CSR order is already that order: a mask picks the entries.
        local = np.cumsum(free) - 1  # free-dof number of each free dof (order kept)
        rows = np.repeat(np.arange(K.shape[0]), np.diff(K.indptr))
        keep = free[rows] & free[K.indices] & (K.indices >= rows)
        self.source = np.flatnonzero(keep)
        nf = int(free.sum())
        colptr = np.zeros(nf + 1, dtype=np.int64)
        np.cumsum(np.bincount(local[rows[self.source]], minlength=nf), out=colptr[1:])
        cols = np.repeat(np.arange(nf), np.diff(colptr))
        self._A = cvxopt.spmatrix(K.data[self.source], local[K.indices[self.source]].astype(np.int64), cols,
                                  (nf, nf))
        self.diagonal = np.flatnonzero(K.indices[self.source] == rows[self.source])  # its diagonal entries
        if perm is None:
            self._F = cholmod.symbolic(self._A, uplo="L")
        else:
            self._F = cholmod.symbolic(self._A, p=cvxopt.matrix(np.asarray(perm, dtype=np.int32)), uplo="L")

    def matches(self, K: sp.csr_matrix, free: np.ndarray) -> bool:
        return (K.shape[0] == len(self.free) and np.array_equal(free, self.free)
                and np.array_equal(K.indptr, self.indptr) and np.array_equal(K.indices, self.indices))

    def factorize(self, K: sp.csr_matrix, shift: float = 0.0) -> "CholmodFactor":
        """The factor of the free block of ``K`` (plus ``shift`` on its diagonal)."""
        data = K.data[self.source]
        if shift:
            data[self.diagonal] += shift
        self._A.V = cvxopt.matrix(data)
        cholmod.numeric(self._A, self._F)
        return self

    def solve(self, b: np.ndarray) -> np.ndarray:
        B = cvxopt.matrix(np.asarray(b, dtype=float))
        cholmod.solve(self._F, B)
        return np.array(B).ravel()


class SchurSolve:
    """Solves of the saddle point ``[[A, Bᵀ], [B, −C]] [u; p] = [b_u; b_p]`` (free dofs) by block
    elimination with a CHOLMOD factor of ``A``: conjugate gradients on the pressure Schur complement
    ``S = C + B A⁻¹ Bᵀ`` (SPD), preconditioned with ``C`` itself (at ν → ½, ``S`` is spectrally
    equivalent to the pressure mass, of which ``C`` is a multiple; PCG does not depend on the
    multiple), then ``u = A⁻¹ (b_u − Bᵀ p)``.  One CG iteration is one pair of triangular solves
    with the factor: 22 iterations to 1e-12 on the mixed 10×10×10 cube.  :attr:`converged` tells
    whether the last :meth:`solve` reached its tolerance (``rtol``, or the one it was given)."""

    def __init__(self, factor: CholmodFactor, Bf: sp.csr_matrix, C: sp.spmatrix, C_lu, rtol: float,
                 maxiter: int = SCHUR_MAXITER):
        self.factor, self.Bf, self.BfT, self.C = factor, Bf, Bf.T.tocsr(), sp.csr_matrix(C)
        self.C_lu, self.rtol, self.maxiter = C_lu, rtol, maxiter
        self.iterations, self.converged = 0, False

    def solve(self, b: np.ndarray, rtol: float | None = None) -> np.ndarray:
        nf, m = self.Bf.shape[1], self.Bf.shape[0]
        bu, bp = b[:nf], b[nf:]
        A_solve, Bf, BfT, C = self.factor.solve, self.Bf, self.BfT, self.C
        S = spla.LinearOperator((m, m), matvec=lambda q: C @ q + Bf @ A_solve(BfT @ q), dtype=float)
        P = spla.LinearOperator((m, m), matvec=self.C_lu.solve, dtype=float)
        count = [0]
        p, info = spla.cg(S, Bf @ A_solve(bu) - bp, M=P, rtol=self.rtol if rtol is None else rtol, atol=0.0,
                          maxiter=self.maxiter, callback=lambda xk: count.__setitem__(0, count[0] + 1))
        self.iterations, self.converged = count[0], info == 0
        return np.concatenate([A_solve(bu - BfT @ p), p])


def _local_order(order: np.ndarray | None, keep: np.ndarray) -> np.ndarray | None:
    """``order`` (a permutation of all unknowns) restricted to the unknowns ``keep`` (boolean) and
    renumbered to their positions among them."""
    if order is None:
        return None
    pos = np.full(len(keep), -1, dtype=np.int64)
    pos[keep] = np.arange(int(keep.sum()))
    p = pos[order]
    return p[p >= 0]


def _choose(method: str, nnz: int, limit: int = DIRECT_MAX_NNZ) -> str:
    if method not in METHODS:
        raise ValueError(f"linear solver must be one of {', '.join(METHODS)}; got {method!r}")
    if method == "auto":
        return "direct" if nnz <= limit else "amg"
    return method


def _choose_spd(method: str, nnz: int, separator: int | None) -> str:
    """``'direct'`` or ``'amg'`` for an SPD system (see :data:`DIRECT_MAX_SEPARATOR`)."""
    if method == "auto" and cholmod is not None and separator is not None:
        return "direct" if nnz <= DIRECT_MAX_NNZ_CHOLMOD and separator <= DIRECT_MAX_SEPARATOR else "amg"
    return _choose(method, nnz)


def _spd_kind(method: str, K: sp.csr_matrix, free: np.ndarray, separator: int | None) -> str:
    """:func:`_choose_spd` for the free block of ``K``, whose entries are counted only when ``K``'s
    own count exceeds the limit that decides (the free block has no more): the same choice, without
    a pass over the entries at every Newton iteration (1.2 s of the 8×8×48 beam's Hex2 reference)."""
    cholmod_rule = method == "auto" and cholmod is not None and separator is not None
    limit = DIRECT_MAX_NNZ_CHOLMOD if cholmod_rule else DIRECT_MAX_NNZ
    return _choose_spd(method, K.nnz if K.nnz <= limit else _submatrix_nnz(K, free), separator)


def _submatrix_nnz(K: sp.csr_matrix, keep: np.ndarray) -> int:
    """Stored entries of ``K[keep][:, keep]`` (without extracting it)."""
    rows = np.repeat(keep, np.diff(K.indptr))
    return int(np.count_nonzero(rows & keep[K.indices]))


AMG_SEED = 0
"""Seed of the start vector of pyamg's spectral-radius estimate (the Jacobi smoothing of its
prolongator): pyamg draws it from NumPy's global generator, so without a seed the same system
gave another preconditioner, other CG iterates and answers that differed by ~1e-14 from one
process to the next (the [B09] L-shape's reference)."""


def _amg(A: sp.csr_matrix, B: np.ndarray):
    """Smoothed-aggregation AMG of ``A`` (near-null space ``B``) as a V-cycle preconditioner, the
    same for the same matrix in any process (:data:`AMG_SEED`; NumPy's global generator is left as
    it was)."""
    import pyamg

    state = np.random.get_state()
    np.random.seed(AMG_SEED)
    try:
        ml = pyamg.smoothed_aggregation_solver(
            A, B=B, symmetry="hermitian", strength="symmetric", max_coarse=500, coarse_solver="splu"
        )
    finally:
        np.random.set_state(state)
    return ml.aspreconditioner(cycle="V")


def solve_spd(
    K: sp.spmatrix,
    f: np.ndarray,
    D: np.ndarray,
    uD: np.ndarray,
    nullspace: np.ndarray,
    method: str = "auto",
    rtol: float = 1e-11,
    stats: SolveStats | None = None,
    cache: dict | None = None,
    order: np.ndarray | None = None,
    separator: int | None = None,
    descent: bool = False,
) -> np.ndarray:
    """Solve ``K u = f`` on the free dofs with ``u[D] = uD``; returns the full ``u``.  ``descent``
    (a Newton step of a minimization): a free block that is not positive definite is replaced by
    its smallest shift that is (:func:`_shifted_factor`), so the step descends the energy; without
    it the solve is exact (SuperLU's LDLᵀ).

    ``nullspace`` (n, 6) are the rigid-body modes (used by AMG only).  ``cache`` (a dict kept by
    the caller, e.g. across Newton iterations with the same prescribed dofs) keeps the AMG
    hierarchy of an earlier matrix as the preconditioner; it is rebuilt when CG needs more than
    twice the iterations per decade of residual reduction it needed when built.  A direct solve
    stores its factorization of the free-dof matrix in ``cache["lu"]`` (its ``solve`` takes free-dof
    vectors), and CHOLMOD's symbolic analysis in ``cache["cholmod"]`` for the next matrix of the
    same pattern.  ``order``: a fill-reducing
    permutation of all ``n`` dofs for the direct factorization (see :func:`dof_order`);
    ``separator``: the dofs of its first separator (:func:`separator_dofs`), for the choice of
    ``method='auto'`` (CHOLMOD up to :data:`DIRECT_MAX_SEPARATOR`, else AMG-CG).
    """
    n = K.shape[0]
    free = np.ones(n, dtype=bool)
    free[D] = False
    u = np.zeros(n)
    u[D] = uD
    K = sp.csr_matrix(K)
    kind = _spd_kind(method, K, free, separator if order is not None else None)
    if kind == "direct" and cholmod is not None:
        x = _spd_cholmod(K, f, u, free, _local_order(order, free), rtol, cache, descent)
        if x is not None:
            u[free] = x[0]
            if stats is not None:
                stats.add(x[1], x[2])
            return u
    if kind == "direct":
        # extract the free block directly in the factorization's order
        perm = _local_order(order, free)
        sel = np.flatnonzero(free) if perm is None else np.flatnonzero(free)[perm]
        Kr = K[sel]
        lu = OrderedLU(Kr[:, sel], perm, permuted=True)
        u[sel] = lu.lu.solve(f[sel] - Kr[:, D] @ uD)
        if cache is not None:
            cache["lu"] = lu
        if stats is not None:
            stats.add(kind, 1)
        return u
    x = _spd_amg(K, f, D, uD, free, nullspace, rtol, cache)
    if x is None:  # a stale preconditioner: rebuild and retry once
        cache.clear()
        return solve_spd(K, f, D, uD, nullspace, method, rtol, stats, cache, order, separator)
    if stats is not None:
        stats.add(kind, x[1])
    u[free] = x[0]
    return u


def _spd_cholmod(K, f, u, free, perm, rtol: float, cache: dict | None, descent: bool = False):
    """CHOLMOD's solve of the free block of ``K`` (``u``: the prescribed values, zero elsewhere):
    ``(x, method, iterations)``, by CG on the last factor of the same pattern when it converges
    within :data:`REUSE_MAXITER`, else by a fresh factorization; ``None`` when the matrix is not
    positive definite, unless ``descent``: then the factor of its smallest shift that is
    (:func:`_shifted_factor`, method ``"cholmod-shifted"``), ``None`` when none is."""
    fac = cache.get("cholmod") if cache is not None else None
    if fac is None or not fac.matches(K, free):
        fac = CholmodFactor(K, free, perm)
        if cache is not None:
            cache["cholmod"] = fac
            cache["factored"] = False
    elif cache.get("factored") and cache.get("lu") is fac:
        x = _pcg_on_factor(K, f, u, free, fac, rtol)  # the last factor of this pattern as preconditioner
        if x is not None:
            return x[0], "cholmod-pcg", x[1]
    method = "cholmod"
    try:
        lu = fac.factorize(K)
    except ArithmeticError:  # not positive definite: the smallest shift that is (else SuperLU's LDLᵀ)
        lu = _shifted_factor(K, free, fac) if descent else None
        method = "cholmod-shifted"
    if cache is not None:
        cache["factored"] = method == "cholmod"  # a later tangent's CG takes only a tangent's factor
    if lu is None:
        return None
    if cache is not None:
        cache["lu"] = lu
    return lu.solve(f[free] - (K @ u)[free]), method, 1


def _shifted_factor(K, free, fac: CholmodFactor) -> CholmodFactor | None:
    """The factor of ``K_ff + μ·mean|diag K_ff|·I`` with the smallest μ of :data:`TANGENT_SHIFTS`
    that is positive definite, None if none is.  Its step is a descent direction of the potential
    energy (the line search's merit), where the indefinite tangent's need not be."""
    diag = K.data[fac.source[fac.diagonal]]
    scale = float(np.abs(diag).mean()) if len(diag) else 0.0
    for mu in TANGENT_SHIFTS:
        try:
            return fac.factorize(K, mu * scale)
        except ArithmeticError:
            continue
    return None


def _spd_amg(K, f, D, uD, free, nullspace, rtol: float, cache: dict | None):
    """AMG-preconditioned CG on the free block of ``K`` to ``rtol``: ``(x, iterations)``; the
    hierarchy is kept in ``cache`` and reused while CG needs at most twice the iterations per decade
    it needed when it was built.  ``None`` when CG with a reused hierarchy fails (rebuild)."""
    Kr = K[free]
    A = Kr[:, free].tocsr()
    b = f[free] - Kr[:, D] @ uD
    reuse = cache is not None and cache.get("n") == A.shape[0] and "M" in cache
    M = cache["M"] if reuse else _amg(A, np.ascontiguousarray(nullspace[free]))
    count = [0]
    x, info = spla.cg(A, b, M=M, rtol=rtol, atol=0.0, maxiter=5000,
                      callback=lambda xk: count.__setitem__(0, count[0] + 1))
    if info != 0 and reuse:
        return None
    if info != 0:
        raise RuntimeError(f"AMG-preconditioned CG did not converge ({count[0]} iterations)")
    its = count[0]
    if cache is not None:
        rate = max(its, 1) / max(1.0, -np.log10(rtol))  # iterations per decade
        if not reuse:
            cache.update(n=A.shape[0], M=M, rate0=rate)
        elif rate > 2 * cache["rate0"]:
            cache.clear()
    return x, its


def solve_saddle(
    A: sp.spmatrix,
    B: sp.spmatrix,
    C: sp.spmatrix,
    f: np.ndarray,
    g: np.ndarray,
    D: np.ndarray,
    uD: np.ndarray,
    nullspace: np.ndarray,
    schur_scale: float,
    method: str = "auto",
    rtol: float = 1e-11,
    stats: SolveStats | None = None,
    cache: dict | None = None,
    order: np.ndarray | None = None,
    separator: int | None = None,
    schur_rtol: float = SCHUR_RTOL,
) -> tuple[np.ndarray, np.ndarray]:
    """Solve ``[[A, Bᵀ], [B, −C]] [u; p] = [f; g]`` with ``u[D] = uD``; returns ``(u, p)``.

    ``schur_scale`` multiplies the pressure mass matrix in the preconditioner:
    ``S ≈ schur_scale · C_mass`` (use ``1/μ + 1/λ`` with ``C = M_p/λ``).  ``cache``: a dict
    that receives the factorization (``cache["lu"]``, of the system on the free dofs and the
    pressure) when the solve is direct.  ``order``: a fill-reducing permutation of the ``n + m``
    unknowns (pressure ``j`` is unknown ``n + j``) for the direct factorization.

    A direct solve with CHOLMOD at hand, an ``order`` and a displacement block that
    :data:`DIRECT_MAX_SEPARATOR` admits (``separator``: dofs of the first separator of the
    displacement unknowns) eliminates the pressure by :class:`SchurSolve` (``cache["lu"]`` is then
    that solver, ``cache["cholmod"]`` the analysis of ``A``), its CG to ``schur_rtol`` (Newton's
    forcing term, :mod:`fem_reference.hyperelastic`); when ``A`` is not positive definite or the CG
    stalls, SuperLU factorizes the whole saddle point.  A saddle point above
    :data:`DIRECT_MAX_NNZ_SADDLE` whose ``A`` CHOLMOD admits (:data:`DIRECT_MAX_NNZ_CHOLMOD`, or a
    larger one whose factorization fits the memory available, :func:`_schur_fits`; any separator) is
    eliminated the same way before MINRES is tried: MINRES with the block-diagonal
    preconditioner needs hundreds of iterations a solve near ν = ½ and, inside Newton, more
    iterations (the finite-strain mixed twist of a 160-cell cylinder at ν = 0.49, 119,614 unknowns:
    6 Newton iterations and 47 s of CPU with the Schur elimination, see
    ``benchmarks/asv_fem_reference.py``).
    """
    n, m = A.shape[0], B.shape[0]
    free = np.ones(n, dtype=bool)
    free[D] = False
    u = np.zeros(n)
    u[D] = uD
    A = sp.csr_matrix(A)
    B = sp.csr_matrix(B)
    Aff = A[free][:, free]
    Bf = B[:, free]
    bu = f[free] - A[free][:, D] @ uD
    bp = g - B[:, D] @ uD
    rhs = np.concatenate([bu, bp])
    kind = _choose(method, Aff.nnz + 2 * Bf.nnz + C.nnz, DIRECT_MAX_NNZ_SADDLE)
    if cache is None:  # a solve on its own: its factor (and memory plan) lives until it returns
        cache = {}
    if cholmod is not None and order is not None and method == "auto" and (
            (kind == "direct" and _choose_spd("auto", Aff.nnz, separator) == "direct")
            or (kind == "amg" and (_holds_factor(cache, A, free) or _schur_fits(Aff.nnz, cache)))):
        x = _schur_solve(A, Bf, C, rhs, free, _local_order(order, np.concatenate([free, np.zeros(m, bool)])),
                         cache, stats, schur_rtol)
        if x is not None:
            u[free] = x[: int(free.sum())]
            return u, x[int(free.sum()):]
    S = sp.bmat([[Aff, Bf.T], [Bf, -C]], format="csr")
    if kind == "direct":
        # [[A, Bᵀ], [B, −C]] with A, C positive definite is symmetric quasi-definite: an LDLᵀ
        # factorization exists for every symmetric ordering, so no pivoting is needed.
        lu = OrderedLU(S, _local_order(order, np.concatenate([free, np.ones(m, dtype=bool)])))
        x = lu.solve(rhs)
        its = 1
        cache["lu"] = lu  # the caller may reuse the factorization (chord steps)
    else:
        x, its = _saddle_minres(S, rhs, Aff, C, np.ascontiguousarray(nullspace[free]), schur_scale, rtol)
    if stats is not None:
        stats.add(kind if kind == "direct" else "amg-minres", its)
    u[free] = x[: int(free.sum())]
    return u, x[int(free.sum()):]


def _saddle_minres(S, rhs, Aff, C, nullspace, schur_scale: float, rtol: float):
    """MINRES on the saddle point ``S`` with the block-diagonal preconditioner
    ``diag(AMG(Aff), (schur_scale · lumped C)⁻¹)``: ``(x, iterations)``."""
    Ma = _amg(Aff.tocsr(), nullspace)
    # Lumped pressure mass for the Schur block.
    Mp = np.asarray(abs(C).sum(axis=1)).ravel()
    Mp = np.where(Mp > 0, Mp, 1.0)
    nu_ = Aff.shape[0]

    def apply(r):
        out = np.empty_like(r)
        out[:nu_] = Ma @ r[:nu_]
        out[nu_:] = r[nu_:] / (schur_scale * Mp)
        return out

    P = spla.LinearOperator(S.shape, matvec=apply, dtype=float)
    count = [0]
    # scipy's MINRES stops on ‖r‖ ≤ rtol (‖S‖ ‖x‖ + ‖b‖), looser than ‖r‖ ≤ rtol ‖b‖ when
    # the blocks are scaled as differently as here (forces vs volumes): tighten it.
    x, info = spla.minres(S, rhs, M=P, rtol=rtol * 1e-3, maxiter=10000,
                          callback=lambda xk: count.__setitem__(0, count[0] + 1))
    if info != 0:
        raise RuntimeError(f"block-preconditioned MINRES did not converge ({count[0]} iterations)")
    return x, count[0]


def _pcg_on_factor(K, f, u, free, fac: CholmodFactor, rtol: float):
    """CG on the free block of ``K`` (right-hand side ``f`` less the prescribed ``u``) preconditioned
    with an earlier CHOLMOD factor of a matrix of the same pattern (a tangent of an earlier Newton
    iteration), to ``rtol``: ``(x, iterations)``, or ``None`` after :data:`REUSE_MAXITER` iterations
    (the factor is then too far from ``K``: refactorize)."""
    nf = int(free.sum())
    full = np.zeros(len(free))

    def matvec(x):
        full[free] = x
        return (K @ full)[free]

    b = f[free] - (K @ u)[free]
    count = [0]
    x, info = spla.cg(spla.LinearOperator((nf, nf), matvec=matvec, dtype=float), b,
                      M=spla.LinearOperator((nf, nf), matvec=fac.solve, dtype=float), rtol=rtol, atol=0.0,
                      maxiter=REUSE_MAXITER, callback=lambda xk: count.__setitem__(0, count[0] + 1))
    return (x, count[0]) if info == 0 else None


def _schur_solve(A, Bf, C, rhs, free, perm, cache, stats, rtol: float = SCHUR_RTOL):
    """:class:`SchurSolve` of the saddle point (see :func:`solve_saddle`), or ``None`` if ``A`` is not
    positive definite or the CG does not converge."""
    if not A.has_sorted_indices:
        A = A.sorted_indices()
    fac = cache.get("cholmod") if cache is not None else None
    if fac is None or not fac.matches(A, free):
        fac = CholmodFactor(A, free, perm)
        if cache is not None:
            cache["cholmod"] = fac
    C_lu = cache.get("C_lu") if cache is not None and cache.get("C") is C else None
    if C_lu is None:
        C_lu = spla.splu(sp.csc_matrix(C))
        if cache is not None:
            cache.update(C=C, C_lu=C_lu)
    try:
        fac.factorize(A)
    except ArithmeticError:
        return None
    solver = SchurSolve(fac, Bf.tocsr(), C, C_lu, rtol)
    x = solver.solve(rhs)
    if not solver.converged:
        return None
    if cache is not None:
        cache["lu"] = solver  # chord steps: the same factor and Schur complement
    if stats is not None:
        stats.add("cholmod-schur", 1)
        stats.details.append(solver.iterations)
    return x
