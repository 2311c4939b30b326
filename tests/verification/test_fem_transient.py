"""The FEM transient (Newmark average acceleration, consistent mass) against closed form.

- a linear system's energy ``½ vᵀMv + ½ uᵀKu`` is conserved by the scheme exactly (round-off);
- a body started in its first mode (scipy's generalized eigenpair of the same K and M) oscillates
  with the scheme's known period ``T_num/T = ωΔt / (2 arctan(ωΔt/2))``;
- the released clamped–free bar (ν = 0: one-dimensional) has the tip period ``4L/c``,
  ``c = √(E/ρ)``; the released slender cantilever the Euler–Bernoulli period
  ``2π / (1.8751² √(EI/(ρA L⁴)))`` within its Timoshenko correction and mesh error;
- the Neo-Hookean transient of a tiny load is the linear one (linearization).
"""

import math

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from fem_reference.transient import ReleasedFem, newmark_period_ratio, newmark_step_for
from hybmss.scene import Body, Load, Material, Plate, Scene
from studies.sweep.dynamics import l2_error, trajectory_oscillation

E, RHO = 1e6, 1000.0


def cantilever(nz=4, nu=0.3, traction=1e3, le=0.1):
    """A 1×1×nz cantilever clamped at z = 0, a tip traction along −y."""
    return Scene(Body.box(1, 1, nz, le), Material(E, nu, RHO), plates=(Plate("base", "z-"),),
                 loads=(Load("z+", (0.0, -traction, 0.0)),))


def first_mode(fem):
    f = fem.free
    vals, vecs = spla.eigsh(fem.K[f][:, f].tocsc(), k=1, M=fem.M[f][:, f].tocsc(), sigma=0)
    u0 = np.zeros(len(f))
    u0[f] = vecs[:, 0] * 0.01 / np.abs(vecs[:, 0]).max()
    return math.sqrt(vals[0]), u0


def test_newmark_step_for_inverts_the_period_ratio():
    dt = newmark_step_for(10.0, 1e-3)
    assert newmark_period_ratio(10.0 * dt) - 1.0 == pytest.approx(1e-3, rel=1e-9)
    # (ωΔt)²/12 is the leading term of the elongation
    assert newmark_period_ratio(0.01) - 1.0 == pytest.approx(0.01**2 / 12, rel=1e-3)


def test_linear_energy_is_conserved_to_round_off():
    fem = ReleasedFem(cantilever(), "hex1")
    T = 2 * math.pi / fem.omega_rayleigh
    tr = fem.run(T / 12, 60 * T, (0.05, 0.05, 0.4))
    assert tr.ok and len(tr.t) == 721
    E0 = tr.energy[0]
    assert E0 == pytest.approx(0.5 * fem.static @ (fem.K @ fem.static), rel=1e-12)
    assert np.abs(tr.energy - E0).max() <= 1e-10 * E0


@pytest.mark.parametrize("omega_dt", [0.3, 1.0, 2.0])
def test_first_mode_period_is_newmarks(omega_dt):
    fem = ReleasedFem(cantilever(), "hex1")
    w1, u0 = first_mode(fem)
    T = 2 * math.pi / w1
    ratio = float(newmark_period_ratio(omega_dt))
    tr = fem.run(omega_dt / w1, 40 * T * ratio, (0.05, 0.05, 0.4), u0=u0)
    o = trajectory_oscillation(tr)
    # a pure mode sampled ≥ π/(ωΔt) times a half period: crossings to ~1e-5 T; 80 of them
    assert o.period / T == pytest.approx(ratio, rel=2e-5)
    assert abs(o.zeta) < 1e-6  # no numerical damping


