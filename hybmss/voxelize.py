"""Voxel bodies beyond boxes: the L-shape of [B09] and closed surface meshes.

- :func:`l_shape`: three cubic blocks of ``n × n × n`` cells each, a column of two blocks
  (x ∈ [0, b], z ∈ [0, 2b]) and an arm on its top (x ∈ [b, 2b], z ∈ [b, 2b]), ``b = n le``,
  one block deep in y.
- :func:`voxelize`: the cells of a regular grid whose centre lies inside a closed triangulated
  surface, given as a file (read with meshio), points and triangles, a ``meshio.Mesh`` or a
  pyvista ``PolyData``/``UnstructuredGrid`` (its outer surface).
- :func:`pieces`: the face-connected pieces of a voxel mask (:func:`hybmss.scene.pieces`).

Inside is decided by **ray parity along the grid's columns** (:func:`column_parity`): the
vertical line through the centres of a column of cells (x = x_i, y = y_j) crosses the surface
where it pierces a triangle's projection on the xy plane; a cell centre is inside when an odd
number of crossings lie below it.  Each triangle is tested once against the few columns its
projection covers (edge functions in 2D, vectorized over all triangle–column pairs), so the cost
is O(triangles + columns covered + cells) instead of the O(cells × triangles) of the winding number.

Parity is exact on a closed surface except where a line meets the surface at an edge, a vertex,
a triangle seen edge-on, or a crossing at a cell centre: there rounding decides whether a
crossing is counted once, twice or not at all.  Such a column (a test within ``1e-9 le`` of
ambiguous) is decided instead by the **generalized winding number** ``w(p) = Σ_t Ω_t(p)/(4π)``
(:func:`winding_number`) with the solid angle Ω_t of each triangle seen from p (Van
Oosterom–Strackee formula): 1 inside and 0 outside a closed, consistently oriented surface,
whatever its orientation sign (|w| > ½ is inside).  A surface that is not closed (an edge not
shared by exactly two triangles) has no parity: it is voxelized with the winding number
throughout, which degrades gracefully on small holes.  :func:`voxel_mask` with
``method="winding"`` is the reference the parity path is tested against.

No file is read at import; :func:`read_surface` reads one when asked.
"""

from __future__ import annotations

import numpy as np

from .scene import Body, pieces  # noqa: F401  (pieces: re-exported for the users of bodies)

PARITY_TOL = 1e-9
"""Closeness (in cell edges) to an edge of a projected triangle, or of a crossing to a cell
centre, at which a column's parity is not trusted and its cells take the winding number."""

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

    return _meshio_triangles(meshio.read(path), str(path))


def _meshio_triangles(mesh, what: str) -> tuple[np.ndarray, np.ndarray]:
    tris = []
    for block in mesh.cells:
        if block.type == "triangle":
            tris.append(block.data)
        elif block.type == "quad":
            q = block.data
            tris += [q[:, [0, 1, 2]], q[:, [0, 2, 3]]]
    if not tris:
        raise ValueError(f"{what}: no triangle or quad cells in the mesh (a closed surface is needed)")
    return np.asarray(mesh.points, dtype=float)[:, :3], np.concatenate(tris).astype(np.int64)


def surface_triangles(surface) -> tuple[np.ndarray, np.ndarray]:
    """Points (p, 3) and triangles (t, 3) of ``surface``: a file path (meshio), a pair
    ``(points, triangles)``, a ``meshio.Mesh`` (its triangles and quads), or a pyvista
    ``PolyData`` / ``UnstructuredGrid`` / any pyvista dataset (its outer surface, triangulated)."""
    if isinstance(surface, (tuple, list)):
        if len(surface) != 2:
            raise ValueError(f"surface as a sequence must be (points, triangles), got {len(surface)} items")
        V = np.asarray(surface[0], dtype=float)
        T = np.asarray(surface[1])
        if V.ndim != 2 or V.shape[1] != 3 or T.ndim != 2 or T.shape[1] != 3:
            raise ValueError(f"surface must be points (p, 3) and triangles (t, 3), got shapes {V.shape} "
                             f"and {T.shape}")
        if len(T) and (T.min() < 0 or T.max() >= len(V)):
            raise ValueError(f"triangles index points 0..{len(V) - 1}, got indices {T.min()}..{T.max()}")
        return V, T.astype(np.int64)
    kind = type(surface).__module__.split(".")[0]
    if kind == "pyvista":
        return _pyvista_triangles(surface)
    if kind == "meshio":
        return _meshio_triangles(surface, "meshio.Mesh")
    if isinstance(surface, (str, bytes)) or hasattr(surface, "__fspath__"):
        return read_surface(surface)
    raise ValueError(f"surface must be a file path, (points, triangles), a meshio.Mesh or a pyvista mesh; "
                     f"got {type(surface).__name__}")


