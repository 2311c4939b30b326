"""The plates of an explicit run: the load ramp, the initial state, the plates in the layout of
the kernels, and the plates' reactions.

Load factor ``s(t) = ½ (1 − cos(π t / T))`` for ``t < T = ramp_time``, then ``s = 1``.  A plate's
reaction is ``−Σ (f_int + m g)`` over its particles, prescribed components only, with the torque
about its current centroid."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..result import reaction_from_nodal
from ..system import System

RAMP_LAW = "s(t) = 0.5 (1 - cos(pi t / T)) for t < T, then 1"


def ramp(t: float, T: float) -> float:
    """Load factor s(t) = ½ (1 − cos(π t/T)) for t < T, then 1 (s ≡ 1 when T ≤ 0)."""
    if T <= 0.0 or t >= T:
        return 1.0
    if t <= 0.0:
        return 0.0
    return 0.5 * (1.0 - math.cos(math.pi * t / T))


def initial_state(system: System, x0, v0, ramp_time: float) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities (n, 3) at t = 0: ``x0``/``v0`` (default: rest, zero velocity),
    with the plates' prescribed components at the start of their ramp and at rest."""
    x = system.X.copy() if x0 is None else np.array(x0, dtype=float).reshape(system.n, 3)
    v = np.zeros((system.n, 3)) if v0 is None else np.array(v0, dtype=float).reshape(system.n, 3)
    P0 = system.prescribed(ramp(0.0, ramp_time))
    x[system.fixed] = P0[system.fixed]
    v[system.fixed] = 0.0
    return x, v


@dataclass(frozen=True, eq=False)
class PlateArrays:
    """Plates of a system in the layout of :func:`hybmss._kernels.apply_plates`: node numbers of
    the kernel (particle indices, or grid indices of the stencil kernel), the displacement at full
    load ``U1`` (3, n), and per plate its prescribed components, motion kind and parameters."""

    nodes: np.ndarray
    U1: np.ndarray
    ptr: np.ndarray
    mask: np.ndarray
    kind: np.ndarray
    disp: np.ndarray
    axis: np.ndarray
    center: np.ndarray
    angle: np.ndarray

    def args(self) -> tuple:
        return (self.nodes, self.U1, self.ptr, self.mask, self.kind, self.disp, self.axis, self.center,
                self.angle)


def plate_arrays(system: System, node: np.ndarray | None = None) -> PlateArrays:
    """The plates of ``system`` for the kernels, particle ``a`` being kernel node ``node[a]``
    (``None``: the particle index).  Raises ``ValueError`` for a motion neither linear in the load
    factor nor a rotation (the kernels know only those two)."""
    le = system.scene.body.le
    nodes, U1, ptr, mask, kind, disp, axis, center, angle = [], [], [0], [], [], [], [], [], []
    for plate, ps in zip(system.scene.plates, system.plates):
        m = plate.motion
        Xp = system.X[ps.particles]
        u1 = m.displacement_at(Xp, 1.0)
        if m.kind != "rotate" and not np.allclose(m.displacement_at(Xp, 0.5), 0.5 * u1, rtol=1e-12,
                                                  atol=1e-12 * le):
            raise ValueError(f"plate {plate.name!r}: the numba kernels need a motion linear in the load factor "
                             f"or a rotation, got {m.kind!r}; use kernel='numpy'")
        nodes.append(ps.particles if node is None else node[ps.particles])
        U1.append(u1.T)
        ptr.append(ptr[-1] + len(ps.particles))
        mask.append(ps.constrained)
        kind.append(1 if m.kind == "rotate" else 0)
        disp.append(m.displacement)
        axis.append(m.axis)
        center.append(m.center if m.center is not None else Xp.mean(axis=0))
        angle.append(m.angle)
    n_pl = len(system.plates)
    return PlateArrays(
        nodes=np.concatenate(nodes).astype(np.int64) if nodes else np.zeros(0, dtype=np.int64),
        U1=np.ascontiguousarray(np.concatenate(U1, axis=1)) if U1 else np.zeros((3, 0)),
        ptr=np.asarray(ptr, dtype=np.int64),
        mask=np.asarray(mask, dtype=np.bool_).reshape(n_pl, 3),
        kind=np.asarray(kind, dtype=np.int64),
        disp=np.asarray(disp, dtype=float).reshape(n_pl, 3),
        axis=np.asarray(axis, dtype=float).reshape(n_pl, 3),
        center=np.asarray(center, dtype=float).reshape(n_pl, 3),
        angle=np.asarray(angle, dtype=float),
    )


def hold_clamped(plates: PlateArrays) -> tuple[PlateArrays, np.ndarray]:
    """``plates`` without the clamped ones (every component prescribed, no motion) whose nodes
    no other plate moves, and those nodes.  A node given ``1/m = 0`` and no gravity keeps its
    position and zero velocity through the kernel's own update, so it needs no plate write."""
    n_pl = len(plates.kind)
    own = [plates.nodes[plates.ptr[i]:plates.ptr[i + 1]] for i in range(n_pl)]
    held = [i for i in range(n_pl) if plates.kind[i] == 0 and plates.mask[i].all()
            and not plates.U1[:, plates.ptr[i]:plates.ptr[i + 1]].any()]
    for i in list(held):
        others = [own[j] for j in range(n_pl) if j != i]
        if others and np.isin(own[i], np.concatenate(others)).any():
            held.remove(i)
    if not held:
        return plates, np.zeros(0, dtype=np.int64)
    keep = [i for i in range(n_pl) if i not in held]
    cols = [np.arange(plates.ptr[i], plates.ptr[i + 1]) for i in keep]
    cols = np.concatenate(cols) if cols else np.zeros(0, dtype=np.int64)
    ptr = np.concatenate([[0], np.cumsum([len(own[i]) for i in keep])]).astype(np.int64)
    kept = PlateArrays(nodes=plates.nodes[cols], U1=np.ascontiguousarray(plates.U1[:, cols]), ptr=ptr,
                       mask=plates.mask[keep].reshape(len(keep), 3), kind=plates.kind[keep],
                       disp=plates.disp[keep].reshape(len(keep), 3), axis=plates.axis[keep].reshape(len(keep), 3),
                       center=plates.center[keep].reshape(len(keep), 3), angle=plates.angle[keep])
    return kept, np.concatenate([own[i] for i in held]).astype(np.int64)


def plate_reactions(system: System, x: np.ndarray, f_int: np.ndarray) -> dict:
    """Each plate's reaction at positions ``x`` with internal forces ``f_int`` (no gravity):
    ``−Σ (f_int + m g)`` over its particles, prescribed components only, torque about its current
    centroid (:func:`hybmss.result.reaction_from_nodal`)."""
    reactions = {}
    for ps in system.plates:
        idx = ps.particles
        r = -f_int[idx]
        if system.gravity is not None:
            r = r - system.mass[idx, None] * system.gravity[None, :]
        r = r * ps.constrained[None, :]
        reactions[ps.name] = reaction_from_nodal(x[idx], r)
    return reactions
