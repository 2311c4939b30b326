"""CHOLMOD's supernodal Cholesky (through cvxopt) for the FEM's SPD systems.

- a Dirichlet-constrained SPD system solved by CHOLMOD satisfies its equations to round-off and
  equals SuperLU's solution, in the nested-dissection order and in CHOLMOD's own;
- a second matrix of the same pattern reuses the symbolic analysis and is solved right; another
  pattern or other prescribed dofs get a new analysis;
- a matrix that is not positive definite falls back to SuperLU's LU;
- a matrix close to the last factorized one (same pattern) is solved by CG preconditioned with that
  factor; a far one is factorized again;
- a Hex2 Newton solve on CHOLMOD (chord steps on its factor) reaches the equilibrium of the
  AMG-preconditioned CG path to 1e-8;
- the mixed u–p saddle point solved by eliminating the pressure (CG on the Schur complement with
  CHOLMOD's factor of the displacement block) equals SuperLU's factorization of the whole system:
  to 1e-10 for a linear solve, to 1e-8 at the end of a finite-strain Newton solve.
"""

import numpy as np
import pytest
import scipy.sparse as sp

from fem_reference import linalg
from fem_reference.dirichlet import plate_dirichlet
from fem_reference.hyperelastic import Hyperelasticity
from fem_reference.linalg import SolveStats, rigid_modes, solve_spd
from fem_reference.mesh import build_mesh
from hybmss.scene import Body, Material, Motion, Plate, Region, Scene

pytestmark = pytest.mark.skipif(linalg.cholmod is None, reason="cvxopt (CHOLMOD) is not installed")


def _laplacian(n):
    """7-point Laplacian on an n³ grid plus a small shift: SPD, the pattern of a 3D mesh."""
    T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    I = sp.eye(n)
    return (sp.kron(sp.kron(T, I), I) + sp.kron(sp.kron(I, T), I) + sp.kron(sp.kron(I, I), T)
            + 0.01 * sp.eye(n**3)).tocsr()


def _constrained_reference(K, f, D, uD):
    """u with u[D] = uD and (K u − f)[free] = 0, by SuperLU on the reduced system."""
    free = np.ones(K.shape[0], bool)
    free[D] = False
    u = np.zeros(K.shape[0])
    u[D] = uD
    Kff = sp.csc_matrix(K[free][:, free])
    u[free] = sp.linalg.spsolve(Kff, f[free] - K[free][:, D] @ uD)
    return u


@pytest.mark.parametrize("ordered", [True, False])
def test_cholmod_solves_the_constrained_system(ordered):
    rng = np.random.default_rng(5)
    K = _laplacian(6)
    n = K.shape[0]
    f = rng.standard_normal(n)
    D = np.arange(0, n, 7)
    uD = rng.standard_normal(len(D))
    order = rng.permutation(n) if ordered else None
    stats = SolveStats()
    u = solve_spd(K, f, D, uD, np.zeros((n, 6)), method="direct", stats=stats, order=order)
    assert stats.method == "cholmod"
    free = np.ones(n, bool)
    free[D] = False
    assert np.array_equal(u[D], uD)
    assert np.abs((K @ u - f)[free]).max() <= 1e-12 * np.abs(f).max() * 10
    ref = _constrained_reference(K, f, D, uD)
    assert np.abs(u - ref).max() <= 1e-12 * np.abs(ref).max()


def test_symbolic_analysis_is_reused_for_the_same_pattern_only():
    rng = np.random.default_rng(6)
    K1 = _laplacian(5)
    n = K1.shape[0]
    K2 = K1.copy()
    K2.data = K2.data * (1.0 + 0.5 * rng.random(K2.nnz))
    K2 = ((K2 + K2.T) * 0.5).tocsr()  # same pattern, other values
    K2.sort_indices()
    K1.sort_indices()
    assert np.array_equal(K1.indices, K2.indices)
    f = rng.standard_normal(n)
    D = np.arange(10)
    uD = np.ones(10)
    cache = {}
    solve_spd(K1, f, D, uD, np.zeros((n, 6)), method="direct", cache=cache)
    analysis = cache["cholmod"]
    u2 = solve_spd(K2, f, D, uD, np.zeros((n, 6)), method="direct", cache=cache)
    assert cache["cholmod"] is analysis  # the same analysis
    ref2 = _constrained_reference(K2, f, D, uD)
    assert np.abs(u2 - ref2).max() <= 1e-12 * np.abs(ref2).max()
    free = np.ones(n, bool)
    free[D] = False
    # the factor left in the cache solves free-dof systems of the last matrix (chord steps)
    b = rng.standard_normal(int(free.sum()))
    assert np.allclose(K2[free][:, free] @ cache["lu"].solve(b), b, rtol=0, atol=1e-11 * np.abs(b).max())
    D3 = np.arange(12)  # other prescribed dofs: a new analysis
    u3 = solve_spd(K2, f, D3, np.ones(12), np.zeros((n, 6)), method="direct", cache=cache)
    assert cache["cholmod"] is not analysis
    ref3 = _constrained_reference(K2, f, D3, np.ones(12))
    assert np.abs(u3 - ref3).max() <= 1e-12 * np.abs(ref3).max()


