"""Static equilibrium and implicit (backward) Euler for the mass-spring system.

Both minimize a potential with Newton's method on the exact Hessian (:func:`hybmss.forces.hessian`)
over the free degrees of freedom, with a sparse direct solve and a backtracking line search:

- static: ``Π(x) = E_springs + E_volume − s Σ m g·x``; the plates' prescribed motion and the body
  loads (gravity, dead loads) are applied together in load steps ``s ∈ (0, 1]`` whose size adapts (halved when Newton fails, grown when it converges
  quickly).  Converged when ``‖f_free‖₂ ≤ rtol · max(|R|, |m g|)`` with R the largest plate
  reaction (``rtol = 1e-8``).
- static with non-conservative terms (:mod:`hybmss.terms`, the [B09] corrections of
  ``baudet2009``): no potential exists, so the same Newton, predictor, load stepping and shifts
  run in **residual mode**: the exact nonsymmetric Jacobian ``∂(−f)/∂x`` (general sparse LU), the
  merit ``½‖f_free‖²`` with a line search on ``‖f_free‖``, a shift retried when that search
  fails, and no stability certificate (the LDLᵀ inertia needs a symmetric Hessian): the result is
  an equilibrium with no inverted cell, its stability is not checked (``info['stability']``).
- implicit Euler with mass-proportional damping c (1/s): ``M (1 + c dt)(x − x_n)/dt² − M v_n/dt =
  f(x)``, i.e. the minimizer of the incremental potential
  ``Φ(x) = (1 + c dt)/(2 dt²) (x − x̃)ᵀ M (x − x̃) + Π(x)``, ``x̃ = x_n + dt v_n/(1 + c dt)``.

**Zero-energy modes.**  Without face diagonals (``hybmss-fd``) the cubic lattice has hourglass
modes, so the constrained Hessian can be singular even with clamped plates.  When the
factorization fails or the Newton direction is not a descent direction, the solver adds a
Levenberg–Marquardt shift ``μ·mean(diag H)·I`` (μ from 1e-6, ×100 until it works).  The shift
only damps the step; convergence is still judged on the unshifted force residual, so the result is
an exact equilibrium in which the zero-energy modes keep their initial (zero) amplitude.  Each
result records in ``info['regularized_steps']`` how often this happened.  A lattice whose cells
have no zero-energy mode (:func:`_cell_zero_energy_modes`: hybmss, hybmss-cf) meets an indefinite
Hessian (the volume term's ``(J − 1) ∂²J`` far from ``J = 1`` at ν → ½) with the same shifts,
Cholesky only, instead of the unshifted LDLᵀ step: a descent direction, and 5× fewer iterations on
the 10³ cube at ν = 0.499 in 20 % compression, to the same equilibrium.  A lattice with such
modes keeps the unshifted step: its equilibria depend on the path (buckled, hourglassed states),
down to rounding.  Measured on the 127 hybmss-fd static runs of ``make reproduce-paper``: with
the same Newton matrices factorized by SuperLU in its minimum-degree order instead of the
nested-dissection one (the same steps up to rounding), 92 reach the same equilibrium (forces,
volume change, largest displacement within 5e-5), 8 its mirror image (the torques change sign),
and 3 another one: the 10³ and 6³ cubes in 5 % compression at ν = 0 escape the saddle at which
they stop otherwise (plate force −4,737 N instead of −11,464 N on 10³), and the 4×4×24 beam in
5 % tension at ν = 0.499 moves by 6e-4.  Such answers hold for this factorization only.

**Loss of stability.**  For ν < 1/4, κ < 0 and the volume energy is unbounded below under
dilation; at large tension the equilibrium disappears.  When the load step cannot be reduced
further, :class:`StaticSolveError` reports the load factor reached and the smallest eigenvalue of
the constrained Hessian there, naming this cause when κ < 0.

**Locating the limit point.**  Near a fold at ``s*`` the stable branch is ``x(s) ≈ x* − c√(s* − s) e``
with λ_min ∝ √(s* − s), so the linear predictor from an equilibrium at ``s < s*`` over a step
``h`` lands on a state whose Hessian is indefinite once ``h > 2 (s* − s)``: beyond the fold.
With κ < 0 (energy mode, ``limit_resolution`` set), a predicted state that dilates the body and
whose smallest eigenvalue is below ``−FOLD_MARGIN`` (0.1) times that of the stable equilibrium it
was predicted from (a failed Cholesky of the shifted Hessian, no Newton needed) therefore
brackets a limit point.  The load factor is then bisected in that bracket: a midpoint whose
predicted state is beyond the fold in that sense moves the upper end down without Newton;
otherwise Newton (``retry_iter`` iterations, giving up when its iterates stay out of the stable
region) decides, converged moving the lower end up, failed the upper end down.  At a width of
``limit_resolution`` (1 %) of the first bracket, the ordinary Newton at the upper end decides
(``limit_iter`` = 4 iterations):
failing, :class:`StaticSolveError` reports the bracket (message as above); converging (a
bifurcation the path passes, as with the soft modes of hybmss-fd at ν = 0.2, not a fold), the
load stepping goes on without bracketing.  This replaces some ten failing Newton attempts of
8–20 iterations with a few predictors, factorizations and short Newton solves.

**Linear algebra.**  The energies, forces and Hessians are the Numba twins of
:mod:`hybmss.forces`; the Hessian is written into one fixed CSR pattern, and the constrained
Hessian, its lower triangle and its shifts are gathers of it on that pattern
(:class:`_Tangent`), explicit zeros kept, so CHOLMOD's symbolic analysis is done once per solve.
CHOLMOD's Cholesky (and SuperLU where a matrix is not positive definite, or in residual mode)
factorize in a nested-dissection order of the lattice nodes (:func:`_grid_dissection`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

try:  # CHOLMOD (SuiteSparse) through cvxopt's wheels: supernodal Cholesky, symbolic analysis reusable
    import cvxopt
    from cvxopt import cholmod
except ImportError:  # pragma: no cover - SuperLU's symmetric LU does everything, slower
    cvxopt = cholmod = None

from .lattice import box_dissection
from .forces import cell_volumes, energy_forces, free_pattern, hessian_pattern, stiffness
from .result import Reaction, Result, reaction_from_nodal
from .scene import Scene
from .system import System, build


class StaticSolveError(RuntimeError):
    """The static solver could not reach equilibrium; the message says where and why."""


NU_RANGE = (-0.99, 0.49999)
"""Poisson ratios for which the Newton solvers reach equilibrium in float64 and the moduli come out
right (tests/test_moduli.py).  Beyond ν = 0.49999 the volume term (κ > 1.6e4 E) drowns the plate
reactions in its round-off; below ν = −0.99 the shear springs (k > 50 E le) do, and finite-strain
terms amplified by G/K make the measured E wrong by more than 1 % at a strain of 1e-4."""


def check_nu(nu: float) -> None:
    """Raise ``ValueError`` for a Poisson ratio outside :data:`NU_RANGE`."""
    lo, hi = NU_RANGE
    if not (lo <= nu <= hi):
        raise ValueError(f"nu={nu!r} is outside [{lo}, {hi}], the range in which the static and implicit "
                         "solvers reach an equilibrium in float64")


@dataclass(frozen=True)
class StaticOptions:
    rtol: float = 1e-8
    max_iter: int = 20
    """Newton iterations of the first attempt at a load step; a retry after a failed (halved)
    step gets ``retry_iter``: from the tangent predictor a reachable state converges in a few."""
    retry_iter: int = 8
    initial_steps: int = 1
    min_step: float = 1.0 / 4096
    max_step: float = 1.0
    line_search: bool = True
    check_stability: bool = True
    """Check the smallest eigenvalue of the constrained Hessian at the solution and leave saddles."""
    max_escapes: int = 5
    limit_resolution: float | None = 0.01
    """Width of the load-factor bracket a suspected limit point is located to, as a fraction of
    the load step that first pointed at it (:func:`solve_static`); None: plain halving of the
    load step down to ``min_step``."""
    limit_iter: int = 4
    """Newton iterations of the attempt at the upper end of a narrowed limit-point bracket that
    decides whether the equilibrium is lost (a path through a bifurcation converges there in 1–2)."""


@dataclass(frozen=True)
class ImplicitOptions:
    dt: float = 1e-2
    steps: int = 1000
    ramp_time: float = 1.0
    until_rest: bool = True
    rest_tol: float = 1e-6
    """Stop when the largest particle speed · dt falls below rest_tol · le (after the ramp)."""
    rtol: float = 1e-8
    max_iter: int = 30

    def __post_init__(self):
        if not (self.dt > 0):
            raise ValueError(f"dt (time step) must be > 0 s, got {self.dt}")
        if self.steps < 1:
            raise ValueError(f"steps must be >= 1, got {self.steps}")
        if self.ramp_time < 0:
            raise ValueError(f"ramp_time must be >= 0 s, got {self.ramp_time}")


def smooth_ramp(t: float, T: float) -> float:
    """Load factor of a plate moved over ``T`` seconds: ``s = (1 − cos(π t/T))/2``, then 1.

    Zero velocity at both ends, so the plate starts and stops without a jolt."""
    if T <= 0 or t >= T:
        return 1.0
    if t <= 0:
        return 0.0
    return 0.5 * (1.0 - np.cos(np.pi * t / T))


# --------------------------------------------------------------------------------- helpers
def _all_cell_volumes(system: System, x: np.ndarray) -> np.ndarray:
    return cell_volumes(x, system.lattice.cells)


def plate_reactions(system: System, x: np.ndarray, f_total: np.ndarray) -> dict[str, Reaction]:
    """Force each plate exerts on the body: ``−(f_int + m g)`` summed over its particles,
    i.e. minus the total force (springs, volume, gravity) on them; torque about its centroid."""
    out = {}
    for p in system.plates:
        out[p.name] = reaction_from_nodal(x[p.particles], -f_total[p.particles])
    return out


def _force_scale(system: System, f_total: np.ndarray) -> float:
    """Force scale of the convergence test: the largest plate reaction or applied load (gravity,
    scaled terms such as dead loads, at their full value), never below :func:`_force_floor`
    (a zero load has the rest state as its answer: the residual is then judged on the floor)."""
    scale = 0.0
    for p in system.plates:
        scale = max(scale, _norm(f_total[p.particles].sum(axis=0)))
    if system.gravity is not None:
        scale = max(scale, _norm(system.mass.sum() * system.gravity))
    for t in system.terms:
        if t.scaled:
            scale = max(scale, _norm(t.forces(system.X).sum(axis=0)))
    return max(scale, _force_floor(system))


def _force_floor(system: System) -> float:
    """Round-off level of the free residual: 1e-12 · E · le² · √(3n).  A spring force's rounding
    error is ≈ 1e-16 k le with k ≈ E le, so this floor sits ~4 orders above round-off and far
    below ``rtol`` times any plate reaction of a loaded body."""
    return 1e-12 * system.scene.material.E * system.scene.body.le**2 * np.sqrt(3 * system.n)


def _norm(v: np.ndarray) -> float:
    """Euclidean norm without overflow or underflow of the squares (forces of E = 1e300 Pa)."""
    a = float(np.max(np.abs(v), initial=0.0))
    if a == 0.0 or not np.isfinite(a):
        return a
    w = v / a
    return a * float(np.sqrt(_dot(w, w)))


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """``a · b`` by NumPy's pairwise sum, not BLAS: a BLAS ``ddot`` of more than 10⁴ entries wakes
    its thread pool, which on a busy machine costs milliseconds per call (3 ms against 30 µs on
    the beam's 11,421 free dofs, while another process keeps the cores busy)."""
    return float(np.sum(a * b))


def _inertia_floor(w: np.ndarray, x: np.ndarray) -> float:
    """Round-off level of the inertia force ``w (x − x̃)`` of implicit Euler: positions carry a
    relative error of one ulp, so its rounding is ≈ eps · max|x| · max w per dof; the floor is 10×
    that over the 3n dofs.  At small dt (w = m (1 + c dt)/dt² large) it exceeds the static floor,
    and a residual at this level is as converged as positions stored in float64 allow."""
    return 10.0 * np.finfo(float).eps * float(np.abs(x).max()) * float(w.max()) * np.sqrt(x.size)


@dataclass
class _NewtonStats:
    iterations: int = 0
    regularized: int = 0
    line_search_cuts: int = 0
    history: list = field(default_factory=list)


_RESIDUAL_SHIFTS = (0.0, 1e-8, 1e-6, 1e-4, 1e-2, 1.0)
"""Levenberg–Marquardt shifts μ tried in residual mode, in order, until the line search accepts."""


def _energy_shifts(mu_last: float):
    """Shifts tried in energy mode: from a tenth of the last one that worked (0 after an unshifted
    step), ×100 (the first nonzero one 1e-6), five in all."""
    mu = 0.0 if mu_last < 1e-6 else mu_last / 10.0
    for _ in range(5):
        yield mu
        mu = 1e-6 if mu == 0.0 else mu * 100.0


class _Tangent:
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

    def shifted(self, sigma: float) -> "_Tangent":
        """``H_ff + σ I`` on the same pattern."""
        if self.pat is not None:
            data = self._data.copy()
            data[self.pat.full_diag] += sigma
            T = _Tangent(self.J, self.free, self.pat, _data=data)
        else:
            A = self._csc.copy()
            A.setdiag(A.diagonal() + sigma)
            T = _Tangent(self.J, self.free, None, _csc=A)
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


def _grid_dissection(grid: np.ndarray, leaf: int = 16) -> np.ndarray:
    """Nested-dissection order of lattice nodes at integer ``grid`` coordinates (n, 3)
    (:func:`hybmss.lattice.box_dissection` of their bounding box).  On the 8×8×48 beam and the
    10³ cube CHOLMOD's numeric factorization in this order takes 0.55–0.65 of the time it takes
    in its own (AMD) order."""
    g = np.asarray(grid, dtype=np.int64)
    return box_dissection(g, g.min(axis=0), g.max(axis=0), step=1, leaf=leaf)


@lru_cache(maxsize=8)
def _free_order(grid_bytes: bytes, free_bytes: bytes) -> np.ndarray:
    """Fill-reducing order of the free dofs (:func:`_grid_dissection` of their nodes), as indices
    into the free dofs."""
    grid = np.frombuffer(grid_bytes, dtype=np.int64).reshape(-1, 3)
    free = np.frombuffer(free_bytes, dtype=bool)
    nodes = _grid_dissection(grid)
    dofs = (3 * nodes[:, None] + np.arange(3)[None, :]).reshape(-1)
    rank = np.cumsum(free) - 1
    return rank[dofs[free[dofs]]]


def _tangent(S: System, x: np.ndarray, load: float, free: np.ndarray, diag: np.ndarray | None = None) -> _Tangent:
    """The constrained tangent at ``x`` (:class:`_Tangent`), plus ``diag`` on its diagonal."""
    J = stiffness(S, x, load)
    indptr, indices, _ = hessian_pattern(S)
    fixed_pattern = J.indices is indices or (J.indices.shape == indices.shape and np.array_equal(J.indptr, indptr)
                                             and np.array_equal(J.indices, indices))
    T = _Tangent(J, free, free_pattern(S, free) if fixed_pattern and S.conservative else None, diag)
    T.order = _free_order(np.ascontiguousarray(S.lattice.grid, dtype=np.int64).tobytes(),
                          np.ascontiguousarray(free, dtype=bool).tobytes())
    return T


def _factor(A, fac: "_Factorizer | None" = None):
    """Factorization of a symmetric matrix ``A`` (CSC or :class:`_Tangent`) with a ``solve`` method: CHOLMOD's Cholesky
    when ``A`` is positive definite (through ``fac``, which keeps the symbolic analysis), else
    SuperLU's LU in symmetric mode with a minimum-degree ordering of A+Aᵀ (3× faster than the
    default COLAMD on the lattice Hessians; no pivoting, so its pivots are the D of LDLᵀ)."""
    if fac is not None:
        F = fac.cholesky(A)
        if F is not None:
            return F
    return _superlu_symmetric(A)


class _PermutedLU:
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


def _superlu_symmetric(A):
    """SuperLU's LU in symmetric mode (no pivoting: its pivots are the D of LDLᵀ) of ``A``; a
    :class:`_Tangent` with a fill-reducing order is factorized in that order (1.2–1.8× faster on
    the cube and the beam than SuperLU's minimum degree), any other matrix in a minimum-degree
    order of A+Aᵀ."""
    if isinstance(A, _Tangent):
        if A.order is not None:
            return _PermutedLU(spla.splu(A.permuted(), permc_spec="NATURAL", diag_pivot_thresh=0.0,
                                         options={"SymmetricMode": True}), A.order)
        A = A.csc()
    return spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})


