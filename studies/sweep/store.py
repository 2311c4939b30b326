"""Stored results: one JSON row and one NPZ of arrays per run, written atomically.

A run is keyed by the SHA-256 of its scene, its solver specification and the solvers' code
version (:func:`code_version`), so an interrupted study resumes without recomputing finished runs
and a change to a solver invalidates exactly the runs it could change.  Files are written to a
temporary name in the same folder and renamed (``os.replace`` is atomic on POSIX).

Rows are strict JSON (a non-finite number is stored as ``null``).  A row names its key and
carries the SHA-256 of its arrays (:func:`arrays_digest`) and of itself (:func:`row_digest`), so a
truncated, empty, unparseable or too deeply nested row, a row without its key, a row with a value
of the wrong type or edited by hand (its code version included), a truncated NPZ or an NPZ of
another run is detected (:meth:`Store.check`); the runner moves such a run aside (``damaged/``,
with the reason) and computes it again, and the report leaves it out and says so.  The same holds for the
results a study computes outside runs (a bisection, a table of its own): ``computed/<name>/<key>.json``,
keyed by the job and the code version, with the SHA-256 of the result beside it
(:meth:`Store.save_computed`, :func:`studies.sweep.executors.map_stored`).  A process claims a run
before computing it (:meth:`Store.claim`, a POSIX lock on ``locks/<key>.lock`` that the kernel
releases when the process ends, however it ends), so two processes on one folder share the work
and a lock left by a killed process never blocks.
"""

from __future__ import annotations

import fcntl
import hashlib
import io
import json
import math
import os
import platform
import socket
import subprocess
import tempfile
import time
import warnings
import zipfile
import zlib
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np


def atomic_write_bytes(path: Path, data: bytes) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def atomic_write_text(path: Path, text: str) -> None:
    atomic_write_bytes(path, text.encode("utf-8"))


def _json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (set, tuple)):
        return list(o)
    raise TypeError(f"not JSON serializable: {type(o)}")


def _plain(obj, nonfinite):
    """``obj`` as plain JSON values: NumPy scalars and arrays made plain, tuples and sets lists, a
    pandas DataFrame ``{"$frame": {"columns": [...], "rows": [[...]]}}``, and each non-finite
    float replaced by ``nonfinite(value)``."""
    if isinstance(obj, dict):
        return {str(k): _plain(v, nonfinite) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, set)):
        return [_plain(v, nonfinite) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist(), nonfinite)
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else nonfinite(float(obj))
    if hasattr(obj, "columns") and hasattr(obj, "itertuples"):  # a pandas DataFrame
        return {"$frame": {"columns": [str(c) for c in obj.columns],
                           "rows": [_plain(list(r), nonfinite) for r in obj.itertuples(index=False)]}}
    return obj


def strict(obj):
    """``obj`` with every non-finite float (NaN, ±inf) replaced by ``None`` and NumPy scalars and
    arrays made plain, so that it serialises as strict JSON."""
    return _plain(obj, lambda v: None)


def dumps(obj) -> str:
    """Strict JSON (``null`` for a non-finite number, never ``NaN`` or ``Infinity``)."""
    return json.dumps(strict(obj), default=_json_default, sort_keys=True, indent=1, allow_nan=False)


def _reject_constant(name):
    raise ValueError(f"{name} is not strict JSON")


def loads(text: str):
    """Parse strict JSON (``NaN``/``Infinity`` rejected)."""
    return json.loads(text, parse_constant=_reject_constant)


def arrays_digest(arrays: dict | None) -> str | None:
    """SHA-256 of a run's arrays (names, dtypes, shapes and values; independent of the NPZ's
    compression and timestamps).  ``None`` for a run without arrays."""
    if not arrays:
        return None
    h = hashlib.sha256()
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name}:{a.dtype.str}:{a.shape};".encode())
        h.update(a.tobytes())
    return h.hexdigest()


SOLVER_SOURCES = {
    # the MSS depends on all of hybmss; the FEM on its package and hybmss's scene, lattice
    # (particle positions, averaged-edge volumes) and result types
    "mss": ("hybmss/**/*.py",),
    "fem": ("fem_reference/**/*.py", "hybmss/scene/*.py", "hybmss/lattice.py", "hybmss/result.py"),
}


