"""The studies of ``make reproduce-paper``: lists of tasks, declared as data.

Each study is a function ``quick -> list[Task]`` built from parameter products.  ``quick``
replaces the publication's meshes by coarse ones (the cube 4×4×4, the beam 2×2×12) so the same
code runs in the test suite within seconds.

Explicit runs follow the publication's protocol (symplectic Euler, dt = 1 ms, 10,000 steps),
with the plates ramped over 1 s and mass-proportional damping c = 2 s⁻¹ (about critical for the
cube's slowest mode; [G20] does not state its damping).
"""

from __future__ import annotations

import itertools
from pathlib import Path

from hybmss import models
from hybmss.experiments import SceneSpec

from . import roles
from .runner import SolverSpec, Task, run_tasks
from .store import Store

NUS = (0.0, 0.25, 0.499)
DEFORMATIONS = (0.05, 0.20)
EXPLICIT_DAMPING = 2.0
TORSION_TABLE_ANGLES = (1.0, 45.0)
TORSION_SWEEP = (2.0, 5.0, 10.0, 20.0, 30.0, 60.0, 90.0)
TORSION_SWEEP_LINEAR_MAX = 10.0
"""Largest angle of the sweep with a linear FEM run (the torque figure shows it up to here)."""

STATIC = SolverSpec("static")
EXPLICIT = SolverSpec("explicit", dt=1e-3, steps=10_000, ramp_time=1.0)


def cube(quick: bool) -> tuple[int, int, int]:
    return (4, 4, 4) if quick else (10, 10, 10)


def beams(quick: bool) -> tuple[tuple[int, int, int], ...]:
    return ((2, 2, 12),) if quick else ((4, 4, 24), (8, 8, 48))


def fem_solvers(spec: SceneSpec, quick: bool, sweep_svk: bool = True) -> list[SolverSpec]:
    """Linear at small deformation; Neo-Hookean and St Venant–Kirchhoff at large (their spread
    is the reference's model-form uncertainty).  Mixed u–p is selected for ν ≥ 0.45 (``auto``)."""
    if spec.experiment == "torsion":
        large = spec.angle_deg > 5.0
    elif spec.experiment == "bending":
        large = True
    else:
        large = spec.deformation > 0.05 + 1e-12
    out = [SolverSpec("fem", element="auto", law="linear")]
    if large:
        out += [SolverSpec("fem", element="auto", law="neo-hookean")]
        if sweep_svk:
            out += [SolverSpec("fem", element="auto", law="svk")]
    return out


def _mss_models(nu: float) -> list[dict]:
    """Every model of the ``tables`` role with each parameter set it is compared in at ν (its
    defaults first; e.g. the E-form of [G20] eq. 5.12 where it differs from the G-form)."""
    return [dict(model=m.name, **v) for m in models.all_models() if roles.takes_part(m.name, "tables")
            for v in m.study_variants(nu)]


def _with_fem(study: str, specs: list[SceneSpec], quick: bool) -> list[Task]:
    tasks = []
    explicit = roles.in_role("explicit-tables")
    for spec in specs:
        for m in _mss_models(spec.nu):
            s = spec.replace(**m)
            tasks.append(Task(s, STATIC, study))
            defaults = len(m) == 1  # the model's own defaults, not a study variant of its parameters
            if not quick and m["model"] in explicit and defaults:
                tasks.append(Task(s.replace(damping=EXPLICIT_DAMPING), EXPLICIT, study))
        for fs in fem_solvers(spec, quick):
            tasks.append(Task(spec, fs, study))
    return tasks


def compression(quick: bool = False) -> list[Task]:
    specs = [SceneSpec.default("compression", mesh=cube(quick), nu=nu, deformation=d)
             for nu, d in itertools.product(NUS, DEFORMATIONS)]
    return _with_fem("compression", specs, quick)


def tension(quick: bool = False) -> list[Task]:
    specs = [SceneSpec.default("tension", mesh=mesh, nu=nu, deformation=d)
             for mesh, nu, d in itertools.product(beams(quick), NUS, DEFORMATIONS)]
    return _with_fem("tension", specs, quick)


def shear(quick: bool = False) -> list[Task]:
    specs = [SceneSpec.default("shear", mesh=cube(quick), nu=nu, deformation=d)
             for nu, d in itertools.product(NUS, DEFORMATIONS)]
    return _with_fem("shear", specs, quick)


