"""Finite-strain hyperelasticity: total Lagrangian, Newton with load stepping and line search.

Displacement formulation (Hex1 or Hex2): find ``u`` (``u = ū(s)`` on the plates) with

    R(u) = ∫ P(F) : ∇v dX − s ∫ ρ g · v dX = 0,     F = I + ∇u,  P = ∂ψ/∂F,

for the laws of :mod:`fem_reference.laws` (gravity is a dead load per reference volume).
Newton solves ``∫ ∇v : A(F) : ∇δu dX = −R`` with ``A = ∂P/∂F``.

Mixed u–p (Hex2 × Hex1, for ν ≥ 0.45): with ``ψ = W₀ + λ/2 g²``, the saddle point of

    Π(u, p) = ∫ W₀(F) + p g(F) − p²/(2λ) dX − s ∫ ρ g · u dX

gives ``R_u = ∫ (P₀ + p G) : ∇v − s ∫ ρ g · v`` and ``R_p = ∫ (g − p/λ) q``, and the Newton
system ``[[∫∇v:(A₀ + p H):∇δu, Bᵀ], [B, −M_p/λ]]`` with ``B = ∫ q G : ∇δu``.

A solve given a ``start`` near its solution (a coarser mesh's, prolonged) tries the whole load from
there first.

Load stepping: the plates' displacements (exact rigid rotations for ``rotate``) and the body load
are scaled by s = s₁ < s₂ < … < 1.  The first step starts from the undeformed state and its first
Newton iteration imposes the plate displacements as an inhomogeneous Dirichlet increment (a
linearized predictor); later steps start from the secant extrapolation of the last two converged
states (plates set to their exact values), unless that inverts an element.  The first increment
is the whole load; an increment that converged in at most :data:`GROW_ITERATIONS` iterations
(tangent factorizations) doubles the next one, unless that reaches the size of an increment that
already failed (a failed increment costs up to three converged ones: the 15³ Hex1 cube twisted
45° at ν = 0.499 doubled its 0.1 increments three times and failed each time, 24 of its 55 s).
An increment larger than ``1/steps`` gets at most :data:`OPTIMISTIC_MAXITER` iterations, and
one more each time the last one cut the residual :data:`BASIN_CONTRACTION`-fold (Newton's
quadratic basin: it is about to converge), up to ``maxiter``; if it fails, the next increment is
``1/steps``.  Linear systems
inside Newton are solved inexactly when iterative (relative tolerance ``0.1 ‖R‖/‖f‖`` within
[:data:`LINEAR_RTOL_MIN`, :data:`LINEAR_RTOL_MAX`]; the pressure CG of the mixed element's
saddle point within [:data:`~fem_reference.linalg.SCHUR_RTOL`, :data:`LINEAR_RTOL_MAX`]); a
direct factorization (the mixed element's saddle point, small displacement systems) is reused
for chord steps near the solution while they converge fast (:data:`CHORD_RATIO`,
:data:`CHORD_NEAR`, :data:`CHORD_NEAR_MIXED`).  The load steps before the last converge to :data:`INTERMEDIATE_RTOL`
only: their states serve as starting points, and the last step converges to ``rtol`` from
wherever they are (the solution at load factor 1 does not depend on how the path got there).  A
trial update is shortened (halved, down to 1/64) while it inverts an element (``det F ≤ 0`` at
a quadrature point) or lowers neither the residual norm nor (displacement formulation) the
potential energy; if a step does not converge the load increment is halved.  Convergence: ``‖R_free‖ ≤ rtol · max(‖f_int‖, ‖f_ext‖) + atol``.

The reaction of the plates is ``r = f_int(u) − f_ext`` at the prescribed dofs.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hybmss.scene import Material

from .dirichlet import Dirichlet
from .laws import LAWS, deviatoric, kinematics, volumetric
from .linalg import SCHUR_RTOL, SchurSolve, SolveStats, solve_saddle, solve_spd
from .linear import Discretization, Solution


OPTIMISTIC_MAXITER = 6
"""Newton iterations allowed to an increment larger than ``1/steps`` (more while it converges fast,
:data:`BASIN_CONTRACTION`)."""
BASIN_CONTRACTION = 0.05
"""An increment past its iterations gets one more while its last full Newton update cut the residual
by at least this factor.  On the publication's large rotations (bending at E = 2 and 10 MPa,
torsion at 45-90°) several whole-load steps ran out of iterations with their last update cutting
the residual 100- to 10,000-fold; the rejected steps cost ~18 % of the FEM's time.  Stalled ones
cut it 4- to 16-fold."""
CHORD_RATIO = 0.25
"""Direct solves: after a full Newton update that reduced the residual by at least this factor,
the next iteration reuses the direct factorization (a chord step); it refactorizes when a chord step
gives no decrease or a slower one."""
CHORD_NEAR = 1e-3
"""Chord steps only once the residual is below this fraction of the force scale (near the
solution, where the tangent changes little)."""
CHORD_NEAR_MIXED = 1e-2
""":data:`CHORD_NEAR` of the mixed element, whose factorization (a large saddle point's Schur
elimination) costs many chord steps.  From a prolonged start (the 2 mm cylinder twisted by 30° at
ν = 0.49, refine 2: 345,524 unknowns) the first Newton update leaves 2.7e-3 of the force scale:
at 1e-3 the second iteration factorized again (57 s); at 1e-2 five chord steps cut the residual
about 30-fold each, the level in 135 s instead of 164, its answer equal to 9 digits."""
CHORD_SCHUR_RTOL = 1e-2
"""Relative tolerance of the mixed element's pressure CG in a chord step.  A chord step converges
linearly at its own rate (at most :data:`CHORD_RATIO`; 0.13 a step on the 8×8×48 beam stretched
20 % at ν = 0.499), which a solve to 1e-2 barely changes, where the forcing term of a Newton step
(``0.1 ‖R‖/‖f‖``) asks down to 1e-11 near the solution: there, the ten chord steps took 51 CG
iterations (pairs of triangular solves with an 88k-dof factor) instead of 170, with the same
residuals to three digits and a plate force equal to 6e-14 (SVK: 50 s -> 36 s)."""
CHORD_MAXITER_FACTOR = 3
"""Chord and Newton iterations together: at most this many times ``maxiter``."""
INTERMEDIATE_RTOL = 1e-6
"""Newton tolerance (relative to the force scale) of the load steps before the last; the last step
and a state returned after a failure are converged to the full ``rtol``."""
GROW_ITERATIONS = 4
"""A load step that converges in at most this many Newton iterations doubles the next increment."""
LINEAR_RTOL_MAX = 1e-3
"""Loosest relative tolerance of an iterative linear solve inside Newton."""
LINEAR_RTOL_MIN = 1e-11
"""Tightest one (the tolerance of a stand-alone linear solve)."""


class ConvergenceError(RuntimeError):
    """Newton failed even after the smallest allowed load increment.

    ``solution`` holds the last converged state, at load factor ``load_factor``."""

    def __init__(self, message, solution=None, log=None, load_factor: float = 0.0):
        super().__init__(message)
        self.solution = solution
        self.log = log
        self.load_factor = load_factor


@dataclass
class NewtonLog:
    steps: list = field(default_factory=list)  # (s, iterations, final residual)
    iterations: int = 0
    rejected: list = field(default_factory=list)  # (s from, s to) of each rejected increment
    converged: bool = True

    @property
    def rejected_steps(self) -> int:
        return len(self.rejected)


def _qp(a: np.ndarray) -> np.ndarray:
    """Move the leading tensor axes of ``a[i, J, e, q]`` behind the point axes."""
    return np.moveaxis(a, (0, 1), (-2, -1))


def _back2(a: np.ndarray) -> np.ndarray:
    return np.moveaxis(a, (-2, -1), (0, 1))


def _secant_guess(U, p, prev, s_done: float, s: float):
    """The secant extrapolation to load factor ``s`` of the converged states ``prev = (s₀, U₀, p₀)``
    and ``(s_done, U, p)``: ``(U, p)``, or ``None`` without an earlier step."""
    if prev is None or s_done <= prev[0]:
        return None
    r = (s - s_done) / (s_done - prev[0])
    return U + r * (U - prev[1]), None if p is None else p + r * (p - prev[2])


@dataclass(frozen=True, eq=False)
class Hyperelasticity(Discretization):
    """Newton solver for one mesh, formulation (``hex1``, ``hex2``, ``mixed``) and law."""

    law: str = "neo-hookean"
    reorder: bool = True
    """Factorize direct systems in the nested-dissection order of :attr:`order` (``False``: SuperLU's
    minimum degree order)."""

    def __post_init__(self):
        super().__post_init__()
        if self.law not in LAWS:
            raise ValueError(f"law must be one of {', '.join(LAWS)}; got {self.law!r}")

    # ---------------------------------------------------------------- state
    def _evaluate(self, U, p, s, fext, material, tangent: bool):
        """Residuals (and tangent blocks) at ``U`` (n_vector), ``p``; ``None`` if inverted."""
        lam, mu = material.lam, material.G
        F = np.eye(3) + _qp(self.space.grad(U.reshape(-1, 3)))
        J = np.linalg.det(F)
        if not np.all(J > 0):
            return None
        kin = kinematics(self.law, F, tangent, J)  # det F, F⁻¹ and their products once for both parts
        W0, P0, A0 = deviatoric(self.law, F, mu, tangent, kin)
        g, G, H = volumetric(self.law, F, tangent, kin)
        out = {"minJ": float(J.min())}
        if self.mixed:
            pq = self.pspace.value(p)
            Pst = P0 + pq[..., None, None] * G
            out["psi"] = W0 + pq * g - pq**2 / (2 * lam)
            out["Rp"] = self.pspace.scalar_load(g - pq / lam)
            if tangent:
                out["K"] = self.space.tangent(A0 + pq[..., None, None, None, None] * H)
                out["B"] = self.space.coupling(self.pspace, _back2(G))
        else:
            Pst = P0 + lam * g[..., None, None] * G
            out["psi"] = W0 + 0.5 * lam * g**2
            if tangent:
                A = A0 + lam * np.einsum("...iJ,...kL->...iJkL", G, G) + lam * g[..., None, None, None, None] * H
                out["K"] = self.space.tangent(A)
        out["fint"] = self.space.vector_load(_back2(Pst))
        out["Ru"] = out["fint"] - s * fext
        return out

    def _norm(self, st, free, mu) -> float:
        r2 = float(np.sum(st["Ru"][free] ** 2))
        if self.mixed:
            r2 += float(np.sum((mu * st["Rp"] / self.fmesh.h) ** 2))
        return np.sqrt(r2)

    # ---------------------------------------------------------------- solve
    def solve(
        self,
        material: Material,
        dirichlet: Dirichlet,
        gravity=(0.0, 0.0, 0.0),
        steps: int = 5,
        rtol: float = 1e-10,
        maxiter: int = 25,
        method: str = "auto",
        min_increment: float = 1e-4,
        load: np.ndarray | None = None,
        adaptive: bool = True,
        intermediate_rtol: float | None = INTERMEDIATE_RTOL,
        chord: bool = True,
        start: tuple | None = None,
    ) -> tuple[Solution, NewtonLog]:
        """Solve up to load factor 1: one full step first, then increments of ``1/steps`` (halved on
        failure, doubled after a fast step).
        ``load``: extra dead load vector (n_vector,), e.g. surface tractions, scaled with gravity.
        ``adaptive=False``: equal increments ``1/steps`` from the linearized predictor only (no
        full first step, no secant predictor, no growth), and linear solves to the tightest
        tolerance.  ``intermediate_rtol``: Newton tolerance of the load steps before the last
        (``None``: ``rtol``); ``chord=False``: a fresh tangent at every iteration.
        ``start``: a state ``(U, p)`` near the solution at the full load (the prolonged solution of
        a coarser mesh, :mod:`fem_reference.prolong`), from which the first, whole-load step starts
        (plates at their values); when that step fails, the load stepping goes on from the
        undeformed state as without it."""
        if self.mixed and material.lam <= 0:
            raise ValueError(f"the mixed u-p element needs lambda > 0 (nu > 0), got nu = {material.nu}")
        space = self.space
        fext = space.body_load(material.rho * np.asarray(gravity, float))
        if load is not None:
            fext = fext + load
        free = np.ones(space.n_vector, dtype=bool)
        free[dirichlet.dofs] = False
        U = np.zeros(space.n_vector)
        p = np.zeros(self.pspace.n_scalar) if self.mixed else None
        atol = 1e-12 * material.G * self.fmesh.body.volume ** (2.0 / 3.0)
        stats = SolveStats()
        log = NewtonLog()
        C = self.pressure_mass / material.lam if self.mixed else None
        amg_cache: dict = {}  # AMG hierarchy reused across Newton iterations (same free dofs)
        lu_cache: dict = {}  # last direct factorization, for chord steps

        base = 1.0 / max(1, int(steps))
        s_done, ds = 0.0, (1.0 if adaptive else base)
        failed = np.inf  # the smallest increment that failed: growth stays below it
        prev = None  # (s, U, p) of the previous converged step, for the secant predictor
        if start is not None and adaptive:
            start = (np.asarray(start[0], float).reshape(-1), None if p is None else np.asarray(start[1], float))
        else:
            start = None
        while s_done < 1.0 - 1e-14:
            s = min(1.0, s_done + ds)
            # An increment above the base one (the first full step, or grown) is optimistic: it
            # gets few iterations, and on failure the base increment takes over.
            optimistic = s - s_done > base * (1.0 + 1e-9)
            its_max = min(maxiter, OPTIMISTIC_MAXITER) if optimistic else maxiter
            guess = _secant_guess(U, p, prev, s_done, s) if adaptive else None
            if start is not None and s_done == 0.0 and s >= 1.0 - 1e-14:
                guess = start
            last = s >= 1.0 - 1e-14
            ok, U_new, p_new, its, res, fresh = self._step(
                U, p, s, fext, dirichlet, material, free, atol,
                rtol if (last or not adaptive or intermediate_rtol is None) else max(rtol, intermediate_rtol),
                its_max, method, stats, C, amg_cache, guess, adaptive, lu_cache if adaptive and chord else None,
                maxiter,
            )
            log.iterations += its
            if ok:
                prev = (s_done, U, p)
                U, p, s_done = U_new, p_new, s
                log.steps.append((s, its, res))
                if adaptive and fresh <= GROW_ITERATIONS and 2.0 * ds < failed * (1.0 - 1e-9):
                    ds *= 2.0
                continue
            log.rejected.append((s_done, s))
            failed = min(failed, s - s_done)
            ds = base if optimistic else 0.5 * min(ds, s - s_done)
            if ds < min_increment:
                log.converged = False
                if adaptive and intermediate_rtol is not None and s_done > 0.0:  # to the full tolerance
                    U, p = self._tighten(U, p, s_done, fext, dirichlet, material, free, atol, rtol, maxiter,
                                         method, stats, C, amg_cache, log)
                st = self._evaluate(U, p, s_done, fext, material, tangent=False)
                partial = Solution(U.reshape(-1, 3), p, st["Ru"], space.integrate(st["psi"]), stats)
                raise ConvergenceError(
                    f"Newton did not converge at load factor {s:.4g} (increment below {min_increment:g})",
                    partial, log, s_done,
                )
        st = self._evaluate(U, p, 1.0, fext, material, tangent=False)
        return Solution(U.reshape(-1, 3), p, st["Ru"], space.integrate(st["psi"]), stats), log

    def _tighten(self, U, p, s, fext, dirichlet, material, free, atol, rtol, maxiter, method, stats, C,
                 amg_cache, log):
        """The converged state at load factor ``s`` (converged to :data:`INTERMEDIATE_RTOL`) taken to
        the full ``rtol`` before a failure is reported; the state as it was if that fails."""
        ok, U_t, p_t, its, _, _ = self._step(U, p, s, fext, dirichlet, material, free, atol, rtol, maxiter,
                                             method, stats, C, amg_cache, None, True, None)
        log.iterations += its
        return (U_t, p_t) if ok else (U, p)

    def _step(self, U, p, s, fext, dirichlet, material, free, atol, rtol, maxiter, method, stats, C,
              amg_cache=None, guess=None, inexact=True, lu_cache=None, extend_to=None):
        """One load step to ``s``: ``(converged, U, p, iterations, residual, fresh tangents)``.
        ``maxiter`` fresh tangent solves (chord steps aside), raised one at a time up to
        ``extend_to`` while the last full update cut the residual :data:`BASIN_CONTRACTION`-fold."""
        mu = material.G
        D = dirichlet.dofs
        target = dirichlet.values(s)
        U, p, st = self._start(U, p, s, guess, target, D, fext, material)
        if st is None:
            return False, U, p, 0, np.inf, 0
        res = np.inf
        it = fresh = 0
        limit = maxiter  # fresh tangent solves allowed
        extend_to = maxiter if extend_to is None else max(maxiter, extend_to)
        chord = False  # the next iteration may reuse the last factorization (a chord step)
        while fresh < limit and it < CHORD_MAXITER_FACTOR * limit:
            it += 1
            dD = target - U[D]
            factors = lu_cache if self.mixed else amg_cache  # where a direct solve leaves its "lu"
            use_chord = chord and lu_cache is not None and factors is not None and "lu" in factors \
                and not np.any(dD != 0.0)
            if not use_chord and "K" not in st:
                st = self._evaluate(U, p, s, fext, material, tangent=True)
            res0 = self._norm(st, free, mu)
            ref0 = max(np.linalg.norm(st["fint"]), s * np.linalg.norm(fext))
            # Inexact Newton: solve the linear system only as accurately as the current residual
            # warrants (forcing term η ≤ 0.1 ‖R‖/‖f‖ keeps the convergence quadratic; convergence
            # is tested on the true residual).
            forcing = 0.1 * res0 / max(ref0, 1e-300)
            eta = float(np.clip(forcing, LINEAR_RTOL_MIN, LINEAR_RTOL_MAX))
            # the mixed element's pressure CG (SchurSolve) the same way, down to its own tighter floor
            eta_p = float(np.clip(forcing, SCHUR_RTOL, LINEAR_RTOL_MAX))
            if not inexact:
                eta, eta_p = LINEAR_RTOL_MIN, SCHUR_RTOL
            if use_chord:
                du, dp = self._chord_solve(factors["lu"], st, free,
                                           max(eta_p, CHORD_SCHUR_RTOL) if inexact else eta_p)
                stats.calls += 1
            else:
                fresh += 1
                du, dp = self._newton_solve(st, C, D, dD, material, method, stats, amg_cache, lu_cache,
                                            eta, eta_p)
            first = np.any(dD != 0.0)
            new, alpha = self._line_search(st, U, p, du, dp, s, fext, material, free, res0, atol, first)
            if new is None and use_chord:
                chord = False  # the old factorization no longer gives a descent: refactorize
                continue
            if new is None:
                if first:
                    return False, U, p, it, np.inf, fresh
                # no decrease: accept the full step only if it keeps J > 0 (Newton may overshoot)
                trial = self._evaluate(U + du, None if p is None else p + dp, s, fext, material, False)
                if trial is None:
                    return False, U, p, it, np.inf, fresh
                new = (U + du, None if p is None else p + dp, self._norm(trial, free, mu), trial)
                alpha = 1.0
            U, p, res, st = new
            ref = max(np.linalg.norm(st["fint"]), s * np.linalg.norm(fext))
            step_small = np.linalg.norm(alpha * du) <= 1e-13 * (np.linalg.norm(U) + self.fmesh.h)
            if res <= rtol * ref + atol or (step_small and res <= 1e-6 * ref + atol):
                return True, U, p, it, res, fresh
            near = CHORD_NEAR_MIXED if self.mixed else CHORD_NEAR
            chord = alpha == 1.0 and res <= CHORD_RATIO * res0 and res <= near * ref
            if fresh >= limit and limit < extend_to and alpha == 1.0 and res <= BASIN_CONTRACTION * res0:
                limit += 1  # out of iterations but in Newton's quadratic basin: one more
        return False, U, p, it, res, fresh

    def _start(self, U, p, s, guess, target, D, fext, material):
        """The state a load step starts from: the secant ``guess`` with the plates at ``target`` when
        it inverts no element, else the last converged state (its first Newton iteration imposes
        the plates: a linearized predictor).  ``(U, p, state with tangent)``, state ``None`` if
        inverted."""
        if guess is not None:  # secant predictor: start from the extrapolated state
            Ug = guess[0].copy()
            Ug[D] = target
            pg = None if guess[1] is None else guess[1].copy()
            st = self._evaluate(Ug, pg, s, fext, material, tangent=True)
            if st is not None:
                return Ug, pg, st
        U = U.copy()
        p = None if p is None else p.copy()
        return U, p, self._evaluate(U, p, s, fext, material, tangent=True)

    def _newton_solve(self, st, C, D, dD, material, method, stats, amg_cache, lu_cache, eta, eta_p):
        """The Newton update ``(du, dp)`` with the tangent of state ``st`` (prescribed increments
        ``dD`` at ``D``), linear solves to ``eta`` (the pressure CG to ``eta_p``)."""
        if self.mixed:
            return solve_saddle(st["K"], st["B"], C, -st["Ru"], -st["Rp"], D, dD,
                                self.nullspace, 1.0 / material.G + 1.0 / material.lam,
                                method=method, stats=stats, cache=lu_cache, order=self.order,
                                separator=self.separator, schur_rtol=eta_p)
        du = solve_spd(st["K"], -st["Ru"], D, dD, self.nullspace, method=method, rtol=eta,
                       stats=stats, cache=amg_cache, order=self.order, separator=self.separator, descent=True)
        return du, None

    def _line_search(self, st, U, p, du, dp, s, fext, material, free, res0, atol, first):
        """Backtracking along ``(du, dp)`` from ``1`` down to ``1/64``: ``((U, p, residual, state),
        step)`` of the first trial that inverts no element and lowers the residual norm or (the
        displacement formulation, a minimum) the potential energy; ``(None, step)`` if none does.
        ``first``: the step imposes new plate displacements (accepted whole unless it inverts)."""
        # Merit of the line search: the residual norm, or (displacement formulation, a
        # minimum) the potential energy Π = ∫ψ − s fext·u, whose slope along du is Ru·du.
        # Far from equilibrium under rotations the Newton step can raise ‖R‖ (spurious
        # stresses of the linearized rotation) while lowering Π: accept on either.
        energy_merit = not self.mixed and not first
        if energy_merit:
            pi0 = self._potential(st, U, s, fext)
            slope = float(st["Ru"] @ du)
            energy_merit = slope < 0.0
        alpha = 1.0
        while alpha >= 1.0 / 64:
            Ut = U + alpha * du
            pt = None if p is None else p + alpha * dp
            trial = self._evaluate(Ut, pt, s, fext, material, tangent=False)
            if trial is not None:
                rt = self._norm(trial, free, material.G)
                if first or rt <= (1.0 - 1e-4 * alpha) * res0 or rt <= atol or (
                        energy_merit
                        and self._potential(trial, Ut, s, fext) <= pi0 + 1e-4 * alpha * slope):
                    return (Ut, pt, rt, trial), alpha
            if first:
                break  # a predictor that inverts elements: shorten the load step instead
            alpha *= 0.5
        return None, alpha

    def _potential(self, st, U, s, fext) -> float:
        """Π = ∫ψ − s fext·u (displacement formulation)."""
        return self.space.integrate(st["psi"]) - s * float(fext @ U)

    def _chord_solve(self, lu, st, free, schur_rtol: float = SCHUR_RTOL):
        """Newton update with an earlier factorization (prescribed dofs already at their values);
        the pressure CG of a :class:`~fem_reference.linalg.SchurSolve` to ``schur_rtol``."""
        du = np.zeros(len(free))
        if self.mixed:
            nf = int(free.sum())
            b = np.concatenate([-st["Ru"][free], -st["Rp"]])
            x = lu.solve(b, schur_rtol) if isinstance(lu, SchurSolve) else lu.solve(b)
            du[free] = x[:nf]
            return du, x[nf:]
        du[free] = lu.solve(-st["Ru"][free])
        return du, None
