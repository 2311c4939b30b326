"""Comparison metrics between a mass-spring result and a FEM reference (SPEC §8).

Displacements are compared at the lattice particles (the FEM evaluates its solution there):
``mean``, ``max`` and relative L2 ``‖u_mss − u_fem‖ / ‖u_fem‖`` of the nodal difference, and the
mean over the middle layer that [G20] Figs 8 and 10 show.

**Middle layer.** The particles of the lattice plane z = const nearest to mid-height
z = (z_min + z_max)/2 of the rest configuration (on the 5 m cube with an even number of cells,
exactly z = 2.5 m; with an odd number, the lower of the two planes nearest to it).  Particles are
selected in the rest configuration, so the same material points are compared.

**Mean position difference.** [G20] prints "the mean position difference" over that layer without
saying which distance; :func:`middle_layer_metrics` gives the alternatives:

- ``mid_layer_mean``: mean over the layer's particles of the Euclidean distance
  ``|x_mss − x_fem| = |u_mss − u_fem|`` (3D; the default, used everywhere a single number is shown);
- ``mid_layer_mean_xy``: the same with only the in-plane (x, y) components, i.e. the difference
  seen in a top view of the cross section (Figs 8 and 10 draw the layer from above);
- ``mid_layer_rms``: root mean square of the 3D distance.
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


def middle_layer_metrics(X: np.ndarray, u_mss: np.ndarray, u_fem: np.ndarray) -> dict:
    """``{"mid_layer_mean", "mid_layer_mean_xy", "mid_layer_rms", "mid_layer_n"}`` over
    :func:`middle_layer` (m; see the module docstring for the definitions)."""
    mid = middle_layer(X)
    du = u_mss[mid] - u_fem[mid]
    d3 = np.linalg.norm(du, axis=1)
    return {"mid_layer_mean": float(d3.mean()), "mid_layer_mean_xy": float(np.linalg.norm(du[:, :2], axis=1).mean()),
            "mid_layer_rms": float(np.sqrt(np.mean(d3 ** 2))), "mid_layer_n": int(mid.size)}


def diff_metrics(X: np.ndarray, u_mss: np.ndarray, u_fem: np.ndarray) -> dict:
    """``{"mean", "max", "rel_l2"}`` of |u_mss − u_fem| (m; rel_l2 unitless) and the middle-layer
    metrics of :func:`middle_layer_metrics`."""
    if u_mss.shape != u_fem.shape:
        raise ValueError(f"displacement arrays differ in shape: {u_mss.shape} vs {u_fem.shape}")
    d = np.linalg.norm(u_mss - u_fem, axis=1)
    ref = float(np.linalg.norm(u_fem))
    return {
        "mean": float(d.mean()),
        "max": float(d.max()),
        "rel_l2": float(np.linalg.norm(u_mss - u_fem) / ref) if ref > 0 else float("nan"),
        **middle_layer_metrics(X, u_mss, u_fem),
    }


def default_law(spec) -> str:
    """Linear at ≤ 5 % (and torsion ≤ 5°), Neo-Hookean above and for bending (SPEC §6 notes);
    by magnitude: a load and its opposite are solved with the same law."""
    if spec.experiment == "torsion":
        return "linear" if abs(spec.angle_deg) <= 5.0 else "neo-hookean"
    if spec.experiment == "bending":
        return "neo-hookean"
    return "linear" if abs(spec.deformation) <= 0.05 + 1e-12 else "neo-hookean"
