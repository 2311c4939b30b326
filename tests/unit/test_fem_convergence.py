"""Observed order and Richardson extrapolation (exact for a pure power law)."""

import numpy as np
import pytest

from fem_reference.convergence import analyze, convergence, observed_order, richardson
from hybmss.scene import Body, Material, Motion, Plate, Region, Scene


@pytest.mark.parametrize("p", [1.0, 2.0, 3.0, 1.5])
@pytest.mark.parametrize("refinements", [(1, 2, 3), (1, 2, 4), (2, 3, 4)])
def test_observed_order_and_richardson_exact_for_power_law(p, refinements):
    h = 1.0 / np.asarray(refinements, float)
    q = 2.0 - 0.7 * h**p
    assert observed_order(h, q) == pytest.approx(p, rel=1e-9)
    assert richardson(h[-2], q[-2], h[-1], q[-1], p) == pytest.approx(2.0, rel=1e-12)
    o = analyze(refinements, q, expected_order=2.0)
    assert o.extrapolated == pytest.approx(2.0, rel=1e-12)
    assert o.error_finest == pytest.approx(0.7 * h[-1] ** p, rel=1e-8)
    assert o.error_coarsest == pytest.approx(0.7 * h[0] ** p, rel=1e-8)


def test_non_monotone_has_no_order_and_uses_expected():
    o = analyze((1, 2, 3), [1.0, 1.2, 1.1], expected_order=2.0)
    assert o.observed_order is None and o.order_used == 2.0


def test_two_refinements_use_expected_order():
    o = analyze((1, 2), [1.0 - 0.25, 1.0 - 0.25 / 4], expected_order=2.0)
    assert o.observed_order is None
    assert o.extrapolated == pytest.approx(1.0, rel=1e-12)


def test_convergence_study_on_shear():
    body = Body.box(2, 2, 2, 0.5)
    sc = Scene(body, Material(1e4, 0.25), plates=(
        Plate("bottom", Region("z-")),
        Plate("top", Region("z+"), Motion("translate", (0.05, 0.0, 0.0))),
    ))
    st = convergence(sc, refinements=(1, 2), element="hex1")
    assert [r.info["refine"] for r in st.results] == [1, 2]
    fx = st.outputs["top.Fx"]
    # Hex1 is too stiff: the reaction decreases under refinement towards the extrapolation.
    assert fx.values[0] > fx.values[1] > fx.extrapolated > 0
    assert "top.Fx" in st.table() and st.to_dict()["outputs"]["volume"]["order_used"] == 2.0
    with pytest.raises(ValueError, match="two refinement"):
        convergence(sc, refinements=(1,))
