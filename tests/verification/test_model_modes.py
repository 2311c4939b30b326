"""Natural frequencies of the models' lattices (hybmss.modes) against exact and FEM answers.

- A 1×1×N column of hybmss-cf cells at ν = 1/4 with its lateral components held is a fixed–free
  spring–mass chain: per cell the springs' axial stiffness is Σ k cos²θ = ke + 2 kf + 4 kc / 3
  (4 edges of weight 1/4, 8 face diagonals of weight 1/2 at cos² = 1/2, 4 inner diagonals at
  cos² = 1/3) = 3 G le = (λ + 2μ) le at ν = 1/4 (G = 2E/5), each interior layer carries ρ le³
  and the free end ρ le³ / 2.  Its modes with uniform layers are those of the chain:
  ω_j = 2 √(k/m) sin(θ_j / 2), θ_j = (2j − 1)π / (2N) (the half end mass is the mirror plane of
  a fixed–fixed chain of 2N cells).
- corot-hex8 at rest is the linear Hex8 element on the lattice's cells with the lattice's
  lumped masses: the FEM's Hex1 with row-sum lumped mass on the same mesh, to round-off.
- MAC: 1 for a shape with itself, 0 between different FEM modes under the consistent mass;
  exactly 0 between shapes orthogonal by symmetry (an even and an odd field on a mirrored grid,
  whose product sums to round-off), while a MAC of 1e-8 stays what it is.
- A lattice's lowest frequency on a cantilever converges to the FEM's under refinement.
"""

import numpy as np
import pytest

from fem_reference.modal import at_particles, matrices, modes
from hybmss.modes import groups, has_tangent, lattice_modes, mac, match
from hybmss import models
from hybmss.lattice import Lattice
from hybmss.scene import Body, Material, Model, Motion, Plate, Region, Scene

E, RHO = 1e7, 1000.0


def cantilever(cells, le, nu, model):
    return Scene(Body.box(*cells, le), Material(E, nu, RHO), plates=(Plate("clamp", Region("z-")),),
                 model=Model(model))


def test_column_of_cells_is_the_exact_spring_mass_chain():
    N, le = 6, 0.5
    held = Plate("lateral", Region(lo=(-1.0, -1.0, -1.0), hi=(9.0, 9.0, 9.0)), Motion("slide", components=(0, 1)))
    sc = Scene(Body.box(1, 1, N, le), Material(E, 0.25, RHO), plates=(Plate("clamp", Region("z-")), held),
               model=Model("hybmss-cf"))
    lm = lattice_modes(sc, 4 * N - 1)
    layer = np.argsort(Lattice.from_body(sc.body).X[:, 2], kind="stable")
    uz = lm.shapes[:, layer, 2].reshape(len(lm.freq), N + 1, 4)  # particles by layer
    uniform = np.abs(uz - uz.mean(axis=2, keepdims=True)).max(axis=(1, 2)) < 1e-9 * np.abs(uz).max()
    m = Material(E, 0.25, RHO)
    k, mass = (m.lam + 2 * m.G) * le, RHO * le**3
    theta = (2 * np.arange(1, N + 1) - 1) * np.pi / (2 * N)
    chain = 2 * np.sqrt(k / mass) * np.sin(theta / 2) / (2 * np.pi)
    got = lm.freq[uniform]
    assert len(got) == N - 1  # the highest chain mode lies above the 4N − 1 computed
    np.testing.assert_allclose(got, chain[: N - 1], rtol=1e-10)


def test_corot_hex8_equals_fem_hex1_with_lumped_mass():
    sc = cantilever((2, 2, 6), 0.25, 0.3, "corot-hex8")
    lm = lattice_modes(sc, 6)
    fm = modes(sc, 6, "hex1", 1, mass="lumped")
    np.testing.assert_allclose(lm.freq, fm.freq, rtol=1e-10)
    m = match(fm.freq, at_particles(fm), lm.freq, lm.shapes)
    np.testing.assert_allclose(m["matched_mac"], 1.0, atol=1e-10)
    np.testing.assert_allclose(m["error"], 0.0, atol=1e-10)


