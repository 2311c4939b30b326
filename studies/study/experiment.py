"""A study file whose body is one of the publication's experiments (``[body] experiment = ...``):
its validation and its runs (the format: ``docs/study-format.md``, second half).

Such a file names an experiment of :mod:`hybmss.experiments` (its body, plates and load), the
lattices it is meshed with, the material and the load parameters (each a value or a list: every
combination is one configuration), the models with their solvers and the FEM reference.  The
publication's studies are files of this kind (``studies/data/studies/*.toml``,
:mod:`studies.paper.reproduce`).

- :func:`validate_experiment` checks every key before any work (:class:`StudyError` naming the
  key, its value and what is allowed; unknown keys with their close matches);
- :func:`experiment_tasks` turns the parsed file into the runner's tasks.

A configuration is one combination, in this order, of ``body.mesh``, ``material.E``,
``material.nu``, ``material.rho`` and the ``[load]`` fields (deformation, angle_deg, gravity).
Its runs are listed model by model (the registry's order), each model's parameter sets in its
study order (:meth:`hybmss.models.base.ModelBase.study_variants`), each with the solvers of the
``[[model]]`` entries that include it (in the file's order); then the FEM references: ``law``
(up to ``law_up_to``, when given) and, when the load is large (its measure above
``large_above``), each of ``large_laws``.  The load's measure is the experiment's load
parameter: ``deformation`` (compression, tension, shear, uniaxial), ``angle_deg`` (torsion),
``gravity`` (bending), by magnitude.

A model whose study part gives it meshes of its own (:attr:`studies.sweep.roles.Part.meshes`: the
engines, whose damped runs to rest cost far more than a Newton solve) runs each configuration on
its own mesh (:func:`studies.sweep.roles.mesh_for`), with the file's FEM references solved on that mesh
too, so that its row is compared with the FEM of its own mesh.  Its runs and their references
follow the configuration's references (one mesh after the other, in the order the models first
give them); a run or reference that two configurations share (the full tension study's two beams
map to one coarse beam) is listed once, at its first place.  In the quick mode such a model runs
the :func:`quick_case` only, and not at all when its part says ``quick=False``; an entry with
``meshes = "file"`` keeps its models on the file's meshes.

The drivers' files (``docs/study-format.md``, "What the drivers' study files add") also give a
list of experiments, ``[material.quick]``, ``[[model]] engines = true`` (every registered engine
model), no ``[reference]`` (no FEM runs) and ``[[table]]`` hooks (:data:`TABLE_HOOKS`,
:func:`file_tables`).
"""

from __future__ import annotations

import itertools
import json
import math
import re

from hybmss import models
from hybmss.experiments import DEFAULTS, EXPERIMENTS, REGISTRY, ParameterError, Range, SceneSpec

from studies.sweep import roles
from studies.sweep.runner import SolverSpec, Task

from studies.study.errors import StudyError
from studies.study.keys import close

BODY_KEYS = ("experiment", "mesh", "quick")
QUICK_KEYS = ("mesh",)
MATERIAL_KEYS = ("E", "nu", "rho")
MODEL_KEYS = ("role", "name", "engines", "params", "defaults_only", "skip_quick", "solver", "meshes")
MESH_POLICIES = ("own", "file")
"""``[[model]] meshes``: ``own``, a model whose study part gives it meshes of its own runs on them
(the default); ``file``, every model runs on the file's meshes."""
SOLVER_KEYS = {"static": ("kind",), "explicit": ("kind", "dt", "steps", "ramp_time", "damping", "kernel", "until_rest"),
               "implicit": ("kind", "dt", "steps", "ramp_time", "damping")}
REFERENCE_KEYS = ("element", "law", "refine", "large_laws", "large_above", "law_up_to")
TOP_KEYS = ("study", "body", "material", "load", "model", "reference", "table")
TABLE_KEYS = ("name", "hook", "repeats", "quick")
TABLE_HOOKS = ("engines-closing", "engines-timing", "regression", "b09-volume")
"""The table hooks a ``[[table]]`` may name: tables of the publication's drivers that a study file
declares and whose code :data:`studies.paper.reproduce.TABLE_HOOKS` holds (a ``hybmss study``
run of the file writes its own tables and leaves them out)."""
STUDY_KEYS = ("name", "title")

LOAD_MEASURE = {name: e.load for name, e in REGISTRY.items()}
"""The load parameter whose magnitude says whether an experiment's load is large (the registry's
:attr:`hybmss.experiments.Experiment.load`)."""

