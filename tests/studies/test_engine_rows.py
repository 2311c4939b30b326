"""The engines' rows in the studies: on meshes of their own with the FEM of the same mesh, the quick
mode's one case, failure rows that say what an engine cannot represent, and the closing study's
table (:mod:`studies.engines`)."""

from __future__ import annotations

import pytest

from studies import engines, pareto, roles
from studies.runner import SolverSpec, Task, compute
from studies.store import Store

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