@lru_cache(maxsize=4)
def code_version(side: str = "all") -> str:
    """Hash of the sources a solver side depends on (``"mss"``, ``"fem"``, or ``"all"``): a change
    to a solver changes the keys of exactly the runs it could affect."""
    h = hashlib.sha256()
    for f in source_files(side):
        h.update(f.relative_to(SOURCE_ROOT).as_posix().encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


SOURCE_ROOT = Path(__file__).resolve().parents[2]
"""The folder that holds the packages ``hybmss`` and ``fem_reference`` (this module is
``studies/sweep/store.py`` under it)."""


def source_files(side: str = "all") -> list[Path]:
    """The source files :func:`code_version` hashes for a side; a side whose patterns match no file
    is an error (a hash of nothing would key every run the same whatever the solver's code)."""
    patterns = SOLVER_SOURCES[side] if side in SOLVER_SOURCES else sum(SOLVER_SOURCES.values(), ())
    files = sorted({f for pat in patterns for f in SOURCE_ROOT.glob(pat)})
    missing = [pat for pat in patterns if not any(SOURCE_ROOT.glob(pat))]
    if missing:
        raise RuntimeError(f"the solver sources {', '.join(missing)} are not under {SOURCE_ROOT}: "
                           "the code version cannot be computed; reinstall hybmss")
    return files


def code_side(solver_kind: str) -> str:
    """The side of the code a solver kind depends on: ``"fem"`` for the FEM, ``"mss"`` for the rest."""
    return "fem" if solver_kind == "fem" else "mss"


CODE_FIELD = "code_version"
"""Field of a row holding the code version of its side (the one its key was made with)."""


def is_current(row: dict) -> bool:
    """True if a stored row was computed by the code of this checkout: its recorded
    :data:`CODE_FIELD` is the :func:`code_version` of its solver's side (a row stored by code
    that did not record it counts as another version)."""
    side = code_side("fem" if str(row.get("solver", "")).startswith("fem") else "mss")
    return row.get(CODE_FIELD) == code_version(side)


@lru_cache(maxsize=1)
def environment() -> dict:
    """Versions, git revision and machine, recorded with every run."""
    import numba
    import scipy
    import skfem

    root = Path(__file__).resolve().parent.parent
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True,
                             text=True, timeout=10).stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        rev = "unknown"
    return {
        "git_revision": rev,
        "code_version": code_version(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
        "scikit-fem": getattr(skfem, "__version__", "unknown"),
        "machine": platform.machine(),
        "processor": cpu_model(),
        "cpus": os.cpu_count(),
    }


def cpu_model(cpuinfo: str = "/proc/cpuinfo") -> str:
    """The processor's model name, which the timings depend on: Linux's ``model name`` in
    ``cpuinfo`` (``platform.processor()`` there is only the architecture), macOS's brand string,
    else whatever ``platform`` knows."""
    try:
        with open(cpuinfo, encoding="utf-8", errors="replace") as fh:
            for line in fh:
                name, sep, value = line.partition(":")
                if sep and name.strip() in ("model name", "Model", "cpu model") and value.strip():
                    return " ".join(value.split())
    except OSError:
        pass
    if platform.system() == "Darwin":
        try:
            out = subprocess.run(["sysctl", "-n", "machdep.cpu.brand_string"], capture_output=True, text=True,
                                 timeout=10).stdout.strip()
            if out:
                return out
        except (OSError, subprocess.SubprocessError):
            pass
    return platform.processor() or platform.machine()


class DamagedRun(Exception):
    """A stored run that cannot be trusted: the file and the reason."""

    def __init__(self, key: str, path: Path, reason: str):
        super().__init__(f"{path}: {reason}")
        self.key, self.path, self.reason = key, Path(path), reason


@dataclass
class Claim:
    """A run claimed by this process (an exclusive lock on ``locks/<key>.lock``)."""

    key: str
    path: Path
    fd: int

    def release(self) -> None:
        if self.fd < 0:
            return
        try:  # unlink first: a process that opened the file before sees another inode and retries
            os.unlink(self.path)
        except FileNotFoundError:
            pass
        os.close(self.fd)
        self.fd = -1

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()


ARRAYS_FIELD = "arrays_sha256"
NONFINITE_FIELD = "nonfinite"
ROW_FIELD = "row_sha256"
"""Field of a row holding the SHA-256 of the rest of it (:func:`row_digest`)."""
NONFINITE_VALUES = ("nan", "inf", "-inf")


def row_digest(row: dict) -> str:
    """SHA-256 of a stored row's strict-JSON values without its :data:`ROW_FIELD`: keys sorted,
    no spaces (independent of the file's indentation)."""
    body = {k: v for k, v in row.items() if k != ROW_FIELD}
    return _sha256(json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False))


