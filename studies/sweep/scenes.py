"""The experiments' scene specifications, defined in :mod:`hybmss.experiments` (one scene builder
for every command, study and benchmark)."""

from hybmss.experiments import (BEAM_LENGTH, BEAM_WIDTH, CUBE_SIDE, DEFAULTS, EXPERIMENTS, SceneSpec,
                                shear_scene, uniaxial_scene)

__all__ = ["BEAM_LENGTH", "BEAM_WIDTH", "CUBE_SIDE", "DEFAULTS", "EXPERIMENTS", "SceneSpec", "shear_scene",
           "uniaxial_scene"]
