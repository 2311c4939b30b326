"""Semi-implicit Euler: integrator checks with known answers, stability limit, divergence,
conservation laws and damped settling to the static equilibrium.

Velocities live at half steps: v_{n+½} = v_{n−½} + dt a(x_n), x_{n+1} = x_n + dt v_{n+½}.
For a linear system this is the leapfrog scheme, which conserves exactly the discrete energy
``U(x_n) + ½ Σ m v_{n−½}·v_{n+½}`` (reported as ``energy['kinetic_centred']``).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from hybmss import Body, Material, Model, Motion, Plate, Region, Scene
from hybmss.explicit import DivergenceError, dt_crit, ramp, simulate_explicit
from hybmss.forces import hessian, internal_forces
from hybmss.system import build

EPS = np.finfo(float).eps
KERNELS = ("numba", "numpy")


def _clamped_cube(n=3, nu=0.3, **kw):
    return Scene(Body.box(n, n, n, 0.5), Material(1e4, nu, 1000.0), Model("hybmss"),
                 plates=(Plate("bottom", Region("z-")),), **kw)


# ------------------------------------------------------------------------- harmonic oscillator
def _spring_pair():
    """Two particles joined by one spring along z (the other 6 corners of the cell carry none)."""
    scene = Scene(Body.box(1, 1, 1, 1.0), Material(1e4, 0.25, 1000.0), Model("hybmss-cf"))
    full = build(scene)
    k = float(full.spring_k.max())
    assert tuple(full.lattice.grid[1] - full.lattice.grid[0]) == (0, 0, 1)
    system = dataclasses.replace(
        full, spring_a=np.array([0]), spring_b=np.array([1]), spring_k=np.array([k]),
        spring_l0=np.array([1.0]), spring_family=np.array([0]),
    )
    m = float(system.mass[0])
    return scene, system, math.sqrt(2.0 * k / m)  # relative coordinate: reduced mass m/2


def test_dt_crit_of_a_spring_pair_is_two_over_omega():
    _, system, omega = _spring_pair()
    assert dt_crit(system) == pytest.approx(2.0 / omega, rel=1e-12)


@pytest.mark.parametrize("kernel", KERNELS)
def test_spring_pair_follows_the_discrete_and_the_exact_oscillator(kernel):
    scene, system, omega = _spring_pair()
    delta = 0.01
    x0 = system.X.copy()
    x0[1, 2] += delta
    # 1. the exact solution of the discrete recurrence: q_n = δ (cos nθ − tan(θ/2) sin nθ),
    #    cos θ = 1 − (ω dt)²/2; only round-off separates it from the run.
    h = 0.2
    dt, steps = h / omega, 400
    r = simulate_explicit(scene, dt=dt, steps=steps, kernel=kernel, system=system, x0=x0,
                          compute_dt_crit=False)
    q = r.x[1, 2] - r.x[0, 2] - 1.0
    theta = math.acos(1.0 - h * h / 2.0)
    q_discrete = delta * (math.cos(steps * theta) - math.tan(theta / 2) * math.sin(steps * theta))
    assert abs(q - q_discrete) <= 1e3 * steps * EPS * delta
    assert np.allclose(r.x[2:], system.X[2:], atol=0.0)  # particles without springs stay
    assert np.allclose(r.x[:2, :2], system.X[:2, :2], atol=0.0)  # motion along z only
    # 2. against the continuous solution δ cos ωt: phase error ωt (θ/h − 1) ≈ ωt h²/24 and the
    #    half-step offset of amplitude tan(θ/2) ≈ h/2.
    h = 0.01
    dt = h / omega
    steps = int(round(3 * 2 * math.pi / omega / dt))  # three periods
    r = simulate_explicit(scene, dt=dt, steps=steps, kernel=kernel, system=system, x0=x0,
                          compute_dt_crit=False)
    q = r.x[1, 2] - r.x[0, 2] - 1.0
    t = steps * dt
    bound = delta * (omega * t * h * h / 24.0 + h / 2.0) * (1.0 + h)
    assert abs(q - delta * math.cos(omega * t)) <= bound


# ------------------------------------------------------------------------- stability limit
def test_dt_crit_matches_the_dense_eigenvalue_problem():
    system = build(_clamped_cube(3, 0.45))
    free = ~system.fixed.ravel()
    m3 = np.repeat(system.mass, 3)[free]
    K = hessian(system, system.X).toarray()[np.ix_(free, free)]
    lam = np.linalg.eigvalsh(K / np.sqrt(np.outer(m3, m3)))[-1]
    assert dt_crit(system) == pytest.approx(2.0 / math.sqrt(lam), rel=1e-10)
    # the volume stiffness κ grows as ν → ½, so dt_crit shrinks
    assert dt_crit(_clamped_cube(3, 0.499)) < dt_crit(_clamped_cube(3, 0.45)) < dt_crit(_clamped_cube(3, 0.25))


def _perturbed(system, seed=1, amplitude=1e-3):
    rng = np.random.default_rng(seed)
    return system.X + amplitude * system.scene.body.le * rng.standard_normal(system.X.shape)


def test_energy_is_conserved_at_half_the_stability_limit():
    """Undamped, clamped, perturbed by 1e-3 le: the leapfrog energy is exact for the linearized
    system, so the drift is set by the nonlinearity, O(amplitude/le) = 1e-3 ≪ 1 %."""
    scene = _clamped_cube(3, 0.3)
    system = build(scene)
    dc = dt_crit(system)
    r = simulate_explicit(scene, dt=0.5 * dc, steps=10_000, system=system, x0=_perturbed(system),
                          record_every=500, dt_crit_value=dc)
    h = r.info["history"]
    E = np.array(h["springs"]) + np.array(h["volume"]) + np.array(h["kinetic_centred"])
    assert E[0] > 0
    assert np.max(np.abs(E - E[0])) <= 0.01 * E[0]
    assert r.info["dt_crit"] == dc and r.iterations == 10_000


def _l_shape_scene():
    mask = np.ones((3, 2, 3), dtype=bool)
    mask[0, :, 1:] = False  # absent grid nodes come first, so node and particle indices differ
    return Scene(Body.from_mask(mask, 0.5), Material(1e4, 0.3, 1000.0), Model("hybmss"),
                 plates=(Plate("bottom", Region("z-")),))


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("shape", ["cube", pytest.param("l-shape", marks=pytest.mark.slow)])
def test_run_beyond_the_stability_limit_raises_naming_step_and_particle(kernel, shape):
    scene = _clamped_cube(3, 0.3) if shape == "cube" else _l_shape_scene()
    system = build(scene)
    dc = dt_crit(system)
    with pytest.raises(DivergenceError) as info:
        simulate_explicit(scene, dt=1.2 * dc, steps=10_000, kernel=kernel, system=system,
                          x0=_perturbed(system), compute_dt_crit=False)
    err = info.value
    assert isinstance(err, RuntimeError)
    assert 1 <= err.step <= 10_000
    assert 0 <= err.particle < system.n and err.grid == tuple(system.lattice.grid[err.particle])
    limit = 10 * max(scene.body.size)
    assert not err.displacement <= limit  # the particle named is one that ran away (or NaN)
    u2 = ((err.positions - system.X) ** 2).sum(axis=1)  # state when detected
    bad = np.flatnonzero(~np.isfinite(u2))
    assert err.particle == (bad[0] if len(bad) else np.argmax(u2))
    msg = str(err)
    assert f"step {err.step}" in msg and f"particle {err.particle}" in msg and str(err.grid) in msg
    assert "exceeds the explicit stability limit" in msg and f"dt={1.2 * dc:g}" in msg
    assert err.dt_crit == pytest.approx(dc, rel=1e-9)


def test_divergence_message_quotes_the_body_size():
    """A 2 x 3 x 4 box of 0.05 m cells is 0.2 m at its largest: the message names that size and
    the bound of 10 body sizes, 2 m (it once quoted the bound as the body size)."""
    scene = Scene(Body.box(2, 3, 4, 0.05), Material(1e4, 0.3, 1000.0), Model("hybmss"),
                  plates=(Plate("bottom", Region("z-")),))
    system = build(scene)
    dc = dt_crit(system)
    with pytest.raises(DivergenceError) as info:
        simulate_explicit(scene, dt=1.2 * dc, steps=10_000, kernel="numpy", system=system,
                          x0=_perturbed(system), compute_dt_crit=False, check_every=1)
    msg = str(info.value)
    assert np.isfinite(info.value.displacement) and info.value.displacement > 2.0
    assert "more than 10× the body size of 0.2 m (the bound 2 m)" in msg


def test_a_particle_far_beyond_the_overflow_of_its_square_is_reported_without_warning():
    """A run that ran away to 1e200 m (|u|² overflows) names the distance, finite, with no
    floating-point warning on the way (the message of a diverged dt bisection)."""
    import warnings

    from hybmss.explicit import divergence_error

    system = build(_clamped_cube(2))
    x = system.X.copy()
    x[3] += (1e200, 2e200, -2e200)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        err = divergence_error(system, x, 3, 812, 1e-3, 10.0, 0.5, 100)
    assert err.displacement == pytest.approx(3e200, rel=1e-12)
    assert "moved 3e+200 m" in str(err) and "particle 3" in str(err)


# ------------------------------------------------------------------------- conservation laws
@pytest.mark.parametrize("kernel", KERNELS)
def test_free_body_conserves_momentum_and_angular_momentum(kernel):
    """Internal forces sum to zero and have zero torque, and the update x_{n+1} = x_n + dt v_{n+½}
    keeps Σ m x × v exactly: only round-off remains, bounded by the sums' magnitudes."""
    scene = Scene(Body.box(3, 2, 3, 0.5), Material(1e4, 0.4, 1000.0), Model("hybmss"))
    system = build(scene)
    rng = np.random.default_rng(7)
    x0 = _perturbed(system, seed=3, amplitude=0.05)
    v0 = 0.05 * rng.standard_normal(x0.shape)
    dc = dt_crit(system)
    dt, steps = 0.5 * dc, 1000
    r = simulate_explicit(scene, dt=dt, steps=steps, kernel=kernel, system=system, x0=x0, v0=v0,
                          dt_crit_value=dc)
    m = system.mass[:, None]
    # invariants of the scheme: P = Σ m v_{n−½} and Q = Σ m x_n × v_{n−½}, since
    # Q_{n+1} = Σ m x_n × v_{n+½} (x_{n+1} − x_n ∥ v_{n+½}) = Q_n + dt Σ x_n × f_n = Q_n
    P0 = (m * v0).sum(axis=0)
    L0 = (m * np.cross(x0, v0)).sum(axis=0)
    f0 = np.abs(internal_forces(system, x0)).sum()
    p_scale = (m * np.abs(v0)).sum() + steps * dt * f0
    l_scale = p_scale * np.abs(x0).max()
    xN = r.x
    vN = _final_velocity(scene, system, r, dt, steps, kernel, x0, v0, dc)
    assert np.abs((m * vN).sum(axis=0) - P0).max() <= 100 * EPS * p_scale
    assert np.abs((m * np.cross(xN, vN)).sum(axis=0) - L0).max() <= 100 * EPS * l_scale


