"""``python -m benchmarks.profile_store DIR``: where the compute seconds of a reproduction went.

Reads a results folder (``python -m studies run --all --out DIR``; ``DIR`` or ``DIR/results``)
and prints, from its stored rows alone:

- **per study**: runs, runs computed and runs not computed (a step budget below the steps to rest,
  :mod:`studies.sweep.rest_bound`), the compute seconds (``elapsed_s`` of each row: the run's
  own process time in its worker, set-up included), their share of the whole and the seconds of
  its expected non-answers (runs not at rest within their budget);
- **per study and model** and **per solver kind**: the same seconds;
- **the longest runs** (the tail a pool of two workers waits for: a run longer than the pool's
  seconds divided by its workers sets the wall time alone);
- **the timeline**: the write times of the tables and of the results computed outside runs
  (``computed/<name>``), in seconds from the first stored run, so that a driver that runs after
  the pool (performance, the pareto repeats, the stability bisections, modes) shows as the gap
  before its table.

The pooled runs on ``w`` workers cannot take less wall time than ``Σ elapsed_s / w`` nor than
the longest run; the ``bound`` line gives both.  ``--compile`` also measures the kernel compile
share: the quick reproduction run twice into fresh folders, the first with empty Numba and
generated-kernel caches (``NUMBA_CACHE_DIR``, ``HYBMSS_KERNEL_CACHE``), the second with the
caches the first filled; their wall times and the difference.
``--json`` prints one strict-JSON object instead of the tables.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

NOT_AT_REST = "not-converged"
"""Status of a run not at rest within its step budget (an expected non-answer)."""


def results_root(path) -> Path:
    """The results folder under ``path`` (``path`` itself or ``path/results``)."""
    p = Path(path)
    if (p / "runs").is_dir():
        return p
    if (p / "results" / "runs").is_dir():
        return p / "results"
    raise FileNotFoundError(f"{path}: no runs/ folder (nor results/runs/)")


def load_rows(root: Path) -> list[dict]:
    """Every stored row of ``root`` (any code version), with ``_mtime`` its file's write time."""
    from studies.sweep.store import loads

    rows = []
    for f in sorted((root / "runs").glob("*.json")):
        try:
            row = loads(f.read_text())
        except (OSError, ValueError):
            continue
        if isinstance(row, dict):
            row["_mtime"] = f.stat().st_mtime
            rows.append(row)
    return rows


def _seconds(row: dict) -> float:
    v = row.get("elapsed_s")
    return float(v) if isinstance(v, (int, float)) else 0.0


def group(rows: list[dict], *fields: str) -> list[dict]:
    """Rows grouped by ``fields``: runs, computed, skipped, seconds and the seconds of expected
    non-answers per group, the costliest group first; ``share`` of all the seconds."""
    acc: dict = defaultdict(lambda: {"runs": 0, "computed": 0, "skipped": 0, "cpu_s": 0.0, "not_at_rest_s": 0.0,
                                     "not_at_rest": 0, "failed": 0})
    for r in rows:
        g = acc[tuple(str(r.get(f)) for f in fields)]
        g["runs"] += 1
        skipped = bool(r.get("skipped"))
        g["skipped"] += skipped
        g["computed"] += not skipped
        g["cpu_s"] += _seconds(r)
        if r.get("status") == NOT_AT_REST:
            g["not_at_rest"] += 1
            g["not_at_rest_s"] += _seconds(r)
        elif r.get("status") not in ("ok", None):
            g["failed"] += 1
    total = sum(g["cpu_s"] for g in acc.values()) or 1.0
    out = [{**dict(zip(fields, k)), **g, "share": g["cpu_s"] / total} for k, g in acc.items()]
    return sorted(out, key=lambda g: -g["cpu_s"])


def longest(rows: list[dict], n: int = 15) -> list[dict]:
    """The ``n`` runs of most seconds."""
    top = sorted(rows, key=_seconds, reverse=True)[:n]
    return [{"study": r.get("study"), "label": r.get("label"), "solver": r.get("solver"), "status": r.get("status"),
             "cpu_s": _seconds(r)} for r in top]


def timeline(root: Path, rows: list[dict]) -> list[dict]:
    """The tables and the computed results (``computed/<name>``, its last write) in the order
    written: seconds from the first stored run, and the seconds since the previous entry."""
    if not rows:
        return []
    t0 = min(r["_mtime"] for r in rows)
    events = [("runs (last stored)", max(r["_mtime"] for r in rows))]
    for csv in (root / "tables").glob("*.csv"):
        events.append((f"table {csv.stem}", csv.stat().st_mtime))
    comp = root / "computed"
    if comp.is_dir():
        for d in comp.iterdir():
            times = [f.stat().st_mtime for f in d.glob("*.json")]
            if times:
                events.append((f"computed {d.name}", max(times)))
    events.sort(key=lambda e: e[1])
    out, prev = [], t0
    for name, t in events:
        out.append({"what": name, "at_s": t - t0, "after_previous_s": t - prev})
        prev = t
    return out


