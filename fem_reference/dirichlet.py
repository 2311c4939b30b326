"""Prescribed displacements from the Scene's plates, and the plates' reactions.

Every plate selects the Lagrange nodes of a space by reference position
(``plate.region.select(points, body)``, the same predicate the lattice uses) and prescribes
``plate.motion.displacement_at(X, s)`` on its constrained components (``slide``: only the
listed components).  A rotated plate follows the exact rigid rotation about its centre; when the
motion gives no centre, the centre is the centroid of the plate's *lattice particles*, so the
FEM and the MSS rotate about the same point whatever the FEM node set.  A dof claimed by two
plates belongs to the first plate that constrains that component.

The reaction of a plate is the force it exerts on the body: the residual
``r = K u − f`` (linear) or ``r = f_int(u) − f_ext`` (finite strain) at its dofs, summed over its
nodes; the torque is taken about the current centroid of the plate's lattice particles.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from hybmss.result import Reaction
from hybmss.scene import Motion, Scene

from .space import Space


@dataclass(frozen=True, eq=False)
class Dirichlet:
    """Prescribed vector dofs of a space.

    Attributes
    ----------
    dofs : (k,) vector dofs ``3 s + c`` (sorted).
    node : (k,) scalar dof (Lagrange node) of each prescribed dof.
    comp : (k,) component of each prescribed dof.
    owner : (k,) index of the plate owning each dof (−1: no plate).
    names : plate names.
    motions : one :class:`Motion` per plate (with its centre made explicit).
    lattice_sel : per plate, boolean mask over the lattice particles it holds.
    fixed : (k,) values for dofs without a plate (scaled by the load factor).
    """

    dofs: np.ndarray
    node: np.ndarray
    comp: np.ndarray
    owner: np.ndarray
    points: np.ndarray
    names: tuple[str, ...] = ()
    motions: tuple[Motion, ...] = ()
    lattice_sel: tuple[np.ndarray, ...] = ()
    fixed: np.ndarray | None = None

    def values(self, s: float = 1.0) -> np.ndarray:
        """Prescribed values at load factor ``s``."""
        out = np.zeros(len(self.dofs)) if self.fixed is None else s * self.fixed
        for i, motion in enumerate(self.motions):
            k = np.flatnonzero(self.owner == i)
            if len(k) == 0:
                continue
            U = motion.displacement_at(self.points[self.node[k]], s)
            out[k] = U[np.arange(len(k)), self.comp[k]]
        return out

    @classmethod
    def from_values(cls, space: Space, nodes: np.ndarray, values: np.ndarray) -> "Dirichlet":
        """All three components of scalar dofs ``nodes`` prescribed to ``values`` (k, 3) at s = 1."""
        nodes = np.asarray(nodes, dtype=np.int64)
        dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
        order = np.argsort(dofs)
        return cls(
            dofs=dofs[order],
            node=np.repeat(nodes, 3)[order],
            comp=np.tile(np.arange(3), len(nodes))[order],
            owner=-np.ones(len(dofs), dtype=np.int64),
            points=space.points,
            fixed=np.asarray(values, float).reshape(-1)[order],
        )

    # ---------------------------------------------------------------- reactions
    def reactions(self, r: np.ndarray, U: np.ndarray, lattice_x: np.ndarray) -> dict[str, Reaction]:
        """Per-plate :class:`Reaction` from the nodal residual ``r`` (n_vector,).

        ``U`` (n_scalar, 3) are the nodal displacements, ``lattice_x`` (n_particles, 3) the
        deformed particle positions (for the torque centre).
        """
        out = {}
        for i, name in enumerate(self.names):
            k = np.flatnonzero(self.owner == i)
            sel = self.lattice_sel[i]
            if len(k) == 0 or not sel.any():
                out[name] = Reaction((0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                     tuple(map(float, lattice_x[sel].mean(axis=0))) if sel.any()
                                     else (0.0, 0.0, 0.0))
                continue
            nodes, inv = np.unique(self.node[k], return_inverse=True)
            rn = np.zeros((len(nodes), 3))
            np.add.at(rn, (inv, self.comp[k]), r[self.dofs[k]])
            xn = self.points[nodes] + U[nodes]
            c = lattice_x[sel].mean(axis=0)
            F = rn.sum(axis=0)
            T = np.cross(xn - c, rn).sum(axis=0)
            out[name] = Reaction(tuple(map(float, F)), tuple(map(float, T)), tuple(map(float, c)))
        return out


def plate_dirichlet(scene: Scene, space: Space) -> Dirichlet:
    """The Dirichlet data of ``scene``'s plates on ``space``."""
    body = scene.body
    pts = space.points
    lattice = space.fmesh.lattice
    taken: set[int] = set()
    dofs, node, comp, owner = [], [], [], []
    motions, sels = [], []
    for i, plate in enumerate(scene.plates):
        sel_lat = plate.region.select(lattice.X, body)
        motion = plate.motion
        if motion.kind == "rotate" and motion.center is None:
            if not sel_lat.any():
                raise ValueError(f"rotated plate {plate.name!r} holds no lattice particle")
            motion = dataclasses.replace(motion, center=tuple(lattice.X[sel_lat].mean(axis=0)))
        motions.append(motion)
        sels.append(sel_lat)
        nodes = np.flatnonzero(plate.region.select(pts, body))
        for c in np.flatnonzero(motion.constrained):
            for s in nodes:
                d = 3 * int(s) + int(c)
                if d in taken:
                    continue
                taken.add(d)
                dofs.append(d)
                node.append(s)
                comp.append(c)
                owner.append(i)
    dofs = np.asarray(dofs, dtype=np.int64)
    order = np.argsort(dofs)
    return Dirichlet(
        dofs=dofs[order],
        node=np.asarray(node, dtype=np.int64)[order],
        comp=np.asarray(comp, dtype=np.int64)[order],
        owner=np.asarray(owner, dtype=np.int64)[order],
        points=pts,
        names=tuple(p.name for p in scene.plates),
        motions=tuple(motions),
        lattice_sel=tuple(sels),
    )
