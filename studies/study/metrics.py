"""The errors of a model run against its FEM reference, every one relative and named.

**Where the FEM is sampled.**  The reference's mesh is the same voxel body, each cell split into
refine³ elements, so every lattice node of a model at that resolution is a node of the FEM mesh;
the FEM's own interpolation evaluated there is its nodal value, which ``fem_reference.solve``
returns at the lattice particles (``Result.u``; the test checks skfem's ``probes`` give the same).
:func:`match_nodes` pairs the model's nodes with the reference's by position and refuses a node
that is not one of them.

**Volume change, two formulas, each applied to both fields:** ``volume_avg_edges`` (Σ a·(b×c) of
the averaged cell edges, the mass-spring systems' formula) and ``volume_detF`` (∫ det F of the
trilinear interpolation of the nodal positions, 2×2×2 Gauss points per cell).  

**Every error is measured on a scale the load defines** (:func:`load_scales`), never on a
quantity the reference puts near zero (a plate force in a twist, a volume change in a shear):

- the reactions on the load's force scale ``F_load = max over supports s of max(|F_s|, |T_s| / R_s)``
  (the FEM's reactions; ``R_s`` the support's radius, the largest distance of its nodes from their
  centroid): ``force_<s>_err = |F − F_FEM| / F_load``, ``torque_<s>_err = |T − T_FEM| / (F_load R_s)``;
- a volume change ΔV/V0 on the load's strain scale ``ε_load = max |u_FEM| / L`` (``L`` the body's
  largest bounding-box edge: the volume change of a body of volume V0 strained by ε_load):
  ``volume_<formula>_err = |ΔV − ΔV_FEM| / (V0 ε_load)``;
- the displacement field on its own magnitude (``u_rel_l2``, ``u_rel_max``), a load-defined scale;
  a named point's displacement on the largest, max |u_FEM|: ``point_<name>_err``.

The relative errors ``|q − q_FEM| / |q_FEM|`` (``force_<s>_rel``, ``torque_<s>_rel``,
``volume_<formula>_rel``, ``point_<name>_rel``) are published only where the reference's ``q_FEM`` is neither near zero
on its scale (below :data:`NEAR_ZERO` of it) nor below the reference's own error estimate
(``reference_error_estimate``, relative to the same scales, when the study refines its reference
"auto"); otherwise they are NaN, and so is ``u_rel_l2`` (the budgets' ranking) when the estimate
reaches the displacement scale itself.
"""

from __future__ import annotations

import numpy as np

GAUSS = 0.5 + np.array([-1.0, 1.0]) / (2.0 * np.sqrt(3.0))
NEAR_ZERO = 0.05
"""A reference quantity below this fraction of its load scale is near zero: no relative error."""


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


def norm(v) -> float:
    """The Euclidean norm of ``v``, scaled by its largest entry first (no overflow to inf for
    entries near the largest double, no underflow to 0 for tiny ones)."""
    v = np.asarray(v, dtype=float).ravel()
    top = float(np.max(np.abs(v))) if v.size else 0.0
    if top == 0.0 or not np.isfinite(top):
        return top
    return top * float(np.sqrt(np.sum((v / top) ** 2)))


def relative(a, b) -> float:
    """``|a − b| / |b|`` (vectors: norms); NaN when the reference is 0."""
    return _ratio(difference(a, b), norm(b))


