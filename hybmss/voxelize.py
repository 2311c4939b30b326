"""Voxel bodies beyond boxes: the L-shape of [B09] and closed surface meshes.

- :func:`l_shape`: three cubic blocks of ``n × n × n`` cells each, a column of two blocks
  (x ∈ [0, b], z ∈ [0, 2b]) and an arm on its top (x ∈ [b, 2b], z ∈ [b, 2b]), ``b = n le``,
  one block deep in y.
- :func:`voxelize`: the cells of a regular grid whose centre lies inside a closed triangulated
  surface (read with meshio from any format it knows, or given as points and triangles).
  Inside is decided by the generalized winding number ``w(p) = Σ_t Ω_t(p)/(4π)`` with the solid
  angle Ω_t of each triangle seen from p (Van Oosterom–Strackee formula); ``w`` is 1 inside and 0
  outside a closed, consistently oriented surface, whatever its orientation sign (|w| is used),
  and it degrades gracefully on small holes, unlike ray parity which fails on rays through
  edges and vertices.  Vectorized over cell centres, in chunks to bound the memory.

No file is read at import; :func:`read_surface` reads one when asked.
"""

from __future__ import annotations

import numpy as np

from .scene import Body


def l_shape(n: int, le: float, origin=(0.0, 0.0, 0.0)) -> Body:
    """The L-shaped body of three ``n³``-cell blocks (see the module docstring)."""
    n = int(n)
    if n < 1:
        raise ValueError(f"n (cells per block edge) must be >= 1, got {n}")
    mask = np.zeros((2 * n, n, 2 * n), dtype=bool)
    mask[:n, :, :] = True  # column, two blocks high
    mask[n:, :, n:] = True  # arm on top of the column
    return Body.from_mask(mask, le, origin)


def read_surface(path) -> tuple[np.ndarray, np.ndarray]:
    """Points (p, 3) and triangles (t, 3) of a surface mesh file (quads are split)."""
    import meshio

    mesh = meshio.read(path)
    tris = []
    for block in mesh.cells:
        if block.type == "triangle":
            tris.append(block.data)
        elif block.type == "quad":
            q = block.data
            tris += [q[:, [0, 1, 2]], q[:, [0, 2, 3]]]
    if not tris:
        raise ValueError(f"{path}: no triangle or quad cells in the mesh (a closed surface is needed)")
    return np.asarray(mesh.points, dtype=float)[:, :3], np.concatenate(tris).astype(np.int64)


def winding_number(points: np.ndarray, vertices: np.ndarray, triangles: np.ndarray,
                   chunk: int = 4096) -> np.ndarray:
    """Generalized winding number (k,) of query ``points`` (k, 3) for a triangle surface."""
    P = np.asarray(points, dtype=float)
    A = vertices[triangles[:, 0]]
    B = vertices[triangles[:, 1]]
    C = vertices[triangles[:, 2]]
    out = np.empty(len(P))
    for s in range(0, len(P), chunk):
        p = P[s:s + chunk, None, :]
        a, b, c = A[None] - p, B[None] - p, C[None] - p  # (k, t, 3)
        la, lb, lc = (np.linalg.norm(v, axis=-1) for v in (a, b, c))
        det = np.einsum("kti,kti->kt", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("kti,kti->kt", a, b) * lc
               + np.einsum("kti,kti->kt", a, c) * lb + np.einsum("kti,kti->kt", b, c) * la)
        out[s:s + chunk] = (2.0 * np.arctan2(det, den)).sum(axis=1) / (4.0 * np.pi)
    return out


def voxel_mask(vertices: np.ndarray, triangles: np.ndarray, le: float, origin=None,
               shape=None) -> tuple[np.ndarray, tuple[float, float, float]]:
    """Boolean mask of the cells (edge ``le``) whose centre is inside the surface, and the grid
    origin.  By default the grid covers the surface's bounding box."""
    vertices = np.asarray(vertices, dtype=float)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    o = lo if origin is None else np.asarray(origin, dtype=float)
    if shape is None:
        shape = tuple(int(max(1, np.ceil((hi[d] - o[d]) / le - 1e-9))) for d in range(3))
    ijk = np.indices(shape).reshape(3, -1).T
    centres = o + (ijk + 0.5) * le
    w = winding_number(centres, vertices, np.asarray(triangles, dtype=np.int64))
    return (np.abs(w) > 0.5).reshape(shape), tuple(float(v) for v in o)


def voxelize(surface, le: float, origin=None, shape=None) -> Body:
    """A :class:`Body` of the cells inside a closed surface: ``surface`` is a file path (read
    with meshio) or a pair ``(vertices, triangles)``."""
    if isinstance(surface, (tuple, list)):
        vertices, triangles = surface
    else:
        vertices, triangles = read_surface(surface)
    mask, o = voxel_mask(vertices, triangles, le, origin, shape)
    if not mask.any():
        raise ValueError(f"no cell centre lies inside the surface at le={le}: use a smaller cell edge")
    return Body.from_mask(mask, le, o)
