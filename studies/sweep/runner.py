"""The study runner: tasks (scene × solver) executed once, stored, resumable.

A :class:`Task` pairs a :class:`~studies.sweep.scenes.SceneSpec` with a :class:`SolverSpec`.
:func:`run_tasks` skips tasks whose key is already stored intact, computes the rest with an
executor (:class:`Runner`: the machine's cores or a Dask cluster, :mod:`studies.sweep.executors`) and a
progress bar, and stores each result atomically, in this process, as soon as it comes back.  A
failure (divergence, loss of equilibrium, an exception in a solver, a worker that died too often)
is stored as a row with ``status`` and ``message``: it is reported, never raised past the runner.
A damaged stored run is reported, moved aside and computed again; a run is claimed in the store
before it is computed, so two sweeps on one folder share the work.  The runs start longest
first; a pool on this machine starts none whose estimated memory, with the running runs', would
not fit (:func:`next_fitting`): it takes the next that does.
"""

from __future__ import annotations

import hashlib
import json
import math
import multiprocessing
import os
import signal
import sys
import threading
import time
import traceback
import warnings
from collections import deque
from dataclasses import asdict, dataclass, field

import numpy as np

from hybmss.scene import nearly_incompressible

from studies.sweep.scenes import SceneSpec
from studies.sweep.executors import EXECUTORS, Call, CallFailed, SweepError, WorkerDied, Workers, local_executor
from studies.sweep.rest_bound import skip_reason, skipped_row
from studies.sweep.outcomes import expected_not_at_rest, finding, non_finite, timing_run, warning_lines
from studies.sweep.solving import measure, solve_scene
from studies.sweep.store import CODE_FIELD, DamagedRun, Store, code_side, code_version, environment

SOLVER_KINDS = ("static", "explicit", "implicit", "fem")


@dataclass(frozen=True)
class SolverSpec:
    """How to solve a scene.  MSS: ``static`` (Newton), ``explicit`` (symplectic Euler,
    ``dt``, ``steps``, ``ramp_time``, ``kernel``), ``implicit`` (backward Euler to rest).
    ``until_rest``: an explicit run of a stepper whose rest state is the fixed point of its own step
    (xpbd-nh) ends there once it has come to rest (:func:`hybmss.explicit.simulate_explicit`).
    FEM: ``fem`` with ``element`` (hex1, hex2, mixed, auto), ``law`` (linear, neo-hookean, svk)
    and ``refine`` (cells split into refine³).  ``repeat`` > 0 numbers a repeat of the same run
    (its own stored run, for a timing's spread: :mod:`studies.sweep.cost`); 0, the run itself, leaves
    the key as it was.  ``timing``: an explicit run asked for its time per step alone (a candidate's
    short timed runs, :func:`studies.paper.pareto.repeat_pairs`); its state is no answer, so ending
    not at rest is what was asked: counted as a timing run, neither a result, nor a finding, nor a
    failure (:func:`studies.sweep.outcomes.timing_run`)."""

    kind: str = "static"
    element: str = "hex2"
    law: str = "linear"
    refine: int = 1
    dt: float = 1e-3
    steps: int = 10_000
    ramp_time: float = 1.0
    kernel: str = "numba"
    repeat: int = 0
    until_rest: bool = False
    timing: bool = False

    def __post_init__(self):
        if self.kind not in SOLVER_KINDS:
            raise ValueError(f"solver must be one of {', '.join(SOLVER_KINDS)}; got {self.kind!r}")
        if not self.dt > 0:
            raise ValueError(f"dt (time step) must be > 0 s, got {self.dt}")
        if self.steps < 1:
            raise ValueError(f"steps must be >= 1, got {self.steps}")
        if self.refine < 1:
            raise ValueError(f"refine must be an integer >= 1, got {self.refine}")
        if self.repeat < 0:
            raise ValueError(f"repeat must be an integer >= 0, got {self.repeat}")
        if self.timing and (self.kind != "explicit" or self.until_rest):
            raise ValueError("timing (a run asked for its time per step alone) applies to an explicit run "
                             "of a fixed number of steps, not until rest")

    def relevant(self) -> dict:
        if self.kind == "fem":
            out = {"kind": "fem", "element": self.element, "law": self.law, "refine": self.refine}
        elif self.kind == "static":
            out = {"kind": "static"}
        elif self.kind == "implicit":
            out = {"kind": "implicit", "dt": self.dt, "steps": self.steps, "ramp_time": self.ramp_time}
        else:
            out = {"kind": "explicit", "dt": self.dt, "steps": self.steps, "ramp_time": self.ramp_time,
                   "kernel": self.kernel}
            if self.until_rest:
                out["until_rest"] = True
            if self.timing:
                out["timing"] = True
        return {**out, "repeat": self.repeat} if self.repeat else out

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
    """A scene with its solver, for a study.  ``answer_only``: the run is of use only if it reaches a
    result (not its state or its time): the runner does not compute it when it cannot
    (:func:`studies.sweep.rest_bound.skip_reason`) and stores it as a run not at rest, with the reason."""

    scene: SceneSpec
    solver: SolverSpec
    study: str = ""
    answer_only: bool = False

    def key(self) -> str:
        own = getattr(self.scene, "digest", None)  # a scene holder without a Scene (studies.sweep.tet_runs)
        fields = {"scene": own() if own else self.scene.build().digest(), "solver": self.solver.relevant(),
                  "code": code_version(code_side(self.solver.kind))}
        extra = getattr(self.scene, "key_extra", None)
        if extra is not None:  # what else a scene holder changes in the answer (a study's reference)
            fields["extra"] = extra
        payload = json.dumps(fields, sort_keys=True)
        return hashlib.sha256(payload.encode()).hexdigest()[:24]


