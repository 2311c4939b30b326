"""Comparison metrics between a mass-spring result and a FEM reference (SPEC §8).

Displacements are compared at the lattice particles (the FEM evaluates its solution there):
``mean``, ``max`` and relative L2 ``‖u_mss − u_fem‖ / ‖u_fem‖`` of the nodal difference, and the
mean over the middle layer (z = H/2) that [G20] Figs 8 and 10 show.
"""

from __future__ import annotations

import numpy as np


def middle_layer(X: np.ndarray) -> np.ndarray:
    """Indices of the particles of the layer nearest to mid-height (z = H/2)."""
    z = X[:, 2]
    mid = 0.5 * (z.min() + z.max())
    levels = np.unique(np.round(z, 12))
    target = levels[np.argmin(np.abs(levels - mid))]
    return np.flatnonzero(np.abs(z - target) <= 1e-9 * max(1.0, abs(target)))


def diff_metrics(X: np.ndarray, u_mss: np.ndarray, u_fem: np.ndarray) -> dict:
    """``{"mean", "max", "rel_l2", "mid_layer_mean"}`` of |u_mss − u_fem| (m; rel_l2 unitless)."""
    if u_mss.shape != u_fem.shape:
        raise ValueError(f"displacement arrays differ in shape: {u_mss.shape} vs {u_fem.shape}")
    d = np.linalg.norm(u_mss - u_fem, axis=1)
    ref = float(np.linalg.norm(u_fem))
    mid = middle_layer(X)
    return {
        "mean": float(d.mean()),
        "max": float(d.max()),
        "rel_l2": float(np.linalg.norm(u_mss - u_fem) / ref) if ref > 0 else float("nan"),
        "mid_layer_mean": float(d[mid].mean()),
    }


def default_law(spec) -> str:
    """Linear at ≤ 5 % (and torsion ≤ 5°), Neo-Hookean above and for bending (SPEC §6 notes);
    by magnitude: a load and its opposite are solved with the same law."""
    if spec.experiment == "torsion":
        return "linear" if abs(spec.angle_deg) <= 5.0 else "neo-hookean"
    if spec.experiment == "bending":
        return "neo-hookean"
    return "linear" if abs(spec.deformation) <= 0.05 + 1e-12 else "neo-hookean"