def test_numpy_hessian_twin_gives_the_same_modes():
    sc = cantilever((2, 2, 4), 0.25, 0.45, "hybmss")
    a, b = lattice_modes(sc, 5), lattice_modes(sc, 5, kernel="numpy")
    np.testing.assert_allclose(a.freq, b.freq, rtol=1e-10)


def test_mac_of_itself_is_one_and_of_different_fem_modes_zero():
    sc = cantilever((2, 2, 6), 0.25, 0.3, "hybmss")
    fm = modes(sc, 6, "hex2", 1)
    _, M, _, _ = matrices(sc, "hex2")
    V = fm.shapes.reshape(6, -1)
    np.testing.assert_allclose(mac(V, V, M), np.eye(6), atol=1e-10)
    plain = mac(at_particles(fm), at_particles(fm))
    np.testing.assert_allclose(np.diag(plain), 1.0, rtol=1e-12)
    assert mac(V[:1], 3.0 * V[:1])[0, 0] == pytest.approx(1.0, rel=1e-12)


def mirrored_even_and_odd_shapes():
    """Two shapes symmetric under the mirror x → −x (u_x odd in x, u_y and u_z even: an axial
    mode's symmetry) and one antisymmetric (u_x even, u_y and u_z odd: a bending mode's) on a grid
    mirrored about x = 0 (41 × 7 × 19 nodes), and an even nodal weight (3 per node).  The
    antisymmetric shape is orthogonal to both by symmetry; its computed product with the first
    is round-off (1.8e-12 against |a| |b| ≈ 1e3)."""
    x = np.linspace(-1.0, 1.0, 41)
    X, Y, Z = np.meshgrid(x, np.linspace(0.0, 1.0, 7), np.linspace(0.0, 3.0, 19), indexing="ij")
    x, y, z = X.ravel(), Y.ravel(), Z.ravel()
    even = np.stack([np.sin(np.pi * x) * 0.3 * z, np.cos(0.7 * x) * y**2, np.exp(x**2) * np.sqrt(1.0 + z)], -1)
    odd = np.stack([np.cos(1.3 * x) * z**2, np.sin(2.1 * x) * np.sqrt(2.0 + y), np.sinh(x) * z / 3.0], -1)
    return even, even * (1.0 + x**2 + z)[:, None], odd, np.repeat(1.0 + np.cos(x), 3)


def test_mac_of_shapes_orthogonal_by_symmetry_is_zero_not_roundoff():
    even, even2, odd, w = mirrored_even_and_odd_shapes()
    a, b = even.ravel(), odd.ravel()
    assert a @ b != 0.0  # round-off: the sum does not cancel exactly
    assert mac(even[None], odd[None])[0, 0] == 0.0
    assert mac(even[None], odd[None], np.diag(w))[0, 0] == 0.0
    m = match(np.array([1.0]), even[None], np.array([1.0, 2.0]), np.stack([odd, even]))
    assert m["matched"] == [1] and m["mac"][0][0] == 0.0
    # the subspace MAC against a degenerate symmetric pair (its orthonormal basis from a QR)
    pair = match(np.array([1.0, 1.0]), np.stack([even, even2]), np.array([1.0]), odd[None])
    assert pair["groups"] == [0, 0] and pair["matched_mac"][pair["matched"].index(0)] == 0.0
    # a small MAC that is not round-off is kept: (aᵀb')² / (|a|² |b'|²) with b' = odd + t a
    t = 1e-4 * np.linalg.norm(b) / np.linalg.norm(a)
    small = mac(even[None], (odd + t * even)[None])[0, 0]
    expected = (t * (a @ a)) ** 2 / ((a @ a) * ((b + t * a) @ (b + t * a)))
    assert small == pytest.approx(expected, rel=1e-6) and 1e-9 < small < 1e-7