AT_THRESHOLD = 1e-12
"""A load within this of ``large_above`` (or ``law_up_to``) counts as at it, not above."""

_NAME = re.compile(r"^[a-z0-9_-]+$")
_SCENE_FIELDS = {f.name: f for f in SceneSpec.parameters()}


# ----------------------------------------------------------------------------------- checks
def _fail(path, key, value, allowed):
    raise StudyError(key, value, allowed, path)


def _unknown(path, where: str, table: dict, allowed) -> None:
    for k, v in table.items():
        if k not in allowed:
            _fail(path, f"{where}.{k}" if where else k, v, f"a key among {', '.join(allowed)}{close(k, allowed, 1)}")


def _table(path, doc: dict, key: str, required: bool = True) -> dict:
    value = doc.get(key)
    if value is None:
        if required:
            _fail(path, key, None, "a table (it is required)")
        return {}
    if not isinstance(value, dict):
        _fail(path, key, value, "a table")
    return value


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _values(value) -> list:
    """A value or a list of values (a sweep) as a list."""
    return list(value) if isinstance(value, list) else [value]


def _number_or_list(path, key: str, value, rng: Range | None, unit: str = "") -> list[float]:
    vals = _values(value)
    if not vals:
        _fail(path, key, value, "a number or a non-empty list of numbers")
    for v in vals:
        if not _is_number(v):
            _fail(path, key, value, "a number or a non-empty list of numbers")
        if rng is not None and v not in rng:
            _fail(path, key, v, f"a number in {rng}{' ' + unit if unit else ''}")
    return [float(v) for v in vals]


def _meshes(path, key: str, value, empty_ok: bool) -> list[tuple[int, int, int]]:
    allowed = "a list of meshes [NX, NY, NZ], each an integer >= 1" + ("" if empty_ok else ", not empty")
    if not isinstance(value, list) or (not value and not empty_ok):
        _fail(path, key, value, allowed)
    for m in value:
        if not (isinstance(m, list) and len(m) == 3 and all(_is_int(n) and n >= 1 for n in m)):
            _fail(path, key, m, allowed)
    return [tuple(m) for m in value]


def _bool(path, key: str, value) -> bool:
    if not isinstance(value, bool):
        _fail(path, key, value, "true or false")
    return value


def _check_study(path, doc: dict) -> None:
    study = _table(path, doc, "study")
    _unknown(path, "study", study, STUDY_KEYS)
    name = study.get("name")
    if not isinstance(name, str) or not _NAME.match(name):
        _fail(path, "study.name", name, "a name of [a-z0-9_-]+ (it is required)")
    if "title" in study and not isinstance(study["title"], str):
        _fail(path, "study.title", study["title"], "a string")


def _check_body(path, doc: dict) -> str:
    body = _table(path, doc, "body")
    _unknown(path, "body", body, BODY_KEYS)
    experiment = body.get("experiment")
    names = experiment if isinstance(experiment, list) else [experiment]
    if not names or len(set(map(str, names))) < len(names) or any(n not in EXPERIMENTS for n in names):
        _fail(path, "body.experiment", experiment, f"one of {', '.join(EXPERIMENTS)}, or a list of distinct ones")
    if "mesh" in body:
        _meshes(path, "body.mesh", body["mesh"], empty_ok=False)
    if "quick" in body:
        quick = _table(path, body, "quick")
        _unknown(path, "body.quick", quick, QUICK_KEYS)
        if "mesh" in quick:  # may be empty: the study has no run under --quick
            _meshes(path, "body.quick.mesh", quick["mesh"], empty_ok=True)
    return experiment


def _check_material(path, doc: dict) -> None:
    material = _table(path, doc, "material", required=False)
    _unknown(path, "material", material, MATERIAL_KEYS + ("quick",))
    quick = material.get("quick", {})
    if not isinstance(quick, dict):
        _fail(path, "material.quick", quick, "a table of material values that replace these under --quick")
    _unknown(path, "material.quick", quick, MATERIAL_KEYS)
    for where, table in (("material", material), ("material.quick", quick)):
        for k, v in table.items():
            if k in MATERIAL_KEYS:
                f = _SCENE_FIELDS[k]
                _number_or_list(path, f"{where}.{k}", v, f.metadata["ranges"], f.metadata["unit"])