def torsion(quick: bool = False) -> list[Task]:
    specs = [SceneSpec.default("torsion", mesh=cube(quick), nu=nu, angle_deg=a)
             for nu, a in itertools.product(NUS, TORSION_TABLE_ANGLES)]
    tasks = _with_fem("torsion", specs, quick)
    if not quick:  # torque against angle at ν = 1/4
        for a in TORSION_SWEEP:
            spec = SceneSpec.default("torsion", mesh=cube(quick), nu=0.25, angle_deg=a)
            for m in roles.in_role("torsion-sweep"):
                tasks.append(Task(spec.replace(model=m), STATIC, "torsion-sweep"))
            for fs in fem_solvers(spec, quick, sweep_svk=False):
                if fs.law == "linear" and a > TORSION_SWEEP_LINEAR_MAX:
                    continue  # the small-strain FEM is no reference there: the figure omits it
                tasks.append(Task(spec, fs, "torsion-sweep"))
    return tasks


def bending(quick: bool = False) -> list[Task]:
    tasks = []
    for mesh, E in itertools.product(beams(quick), (1e7, 2e6)):
        spec = SceneSpec.default("bending", mesh=mesh, E=E, nu=0.25, gravity=10.0)
        for m in roles.in_role("bending"):
            tasks.append(Task(spec.replace(model=m), STATIC, "bending"))
        tasks.append(Task(spec, SolverSpec("fem", element="hex2", law="linear"), "bending"))
        tasks.append(Task(spec, SolverSpec("fem", element="hex2", law="neo-hookean"), "bending"))
    return tasks


STUDIES = {
    "compression": compression,
    "tension": tension,
    "shear": shear,
    "torsion": torsion,
    "bending": bending,
}


EXTRA_STUDIES: dict[str, str] = {
    "b09": "studies.baudet:run",  # [B09]'s cantilever and L-shape (models of the b09 role); moduli
    "performance": "studies.performance:run",  # [G20] Figs 11-12: explicit kernel time per step
    "pareto": "studies.pareto:run",  # speed against error vs a converged FEM reference; error budgets
    "stability": "studies.stability:run",  # dt_crit, extreme deformation, limit stretch, irregular input
}
"""Studies with their own driver, run after the task lists above: name -> "module:function",
where the function is ``run(store: Store, quick: bool, jobs: int | None, progress: bool, runner)``
(``runner``: the :class:`studies.runner.Runner` its runs go to, or ``None``) and writes its own
tables into ``store`` (e.g. performance, speed against error, stability)."""


def tasks_for(names=None, quick: bool = False) -> list[Task]:
    names = list(STUDIES) if not names else list(names)
    unknown = [n for n in names if n not in STUDIES]
    if unknown:
        raise ValueError(f"unknown study {unknown[0]!r}; studies: {', '.join(STUDIES)}")
    return [t for n in names for t in STUDIES[n](quick)]


def run_studies(out, names=None, quick: bool = False, jobs: int | None = None, progress: bool = True,
                runner=None):
    """Run (or resume) the named studies into the results folder ``out`` and write the tables.
    ``runner`` (a :class:`studies.runner.Runner`) chooses where runs are computed."""
    from .claims import write_claims
    from .tables import write_tables

    import importlib

    store = Store(Path(out))
    names = list(STUDIES) + list(EXTRA_STUDIES) if not names else list(names)
    unknown = [n for n in names if n not in STUDIES and n not in EXTRA_STUDIES]
    if unknown:
        raise ValueError(f"unknown study {unknown[0]!r}; studies: {', '.join(list(STUDIES) + list(EXTRA_STUDIES))}")
    # one pool for every task list, the extra studies' pooled runs included (their ``tasks``), so
    # that no core idles at the end of a study's slowest run; each extra study then finds its
    # runs stored
    listed = [n for n in names if n in STUDIES]
    pooled = tasks_for(listed, quick) if listed else []
    n_listed = len(pooled)
    extra = [n for n in names if n in EXTRA_STUDIES]
    for name in extra:
        module = importlib.import_module(EXTRA_STUDIES[name].split(":")[0])
        if hasattr(module, "tasks"):
            pooled += module.tasks(quick)
    rows = run_tasks(pooled, store, jobs=jobs, progress=progress, desc=", ".join(listed + extra),
                     runner=runner)[:n_listed] if pooled else []
    write_tables(store, {t.key() for t in pooled[:n_listed]} if listed else None)
    for name in names:
        if name in EXTRA_STUDIES:
            module, func = EXTRA_STUDIES[name].split(":")
            getattr(importlib.import_module(module), func)(store, quick=quick, jobs=jobs, progress=progress,
                                                           runner=runner)
    write_claims(store)  # the verdicts, from every table the studies just wrote
    return rows