def test_indefinite_matrix_falls_back_to_superlu():
    rng = np.random.default_rng(7)
    K = _laplacian(4) - 2.0 * sp.eye(64)  # the shifted Laplacian's eigenvalues span [1.16, 10.9]: indefinite
    K = K.tocsr()
    f = rng.standard_normal(64)
    D = np.array([0, 5])
    stats = SolveStats()
    u = solve_spd(K, f, D, np.zeros(2), np.zeros((64, 6)), method="direct", stats=stats)
    assert stats.method == "direct"
    ref = _constrained_reference(K, f, D, np.zeros(2))
    assert np.abs(u - ref).max() <= 1e-10 * np.abs(ref).max()


def test_hex2_newton_on_cholmod_matches_amg():
    body = Body.box(2, 2, 3, 0.1)
    sc = Scene(body, Material(1e4, 0.3, 1000.0),
               plates=(Plate("bottom", Region("z-")), Plate("top", Region("z+"), Motion("translate", (0.06, 0.0, -0.06)))))
    hy = Hyperelasticity(build_mesh(body, 1), "hex2", "neo-hookean")
    d = plate_dirichlet(sc, hy.space)
    direct, log_d = hy.solve(sc.material, d, method="direct")
    amg, _ = hy.solve(sc.material, d, method="amg")
    assert direct.stats.method.startswith("cholmod") and amg.stats.method == "amg"
    assert np.abs(direct.U - amg.U).max() <= 1e-8 * np.abs(amg.U).max()
    assert np.abs(direct.r[d.dofs] - amg.r[d.dofs]).max() <= 1e-8 * np.abs(amg.r[d.dofs]).max()
    assert rigid_modes(hy.space.points).shape[1] == 6


def test_separator_size_picks_cholmod_for_slender_and_small_bodies():
    from fem_reference.space import Space

    space = Space.create(build_mesh(Body.box(3, 2, 5, 0.5), 1), "hex1")
    # the first cut is across z (5 cells) at 2 cells: a plane of 4 × 3 vertices, 3 dofs each
    assert linalg.separator_dofs(space.points, 0.5) == 36
    hex2 = Space.create(build_mesh(Body.box(3, 2, 5, 0.5), 1), "hex2")
    assert linalg.separator_dofs(hex2.points, 0.5) == 3 * 7 * 5
    assert linalg.separator_dofs(space.points + 0.01 * np.sin(space.points), 0.5) is None  # not a grid
    assert linalg._choose_spd("auto", 10**6, 1_000) == "direct"
    assert linalg._choose_spd("auto", 10**6, 3_000) == "amg"  # a thick body: AMG-CG
    assert linalg._choose_spd("auto", 5 * 10**6, None) == "amg"  # no order known: the SuperLU limit
    assert linalg._choose_spd("amg", 10, 10) == "amg" and linalg._choose_spd("direct", 10**9, 10**6) == "direct"


def test_mixed_schur_elimination_matches_the_factorized_saddle_point():
    from fem_reference.linear import LinearElasticity

    body = Body.box(2, 2, 3, 0.1)
    sc = Scene(body, Material(1e4, 0.499, 1000.0),
               plates=(Plate("bottom", Region("z-")), Plate("top", Region("z+"), Motion("translate", (0.02, 0.0, -0.06)))))
    fm = build_mesh(body, 1)
    le = LinearElasticity(fm, "mixed")
    d = plate_dirichlet(sc, le.space)
    a = le.solve(sc.material, d, method="auto")
    b = le.solve(sc.material, d, method="direct")
    assert a.stats.method == "cholmod-schur" and b.stats.method == "direct"
    assert np.abs(a.U - b.U).max() <= 1e-10 * np.abs(b.U).max()
    assert np.abs(a.p - b.p).max() <= 1e-10 * np.abs(b.p).max()
    assert np.abs(a.r[d.dofs] - b.r[d.dofs]).max() <= 1e-10 * np.abs(b.r[d.dofs]).max()
    hy = Hyperelasticity(fm, "mixed", "neo-hookean")
    sa, _ = hy.solve(sc.material, d, method="auto")
    sb, _ = hy.solve(sc.material, d, method="direct")
    assert sa.stats.method == "cholmod-schur" and sb.stats.method == "direct"
    assert np.abs(sa.U - sb.U).max() <= 1e-8 * np.abs(sb.U).max()
    assert np.abs(sa.p - sb.p).max() <= 1e-8 * np.abs(sb.p).max()


def test_a_close_matrix_is_solved_by_cg_on_the_last_factor_a_far_one_refactorized():
    rng = np.random.default_rng(8)
    K1 = _laplacian(5)
    K1.sort_indices()
    n = K1.shape[0]
    f = rng.standard_normal(n)
    D = np.arange(10)
    uD = np.ones(10)
    cache = {}
    stats = SolveStats()
    solve_spd(K1, f, D, uD, np.zeros((n, 6)), method="direct", cache=cache, stats=stats)
    assert stats.method == "cholmod"
    near = K1.copy()
    near.data = K1.data * (1.0 + 0.01 * rng.random(K1.nnz))
    near = ((near + near.T) * 0.5).tocsr()
    near.sort_indices()
    for K, expected in ((near, "cholmod-pcg"), (K1 * 0.2 + 2.0 * sp.eye(n, format="csr"), "cholmod")):
        K = sp.csr_matrix(K)
        K.sort_indices()
        assert np.array_equal(K.indices, K1.indices)  # the pattern of K1: the same analysis
        st = SolveStats()
        u = solve_spd(K, f, D, uD, np.zeros((n, 6)), method="direct", rtol=1e-12, cache=cache, stats=st)
        assert st.method == expected
        ref = _constrained_reference(K, f, D, uD)
        assert np.abs(u - ref).max() <= 1e-9 * np.abs(ref).max()