# --------------------------------------------------------------------------------- execution
def solve(task: Task):
    """Run one task; returns the :class:`hybmss.result.Result`.  A scene holder with a ``solve``
    of its own (a study's :class:`studies.study.tasks.StudyScene`: repeats, an adaptive
    reference) runs it; otherwise :func:`studies.sweep.solving.solve_scene`."""
    own = getattr(task.scene, "solve", None)
    if own is not None:
        return own(task.solver)
    return solve_scene(task.scene.build(), task.solver)


def base_row(task: Task, key: str | None = None) -> dict:
    """The fields of a run's row that describe it: the scene's under the specification's own
    names (:meth:`SceneSpec.to_dict`: the experiment's fields, the model's parameters, the variant
    name), listed in ``scene_fields``; the solver's (``solver_*``); the environment's (``env_*``)."""
    scene = task.scene.to_dict()
    return {
        "key": key or task.key(),
        "study": task.study,
        "solver": task.solver.label,
        **scene,
        "scene_fields": " ".join(scene),
        **{f"solver_{k}": v for k, v in task.solver.relevant().items()},
        "label": task.scene.label,
        CODE_FIELD: code_version(code_side(task.solver.kind)),
        **{f"env_{k}": v for k, v in environment().items()},
    }


def failure_row(exc: Exception) -> dict:
    """The fields of a failed run's row: its ``status`` by the exception's type ("diverged": an
    explicit run left the physical range, :class:`hybmss.explicit.DivergenceError`; "unstable": a
    Newton solve lost the equilibrium, :class:`hybmss.solve.StaticSolveError`; an exception's own
    ``row_status``, e.g. "not-representable": a scene an engine cannot represent; else "error"), its
    ``message`` (the type's name and the message on one line) and, for a solver error, its numbers
    (``failure_<name>`` for each field of :meth:`hybmss.solve.StaticSolveError.fields`, None where
    it does not apply: top-level scalars, so the store keeps a non-finite one)."""
    from hybmss.explicit import DivergenceError
    from hybmss.solve import StaticSolveError

    row = {"status": getattr(exc, "row_status", None) or ("diverged" if isinstance(exc, DivergenceError) else (
               "unstable" if isinstance(exc, StaticSolveError) else "error")),
           "message": f"{type(exc).__name__}: {' '.join(str(exc).split())}"}
    if isinstance(exc, StaticSolveError):
        row.update({f"failure_{k}": v for k, v in exc.fields().items()})
    return row


