"""The cubic lattice of a body (SPEC §1).

A particle sits at every vertex of an active cell.  Each cell has 12 edges (length ``le``),
12 face diagonals (``√2 le``, two per face) and 4 inner diagonals (``√3 le``).  Springs shared
between cells are merged into one spring whose constant is the sum of the cells' shares
(Kirchhoff's law): every cell gives each of its edges ``ke/4``, each face diagonal ``kf/2`` and
each inner diagonal ``kc``.  The lattice stores these shares as *weights* in units of the
family's constant (an interior edge has weight 1, an edge on a free face 1/2, on a free lattice
edge 1/4), so the calibrated constants are applied later as ``k = weight · k_family``.

Cell corners are ordered ``c = di + 2 dj + 4 dk`` for the corner at offset (di, dj, dk).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .scene import Body

CORNERS = np.array([[(c >> 0) & 1, (c >> 1) & 1, (c >> 2) & 1] for c in range(8)], dtype=np.int64)
"""Offsets (di, dj, dk) of the 8 corners of a cell, index c = di + 2 dj + 4 dk."""

EDGE, FACE, INNER = 0, 1, 2
FAMILY_NAMES = ("edge", "face_diagonal", "inner_diagonal")
FAMILY_SHARE = (0.25, 0.5, 1.0)
"""Fraction of the family constant that one cell gives to one of its springs."""


def _cell_spring_pairs() -> tuple[np.ndarray, np.ndarray]:
    """Local corner pairs (28, 2) of a cell's springs and their family (28,)."""
    pairs, fam = [], []
    for a in range(8):
        for b in range(a + 1, 8):
            d = np.abs(CORNERS[b] - CORNERS[a]).sum()
            pairs.append((a, b))
            fam.append(d - 1)  # 1 differing coordinate: edge, 2: face diagonal, 3: inner
    return np.array(pairs, dtype=np.int64), np.array(fam, dtype=np.int64)


CELL_PAIRS, CELL_PAIR_FAMILY = _cell_spring_pairs()

# Signs s_{c,d} = ±1/4 of corner c in the averaged edge vector along axis d (a, b, c of SPEC §3).
VOLUME_SIGNS = (2.0 * CORNERS - 1.0) / 4.0


