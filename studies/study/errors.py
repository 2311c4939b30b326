"""The one error of a study file that is not allowed (exit status 2 on the command line)."""

from __future__ import annotations


class StudyError(ValueError):
    """A study file's key whose value is not allowed: ``key`` is its dotted path
    (``material.nu``, ``load_case[1].support[0].region``), ``value`` what the file gave and
    ``allowed`` what is allowed.  The message is one line naming all three."""

    def __init__(self, key: str, value, allowed: str, path: str | None = None):
        self.key, self.value, self.allowed, self.path = key, value, allowed, path
        where = f"study file {path}: " if path else "study file: "
        super().__init__(f"{where}{key} = {_show(value)} is not allowed: {allowed}")


def _show(value) -> str:
    text = repr(value) if isinstance(value, str) else str(value)
    text = " ".join(text.split())
    return text if len(text) <= 80 else text[:77] + "..."