def _pyvista_triangles(mesh) -> tuple[np.ndarray, np.ndarray]:
    import pyvista as pv

    if not isinstance(mesh, pv.PolyData):
        try:
            mesh = mesh.extract_surface(algorithm="dataset_surface")
        except TypeError:  # pyvista before 0.47 has no choice of algorithm (and only this one)
            mesh = mesh.extract_surface()
    if mesh.n_cells == 0 or len(mesh.faces) == 0:
        raise ValueError(f"pyvista {type(mesh).__name__}: no polygon faces (a closed surface is needed)")
    tri = mesh.triangulate()
    faces = np.asarray(tri.faces).reshape(-1, 4)
    return np.asarray(tri.points, dtype=float), faces[:, 1:].astype(np.int64)


def is_closed(triangles: np.ndarray) -> bool:
    """Whether every edge of the triangles is shared by exactly two of them (a closed surface)."""
    T = np.asarray(triangles, dtype=np.int64)
    e = np.sort(np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return bool(len(T)) and bool(np.all(counts == 2))


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


def _cross2(ux, uy, vx, vy):
    return ux * vy - uy * vx


def column_parity(vertices: np.ndarray, triangles: np.ndarray, le: float, origin, shape,
                  tol: float = PARITY_TOL) -> tuple[np.ndarray, np.ndarray]:
    """Cells of the grid (``origin``, ``le``, ``shape``) whose centre is inside a closed surface by
    ray parity along z, and the (nx, ny) columns whose parity is not trusted (see the module
    docstring); vectorized over triangle–column pairs.

    A pair (triangle, column) is a crossing when the column's line ``(x_i, y_j)`` is inside the
    triangle's projection, every edge function ``e = (b − a) × (p − a)`` of its projected edges
    having the sign of its projected area, each farther than ``tol · le`` from the edge.  An edge
    function is always evaluated from the edge's lower vertex index, so the two triangles sharing
    an edge see exactly opposite values: no column slips between them.  The crossing's height
    comes from the barycentric weights ``e_bc, e_ca, e_ab``; a crossing at ``k_hit`` (the first
    centre above it) toggles the cells from ``k_hit`` up, a cumulative sum along z."""
    V = np.asarray(vertices, dtype=float)
    T = np.asarray(triangles, dtype=np.int64)
    o = np.asarray(origin, dtype=float)
    nx, ny, nz = (int(n) for n in shape)
    ambiguous = np.zeros((nx, ny), dtype=bool)
    count = np.zeros((nx, ny, nz + 1), dtype=np.int64)
    if len(T) == 0:
        return np.zeros((nx, ny, nz), dtype=bool), ambiguous
    P = V[T]  # (t, 3 vertices, 3)
    margin = 1e-6  # cell edges: columns just outside a projection's box are tested too
    lo = (P[:, :, :2].min(axis=1) - o[:2]) / le - 0.5
    hi = (P[:, :, :2].max(axis=1) - o[:2]) / le - 0.5
    i0 = np.maximum(np.ceil(lo - margin), 0).astype(np.int64)
    i1 = np.minimum(np.floor(hi + margin), np.array([nx - 1, ny - 1])).astype(np.int64)
    n = np.maximum(i1 - i0 + 1, 0)  # (t, 2): columns covered along x and y
    per = n[:, 0] * n[:, 1]
    tri = np.repeat(np.arange(len(T)), per)
    q = np.arange(len(tri)) - np.repeat(np.cumsum(per) - per, per)
    ii = i0[tri, 0] + q // n[tri, 1]
    jj = i0[tri, 1] + q % n[tri, 1]
    px = o[0] + (ii + 0.5) * le
    py = o[1] + (jj + 0.5) * le

    # edge functions of the projected edges (a, b), (b, c), (c, a), each from its lower vertex index
    e, length = [], []
    for a, b in ((0, 1), (1, 2), (2, 0)):
        va, vb = T[tri, a], T[tri, b]
        flip = va > vb
        s = np.where(flip, vb, va)
        t = np.where(flip, va, vb)
        dx, dy = V[t, 0] - V[s, 0], V[t, 1] - V[s, 1]
        ev = _cross2(dx, dy, px - V[s, 0], py - V[s, 1])
        e.append(np.where(flip, -ev, ev))
        length.append(np.hypot(dx, dy))
    e = np.stack(e)  # (3, pairs): e_ab, e_bc, e_ca
    length = np.stack(length)
    area2 = e.sum(axis=0)
    sign = np.where(area2 < 0, -1.0, 1.0)
    d = sign * e / np.where(length > 0, length, 1.0)  # signed distances to the edges, inside > 0
    inside = np.all(d > tol * le, axis=0)
    out = np.any(d < -tol * le, axis=0)
    near = ~inside & ~out
    ambiguous[ii[near], jj[near]] = True

    # crossings: height, and its place among the cell centres of the column
    e_ab, e_bc, e_ca = e[:, inside]
    t_in = tri[inside]
    z = (e_bc * P[t_in, 0, 2] + e_ca * P[t_in, 1, 2] + e_ab * P[t_in, 2, 2]) / area2[inside]
    h = (z - o[2]) / le - 0.5
    ci, cj = ii[inside], jj[inside]
    k_near = np.rint(h)
    at_centre = (np.abs(h - k_near) <= tol) & (k_near >= 0) & (k_near < nz)
    ambiguous[ci[at_centre], cj[at_centre]] = True
    k_hit = np.clip(np.floor(h) + 1, 0, nz).astype(np.int64)
    flat = np.bincount((ci * ny + cj) * (nz + 1) + k_hit, minlength=count.size)
    count = flat.reshape(count.shape)
    mask = (np.cumsum(count, axis=2)[:, :, :nz] % 2) == 1
    return mask, ambiguous


def clean_surface(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The surface with coincident points merged (an STL file repeats every vertex) and
    triangles that repeat a vertex (zero area) dropped."""
    V = np.asarray(vertices, dtype=float)
    T = np.asarray(triangles, dtype=np.int64)
    U, inv = np.unique(V, axis=0, return_inverse=True)
    T = inv.reshape(-1)[T]
    keep = (T[:, 0] != T[:, 1]) & (T[:, 1] != T[:, 2]) & (T[:, 2] != T[:, 0])
    return U, T[keep]


METHODS = ("parity", "winding")


def voxel_mask(vertices: np.ndarray, triangles: np.ndarray, le: float, origin=None,
               shape=None, method: str = "parity") -> tuple[np.ndarray, tuple[float, float, float]]:
    """Boolean mask of the cells (edge ``le``) whose centre is inside the surface, and the grid
    origin.  By default the grid covers the surface's bounding box.

    ``method="parity"``: ray parity along the grid's columns with the winding number in the
    columns where parity is not trusted, or everywhere when the surface is not closed;
    ``method="winding"``: the winding number of every cell centre (the reference, slow:
    O(cells × triangles))."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}; got {method!r}")
    vertices = np.asarray(vertices, dtype=float)
    triangles = np.asarray(triangles, dtype=np.int64)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    o = lo if origin is None else np.asarray(origin, dtype=float)
    if shape is None:
        shape = tuple(int(max(1, np.ceil((hi[d] - o[d]) / le - 1e-9))) for d in range(3))
    shape = tuple(int(n) for n in shape)
    ijk = np.indices(shape).reshape(3, -1).T
    if method == "winding":
        w = winding_number(o + (ijk + 0.5) * le, vertices, triangles)
        return (np.abs(w) > 0.5).reshape(shape), tuple(float(v) for v in o)
    V, T = clean_surface(vertices, triangles)
    if not is_closed(T):
        return voxel_mask(vertices, triangles, le, origin, shape, method="winding")
    mask, ambiguous = column_parity(V, T, le, o, shape)
    cols = np.argwhere(ambiguous)
    if len(cols):  # the winding number decides the cells of the columns parity cannot
        k = np.arange(shape[2])
        cells = np.column_stack([np.repeat(cols, shape[2], axis=0), np.tile(k, len(cols))])
        w = winding_number(o + (cells + 0.5) * le, V, T)
        mask[cells[:, 0], cells[:, 1], cells[:, 2]] = np.abs(w) > 0.5
    return mask, tuple(float(v) for v in o)


def voxelize(surface, le: float, origin=None, shape=None, method: str = "parity") -> Body:
    """A :class:`Body` of the cells inside a closed surface: ``surface`` is a file path (read
    with meshio), a pair ``(points, triangles)``, a ``meshio.Mesh`` or a pyvista mesh
    (:func:`surface_triangles`); ``method`` as in :func:`voxel_mask`.  A surface whose cells fall
    apart into pieces is refused (:meth:`Body.from_mask`)."""
    le = float(le)
    if not (np.isfinite(le) and le > 0):
        raise ValueError(f"le (cell edge) must be > 0, got {le}")
    vertices, triangles = surface_triangles(surface)
    mask, o = voxel_mask(vertices, triangles, le, origin, shape, method)
    if not mask.any():
        raise ValueError(f"no cell centre lies inside the surface at le={le}: use a smaller cell edge")
    return Body.from_mask(mask, le, o)