class _CholeskyFactor:
    """A CHOLMOD factor ``A = P L Lᵀ Pᵀ`` (valid until its :class:`_Factorizer` factorizes again)."""

    def __init__(self, F):
        self._F = F

    def solve(self, r: np.ndarray) -> np.ndarray:
        B = cvxopt.matrix(np.asarray(r, dtype=float))
        cholmod.solve(self._F, B)
        return np.array(B).ravel()


class _Factorizer:
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

    def cholesky(self, A) -> _CholeskyFactor | None:
        """Cholesky of ``A`` (a :class:`_Tangent` or a symmetric sparse matrix), None if it is
        not positive definite."""
        if cholmod is None:
            return None
        order = None
        if isinstance(A, _Tangent):
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
        return _CholeskyFactor(self._F)


def _factor_general(A):
    """Sparse LU with partial pivoting of a nonsymmetric Jacobian (residual mode): a
    :class:`_Tangent` in its nested-dissection order (4× faster than COLAMD on the 10³ cube of
    baudet2009, half the fill), any other matrix in COLAMD's."""
    if isinstance(A, _Tangent):
        if A.order is not None:
            return _PermutedLU(spla.splu(A.permuted(), permc_spec="NATURAL"), A.order)
        A = A.csc()
    return spla.splu(A)


