"""Implicit (backward) Euler with Newton per step (solver name ``mss-implicit``).

With mass-proportional damping c (1/s): ``M (1 + c dt)(x − x_n)/dt² − M v_n/dt = f(x)``, i.e. the
minimizer of the incremental potential ``Φ(x) = (1 + c dt)/(2 dt²) (x − x̃)ᵀ M (x − x̃) + Π(x)``,
``x̃ = x_n + dt v_n/(1 + c dt)`` (:func:`hybmss.solve.newton.newton` with an inertia term).  The
plates follow the explicit runs' load ramp (:func:`hybmss.explicit.ramp`), and a run is
``converged`` when it ends at rest by the explicit runs' criterion
(:func:`hybmss.explicit.rest_report`: the ramp finished, the free force residual and the kinetic
energy small against the scene's own scales), never merely because it ran out of steps.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..explicit import REST_RTOL, ramp, rest_report
from ..forces import energy_forces
from ..result import Result
from ..scene import Scene, check_nu
from ..system import System, build
from .common import make_result
from .errors import StaticSolveError
from .linalg import Factorizer
from .newton import NewtonStats, newton


@dataclass(frozen=True)
class ImplicitOptions:
    dt: float = 1e-2
    steps: int = 1000
    ramp_time: float = 1.0
    until_rest: bool = True
    """Stop at the first step at which the run is at rest (:func:`hybmss.explicit.rest_report`)."""
    rest_tol: float = REST_RTOL
    """``rtol`` of the rest criterion (:func:`hybmss.explicit.rest_report`)."""
    rtol: float = 1e-8
    max_iter: int = 30

    def __post_init__(self):
        if not (self.dt > 0):
            raise ValueError(f"dt (time step) must be > 0 s, got {self.dt}")
        if self.steps < 1:
            raise ValueError(f"steps must be >= 1, got {self.steps}")
        if self.ramp_time < 0:
            raise ValueError(f"ramp_time must be >= 0 s, got {self.ramp_time}")
        if not (self.rest_tol >= 0):
            raise ValueError(f"rest_tol must be >= 0, got {self.rest_tol}")


def step_error(S: System, n: int, t: float, dt: float, rnorm: float, scale: float) -> StaticSolveError:
    """Why Newton failed in step ``n``: a residual already small against the step's forces
    stalled at round-off (the inertia term M/dt² dwarfs the elastic forces: a larger dt helps); a
    large one is a step too big for Newton or a lost equilibrium (a smaller dt helps if not κ < 0)."""
    head = (f"implicit Euler step {n} (t={t:.4g} s) did not converge: residual {rnorm:.3g} N vs "
            f"scale {scale:.3g} N")
    if np.isfinite(rnorm) and rnorm <= 1e-3 * scale:
        why = (f"; Newton stalled at round-off of the inertia term M/dt^2: increase dt={dt:g} s "
               "(or use solve_static for the rest state)")
    elif S.kappa < 0:
        why = (f"; kappa={S.kappa:.4g} Pa < 0 (nu < 1/4): the equilibrium may be lost (check with "
               f"solve_static); otherwise reduce dt={dt:g} s")
    else:
        why = f"; the step is too large for Newton: reduce dt={dt:g} s"
    return StaticSolveError(head + why, cause="implicit-step", residual=float(rnorm), step=n, time=t)


def _check_supported(scene: Scene, S: System) -> None:
    """Refuse (``ValueError``) a model without an implicit solver or a system with
    non-conservative forces: implicit Euler minimizes an incremental potential."""
    model = scene.model.spec
    if "implicit" not in model.solvers:
        raise ValueError(f"model {model.name} has no implicit solver (its solvers: {', '.join(model.solvers)}); "
                         "implicit Euler minimizes an incremental potential")
    if not S.conservative:
        raise ValueError(f"implicit Euler minimizes an incremental potential and model {scene.model.name!r} has "
                         "non-conservative forces (no energy): use simulate_explicit(kernel='numpy') or solve_static")


def _rest(S: System, x: np.ndarray, v: np.ndarray, load: float, rtol: float):
    """``(rest report, total forces, energy parts with the kinetic energy)`` at ``x`` moving at ``v``."""
    _, f, parts = energy_forces(S, x)
    parts = dict(parts)
    parts["kinetic"] = 0.5 * float(np.sum(S.mass[:, None] * v * v))
    f_int = f if S.gravity is None else f - S.mass[:, None] * S.gravity[None, :]
    return rest_report(S, f_int, parts, load, rtol, x), f, parts


def simulate_implicit(scene: Scene, options: ImplicitOptions | None = None,
                      system: System | None = None) -> Result:
    """Backward Euler with Newton per step (solver name ``mss-implicit``).

    The plates follow :func:`hybmss.explicit.ramp` over ``ramp_time``.  With ``until_rest`` the
    run stops at the first step at which it is at rest; ``converged`` says whether the last
    state is at rest (``info['rest']``), so a run that ran out of steps first is not converged.
    Raises ``ValueError`` for a model without an implicit solver, :class:`StaticSolveError` when
    Newton fails in a step."""
    opts = options or ImplicitOptions()
    t0 = time.perf_counter()
    check_nu(scene.material.nu)
    S = system if system is not None else build(scene)
    _check_supported(scene, S)
    free = ~S.fixed.ravel()
    dt, c = opts.dt, scene.damping
    w = S.mass * (1.0 + c * dt) / dt**2
    if np.any(w[~S.fixed.all(axis=1)] <= 0):
        raise ValueError("implicit Euler needs a positive mass on every free particle (rho > 0)")
    x, v = S.X.copy(), np.zeros_like(S.X)
    stats = NewtonStats()
    fac = Factorizer()
    rest = f = parts = None
    n = 0
    for n in range(1, opts.steps + 1):
        t = n * dt
        target = S.prescribed(ramp(t, opts.ramp_time))
        x_tilde = x + dt * v / (1.0 + c * dt)
        guess = x_tilde.copy()
        guess[S.fixed] = target[S.fixed]
        ok, x_new, _, rnorm, scale = newton(S, guess, free, opts.rtol, opts.max_iter, (w, x_tilde), stats, fac=fac)
        if not ok:
            raise step_error(S, n, t, dt, rnorm, scale)
        v = (x_new - x) / dt
        x = x_new
        rest = None
        if opts.until_rest and ramp(t, opts.ramp_time) >= 1.0:
            rest, f, parts = _rest(S, x, v, 1.0, opts.rest_tol)
            if rest["at_rest"]:
                break
    if rest is None:
        rest, f, parts = _rest(S, x, v, ramp(n * dt, opts.ramp_time), opts.rest_tol)
    info = {"steps": n, "dt": dt, "time": n * dt, "newton_iterations": stats.iterations,
            "regularized_steps": stats.regularized, "rest": rest, "at_rest": rest["at_rest"]}
    if not rest["at_rest"]:
        info["warning"] = f"not at rest after {n} steps ({rest['not_at_rest_because']})"
    return make_result(S, "mss-implicit", x, f, parts, n, t0, bool(rest["at_rest"]), info)
