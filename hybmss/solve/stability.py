"""Stability of an equilibrium: the smallest eigenpair of the constrained Hessian, the saddle check
and escape, zero-energy modes of a cell, the limit-point (fold) test and the failure it reports.

**Zero-energy modes.**  Without face diagonals (``hybmss-fd``) the cubic lattice has hourglass
modes, so the constrained Hessian can be singular even with clamped plates
(:func:`cell_zero_energy_modes`; :mod:`hybmss.solve.newton` says what the Newton does about them).

**Loss of stability.**  For ν < 1/4, κ < 0 and the volume energy is unbounded below under
dilation; at large tension the equilibrium disappears.  When the load step cannot be reduced
further, :class:`StaticSolveError` reports the load factor reached and the smallest eigenvalue of
the constrained Hessian there (:func:`fold_error`), naming this cause when κ < 0.

**Locating the limit point.**  Near a fold at ``s*`` the stable branch is ``x(s) ≈ x* − c√(s* − s) e``
with λ_min ∝ √(s* − s), so the linear predictor from an equilibrium at ``s < s*`` over a step
``h`` lands on a state whose Hessian is indefinite once ``h > 2 (s* − s)``: beyond the fold.
With κ < 0, a predicted state that dilates the body and whose smallest eigenvalue is below
``−FOLD_MARGIN`` times that of the stable equilibrium it was predicted from (a failed Cholesky of
the shifted Hessian, no Newton needed) therefore brackets a limit point (:func:`fold_suspected`;
:mod:`hybmss.solve.static` bisects the bracket).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla

from ..forces import cell_volumes, energy_forces
from ..scene import Scene, unsupported
from ..system import System
from .errors import StaticSolveError
from .linalg import CholeskyFactor, Factorizer, cholmod, factor, not_definite, positive_definite, \
    superlu_symmetric, tangent


def cell_zero_energy_modes(S: System) -> bool:
    """Whether a cell of the lattice, on its own, has a zero-energy mode at rest besides the six
    rigid motions (the hourglass modes of a cubic lattice without face diagonals, hybmss-fd): the
    rest Hessian of the springs joining two of its corners, ``Σ k ê êᵀ``, plus the volume term's
    rank-one ``g gᵀ`` (``g = ∂V/∂x``: any energy of the cell volume has that Hessian at rest),
    has more than six eigenvalues below 1e-9 of the largest.  Such a lattice has equilibria that
    depend on the path (buckled, hourglassed), so :func:`hybmss.solve.newton.newton` keeps its unshifted steps on it."""
    cells = S.lattice.cells
    if len(cells) == 0:
        return False
    return _zero_energy_modes_of_cell(S, int(len(cells) // 2))


def _zero_energy_modes_of_cell(S: System, c: int) -> bool:
    nodes = np.asarray(S.lattice.cells[c], dtype=np.int64)
    local = np.full(S.n, -1, dtype=np.int64)
    local[nodes] = np.arange(8)
    la, lb = local[S.spring_a], local[S.spring_b]
    inside = (la >= 0) & (lb >= 0)
    K = np.zeros((24, 24))
    X = S.X
    for a, b, k in zip(la[inside], lb[inside], S.spring_k[inside]):
        e = X[nodes[b]] - X[nodes[a]]
        e = e / np.linalg.norm(e)
        B = np.zeros(24)
        B[3 * a:3 * a + 3], B[3 * b:3 * b + 3] = -e, e
        K += k * np.outer(B, B)
    if S.has_volume:
        x0 = X[nodes].reshape(1, 8, 3)
        h = 1e-6 * S.scene.body.le
        g = np.empty(24)
        idx = np.arange(8).reshape(1, 8)
        for j in range(24):
            xp, xm = x0.copy(), x0.copy()
            xp[0, j // 3, j % 3] += h
            xm[0, j // 3, j % 3] -= h
            g[j] = (cell_volumes(xp.reshape(8, 3), idx)[0] - cell_volumes(xm.reshape(8, 3), idx)[0]) / (2 * h)
        scale = np.abs(np.diag(K)).max() if K.any() else 1.0
        K += scale * np.outer(g, g) / float(g @ g)
    w = np.linalg.eigvalsh(K)
    return int(np.count_nonzero(w <= 1e-9 * max(abs(w).max(), 1e-300))) > 6


def smallest_eigenpair(system: System, x: np.ndarray, fac: Factorizer | None = None) -> tuple[float, np.ndarray]:
    """Smallest eigenvalue (N/m) of the constrained Hessian at ``x`` and its eigenvector
    (over the free dofs).  ``fac``: a factorizer whose symbolic analysis of the pattern is reused
    (its factor is overwritten)."""
    free = ~system.fixed.ravel()
    T = tangent(system, x, 1.0, free)
    Hff = T.csc()
    if Hff.shape[0] <= 600:
        w, v = np.linalg.eigh(Hff.toarray())
        return float(w[0]), v[:, 0]
    fac = fac if fac is not None else Factorizer()
    dmax = float(abs(Hff.diagonal()).max())
    # Gershgorin: no eigenvalue lies below min_i (H_ii − Σ_j≠i |H_ij|)
    floor = float((Hff.diagonal() - (abs(Hff).sum(axis=1).A1 - abs(Hff.diagonal()))).min())
    # a fixed start vector: ARPACK's default is random, and the mode it returns then picks which
    # of two nearly equal soft directions a saddle escape follows (runs would differ)
    v0 = np.random.default_rng(0).standard_normal(Hff.shape[0])
    try:
        shift = -1e-3 * dmax
        for _ in range(12):
            # shift-invert with the factorization of A − σI the Newton solves use (Cholesky, or
            # the minimum-degree symmetric LU when it is indefinite), not splu's default ordering
            with np.errstate(all="ignore"):
                F = factor(T.shifted(-shift), fac)
            op = spla.LinearOperator(Hff.shape, matvec=F.solve, dtype=float)
            vals, vecs = spla.eigsh(Hff, k=1, sigma=shift, which="LM", OPinv=op, v0=v0)
            lam = float(vals[0])
            if not np.isfinite(lam):
                raise ArithmeticError("shift-invert without pivoting broke down")
            # the eigenvalue nearest the shift is the smallest only if H − (λ − ε) I is positive
            # definite; a more negative one lies beyond it (a saddle deep in the spectrum)
            below = lam - 1e-9 * dmax - 1e-6 * abs(lam)
            if positive_definite(T.shifted(-below), fac) or shift <= floor:
                return lam, vecs[:, 0]
            shift = max(min(lam, shift) - 10.0 * abs(min(lam, shift)), floor - 1e-6 * dmax)
        raise ArithmeticError("the smallest eigenvalue was not isolated")
    except Exception:  # pragma: no cover - fall back to a dense solve
        w, v = np.linalg.eigh(Hff.toarray())
        return float(w[0]), v[:, 0]


def smallest_eigenvalue(system: System, x: np.ndarray, fac: Factorizer | None = None) -> float:
    """Smallest eigenvalue of the constrained Hessian at ``x`` (N/m) (``fac``: as for
    :func:`smallest_eigenpair`)."""
    return smallest_eigenpair(system, x, fac)[0]


def stable_at(S: System, x: np.ndarray, free: np.ndarray, fac: Factorizer | None = None):
    """``(stable, lam, vec)`` at ``x``.  A Cholesky factorization that succeeds certifies that
    the constrained Hessian is positive definite; otherwise its inertia comes from the symmetric
    LU (no pivoting: the pivots are the D of LDLᵀ, Sylvester's law); only when a pivot is
    negative or tiny is the smallest eigenpair computed (shift-invert)."""
    Hff = tangent(S, x, 1.0, free)
    if fac is not None and fac.cholesky(Hff) is not None:
        return True, float("nan"), None
    tol = 1e-9 * float(np.abs(Hff.diagonal()).mean())
    try:
        with np.errstate(all="ignore"):
            pivots = superlu_symmetric(Hff).U.diagonal()
        if np.all(np.isfinite(pivots)) and pivots.min() > tol:
            return True, float("nan"), None
    except RuntimeError:  # singular: zero-energy modes, decide from the eigenvalue
        pass
    lam, vec = smallest_eigenpair(S, x, fac)
    return lam >= -tol, lam, vec


def escape_saddle(S: System, x: np.ndarray, free: np.ndarray, vec: np.ndarray):
    """The point of lowest energy along the unstable eigenvector ``vec`` (both signs, amplitudes
    from 1e-3 to 3 le for the largest particle displacement); None if none is lower."""
    e0 = energy_forces(S, x)[0]
    step = np.zeros(x.size)
    step[free] = vec / np.abs(vec).max()
    step = step.reshape(x.shape)
    best, best_e = None, e0
    for amp in (1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.3, 1.0, 3.0):
        for sign in (1.0, -1.0):
            xt = x + sign * amp * S.scene.body.le * step
            if np.any(cell_volumes(xt, S.lattice.cells) <= 0.0):
                continue
            et = energy_forces(S, xt)[0]
            if et < best_e:
                best, best_e = xt, et
    return best


FOLD_MARGIN = 0.1
"""A predicted state lies beyond a limit point when its smallest eigenvalue is below
``−FOLD_MARGIN`` times that of the stable equilibrium it was predicted from: past a fold it is of
the order of minus that one (−0.4 to −8 N/m against 1.6–2.4 N/m on the ν = 0 beams of 4×4×24), while
round-off and slightly soft modes stay above.  It only steers the bisection: a bifurcation
(hybmss-fd at ν = 0.2 in tension dips to −0.35 against 0.32 N/m on a path that goes on) is told
apart by the ordinary Newton at the end of the bracket."""


def fold_suspected(S: System, guess: np.ndarray, free: np.ndarray, fac: Factorizer, load: float,
                    lam_x) -> tuple[bool, CholeskyFactor | None]:
    """Whether a predicted state ``guess`` of a κ < 0 body lies beyond a limit point: it dilates
    the body and the smallest eigenvalue of its constrained Hessian is below ``−FOLD_MARGIN ·
    lam_x()`` (``lam_x``: the smallest eigenvalue at the equilibrium predicted from, computed only
    when the Hessian at ``guess`` is not positive definite; no fold is suspected unless it is > 0).
    ``fac`` is a factorizer of its own, so the factor the predictor hands to Newton stays valid.
    Returns ``(suspected, F)``: ``F`` the Cholesky factor of the Hessian at ``guess`` when it is
    positive definite (Newton's first step from ``guess`` is then an exact one at no cost; valid
    until ``fac`` factorizes again), else None."""
    vols = cell_volumes(guess, S.lattice.cells)
    if np.any(vols <= 0.0) or not float(vols.sum()) > float(S.lattice.cell_volumes(S.X).sum()):
        return False, None
    Hff = tangent(S, guess, load, free)
    if cholmod is not None:
        F = fac.cholesky(Hff)
        if F is not None:
            return False, F
    elif not not_definite(Hff, 0.0, fac):
        return False, None
    lam = lam_x()
    return bool(lam > 0.0 and not_definite(Hff, FOLD_MARGIN * lam, fac)), None



def fold_error(S: System, scene: Scene, x: np.ndarray, guess: np.ndarray, s: float, s_new: float,
               lam: float | None = None, fac: Factorizer | None = None) -> StaticSolveError:
    """Why the load could not be increased past ``s`` (energy mode): the smallest eigenvalue of
    the constrained Hessian at the last equilibrium ``x`` (``lam`` when already known) and at the
    predicted state ``guess`` just beyond it, as the fields of the error and in its message."""
    if lam is None:
        lam = smallest_eigenvalue(S, x, fac)
    lam_next = smallest_eigenvalue(S, guess, fac)
    head = (f"static solve of scene {scene.name or '(unnamed)'} failed at load factor s={s_new:.6g} "
            f"(last converged s={s:.6g}); smallest eigenvalue of the constrained Hessian: {lam:.4g} N/m at "
            f"s={s:.6g}, {lam_next:.4g} N/m at the predicted state s={s_new:.6g}")
    cause, why = _fold_cause(S, x, s, lam, lam_next)
    return StaticSolveError(head + why, cause=cause, load_factor=float(s), next_load_factor=float(s_new),
                            smallest_eigenvalue=float(lam), next_smallest_eigenvalue=float(lam_next))


def _fold_cause(S: System, x: np.ndarray, s: float, lam: float, lam_next: float) -> tuple[str, str]:
    """``(cause, the message's tail)`` of :func:`fold_error`."""
    if s == 0.0 and lam < 0 and unsupported(S.scene):  # a zero-energy rigid mode, not a negative modulus
        return "indefinite-at-rest", "; " + unsupported(S.scene)
    if s == 0.0 and lam < 0:
        return "indefinite-at-rest", ("; the model is not positive definite even at rest (its effective bulk or "
                                      "shear modulus is negative for these constants): no stable equilibrium exists")
    dilating = float(cell_volumes(x, S.lattice.cells).sum()) > float(S.lattice.cell_volumes(S.X).sum())
    if S.kappa < 0 and dilating:
        evidence = ("the Hessian becomes indefinite" if min(lam, lam_next) < 0 else
                    "Newton no longer converges from the tangent predictor, as at a fold")
        return "limit-point", (f"; {evidence}: the volume term has kappa={S.kappa:.4g} Pa < 0 (nu < 1/4) and is "
                               "unbounded below under dilation, so the equilibrium is lost at a limit point "
                               "(instability), not a numerical failure")
    if min(lam, lam_next) < 0:
        return "unstable-path", ("; the Hessian becomes indefinite: the equilibrium path is unstable (buckling or "
                                 "zero-energy modes)")
    return "newton", ("; the Hessian stays positive definite: Newton failed to converge; remedy: more load steps "
                      "(StaticOptions(initial_steps=N, max_step=1/N), --load-steps N of hybmss compare)")


def residual_error(scene: Scene, s: float, s_new: float, rnorm: float) -> StaticSolveError:
    """Why a residual-mode solve could not increase the load past ``s``."""
    return StaticSolveError(
        f"static solve of scene {scene.name or '(unnamed)'} (model {scene.model.name}) failed at load "
        f"factor s={s_new:.6g} (last converged s={s:.6g}); residual {rnorm:.3g} N: its non-conservative "
        "forces have no energy to certify a stable state, so the equilibrium path may be lost; "
        "remedy: a smaller load, or more load steps (StaticOptions(initial_steps=N, max_step=1/N), --load-steps N of "
        "hybmss compare)",
        cause="residual", load_factor=float(s), next_load_factor=float(s_new), residual=float(rnorm))
