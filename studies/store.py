"""Stored results: one JSON row and one NPZ of arrays per run, written atomically.

A run is keyed by the SHA-256 of its scene, its solver specification and the solvers' code
version (:func:`code_version`), so an interrupted study resumes without recomputing finished runs
and a change to a solver invalidates exactly the runs it could change.  Files are written to a
temporary name in the same folder and renamed (``os.replace`` is atomic on POSIX).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import platform
import subprocess
import tempfile
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


def dumps(obj) -> str:
    return json.dumps(obj, default=_json_default, sort_keys=True, indent=1)


SOLVER_SOURCES = {
    # the MSS depends on all of hybmss; the FEM on its package and hybmss's scene, lattice
    # (particle positions, averaged-edge volumes) and result types
    "mss": ("hybmss/**/*.py",),
    "fem": ("fem_reference/**/*.py", "hybmss/scene.py", "hybmss/lattice.py", "hybmss/result.py"),
}


@lru_cache(maxsize=4)
def code_version(side: str = "all") -> str:
    """Hash of the sources a solver side depends on (``"mss"``, ``"fem"``, or ``"all"``): a change
    to a solver changes the keys of exactly the runs it could affect."""
    h = hashlib.sha256()
    root = Path(__file__).resolve().parent.parent
    patterns = SOLVER_SOURCES[side] if side in SOLVER_SOURCES else sum(SOLVER_SOURCES.values(), ())
    files = sorted({f for pat in patterns for f in root.glob(pat)})
    for f in files:
        h.update(f.relative_to(root).as_posix().encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


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
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
    }


class Store:
    """Folder of run records: ``runs/<key>.json`` (row) and ``runs/<key>.npz`` (arrays)."""

    def __init__(self, root):
        self.root = Path(root)
        self.runs = self.root / "runs"

    def has(self, key: str) -> bool:
        return (self.runs / f"{key}.json").exists()

    def save(self, key: str, row: dict, arrays: dict | None = None) -> None:
        if arrays:
            buf = io.BytesIO()
            np.savez_compressed(buf, **{k: np.asarray(v) for k, v in arrays.items() if v is not None})
            atomic_write_bytes(self.runs / f"{key}.npz", buf.getvalue())
        # the JSON row is written last: its presence means the run is complete
        atomic_write_text(self.runs / f"{key}.json", dumps(row))

    def row(self, key: str) -> dict:
        return json.loads((self.runs / f"{key}.json").read_text())

    def arrays(self, key: str) -> dict:
        path = self.runs / f"{key}.npz"
        if not path.exists():
            return {}
        with np.load(path) as z:
            return {k: z[k] for k in z.files}

    def rows(self) -> list[dict]:
        if not self.runs.exists():
            return []
        return [json.loads(p.read_text()) for p in sorted(self.runs.glob("*.json"))]

    def write_table(self, name: str, df) -> Path:
        """Write a pandas table as CSV and Markdown under ``tables/``."""
        out = self.root / "tables"
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


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)
