"""The errors of a model run against its FEM reference, every one relative and named.

**Where the FEM is sampled.**  The reference's mesh is the same voxel body, each cell split into
refine³ elements, so every lattice node of a model at that resolution is a node of the FEM mesh;
the FEM's own interpolation evaluated there is its nodal value, which ``fem_reference.solve``
returns at the lattice particles (``Result.u``; the test checks skfem's ``probes`` give the same).
:func:`match_nodes` pairs the model's nodes with the reference's by position and refuses a node
that is not one of them.

**Volume change, two formulas, each applied to both fields:** ``volume_avg_edges`` (Σ a·(b×c) of
the averaged cell edges, the mass-spring systems' formula) and ``volume_detF`` (∫ det F of the
trilinear interpolation of the nodal positions, 2×2×2 Gauss points per cell).  The relative error
of a volume change is ``|ΔV_model − ΔV_FEM| / |ΔV_FEM|``.
"""

from __future__ import annotations

import numpy as np

GAUSS = 0.5 + np.array([-1.0, 1.0]) / (2.0 * np.sqrt(3.0))


def match_nodes(X_model: np.ndarray, X_ref: np.ndarray, le: float) -> np.ndarray:
    """Index into ``X_ref`` of each row of ``X_model`` (equal within 1e-6 le)."""
    if X_model.shape == X_ref.shape and np.allclose(X_model, X_ref, rtol=0, atol=1e-6 * le):
        return np.arange(len(X_model))
    keys = {tuple(k): i for i, k in enumerate(np.round(X_ref / le).astype(np.int64).tolist())}
    idx = [keys.get(tuple(k), -1) for k in np.round(X_model / le).astype(np.int64).tolist()]
    idx = np.asarray(idx)
    if (idx < 0).any() or not np.allclose(X_ref[idx], X_model, rtol=0, atol=1e-6 * le):
        raise ValueError("a model node is not a node of the reference mesh")
    return idx


