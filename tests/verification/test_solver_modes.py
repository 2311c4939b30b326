"""The static Newton's two modes (energy, residual) over System.terms, zero and extreme loads, the
Poisson-ratio range of the solvers, and implicit Euler at its default step."""

import numpy as np
import pytest

from hybmss.models.baudet2009.corrections import Corrections
from hybmss.forces import energy_forces, spring_energy_forces, stiffness
from hybmss.moduli import measure_moduli
from hybmss.scene import Body, Material, Model, Motion, Plate, Region, Scene
from hybmss.solve import NU_RANGE, ImplicitOptions, StaticSolveError, simulate_implicit, solve_static
from hybmss.solve.common import force_floor
from hybmss.system import build
from hybmss.terms import DeadLoad, ForceTerm
from studies.sweep.scenes import SceneSpec


def _fd_jacobian_of_minus(force, x, h):
    """Central differences of ``−force`` (3n × 3n, dense)."""
    N = x.size
    J = np.zeros((N, N))
    for j in range(N):
        xp, xm = x.copy().ravel(), x.copy().ravel()
        xp[j] += h
        xm[j] -= h
        J[:, j] = -(force(xp.reshape(x.shape)) - force(xm.reshape(x.shape))).ravel() / (2 * h)
    return J


def _small_baudet(nu=0.3):
    mask = np.ones((2, 1, 2), dtype=bool)
    mask[1, :, 1] = False
    return build(Scene(Body.from_mask(mask, 0.1), Material(1000.0, nu), Model("baudet2009")))


def test_terms_follow_the_contract():
    S = _small_baudet()
    corr = S.term(Corrections.name)
    assert isinstance(corr, ForceTerm) and not corr.conservative and not corr.scaled
    assert not S.conservative
    with pytest.raises(TypeError):
        corr.energy(S.X)
    dead = DeadLoad(np.ones_like(S.X))
    assert isinstance(dead, ForceTerm) and dead.conservative and dead.scaled


def test_total_stiffness_is_the_jacobian_of_minus_the_forces():
    """forces.stiffness (spring Hessian + the corrections' nonsymmetric term) against central
    differences of the total forces; the [B09] part alone is not symmetric."""
    S = _small_baudet()
    rng = np.random.default_rng(3)
    x = S.X + 0.004 * rng.standard_normal(S.X.shape)
    K = stiffness(S, x).toarray()
    J = _fd_jacobian_of_minus(lambda y: energy_forces(S, y)[1], x, 1e-6)
    assert np.abs(K - J).max() <= 1e-6 * np.abs(K).max()
    Kc = S.term(Corrections.name).stiffness(x).toarray()
    assert np.abs(Kc - Kc.T).max() > 1e-3 * np.abs(Kc).max()


def test_dead_load_energy_is_the_potential_of_its_forces():
    S = build(Scene(Body.box(1, 1, 1, 1.0), Material(10.0, 0.3)))
    f = np.random.default_rng(0).standard_normal(S.X.shape)
    t = DeadLoad(f)
    x = S.X + 0.1
    g = np.array([(t.energy(x + h) - t.energy(x - h)) / 2e-6 for h in 1e-6 * np.eye(x.size).reshape(-1, *x.shape)])
    assert np.allclose(-g, f.ravel(), rtol=1e-8, atol=1e-8)
    assert t.stiffness(x).nnz == 0


# the force-residual solver before it became the residual mode of the static Newton: regression
# baseline (max |u| in m) of the [B09] cantilever below, kept to show the unified solver
# reproduces it to 1e-9
_BEFORE = {1: 0.0016915705849550045, 2: 0.002793129467168809}


def _cantilever(n):
    """[B09]'s cantilever 0.4 × 0.1 × 0.1 m (4n × n × n cells), E = 1 kPa, ν = 0.3, ρ = 0.1 kg/m³,
    clamped at x = 0, under g = 9.81 m/s² along −z."""
    return Scene(Body.box(4 * n, n, n, 0.1 / n), Material(1000.0, 0.3, 0.1), Model("baudet2009"),
                 plates=(Plate("clamp", Region("x-"), Motion("clamped")),), gravity=(0.0, 0.0, -9.81))


