"""Sparse linear solves with prescribed (Dirichlet) dofs.

Two kinds of systems occur:

- symmetric positive definite ``K u = f`` (displacement formulations, linear or the
  finite-strain tangent at a stable state);
- symmetric saddle-point systems of the mixed u–p formulation,
  ``[[A, Bᵀ], [B, −C]] [u; p] = [f; g]`` with ``A`` the displacement block and ``C ≥ 0``
  the (scaled) pressure mass matrix.

``method='auto'`` factorizes directly (SuperLU) while the reduced matrix has at most
:data:`DIRECT_MAX_NNZ` non-zeros (about 50k Hex1 dofs; a Hex2 stencil is about 3× denser, so the
crossover comes at fewer dofs: on the 10×10×10 cube, 27k Hex2 dofs, SuperLU took 9–12 s and
AMG-CG 2.3 s), or :data:`DIRECT_MAX_NNZ_SADDLE` for the saddle point, otherwise it iterates: conjugate gradients preconditioned with
smoothed-aggregation algebraic multigrid (pyamg) whose near-null space holds the six rigid-body
modes; MINRES with the block-diagonal preconditioner ``diag(AMG(A), S⁻¹)``,
``S = M_p (1/μ_s + 1/λ)`` (a spectrally equivalent Schur complement) for the saddle point.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

DIRECT_MAX_NNZ = 4_000_000
"""Largest reduced SPD matrix (non-zeros) that ``method='auto'`` factorizes directly."""

DIRECT_MAX_NNZ_SADDLE = 20_000_000
"""Largest saddle-point matrix that ``method='auto'`` factorizes directly.  Higher than for SPD
systems: block-preconditioned MINRES needs hundreds of iterations at ν → ½ (measured: 654
iterations, 241 s, against 14 s for the factorization on the 10×10×10 cube, 29k dofs)."""

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


def _choose(method: str, A: sp.spmatrix, limit: int = DIRECT_MAX_NNZ) -> str:
    if method not in METHODS:
        raise ValueError(f"linear solver must be one of {', '.join(METHODS)}; got {method!r}")
    if method == "auto":
        return "direct" if A.nnz <= limit else "amg"
    return method


def _amg(A: sp.csr_matrix, B: np.ndarray):
    import pyamg

    ml = pyamg.smoothed_aggregation_solver(
        A, B=B, symmetry="hermitian", strength="symmetric", max_coarse=500, coarse_solver="splu"
    )
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
) -> np.ndarray:
    """Solve ``K u = f`` on the free dofs with ``u[D] = uD``; returns the full ``u``.

    ``nullspace`` (n, 6) are the rigid-body modes (used by AMG only).  ``cache`` (a dict kept by
    the caller, e.g. across Newton iterations with the same prescribed dofs) keeps the AMG
    hierarchy of an earlier matrix as the preconditioner; it is rebuilt when CG needs more than
    twice the iterations per decade of residual reduction it needed when built.  A direct solve
    stores its factorization of the free-dof matrix in ``cache["lu"]``.
    """
    n = K.shape[0]
    free = np.ones(n, dtype=bool)
    free[D] = False
    u = np.zeros(n)
    u[D] = uD
    K = sp.csr_matrix(K)
    A = K[free][:, free].tocsr()
    b = f[free] - K[free][:, D] @ uD
    kind = _choose(method, A)
    if kind == "direct":
        lu = spla.splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options=dict(SymmetricMode=True))
        x = lu.solve(b)
        its = 1
        if cache is not None:
            cache["lu"] = lu
    else:
        reuse = cache is not None and cache.get("n") == A.shape[0] and "M" in cache
        M = cache["M"] if reuse else _amg(A, np.ascontiguousarray(nullspace[free]))
        count = [0]
        x, info = spla.cg(A, b, M=M, rtol=rtol, atol=0.0, maxiter=5000,
                          callback=lambda xk: count.__setitem__(0, count[0] + 1))
        if info != 0 and reuse:  # a stale preconditioner: rebuild and retry once
            cache.clear()
            return solve_spd(K, f, D, uD, nullspace, method, rtol, stats, cache)
        if info != 0:
            raise RuntimeError(f"AMG-preconditioned CG did not converge ({count[0]} iterations)")
        its = count[0]
        if cache is not None:
            rate = max(its, 1) / max(1.0, -np.log10(rtol))  # iterations per decade
            if not reuse:
                cache.update(n=A.shape[0], M=M, rate0=rate)
            elif rate > 2 * cache["rate0"]:
                cache.clear()
    if stats is not None:
        stats.add(kind, its)
    u[free] = x
    return u


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
) -> tuple[np.ndarray, np.ndarray]:
    """Solve ``[[A, Bᵀ], [B, −C]] [u; p] = [f; g]`` with ``u[D] = uD``; returns ``(u, p)``.

    ``schur_scale`` multiplies the pressure mass matrix in the preconditioner:
    ``S ≈ schur_scale · C_mass`` (use ``1/μ + 1/λ`` with ``C = M_p/λ``).  ``cache``: a dict
    that receives the factorization (``cache["lu"]``, of the system on the free dofs and the
    pressure) when the solve is direct.
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
    S = sp.bmat([[Aff, Bf.T], [Bf, -C]], format="csr")
    rhs = np.concatenate([bu, bp])
    kind = _choose(method, S, DIRECT_MAX_NNZ_SADDLE)
    if kind == "direct":
        # [[A, Bᵀ], [B, −C]] with A, C positive definite is symmetric quasi-definite: an LDLᵀ
        # factorization exists for every symmetric ordering, so no pivoting is needed.
        lu = spla.splu(S.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options=dict(SymmetricMode=True))
        x = lu.solve(rhs)
        its = 1
        if cache is not None:
            cache["lu"] = lu  # the caller may reuse the factorization (chord steps)
    else:
        Ma = _amg(Aff.tocsr(), np.ascontiguousarray(nullspace[free]))
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
        its = count[0]
    if stats is not None:
        stats.add(kind if kind == "direct" else "amg-minres", its)
    u[free] = x[: int(free.sum())]
    return u, x[int(free.sum()):]
