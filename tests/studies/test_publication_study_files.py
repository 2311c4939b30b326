"""The publication's experiments as study files (``studies/data/studies/*.toml``): the tasks they
give are the reproduction's runs, in order, at --quick and in full; an invalid file is refused
naming its key (exit 2 on the command line).

``tests/regression/publication_tasks.csv`` freezes those runs: one row per task (study, quick,
the scene's parameters, the solver's), written by the task builders that were Python functions
before the studies became files.  Where the publication's runs change on purpose (a model joins a
study role, a study gains a load), regenerate it and say why in the commit:

    PYTHONPATH=. python tests/studies/test_publication_study_files.py --write
"""

from __future__ import annotations

import copy
import csv
import json
import sys
from pathlib import Path

import pytest

FROZEN = Path(__file__).resolve().parents[1] / "regression" / "publication_tasks.csv"
COLUMNS = ("study", "quick", "experiment", "mesh", "E", "nu", "rho", "model", "params", "deformation",
           "angle_deg", "gravity", "damping", "le", "solver")


def row(task, quick: bool) -> dict:
    """A task as plain text: every field of its scene (floats by ``repr``, exact) and its solver."""
    s = task.scene
    return {"study": task.study, "quick": str(quick).lower(), "experiment": s.experiment,
            "mesh": "x".join(map(str, s.mesh)), "E": repr(s.E), "nu": repr(s.nu), "rho": repr(s.rho),
            "model": s.model, "params": json.dumps(dict(s.params), sort_keys=True),
            "deformation": repr(s.deformation), "angle_deg": repr(s.angle_deg), "gravity": repr(s.gravity),
            "damping": repr(s.damping), "le": repr(s.le), "solver": json.dumps(task.solver.relevant(), sort_keys=True)}


def current_rows() -> list[dict]:
    from studies.paper.reproduce import STUDIES, tasks_for

    return [row(t, quick) for quick in (True, False) for t in tasks_for(list(STUDIES), quick)]


def frozen_rows() -> list[dict]:
    with FROZEN.open() as fh:
        return list(csv.DictReader(line for line in fh if not line.startswith("#")))


