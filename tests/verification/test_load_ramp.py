"""The plates' load ramp s(t) = ½(1 − cos(π t/T)) of every time-stepping solver, read from the
plate positions part-way through the ramp (a linear ramp t/T puts them elsewhere), and the
reaction history of a slow ramp against the static reactions along the same law."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hybmss.explicit import simulate_explicit
from hybmss.scene import Body, Material, Model, Motion, Plate, Region, Scene
from hybmss.solve import ImplicitOptions, simulate_implicit, solve_static

D = -0.02  # the top plate's displacement at full load (m)


def _smooth(t: float, T: float) -> float:
    return 0.5 * (1.0 - math.cos(math.pi * min(t, T) / T))


def _cube(model: str = "hybmss", rho: float = 1000.0, d: float = D) -> Scene:
    return Scene(Body.box(2, 2, 2, 0.1), Material(1e6, 0.3, rho), Model(model),
                 plates=(Plate("bottom", Region("z-")), Plate("top", Region("z+"), Motion("translate", (0.0, 0.0, d)))))


def _top(r) -> np.ndarray:
    return np.isclose(r.X[:, 2], 0.2)


@pytest.mark.parametrize("n", [1, 3])
def test_implicit_plates_follow_the_smooth_ramp(n):
    """Implicit Euler in steps of T/4: after step n the top plate is at s(n T/4) D (0.146 and 0.854
    of D; a linear ramp gives 0.25 and 0.75)."""
    T, dt = 1.0, 0.25
    r = simulate_implicit(_cube(), ImplicitOptions(dt=dt, steps=n, ramp_time=T, until_rest=False))
    np.testing.assert_allclose(r.u[_top(r), 2], _smooth(n * dt, T) * D, rtol=1e-12, atol=0)
    np.testing.assert_array_equal(r.u[np.isclose(r.X[:, 2], 0.0)], 0.0)


def test_implicit_reactions_follow_the_static_reactions_along_the_ramp():
    """A light body (ρ = 1e-3 kg/m³: inertia ~1e-9 of the stiffness forces) ramped in ten steps is
    quasi-static: its top reaction after step n is the static reaction of the plate moved by
    s(n T/10) D (a linear ramp misses it by up to 60 %)."""
    T, steps = 1.0, 10
    scene = _cube(rho=1e-3)
    for n in (2, 5, 8):
        r = simulate_implicit(scene, ImplicitOptions(dt=T / steps, steps=n, ramp_time=T, until_rest=False))
        s = _smooth(n * T / steps, T)
        static = solve_static(_cube(rho=1e-3, d=s * D)).reactions["top"].force
        np.testing.assert_allclose(r.reactions["top"].force, static, rtol=0, atol=1e-6 * abs(static[2]))


@pytest.mark.parametrize("model,kernel", [("hybmss", "numba"), ("hybmss", "numpy"), ("corot-hex8", "numba"),
                                          ("xpbd-nh", "numba")])
def test_explicit_plates_follow_the_smooth_ramp(model, kernel):
    """After n steps of dt the top plate is at s(n dt) D, also in each model's own integrator; the
    result's load factor is s(n dt)."""
    T, dt, n = 0.02, 1e-3, 7
    r = simulate_explicit(_cube(model), dt=dt, steps=n, ramp_time=T, kernel=kernel)
    np.testing.assert_allclose(r.u[_top(r), 2], _smooth(n * dt, T) * D, rtol=1e-12, atol=0)
    assert r.info["load_factor"] == pytest.approx(_smooth(n * dt, T), rel=1e-14)
