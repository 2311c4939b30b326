"""Static equilibrium by load stepping: a tangent predictor and Newton (:mod:`hybmss.solve.newton`)
per load step, the bracketing of a limit point, and the stability check of the answer.

- energy mode: ``Π(x) = E_springs + E_volume − s Σ m g·x``; the plates' prescribed motion and the
  body loads (gravity, dead loads) are applied together in load steps ``s ∈ (0, 1]`` whose size
  adapts (halved when Newton fails, grown when it converges quickly).  Converged when
  ``‖f_free‖₂ ≤ rtol · max(|R|, |m g|)`` with R the largest plate reaction (``rtol = 1e-8``).
- residual mode (non-conservative terms, :mod:`hybmss.terms`, the [B09] corrections of
  ``baudet2009``): no potential exists, so the same Newton, predictor, load stepping and shifts
  run on the exact nonsymmetric Jacobian ``∂(−f)/∂x`` (general sparse LU) with the merit
  ``½‖f_free‖²``, and no stability certificate (the LDLᵀ inertia needs a symmetric Hessian): the
  result is an equilibrium with no inverted cell, its stability is not checked
  (``info['stability']``).

**Locating the limit point** (κ < 0, ``limit_resolution`` set; :mod:`hybmss.solve.stability`).
A predicted state beyond a fold (:func:`hybmss.solve.stability.fold_suspected`) brackets it; the
load factor is then bisected in that bracket: a midpoint whose predicted state is beyond the fold
moves the upper end down without Newton; otherwise Newton (``retry_iter`` iterations, giving up
when its iterates stay out of the stable region) decides, converged moving the lower end up,
failed the upper end down.  At a width of ``limit_resolution`` (1 %) of the first bracket, the
ordinary Newton at the upper end decides (``limit_iter`` = 4 iterations): failing,
:class:`StaticSolveError` reports the bracket (its fields ``load_factor``, ``next_load_factor``,
``smallest_eigenvalue``); converging (a bifurcation the path passes, as with the soft modes of
hybmss-fd at ν = 0.2, not a fold), the load stepping goes on without bracketing.  This replaces
some ten failing Newton attempts of 8–20 iterations with a few predictors, factorizations and
short Newton solves.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..forces import cell_volumes, energy_forces
from ..result import Result
from ..scene import Scene, check_nu, unsupported
from ..system import System, build
from .common import force_floor, force_scale, make_result, norm
from .errors import StaticSolveError
from .linalg import CholeskyFactor, Factorizer, factor, factor_general, not_definite, tangent
from .newton import NewtonStats, newton
from .stability import escape_saddle, fold_error, fold_suspected, residual_error, smallest_eigenvalue, stable_at


@dataclass(frozen=True)
class StaticOptions:
    rtol: float = 1e-8
    max_iter: int = 20
    """Newton iterations of the first attempt at a load step; a retry after a failed (halved)
    step gets ``retry_iter``: from the tangent predictor a reachable state converges in a few."""
    retry_iter: int = 8
    initial_steps: int = 1
    min_step: float = 1.0 / 4096
    max_step: float = 1.0
    line_search: bool = True
    check_stability: bool = True
    """Check the smallest eigenvalue of the constrained Hessian at the solution and leave saddles."""
    max_escapes: int = 5
    limit_resolution: float | None = 0.01
    """Width of the load-factor bracket a suspected limit point is located to, as a fraction of
    the load step that first pointed at it (:func:`solve_static`); None: plain halving of the
    load step down to ``min_step``."""
    limit_iter: int = 4
    """Newton iterations of the attempt at the upper end of a narrowed limit-point bracket that
    decides whether the equilibrium is lost (a path through a bifurcation converges there in 1–2)."""


def tangent_predictor(system: System, x: np.ndarray, target: np.ndarray, free: np.ndarray,
                      load: float = 1.0, fac: Factorizer | None = None, cache: dict | None = None):
    """First-order guess for a new load step: move the prescribed dofs to ``target`` and the free
    dofs by the linear response ``δ_f = J_ff⁻¹ (f_f − J_fc δ_c)``, J = ∂(−f)/∂x at ``x``.  Energy
    mode: J is the Hessian, factorized as is; returns ``(guess, lu)`` (the factorization, reusable
    by Newton).  Residual mode: J is shifted by 1e-8 · mean diag against zero-stiffness modes and
    ``lu`` is None.  ``(None, None)`` if it fails.

    ``cache`` (energy mode, with a ``fac`` only the predictor uses): the tangent and its
    factorization at the last ``x`` (the same object), reused for another target from that
    state, as when a limit point is bisected.  Only a Hessian of springs and cells (the fixed
    pattern) is reused: it does not depend on the load factor."""
    residual = not system.conservative
    hit = cache is not None and not residual and cache.get("x") is x
    Jff = cache["T"] if hit else tangent(system, x, load, free)
    delta = (target - x).ravel().copy()
    delta[free] = 0.0
    _, f, _ = energy_forces(system, x, load)
    rhs = f.ravel()[free] - (Jff.J @ delta)[free]
    try:
        with np.errstate(all="ignore"):
            if residual:
                lu = factor_general(Jff.shifted(1e-8 * float(np.abs(Jff.diagonal()).mean())))
            elif hit:
                lu = cache["lu"]
            else:
                if cache is not None:
                    cache.clear()
                lu = factor(Jff, fac)
                if cache is not None and Jff.pat is not None:
                    cache.update(x=x, T=Jff, lu=lu)
            d_f = lu.solve(rhs)
    except RuntimeError:
        return None, None
    if not np.all(np.isfinite(d_f)):
        return None, None
    delta[free] = d_f
    return x + delta.reshape(x.shape), (None if residual else lu)


class _LoadPath:
    """The load stepping of one :func:`solve_static`: the last equilibrium ``x`` at load factor
    ``s``, the step ``ds``, and a bracketed limit point (no equilibrium found at ``s_hi > s``,
    bisected until ``s_hi − s <= s_tol``)."""

    def __init__(self, S: System, scene: Scene, opts: StaticOptions):
        self.S, self.scene, self.opts = S, scene, opts
        self.residual = not S.conservative
        self.free = ~S.fixed.ravel()
        self.stats = NewtonStats()
        self.fac = Factorizer()
        self.x = S.X.copy()
        self.s, self.ds = 0.0, min(opts.max_step, 1.0 / max(1, opts.initial_steps))
        self.x_prev, self.s_prev = None, None
        self.load_steps = 0
        self.failed_before = False
        self.fold_check = not self.residual and S.kappa < 0 and opts.limit_resolution is not None
        self.fold_fac = Factorizer()
        # the predictor's own factorizer: its factor at the last equilibrium stays valid while Newton
        # factorizes, so another step from that equilibrium reuses it (pred_cache)
        self.pred_fac, self.pred_cache = Factorizer(), {}
        self.lam_at = {}  # smallest eigenvalue at the equilibrium of a load factor, computed once when needed
        self.s_hi, self.s_tol = None, 0.0
        self.tried = None  # (s_hi, x, guess) of a failed Newton inside a bracket that made limit_iter steps

    def lam_x(self) -> float:
        """Smallest eigenvalue at the current equilibrium if it is stable (its Hessian factorizes
        by Cholesky: shift-invert alone can miss a negative eigenvalue far below the shift), else 0."""
        s, x = self.s, self.x
        if s not in self.lam_at:
            Hx = tangent(self.S, x, s, self.free)
            # the predictor's Cholesky at x, when it succeeded, already proved it positive definite
            cache = self.pred_cache
            definite = cache.get("x") is x and isinstance(cache.get("lu"), CholeskyFactor)
            self.lam_at[s] = (smallest_eigenvalue(self.S, x, self.fold_fac)
                              if definite or not not_definite(Hx, 0.0, self.fold_fac) else 0.0)
        return self.lam_at[s]

    def accept(self, x_new: np.ndarray, s_new: float) -> None:
        self.load_steps += 1
        self.x_prev, self.s_prev, self.x, self.s = self.x, self.s, x_new, s_new

    def newton(self, guess, iters: int, lu=None, load: float = 1.0, definite_after: int | None = None):
        return newton(self.S, guess, self.free, self.opts.rtol, iters, None, self.stats, self.opts.line_search,
                      lu=lu, load=load, fac=self.fac, definite_after=definite_after)

    def predict(self, target: np.ndarray, s_new: float, extrapolate: bool):
        """The tangent predictor's guess at ``s_new`` and its factorization; when it fails (or
        inverts a cell) the last equilibrium, moved linearly along the last increment when
        ``extrapolate``; the prescribed dofs at ``target``."""
        S, x = self.S, self.x
        guess, lu = tangent_predictor(S, x, target, self.free, s_new, self.pred_fac, self.pred_cache)
        if guess is None or np.any(cell_volumes(guess, S.lattice.cells) <= 0.0):
            guess, lu = x.copy(), None
            if extrapolate and self.x_prev is not None:  # linear extrapolation of the free dofs
                guess += (x - self.x_prev) * ((s_new - self.s) / (self.s - self.s_prev))
        guess[S.fixed] = target[S.fixed]
        return guess, lu

    def fold_error(self, guess, s_new: float) -> StaticSolveError:
        return fold_error(self.S, self.scene, self.x, guess, self.s, s_new, self.lam_at.get(self.s) or None,
                          self.fold_fac)

    def decide_bracket(self) -> None:
        """The bracket is narrow: the ordinary Newton at its upper end decides.  Failing, the
        limit point is reported; converging (a bifurcation the path passes, not a fold), the load
        stepping goes on without the bracketing.  A Newton from this equilibrium to ``s_hi`` that
        already made ``limit_iter`` steps without converging has decided it."""
        s_hi = self.s_hi
        if self.tried is not None and self.tried[0] == s_hi and self.tried[1] is self.x:
            self.lost(self.fold_error(self.tried[2], s_hi))
            return
        guess, lu = self.predict(self.S.prescribed(s_hi), s_hi, extrapolate=False)
        ok, x_new, f, rnorm, scale = self.newton(guess, self.opts.limit_iter, lu=lu, load=s_hi)
        if not ok:
            self.lost(self.fold_error(guess, s_hi))
            return
        self.accept(x_new, s_hi)
        self.ds, self.s_hi, self.fold_check = 2.0 * self.s_tol, None, False

    def lost(self, error: StaticSolveError) -> None:
        """Newton failed at the upper end of a narrow bracket.  With evidence of a fold (the
        Hessian indefinite, or a κ < 0 body dilated: :func:`hybmss.solve.stability.fold_error`'s
        cause) the equilibrium is lost: raise ``error``.  Without (cause ``newton``: positive
        definite at the last equilibrium and at the predicted state) the suspicion was the
        predictor's, far beyond: the bracket is dropped and the load steps on from the last
        equilibrium with half the bracket's width, down to ``min_step`` as any failed step."""
        if error.cause != "newton":
            raise error
        self.ds = 0.5 * (self.s_hi - self.s)
        self.s_hi, self.tried, self.failed_before = None, None, True
        if self.ds < self.opts.min_step:
            raise error

    def unchanged(self, target: np.ndarray, s_new: float) -> bool:
        """A step that changes nothing (a zero load: no plate motion, no body load) is already in
        equilibrium: the rest state is the answer, exactly."""
        trial = self.x.copy()
        trial[self.S.fixed] = target[self.S.fixed]
        if self.newton(trial, 0, load=s_new)[0]:
            self.accept(trial, s_new)
            self.ds = min(self.opts.max_step, self.ds * 1.5)
            return True
        return False

    def step(self) -> None:
        """One load step (or one bisection of a bracket) from the last equilibrium."""
        opts = self.opts
        if self.s_hi is not None and self.s_hi - self.s <= self.s_tol:
            self.decide_bracket()
            return
        s_new = 0.5 * (self.s + self.s_hi) if self.s_hi is not None else min(1.0, self.s + self.ds)
        target = self.S.prescribed(s_new)
        if self.unchanged(target, s_new):
            return
        guess, lu = self.predict(target, s_new, extrapolate=True)
        if self.fold_check:
            suspected, F_guess = fold_suspected(self.S, guess, self.free, self.fold_fac, s_new, self.lam_x)
            if suspected:
                # beyond a limit point as it stands: bracket it (or narrow the bracket) without Newton
                if self.s_hi is None:
                    self.s_tol = opts.limit_resolution * (s_new - self.s)
                self.s_hi = s_new
                return
            if F_guess is not None:
                lu = F_guess
        # inside a bracket, Newton gives up when its iterates stay out of the stable region
        iters = opts.max_iter if not (self.failed_before or self.s_hi is not None) else opts.retry_iter
        it0 = self.stats.iterations
        ok, x_new, f, rnorm, scale = self.newton(guess, iters, lu=lu, load=s_new,
                                                 definite_after=3 if self.s_hi is not None else None)
        self.failed_before = not ok
        if ok:
            self.accept(x_new, s_new)
            if self.s_hi is None:
                self.ds = min(opts.max_step, self.ds * 1.5)
            return
        if self.s_hi is not None:
            self.s_hi = s_new
            self.tried = (s_new, self.x, guess) if self.stats.iterations - it0 >= opts.limit_iter else None
            return
        self.ds *= 0.5
        if self.ds < opts.min_step:
            raise (residual_error(self.scene, self.s, s_new, rnorm) if self.residual
                   else self.fold_error(guess, s_new))

    def stabilize(self):
        """Stability of the equilibrium found: Newton converges to any stationary point, so check
        the smallest eigenvalue of the constrained Hessian and, at a saddle (e.g. the buckled
        zero-energy modes of hybmss-fd under compression), descend along the unstable mode and
        solve again.  Returns ``(escapes, lam, stable, warning)``."""
        opts, S, free = self.opts, self.S, self.free
        escapes, lam, stable, warning = 0, None, True, ""
        for escapes in range(opts.max_escapes + 1):
            stable, lam, vec = stable_at(S, self.x, free, self.fac)
            if stable or escapes == opts.max_escapes:
                break
            xt = escape_saddle(S, self.x, free, vec)
            if xt is None:
                break
            ok, x_new, f, rnorm, scale = self.newton(xt, 5 * opts.max_iter)
            if not ok:
                warning = (f"the equilibrium found is a saddle (smallest eigenvalue {lam:.4g} N/m: buckling or "
                           "zero-energy modes); descending along the unstable mode did not reach another "
                           "equilibrium, so the symmetric stationary state is returned")
                break
            self.x = x_new
        return escapes, lam, stable, warning

    def info(self, f: np.ndarray, stability) -> dict:
        """``Result.info`` of the answer (``f`` the forces there, ``stability`` of :meth:`stabilize`)."""
        S = self.S
        r = norm(f.ravel()[self.free])
        if self.residual:
            info = {
                "equilibrium": "force-residual Newton (non-conservative terms, no energy)",
                "stability": "not certified: no energy to minimize and a nonsymmetric Jacobian",
            }
        else:
            escapes, lam, stable, warning = stability
            info = {
                "min_eigenvalue": lam if lam is not None else float("nan"),
                "saddle_escapes": int(escapes) if lam is not None else 0,
                "stable": bool(stable),
                "warning": warning,
            }
        info.update({
            "load_steps": self.load_steps,
            "regularized_steps": self.stats.regularized,
            "line_search_cuts": self.stats.line_search_cuts,
            "residual": r,
            "relative_residual": r / force_scale(S, f),
            "residual_floor": force_floor(S),
            "kappa": S.kappa,
            "springs": int(len(S.spring_k)),
            "volume_cells": int(len(S.vol_cells)),
        })
        return info