def bound(rows: list[dict], workers: int = 2) -> dict:
    """The least wall time of the computed runs on ``workers`` workers: their seconds over the
    workers, and the longest run."""
    total = sum(_seconds(r) for r in rows)
    return {"cpu_s": total, "workers": workers, "per_worker_s": total / workers,
            "longest_s": max((_seconds(r) for r in rows), default=0.0)}


def _quick_run(out: Path, env: dict) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "studies", "run", "--all", "--quick", "--out", str(out), "--no-progress"],
                   env=env, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def compile_share() -> dict:
    """Wall time of the quick reproduction with empty kernel caches, then with the caches it
    filled (each into a fresh folder), the load average before each."""
    with tempfile.TemporaryDirectory(prefix="hybmss-compile-") as tmp:
        env = {**os.environ, "NUMBA_CACHE_DIR": f"{tmp}/numba", "HYBMSS_KERNEL_CACHE": f"{tmp}/kernels"}
        load_cold = os.getloadavg()[0]
        cold = _quick_run(Path(tmp) / "cold", env)
        load_warm = os.getloadavg()[0]
        warm = _quick_run(Path(tmp) / "warm", env)
    return {"cold_s": cold, "warm_s": warm, "compile_s": cold - warm, "compile_share": (cold - warm) / cold,
            "load_cold": load_cold, "load_warm": load_warm}


def profile(path, workers: int = 2, n_longest: int = 15) -> dict:
    """Everything the command prints, as one dict."""
    root = results_root(path)
    rows = load_rows(root)
    return {"root": str(root), "runs": len(rows), "bound": bound(rows, workers),
            "by_study": group(rows, "study"), "by_study_model": group(rows, "study", "model"),
            "by_kind": group(rows, "study", "solver_kind"), "longest": longest(rows, n_longest),
            "timeline": timeline(root, rows)}


def _table(records: list[dict], columns: list[str], limit: int | None = None) -> str:
    def fmt(v):
        if isinstance(v, float):
            return f"{v:.3f}" if abs(v) < 1 else f"{v:.1f}"
        return str(v)

    recs = records[:limit] if limit else records
    cells = [[fmt(r.get(c, "")) for c in columns] for r in recs]
    widths = [max([len(c)] + [len(row[i]) for row in cells]) for i, c in enumerate(columns)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(columns, widths))]
    lines += ["  ".join(v.ljust(w) for v, w in zip(row, widths)) for row in cells]
    return "\n".join(lines)


def format_profile(p: dict, limit: int = 30) -> str:
    b = p["bound"]
    cols = ["runs", "computed", "skipped", "failed", "not_at_rest", "cpu_s", "share", "not_at_rest_s"]
    parts = [f"{p['root']}: {p['runs']} runs, {b['cpu_s']:.1f} s of runs; on {b['workers']} workers at least "
             f"{b['per_worker_s']:.1f} s wall (longest run {b['longest_s']:.1f} s)",
             "\nper study", _table(p["by_study"], ["study"] + cols),
             "\nper study and model", _table(p["by_study_model"], ["study", "model"] + cols, limit),
             "\nper study and solver kind", _table(p["by_kind"], ["study", "solver_kind"] + cols, limit),
             "\nlongest runs", _table(p["longest"], ["cpu_s", "study", "label", "solver", "status"]),
             "\ntimeline (s from the first stored run)", _table(p["timeline"], ["at_s", "after_previous_s", "what"])]
    if "compile" in p:
        c = p["compile"]
        parts.append(f"\nquick reproduction: cold caches {c['cold_s']:.1f} s (load {c['load_cold']:.2f}), warm "
                     f"{c['warm_s']:.1f} s (load {c['load_warm']:.2f}): compiling {c['compile_s']:.1f} s, "
                     f"{100 * c['compile_share']:.0f} % of the cold run")
    return "\n".join(parts)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.profile_store", description=__doc__.splitlines()[0])
    parser.add_argument("dir", help="a results folder (or the folder holding results/)")
    parser.add_argument("--workers", type=int, default=2, help="workers of the pool for the bound (default 2)")
    parser.add_argument("--limit", type=int, default=30, help="rows of the per-model tables printed (default 30)")
    parser.add_argument("--compile", action="store_true", help="also time the quick reproduction cold and warm")
    parser.add_argument("--json", action="store_true", help="one strict-JSON object")
    args = parser.parse_args(argv)
    if args.workers < 1:
        print(f"--workers: {args.workers} is not allowed; allowed: an integer >= 1", file=sys.stderr)
        return 2
    try:
        p = profile(args.dir, args.workers)
    except FileNotFoundError as e:
        print(f"dir: {e}; allowed: a results folder of python -m studies run", file=sys.stderr)
        return 2
    if args.compile:
        p["compile"] = compile_share()
    if args.json:
        from studies.sweep.store import dumps

        print(dumps(p))
    else:
        print(format_profile(p, args.limit))
    return 0


if __name__ == "__main__":  # pragma: no cover
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        sys.exit(130)
