"""The drivers' studies as study files (``studies/data/studies/engines.toml``, ``regression-*.toml``,
``b09-volume-*.toml``): the runs they give are the runs the drivers built in Python before
(rebuilt here from the experiments' specifications, independently of the files), and every key
the format grew for them (an experiment list, ``[material.quick]``, ``[[model]] engines`` and
``meshes``, ``[[table]]``, no ``[reference]``) is checked before any work, naming the key."""

from __future__ import annotations

import copy

import pytest

from hybmss import models
from hybmss.experiments import SceneSpec


def _doc(name: str) -> dict:
    from studies.paper.reproduce import load_study_file

    return copy.deepcopy(load_study_file(name))


def _keys(tasks) -> list[str]:
    return sorted(t.key() for t in tasks)


# ------------------------------------------------------------------------------ same runs
@pytest.mark.parametrize("quick", [True, False])
def test_the_engines_file_gives_every_engine_and_the_context_on_the_file_s_cube(quick):
    """Compression and shear at 5 % on the 10³ cube for ν = 0.25, 0.45, 0.499 (quick: the 2³ cube
    at ν = 0.25): every engine model and hybmss and corot-hex8, static, and the linear FEM, each on
    the file's cube (not on an engine's own coarse mesh)."""
    from studies.paper import engines
    from studies.sweep.runner import SolverSpec, Task

    mesh, nus = ((2, 2, 2), (0.25,)) if quick else ((10, 10, 10), (0.25, 0.45, 0.499))
    engine = [m for m in models.names() if models.get(m).kernels == ("engine",)]
    assert engine, "no engine model registered"
    want = []
    for e in ("compression", "shear"):
        for nu in nus:
            spec = SceneSpec.default(e, mesh=mesh, nu=nu, deformation=0.05)
            want += [Task(spec.replace(model=m), SolverSpec("static")) for m in engine + ["hybmss", "corot-hex8"]]
            want.append(Task(spec, SolverSpec("fem", element="auto", law="linear")))
    got = engines.tasks(quick)
    assert _keys(got) == _keys(want)
    assert {t.scene.mesh for t in got} == {mesh}
    assert [(s.experiment, s.nu) for s in engines.specs(quick)] == [(e, nu) for e in ("compression", "shear")
                                                                    for nu in nus]


def test_the_regression_files_give_the_ci_cases():
    from studies.paper.reproduce import DRIVER_STUDIES
    from studies.sweep import roles
    from studies.sweep.runner import SolverSpec, Task

    specs = [SceneSpec.default("bending", mesh=(2, 2, 12), E=1e7, nu=0.25, gravity=10.0)]
    for nu in (0.0, 0.25, 0.499):
        specs += [SceneSpec.default("compression", mesh=(4, 4, 4), nu=nu, deformation=0.05),
                  SceneSpec.default("tension", mesh=(2, 2, 12), nu=nu, deformation=0.05),
                  SceneSpec.default("shear", mesh=(4, 4, 4), nu=nu, deformation=0.05),
                  SceneSpec.default("torsion", mesh=(4, 4, 4), nu=nu, angle_deg=1.0)]
    want = [Task(s, SolverSpec("fem", element="auto", law="linear")) for s in specs]
    want += [Task(s.replace(model=m), SolverSpec("static")) for s in specs for m in roles.in_role("regression")]
    assert _keys(DRIVER_STUDIES["regression"](False)) == _keys(want)


@pytest.mark.parametrize("quick", [True, False])
def test_the_b09_volume_files_give_the_compression_and_tension_studies_runs(quick):
    """[B09]'s models at [G20]'s (ν, d) on the cube and the first beam: runs of the compression and
    tension studies (the same keys: the reproduction computes them once), and no FEM."""
    from studies.paper import baudet
    from studies.paper.reproduce import STUDIES
    from studies.sweep import roles

    got = baudet.tasks(quick)
    b09 = set(roles.in_role("b09"))
    assert {t.scene.model for t in got} == b09 and all(t.solver.kind == "static" for t in got)
    assert len(got) == 2 * 6 * len(b09)
    published = {t.key() for n in ("compression", "tension") for t in STUDIES[n](quick)}
    assert {t.key() for t in got} <= published
    cube, beam = ((4, 4, 4), (2, 2, 12)) if quick else ((10, 10, 10), (4, 4, 24))
    assert {(t.scene.experiment, t.scene.mesh) for t in got} == {("compression", cube), ("tension", beam)}


def test_the_volume_table_reads_the_publication_s_rows_and_says_what_was_not_run():
    """A (ν, d) of the publication's table that the files do not give is a row ``not run``, not a
    gap; the others carry the stored volume change."""
    from studies.paper.baudet import MODELS, tasks, volume_hook
    from studies.paper.reproduce import HookInput
    from studies.study.experiment import configurations

    docs = (_doc("b09-volume-cube"),)
    configs = tuple(configurations(docs[0], True))
    ts = [t for t in tasks(True) if t.scene.experiment == "compression" and t.scene.deformation == 0.05]
    rows = [{"status": "ok", "volume_change": -0.01 * (i + 1)} for i in range(len(ts))]
    t = volume_hook(HookInput(docs, configs, tuple(ts), tuple(rows), True))
    assert len(t) == 6 and set(t["experiment"]) == {"compression"}
    small = t[t["d_pct"] == 5.0]
    for m in MODELS:
        assert (small[f"{m}_state"] == "ok").all()
    large = t[t["d_pct"] == 20.0]
    assert all(large[f"{m}_state"].str.startswith("failed (not run").all() for m in MODELS)
    first = ts[0]
    assert t.loc[(t["nu"] == first.scene.nu) & (t["d_pct"] == 5.0), f"{first.scene.model}_e_pct"].iloc[0] == \
        pytest.approx(1.0)


