"""The engines' rows in the studies: on meshes of their own with the FEM of the same mesh, the quick
mode's one case, failure rows that say what an engine cannot represent, and the closing study's
table (:mod:`studies.engines`)."""

from __future__ import annotations

import pytest

from studies import engines, pareto, reproduce, roles
from studies.runner import SolverSpec, Task, compute
from studies.store import Store

pytest.importorskip("mujoco")


def _engine_tasks(ts):
    return [t for t in ts if roles.part(t.scene.model).meshes and t.solver.kind != "fem"]


def test_engine_rows_run_on_their_meshes_beside_the_fem_of_it():
    ts = reproduce.tasks_for(None, quick=False)
    eng = _engine_tasks(ts)
    assert {t.scene.model for t in eng} == set(engines.engine_models()) - {"newton-vbd", "pbd-xpbd-fem"}
    fem = {(t.scene.experiment, t.scene.mesh, t.scene.nu, t.scene.deformation, t.scene.angle_deg, t.scene.E)
           for t in ts if t.solver.kind == "fem"}
    for t in eng:
        s = t.scene
        own = roles.part(s.model).meshes["beam" if s.is_beam else "cube"]
        assert s.mesh == own, (s.model, s.mesh)
        assert (s.experiment, s.mesh, s.nu, s.deformation, s.angle_deg, s.E) in fem, t.scene.label
    assert all(t.solver.kind == "static" for t in eng)  # no explicit protocol for the engines


def test_quick_mode_runs_one_case_per_experiment_and_leaves_slow_engines_out():
    eng = _engine_tasks(reproduce.tasks_for(None, quick=True))
    assert eng and all(reproduce.quick_case(t.scene) for t in eng)
    assert not [t for t in eng if not roles.part(t.scene.model).quick]
    per_model = {}
    for t in eng:
        per_model.setdefault(t.scene.model, set()).add(t.scene.experiment)
    assert per_model["mujoco-tet"] == {"compression", "tension", "shear", "torsion"}
    assert "pbd-xpbd-fem" not in per_model and "newton-vbd" not in per_model
    pq = [t for t in pareto.tasks(quick=True) if t.scene.model in engines.engine_models()]
    assert pq and all(t.solver.kind == "static" for t in pq)


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
