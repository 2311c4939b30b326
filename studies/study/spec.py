"""A study read from its TOML file (the format: ``docs/study-format.md``), every key checked
before any work starts.

:meth:`Study.from_toml` reads the file in named steps (the study, the body, the material, the
load cases, the models, the reference, the metrics), then checks the whole against the body at
every resolution (:func:`_check_resolutions`: each support selects nodes, each traction faces,
every piece of the body is held against the six rigid motions).  An ``experiment`` body (the
publication's experiments as study files) is handed to :mod:`studies.study.experiment` once the
shared keys are checked (:func:`_experiment_study`)."""

from __future__ import annotations

import dataclasses
import functools
import itertools
import re
import subprocess
import sys
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hybmss import models as registry
from hybmss.lattice import Lattice
from hybmss.scene import Load, Material, NU_OPEN_RANGE, Scene, plates_cross

from studies.study import checks, tet
from studies.study.body import BodySource, Voxels, body_checks, cell_sizes, folder_of, grid_shape, read_source, source_typo
from studies.study.errors import StudyError
from studies.study.outcome import read_expected
from studies.study.keys import Table, close
from studies.study.modes import check_modes, read_modes
from studies.study.release import Release, read_point, read_release
from studies.study.regions import SupportSpec, TractionSpec, held_modes, read_support, read_traction

TOP_KEYS = ("study", "body", "material", "load_case", "model", "reference", "metrics")
EXPERIMENT_KEYS = ("study", "body", "material", "load", "model", "reference")
NAME = re.compile(r"[a-z0-9_-]+")
PRINTABLE = re.compile(r"[ -~]*[!-~][ -~]*")
"""Printable ASCII with at least one visible character: a model's label, a support's name."""
FILE_SAFE = re.compile(r"[^A-Za-z0-9_.+-]+")
"""The characters a model's label loses in its VTU file's name (each run of others becomes ``_``):
two labels that become the same name are refused."""
ELEMENTS = ("auto", "hex1", "hex2", "mixed")
LAWS = ("linear", "neo-hookean", "svk")
SOLVER_KINDS = ("static", "explicit", "implicit")


@dataclass(frozen=True)
class LoadCase:
    name: str
    gravity: tuple[float, float, float]
    supports: tuple[SupportSpec, ...]
    tractions: tuple[TractionSpec, ...]
    release: Release | None = None  # a released transient after the static runs (studies.study.release)


@dataclass(frozen=True)
class ModelRun:
    """One model of the study: registry ``name``, its ``params`` (sorted pairs), display
    ``label``, solver (``kind``, ``dt``, ``steps``, ``ramp_time``) and the scene's ``damping``."""

    name: str
    params: tuple[tuple[str, object], ...]
    label: str
    kind: str = "static"
    dt: float = 1e-3
    steps: int = 10_000
    ramp_time: float = 1.0
    damping: float = 0.0
    expect_no_result: tuple[str, ...] = ()


@dataclass(frozen=True)
class Reference:
    element: str = "auto"
    law: str = "linear"
    refine: int | str = 1
    tolerance: float = 0.25


@dataclass(frozen=True)
class Metrics:
    plate_force: tuple[str, ...] = ()
    volume_change: bool = True
    displacement: bool = True
    points: tuple[tuple[str, tuple[float, float, float]], ...] = ()
    modes: int = 0  # natural frequencies: the lowest k modes (studies.study.modes); 0: none
    point: str | None = None  # the point a released transient tracks (a name of points); None: largest sag


