"""The explicit protocol of the mass-spring system for models with their own kernels.

The competitors (:mod:`hybmss.models.corot_hex8`, :mod:`hybmss.models.xpbd_nh`) run on the same
voxel grid as the MSS: nodes are the lattice particles, masses the lumped ``ρ Vc / 8`` per cell
corner, the plates and their ramp ``s(t) = ½(1 − cos(π t/T))`` those of
:mod:`hybmss.explicit`, and a run that leaves the physical range raises the same
:class:`hybmss.explicit.DivergenceError`.  This module holds what they share beyond the plate arrays of
:func:`hybmss.explicit.plate_arrays`: the kernel state in either precision, the divergence check
of the NumPy twins and the :class:`~hybmss.result.Result` of a run.

Precision.  ``f64`` stores positions x; ``f32`` stores displacements u = x − X and velocities in
float32, as the MSS's float32 kernel (:mod:`hybmss._stencil_gen`): a position of a few metres
keeps only ~1e-7 m in float32, a displacement 1e-7 of itself.  The kernels then evaluate the
element arithmetic in float64 from ``X + u`` (edges ``ΔX + Δu``), so the float32 state is the
only rounding: after 10,000 steps the positions differ from the float64 run by ~1e-7 of the
largest displacement (a test bounds it by 1e-5).
"""

from __future__ import annotations

import numpy as np

from .._kernels import particle_state
from ..explicit import BLOWUP_FACTOR, PRECISIONS, RAMP_LAW, DivergenceError
from ..result import Result, reaction_from_nodal
from ..system import System


def kernel_state(x: np.ndarray, v: np.ndarray, X: np.ndarray, precision: str = "f64"):
    """``(W, xg, vg, posmode)``: the flat state of :func:`hybmss._kernels.particle_state` and its
    (3, n) views.  ``f64``: positions, float64 (``posmode`` True); ``f32``: displacements
    ``x − X`` and velocities, float32.  ``x``, ``v``, ``X``: (n, 3)."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)}; got {precision!r}")
    if precision == "f64":
        W, xg, vg = particle_state(x, v)
        return W, xg, vg, True
    W64, _, _ = particle_state(np.asarray(x) - np.asarray(X), v)
    W = W64.astype(np.float32)
    n = len(x)
    return W, W[:3 * n].reshape(3, n), W[3 * n:].reshape(3, n), False


def read_state(xg: np.ndarray, vg: np.ndarray, X: np.ndarray, posmode: bool) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities (n, 3), float64, of the views of :func:`kernel_state`."""
    x = xg.T.astype(np.float64)
    if not posmode:
        x = x + X
    return np.ascontiguousarray(x), np.ascontiguousarray(vg.T, dtype=np.float64)


def one_thread(threads, model: str) -> None:
    """The competitors' kernels are serial: ``threads`` other than 1 is a :class:`ValueError`
    (rather than a run on one thread reported as two)."""
    if int(threads) != 1:
        raise ValueError(f"threads must be 1 for {model} (its kernel is serial), got {threads}")


def blowup_limit2(system: System) -> float:
    """Square of the runaway displacement: 10× the largest body edge (as the MSS)."""
    limit = BLOWUP_FACTOR * max(system.scene.body.size)
    return limit * limit


def find_bad(x: np.ndarray, X: np.ndarray, limit2: float) -> int:
    """NumPy twin of :func:`hybmss._kernels.find_bad` on (n, 3) arrays."""
    u2 = np.einsum("ij,ij->i", x - X, x - X)
    bad = np.flatnonzero(~np.isfinite(u2))
    if len(bad):
        return int(bad[0])
    i = int(np.argmax(u2))
    return i if u2[i] > limit2 else -1


def divergence(system: System, x: np.ndarray, particle: int, step: int, dt: float, dt_c: float | None,
               check_every: int, model: str) -> DivergenceError:
    """The :class:`DivergenceError` of a run that left the physical range at ``step``."""
    grid = tuple(int(g) for g in system.lattice.grid[particle])
    u = x[particle] - system.X[particle]
    unorm = float(np.hypot.reduce(u))  # no overflow of the squares: a run away can reach 1e200 m
    limit = BLOWUP_FACTOR * max(system.scene.body.size)
    what = ("has a non-finite position" if not np.all(np.isfinite(u)) else
            f"moved {unorm:.3g} m, more than {BLOWUP_FACTOR:g}× the body size ({limit:.3g} m)")
    if dt_c is not None and dt > dt_c:
        cause = f"time step dt={dt:g} s exceeds the explicit stability limit dt_crit≈{dt_c:.4g} s of {model}"
    else:
        cause = ("the motion itself ran away (inverted elements under large deformation, or a plate ramp "
                 "too fast); reduce dt or lengthen the ramp")
    msg = (f"explicit {model} run diverged at step {step} (t = {step * dt:.6g} s; checked every "
           f"{check_every} steps): particle {particle} (grid {grid}) {what}. Likely cause: {cause}.")
    return DivergenceError(msg, step=step, particle=int(particle), grid=grid, displacement=unorm, dt=dt,
                           dt_crit=float("nan") if dt_c is None else dt_c, positions=x)


def run_result(system: System, solver: str, x: np.ndarray, v: np.ndarray, f_int: np.ndarray, energy: dict,
               steps: int, wall: float, info: dict) -> Result:
    """Result of an explicit run ending at ``x, v`` with internal forces ``f_int`` (no gravity).

    Reactions as in :func:`hybmss.explicit.simulate_explicit`: ``−(f_int + m g)`` summed over each
    plate's particles, prescribed components only."""
    lat = system.lattice
    vols = lat.cell_volumes(x)
    reactions = {}
    for ps in system.plates:
        idx = ps.particles
        r = -f_int[idx]
        if system.gravity is not None:
            r = r - system.mass[idx, None] * system.gravity[None, :]
        reactions[ps.name] = reaction_from_nodal(x[idx], r * ps.constrained[None, :])
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
