"""Released transients of models and engines beside the FEM's, with their cost.

:func:`fem_transient` is the reference: the FEM transient (:mod:`fem_reference.transient`) at a
step whose own period error is below ``period_tol``, checked by halving: the step starts where
Newmark's known elongation of the Rayleigh frequency is ``period_tol/4``; the run at ``Δt`` and at
``Δt/2`` give ``T(Δt)`` and ``T(Δt/2)``; for a second-order scheme the error of the finer one is
``|T(Δt) − T(Δt/2)| / 3`` (taken at least Newmark's elongation of the Rayleigh frequency at
``Δt/2``: the measured periods also move with the higher modes' phases) and the step is accepted
when that is below ``period_tol`` (else halved again, at most :data:`MAX_HALVINGS` times).  The finer run is the reference.

:func:`compare_released` steps every model with its own integrator at the step a user would pick
(:func:`hybmss.released.user_step`) and returns the metrics of :mod:`studies.sweep.dynamics` per model with
its wall time per simulated second; a model that cannot run the scene has a row with the reason.
"""

from __future__ import annotations

import math
import os

import numpy as np

from fem_reference.transient import ReleasedFem, newmark_period_ratio, newmark_step_for
from hybmss.released import released_model, released_transient, user_step, with_model
from hybmss.scene import Scene
from hybmss.solve import StaticSolveError
from hybmss.trajectory import Trajectory

from studies.sweep.dynamics import metrics, trajectory_oscillation

MAX_HALVINGS = 4
SAMPLES_PER_PERIOD = 200
"""Samples of a model's point per first period (its step permitting)."""


def largest_static_point(fem: ReleasedFem) -> tuple[float, float, float]:
    """The lattice particle of largest static displacement of ``fem`` (its position)."""
    X = fem.ops.fmesh.lattice.X
    u = fem.static.reshape(-1, 3)[fem.space.particle_dofs]
    k = int(np.argmax(np.linalg.norm(u, axis=1)))
    return tuple(float(c) for c in X[k])


def fem_transient(scene: Scene, point, periods: float = 5.0, period_tol: float = 1e-3, element: str = "hex2",
                  law: str = "linear", refine: int = 1, t_end: float | None = None,
                  fem: ReleasedFem | None = None) -> Trajectory:
    """The FEM reference transient (module docstring) over ``periods`` Rayleigh periods, or up to
    ``t_end`` (s) when given; ``info['dt_check']`` holds the steps, the two periods and the
    estimated period error.  ``fem``: the scene's :class:`ReleasedFem` when already built (its
    static state is then solved once)."""
    fem = ReleasedFem(scene, element, law, refine) if fem is None else fem
    T_est = 2.0 * math.pi / fem.omega_rayleigh
    if t_end is None:
        t_end = float(periods) * T_est * 1.05  # the Rayleigh quotient bounds ω₁ from above
    dt = newmark_step_for(fem.omega_rayleigh, 0.25 * period_tol)
    coarse = fem.run(dt, t_end, point)
    for halving in range(MAX_HALVINGS + 1):
        fine = fem.run(dt / 2, t_end, point)
        a, b = trajectory_oscillation(coarse), trajectory_oscillation(fine)
        if not (a.ok and b.ok):
            raise RuntimeError(f"the FEM transient has no first period: {a.reason or b.reason}")
        # the measured estimate, and never below Newmark's known elongation of ω at the finer step
        err = max(abs(a.period - b.period) / 3.0 / b.period,
                  float(newmark_period_ratio(fem.omega_rayleigh * dt / 2)) - 1.0)
        check = {"dt": dt / 2, "period_dt": a.period, "period_half_dt": b.period, "period_error_estimate": err,
                 "period_tol": period_tol, "halvings": halving, "within_tol": err <= period_tol}
        if err <= period_tol:
            break
        dt, coarse = dt / 2, fine
    fine.info["dt_check"] = check
    return fine


def samples_every(dt: float, substeps: int, period: float) -> int:
    """Steps between two recorded samples: one per frame of an engine, else about
    :data:`SAMPLES_PER_PERIOD` per ``period``."""
    if substeps > 1:
        return substeps  # an engine: one sample per frame
    return max(1, int(period / dt / SAMPLES_PER_PERIOD))


def model_row(scene: Scene, model, ref: Trajectory, point, periods: int) -> dict:
    """The metrics of ``model``'s (a name, run with its engine's released parameters, or a
    :class:`hybmss.scene.Model`) released transient against ``ref`` (:func:`studies.sweep.dynamics.metrics`),
    with its step, substeps per frame and integrator; a model that cannot run has the reason."""
    row = {"model": model if isinstance(model, str) else model.variant, "dt": None, "substeps": None}
    T = trajectory_oscillation(ref).period
    try:
        model = released_model(model)
        dt, sub = user_step(with_model(scene, model))
        row.update(dt=dt, substeps=sub)
        tr = released_transient(scene, model, dt, ref.t_end, point, record_every=samples_every(dt, sub, T))
    except (ValueError, StaticSolveError, RuntimeError) as exc:
        row.update({"reason": f"{type(exc).__name__}: {exc}".splitlines()[0], "period_error": None,
                    "zeta": None, "phase_error_rad": None, "l2_error": None, "wall_per_simulated_s": None})
        return row
    row.update(metrics(tr, ref, periods))
    row["integrator"] = tr.info.get("integrator")
    row["status"] = tr.status
    return row


def compare_released(scene: Scene, models, point, periods: int = 5, period_tol: float = 1e-3,
                     element: str = "hex2", law: str = "linear", refine: int = 1) -> dict:
    """The FEM reference (:func:`fem_transient`) and one row per model (:func:`model_row`): period,
    damping, phase and L2 errors, wall time per simulated second; the load average of the machine
    at the start and the end (cost figures are comparable as ratios within one call)."""
    load0 = os.getloadavg()[0]
    ref = fem_transient(scene, point, periods + 0.5, period_tol, element, law, refine)
    rows = [model_row(scene, m, ref, point, periods) for m in models]
    return {"reference": ref, "rows": rows, "load_average": (load0, os.getloadavg()[0]),
            "fem_wall_per_simulated_s": ref.wall_per_simulated_second()}