@dataclass(frozen=True)
class Study:
    """A study as plain data (``Study.from_toml`` reads and checks one)."""

    name: str
    title: str
    file: str = ""
    path: str = ""
    budgets: tuple[float, ...] = (0.02,)
    repeats: int = 5
    quick: bool = False
    source: BodySource | None = None
    cell_sizes: tuple[float, ...] = ()
    materials: tuple[Material, ...] = ()
    load_cases: tuple[LoadCase, ...] = ()
    models: tuple[ModelRun, ...] = ()
    reference: Reference = Reference()
    metrics: Metrics = Metrics()
    experiment: dict | None = field(default=None, compare=False)
    voxels: tuple[Voxels, ...] = field(default=(), compare=False, repr=False)
    tet_sizes: tuple[float, ...] = ()  # [body] tet_sizes: conforming tetrahedra (studies.study.tet)
    tet_bodies: tuple = field(default=(), compare=False, repr=False)

    @classmethod
    def from_toml(cls, path, quick: bool = False) -> "Study":
        """Read and check the study file ``path`` (:class:`StudyError` on the first key not
        allowed); ``quick`` takes ``[body.quick]``'s values."""
        path = Path(path)
        file = path.name
        try:
            doc = tomllib.loads(path.read_text())
        except FileNotFoundError:
            raise StudyError("FILE", str(path), "an existing study file (.toml)") from None
        except IsADirectoryError:
            raise StudyError("FILE", str(path), "a study file (.toml), not a folder") from None
        except OSError as exc:
            raise StudyError("FILE", str(path), f"a readable study file ({exc.strerror or type(exc).__name__})") \
                from None
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise StudyError("FILE", str(path), f"a TOML file ({' '.join(str(exc).split())})") from None
        top = Table(doc, "", file, folder_of(path))
        body = top.sub("body", required=True)
        source_typo(body)
        if body.has("experiment"):
            return _experiment_study(top, doc, quick)
        return _user_study(top, body, quick)

    # ------------------------------------------------------------------ what it does
    def tasks(self):
        from studies.study.tasks import study_tasks

        if self.experiment is not None:
            from studies.study.experiment import experiment_tasks

            return experiment_tasks(self.experiment, self.quick)
        return study_tasks(self)

    def run(self, out, jobs=None, runner=None, progress=True):
        from studies.study.run import run_study

        return run_study(self, out, jobs=jobs, runner=runner, progress=progress)

    def tables(self, out):
        from studies.study.tables import study_tables

        return study_tables(self, out)

    def report(self, out, pdf: bool = False) -> Path:
        """Write the report (``<out>/report/<name>.html``) with :mod:`reports.study`, in a process
        of its own: imports flow one way (``studies`` <- ``reports``), and the renderer's VTK
        stays out of this one."""
        cmd = [sys.executable, "-m", "reports.study", self.path, str(out)]
        cmd += ["--quick"] * self.quick + ["--pdf"] * pdf
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            last = (proc.stderr.strip().splitlines() or ["no message"])[-1]
            raise RuntimeError(f"the study report failed: {last}")
        return Path(proc.stdout.strip().splitlines()[-1])


# ---------------------------------------------------------------------------- reading steps
def _user_study(top: Table, body: Table, quick: bool) -> Study:
    head = _read_head(top)
    source, voxel_sizes, tet_sizes = _read_body(body, quick)
    has_labels = source.kind == "mask"
    materials = _read_materials(top.sub("material", required=True))
    cases = tuple(_read_load_case(t, has_labels) for t in top.items("load_case", required=True))
    _unique(top, "load_case", [c.name for c in cases])
    runs = tuple(_read_model(t) for t in top.items("model", required=True))
    _unique(top, "model", [m.label for m in runs], "label")
    _unique(top, "model", [FILE_SAFE.sub("_", m.label) for m in runs], "label",
            " once its characters outside A-Z a-z 0-9 _ . + - are _ (it names the VTU files)")
    reference = _read_reference(top.sub("reference"))
    metrics = _read_metrics(top.sub("metrics"), cases)
    top.done()
    checks.check_size(body, functools.partial(grid_shape, source), voxel_sizes, runs,
                      None if tet_sizes else reference, materials)  # a tetrahedral reference: studies.study.tet
    voxels = _voxelize(body, source, voxel_sizes)
    tet_bodies = tet.mesh_tets(body, source, tet_sizes) if tet_sizes else ()
    study = Study(**head, quick=quick, source=source, cell_sizes=tuple(voxel_sizes), materials=materials,
                  load_cases=cases, models=runs, reference=reference, metrics=metrics, voxels=voxels,
                  tet_sizes=tet_sizes, tet_bodies=tet_bodies)
    if tet_bodies:
        tet.check_tet_study(study, top)
    _check_resolutions(study, top)
    _check_points(study, top)
    check_modes(study, top.file)
    checks.check_models(study, top)
    checks.check_time(study, top)
    return study


