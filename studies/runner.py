"""The study runner: tasks (scene × solver) executed once, stored, resumable.

A :class:`Task` pairs a :class:`~studies.scenes.SceneSpec` with a :class:`SolverSpec`.
:func:`run_tasks` skips tasks whose key is already stored, runs the rest over the machine's
cores with a progress bar, and stores each result atomically as soon as it finishes.  A failure
(divergence, loss of equilibrium, an exception in a solver) is stored as a row with
``status`` and ``message``: it is reported, never raised past the runner.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass

import numpy as np

from .scenes import BEAM_LENGTH, SceneSpec
from .store import Store, code_version, environment

SOLVER_KINDS = ("static", "explicit", "implicit", "fem")


@dataclass(frozen=True)
class SolverSpec:
    """How to solve a scene.  MSS: ``static`` (Newton), ``explicit`` (symplectic Euler,
    ``dt``, ``steps``, ``ramp_time``, ``kernel``), ``implicit`` (backward Euler to rest).
    FEM: ``fem`` with ``element`` (hex1, hex2, mixed, auto), ``law`` (linear, neo-hookean, svk)
    and ``refine`` (cells split into refine³)."""

    kind: str = "static"
    element: str = "hex2"
    law: str = "linear"
    refine: int = 1
    dt: float = 1e-3
    steps: int = 10_000
    ramp_time: float = 1.0
    kernel: str = "numba"

    def __post_init__(self):
        if self.kind not in SOLVER_KINDS:
            raise ValueError(f"solver must be one of {', '.join(SOLVER_KINDS)}; got {self.kind!r}")
        if not self.dt > 0:
            raise ValueError(f"dt (time step) must be > 0 s, got {self.dt}")
        if self.steps < 1:
            raise ValueError(f"steps must be >= 1, got {self.steps}")
        if self.refine < 1:
            raise ValueError(f"refine must be an integer >= 1, got {self.refine}")

    def relevant(self) -> dict:
        if self.kind == "fem":
            return {"kind": "fem", "element": self.element, "law": self.law, "refine": self.refine}
        if self.kind == "static":
            return {"kind": "static"}
        if self.kind == "implicit":
            return {"kind": "implicit", "dt": self.dt, "steps": self.steps, "ramp_time": self.ramp_time}
        return {"kind": "explicit", "dt": self.dt, "steps": self.steps, "ramp_time": self.ramp_time,
                "kernel": self.kernel}

    @property
    def label(self) -> str:
        if self.kind == "fem":
            r = f" r{self.refine}" if self.refine != 1 else ""
            return f"fem-{self.element}-{self.law}{r}"
        if self.kind == "static":
            return "mss-static"
        return f"mss-{self.kind}"


@dataclass(frozen=True)
class Task:
    scene: SceneSpec
    solver: SolverSpec
    study: str = ""

    def key(self) -> str:
        payload = json.dumps({"scene": self.scene.build().digest(), "solver": self.solver.relevant(),
                              "code": code_version("fem" if self.solver.kind == "fem" else "mss")},
                             sort_keys=True)
        return hashlib.sha256(payload.encode()).hexdigest()[:24]


# --------------------------------------------------------------------------------- execution
def solve(task: Task):
    """Run one task; returns the :class:`hybmss.result.Result`."""
    scene = task.scene.build()
    s = task.solver
    if s.kind == "static":
        from hybmss.solvers import solve_static

        return solve_static(scene)
    if s.kind == "implicit":
        from hybmss.solvers import ImplicitOptions, simulate_implicit

        return simulate_implicit(scene, ImplicitOptions(dt=s.dt, steps=s.steps, ramp_time=s.ramp_time))
    if s.kind == "explicit":
        from hybmss.explicit import simulate_explicit

        return simulate_explicit(scene, dt=s.dt, steps=s.steps, kernel=s.kernel, ramp_time=s.ramp_time)
    from fem_reference.solve import solve as fem_solve

    return fem_solve(scene, element=s.element, law=s.law, refine=s.refine)


def measure(spec: SceneSpec, result) -> dict:
    """Scalar outputs of one result (SPEC §8): volume change, plate reaction, tip deflection."""
    row = {
        "volume_change": float(result.volume_change),
        "max_displacement": float(result.max_displacement),
        "converged": bool(result.converged),
        "iterations": int(result.iterations),
        "wall_time_s": float(result.wall_time_s),
    }
    plate = "bottom" if spec.experiment == "bending" else "top"
    if plate in result.reactions:
        r = result.reactions[plate]
        row.update({f"force_{c}": float(v) for c, v in zip("xyz", r.force)})
        row.update({f"torque_{c}": float(v) for c, v in zip("xyz", r.torque)})
    if spec.experiment == "bending":
        row["tip_deflection"] = tip_deflection(result.X, result.u)
        row["euler_bernoulli_tip"] = spec.euler_bernoulli_tip()
    for k in ("inverted_cells", "kappa", "dt_crit", "load_steps", "volume_avg_edges", "volume_lnJ",
              "newton_iterations", "steps", "stable", "saddle_escapes", "min_eigenvalue"):
        if k in result.info:
            v = result.info[k]
            row[k] = v if isinstance(v, bool) else (
                float(v) if isinstance(v, (int, float, np.floating, np.integer)) else v)
    return row


def centre_line(X: np.ndarray) -> np.ndarray:
    """Indices of the particles on the beam's centre line (x = w/2, y = h/2), sorted by z; for an
    odd number of cells across, the two nearest lines are averaged by the caller."""
    cx, cy = (X[:, 0].min() + X[:, 0].max()) / 2, (X[:, 1].min() + X[:, 1].max()) / 2
    d = np.hypot(X[:, 0] - cx, X[:, 1] - cy)
    sel = np.flatnonzero(d <= d.min() + 1e-9)
    return sel[np.argsort(X[sel, 2], kind="stable")]


def neutral_axis(X: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(z, mean vertical displacement u_y) along the beam's centre line."""
    sel = centre_line(X)
    z = np.round(X[sel, 2], 12)
    zs = np.unique(z)
    uy = np.array([u[sel][z == v, 1].mean() for v in zs])
    return zs, uy


