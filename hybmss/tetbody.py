"""Tetrahedral bodies: a closed surface meshed into conforming linear tetrahedra (plain data).

A :class:`TetBody` holds the nodes ``X`` (n, 3), the tetrahedra ``tets`` (m, 4) of positive
orientation, the target edge length ``h`` and the enclosed volume of the source surface.  The
signed volume of tetrahedron ``(a, b, c, d)`` is

    V = ((x_b − x_a) × (x_c − x_a)) · (x_d − x_a) / 6,

positive when ``d`` lies on the side of the face ``abc`` its normal points to.  A mesh whose
tetrahedra are *all* negative is consistently mirrored and is fixed by swapping two vertices of
each; a mesh with tetrahedra of both signs, or with any ``|V| ≤ tol · h³`` (degenerate), is
refused with the counts (:class:`TetMeshError`).

The mesh volume ``Σ V`` is compared with the surface's own volume (divergence theorem over its
triangles); a tetrahedral mesh of a curved surface is inscribed in it, so the mesh volume is a
little smaller, by ``O(h²)`` relative.

Meshing uses gmsh (the ``tet`` extra: ``pip install hybmss[tet]``): the surface's triangles
become a discrete surface, which gmsh classifies into patches (feature angle), reparametrizes
and remeshes at the target edge length before filling the volume (Delaunay).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

DEGENERATE_TOL = 1e-6
"""A tetrahedron with ``|V| ≤ DEGENERATE_TOL · h³`` is degenerate (a regular one has 0.118 h³)."""

INSTALL_HINT = "the tetrahedral mesher gmsh is not installed: pip install 'hybmss[tet]' (or pip install gmsh)"


class TetMeshError(ValueError):
    """A tetrahedral mesh that cannot be used (inverted or degenerate tetrahedra, open surface)."""


@dataclass(frozen=True, eq=False)
class TetBody:
    """Conforming linear tetrahedra of a body (SI units).

    ``X`` (n, 3) node positions, ``tets`` (m, 4) node indices with positive signed volume,
    ``h`` the target edge length it was meshed with, ``surface_volume`` the volume enclosed by the
    source surface (``None`` when there was none), ``swapped`` how many tetrahedra were
    reoriented."""

    X: np.ndarray
    tets: np.ndarray
    h: float
    surface_volume: float | None = None
    swapped: int = 0

    @property
    def n_nodes(self) -> int:
        return int(self.X.shape[0])

    @property
    def n_tets(self) -> int:
        return int(self.tets.shape[0])

    @property
    def volumes(self) -> np.ndarray:
        return signed_volumes(self.X, self.tets)

    @property
    def volume(self) -> float:
        return float(self.volumes.sum())

    @property
    def volume_error(self) -> float | None:
        """``(V_mesh − V_surface) / V_surface``, or ``None`` without a surface."""
        if not self.surface_volume:
            return None
        return (self.volume - self.surface_volume) / self.surface_volume

    def summary(self) -> dict:
        return {"nodes": self.n_nodes, "tets": self.n_tets, "h": self.h, "mesh_volume": self.volume,
                "surface_volume": self.surface_volume, "volume_error": self.volume_error,
                "swapped": self.swapped}


def signed_volumes(X: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volume of each tetrahedron (module docstring)."""
    a, b, c, d = (X[tets[:, i]] for i in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def oriented(X, tets, h: float, tol: float = DEGENERATE_TOL) -> tuple[np.ndarray, int]:
    """``tets`` with positive orientation and how many were swapped; :class:`TetMeshError` for a
    degenerate tetrahedron or a mix of orientations (with the counts)."""
    X = np.asarray(X, float)
    tets = np.asarray(tets, np.int64)
    if tets.ndim != 2 or tets.shape[1] != 4 or len(tets) == 0:
        raise TetMeshError(f"tets must be a non-empty (m, 4) array; got shape {tets.shape}")
    if tets.min() < 0 or tets.max() >= len(X):
        raise TetMeshError(f"tets index nodes outside [0, {len(X) - 1}]")
    V = signed_volumes(X, tets)
    small = np.abs(V) <= tol * h**3
    neg = (V < 0) & ~small
    pos = (V > 0) & ~small
    if small.any() or (neg.any() and pos.any()):
        raise TetMeshError(
            f"{int(small.sum())} degenerate (|V| <= {tol:g} h^3) and {int(min(neg.sum(), pos.sum()))} "
            f"inverted of {len(tets)} tetrahedra ({int(pos.sum())} positive, {int(neg.sum())} negative)")
    if neg.all():
        return tets[:, [0, 2, 1, 3]].copy(), len(tets)
    return tets.copy(), 0


def contains(body: TetBody, points, k: int = 16) -> np.ndarray:
    """Which ``points`` (p, 3) lie in the tetrahedra of ``body``: non-negative barycentric
    coordinates in one of the ``k`` tetrahedra of nearest centroid."""
    from scipy.spatial import cKDTree

    points = np.asarray(points, float)
    P = body.X[body.tets]  # (m, 4, 3)
    k = min(k, body.n_tets)
    _, cand = cKDTree(P.mean(axis=1)).query(points, k)
    cand = np.asarray(cand).reshape(len(points), k)
    v0 = P[cand, 0]  # (p, k, 3)
    M = np.stack([P[cand, i] - v0 for i in (1, 2, 3)], axis=-1)  # (p, k, 3, 3)
    lam = np.linalg.solve(M, (points[:, None, :] - v0)[..., None])[..., 0]
    bary = np.concatenate([1.0 - lam.sum(-1, keepdims=True), lam], axis=-1)
    return bary.min(-1).max(-1) >= 0.0


def make_body(X, tets, h: float, surface_volume: float | None = None, tol: float = DEGENERATE_TOL) -> TetBody:
    """A :class:`TetBody` after the orientation check (:func:`oriented`); unused nodes are dropped."""
    X = np.asarray(X, float)
    tets, swapped = oriented(X, tets, h, tol)
    used, inverse = np.unique(tets, return_inverse=True)
    return TetBody(X[used].copy(), inverse.reshape(-1, 4), float(h), surface_volume, swapped)


def surface_triangles(surface) -> tuple[np.ndarray, np.ndarray]:
    """``(points, triangles)`` of a closed surface: a file path (STL/OBJ/PLY..., read by pyvista)
    or a pyvista ``PolyData`` (e.g. ``pyvista.Cylinder(...)``), triangulated."""
    import pyvista as pv

    mesh = pv.read(str(surface)) if not isinstance(surface, pv.DataSet) else surface
    mesh = mesh.extract_surface(algorithm=None) if not isinstance(mesh, pv.PolyData) else mesh
    mesh = mesh.triangulate().clean()
    faces = np.asarray(mesh.faces).reshape(-1, 4)
    if len(faces) == 0:
        raise TetMeshError("the surface has no triangles")
    return np.asarray(mesh.points, float), faces[:, 1:].astype(np.int64)


def enclosed_volume(P: np.ndarray, T: np.ndarray) -> float:
    """Volume enclosed by a closed triangulated surface: ``|Σ x_a · (x_b × x_c)| / 6``."""
    a, b, c = P[T[:, 0]], P[T[:, 1]], P[T[:, 2]]
    return float(abs(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6.0)


def mesh_surface(surface, h: float, feature_angle: float = 40.0) -> TetBody:
    """Conforming tetrahedra of the body a closed surface encloses, target edge length ``h`` (m)."""
    if not (math.isfinite(h) and h > 0):
        raise ValueError(f"h must be a positive length; got {h}")
    P, T = surface_triangles(surface)
    V_surface = enclosed_volume(P, T)
    if V_surface <= 0:
        raise TetMeshError("the surface encloses no volume")
    X, tets = _gmsh_volume(P, T, h, feature_angle)
    return make_body(X, tets, h, V_surface)


def _gmsh_volume(P, T, h, feature_angle):
    try:
        import gmsh
    except ImportError as exc:  # the optional extra is missing
        raise ImportError(INSTALL_HINT) from exc
    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add("body")
        s = gmsh.model.addDiscreteEntity(2)
        gmsh.model.mesh.addNodes(2, s, np.arange(1, len(P) + 1), P.ravel())
        gmsh.model.mesh.addElementsByType(s, 2, [], (T + 1).ravel())
        gmsh.model.mesh.classifySurfaces(math.radians(feature_angle), True, True, math.pi)
        gmsh.model.mesh.createGeometry()
        loop = gmsh.model.geo.addSurfaceLoop([e[1] for e in gmsh.model.getEntities(2)])
        gmsh.model.geo.addVolume([loop])
        gmsh.model.geo.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMin", h)
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.model.mesh.generate(3)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        _, nodes = gmsh.model.mesh.getElementsByType(4)
    except Exception as exc:  # gmsh raises a bare Exception with its log line
        raise TetMeshError(f"gmsh could not mesh the surface: {exc}") from exc
    finally:
        gmsh.finalize()
    if len(nodes) == 0:
        raise TetMeshError("gmsh produced no tetrahedra (is the surface closed?)")
    index = np.full(int(tags.max()) + 1, -1, np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    return coords.reshape(-1, 3), index[nodes.astype(np.int64)].reshape(-1, 4)
