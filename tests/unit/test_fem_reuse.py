"""The cheaper paths of the FEM reference give the answers of the plain ones.

- the nested-dissection order of the direct factorizations is a permutation of the unknowns and
  gives the solution of SuperLU's own order (linear Hex2 and mixed u–p solves);
- the tangent's sparsity pattern built from the scalar pattern equals the one built from every
  vector entry, and the compiled one equals both;
- the linear stiffness ``λ K_λ + μ K_μ`` summed on the parts' shared pattern is SciPy's sum,
  array for array (entries that cancel left out);
- the linear solver chosen without counting the free block's entries is the one chosen with them;
- Newton with reused factorizations (chord steps), loosely converged intermediate load steps and
  the reordered factorizations reaches the equilibrium of the plain scheme (a fresh tangent at
  every iteration, every step to the full tolerance, minimum degree order) to 1e-8.
"""

import numpy as np
import pytest
import scipy.sparse as sp

from fem_reference.dirichlet import plate_dirichlet
from fem_reference.hyperelastic import Hyperelasticity
from fem_reference.linalg import OrderedLU, dof_order, nested_dissection
from fem_reference.linear import LinearElasticity, _weighted_sum
from fem_reference.mesh import build_mesh
from fem_reference.space import Space
from hybmss.scene import Body, Material, Motion, Plate, Region, Scene


def _box_scene(body, nu, motion, gravity=(0.0, 0.0, 0.0), E=1e4):
    return Scene(body, Material(E, nu, 1000.0), gravity=gravity,
                 plates=(Plate("bottom", Region("z-")),) + ((Plate("top", Region("z+"), motion),) if motion else ()))


@pytest.mark.parametrize("element", ["hex1", "hex2", "mixed"])
def test_stiffness_sum_on_the_shared_pattern_is_scipys(element):
    L = LinearElasticity(build_mesh(Body.box(2, 2, 3, 0.5), 1), element)
    A, B = L.parts
    for lam, mu in ((0.0, 1.0), (3.0, 1.0), (1.0, 0.0)):
        K, ref = _weighted_sum(lam, A, mu, B), (lam * A + mu * B).sorted_indices()
        for name in ("indptr", "indices", "data"):
            assert np.array_equal(getattr(K, name), getattr(ref, name))
    # a pattern of its own: SciPy's sum
    C = sp.identity(A.shape[0], format="csr")
    assert np.array_equal(_weighted_sum(2.0, A, 1.0, C).toarray(), (2.0 * A + C).toarray())