def difference(a, b) -> float:
    """``|a − b|`` (vectors: norm), both scaled by their largest entry first (no overflow)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    top = max(float(np.max(np.abs(a), initial=0.0)), float(np.max(np.abs(b), initial=0.0)))
    if top == 0.0 or not np.isfinite(top):
        return top
    return top * norm(a / top - b / top)


def _ratio(num: float, den: float) -> float:
    return float(num / den) if den > 0 and np.isfinite(den) else float("nan")


def scaled(a, b, scale: float) -> float:
    """``|a − b| / scale`` (vectors: norms); NaN without a positive scale."""
    return _ratio(difference(a, b), scale)


def published_relative(a, b, scale: float, estimate: float) -> float:
    """:func:`relative`, or NaN where the reference ``b`` is near zero on ``scale``
    (:data:`NEAR_ZERO`) or below its own error estimate (``estimate`` × ``scale``)."""
    floor = max(NEAR_ZERO, estimate if np.isfinite(estimate) else 0.0) * scale
    return relative(a, b) if norm(b) >= floor and norm(b) > 0 else float("nan")


def support_radius(X: np.ndarray, selected: np.ndarray, le: float) -> float:
    """The largest distance of a support's nodes ``X[selected]`` from their centroid (``le`` for a
    single node): the lever arm of its torque."""
    P = X[selected]
    if len(P) == 0:
        return le
    r = float(np.linalg.norm(P - P.mean(axis=0), axis=1).max())
    return r if r > 0 else le


def load_scales(info_f: dict, radii: dict, u_f: np.ndarray, X: np.ndarray) -> dict:
    """The load's scales from the reference (module docstring): ``force_N`` (F_load over every
    support in ``radii``, name → R_s), ``u_m`` (max |u_FEM|) and ``strain`` (ε_load)."""
    force = 0.0
    for name, R in radii.items():
        f = [info_f.get(f"reaction_{name}_f{c}", np.nan) for c in "xyz"]
        t = [info_f.get(f"reaction_{name}_t{c}", np.nan) for c in "xyz"]
        for v in (norm(f), norm(t) / R):
            force = max(force, v) if np.isfinite(v) else force
    u = float(np.linalg.norm(u_f, axis=1).max()) if len(u_f) else 0.0
    L = float((X.max(axis=0) - X.min(axis=0)).max()) if len(X) else 0.0
    return {"force_N": force, "u_m": u, "strain": u / L if L > 0 else float("nan")}


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


def errors(model: dict, ref: dict, metrics, le: float, supports: dict, radii: dict | None = None) -> dict:
    """Every named error of one model run (``model``/``ref``: ``row`` and ``arrays``) against
    the reference; ``supports`` maps support names to their motion kind, ``radii`` to their radius
    (m, :func:`support_radius`; ``le`` where not given).  The load's scales (:func:`load_scales`)
    are columns of their own: ``force_scale_N``, ``strain_scale``."""
    X, u_m, cells = model["arrays"]["X"], model["arrays"]["u"], model["arrays"]["cells"]
    u_f = ref["arrays"]["u"][match_nodes(X, ref["arrays"]["X"], le)]
    info_m, info_f = model["row"].get("info", {}), ref["row"].get("info", {})
    radii = {name: (radii or {}).get(name, le) for name in supports}
    sc = load_scales(info_f, radii, u_f, X)
    est = info_f.get("reference_error_estimate")
    est = float(est) if est is not None else float("nan")
    out: dict = {"force_scale_N": sc["force_N"], "strain_scale": sc["strain"], "reference_error_estimate": est}
    for name in metrics.plate_force:
        if name in supports:
            out.update(_reaction_errors(name, supports[name], info_m, info_f, sc["force_N"], radii[name], est))
    if metrics.volume_change:
        vm, vf = volume_changes(X, u_m, cells, le), volume_changes(X, u_f, cells, le)
        for k in vm:
            out[f"{k}"], out[f"{k}_fem"] = vm[k], vf[k]
            out[f"{k}_err"] = scaled(vm[k], vf[k], sc["strain"])
            out[f"{k}_rel"] = published_relative(vm[k], vf[k], sc["strain"], est)
        out["volume_fem_own_detF"] = info_f.get("volume_detF", np.nan) / (len(cells) * le ** 3) - 1.0
    if metrics.displacement:
        out.update(field_errors(u_m, u_f))
        if np.isfinite(est) and est >= 1.0:  # the reference is below its own error estimate
            out.update(u_rel_l2=float("nan"), u_rel_max=float("nan"))
    for name, p in metrics.points:
        i = nearest_node(X, p)
        out[f"point_{name}_u_m"] = float(np.linalg.norm(u_m[i]))
        out[f"point_{name}_fem_u_m"] = float(np.linalg.norm(u_f[i]))
        out[f"point_{name}_err"] = scaled(u_m[i], u_f[i], sc["u_m"])
        out[f"point_{name}_rel"] = published_relative(u_m[i], u_f[i], sc["u_m"], est)
    return out


def _reaction_errors(name: str, kind: str, info_m: dict, info_f: dict, force: float, R: float, est: float) -> dict:
    """Force (and for a rotate support torque) of support ``name``: the values, the error on the
    load's scale (``force`` N, ``force`` × ``R`` N m) and the published relative error."""
    f_m = [info_m.get(f"reaction_{name}_f{c}", np.nan) for c in "xyz"]
    f_f = [info_f.get(f"reaction_{name}_f{c}", np.nan) for c in "xyz"]
    out = {f"force_{name}_N": _signed_norm(f_m, f_f), f"force_{name}_fem_N": _signed_norm(f_f, f_f),
           f"force_{name}_err": scaled(f_m, f_f, force),
           f"force_{name}_rel": published_relative(f_m, f_f, force, est)}
    if kind == "rotate":
        t_m = [info_m.get(f"reaction_{name}_t{c}", np.nan) for c in "xyz"]
        t_f = [info_f.get(f"reaction_{name}_t{c}", np.nan) for c in "xyz"]
        out[f"torque_{name}_err"] = scaled(t_m, t_f, force * R)
        out[f"torque_{name}_rel"] = published_relative(t_m, t_f, force * R, est)
    return out


def _signed_norm(v, ref) -> float:
    """|v| with the sign of its component along the reference's largest component."""
    v, ref = np.asarray(v, dtype=float), np.asarray(ref, dtype=float)
    k = int(np.argmax(np.abs(ref)))
    return float(np.sign(v[k]) * norm(v)) if v[k] != 0 else float(norm(v))
