"""An explicit run with ``until_rest`` whose stepper can settle (xpbd-nh: its rest state is the fixed
point of its own substep) ends at that fixed point once the run is at rest, instead of stepping to
the end of its budget: checked against the same run taken to the end (its state, reactions and
verdict), and for a settling that would carry the state to another equilibrium, refused so that the
run is the full run bit for bit."""

from __future__ import annotations

import numpy as np

from hybmss.experiments import SceneSpec
from hybmss.models import xpbd_nh
from studies.sweep.runner import SolverSpec, Task, solve


def _runs(spec: SceneSpec):
    solver = SolverSpec("explicit", dt=1e-3, steps=10_000, ramp_time=1.0)
    full = solve(Task(spec, solver))
    early = solve(Task(spec, SolverSpec("explicit", dt=1e-3, steps=10_000, ramp_time=1.0, until_rest=True)))
    return full, early


def test_a_beam_at_rest_ends_at_the_fixed_point_the_whole_run_reaches():
    """The 2×2×12 beam under gravity (E = 2 MPa): at rest before 10 s.  The full run's state at 10 s
    is still on its way to the fixed point: what the settling moved, decayed at the damping's
    slowest envelope rate σ = c/2 over the rest of the run, ``move · e^(−σ (10 s − t_stop))``.  The
    settled state and the clamp's reaction are the full run's within twice that."""
    spec = SceneSpec.default("bending", mesh=(2, 2, 12), E=2e6, nu=0.25, gravity=10.0, model="xpbd-nh", damping=2.0)
    full, early = _runs(spec)
    assert full.converged and early.converged
    t_stop, settle = early.info["rest_stop_t"], early.info["settle"]
    assert t_stop < 8.0 and early.iterations == round(t_stop / 1e-3) < full.iterations
    assert settle["settle_move"] <= xpbd_nh.SETTLE_MAX_MOVE and not settle.get("refused")
    left = 2.0 * settle["settle_move"] * np.exp(-0.5 * spec.damping * (10.0 - t_stop))
    scale = np.abs(full.u).max()
    assert np.abs(early.u - full.u).max() <= left * scale
    weight = float(np.linalg.norm(full.reactions["bottom"].force))
    assert np.linalg.norm(np.subtract(early.reactions["bottom"].force, full.reactions["bottom"].force)) <= left * weight
    assert early.info["rest"]["kinetic_energy_J"] == 0.0  # the fixed point, loaded at rest


def test_a_settling_to_another_equilibrium_is_refused_and_the_run_goes_on():
    """The 6³ cube compressed by 20 % at ν = 0.499 is at rest at 5 s, but the fixed point reached from
    there is an asymmetric state 45 % away: the settling is refused and the run is the full run."""
    spec = SceneSpec.default("compression", mesh=(6, 6, 6), nu=0.499, deformation=0.2, model="xpbd-nh", damping=2.0)
    full, early = _runs(spec)
    assert early.info["settle"]["refused"] and early.info["settle"]["settle_move"] > xpbd_nh.SETTLE_MAX_MOVE
    assert "rest_stop_t" not in early.info and early.iterations == full.iterations
    assert np.array_equal(early.u, full.u) and early.converged == full.converged


def test_a_stepper_that_cannot_settle_runs_its_whole_budget():
    """``until_rest`` changes nothing for a model whose rest state is not the fixed point of its step
    (the spring lattice): the same steps, the same state."""
    spec = SceneSpec.default("compression", mesh=(4, 4, 4), nu=0.25, deformation=0.05, model="hybmss", damping=2.0)
    full, early = _runs(spec)
    assert early.iterations == full.iterations == 10_000
    assert np.array_equal(early.u, full.u)


def test_until_rest_is_part_of_a_runs_key_only_when_set():
    base = SolverSpec("explicit", dt=1e-3, steps=10_000, ramp_time=1.0)
    assert "until_rest" not in base.relevant()
    assert SolverSpec("explicit", until_rest=True).relevant()["until_rest"] is True


def test_a_run_at_rest_at_the_end_of_its_budget_ends_at_its_fixed_point_whatever_the_interval(monkeypatch):
    """The last step of the budget is tested whatever the rest watch's interval.  The 6³ cube
    sheared 20 % at ν = 0.499 (xpbd-nh, c = 2 s⁻¹) comes to rest between 8 and 10 s.  Tested every
    0.25 s, it stops at the first test at rest; tested every 4 s (at 4 and 8 s), no test falls on
    10 s but the last.  Both end at the same fixed point, reached by the same relaxation to its
    tolerance (:data:`xpbd_nh.REST_TOL` of an edge per check window): measured 3e-8 of the largest
    displacement apart, bound 1e-6.  With the last state left unsettled they were 7.6e-5 apart
    (the plate force of the 10³ cube: 185.24 N against 185.49 N)."""
    import hybmss.explicit.loop as loop
    from hybmss.explicit import simulate_explicit

    spec = SceneSpec.default("shear", mesh=(6, 6, 6), nu=0.499, deformation=0.2, model="xpbd-nh", damping=2.0)
    runs = {}
    for interval in (0.25, 4.0):
        monkeypatch.setattr(loop, "REST_SAMPLE_S", interval)
        runs[interval] = simulate_explicit(spec.build(), dt=1e-3, steps=10_000, ramp_time=1.0, until_rest=True)
    every, sparse = runs[0.25], runs[4.0]
    assert every.converged and sparse.converged
    assert every.info["rest_stop_t"] < 10.0 and sparse.info["rest_stop_t"] == 10.0
    assert not sparse.info["settle"].get("refused")
    assert np.abs(every.u - sparse.u).max() <= 1e-6 * np.abs(every.u).max()