# ------------------------------------------------------------------------------ refusals
INVALID = [
    ("engines", "body.experiment", "body.experiment", ["compression", "compression"]),
    ("engines", "body.experiment", "body.experiment", []),
    ("engines", "body.experiment", "body.experiment", ["compression", "twist"]),
    ("engines", "load.angle_deg", "load.angle_deg", 1.0),  # neither compression nor shear takes it
    ("engines", "material.quick.nu", "material.quick.nu", 0.5),
    ("engines", "material.quick.G", "material.quick.G", 1.0),
    ("engines", "material.quick", "material.quick", 0.25),
    ("engines", "model[0].engines", "model[0].engines", "yes"),
    ("engines", "model[0].params", "model[0].params", {"timestep": 1e-3}),
    ("engines", "model[0]", "model[0].name", "hybmss"),  # engines and name together
    ("engines", "model[0].meshes", "model[0].meshes", "coarse"),
    ("engines", "model[0].solver", "model[0].solver", {"kind": "implicit", "dt": 1e-3, "steps": 10}),
    ("engines", "table", "table", {"name": "x", "hook": "regression"}),
    ("engines", "table[0].name", "table[0].name", "Engines Closing"),
    ("engines", "table[1].name", "table[1].name", "engines_closing"),  # twice
    ("engines", "table[0].hook", "table[0].hook", "engines_closing"),
    ("engines", "table[1].repeats", "table[1].repeats", 0),
    ("engines", "table[1].quick.repeats", "table[1].quick.repeats", 1.5),
    ("engines", "table[1].quick.target_s", "table[1].quick.target_s", 0.1),
    ("engines", "table[0].repeat", "table[0].repeat", 3),
    ("regression-cube", "load.deformation", "load.deformation", 1.2),  # compression's d < 1
]


def _set(doc: dict, dotted: str, value) -> dict:
    parts = dotted.replace("]", "").replace("[", ".").split(".")
    target = doc
    for p in parts[:-1]:
        target = target[int(p)] if p.isdigit() else target.setdefault(p, {})
    target[parts[-1]] = value
    return doc


@pytest.mark.parametrize("file,key,where,value", INVALID, ids=[f"{w}={v!r}"[:40] for _, _, w, v in INVALID])
def test_a_new_key_out_of_range_is_refused_naming_it(file, key, where, value):
    from studies.study import StudyError
    from studies.study.experiment import validate_experiment

    doc = _set(_doc(file), where, value)
    with pytest.raises(StudyError) as info:
        validate_experiment(doc, f"{file}.toml")
    assert info.value.key == key, str(info.value)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(f"study file {file}.toml: {key} = ") and "is not allowed: " in msg


def test_a_study_without_reference_has_no_fem_runs_and_the_quick_material_replaces_the_file_s():
    from studies.study.experiment import experiment_tasks

    doc = _doc("engines")
    full = experiment_tasks(doc, quick=False)
    assert {t.scene.nu for t in experiment_tasks(doc, quick=True)} == {0.25}
    assert {t.scene.nu for t in full} == {0.25, 0.45, 0.499}
    del doc["reference"]
    assert [t for t in experiment_tasks(doc, quick=False) if t.solver.kind == "fem"] == []


def test_an_engine_on_its_own_meshes_unless_the_file_says_file():
    """``meshes = "own"`` (the default) puts an engine whose study part gives it meshes of its own
    on them; ``"file"`` keeps it on the file's."""
    from studies.sweep import roles
    from studies.study.experiment import experiment_tasks

    own = [m for m in models.names() if models.get(m).kernels == ("engine",) and roles.part(m).meshes]
    if not own:
        pytest.skip("no engine model with meshes of its own is registered")
    doc = _doc("engines")
    on_file = {t.scene.mesh for t in experiment_tasks(doc, False) if t.scene.model in own}
    del doc["model"][0]["meshes"]
    on_own = {t.scene.mesh for t in experiment_tasks(doc, False) if t.scene.model in own}
    assert on_file == {(10, 10, 10)} and (10, 10, 10) not in on_own


def test_the_hooks_the_format_allows_are_the_hooks_the_paper_has():
    from studies.paper.reproduce import TABLE_HOOKS
    from studies.study.experiment import TABLE_HOOKS as NAMES

    assert set(TABLE_HOOKS) == set(NAMES)


@pytest.mark.parametrize("edit,key", [
    (("hook = \"engines-timing\"", "hook = \"engines-timng\""), "table[1].hook"),
    (("meshes = \"file\"", "meshes = \"fine\""), "model[0].meshes"),
    (("quick = { nu = 0.25 }", "quick = { nu = 0.7 }"), "material.quick.nu"),
])
def test_the_reproduction_refuses_an_invalid_driver_file_before_work(tmp_path, monkeypatch, cli_in_process,
                                                                      edit, key):
    """``hybmss run --study engines`` reads its file before any work: a key out of range exits 2
    with one line naming the file and the key, and writes nothing."""
    from studies.paper import reproduce

    original = reproduce.study_file_path("engines")
    broken = tmp_path / "engines.toml"
    text = original.read_text()
    assert edit[0] in text
    broken.write_text(text.replace(edit[0], edit[1]))
    monkeypatch.setattr(reproduce, "study_file_path", lambda name: broken if name == "engines" else
                        original.with_name(f"{name}.toml"))
    out = tmp_path / "res"
    r = cli_in_process("run", "--study", "engines", "--quick", "--no-progress", "--out", out)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{broken}: {key} = " in lines[0] and "is not allowed: " in lines[0], r.stderr
    assert r.stdout == "" and not out.exists()
