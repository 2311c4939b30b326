"""The studies of ``make reproduce-paper``: the publication's experiments as study files.

Each of the five experiment studies is one or more study files shipped in
``studies/data/studies/`` (the format: ``docs/study-format.md``), read with ``tomllib`` and
turned into the runner's tasks by :func:`studies.study.experiment.experiment_tasks`: the
publication's meshes, materials, loads, the models of each study role with their solvers, and
the FEM references.  ``quick`` takes each file's ``[body.quick]`` meshes (the cube 4×4×4, the
beam 2×2×12) and leaves out its ``skip_quick`` models, so the same files run in the test suite
within seconds.

Explicit runs follow the publication's protocol (symplectic Euler, dt = 1 ms, 10,000 steps),
with the plates ramped over 1 s and mass-proportional damping c = 2 s⁻¹ (about critical for the
cube's slowest mode; [G20] does not state its damping): the ``solver`` of the files'
``explicit-tables`` models.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from studies.sweep.outcomes import expected_finding
from studies.sweep.runner import Runner, SolverSpec, Task, run_tasks
from studies.sweep.store import Store
from studies.study.experiment import configurations, experiment_tasks, file_tables, validate_experiment

STATIC = SolverSpec("static")

STUDY_FILES = {
    "compression": ("compression",),
    "tension": ("tension",),
    "shear": ("shear",),
    "torsion": ("torsion", "torsion-sweep"),  # the table's angles, then torque against angle (full only)
    "bending": ("bending",),
}
"""Each study of the reproduction: its files in ``studies/data/studies`` (``<name>.toml``)."""


def study_file_path(name: str) -> Path:
    """The shipped study file ``name`` (``compression``, ``torsion-sweep``, ...)."""
    return Path(str(resources.files("studies").joinpath("data", "studies", f"{name}.toml")))


def load_study_file(name: str) -> dict:
    """The shipped study file ``name``, parsed and validated (:class:`studies.study.StudyError`)."""
    path = study_file_path(name)
    with path.open("rb") as fh:
        doc = tomllib.load(fh)
    validate_experiment(doc, str(path))
    return doc


class FileStudy:
    """A study of the reproduction: ``study(quick) -> list[Task]``, the tasks of its ``files``
    in order (read at each call, so that the files are the one place the studies are declared)."""

    def __init__(self, files: tuple[str, ...]):
        self.files = tuple(files)

    def __call__(self, quick: bool = False) -> list[Task]:
        return [t for f in self.files for t in experiment_tasks(load_study_file(f), quick)]

    def __repr__(self) -> str:
        return f"FileStudy({', '.join(f + '.toml' for f in self.files)})"


STUDIES = {name: FileStudy(files) for name, files in STUDY_FILES.items()}

DRIVER_FILES = {
    "engines": ("engines",),
    "regression": ("regression-cube", "regression-tension", "regression-bending"),
    "b09": ("b09-volume-cube", "b09-volume-beam"),
}
"""The studies of the drivers (:data:`EXTRA_STUDIES`, :data:`ON_REQUEST_STUDIES`, the CI
regression) whose runs are study files too, read on the same path as :data:`STUDY_FILES`; their
tables are the files' ``[[table]]`` hooks (:data:`TABLE_HOOKS`)."""

DRIVER_STUDIES = {name: FileStudy(files) for name, files in DRIVER_FILES.items()}

TABLE_HOOKS = {
    "engines-closing": "studies.paper.engines:closing_hook",
    "engines-timing": "studies.paper.engines:timing_hook",
    "regression": "studies.paper.regression:table_hook",
    "b09-volume": "studies.paper.baudet:volume_hook",
}
"""The code of each table hook a study file may name (``[[table]] hook``,
:data:`studies.study.experiment.TABLE_HOOKS`): "module:function", the function taking a
:class:`HookInput` and returning the table (a ``pandas.DataFrame``)."""


@dataclass(frozen=True)
class HookInput:
    """What a table hook reads: the study's parsed files (``docs``), their configurations in
    order (``configurations``, :func:`studies.study.experiment.configurations`), its tasks and
    their stored rows (in the same order), the mode, the ``[[table]]`` entry's ``repeats``, and the
    store the rows came from (for their arrays)."""

    docs: tuple
    configurations: tuple
    tasks: tuple
    rows: tuple
    quick: bool
    repeats: int | None = None
    store: Store | None = None


def file_study_tables(name: str, tasks: list[Task], rows: list[dict], quick: bool, skip=(),
                      store: Store | None = None) -> dict:
    """The tables of the driver study ``name`` (:data:`DRIVER_FILES`): each ``[[table]]`` of its
    files (once by name, in the files' order; not those whose hook is in ``skip``), computed by
    its hook from the study's ``tasks`` and their ``rows``."""
    import importlib

    docs = tuple(load_study_file(f) for f in DRIVER_STUDIES[name].files)
    configs = tuple(c for d in docs for c in configurations(d, quick))
    out = {}
    for doc in docs:
        for t in file_tables(doc, quick):
            if t["name"] in out or t["hook"] in skip:
                continue
            module, func = TABLE_HOOKS[t["hook"]].split(":")
            hook = getattr(importlib.import_module(module), func)
            out[t["name"]] = hook(HookInput(docs, configs, tuple(tasks), tuple(rows), quick, t["repeats"], store))
    return out


def check_study_files(names=None) -> None:
    """Read and validate the files of the named studies (every one by default) before any work:
    :class:`studies.study.StudyError` at the first key that is not allowed."""
    studies = {**STUDIES, **DRIVER_STUDIES}
    for name in (list(studies) if not names else [n for n in names if n in studies]):
        for f in studies[name].files:
            load_study_file(f)


