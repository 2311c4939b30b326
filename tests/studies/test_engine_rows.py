"""The engines' rows in the studies: on meshes of their own with the FEM of the same mesh, the quick
mode's one case, failure rows that say what an engine cannot represent, and the closing study's
table (:mod:`studies.paper.engines`)."""

from __future__ import annotations

import pytest

from studies.paper import engines

from studies.paper import pareto

from studies.sweep import roles
from studies.sweep.runner import SolverSpec, Task, compute
from studies.sweep.store import Store

pytest.importorskip("mujoco")


def test_pareto_runs_the_engines_static_answer_at_the_base_resolution_only():
    pq = [t for t in pareto.tasks(quick=True) if t.scene.model in engines.engine_models()]
    assert pq and all(t.solver.kind == "static" for t in pq)
    assert not [t for t in pq if t.scene.experiment == "bending"]


def test_a_scene_an_engine_cannot_represent_is_a_failure_row_that_says_so():
    pytest.importorskip("newton")
    spec = engines.specs(quick=True)[0].replace(model="newton-xpbd")
    row, arrays = compute(Task(spec, SolverSpec("static"), "engines"))
    assert row["status"] == "not-representable" and arrays is None
    assert "SceneNotRepresentable" in row["message"] and "shear modulus" in row["message"]


@pytest.mark.slow
def test_closing_table_on_the_small_cube(tmp_path):
    """mujoco-trilinear's cells are corotational linear Hex8, corot-hex8's element: the same force
    to round-off on the same mesh; the errors are against the FEM row of the same scene."""
    t = engines.run(Store(tmp_path), quick=True, jobs=1, progress=False, timing=False,
                    names=("mujoco-trilinear", "corot-hex8"))["engines_closing"]
    assert set(t["experiment"]) == {"compression", "shear"}
    for _, g in t.groupby("experiment"):
        r = g.set_index("model")
        assert r.loc["mujoco-trilinear", "force_N"] == pytest.approx(r.loc["corot-hex8", "force_N"], rel=1e-6)
        for m in ("mujoco-trilinear", "corot-hex8"):
            F, Ff = r.loc[m, "force_N"], r.loc[m, "force_fem_N"]
            assert r.loc[m, "force_rel_error"] == pytest.approx(abs(F - Ff) / abs(Ff), rel=1e-12)
            assert r.loc[m, "status"] == "ok"


def test_the_report_says_what_each_registered_engine_is():
    assert set(roles.ENGINE_LAWS) == set(engines.engine_models())


# ------------------------------------------------------------------ the publication's experiment tables
def _doc(name: str, **over):
    from studies.paper.reproduce import load_study_file

    doc = load_study_file(name)
    for k, v in over.items():
        section, key = k.split("__")
        doc[section][key] = v
    return doc


def _engines():
    return [m for m in roles.in_role("tables") if roles.part(m).meshes]


@pytest.mark.parametrize("name", ["compression", "tension", "shear", "torsion", "bending"])
def test_the_engines_run_the_experiments_on_their_own_meshes_beside_the_fem_of_that_mesh(name):
    """Full study: every engine run is on its part's mesh, and each has the study's references
    (law and large laws) on that same mesh and configuration; no task is listed twice."""
    from studies.study.experiment import experiment_tasks, reference_solvers

    doc = _doc(name)
    ts = experiment_tasks(doc, quick=False)
    assert set(_engines()) >= {"mujoco-tet", "mujoco-trilinear", "newton-semi"}
    eng = [t for t in ts if t.scene.model in _engines() and t.solver.kind == "static"]
    kind = "beam" if name in ("tension", "bending") else "cube"
    assert {t.scene.model for t in eng} == set(_engines())
    for t in eng:
        assert t.scene.mesh == tuple(roles.part(t.scene.model).meshes[kind])
        want = {json_(fs) for fs in reference_solvers(doc["reference"], t.scene)}
        have = {json_(r.solver) for r in ts if r.solver.kind == "fem" and r.scene.mesh == t.scene.mesh
                and r.scene.nu == t.scene.nu and r.scene.deformation == t.scene.deformation
                and r.scene.angle_deg == t.scene.angle_deg and r.scene.E == t.scene.E}
        assert want and want <= have, (t.scene, want, have)
    keys = [(t.scene, json_(t.solver), t.study) for t in ts]
    assert len(keys) == len(set(keys))
    # the other models stay on the publication's meshes
    pub = {tuple(m) for m in doc["body"]["mesh"]}
    assert {t.scene.mesh for t in ts if t.solver.kind != "fem" and t.scene.model not in _engines()} <= pub


def json_(solver) -> str:
    import json

    return json.dumps(solver.relevant(), sort_keys=True)


