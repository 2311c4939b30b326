"""A hostile probe of the study-file check: study files made from one small valid study by one
hostile change each (wrong types, non-finite and huge numbers, broken structure, contradictory
supports, models' own limits, bodies that are not what they say, sizes past the machine, names
that would break files or pages, misspelt keys, a broken environment).  Each is refused before
any work: exit 2, exactly one stderr line naming the key, no traceback, no results folder; or,
where the file is valid, accepted by the check (the runs themselves are the other tests')."""

from __future__ import annotations

import numpy as np
import pytest

from study_files import changed, small_study, write

NAN = 123456.789
"""Written as TOML's nan (a document holding nan is not equal to itself when read back)."""
BIG = 10**400
"""An integer TOML reads and no float holds."""
SUP = "load_case.0.support"


def at(path: str, value=None, delete: bool = False):
    """An edit setting the dotted ``path`` to ``value`` (or deleting it)."""
    def edit(doc):
        keys = [int(k) if k.isdigit() else k for k in path.split(".")]
        node = doc
        for k in keys[:-1]:
            node = node[k]
        if delete:
            del node[keys[-1]]
        else:
            node[keys[-1]] = value
    return edit


def both(*edits):
    def edit(doc):
        for e in edits:
            e(doc)
    return edit


def add_support(**support):
    return lambda d: d["load_case"][0]["support"].append(support)


def body(**b):
    return at("body", {"cell_sizes": [0.01], **b})


