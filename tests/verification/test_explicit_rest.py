"""An explicit run reports whether it reached rest, against a stated criterion, and the caller
sets its damping.  The rest state is checked against the static solver (an independent method:
Newton on the potential energy)."""

from __future__ import annotations

import numpy as np
import pytest

from hybmss import Body, Material, Model, Motion, Plate, Region, Scene
from hybmss.explicit import dt_crit, rest_report, simulate_explicit
from hybmss.forces import internal_forces
from hybmss.solve import solve_static
from hybmss.system import build


def _scene(damping=0.0):
    body = Body.box(2, 2, 2, 0.5)
    return Scene(body, Material(1e4, 0.3, 1000.0), Model("hybmss"),
                 plates=(Plate("bottom", Region("z-")),
                         Plate("top", Region("z+"), Motion("translate", (0.0, 0.0, -0.05)))),
                 damping=damping)


def _run(scene, t_end, **kw):
    system = build(scene)
    dc = dt_crit(system)
    dt = 0.5 * dc
    return simulate_explicit(scene, dt=dt, steps=int(np.ceil(t_end / dt)), ramp_time=2.0, kernel="numpy",
                             system=system, dt_crit_value=dc, **kw)


def test_undamped_run_is_not_at_rest():
    r = _run(_scene(), 6.0)
    rest = r.info["rest"]
    assert not r.converged and not rest["at_rest"]
    assert rest["relative_residual"] > rest["rtol"] or rest["relative_kinetic_energy"] > rest["rtol"] ** 2
    assert "kinetic energy" in rest["not_at_rest_because"] or "residual" in rest["not_at_rest_because"]


def test_unfinished_ramp_is_not_at_rest():
    r = _run(_scene(damping=20.0), 1.0)
    assert not r.converged and "ramp" in r.info["rest"]["not_at_rest_because"]


def test_damped_run_comes_to_rest_at_the_static_equilibrium():
    scene = _scene()
    r = _run(scene, 25.0, damping=8.0)
    rest = r.info["rest"]
    assert r.converged and rest["at_rest"], rest
    assert rest["not_at_rest_because"] is None
    assert r.info["damping"] == 8.0
    # the result is keyed by the scene it actually ran: the one with that damping
    assert r.scene_digest == _scene(damping=8.0).digest() != scene.digest()
    s = solve_static(scene)
    F, Fs = r.reactions["top"].force[2], s.reactions["top"].force[2]
    assert F == pytest.approx(Fs, rel=3 * rest["rtol"])
    assert np.abs(r.u - s.u).max() <= 3e-3 * np.abs(s.u).max()


def test_rest_asks_a_kinetic_energy_below_rtol_squared_of_the_energy_scale():
    """A vibration of relative amplitude a about the equilibrium has a kinetic energy of order
    a² times the energy scale, so rest asks for ``ke ≤ rtol² · max(|elastic energy|, force scale ·
    le)``.  At the static equilibrium (Newton: an independent method), with its reaction and
    elastic energy giving the scale, a kinetic energy of (2 rtol)² times it is not rest, one of
    (rtol/2)² is."""
    scene = _scene()
    s = solve_static(scene)
    system = build(scene)
    x = s.X + s.u
    f_int = internal_forces(system, x)
    e_scale = max(sum(s.energy.values()), abs(s.reactions["top"].force[2]) * scene.body.le)
    rtol = 1e-3
    for a, at_rest in ((0.5 * rtol, True), (2.0 * rtol, False)):
        rest = rest_report(system, f_int, {**s.energy, "kinetic": a * a * e_scale}, 1.0, rtol, x)
        assert rest["at_rest"] is at_rest, rest
        assert rest["relative_kinetic_energy"] == pytest.approx(a * a, rel=1e-6)


def test_damping_must_be_non_negative():
    with pytest.raises(ValueError, match="damping"):
        _run(_scene(), 0.1, damping=-1.0)