def _load_keys(experiment: str) -> tuple[str, ...]:
    return tuple(n for n, f in _SCENE_FIELDS.items()
                 if f.metadata["experiments"] is not None and experiment in f.metadata["experiments"])


def experiments_of(doc: dict) -> list[str]:
    """The experiments of the file's ``[body] experiment`` (a name or a list of them)."""
    e = doc["body"]["experiment"]
    return list(e) if isinstance(e, list) else [e]


def _check_load(path, doc: dict) -> None:
    """Each ``[load]`` key is the load parameter of one of the file's experiments, in its range
    for each of them that takes it."""
    load = _table(path, doc, "load", required=False)
    names = experiments_of(doc)
    allowed = tuple(dict.fromkeys(k for e in names for k in _load_keys(e)))
    for k, v in load.items():
        if k not in allowed:
            _fail(path, f"load.{k}", v, f"{' and '.join(names)} take{'s' if len(names) == 1 else ''} "
                  f"{', '.join(allowed)}{close(k, allowed, 1)}")
        f = _SCENE_FIELDS[k]
        for e in names:
            if k in _load_keys(e):
                rng = f.metadata["ranges"]
                rng = rng.get(e) if isinstance(rng, dict) else rng
                _number_or_list(path, f"load.{k}", v, rng, f.metadata["unit"])


def _check_solver(path, key: str, solver) -> str:
    if solver == "static":
        return "static"
    if not isinstance(solver, dict):
        _fail(path, key, solver, '"static" or a table {kind = "explicit" | "implicit", dt, steps, ...}')
    kind = solver.get("kind")
    if kind not in SOLVER_KEYS:
        _fail(path, f"{key}.kind", kind, f"one of {', '.join(SOLVER_KEYS)}")
    _unknown(path, key, solver, SOLVER_KEYS[kind])
    for k, ok, allowed in (("dt", lambda v: _is_number(v) and v > 0, "a number > 0 (s)"),
                           ("steps", lambda v: _is_int(v) and v >= 1, "an integer >= 1"),
                           ("ramp_time", lambda v: _is_number(v) and v >= 0, "a number >= 0 (s)"),
                           ("damping", lambda v: _is_number(v) and v >= 0, "a number >= 0 (1/s)"),
                           ("kernel", lambda v: v in ("numba", "numpy"), "numba or numpy"),
                           ("until_rest", lambda v: isinstance(v, bool), "true or false")):
        if k in solver and not ok(solver[k]):
            _fail(path, f"{key}.{k}", solver[k], allowed)
    return kind


def _check_models(path, doc: dict) -> None:
    entries = doc.get("model")
    if not isinstance(entries, list) or not entries or not all(isinstance(e, dict) for e in entries):
        _fail(path, "model", entries, "one or more [[model]] tables")
    for i, e in enumerate(entries):
        key = f"model[{i}]"
        _unknown(path, key, e, MODEL_KEYS)
        if sum(k in e for k in ("role", "name", "engines")) != 1:
            _fail(path, key, {k: e[k] for k in ("role", "name", "engines") if k in e} or None,
                  "exactly one of role (every model of a study role), name (one registered model) or "
                  "engines = true (every registered model an engine steps)")
        for flag in ("defaults_only", "skip_quick"):
            if flag in e:
                _bool(path, f"{key}.{flag}", e[flag])
        if "meshes" in e and e["meshes"] not in MESH_POLICIES:
            _fail(path, f"{key}.meshes", e["meshes"], f"one of {', '.join(MESH_POLICIES)} (own: a model's own "
                  "meshes where its study part gives it some; file: the file's meshes)")
        kind = _check_solver(path, f"{key}.solver", e.get("solver", "static"))
        if "engines" in e:
            _check_engines(path, key, e, kind)
            continue
        if "role" in e:
            if e["role"] not in roles.STUDY_ROLES:
                _fail(path, f"{key}.role", e["role"], f"one of {', '.join(roles.STUDY_ROLES)}")
            if "params" in e:
                _fail(path, f"{key}.params", e["params"], "parameters only with name (a role's models take "
                      "their study variants, or their defaults with defaults_only)")
            lacking = [m for m in roles.in_role(e["role"]) if kind not in models.get(m).solvers]
            if lacking:
                _fail(path, f"{key}.solver", kind, f"a solver every model of role {e['role']!r} has "
                      f"({lacking[0]} has {', '.join(models.get(lacking[0]).solvers)})")
            continue
        name = e["name"]
        if name not in models.names():
            why = models.unavailable().get(name)
            _fail(path, f"{key}.name", name, f"a registered model: {', '.join(models.names())}"
                  + (f" ({name} is unavailable: {why})" if why else close(name, models.names(), 1)))
        if "defaults_only" in e:
            _fail(path, f"{key}.defaults_only", e["defaults_only"], "only with role (a named model runs "
                  "its defaults or the given params)")
        if kind not in models.get(name).solvers:
            _fail(path, f"{key}.solver", kind, f"a solver of {name}: {', '.join(models.get(name).solvers)}")
        params = e.get("params", {})
        if not isinstance(params, dict):
            _fail(path, f"{key}.params", params, f"a table of {name}'s parameters")
        clash = [k for k in params if k in _SCENE_FIELDS or k == "experiment"]
        if clash:
            _fail(path, f"{key}.params.{clash[0]}", params[clash[0]], f"a parameter of {name}: "
                  f"{', '.join(models.get(name).parameter_names()) or 'it has none'}")
        try:
            models.get(name).parameters(**params)
        except (TypeError, ValueError) as exc:
            _fail(path, f"{key}.params", params, f"{name}'s parameters ({' '.join(str(exc).split())})")


