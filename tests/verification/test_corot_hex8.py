"""Corotational linear hexahedra (corot-hex8, corot-hex8-sri): element, kernel twin, patch test,
rigid rotations, the scikit-fem Hex1 answer at small strain, exact moduli, locking at ν → ½; the
float32 state and the one-thread refusal of both competitors' kernels (corot-hex8, xpbd-nh)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fem_reference.solve import solve as fem_solve
from hybmss.explicit import DivergenceError
from hybmss.models.corot_hex8 import corot_term, dt_crit, element_stiffness, simulate_explicit
from hybmss.moduli import measure_moduli
from hybmss.solve import StaticOptions
from hybmss.solve import solve_static as harness_static
from hybmss.scene import Body, Material, Model, Motion, Plate, Region, Scene, rotation_matrix
from hybmss.system import build

E = 1e4
PLAIN, SRI = Model("corot-hex8"), Model("corot-hex8-sri")


def compression(n: int, nu: float, d: float, le: float = 0.5, **kw) -> Scene:
    H = n * le
    return Scene(Body.box(n, n, n, le), Material(E, nu, 1000.0), PLAIN,
                 plates=(Plate("bottom", Region("z-")), Plate("top", Region("z+"), Motion("translate", (0, 0, -d * H)))),
                 name="compression", **kw)


def term_of(scene: Scene, sri: bool = False):
    """The system of ``scene`` as a corot-hex8 (or -sri) model and its corotational term."""
    S = build(dataclasses.replace(scene, model=SRI if sri else PLAIN))
    return S, corot_term(S)


def solve_static(S, T=None, options=None):
    """The project's static Newton (residual mode: the corotational term is non-conservative)."""
    return harness_static(S.scene, options, system=S)


@pytest.mark.parametrize("sri", [False, True])
def test_element_stiffness_has_exactly_the_rigid_modes(sri):
    K = element_stiffness(5769.2, 3846.2, 0.5, sri)
    w = np.linalg.eigvalsh(K)
    assert np.allclose(K, K.T)
    assert np.all(np.abs(w[:6]) < 1e-10 * w[-1]) and w[6] > 1e-3 * w[-1]


@pytest.mark.parametrize("sri", [False, True])
def test_forces_twin_and_90_degree_rotation(sri):
    S, T = term_of(compression(3, 0.3, 0.0), sri)
    rng = np.random.default_rng(0)
    x = S.X + 0.1 * S.scene.body.le * rng.standard_normal(S.X.shape)
    f = T.forces(x)
    assert np.abs(T.forces_numba(x) - f).max() <= 1e-10 * np.abs(f).max()
    Q = rotation_matrix((1.0, 2.0, 3.0), np.pi / 2)
    scale = E * S.scene.body.le**2
    assert np.abs(T.forces(S.X @ Q.T + (1.0, -2.0, 0.5))).max() <= 1e-10 * scale
    assert np.abs(T.forces_numba(S.X @ Q.T)).max() <= 1e-10 * scale


def test_tangent_is_the_jacobian_at_rest_and_under_rigid_rotation():
    S, T = term_of(compression(1, 0.3, 0.0))
    Q = rotation_matrix((0.0, 1.0, 1.0), 0.7)
    for x0 in (S.X, S.X @ Q.T):
        K = T.stiffness(x0).toarray()
        J = np.zeros_like(K)
        h = 1e-6 * S.scene.body.le
        for i in range(K.shape[0]):
            d = np.zeros(x0.size)
            d[i] = h
            J[:, i] = -(T.forces(x0 + d.reshape(-1, 3)) - T.forces(x0 - d.reshape(-1, 3))).ravel() / (2 * h)
        assert np.abs(J - K).max() <= 1e-6 * np.abs(K).max()


@pytest.mark.parametrize("sri", [False, True])
def test_tangent_is_the_jacobian_under_large_rotation_and_strain(sri):
    """With the derivative of the polar rotation the tangent is the Jacobian of the forces at a
    rotated (0.9 rad), stretched and perturbed state of a 2×2×3 body (central differences, error
    O(h²) ≈ 1e-10); ``R K Rᵀ`` alone is off by percents there, and the tangent is nonsymmetric."""
    S, T = term_of(dataclasses.replace(compression(2, 0.3, 0.0), model=SRI if sri else PLAIN))
    rng = np.random.default_rng(0)
    Q = rotation_matrix((0.0, 0.0, 1.0), 0.9)
    x0 = S.X @ (Q @ np.diag([1.1, 0.95, 1.2])).T + 0.05 * rng.standard_normal(S.X.shape)
    K = T.stiffness(x0).toarray()
    K_rot = T.stiffness(x0, rotation_derivative=False).toarray()
    h = 1e-6 * S.scene.body.le
    for _ in range(3):
        d = rng.standard_normal(x0.shape)
        fd = -(T.forces(x0 + h * d) - T.forces(x0 - h * d)).ravel() / (2 * h)
        assert np.abs(K @ d.ravel() - fd).max() <= 1e-8 * np.abs(fd).max()
        assert np.abs(K_rot @ d.ravel() - fd).max() >= 1e-2 * np.abs(fd).max()
    assert np.abs(K - K.T).max() >= 1e-4 * np.abs(K).max()


