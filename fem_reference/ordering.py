"""Fill-reducing orders of the unknowns of voxel meshes: nested dissection of the Lagrange nodes.

The box of elements is cut recursively along its longest extent by a plane of element faces
(a separator: no element couples the two sides through it), whose nodes come last; the
unknowns follow their nodes (:func:`dof_order`).
"""

from __future__ import annotations

import numpy as np

from hybmss.lattice import box_dissection


def nested_dissection(points: np.ndarray, h: float, leaf: int = 16) -> np.ndarray | None:
    """Nested-dissection order of the Lagrange nodes ``points`` (n, 3) of a voxel mesh with
    element edge ``h``: the box of elements is split at the middle element-face plane of its
    longest extent; the nodes strictly on either side are ordered first (recursively, down to
    ``leaf`` nodes or one element across), the nodes on the plane (a separator: no element
    couples the two sides through it) after them.  Returns the node order, or ``None`` when the
    nodes are not on the half-element grid of Hex1/Hex2 nodes (e.g. a distorted mesh)."""
    p = np.asarray(points, float)
    q = (p - p.min(axis=0)) / (0.5 * h)
    g = np.rint(q).astype(np.int64)  # half-element units: vertices even, Hex2 mid-nodes odd
    if len(p) == 0 or np.abs(q - g).max() > 1e-6:
        return None
    return box_dissection(g, np.zeros(3, np.int64), -(-g.max(axis=0) // 2), step=2, leaf=leaf)


def separator_dofs(points: np.ndarray, h: float, components: int = 3) -> int | None:
    """Unknowns on the first separator of :func:`nested_dissection` (the middle element-face plane
    across the longest extent of the nodes ``points``), ``components`` per node; ``None`` when the
    nodes are not on the half-element grid."""
    p = np.asarray(points, float)
    if len(p) == 0:
        return None
    q = (p - p.min(axis=0)) / (0.5 * h)
    g = np.rint(q).astype(np.int64)
    if np.abs(q - g).max() > 1e-6:
        return None
    ext = -(-g.max(axis=0) // 2)
    ax = int(np.argmax(ext))
    return components * int(np.count_nonzero(g[:, ax] == 2 * (ext[ax] // 2)))


def dof_order(node_order: np.ndarray | None, n_vector_nodes: int, n_scalar: int = 0) -> np.ndarray | None:
    """Unknowns in the order of ``node_order`` (a permutation of ``n_vector_nodes + n_scalar``
    nodes): vector node ``k`` (< ``n_vector_nodes``) stands for dofs ``3k, 3k+1, 3k+2``, scalar
    node ``n_vector_nodes + j`` for unknown ``3 n_vector_nodes + j`` (the pressure of a saddle point)."""
    if node_order is None:
        return None
    k = np.asarray(node_order, np.int64)
    vec = k < n_vector_nodes
    counts = np.where(vec, 3, 1)
    start = np.where(vec, 3 * k, 3 * n_vector_nodes + (k - n_vector_nodes))
    first = np.cumsum(counts) - counts
    return np.repeat(start, counts) + (np.arange(int(counts.sum())) - np.repeat(first, counts))


def unknown_order(space, h: float, pspace=None) -> np.ndarray | None:
    """Fill-reducing order of the unknowns of ``space`` (displacement dofs, then the pressures of
    ``pspace`` for a mixed element) by nested dissection of their nodes, or ``None`` (no grid)."""
    if pspace is None:
        return dof_order(nested_dissection(space.points, h), space.n_scalar)
    pts = np.vstack([space.points, pspace.points])
    return dof_order(nested_dissection(pts, h), space.n_scalar, pspace.n_scalar)
