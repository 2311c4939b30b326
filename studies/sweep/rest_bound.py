"""The fewest steps an explicit run needs to come to rest, known before the run: a run whose step
budget is below it cannot answer and is not computed (:func:`skip_reason`, used by the runner).

**The step.**  The harness's explicit loop (:mod:`hybmss.explicit`) takes the mass-proportional
damping c implicitly::

    v ← (v + dt (f(x)/m + g)) / (1 + c dt),    x ← x + dt v.

On a mode of frequency ω (deviation e from the equilibrium, ë = −ω² e − c ė) one step maps
(e, v) by a matrix of trace ``1 + d − d ω² dt²`` and determinant ``d = 1/(1 + c dt)``, so its
eigenvalues solve ``λ² − (1 + d − d ω² dt²) λ + d = 0``.  A mode with complex roots
(underdamped, about ω > c/2) shrinks by exactly ``|λ| = √d`` a step, whatever ω: mass-proportional
damping gives every such mode the decay rate ``ζ ω = c/2`` (time constant 2/c).  A mode with real
roots (overdamped, ω < c/2) creeps with its larger root ``ρ > √d`` (``≈ 1 − ω² dt / c``: the time
constant c/ω²).  :func:`step_factor` is that largest ``|λ|``; it does not grow as ω falls, so
the lowest mode is the slowest.

**The bound** (:func:`steps_to_rest`).  At rest (:func:`hybmss.explicit.rest_report`) means the
load ramp complete, ``s(n dt) = 1 ⇔ n dt ≥ T``, and the deviation within ``rtol`` of the load's
own scale.  A deviation of relative size ``a₀`` after the ramp then needs at least
``ln(a₀ / (2 rtol)) / (−ln ρ₁)`` steps more (``2 rtol``: the rest test bounds the force residual
and the kinetic energy each by ``rtol``, together the deviation's energy norm by ``√2 rtol``; the
other factor √2 covers the step's departure from that norm, ω dt and ζ up to critical).  ``a₀``
must be a *lower* bound of the deviation, or the bound would skip a run that comes to rest: a
sudden load (``T = 0``) on a single-mode body starts it a whole static displacement away
(``a₀ = 1``); a smooth ramp can leave every mode nearly at rest (its jolt s̈ ≈ π²/(2T²) against
ω₁²: 2·10⁻⁴ of the static displacement for the 1 m cube's ω₁ ≈ 150 s⁻¹), so a ramped load has
``a₀ = 0`` and only the ramp counts.  The bound is conservative by construction: it never
exceeds the steps the run would need.
"""

from __future__ import annotations

import math

REST_RTOL = 1e-3
"""The rest test's tolerance (:data:`hybmss.explicit.REST_RTOL`)."""


def step_factor(omega: float, c: float, dt: float) -> float:
    """The largest ``|λ|`` of one damped step on a mode of frequency ``omega`` (module docstring)."""
    d = 1.0 / (1.0 + c * dt)
    tr = 1.0 + d - d * (omega * dt) ** 2
    disc = tr * tr - 4.0 * d
    if disc <= 0.0:
        return math.sqrt(d)
    return max(abs(tr + math.sqrt(disc)), abs(tr - math.sqrt(disc))) / 2.0


def ramp_steps(dt: float, ramp_time: float) -> int:
    """Steps until the load ramp is complete: the fewest n with ``n dt ≥ T`` (0 without ramp),
    in the rest test's own arithmetic (:func:`hybmss.explicit.ramp` at ``n dt``)."""
    if ramp_time <= 0.0:
        return 0
    n = max(int(math.floor(ramp_time / dt)) - 1, 0)
    while n * dt < ramp_time:
        n += 1
    return n


def decay_steps(omega: float, c: float, dt: float, a0: float, rtol: float = REST_RTOL) -> int:
    """Steps the slowest mode (``omega``) needs to shrink from ``a0`` to the rest test's ``2 rtol``."""
    target = 2.0 * rtol
    if not a0 > target:
        return 0
    rho = step_factor(omega, c, dt)
    if rho >= 1.0:
        return 10**18  # no decay: never at rest
    return int(math.ceil(math.log(a0 / target) / -math.log(rho)))


def steps_to_rest(dt: float, ramp_time: float, omega1: float = math.inf, c: float = 0.0, a0: float = 0.0,
                  rtol: float = REST_RTOL) -> int:
    """A lower bound of the steps a run needs to come to rest: the ramp, then the decay of a
    deviation of at least ``a0`` in its slowest mode ``omega1`` (module docstring)."""
    extra = decay_steps(omega1, c, dt, a0, rtol) if a0 > 0.0 else 0
    return ramp_steps(dt, ramp_time) + extra


def skip_reason(task) -> str:
    """Why ``task`` is not run: ``""`` unless it is a run that only an answer at rest makes useful
    (``task.answer_only``) and a time-stepping run (explicit) whose step budget is below
    :func:`steps_to_rest` (its ramp: the studies' loads are ramped, ``a₀ = 0``)."""
    s = task.solver
    if not getattr(task, "answer_only", False) or s.kind != "explicit":
        return ""
    need = steps_to_rest(s.dt, s.ramp_time)
    if s.steps >= need:
        return ""
    return (f"not at rest after {s.steps} steps: not run, it needs at least {need} steps to come to rest "
            f"(the load ramp of {s.ramp_time:g} s at dt {s.dt:g} s) and its budget is {s.steps}")


def skipped_row(task, base: dict, reason: str) -> dict:
    """The row of a run not computed (``base``: the fields that describe it,
    :func:`studies.sweep.runner.base_row`): status "not-converged" (a time-stepping run not at rest, an
    expected non-answer), ``reason``, no result and no cost; the critical step where the model has
    one (cheap, and no result of the run)."""
    row = {**base, "status": "not-converged", "message": reason, "skipped": True, "steps": 0, "elapsed_s": 0.0}
    try:
        from hybmss import models
        from hybmss.explicit import dt_crit
        from hybmss.system import build

        if models.get(task.scene.model).explicit_limit:
            row["dt_crit"] = float(dt_crit(build(task.scene.build())))
    except Exception:  # noqa: BLE001 - the limit is an extra; the row stands without it
        pass
    return row
