"""The runs of a study: one per load case × material × resolution × model, and ONE FEM
reference per load case × material × resolution (every model at that resolution is compared with
it), as :class:`studies.sweep.runner.Task` s holding a :class:`StudyScene`.

A :class:`StudyScene` is a built :class:`hybmss.scene.Scene` with the fields of a row (study,
load case, cell size, model label, material), a ``build()`` like the experiments'
:class:`~studies.sweep.scenes.SceneSpec` and its own ``solve``: a model run is timed ``repeats`` times
(best and spread kept), a reference with ``refine = "auto"`` refines until its own error estimate
is below its target.  Both add the reactions of every support to the result's ``info``."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

from hybmss import models
from hybmss.scene import Material, Model, Scene

from studies.sweep.runner import SolverSpec, Task, solve_scene

TIMING_BUDGET_S = 10.0
"""A re-timing's repeats (:func:`_timed`) stop once together they took this long (at least one):
the ``repeats`` of a study are for runs short enough to be disturbed by the machine; a run of a
minute is timed once (its spread unknown) instead of costing ``repeats`` minutes more."""

ONE_TIME_SHARE = 0.01
"""A first run of at least :data:`TIMING_BUDGET_S` is its own (single) timing when the one-time
cost it reports (``info['compile_time_s']`` + ``info['warm_up_s']``: an engine's kernel or model
compilation, the explicit loop's warm-up call) is below this share of it: a second run would
only repeat the measurement (measured on the cylinder study: the engines' first runs of 10–120 s
within −5 … +7 % of the second runs of an earlier study run, the run-to-run spread of the two)."""

RETIME_NOISE = 0.5
"""The noise of a lead between two single timings (:func:`_single`): a budget answer whose winner
leads its runner-up by less than ``1 + RETIME_NOISE`` on single timings has both re-timed with the
study's ``repeats`` (:func:`near_ties`); a lead beyond it is no tie.  Measured on the cylinder
study (``studies/examples/cylinder-squeeze-twist.toml``, 2 busy cores): the 82 model runs under
10 s (9 ms to 9 s) timed again, 3 repeats after an untimed run in fresh workers; the log of the
single timing over the repeats' best had a median of −0.003, a 95th percentile of 0.036, and
lay within −0.21 … +0.13 (the extremes: runs of 9 and 12 ms).  Two single timings at opposite
extremes make a lead off by a factor e^0.34 = 1.41; 0.5 covers it."""

WARM: set[tuple] = set()
"""The (model, solver) pairs this worker process has solved: their one-time costs (Numba's
compilation or the loading of its cache, an engine's kernel modules) are paid, so that a later run
of the same pair in this process is its own timing (:func:`_single`).  A memo of the process, as
Numba's dispatchers are: it changes which solves are timed, never a result."""


def timed_repeats(seconds: float, repeats: int) -> int:
    """How many of ``repeats`` timed runs of ``seconds`` each a re-timing (:func:`_timed`) makes
    after the first (none when the first is its own timing, :func:`first_is_timing`, which an
    estimate cannot know: it counts them)."""
    return min(repeats, max(1, math.ceil(TIMING_BUDGET_S / seconds))) if seconds > 0 else repeats


def first_is_timing(seconds: float, info: dict) -> bool:
    """Whether a first run of ``seconds`` whose result reported ``info`` is its own timing
    (:data:`ONE_TIME_SHARE`): long, and its one-time cost reported and negligible.  A solver that
    does not report it (the Numba models compile inside their first call) is timed again."""
    if "compile_time_s" not in info or not seconds >= TIMING_BUDGET_S:
        return False
    one_time = float(info.get("compile_time_s") or 0.0) + float(info.get("warm_up_s") or 0.0)
    return math.isfinite(one_time) and one_time < ONE_TIME_SHARE * seconds


AUTO_REFINE_MAX = 3
"""``refine = "auto"`` refines up to this factor (cells split into 3³ elements)."""


def reference_model() -> str:
    """The model named in a reference scene: the registry's default (the FEM does not use it; a
    fixed name keeps the reference's key when the study's models change)."""
    return models.default_name()


@dataclass(frozen=True)
class StudyScene:
    scene: Scene
    study: str
    load_case: str
    cell_size: float
    label: str
    repeats: int = 1
    refine_auto: tuple[int, float] | None = None  # (largest refine, target relative error)
    predictor: str | None = None  # the key of the reference whose refine-1 error predicts this one's
    predicted: float | None = field(default=None, compare=False)  # that error, once it is stored
    retime: bool = False  # a near tie's re-timing: the run timed ``repeats`` times (:func:`near_ties`)
    warm_up: Scene | None = field(default=None, compare=False)  # the same run on the coarsest body (:func:`_single`)

    experiment = "study"

    def build(self) -> Scene:
        return self.scene

    @property
    def key_extra(self) -> dict:
        """What else changes the stored answer: the timing repeats, an adaptive reference."""
        if self.refine_auto is not None:
            extra = {"refine": "auto", "largest": self.refine_auto[0], "target": self.refine_auto[1]}
            return {**extra, "predictor": self.predictor} if self.predictor else extra
        return {"repeats": self.repeats, "retime": True} if self.retime else {"repeats": self.repeats}

    @property
    def refine_one(self) -> bool:
        """An adaptive reference whose predicted refine-1 error (:func:`predicted_refine_one`)
        meets its target: it solves refine 1 only."""
        return (self.refine_auto is not None and self.predicted is not None
                and self.predicted <= self.refine_auto[1])

    @property
    def mesh(self) -> tuple[int, int, int]:
        return self.scene.body.shape

    @property
    def nu(self) -> float:
        return self.scene.material.nu

    @property
    def model(self) -> str:
        return self.scene.model.name

    def expected_bytes(self, solver: SolverSpec) -> float:
        """The estimated peak memory of the run (:mod:`studies.sweep.sizing`): an adaptive
        reference's at its largest refinement, a model run's as the sweep's."""
        from studies.sweep import sizing

        if solver.kind == "fem":
            refine = self.refine_auto[0] if self.refine_auto is not None and not self.refine_one else solver.refine
            return sizing.fem(self.mesh, solver.element, refine, solver.law, self.nu).bytes
        steps = getattr(solver, "steps", None) or 10_000
        return sizing.mss(self.mesh, solver.kind, steps).bytes

    def to_dict(self) -> dict:
        m = self.scene.material
        return {"experiment": "study", "load_case": self.load_case, "cell_size": self.cell_size,
                "mesh": "x".join(map(str, self.mesh)), "cells": self.scene.body.n_cells, "E": m.E,
                "nu": m.nu, "rho": m.rho, "model": self.scene.model.name, "variant": self.label,
                "repeats": self.repeats}

    def solve(self, solver: SolverSpec):
        if solver.kind == "fem" and self.refine_auto is not None:
            res = _auto_reference(self.scene, solver, *self.refine_auto,
                                  predicted=self.predicted if self.refine_one else None)
        elif solver.kind == "fem":
            res = _once(self.scene, solver)
        else:
            res = (_timed(self.scene, solver, self.repeats) if self.retime
                   else _single(self.scene, solver, self.warm_up))
        for name, r in res.reactions.items():
            for c, v in zip("xyz", r.force):
                res.info[f"reaction_{name}_f{c}"] = float(v)
            for c, v in zip("xyz", r.torque):
                res.info[f"reaction_{name}_t{c}"] = float(v)
        return res


def _once(scene: Scene, solver: SolverSpec):
    res = solve_scene(scene, solver)
    res.info.update(time_s=float(res.wall_time_s), time_repeats=1)
    return res


def _single(scene: Scene, solver: SolverSpec, warm_up: Scene | None = None):
    """The result of one run, timed: the run itself where this process has solved the same model
    and solver before (:data:`WARM`: no one-time cost left to pay), or has just solved ``warm_up``
    with them (the same run on the study's coarsest body, untimed, its result not used: a run of
    a minute at 2 mm is not solved twice to time it), or where it is its own timing
    (:func:`first_is_timing`); else an untimed first run and one timed run after it.  ``info``:
    ``time_s`` (``time_median_s`` the same, ``time_spread`` nan: one sample), ``time_repeats`` 1,
    ``time_first_run`` whether the stored run is the timed one."""
    from hybmss.timing import Timing

    warm_key = (repr(scene.model), solver.kind, solver.kernel)
    if warm_key not in WARM and warm_up is not None:
        try:
            solve_scene(warm_up, solver)
        except Exception:  # noqa: BLE001 -- the coarser run's failure is its own row's, not this run's
            pass
        else:
            WARM.add(warm_key)
    t0 = time.perf_counter()
    first = solve_scene(scene, solver)
    seconds = time.perf_counter() - t0
    once = warm_key in WARM or first_is_timing(seconds, first.info)
    WARM.add(warm_key)
    if not once:
        t0 = time.perf_counter()
        solve_scene(scene, solver)
        seconds = time.perf_counter() - t0
    first.info.update(Timing.from_samples([seconds]).as_dict("time"))
    first.info["time_first_run"] = once
    return first


def _timed(scene: Scene, solver: SolverSpec, repeats: int):
    """The result of a first run with the timing of up to ``repeats`` more, stopped once they
    took :data:`TIMING_BUDGET_S` together (:func:`hybmss.timing.time_repeated`: best, median,
    spread, their number) in ``info['time_*']``; a first run that is its own timing
    (:func:`first_is_timing`: long, its reported one-time cost negligible) is not run again:
    ``time_repeats`` 1, ``time_first_run`` true."""
    from hybmss.timing import Timing, time_repeated

    t0 = time.perf_counter()
    first = solve_scene(scene, solver)
    seconds = time.perf_counter() - t0
    once = first_is_timing(seconds, first.info)
    if once:
        timing = Timing.from_samples([seconds])
    else:
        timing = time_repeated(lambda: solve_scene(scene, solver), repeats=repeats, warmup=0,
                               budget_s=TIMING_BUDGET_S)
    first.info.update(timing.as_dict("time"))
    first.info["time_first_run"] = once
    return first


def _auto_reference(scene: Scene, solver: SolverSpec, largest: int, target: float,
                    predicted: float | None = None):
    """Refine (1, 2, ... ``largest``) until the Richardson estimate of the reference's own error
    (expected order of the element; max |u| on itself, the plates' forces and torques on the load's
    force scale, :func:`reference_estimate`) is below ``target``; the result of the last
    refinement, with the estimate in its ``info`` and the time of every level solved in ``time_s``.
    Each finite-strain level starts from the one before (:func:`fem_reference.solve.solve_levels`).

    A ``predicted`` refine-1 error (:func:`predicted_refine_one`, at or below ``target``:
    :attr:`StudyScene.refine_one`) is the estimate of refine 1, which is then the only level
    solved (``reference_error_basis`` ``"predicted"``).  Every reference keeps the estimate of its refine-1 error,
    ``reference_refine1_error`` (measured from its first two levels, or the prediction), for the
    finer configurations it predicts."""
    from fem_reference.solve import solve_levels

    if predicted is not None:
        largest = 1
    results, estimate, refine1 = [], float("nan"), float("nan")
    for res in solve_levels(scene, range(1, largest + 1), solver.element, solver.law):
        results.append(res)
        if len(results) < 2:
            continue
        estimate = reference_estimate(scene, results[-2:], [len(results) - 1, len(results)])
        if len(results) == 2:
            refine1 = reference_estimate(scene, results, [1, 2], level="coarsest")
        if estimate <= target:
            break
    if predicted is not None:
        estimate = refine1 = float(predicted)
    res = results[-1]
    res.info.update(reference_refine=len(results), reference_error_estimate=estimate,
                    reference_error_target=target, reference_refine1_error=refine1,
                    reference_error_basis="predicted" if predicted is not None else "richardson" if len(results) > 1
                    else "none",
                    time_s=float(sum(r.wall_time_s for r in results)), time_repeats=1)
    return res


def reference_estimate(scene: Scene, results, refinements, level: str = "finest") -> float:
    """The largest Richardson error estimate of the finest of ``results`` (``fem_reference.
    convergence.analyze``; ``level="coarsest"``: of the first) over max |u|, on its extrapolated
    value, and each plate's force and torque norms, on the load's force scale ``F_load`` and
    ``F_load R_s`` (:func:`studies.study.metrics.load_scales` and ``support_radius``): a reaction the
    load puts near zero is not measured on itself."""
    import numpy as np

    from fem_reference.convergence import EXPECTED_ORDER, analyze
    from hybmss.lattice import Lattice

    from studies.study.metrics import norm, support_radius

    order = EXPECTED_ORDER[results[-1].info["element"]]
    X = Lattice.from_body(scene.body).X
    radii = {p.name: support_radius(X, p.region.select(X, scene.body), scene.body.le) for p in scene.plates}
    last = results[-1].reactions
    force = max([0.0] + [max(norm(last[n].force), norm(last[n].torque) / R) for n, R in radii.items()])

    def err(q) -> float:
        return getattr(analyze(refinements, [q(x) for x in results], order), f"error_{level}")

    out = [getattr(analyze(refinements, [x.max_displacement for x in results], order), f"relative_error_{level}")]
    for name, R in radii.items():
        if force > 0:
            out.append(err(lambda x, n=name: norm(x.reactions[n].force)) / force)
            out.append(err(lambda x, n=name: norm(x.reactions[n].torque)) / (force * R))
    return float(max(out)) if np.isfinite(out).all() else float("inf")


def near_ties(tasks: list[Task], budgets: list, done: set[str] = frozenset()) -> list[Task]:
    """The re-timings (:attr:`StudyScene.retime`) of every model run that wins a budget answer of
    ``budgets`` (the study's ``budget_<case>`` tables, :func:`studies.study.tables.budget_answer`)
    or is its runner-up, where the lead is within :data:`RETIME_NOISE` of single timings: the
    runs whose order the noise of one timing could reverse, timed ``repeats`` times so that their
    spreads decide the tie (:func:`studies.sweep.cost.is_tie`); none whose key is in ``done``."""
    wanted = set()
    for b in budgets:
        if b is None or b.empty or "answer" not in b:
            continue
        near = b[(b["answer"] == "fastest") & (b["runner_up"].fillna("") != "") & (b["lead"] < 1.0 + RETIME_NOISE)]
        for r in near.itertuples():
            for model, le in ((r.method, r.cell_size_m), (r.runner_up, r.runner_up_cell_size_m)):
                wanted.add((r.load_case, float(r.E), float(r.nu), float(r.rho), model, float(le)))
    out = []
    for t in tasks:
        s = t.scene
        if not isinstance(s, StudyScene) or is_reference(t) or s.retime:
            continue
        m = s.scene.material
        if (s.load_case, float(m.E), float(m.nu), float(m.rho), s.label, float(s.cell_size)) in wanted:
            retimed = replace(t, scene=replace(s, retime=True))
            if retimed.key() not in done:
                out.append(retimed)
    return out


# ---------------------------------------------------------------------------- the task list
def study_tasks(study) -> list[Task]:
    """Model runs first (load case, material, resolution, model), then the references; a
    tetrahedral body's (``[body] tet_sizes``): :func:`studies.study.tet.tet_study_tasks`."""
    if study.tet_bodies:
        from studies.study.tet import tet_study_tasks

        return tet_study_tasks(study, lambda run, case, mat: with_warm_ups([_model_task(study, run, case, mat, vox)
                                                                            for vox in study.voxels]))
    tasks, refs = [], {}
    for case in study.load_cases:
        for mat in study.materials:
            for vox in study.voxels:
                plates = tuple(s.plate(vox.labels) for s in case.supports)
                loads = tuple(t.load(vox.labels) for t in case.tractions)
                for run in study.models:
                    scene = Scene(vox.body, mat, Model(run.name, **dict(run.params)), plates, case.gravity,
                                  run.damping, f"{study.name} {case.name} {run.label}", loads)
                    tasks.append(Task(StudyScene(scene, study.name, case.name, vox.le, run.label, study.repeats),
                                      _solver(run), study.name))
                refs[(case.name, mat, vox.le)] = _reference_task(study, case, mat, vox, plates, loads)
    return with_warm_ups(tasks) + _with_predictors(refs)


def with_warm_ups(tasks: list[Task]) -> list[Task]:
    """``tasks`` with each model run at a finer cell size than its study's coarsest holding the same
    run on the coarsest body as its :attr:`StudyScene.warm_up` (:func:`_single`)."""
    def run_of(t: Task):
        """The run at every cell size (None: a reference, or not a study's scene)."""
        s = t.scene
        if not isinstance(s, StudyScene) or is_reference(t):
            return None
        return (s.load_case, s.scene.material, s.label, t.solver)

    coarsest: dict = {}
    for t in tasks:
        k = run_of(t)
        if k is not None and (k not in coarsest or t.scene.cell_size > coarsest[k].cell_size):
            coarsest[k] = t.scene
    out = []
    for t in tasks:
        c = coarsest.get(run_of(t))
        if c is not None and c.cell_size > t.scene.cell_size:
            t = replace(t, scene=replace(t.scene, warm_up=c.scene))
        out.append(t)
    return out


PREDICTOR_RATIO = 2.0
"""An adaptive reference's refine-1 error is predicted by that of the same load case and material
on a voxelization at least this many times coarser (the nearest such): a finer voxelization of the
same body, solved on its own cells, is not less accurate than a coarser one on its own.  Measured
on 12 pairs of Richardson estimates (levels 1 and 2 solved on both): the cylinder study at 8, 4
and 2 mm, squeeze and twist, ν 0.3 and 0.49 (8 pairs), the soft cantilever's sag at 10 and 5 mm,
the liver block's compression and self-weight at 20 and 10 mm, a 2 × 2 × 4 cm block hanging from
its top at 10 and 5 mm (the test's): the finer one's refine-1 error was 1.3 to 3.2 times smaller
(equal for the homogeneous compression, which both solve exactly)."""


def _with_predictors(refs: dict) -> list[Task]:
    """The references of ``refs`` (by load case, material, cell size), each adaptive one that has a
    configuration :data:`PREDICTOR_RATIO` times coarser naming that one's key as its predictor."""
    done: dict = {}
    for (case, mat, le), task in sorted(refs.items(), key=lambda kv: -kv[0][2]):
        coarser = [c for c in done if c[:2] == (case, mat) and c[2] >= PREDICTOR_RATIO * le * (1 - 1e-9)]
        if task.scene.refine_auto is not None and coarser:
            source = done[min(coarser, key=lambda c: c[2])]
            task = replace(task, scene=replace(task.scene, predictor=source.key()))
        done[(case, mat, le)] = task
    return [done[c] for c in refs]


def predictor_sweeps(tasks: list[Task]) -> list[list[Task]]:
    """The references other references are predicted from, in the order they must be computed:
    one list per step of the chain (coarsest first); the tasks that are no one's predictor come
    after them all."""
    by_key = {t.key(): t for t in tasks if is_reference(t) and isinstance(t.scene, StudyScene)}
    wanted = {t.scene.predictor for t in by_key.values() if t.scene.predictor in by_key}

    def depth(key: str) -> int:
        up = by_key[key].scene.predictor
        return 0 if up not in by_key else 1 + depth(up)

    steps: dict[int, list[Task]] = {}
    for key in wanted:
        steps.setdefault(depth(key), []).append(by_key[key])
    return [steps[d] for d in sorted(steps)]


def given_predictions(tasks: list[Task], rows: dict[str, dict]) -> list[Task]:
    """``tasks`` with each reference whose predictor's row is in ``rows`` (by key) holding the
    predicted refine-1 error (:func:`predicted_refine_one`)."""
    out = []
    for t in tasks:
        row = rows.get(getattr(t.scene, "predictor", None) or "")
        if row is not None:
            t = replace(t, scene=replace(t.scene, predicted=predicted_refine_one(row)))
        out.append(t)
    return out


def predicted_refine_one(row: dict) -> float | None:
    """The refine-1 error a predictor's stored ``row`` gives its finer configurations
    (:data:`PREDICTOR_RATIO`): its own ``reference_refine1_error``; none when it has no result."""
    info = (row or {}).get("info") or {}
    value = info.get("reference_refine1_error")
    if (row or {}).get("status") != "ok" or not isinstance(value, (int, float)) or not math.isfinite(value):
        return None
    return float(value)


def _model_task(study, run, case, mat: Material, vox) -> Task:
    plates = tuple(s.plate(vox.labels) for s in case.supports)
    loads = tuple(t.load(vox.labels) for t in case.tractions)
    scene = Scene(vox.body, mat, Model(run.name, **dict(run.params)), plates, case.gravity, run.damping,
                  f"{study.name} {case.name} {run.label}", loads)
    return Task(StudyScene(scene, study.name, case.name, vox.le, run.label, study.repeats), _solver(run), study.name)


def _solver(run) -> SolverSpec:
    if run.kind == "static":
        return SolverSpec("static")
    return SolverSpec(run.kind, dt=run.dt, steps=run.steps, ramp_time=run.ramp_time)


def _reference_task(study, case, mat: Material, vox, plates, loads) -> Task:
    ref = study.reference
    scene = Scene(vox.body, mat, Model(reference_model()), plates, case.gravity, 0.0,
                  f"{study.name} {case.name} FEM", loads)
    auto = None
    if ref.refine == "auto":
        auto = (auto_refine_cap(vox.body.shape, ref, mat.nu), ref.tolerance * min(study.budgets))
    solver = SolverSpec("fem", element=ref.element, law=ref.law, refine=1 if auto else int(ref.refine))
    return Task(StudyScene(scene, study.name, case.name, vox.le, "FEM", 1, auto), solver, study.name)


def auto_refine_cap(shape, reference, nu: float) -> int:
    """The finest refinement ``refine = "auto"`` may reach on a grid of ``shape``: the largest of
    1 ... :data:`AUTO_REFINE_MAX` whose solve fits this machine's memory (the estimate of
    :func:`studies.sweep.sizing.fem`; 1 if none does, which the memory check then refuses).  A
    reference that stops there above its target says so in its row (``reference_error_estimate``
    beside ``reference_error_target``)."""
    from studies.sweep import sizing

    fitting = [r for r in range(1, AUTO_REFINE_MAX + 1)
               if sizing.fits(sizing.fem(shape, reference.element, r, reference.law, nu))]
    return max(fitting, default=1)


def is_reference(task: Task) -> bool:
    return task.solver.kind == "fem"
