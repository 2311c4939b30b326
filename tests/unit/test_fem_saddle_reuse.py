"""Modified Newton of the mixed element: a Newton iteration whose displacement block has the
pattern of the last CHOLMOD factor solves its saddle point by flexible GMRES preconditioned with
the last Schur-complement solver (an earlier tangent's exact inverse), and factorizes afresh only
when that does not converge.

Checks, each against something computed apart from the code it guards:
- flexible GMRES (``fem_reference.krylov.fgmres``) on a random non-symmetric system: the residual
  ``‖b − A x‖`` recomputed from ``A`` meets the tolerance, with a preconditioner that changes
  from one application to the next, and it gives up (``None``) when the iterations allowed cannot
  reach the tolerance;
- one saddle-point solve with the factor of another tangent: the residual of the whole system
  ``[[A, Bᵀ], [B, −C]]`` assembled here meets the weighted tolerance of the fast path, and the
  solution is SuperLU's of the same matrix to that tolerance times the system's condition number;
- Newton on the 30° twist of a 2×2×2 block at ν = 0.49 (the Schur path forced by lowering the
  saddle point's direct limit): with reuse on, solves do reuse the factor, and the displacement,
  pressure and plate reactions are those of Newton without reuse to ``1e-8`` relative (both stop at
  ``‖R‖ ≤ 1e-10 ‖f‖``; their difference is ``K⁻¹ δR``, the condition number times ``2e-10`` at
  most, as in ``test_fem_large_saddle.py``).
"""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fem_reference import linalg
from fem_reference.dirichlet import plate_dirichlet
from fem_reference.hyperelastic import Hyperelasticity
from fem_reference.krylov import fgmres
from fem_reference.mesh import build_mesh
from hybmss.scene import Body, Material, Motion, Plate, Region, Scene

needs_cholmod = pytest.mark.skipif(linalg.cholmod is None, reason="cvxopt (CHOLMOD) is not installed")


def _system(n=60, seed=3):
    rng = np.random.default_rng(seed)
    A = np.eye(n) * 4 + rng.standard_normal((n, n)) / np.sqrt(n)
    return A, rng.standard_normal(n)


def test_fgmres_meets_its_tolerance_with_a_changing_preconditioner():
    A, b = _system()
    Ainv = np.linalg.inv(A)
    rng = np.random.default_rng(7)

    def precond(r):  # an approximate inverse that differs at every application
        E = 0.05 * rng.standard_normal(A.shape) / np.sqrt(len(b))
        return (Ainv + E) @ r

    x, its = fgmres(lambda v: A @ v, precond, b, 1e-10, 20)
    assert x is not None and its <= 20
    assert np.linalg.norm(b - A @ x) <= 1e-10 * np.linalg.norm(b)
    assert np.allclose(x, np.linalg.solve(A, b), rtol=0, atol=1e-8 * np.abs(np.linalg.solve(A, b)).max())


def test_fgmres_gives_up_when_its_iterations_cannot_reach_the_tolerance():
    A, b = _system()
    x, its = fgmres(lambda v: A @ v, lambda r: r, b, 1e-12, 3)  # no preconditioner, 3 iterations
    assert x is None and its <= 3
    x, its = fgmres(lambda v: A @ v, lambda r: r, b, 1e-12, 200)  # enough of them
    assert x is not None and np.linalg.norm(b - A @ x) <= 1e-12 * np.linalg.norm(b)


def _twist(nu: float) -> Scene:
    motion = Motion("rotate", angle=np.radians(30.0), axis=(0.0, 0.0, 1.0), center=(0.5, 0.5, 1.0))
    return Scene(Body.box(2, 2, 2, 0.5), Material(1e4, nu, 1000.0),
                 plates=(Plate("bottom", Region("z-")), Plate("top", Region("z+"), motion)))


def _tangent(ops, U, p, mat, s=1.0):
    st = ops._evaluate(U, p, s, np.zeros(ops.space.n_vector), mat, tangent=True)
    return st["K"], st["B"]


@needs_cholmod
def test_saddle_solve_with_an_earlier_factor_meets_the_residual_of_the_whole_system():
    sc = _twist(0.49)
    mat = sc.material
    ops = Hyperelasticity(build_mesh(sc.body, 1), "mixed", "neo-hookean")
    d = plate_dirichlet(sc, ops.space)
    C = ops.pressure_mass / mat.lam
    rng = np.random.default_rng(1)
    n, m = ops.space.n_vector, ops.pspace.n_scalar
    A0, B0 = _tangent(ops, np.zeros(n), np.zeros(m), mat)
    U1 = 1e-3 * rng.standard_normal(n)  # a nearby state: another tangent of the same pattern
    A1, B1 = _tangent(ops, U1, 5.0 * rng.standard_normal(m), mat)
    f, g = rng.standard_normal(n), 1e-6 * rng.standard_normal(m)
    D, uD = d.dofs, np.zeros(len(d.dofs))
    kw = dict(schur_scale=1.0 / mat.G + 1.0 / mat.lam, order=ops.order, separator=ops.separator)
    cache, stats = {}, linalg.SolveStats()
    linalg.solve_saddle(A0, B0, C, f, g, D, uD, ops.nullspace, cache=cache, stats=stats, **kw)
    rtol = 1e-9
    u, p = linalg.solve_saddle(A1, B1, C, f, g, D, uD, ops.nullspace, cache=cache, stats=stats,
                               schur_rtol=rtol, **kw)
    assert stats.reused == 1 and stats.calls == 2
    free = np.ones(n, bool)
    free[D] = False
    A1f, B1f = sp.csr_matrix(A1)[free][:, free], sp.csr_matrix(B1)[:, free]
    S = sp.bmat([[A1f, B1f.T], [B1f, -C]], format="csc")
    rhs = np.concatenate([f[free], g])
    x = np.concatenate([u[free], p])
    w = np.sqrt(A1f.diagonal().mean() / C.diagonal().mean())
    W = np.concatenate([np.ones(int(free.sum())), np.full(m, w)])
    assert np.linalg.norm(W * (rhs - S @ x)) <= rtol * np.linalg.norm(W * rhs)
    exact = spla.spsolve(S, rhs)
    Sw = (sp.diags(W) @ S).toarray()
    cond = np.linalg.cond(Sw)
    assert np.linalg.norm(W * (x - exact)) <= 2 * cond * rtol * np.linalg.norm(W * exact)


@needs_cholmod
def test_newton_with_the_reused_factor_reaches_the_same_equilibrium(monkeypatch):
    sc = _twist(0.49)
    ops = Hyperelasticity(build_mesh(sc.body, 1), "mixed", "neo-hookean")
    d = plate_dirichlet(sc, ops.space)
    monkeypatch.setattr(linalg, "DIRECT_MAX_NNZ_SADDLE", 1)  # the large meshes' Schur path
    monkeypatch.setattr(linalg, "REUSE_MAXITER_SADDLE", 0)
    fresh, log_f = ops.solve(sc.material, d, rtol=1e-10)
    monkeypatch.setattr(linalg, "REUSE_MAXITER_SADDLE", 6)
    reused, log_r = ops.solve(sc.material, d, rtol=1e-10)
    assert log_f.converged and log_r.converged
    assert fresh.stats.reused == 0 and reused.stats.reused > 0
    assert np.abs(reused.U - fresh.U).max() <= 1e-8 * np.abs(fresh.U).max()
    assert np.abs(reused.p - fresh.p).max() <= 1e-8 * np.abs(fresh.p).max()
    D = d.dofs
    assert np.abs(reused.r[D] - fresh.r[D]).max() <= 1e-8 * np.abs(fresh.r[D]).max()