def test_the_quick_mode_runs_an_engine_s_first_case_only_or_none():
    from studies.study.experiment import experiment_tasks

    for name, load in (("compression", ("deformation", 0.05)), ("torsion", ("angle_deg", 1.0))):
        eng = [t for t in experiment_tasks(_doc(name), quick=True) if t.scene.model in _engines()
               and t.solver.kind == "static"]
        assert {t.scene.model for t in eng} == set(_engines())
        assert {(t.scene.nu, getattr(t.scene, load[0])) for t in eng} == {(0.25, load[1])}
    was = roles.part("mujoco-tet")
    roles.declare("mujoco-tet", roles.Part(was.roles, meshes=was.meshes, run_cost=was.run_cost, quick=False))
    try:
        models_ = {t.scene.model for t in experiment_tasks(_doc("shear"), quick=True)}
    finally:
        roles.withdraw("mujoco-tet")
    assert "mujoco-tet" not in models_ and "mujoco-trilinear" in models_


@pytest.fixture
def trilinear_on_2_cubed():
    """mujoco-trilinear's part with the 2³ cube as its own mesh (the shipped part's 5³ would make the
    test below solve a 6³ and a 5³ study)."""
    import dataclasses

    roles.declare("mujoco-trilinear", dataclasses.replace(roles.part("mujoco-trilinear"), meshes={"cube": (2, 2, 2)}))
    yield
    roles.withdraw("mujoco-trilinear")


def test_engine_rows_in_the_tables_against_the_fem_of_their_own_mesh(tmp_path, trilinear_on_2_cubed):
    """A compression study on the 3³ cube (not in the quick mode: every case of the file) with
    hybmss and mujoco-trilinear, whose part puts it on the 2³ cube: its row is on the 2³ mesh and
    its Δe is against the FEM solved on 2³ (recomputed here with scikit-fem directly), its plate
    force that of corot-hex8 on the same cells (the same element: equal to 1e-6); at ν = −0.1,
    which MuJoCo cannot represent, its cell is a failure; the 3³ rows say "–" for it, and the table
    beside [G20] has no 2³ row."""
    from fem_reference.solve import solve as fem_solve
    from hybmss.solve import solve_static
    from reports.data import Results
    from reports.sections.publication import competitors_volume_tables, volume_table
    from studies.sweep.runner import run_tasks
    from studies.study.experiment import experiment_tasks
    from studies.paper.tables import write_tables

    doc = _doc("compression", body__mesh=[[3, 3, 3]], material__nu=[0.25, -0.1], load__deformation=[0.05])
    ts = [t for t in experiment_tasks(doc, quick=False)
          if t.solver.kind == "fem" or t.scene.model in ("hybmss", "mujoco-trilinear")]
    assert {t.scene.mesh for t in ts if t.scene.model == "mujoco-trilinear" and t.solver.kind == "static"} == {(2, 2, 2)}
    store = Store(tmp_path)
    rows = run_tasks(ts, store, jobs=1, progress=False)
    write_tables(store, {t.key() for t in ts})
    results = Results(tmp_path)

    tri = next(r for t, r in zip(ts, rows) if t.scene.model == "mujoco-trilinear" and t.scene.nu == 0.25
               and t.solver.kind == "static")
    assert tri["status"] == "ok" and tri["mesh"] == "2x2x2"
    spec = next(t.scene for t in ts if t.scene.model == "mujoco-trilinear" and t.scene.nu == 0.25)
    corot = solve_static(spec.replace(model="corot-hex8").build())
    assert tri["force_z"] == pytest.approx(corot.reactions["top"].force[2], rel=1e-6)
    fem_own = fem_solve(spec.build(), element="auto", law="linear")
    e_tet, e_fem_own = 100 * abs(tri["volume_change"]), 100 * abs(fem_own.volume_change)

    tab = competitors_volume_tables(results, "table2_compression", "compression", 2)[0]
    col = tab.columns.index("mujoco-trilinear (pp)")
    by = {(r[0][0], r[1][0]): r for r in tab.rows}
    cell = by[("2x2x2", "0.25")][col]
    assert float(cell[0]) == pytest.approx(round(e_tet - e_fem_own, 3), abs=1.5e-3)
    fem_pub = fem_solve(spec.replace(mesh=(3, 3, 3)).build(), element="auto", law="linear")
    assert abs((e_tet - 100 * abs(fem_pub.volume_change)) - (e_tet - e_fem_own)) > 2e-3  # another mesh's FEM differs
    assert by[("2x2x2", "-0.1")][col][1] == "fail" and "not-representable" in by[("2x2x2", "-0.1")][col][0]
    assert by[("3x3x3", "0.25")][col] == ("–", "")
    hyb = tab.columns.index("hybmss (E-form) (pp)") if "hybmss (E-form) (pp)" in tab.columns else None
    if hyb is not None:
        assert by[("2x2x2", "0.25")][hyb][0] in ("–", "not in the study at this ν")
    g20 = volume_table(results, "table2_compression", "compression", 2)
    assert {r[0][0] for r in g20.rows} == {"3x3x3"}


