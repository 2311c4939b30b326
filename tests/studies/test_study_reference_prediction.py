"""An adaptive reference (``refine = "auto"``) predicted by a coarser configuration's: the finer
voxelization solves refine 1 only when the coarser one's refine-1 error estimate meets the target,
and refines as before otherwise (:func:`studies.study.tasks.predicted_refine_one`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from study_files import small_study, write


def _hanging(tmp_path, tolerance: float, sizes=(0.01, 0.005), budget: float = 0.1):
    from studies.study import Study

    doc = small_study()
    doc["body"]["cell_sizes"] = list(sizes)
    doc["load_case"] = [{"name": "hang", "gravity": [-9.81, 0.0, 0.0],
                         "support": [{"name": "top", "region": "z+", "motion": "clamped"}]}]
    doc["metrics"] = {"plate_force": ["top"]}
    doc["reference"] = {"element": "hex2", "law": "linear", "refine": "auto", "tolerance": tolerance}
    doc["study"]["budgets"] = [budget]
    return Study.from_toml(write(doc, tmp_path / f"hang-{tolerance}.toml"))


def _levels(scene):
    from fem_reference.solve import solve

    return [solve(scene, element="hex2", law="linear", refine=r) for r in (1, 2)]


def test_a_finer_configuration_solves_refine_one_when_the_coarser_predicts_it_meets_the_target(tmp_path):
    """A cantilever under its weight at 10 and 5 mm: the 5 mm reference takes the 10 mm one's
    refine-1 estimate (two levels solved here again) as its own and solves refine 1 only; that
    prediction bounds the 5 mm refine-1 error measured here from its own two levels."""
    from studies.study.tasks import is_reference, reference_estimate

    study = _hanging(tmp_path, tolerance=0.5)
    study.run(tmp_path / "out", jobs=1, progress=False)
    refs = study.tables(tmp_path / "out")["reference"].set_index("cell_size_m")
    coarse, fine = (t.scene.build() for t in sorted((t for t in study.tasks() if is_reference(t)),
                                                     key=lambda t: -t.scene.cell_size))
    c1c2, f1f2 = _levels(coarse), _levels(fine)
    predicted = reference_estimate(coarse, c1c2, [1, 2], level="coarsest")
    measured = reference_estimate(fine, f1f2, [1, 2], level="coarsest")
    assert refs.loc[0.01, "refine"] == 2 and refs.loc[0.01, "error_basis"] == "richardson"
    assert refs.loc[0.005, "refine"] == 1 and refs.loc[0.005, "error_basis"] == "predicted"
    assert math.isclose(refs.loc[0.005, "error_estimate"], predicted, rel_tol=1e-9)
    assert predicted <= refs.loc[0.005, "error_target"] == 0.05
    assert measured < predicted  # the rule's premise, on this body
    # the stored field is the 5 mm refine-1 solution
    from studies.sweep.store import Store

    task = [t for t in study.tasks() if is_reference(t) and t.scene.cell_size == 0.005][0]
    u = Store(tmp_path / "out").arrays(task.key())["u"]
    assert np.allclose(u, f1f2[0].u, rtol=0, atol=1e-12 * np.abs(u).max())


def test_a_prediction_above_the_target_refines_as_before(tmp_path):
    """The same bodies with a target below the 10 mm refine-1 estimate: the 5 mm reference
    refines (refine 2 at least, its own Richardson estimate)."""
    study = _hanging(tmp_path, tolerance=0.02)
    study.run(tmp_path / "out", jobs=1, progress=False)
    refs = study.tables(tmp_path / "out")["reference"].set_index("cell_size_m")
    assert refs.loc[0.005, "refine"] >= 2 and refs.loc[0.005, "error_basis"] == "richardson"
    from studies.study.tasks import is_reference
    from studies.sweep.store import Store

    coarse = [t for t in study.tasks() if is_reference(t) and t.scene.cell_size == 0.01][0]
    info = Store(tmp_path / "out").row(coarse.key())["info"]
    assert info["reference_refine1_error"] > refs.loc[0.005, "error_target"]  # the prediction it refused


def test_a_chain_of_predictions_passes_each_prediction_on(tmp_path):
    """At 20, 10 and 5 mm the 10 mm reference is predicted by the 20 mm one and predicts the 5 mm
    one in turn: both solve refine 1 only, with the 20 mm refine-1 estimate as theirs."""
    study = _hanging(tmp_path, tolerance=1.0, sizes=(0.02, 0.01, 0.005), budget=0.5)
    study.run(tmp_path / "out", jobs=1, progress=False)
    refs = study.tables(tmp_path / "out")["reference"].set_index("cell_size_m")
    assert refs.loc[0.02, "error_basis"] == "richardson" and refs.loc[0.02, "refine"] >= 2
    assert list(refs.loc[[0.01, 0.005], "error_basis"]) == ["predicted", "predicted"]
    assert list(refs.loc[[0.01, 0.005], "refine"]) == [1, 1]
    assert refs.loc[0.005, "error_estimate"] == refs.loc[0.01, "error_estimate"] <= refs.loc[0.005, "error_target"]


@pytest.mark.parametrize("sizes, predictors", [
    ((0.01, 0.005), {0.005: 0.01}),
    ((0.005, 0.004, 0.0025), {0.0025: 0.005}),  # 0.004 has none twice as coarse
    ((0.02, 0.01, 0.005), {0.01: 0.02, 0.005: 0.01}),  # a chain: two sweeps before the rest
])
def test_each_reference_names_the_nearest_configuration_twice_as_coarse(tmp_path, sizes, predictors):
    from studies.study.tasks import is_reference, predictor_sweeps

    study = _hanging(tmp_path, tolerance=0.5, sizes=sizes)
    tasks = study.tasks()
    refs = {t.scene.cell_size: t for t in tasks if is_reference(t)}
    named = {le: next(c for c, s in refs.items() if s.key() == t.scene.predictor)
             for le, t in refs.items() if t.scene.predictor}
    assert named == predictors
    sweeps = predictor_sweeps(tasks)
    assert [[t.scene.cell_size for t in s] for s in sweeps] == [[c] for c in sorted(set(predictors.values()),
                                                                                   reverse=True)]
