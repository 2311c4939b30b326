"""Natural frequencies of the FEM reference against closed form, and their convergence.

- Axial modes of a clamped–free bar at ν = 0: the 3D problem is exactly one-dimensional
  (λ = 0: an axial field u_z(z) has no lateral stress, and the clamp holds no lateral motion of
  it), so f_i = (2i−1)/(4L)·√(E/ρ) is the exact limit, and on Hex1 the exact discrete answer is
  that of the 1D bar of linear elements (consistent mass: ω² = 6c²/h²·(1 − cos θ)/(2 + cos θ),
  lumped: ω² = 4c²/h²·sin²(θ/2), θ = (2i−1)π/(2n), n elements along the bar).
- Bending modes of a slender cantilever (Euler–Bernoulli, β₁L = 1.8751, β₂L = 4.6941). Shear and
  rotary inertia lower a mode by about ½(β_iL)²(r/L)²(1 + E/(κG)) (r the radius of gyration, κ
  the shear coefficient; exact in this form for a simply supported beam, a cantilever's factor
  is of order one); twice that is the modelling tolerance.
- Convergence: the relative frequency error against the closed form falls as h^(2p) (Hex1:
  h², Hex2: h⁴), the rate fitted by ``polyfit(log h, log err)`` and asserted within a window, as
  the static references assert their observed orders.
"""

import numpy as np
import pytest
import scipy.linalg as sla

from fem_reference.modal import at_particles, direction_share, matrices, modes
from hybmss.scene import Body, Material, Plate, Region, Scene

E, RHO = 1e7, 1000.0
C = np.sqrt(E / RHO)
BETA_L = np.array([1.8751, 4.6941])


def clamped(cells, nu, le=1.0):
    return Scene(Body.box(*cells, le), Material(E, nu, RHO), plates=(Plate("clamp", Region("z-")),))


def axial(m, n=2):
    """The lowest ``n`` modes whose motion is along the bar (z share of the lumped kinetic energy > 0.99)."""
    f = m.freq[direction_share(m, 2) > 0.99]
    assert len(f) >= n
    return f[:n]


def rate(h, err):
    return np.polyfit(np.log(h), np.log(err), 1)[0]


BAR = (1, 1, 4)


@pytest.mark.parametrize("element, window", [("hex1", (1.9, 2.1)), ("hex2", (3.8, 4.2))])
def test_axial_bar_converges_to_closed_form(element, window):
    L = BAR[2]
    exact = np.array([1.0, 3.0]) / (4 * L) * C
    refine = (1, 2, 4)
    err = np.array([np.abs(axial(modes(clamped(BAR, 0.0), 16, element, r)) / exact - 1) for r in refine])
    h = 1.0 / np.array(refine)
    for i in range(2):
        assert window[0] <= rate(h, err[:, i]) <= window[1]
    assert err[-1].max() < (0.004 if element == "hex1" else 1e-5)


@pytest.mark.parametrize("mass", ["consistent", "lumped"])
def test_axial_bar_hex1_equals_the_discrete_1d_bar(mass):
    n = BAR[2] * 2
    h = BAR[2] / n
    theta = np.array([1.0, 3.0]) * np.pi / (2 * n)
    if mass == "consistent":
        w2 = 6 * C**2 / h**2 * (1 - np.cos(theta)) / (2 + np.cos(theta))
    else:
        w2 = 4 * C**2 / h**2 * np.sin(theta / 2) ** 2
    f = axial(modes(clamped(BAR, 0.0), 16, "hex1", 2, mass=mass))
    np.testing.assert_allclose(f, np.sqrt(w2) / (2 * np.pi), rtol=1e-9)
    exact = np.array([1.0, 3.0]) / (4 * BAR[2]) * C
    assert np.all(f > exact) if mass == "consistent" else np.all(f < exact)


BEAM = (1, 1, 24)


def euler_bernoulli(cells, le=1.0):
    L, a = cells[2] * le, cells[0] * le
    return BETA_L**2 / (2 * np.pi * L**2) * np.sqrt(E * a**2 / 12 / RHO)


def timoshenko_shift(cells, nu, le=1.0):
    """½(β_iL)²(r/L)²(1 + E/(κG)), κ = 10(1+ν)/(12+11ν) (Cowper, rectangle)."""
    r2 = (cells[0] * le) ** 2 / 12
    L = cells[2] * le
    kappa = 10 * (1 + nu) / (12 + 11 * nu)
    return 0.5 * BETA_L**2 * r2 / L**2 * (1 + 2 * (1 + nu) / kappa)


def bending(m):
    """Frequencies of the lowest two bending pairs (x and y shares of the kinetic energy > 0.8)."""
    lat = direction_share(m, 0) + direction_share(m, 1)
    f = m.freq[lat > 0.8]
    assert len(f) >= 4
    return f[[0, 2]]