def test_large_deflection_static_converges_quadratically():
    """The cantilever under gravity at E = 2 MPa (tip deflection ≈ a quarter of its length): Newton
    with the full tangent converges in a few iterations, each reducing the residual
    quadratically; with ``R K Rᵀ`` alone the contraction is linear and the solve stalled on the
    8×8×48 beam."""
    from hybmss.experiments import SceneSpec

    sc = SceneSpec.default("bending", model="corot-hex8", mesh=(2, 2, 12), nu=0.25, E=2e6).build()
    r = harness_static(sc)
    assert r.converged and r.iterations <= 8
    assert np.abs(r.u).max() > 0.2 * sc.body.size[2]


@pytest.mark.parametrize("sri", [False, True])
def test_patch_test_affine_state_reproduced(sri):
    """All boundary nodes follow an affine map (finite rotation and stretch); the static interior
    reproduces it to 1e-10."""
    Q = rotation_matrix((1.0, 1.0, 0.0), 0.6)
    Fm = Q @ np.array([[1.1, 0.05, 0.0], [0.0, 0.95, 0.02], [0.03, 0.0, 1.05]])
    motion = Motion("affine", gradient=tuple((Fm - np.eye(3)).ravel()), displacement=(0.1, 0.2, -0.1))
    plates = tuple(Plate(f, Region(f), motion) for f in ("x-", "x+", "y-", "y+", "z-", "z+"))
    scene = Scene(Body.box(3, 3, 3, 0.5), Material(E, 0.3, 1000.0), PLAIN, plates)
    S, T = term_of(scene, sri)
    r = solve_static(S, T, StaticOptions(rtol=1e-13))
    exact = S.X @ Fm.T + np.array([0.1, 0.2, -0.1])
    assert (~S.fixed.any(axis=1)).sum() == 8
    assert np.abs(r.x - exact).max() <= 1e-10 * scene.body.le


@pytest.mark.parametrize("nu", [0.0, 0.3, 0.499])
def test_small_strain_static_equals_scikit_fem_hex1(nu):
    scene = compression(4, nu, 1e-6)
    S, T = term_of(scene)
    r = solve_static(S, T)
    ref = fem_solve(scene, element="hex1", law="linear")
    assert np.linalg.norm(r.u - ref.u) <= 1e-6 * np.linalg.norm(ref.u)
    Fz, Fz_ref = r.reactions["top"].force[2], ref.reactions["top"].force[2]
    assert abs(Fz - Fz_ref) <= 1e-6 * abs(Fz_ref)


@pytest.mark.parametrize("sri", [False, True])
@pytest.mark.parametrize("nu", [0.0, 0.3, 0.45])
def test_effective_moduli_exact(nu, sri):
    """The project's homogeneous tests (hybmss.moduli): uniaxial stress and simple shear."""
    mat = Material(E, nu, 1000.0)
    m = measure_moduli(SRI if sri else PLAIN, mat)
    E_eff, nu_eff, G_eff = m["E_eff"], m["nu_eff"], m["G_eff"]
    assert abs(E_eff - E) <= 1e-6 * E
    assert abs(nu_eff - nu) <= 1e-6
    assert abs(G_eff - mat.G) <= 1e-6 * mat.G


def test_sri_does_not_lock_at_nu_0499():
    scene = compression(4, 0.499, 0.05)
    ref = fem_solve(scene, element="mixed", law="linear").reactions["top"].force[2]
    plain = solve_static(*term_of(scene, False)).reactions["top"].force[2]
    sri = solve_static(*term_of(scene, True)).reactions["top"].force[2]
    assert abs(sri - ref) <= 0.05 * abs(ref)
    assert abs(plain) > 3.0 * abs(ref)  # plain full integration locks: several times too stiff


def _twisted(nu=0.3, **kw):
    H = 1.5
    return Scene(Body.box(3, 3, 3, 0.5), Material(E, nu, 1000.0), PLAIN,
                 plates=(Plate("bottom", Region("z-")),
                         Plate("top", Region("z+"), Motion("rotate", (0.0, 0.0, -0.1 * H), angle=0.6))),
                 gravity=(0.0, 0.0, -10.0), **kw)


@pytest.mark.parametrize("sri", [False, True])
def test_numba_kernel_matches_numpy_twin_over_100_steps(sri):
    S, T = term_of(_twisted(damping=0.5), sri)
    a = simulate_explicit(S, T, dt=1e-2, steps=100, kernel="numba", ramp_time=0.6)
    b = simulate_explicit(S, T, dt=1e-2, steps=100, kernel="numpy", ramp_time=0.6)
    assert np.abs(a.u).max() > 0.1
    assert np.abs(a.u - b.u).max() <= 1e-10 * np.abs(a.u).max()
    assert a.info["dt_crit"] == pytest.approx(dt_crit(S, T))