def row_problem(row: dict) -> str | None:
    """Why a parsed row (checksum verified) cannot be read as a run record: a field of the
    wrong type; ``None`` if it can."""
    for field, kinds in (("key", str), ("status", str), (ARRAYS_FIELD, (str, type(None))),
                         ("info", (dict, type(None))), (NONFINITE_FIELD, (dict, type(None)))):
        if field in row and not isinstance(row[field], kinds):
            return f"{field!r} holds a {type(row[field]).__name__}"
    for path, text in (row.get(NONFINITE_FIELD) or {}).items():
        if text not in NONFINITE_VALUES:
            return f"{NONFINITE_FIELD!r} maps {path!r} to {text!r}, not one of {', '.join(NONFINITE_VALUES)}"
    return None


def _nonfinite(row: dict) -> dict:
    """``{field: "nan" | "inf" | "-inf"}`` for the non-finite numbers of a row (top level and
    ``info``), which strict JSON stores as ``null``; :meth:`Store.row` restores them."""
    out = {}
    for prefix, d in (("", row), ("info.", row.get("info") if isinstance(row.get("info"), dict) else {})):
        for k, v in d.items():
            if isinstance(v, (float, np.floating)) and not math.isfinite(v):
                out[prefix + k] = repr(float(v))
    return out


def _restore_nonfinite(row: dict) -> dict:
    for path, text in (row.get(NONFINITE_FIELD) or {}).items():
        head, _, tail = path.partition(".")
        target, name = (row.get(head), tail) if tail and isinstance(row.get(head), dict) else (row, path)
        if name in target and target[name] is None:
            target[name] = float(text)
    return row


def encode(obj):
    """``obj`` as plain JSON values, exactly: as :func:`strict`, but a non-finite float becomes
    ``{"$float": "nan"}`` (``"inf"``, ``"-inf"``) (:func:`decode` reverses all but NumPy types and
    tuples)."""
    return _plain(obj, lambda v: {"$float": repr(v)})


def decode(obj):
    """The value :func:`encode` made ``obj`` from (a DataFrame as a DataFrame)."""
    if isinstance(obj, list):
        return [decode(v) for v in obj]
    if isinstance(obj, dict):
        if set(obj) == {"$float"}:
            return float(obj["$float"])
        if set(obj) == {"$frame"}:
            import pandas as pd

            return pd.DataFrame([decode(r) for r in obj["$frame"]["rows"]], columns=obj["$frame"]["columns"])
        return {k: decode(v) for k, v in obj.items()}
    return obj


