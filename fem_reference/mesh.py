"""Hexahedral meshes of a voxel body, and the map between FEM nodes and lattice particles.

The body of a :class:`~hybmss.scene.Scene` is a set of cubic cells of edge ``le`` on a regular
grid.  :func:`build_mesh` turns it into a scikit-fem :class:`~skfem.MeshHex` whose elements
are the same cells, each split into ``r³`` cubes of edge ``h = le / r`` (refinement factor
``r``).  The vertices of the refined grid include every lattice particle (grid index times
``r``); :attr:`FemMesh.particle_nodes` matches them by coordinates.

A mesh is an immutable value: :meth:`FemMesh.refined` and :meth:`FemMesh.with_points`
return new meshes.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from skfem import MeshHex

from hybmss.lattice import Lattice
from hybmss.scene import Body

HEX_CORNERS = np.array(
    [[0, 0, 0], [0, 0, 1], [0, 1, 0], [1, 0, 0], [0, 1, 1], [1, 0, 1], [1, 1, 0], [1, 1, 1]],
    dtype=np.int64,
)
"""Offsets (di, dj, dk) of the 8 vertices of a scikit-fem ``MeshHex`` element, in its order."""


def match_points(points: np.ndarray, targets: np.ndarray, tol: float) -> np.ndarray:
    """Index ``i`` into ``points`` (n, 3) of each row of ``targets`` (k, 3), matched by coordinates.

    Raises :class:`ValueError` if a target has no point within ``tol`` (max-norm).
    """
    points = np.asarray(points, dtype=float)
    targets = np.asarray(targets, dtype=float)
    scale = tol if tol > 0 else 1.0
    keys_p = np.round(points / scale).astype(np.int64)
    keys_t = np.round(targets / scale).astype(np.int64)
    order = np.lexsort(keys_p.T[::-1])
    sorted_keys = keys_p[order]
    # Binary search on the lexicographically sorted rows via a structured view.
    dt = np.dtype([("x", np.int64), ("y", np.int64), ("z", np.int64)])
    sp = np.ascontiguousarray(sorted_keys).view(dt).ravel()
    st = np.ascontiguousarray(keys_t).view(dt).ravel()
    pos = np.searchsorted(sp, st)
    pos = np.clip(pos, 0, len(sp) - 1)
    idx = order[pos]
    bad = np.abs(points[idx] - targets).max(axis=1) > tol
    if bad.any():
        raise ValueError(f"{int(bad.sum())} target point(s) have no mesh node within {tol:g}")
    return idx


@dataclass(frozen=True, eq=False)
class FemMesh:
    """A hexahedral mesh of ``body`` refined ``refine`` times per cell edge.

    Attributes
    ----------
    body : the voxel body.
    refine : refinement factor r (each cell is split into r³ elements of edge ``h = le / r``).
    mesh : the scikit-fem ``MeshHex``.
    grid : (N, 3) integer index of each mesh vertex on the refined grid.
    """

    body: Body
    refine: int
    mesh: MeshHex
    grid: np.ndarray

    @property
    def h(self) -> float:
        """Element edge length le / r."""
        return self.body.le / self.refine

    @property
    def points(self) -> np.ndarray:
        """(N, 3) vertex coordinates."""
        return self.mesh.p.T

    @cached_property
    def lattice(self) -> Lattice:
        return Lattice.from_body(self.body)

    @cached_property
    def particle_nodes(self) -> np.ndarray:
        """Mesh vertex index of every lattice particle (matched by reference coordinates)."""
        return match_points(self.points, self.lattice.X, 1e-6 * self.h)

    def elements_at(self, points: np.ndarray) -> np.ndarray:
        """The element containing each of ``points`` (k, 3) (one of those sharing a face, edge or
        vertex the point lies on): a look-up on the refined grid.  Raises :class:`ValueError` for a
        point outside the body."""
        h, shape = self.h, np.asarray(self.body.shape) * self.refine
        g = (np.asarray(points, float) - np.asarray(self.body.origin)) / h
        base = np.floor(g + 1e-9).astype(np.int64)
        on_face = np.abs(g - np.round(g)) <= 1e-9
        ids = -np.ones(tuple(shape), dtype=np.int64)
        ijk = self.element_cells
        ids[ijk[:, 0], ijk[:, 1], ijk[:, 2]] = np.arange(len(ijk))
        found = -np.ones(len(g), dtype=np.int64)
        for back in HEX_CORNERS:  # the cell above the point, then those behind the faces it lies on
            idx = base - back[None, :] * on_face
            ok = (found < 0) & np.all((idx >= 0) & (idx < shape), axis=1) & ~np.any(back[None, :] & ~on_face, axis=1)
            cand = np.full(len(g), -1, dtype=np.int64)
            cand[ok] = ids[idx[ok, 0], idx[ok, 1], idx[ok, 2]]
            found = np.where(found < 0, cand, found)
        if np.any(found < 0):
            raise ValueError(f"{int(np.sum(found < 0))} point(s) lie outside the body's cells")
        return found

    @cached_property
    def element_cells(self) -> np.ndarray:
        """(ne, 3) integer index of each element on the refined grid (its lowest vertex)."""
        return self.grid[self.mesh.t[0]]

    def refined(self, r: int) -> "FemMesh":
        """The same body meshed with refinement factor ``r`` (absolute, not relative)."""
        return build_mesh(self.body, r)

    def with_points(self, p: np.ndarray) -> "FemMesh":
        """A copy with moved vertices (same connectivity), e.g. a distorted mesh for patch tests.

        :attr:`particle_nodes` keeps the original vertex indices.
        """
        new = FemMesh(self.body, self.refine, MeshHex(np.asarray(p, float).T.copy(), self.mesh.t), self.grid)
        new.__dict__["particle_nodes"] = self.particle_nodes
        return new


def build_mesh(body: Body, refine: int = 1) -> FemMesh:
    """Mesh the active cells of ``body``, each split into ``refine³`` cubes."""
    r = int(refine)
    if r < 1:
        raise ValueError(f"refine must be an integer >= 1, got {refine!r}")
    mask = body.mask
    fine = np.repeat(np.repeat(np.repeat(mask, r, axis=0), r, axis=1), r, axis=2)
    elem_ijk = np.argwhere(fine).astype(np.int64)  # (ne, 3)
    corner_grid = elem_ijk[:, None, :] + HEX_CORNERS[None, :, :]  # (ne, 8, 3)
    used = np.zeros(tuple(np.asarray(fine.shape) + 1), dtype=bool)
    used[corner_grid[..., 0], corner_grid[..., 1], corner_grid[..., 2]] = True
    grid = np.argwhere(used).astype(np.int64)
    node_id = -np.ones(used.shape, dtype=np.int64)
    node_id[grid[:, 0], grid[:, 1], grid[:, 2]] = np.arange(len(grid))
    t = node_id[corner_grid[..., 0], corner_grid[..., 1], corner_grid[..., 2]].T
    h = body.le / r
    p = np.asarray(body.origin)[:, None] + grid.T * h
    mesh = MeshHex(np.ascontiguousarray(p, dtype=float), np.ascontiguousarray(t, dtype=np.int64))
    return FemMesh(body, r, mesh, grid)