def solve_static(scene: Scene, options: StaticOptions | None = None, system: System | None = None) -> Result:
    """Static equilibrium of ``scene`` (solver name ``mss-static``).

    Load steps with a tangent predictor and Newton (:func:`hybmss.solve.newton.newton`) in energy
    mode when every force is conservative, in residual mode when the system has non-conservative
    terms (``baudet2009``).  Energy mode then certifies stability from the inertia of the
    constrained Hessian and leaves saddles; residual mode returns the equilibrium without that
    certificate.  Raises :class:`StaticSolveError` (with its numbers as fields) when the load
    cannot be applied, and ``ValueError`` before any work when the plates leave a rigid-body
    motion free (:func:`hybmss.scene.unsupported`)."""
    model = scene.model.spec
    if "static" not in model.solvers:
        raise ValueError(f"model {model.name} has no static solver (its solvers: {', '.join(model.solvers)})")
    why = unsupported(scene)
    if why:  # free rigid-body modes: no unique equilibrium to look for (refused before any work)
        raise ValueError(why)
    if model.solve_static is not None:  # a model with its own static solver (hybmss.models.base)
        return model.solve_static(scene, options, system)
    opts = options or StaticOptions()
    t0 = time.perf_counter()
    check_nu(scene.material.nu)
    S = system if system is not None else build(scene)
    path = _LoadPath(S, scene, opts)
    while path.s < 1.0 - 1e-14:
        path.step()
    # Residual mode has no stability certificate (no energy, nonsymmetric Jacobian): its result is
    # an equilibrium with no inverted cell, and info['stability'] says that stability is not checked.
    stability = path.stabilize() if opts.check_stability and not path.residual else (0, None, True, "")
    e, f, parts = energy_forces(S, path.x)
    return make_result(S, "mss-static", path.x, f, parts, path.stats.iterations, t0, True, path.info(f, stability))
