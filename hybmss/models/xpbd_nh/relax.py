"""The static relaxation of ``xpbd-nh``: the rest state of the XPBD substep h reached by a damped
iteration in pseudo-time steps H ≥ h (:func:`relax_static`)::

    y = x + β (x − x_prev),  β = 1/(1 + c H)
    x_new = y + (H/h)² (P_h(y + d_h h² g) − y)       (prescribed components: P_h's values)

``P_h`` the constraint projection of one XPBD substep, ``d_h = 1/(1 + c_h h)``.  A fixed point
satisfies ``P_h(x + d_h h² g) = x``, the rest state of the XPBD run with substep h, for any H.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ...explicit import (BLOWUP_FACTOR, RAMP_LAW, divergence_error, find_bad, initial_state, plate_arrays,
                         plate_reactions, ramp)
from ...result import Result
from ...stepper import Chunks, interruptible, timed
from ...system import System
from . import _kernels as _kernels_xpbd
from .constraints import KERNELS, XpbdNH, external_acceleration, inverse_masses, numpy_substep

RELAX_CHECK_FRAMES = 20.0
"""The relaxation's rest criterion spans this many frames ``dt = 1/ω_max`` of pseudo-time (the
dynamic run's: 10).  Right after the ramp its pseudo-time motion can be quiet over 10 frames while
the state is still far from rest: on the 4×1×1 [B09] cantilever under gravity it stopped 2e-3 from
the converged tip; over 20 frames 8e-5 (the dynamic run: 5e-5), for 3 % more iterations on 16×4×4."""

RELAX_H_OMEGA = 0.5
"""``H ω_max`` of the relaxation's pseudo-time step H (:func:`relax_static`): 5× the substep of the
rest-state run at 10 substeps per frame (``over = (H/h)² = 25``).  Measured on five scenes (6³ cube:
torsion 45° at ν = 0.499, compression 20 % at ν = 0.25 and 0.499, shear 20 % at ν = 0; 4×4×24 beam
under gravity): the rest state at 0.5 is the run's own within 3.6e-7 of the largest displacement;
at 1.0 the shear did not come to rest and the ν = 0.499 compression came to rest in another state
(48 % away), at 1.2 every one diverged: the damped linearization's limit ``H ω < 2`` is reached
near ``H ω_max ≈ 1`` because XPBD's tetrahedra are stiffer than the Hex8 cells that give ω_max.
0.5 keeps a factor 2 from it."""


RELAX_ROUNDING = 64.0
"""The relaxation's motion test never asks for less motion than this many roundings of its update
(:func:`rounding_floor`)."""


def rounding_floor(system: System, over: float) -> float:
    """The motion (m) that rounding alone leaves in :func:`relax_static`'s update
    ``y + over (P_h(y) − y)``: positions of magnitude |x| carry ``eps |x|``, which the factor
    ``over = (H/h)²`` multiplies; :data:`RELAX_ROUNDING` of it, for positions up to the body's
    farthest point plus its size."""
    extent = float(np.abs(system.X).max()) + max(system.scene.body.size)
    return RELAX_ROUNDING * over * float(np.finfo(float).eps) * extent


def relax_static(system: System, term: XpbdNH, h: float, H: float, damping: float, ramp_time: float,
                 max_time: float, check_time: float, rest_tol: float, iterations: int = 1, coupled: bool = True,
                 kernel: str = "numba", damping_h: float | None = None, x0: np.ndarray | None = None) -> Result:
    """The rest state of the XPBD substep ``h`` (damping ``damping_h``, default ``damping``),
    reached by a damped iteration in pseudo-time steps ``H ≥ h``::

        y = x + β (x − x_prev),  β = 1/(1 + c H)
        x_new = y + (H/h)² (P_h(y + d_h h² g) − y)       (prescribed components: P_h's values)

    with ``P_h`` the constraint projection of one XPBD substep (``iterations`` sweeps, multipliers
    reset, plates at the load of the pseudo-time ``(k + 1) H`` on the ramp ``ramp_time``) and
    ``d_h = 1/(1 + c_h h)`` the XPBD substep's damping factor.  A fixed point satisfies
    ``P_h(x + d_h h² g) = x``: exactly the rest state of the XPBD run with substep h and damping
    c_h (one substep maps (x, v = 0) to itself), for any ``H``; with ``H = h`` and ``c = c_h`` the
    iteration *is* that run (``v = (x − x_prev)/h``).  For soft constraints (``h ω ≪ 1``, the
    accuracy rule) ``P_h(z) − z ≈ −h² W ∇E``, so the iteration is the damped dynamics in steps H:
    the rest state is reached in ``h/H`` of the substeps.  Stops at rest (no node moved more than
    ``rest_tol · le`` over ``check_time`` of pseudo-time after the ramp) or at ``max_time``.
    ``x0``: the start (default the reference positions), its prescribed components at the ramp's
    start (a start already under the whole load: ``ramp_time`` 0)."""
    if kernel not in KERNELS:
        raise ValueError(f"kernel must be one of {', '.join(KERNELS)}; got {kernel!r}")
    if not (0.0 < h <= H):
        raise ValueError(f"0 < h <= H required, got h={h}, H={H}")
    c_h = float(damping) if damping_h is None else float(damping_h)
    over = (H / h) ** 2
    d_h = 1.0 / (1.0 + c_h * h)
    rest_disp = rest_tol * system.scene.body.le  # 0: no rest test (a fixed count of iterations)
    if rest_disp > 0.0:
        rest_disp = max(rest_disp, rounding_floor(system, over))
    limit = BLOWUP_FACTOR * max(system.scene.body.size)
    it = _Relaxation(h=h, H=H, over=over, beta=1.0 / (1.0 + float(damping) * H), ramp_time=ramp_time,
                     n_max=int(math.ceil(max_time / H)), check=max(1, int(round(check_time / H))),
                     rest_after=int(math.ceil(ramp_time / H)), rest_disp=rest_disp, limit2=limit * limit,
                     iterations=iterations, coupled=coupled)
    x, _ = initial_state(system, x0, None, ramp_time)
    winv = inverse_masses(system)
    gdisp = np.zeros((system.n, 3))
    accel = external_acceleration(system)
    if accel is not None:
        gdisp[:] = d_h * h * h * accel
    gdisp[winv == 0.0] = 0.0
    c0, t0 = time.process_time(), time.perf_counter()
    run = _relax_numba if kernel == "numba" else _relax_numpy
    x, x_prev, done, bad, rest = run(system, term, x, winv, gdisp, accel is not None, it)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    if bad >= 0:
        raise divergence_error(system, x, bad, done, H, limit, None, it.check)
    v = (x - x_prev) / H
    info = {"kernel": kernel, "threads": 1, "precision": "f64", "cpu_time_s": cpu, "h": h, "H": H,
            "over_relaxation": over, "beta": it.beta, "steps": done, "iterations": iterations,
            "coupled": bool(coupled), "t_end": done * H, "damping": float(damping), "damping_h": c_h,
            "ramp_time": float(ramp_time), "load_factor": ramp(done * H, ramp_time), "model": term.name,
            "until_rest": True, "rest": rest, "t_rest": done * H if rest else None, "rest_tol": rest_tol,
            "rest_disp": rest_disp, "check_time": it.check * H,
            "tet_split": "two complementary 5-tet splits at half weight"}
    return _rest_result(system, f"{term.name}-rest", x, v, term.forces(x), {"strain": term.energy(x)}, done, wall,
                        info)


@dataclass(frozen=True)
class _Relaxation:
    """The schedule of :func:`relax_static`'s iteration: substep ``h``, pseudo-time step ``H``,
    ``over = (H/h)²``, ``β = 1/(1 + c H)``, the ramp, at most ``n_max`` steps, the motion and
    blow-up tests every ``check`` steps (the motion test from step ``rest_after`` on, against
    ``rest_disp``; blow-up beyond ``√limit2``) and the projection's sweeps."""

    h: float
    H: float
    over: float
    beta: float
    ramp_time: float
    n_max: int
    check: int
    rest_after: int
    rest_disp: float
    limit2: float
    iterations: int
    coupled: bool


def _relax_numba(system: System, term: XpbdNH, x: np.ndarray, winv: np.ndarray, gdisp: np.ndarray, loaded: bool,
                 it: _Relaxation):
    """``(x, x_prev, steps done, bad particle or −1, at rest)`` of the iteration by the Numba
    kernel ``relax`` of :func:`hybmss.models.xpbd_nh._kernels.stepping`, in calls of whole check intervals."""
    n = system.n
    W = np.zeros(6 * n)
    xg = W[:3 * n].reshape(3, n)
    xg[:] = x.T
    xprev, y = xg.copy(), np.empty((3, n))
    plates = plate_arrays(system)
    args = (np.ascontiguousarray(system.X.T), np.ascontiguousarray(winv.T), term.tets, term.Dminv, term.Vt,
            term.mu, term.lam, term.gamma, np.ascontiguousarray(gdisp.T), loaded, it.h, it.over,
            it.beta, it.H, float(it.ramp_time), *plates.args())
    lamb = np.empty((len(term.tets), 2))
    bnodes, bcount = term.batches()
    B = np.empty(_kernels_xpbd.SLOTS * _kernels_xpbd.LANES)
    relax = _kernels_xpbd.stepping(bnodes, it.iterations, it.coupled)[1]
    chunks = Chunks(it.check)
    done, bad, rest = 0, -1, False
    with interruptible():  # calls of whole check intervals (~0.1 s): a signal stops it between them
        while done < it.n_max and bad < 0 and not rest:
            interruptible.check()
            n_call = chunks.next(it.n_max - done)
            (k, bad, rest), w, _ = timed(
                relax, W, *args, np.int64(done), np.int64(n_call), np.int64(it.iterations),
                bool(it.coupled), np.int64(it.check), float(it.limit2), np.int64(it.rest_after),
                float(it.rest_disp), xprev, y, lamb, bnodes, bcount, B)
            chunks.took(n_call, w)
            done, bad, rest = done + int(k), int(bad), bool(rest)
    return np.ascontiguousarray(xg.T), np.ascontiguousarray(xprev.T), done, bad, rest


def _relax_numpy(system: System, term: XpbdNH, x: np.ndarray, winv: np.ndarray, gdisp: np.ndarray, loaded: bool,
                 it: _Relaxation):
    """The readable twin of :func:`_relax_numba` (same result to rounding)."""
    fixed = system.fixed
    free = winv != 0.0
    x_prev, x_check = x.copy(), x.copy()
    for k in range(it.n_max):
        y = x + it.beta * (x - x_prev)
        x_prev = x
        target = system.prescribed(ramp((k + 1) * it.H, it.ramp_time))
        p = y + gdisp
        p[fixed] = target[fixed]
        v = np.zeros_like(p)
        numpy_substep(term, p, v, winv, it.h, 1.0, it.iterations, None, lambda xx: None, it.coupled)
        x = np.where(free, y + it.over * (p - y), p)
        if (k + 1) % it.check == 0 or k == it.n_max - 1:
            bad = find_bad(x, system.X, it.limit2)
            if bad >= 0:
                return x, x_prev, k + 1, bad, False
            if k + 1 >= it.rest_after and (k + 1) % it.check == 0:
                if np.abs(x - x_check).max() <= it.rest_disp:
                    return x, x_prev, k + 1, -1, True
            x_check = x.copy()
    return x, x_prev, it.n_max, -1, False


def _rest_result(system: System, solver: str, x: np.ndarray, v: np.ndarray, f_int: np.ndarray, energy: dict,
                 steps: int, wall: float, info: dict) -> Result:
    """Result of the relaxation ending at ``x, v`` with internal forces ``f_int`` (no gravity);
    reactions as in :func:`hybmss.explicit.simulate_explicit`: ``−(f_int + m g)`` summed over
    each plate's particles, prescribed components only.  ``converged``: True (the caller sets it
    from ``info['rest']``)."""
    lat = system.lattice
    vols = lat.cell_volumes(x)
    reactions = plate_reactions(system, x, f_int)
    energy = dict(energy)
    energy["kinetic"] = float(0.5 * np.sum(system.mass[:, None] * v * v))
    info = dict(info)
    info.setdefault("ramp_law", RAMP_LAW)
    info["inverted_cells"] = int(np.count_nonzero(vols <= 0.0))
    info["max_speed"] = float(np.linalg.norm(v, axis=1).max()) if len(v) else 0.0
    return Result(solver=solver, scene_digest=system.scene.digest(), X=system.X.copy(), u=x - system.X,
                  volume=float(vols.sum()), volume0=float(lat.cell_volumes(system.X).sum()),
                  reactions=reactions, energy=energy, iterations=int(steps), wall_time_s=float(wall),
                  converged=True, cell_volumes=vols, info=info)