def _cell_zero_energy_modes(S: System) -> bool:
    """Whether a cell of the lattice, on its own, has a zero-energy mode at rest besides the six
    rigid motions (the hourglass modes of a cubic lattice without face diagonals, hybmss-fd): the
    rest Hessian of the springs joining two of its corners, ``Σ k ê êᵀ``, plus the volume term's
    rank-one ``g gᵀ`` (``g = ∂V/∂x``: any energy of the cell volume has that Hessian at rest),
    has more than six eigenvalues below 1e-9 of the largest.  Such a lattice has equilibria that
    depend on the path (buckled, hourglassed), so :func:`_newton` keeps its unshifted steps on it."""
    cells = S.lattice.cells
    if len(cells) == 0:
        return False
    return _zero_energy_modes_of_cell(S, int(len(cells) // 2))


def _zero_energy_modes_of_cell(S: System, c: int) -> bool:
    nodes = np.asarray(S.lattice.cells[c], dtype=np.int64)
    local = np.full(S.n, -1, dtype=np.int64)
    local[nodes] = np.arange(8)
    la, lb = local[S.spring_a], local[S.spring_b]
    inside = (la >= 0) & (lb >= 0)
    K = np.zeros((24, 24))
    X = S.X
    for a, b, k in zip(la[inside], lb[inside], S.spring_k[inside]):
        e = X[nodes[b]] - X[nodes[a]]
        e = e / np.linalg.norm(e)
        B = np.zeros(24)
        B[3 * a:3 * a + 3], B[3 * b:3 * b + 3] = -e, e
        K += k * np.outer(B, B)
    if S.has_volume:
        x0 = X[nodes].reshape(1, 8, 3)
        h = 1e-6 * S.scene.body.le
        g = np.empty(24)
        idx = np.arange(8).reshape(1, 8)
        for j in range(24):
            xp, xm = x0.copy(), x0.copy()
            xp[0, j // 3, j % 3] += h
            xm[0, j // 3, j % 3] -= h
            g[j] = (cell_volumes(xp.reshape(8, 3), idx)[0] - cell_volumes(xm.reshape(8, 3), idx)[0]) / (2 * h)
        scale = np.abs(np.diag(K)).max() if K.any() else 1.0
        K += scale * np.outer(g, g) / float(g @ g)
    w = np.linalg.eigvalsh(K)
    return int(np.count_nonzero(w <= 1e-9 * max(abs(w).max(), 1e-300))) > 6


def _newton(system: System, x: np.ndarray, free: np.ndarray, rtol: float, max_iter: int,
            inertia: tuple[np.ndarray, np.ndarray] | None, stats: _NewtonStats, line_search=True,
            lu=None, load: float = 1.0, fac: _Factorizer | None = None, definite_after: int | None = None):
    """Newton's method over the free dofs from ``x`` at load factor ``load``, in one of two modes:

    - **energy** (every force conservative): minimize Π (+ the inertia term ``½ Σ w_a |x_a − x̃_a|²``
      when ``inertia = (w, x̃)``) with the exact symmetric Hessian; a step is a descent direction of
      Π and the backtracking line search asks Π to decrease (Armijo);
    - **residual** (non-conservative terms, no energy; ``inertia`` must be None): find a zero of the
      force residual r with the exact nonsymmetric Jacobian ``∂(−f)/∂x`` (general LU); the merit
      is ``‖r‖``, a line search asks it to decrease (Armijo on the norm), and a step the
      search rejects is retried with the next Levenberg–Marquardt shift of ``_RESIDUAL_SHIFTS``.

    Both share the shifts ``μ·mean(diag)·I`` against zero-energy modes, the rejection of inverted
    cells (also of an inverted start: an inverted lattice can have zero forces) and the
    convergence test ``‖r‖ ≤ max(rtol · scale, floor)`` on the unshifted residual.

    ``lu`` (energy mode): a factorization of a nearby Hessian (the predictor's).  It is reused for
    the next step (a chord step) as long as it reduced the residual at least 5-fold and gives a
    descent direction; otherwise the exact Hessian at the current point is factorized.  The
    converged state does not depend on this (the residual test uses the exact forces).
    ``definite_after`` (energy mode, with ``fac``): give up when the unshifted Hessian is still (or
    again) not positive definite after that many iterations, as near a limit point, where iterates
    that stay out of the stable region are taken as the sign that no equilibrium is near
    (:func:`solve_static` then brackets the fold).
    Returns (converged, x, f_total, residual_norm, scale).
    """
    residual = not system.conservative
    if residual and inertia is not None:
        raise ValueError("the residual mode has no incremental potential for an inertia term")
    n = system.n
    cells = system.lattice.cells
    le = system.scene.body.le

    def evaluate(xx):
        """(merit, forces): Π (+ inertia) in energy mode, ‖r_free‖ in residual mode."""
        e, f, _ = energy_forces(system, xx, load)
        if inertia is not None:
            w, xt = inertia
            d = xx - xt
            e += 0.5 * float(np.sum(w[:, None] * d * d))
            f = f - w[:, None] * d
        if residual:
            e = _norm(f.ravel()[free])
        return e, f

    e, f = evaluate(x)
    floor = _force_floor(system)
    if inertia is not None:
        floor = max(floor, _inertia_floor(inertia[0], x))
    if np.any(cell_volumes(x, cells) <= 0.0):
        return False, x, f, np.inf, _force_scale(system, f)
    best, e_best, stalled = np.inf, np.inf, 0
    mu_last, lu_mu = 0.0, 0.0
    # every unshifted Hessian is tried by Cholesky first (a failure is cheap against SuperLU's LU,
    # 2.5–3× a Cholesky, and Newton's Hessians turn positive definite again within a call).  A
    # lattice whose cells have no zero-energy mode then steps with the Cholesky of the smallest
    # shift that is positive definite; one with such modes keeps the unshifted (LDLᵀ) step
    definite_steps = None  # decided (by the cell rank test) when a Cholesky first fails
    if residual:
        lu = None
    for it in range(max_iter + 1):
        r = f.ravel()[free]
        rnorm = _norm(r)
        # the reaction scale uses the static forces: remove the inertia term (derivable, no re-evaluation)
        scale = _force_scale(system, f if inertia is None else f + inertia[0][:, None] * (x - inertia[1]))
        stats.history.append(rnorm / scale)
        if not np.isfinite(rnorm):
            return False, x, f, rnorm, scale
        if rnorm <= max(rtol * scale, floor):
            return True, x, f, rnorm, scale
        if it == max_iter:
            break
        # give up early when for 6 iterations neither the residual has halved nor the merit
        # dropped by more than 1e-8 of its scale (no progress toward a solution)
        progress = rnorm < 0.5 * best or e < e_best - 1e-8 * max(abs(e_best), floor * le)
        best, e_best = min(best, rnorm), min(e_best, e)
        stalled = 0 if progress else stalled + 1
        if stalled >= 6:
            break
        chord = None
        if lu is not None:
            with np.errstate(all="ignore"):
                cand = lu.solve(r)
            if np.all(np.isfinite(cand)) and _dot(r, cand) > 0.0:
                chord = cand
            else:
                lu = None
        fresh = chord is None
        if fresh:
            Jff = _tangent(system, x, load, free, None if inertia is None else np.repeat(inertia[0], 3)[free])
            diag_mean = float(np.abs(Jff.diagonal()).mean())
            shifts = _RESIDUAL_SHIFTS if residual else _energy_shifts(mu_last)
        else:
            shifts = (None,)
        accepted = False
        for mu in shifts:
            if mu is None:
                dx = chord
            else:
                A = Jff if mu == 0.0 else Jff.shifted(mu * diag_mean)
                try:
                    with np.errstate(all="ignore"):
                        if residual:
                            lu = _factor_general(A)
                        else:
                            lu = fac.cholesky(A) if fac is not None else None
                            if lu is None and fac is not None and cholmod is not None:
                                if mu == 0.0 and definite_after is not None and it >= definite_after:
                                    return False, x, f, rnorm, scale
                                if definite_steps is None:
                                    definite_steps = not _cell_zero_energy_modes(system)
                                if definite_steps and mu < 1.0:
                                    continue
                            if lu is None:
                                lu = _superlu_symmetric(A)
                        dx = lu.solve(r)
                    ok = np.all(np.isfinite(dx)) and (residual or _dot(r, dx) > 0.0)
                except RuntimeError:  # exactly singular
                    ok = False
                if not ok:
                    lu = None
                    continue
                mu_last, lu_mu = mu, mu
            # backtracking line search on the merit, rejecting inverted cells
            step = np.zeros(3 * n)
            step[free] = dx
            step = step.reshape(n, 3)
            alpha = 1.0
            slope = _dot(r, dx)
            for _ in range((12 if mu == 1.0 else 4) if residual else 12):
                xt = x + alpha * step
                if np.all(cell_volumes(xt, cells) > 0.0):
                    et, ft = evaluate(xt)
                    rt = _norm(ft.ravel()[free])
                    if residual:
                        accepted = rt <= (1.0 - 1e-4 * alpha) * rnorm
                    else:
                        accepted = (not line_search) or et <= e - 1e-4 * alpha * slope or (
                            rt < rnorm and abs(et - e) <= 1e-10 * max(abs(e), floor * le))
                    if accepted:
                        break
                alpha *= 0.5
                stats.line_search_cuts += 1
            if accepted or not residual:
                break
        if not accepted:
            if not fresh:  # the chord direction failed: retry with the exact Hessian
                lu = None
                continue
            return False, x, f, rnorm, scale
        stats.iterations += 1
        if lu_mu > 0.0:
            stats.regularized += 1
        if residual or alpha < 1.0 or rt > 0.2 * rnorm:
            lu = None  # slow contraction (or residual mode): refactorize at the new point
        x, e, f = xt, et, ft
    return False, x, f, rnorm, scale


def _tangent_predictor(system: System, x: np.ndarray, target: np.ndarray, free: np.ndarray,
                       load: float = 1.0, fac: _Factorizer | None = None, cache: dict | None = None):
    """First-order guess for a new load step: move the prescribed dofs to ``target`` and the free
    dofs by the linear response ``δ_f = J_ff⁻¹ (f_f − J_fc δ_c)``, J = ∂(−f)/∂x at ``x``.  Energy
    mode: J is the Hessian, factorized as is; returns ``(guess, lu)`` (the factorization, reusable
    by Newton).  Residual mode: J is shifted by 1e-8 · mean diag against zero-stiffness modes and
    ``lu`` is None.  ``(None, None)`` if it fails.

    ``cache`` (energy mode, with a ``fac`` only the predictor uses): the tangent and its
    factorization at the last ``x`` (the same object), reused for another target from that
    state, as when a limit point is bisected.  Only a Hessian of springs and cells (the fixed
    pattern) is reused: it does not depend on the load factor."""
    residual = not system.conservative
    hit = cache is not None and not residual and cache.get("x") is x
    Jff = cache["T"] if hit else _tangent(system, x, load, free)
    delta = (target - x).ravel().copy()
    delta[free] = 0.0
    _, f, _ = energy_forces(system, x, load)
    rhs = f.ravel()[free] - (Jff.J @ delta)[free]
    try:
        with np.errstate(all="ignore"):
            if residual:
                lu = _factor_general(Jff.shifted(1e-8 * float(np.abs(Jff.diagonal()).mean())))
            elif hit:
                lu = cache["lu"]
            else:
                if cache is not None:
                    cache.clear()
                lu = _factor(Jff, fac)
                if cache is not None and Jff.pat is not None:
                    cache.update(x=x, T=Jff, lu=lu)
            d_f = lu.solve(rhs)
    except RuntimeError:
        return None, None
    if not np.all(np.isfinite(d_f)):
        return None, None
    delta[free] = d_f
    return x + delta.reshape(x.shape), (None if residual else lu)


def smallest_eigenpair(system: System, x: np.ndarray, fac: "_Factorizer | None" = None) -> tuple[float, np.ndarray]:
    """Smallest eigenvalue (N/m) of the constrained Hessian at ``x`` and its eigenvector
    (over the free dofs).  ``fac``: a factorizer whose symbolic analysis of the pattern is reused
    (its factor is overwritten)."""
    free = ~system.fixed.ravel()
    T = _tangent(system, x, 1.0, free)
    Hff = T.csc()
    if Hff.shape[0] <= 600:
        w, v = np.linalg.eigh(Hff.toarray())
        return float(w[0]), v[:, 0]
    fac = fac if fac is not None else _Factorizer()
    dmax = float(abs(Hff.diagonal()).max())
    # Gershgorin: no eigenvalue lies below min_i (H_ii − Σ_j≠i |H_ij|)
    floor = float((Hff.diagonal() - (abs(Hff).sum(axis=1).A1 - abs(Hff.diagonal()))).min())
    # a fixed start vector: ARPACK's default is random, and the mode it returns then picks which
    # of two nearly equal soft directions a saddle escape follows (runs would differ)
    v0 = np.random.default_rng(0).standard_normal(Hff.shape[0])
    try:
        shift = -1e-3 * dmax
        for _ in range(12):
            # shift-invert with the factorization of A − σI the Newton solves use (Cholesky, or
            # the minimum-degree symmetric LU when it is indefinite), not splu's default ordering
            with np.errstate(all="ignore"):
                F = _factor(T.shifted(-shift), fac)
            op = spla.LinearOperator(Hff.shape, matvec=F.solve, dtype=float)
            vals, vecs = spla.eigsh(Hff, k=1, sigma=shift, which="LM", OPinv=op, v0=v0)
            lam = float(vals[0])
            if not np.isfinite(lam):
                raise ArithmeticError("shift-invert without pivoting broke down")
            # the eigenvalue nearest the shift is the smallest only if H − (λ − ε) I is positive
            # definite; a more negative one lies beyond it (a saddle deep in the spectrum)
            below = lam - 1e-9 * dmax - 1e-6 * abs(lam)
            if _positive_definite(T.shifted(-below), fac) or shift <= floor:
                return lam, vecs[:, 0]
            shift = max(min(lam, shift) - 10.0 * abs(min(lam, shift)), floor - 1e-6 * dmax)
        raise ArithmeticError("the smallest eigenvalue was not isolated")
    except Exception:  # pragma: no cover - fall back to a dense solve
        w, v = np.linalg.eigh(Hff.toarray())
        return float(w[0]), v[:, 0]


def _positive_definite(T: "_Tangent", fac: "_Factorizer") -> bool:
    """Whether ``T`` is positive definite: its Cholesky factorization succeeds, or (without
    CHOLMOD) every pivot of its symmetric LU without pivoting is positive (Sylvester's law)."""
    if cholmod is not None:
        return fac.cholesky(T) is not None
    try:
        with np.errstate(all="ignore"):
            pivots = _superlu_symmetric(T).U.diagonal()
    except RuntimeError:
        return False
    return bool(np.all(np.isfinite(pivots)) and pivots.min() > 0.0)


def smallest_eigenvalue(system: System, x: np.ndarray, fac: "_Factorizer | None" = None) -> float:
    """Smallest eigenvalue of the constrained Hessian at ``x`` (N/m) (``fac``: as for
    :func:`smallest_eigenpair`)."""
    return smallest_eigenpair(system, x, fac)[0]


def _stability(S: System, x: np.ndarray, free: np.ndarray, fac: _Factorizer | None = None):
    """``(stable, lam, vec)`` at ``x``.  A Cholesky factorization that succeeds certifies that
    the constrained Hessian is positive definite; otherwise its inertia comes from the symmetric
    LU (no pivoting: the pivots are the D of LDLᵀ, Sylvester's law); only when a pivot is
    negative or tiny is the smallest eigenpair computed (shift-invert)."""
    Hff = _tangent(S, x, 1.0, free)
    if fac is not None and fac.cholesky(Hff) is not None:
        return True, float("nan"), None
    tol = 1e-9 * float(np.abs(Hff.diagonal()).mean())
    try:
        with np.errstate(all="ignore"):
            pivots = _superlu_symmetric(Hff).U.diagonal()
        if np.all(np.isfinite(pivots)) and pivots.min() > tol:
            return True, float("nan"), None
    except RuntimeError:  # singular: zero-energy modes, decide from the eigenvalue
        pass
    lam, vec = smallest_eigenpair(S, x, fac)
    return lam >= -tol, lam, vec


def _escape_saddle(S: System, x: np.ndarray, free: np.ndarray, vec: np.ndarray):
    """The point of lowest energy along the unstable eigenvector ``vec`` (both signs, amplitudes
    from 1e-3 to 3 le for the largest particle displacement); None if none is lower."""
    e0 = energy_forces(S, x)[0]
    step = np.zeros(x.size)
    step[free] = vec / np.abs(vec).max()
    step = step.reshape(x.shape)
    best, best_e = None, e0
    for amp in (1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.3, 1.0, 3.0):
        for sign in (1.0, -1.0):
            xt = x + sign * amp * S.scene.body.le * step
            if np.any(cell_volumes(xt, S.lattice.cells) <= 0.0):
                continue
            et = energy_forces(S, xt)[0]
            if et < best_e:
                best, best_e = xt, et
    return best


def _result(system: System, solver: str, x: np.ndarray, f_total: np.ndarray, parts: dict,
            iterations: int, t0: float, converged: bool, info: dict) -> Result:
    vols = _all_cell_volumes(system, x)
    V0 = system.scene.body.volume
    info = dict(info)
    info["inverted_cells"] = int(np.count_nonzero(vols <= 0.0))
    return Result(
        solver=solver,
        scene_digest=system.scene.digest(),
        X=system.X.copy(),
        u=x - system.X,
        volume=float(vols.sum()),
        volume0=float(V0),
        reactions=plate_reactions(system, x, f_total),
        energy={k: float(v) for k, v in parts.items()},
        iterations=int(iterations),
        wall_time_s=time.perf_counter() - t0,
        converged=converged,
        cell_volumes=vols,
        info=info,
    )


# --------------------------------------------------------------------------------- static
FOLD_MARGIN = 0.1
"""A predicted state lies beyond a limit point when its smallest eigenvalue is below
``−FOLD_MARGIN`` times that of the stable equilibrium it was predicted from: past a fold it is of
the order of minus that one (−0.4 to −8 N/m against 1.6–2.4 N/m on the ν = 0 beams of 4×4×24), while
round-off and slightly soft modes stay above.  It only steers the bisection: a bifurcation
(hybmss-fd at ν = 0.2 in tension dips to −0.35 against 0.32 N/m on a path that goes on) is told
apart by the ordinary Newton at the end of the bracket."""


def _not_definite(Hff, shift: float, fac: _Factorizer) -> bool:
    """Whether ``Hff + shift·I`` is not positive definite (a failed Cholesky; without cvxopt, an
    LDLᵀ pivot ≤ 0)."""
    A = Hff.shifted(shift) if shift != 0.0 else Hff
    if cholmod is not None:
        return fac.cholesky(A) is None
    try:
        with np.errstate(all="ignore"):
            pivots = _superlu_symmetric(A).U.diagonal()
    except RuntimeError:  # exactly singular
        return True
    return not (np.all(np.isfinite(pivots)) and pivots.min() > 0.0)


def _fold_suspected(S: System, guess: np.ndarray, free: np.ndarray, fac: _Factorizer, load: float,
                    lam_x) -> tuple[bool, "_CholeskyFactor | None"]:
    """Whether a predicted state ``guess`` of a κ < 0 body lies beyond a limit point: it dilates
    the body and the smallest eigenvalue of its constrained Hessian is below ``−FOLD_MARGIN ·
    lam_x()`` (``lam_x``: the smallest eigenvalue at the equilibrium predicted from, computed only
    when the Hessian at ``guess`` is not positive definite; no fold is suspected unless it is > 0).
    ``fac`` is a factorizer of its own, so the factor the predictor hands to Newton stays valid.
    Returns ``(suspected, F)``: ``F`` the Cholesky factor of the Hessian at ``guess`` when it is
    positive definite (Newton's first step from ``guess`` is then an exact one at no cost; valid
    until ``fac`` factorizes again), else None."""
    vols = cell_volumes(guess, S.lattice.cells)
    if np.any(vols <= 0.0) or not float(vols.sum()) > float(S.lattice.cell_volumes(S.X).sum()):
        return False, None
    Hff = _tangent(S, guess, load, free)
    if cholmod is not None:
        F = fac.cholesky(Hff)
        if F is not None:
            return False, F
    elif not _not_definite(Hff, 0.0, fac):
        return False, None
    lam = lam_x()
    return bool(lam > 0.0 and _not_definite(Hff, FOLD_MARGIN * lam, fac)), None


def _failure_message(S: System, scene: Scene, x: np.ndarray, guess: np.ndarray, s: float, s_new: float,
                     lam: float | None = None, fac: "_Factorizer | None" = None) -> str:
    """Why the load could not be increased past ``s``: the smallest eigenvalue of the
    constrained Hessian at the last equilibrium (``lam`` when already known) and at the
    predicted state just beyond it."""
    if lam is None:
        lam = smallest_eigenvalue(S, x, fac)
    lam_next = smallest_eigenvalue(S, guess, fac)
    head = (f"static solve of scene {scene.name or '(unnamed)'} failed at load factor s={s_new:.6g} "
            f"(last converged s={s:.6g}); smallest eigenvalue of the constrained Hessian: {lam:.4g} N/m at "
            f"s={s:.6g}, {lam_next:.4g} N/m at the predicted state s={s_new:.6g}")
    if s == 0.0 and lam < 0:
        return head + ("; the model is not positive definite even at rest (its effective bulk or shear "
                       "modulus is negative for these constants): no stable equilibrium exists")
    dilating = float(cell_volumes(x, S.lattice.cells).sum()) > float(S.lattice.cell_volumes(S.X).sum())
    if S.kappa < 0 and dilating:
        evidence = ("the Hessian becomes indefinite" if min(lam, lam_next) < 0 else
                    "Newton no longer converges from the tangent predictor, as at a fold")
        return head + (f"; {evidence}: the volume term has kappa={S.kappa:.4g} Pa < 0 (nu < 1/4) and is "
                       "unbounded below under dilation, so the equilibrium is lost at a limit point "
                       "(instability), not a numerical failure")
    if min(lam, lam_next) < 0:
        return head + "; the Hessian becomes indefinite: the equilibrium path is unstable (buckling or zero-energy modes)"
    return head + "; the Hessian stays positive definite: Newton failed to converge (try more load steps)"


def _residual_failure_message(S: System, scene: Scene, s: float, s_new: float, rnorm: float) -> str:
    """Why a residual-mode solve could not increase the load past ``s``."""
    return (f"static solve of scene {scene.name or '(unnamed)'} (model {scene.model.name}) failed at load "
            f"factor s={s_new:.6g} (last converged s={s:.6g}); residual {rnorm:.3g} N: its non-conservative "
            "forces have no energy to certify a stable state, so the equilibrium path may be lost; "
            "remedy: a smaller load (or more initial load steps)")


def solve_static(scene: Scene, options: StaticOptions | None = None, system: System | None = None) -> Result:
    """Static equilibrium of ``scene`` (solver name ``mss-static``).

    Load steps with a tangent predictor and Newton (:func:`_newton`) in energy mode when every
    force is conservative, in residual mode when the system has non-conservative terms
    (``baudet2009``).  Energy mode then certifies stability from the inertia of the constrained
    Hessian and leaves saddles; residual mode returns the equilibrium without that certificate."""
    model = scene.model.spec
    if "static" not in model.solvers:
        raise ValueError(f"model {model.name} has no static solver (its solvers: {', '.join(model.solvers)})")
    if model.solve_static is not None:  # a model with its own static solver (hybmss.models.base)
        return model.solve_static(scene, options, system)
    opts = options or StaticOptions()
    t0 = time.perf_counter()
    check_nu(scene.material.nu)
    S = system if system is not None else build(scene)
    residual = not S.conservative
    free = ~S.fixed.ravel()
    stats = _NewtonStats()
    fac = _Factorizer()
    x = S.X.copy()
    s, ds = 0.0, min(opts.max_step, 1.0 / max(1, opts.initial_steps))
    x_prev, s_prev = None, None
    load_steps = 0
    failed_before = False
    # a bracketed limit point (module docstring): no equilibrium found at s_hi > s, bisected until
    # s_hi − s <= s_tol
    fold_check = not residual and S.kappa < 0 and opts.limit_resolution is not None
    fold_fac = _Factorizer()
    # the predictor's own factorizer: its factor at the last equilibrium stays valid while Newton
    # factorizes, so another step from that equilibrium reuses it (pred_cache)
    pred_fac, pred_cache = _Factorizer(), {}
    lam_at = {}  # smallest eigenvalue at the equilibrium of a load factor, computed once when needed

    def lam_x():
        """Smallest eigenvalue at the current equilibrium if it is stable (its Hessian factorizes
        by Cholesky: shift-invert alone can miss a negative eigenvalue far below the shift), else 0."""
        if s not in lam_at:
            Hx = _tangent(S, x, s, free)
            # the predictor's Cholesky at x, when it succeeded, already proved it positive definite
            definite = pred_cache.get("x") is x and isinstance(pred_cache.get("lu"), _CholeskyFactor)
            lam_at[s] = smallest_eigenvalue(S, x, fold_fac) if definite or not _not_definite(Hx, 0.0, fold_fac) else 0.0
        return lam_at[s]

    s_hi, s_tol = None, 0.0
    tried = None  # (s_hi, x, guess) of a failed Newton inside a bracket that made limit_iter steps
    while s < 1.0 - 1e-14:
        if s_hi is not None and s_hi - s <= s_tol:
            # the bracket is narrow: the ordinary Newton at its upper end decides.  Failing, the
            # limit point is reported; converging (a bifurcation the path passes, not a fold), the
            # load stepping goes on without the bracketing.  A Newton from this equilibrium to
            # s_hi that already made limit_iter steps without converging has decided it
            if tried is not None and tried[0] == s_hi and tried[1] is x:
                raise StaticSolveError(_failure_message(S, scene, x, tried[2], s, s_hi, lam_at.get(s) or None, fold_fac))
            target = S.prescribed(s_hi)
            guess, lu = _tangent_predictor(S, x, target, free, s_hi, pred_fac, pred_cache)
            if guess is None or np.any(cell_volumes(guess, S.lattice.cells) <= 0.0):
                guess, lu = x.copy(), None
            guess[S.fixed] = target[S.fixed]
            ok, x_new, f, rnorm, scale = _newton(S, guess, free, opts.rtol, opts.limit_iter, None, stats,
                                                 opts.line_search, lu=lu, load=s_hi, fac=fac)
            if not ok:
                raise StaticSolveError(_failure_message(S, scene, x, guess, s, s_hi, lam_at.get(s) or None, fold_fac))
            load_steps += 1
            x_prev, s_prev, x, s = x, s, x_new, s_hi
            ds, s_hi, fold_check = 2.0 * s_tol, None, False
            continue
        s_new = 0.5 * (s + s_hi) if s_hi is not None else min(1.0, s + ds)
        target = S.prescribed(s_new)
        # a step that changes nothing (a zero load: no plate motion, no body load) is already in
        # equilibrium: the rest state is the answer, exactly
        trial = x.copy()
        trial[S.fixed] = target[S.fixed]
        if _newton(S, trial, free, opts.rtol, 0, None, stats, load=s_new, fac=fac)[0]:
            x_prev, s_prev, x, s = x, s, trial, s_new
            load_steps += 1
            ds = min(opts.max_step, ds * 1.5)
            continue
        guess, lu = _tangent_predictor(S, x, target, free, s_new, pred_fac, pred_cache)
        if guess is None or np.any(cell_volumes(guess, S.lattice.cells) <= 0.0):
            guess, lu = x.copy(), None
            if x_prev is not None:  # linear extrapolation of the free dofs from the last increment
                guess += (x - x_prev) * ((s_new - s) / (s - s_prev))
        guess[S.fixed] = target[S.fixed]
        if fold_check:
            suspected, F_guess = _fold_suspected(S, guess, free, fold_fac, s_new, lam_x)
            if suspected:
                # beyond a limit point as it stands: bracket it (or narrow the bracket) without Newton
                if s_hi is None:
                    s_tol = opts.limit_resolution * (s_new - s)
                s_hi = s_new
                continue
            if F_guess is not None:
                lu = F_guess
        # inside a bracket, Newton gives up when its iterates stay out of the stable region
        iters = opts.max_iter if not (failed_before or s_hi is not None) else opts.retry_iter
        it0 = stats.iterations
        ok, x_new, f, rnorm, scale = _newton(S, guess, free, opts.rtol, iters, None, stats,
                                             opts.line_search, lu=lu, load=s_new, fac=fac,
                                             definite_after=3 if s_hi is not None else None)
        failed_before = not ok
        if ok:
            load_steps += 1
            x_prev, s_prev, x, s = x, s, x_new, s_new
            if s_hi is None:
                ds = min(opts.max_step, ds * 1.5)
            continue
        if s_hi is not None:
            s_hi = s_new
            tried = (s_new, x, guess) if stats.iterations - it0 >= opts.limit_iter else None
            continue
        ds *= 0.5
        if ds < opts.min_step:
            raise StaticSolveError(_residual_failure_message(S, scene, s, s_new, rnorm) if residual
                                   else _failure_message(S, scene, x, guess, s, s_new, lam_at.get(s) or None, fold_fac))
    # Stability of the equilibrium found: Newton converges to any stationary point, so check the
    # smallest eigenvalue of the constrained Hessian and, at a saddle (e.g. the buckled zero-energy
    # modes of hybmss-fd under compression), descend along the unstable mode and solve again.
    # Residual mode has no such certificate (no energy, nonsymmetric Jacobian): its result is an
    # equilibrium with no inverted cell, and info['stability'] says that stability is not checked.
    escapes, lam, stable, warning = 0, None, True, ""
    if opts.check_stability and not residual:
        for escapes in range(opts.max_escapes + 1):
            stable, lam, vec = _stability(S, x, free, fac)
            if stable or escapes == opts.max_escapes:
                break
            xt = _escape_saddle(S, x, free, vec)
            if xt is None:
                break
            ok, x_new, f, rnorm, scale = _newton(S, xt, free, opts.rtol, 5 * opts.max_iter, None, stats,
                                                 opts.line_search, fac=fac)
            if not ok:
                warning = (f"the equilibrium found is a saddle (smallest eigenvalue {lam:.4g} N/m: buckling or "
                           "zero-energy modes); descending along the unstable mode did not reach another "
                           "equilibrium, so the symmetric stationary state is returned")
                break
            x = x_new
    e, f, parts = energy_forces(S, x)
    r = _norm(f.ravel()[free])
    if residual:
        info = {
            "equilibrium": "force-residual Newton (non-conservative terms, no energy)",
            "stability": "not certified: no energy to minimize and a nonsymmetric Jacobian",
        }
    else:
        info = {
            "min_eigenvalue": lam if lam is not None else float("nan"),
            "saddle_escapes": int(escapes) if lam is not None else 0,
            "stable": bool(stable),
            "warning": warning,
        }
    info.update({
        "load_steps": load_steps,
        "regularized_steps": stats.regularized,
        "line_search_cuts": stats.line_search_cuts,
        "residual": r,
        "relative_residual": r / _force_scale(S, f),
        "residual_floor": _force_floor(S),
        "kappa": S.kappa,
        "springs": int(len(S.spring_k)),
        "volume_cells": int(len(S.vol_cells)),
    })
    return _result(S, "mss-static", x, f, parts, stats.iterations, t0, True, info)


# --------------------------------------------------------------------------------- implicit
def _implicit_failure_message(S: System, n: int, t: float, dt: float, rnorm: float, scale: float) -> str:
    """Why Newton failed in step ``n``: a residual already small against the step's forces
    stalled at round-off (the inertia term M/dt² dwarfs the elastic forces: a larger dt helps); a
    large one is a step too big for Newton or a lost equilibrium (a smaller dt helps if not κ < 0)."""
    head = (f"implicit Euler step {n} (t={t:.4g} s) did not converge: residual {rnorm:.3g} N vs "
            f"scale {scale:.3g} N")
    if np.isfinite(rnorm) and rnorm <= 1e-3 * scale:
        return head + (f"; Newton stalled at round-off of the inertia term M/dt^2: increase dt={dt:g} s "
                       "(or use solve_static for the rest state)")
    if S.kappa < 0:
        return head + (f"; kappa={S.kappa:.4g} Pa < 0 (nu < 1/4): the equilibrium may be lost (check with "
                       f"solve_static); otherwise reduce dt={dt:g} s")
    return head + f"; the step is too large for Newton: reduce dt={dt:g} s"


def simulate_implicit(scene: Scene, options: ImplicitOptions | None = None,
                      system: System | None = None) -> Result:
    """Backward Euler with Newton per step (solver name ``mss-implicit``).

    The plates follow :func:`smooth_ramp` over ``ramp_time``.  With ``until_rest`` the run stops
    once the ramp is over and every particle moves less than ``rest_tol · le`` in one step."""
    opts = options or ImplicitOptions()
    t0 = time.perf_counter()
    check_nu(scene.material.nu)
    S = system if system is not None else build(scene)
    if not S.conservative:
        raise StaticSolveError(
            f"implicit Euler minimizes an incremental potential and model {scene.model.name!r} has "
            "non-conservative forces (no energy): use simulate_explicit(kernel='numpy') or solve_static"
        )
    free = ~S.fixed.ravel()
    dt, c = opts.dt, scene.damping
    w = S.mass * (1.0 + c * dt) / dt**2
    if np.any(w[~S.fixed.all(axis=1)] <= 0):
        raise ValueError("implicit Euler needs a positive mass on every free particle (rho > 0)")
    x, v = S.X.copy(), np.zeros_like(S.X)
    stats = _NewtonStats()
    fac = _Factorizer()
    le = scene.body.le
    steps_done = 0
    for n in range(1, opts.steps + 1):
        t = n * dt
        target = S.prescribed(smooth_ramp(t, opts.ramp_time))
        x_tilde = x + dt * v / (1.0 + c * dt)
        guess = x_tilde.copy()
        guess[S.fixed] = target[S.fixed]
        ok, x_new, _, rnorm, scale = _newton(S, guess, free, opts.rtol, opts.max_iter, (w, x_tilde), stats,
                                             fac=fac)
        if not ok:
            raise StaticSolveError(_implicit_failure_message(S, n, t, dt, rnorm, scale))
        v = (x_new - x) / dt
        x = x_new
        steps_done = n
        if opts.until_rest and t >= opts.ramp_time and float(np.abs(v).max()) * dt < opts.rest_tol * le:
            break
    e, f, parts = energy_forces(S, x)
    parts = dict(parts)
    parts["kinetic"] = 0.5 * float(np.sum(S.mass[:, None] * v * v))
    info = {"steps": steps_done, "dt": dt, "time": steps_done * dt, "newton_iterations": stats.iterations,
            "regularized_steps": stats.regularized}
    return _result(S, "mss-implicit", x, f, parts, steps_done, t0, True, info)
