"""An explicit run reports whether it reached rest, against a stated criterion, and the caller
sets its damping.  The rest state is checked against the static solver (an independent method:
Newton on the potential energy)."""

from __future__ import annotations

import numpy as np
import pytest

from hybmss import Body, Material, Model, Motion, Plate, Region, Scene
from hybmss.explicit import dt_crit, simulate_explicit
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


def test_damping_must_be_non_negative():
    with pytest.raises(ValueError, match="damping"):
        _run(_scene(), 0.1, damping=-1.0)
