"""A study's errors are measured on scales the load defines: the force scale of a compression is
E·A·ε, its strain scale ε (closed form, ν = 0 between clamped plates: a uniform uniaxial strain
the FEM's hex2 reproduces exactly); in a twist the plate force and the volume change the FEM puts
near zero get no relative error, only an error on the load's scale; a reference below its own
error estimate ranks nothing."""

from __future__ import annotations

import numpy as np
import pandas as pd

from study_files import changed, small_study, write

from studies.study import Study
from studies.study.metrics import errors, load_scales, published_relative, support_radius


def _errors(tmp_path, doc, case):
    from studies.cli.parser import main

    f = write(doc, tmp_path / "s.toml")
    assert main(["study", str(f), "--out", str(tmp_path / "out"), "--jobs", "1", "--no-report",
                 "--no-progress"]) == 0
    return pd.read_csv(tmp_path / "out" / "tables" / f"{doc['study']['name']}_errors_{case}.csv")


def test_compression_scales_are_the_load_s_own(tmp_path):
    E, a, H, d = 3000.0, 0.02, 0.04, 0.0004
    doc = changed(small_study(), lambda s: s["material"].update(nu=0.0))
    row = _errors(tmp_path, doc, "press").iloc[0]
    assert np.isclose(row["force_scale_N"], E * a * a * d / H, rtol=1e-6)  # E A eps
    assert np.isclose(row["strain_scale"], d / H, rtol=1e-9)                # max |u| / longest edge
    # the force carries the whole scale: its relative error is published and is the scaled one
    assert np.isclose(row["force_top_rel"], row["force_top_err"], rtol=1e-9)
    assert np.isclose(row["force_top_err"], abs(row["force_top_N"] - row["force_top_fem_N"]) / row["force_scale_N"],
                      rtol=1e-6)
    # ΔV/V0 = -ε at ν = 0: its error on the strain scale is its relative error
    assert np.isclose(row["volume_detF_fem"], -d / H, rtol=1e-6)
    assert np.isclose(row["volume_detF_err"], row["volume_detF_rel"], rtol=1e-6)


def _twist(s):
    s["study"]["name"] = "twist"
    s["material"]["nu"] = 0.45
    s["load_case"][0]["name"] = "twist"
    s["load_case"][0]["support"][1] = {"name": "top", "region": "z+", "motion": "rotate", "angle_deg": 15.0,
                                       "axis": [0.0, 0.0, 1.0], "center": [0.01, 0.01, 0.04]}
    s["model"].append({"name": "corot-hex8"})
    s["reference"].update(law="neo-hookean", refine="auto")


def test_a_twist_publishes_no_relative_error_of_what_the_fem_puts_near_zero(tmp_path):
    """15° on the 2x2x4 block (neo-Hookean FEM): the plate's axial force is ~2 % of the load's
    force scale |T|/R and the volume change ~1 % of its strain scale; their relative errors were
    100 % and more for every model while the displacement error was below 1 %."""
    df = _errors(tmp_path, changed(small_study(), _twist), "twist")
    assert len(df) == 2 and (df["status"] == "ok").all()
    for _, row in df.iterrows():
        assert abs(row["force_top_fem_N"]) < 0.05 * row["force_scale_N"]
        assert np.isnan(row[["force_top_rel", "volume_detF_rel", "volume_avg_edges_rel"]].astype(float)).all()
        assert row["force_top_err"] < 0.05 and row["volume_detF_err"] < 0.05 and row["u_rel_l2"] < 0.05
        assert np.isfinite(row["torque_top_rel"])
        assert np.isclose(row["torque_top_rel"], row["torque_top_err"], rtol=1e-6)
    assert (df["reference_error_estimate"] < 0.125).all()  # refined until below tolerance x budget


