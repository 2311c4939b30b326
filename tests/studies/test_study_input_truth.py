"""A study file whose scene is contradictory, impossible, or not the body the user gave is refused
before any work (exit 2, one line naming the key); the report escapes what the file says."""

from __future__ import annotations

import math

import numpy as np
import pytest

from study_files import changed, small_study, write


NAN = 123456.789
"""Written as TOML's nan (a document holding nan is not equal to itself when read back)."""


def _refused(cli, tmp_path, doc, key, *words):
    path = write(doc, tmp_path / "study.toml")
    path.write_text(path.read_text().replace(repr(NAN), "nan"))
    out = tmp_path / "out"
    proc = cli("study", path, "--out", out, "--no-progress")
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert key in lines[0] and "is not allowed" in lines[0], lines[0]
    for w in words:
        assert w in lines[0], lines[0]
    assert not out.exists()
    return lines[0]


def _supports(doc):
    return doc["load_case"][0]["support"]


# ---------------------------------------------------------------------------- contradictory supports
def test_a_clamp_and_a_translate_on_the_same_face(tmp_path, cli_in_process):
    doc = small_study()
    _supports(doc).append({"name": "push", "region": "z-", "motion": "translate",
                           "displacement": [0.0, 0.0, 0.0002]})
    line = _refused(cli_in_process, tmp_path, doc, "load_case[0].support[2].region", "'bottom'")
    assert "9 of the nodes of 'push'" in line and "0.0002 m" in line  # a 2 x 2 face: 3 x 3 nodes, 0.2 mm apart


