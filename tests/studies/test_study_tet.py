"""Study files with a tetrahedral body (``[body] tet_sizes``): the keys a tetrahedral body cannot
take refused before any work (exit 2, the key named), and the engines scored on their own
tetrahedra exactly as :mod:`studies.paper.tet_compare` scores them (the same reference, the same
nodes, the same error), the voxel models on the lattice nodes inside the faceted body."""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv

from study_files import write

pytest.importorskip("gmsh")

R, H, h, le = 0.01, 0.04, 0.008, 0.005


def _stl(folder) -> str:
    path = folder / "cyl.stl"
    pv.Cylinder(center=(0, 0, H / 2), direction=(0, 0, 1), radius=R, height=H, resolution=48).save(path)
    return str(path)


def _doc(models=("hybmss",), law="linear", refine=2) -> dict:
    return {
        "study": {"name": "tetcyl", "title": "cylinder on tets", "budgets": [0.05], "repeats": 1},
        "body": {"mesh": "cyl.stl", "tet_sizes": [h], "cell_sizes": [le]},
        "material": {"E": 1.0e4, "nu": 0.3, "rho": 1000.0},
        "load_case": [{"name": "squeeze", "support": [
            {"name": "bottom", "region": "z-", "motion": "clamped"},
            {"name": "top", "region": "z+", "motion": "translate", "displacement": [0.0, 0.0, -0.01 * H]}]}],
        "model": [{"name": m} for m in models],
        "reference": {"law": law, "refine": refine},
        "metrics": {"plate_force": ["top"]},
    }


def _set(doc, path, value):
    keys = [int(k) if k.isdigit() else k for k in path.split(".")]
    node = doc
    for k in keys[:-1]:
        node = node[k]
    node[keys[-1]] = value
    return doc


REFUSED = [
    ("body.tet_sizes", [0.005, 0.008], "body.tet_sizes"),  # increasing
    ("reference.law", "neo-hookean", "reference.law"),  # no nonlinear tetrahedral reference
    ("reference.refine", 3, "reference.refine"),  # a split halves h: 1, 2, 4
    ("load_case.0.gravity", [0.0, 0.0, -9.81], "load_case[0].gravity"),
    ("load_case.0.support.1.motion", "slide", "load_case[0].support[1].motion"),
    ("body.origin", [0.0, 0.0, 0.0], "body.origin"),
]


@pytest.mark.parametrize("path, value, key", REFUSED, ids=[k for _, _, k in REFUSED])
def test_a_tet_body_refuses_what_it_cannot_take(tmp_path, cli_in_process, path, value, key):
    _stl(tmp_path)
    doc = _doc()
    if path == "load_case.0.support.1.motion":
        doc["load_case"][0]["support"][1]["components"] = ["z"]
    file = write(_set(doc, path, value), tmp_path / "s.toml")
    out = tmp_path / "out"
    proc = cli_in_process("study", file, "--out", out, "--no-progress")
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and key in lines[0], proc.stderr
    assert not out.exists()


def test_tet_sizes_on_a_box_body_are_refused(tmp_path):
    from studies.study import Study
    from studies.study.errors import StudyError

    doc = _doc()
    doc["body"] = {"box": [0.02, 0.02, 0.04], "cell_sizes": [0.01], "tet_sizes": [0.01]}
    with pytest.raises(StudyError, match="body.tet_sizes"):
        Study.from_toml(write(doc, tmp_path / "s.toml"))


def test_the_engine_and_the_mss_are_scored_as_tet_compare_scores_them(tmp_path):
    """mujoco-tet on the study's own tetrahedra and hybmss on its voxels, against the P2
    reference refined once: the study's field error, reaction and counts of scored nodes equal
    those computed directly with studies.paper.tet_compare (its reference, its engine run on the
    gmsh tetrahedra of the same surface, its inside test)."""
    pytest.importorskip("mujoco")
    import pandas as pd

    from hybmss.scene import Material
    from hybmss.tetbody import mesh_surface
    from studies.paper import tet_compare as tc
    from studies.study import Study

    stl = _stl(tmp_path)
    study = Study.from_toml(write(_doc(("hybmss", "mujoco-tet")), tmp_path / "s.toml"))
    done = study.run(tmp_path / "out", jobs=1, progress=False)
    assert done["failed"] == 0, done["failures"]
    rows = pd.read_csv(done["tables"]["errors_squeeze"]).set_index("model")
    assert rows.loc["mujoco-tet", "mesh"] == "tets" and rows.loc["hybmss", "mesh"] == "voxels"

    body = mesh_surface(stl, h)
    assert np.array_equal(body.X, study.tet_bodies[0].X) and np.array_equal(body.tets, study.tet_bodies[0].tets)
    mat = Material(1.0e4, 0.3, 1000.0)
    z0, z1 = float(body.X[:, 2].min()), float(body.X[:, 2].max())
    motion = tc.loads(z0, z1, 0.01 * H / (z1 - z0), 0.0)["squeeze"]
    ref, prev, conv = tc.reference(body, mat, "squeeze", motion, levels=2)
    engine = tc.engine_rows(body, mat, "squeeze", motion, ref, prev, conv, ("mujoco-tet",))[0]
    voxel = tc.voxel_rows(body, stl, mat, "squeeze", 0.01 * H / (z1 - z0), 0.0, le, ref, prev, conv, ("hybmss",))[0]
    # the engine's run is repeated exactly; the MSS's Newton stops within its tolerance
    for name, direct, rel in (("mujoco-tet", engine, 1e-9), ("hybmss", voxel, 1e-4)):
        row = rows.loc[name]
        assert row["nodes_scored"] == direct["nodes"] and row["nodes_outside"] == direct["outside"]
        assert row["u_rel_l2"] == pytest.approx(direct["field"], rel=rel)
        # the squeeze's reaction is along z: its norm's error is the z component's within the lateral forces
        assert row["force_top_rel"] == pytest.approx(direct["reaction"], rel=1e-2, abs=1e-4)
    assert voxel["outside"] > 0 and engine["outside"] == 0