def test_a_reference_below_its_own_estimate_ranks_nothing():
    """Synthetic runs: the FEM's own error estimate (relative to the load's scales) above the
    quantity, or at the displacement scale, leaves no relative error and no u_rel_l2."""
    X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1], [1, 1, 1]], float)
    cells = np.arange(8)[None, :]
    u_f = 0.01 * X * np.array([0.0, 0.0, -1.0])
    u_m = 1.02 * u_f

    class M:
        plate_force, volume_change, displacement = ("top",), True, True
        points = (("corner", (1.0, 1.0, 1.0)), ("floor", (1.0, 1.0, 0.0)))

    info = {"reaction_top_fx": 0.0, "reaction_top_fy": 0.0, "reaction_top_fz": -10.0}
    info_m = {"reaction_top_fx": 0.0, "reaction_top_fy": 0.0, "reaction_top_fz": -10.2}
    run = {"arrays": {"X": X, "u": u_m, "cells": cells}, "row": {"info": info_m}}
    for est, ranked in ((0.01, True), (0.5, True), (1.5, False)):
        ref = {"arrays": {"X": X, "u": u_f, "cells": cells}, "row": {"info": {**info, "reference_error_estimate": est}}}
        out = errors(run, ref, M, 1.0, {"top": "translate"}, {"top": 0.5})
        assert np.isclose(out["force_scale_N"], 10.0) and np.isclose(out["force_top_err"], 0.02)
        assert np.isfinite(out["u_rel_l2"]) == ranked and np.isfinite(out["force_top_rel"]) == ranked
        assert np.isclose(out["point_corner_err"], 0.02) and np.isfinite(out["point_corner_rel"]) == ranked
    # a point the FEM barely moves (1 % of max |u|) has an error on max |u| and no relative error
    u_f[6] = [0.0, 0.0, -1e-4]
    ref = {"arrays": {"X": X, "u": u_f, "cells": cells}, "row": {"info": info}}
    run = {"arrays": {"X": X, "u": u_f + [0.0, 0.0, -2e-4], "cells": cells}, "row": {"info": info_m}}
    M.points = (("side", (0.0, 1.0, 1.0)),)
    out = errors(run, ref, M, 1.0, {"top": "translate"}, {"top": 0.5})
    assert np.isclose(out["point_side_err"], 2e-4 / 0.01) and np.isnan(out["point_side_rel"])
    assert np.isclose(published_relative([0.2], [0.1], 1.0, 0.0), 1.0)  # 10 % of its scale: not near zero
    assert np.isnan(published_relative([1.2], [1.0], 1.0, 1.5))    # below its own estimate (1.5 x scale)
    assert np.isclose(published_relative([1.2], [1.0], 1.0, 0.5), 0.2)
    assert np.isnan(published_relative([0.04], [0.03], 1.0, 0.0))  # 3 % of its scale: near zero


def test_load_scales_and_radius_from_first_principles():
    X = np.array([[x, y, 0.0] for x in (0.0, 0.02) for y in (0.0, 0.02)])
    assert np.isclose(support_radius(X, np.ones(4, bool), 0.01), np.hypot(0.01, 0.01))
    info = {"reaction_a_fx": 3.0, "reaction_a_fy": 4.0, "reaction_a_fz": 0.0,
            "reaction_a_tx": 0.0, "reaction_a_ty": 0.0, "reaction_a_tz": 2.0,
            "reaction_b_fx": 0.0, "reaction_b_fy": 0.0, "reaction_b_fz": 0.0,
            "reaction_b_tx": 0.0, "reaction_b_ty": 0.0, "reaction_b_tz": 9.0}
    sc = load_scales(info, {"a": 1.0, "b": 1.5}, np.array([[0.0, 0.0, 0.3]]), np.array([[0, 0, 0], [1, 2, 3.0]]))
    assert np.isclose(sc["force_N"], 9.0 / 1.5) and np.isclose(sc["u_m"], 0.3) and np.isclose(sc["strain"], 0.1)


def test_the_reference_s_estimate_measures_reactions_on_the_load_s_scale(tmp_path):
    """Two refinements of a twist's reference, made up: the plates' axial force doubles from
    1e-4 N (near zero beside a 1 N m torque), the torque grows from 1.0 to 1.1 N m.  Richardson
    (hex2, order 3, h ratio 2): the torque's error is 0.1 / 7, on the scale F_load R = 1.1 N m;
    the force's 1e-4 / 7 N on F_load = 1.1 / R is negligible (on itself it would be 1/7)."""
    import dataclasses

    from hybmss.result import Reaction
    from studies.sweep.runner import SolverSpec, solve_scene
    from studies.study.tasks import reference_estimate

    study = Study.from_toml(write(changed(small_study(), _twist), tmp_path / "s.toml"))
    scene = [t for t in study.tasks() if t.solver.kind == "fem"][0].scene.build()
    base = solve_scene(scene, SolverSpec("fem", element="hex2"))

    def made(force, torque):
        return dataclasses.replace(base, reactions={p.name: Reaction((0.0, 0.0, force), (0.0, 0.0, torque), (0, 0, 0))
                                                    for p in scene.plates})

    est = reference_estimate(scene, [made(1e-4, 1.0), made(2e-4, 1.1)], [1, 2])
    assert np.isclose(est, (0.1 / 7) / 1.1, rtol=1e-9)