def test_a_box_support_over_every_node(tmp_path, cli_in_process):
    doc = small_study()
    _supports(doc).append({"name": "all", "region": {"box": [[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]},
                           "motion": "clamped"})
    _refused(cli_in_process, tmp_path, doc, "load_case[0].support[2].region", "'top'")


def test_one_support_prescribing_every_node(tmp_path, cli_in_process):
    doc = small_study()
    doc["load_case"][0]["support"] = [{"name": "all", "region": {"box": [[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]},
                                       "motion": "clamped"}]
    doc["metrics"] = {}
    _refused(cli_in_process, tmp_path, doc, "load_case[0].support =", "all 45 nodes")


def test_agreeing_supports_on_shared_nodes_pass():
    """A clamped floor and a slide in z on the same face prescribe the same z (0): allowed."""
    from studies.study import Study
    import tempfile
    from pathlib import Path

    doc = small_study()
    _supports(doc).append({"name": "floor-z", "region": "z-", "motion": "slide", "components": ["z"]})
    with tempfile.TemporaryDirectory() as d:
        assert Study.from_toml(write(doc, Path(d) / "s.toml")).voxels[0].body.n_cells == 16


# ---------------------------------------------------------------------------- models' own limits
def _pbd(doc, nu=0.3):
    doc["model"] = [{"name": "pbd-xpbd-fem"}]
    doc["material"]["nu"] = nu
    return doc


def test_a_model_refuses_a_poisson_ratio_it_cannot_run(tmp_path, cli_in_process):
    from hybmss import models

    if "pbd-xpbd-fem" not in models.names():
        pytest.skip("pypbd is not installed")
    line = _refused(cli_in_process, tmp_path, _pbd(small_study(), 0.495), "material.nu = 0.495", "pbd-xpbd-fem")
    assert "[0, 0.49]" in line


def test_a_model_refuses_a_traction(tmp_path, cli_in_process):
    from hybmss import models

    if "pbd-xpbd-fem" not in models.names():
        pytest.skip("pypbd is not installed")
    doc = _pbd(small_study())
    doc["load_case"][0]["traction"] = [{"region": "x+", "traction": [10.0, 0.0, 0.0]}]
    _refused(cli_in_process, tmp_path, doc, "load_case[0].traction", "surface tractions")


def test_the_newton_solver_limit_is_the_file_checks(tmp_path, cli_in_process):
    """ν = 0.49999999 is a material (in (-1, 0.5)) the static solver refuses: the file check asks
    the solver's own check; ν = 0.49999 (its end point) passes it."""
    from hybmss.solve import NU_RANGE

    doc = small_study()
    doc["material"]["nu"] = 0.49999999
    _refused(cli_in_process, tmp_path, doc, "material.nu = 0.49999999", "model[0]")
    from studies.study import Study

    doc["material"]["nu"] = NU_RANGE[1]
    assert Study.from_toml(write(doc, tmp_path / "ok.toml")).materials[0].nu == NU_RANGE[1]


@pytest.mark.parametrize("key,value", [("E", 1e300), ("E", 1e-300), ("E", math.inf), ("E", NAN),
                                       ("E", [3000.0, math.inf]), ("rho", -1.0), ("rho", 1e30),
                                       ("rho", NAN), ("E", 10**400)])
def test_absurd_materials(tmp_path, cli_in_process, key, value):
    doc = small_study()
    doc["material"][key] = value
    line = _refused(cli_in_process, tmp_path, doc, f"material.{key}")
    assert ">=" in line and "<=" in line  # the allowed range, both ends


# ---------------------------------------------------------------------------- the body
def test_a_mask_far_finer_than_its_cells(tmp_path, cli_in_process):
    """A 2 x 2 x 4 mask at 1 nm spacing is 2 x 2 x 4 nm: a 1 cm cell is not that body."""
    np.save(tmp_path / "tiny.npy", np.ones((2, 2, 4), dtype=np.int8))
    doc = small_study()
    doc["body"] = {"mask": "tiny.npy", "spacing": [1e-9, 1e-9, 1e-9], "cell_sizes": [0.01]}
    _refused(cli_in_process, tmp_path, doc, "body.cell_sizes", "extent")


def test_a_coarse_sampling_within_the_shell_is_accepted(tmp_path):
    """A 30 x 3 x 10 mm block with a fin one voxel thick, sampled by cells 3 voxels wide: the fin
    falls between the cell centres and the block keeps 10 x 1 x 4 cells (centres at voxels 1, 4,
    7, ...): 1.08 of the mask's 1.41 cm^3, within the shell's tolerance."""
    from studies.study.checks import mask_measures

    image = np.zeros((30, 30, 30), dtype=np.int8)
    image[:, :, :] = 0
    image[:, 10:13, 10:20] = 1
    image[:, 13:, 14] = 1  # a fin one voxel thick
    volume, area = mask_measures(image.astype(bool), [0.001] * 3)
    assert volume == pytest.approx((30 * 3 * 10 + 30 * 17) * 1e-9) and area > 0
    np.save(tmp_path / "fin.npy", image)
    doc = small_study()
    doc["body"] = {"mask": "fin.npy", "spacing": [0.001] * 3, "cell_sizes": [0.003]}
    doc["load_case"][0]["support"] = [{"name": "bottom", "region": "z-", "motion": "clamped"},
                                      {"name": "top", "region": "z+", "motion": "clamped"}]
    doc["metrics"] = {}
    from studies.study import Study

    vox = Study.from_toml(write(doc, tmp_path / "ok.toml")).voxels[0]  # the block's cells: within the shell
    assert vox.body.n_cells == 10 * 1 * 4


def _two_boxes(tmp_path, overlap: bool):
    """Two closed boxes of 2 x 2 x 3 cm written as one STL surface: overlapping by 1 cm along z
    (a surface that crosses itself), or 1 cm apart."""
    import pyvista as pv

    dz = 0.02 if overlap else 0.04
    a = pv.Box(bounds=(0, 0.02, 0, 0.02, 0, 0.03)).triangulate()
    b = pv.Box(bounds=(0, 0.02, 0, 0.02, dz, dz + 0.03)).triangulate()
    a.append_polydata(b).save(tmp_path / "two.stl")
    doc = small_study()
    doc["body"] = {"mesh": "two.stl", "cell_sizes": [0.01]}
    doc["load_case"][0]["support"][1]["displacement"] = [0.0, 0.0, -0.0001]
    doc["metrics"] = {"plate_force": ["top"]}
    return doc


def test_a_self_intersecting_surface(tmp_path, cli_in_process):
    line = _refused(cli_in_process, tmp_path, _two_boxes(tmp_path, True), "body.mesh",
                    "does not cross itself", "from 0 to 2", "2 at")
    assert "0.025" in line  # a point of the overlap, z in (0.02, 0.03)


def test_the_winding_check_alone_finds_the_overlap(tmp_path):
    from hybmss.voxelize import clean_surface
    from studies.study.body import read_surface
    from studies.study.checks import check_winding, surface_measures
    from studies.study.keys import Table

    _two_boxes(tmp_path, True)
    V, T = clean_surface(*read_surface(str(tmp_path / "two.stl")))
    # the divergence theorem counts the overlap twice: 2 x 12 cm^3, where the solid is 20 cm^3
    assert surface_measures(V, T)[0] == pytest.approx(24e-6)
    with pytest.raises(ValueError, match="from 0 to 2"):
        check_winding(Table({"mesh": "two.stl"}, "body", "s.toml"), "mesh", V, T, 0.01)


def test_a_body_of_two_pieces_each_held_is_accepted(tmp_path):
    """Disconnected pieces are supported explicitly when each is held (docs/study-format.md)."""
    from studies.study import Study

    doc = _two_boxes(tmp_path, False)
    study = Study.from_toml(write(doc, tmp_path / "s.toml"))
    assert study.voxels[0].pieces()[1] == 2 and study.voxels[0].body.n_cells == 24


def test_the_surface_volume_check(tmp_path):
    """A voxel body further from the surface's volume than the shell around it is refused."""
    from studies.study.body import BodySource
    from studies.study.checks import check_volume
    from studies.study.keys import Table

    _two_boxes(tmp_path, False)
    vox = BodySource("mesh", path=str(tmp_path / "two.stl")).voxels(0.01)
    t = Table({"cell_sizes": [0.01]}, "body", "s.toml")
    area = 2 * 2 * (4 + 6 + 6) * 1e-4
    check_volume(t, [0.01], vox, 24e-6, area)  # exact
    tol = area * 0.01 * math.sqrt(3) / 2
    check_volume(t, [0.01], vox, 24e-6 + 0.99 * tol, area)
    with pytest.raises(ValueError, match="cells hold 2.4e-05 m\\^3"):
        check_volume(t, [0.01], vox, 24e-6 + 1.01 * tol, area)


# ---------------------------------------------------------------------------- guards
def test_a_grid_that_does_not_fit_memory(tmp_path, cli_in_process):
    doc = small_study()
    doc["body"] = {"pyvista": "sphere", "cell_sizes": [0.02]}
    doc["load_case"][0]["support"] = [{"name": "bottom", "region": "z-", "motion": "clamped"}]
    doc["metrics"] = {}
    line = _refused(cli_in_process, tmp_path, doc, "body.cell_sizes", "TiB", "or more fit")
    fit = float(line.split("cell sizes of ")[1].split(" m or more")[0])
    from studies.sweep import sizing
    from studies.study.body import grid_shape
    from studies.study.checks import run_estimates
    from studies.study.spec import Reference
    from studies.study.body import BodySource, pyvista_example
    from hybmss.scene import Material

    src = BodySource("pyvista", path=pyvista_example("sphere"))
    runs = [("hybmss", ())]
    from studies.study.spec import ModelRun

    est = run_estimates(grid_shape(src, fit), [ModelRun("hybmss", (), "hybmss")], Reference("hex2", "linear", 1),
                        [Material(3000.0, 0.3)])
    assert all(sizing.fits(e) for _, e, _ in est), runs  # the remedy it names fits


def test_an_explicit_run_of_a_billion_steps(tmp_path, cli_in_process):
    doc = small_study()
    doc["model"][0]["solver"] = {"kind": "explicit", "dt": 1e-4, "steps": 10**9}
    _refused(cli_in_process, tmp_path, doc, "model[0].solver.steps = 1000000000", "would take about")


# ---------------------------------------------------------------------------- names, files, report
def test_labels_that_would_share_a_vtu_file_name(tmp_path, cli_in_process):
    doc = small_study()
    doc["model"] = [{"name": "hybmss", "label": "a b"}, {"name": "hybmss-fd", "label": "a_b"}]
    _refused(cli_in_process, tmp_path, doc, "model[1].label", "VTU")


@pytest.mark.parametrize("label", ["modèle", "模型", "tab\tlabel", ""])
def test_non_ascii_labels_are_refused_at_the_file_check(tmp_path, cli_in_process, label):
    doc = small_study()
    doc["model"][0]["label"] = label
    _refused(cli_in_process, tmp_path, doc, "model[0].label", "printable ASCII")


def test_non_ascii_support_name(tmp_path, cli_in_process):
    doc = small_study()
    _supports(doc)[1]["name"] = "tête"
    doc["metrics"] = {}
    _refused(cli_in_process, tmp_path, doc, "load_case[0].support[1].name", "printable ASCII")


def test_the_study_file_is_a_folder(tmp_path, cli_in_process):
    (tmp_path / "study.toml").mkdir()
    proc = cli_in_process("study", tmp_path / "study.toml", "--out", tmp_path / "out")
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert "FILE" in proc.stderr and "not a folder" in proc.stderr


@pytest.mark.parametrize("image", [np.zeros((0, 2, 2), dtype=np.int8), np.zeros((2, 2, 2), dtype=np.int8)])
def test_an_empty_mask(tmp_path, cli_in_process, image):
    np.save(tmp_path / "empty.npy", image)
    doc = small_study()
    doc["body"] = {"mask": "empty.npy", "spacing": [0.01] * 3, "cell_sizes": [0.01]}
    _refused(cli_in_process, tmp_path, doc, "body.mask", "none non-zero")


def test_the_title_is_no_script_in_the_report(tmp_path):
    """The title in the page's CSS footer and heading: no '</style>' or '<script>' in the page."""
    from reports.study import _render
    from studies.study import Study

    doc = small_study()
    doc["study"]["title"] = '</style><script>alert(1)</script>"\\'
    study = Study.from_toml(write(doc, tmp_path / "s.toml"))
    page = _render(study, [], None, None, 0)
    assert "<script>" not in page and page.count("</style>") == 1
    assert "\\3C /style\\3E " in page  # the CSS string still says '</style>' (a CSS escape)


# ---------------------------------------------------------------------------- did you mean
@pytest.mark.parametrize("where,typo,hint", [
    ("study", "budget", "budgets"), ("body", "cell_size", "cell_sizes"), ("material", "rh0", "rho"),
    ("load_case.0", "gravty", "gravity"), ("load_case.0.support.0", "moton", "motion"),
    ("model.0", "solvr", "solver"), ("reference", "elemnt", "element"), ("metrics", "plate_forces", "plate_force"),
    ("", "refrence", "reference"), ("body.quick", "cell_size", "cell_sizes")])
def test_misspelt_keys_get_did_you_mean(tmp_path, cli_in_process, where, typo, hint):
    def edit(doc):
        node = doc
        for k in [int(k) if k.isdigit() else k for k in where.split(".") if k]:
            node = node.setdefault(k, {}) if isinstance(node, dict) else node[k]
        node[typo] = 1
    line = _refused(cli_in_process, tmp_path, changed(small_study(), edit), typo)
    assert f"did you mean {hint}" in line, line


@pytest.mark.parametrize("edit,key,hint", [
    (lambda d: d["body"].update(boxx=d["body"].pop("box")), "body.boxx", "box"),
    (lambda d: d["model"][0].update(params={"e_from": True}), "model[0].params", "e_form"),
    (lambda d: d["load_case"][0]["support"][1].update(region="zz+"), "load_case[0].support[1].region", "z+"),
    (lambda d: d["model"][0].update(solver={"kind": "explicit", "dt": 1e-4, "steps": 10, "dampin": 1.0}),
     "model[0].solver.dampin", "damping")])
def test_misspelt_names_get_did_you_mean(tmp_path, cli_in_process, edit, key, hint):
    line = _refused(cli_in_process, tmp_path, changed(small_study(), edit), key)
    assert f"did you mean {hint}" in line, line


def test_a_hostile_and_unicode_title_in_the_written_report(tmp_path, cli_in_process):
    """The whole study with its report: the title is text in the page (no script element, the
    non-ASCII characters as written), one model run and its reference, exit 0."""
    doc = small_study()
    doc["study"]["title"] = "</style><script>alert(1)</script> Étude 肝臓"
    path = write(doc, tmp_path / "study.toml")
    proc = cli_in_process("study", path, "--out", tmp_path / "out", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    page = (tmp_path / "out" / "report" / "small.html").read_text(encoding="utf-8")
    assert "<script>" not in page and page.count("</style>") == 1
    assert "&lt;/style&gt;&lt;script&gt;alert(1)&lt;/script&gt; Étude 肝臓" in page


def test_a_body_of_two_pieces_runs_against_its_fem(tmp_path, cli_in_process):
    """Two separate 2 x 2 x 4 cm blocks of one mask, each held by the floor and the lid (a body of
    pieces is supported, not refused): the study runs (exit 0, no failed run), and the model's
    field and lid force meet the study's 5 % budget against the FEM of both pieces."""
    import json

    import pandas as pd

    two = np.zeros((5, 2, 4), dtype=np.int8)
    two[:2], two[3:] = 1, 2
    np.save(tmp_path / "two.npy", two)
    doc = small_study()
    doc["body"] = {"mask": "two.npy", "spacing": [0.01] * 3, "cell_sizes": [0.01]}
    doc["load_case"][0]["support"] = [
        {"name": "floor", "region": "z-"},
        {"name": "top", "region": "z+", "motion": "translate", "displacement": [0.0, 0.0, -0.0001]}]
    doc["metrics"] = {"plate_force": ["top"]}
    path = write(doc, tmp_path / "study.toml")
    proc = cli_in_process("study", path, "--out", tmp_path / "out", "--no-progress", "--no-report", "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["summary"]["failed"] == 0 and out["runs"] == 2
    errors = pd.read_csv(tmp_path / "out" / "tables" / "small_errors_press.csv")
    assert len(errors) == 1 and errors["u_rel_l2"].iloc[0] < 0.05
    assert errors["force_top_rel"].iloc[0] < 0.05


def test_out_of_memory_in_a_study_names_the_study_files_keys(tmp_path, cli_in_process, monkeypatch):
    """A MemoryError during a study (here raised by its runs) is exit 3 with one line whose remedy
    exists for a study file (no --refine: the cell sizes or reference.refine), nothing stored."""
    from studies.study import Study

    def no_memory(self, out, **kw):
        raise MemoryError

    monkeypatch.setattr(Study, "run", no_memory)
    path = write(small_study(), tmp_path / "study.toml")
    proc = cli_in_process("study", path, "--out", tmp_path / "out", "--no-progress")
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 3 and len(lines) == 1, proc.stderr
    assert "body.cell_sizes" in lines[0] and "--refine" not in lines[0], lines[0]
    assert not (tmp_path / "out" / "runs").exists() or not any((tmp_path / "out" / "runs").iterdir())


@pytest.mark.parametrize("edit,key,hint", [
    (lambda d: d["material"].update(Nu=d["material"].pop("nu")), "material.Nu", "nu"),
    (lambda d: d["body"].update(experimnt=d["body"].pop("experiment")), "body.experimnt", "experiment"),
    (lambda d: d["load"].update(deformaton=d["load"].pop("deformation")), "load.deformaton", "deformation")])
def test_misspelt_keys_of_an_experiment_study(tmp_path, cli_in_process, edit, key, hint):
    import tomllib
    from pathlib import Path

    doc = tomllib.loads((Path(__file__).parents[2] / "studies/data/studies/compression.toml").read_text())
    line = _refused(cli_in_process, tmp_path, changed(doc, edit), key)
    assert f"did you mean {hint}?" in line, line
