"""The shipped example studies end to end at --quick (tables, report, VTU files), their tables
held to theory where theory exists, and the reference solved once per configuration.

Theory:
- compression of a block between frictionless plates with two symmetry planes is homogeneous
  uniaxial stress: for the compressible Neo-Hookean law of the reference
  (ψ = μ/2 (I₁ − 3) − μ ln J + λ/2 (ln J)²) the lateral stretch b solves
  μ(b − 1/b) + λ ln(a b²)/b = 0 at the axial stretch a, the plate force is
  A₀ (μ(a − 1/a) + λ ln(a b²)/a) and the volume change a b² − 1; for the linear law the force
  is E A ε;
- a cantilever under its weight q = ρ g A: the tip deflection lies between Euler–Bernoulli's
  q L⁴ / 8EI (shear-rigid) and Timoshenko's q L⁴ / 8EI + q L² / (2 κ G A), κ = 5/6 (shear
  flexible, the clamped section free to warp); a 3D clamp holds the section flat, so the answer
  lies strictly inside the bracket;
- the clamp of a hanging body carries its weight ρ g V (statics).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import tomllib
from scipy.optimize import brentq

from study_files import write
from studies.sweep.cost import TIMING_NOISE
from studies.study.tasks import RETIME_NOISE

EXAMPLES = Path(__file__).resolve().parents[2] / "studies" / "examples"
LIVER = tomllib.loads((EXAMPLES / "liver-block.toml").read_text())


def _table(out: Path, study: str, name: str) -> pd.DataFrame:
    return pd.read_csv(out / "tables" / f"{study}_{name}.csv")


def neo_hookean_uniaxial(E, nu, a):
    mu, lam = E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))
    b = brentq(lambda b: mu * (b - 1 / b) + lam * math.log(a * b * b) / b, 0.5, 2.0, xtol=1e-15)
    return b, mu * (a - 1 / a) + lam * math.log(a * b * b) / a


@pytest.fixture(scope="module")
def liver(tmp_path_factory, cli_in_process):
    out = tmp_path_factory.mktemp("liver") / "out"
    proc = cli_in_process("study", EXAMPLES / "liver-block.toml", "--quick", "--out", out, "--jobs", "1", "--json",
                   "--no-progress")
    assert proc.returncode == 0, proc.stderr
    return out, json.loads(proc.stdout)


def test_liver_compression_is_the_exact_uniaxial_neo_hookean_state(liver):
    out, _ = liver
    df = _table(out, "liver-block", "errors_compression")
    mat = LIVER["material"]
    H, d = LIVER["body"]["box"][2], -LIVER["load_case"][0]["support"][1]["displacement"][2]
    b, P = neo_hookean_uniaxial(mat["E"], mat["nu"], 1 - d / H)
    A = LIVER["body"]["box"][0] * LIVER["body"]["box"][1]
    assert np.allclose(df["force_top_fem_N"], P * A, rtol=1e-6, atol=0)
    assert np.allclose(df["volume_fem_own_detF"], (1 - d / H) * b * b - 1, rtol=1e-6)
    # the named point, the middle of the top face: lateral (b - 1) x 2 cm each way, -d along z
    tip = np.linalg.norm([0.02 * (b - 1), 0.02 * (b - 1), d])
    assert np.allclose(df["point_tip_fem_u_m"], tip, rtol=1e-6)
    # each error is relative to the reference: recomputed from the table's own columns
    assert np.allclose(df["force_top_rel"], abs(df["force_top_N"] - df["force_top_fem_N"]) / abs(df["force_top_fem_N"]),
                       rtol=1e-9)


def test_liver_self_weight_clamp_carries_the_weight(liver):
    out, _ = liver
    df = _table(out, "liver-block", "errors_self-weight")
    mat, box = LIVER["material"], LIVER["body"]["box"]
    weight = mat["rho"] * 9.81 * box[0] * box[1] * box[2]
    assert np.allclose(df["force_clamp_fem_N"], weight, rtol=1e-9)


def test_liver_budget_answers_and_report(liver):
    out, obj = liver
    assert obj["status"] == "ok" and obj["failed"] == 0 and obj["runs"] == 16
    for case in ("compression", "self-weight"):
        cost, budget = _table(out, "liver-block", f"cost_{case}"), _table(out, "liver-block", f"budget_{case}")
        fastest = budget[budget["answer"] == "fastest"]
        assert list(fastest["budget"]) == LIVER["study"]["budgets"]
        for _, b in fastest.iterrows():
            # each model's cheapest run within the budget, then the cheapest model
            meets = (cost[cost["u_rel_l2"] <= b["budget"]].sort_values("time_s", kind="stable")
                     .drop_duplicates("model"))
            if meets.empty:
                assert b["method"] == "none within budget"
                continue
            assert b["method"] == meets.iloc[0]["model"] and b["error"] <= b["budget"]
            assert b["cell_size_m"] == meets.iloc[0]["cell_size_m"]
            if len(meets) > 1:
                lead = meets.iloc[1]["time_s"] / meets.iloc[0]["time_s"]
                assert math.isclose(b["lead"], lead, rel_tol=1e-12)
                if lead < 1 + RETIME_NOISE:  # a near tie on single timings: both timed again, their spreads known
                    spread = max(meets.iloc[0]["time_spread"], meets.iloc[1]["time_spread"])
                    assert np.isfinite(spread) and bool(b["tie"]) == (lead < 1 + max(spread, TIMING_NOISE))
                else:  # single timings further apart than their noise: no tie
                    assert str(b["tie"]) == "False"
    page = (out / "report" / "liver-block.html").read_text()
    assert LIVER["study"]["title"] in page and page.count("<h2>Load case") == 2
    assert "views-" not in page and page.count("data:image/png") == 3  # chart + one view per load case


def test_liver_vtu_files_carry_model_scene_fem_and_error(liver):
    import pyvista as pv

    out, _ = liver
    names = sorted(p.name for p in (out / "vtu").glob("*.vtu"))
    assert "hybmss-10mm-compression.vtu" in names and "xpbd-nh-20mm-self-weight.vtu" in names
    grid = pv.read(out / "vtu" / "corot-hex8-10mm-self-weight.vtu")
    assert str(grid.field_data["model"][0]) == "corot-hex8" and len(str(grid.field_data["scene_digest"][0])) == 64
    assert "m" in str(grid.field_data["units"][0])
    err = grid.point_data["displacement"] - grid.point_data["fem_displacement"]
    assert np.allclose(grid.point_data["error"], err)
    df = _table(out, "liver-block", "errors_self-weight")
    row = df[(df["model"] == "corot-hex8") & (df["cell_size_m"] == 0.01)].iloc[0]
    assert np.isclose(np.linalg.norm(err) / np.linalg.norm(grid.point_data["fem_displacement"]), row["u_rel_l2"])


def _linear_variant(tmp_path) -> Path:
    """The liver block 1000 times stiffer (a 0.16 mm deflection), linear reference, 1 cm cells."""
    doc = json.loads(json.dumps(LIVER))
    doc["study"].update(name="liver-linear", repeats=1)
    doc["body"] = {"box": doc["body"]["box"], "cell_sizes": [0.01]}
    doc["material"]["E"] = 3.0e6
    doc["reference"] = {"element": "auto", "law": "linear", "refine": 1}
    doc["model"] = [{"name": "corot-hex8"}]
    return write(doc, tmp_path / "liver-linear.toml")


def test_linear_compression_force_and_cantilever_tip_against_theory(tmp_path):
    from studies.study import Study

    study = Study.from_toml(_linear_variant(tmp_path))
    out = tmp_path / "out"
    study.run(out, jobs=1, progress=False)
    t = study.tables(out)
    E, nu, rho = 3.0e6, LIVER["material"]["nu"], LIVER["material"]["rho"]
    a, L = 0.04, 0.08
    comp = t["errors_compression"].iloc[0]
    assert math.isclose(-comp["force_top_fem_N"], E * a * a * 0.1, rel_tol=1e-9)
    q, I, G = rho * 9.81 * a * a, a ** 4 / 12, E / (2 * (1 + nu))
    euler_bernoulli = q * L ** 4 / (8 * E * I)
    timoshenko = euler_bernoulli + q * L ** 2 / (2 * 5 / 6 * G * a * a)
    tip = t["errors_self-weight"].iloc[0]["point_tip_fem_u_m"]
    assert euler_bernoulli < tip < timoshenko, (euler_bernoulli, tip, timoshenko)


def test_nut_example_end_to_end(tmp_path, cli_in_process):
    out = tmp_path / "out"
    proc = cli_in_process("study", EXAMPLES / "nut.toml", "--quick", "--out", out, "--jobs", "1", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    for case in ("squeeze", "twist"):
        df = _table(out, "rubber-nut", f"errors_{case}")
        assert (df["status"] == "ok").all() and df["u_rel_l2"].notna().all()
    twist = _table(out, "rubber-nut", "errors_twist")
    assert twist["torque_top_rel"].notna().all()
    assert (out / "report" / "rubber-nut.html").is_file()
    assert len(list((out / "vtu").glob("*-4mm-*.vtu"))) == 8


def test_the_reference_is_solved_once_per_configuration(tmp_path, monkeypatch):
    """2 load cases x 2 materials x 2 resolutions = 8 references for 3 models (24 model runs)."""
    import importlib

    fem = importlib.import_module("fem_reference.solve")

    from study_files import small_study
    from studies.study import Study

    doc = small_study()
    doc["body"]["cell_sizes"] = [0.02, 0.01]
    doc["material"]["E"] = [3000.0, 6000.0]
    doc["load_case"].append({"name": "hang", "gravity": [-9.81, 0.0, 0.0],
                             "support": [{"name": "top", "region": "z+", "motion": "clamped"}]})
    doc["model"] = [{"name": "hybmss"}, {"name": "hybmss", "params": {"e_form": True}, "label": "e-form"},
                    {"name": "corot-hex8"}]
    calls = []
    real = fem.solve
    monkeypatch.setattr(fem, "solve", lambda scene, **kw: calls.append(scene.digest()) or real(scene, **kw))
    study = Study.from_toml(write(doc, tmp_path / "count.toml"))
    summary = study.run(tmp_path / "out", jobs=1, progress=False)
    assert summary["runs"] == 24 + 8 and summary["failed"] == 0
    assert len(calls) == 8 and len(set(calls)) == 8
    study.run(tmp_path / "out", jobs=1, progress=False)  # resumed: nothing solved again
    assert len(calls) == 8
    errors = study.tables(tmp_path / "out")["errors_hang"]
    assert len(errors) == 12 and errors["u_rel_l2"].notna().all()


def test_fem_at_the_lattice_nodes_is_its_own_interpolation():
    """skfem's probes of the reference's field at the lattice nodes give the nodal values the
    study compares with (hex2 on cells split 2³: the lattice nodes are vertices of the mesh)."""
    from fem_reference.dirichlet import plate_dirichlet
    from fem_reference.linear import LinearElasticity
    from fem_reference.mesh import build_mesh
    from fem_reference.solve import solve
    from hybmss.scene import Body, Material, Motion, Plate, Region, Scene

    scene = Scene(Body.box(2, 2, 3, 0.01), Material(3000.0, 0.3, 1000.0),
                  plates=(Plate("clamp", Region("z-"), Motion("clamped")),), gravity=(-9.81, 0.0, 0.0))
    res = solve(scene, element="hex2", law="linear", refine=2)
    ops = LinearElasticity(build_mesh(scene.body, 2), "hex2")
    sol = ops.solve(scene.material, plate_dirichlet(scene, ops.space), scene.gravity)
    probes = ops.space.basis.probes(res.X.T)
    U = np.asarray(sol.U).reshape(ops.space.n_scalar, 3) if np.ndim(sol.U) == 1 else np.asarray(sol.U)
    assert np.allclose(probes @ U, res.u, rtol=0, atol=1e-12 * np.abs(res.u).max())


def test_auto_reference_refines_until_its_own_estimate_meets_the_target(tmp_path):
    """A cantilever under its weight on 1 cm cells: refine = "auto" solves r = 1, 2, ... and
    stops at the first whose Richardson estimate (from r - 1 and r) is below tolerance x the
    smallest budget; the estimate is recomputed here from two independent solves."""
    from fem_reference.convergence import EXPECTED_ORDER, analyze
    from fem_reference.solve import solve

    from study_files import small_study
    from studies.study import Study

    doc = small_study()
    doc["load_case"] = [{"name": "hang", "gravity": [-9.81, 0.0, 0.0],
                         "support": [{"name": "top", "region": "z+", "motion": "clamped"}]}]
    doc["metrics"] = {"plate_force": ["top"]}
    doc["reference"] = {"element": "hex1", "law": "linear", "refine": "auto", "tolerance": 1.0}
    doc["study"]["budgets"] = [0.5]
    study = Study.from_toml(write(doc, tmp_path / "auto.toml"))
    study.run(tmp_path / "out", jobs=1, progress=False)
    ref = study.tables(tmp_path / "out")["reference"].iloc[0]
    scene = [t for t in study.tasks() if t.solver.kind == "fem"][0].scene.build()
    r1, r2 = (solve(scene, element="hex1", law="linear", refine=r) for r in (1, 2))
    expected = analyze([1, 2], [r1.max_displacement, r2.max_displacement], EXPECTED_ORDER["hex1"]).relative_error_finest
    assert ref["refine"] == 2 and ref["error_target"] == 0.5
    assert math.isclose(ref["error_estimate"], expected, rel_tol=1e-9) and expected <= 0.5


@pytest.mark.slow
def test_explicit_cost_columns(tmp_path):
    """µs per step, dt_crit and the wall time of one simulated second of an explicit run, from
    its one timing (no budget answer to re-time: one model, its spread unknown); the run is stable
    (dt below its dt_crit) and ends at rest (a cost is that of a result)."""
    from study_files import small_study
    from studies.study import Study

    doc = small_study()
    doc["study"]["repeats"] = 2
    doc["model"] = [{"name": "corot-hex8", "solver": {"kind": "explicit", "dt": 1e-4, "steps": 3000,
                                                      "ramp_time": 0.01, "damping": 50.0}}]
    study = Study.from_toml(write(doc, tmp_path / "explicit.toml"))
    study.run(tmp_path / "out", jobs=1, progress=False)
    tables = study.tables(tmp_path / "out")
    assert list(tables["errors_press"]["status"]) == ["ok"]
    cost = tables["cost_press"].iloc[0]
    assert math.isclose(cost["us_per_step"], 1e6 * cost["time_s"] / 3000, rel_tol=1e-12)
    assert math.isclose(cost["wall_per_simulated_s"], cost["time_s"] / 3000 / 1e-4, rel_tol=1e-12)
    assert math.isclose(cost["wall_per_simulated_s_stable"], cost["time_s"] / 3000 / (0.5 * cost["dt_crit_s"]),
                        rel_tol=1e-12)
    assert cost["dt_s"] == 1e-4 < cost["dt_crit_s"] and cost["time_s"] > 0 and math.isnan(cost["time_spread"])


@pytest.mark.slow
def test_a_run_not_at_rest_has_no_error_nor_cost_and_wins_no_budget(tmp_path):
    """corot-hex8 stepped 300 × 0.1 ms with its plates ramped over 0.01 s: 0.02 s after the ramp
    the damping c = 50 s⁻¹ has taken a vibration down by e^(−50 · 0.02 / 2) ≈ 0.6 only, where the
    rest test asks for about 10⁻³ of it: the run is no result.  Beside a static hybmss, it has no
    error, no cost, is neither fastest nor runner-up in any budget (a generous one, 50 %, that the
    static run meets), and is listed as 'no result' with its reason."""
    from study_files import small_study
    from studies.sweep.cost import NO_RESULT
    from studies.study import Study

    doc = small_study()
    doc["study"]["budgets"] = [0.05, 0.5]
    doc["model"] = [{"name": "hybmss"},
                    {"name": "corot-hex8", "solver": {"kind": "explicit", "dt": 1e-4, "steps": 300,
                                                      "ramp_time": 0.01, "damping": 50.0}}]
    study = Study.from_toml(write(doc, tmp_path / "cut.toml"))
    study.run(tmp_path / "out", jobs=1, progress=False)
    t = study.tables(tmp_path / "out")
    err, cost, budget = t["errors_press"], t["cost_press"], t["budget_press"]
    cut = err["status"] != "ok"
    assert list(err.loc[cut, "status"]) == ["not-converged"] and (~cut).sum() == 1
    measures = [c for c in err.columns if c not in ("model", "cell_size_m", "E", "nu", "rho", "status", "message")]
    assert measures and err.loc[cut, measures].isna().all().all()
    assert np.isfinite(err.loc[~cut, "u_rel_l2"]).all()
    assert cost.loc[cut.values, ["time_s", "us_per_step", "wall_per_simulated_s", "u_rel_l2"]].isna().all().all()
    explicit = err.loc[cut, "model"].iloc[0]
    fastest = budget[budget["answer"] == "fastest"]
    assert explicit not in set(fastest["method"]) | set(fastest["runner_up"])
    assert fastest.loc[fastest["budget"] == 0.5, "method"].iloc[0] == err.loc[~cut, "model"].iloc[0]
    none = budget[budget["answer"] == NO_RESULT]
    assert list(none["method"]) == [explicit]
    assert none["failure"].iloc[0] == "not-converged: not at rest after 300 steps"


def test_an_experiment_study_file_gives_the_experiment_tasks():
    """A publication study file (``[body] experiment``) read as a study: the same tasks, in the
    same order, as studies.study.experiment.experiment_tasks gives."""
    from studies.study import Study
    from studies.study.experiment import experiment_tasks

    path = Path(__file__).resolve().parents[2] / "studies" / "data" / "studies" / "compression.toml"
    study = Study.from_toml(path, quick=True)
    expected = experiment_tasks(tomllib.loads(path.read_text()), True)
    assert [t.key() for t in study.tasks()] == [t.key() for t in expected] and len(expected) > 10


def test_auto_reference_stops_at_the_finest_refinement_that_fits_memory(tmp_path, monkeypatch):
    """refine = "auto" on a machine whose memory holds the reference at refine 2 but not at 3:
    the study is accepted (not refused for a level it may not need), the reference stops at 2 with
    its estimate above an unreachable target, and says so in its row."""
    from study_files import small_study
    from studies.study import Study
    from studies.sweep import sizing

    doc = small_study()
    doc["load_case"] = [{"name": "hang", "gravity": [-9.81, 0.0, 0.0],
                         "support": [{"name": "top", "region": "z+", "motion": "clamped"}]}]
    doc["metrics"] = {"plate_force": ["top"]}
    doc["reference"] = {"element": "hex1", "law": "linear", "refine": "auto", "tolerance": 1e-9}
    doc["study"]["budgets"] = [0.5]
    path = write(doc, tmp_path / "auto.toml")
    shape = [t for t in Study.from_toml(path).tasks() if t.solver.kind == "fem"][0].scene.build().body.shape
    need = [sizing.fem(shape, "hex1", r, "linear", 0.3).bytes for r in (2, 3)]
    monkeypatch.setattr(sizing, "limit", lambda: (need[0] + need[1]) / 2)
    study = Study.from_toml(path)
    study.run(tmp_path / "out", jobs=1, progress=False)
    ref = study.tables(tmp_path / "out")["reference"].iloc[0]
    assert ref["refine"] == 2 and ref["error_estimate"] > ref["error_target"] == 5e-10
