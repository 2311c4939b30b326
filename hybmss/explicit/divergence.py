"""Divergence of an explicit run: a non-finite position or a displacement beyond
:data:`BLOWUP_FACTOR` body sizes, ``|x_a − X_a| > BLOWUP_FACTOR · max(body size)``, raised as a
:class:`DivergenceError` that names the step, the particle and the likely cause
(:func:`divergence_cause`: the time step against ``dt_crit``, a singular force, or a motion that
ran away)."""

from __future__ import annotations

import math

import numpy as np

from .limits import dt_crit

BLOWUP_FACTOR = 10.0
"""A displacement beyond this many body sizes (largest bounding-box edge) counts as divergence."""


class DivergenceError(RuntimeError):
    """An explicit run left the physical range (non-finite values or a runaway displacement).

    Attributes: ``step`` (1-based step at which it was detected), ``particle`` (index),
    ``grid`` (its integer grid coordinates), ``displacement`` (its |u|, m; nan or inf if not
    finite), ``positions`` (n, 3) when detected, ``dt`` and ``dt_crit``.  The particle is the
    first with a non-finite position, else the one with the largest displacement.
    """

    def __init__(self, message, *, step, particle, grid, displacement, dt, dt_crit, positions=None):
        super().__init__(message)
        self.positions = positions
        self.step = step
        self.particle = particle
        self.grid = grid
        self.displacement = displacement
        self.dt = dt
        self.dt_crit = dt_crit


def find_bad(x: np.ndarray, X: np.ndarray, limit2: float) -> int:
    """NumPy twin of :func:`hybmss._kernels.find_bad` on (n, 3) arrays: the first particle with a
    non-finite displacement, else the farthest if its squared displacement exceeds ``limit2``,
    else −1."""
    u2 = np.einsum("ij,ij->i", x - X, x - X)
    bad = np.flatnonzero(~np.isfinite(u2))
    if len(bad):
        return int(bad[0])
    i = int(np.argmax(u2))
    return i if u2[i] > limit2 else -1


NEAR_LIMIT = 0.5
"""A step above this fraction of ``dt_crit`` at rest is named as the likely cause of a divergence
(:func:`divergence_cause`): a deformed body can be stiffer than at rest, so such a step can be
unstable there although it is stable at rest."""


def divergence_cause(system, x, dt: float, dt_c: float | None, model) -> str:
    """The likely cause of a divergence at positions ``x``, for the message of
    :func:`divergence_error`.  The time step is named only when it is above :data:`NEAR_LIMIT` of the
    stability limit at rest; a step far below it is said not to be the cause.  Then a non-finite
    position while every other particle stayed within one body size of rest is a singular force (a
    zero-length spring, a degenerate cell) in a bounded state, not a motion that ran away."""
    u = np.asarray(x, dtype=float) - system.X
    finite = np.isfinite(u).all(axis=1)
    size = max(system.scene.body.size)
    moved = float(np.hypot.reduce(u[finite], axis=1).max()) if finite.any() else math.inf
    singular = not finite.all() and moved <= size
    if dt_c is None:
        return (f"the motion itself ran away ({model.name} has no explicit stability limit): large "
                "deformation or a plate ramp too fast; reduce dt or lengthen the ramp")
    if math.isnan(dt_c):
        return (f"unknown (dt_crit could not be computed); check dt={dt:g} s against the explicit "
                "stability limit 2/√λmax(M⁻¹K)")
    if dt > dt_c:
        return f"time step dt={dt:g} s exceeds the explicit stability limit dt_crit≈{dt_c:.4g} s"
    if dt > NEAR_LIMIT * dt_c:
        return (f"time step dt={dt:g} s is {dt / dt_c:.2f} of the stability limit dt_crit≈{dt_c:.4g} s at "
                "rest, and a deformed body can be stiffer than at rest; reduce dt")
    not_dt = f"not the time step: dt={dt:g} s is {dt_c / dt:.3g}× below the stability limit dt_crit≈{dt_c:.4g} s at rest"
    if singular:
        return (f"a non-finite force in a bounded state (the other particles within {moved:.3g} m of rest), "
                f"i.e. a singular configuration such as two particles at one point or a degenerate cell; {not_dt}")
    return (f"the motion itself ran away, {not_dt}: large deformation (inverted cells, a plate ramp too "
            "fast) or a volume energy with κ < 0 (ν < 1/4) that rewards dilation")


def divergence_error(system, x, particle, step, dt, limit, dt_c, check_every, model=None):
    """The :class:`DivergenceError` of a run that left the physical range at ``step``."""
    model = system.scene.model.spec if model is None else model
    grid = tuple(int(g) for g in system.lattice.grid[particle])
    u = x[particle] - system.X[particle]
    unorm = float(np.hypot.reduce(u))  # no overflow of the squares: a run away can reach 1e200 m
    if not np.all(np.isfinite(u)):
        what = "has a non-finite position"
    else:
        size = max(system.scene.body.size)  # the bound ``limit`` is BLOWUP_FACTOR body sizes
        what = (f"moved {unorm:.3g} m, more than {BLOWUP_FACTOR:g}× the body size of {size:.3g} m "
                f"(the bound {limit:.3g} m)")
    if dt_c is None and model.explicit_limit:
        try:
            dt_c = dt_crit(system)
        except Exception:  # the message must still be raised
            dt_c = float("nan")
    cause = divergence_cause(system, x, dt, dt_c, model)
    msg = (f"explicit {model.name} run diverged at step {step} (t = {step * dt:.6g} s; checked every "
           f"{check_every} steps): particle {particle} "
           f"(grid {grid}) {what}. Likely cause: {cause}.")
    return DivergenceError(msg, step=step, particle=int(particle), grid=grid, displacement=unorm,
                           dt=dt, dt_crit=float("nan") if dt_c is None else dt_c, positions=x)