def _meshes(name: str, quick: bool) -> tuple[tuple[int, int, int], ...]:
    body = load_study_file(name)["body"]
    meshes = body["quick"]["mesh"] if quick and "mesh" in body.get("quick", {}) else body["mesh"]
    return tuple(tuple(m) for m in meshes)


def cube(quick: bool) -> tuple[int, int, int]:
    """The cube's mesh of the compression study (other studies that run its scenes take it here)."""
    return _meshes("compression", quick)[0]


def beams(quick: bool) -> tuple[tuple[int, int, int], ...]:
    """The beam's meshes of the tension study."""
    return _meshes("tension", quick)


EXTRA_STUDIES: dict[str, str] = {
    "b09": "studies.paper.baudet:run",  # [B09]'s cantilever and L-shape (models of the b09 role); moduli
    "performance": "studies.paper.performance:run",  # [G20] Figs 11-12: explicit kernel time per step
    "pareto": "studies.paper.pareto:run",  # speed against error vs a converged FEM reference; error budgets
    "stability": "studies.paper.stability:run",  # dt_crit, extreme deformation, limit stretch, irregular input
    "modes": "studies.paper.modes_study:run",  # natural frequencies of the cube and beam against the FEM's
    "dynamics": "studies.paper.dynamics_study:run",  # released transients of the cube and beam against the FEM's
}
"""Studies with their own driver, run after the task lists above: name -> "module:function",
where the function is ``run(store: Store, quick: bool, jobs: int | None, progress: bool, runner)``
(``runner``: the :class:`studies.sweep.runner.Runner` its runs go to, or ``None``) and writes its own
tables into ``store`` (e.g. performance, speed against error, stability)."""

ON_REQUEST_STUDIES: dict[str, str] = {
    "engines": "studies.paper.engines:run",  # the engines on the 10³ cube against the FEM: the closing table
}
"""Studies with their own driver that ``--all`` (``make reproduce-paper``) leaves out for their
cost, run when named (``--study engines``); the signature of :data:`EXTRA_STUDIES`' drivers."""


def tasks_for(names=None, quick: bool = False) -> list[Task]:
    names = list(STUDIES) if not names else list(names)
    unknown = [n for n in names if n not in STUDIES]
    if unknown:
        raise ValueError(f"unknown study {unknown[0]!r}; studies: {', '.join(STUDIES)}")
    return [t for n in names for t in STUDIES[n](quick)]


CALLS_FIRST = ("b09", "stability", "performance")
"""The drivers whose computations outside runs (their ``calls(quick)``) the sweep does once its
runs are handed out, in this order (the longest first: [B09]'s three tables, the irregular
lattices, the bisections of dt, then the performance study's kernels); the moduli of the tables
(:func:`studies.paper.tables.calls`) come last."""


def study_calls(names, quick: bool) -> list:
    """The computations outside runs of the drivers ``names`` (:data:`CALLS_FIRST` that have
    them) and of the tables (the moduli), for :meth:`studies.sweep.runner.Runner.run`'s ``calls``:
    they do not depend on the sweep's runs, so its workers do them as its last runs leave
    cores idle, and each driver then finds its results stored (or its kernels compiled)."""
    import importlib

    from studies.paper import tables

    out = []
    for name in CALLS_FIRST:
        if name in names:
            module = importlib.import_module({**EXTRA_STUDIES, **ON_REQUEST_STUDIES}[name].split(":")[0])
            out += module.calls(quick)
    return out + tables.calls()


def run_studies(out, names=None, quick: bool = False, jobs: int | None = None, progress: bool = True,
                runner=None):
    """Run (or resume) the named studies into the results folder ``out`` and write the tables.
    ``runner`` (a :class:`studies.sweep.runner.Runner`) chooses where runs are computed; without
    one, a runner of ``jobs`` local workers kept for every study (its session)."""
    if runner is None:
        with Runner(jobs=jobs, progress=progress) as own:
            return run_studies(out, names, quick, jobs, progress, own)
    from studies.paper.claims import write_claims
    from studies.paper.stored import write_derived
    from studies.paper.tables import write_tables

    import importlib

    store = Store(Path(out))
    names = list(STUDIES) + list(EXTRA_STUDIES) if not names else list(names)
    drivers = {**EXTRA_STUDIES, **ON_REQUEST_STUDIES}
    unknown = [n for n in names if n not in STUDIES and n not in drivers]
    if unknown:
        raise ValueError(f"unknown study {unknown[0]!r}; studies: {', '.join(list(STUDIES) + list(drivers))}")
    # one pool for every task list, the extra studies' pooled runs included (their ``tasks``), so
    # that no core idles at the end of a study's slowest run; each extra study then finds its
    # runs stored
    listed = [n for n in names if n in STUDIES]
    pooled = tasks_for(listed, quick) if listed else []
    n_listed = len(pooled)
    extra = [n for n in names if n in drivers]
    for name in extra:
        module = importlib.import_module(drivers[name].split(":")[0])
        if hasattr(module, "tasks"):
            pooled += module.tasks(quick)
    rows = run_tasks(pooled, store, jobs=jobs, progress=progress, desc=", ".join(listed + extra),
                     runner=runner, expected=expected_finding, calls=lambda: study_calls(extra, quick))[:n_listed]
    write_tables(store, {t.key() for t in pooled[:n_listed]} if listed else None, runner)
    for name in names:
        if name in drivers:
            module, func = drivers[name].split(":")
            getattr(importlib.import_module(module), func)(store, quick=quick, jobs=jobs, progress=progress,
                                                           runner=runner)
    write_claims(store)  # the verdicts, from every table the studies just wrote
    write_derived(store)  # the tables the report shows that the studies derive from the others
    return rows
