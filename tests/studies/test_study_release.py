"""``release = true`` of a study's load case through ``hybmss study``: the table
``<name>_dynamics_<load case>.csv`` held to independent computations, and the refusals of release
keys not allowed.

Theory: a 1×1×6 cantilever (1 cm cells) released from its sag under gravity along y swings in its
first bending mode in y (the load is nearly that mode's shape; the square section's x mode is not
excited).  A model's measured period is its own lattice's first period 2π/ω₁
(:func:`hybmss.modes.lattice_modes`, K φ = ω² M φ with its lumped masses) lengthened by its
integrator's known factor, semi-implicit Euler's ``z / (2 arcsin(z/2))`` at ``z = ω₁ Δt`` with the
table's ``Δt``; the rest is the higher modes the release also excites (a fraction of a per mille
here).  The FEM reference's period is its own modal period (:func:`fem_reference.modal.modes`,
Hex2, consistent mass) within the study's period tolerance of the FEM transient (0.1 %).
"""

from __future__ import annotations

import math

import pandas as pd
import pytest

from study_files import small_study, write

E, NU, RHO, LE, N = 1e6, 0.3, 1000.0, 0.01, 6


def swing_study() -> dict:
    return {
        "study": {"name": "swing", "title": "released cantilever", "budgets": [0.05, 0.2, 0.4], "repeats": 1},
        "body": {"box": [LE, LE, N * LE], "cell_sizes": [LE]},
        "material": {"E": E, "nu": NU, "rho": RHO},
        "load_case": [{"name": "drop", "gravity": [0.0, -9.81, 0.0], "release": True, "periods": 3,
                       "support": [{"name": "clamp", "region": "z-", "motion": "clamped"}]}],
        "model": [{"name": "hybmss-cf"}, {"name": "corot-hex8"}],
        "reference": {"element": "hex2", "law": "linear", "refine": 1},
        "metrics": {"plate_force": ["clamp"]},
    }


@pytest.fixture(scope="module")
def swing(tmp_path_factory, cli_in_process):
    tmp = tmp_path_factory.mktemp("swing")
    out = tmp / "out"
    path = write(swing_study(), tmp / "swing.toml")
    proc = cli_in_process("study", path, "--out", out, "--jobs", "1", "--no-progress", "--no-report")
    assert proc.returncode == 0, proc.stderr
    table = pd.read_csv(out / "tables" / "swing_dynamics_drop.csv")
    table.attrs.update(out=out, path=path, stdout=proc.stdout)
    return table


def _scenes(path) -> dict:
    from studies.study import Study
    from studies.study.tasks import is_reference

    return {("fem" if is_reference(t) else t.scene.label): t.scene.scene for t in Study.from_toml(path).tasks()}


def test_model_periods_are_their_lattice_modes_through_their_integrator(swing):
    from hybmss.modes import lattice_modes

    scenes = _scenes(swing.attrs["path"])
    assert sorted(swing["model"]) == ["corot-hex8", "hybmss-cf"] and (swing["status"] == "ok").all()
    for row in swing.to_dict("records"):
        w = 2 * math.pi * lattice_modes(scenes[row["model"]], 1).freq[0]
        z = w * row["dt_s"]
        expected = 2 * math.pi / w * z / (2 * math.asin(z / 2))
        assert row["period_s"] == pytest.approx(expected, rel=3e-3), row["model"]
        assert row["integrator"].startswith("semi-implicit Euler") and row["substeps"] == 1
        assert abs(row["zeta"]) < 2e-3  # symplectic Euler keeps the amplitude
        assert row["period_error_pct"] == pytest.approx(100 * (row["period_s"] / row["period_ref_s"] - 1), rel=1e-9)
        assert row["wall_per_simulated_s"] > 0 and row["phase_periods"] == 3


def test_the_fem_period_is_its_modal_period(swing):
    from fem_reference.modal import modes

    f1 = modes(_scenes(swing.attrs["path"])["fem"], 2, "hex2", 1).freq[0]
    assert swing["period_ref_s"].iloc[0] == pytest.approx(1 / f1, rel=1e-3)
    assert (swing["fem_period_error_pct"] <= 0.1).all() and (swing["fem_dt_s"] > 0).all()
    # the tracked point: the particle of largest sag, a corner of the free end
    assert swing["point"].iloc[0].split()[-1] == f"{N * LE:g}"


def test_the_budget_names_the_fastest_model_within_each_period_budget(swing):
    budget = pd.read_csv(swing.attrs["out"] / "tables" / "swing_dynamics_budget_drop.csv")
    assert list(budget["period_budget_pct"]) == [5.0, 20.0, 40.0]
    for b in budget.to_dict("records"):
        within = swing[swing["period_error_pct"].abs() <= b["period_budget_pct"]]
        if within.empty:
            assert b["answer"] == "none" and b["n_within"] == 0
            continue
        best = within.loc[within["wall_per_simulated_s"].idxmin()]
        assert b["answer"] == "fastest" and b["model"] == best["model"] and b["n_within"] == len(within)
        if len(within) > 1:
            assert b["lead"] == pytest.approx(within["wall_per_simulated_s"].nsmallest(2).iloc[1]
                                              / best["wall_per_simulated_s"], rel=1e-12)
    assert (budget["n_within"] == 2).any()  # both models within the widest budget: the cost decides
    assert "period within" in swing.attrs["stdout"]