@pytest.mark.slow
def test_gel_cylinder_example_scores_every_engine_on_its_own_tetrahedra(tmp_path, cli_in_process):
    """The shipped example at --quick: every tetrahedral engine on the gmsh tetrahedra of the STL,
    hybmss and corot-hex8 on voxels; each engine's field error is tet_compare's score of the same
    nodes against tet_compare's reference on the same tetrahedra, and each engine's twist torque is
    above the reference's (P1 is a conforming displacement method: too stiff, never too soft)."""
    import json
    from pathlib import Path

    import pandas as pd

    from hybmss import models
    from hybmss.scene import Material
    from studies.paper import tet_compare as tc
    from studies.study import Study
    from studies.study.tables import loaded_runs
    from studies.sweep.tet_runs import TetEngineScene

    example = Path(__file__).resolve().parents[2] / "studies" / "examples" / "gel-cylinder.toml"
    out = tmp_path / "out"
    proc = cli_in_process("study", example, "--quick", "--out", out, "--jobs", "1", "--json", "--no-progress",
                          "--no-report")
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["failed"] == 0
    study = Study.from_toml(example, quick=True)
    body = study.tet_bodies[0]
    engines = {"mujoco-tet", "newton-semi", "newton-vbd", "pbd-xpbd-fem"} - set(models.unavailable())
    mat = Material(1.0e4, 0.3, 1000.0)
    z0, z1 = float(body.X[:, 2].min()), float(body.X[:, 2].max())
    runs = loaded_runs(study, out)
    # the file's 0.4 mm on gmsh's height z1 - z0 (its cap nodes within rounding of 0 and H)
    for load, motion in tc.loads(z0, z1, 0.01 * H / (z1 - z0), 0.01).items():
        rows = pd.read_csv(out / "tables" / f"gel-cylinder_errors_{load}.csv").set_index("model")
        assert set(rows.index) == engines | {"hybmss", "corot-hex8"}
        assert (rows.loc[list(engines), "mesh"] == "tets").all() and (rows.loc[list(engines), "nodes_outside"] == 0).all()
        assert (rows.loc[["hybmss", "corot-hex8"], "nodes_outside"] > 0).all()
        ref, prev, conv = tc.reference(body, mat, load, motion, levels=2)
        for r in runs:
            s = r["task"].scene
            if not (isinstance(s, TetEngineScene) and s.load_case == load):
                continue
            reaction = r["row"]["info"]["reaction_top_fz" if load == "squeeze" else "reaction_top_tz"]
            direct = tc.score(ref, prev, conv, r["arrays"]["X"], r["arrays"]["u"], reaction)
            assert rows.loc[s.label, "u_rel_l2"] == pytest.approx(direct["field"], rel=1e-9)
            assert direct["field"] > direct["ref_field"]  # the reference resolves the engine's error
            if load == "twist":
                assert abs(reaction) > abs(conv.values[-1]) and reaction * conv.values[-1] > 0
                assert rows.loc[s.label, "torque_top_rel"] == pytest.approx(direct["reaction"], rel=1e-2)


def test_the_reference_size_counts_the_p2_unknowns_scikit_fem_solves(tmp_path):
    """The guard's unknowns are scikit-fem's own: 3 per P2 node (vertices and edge midpoints) on
    the tetrahedra as meshed (refine 1) and on the mesh split once and twice (refine 2, 4)."""
    import skfem

    from studies.study import Study
    from studies.study.tet import reference_size
    from studies.sweep import sizing

    _stl(tmp_path)
    body = Study.from_toml(write(_doc(), tmp_path / "s.toml")).tet_bodies[-1]
    mesh = skfem.MeshTet(np.asarray(body.X, dtype=float).T, np.asarray(body.tets).T)
    for refine, m in ((1, mesh), (2, mesh.refined()), (4, mesh.refined(2))):
        n = skfem.Basis(m, skfem.ElementVector(skfem.ElementTetP2())).N
        guessed = (reference_size(body, refine, 0.3).bytes - sizing.BASE_BYTES) / \
            (sizing.fem_of(1.0).bytes - sizing.BASE_BYTES)
        assert guessed == n, (refine, guessed, n)


def test_a_reference_that_does_not_fit_memory_is_refused_and_auto_stops_where_it_fits(tmp_path, cli_in_process,
                                                                                      monkeypatch):
    """On a machine whose memory holds the reference at refine 1 but not 2: refine = 2 is refused
    before any work (exit 2, reference.refine), and refine = "auto" is accepted with its finest
    level 1 (its row then says its estimate was not reached)."""
    from studies.study import Study
    from studies.study.tet import reference_size
    from studies.sweep import sizing

    _stl(tmp_path)
    body = Study.from_toml(write(_doc(), tmp_path / "s.toml")).tet_bodies[-1]
    need = [reference_size(body, r, 0.3).bytes for r in (1, 2)]
    monkeypatch.setattr(sizing, "limit", lambda: (need[0] + need[1]) / 2)
    out = tmp_path / "out"
    proc = cli_in_process("study", write(_doc(refine=2), tmp_path / "two.toml"), "--out", out, "--no-progress")
    assert proc.returncode == 2 and "reference.refine" in proc.stderr and not out.exists(), proc.stderr
    study = Study.from_toml(write(_doc(refine="auto"), tmp_path / "auto.toml"))
    (ref,) = [t for t in study.tasks() if t.solver.kind == "fem"]
    assert ref.scene.largest == 1
