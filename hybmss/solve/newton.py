"""Newton's method over the free degrees of freedom, in named steps: evaluate, tangent, factor or
shift, line search, chord steps; and the tangent predictor of a load step.

**Zero-energy modes.**  Without face diagonals (``hybmss-fd``) the cubic lattice has hourglass
modes, so the constrained Hessian can be singular even with clamped plates.  When the
factorization fails or the Newton direction is not a descent direction, the solver adds a
Levenberg–Marquardt shift ``μ·mean(diag H)·I`` (μ from 1e-6, ×100 until it works).  The shift
only damps the step; convergence is still judged on the unshifted force residual, so the result is
an exact equilibrium in which the zero-energy modes keep their initial (zero) amplitude.  Each
result records in ``info['regularized_steps']`` how often this happened.  A lattice whose cells
have no zero-energy mode (:func:`hybmss.solve.stability.cell_zero_energy_modes`: hybmss,
hybmss-cf) meets an indefinite Hessian (the volume term's ``(J − 1) ∂²J`` far from ``J = 1`` at
ν → ½) with the same shifts, Cholesky only, instead of the unshifted LDLᵀ step: a descent
direction, and 5× fewer iterations on the 10³ cube at ν = 0.499 in 20 % compression, to the same
equilibrium.  A lattice with such modes keeps the unshifted step: its equilibria depend on the
path (buckled, hourglassed states), down to rounding.  Measured on the 127 hybmss-fd static runs
of ``make reproduce-paper``: with the same Newton matrices factorized by SuperLU in its
minimum-degree order instead of the nested-dissection one (the same steps up to rounding), 92
reach the same equilibrium (forces, volume change, largest displacement within 5e-5), 8 its mirror
image (the torques change sign), and 3 another one: the 10³ and 6³ cubes in 5 % compression at
ν = 0 escape the saddle at which they stop otherwise (plate force −4,737 N instead of −11,464 N on
10³), and the 4×4×24 beam in 5 % tension at ν = 0.499 moves by 6e-4.  Such answers hold for this
factorization only.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..forces import cell_volumes, energy_forces
from ..system import System
from .common import dot, force_floor, force_scale, inertia_floor, norm
from .linalg import Factorizer, Tangent, cholmod, factor_general, superlu_symmetric, tangent
from .stability import cell_zero_energy_modes


@dataclass
class NewtonStats:
    iterations: int = 0
    regularized: int = 0
    line_search_cuts: int = 0
    history: list = field(default_factory=list)


RESIDUAL_SHIFTS = (0.0, 1e-8, 1e-6, 1e-4, 1e-2, 1.0)
"""Levenberg–Marquardt shifts μ tried in residual mode, in order, until the line search accepts."""


def energy_shifts(mu_last: float):
    """Shifts tried in energy mode: from a tenth of the last one that worked (0 after an unshifted
    step), ×100 (the first nonzero one 1e-6), five in all."""
    mu = 0.0 if mu_last < 1e-6 else mu_last / 10.0
    for _ in range(5):
        yield mu
        mu = 1e-6 if mu == 0.0 else mu * 100.0


class _GiveUp(Exception):
    """The unshifted Hessian is still not positive definite after ``definite_after`` iterations."""


@dataclass
class _Trial:
    """The outcome of a line search: whether it accepted, its step length, state, merit, forces
    and free residual norm."""
    accepted: bool
    alpha: float = 1.0
    x: np.ndarray | None = None
    e: float = 0.0
    f: np.ndarray | None = None
    rnorm: float = np.inf


class _Newton:
    """One call of :func:`newton`: the problem (system, free dofs, load, inertia) and the state the
    iterations share (the factorization in use and its shift)."""

    def __init__(self, system: System, free, rtol, inertia, stats, line_search, lu, load, fac, definite_after):
        self.system, self.free, self.rtol, self.inertia = system, free, rtol, inertia
        self.stats, self.line_search, self.load, self.fac = stats, line_search, load, fac
        self.definite_after = definite_after
        self.residual = not system.conservative
        if self.residual and inertia is not None:
            raise ValueError("the residual mode has no incremental potential for an inertia term")
        self.cells, self.le = system.lattice.cells, system.scene.body.le
        self.lu = None if self.residual else lu
        self.mu_last, self.lu_mu = 0.0, 0.0
        # decided (by the cell rank test) when a Cholesky first fails
        self.definite_steps = None

    # ---------------------------------------------------------------- evaluate
    def evaluate(self, xx):
        """(merit, forces): Π (+ inertia) in energy mode, ‖r_free‖ in residual mode."""
        e, f, _ = energy_forces(self.system, xx, self.load)
        if self.inertia is not None:
            w, xt = self.inertia
            d = xx - xt
            e += 0.5 * float(np.sum(w[:, None] * d * d))
            f = f - w[:, None] * d
        if self.residual:
            e = norm(f.ravel()[self.free])
        return e, f

    def floor(self, x) -> float:
        floor = force_floor(self.system)
        if self.inertia is not None:
            floor = max(floor, inertia_floor(self.inertia[0], x))
        return floor

    def scale(self, x, f) -> float:
        """The reaction scale of the static forces (the inertia term removed, no re-evaluation)."""
        return force_scale(self.system, f if self.inertia is None else f + self.inertia[0][:, None] * (x - self.inertia[1]))

    # ---------------------------------------------------------------- tangent and directions
    def tangent(self, x) -> Tangent:
        diag = None if self.inertia is None else np.repeat(self.inertia[0], 3)[self.free]
        return tangent(self.system, x, self.load, self.free, diag)

    def chord(self, r):
        """The step of the factorization in use (a chord step), None (dropping it) if it is not a
        finite descent direction."""
        if self.lu is None:
            return None
        with np.errstate(all="ignore"):
            cand = self.lu.solve(r)
        if np.all(np.isfinite(cand)) and dot(r, cand) > 0.0:
            return cand
        self.lu = None
        return None

    def factorize(self, A, mu: float, it: int):
        """A factorization of ``A`` (the tangent shifted by ``mu``), None to try the next shift.
        Every unshifted Hessian is tried by Cholesky first (a failure is cheap against SuperLU's
        LU, 2.5–3× a Cholesky, and Newton's Hessians turn positive definite again within a call).
        A lattice whose cells have no zero-energy mode then steps with the Cholesky of the smallest
        shift that is positive definite; one with such modes keeps the unshifted (LDLᵀ) step."""
        if self.residual:
            return factor_general(A)
        fac = self.fac
        lu = fac.cholesky(A) if fac is not None else None
        if lu is None and fac is not None and cholmod is not None:
            if mu == 0.0 and self.definite_after is not None and it >= self.definite_after:
                raise _GiveUp
            if self.definite_steps is None:
                self.definite_steps = not cell_zero_energy_modes(self.system)
            if self.definite_steps and mu < 1.0:
                return None
        return lu if lu is not None else superlu_symmetric(A)

    def shifted_direction(self, Jff: Tangent, diag_mean: float, mu: float, r, it: int):
        """The Newton step of ``Jff + μ·diag_mean·I``, None if it fails (no factorization, not
        finite, not a descent direction in energy mode)."""
        A = Jff if mu == 0.0 else Jff.shifted(mu * diag_mean)
        try:
            with np.errstate(all="ignore"):
                self.lu = self.factorize(A, mu, it)
                if self.lu is None:
                    return None
                dx = self.lu.solve(r)
            ok = np.all(np.isfinite(dx)) and (self.residual or dot(r, dx) > 0.0)
        except RuntimeError:  # exactly singular
            ok = False
        if not ok:
            self.lu = None
            return None
        self.mu_last, self.lu_mu = mu, mu
        return dx

    # ---------------------------------------------------------------- line search
    def search(self, x, e, r, rnorm, dx, mu, floor) -> _Trial:
        """Backtracking line search on the merit along ``dx``, rejecting inverted cells."""
        n, free = self.system.n, self.free
        step = np.zeros(3 * n)
        step[free] = dx
        step = step.reshape(n, 3)
        alpha = 1.0
        slope = dot(r, dx)
        trial = _Trial(False)
        for _ in range((12 if mu == 1.0 else 4) if self.residual else 12):
            xt = x + alpha * step
            if np.all(cell_volumes(xt, self.cells) > 0.0):
                et, ft = self.evaluate(xt)
                rt = norm(ft.ravel()[free])
                if self.residual:
                    accepted = rt <= (1.0 - 1e-4 * alpha) * rnorm
                else:
                    accepted = (not self.line_search) or et <= e - 1e-4 * alpha * slope or (
                        rt < rnorm and abs(et - e) <= 1e-10 * max(abs(e), floor * self.le))
                trial = _Trial(accepted, alpha, xt, et, ft, rt)
                if accepted:
                    return trial
            alpha *= 0.5
            self.stats.line_search_cuts += 1
        trial.accepted = False
        return trial

    def step(self, x, e, r, rnorm, it, floor):
        """One Newton iteration from ``x``: the accepted :class:`_Trial`, or None when no direction
        passes the line search; ``fresh`` whether the exact tangent at ``x`` was factorized."""
        chord = self.chord(r)
        fresh = chord is None
        if not fresh:
            trial = self.search(x, e, r, rnorm, chord, None, floor)
            return (trial if trial.accepted else None), fresh
        Jff = self.tangent(x)
        diag_mean = float(np.abs(Jff.diagonal()).mean())
        for mu in RESIDUAL_SHIFTS if self.residual else energy_shifts(self.mu_last):
            dx = self.shifted_direction(Jff, diag_mean, mu, r, it)
            if dx is None:
                continue
            trial = self.search(x, e, r, rnorm, dx, mu, floor)
            if trial.accepted or not self.residual:
                return (trial if trial.accepted else None), fresh
        return None, fresh


def newton(system: System, x: np.ndarray, free: np.ndarray, rtol: float, max_iter: int,
           inertia: tuple[np.ndarray, np.ndarray] | None, stats: NewtonStats, line_search=True,
           lu=None, load: float = 1.0, fac: Factorizer | None = None, definite_after: int | None = None):
    """Newton's method over the free dofs from ``x`` at load factor ``load``, in one of two modes:

    - **energy** (every force conservative): minimize Π (+ the inertia term ``½ Σ w_a |x_a − x̃_a|²``
      when ``inertia = (w, x̃)``) with the exact symmetric Hessian; a step is a descent direction of
      Π and the backtracking line search asks Π to decrease (Armijo);
    - **residual** (non-conservative terms, no energy; ``inertia`` must be None): find a zero of the
      force residual r with the exact nonsymmetric Jacobian ``∂(−f)/∂x`` (general LU); the merit
      is ``‖r‖``, a line search asks it to decrease (Armijo on the norm), and a step the
      search rejects is retried with the next Levenberg–Marquardt shift of :data:`RESIDUAL_SHIFTS`.

    Both share the shifts ``μ·mean(diag)·I`` against zero-energy modes, the rejection of inverted
    cells (also of an inverted start: an inverted lattice can have zero forces) and the
    convergence test ``‖r‖ ≤ max(rtol · scale, floor)`` on the unshifted residual.

    ``lu`` (energy mode): a factorization of a nearby Hessian (the predictor's).  It is reused for
    the next step (a chord step) as long as it reduced the residual at least 5-fold and gives a
    descent direction; otherwise the exact Hessian at the current point is factorized.  The
    converged state does not depend on this (the residual test uses the exact forces).
    ``definite_after`` (energy mode, with ``fac``): give up when the unshifted Hessian is still (or
    again) not positive definite after that many iterations, as near a limit point, where iterates
    that stay out of the stable region are taken as the sign that no equilibrium is near
    (:func:`hybmss.solve.static.solve_static` then brackets the fold).
    Returns (converged, x, f_total, residual_norm, scale).
    """
    nt = _Newton(system, free, rtol, inertia, stats, line_search, lu, load, fac, definite_after)
    e, f = nt.evaluate(x)
    floor = nt.floor(x)
    if np.any(cell_volumes(x, nt.cells) <= 0.0):
        return False, x, f, np.inf, force_scale(system, f)
    best, e_best, stalled = np.inf, np.inf, 0
    for it in range(max_iter + 1):
        r = f.ravel()[free]
        rnorm = norm(r)
        scale = nt.scale(x, f)
        stats.history.append(rnorm / scale)
        if not np.isfinite(rnorm):
            return False, x, f, rnorm, scale
        if rnorm <= max(rtol * scale, floor):
            return True, x, f, rnorm, scale
        if it == max_iter:
            break
        # give up early when for 6 iterations neither the residual has halved nor the merit
        # dropped by more than 1e-8 of its scale (no progress toward a solution)
        progress = rnorm < 0.5 * best or e < e_best - 1e-8 * max(abs(e_best), floor * nt.le)
        best, e_best = min(best, rnorm), min(e_best, e)
        stalled = 0 if progress else stalled + 1
        if stalled >= 6:
            break
        try:
            trial, fresh = nt.step(x, e, r, rnorm, it, floor)
        except _GiveUp:
            return False, x, f, rnorm, scale
        if trial is None:
            if not fresh:  # the chord direction failed: retry with the exact Hessian
                nt.lu = None
                continue
            return False, x, f, rnorm, scale
        stats.iterations += 1
        if nt.lu_mu > 0.0:
            stats.regularized += 1
        if nt.residual or trial.alpha < 1.0 or trial.rnorm > 0.2 * rnorm:
            nt.lu = None  # slow contraction (or residual mode): refactorize at the new point
        x, e, f = trial.x, trial.e, trial.f
    return False, x, f, rnorm, scale