def tip_deflection(X: np.ndarray, u: np.ndarray) -> float:
    """Signed vertical displacement of the free end's centre (m)."""
    z, uy = neutral_axis(X, u)
    return float(uy[np.argmax(z)])


def run_task(task: Task, store_root: str) -> dict:
    """Execute ``task`` and store its row and arrays (worker entry point)."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    store = Store(store_root)
    key = task.key()
    row = {
        "key": key,
        "study": task.study,
        "solver": task.solver.label,
        **{f"scene_{k}": v for k, v in task.scene.to_dict().items()},
        **{f"solver_{k}": v for k, v in task.solver.relevant().items()},
        "label": task.scene.label,
        **{f"env_{k}": v for k, v in environment().items()},
    }
    t0 = time.perf_counter()
    arrays = None
    try:
        res = solve(task)
        row.update(measure(task.scene, res))
        row["status"] = "ok" if res.converged else "not-converged"
        row["message"] = str(res.info.get("warning", "") or "")
        from hybmss.lattice import Lattice

        arrays = {"X": res.X, "u": res.u, "cells": Lattice.from_body(task.scene.build().body).cells}
        if res.cell_volumes is not None:
            arrays["cell_volumes"] = res.cell_volumes
        row["info"] = {k: v for k, v in res.info.items() if isinstance(v, (int, float, str, bool))}
    except Exception as exc:  # noqa: BLE001 - every failure becomes a stored, reported row
        name = type(exc).__name__
        row["status"] = "diverged" if "Divergence" in name else (
            "unstable" if name == "StaticSolveError" else "error")
        row["message"] = f"{name}: {' '.join(str(exc).split())}"
        row["traceback"] = traceback.format_exc(limit=4)
    row["elapsed_s"] = time.perf_counter() - t0
    store.save(key, row, arrays)
    return row


def _expected_cost(task: Task) -> float:
    """A rough relative cost, only to order the runs (finite-strain FEM on large meshes first)."""
    cells = float(np.prod(task.scene.mesh))
    s = task.solver
    if s.kind == "fem":
        per = {"linear": 3.0, "neo-hookean": 20.0, "svk": 20.0}.get(s.law, 10.0) * s.refine**3
        if task.scene.nu >= 0.45:
            per *= 3.0  # mixed u-p
        return cells * per
    if s.kind == "explicit":
        return cells * 0.5
    return cells * (2.0 if task.scene.nu < 0.25 else 1.0)


def run_tasks(tasks: list[Task], store: Store, jobs: int | None = None, progress: bool = True,
              desc: str = "runs") -> list[dict]:
    """Run the tasks not yet stored; return the rows of all tasks (in task order)."""
    from tqdm import tqdm

    keys = [t.key() for t in tasks]
    todo = [(t, k) for t, k in zip(tasks, keys) if not store.has(k)]
    # unique keys only (two studies may share a run)
    seen, unique = set(), []
    for t, k in todo:
        if k not in seen:
            seen.add(k)
            unique.append(t)
    unique.sort(key=_expected_cost, reverse=True)  # longest first: the pool's tail stays short
    jobs = max(1, min(jobs or os.cpu_count() or 1, len(unique) or 1))
    bar = tqdm(total=len(tasks), initial=len(tasks) - len(unique), desc=desc, disable=not progress,
               unit="run", dynamic_ncols=True)
    if jobs == 1:
        for t in unique:
            bar.set_postfix_str(t.scene.label[:40], refresh=False)
            run_task(t, str(store.root))
            bar.update(1)
    else:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            futures = {pool.submit(run_task, t, str(store.root)): t for t in unique}
            for fut in as_completed(futures):
                fut.result()
                bar.update(1)
    bar.close()
    return [store.row(k) for k in keys]


def task_dict(task: Task) -> dict:
    return {"study": task.study, "scene": asdict(task.scene), "solver": asdict(task.solver)}