@pytest.mark.parametrize("n", [1, 2])
def test_residual_mode_balances_the_loads_and_reproduces_the_force_residual_solver(n):
    scene = _cantilever(n)
    r = solve_static(scene)
    S = build(scene)
    # independent residual: springs + corrections + gravity + dead loads, free dofs only
    f = spring_energy_forces(r.x, S.spring_a, S.spring_b, S.spring_k, S.spring_l0)[1]
    f += S.term(Corrections.name).forces(r.x)
    if S.gravity is not None:
        f += S.mass[:, None] * S.gravity[None, :]
    for t in S.terms:
        if t.scaled:
            f += t.forces(r.x)
    applied = np.abs(f[S.fixed.any(axis=1)]).sum()
    assert np.linalg.norm(f.ravel()[~S.fixed.ravel()]) <= 1e-8 * applied
    # global equilibrium: the plates' reactions balance gravity and the dead loads
    external = sum(t.forces(r.x).sum(axis=0) for t in S.terms if t.scaled) + (
        S.mass.sum() * S.gravity if S.gravity is not None else 0.0)
    total = sum(np.asarray(R.force) for R in r.reactions.values()) + external
    assert np.abs(total).max() <= 1e-8 * np.abs(external).max()
    assert np.abs(r.u).max() == pytest.approx(_BEFORE[n], rel=1e-9)


@pytest.mark.parametrize("experiment,kw", [
    ("compression", dict(deformation=0.0)),
    ("torsion", dict(angle_deg=0.0)),
    ("tension", dict(deformation=0.0, nu=0.45, mesh=(2, 2, 6))),
    ("bending", dict(gravity=0.0, mesh=(2, 2, 6))),
    ("bending", dict(rho=0.0, mesh=(2, 2, 6))),
])
@pytest.mark.parametrize("model", ["hybmss", "hybmss-fd", "baudet2009"])
def test_zero_load_returns_the_rest_state(experiment, kw, model):
    kw = {"mesh": (3, 3, 3), **kw}
    scene = SceneSpec.default(experiment, model=model, **kw).build()
    r = solve_static(scene)
    assert r.converged and np.all(r.u == 0.0)
    floor = force_floor(build(scene))
    assert all(np.abs(R.force).max() <= floor for R in r.reactions.values())


@pytest.mark.parametrize("E", [1e-300, 1e300])
def test_moduli_at_extreme_young_modulus(E):
    m = measure_moduli(Model("hybmss"), Material(E, 0.3))
    assert m["E_eff"] / E == pytest.approx(1.0, rel=1e-6)
    assert m["nu_eff"] == pytest.approx(0.3, rel=1e-6)


@pytest.mark.parametrize("nu", [0.499999, -0.9999, -0.999999])
def test_nu_outside_the_solvable_range_is_refused(nu):
    with pytest.raises(ValueError, match=r"outside \[-0.99, 0.49999\]"):
        measure_moduli(Model("hybmss"), Material(1e4, nu))
    with pytest.raises(ValueError, match="nu="):
        solve_static(SceneSpec.default("compression", nu=nu, mesh=(2, 2, 2)).build())


@pytest.mark.parametrize("nu", NU_RANGE)
def test_moduli_at_the_ends_of_the_range(nu):
    """E to 2e-3 (at ν = −0.99 finite-strain terms grow as G/K), ν to 2e-5, G to 1e-6."""
    m = measure_moduli(Model("hybmss"), Material(1e4, nu))
    assert m["E_eff"] / 1e4 == pytest.approx(1.0, rel=2e-3)
    assert m["nu_eff"] == pytest.approx(nu, abs=2e-5)
    assert m["G_eff"] == pytest.approx(1e4 / (2 * (1 + nu)), rel=1e-6)


def test_moduli_refuse_a_zero_strain():
    with pytest.raises(ValueError, match="strain=0"):
        measure_moduli(Model("hybmss"), Material(1e4, 0.3), strain=0.0)


@pytest.mark.parametrize("dt", [ImplicitOptions().dt, 1e-3])
def test_implicit_euler_converges_at_small_steps(dt):
    """The compression cube (4³, ν = 1/4) whose first steps at dt = 1e-3 used to fail: the inertia
    term's round-off is now part of the convergence floor.  Every step's Newton converges (no
    error); three steps into a 1 s ramp the run is not at rest, so it is not converged."""
    scene = SceneSpec.default("compression", mesh=(4, 4, 4)).build()
    r = simulate_implicit(scene, ImplicitOptions(dt=dt, steps=3, until_rest=False))
    assert r.info["steps"] == 3 and np.abs(r.u).max() > 0 and r.info["newton_iterations"] >= 3
    assert not r.converged and r.info["rest"]["load_factor"] < 1.0