def no_result_because(row: dict | None) -> str:
    """Why a stored row is no result, on one line; ``""`` for a result (``status`` ok: a static
    solve that converged, an explicit run at rest by :func:`hybmss.explicit.rest_report`).  A run
    not at rest ("not-converged") without a message of its own reads "not at rest after n steps"
    (a static solve: "not converged"); a failed run, its status and message."""
    if row is None:
        return "missing: not computed"
    status = str(row.get("status") or "missing")
    if status == "ok":
        return ""
    msg = row.get("message")
    msg = "" if msg is None or (isinstance(msg, float) and np.isnan(msg)) else " ".join(str(msg).split())
    if status == "not-converged" and not msg:
        steps = row.get("steps", row.get("solver_steps"))
        explicit = str(row.get("solver", "")).endswith("explicit")
        if explicit:
            msg = (f"not at rest after {int(steps)} steps" if steps is not None and np.isfinite(float(steps))
                   else "not at rest")
        else:
            msg = "not converged"
    return f"{status}: {msg}" if msg else status


OUT_OF_MEMORY = "out-of-memory"
"""Status of a run that ran out of this machine's memory: counted as a failure, never stored (a
stored row is the code's answer to its scene; memory is the machine's, and the next run retries)."""


def compute(task: Task, key: str | None = None) -> tuple[dict, dict | None]:
    """Execute ``task``; return its row and arrays (a worker's part: nothing is written here,
    the process that runs the sweep stores them)."""
    row = base_row(task, key)
    t0 = time.perf_counter()
    arrays = None
    with warnings.catch_warnings(record=True) as caught:  # kept in the row, never printed by a worker
        warnings.simplefilter("always")
        row, arrays = _compute(task, row)
    if caught:
        row["warnings"] = warning_lines(caught)
    row["elapsed_s"] = time.perf_counter() - t0
    return row, arrays


def _compute(task: Task, row: dict) -> tuple[dict, dict | None]:
    arrays = None
    try:
        res = solve(task)
        row.update(measure(task.scene, res))
        row["status"] = "ok" if res.converged else "not-converged"
        row["message"] = str(res.info.get("warning", "") or "")
        bad = non_finite(res)
        if bad:
            row.update(status="non-finite", message=f"non-finite result: {bad}; the scene's numbers (E, loads, "
                       "sizes) are out of the range double precision resolves: rescale the units or the load")
        from hybmss.lattice import Lattice

        own = getattr(task.scene, "arrays", None)
        arrays = own(res) if own else {"X": res.X, "u": res.u, "cells": Lattice.from_body(task.scene.build().body).cells}
        arrays.update(res.info.pop("arrays", None) or {})  # a solver's own arrays (a released run's samples)
        if res.cell_volumes is not None:
            arrays["cell_volumes"] = res.cell_volumes
        row["info"] = {k: v for k, v in res.info.items() if isinstance(v, (int, float, str, bool))}
    except MemoryError:  # the machine's limit, not the scene's answer: reported, never stored
        row.update(status=OUT_OF_MEMORY, message="MemoryError: this machine's memory ran out during the run; "
                   "it is not stored, so a rerun computes it again (with fewer --jobs, or a coarser mesh)")
        arrays = None
    except Exception as exc:  # noqa: BLE001 - every failure becomes a stored, reported row
        row.update(failure_row(exc))
        row["traceback"] = traceback.format_exc(limit=4)
    return row, arrays


def _expected_cost(task: Task) -> float:
    """A rough relative cost, only to order the runs (longest first): finite-strain FEM on large
    meshes, the other runs by their model's estimate (:func:`studies.sweep.roles.run_cost`)."""
    s = task.solver
    if hasattr(task.scene, "expected_cost"):
        return task.scene.expected_cost(s)
    cells = float(np.prod(task.scene.mesh))
    if s.kind == "fem":
        per = {"linear": 3.0, "neo-hookean": 20.0, "svk": 20.0}.get(s.law, 10.0) * s.refine**3
        if nearly_incompressible(task.scene.nu):
            per *= 3.0  # mixed u-p
        return cells * per
    from studies.sweep import roles

    try:
        per = roles.run_cost(task.scene, s.kind)
    except (KeyError, ValueError, AttributeError):
        per = 1.0
    if s.kind == "explicit":
        per *= (getattr(s, "steps", None) or 10_000) / 10_000
    return cells * per  # the FEM's units (8×8×48 beam: about 3,800 per second)


