"""Deformed states as VTU files (meshio), one per run, for ParaView.

Each file holds the reference lattice as points and hexahedral cells (VTK order), the point
field ``displacement`` (m) and ``displacement_magnitude`` (m), and the cell field
``relative_volume_change`` = V′/V0 − 1 (–), V′ the stored deformed cell volume (the averaged-edge
formula of SPEC §8 when none was stored) and V0 the undeformed one.  Apply *Warp By Vector* on
``displacement`` to see the deformed shape.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .data import VTK_HEX_ORDER, Results


def averaged_edge_volumes(P: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Cell volumes ``a · (b × c)`` with a, b, c the averages of the 4 edges along i, j, k
    (corner c = di + 2 dj + 4 dk)."""
    C = P[cells]  # (m, 8, 3)
    a = 0.25 * (C[:, 1] - C[:, 0] + C[:, 3] - C[:, 2] + C[:, 5] - C[:, 4] + C[:, 7] - C[:, 6])
    b = 0.25 * (C[:, 2] - C[:, 0] + C[:, 3] - C[:, 1] + C[:, 6] - C[:, 4] + C[:, 7] - C[:, 5])
    c = 0.25 * (C[:, 4] - C[:, 0] + C[:, 5] - C[:, 1] + C[:, 6] - C[:, 2] + C[:, 7] - C[:, 3])
    return np.einsum("ij,ij->i", a, np.cross(b, c))


def relative_volume_change(arrays: dict) -> np.ndarray:
    X, u, cells = arrays["X"], arrays["u"], arrays["cells"]
    V0 = averaged_edge_volumes(X, cells)
    V = arrays.get("cell_volumes")
    if V is None or len(V) != len(cells):
        V = averaged_edge_volumes(X + u, cells)
    return np.asarray(V, dtype=float) / V0 - 1.0


def write_vtu(arrays: dict, path: Path) -> Path:
    import meshio

    X, u, cells = arrays["X"], arrays["u"], np.asarray(arrays["cells"])
    mesh = meshio.Mesh(
        points=np.asarray(X, dtype=float),
        cells=[("hexahedron", cells[:, VTK_HEX_ORDER].astype(np.int64))],
        point_data={"displacement": np.asarray(u, dtype=float),
                    "displacement_magnitude": np.linalg.norm(u, axis=1)},
        cell_data={"relative_volume_change": [relative_volume_change(arrays)]},
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.vtu")
    meshio.write(tmp, mesh, binary=True)
    tmp.replace(path)
    return path


def export_all(results: Results, out_dir: Path) -> dict[str, str]:
    """One VTU per run with arrays (skipped when up to date); returns {key: file name}."""
    out_dir = Path(out_dir)
    files = {}
    df = results.rows
    if df.empty:
        return files
    for key in df["key"]:
        npz = results.runs_dir / f"{key}.npz"
        if not npz.exists():
            continue
        path = out_dir / f"{key}.vtu"
        if not path.exists() or path.stat().st_mtime < npz.stat().st_mtime:
            arrays = results.arrays(key)
            if not {"X", "u", "cells"} <= set(arrays):
                continue
            write_vtu(arrays, path)
        files[key] = path.name
    return files
