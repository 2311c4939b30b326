"""Finite-strain references: laws, homogeneous closed forms, linear limit, rigid rotation.

A homogeneous deformation is affine, hence exactly representable by every element, so the
FEM must reproduce the closed-form stress of each law up to the Newton tolerance (1e-8).
"""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from fem_reference.laws import LAWS, deviatoric, energy_density, first_piola, volumetric
from fem_reference.solve import solve
from hybmss.scene import Body, Material, Motion, Plate, Region, Scene


@pytest.mark.parametrize("law", LAWS)
def test_law_derivatives_by_finite_differences(law):
    """P = ∂ψ/∂F and A = ∂P/∂F (central differences, step 1e-6: error O(1e-10))."""
    rng = np.random.default_rng(3)
    F = np.eye(3) + 0.2 * rng.standard_normal((3, 3))
    lam, mu = 1.3, 0.7
    W0, P0, A0 = deviatoric(law, F, mu)
    g, G, H = volumetric(law, F)
    A = A0 + lam * np.einsum("ij,kl->ijkl", G, G) + lam * g * H
    P = first_piola(law, F, lam, mu)
    eps = 1e-6
    for k in range(3):
        for L in range(3):
            dF = np.zeros((3, 3))
            dF[k, L] = eps
            dpsi = (energy_density(law, F + dF, lam, mu) - energy_density(law, F - dF, lam, mu)) / (2 * eps)
            assert dpsi == pytest.approx(P[k, L], abs=1e-8)
            dP = (first_piola(law, F + dF, lam, mu) - first_piola(law, F - dF, lam, mu)) / (2 * eps)
            assert np.allclose(dP, A[:, :, k, L], atol=1e-8)


@pytest.mark.parametrize("law", LAWS)
def test_law_tangent_at_identity_is_linear_elastic(law):
    lam, mu = 2.0, 0.5
    I = np.eye(3)
    W0, P0, A0 = deviatoric(law, I, mu)
    g, G, H = volumetric(law, I)
    A = A0 + lam * np.einsum("ij,kl->ijkl", G, G) + lam * g * H
    C = lam * np.einsum("ij,kl->ijkl", I, I) + mu * (np.einsum("ik,jl->ijkl", I, I) + np.einsum("il,jk->ijkl", I, I))
    assert np.allclose(A, C, atol=1e-15) and np.allclose(P0, 0) and g == pytest.approx(0)


def uniaxial(nu, stretch, body=Body.box(1, 1, 2, 0.5)):
    H = body.size[2]
    plates = (
        Plate("x-", Region("x-"), Motion("slide", components=(0,))),
        Plate("y-", Region("y-"), Motion("slide", components=(1,))),
        Plate("z-", Region("z-"), Motion("slide", components=(2,))),
        Plate("top", Region("z+"), Motion("slide", (0.0, 0.0, (stretch - 1) * H), components=(2,))),
    )
    return Scene(body, Material(1e4, nu), plates=plates)


def closed_form(law, mat, l1):
    """Lateral stretch l2 and nominal axial stress P11 of uniaxial stress at axial stretch l1."""
    lam, mu = mat.lam, mat.G
    if law == "svk":
        E11 = 0.5 * (l1**2 - 1)
        l2 = math.sqrt(1 - 2 * mat.nu * E11)  # S22 = 0  ⇒  E22 = −ν E11
        return l2, l1 * mat.E * E11  # S11 = E E11, P11 = l1 S11

    def P22(l2):  # Neo-Hookean: μ(l2 − 1/l2) + λ ln J / l2 = 0
        return mu * (l2 - 1 / l2) + lam * math.log(l1 * l2**2) / l2

    l2 = brentq(P22, 0.3, 1.5, xtol=1e-16, rtol=1e-15)
    return l2, mu * (l1 - 1 / l1) + lam * math.log(l1 * l2**2) / l1


@pytest.mark.parametrize(
    "law,element,nu",
    [("neo-hookean", "hex1", 0.3), ("svk", "hex1", 0.3), ("neo-hookean", "hex2", 0.0),
     ("svk", "hex2", 0.3), ("neo-hookean", "mixed", 0.49), ("svk", "mixed", 0.49)],
)
def test_uniaxial_stretch_20_percent_closed_form(law, element, nu):
    sc = uniaxial(nu, 1.2)
    res = solve(sc, element=element, law=law, steps=2)
    l2, P11 = closed_form(law, sc.material, 1.2)
    area = sc.body.size[0] * sc.body.size[1]
    F = res.reactions["top"].force[2]
    assert F / area == pytest.approx(P11, rel=1e-8)
    W = sc.body.size[0]
    xp = np.isclose(res.X[:, 0], W)
    assert 1 + res.u[xp, 0].mean() / W == pytest.approx(l2, rel=1e-8)
    assert res.volume == pytest.approx(sc.body.volume * 1.2 * l2**2, rel=1e-8)