ALL = {"box": [[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]}
NO_METRICS = at("metrics", {})

CASES = [
    # ------------------------------------------------ A. types
    ("A-name-int", at("study.name", 3), "study.name"),
    ("A-title-list", at("study.title", ["x"]), "study.title"),
    ("A-budgets-bool", at("study.budgets", True), "study.budgets"),
    ("A-budgets-table", at("study.budgets", {"a": 0.1}), "study.budgets"),
    ("A-repeats-float", at("study.repeats", 2.5), "study.repeats"),
    ("A-repeats-text", at("study.repeats", "5"), "study.repeats"),
    ("A-box-text", at("body.box", "0.02 0.02 0.04"), "body.box"),
    ("A-box-bools", at("body.box", [True, True, True]), "body.box"),
    ("A-cell-sizes-text", at("body.cell_sizes", "0.01"), "body.cell_sizes"),
    ("A-origin-2", at("body.origin", [0.0, 0.0]), "body.origin"),
    ("A-E-text", at("material.E", "3 kPa"), "material.E"),
    ("A-nu-bool", at("material.nu", False), "material.nu"),
    ("A-rho-table", at("material.rho", {"v": 1.0}), "material.rho"),
    ("A-case-name-int", at("load_case.0.name", 1), "load_case[0].name"),
    ("A-gravity-text", at("load_case.0.gravity", "down"), "load_case[0].gravity"),
    ("A-support-name-int", at(f"{SUP}.0.name", 7), "load_case[0].support[0].name"),
    ("A-region-int", at(f"{SUP}.1.region", 5), "load_case[0].support[1].region"),
    ("A-motion-list", at(f"{SUP}.1.motion", ["clamped"]), "load_case[0].support[1].motion"),
    ("A-displacement-text", at(f"{SUP}.1.displacement", "down"), "load_case[0].support[1].displacement"),
    ("A-components-text", both(at(f"{SUP}.1.motion", "slide"), at(f"{SUP}.1.components", "z")),
     "load_case[0].support[1].components"),
    ("A-model-name-int", at("model.0.name", 1), "model[0].name"),
    ("A-params-list", at("model.0.params", [1, 2]), "model[0].params"),
    ("A-label-int", at("model.0.label", 9), "model[0].label"),
    ("A-solver-int", at("model.0.solver", 1), "model[0].solver"),
    ("A-dt-text", at("model.0.solver", {"kind": "explicit", "dt": "small", "steps": 10}), "model[0].solver.dt"),
    ("A-steps-float", at("model.0.solver", {"kind": "explicit", "dt": 1e-4, "steps": 10.5}),
     "model[0].solver.steps"),
    ("A-refine-text", at("reference.refine", "two"), "reference.refine"),
    ("A-plate-force-text", at("metrics.plate_force", "top"), "metrics.plate_force"),
    ("A-volume-change-int", at("metrics.volume_change", 1), "metrics.volume_change"),
    ("A-point-text", at("metrics.points.tip", "top"), "metrics.points.tip"),
    # ------------------------------------------------ B. non-finite and huge numbers
    ("B-E-inf", at("material.E", float("inf")), "material.E"),
    ("B-E-minus-inf", at("material.E", float("-inf")), "material.E"),
    ("B-E-nan", at("material.E", NAN), "material.E"),
    ("B-E-1e300", at("material.E", 1e300), "material.E"),
    ("B-E-1e-300", at("material.E", 1e-300), "material.E"),
    ("B-E-big-int", at("material.E", BIG), "material.E"),
    ("B-nu-nan", at("material.nu", NAN), "material.nu"),
    ("B-nu-big-int", at("material.nu", BIG), "material.nu"),
    ("B-rho-inf", at("material.rho", float("inf")), "material.rho"),
    ("B-rho-negative", at("material.rho", -1000.0), "material.rho"),
    ("B-rho-1e30", at("material.rho", 1e30), "material.rho"),
    ("B-box-inf", at("body.box", [0.02, 0.02, float("inf")]), "body.box"),
    ("B-cell-size-nan", at("body.cell_sizes", [NAN]), "body.cell_sizes"),
    ("B-cell-size-big-int", at("body.cell_sizes", [BIG]), "body.cell_sizes"),
    ("B-gravity-nan", at("load_case.0.gravity", [0.0, 0.0, NAN]), "load_case[0].gravity"),
    ("B-displacement-inf", at(f"{SUP}.1.displacement", [0.0, 0.0, float("-inf")]),
     "load_case[0].support[1].displacement"),
    ("B-dt-big-int", at("model.0.solver", {"kind": "explicit", "dt": BIG, "steps": 10}), "model[0].solver.dt"),
    ("B-steps-big-int", at("model.0.solver", {"kind": "explicit", "dt": 1e-4, "steps": BIG}),
     "model[0].solver.steps"),
    ("B-budget-nan", at("study.budgets", [NAN]), "study.budgets"),
    ("B-point-inf", at("metrics.points.tip", [0.0, 0.0, float("inf")]), "metrics.points.tip"),
    # ------------------------------------------------ C. structure
    ("C-study-list", at("study", [1, 2]), "study"),
    ("C-body-text", at("body", "box"), "body"),
    ("C-material-list", at("material", [3000.0]), "material"),
    ("C-load-case-table", at("load_case", {"name": "x"}), "load_case"),
    ("C-load-case-empty", at("load_case", []), "load_case"),
    ("C-model-empty", at("model", []), "model"),
    ("C-model-strings", at("model", ["hybmss"]), "model"),
    ("C-support-table", at(f"{SUP}", {"name": "a"}), "load_case[0].support"),
    ("C-region-empty-table", at(f"{SUP}.1.region", {}), "load_case[0].support[1].region"),
    ("C-box-one-corner", at(f"{SUP}.1.region", {"box": [[0.0, 0.0, 0.0]]}), "load_case[0].support[1].region.box"),
    ("C-box-inverted", at(f"{SUP}.1.region", {"box": [[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]]}),
     "load_case[0].support[1].region.box"),
    ("C-patch-zero-normal", at(f"{SUP}.1.region", {"patch": {"normal": [0, 0, 0], "point": [0, 0, 0],
                                                             "radius": 1.0}}),
     "load_case[0].support[1].region.patch.normal"),
    ("C-cell-sizes-empty", at("body.cell_sizes", []), "body.cell_sizes"),
    ("C-cell-sizes-repeated", at("body.cell_sizes", [0.01, 0.01]), "body.cell_sizes"),
    ("C-quick-cell-sizes-text", at("body.quick", {"cell_sizes": "fast"}), "body.quick.cell_sizes"),
    ("C-reference-list", at("reference", ["hex2"]), "reference"),
    ("C-metrics-text", at("metrics", "all"), "metrics"),
    ("C-points-list", at("metrics.points", [[0.0, 0.0, 0.0]]), "metrics.points"),
    # ------------------------------------------------ D. contradictory supports
    ("D-clamp-and-translate-z-", add_support(name="push", region="z-", motion="translate",
                                             displacement=[0.0, 0.0, 0.0002]), "load_case[0].support[2].region"),
    ("D-translate-twice-z+", add_support(name="again", region="z+", motion="translate",
                                         displacement=[0.0, 0.0, -0.0003]), "load_case[0].support[2].region"),
    ("D-box-over-all", add_support(name="all", region=ALL, motion="clamped"), "load_case[0].support[2].region"),
    ("D-box-over-all-alone", both(at(SUP, [{"name": "all", "region": ALL, "motion": "clamped"}]), NO_METRICS),
     "load_case[0].support ="),
    ("D-slide-z-against-top", add_support(name="slide", region="z+", motion="slide", components=["z"],
                                          displacement=[0.0, 0.0, 0.0001]), "load_case[0].support[2].region"),
    ("D-rotate-on-the-floor", add_support(name="turn", region="z-", motion="rotate", angle_deg=5.0),
     "load_case[0].support[2].region"),
    ("D-edge-shared", add_support(name="side", region="x-", motion="translate", displacement=[0.0001, 0.0, 0.0]),
     "load_case[0].support[2].region"),
    ("D-slide-x-all-and-floor", both(add_support(name="sx", region=ALL, motion="slide", components=["x"],
                                                 displacement=[0.0001, 0.0, 0.0]), NO_METRICS),
     "load_case[0].support[2].region"),
    # ------------------------------------------------ E. models' own limits
    ("E-hybmss-nu-0.49999999", at("material.nu", 0.49999999), "material.nu"),
    ("E-hybmss-implicit-nu", both(at("material.nu", 0.4999999),
                                  at("model.0.solver", {"kind": "implicit", "dt": 0.01, "steps": 10})),
     "material.nu"),
    ("E-hybmss-nu-list-one-too-close", at("material.nu", [0.3, 0.499999999]), "material.nu"),
    ("E-hybmss-nu-minus-0.995", at("material.nu", -0.995), "material.nu"),
    ("E-unknown-param", at("model.0.params", {"stiffness": 1.0}), "model[0].params"),
    ("E-pbd-nu-0.495", both(at("model", [{"name": "pbd-xpbd-fem"}]), at("material.nu", 0.495)), "material.nu"),
    ("E-pbd-negative-nu", both(at("model", [{"name": "pbd-xpbd-fem"}]), at("material.nu", -0.2)), "material.nu"),
    ("E-pbd-traction", both(at("model", [{"name": "pbd-xpbd-fem"}]),
                            at("load_case.0.traction", [{"region": "x+", "traction": [1.0, 0.0, 0.0]}])),
     "load_case[0].traction"),
    ("E-pbd-second-model", both(at("model", [{"name": "hybmss"}, {"name": "pbd-xpbd-fem"}]),
                                at("material.nu", [0.3, 0.495])), "material.nu"),
    ("E-newton-xpbd", at("model", [{"name": "newton-xpbd"}]), "model[0].name"),
    ("E-newton-vbd-slide", both(at("model", [{"name": "newton-vbd"}]), add_support(
        name="side", region="x+", motion="slide", components=["x"])), "model[0].name"),
    ("E-mujoco-negative-nu", both(at("model", [{"name": "mujoco-tet"}]), at("material.nu", -0.3)), "material.nu"),
    ("E-mujoco-trilinear-not-a-box", both(body(mask="ell.npy", spacing=[0.01] * 3),
                                          at("model", [{"name": "mujoco-trilinear"}])), "model[0].name"),
    ("E-engine-explicit-massless", both(at("material.rho", 0.0), at("model", [
        {"name": "mujoco-tet", "solver": {"kind": "explicit", "dt": 1e-4, "steps": 100}}])), "material.rho"),
    ("E-corot-implicit", at("model.0", {"name": "corot-hex8", "solver": {"kind": "implicit", "dt": 0.1,
                                                                         "steps": 5}}), "model[0].solver"),
    # ------------------------------------------------ F. bodies
    ("F-box-and-mesh", at("body.mesh", "x.stl"), "body.mesh"),
    ("F-cell-larger-than-box", at("body.cell_sizes", [0.05]), "body.cell_sizes"),
    ("F-box-zero-edge", at("body.box", [0.02, 0.0, 0.04]), "body.box"),
    ("F-scale-zero", both(at("body.box", delete=True), at("body.pyvista", "ant"), at("body.scale", 0.0)),
     "body.scale"),
    ("F-mesh-is-a-folder", both(at("body.box", delete=True), at("body.mesh", ".")), "body.mesh"),
    ("F-mesh-wrong-suffix", both(at("body.box", delete=True), at("body.mesh", "study.toml")), "body.mesh"),
    ("F-mask-wrong-suffix", body(mask="study.toml", spacing=[0.01] * 3), "body.mask"),
    ("F-labels-zero", body(mask="m.npy", spacing=[0.01] * 3, labels=[0]), "body.labels"),
    ("F-labels-text", body(mask="m.npy", spacing=[0.01] * 3, labels="all"), "body.labels"),
    ("F-labels-absent", body(mask="m.npy", spacing=[0.01] * 3, labels=[7]), "body.labels"),
    ("F-spacing-negative", body(mask="m.npy", spacing=[0.01, -0.01, 0.01]), "body.spacing"),
    ("F-spacing-1nm", body(mask="m.npy", spacing=[1e-9] * 3), "body.cell_sizes"),
    ("F-mask-2d", body(mask="flat.npy", spacing=[0.01] * 3), "body.mask"),
    ("F-mask-float", body(mask="float.npy", spacing=[0.01] * 3), "body.mask"),
    ("F-mask-empty", body(mask="empty.npy", spacing=[0.01] * 3), "body.mask"),
    ("F-mask-zeros", body(mask="zeros.npy", spacing=[0.01] * 3), "body.mask"),
    ("F-mask-garbage", body(mask="garbage.npy", spacing=[0.01] * 3), "body.mask"),
    ("F-mesh-garbage", both(at("body.box", delete=True), at("body.mesh", "garbage.stl")), "body.mesh"),
    ("F-mesh-empty-file", both(at("body.box", delete=True), at("body.mesh", "empty.stl")), "body.mesh"),
    ("F-mesh-self-crossing", both(at("body.box", delete=True), at("body.mesh", "crossing.stl")), "body.mesh"),
    ("F-label-region-on-box", at(f"{SUP}.1.region", {"label": 1}), "load_case[0].support[1].region.label"),
    ("F-origin-far", at("body.origin", [1e300, 0.0, 0.0]), "body.origin"),
    ("F-surface-coordinates-far", both(at("body", {"mesh": "far.vtp", "cell_sizes": [0.01]}), NO_METRICS),
     "body.mesh"),
    # ------------------------------------------------ G. sizes past the machine
    ("G-sphere-at-2-cm", both(at("body", {"pyvista": "sphere", "cell_sizes": [0.02]}),
                              at(SUP, [{"name": "bottom", "region": "z-"}]), NO_METRICS), "body.cell_sizes"),
    ("G-box-of-a-km", both(at("body.box", [1000.0, 1000.0, 1000.0]), at("body.cell_sizes", [0.1]),
                           NO_METRICS), "body.cell_sizes"),
    ("G-explicit-1e9-steps", at("model.0.solver", {"kind": "explicit", "dt": 1e-4, "steps": 10**9}),
     "model[0].solver.steps"),
    ("G-implicit-1e8-steps", at("model.0.solver", {"kind": "implicit", "dt": 1e-4, "steps": 10**8}),
     "model[0].solver.steps"),
    # ------------------------------------------------ H. names
    ("H-label-accent", at("model.0.label", "modèle"), "model[0].label"),
    ("H-label-cjk", at("model.0.label", "模型"), "model[0].label"),
    ("H-label-newline", at("model.0.label", "a\nb"), "model[0].label"),
    ("H-label-blank", at("model.0.label", "   "), "model[0].label"),
    ("H-labels-one-file", at("model", [{"name": "hybmss", "label": "a/b"}, {"name": "hybmss-fd", "label": "a:b"}]),
     "model[1].label"),
    ("H-support-name-emoji", both(at(f"{SUP}.1.name", "top ⬆"), NO_METRICS), "load_case[0].support[1].name"),
    ("H-support-names-equal", at(f"{SUP}.1.name", "bottom"), "load_case[0].support[1].name"),
    ("H-point-name-unicode", at("metrics.points", {"tête": [0.01, 0.01, 0.04]}), "metrics.points.tête"),
    ("H-study-name-unicode", at("study.name", "étude"), "study.name"),
    ("H-study-name-path", at("study.name", "../../etc"), "study.name"),
    ("H-case-name-space", at("load_case.0.name", "press down"), "load_case[0].name"),
    # ------------------------------------------------ I. misspelt keys
    ("I-top", at("materials", {}), "materials"),
    ("I-study", at("study.titel", "x"), "study.titel"),
    ("I-body", at("body.cellsizes", [0.01]), "body.cellsizes"),
    ("I-body-source", both(at("body.box", delete=True), at("body.bxo", [0.02, 0.02, 0.04])), "body.bxo"),
    ("I-material", at("material.Nu", 0.3), "material.Nu"),
    ("I-body-experiment", at("body", {"experimnt": "compression", "mesh": [[2, 2, 2]]}), "body.experimnt"),
    ("I-load-case", at("load_case.0.gravitiy", [0.0, 0.0, -9.81]), "load_case[0].gravitiy"),
    ("I-support", at(f"{SUP}.1.motoin", "clamped"), "load_case[0].support[1].motoin"),
    ("I-region", at(f"{SUP}.1.region", {"fase": "z+"}), "load_case[0].support[1].region.fase"),
    ("I-model", at("model.0.lable", "x"), "model[0].lable"),
    ("I-solver", at("model.0.solver", {"kind": "explicit", "dt": 1e-4, "step": 10}), "model[0].solver.step"),
    ("I-reference", at("reference.laws", "linear"), "reference.laws"),
    ("I-metrics", at("metrics.point", {}), "metrics.point"),
]

ACCEPTED = [
    # valid files the check must let through (exit 0 at the check; the runs are other tests')
    ("ok-title-script", at("study.title", "</style><script>alert(1)</script>")),
    ("ok-title-unicode", at("study.title", "Étude du foie — 肝臓")),
    ("ok-nu-at-the-solvers-end", at("material.nu", 0.49999)),
    ("ok-E-steel", at("material.E", 2.1e11)),
    ("ok-agreeing-supports", add_support(name="floor-z", region="z-", motion="slide", components=["z"])),
    ("ok-label-punctuation", at("model.0.label", "hybmss (E-form, A=2)")),
    ("ok-mask", body(mask="m.npy", spacing=[0.01] * 3)),
    ("ok-two-pieces-each-held", both(body(mask="two.npy", spacing=[0.01] * 3), at(SUP, [
        {"name": "floor", "region": "z-"},
        {"name": "top", "region": "z+", "motion": "translate", "displacement": [0.0, 0.0, -0.0001]}]))),
]


def _files(folder):
    """The files the cases name, in the study's folder."""
    import pyvista as pv

    block = np.ones((2, 2, 4), dtype=np.int8)
    np.save(folder / "m.npy", block)
    np.save(folder / "flat.npy", np.ones((4, 4), dtype=np.int8))
    np.save(folder / "float.npy", block.astype(float))
    np.save(folder / "empty.npy", np.zeros((0, 2, 4), dtype=np.int8))
    np.save(folder / "zeros.npy", np.zeros((2, 2, 4), dtype=np.int8))
    ell = np.ones((2, 2, 4), dtype=np.int8)
    ell[1, 1, 2:] = 0
    np.save(folder / "ell.npy", ell)
    two = np.zeros((5, 2, 4), dtype=np.int8)
    two[:2], two[3:] = 1, 2
    np.save(folder / "two.npy", two)
    (folder / "garbage.npy").write_bytes(b"\x93NUMPY not really")
    (folder / "garbage.stl").write_bytes(b"solid x\nfacet nonsense\n" * 3)
    (folder / "empty.stl").write_bytes(b"")
    a = pv.Box(bounds=(0, 0.02, 0, 0.02, 0, 0.03)).triangulate()
    b = pv.Box(bounds=(0, 0.02, 0, 0.02, 0.02, 0.05)).triangulate()
    a.append_polydata(b).save(folder / "crossing.stl")
    far = pv.Box(bounds=(0, 0.02, 0, 0.02, 0, 0.04)).triangulate()
    far.points = far.points.astype(float) + [1e8, 0.0, 0.0]  # float64 (an STL holds float32)
    far.save(folder / "far.vtp")


def test_the_probe_has_a_hundred_cases():
    assert len(CASES) + len(ACCEPTED) + 3 >= 100


def _write(doc, path):
    write(doc, path)
    path.write_text(path.read_text().replace(repr(float(NAN)), "nan"))
    return path


@pytest.mark.parametrize("case_id,edit,key", CASES, ids=[c[0] for c in CASES])
def test_refused_with_one_line_naming_the_key(tmp_path, cli_in_process, case_id, edit, key):
    _files(tmp_path)
    path = _write(changed(small_study(), edit), tmp_path / "study.toml")
    out = tmp_path / "out"
    proc = cli_in_process("study", path, "--out", out, "--no-progress")
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1 and "Traceback" not in proc.stderr and proc.stdout == "", proc.stderr
    assert f": {key} " in lines[0] or f": {key}[" in lines[0] or f": {key}." in lines[0], lines[0]
    assert "is not allowed" in lines[0], lines[0]
    assert not out.exists()


@pytest.mark.parametrize("case_id,edit", ACCEPTED, ids=[c[0] for c in ACCEPTED])
def test_valid_files_pass_the_check(tmp_path, case_id, edit):
    from studies.study import Study

    _files(tmp_path)
    study = Study.from_toml(_write(changed(small_study(), edit), tmp_path / "study.toml"))
    assert study.tasks()


def test_the_study_file_is_a_folder(tmp_path, cli_in_process):
    (tmp_path / "s.toml").mkdir()
    proc = cli_in_process("study", tmp_path / "s.toml", "--out", tmp_path / "out")
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1 and "FILE" in proc.stderr


def test_the_study_file_is_binary(tmp_path, cli_in_process):
    (tmp_path / "s.toml").write_bytes(bytes(range(256)))
    proc = cli_in_process("study", tmp_path / "s.toml", "--out", tmp_path / "out")
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1 and "FILE" in proc.stderr


def test_out_is_a_file(tmp_path, cli_in_process):
    (tmp_path / "out").write_text("x")
    path = write(small_study(), tmp_path / "s.toml")
    proc = cli_in_process("study", path, "--out", tmp_path / "out" / "deeper")
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert "out" in proc.stderr and "Traceback" not in proc.stderr


def test_the_study_file_is_empty(tmp_path, cli_in_process):
    (tmp_path / "s.toml").write_text("")
    proc = cli_in_process("study", tmp_path / "s.toml", "--out", tmp_path / "out")
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and ": body = '(missing)'" in lines[0], proc.stderr