def engine_models() -> tuple[str, ...]:
    """The registered models an engine steps (kernel ``engine``), in the registry's order."""
    return tuple(n for n in models.names() if models.get(n).kernels == ("engine",))


def _check_engines(path, key: str, e: dict, kind: str) -> None:
    if e["engines"] is not True:
        _fail(path, f"{key}.engines", e["engines"], "true (every registered model an engine steps)")
    for k in ("params", "defaults_only"):
        if k in e:
            _fail(path, f"{key}.{k}", e[k], "only with role or name (the engines run their defaults)")
    lacking = [m for m in engine_models() if kind not in models.get(m).solvers]
    if lacking:
        _fail(path, f"{key}.solver", kind, f"a solver every engine model has ({lacking[0]} has "
              f"{', '.join(models.get(lacking[0]).solvers)})")


def _check_tables(path, doc: dict) -> None:
    entries = doc.get("table", [])
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        _fail(path, "table", entries, "[[table]] tables, each {name, hook}")
    names = set()
    for i, e in enumerate(entries):
        key = f"table[{i}]"
        _unknown(path, key, e, TABLE_KEYS)
        name = e.get("name")
        if not isinstance(name, str) or not _NAME.match(name) or name in names:
            _fail(path, f"{key}.name", name, "a name of [a-z0-9_-]+ that no other [[table]] has (it is required)")
        names.add(name)
        if e.get("hook") not in TABLE_HOOKS:
            _fail(path, f"{key}.hook", e.get("hook"), f"one of {', '.join(TABLE_HOOKS)}"
                  + close(str(e.get("hook")), TABLE_HOOKS, 1))
        quick = e.get("quick", {})
        if not isinstance(quick, dict):
            _fail(path, f"{key}.quick", quick, "a table of values that replace these under --quick (repeats)")
        _unknown(path, f"{key}.quick", quick, ("repeats",))
        for where, table in ((key, e), (f"{key}.quick", quick)):
            if "repeats" in table and not (_is_int(table["repeats"]) and 1 <= table["repeats"] <= 100):
                _fail(path, f"{where}.repeats", table["repeats"], "an integer in [1, 100] (timed repeats: "
                      "the best is kept)")


def file_tables(doc: dict, quick: bool = False) -> list[dict]:
    """The ``[[table]]`` entries of the validated file ``doc``: ``name``, ``hook`` and ``repeats``
    (``None`` when not given), the ``quick`` values in place under ``quick``."""
    out = []
    for e in doc.get("table", []):
        values = {**e, **(e.get("quick", {}) if quick else {})}
        out.append({"name": e["name"], "hook": e["hook"], "repeats": values.get("repeats")})
    return out


