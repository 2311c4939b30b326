"""Invalid study files, each made from one valid file by one change: ``hybmss study`` exits 2
with one line naming the key, before any work, with nothing written (the results folder is not
created)."""

from __future__ import annotations

import numpy as np
import pytest

from study_files import changed, small_study, write


def _set(path: str, value):
    """An edit setting the dotted ``path`` (``load_case.0.support.1.region``) to ``value``
    (``DELETE`` removes it)."""
    def edit(doc):
        keys = [int(k) if k.isdigit() else k for k in path.split(".")]
        node = doc
        for k in keys[:-1]:
            node = node[k]
        if value is DELETE:
            del node[keys[-1]]
        else:
            node[keys[-1]] = value
    return edit


DELETE = object()
TOP = "load_case.0.support.1"

CASES = [
    # (id, edit, key named in the message)
    ("no-study-table", _set("study", DELETE), "study ="),
    ("bad-name", _set("study.name", "Liver Block"), "study.name"),
    ("budget-above-1", _set("study.budgets", [1.5]), "study.budgets"),
    ("budget-text", _set("study.budgets", "two percent"), "study.budgets"),
    ("repeats-0", _set("study.repeats", 0), "study.repeats"),
    ("study-typo", _set("study.titel", "x"), "study.titel"),
    ("top-level-typo", _set("modles", {"x": 1}), "modles"),
    ("no-source", _set("body.box", DELETE), "body.box"),
    ("two-sources", _set("body.pyvista", "nut"), "body.pyvista"),
    ("box-2-numbers", _set("body.box", [0.02, 0.02]), "body.box"),
    ("box-negative", _set("body.box", [-0.02, 0.02, 0.04]), "body.box"),
    ("no-cell-sizes", _set("body.cell_sizes", DELETE), "body.cell_sizes"),
    ("cell-size-not-dividing", _set("body.cell_sizes", [0.003]), "body.cell_sizes"),
    ("cell-sizes-increasing", _set("body.cell_sizes", [0.005, 0.01]), "body.cell_sizes"),
    ("quick-other-key", _set("body.quick", {"box": [1.0, 1.0, 1.0]}), "body.quick.box"),
    ("E-negative", _set("material.E", -3000.0), "material.E"),
    ("nu-half", _set("material.nu", 0.5), "material.nu"),
    ("nu-list-one-bad", _set("material.nu", [0.3, 0.7]), "material.nu"),
    ("rho-text", _set("material.rho", "heavy"), "material.rho"),
    ("no-E", _set("material.E", DELETE), "material.E"),
    ("no-load-case", _set("load_case", DELETE), "load_case ="),
    ("no-support", _set("load_case.0.support", DELETE), "load_case[0].support"),
    ("face-z0", _set(f"{TOP}.region", "z0"), "load_case[0].support[1].region"),
    ("motion-glue", _set(f"{TOP}.motion", "glue"), "load_case[0].support[1].motion"),
    ("slide-no-components", _set(f"{TOP}.motion", "slide"), "load_case[0].support[1].components"),
    ("region-selects-nothing", _set(f"{TOP}.region", {"box": [[1.0, 1.0, 1.0], [2.0, 2.0, 2.0]]}),
     "load_case[0].support[1].region"),
    ("rotate-no-angle", _set(f"{TOP}.motion", "rotate"), "load_case[0].support[1].angle_deg"),
    ("label-on-a-box", _set(f"{TOP}.region", {"label": 2}), "load_case[0].support[1].region.label"),
    ("support-typo", _set(f"{TOP}.displacment", [0.0, 0.0, 0.0]), "load_case[0].support[1].displacment"),
    ("gravity-2", _set("load_case.0.gravity", [0.0, -9.81]), "load_case[0].gravity"),
    ("traction-missing", _set("load_case.0.traction", [{"region": "x+"}]), "load_case[0].traction[0].traction"),
    ("plates-cross", _set(f"{TOP}.displacement", [0.0, 0.0, -0.05]), "load_case[0].support ="),
    ("model-unknown", _set("model.0.name", "hybms"), "model[0].name"),
    ("model-param-range", _set("model.0.params", {"A": -1.0}), "model[0].params"),
    ("model-param-unknown", _set("model.0.params", {"stiffness": 2.0}), "model[0].params"),
    ("solver-dynamic", _set("model.0.solver", "dynamic"), "model[0].solver"),
    ("explicit-no-dt", _set("model.0.solver", {"kind": "explicit", "steps": 10}), "model[0].solver.dt"),
    ("implicit-corot", _set("model.0", {"name": "corot-hex8", "solver": {"kind": "implicit", "dt": 0.01,
                                                                          "steps": 10}}), "model[0].solver"),
    ("element-hex27", _set("reference.element", "hex27"), "reference.element"),
    ("refine-0", _set("reference.refine", 0), "reference.refine"),
    ("force-of-no-support", _set("metrics.plate_force", ["lid"]), "metrics.plate_force"),
    ("point-outside", _set("metrics.points.tip", [1.0, 1.0, 1.0]), "metrics.points.tip"),
    ("pyvista-unknown", lambda d: (d["body"].pop("box"), d["body"].update(pyvista="teapot")), "body.pyvista"),
    ("pyvista-open-surface", lambda d: (d["body"].pop("box"), d["body"].update(pyvista="airplane")),
     "body.pyvista"),
    ("mesh-missing-file", lambda d: (d["body"].pop("box"), d["body"].update(mesh="no-such.stl")), "body.mesh"),
]


