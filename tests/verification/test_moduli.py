"""Effective moduli from homogeneous static tests (SPEC §8, §9)."""

import pytest

from hybmss.moduli import measure_moduli
from hybmss.scene import Material, Model


@pytest.mark.parametrize("nu", [-0.5, 0.0, 0.25, 0.45, 0.499])
@pytest.mark.parametrize("model", [Model("hybmss", A=0.0), Model("hybmss", A=1.0), Model("hybmss", A=3.0),
                                   Model("hybmss-fd")], ids=lambda m: f"{m.name}-A{m.A:g}")
def test_hybrid_models_recover_E_nu_G(model, nu):
    mat = Material(1e4, nu)
    m = measure_moduli(model, mat)
    assert m["E_eff"] == pytest.approx(mat.E, rel=1e-3)
    assert m["nu_eff"] == pytest.approx(nu, rel=1e-3, abs=1e-6)
    assert m["G_eff"] == pytest.approx(mat.E / (2 * (1 + nu)), rel=1e-3)


@pytest.mark.parametrize("nu", [0.0, 0.3, 0.499])
def test_springs_only_give_quarter_poisson(nu):
    m = measure_moduli(Model("hybmss-cf"), Material(1e4, nu))
    assert m["nu_eff"] == pytest.approx(0.25, rel=1e-3)
    assert m["E_eff"] == pytest.approx(1e4, rel=1e-3)


def test_e_form_of_eq_5_12_is_wrong_away_from_quarter():
    """E-form: springs carry G_s = 2E/5 and κ = E(4ν−1)/(2(1+ν)(1−2ν)); at ν = 0 that is
    λ = G_s + κ = −0.1 E, μ = 0.4 E, so E_eff = μ(3λ+2μ)/(λ+μ) = 2E/3 and ν_eff = λ/(2(λ+μ)) = −1/6."""
    m = measure_moduli(Model("hybmss", e_form=True), Material(1e4, 0.0))
    assert m["E_eff"] == pytest.approx(1e4 * 2 / 3, rel=1e-3)
    assert m["nu_eff"] == pytest.approx(-1 / 6, rel=1e-3)
    exact = measure_moduli(Model("hybmss", e_form=True), Material(1e4, 0.25))
    assert exact["E_eff"] == pytest.approx(1e4, rel=1e-3)