def _sha256(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _ordered_json(obj) -> str:
    """Strict JSON of plain values with the keys in their order (:func:`dumps` sorts them)."""
    return json.dumps(obj, allow_nan=False, indent=1)


class Store:
    """Folder of run records: ``runs/<key>.json`` (row) and ``runs/<key>.npz`` (arrays);
    ``locks/`` holds the claims of runs being computed, ``damaged/`` the runs moved aside,
    ``computed/<name>/`` the results a study computes outside runs (:meth:`save_computed`)."""

    def __init__(self, root):
        if isinstance(root, str) and not root.strip():
            raise ValueError("out (results folder) is '': a folder path is required")
        self.root = Path(root)
        self.runs = self.root / "runs"
        self.locks = self.root / "locks"
        self.damaged_dir = self.root / "damaged"
        self.computed = self.root / "computed"

    # ----------------------------------------------------------------- writing
    def check_writable(self) -> None:
        """Raise ``ValueError`` (naming the folder) unless the results folder is, or can be
        created as, a writable folder: checked before any work."""
        p = self.root.absolute()
        probe = p
        while not probe.exists():
            if probe.parent == probe:
                break
            probe = probe.parent
        if probe.exists() and not probe.is_dir():
            what = "is a file" if probe == p else f"is under {probe}, which is not a folder"
            raise ValueError(f"out (results folder) {str(self.root)!r} {what}: a writable folder is required")
        if not os.access(probe, os.W_OK | os.X_OK):
            raise ValueError(f"out (results folder) {str(self.root)!r}: {probe} is not writable; "
                             "a writable folder is required")
        for sub in (self.runs, self.locks):
            if sub.exists() and not sub.is_dir():
                raise ValueError(f"out (results folder) {str(self.root)!r}: {sub} is a file; "
                                 "a results folder holds runs/ and locks/ folders")

    def save(self, key: str, row: dict, arrays: dict | None = None) -> dict:
        """Store a run (arrays first, then the row naming their digest); returns the stored row."""
        arrays = {k: np.asarray(v) for k, v in (arrays or {}).items() if v is not None}
        row = {**row, "key": key, ARRAYS_FIELD: arrays_digest(arrays)}
        row[NONFINITE_FIELD] = _nonfinite(row)
        if arrays:
            buf = io.BytesIO()
            np.savez_compressed(buf, **arrays)
            atomic_write_bytes(self.runs / f"{key}.npz", buf.getvalue())
        else:
            self.runs.mkdir(parents=True, exist_ok=True)
            (self.runs / f"{key}.npz").unlink(missing_ok=True)
        # the JSON row is written last: its presence means the run is complete
        plain = loads(dumps(row))
        plain[ROW_FIELD] = row_digest(plain)
        text = dumps(plain)
        atomic_write_text(self.runs / f"{key}.json", text)
        del plain[ROW_FIELD]
        return _restore_nonfinite(loads(dumps(plain)))

    # ----------------------------------------------------------------- reading
    def _load_row(self, key: str) -> dict | None:
        path = self.runs / f"{key}.json"
        try:
            text = path.read_text()
        except FileNotFoundError:
            return None
        except (OSError, UnicodeDecodeError) as exc:
            raise DamagedRun(key, path, f"unreadable ({type(exc).__name__}: {exc})") from None
        if not text.strip():
            raise DamagedRun(key, path, "empty file")
        try:
            row = loads(text)
        except ValueError as exc:  # json.JSONDecodeError is a ValueError
            raise DamagedRun(key, path, f"not valid JSON ({' '.join(str(exc).split())[:200]})") from None
        except RecursionError:
            raise DamagedRun(key, path, "nested too deeply to be a run record") from None
        if not isinstance(row, dict) or not row:
            raise DamagedRun(key, path, "not a run record (empty or not an object)")
        if row.get("key") != key:
            raise DamagedRun(key, path, f"names key {str(row.get('key'))[:80]!r}, not its own")
        for field in ("status", ARRAYS_FIELD):
            if field not in row:
                raise DamagedRun(key, path, f"no {field!r} field (incomplete or an older store format)")
        if ROW_FIELD not in row and is_current(row):
            raise DamagedRun(key, path, f"no {ROW_FIELD!r} field (incomplete or an older store format)")
        try:  # a row of older code, stored before rows had checksums, has none
            same = ROW_FIELD not in row or row_digest(row) == row[ROW_FIELD]
        except (ValueError, TypeError, RecursionError):
            same = False
        if not same:
            raise DamagedRun(key, path, "the row does not match its checksum (edited or altered)")
        why = row_problem(row)
        if why:
            raise DamagedRun(key, path, f"not a run record ({why})")
        row.pop(ROW_FIELD, None)  # verified: a detail of the file, not a field of the run
        return _restore_nonfinite(row)

    def _load_arrays(self, key: str, row: dict) -> dict:
        path = self.runs / f"{key}.npz"
        want = row.get(ARRAYS_FIELD)
        if want is None:
            return {}
        try:
            with np.load(path) as z:
                arrays = {k: z[k] for k in z.files}
        except FileNotFoundError:
            raise DamagedRun(key, path, "missing (the row names arrays)") from None
        except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
            raise DamagedRun(key, path, f"unreadable ({type(exc).__name__}: {' '.join(str(exc).split())})") from None
        if arrays_digest(arrays) != want:
            raise DamagedRun(key, path, "arrays do not match the row's checksum (from another run or altered)")
        return arrays

    def check(self, key: str) -> dict | None:
        """The verified row of a stored run of the current code (the runner's keys are made with
        it), ``None`` if not stored; raises :class:`DamagedRun` (a row recording another code
        version at such a key is one: it would be left out of every table and never recomputed)."""
        row = self._load_row(key)
        if row is not None:
            if not is_current(row):
                raise DamagedRun(key, self.runs / f"{key}.json",
                                 f"records code version {str(row.get(CODE_FIELD))[:40]!r}, not the current one "
                                 "its key was made with")
            self._load_arrays(key, row)
        return row

    def has(self, key: str) -> bool:
        """True if the run is stored and intact."""
        try:
            return self.check(key) is not None
        except DamagedRun:
            return False

    def row(self, key: str) -> dict:
        row = self._load_row(key)
        if row is None:
            raise FileNotFoundError(f"{self.runs / (key + '.json')}: run not stored")
        return row

    def arrays(self, key: str) -> dict:
        """The arrays of a run, verified against its row's checksum ({} for a run without)."""
        row = self._load_row(key)
        return {} if row is None else self._load_arrays(key, row)

    def keys(self) -> list[str]:
        if not self.runs.is_dir():
            return []
        return sorted(p.stem for p in self.runs.glob("*.json") if not p.name.startswith("."))

    def scan(self, verify_arrays: bool = True, all_versions: bool = False) -> tuple[list[dict], list[DamagedRun]]:
        """Every stored row of the current code version (:func:`is_current`; every version with
        ``all_versions``) and every damaged run."""
        rows, damaged = [], []
        for key in self.keys():
            try:
                row = self._load_row(key)
                if not (all_versions or is_current(row)):
                    continue
                if verify_arrays:
                    self._load_arrays(key, row)
                rows.append(row)
            except DamagedRun as exc:
                damaged.append(exc)
        return rows, damaged

    def rows(self, all_versions: bool = False) -> list[dict]:
        """Every intact stored row computed by the current code (rows stored by other code
        versions too with ``all_versions``); a damaged run is left out with a warning naming it."""
        rows, damaged = self.scan(verify_arrays=False, all_versions=all_versions)
        for d in damaged:
            warnings.warn(f"damaged run left out: {d}", stacklevel=2)
        return rows

    # ----------------------------------------------------------------- computed results
    def computed_key(self, name: str, job) -> str:
        """Key of the result of ``job`` (JSON-able: numbers, strings, tuples) of the computation
        ``name``, made with the code version of the whole checkout (a change anywhere computes it
        again: these results mix the solvers)."""
        payload = dumps({"name": name, "job": encode(job), "code": code_version()})
        return _sha256(payload)[:24]

    def save_computed(self, name: str, key: str, result):
        """Store ``result`` (:func:`encode`-able) of job ``key`` of ``name`` atomically, with the
        SHA-256 of its text (keys in their order: a row's columns keep theirs); returns it as
        :meth:`load_computed` will give it back."""
        body = _ordered_json(encode(result))
        plain = loads(body)
        claim = self.claim(key)  # None: another process is writing the same job's result
        if claim is not None:
            with claim:
                atomic_write_text(self.computed / name / f"{key}.json", _ordered_json(
                    {"key": key, "name": name, "sha256": _sha256(body), "result": plain}) + "\n")
        return decode(plain)

    def load_computed(self, name: str, key: str) -> tuple[bool, object]:
        """``(True, result)`` of a stored job of ``name``, ``(False, None)`` if not stored;
        raises :class:`DamagedRun` for a file that is unreadable, not its own or altered."""
        path = self.computed / name / f"{key}.json"
        try:
            text = path.read_text()
        except FileNotFoundError:
            return False, None
        except (OSError, UnicodeDecodeError) as exc:
            raise DamagedRun(key, path, f"unreadable ({type(exc).__name__}: {exc})") from None
        try:
            doc = loads(text)
        except ValueError as exc:
            raise DamagedRun(key, path, f"not valid JSON ({' '.join(str(exc).split())[:200]})") from None
        except RecursionError:
            raise DamagedRun(key, path, "nested too deeply to be a stored result") from None
        if not isinstance(doc, dict) or doc.get("key") != key or doc.get("name") != name or "result" not in doc:
            raise DamagedRun(key, path, "not the result of this job (key, name or result missing)")
        try:
            same = _sha256(_ordered_json(doc["result"])) == doc.get("sha256")
        except (ValueError, TypeError, RecursionError):
            same = False
        if not same:
            raise DamagedRun(key, path, "the result does not match its checksum (altered)")
        try:
            return True, decode(doc["result"])
        except (ValueError, TypeError, KeyError, AttributeError, RecursionError) as exc:
            raise DamagedRun(key, path, f"not a stored result ({type(exc).__name__})") from None

    # ----------------------------------------------------------------- healing
    def quarantine(self, damaged: DamagedRun) -> Path:
        """Move a damaged run's files (or a damaged computed result) to ``damaged/`` (with the
        reason beside them)."""
        stamp = time.strftime("%Y%m%dT%H%M%S") + f"-{os.getpid()}"
        dest = self.damaged_dir
        dest.mkdir(parents=True, exist_ok=True)
        files = ([self.runs / f"{damaged.key}{suffix}" for suffix in (".json", ".npz")]
                 if damaged.path.parent == self.runs else [damaged.path])
        for src in files:
            if src.exists():
                os.replace(src, dest / f"{damaged.key}.{stamp}{src.suffix}")
        atomic_write_text(dest / f"{damaged.key}.{stamp}.reason.txt", f"{damaged}\n")
        return dest

    def claim(self, key: str) -> Claim | None:
        """Claim a run for this process; ``None`` if another live process holds it.  The lock
        is a POSIX record lock: it is not inherited by child processes and the kernel drops it
        when the holder exits, even on SIGKILL, so a lock file left behind never blocks."""
        self.locks.mkdir(parents=True, exist_ok=True)
        path = self.locks / f"{key}.lock"
        while True:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
            try:
                fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                os.close(fd)
                return None
            try:
                same = os.stat(path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if not same:  # released and unlinked by its holder meanwhile: take the new file
                os.close(fd)
                continue
            os.ftruncate(fd, 0)
            os.write(fd, f"{socket.gethostname()} {os.getpid()}\n".encode())
            return Claim(key, path, fd)

    def holder(self, key: str) -> str:
        """``host pid`` written by the process holding a run's claim ('' if unknown)."""
        try:
            return (self.locks / f"{key}.lock").read_text().strip()
        except OSError:
            return ""

    def remove_orphans(self) -> list[Path]:
        """Delete temporary files in ``runs/`` and ``computed/`` left by a process that was killed
        while writing (a key's files are written only under its claim: an unclaimed key's are
        orphans)."""
        removed = []
        for tmp in sorted([*self.runs.glob(".*.tmp"), *self.computed.glob("*/.*.tmp")]):
            key = tmp.name[1:].split(".", 1)[0]
            claim = self.claim(key)
            if claim is None:
                continue
            with claim:
                try:
                    tmp.unlink()
                    removed.append(tmp)
                except FileNotFoundError:
                    pass
        return removed

    def write_table(self, name: str, df) -> Path:
        """Write a pandas table as CSV and Markdown under ``tables/``, and the code version that
        wrote it beside them (``<name>.version``: :func:`table_is_current`)."""
        out = self.root / "tables"
        atomic_write_text(out / f"{name}.version", code_version() + "\n")
        atomic_write_text(out / f"{name}.csv", df.to_csv(index=False))
        try:
            md = df.to_markdown(index=False)
        except ImportError:  # tabulate not installed: a plain pipe table
            cols = list(df.columns)
            lines = ["| " + " | ".join(map(str, cols)) + " |", "|" + "---|" * len(cols)]
            lines += ["| " + " | ".join(_fmt(v) for v in r) + " |" for r in df.itertuples(index=False)]
            md = "\n".join(lines)
        atomic_write_text(out / f"{name}.md", md + "\n")
        return out / f"{name}.csv"


def table_is_current(csv_path) -> bool:
    """True if the table ``csv_path`` was written by the code of this checkout (its
    ``.version`` file names the current :func:`code_version`); a table without one counts as
    another version."""
    try:
        return Path(csv_path).with_suffix(".version").read_text().strip() == code_version()
    except OSError:
        return False


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)