@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("element", ["hex2", "mixed"])
def test_small_strain_limit_equals_linear(law, element):
    """At 1e-4 strain the finite-strain reference equals the linear one to O(strain) ≤ 1e-3,
    on a non-homogeneous problem (bonded compression)."""
    body = Body.box(2, 2, 2, 0.5)
    sc = Scene(body, Material(1e4, 0.3), plates=(
        Plate("bottom", Region("z-")),
        Plate("top", Region("z+"), Motion("translate", (0.0, 0.0, -1e-4))),
    ))
    lin = solve(sc, element=element, law="linear")
    non = solve(sc, element=element, law=law, steps=1)
    assert non.reactions["top"].force[2] == pytest.approx(lin.reactions["top"].force[2], rel=1e-3)
    assert np.abs(non.u - lin.u).max() <= 1e-3 * np.abs(lin.u).max()


def rotated_scene(angle, body=Body.box(2, 2, 2, 0.5)):
    """Every face follows the same rigid rotation about the body's centre."""
    c = tuple(body.origin[i] + body.size[i] / 2 for i in range(3))
    motion = Motion("rotate", angle=angle, axis=(0.0, 0.0, 1.0), center=c)
    plates = tuple(Plate(f, Region(f), motion) for f in ("z-", "z+", "x-", "x+", "y-", "y+"))
    return Scene(body, Material(1e4, 0.3), plates=plates)


@pytest.mark.parametrize("law", LAWS)
def test_rigid_rotation_45_is_stress_free(law):
    sc = rotated_scene(math.pi / 4)
    res = solve(sc, element="hex2", law=law, steps=3)
    mu, V = sc.material.G, sc.body.volume
    assert res.energy["strain"] <= 1e-12 * mu * V
    for r in res.reactions.values():
        assert np.abs(r.force).max() <= 1e-8 * mu * V ** (2 / 3)
    exact = sc.plates[0].motion.displacement_at(res.X, 1.0)
    assert np.abs(res.u - exact).max() <= 1e-10 * sc.body.le
    assert res.volume == pytest.approx(V, rel=1e-12)


def test_linear_law_spurious_stress_under_rotation():
    """Documented limitation: the linear law sees a rigid rotation by θ as the strain
    ε = (cos θ − 1)(e₁e₁ + e₂e₂); with the whole boundary rotated the affine field is the
    exact solution, of energy density 2(λ + μ)(1 − cos θ)² (not zero)."""
    theta = math.pi / 4
    sc = rotated_scene(theta)
    res = solve(sc, element="hex2", law="linear")
    lam, mu = sc.material.lam, sc.material.G
    expected = 2 * (lam + mu) * (1 - math.cos(theta)) ** 2 * sc.body.volume
    assert res.energy["strain"] == pytest.approx(expected, rel=1e-10)
    # ∫(1 + div u) reports a volume loss of 2(1 − cos θ) ≈ 59 % for a rotation.
    assert res.volume_change == pytest.approx(2 * (math.cos(theta) - 1), rel=1e-10)


@pytest.mark.parametrize("element,law", [("hex2", "neo-hookean"), ("mixed", "neo-hookean"), ("hex1", "svk")])
def test_newton_reactions_balance_body_load(element, law):
    body = Body.box(2, 2, 3, 0.5)
    # E = 1e6 Pa: with 1e4 Pa the body would collapse under its own weight (ρ g H ≈ E).
    sc = Scene(body, Material(1e6, 0.3, 1000.0), plates=(
        Plate("bottom", Region("z-")),
        Plate("top", Region("z+"), Motion("translate", (0.05, 0.0, -0.2))),
    ), gravity=(0.0, -10.0, -10.0))
    res = solve(sc, element=element, law=law, steps=3)
    W = np.asarray(res.info["body_load"])
    total = sum(np.asarray(r.force) for r in res.reactions.values()) + W
    assert np.abs(total).max() <= 1e-8 * np.abs(W).max()


def test_nearly_incompressible_compression_keeps_volume():
    """ν = 0.499 Neo-Hookean, 20 % bonded compression with the mixed element: the volume is
    preserved to ~(stress/K); ∫(det F − 1) and ∫ ln J are both reported."""
    body = Body.box(3, 3, 3, 1.0)
    sc = Scene(body, Material(1e4, 0.499), plates=(
        Plate("bottom", Region("z-")),
        Plate("top", Region("z+"), Motion("translate", (0.0, 0.0, -0.6))),
    ))
    res = solve(sc, law="neo-hookean")
    assert res.solver == "fem-mixed-neo-hookean"
    assert abs(res.volume_change) < 5e-3
    assert abs(res.info["integral_lnJ"]) / sc.body.volume < 5e-3
    assert res.info["min_J"] > 0 and res.converged


def test_newton_failure_is_reported():
    """A body far too soft for its weight (ρ g H ≫ E) collapses: SVK has no barrier against
    J → 0, so Newton fails; strict mode raises, otherwise the last converged state is returned."""
    from fem_reference.hyperelastic import ConvergenceError

    body = Body.box(1, 1, 2, 0.5)
    sc = Scene(body, Material(1e3, 0.3, 1000.0), plates=(Plate("bottom", Region("z-")),),
               gravity=(0.0, 0.0, -100.0))
    with pytest.raises(ConvergenceError, match="load factor"):
        solve(sc, element="hex1", law="svk", steps=2)
    res = solve(sc, element="hex1", law="svk", steps=2, strict=False)
    assert not res.converged and 0 < res.info["load_factor"] < 1
    total = sum(np.asarray(r.force) for r in res.reactions.values()) + np.asarray(res.info["body_load"])
    assert np.abs(total).max() <= 1e-8 * np.abs(res.info["body_load"]).max()