def _final_velocity(scene, system, r, dt, steps, kernel, x0, v0, dc):
    """v_{N−½} = (x_N − x_{N−1}) / dt, from a run one step shorter (same kernel, same state)."""
    r1 = simulate_explicit(scene, dt=dt, steps=steps - 1, kernel=kernel, system=system, x0=x0,
                           v0=v0, dt_crit_value=dc)
    return (r.x - r1.x) / dt


# ------------------------------------------------------------------------- damping, plates
@pytest.mark.slow
def test_damped_run_settles_to_the_static_equilibrium():
    """6×6×6 cube, bottom clamped, top pushed down 20 %.  With mass-proportional damping c every
    mode decays at least as exp(−min(c/2, ω²/c)·t); c = 2 ω_min gives the rate ω_min for all modes,
    so 14/ω_min after the ramp leaves e^-14 ≈ 1e-6 of the transient (the 20 % compression shifts
    ω_min by tens of % at most)."""
    from hybmss.solve import solve_static

    side = 1.0
    n = 6
    base = Scene(Body.box(n, n, n, side / n), Material(1e4, 0.3, 1000.0), Model("hybmss"),
                 plates=(Plate("bottom", Region("z-")),
                         Plate("top", Region("z+"), Motion("translate", (0.0, 0.0, -0.2 * side)))))
    system = build(base)
    free = ~system.fixed.ravel()
    m3 = np.repeat(system.mass, 3)[free]
    K = hessian(system, system.X).toarray()[np.ix_(free, free)]
    lam = np.linalg.eigvalsh(K / np.sqrt(np.outer(m3, m3)))
    omega_min, dc = math.sqrt(lam[0]), 2.0 / math.sqrt(lam[-1])
    scene = dataclasses.replace(base, damping=2.0 * omega_min)
    system = build(scene)
    ramp_time = 2.0 * math.pi / omega_min
    dt = 0.5 * dc
    steps = int(math.ceil((ramp_time + 14.0 / omega_min) / dt))
    r = simulate_explicit(scene, dt=dt, steps=steps, ramp_time=ramp_time, system=system,
                          dt_crit_value=dc)
    s = solve_static(scene, system=system)
    assert np.abs(r.x - s.x).max() <= 1e-4 * side
    assert r.info["load_factor"] == 1.0
    top = system.plate("top").particles
    assert np.allclose(r.x[top, 2], side - 0.2 * side, rtol=0, atol=1e-12)
    for name in ("top", "bottom"):
        F, Fs = np.array(r.reactions[name].force), np.array(s.reactions[name].force)
        assert np.linalg.norm(F - Fs) <= 1e-3 * np.linalg.norm(Fs)
    # the plates push the body from both sides: equal and opposite at rest
    assert r.reactions["top"].force[2] < 0 < r.reactions["bottom"].force[2]