def _experiment_study(top: Table, doc: dict, quick: bool) -> Study:
    """The shared keys of an ``experiment`` study (the top-level tables, the study's name and
    title), then the experiment's own (:func:`studies.study.experiment.validate_experiment`)."""
    for k in doc:
        if k not in EXPERIMENT_KEYS:
            raise top.error(k, doc[k], f"not a key of an experiment study; allowed: {', '.join(EXPERIMENT_KEYS)}"
                            f"{close(k, EXPERIMENT_KEYS)}")
    t = top.sub("study", required=True)
    name = t.text("name", required=True)
    if not NAME.fullmatch(name):
        raise t.error("name", name, "lower-case letters, digits, - and _ (it names the results folder)")
    title = t.text("title", default=name)
    try:
        from studies.study.experiment import validate_experiment  # the publication's experiments as study files
    except ImportError:
        raise top.error("body.experiment", doc["body"]["experiment"],
                        "a body source this version reads: box, mesh, pyvista or mask") from None
    validate_experiment(doc, top.file)
    return Study(name, title, top.file, str(top.folder / top.file), quick=quick, experiment=doc)


def _read_head(top: Table) -> dict:
    t = top.sub("study", required=True)
    name = t.text("name", required=True)
    if not NAME.fullmatch(name):
        raise t.error("name", name, "lower-case letters, digits, - and _ (it names the results folder)")
    title = t.text("title", default=name)
    budgets = t.numbers("budgets", default=[0.02], lo=0.0, lo_open=True)
    if any(b >= 1 for b in budgets):
        raise t.error("budgets", budgets, "relative error levels in (0, 1)")
    repeats = t.number("repeats", 5, lo=1, hi=100, integer=True)
    t.done()
    return {"name": name, "title": title, "file": t.file, "path": str(t.folder / t.file), "budgets": tuple(budgets),
            "repeats": repeats}


def _read_body(t: Table, quick: bool) -> tuple[BodySource, list[float], tuple[float, ...]]:
    q = t.sub("quick")
    if q is not None:
        for k in q.data:
            if k not in ("cell_sizes", "tet_sizes"):
                raise q.error(k, q.data[k], f"only cell_sizes and tet_sizes may change under --quick"
                              f"{close(k, ('cell_sizes', 'tet_sizes'))}")
        q.numbers("cell_sizes", required=True, lo=0.0, lo_open=True)  # checked with or without --quick
        q.numbers("tet_sizes", lo=0.0, lo_open=True)
        if quick:
            t.data = {**t.data, **q.data}
    source, _ = read_source(t)
    sizes = cell_sizes(t, source)
    tet_sizes = tet.read_tet_sizes(t, source)
    t.done()
    return source, sizes, tet_sizes


def _read_materials(t: Table) -> tuple[Material, ...]:
    E = t.numbers("E", required=True, lo=checks.E_RANGE[0], hi=checks.E_RANGE[1], allow_scalar=True)
    nu = t.numbers("nu", required=True, allow_scalar=True)
    lo, hi = NU_OPEN_RANGE
    if any(not lo < v < hi for v in nu):
        raise t.error("nu", t.data["nu"], f"a number in ({lo:g}, {hi:g}) or a list of them")
    rho = t.numbers("rho", default=[1000.0], lo=0.0, hi=checks.RHO_MAX, allow_scalar=True)
    t.done()
    return tuple(Material(*m) for m in itertools.product(E, nu, rho))


def _read_load_case(t: Table, has_labels: bool) -> LoadCase:
    name = t.text("name", required=True)
    if not NAME.fullmatch(name):
        raise t.error("name", name, "lower-case letters, digits, - and _ (it names files)")
    gravity = t.numbers("gravity", 3, default=[0.0, 0.0, 0.0])
    supports = tuple(read_support(s, has_labels) for s in t.items("support"))
    if not supports:
        raise t.error("support", "(none)", "at least one support: a body without one is unsupported (free "
                      "to move as a rigid body)")
    _unique(t, "support", [s.name for s in supports])
    tractions = tuple(read_traction(s, has_labels) for s in t.items("traction"))
    release = read_release(t, gravity, tractions)
    t.done()
    return LoadCase(name, tuple(gravity), supports, tractions, release)


