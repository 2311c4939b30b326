"""``baudet2009``: the cubic-cell MSS of [B09] — per-cell edges and inner diagonals, no face
diagonals, no volume energy, and lateral correction forces for ν (not an energy).

The folder holds the whole model: this module (the registry's ``MODEL``), the corrections and
their derivation (:mod:`hybmss.models.baudet2009.corrections`, the NumPy reference) and their
Numba kernels (:mod:`hybmss.models.baudet2009._kernels`), among them the stage the corrections
contribute to the lattice's generated stencil kernel (``Corrections.stencil_stage``)."""

from __future__ import annotations

from ...calibrate import b09_springs
from ..base import ModelBase, Style
from .corrections import Corrections


class Baudet2009(ModelBase):
    name = "baudet2009"
    label = "cubic-cell MSS with lateral corrections [B09]"
    style = Style("#8c564b", "v")
    conservative = False
    solvers = ("static", "explicit")
    kernels = ("numba", "numpy")  # the Numba kernel runs its corrections (float64)
    order = 3

    def constants(self, p, material, le):
        return b09_springs(material, le)

    def terms(self, p, scene, lattice, consts):
        return (Corrections.for_system(consts, scene.material, lattice),)


MODEL = Baudet2009()