@pytest.mark.slow
def test_ramp_law_and_result_fields():
    assert ramp(0.0, 2.0) == 0.0 and ramp(1.0, 2.0) == pytest.approx(0.5) and ramp(2.0, 2.0) == 1.0
    assert ramp(0.3, 0.0) == 1.0
    scene = dataclasses.replace(_clamped_cube(3, 0.3), gravity=(0.0, 0.0, -10.0), damping=2.0)
    r = simulate_explicit(scene, dt=2e-3, steps=50, record_every=25)
    assert r.solver == "mss-explicit" and r.iterations == 50
    assert r.cell_volumes.shape == (27,) and r.volume == pytest.approx(r.cell_volumes.sum())
    assert r.volume0 == pytest.approx(27 * 0.5**3)
    assert set(r.energy) >= {"springs", "volume", "gravity", "kinetic", "kinetic_centred"}
    assert r.info["history"]["t"] == [0.0, 0.05, 0.1]
    assert r.info["dt_crit"] > 0 and r.wall_time_s > 0
    assert "bottom" in r.reactions


@pytest.mark.parametrize(
    "kw, match",
    [({"kernel": "cuda"}, "kernel"), ({"dt": 0.0}, "dt"), ({"steps": -1}, "steps"),
     ({"ramp_time": -1.0}, "ramp_time"), ({"threads": 0}, "threads")],
)
def test_bad_arguments_raise_value_error(kw, match):
    with pytest.raises(ValueError, match=match):
        simulate_explicit(_clamped_cube(2), **kw)


def test_massless_body_is_refused():
    scene = _clamped_cube(2).with_material(rho=0.0)
    with pytest.raises(ValueError, match="rho"):
        simulate_explicit(scene, steps=1, compute_dt_crit=False)