def relative(a, b) -> float:
    """``|a − b| / |b|`` (vectors: norms); NaN when the reference is 0."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    ref = float(np.linalg.norm(b))
    return float(np.linalg.norm(a - b) / ref) if ref > 0 else float("nan")


def averaged_edge_volumes(P: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """``a · (b × c)`` per cell (corner c = di + 2 dj + 4 dk)."""
    C = P[cells]
    a = 0.25 * (C[:, 1] - C[:, 0] + C[:, 3] - C[:, 2] + C[:, 5] - C[:, 4] + C[:, 7] - C[:, 6])
    b = 0.25 * (C[:, 2] - C[:, 0] + C[:, 3] - C[:, 1] + C[:, 6] - C[:, 4] + C[:, 7] - C[:, 5])
    c = 0.25 * (C[:, 4] - C[:, 0] + C[:, 5] - C[:, 1] + C[:, 6] - C[:, 2] + C[:, 7] - C[:, 3])
    return np.einsum("ij,ij->i", a, np.cross(b, c))


def trilinear_detF_volumes(P: np.ndarray, cells: np.ndarray, le: float) -> np.ndarray:
    """∫ det(∂x/∂X) over each cell for the trilinear map of its corner positions ``P[cells]``."""
    C = P[cells]  # (m, 8, 3), corner c = di + 2 dj + 4 dk
    corners = np.array([[c & 1, (c >> 1) & 1, (c >> 2) & 1] for c in range(8)], dtype=float)
    total = np.zeros(len(cells))
    for xi in GAUSS:
        for eta in GAUSS:
            for zeta in GAUSS:
                q = np.array([xi, eta, zeta])
                dw = np.empty((8, 3))  # dN_c/dxi_d of the trilinear shape functions
                for d in range(3):
                    others = np.where(corners == 1, q, 1 - q)
                    others[:, d] = np.where(corners[:, d] == 1, 1.0, -1.0)
                    dw[:, d] = np.prod(others, axis=1)
                F = np.einsum("mci,cj->mij", C, dw) / le
                total += np.linalg.det(F) * (le ** 3) / 8.0
    return total


def volume_changes(X: np.ndarray, u: np.ndarray, cells: np.ndarray, le: float) -> dict:
    """ΔV/V0 by both formulas for the nodal displacement ``u``."""
    V0 = len(cells) * le ** 3
    return {"volume_avg_edges": float(averaged_edge_volumes(X + u, cells).sum() / V0 - 1.0),
            "volume_detF": float(trilinear_detF_volumes(X + u, cells, le).sum() / V0 - 1.0)}


def field_errors(u_model: np.ndarray, u_ref: np.ndarray) -> dict:
    """Relative L2 ``‖u_m − u_f‖ / ‖u_f‖`` and relative max ``max|u_m − u_f| / max|u_f|``."""
    d = np.linalg.norm(u_model - u_ref, axis=1)
    ref, top = float(np.linalg.norm(u_ref)), float(np.linalg.norm(u_ref, axis=1).max())
    return {"u_rel_l2": float(np.linalg.norm(u_model - u_ref) / ref) if ref > 0 else float("nan"),
            "u_rel_max": float(d.max() / top) if top > 0 else float("nan"), "u_err_max_m": float(d.max())}


def nearest_node(X: np.ndarray, point) -> int:
    return int(np.argmin(np.linalg.norm(X - np.asarray(point, dtype=float), axis=1)))


def errors(model: dict, ref: dict, metrics, le: float, supports: dict) -> dict:
    """Every named error of one model run (``model``/``ref``: ``row`` and ``arrays``) against
    the reference; ``supports`` maps support names to their motion kind."""
    X, u_m, cells = model["arrays"]["X"], model["arrays"]["u"], model["arrays"]["cells"]
    u_f = ref["arrays"]["u"][match_nodes(X, ref["arrays"]["X"], le)]
    out: dict = {}
    info_m, info_f = model["row"].get("info", {}), ref["row"].get("info", {})
    for name in metrics.plate_force:
        if name not in supports:
            continue
        f_m = [info_m.get(f"reaction_{name}_f{c}", np.nan) for c in "xyz"]
        f_f = [info_f.get(f"reaction_{name}_f{c}", np.nan) for c in "xyz"]
        out[f"force_{name}_N"], out[f"force_{name}_fem_N"] = _signed_norm(f_m, f_f), _signed_norm(f_f, f_f)
        out[f"force_{name}_rel"] = relative(f_m, f_f)
        if supports[name] == "rotate":
            t_m = [info_m.get(f"reaction_{name}_t{c}", np.nan) for c in "xyz"]
            t_f = [info_f.get(f"reaction_{name}_t{c}", np.nan) for c in "xyz"]
            out[f"torque_{name}_rel"] = relative(t_m, t_f)
    if metrics.volume_change:
        vm, vf = volume_changes(X, u_m, cells, le), volume_changes(X, u_f, cells, le)
        for k in vm:
            out[f"{k}"], out[f"{k}_fem"] = vm[k], vf[k]
            out[f"{k}_rel"] = abs(vm[k] - vf[k]) / abs(vf[k]) if vf[k] != 0 else float("nan")
        out["volume_fem_own_detF"] = info_f.get("volume_detF", np.nan) / (len(cells) * le ** 3) - 1.0
    if metrics.displacement:
        out.update(field_errors(u_m, u_f))
    for name, p in metrics.points:
        i = nearest_node(X, p)
        out[f"point_{name}_u_m"] = float(np.linalg.norm(u_m[i]))
        out[f"point_{name}_fem_u_m"] = float(np.linalg.norm(u_f[i]))
        out[f"point_{name}_rel"] = relative(u_m[i], u_f[i])
    return out


def _signed_norm(v, ref) -> float:
    """|v| with the sign of its component along the reference's largest component."""
    v, ref = np.asarray(v, dtype=float), np.asarray(ref, dtype=float)
    k = int(np.argmax(np.abs(ref)))
    return float(np.sign(v[k]) * np.linalg.norm(v)) if v[k] != 0 else float(np.linalg.norm(v))
