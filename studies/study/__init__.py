"""Study files: a user's body, material, loads, models and meshes, answered against one FEM
reference with cost (the format: ``docs/study-format.md``)."""

from .errors import StudyError

__all__ = ["StudyError"]
