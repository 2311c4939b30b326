"""Scenes and meshes of the asv suite (``asv run --python=same`` in the project's environment).

Meshes: the compression cube of SPEC §6 at 10³, 20³ and 30³ cells of 0.5 m, and the tension
beam 0.4 × 0.4 × 2.4 m of 8×8×48 cells (SPEC §9), both at E = 10⁴ Pa, ρ = 1000 kg/m³, the
bottom clamped and the top plate moved by 5 % of the height (down on the cube, up on the beam).
"""

from __future__ import annotations

import os

import numpy as np

from hybmss import models
from hybmss.scene import Body, Material, Model, Motion, Plate, Region, Scene

MESHES = os.environ.get("HYBMSS_ASV_MESHES", "10x10x10,20x20x20,30x30x30,beam-8x8x48").split(",")
"""The meshes of every benchmark; ``HYBMSS_ASV_MESHES`` (comma-separated) selects fewer (``make bench``)."""
MODELS = models.names()


def scene(mesh: str, model: str | None = None, nu: float = 0.3, d: float = 0.05) -> Scene:
    model = models.default_name() if model is None else model
    if mesh.startswith("beam-"):
        n = tuple(int(v) for v in mesh[5:].split("x"))
        le, sign = 0.4 / n[0], 1.0
    else:
        n = tuple(int(v) for v in mesh.split("x"))
        le, sign = 0.5, -1.0
    H = n[2] * le
    return Scene(Body.box(*n, le), Material(1e4, nu, 1000.0), Model(model),
                 plates=(Plate("bottom", Region("z-")),
                         Plate("top", Region("z+"), Motion("translate", (0.0, 0.0, sign * d * H)))),
                 name=f"{mesh} {model} nu={nu:g}")


def rel_l2(u, u_ref) -> float:
    """‖u − u_ref‖₂ / ‖u_ref‖₂ over the lattice particles."""
    return float(np.linalg.norm(u - u_ref) / np.linalg.norm(u_ref))