def _code_of(task: Task) -> tuple:
    """What a run compiles on its first call in a worker process: its model, whatever the solver
    (a model's solvers share its kernels: xpbd-nh's static answer relaxes the very substep its
    explicit run takes), or the FEM's element and law; ``None`` for a task without a solver (a
    stand-in)."""
    s = getattr(task, "solver", None)
    if s is None:
        return None
    if s.kind == "fem":
        return ("fem", s.element, s.law)
    return (str(getattr(task.scene, "model", "")),)


def run_order(todo: list[tuple[str, Task]]) -> list[tuple[str, Task]]:
    """The order runs are handed to the workers: the longest run of each model (:func:`_code_of`)
    first, longest first, then every other run longest first (a short tail).  On a cold cache a
    model's first run compiles its kernels (xpbd-nh's: 34 s on one core); the two longest runs of
    one model handed to two workers at once compiled them twice at the same time (the quick
    reproduction's two xpbd-nh stability runs: 38.8 s each, both workers, at its start; then its
    explicit stability run and its static compression run, 56.7 and 55.6 s, while they were
    ordered per model and solver), where the second worker now compiles another model's and
    later loads the first's from the cache."""
    ordered = sorted(todo, key=lambda kt: _expected_cost(kt[1]), reverse=True)
    seen, first, rest = set(), [], []
    for kt in ordered:
        code = _code_of(kt[1])
        (rest if code in seen else first).append(kt)
        seen.add(code)
    return first + rest


def expected_bytes(task: Task) -> float:
    """Estimated peak memory of a run (:mod:`studies.sweep.sizing`; a scene holder's own
    ``expected_bytes``, e.g. a study's adaptive reference at its finest level); 0 where there is no
    estimate."""
    from studies.sweep import sizing

    own = getattr(task.scene, "expected_bytes", None)
    try:
        return float(own(task.solver)) if own is not None else float(sizing.task(task.scene, task.solver).bytes)
    except (AttributeError, KeyError, TypeError, ValueError):
        return 0.0


def memory_budget() -> float:
    """The memory the runs of a local pool may plan together (:func:`studies.sweep.sizing.limit`)."""
    from studies.sweep import sizing

    return sizing.limit()


def next_fitting(pending: deque, running: list[float], needs: dict, budget: float, warming=frozenset()):
    """Remove and return the first ``(key, task)`` of ``pending`` whose expected memory
    (``needs``) fits ``budget`` beside the ``running`` runs' (any run when none is running: the
    solvers' own memory plan, :mod:`fem_reference.memory`, then rules); ``None`` if none fits.
    Two references of 10 GB on a 24 GB machine: the second waits for the first while the other
    worker computes the runs after it, instead of idling its core in the memory plan's wait.

    A run whose code (:func:`_code_of`) is in ``warming`` (a first run of it is still running, and
    compiling on a cold cache) is taken only when no other run fits: started beside it, it would
    compile the same kernels a second time (the quick reproduction's two xpbd-nh stability runs,
    handed out a few seconds apart on a cold cache, took 59.6 and 52.4 s, each compiling)."""
    used = sum(running)
    for skip in (True, False) if warming else (False,):
        for i, (k, t) in enumerate(pending):
            if skip and _code_of(t) in warming:
                continue
            if not running or used + needs.get(k, 0.0) <= budget:
                del pending[i]
                return k, t
    return None


