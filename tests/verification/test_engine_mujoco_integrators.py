"""MuJoCo's integrators (the ``integrator`` parameter of the ``mujoco-*`` models) against their
closed forms on a linear mode of the engine's own forces.

A 1×1×2 cantilever of ``mujoco-tet`` is started in the first mode of its linearized system
(MuJoCo's ``qfrc_spring`` differentiated by central differences at rest, the nodes' lumped masses,
the plate nodes held) at an amplitude of 1e-6 of the cell edge (the SVK nonlinearity ~1e-6 of the
force) and released.  For ``ẍ = −ω² x`` and a step ``h`` (``z = ω h``):

- ``Euler`` (semi-implicit): ``T = 2π h / (2 arcsin(z/2))``, no decay;
- ``RK4``: per step ``R = Σ_{k≤4} (iz)^k / k!``, ``T = 2π h / arg R``, decay ``|R|`` per step;
- ``discrete`` (``M + h D + h² K``, implicit in position): backward Euler, ``g = 1/(1 + iz)``,
  ``T = 2π h / atan z``, decay ``|g|`` per step.

The damping ratio of a decay ``|G|`` per step over a period ``T``: ``δ = −ln|G| · T/h``,
``ζ = δ / √(4π² + δ²)``.  Tolerances: the period to 5e-6 relative (measured residual ≤ 5e-7: the
central-difference stiffness is symmetric to 1e-10 and the crossing interpolation of a sampled
sinusoid is exact to O(z³) of its curvature, zero at a crossing), below the smallest integrator
effect resolved (RK4's elongation 2.3e-5 at z = 0.23, Euler's −1.1e-3, discrete's 3.3e-3);
``discrete``'s ζ (0.050) to 1e-3 relative, RK4's (4.5e-6) to 1e-6 absolute (the parabola peaks
of 10 periods resolve ln A to ~1e-5), Euler's below 1e-6.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg as sla

pytest.importorskip("mujoco")

from hybmss.released import (FRAME, UNLIMITED_SUBSTEPS, _stepper, released_model,  # noqa: E402
                             released_scene, released_transient, user_step, with_model)
from hybmss.scene import Body, Material, Model, Plate, Scene  # noqa: E402
from hybmss.system import build  # noqa: E402
from studies.sweep.dynamics import trajectory_oscillation  # noqa: E402

TIP = (0.05, 0.05, 0.2)


def cantilever() -> Scene:
    return Scene(Body.box(1, 1, 2, 0.1), Material(1e6, 0.3, 1000.0), plates=(Plate("base", "z-"),),
                 gravity=(0.0, -10.0, 0.0), model="mujoco-tet")


def engine_modes(integrator: str):
    """ω (ascending), the first mode (nodes × 3), the nodes' reference positions and the stepper."""
    sc = with_model(cantilever(), Model("mujoco-tet", integrator=integrator))
    st = _stepper(build(released_scene(sc)), 1e-4, None, None)
    X = st.nodes.X
    free = np.flatnonzero(~st.nodes.fixed.ravel())
    eps = 1e-8
    K = np.zeros((X.size, X.size))
    for j in free:
        d = np.zeros(X.size)
        d[j] = eps
        fp = st.internal_forces(X + d.reshape(-1, 3))
        fm = st.internal_forces(X - d.reshape(-1, 3))
        K[:, j] = -(fp - fm).ravel() / (2 * eps)
    Kf = K[np.ix_(free, free)]
    assert np.abs(Kf - Kf.T).max() < 1e-8 * np.abs(Kf).max()
    w2, V = sla.eigh(0.5 * (Kf + Kf.T), np.diag(np.repeat(st.nodes.mass, 3)[free]))
    phi = np.zeros(X.size)
    phi[free] = V[:, 0]
    return np.sqrt(w2), phi.reshape(-1, 3), X, st


def zeta_of(decay_per_step: float, T: float, h: float) -> float:
    delta = -math.log(decay_per_step) * T / h
    return delta / math.sqrt(4 * math.pi**2 + delta**2)


def closed_form(integrator: str, w: float, h: float) -> tuple[float, float]:
    """(period, damping ratio) of the integrator for the mode ω at step h (module docstring)."""
    z = w * h
    if integrator == "Euler":
        return 2 * math.pi * h / (2 * math.asin(z / 2)), 0.0
    if integrator == "RK4":
        R = sum((1j * z) ** k / math.factorial(k) for k in range(5))
        T = 2 * math.pi * h / abs(np.angle(R))
        return T, zeta_of(abs(R), T, h)
    T = 2 * math.pi * h / math.atan(z)
    return T, zeta_of(1.0 / abs(1 + 1j * z), T, h)


@pytest.mark.parametrize("integrator", ["Euler", "RK4", "discrete"])
def test_released_mode_keeps_the_integrators_period_and_decay(integrator):
    w, phi, X, st = engine_modes(integrator)
    # Euler and RK4 at 0.9 of their limits on ω_max (2 and 2√2), discrete at ω₁h = 0.1
    h = {"Euler": 1.8 / w[-1], "RK4": 1.8 * math.sqrt(2) / w[-1], "discrete": 0.1 / w[0]}[integrator]
    T, zeta = closed_form(integrator, w[0], h)
    start = X + 1e-7 * phi / np.abs(phi).max()
    tr = released_transient(cantilever(), Model("mujoco-tet", integrator=integrator), h, 10 * T, TIP, start=start)
    assert tr.ok and tr.info["integrator"] == integrator
    o = trajectory_oscillation(tr)
    assert o.period == pytest.approx(T, rel=5e-6)
    if integrator == "discrete":
        assert o.zeta == pytest.approx(zeta, rel=1e-3)
    else:
        assert abs(o.zeta - zeta) < 1e-6
    assert abs(T * w[0] / (2 * math.pi) - 1.0) > 2e-5  # the integrator's own period error is resolved


def test_integrator_parameter_and_released_choice():
    assert Model("mujoco-tet").integrator == "Euler"  # the static runs' default
    for bad in ("implicitfast", "implicit"):
        with pytest.raises(ValueError, match="integrator.*discrete"):
            Model("mujoco-tet", integrator=bad)
    with pytest.raises(ValueError, match="integrator must be one of"):
        Model("mujoco-tet", integrator="Verlet")
    m = released_model("mujoco-trilinear")
    assert m.integrator == "discrete" and m.variant == "mujoco-trilinear (discrete)"
    assert released_model("hybmss").name == "hybmss"
    # discrete has no stability limit: the frame cut into the unlimited scheme's substeps
    assert user_step(with_model(cantilever(), m)) == (FRAME / UNLIMITED_SUBSTEPS, UNLIMITED_SUBSTEPS)
    dt, n = user_step(with_model(cantilever(), Model("mujoco-tet", integrator="RK4")))
    dt_e, n_e = user_step(with_model(cantilever(), Model("mujoco-tet")))
    assert n < n_e and dt > dt_e  # RK4's limit is √2 times Euler's
