"""Study files: a user's body, material, loads, models and meshes, answered against one FEM
reference with cost (the format: ``docs/study-format.md``).

``Study.from_toml(path, quick=False)`` reads and checks a file (:class:`StudyError` naming the
key); ``.tasks()``, ``.run(out)``, ``.tables(out)`` and ``.report(out)`` do the work."""

from studies.study.errors import StudyError
from studies.study.spec import Study

__all__ = ["Study", "StudyError"]
