"""Released transients of the models against their integrators' closed forms.

- symplectic Euler (the harness's explicit loop) conserves the time-centred energy of a linear
  system exactly and a nonlinear one's to a bounded error: no drift over 1,000 periods of the
  lattice of a small body at small amplitude;
- its period of a mode ω is ``T_num = 2π Δt / (2 arcsin(ωΔt/2))``: the hybmss lattice started in its
  first mode (the generalized eigenproblem of its Hessian with its lumped masses) keeps it, and
  released from its static state under gravity its first period is that one within the higher
  modes' share;
- implicit Euler's step multiplies a mode by ``g = 1/(1 + iωΔt)``: the decay per period the
  metrics measure equals ``|g|^(T_num/Δt)``.
"""

import math

import numpy as np
import pytest
import scipy.linalg as sla

from hybmss.explicit import dt_crit
from hybmss.forces import hessian
from hybmss.released import USER_CFL, released_scene, released_transient, static_state, user_step, with_model
from hybmss.scene import Body, Material, Plate, Scene
from hybmss.system import build
from hybmss.trajectory import Trajectory
from studies.sweep.dynamics import oscillation, trajectory_oscillation

TIP = (0.05, 0.05, 0.6)


def cantilever(nz=6, model="hybmss"):
    return Scene(Body.box(1, 1, nz, 0.1), Material(1e6, 0.3, 1000.0), plates=(Plate("base", "z-"),),
                 gravity=(0.0, -10.0, 0.0), model=model)


def lattice_modes(scene):
    """ω and mode shapes (particles × 3) of the released lattice: Hessian at rest, lumped masses."""
    S = build(released_scene(scene))
    K = hessian(S, S.X).toarray()
    m = np.repeat(S.mass, 3)
    free = ~S.fixed.ravel()
    w2, V = sla.eigh(K[np.ix_(free, free)], np.diag(m[free]))
    modes = np.zeros((len(w2), 3 * S.n))
    modes[:, free] = V.T
    return np.sqrt(w2), modes.reshape(len(w2), S.n, 3), S


def symplectic_period(w, dt):
    return 2 * math.pi * dt / (2 * math.asin(0.5 * w * dt))


def test_symplectic_euler_energy_is_bounded_over_1000_periods():
    sc = cantilever(nz=2)
    w, modes, S = lattice_modes(sc)
    dt = USER_CFL * dt_crit(S)
    T = symplectic_period(w[0], dt)
    start = S.X + 1e-6 * modes[0] / np.abs(modes[0]).max()  # linear regime
    steps = int(1000 * T / dt)
    tr = released_transient(sc, "hybmss", dt, steps * dt, (0.05, 0.05, 0.2), record_every=7, start=start)
    assert tr.ok and tr.t[-1] >= 1000 * T - dt
    E0 = tr.energy[0]
    err = np.abs(tr.energy - E0) / E0
    n = len(err) // 10
    assert err.max() < 1e-6  # bounded: the centred energy is the scheme's invariant of the linearized system
    assert err[-n:].max() < 2 * err[:n].max() + 1e-9  # no drift from the first to the last 100 periods


def test_lattice_keeps_its_modal_period_from_a_mode():
    sc = cantilever()
    w, modes, S = lattice_modes(sc)
    dt = USER_CFL * dt_crit(S)
    T = symplectic_period(w[0], dt)
    start = S.X + 1e-6 * modes[0] / np.abs(modes[0]).max()
    tr = released_transient(sc, "hybmss", dt, 20 * T, TIP, start=start)
    o = trajectory_oscillation(tr)
    # ω₁Δt = 0.025 here: the scheme shortens the period by (ω₁Δt)²/24 = 2.6e-5, resolved to 2e-6
    assert o.period == pytest.approx(T, rel=2e-6)
    assert abs(o.period * w[0] / (2 * math.pi) - 1.0) > 1e-5


def test_released_lattice_first_period_is_its_modal_period():
    """Released from its static state under gravity: mode 1 carries most of the tip motion, the
    bending mode 2 (ω₂ ≈ 6 ω₁) shifts crossings by at most its share of the tip amplitude over
    2π; the fitted period agrees with mode 1's within 1 %."""
    sc = cantilever()
    w, modes, S = lattice_modes(sc)
    dt, sub = user_step(with_model(sc, "hybmss"))
    assert sub == 1 and dt == pytest.approx(USER_CFL * dt_crit(S))
    T = symplectic_period(w[0], dt)
    tr = released_transient(sc, "hybmss", dt, 10 * T, TIP)
    x_s = static_state(sc)
    assert np.allclose(tr.u[0], (x_s - S.X)[np.argmin(np.linalg.norm(S.X - TIP, axis=1))])
    o = trajectory_oscillation(tr)
    assert o.period == pytest.approx(T, rel=0.01)
    assert abs(o.zeta) < 2e-3  # symplectic Euler adds no damping


def implicit_euler(w, dt, steps, x0=1.0):
    """Backward Euler of ẍ = −ω²x: (x, v)_{n+1} = A⁻¹ (x, v)_n, A = [[1, −Δt], [ω²Δt, 1]]."""
    A = np.array([[1.0, -dt], [w * w * dt, 1.0]])
    step = np.linalg.inv(A)
    z = np.array([x0, 0.0])
    out = [z[0]]
    for _ in range(steps):
        z = step @ z
        out.append(z[0])
    return np.array(out)


@pytest.mark.parametrize("w_dt", [0.02, 0.1, 0.2])
def test_implicit_euler_decay_is_its_amplification_factor(w_dt):
    w = 2 * math.pi
    dt = w_dt / w
    T_num = 2 * math.pi * dt / math.atan(w_dt)  # arg g = −atan(ωΔt) per step
    steps = int(5 * T_num / dt)
    x = implicit_euler(w, dt, steps)
    t = dt * np.arange(steps + 1)
    o = oscillation(t, x)
    g = 1.0 / abs(1 + 1j * w_dt)
    delta = -math.log(g) * T_num / dt  # decay per period ln(A_k / A_{k+1})
    zeta = delta / math.sqrt(4 * math.pi**2 + delta**2)
    assert o.period == pytest.approx(T_num, rel=1e-3)
    assert o.zeta == pytest.approx(zeta, rel=2e-3)


def test_a_diverged_run_is_kept_with_its_reason():
    sc = cantilever(nz=2)
    S = build(released_scene(sc))
    tr = released_transient(sc, "hybmss", 3.0 * dt_crit(S), 0.5, (0.05, 0.05, 0.2))
    assert tr.status == "diverged" and "body sizes" in tr.reason
    assert isinstance(tr, Trajectory) and "diverged" in trajectory_oscillation(tr).reason


def test_refusals():
    sc = cantilever(nz=2)
    with pytest.raises(ValueError, match="dt"):
        released_transient(sc, "hybmss", -1.0, 1.0, (0, 0, 0))
    with pytest.raises(ValueError, match="no load"):
        released_transient(Scene(sc.body, sc.material, plates=sc.plates), "hybmss", 1e-3, 1.0, (0, 0, 0))