@dataclass
class Summary:
    """What a sweep did: runs asked for, computed here, found stored, computed meanwhile by
    another process, damaged runs moved aside; and over every run asked for (computed or stored),
    ``failed``: the runs without result that were not expected, and ``expected``: the runs without
    result that were (a run not at rest within its step budget; in the publication's studies, any of
    their findings, :func:`studies.sweep.outcomes.finding`), counted by ``"study, reason"`` in
    ``expected_by``; ``timed``: the timing runs not at rest, as asked
    (:func:`studies.sweep.outcomes.timing_run`), counted in neither."""

    runs: int = 0
    computed: int = 0
    stored: int = 0
    by_other: int = 0
    failed: int = 0
    expected: int = 0
    timed: int = 0
    skipped: int = 0
    orphans: int = 0
    failed_stored: int = 0
    damaged: list[str] = field(default_factory=list)
    expected_by: dict[str, int] = field(default_factory=dict)

    def add(self, other: "Summary") -> None:
        for k in ("runs", "computed", "stored", "by_other", "failed", "expected", "timed", "skipped", "orphans",
                  "failed_stored"):
            setattr(self, k, getattr(self, k) + getattr(other, k))
        self.damaged += other.damaged
        for k, n in other.expected_by.items():
            self.expected_by[k] = self.expected_by.get(k, 0) + n

    def count(self, task, row: dict | None, expected, computed: bool = True) -> None:
        """Count one run asked for by its stored ``row``: a result, an expected non-answer
        (``expected(task, row)``) or a failure (``computed``: by this sweep, else found stored)."""
        if no_result_because(row) == "":
            return
        if timing_run(row):
            self.timed += 1
        elif expected(task, row):
            self.expected += 1
            why = finding(row) or no_result_because(row).split(":")[0]
            where = f"{task.study}, {why}" if task.study else why
            self.expected_by[where] = self.expected_by.get(where, 0) + 1
        else:
            self.failed += 1
            self.failed_stored += not computed

    def as_dict(self) -> dict:
        return asdict(self)

    def line(self) -> str:
        out = (f"{self.runs} runs: {self.computed} computed, {self.stored} already stored"
               f"{f', {self.by_other} computed by another process' if self.by_other else ''}, "
               f"{self.failed} failed")
        if self.failed_stored:
            out += (f" ({self.failed_stored} of them stored by an earlier run and not computed again: a stored "
                    "failure is this code's answer to its scene; a changed scene or code computes it anew)")
        if self.expected:
            parts = "; ".join(f"{k}: {n}" for k, n in sorted(self.expected_by.items()))
            out += f", {self.expected} without result as expected ({parts})"
        if self.timed:
            out += (f", {self.timed} timing runs (short explicit runs timing a candidate's steps, not at rest "
                    "as asked: neither results nor failures)")
        if self.skipped:
            out += f", {self.skipped} of them not run (their step budget is below the steps to rest)"
        if self.damaged:
            out += f", {len(self.damaged)} damaged (moved to damaged/ and computed again)"
        return out


class Interrupted(KeyboardInterrupt):
    """A sweep stopped by SIGINT: finished runs are stored, running ones were abandoned."""

    def __init__(self, summary: Summary):
        super().__init__(f"{summary.computed} runs computed and stored before the "
                         "interrupt, running ones abandoned; rerun to resume")
        self.summary = summary


def exit_now(signum, frame):  # a second Ctrl-C while the first is being handled
    os.write(2, b"interrupted again: exiting now\n")
    for p in multiprocessing.active_children():
        p.kill()
    os._exit(130)