def test_match_pairs_degenerate_groups_and_reordered_modes():
    rng = np.random.default_rng(3)
    Q, _ = np.linalg.qr(rng.standard_normal((30, 4)))
    ref, f_ref = Q.T, np.array([1.0, 1.0, 2.0, 3.0])
    c, s = np.cos(0.7), np.sin(0.7)
    shapes = np.array([ref[3], c * ref[0] + s * ref[1], -s * ref[0] + c * ref[1], ref[2]])  # pair rotated
    m = match(f_ref, ref, np.array([3.3, 1.1, 1.1, 2.2]), shapes)
    assert groups(f_ref).tolist() == [0, 0, 1, 2]
    assert m["matched"][2:] == [3, 0] and sorted(m["matched"][:2]) == [1, 2]
    np.testing.assert_allclose(m["matched_mac"], 1.0, rtol=1e-12)
    np.testing.assert_allclose(m["error"], 0.1, rtol=1e-12)
    assert m["error_by_order"][0] == pytest.approx(2.3)


@pytest.mark.parametrize("model", ["hybmss-cf", "corot-hex8"])
def test_lowest_frequency_converges_to_the_fem(model):
    """The bending frequency of a 1×1×6 m cantilever on n×n×6n cells (n = 1, 2, 4) against the
    FEM's (Hex2 on the finest cells): the error falls at the lattice's order h² (fitted rate within
    [1.6, 2.4]) to below 5 %."""
    fem = modes(cantilever((4, 4, 24), 0.25, 0.25, model), 2, "hex2", 1).freq[0]
    ns = np.array([1, 2, 4])
    err = np.array([lattice_modes(cantilever((n, n, 6 * n), 1.0 / n, 0.25, model), 2).freq[0] / fem - 1 for n in ns])
    assert np.all(err > 0) and np.all(np.diff(err) < 0)
    assert 1.6 <= np.polyfit(np.log(1.0 / ns), np.log(err), 1)[0] <= 2.4
    assert err[-1] < 0.05


def test_models_without_tangent_are_refused():
    assert {m for m in models.names() if has_tangent(models.get(m))} >= {"hybmss", "hybmss-fd", "hybmss-cf",
                                                                         "baudet2009", "corot-hex8"}
    assert not has_tangent(models.get("xpbd-nh"))
    with pytest.raises(ValueError, match="no tangent stiffness"):
        lattice_modes(cantilever((1, 1, 2), 0.5, 0.3, "xpbd-nh"), 2)
    with pytest.raises(ValueError, match="k .number of modes"):
        lattice_modes(cantilever((1, 1, 2), 0.5, 0.3, "hybmss"), 24)


def _arpack_called():
    """An eigen solve with ARPACK's own start vector, whose generator's state persists in the process."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    spla.eigsh(sp.diags(np.arange(1.0, 51.0)).tocsc(), k=2, sigma=0.0)


def test_the_modes_of_a_degenerate_pair_do_not_depend_on_earlier_solves():
    """A square cantilever's first two bending modes share one frequency: any basis of their plane
    is an answer, and the shapes (so the pairing of model and FEM modes) must come out the same
    whatever eigen solves the process made before (ARPACK's own start vector did not)."""
    sc = cantilever((2, 2, 4), 0.5, 0.25, "hybmss-cf")
    first = lattice_modes(sc, 4)
    assert groups(first.freq)[0] == groups(first.freq)[1]  # the pair is degenerate
    _arpack_called()
    again = lattice_modes(sc, 4)
    np.testing.assert_array_equal(again.shapes, first.shapes)
    ref = modes(sc, 4, element="hex1")
    _arpack_called()
    np.testing.assert_array_equal(modes(sc, 4, element="hex1").shapes, ref.shapes)
