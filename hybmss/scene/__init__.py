"""Scenes as plain, frozen data.

A :class:`Scene` says everything both solvers (the mass-spring system and the FEM reference)
need: the body (a set of cubic cells of edge ``le`` on a regular grid), the material
(E, ν, ρ), the model (by name, with its parameters), the plates (particle sets with a prescribed motion),
gravity and damping.  It holds no arrays that could be mutated: a voxel mask is stored as packed
bytes, so a scene is hashable and has a stable :meth:`Scene.digest`.

Variants of a scene come from :func:`dataclasses.replace`; every constructor validates its
values and raises :class:`ValueError` naming the parameter and its allowed range.

The package is split by concept: :mod:`.body` (the cells), :mod:`.material` (material and model),
:mod:`.boundary` (motions, regions, plates, loads), :mod:`.scene` (the scene) and :mod:`.checks`
(validators, the JSON schema, the support checks).  Every public name is importable from here.
"""

from .body import Body, parse_mesh
from .boundary import MOTIONS, REGION_EXTRAS, Load, Motion, Plate, Region, rotation_matrix
from .checks import (PLATE_PATH_SAMPLES, RIGID_MODES, SceneTypeError, free_rigid_modes, pieces, plates_cross,
                     scene_dict_error, unsupported)
from .material import (NEARLY_INCOMPRESSIBLE_NU, NU_OPEN_RANGE, NU_RANGE, Material, Model, admissible_nu, check_nu,
                       nearly_incompressible)
from .scene import Scene

__all__ = [
    "Body", "parse_mesh",
    "MOTIONS", "REGION_EXTRAS", "Load", "Motion", "Plate", "Region", "rotation_matrix",
    "PLATE_PATH_SAMPLES", "RIGID_MODES", "SceneTypeError", "free_rigid_modes", "pieces", "plates_cross",
    "scene_dict_error", "unsupported",
    "NEARLY_INCOMPRESSIBLE_NU", "NU_OPEN_RANGE", "NU_RANGE", "Material", "Model", "admissible_nu", "check_nu",
    "nearly_incompressible",
    "Scene",
]