def _read_model(t: Table) -> ModelRun:
    name = t.text("name", required=True)
    try:
        spec = registry.get(name)
    except ValueError:
        why = registry.unavailable().get(name)
        raise t.error("name", name, f"a registered model: {', '.join(registry.names())}"
                      + (f" ({name} is unavailable: {why})" if why else close(name, registry.names()))) from None
    params = t.raw("params", {})
    if not isinstance(params, dict):
        raise t.error("params", params, f"a table of model {name}'s parameters")
    try:
        values = spec.parameters(**params)
    except (TypeError, ValueError) as exc:
        hint = "".join(close(k, spec.parameter_names()) for k in params if k not in spec.parameter_names())
        raise t.error("params", params, f"model {name}'s parameters ({' '.join(str(exc).split())}){hint}") from None
    label = t.text("label", default=spec.variant(values))
    if not PRINTABLE.fullmatch(label):
        raise t.error("label", label, "printable ASCII characters (a label names files, table columns and legends)")
    solver = _read_solver(t, spec)
    expect = read_expected(t)
    t.done()
    return ModelRun(name, tuple(sorted(params.items())), label, **solver, expect_no_result=expect)


def _read_solver(t: Table, spec) -> dict:
    value = t.raw("solver", "static")
    if isinstance(value, str):
        if value != "static":
            raise t.error("solver", value, '"static" or a table {kind = "explicit" | "implicit", dt, steps, ...}')
        out = {"kind": "static"}
    else:
        s = t.sub("solver")
        kind = s.text("kind", required=True, choices=SOLVER_KINDS)
        out = {"kind": kind}
        if kind != "static":
            out["dt"] = s.number("dt", required=True, lo=0.0, lo_open=True)
            out["steps"] = s.number("steps", required=True, lo=1, integer=True)
            out["ramp_time"] = s.number("ramp_time", 1.0, lo=0.0)
            out["damping"] = s.number("damping", 0.0, lo=0.0)
        s.done()
    if not spec.supports(out["kind"]):
        raise t.error("solver", value, f"a solver model {spec.name} supports: {', '.join(spec.solvers)}")
    return out


def _read_reference(t: Table | None) -> Reference:
    if t is None:
        return Reference()
    element = t.text("element", "auto", choices=ELEMENTS)
    law = t.text("law", "linear", choices=LAWS)
    refine = t.raw("refine", 1)
    if refine != "auto":
        refine = t.number("refine", 1, lo=1, hi=4, integer=True)
    tolerance = t.number("tolerance", 0.25, lo=0.0, hi=1.0, lo_open=True)
    t.done()
    return Reference(element, law, refine, tolerance)


def _read_metrics(t: Table | None, cases: tuple[LoadCase, ...]) -> Metrics:
    if t is None:
        return Metrics()
    names = {s.name for c in cases for s in c.supports}
    forces = t.raw("plate_force", [])
    if not isinstance(forces, list) or not all(isinstance(f, str) for f in forces):
        raise t.error("plate_force", forces, "a list of support names")
    for f in forces:
        if f not in names:
            raise t.error("plate_force", forces, f"names of supports ({', '.join(sorted(names))}){close(f, names)}")
    volume = t.flag("volume_change", True)
    displacement = t.flag("displacement", True)
    p = t.sub("points")
    points = ()
    if p is not None:
        points = tuple((k, tuple(p.numbers(k, 3))) for k in list(p.data))
        for k, _ in points:
            if not PRINTABLE.fullmatch(k):
                raise p.error(k, list(p.data[k]), "a point named in printable ASCII characters (it names a table "
                              "column)")
    modes = read_modes(t)
    point = read_point(t, points, cases)
    t.done()
    return Metrics(tuple(forces), volume, displacement, points, modes, point)


def _unique(t: Table, key: str, names: list[str], what: str = "name", how: str = "") -> None:
    seen = set()
    for i, n in enumerate(names):
        if n in seen:
            raise StudyError(f"{t.key(key)}[{i}].{what}", n, f"a {what} unique among the {key} tables{how}", t.file)
        seen.add(n)


