"""What the static and implicit Newton solvers share: norms, force scales and round-off floors
of the convergence test, plate reactions and the :class:`hybmss.result.Result` of a solve."""

from __future__ import annotations

import time

import numpy as np

from ..forces import cell_volumes
from ..result import Reaction, Result, reaction_from_nodal
from ..system import System


def plate_reactions(system: System, x: np.ndarray, f_total: np.ndarray) -> dict[str, Reaction]:
    """Force each plate exerts on the body: ``−(f_int + m g)`` summed over its particles,
    i.e. minus the total force (springs, volume, gravity) on them; torque about its centroid."""
    out = {}
    for p in system.plates:
        out[p.name] = reaction_from_nodal(x[p.particles], -f_total[p.particles])
    return out


def force_scale(system: System, f_total: np.ndarray) -> float:
    """Force scale of the convergence test: the largest plate reaction or applied load (gravity,
    scaled terms such as dead loads, at their full value), never below :func:`force_floor`
    (a zero load has the rest state as its answer: the residual is then judged on the floor)."""
    scale = 0.0
    for p in system.plates:
        scale = max(scale, norm(f_total[p.particles].sum(axis=0)))
    if system.gravity is not None:
        scale = max(scale, norm(system.mass.sum() * system.gravity))
    for t in system.terms:
        if t.scaled:
            scale = max(scale, norm(t.forces(system.X).sum(axis=0)))
    return max(scale, force_floor(system))


def force_floor(system: System) -> float:
    """Round-off level of the free residual: 1e-12 · E · le² · √(3n).  A spring force's rounding
    error is ≈ 1e-16 k le with k ≈ E le, so this floor sits ~4 orders above round-off and far
    below ``rtol`` times any plate reaction of a loaded body."""
    return 1e-12 * system.scene.material.E * system.scene.body.le**2 * np.sqrt(3 * system.n)


def norm(v: np.ndarray) -> float:
    """Euclidean norm without overflow or underflow of the squares (forces of E = 1e300 Pa)."""
    a = float(np.max(np.abs(v), initial=0.0))
    if a == 0.0 or not np.isfinite(a):
        return a
    w = v / a
    return a * float(np.sqrt(dot(w, w)))


def dot(a: np.ndarray, b: np.ndarray) -> float:
    """``a · b`` by NumPy's pairwise sum, not BLAS: a BLAS ``ddot`` of more than 10⁴ entries wakes
    its thread pool, which on a busy machine costs milliseconds per call (3 ms against 30 µs on
    the beam's 11,421 free dofs, while another process keeps the cores busy)."""
    return float(np.sum(a * b))


def inertia_floor(w: np.ndarray, x: np.ndarray) -> float:
    """Round-off level of the inertia force ``w (x − x̃)`` of implicit Euler: positions carry a
    relative error of one ulp, so its rounding is ≈ eps · max|x| · max w per dof; the floor is 10×
    that over the 3n dofs.  At small dt (w = m (1 + c dt)/dt² large) it exceeds the static floor,
    and a residual at this level is as converged as positions stored in float64 allow."""
    return 10.0 * np.finfo(float).eps * float(np.abs(x).max()) * float(w.max()) * np.sqrt(x.size)



def make_result(system: System, solver: str, x: np.ndarray, f_total: np.ndarray, parts: dict,
                iterations: int, t0: float, converged: bool, info: dict) -> Result:
    """The :class:`Result` of a solve that ended at ``x`` (``f_total``: the forces there)."""
    vols = cell_volumes(x, system.lattice.cells)
    V0 = system.scene.body.volume
    info = dict(info)
    info["inverted_cells"] = int(np.count_nonzero(vols <= 0.0))
    return Result(
        solver=solver,
        scene_digest=system.scene.digest(),
        X=system.X.copy(),
        u=x - system.X,
        volume=float(vols.sum()),
        volume0=float(V0),
        reactions=plate_reactions(system, x, f_total),
        energy={k: float(v) for k, v in parts.items()},
        iterations=int(iterations),
        wall_time_s=time.perf_counter() - t0,
        converged=converged,
        cell_volumes=vols,
        info=info,
    )

