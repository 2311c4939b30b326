"""Reading a study file's tables key by key: every value is checked where it is read, and every
refusal is a :class:`StudyError` naming the dotted key path (``load_case[0].support[1].region``)."""

from __future__ import annotations

import difflib
import math
from pathlib import Path

from studies.study.errors import StudyError


def is_number(v) -> bool:
    """A finite number that a float holds (TOML integers are unbounded: 1e400 written as digits
    is not one)."""
    if not isinstance(v, (int, float)) or isinstance(v, bool):
        return False
    try:
        return math.isfinite(v)
    except OverflowError:
        return False


class Table:
    """One table of the file (``path`` its dotted key) and the file it came from (``file``, for
    the message and for relative paths).  Keys read through it are remembered; :meth:`done`
    refuses the ones never read, with the close matches."""

    def __init__(self, data, path: str, file: str | None, folder: Path | None = None):
        if not isinstance(data, dict):
            raise StudyError(path, data, "a table", file)
        self.data, self.path, self.file, self.folder = data, path, file, folder
        self._read: set[str] = set()

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def error(self, name: str, value, allowed: str) -> StudyError:
        return StudyError(self.key(name), value, allowed, self.file)

    def has(self, name: str) -> bool:
        return name in self.data

    def raw(self, name: str, default=None, required: bool = False):
        self._read.add(name)
        if name not in self.data:
            if required:
                typo = [k for k in self.data if k not in self._read and close(k, [name])]
                if typo:  # a misspelt key, not a missing one
                    raise self.error(typo[0], self.data[typo[0]], f"not a key of [{self.path or 'the file'}]"
                                     f"{close(typo[0], [name])}")
                raise self.error(name, "(missing)", "a value is required")
            return default
        return self.data[name]

    def sub(self, name: str, required: bool = False) -> "Table | None":
        value = self.raw(name, required=required)
        if value is None:
            return None
        return Table(value, self.key(name), self.file, self.folder)

    def items(self, name: str, required: bool = False) -> list["Table"]:
        """An array of tables (``[[load_case]]``)."""
        value = self.raw(name, required=required)
        if value is None:
            return []
        if not isinstance(value, list) or not value or not all(isinstance(v, dict) for v in value):
            raise self.error(name, value, "one or more tables ([[" + self.key(name) + "]])")
        return [Table(v, f"{self.key(name)}[{i}]", self.file, self.folder) for i, v in enumerate(value)]

    def number(self, name: str, default=None, lo=None, hi=None, lo_open=False, hi_open=False,
               required: bool = False, integer: bool = False) -> float | None:
        value = self.raw(name, default, required)
        if value is None:
            return None
        check_number(value, lo, hi, lo_open, hi_open, integer, lambda what: self.error(name, value, what))
        return int(value) if integer else float(value)

    def numbers(self, name: str, n: int | None = None, default=None, required: bool = False, lo=None,
                lo_open=False, allow_scalar=False, hi=None) -> list[float] | None:
        """A list of ``n`` numbers (any length >= 1 if ``n`` is None); a single number when
        ``allow_scalar`` (returned as a list of one)."""
        value = self.raw(name, default, required)
        if value is None:
            return None
        if allow_scalar and is_number(value):
            value = [value]
        what = f"a list of {n} finite numbers" if n else "a finite number or a non-empty list of them"
        if lo is not None or hi is not None:
            what += " " + _range(lo, hi, lo_open, False)
        if not isinstance(value, list) or (n and len(value) != n) or not value \
                or not all(is_number(v) for v in value):
            raise self.error(name, self.data.get(name), what)
        for v in value:
            check_number(v, lo, hi, lo_open, False, False, lambda w: self.error(name, self.data[name], what))
        return [float(v) for v in value]

    def text(self, name: str, default=None, choices=None, required: bool = False) -> str | None:
        value = self.raw(name, default, required)
        if value is None:
            return None
        if not isinstance(value, str):
            raise self.error(name, value, "a string" + (f": one of {', '.join(choices)}" if choices else ""))
        if choices is not None and value not in choices:
            raise self.error(name, value, f"one of {', '.join(choices)}{close(value, choices)}")
        return value

    def flag(self, name: str, default: bool) -> bool:
        value = self.raw(name, default)
        if not isinstance(value, bool):
            raise self.error(name, value, "true or false")
        return value

    def file_path(self, name: str, suffixes: tuple[str, ...]) -> Path | None:
        value = self.text(name)
        if value is None:
            return None
        p = Path(value)
        if not p.is_absolute() and self.folder is not None:
            p = self.folder / p
        if not p.is_file():
            raise self.error(name, value, f"an existing file ({', '.join(suffixes)}), relative to the study file")
        if p.suffix.lower() not in suffixes:
            raise self.error(name, value, f"a file of type {', '.join(suffixes)}")
        return p

    def done(self) -> None:
        """Refuse the keys never read (unknown to the format), naming the close matches."""
        for k in self.data:
            if k not in self._read:
                raise self.error(k, self.data[k], f"not a key of [{self.path or 'the file'}]; allowed: "
                                 f"{', '.join(sorted(self._read))}{close(k, self._read)}")


def check_number(value, lo, hi, lo_open, hi_open, integer, error) -> None:
    """Raise ``error(what)`` unless ``value`` is a finite number in the range."""
    what = ("an integer" if integer else "a finite number") + (" " if lo is not None or hi is not None else "") + \
        _range(lo, hi, lo_open, hi_open)
    if not is_number(value) or (integer and float(value) != int(value)):
        raise error(what)
    if lo is not None and (value < lo or (lo_open and value == lo)):
        raise error(what)
    if hi is not None and (value > hi or (hi_open and value == hi)):
        raise error(what)


def _range(lo, hi, lo_open, hi_open) -> str:
    lo_s = "" if lo is None else (f"> {lo:g}" if lo_open else f">= {lo:g}")
    hi_s = "" if hi is None else (f"< {hi:g}" if hi_open else f"<= {hi:g}")
    return " and ".join(s for s in (lo_s, hi_s) if s)


def close(word: str, choices, n: int = 3) -> str:
    """" (did you mean a, b?)" naming up to ``n`` choices close to ``word`` (difflib, case aside),
    or ""."""
    by_lower = {}
    for c in sorted(map(str, choices)):
        by_lower.setdefault(c.lower(), c)
    found = difflib.get_close_matches(str(word).lower(), list(by_lower), n=n)
    return f" (did you mean {', '.join(by_lower[f] for f in found)}?)" if found else ""
