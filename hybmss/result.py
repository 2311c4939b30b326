"""One result schema for every solver (MSS and FEM), so any comparison is a merge.

Displacements are given at the lattice particles (the FEM reference evaluates its solution at
the same points), reactions per plate, and scalar summaries in :meth:`Result.summary`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

VTK_HEX_ORDER = np.array([0, 1, 3, 2, 4, 5, 7, 6])
"""VTK's hexahedron corner order from the lattice's (corner c = di + 2 dj + 4 dk)."""


@dataclass(frozen=True)
class Reaction:
    """Force (N) the plate exerts on the body, and its torque (N·m) about the plate's
    current centroid ``center``."""

    force: tuple[float, float, float]
    torque: tuple[float, float, float]
    center: tuple[float, float, float]

    def to_dict(self) -> dict:
        return {"force": list(self.force), "torque": list(self.torque), "center": list(self.center)}


def reaction_from_nodal(x_plate: np.ndarray, r_plate: np.ndarray) -> Reaction:
    """Reaction from per-node forces ``r_plate`` (k, 3) the plate applies at positions ``x_plate``."""
    c = x_plate.mean(axis=0)
    F = r_plate.sum(axis=0)
    T = np.cross(x_plate - c, r_plate).sum(axis=0)
    return Reaction(tuple(map(float, F)), tuple(map(float, T)), tuple(map(float, c)))


@dataclass(frozen=True, eq=False)
class Result:
    """Outcome of one solve.

    ``solver`` names what produced it (``"mss-static"``, ``"mss-explicit"``,
    ``"fem-hex2-linear"``, ...).  ``X`` and ``u`` are the lattice particles' reference positions
    and displacements (n, 3).  ``volume`` is the deformed volume (m³) and ``volume_change`` the
    signed relative change (V' − V0)/V0.  ``cell_volumes`` (per cell, MSS formula ``a·(b×c)``)
    may be ``None``.  ``energy`` maps term names to energies (J).  ``info`` holds anything else
    (solver statistics, warnings, inverted-cell count, ...), JSON-serializable.
    """

    solver: str
    scene_digest: str
    X: np.ndarray
    u: np.ndarray
    volume: float
    volume0: float
    reactions: dict[str, Reaction]
    energy: dict[str, float]
    iterations: int
    wall_time_s: float
    converged: bool = True
    cell_volumes: np.ndarray | None = None
    info: dict = field(default_factory=dict)

    @property
    def x(self) -> np.ndarray:
        return self.X + self.u

    @property
    def volume_change(self) -> float:
        return (self.volume - self.volume0) / self.volume0

    @property
    def max_displacement(self) -> float:
        return float(np.linalg.norm(self.u, axis=1).max())

    def summary(self) -> dict:
        """JSON-ready scalars and small vectors."""
        return {
            "solver": self.solver,
            "scene_digest": self.scene_digest,
            "volume": float(self.volume),
            "volume0": float(self.volume0),
            "volume_change": float(self.volume_change),
            "max_displacement": self.max_displacement,
            "reactions": {k: r.to_dict() for k, r in self.reactions.items()},
            "energy": {k: float(v) for k, v in self.energy.items()},
            "iterations": int(self.iterations),
            "wall_time_s": float(self.wall_time_s),
            "converged": bool(self.converged),
            "info": self.info,
        }

    def to_pyvista(self, cells: np.ndarray | None = None):
        """The reference configuration as a pyvista mesh: hexahedra of the lattice ``cells``
        (m, 8), corner c = di + 2 dj + 4 dk (``Lattice.cells``), or the points alone without
        them; point data ``displacement`` (m) and ``|u|`` (m), field data ``solver``,
        ``scene_digest`` and ``units``.  Warp by ``displacement`` to see the deformed state."""
        import pyvista as pv

        X = np.asarray(self.X, dtype=float)
        if cells is None:
            grid = pv.PolyData(X)
        else:
            grid = pv.UnstructuredGrid({pv.CellType.HEXAHEDRON: np.asarray(cells)[:, VTK_HEX_ORDER]}, X)
        grid.point_data["displacement"] = np.asarray(self.u, dtype=float)
        grid.point_data["|u|"] = np.linalg.norm(self.u, axis=1)
        grid.field_data["solver"] = [self.solver]
        grid.field_data["scene_digest"] = [self.scene_digest]
        grid.field_data["units"] = ["SI: m, N, Pa, s"]
        return grid
