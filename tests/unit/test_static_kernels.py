"""The Numba twins of the static solver's energies, forces and Hessian against the NumPy
reference (hybmss.forces, kernel='numpy', itself checked against finite differences in
test_forces.py), and the fixed-pattern constrained Hessian against slicing the full one."""

import numpy as np
import pytest

from hybmss.experiments import SceneSpec
from hybmss.forces import cell_volumes, energy_forces, hessian, stiffness
from hybmss.solve.linalg import Factorizer, cholmod, grid_dissection, superlu_symmetric, tangent
from hybmss.system import build


@pytest.mark.parametrize("model,nu,form", [("hybmss", 0.499, "quadratic"), ("hybmss", 0.1, "squared"),
                                           ("hybmss-fd", 0.25, None), ("hybmss-cf", 0.3, None)])
def test_numba_twins_match_the_numpy_reference(model, nu, form):
    kw = {"volume_energy": form} if form else {}
    S = build(SceneSpec.default("compression", mesh=(3, 4, 5), model=model, nu=nu, **kw).build())
    x = S.X + 0.05 * np.random.default_rng(1).standard_normal(S.X.shape)
    e1, f1, p1 = energy_forces(S, x)
    e0, f0, p0 = energy_forces(S, x, kernel="numpy")
    assert p1.keys() == p0.keys()
    assert abs(e1 - e0) <= 1e-13 * abs(e0)
    assert np.abs(f1 - f0).max() <= 1e-13 * np.abs(f0).max()
    H1, H0 = hessian(S, x), hessian(S, x, "numpy")
    assert (H1.indptr == H0.indptr).all() and (H1.indices == H0.indices).all()
    assert np.abs(H1.data - H0.data).max() <= 1e-13 * np.abs(H0.data).max()
    assert np.allclose(cell_volumes(x, S.lattice.cells), cell_volumes(x, S.lattice.cells, "numpy"),
                       rtol=1e-14, atol=0)


def test_fixed_pattern_tangent_is_the_sliced_hessian_and_keeps_one_analysis():
    """H_ff gathered on the fixed pattern equals slicing the full Hessian; its shifts and the
    Hessians of other states keep the pattern (explicit zeros too), so CHOLMOD analyses once."""
    S = build(SceneSpec.default("tension", mesh=(2, 2, 6), nu=0.45).build())
    free = ~S.fixed.ravel()
    rng = np.random.default_rng(3)
    fac = Factorizer()
    b = rng.standard_normal(np.count_nonzero(free))
    for amp in (0.0, 1e-3):
        x = S.X + amp * rng.standard_normal(S.X.shape)
        T = tangent(S, x, 1.0, free)
        ref = stiffness(S, x)[free][:, free].toarray()
        # the CSR rows are read as CSC columns: H_ffᵀ, equal to H_ff but for the round-off asymmetry
        # of the volume blocks (d2W g_p g_q against d2W g_q g_p)
        tol = 1e-15 * np.abs(ref).max()
        assert np.abs(T.csc().toarray() - ref).max() <= tol
        assert np.abs(T.shifted(2.5).csc().toarray() - ref - 2.5 * np.eye(len(ref))).max() <= tol
        for A in (T, T.shifted(1e-6 * np.abs(T.diagonal()).mean())):
            F = fac.cholesky(A)
            if cholmod is not None:
                assert np.allclose(A.csc() @ F.solve(b), b, rtol=0, atol=1e-9 * np.abs(b).max())
        for A in (T, T.shifted(-0.5)):  # the permuted matrix SuperLU factorizes is a gather on the pattern
            Ap, ref_p = A.permuted(), A.csc()[A.order][:, A.order].tocsc()
            assert Ap.has_sorted_indices and np.array_equal(Ap.toarray(), ref_p.toarray())
        lu = superlu_symmetric(T)  # in the nested-dissection order: same inertia, same solution
        assert np.allclose(ref @ lu.solve(b), b, rtol=0, atol=1e-9 * np.abs(b).max())
        assert np.count_nonzero(lu.U.diagonal() < 0) == np.count_nonzero(np.linalg.eigvalsh(ref) < 0)
    if cholmod is not None:
        assert (fac.symbolic, fac.numeric) == (1, 4)


def testgrid_dissection_is_a_permutation_with_separators_last():
    S = build(SceneSpec.default("compression", mesh=(4, 3, 6)).build())
    order = grid_dissection(S.lattice.grid, leaf=4)
    assert np.array_equal(np.sort(order), np.arange(S.n))
    # the last nodes form the first separator: the middle plane of the longest extent (z)
    z = S.lattice.grid[order, 2]
    n_plane = 5 * 4
    assert (z[-n_plane:] == 3).all() and (z[:-n_plane] != 3).all()