class Runner:
    """How the runs of a sweep are computed: ``executor`` ``"local"`` (a process pool of ``jobs``
    workers, all cores by default; ``jobs = 1`` runs in this process) or ``"dask"`` (the
    ``dask.distributed`` scheduler at ``scheduler``, or a ``LocalCluster`` of ``jobs``
    single-threaded workers).  Whatever computes, this process stores every result.

    Arguments are checked here, before any work (``ValueError`` naming the parameter, its value
    and what is allowed).  Use it as a context manager to keep one Dask cluster, or one set of
    local worker processes (:meth:`local_workers`), for several sweeps and the maps of the
    studies' own work (:func:`studies.sweep.executors.map_stored`); :attr:`summary` adds up what
    every sweep did."""

    def __init__(self, executor: str = "local", jobs: int | None = None, scheduler: str | None = None,
                 progress: bool = True):
        if executor not in EXECUTORS:
            raise ValueError(f"executor {executor!r} is not allowed; one of {', '.join(EXECUTORS)}")
        if jobs is not None and (isinstance(jobs, bool) or not isinstance(jobs, (int, np.integer))
                                 or jobs < 1):
            raise ValueError(f"jobs {jobs!r} is not allowed: an integer >= 1 (parallel runs), or "
                             "none for all cores")
        if scheduler is not None and executor != "dask":
            raise ValueError(f"scheduler {scheduler!r} is given with executor {executor!r}; a "
                             "scheduler address needs executor dask")
        if scheduler is not None and not str(scheduler).strip():
            raise ValueError("scheduler '' is not allowed: the address of a running dask scheduler, "
                             "e.g. tcp://host:8786")
        if executor == "dask":
            try:
                import distributed  # noqa: F401 - optional dependency, checked before any work
            except ImportError:
                raise ValueError("executor 'dask' needs dask.distributed, which is not installed: "
                                 "pip install 'hybmss[dask]'") from None
        self.executor, self.jobs, self.scheduler, self.progress = executor, jobs, scheduler, progress
        self.summary = Summary()
        self._seen: set[str] = set()  # keys of earlier sweeps of this runner: counted once in the summary
        self._dask = None
        self._session = False
        self._workers: Workers | None = None

    # -------------------------------------------------------------- session
    def __enter__(self):
        self._session = True
        if self.executor == "dask" and self._dask is None:
            from studies.sweep.dask_cluster import DaskCluster  # optional dependency, imported when asked for

            self._dask = DaskCluster(compute, self.jobs, self.scheduler)
            if self._dask.dashboard:
                self._write(f"dask dashboard: {self._dask.dashboard}")
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self) -> None:
        if self._dask is not None:
            self._dask.close()
            self._dask = None
        if self._workers is not None:
            self._workers.close()
            self._workers = None
        self._session = False

    def local_workers(self) -> Workers | None:
        """The local worker processes of this session (``with runner:``), started at first use and
        ended with it; None outside a session, with one job or with the Dask executor.  A later
        sweep thus finds loaded in its workers what the earlier ones compiled and imported, and the
        maps of a study's own work (moduli, bisections) start no processes of their own."""
        if self.executor != "local" or not self._session:
            return None
        n = self.jobs or os.cpu_count() or 1
        if n <= 1:
            return None
        if self._workers is None:
            self._workers = Workers(n)
        return self._workers

    def _write(self, msg: str) -> None:
        from tqdm import tqdm

        tqdm.write(msg, file=sys.stderr)

    # -------------------------------------------------------------- one sweep
    def run(self, tasks: list[Task], store: Store, desc: str = "runs", expected=expected_not_at_rest,
            calls=()) -> list[dict]:
        """Compute the tasks not yet stored (or stored damaged); return every task's row, in
        task order; every run asked for the first time is counted in :attr:`summary` as a
        result, an expected non-answer (``expected(task, row)``) or a failure.  SIGINT stops at
        once: runs finished are kept, running ones abandoned, the workers shut down
        (:class:`Interrupted`); a second SIGINT exits immediately.

        ``calls`` (:class:`studies.sweep.executors.Call`, or a function of no argument returning
        them, called when they are first needed): computations of the studies outside runs that
        do not depend on them, done on a local pool's workers once no run is left to hand out, so
        that they fill the cores the sweep's last runs leave idle; each result is kept where
        :func:`studies.sweep.executors.map_stored` finds it, those already stored are not done
        again.  In this process (one job) and on Dask they are left to the studies' maps.  A call
        that raises keeps nothing (the map computes it again and reports the error)."""
        from tqdm import tqdm

        store.check_writable()
        keys = [t.key() for t in tasks]
        unique, new, s, todo = self._plan(tasks, keys, store)
        lazy = None
        if calls and self.executor == "local":
            def lazy():
                return pending_calls(calls() if callable(calls) else calls, store)
        bar = tqdm(total=len(unique), initial=s.stored, desc=desc, disable=not self.progress, unit="run",
                   dynamic_ncols=True, file=sys.stderr)
        own = self._dask is None and self.executor == "dask" and bool(todo)
        if own:
            self.__enter__()
        ex = None
        claims: dict = {}
        unstored: dict = {}
        try:
            if todo or lazy is not None:
                n = len(todo) if lazy is None else max(len(todo), self.jobs or os.cpu_count() or 1)
                ex = self._dask if self.executor == "dask" else local_executor(compute, self.jobs, n,
                                                                                      self.local_workers())
                self._sweep(ex, todo, store, s, bar, claims, unstored, lazy if hasattr(ex, "submit_call") else None)
        except KeyboardInterrupt:
            self._interrupted(ex, claims, store, bar, s)
        except BaseException:
            for c in claims.values():
                c.release()
            if ex is not None and ex is not self._dask:
                ex.abandon()
            if own:
                self.close()
            bar.close()
            self.summary.add(s)
            raise
        if ex is not None and ex is not self._dask:
            ex.close()
        if own:
            self.close()
        bar.close()
        rows = {k: unstored[k] if k in unstored else store.row(k) for k in unique}
        computed = {k for k, _ in todo}
        for k in new:
            s.count(unique[k], rows[k], expected, computed=k in computed)
        self.summary.add(s)
        return [rows[k] for k in keys]

    def _plan(self, tasks: list[Task], keys: list[str], store: Store):
        """The sweep's distinct runs by key (two studies may share a run), the keys new to this
        runner, the sweep's :class:`Summary` so far (runs found stored, runs skipped: they cannot
        answer, :func:`studies.sweep.rest_bound.skip_reason`, and are stored as not at rest) and the
        runs to compute in :func:`run_order` (each model's longest first, then longest first)."""
        unique: dict[str, Task] = {}
        state: set[str] = set()  # runs some task needs whether or not they answer: never skipped
        for t, k in zip(tasks, keys):
            unique.setdefault(k, t)
            if not t.answer_only:
                state.add(k)
        new = set(unique) - self._seen
        s = Summary(runs=len(new), orphans=len(store.remove_orphans()))
        todo = []
        for k, t in unique.items():
            if store.has(k):
                s.stored += k not in self._seen
            elif k not in state and (why := skip_reason(t)):
                store.save(k, skipped_row(t, base_row(t, k), why))
                s.skipped += 1
            else:
                todo.append((k, t))
        self._seen.update(unique)
        return unique, new, s, run_order(todo)

    def _interrupted(self, ex, claims: dict, store: Store, bar, s: Summary) -> None:
        """SIGINT during a sweep: the running runs abandoned, their claims released, the sweep's
        counts added to :attr:`summary`; raises :class:`Interrupted` (a second SIGINT meanwhile
        exits at once)."""
        main = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGINT, exit_now) if main else None
        try:
            if ex is not None:
                ex.abandon()
                if ex is self._dask:
                    self._dask = None
        finally:
            for c in claims.values():
                c.release()
            if ex is not None and self.executor != "dask":
                # a worker killed while writing leaves its temporary file: the workers are
                # dead and their claims released, so it is an orphan now, not at the next run
                store.remove_orphans()
            bar.close()
            self.summary.add(s)
            if main:
                signal.signal(signal.SIGINT, previous)
        raise Interrupted(self.summary) from None

    def _sweep(self, ex, todo: list[tuple[str, Task]], store: Store, s: Summary, bar, claims: dict,
               unstored: dict, calls=None) -> None:
        """Hand out the runs ``todo`` (and, once none is left, the studies' ``calls``: a function
        returning them, :meth:`run`), store each result as it comes back."""
        pending = deque(todo)
        queued, running_calls = deque(), 0
        by_key = dict(todo)
        waiting: list[tuple[str, Task]] = []
        own_version = code_version()
        # a pool on this machine starts no run whose memory, with the running runs', would not fit
        # (it takes the next that does); a cluster's workers have their own memory
        budget = memory_budget() if getattr(ex, "shares_memory", False) else math.inf
        needs = {k: expected_bytes(t) for k, t in todo} if budget < math.inf else {}
        seen, warming = set(), {}  # codes run before; code -> key of its first run, still running
        while pending or claims or waiting or queued or running_calls or calls is not None:
            while pending and len(claims) + running_calls < ex.capacity():
                nxt = next_fitting(pending, [needs.get(c, 0.0) for c in claims], needs, budget,
                                   frozenset(warming))
                if nxt is None:
                    break
                k, t = nxt
                claim = store.claim(k)
                if claim is None:  # another process is computing it
                    waiting.append((k, t))
                    continue
                try:
                    done = store.check(k) is not None
                except DamagedRun as d:
                    where = store.quarantine(d)
                    s.damaged.append(str(d))
                    self._write(f"damaged run {d.path.name}: {d.reason}; moved to {where} and "
                                "computed again")
                    done = False
                if done:  # stored meanwhile by another process
                    claim.release()
                    s.by_other += 1
                    bar.update(1)
                    continue
                claims[k] = claim
                code = _code_of(t)
                if code is not None and code not in seen:
                    seen.add(code)
                    warming[code] = k
                ex.submit(k, t)
            if not pending and calls is not None:  # no run left to hand out: the studies' own computations
                queued, calls = deque(calls()), None
            while not pending and queued and len(claims) + running_calls < ex.capacity():
                ex.submit_call(queued.popleft())
                running_calls += 1
            if claims or running_calls:
                k, outcome = ex.wait_one()
                if isinstance(k, Call):
                    running_calls -= 1
                    if k.name is not None and not isinstance(outcome, CallFailed):
                        store.save_computed(k.name, store.computed_key(k.name, k.item), outcome)
                    continue
                warming = {c: w for c, w in warming.items() if w != k}
                if isinstance(outcome, WorkerDied):
                    row, arrays = base_row(by_key[k], k), None
                    row.update(status="error", message=outcome.message)
                else:
                    row, arrays = outcome
                    if row.get("env_code_version") != own_version:
                        raise SweepError(
                            f"a worker computed run {k} with hybmss code version "
                            f"{row.get('env_code_version')}, this process has {own_version}: install "
                            "the same hybmss on every worker (README)")
                if row.get("status") == OUT_OF_MEMORY:
                    stored = unstored[k] = row
                else:
                    stored = store.save(k, row, arrays)
                claims.pop(k).release()
                s.computed += 1
                bar.set_postfix_str(str(stored.get("label", ""))[:40], refresh=False)
                bar.update(1)
            elif waiting:
                holders = sorted({store.holder(k) for k, _ in waiting} - {""})
                bar.set_postfix_str(f"waiting for {len(waiting)} runs claimed by "
                                    f"{', '.join(holders) or 'another process'}"[:60], refresh=True)
                time.sleep(0.5)
                pending.extend(waiting)
                waiting.clear()


def pending_calls(calls, store: Store) -> list[Call]:
    """The ``calls`` whose results ``store`` does not hold (each once; a damaged stored result is
    left to the study's map, which moves it aside and computes it again)."""
    out, seen = [], set()
    for c in calls:
        if c.name is not None:
            key = (c.name, store.computed_key(c.name, c.item))
            if key in seen:
                continue
            seen.add(key)
            try:
                if store.load_computed(*key)[0]:
                    continue
            except DamagedRun:
                continue
        out.append(c)
    return out


def run_tasks(tasks: list[Task], store: Store, jobs: int | None = None, progress: bool = True,
              desc: str = "runs", runner: Runner | None = None, expected=expected_not_at_rest,
              calls=()) -> list[dict]:
    """Run the tasks not yet stored; return the rows of all tasks (in task order).  ``runner``
    (a :class:`Runner`) chooses the executor; without one, the local process pool of ``jobs``
    workers.  ``calls``: as :meth:`Runner.run`'s."""
    if runner is None:
        runner = Runner(jobs=jobs, progress=progress)
    return runner.run(tasks, store, desc=desc, expected=expected, calls=calls)