@pytest.mark.parametrize("rest_tol", [1e-3, 1e-6, 1e-8])
def test_implicit_euler_comes_to_rest_at_the_static_solution(rest_tol):
    """At rest by the explicit runs' criterion (force residual and kinetic energy below rest_tol
    of the scene's scales): the state is the static equilibrium to about rest_tol (measured
    1.2, 0.30 and 1.2 times rest_tol)."""
    scene = SceneSpec.default("compression", mesh=(4, 4, 4), rho=1.0, damping=60.0).build()
    st = solve_static(scene)
    im = simulate_implicit(scene, ImplicitOptions(ramp_time=0.5, steps=400, rest_tol=rest_tol))
    assert im.converged and im.info["rest"]["at_rest"] and im.info["time"] < 4.0
    assert im.info["rest"]["relative_residual"] <= rest_tol
    assert np.abs(im.u - st.u).max() <= 5 * rest_tol * np.abs(st.u).max()


def test_implicit_euler_that_ends_before_rest_is_not_converged():
    """The compression cube of ``hybmss compare --solver implicit --steps 5``: five steps of 1 ms
    end before the 1 s ramp (it used to stop there, converged, at a reaction of −1.85 N against
    the static −13,277 N); with the ramp done but the body still moving it is not at rest either."""
    scene = SceneSpec.default("compression", mesh=(2, 2, 2)).build()
    r = simulate_implicit(scene, ImplicitOptions(dt=1e-3, steps=5))
    assert not r.converged and r.info["steps"] == 5 and not r.info["rest"]["at_rest"]
    assert "not at rest after 5 steps" in r.info["warning"] and "load ramp" in r.info["warning"]
    moving = simulate_implicit(scene, ImplicitOptions(dt=1e-2, steps=150, ramp_time=1.0))
    assert moving.info["rest"]["load_factor"] == 1.0 and not moving.converged
    assert moving.info["steps"] == 150


def test_implicit_failure_advice_names_dt_in_the_right_direction():
    from hybmss.solve.implicit import step_error

    S = build(SceneSpec.default("compression", mesh=(2, 2, 2)).build())
    small, large = step_error(S, 1, 1e-3, 1e-3, 1e-6, 0.1), step_error(S, 1, 1e-3, 1e-3, 1.0, 0.1)
    assert "increase dt" in str(small) and "reduce dt" in str(large)
    assert (small.cause, small.step, small.residual) == ("implicit-step", 1, 1e-6)
    # a model without an implicit solver (non-conservative forces) is refused before any step
    with pytest.raises(ValueError, match="has no implicit solver"):
        simulate_implicit(_cantilever(1))


def test_cholesky_factorizer_solves_reuses_its_analysis_and_detects_indefiniteness():
    """CHOLMOD against SuperLU on the constrained Hessian of a stretched beam; the symbolic
    analysis is done once for every numeric factorization of the same pattern; a matrix with a
    negative eigenvalue (shifted by −2 λ_min) is refused (None), and SuperLU takes it."""
    import scipy.sparse as sp

    from hybmss.solve.linalg import Factorizer, cholmod, factor, superlu_symmetric

    if cholmod is None:
        pytest.skip("cvxopt not installed: SuperLU does everything")
    S = build(SceneSpec.default("tension", mesh=(2, 2, 6), nu=0.45).build())
    free = ~S.fixed.ravel()
    fac = Factorizer()
    b = np.random.default_rng(1).standard_normal(np.count_nonzero(free))
    for amp in (0.0, 1e-3, 2e-3):
        x = S.X + amp * np.random.default_rng(2).standard_normal(S.X.shape)
        H = stiffness(S, x)[free][:, free].tocsc()
        F = fac.cholesky(H)
        assert F is not None
        assert np.allclose(F.solve(b), superlu_symmetric(H).solve(b), rtol=1e-10, atol=0)
    assert (fac.symbolic, fac.numeric) == (1, 3)
    lam = np.linalg.eigvalsh(H.toarray())[0]
    Hneg = (H - sp.identity(H.shape[0], format="csc") * (2 * lam)).tocsc()
    assert fac.cholesky(Hneg) is None
    x_neg = factor(Hneg, fac).solve(b)
    assert np.allclose(Hneg @ x_neg, b, rtol=1e-8, atol=1e-8 * np.abs(b).max())