def test_cantilever_hex2_matches_euler_bernoulli():
    m = modes(clamped(BEAM, 0.0), 4, "hex2", 1)
    f, f_eb = bending(m), euler_bernoulli(BEAM)
    np.testing.assert_allclose(m.freq[[0, 2]], m.freq[[1, 3]], rtol=1e-8)  # the square section's pairs
    err = f / f_eb - 1
    assert np.all(err < 0)  # shear and rotary inertia soften every mode
    assert np.all(-err < 2 * timoshenko_shift(BEAM, 0.0))


def test_cantilever_hex1_converges_at_rate_two():
    f_eb = euler_bernoulli(BEAM)[0]
    refine = (1, 2, 4)
    err = np.array([bending(modes(clamped(BEAM, 0.0), 4, "hex1", r))[0] / f_eb - 1 for r in refine])
    assert np.all(err > 0)  # Hex1 is too stiff in bending (shear locking), more so on coarse meshes
    assert 1.8 <= rate(1.0 / np.array(refine), err) <= 2.3
    assert err[-1] < 0.02


def test_mixed_condenses_the_pressure_exactly():
    """The shift-invert iteration on the saddle point equals the dense eigenproblem of
    μK_μ + λ Bᵀ M_p⁻¹ B (the pressure eliminated on its Schur complement)."""
    sc = clamped((1, 1, 2), 0.45)
    (A, B, Cp), M, free, _ = matrices(sc, "mixed")
    A, M, B = A.toarray()[np.ix_(free, free)], M.toarray()[np.ix_(free, free)], B.toarray()[:, free]
    K = A + B.T @ np.linalg.solve(Cp.toarray(), B)
    w = sla.eigh(K, M, eigvals_only=True, subset_by_index=(0, 5))
    m = modes(sc, 6, "mixed")
    np.testing.assert_allclose(m.omega2, w, rtol=1e-9)


@pytest.mark.parametrize("element", ["hex1", "hex2", "mixed"])
def test_factorized_shift_invert_equals_the_dense_eigenproblem(element):
    """The shift-invert operators (CHOLMOD's ``L Lᵀ`` of ``K − σM``, the saddle point's LU, each in
    the nested-dissection order of a grid large enough to be cut) give the dense eigenproblem's
    lowest eigenvalues and mode shapes."""
    sc = clamped((3, 3, 6), 0.45)
    K, M, free, ops = matrices(sc, element)
    assert ops.order is not None
    Mf = M.toarray()[np.ix_(free, free)]
    if element == "mixed":
        A, B, Cp = K
        Bf = B.toarray()[:, free]
        Kf = A.toarray()[np.ix_(free, free)] + Bf.T @ np.linalg.solve(Cp.toarray(), Bf)
    else:
        Kf = K.toarray()[np.ix_(free, free)]
    w, V = sla.eigh(Kf, Mf, subset_by_index=(0, 5))
    m = modes(sc, 6, element)
    np.testing.assert_allclose(m.omega2, w, rtol=1e-9)
    # a simple mode's shape equals the dense one up to sign: |φ_dense · M φ| = 1
    phi = m.shapes.reshape(6, -1)[:, free]
    simple = [i for i in range(6) if min(abs(w[i] - w[j]) for j in range(6) if j != i) > 1e-6 * w[i]]
    assert simple
    for i in simple:
        assert abs(abs(V[:, i] @ Mf @ phi[i]) - 1.0) < 1e-8


def test_mixed_avoids_locking_near_incompressibility():
    """At ν = 0.4999 the slender cantilever's first frequency from the mixed element stays within
    1 % of Euler–Bernoulli (the Timoshenko shift, and the clamp's hold on the lateral contraction,
    +0.25 % at ν = 0.3), where the displacement Hex2 on the same mesh is stiffer by locking."""
    sc = clamped(BEAM, 0.4999)
    f_eb = euler_bernoulli(BEAM)[0]
    mixed = bending(modes(sc, 4, "mixed"))[0] / f_eb - 1
    hex2 = bending(modes(sc, 4, "hex2"))[0] / f_eb - 1
    assert abs(mixed) < 0.01
    assert hex2 > 2 * abs(mixed)


def test_modes_are_mass_orthonormal_and_sampled_at_particles():
    sc = clamped((2, 2, 6), 0.25, le=0.25)
    m = modes(sc, 6, "hex2", 1)
    _, M, _, _ = matrices(sc, "hex2")
    V = m.shapes.reshape(len(m.freq), -1)
    np.testing.assert_allclose(V @ M @ V.T, np.eye(6), atol=1e-9)
    P = at_particles(m)
    lat = sc.body
    assert P.shape == (6, np.prod(np.add(lat.shape, 1)), 3)
    np.testing.assert_allclose(np.abs(P[:, 0]).max(), 0.0)  # particle 0 is on the clamp
