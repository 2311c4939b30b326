"""The FEM reference of a released transient at a step checked by halving, and the comparison rows."""

import math

import pytest

from fem_reference.transient import ReleasedFem
from hybmss.scene import Body, Load, Material, Plate, Scene
from studies.sweep.dynamics import trajectory_oscillation
from studies.sweep.transients import compare_released, fem_transient

TIP = (0.05, 0.05, 0.4)


def cantilever(**kw):
    return Scene(Body.box(1, 1, 4, 0.1), Material(1e6, 0.3, 1000.0), plates=(Plate("base", "z-"),), **kw)


@pytest.mark.parametrize("tol", [1e-2, 1e-3])
def test_fem_reference_step_is_within_its_period_tolerance(tol):
    """The accepted step's period agrees with a run at an eighth of it within ``tol``."""
    sc = cantilever(gravity=(0.0, -10.0, 0.0))
    ref = fem_transient(sc, TIP, periods=4, period_tol=tol, element="hex1")
    check = ref.info["dt_check"]
    assert check["within_tol"] and check["dt"] == ref.dt
    assert check["period_error_estimate"] <= tol
    fine = ReleasedFem(sc, "hex1").run(ref.dt / 8, ref.t_end, TIP)
    T, T_fine = trajectory_oscillation(ref).period, trajectory_oscillation(fine).period
    assert abs(T / T_fine - 1.0) <= tol
    assert ref.dt <= 2 * math.pi / ReleasedFem(sc, "hex1").omega_rayleigh * math.sqrt(12 * tol) / 2


def test_comparison_rows():
    sc = cantilever(gravity=(0.0, -10.0, 0.0))
    out = compare_released(sc, ["hybmss", "corot-hex8"], TIP, periods=3, period_tol=1e-3, element="hex1")
    assert len(out["rows"]) == 2 and len(out["load_average"]) == 2
    T_ref = trajectory_oscillation(out["reference"]).period
    for row in out["rows"]:
        assert row["reason"] == "" and row["status"] == "ok" and row["substeps"] == 1
        assert row["period_error"] == pytest.approx(row["period"] / T_ref - 1.0)
        assert row["wall_per_simulated_s"] > 0 and row["l2_error"] > 0


def test_a_model_that_cannot_run_the_scene_has_a_row_with_the_reason():
    pytest.importorskip("mujoco")
    sc = cantilever(loads=(Load("z+", (0.0, -1e3, 0.0)),))
    out = compare_released(sc, ["mujoco-trilinear"], TIP, periods=2, period_tol=1e-2, element="hex1")
    row = out["rows"][0]
    assert "surface tractions" in row["reason"] and row["period_error"] is None