def _check_reference(path, doc: dict) -> None:
    from fem_reference.solve import ELEMENT_CHOICES, LAW_CHOICES

    if "reference" not in doc:  # a study of the models alone (their runs feed a table hook)
        return
    ref = _table(path, doc, "reference")
    _unknown(path, "reference", ref, REFERENCE_KEYS)
    if "element" in ref and ref["element"] not in ELEMENT_CHOICES:
        _fail(path, "reference.element", ref["element"], f"one of {', '.join(ELEMENT_CHOICES)}")
    if "law" in ref and ref["law"] not in LAW_CHOICES:
        _fail(path, "reference.law", ref["law"], f"one of {', '.join(LAW_CHOICES)}")
    if "refine" in ref and not (_is_int(ref["refine"]) and ref["refine"] >= 1):
        _fail(path, "reference.refine", ref["refine"], "an integer >= 1")
    large = ref.get("large_laws", [])
    if not isinstance(large, list) or any(law not in LAW_CHOICES for law in large) or len(set(large)) < len(large):
        _fail(path, "reference.large_laws", large, f"a list of distinct laws among {', '.join(LAW_CHOICES)}")
    if ref.get("law", "linear") in large:
        _fail(path, "reference.large_laws", large, f"laws other than law ({ref.get('law', 'linear')})")
    if large and "large_above" not in ref:
        _fail(path, "reference.large_above", None, "a number >= 0 (required with large_laws: the load "
              "above which they are solved)")
    for k in ("large_above", "law_up_to"):
        if k in ref and not (_is_number(ref[k]) and ref[k] >= 0):
            _fail(path, f"reference.{k}", ref[k], "a number >= 0 (the magnitude of the experiment's load: "
                  "deformation, angle_deg or gravity)")


def _check_configurations(path, doc: dict) -> None:
    """Every configuration, as the experiment builds it, passes the scene's own checks (e.g. a
    plate on each end needs two cell layers)."""
    which = {"mesh": "body.mesh", **{k: f"material.{k}" for k in MATERIAL_KEYS},
             **{k: f"load.{k}" for e in experiments_of(doc) for k in _load_keys(e)}}
    for quick in (False, True):
        for spec in configurations(doc, quick):
            try:
                spec.check()
            except ParameterError as exc:
                key = which.get(exc.name, exc.name)
                if quick and key == "body.mesh" and "mesh" in doc["body"].get("quick", {}):
                    key = "body.quick.mesh"
                why = str(exc).split(" is not allowed: ", 1)[-1]
                why = why[:-len(f"allowed: {exc.allowed}")].rstrip("; ")
                _fail(path, key, exc.value, f"{exc.allowed}" + (f" ({' '.join(why.split())})" if why else ""))
            except ValueError as exc:  # the material's own constraints
                _fail(path, "material", {k: getattr(spec, k) for k in MATERIAL_KEYS}, " ".join(str(exc).split()))


def validate_experiment(doc: dict, path: str | None = None) -> None:
    """Check every key of the parsed study file ``doc`` whose body is an experiment; raise
    :class:`StudyError` (key, value, what is allowed; ``path`` names the file) at the first
    that is not allowed."""
    if not isinstance(doc, dict):
        _fail(path, "(file)", doc, "a TOML document")
    _unknown(path, "", doc, TOP_KEYS)
    _check_study(path, doc)
    _check_body(path, doc)
    _check_material(path, doc)
    _check_load(path, doc)
    _check_models(path, doc)
    _check_reference(path, doc)
    _check_tables(path, doc)
    _check_configurations(path, doc)


# ----------------------------------------------------------------------------------- runs
def configurations(doc: dict, quick: bool) -> list[SceneSpec]:
    """The file's configurations: one scene per combination of experiment, mesh, material and
    load values (each experiment with its own load parameters)."""
    body = doc["body"]
    out = []
    for experiment in experiments_of(doc):
        meshes = body.get("mesh", [list(DEFAULTS[experiment]["mesh"])])
        if quick and "mesh" in body.get("quick", {}):
            meshes = body["quick"]["mesh"]
        material, load = doc.get("material", {}), doc.get("load", {})
        if quick:
            material = {**material, **material.get("quick", {})}
        axes = [("mesh", [tuple(int(n) for n in m) for m in meshes])]
        axes += [(k, [float(v) for v in _values(material[k])]) for k in MATERIAL_KEYS if k in material]
        axes += [(k, [float(v) for v in _values(load[k])]) for k in _load_keys(experiment) if k in load]
        names = [k for k, _ in axes]
        out += [SceneSpec.default(experiment, **dict(zip(names, combo)))
                for combo in itertools.product(*(vals for _, vals in axes))]
    return out