@dataclass(frozen=True, eq=False)
class Lattice:
    """Particles, cells and merged springs of a :class:`~hybmss.scene.Body`.

    Attributes
    ----------
    X : (n, 3) reference positions.
    grid : (n, 3) integer grid coordinates of each particle.
    node_id : (nx+1, ny+1, nz+1) particle index of each grid vertex, −1 where absent.
    cells : (m, 8) particle indices of each active cell's corners.
    cell_ijk : (m, 3) grid index of each active cell.
    springs : (s, 2) particle pairs (a < b) of the merged springs.
    family : (s,) 0 edge, 1 face diagonal, 2 inner diagonal.
    weight : (s,) merged share, in units of the family constant.
    """

    body: Body
    X: np.ndarray
    grid: np.ndarray
    node_id: np.ndarray
    cells: np.ndarray
    cell_ijk: np.ndarray
    springs: np.ndarray
    family: np.ndarray
    weight: np.ndarray

    @classmethod
    def from_body(cls, body: Body) -> "Lattice":
        mask = body.mask
        nx, ny, nz = body.shape
        cell_ijk = np.argwhere(mask).astype(np.int64)  # C order: i slowest
        corner_grid = cell_ijk[:, None, :] + CORNERS[None, :, :]  # (m, 8, 3)
        used = np.zeros((nx + 1, ny + 1, nz + 1), dtype=bool)
        used[corner_grid[..., 0], corner_grid[..., 1], corner_grid[..., 2]] = True
        grid = np.argwhere(used).astype(np.int64)
        node_id = -np.ones(used.shape, dtype=np.int64)
        node_id[grid[:, 0], grid[:, 1], grid[:, 2]] = np.arange(len(grid))
        cells = node_id[corner_grid[..., 0], corner_grid[..., 1], corner_grid[..., 2]]
        X = np.asarray(body.origin) + grid * body.le

        # Every cell's 28 springs with their share, then merge duplicates.
        a = cells[:, CELL_PAIRS[:, 0]].ravel()
        b = cells[:, CELL_PAIRS[:, 1]].ravel()
        fam = np.tile(CELL_PAIR_FAMILY, len(cells))
        share = np.asarray(FAMILY_SHARE)[fam]
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        key = lo * len(grid) + hi
        uniq, first, inv = np.unique(key, return_index=True, return_inverse=True)
        weight = np.bincount(inv, weights=share, minlength=len(uniq))
        springs = np.stack([lo[first], hi[first]], axis=1)
        family = fam[first]
        return cls(body, X, grid, node_id, cells, cell_ijk, springs, family, weight)

    # ---------------------------------------------------------------- counts
    @property
    def n_particles(self) -> int:
        return len(self.X)

    @property
    def n_cells(self) -> int:
        return len(self.cells)

    def count(self, family: int) -> int:
        return int(np.count_nonzero(self.family == family))

    def counts(self) -> dict:
        """Counts in the solver's convention (merged springs) and in [G20] Table 6's."""
        edge, face, inner = self.count(EDGE), self.count(FACE), self.count(INNER)
        return {
            "volumes": self.n_cells,
            "vertices": self.n_particles,
            "springs": {
                "edge": edge,
                "face_diagonal": face,
                "inner_diagonal": inner,
                "total": edge + face + inner,
            },
            # [G20] Table 6 counts unique edges + inner diagonals ("no FD"), and adds 12 face
            # diagonals per cell without merging them ("with FD").
            "paper_springs_no_fd": edge + inner,
            "paper_springs_with_fd": edge + inner + 12 * self.n_cells,
        }

    # ---------------------------------------------------------------- geometry
    @cached_property
    def masses_per_density(self) -> np.ndarray:
        """Lumped mass per unit density: Σ_cells∋a Vc / 8."""
        m = np.zeros(self.n_particles)
        np.add.at(m, self.cells.ravel(), self.body.cell_volume / 8.0)
        return m

    def cell_volumes(self, x: np.ndarray) -> np.ndarray:
        """Per-cell volume ``a · (b × c)`` with a, b, c the averaged edge vectors (SPEC §3)."""
        xc = np.asarray(x)[self.cells]  # (m, 8, 3)
        # Average of the 4 parallel edges along axis d: (1/4) Σ (x_hi − x_lo) = Σ_c s_{c,d} x_c.
        abc = np.einsum("cd,mci->mdi", VOLUME_SIGNS, xc)
        a, b, c = abc[:, 0], abc[:, 1], abc[:, 2]
        return np.einsum("mi,mi->m", a, np.cross(b, c))


def box_dissection(grid: np.ndarray, lo, hi, step: int = 1, leaf: int = 16) -> np.ndarray:
    """Nested-dissection order of nodes at integer ``grid`` coordinates (n, 3) in the box of cells
    ``lo``..``hi`` (cell units; a node of cell plane m sits at coordinate ``step``·m): the box is
    split at the middle cell plane of its longest extent; the nodes strictly on either side come
    first (recursively, down to ``leaf`` nodes or one cell across), the nodes on the plane (a
    separator: no cell couples the two sides through it) after them.  ``step`` 1: lattice nodes;
    2: Hex1/Hex2 nodes on the half-cell grid (mid-nodes at odd coordinates)."""
    g = np.asarray(grid, dtype=np.int64)
    out = []
    stack = [(np.arange(len(g)), np.asarray(lo, np.int64), np.asarray(hi, np.int64))]
    while stack:  # depth first: left box, right box, then the separator
        item = stack.pop()
        if isinstance(item, np.ndarray):
            out.append(item)
            continue
        idx, lo_, hi_ = item
        ext = hi_ - lo_
        if len(idx) <= leaf or ext.max() < 2:
            out.append(idx)
            continue
        ax = int(np.argmax(ext))
        m = lo_[ax] + ext[ax] // 2
        c = g[idx, ax]
        hi_left, lo_right = hi_.copy(), lo_.copy()
        hi_left[ax] = lo_right[ax] = m
        stack += [idx[c == step * m], (idx[c > step * m], lo_right, hi_), (idx[c < step * m], lo_, hi_left)]
    return np.concatenate(out)