def write(path: Path = FROZEN) -> None:
    rows = current_rows()
    with path.open("w", newline="") as fh:
        fh.write("# The runs of the publication's studies (make reproduce-paper), one row per task, in order:\n"
                 "# the study files must give exactly these. Regenerate only when the runs change on purpose:\n"
                 "#   PYTHONPATH=. python tests/studies/test_publication_study_files.py --write\n")
        w = csv.DictWriter(fh, COLUMNS, lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
    print(f"{path}: {len(rows)} tasks")


# ----------------------------------------------------------------------------- same runs
def test_the_study_files_give_the_publication_s_runs():
    """Every task of every study, in order, at --quick and in full, equals the frozen list (its
    scene field by field, its solver): hence the same run keys and the same tables."""
    now, frozen = current_rows(), frozen_rows()
    for quick in ("true", "false"):
        a = [r for r in now if r["quick"] == quick]
        b = [r for r in frozen if r["quick"] == quick]
        assert len(a) == len(b), f"quick={quick}: {len(a)} tasks from the files, {len(b)} frozen"
        for i, (x, y) in enumerate(zip(a, b)):
            assert x == y, f"quick={quick} task {i}: " + ", ".join(
                f"{k} {x[k]} (files) != {y[k]} (frozen)" for k in COLUMNS if x[k] != y[k])


def test_the_frozen_list_covers_every_study_and_solver():
    """The frozen list is the publication's sweep, not a fragment of it: its counts per study,
    solver kind and mode follow from the design (3 ν × 2 loads per mesh; torsion's sweep of 7
    angles in full only; bending's 2 E per mesh, each with two quadratic FEM references)."""
    from collections import Counter

    rows = frozen_rows()
    # the publication's meshes of each study and mode: those of its mass-spring rows; the other FEM
    # rows are the references on the engines' own meshes (counted below)
    pub = {(r["study"], r["quick"], r["mesh"]) for r in rows
           if r["model"] == "hybmss" and json.loads(r["solver"])["kind"] != "fem"}
    own = [r for r in rows if json.loads(r["solver"])["kind"] == "fem" and (r["study"], r["quick"], r["mesh"]) not in pub]
    rows = [r for r in rows if r not in own]
    count = Counter((r["study"], r["quick"], json.loads(r["solver"])["kind"]) for r in rows)
    assert {s for s, _, _ in count} == {"compression", "tension", "shear", "torsion", "torsion-sweep", "bending"}
    assert not [k for k in count if k[0] == "torsion-sweep" and k[1] == "true"]
    assert not [k for k in count if k[1] == "true" and k[2] == "explicit"]
    fem = {r["solver"] for r in rows if r["study"] == "bending" and json.loads(r["solver"])["kind"] == "fem"}
    assert {json.loads(s)["law"] for s in fem} == {"linear", "neo-hookean"}
    # linear FEM at each of the 3 × 2 (ν, d); Neo-Hookean and SVK at the 3 large ones (d = 20 %)
    assert count[("compression", "true", "fem")] == count[("shear", "false", "fem")] == 6 + 2 * 3
    assert count[("tension", "false", "fem")] == 2 * 12  # two beams
    assert count[("torsion-sweep", "false", "fem")] == 3 + 5  # linear up to 10°; Neo-Hookean above 5°
    assert count[("bending", "true", "fem")] == 2 * 2 and count[("bending", "false", "fem")] == 2 * 2 * 2
    # the engines' meshes (5³ cube and 2×2×12 beam, 2³ and 1×1×6): in full every configuration's
    # references on each (the tension's two beams share them), in the quick mode the one case's
    # linear reference on the meshes that are not the quick ones (2³, 1×1×6)
    extra = Counter((r["study"], r["quick"]) for r in own)
    for study in ("compression", "tension", "shear", "torsion"):
        assert extra[(study, "false")] == 2 * 12 and extra[(study, "true")] == 1, study
    # bending: its two references (linear, Neo-Hookean) at each E on the engines' beams (2×2×12, 1×1×6;
    # the quick mode: 1×1×6 at the one case's E, 2×2×12 being the quick beam)
    assert extra[("bending", "false")] == 2 * 2 * 2 and extra[("bending", "true")] == 2
    assert not [r for r in own if r["study"] == "torsion-sweep"]


def test_the_reproduction_runs_the_files():
    """Each study of the reproduction is its shipped files' tasks: a changed file changes it."""
    from studies.paper import reproduce
    from studies.study.experiment import experiment_tasks

    assert set(reproduce.STUDIES) == {"compression", "tension", "shear", "torsion", "bending"}
    for name, study in reproduce.STUDIES.items():
        docs = [reproduce.load_study_file(f) for f in study.files]
        assert [t.key() for t in study(True)] == [t.key() for d in docs for t in experiment_tasks(d, True)]
    doc = reproduce.load_study_file("compression")
    doc["material"]["nu"] = [0.0, 0.3, 0.499]
    changed = {t.scene.nu for t in experiment_tasks(doc, True)}
    assert changed == {0.0, 0.3, 0.499}


def test_a_changed_file_breaks_the_equality(monkeypatch):
    """The comparison can fail: one ν changed in one shipped file gives other runs than the frozen."""
    from studies.paper import reproduce

    original = reproduce.load_study_file

    def edited(name):
        doc = original(name)
        if name == "shear":
            doc["material"]["nu"] = [0.0, 0.25, 0.49]
        return doc

    monkeypatch.setattr(reproduce, "load_study_file", edited)
    with pytest.raises(AssertionError, match=r"nu 0\.49 \(files\) != 0\.499 \(frozen\)"):
        test_the_study_files_give_the_publication_s_runs()


def test_the_shipped_files_are_package_data():
    import tomllib as _tomllib

    from studies.paper.reproduce import STUDY_FILES, study_file_path

    root = Path(__file__).resolve().parents[2]
    pyproject = _tomllib.loads((root / "pyproject.toml").read_text())
    patterns = pyproject["tool"]["setuptools"]["package-data"]["studies"]
    for name in (f for files in STUDY_FILES.values() for f in files):
        path = study_file_path(name)
        rel = path.relative_to(root / "studies")
        assert any(rel.match(p) for p in patterns), f"{rel} is not package data ({patterns})"


# ----------------------------------------------------------------------------- refusals
def _compression() -> dict:
    from studies.paper.reproduce import load_study_file

    return load_study_file("compression")


def _set(doc: dict, dotted: str, value) -> dict:
    doc = copy.deepcopy(doc)
    parts = dotted.replace("]", "").replace("[", ".").split(".")
    target = doc
    for p in parts[:-1]:
        target = target[int(p)] if p.isdigit() else target.setdefault(p, {})
    if value is _DELETE:
        del target[parts[-1]]
    else:
        target[parts[-1]] = value
    return doc


_DELETE = object()

INVALID = [
    ("body.experiment", "body.experiment", "bendng"),
    ("body.mesh", "body.mesh", [[10, 10]]),
    ("body.mesh", "body.mesh", []),
    ("body.mesh", "body.mesh", [[4, 4, 1]]),  # a plate on each end: NZ >= 2
    ("body.quick.mesh", "body.quick.mesh", [[4, 4, 0]]),
    ("body.cell_sizes", "body.cell_sizes", [0.01]),  # a box body's key, not an experiment's
    ("material.nu", "material.nu", [0.0, 0.5]),
    ("material.E", "material.E", -1.0),
    ("material.E", "material.E", "10 kPa"),
    ("material.G", "material.G", 1.0),
    ("load.angle_deg", "load.angle_deg", 45.0),  # compression takes deformation
    ("load.deformation", "load.deformation", [0.05, 1.2]),
    ("model", "model", []),
    ("model[0]", "model[0].name", "hybmss"),  # role and name together
    ("model[0].role", "model[0].role", "table"),
    ("model[1].defaults_only", "model[1].defaults_only", "yes"),
    ("model[1].skip_quik", "model[1].skip_quik", True),
    ("model[1].solver.kind", "model[1].solver.kind", "verlet"),
    ("model[1].solver.dt", "model[1].solver.dt", 0.0),
    ("model[1].solver.steps", "model[1].solver.steps", 1.5),
    ("model[0].solver", "model[0].solver", {"kind": "implicit", "dt": 1e-3, "steps": 10}),  # baudet2009 has none
    ("model[0].params", "model[0].params", {"e_form": True}),  # a role's models take their variants
    ("reference.element", "reference.element", "tet4"),
    ("reference.law", "reference.law", "mooney"),
    ("reference.large_laws", "reference.large_laws", ["neo-hookean", "ogden"]),
    ("reference.large_above", "reference.large_above", _DELETE),
    ("reference.large_above", "reference.large_above", -0.05),
    ("reference.refine", "reference.refine", 0),
    ("study.name", "study.name", "Compression 2"),
    ("study.budgets", "study.budgets", [0.02]),
]


@pytest.mark.parametrize("key,where,value", INVALID, ids=[f"{w}={v!r}"[:40] for _, w, v in INVALID])
def test_an_invalid_experiment_study_names_its_key(key, where, value):
    from studies.study import StudyError
    from studies.study.experiment import experiment_tasks, validate_experiment

    doc = _set(_compression(), where, value)
    with pytest.raises(StudyError) as info:
        validate_experiment(doc, "compression.toml")
    err = info.value
    assert err.key == key, str(err)
    msg = str(err)
    assert "\n" not in msg and msg.startswith(f"study file compression.toml: {key} = ") and "is not allowed: " in msg
    with pytest.raises(StudyError):
        experiment_tasks(doc, quick=True)


def test_a_named_model_with_its_parameters_and_the_close_match():
    from studies.study import StudyError
    from studies.study.experiment import experiment_tasks, validate_experiment

    doc = _compression()
    doc["model"] = [{"name": "hybmss", "params": {"e_form": True}}]
    tasks = experiment_tasks(doc, quick=True)
    mss = [t for t in tasks if t.solver.kind == "static"]
    assert len(mss) == 6 and {dict(t.scene.params)["e_form"] for t in mss} == {True}
    doc["model"] = [{"name": "hybms"}]
    with pytest.raises(StudyError, match=r"model\[0\]\.name = 'hybms'.*did you mean hybmss\?"):
        validate_experiment(doc)
    doc["model"] = [{"name": "hybmss", "params": {"e_frm": True}}]
    with pytest.raises(StudyError, match=r"model\[0\]\.params = "):
        validate_experiment(doc)


@pytest.mark.parametrize("edit,key", [
    (("[load]\ndeformation = [0.05, 0.20]", "[load]\ndeformation = [0.05, 1.5]"), "load.deformation"),
    (('role = "tables"', 'role = "tabels"'), "model[0].role"),
    (('large_above = 0.05', 'large_abve = 0.05'), "reference.large_abve"),
    (('experiment = "compression"', 'experiment = "compresion"'), "body.experiment"),
])
def test_the_reproduction_refuses_an_invalid_shipped_file(tmp_path, monkeypatch, cli_in_process, edit, key):
    """``hybmss run`` reads the study files before any work: one of them invalid exits 2 with one
    line naming the file and its key, and writes nothing."""
    from studies.paper import reproduce

    original = reproduce.study_file_path("compression")
    broken = tmp_path / "compression.toml"
    text = original.read_text()
    assert edit[0] in text
    broken.write_text(text.replace(edit[0], edit[1]))
    monkeypatch.setattr(reproduce, "study_file_path", lambda name: broken if name == "compression" else
                        original.with_name(f"{name}.toml"))
    out = tmp_path / "res"
    r = cli_in_process("run", "--study", "compression", "--quick", "--no-progress", "--out", out)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{broken}: {key} = " in lines[0] and "is not allowed: " in lines[0], r.stderr
    assert r.stdout == "" and not out.exists()


if __name__ == "__main__":
    if sys.argv[1:] != ["--write"]:
        sys.exit(f"usage: PYTHONPATH=. python {sys.argv[0]} --write  (rewrites {FROZEN})")
    write()