def _solver(entry: dict):
    """(solver, scene damping or None) of a ``[[model]]`` entry."""
    s = entry.get("solver", "static")
    if s == "static":
        return SolverSpec("static"), None
    kw = {k: (float(v) if k in ("dt", "ramp_time") else v) for k, v in s.items() if k not in ("kind", "damping")}
    damping = float(s["damping"]) if "damping" in s else None
    return SolverSpec(s["kind"], **kw), damping


def load_measure(spec: SceneSpec) -> float:
    """The magnitude of ``spec``'s load (:data:`LOAD_MEASURE`)."""
    return abs(float(getattr(spec, LOAD_MEASURE[spec.experiment])))


def reference_solvers(ref: dict, spec: SceneSpec) -> list:
    """The FEM references of the configuration ``spec`` (module docstring)."""
    if ref is None:
        return []
    element, law, refine = ref.get("element", "auto"), ref.get("law", "linear"), ref.get("refine", 1)
    load = load_measure(spec)
    laws = [] if "law_up_to" in ref and load > ref["law_up_to"] + AT_THRESHOLD else [law]
    if ref.get("large_laws") and load > ref["large_above"] + AT_THRESHOLD:
        laws += list(ref["large_laws"])
    return [SolverSpec("fem", element=element, law=lw, refine=refine) for lw in laws]


def quick_case(configurations: list[SceneSpec]) -> SceneSpec | None:
    """The configuration a model with meshes of its own runs in the quick mode: the one nearest
    ν = 1/4 at the smallest load (compression, tension, shear: ν = 1/4, d = 5 %; torsion: 1°),
    the first of them in the file's order; ``None`` when there is none."""
    if not configurations:
        return None
    return min(configurations, key=lambda s: (abs(float(s.nu) - 0.25), load_measure(s)))


def _own_mesh(model: str, entry: dict) -> bool:
    return entry.get("meshes", "own") == "own" and bool(roles.part(model).meshes)


def experiment_tasks(doc: dict, quick: bool = False) -> list:
    """The runner's tasks (:class:`studies.sweep.runner.Task`, study ``[study] name``) of the parsed
    experiment study ``doc``, at the file's ``[body.quick]`` meshes and without its
    ``skip_quick`` models when ``quick`` (order: module docstring).  Raises :class:`StudyError`
    for a file :func:`validate_experiment` refuses."""
    validate_experiment(doc)
    study = doc["study"]["name"]
    order = {n: i for i, n in enumerate(models.names())}
    entries = [e for e in doc["model"] if not (quick and e.get("skip_quick", False))]
    configs = configurations(doc, quick)
    first = quick_case(configs) if quick else None
    tasks, seen = [], set()

    def add(ts):
        for t in ts:
            k = (t.scene, json.dumps(t.solver.relevant(), sort_keys=True), t.study)
            if k not in seen:
                seen.add(k)
                tasks.append(t)

    for spec in configs:
        runs = []  # (model's position, parameter set's position, entry's position, task)
        own = {}  # a mesh of a model's own -> its runs, as ``runs``
        for j, e in enumerate(entries):
            solver, damping = _solver(e)
            if "engines" in e:
                names = engine_models()
                sets = {m: [{}] for m in names}
            elif "role" in e:
                names = roles.in_role(e["role"])
                sets = {m: ([{}] if e.get("defaults_only", False) else list(models.get(m).study_variants(spec.nu)))
                        for m in names}
            else:
                names = [e["name"]]
                sets = {e["name"]: [dict(e.get("params", {}))]}
            for m in names:
                base = spec
                if _own_mesh(m, e):
                    if quick and (not roles.part(m).quick or spec is not first):
                        continue
                    base = roles.mesh_for(m, spec)
                variants = [dict(v) for v in models.get(m).study_variants(spec.nu)]
                for params in sets[m]:
                    scene = base.replace(model=m, **params)
                    if damping is not None:
                        scene = scene.replace(damping=damping)
                    at = variants.index(params) if params in variants else len(variants)
                    into = runs if base.mesh == spec.mesh else own.setdefault(base, [])
                    into.append((order[m], at, j, Task(scene, solver, study)))
        add(r[3] for r in sorted(runs, key=lambda r: r[:3]))
        add(Task(spec, fs, study) for fs in reference_solvers(doc.get("reference"), spec))
        for base, mine in own.items():  # each mesh of a model's own, with the FEM on that mesh
            add(r[3] for r in sorted(mine, key=lambda r: r[:3]))
            add(Task(base, fs, study) for fs in reference_solvers(doc.get("reference"), base))
    return tasks