# ---------------------------------------------------------------------------- whole-file checks
def _voxelize(t: Table, source: BodySource, sizes: list[float]) -> tuple[Voxels, ...]:
    out = []
    for le in sizes:
        try:
            out.append(source.voxels(le))
        except ValueError as exc:
            raise t.error("cell_sizes", sizes, f"cell sizes that leave cells in the body ({le:g}: "
                          f"{' '.join(str(exc).split())})") from None
    body_checks(t, source, sizes, out)
    return tuple(out)


def _check_resolutions(study: Study, top: Table) -> None:
    """Every support selects nodes, every traction surface faces, and every piece of the body is
    held against the six rigid motions, at every resolution."""
    for vox in study.voxels:
        X = Lattice.from_body(vox.body).X
        pieces, n_pieces = vox.pieces()
        node_piece = _node_pieces(vox.body, pieces)
        for i, case in enumerate(study.load_cases):
            where = f"load_case[{i}]"
            plates = []
            for j, s in enumerate(case.supports):
                plate = s.plate(vox.labels)
                sel = plate.region.select(X, vox.body)
                if not sel.any():
                    raise StudyError(f"{where}.support[{j}].region", _region_text(s.region),
                                     f"a region that selects nodes of the body (none at cell size {vox.le:g} m)",
                                     top.file)
                plates.append((plate, sel))
            for j, tr in enumerate(case.tractions):
                if not len(tr.load(vox.labels).faces(vox.body)[0]):
                    raise StudyError(f"{where}.traction[{j}].region", _region_text(tr.region),
                                     f"a region that holds surface faces of the body (none at cell size "
                                     f"{vox.le:g} m)", top.file)
            checks.check_supports_agree(top, where, vox, X, plates)
            _check_held(top, where, vox, X, node_piece, n_pieces, plates)
            _check_crossing(top, where, vox, case, plates)


def _node_pieces(body, pieces: np.ndarray) -> np.ndarray:
    """The piece of each lattice node (a node shared by two pieces cannot exist: pieces touching
    at a node are one face-connected body only if they share a face; such a node gets the
    lowest piece number, and the check below holds each piece by its own nodes)."""
    lat = Lattice.from_body(body)
    node = np.zeros(lat.n_particles, dtype=np.int64)
    cell_piece = pieces[body.mask]
    for c in range(8):
        idx = lat.cells[:, c]
        node[idx] = np.where(node[idx] == 0, cell_piece, np.minimum(node[idx], cell_piece))
    return node


def _check_held(top, where, vox, X, node_piece, n_pieces, plates) -> None:
    for piece in range(1, n_pieces + 1):
        on = node_piece == piece
        held = held_modes(X[on], [(sel[on], p.motion.components) for p, sel in plates])
        if held < 6:
            what = f"piece {piece} of {n_pieces} of the body (it falls apart at cell size {vox.le:g} m)" \
                if n_pieces > 1 else "the body"
            raise StudyError(f"{where}.support", [p.name for p, _ in plates],
                             f"supports that hold {what} against the 6 rigid motions: these stop "
                             f"{held} of 6, so it is unsupported", top.file)


def _check_crossing(top, where, vox, case, plates) -> None:
    scene = Scene(vox.body, Material(1.0, 0.0), plates=tuple(p for p, _ in plates))
    why = plates_cross(scene)
    if why:
        raise StudyError(f"{where}.support", [p.name for p, _ in plates], f"plates that stay apart ({why})", top.file)


def _check_points(study: Study, top: Table) -> None:
    for name, xyz in study.metrics.points:
        for vox in study.voxels:
            lo, hi = vox.body.bounds
            if np.any(np.asarray(xyz) < lo - vox.le) or np.any(np.asarray(xyz) > hi + vox.le):
                raise StudyError(f"metrics.points.{name}", list(xyz), f"a point in the body's bounding box "
                                 f"{lo.tolist()} to {hi.tolist()} (m)", top.file)


def _region_text(region) -> str:
    return str({k: v for k, v in dataclasses.asdict(region).items() if v is not None})


__all__ = ["Study", "LoadCase", "ModelRun", "Reference", "Metrics", "Load"]