def test_released_bar_has_the_axial_period():
    """Tip of a released clamped–free bar, ν = 0: a triangle wave of period 4L/c.  Its crossings
    move with the higher modes' phase drift, mode 3 (amplitude 1/9 of mode 1) shifting a crossing by
    δt/T ≈ 2φ₃/(9π²) for a phase error φ₃; with ω₁Δt = 0.02 over 10 periods φ₃ ≤ 0.06 (Newmark) +
    0.05 (Hex2's dispersion, (kh)⁴/1440 with kh = 3π/12): δt/T ≤ 2.5e-3 at the end, < 5e-4 on the
    slope fitted to 20 crossings; mode 1's own mesh error is (π/12)⁴/1440 = 3e-6."""
    L, c = 0.6, math.sqrt(E / RHO)
    bar = Scene(Body.box(1, 1, 6, 0.1), Material(E, 0.0, RHO), plates=(Plate("base", "z-"),),
                loads=(Load("z+", (0.0, 0.0, 1e3)),))
    T = 4 * L / c
    w = 2 * math.pi / T
    tr = ReleasedFem(bar, "hex2").run(0.02 / w, 10 * T, (0.05, 0.05, L))
    o = trajectory_oscillation(tr)
    assert o.period / T == pytest.approx(float(newmark_period_ratio(0.02)), abs=1e-3)


def test_released_cantilever_has_the_euler_bernoulli_period():
    """1×1×12 cantilever (L/h = 12), Hex2, ν = 0.3.  Timoshenko's shear and rotary inertia lower
    ω₁ by δ ≈ ½ (β₁L)² (r/L)² (1 + E/(κG)) (κ = 5/6): 0.4 %; one Hex2 element per thickness
    differs from two by 0.3 %: the period agrees with Euler–Bernoulli's (times Newmark's ratio)
    within δ + 0.5 %."""
    nz, h = 12, 0.1
    L = nz * h
    sc = cantilever(nz, traction=1e2)
    I, A = h**4 / 12, h * h
    w_eb = 1.8751**2 * math.sqrt(E * I / (RHO * A * L**4))
    G = E / (2 * 1.3)
    delta = 0.5 * 1.8751**4 * (I / A / L**2) * (1 + E / (5 / 6 * G))
    T = 2 * math.pi / w_eb
    tr = ReleasedFem(sc, "hex2").run(0.05 / w_eb, 12 * T, (0.05, 0.05, L))
    o = trajectory_oscillation(tr)
    assert o.period / (T * float(newmark_period_ratio(0.05))) == pytest.approx(1.0, abs=delta + 5e-3)


def test_neo_hookean_small_load_follows_the_linear_transient():
    """A tiny load (tip deflection ~1e-5 of the length): the Neo-Hookean transient equals the
    linear one up to the strain, O(1e-5)."""
    sc = cantilever(traction=0.1)
    lin, nh = ReleasedFem(sc, "hex1"), ReleasedFem(sc, "hex1", "neo-hookean")
    T = 2 * math.pi / lin.omega_rayleigh
    a = lin.run(T / 20, 2 * T, (0.05, 0.05, 0.4))
    b = nh.run(T / 20, 2 * T, (0.05, 0.05, 0.4))
    assert b.ok and b.info["newton_iterations"] > 0
    assert np.abs(a.u).max() < 1e-4 * 0.4
    assert l2_error(b, a) < 1e-4
    # a large load: the finite-strain response differs measurably (the check can fail)
    big = cantilever(traction=1e3)
    a = ReleasedFem(big, "hex1").run(T / 20, T, (0.05, 0.05, 0.4))
    b = ReleasedFem(big, "hex1", "neo-hookean").run(T / 20, T, (0.05, 0.05, 0.4))
    assert l2_error(b, a) > 1e-3


def test_refusals():
    with pytest.raises(ValueError, match="element"):
        ReleasedFem(cantilever(), "mixed")
    with pytest.raises(ValueError, match="no load"):
        ReleasedFem(Scene(Body.box(1, 1, 2, 0.1), Material(E, 0.3, RHO), plates=(Plate("base", "z-"),)))
    with pytest.raises(ValueError, match="dt"):
        ReleasedFem(cantilever(), "hex1").run(0.0, 1.0, (0, 0, 0))