def test_bending_row_of_mujoco_trilinear_is_corot_hex8_on_the_same_cells():
    """The cantilever under its weight on the engine's own beam: MuJoCo's trilinear cells are
    corotational linear Hex8, corot-hex8's element, so the engine's damped run to rest gives the tip
    deflection of corot-hex8's Newton solve on the same cells (to the rest test's tolerance), a
    stored row of the study's table beside the FEM of that mesh."""
    from studies.study.experiment import experiment_tasks

    ts = experiment_tasks(_doc("bending"), quick=True)
    tri = next(t for t in ts if t.scene.model == "mujoco-trilinear")
    assert tri.scene.mesh == tuple(roles.part("mujoco-trilinear").meshes["beam"])
    row, _ = compute(tri)
    corot, _ = compute(Task(tri.scene.replace(model="corot-hex8"), tri.solver, "bending"))
    assert row["status"] == corot["status"] == "ok"
    assert row["tip_deflection"] == pytest.approx(corot["tip_deflection"], rel=1e-5)
    assert row["tip_deflection"] < 0


# ------------------------------------------------------------------ the stability study's hard cases
def test_the_stability_hard_cases_of_the_engines_are_runs_of_the_tables():
    """Full mode: every run of part (g) (engines and their same-mesh FEM) is a run of the
    experiment tables (the same key), so the part costs make reproduce-paper nothing; each engine
    on its own cube, at ν = 0.499 and 20 %."""
    from studies.paper import stability
    from studies.paper.reproduce import tasks_for

    g = stability.engine_tasks(quick=False)
    table_keys = {t.key() for t in tasks_for(["compression", "shear"], quick=False)}
    assert g and all(t.key() in table_keys for _, t in g)
    eng = [t for kind, t in g if kind == "engine"]
    assert {t.scene.model for t in eng} == set(_engines())
    assert all(t.scene.mesh == tuple(roles.part(t.scene.model).meshes["cube"]) for t in eng)
    assert {(t.scene.experiment, t.scene.nu, t.scene.deformation) for t in eng} >= {
        ("compression", 0.499, 0.20), ("shear", 0.499, 0.20)}
    fems = {(t.scene.experiment, t.scene.mesh, t.scene.nu, t.scene.deformation) for kind, t in g if kind == "fem"}
    assert {(t.scene.experiment, t.scene.mesh, t.scene.nu, t.scene.deformation) for t in eng} == fems


def test_the_stability_table_says_rest_locking_no_rest_and_refusal():
    """The behaviour of each engine row from its run and the same-mesh FEM's: a force 2× the FEM's
    at rest locks, 1.2× is rest; a run that did not come to rest and a refused scene say so."""
    from hybmss.experiments import SceneSpec
    from studies.paper import stability

    spec = SceneSpec.default("compression", mesh=(5, 5, 5), nu=0.499, deformation=0.2)
    ts = [("engine", Task(spec.replace(model=m), SolverSpec("static"), "stability"))
          for m in ("mujoco-tet", "mujoco-trilinear", "newton-semi", "mujoco-quadratic")]
    ts.append(("fem", Task(spec, SolverSpec("fem", element="auto", law="neo-hookean"), "stability")))
    rows = [{"status": "ok", "force_z": -2000.0, "solver_iterations": 4000, "wall_time_s": 1.0},
            {"status": "ok", "force_z": -1200.0, "solver_iterations": 3000, "wall_time_s": 1.0},
            {"status": "unstable", "message": "StaticSolveError: newton-semi scene: the damped run did not come to "
             "rest within 9 s (kinetic energy); raise the damping or the time budget", "wall_time_s": 9.0},
            {"status": "not-representable", "message": "SceneNotRepresentable: nu must lie in [0, 0.5)"},
            {"status": "ok", "force_z": -1000.0, "solver": "fem-auto-neo-hookean"}]
    t = stability.engine_table(ts, rows).set_index("model")
    assert t.loc["mujoco-tet", "behaviour"] == "locks" and t.loc["mujoco-tet", "force_ratio"] == pytest.approx(2.0)
    assert t.loc["mujoco-trilinear", "behaviour"] == "rest"
    assert t.loc["mujoco-trilinear", "force_rel_error"] == pytest.approx(0.2)
    assert t.loc["newton-semi", "behaviour"] == "no rest" and pd_isna(t.loc["newton-semi", "force_N"])
    assert t.loc["mujoco-quadratic", "behaviour"] == "not-representable"
    assert "nu must lie" in t.loc["mujoco-quadratic", "message"]


def pd_isna(v) -> bool:
    import pandas as pd

    return bool(pd.isna(v))


def test_the_speed_against_error_study_runs_no_engine_on_a_base_finer_than_its_own_mesh():
    """Cost: mujoco-quadratic's 27-node cells on the full level's 5³ cube (2.6–12 s a run, three
    timed runs each) were about half the engines' time; it keeps its rows at the quick level."""
    from studies.paper.engines import engine_models

    for quick in (True, False):
        ts = [t for _, t in pareto.all_tasks(quick) if t.scene.model in engine_models()]
        assert all(roles.mesh_for(t.scene.model, t.scene) == t.scene for t in ts)
        assert ("mujoco-quadratic" in {t.scene.model for t in ts}) == quick
        assert {"mujoco-tet", "mujoco-trilinear", "newton-semi"} <= {t.scene.model for t in ts}