def test_polar_rotation_lanes_is_the_scalar_iteration_bit_for_bit():
    """The lane iteration of the kernel against the scalar one, per lane, on matrices that need
    from 1 to many iterations in one batch (converged lanes must stop while the others go on):
    identical to the last bit, and R is a rotation with Rᵀ F symmetric."""
    from hybmss.models.corot_hex8 import _kernels as K

    rng = np.random.default_rng(3)
    L = K.LANES
    for amp in (0.0, 1e-9, 1e-3, 0.3, 0.9):
        F = np.empty((3, 3, L))
        for l in range(L):
            Q = rotation_matrix((0.0, 0.0, 1.0), float(rng.uniform(-3, 3)))
            S = np.eye(3) + amp * (l + 1) / L * rng.standard_normal((3, 3))
            F[:, :, l] = Q @ (S @ S.T)  # det F > 0
        R = np.empty_like(F)
        K.polar_rotation_lanes(F, R, np.empty(L, dtype=bool))
        iters = set()
        for l in range(L):
            Rs = np.empty((3, 3))
            iters.add(K.polar_rotation(np.ascontiguousarray(F[:, :, l]), Rs, np.empty((3, 3))))
            assert np.array_equal(R[:, :, l], Rs)
            assert np.allclose(Rs.T @ Rs, np.eye(3), atol=1e-13)
            M = Rs.T @ F[:, :, l]
            assert np.allclose(M, M.T, atol=1e-12 * np.abs(M).max())
        if amp == 0.3:
            assert len(iters) > 1  # lanes that converge at different iterations


def test_dt_crit_separates_stable_and_unstable_runs():
    """Undamped runs from a tiny random perturbation: bounded just below dt_crit, divergent just
    above (the growth of the highest mode beyond the symplectic Euler limit)."""
    S, T = term_of(compression(2, 0.3, 0.0))
    dc = dt_crit(S, T)
    rng = np.random.default_rng(3)
    x0 = S.X + 1e-6 * rng.standard_normal(S.X.shape)
    r = simulate_explicit(S, T, dt=0.97 * dc, steps=3000, ramp_time=0.0, x0=x0, dt_crit_value=dc)
    assert np.abs(r.u).max() < 1e-4
    with pytest.raises(DivergenceError, match="exceeds the explicit stability limit"):
        simulate_explicit(S, T, dt=1.03 * dc, steps=3000, ramp_time=0.0, x0=x0, dt_crit_value=dc)


def _f32_against_f64(model: str):
    """Largest position difference of float32 and float64 runs of the publication's explicit
    protocol (10,000 steps of 1 ms, damping 2/s, 5 % compression of the 2³ cube), relative to the
    largest displacement."""
    from hybmss.experiments import SceneSpec
    from hybmss.explicit import simulate_explicit as harness_explicit

    scene = SceneSpec.default("compression", mesh=(2, 2, 2), nu=0.25, model=model, deformation=0.05,
                              damping=2.0).build()
    a = harness_explicit(scene, dt=1e-3, steps=10_000, precision="f64")
    b = harness_explicit(scene, dt=1e-3, steps=10_000, precision="f32")
    assert (a.info["precision"], b.info["precision"]) == ("f64", "f32")
    return float(np.abs(a.u - b.u).max() / np.abs(a.u).max())


@pytest.mark.slow
@pytest.mark.parametrize("model", ["corot-hex8", "xpbd-nh"])
def test_float32_state_stays_within_1e_5_of_float64_after_10000_steps(model):
    """The float32 mode stores displacements (the MSS's float32 layout): its only error is the
    rounding of the state, ~1e-7 of the displacement per step, which the damped motion does not
    accumulate; a float32 mode that computed nothing in float32 would agree exactly."""
    err = _f32_against_f64(model)
    assert 1e-9 < err <= 1e-5


@pytest.mark.parametrize("model", ["corot-hex8", "xpbd-nh"])
def test_serial_kernels_refuse_two_threads_and_the_twin_refuses_float32(model):
    from hybmss.experiments import SceneSpec
    from hybmss.explicit import simulate_explicit as harness_explicit

    scene = SceneSpec.default("compression", mesh=(1, 1, 1), model=model).build()
    with pytest.raises(ValueError, match="threads must be 1"):
        harness_explicit(scene, steps=1, threads=2)
    with pytest.raises(ValueError, match="needs kernel='numba'"):
        harness_explicit(scene, steps=1, kernel="numpy", precision="f32")


def test_frequencies_and_dt_crit_are_the_same_in_every_call():
    """The Lanczos solves start from a fixed vector (ARPACK's default start is random): ω₁, ω_max
    of the competitors' grid and the mass-spring dt_crit come out bit for bit the same each time
    (they set dt and the substeps of the runs, so results would differ in their last bits)."""
    from hybmss.experiments import SceneSpec
    from hybmss.explicit import dt_crit as mss_dt_crit
    from hybmss.models.xpbd_nh import frequencies

    S = build(SceneSpec.default("tension", model="xpbd-nh", mesh=(4, 4, 24), nu=0.499).build())
    assert frequencies(S) == frequencies(S)
    S2 = build(SceneSpec.default("compression", model="hybmss", mesh=(12, 12, 12), nu=0.499).build())
    assert mss_dt_crit(S2) == mss_dt_crit(S2)
