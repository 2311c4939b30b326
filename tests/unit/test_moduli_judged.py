"""``measure_moduli(judge=True)`` (``hybmss moduli``) reports only measurements: states near an
equilibrium and moduli a stable isotropic solid can have (E > 0, G > 0, −1 < ν < ½); anything
else is a :class:`MeasurementError` with its cause (exit 3 on the command line)."""

import pytest

from hybmss.experiments import uniaxial_scene
from hybmss.moduli import EQUILIBRIUM_TOL, MeasurementError, check_moduli, equilibrium_error, measure_moduli
from hybmss.scene import Material, Model
from hybmss.solve import StaticSolveError, solve_static


@pytest.mark.parametrize("m, bad", [
    ({"E_eff": 700.0, "nu_eff": 1.09, "G_eff": 4e3}, "nu_eff"),   # the xpbd-nh --sequential answer
    ({"E_eff": -1.0, "nu_eff": 0.3, "G_eff": 4e3}, "E_eff"),
    ({"E_eff": 1e4, "nu_eff": 0.3, "G_eff": 0.0}, "G_eff"),
    ({"E_eff": 1e4, "nu_eff": 0.5, "G_eff": 4e3}, "nu_eff"),
    ({"E_eff": 1e4, "nu_eff": -1.0, "G_eff": 4e3}, "nu_eff"),
    ({"E_eff": float("nan"), "nu_eff": 0.3, "G_eff": 4e3}, "E_eff"),
])
def test_moduli_outside_the_thermodynamic_bounds_are_refused(m, bad):
    with pytest.raises(MeasurementError, match=bad):
        check_moduli(m, "model")
    ok = {"E_eff": 1e4, "nu_eff": 0.499, "G_eff": 3.3e3}
    assert check_moduli(ok, "model") is ok


def test_a_newton_equilibrium_has_no_net_force_on_free_particles():
    """The criterion's zero: Newton's state of the uniaxial test balances to round-off (the free
    particles' net force is ~1e-12 of the plate forces), far below the tolerance."""
    scene = uniaxial_scene(Model("hybmss"), Material(1e4, 0.3), 1e-4, 2, 1.0)
    assert equilibrium_error(scene, solve_static(scene)) < 1e-8 < EQUILIBRIUM_TOL


def test_the_e_form_at_negative_nu_is_not_a_material():
    """[G20] eq. 5.12's E-form at ν = −0.5 gives ν_eff ≈ 0.79 (> ½): measured, then refused;
    unjudged (the studies' table, which marks it unstable) the same numbers come back."""
    model, mat = Model("hybmss", e_form=True), Material(1e4, -0.5)
    m = measure_moduli(model, mat)
    assert m["nu_eff"] > 0.5
    with pytest.raises(MeasurementError, match="nu_eff = 0.78"):
        measure_moduli(model, mat, judge=True)
    good = measure_moduli(Model("hybmss"), Material(1e4, 0.3), judge=True)
    assert good["nu_eff"] == pytest.approx(0.3, abs=1e-4)


@pytest.mark.slow
def test_a_relaxation_that_never_moved_is_not_a_measurement():
    """xpbd-nh with 1e12 substeps: a substep of 1e-13 s projects nothing, the free particles
    stay where the relaxation started (net force 100 % of the plate forces).  The static solve
    judges its end by the force balance and fails with its cause and remedy, so no measurement
    (judged or not) is made of it; with its default substeps the measurement is ν."""
    model, mat = Model("xpbd-nh", substeps=10**12), Material(1e4, 0.25)
    with pytest.raises(StaticSolveError, match="did not reach rest.*raise the substeps"):
        measure_moduli(model, mat)
    with pytest.raises((StaticSolveError, MeasurementError), match="did not reach rest|where it started"):
        measure_moduli(model, mat, judge=True)
    good = measure_moduli(Model("xpbd-nh"), mat, judge=True)
    assert good["nu_eff"] == pytest.approx(0.25, abs=2e-3)


@pytest.mark.slow
def test_compare_refuses_a_static_answer_that_never_moved(cli_in_process):
    """The same criterion in ``hybmss compare``: xpbd-nh's relaxation with 1e12 substeps ends
    where it started, away from the force balance (exit 3, the cause and the remedy); with its
    default substeps it is an answer (exit 0)."""
    run_cli = cli_in_process
    args = ("compare", "compression", "--mesh", "2x2x2", "--element", "hex1", "--model", "xpbd-nh")
    bad = run_cli(*args, "--substeps", "1000000000000")
    assert bad.returncode == 3 and "did not reach rest" in bad.stderr and "raise the substeps" in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1
    assert run_cli(*args).returncode == 0