def _refused(tmp_path, cli_in_process, doc, key: str, allowed: str):
    out = tmp_path / "out"
    proc = cli_in_process("study", write(doc, tmp_path / "study.toml"), "--out", out, "--no-progress")
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and key in lines[0] and "is not allowed" in lines[0], lines
    assert allowed in lines[0], lines[0]
    assert not out.exists()


@pytest.mark.parametrize("keys,key,allowed", [
    ({"release": True}, "load_case[0].release", "a non-zero gravity or a traction"),
    ({"release": 1}, "load_case[0].release", "true or false"),
    ({"periods": 3}, "load_case[0].periods", "only with release = true"),
    ({"release_time": 0.5}, "load_case[0].release_time", "only with release = true"),
    ({"release": True, "gravity": [0.0, -9.81, 0.0], "periods": 0}, "load_case[0].periods", ">= 1"),
    ({"release": True, "gravity": [0.0, -9.81, 0.0], "periods": 2.5}, "load_case[0].periods", "an integer"),
    ({"release": True, "gravity": [0.0, -9.81, 0.0], "release_time": -1.0}, "load_case[0].release_time", "> 0"),
    ({"release": True, "gravity": [0.0, -9.81, 0.0], "periods": 3, "release_time": 0.5},
     "load_case[0].release_time", "absent when periods is given"),
])
def test_release_keys_not_allowed_are_refused_naming_the_key(tmp_path, cli_in_process, keys, key, allowed):
    doc = small_study()  # its load case moves a plate: no load to remove
    doc["load_case"][0].update(keys)
    _refused(tmp_path, cli_in_process, doc, key, allowed)


@pytest.mark.parametrize("release,value,allowed", [(True, "nose", "a point of metrics.points (tip)"),
                                                    (True, 3, "a point of metrics.points"),
                                                    (False, "tip", "only with a load case that has release")])
def test_a_point_not_allowed_is_refused_naming_the_key(tmp_path, cli_in_process, release, value, allowed):
    doc = small_study()
    if release:
        doc["load_case"][0].update(release=True, gravity=[0.0, -9.81, 0.0])
    doc["metrics"]["point"] = value
    _refused(tmp_path, cli_in_process, doc, "metrics.point", allowed)


def test_a_released_run_without_result_is_a_failure(tmp_path):
    from studies.study import Study
    from studies.study.outcome import study_outcome

    doc = swing_study()
    doc["model"][1]["expect_no_result"] = ["diverged"]
    study = Study.from_toml(write(doc, tmp_path / "swing.toml"))
    (tmp_path / "out" / "tables").mkdir(parents=True)
    rows = pd.DataFrame({"model": ["hybmss-cf", "corot-hex8"], "cell_size_m": [LE, LE],
                         "status": ["error", "diverged"], "reason": ["no first period", "node 3 non-finite"]})
    rows.to_csv(tmp_path / "out" / "tables" / "swing_dynamics_drop.csv", index=False)
    got = study_outcome(study, tmp_path / "out")  # the static runs are not stored: missing
    assert got["runs"] == 3 + 2  # two models and the FEM, two released runs
    released = [f for f in got["failures"] if "released" in f]
    assert released == ["hybmss-cf 0.01 m drop released: no first period"]
    assert got["expected_no_result"] == ["corot-hex8 0.01 m drop released: node 3 non-finite"]
    assert got["failed"] == 3 + 1 and got["results"] == 0


def test_the_study_report_shows_the_stored_tables(swing):
    from reports.study_modes import dynamics_html

    page = dynamics_html(swing.attrs["out"], "swing", "drop")
    assert page.count("<table>") == 2 and page.count("<tr>") == 2 * (1 + len(swing)) + 1  # 3 budgets: 1 + 3 rows
    assert f"{swing['period_error_pct'].iloc[0]:.4g}" in page and "semi-implicit Euler" in page
    assert dynamics_html(swing.attrs["out"], "swing", "other") is None


def test_a_model_that_raises_has_a_row_with_its_reason(tmp_path, monkeypatch):
    import studies.sweep.transients as transients
    from studies.study import Study
    from studies.study.release import dynamics_tables

    real = transients.model_row

    def model_row(scene, model, *args):
        if scene.model.name == "corot-hex8":
            raise ZeroDivisionError("the element's volume is zero")
        return real(scene, model, *args)

    monkeypatch.setattr(transients, "model_row", model_row)
    doc = swing_study()
    doc["load_case"][0]["periods"] = 1
    table = dynamics_tables(Study.from_toml(write(doc, tmp_path / "swing.toml")))["dynamics_drop"]
    bad = table[table["model"] == "corot-hex8"].iloc[0]
    assert bad["status"] == "error" and bad["reason"] == "ZeroDivisionError: the element's volume is zero"
    assert bad[["period_error_pct", "zeta", "l2_error", "wall_per_simulated_s"]].isna().all()
    assert table[table["model"] == "hybmss-cf"]["status"].iloc[0] == "ok"