def test_solver_choice_without_counting_is_the_choice_with_counting(monkeypatch):
    import fem_reference.linalg as L

    A, B = LinearElasticity(build_mesh(Body.box(2, 2, 3, 0.5), 1), "hex2").parts
    K = A + B
    free = np.ones(K.shape[0], dtype=bool)
    free[: K.shape[0] // 3] = False
    sub = L._submatrix_nnz(K, free)
    assert sub < K.nnz
    for limit in (sub - 1, sub, (sub + K.nnz) // 2, K.nnz, K.nnz + 1):  # around both counts
        monkeypatch.setattr(L, "DIRECT_MAX_NNZ", limit)
        monkeypatch.setattr(L, "DIRECT_MAX_NNZ_CHOLMOD", limit)
        for method in ("auto", "direct", "amg"):
            for separator in (None, 10, 10**6):
                assert L._spd_kind(method, K, free, separator) == L._choose_spd(method, sub, separator)


def test_dof_order_expands_nodes():
    assert dof_order(np.array([1, 0]), 2).tolist() == [3, 4, 5, 0, 1, 2]
    # two vector nodes (dofs 0..5) and one scalar node (unknown 6)
    assert dof_order(np.array([2, 0, 1]), 2, 1).tolist() == [6, 0, 1, 2, 3, 4, 5]


@pytest.mark.parametrize("element", ["hex1", "hex2"])
def test_nested_dissection_is_a_permutation_with_separators_last(element):
    space = Space.create(build_mesh(Body.box(3, 2, 5, 0.5), 1), element)
    order = nested_dissection(space.points, 0.5, leaf=4)
    assert np.array_equal(np.sort(order), np.arange(space.n_scalar))
    # the first cut halves the longest extent (z, 5 cells) at z = 2 cells: its plane comes last
    z = space.points[order, 2]
    n_plane = int(np.count_nonzero(np.isclose(space.points[:, 2], 1.0)))
    assert np.allclose(z[-n_plane:], 1.0)
    assert nested_dissection(space.points + 0.01 * np.sin(space.points), 0.5) is None  # not a grid


def test_ordered_factorization_solves_the_same_system():
    rng = np.random.default_rng(3)
    M = sp.random(40, 40, density=0.1, random_state=4)
    A = (M @ M.T + 40 * sp.eye(40)).tocsr()
    b = rng.standard_normal(40)
    perm = rng.permutation(40)
    x0 = OrderedLU(A, None).solve(b)
    x1 = OrderedLU(A, perm).solve(b)
    x2 = OrderedLU(A[perm][:, perm], perm, permuted=True).solve(b)
    assert np.abs(A @ x0 - b).max() <= 1e-12 * np.abs(b).max()
    assert np.abs(x1 - x0).max() <= 1e-12 * np.abs(x0).max()
    assert np.abs(x2 - x0).max() <= 1e-12 * np.abs(x0).max()


@pytest.mark.parametrize("element,nu", [("hex2", 0.3), ("mixed", 0.499)])
def test_reordered_linear_solve_same_answer(element, nu):
    body = Body.box(2, 2, 4, 0.5)
    sc = _box_scene(body, nu, Motion("translate", (0.02, 0.0, -0.05)))
    fm = build_mesh(body, 1)
    sols = []
    for reorder in (False, True):
        le = LinearElasticity(fm, element, reorder=reorder)
        sols.append(le.solve(sc.material, plate_dirichlet(sc, le.space), method="direct"))
    a, b = sols
    assert np.abs(b.U - a.U).max() <= 1e-10 * np.abs(a.U).max()
    if element == "mixed":
        assert np.abs(b.p - a.p).max() <= 1e-10 * np.abs(a.p).max()


@pytest.mark.parametrize("element", ["hex1", "hex2"])
def test_block_pattern_equals_vector_pattern(element, monkeypatch):
    import fem_reference.space as space_module

    space = Space.create(build_mesh(Body.box(3, 2, 2, 0.5), 1), element)
    V = (3 * space.edofs[:, :, None] + np.arange(3)).astype(np.int64)
    plain = space._pattern(V[:, None, :, :, None], V[None, :, :, None, :])
    for x, y in zip(plain, space._block_pattern()):
        assert np.array_equal(x, y)
    monkeypatch.setattr(space_module, "COMPILED_PATTERN_KEYS", 0)  # the compiled path on this mesh
    for x, y in zip(space._block_pattern(), space._uniform_pattern):  # compiled against its NumPy twin
        assert x.dtype == y.dtype and np.array_equal(x, y)


CASES = {
    # soft cantilever under its weight: several load steps, SPD direct solves (chord steps)
    "cantilever": (Body.box(1, 1, 6, 0.4), "hex2", 0.25, None, (0.0, -10.0, 0.0), 2e6),
    # 90° torsion of a nearly incompressible cube: mixed u–p, saddle-point factorizations
    "torsion": (Body.box(2, 2, 2, 0.5), "mixed", 0.499,
                Motion("rotate", angle=np.pi / 2, axis=(0.0, 0.0, 1.0), center=(0.5, 0.5, 1.0)), (0, 0, 0), 1e4),
    # 50 % compression, Hex2 displacement formulation
    "compression": (Body.box(2, 2, 2, 0.5), "hex2", 0.25, Motion("translate", (0.0, 0.0, -0.5)), (0, 0, 0), 1e4),
}


@pytest.mark.parametrize("case", [c if c == "compression" else pytest.param(c, marks=pytest.mark.slow) for c in CASES])
def test_reused_factorizations_same_equilibrium(case):
    body, element, nu, motion, g, E = CASES[case]
    sc = _box_scene(body, nu, motion, g, E)
    fm = build_mesh(body, 1)
    plain_ops = Hyperelasticity(fm, element, "neo-hookean", reorder=False)
    fast_ops = Hyperelasticity(fm, element, "neo-hookean")
    d = plate_dirichlet(sc, plain_ops.space)
    plain, log_p = plain_ops.solve(sc.material, d, g, method="direct", intermediate_rtol=None, chord=False)
    fast, log_f = fast_ops.solve(sc.material, d, g, method="direct")
    assert log_p.converged and log_f.converged
    assert fast.stats.method in ("direct", "cholmod")  # SPD: CHOLMOD when cvxopt is installed
    assert np.abs(fast.U - plain.U).max() <= 1e-8 * np.abs(plain.U).max()
    D = d.dofs
    assert np.abs(fast.r[D] - plain.r[D]).max() <= 1e-8 * np.abs(plain.r[D]).max()
    if element == "mixed":
        assert np.abs(fast.p - plain.p).max() <= 1e-8 * np.abs(plain.p).max()
    # a direct solve counts one iteration per factorization, a chord step a call only
    assert fast.stats.iterations < plain.stats.iterations