def _unsupported(doc):
    for s in doc["load_case"][0]["support"]:
        s.update(motion="slide", components=["z"])


def _duplicate_model(doc):
    doc["model"].append({"name": "hybmss"})


def _duplicate_case(doc):
    doc["load_case"].append(dict(doc["load_case"][0]))


CASES += [
    ("unsupported-slides", _unsupported, "load_case[0].support ="),
    ("duplicate-model", _duplicate_model, "model[1].label"),
    ("duplicate-load-case", _duplicate_case, "load_case[1].name"),
]


def _mask_doc(tmp_path, spacing=True, both_held=False):
    """A mask of two separate blocks along x, held at z- only where x is low (one piece
    unsupported) unless ``both_held``."""
    mask = np.zeros((5, 2, 4), dtype=np.int64)
    mask[:2] = 1
    mask[3:] = 2
    np.save(tmp_path / "two.npy", mask)
    doc = small_study()
    doc["body"] = {"mask": "two.npy", "cell_sizes": [0.01]}
    if spacing:
        doc["body"]["spacing"] = [0.01, 0.01, 0.01]
    sup = doc["load_case"][0]["support"]
    sup[0]["region"] = {"face": "z-", "box": [[0.0, 0.0, 0.0], [0.02, 0.02, 0.0]]}
    sup[1]["region"] = {"label": 1, "face": "z+"}
    if both_held:
        sup.append({"name": "other", "region": {"label": 2, "face": "z-"}, "motion": "clamped"})
    doc["metrics"] = {"plate_force": ["top"]}
    return doc


def test_there_are_thirty_refusals_or_more():
    assert len(CASES) + 3 >= 30


@pytest.mark.parametrize("case_id,edit,key", CASES, ids=[c[0] for c in CASES])
def test_refused_naming_the_key(tmp_path, cli_in_process, case_id, edit, key):
    path = write(changed(small_study(), edit), tmp_path / "study.toml")
    _refused(cli_in_process, path, tmp_path, key)


def test_invalid_toml(tmp_path, cli_in_process):
    path = tmp_path / "study.toml"
    path.write_text("[study\nname = 'x'\n")
    _refused(cli_in_process, path, tmp_path, "FILE")


def test_disconnected_mask_with_one_piece_unsupported(tmp_path, cli_in_process):
    path = write(_mask_doc(tmp_path), tmp_path / "study.toml")
    proc = _refused(cli_in_process, path, tmp_path, "load_case[0].support =")
    assert "piece" in proc.stderr and "falls apart" in proc.stderr


def test_mask_without_spacing(tmp_path, cli_in_process):
    path = write(_mask_doc(tmp_path, spacing=False), tmp_path / "study.toml")
    _refused(cli_in_process, path, tmp_path, "body.spacing")


def test_disconnected_mask_with_every_piece_supported_is_accepted(tmp_path):
    from studies.study import Study

    study = Study.from_toml(write(_mask_doc(tmp_path, both_held=True), tmp_path / "study.toml"))
    assert study.voxels[0].pieces()[1] == 2 and study.voxels[0].body.n_cells == 32


def _refused(cli, path, tmp_path, key):
    out = tmp_path / "out"
    proc = cli("study", path, "--out", out, "--no-progress")
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert key in lines[0] and "is not allowed" in lines[0], lines[0]
    assert not out.exists(), "a refused study wrote its results folder"
    return proc
