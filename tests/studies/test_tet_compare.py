"""studies.paper.tet_compare: which lattice nodes are scored (inside the faceted tetrahedral body) and
one engine and the MSS scored on the squeezed cylinder with the reference resolving their errors."""

import numpy as np
import pytest
import pyvista as pv

from hybmss.tetbody import mesh_surface
from studies.paper.tet_compare import compare, inside
from studies.paper.tet_cylinder import H, R

pytest.importorskip("gmsh")


def test_inside_the_faceted_cylinder():
    body = mesh_surface(pv.Cylinder(center=(0, 0, H / 2), direction=(0, 0, 1), radius=R, height=H, resolution=48),
                        0.008)
    pts = np.array([[0.0, 0.0, H / 2], [0.5 * R, 0.0, 0.3 * H],  # in
                    [1.05 * R, 0.0, H / 2], [0.0, 0.0, 1.02 * H], [0.0, R, -0.01 * H]])  # out: radius, top, bottom
    assert inside(body, pts).tolist() == [True, True, False, False, False]


def test_compare_scores_an_engine_and_the_mss_above_the_reference_error():
    pytest.importorskip("mujoco")
    rows = compare(h=0.008, le=0.005, engines=("mujoco-tet",), voxel_models=("hybmss",))
    assert {(r["load"], r["model"]) for r in rows} == {(a, b) for a in ("squeeze", "twist")
                                                      for b in ("mujoco-tet", "hybmss")}
    for r in rows:
        assert "failed" not in r and r["converged"]
        assert r["field"] > r["ref_field"] and r["reaction"] > r["ref_reaction"]
        if r["model"] == "hybmss":
            assert r["outside"] > 0 and r["nodes"] > 0  # the staircase reaches past the facets
        else:
            assert r["outside"] == 0


def test_the_engines_on_tetrahedra_are_asked_of_the_registry():
    """The comparison takes its engines from the registry: those whose tetrahedral body is not
    refused (MuJoCo's box kinds and Newton's XPBD refuse one, with a reason naming the body)."""
    from hybmss import models
    from studies.paper.tet_compare import lattice_models, tet_engines

    engines = {"mujoco-tet", "newton-semi", "newton-vbd", "pbd-xpbd-fem"} - set(models.unavailable())
    assert set(tet_engines()) == engines
    for name in {"mujoco-trilinear", "mujoco-quadratic", "newton-xpbd"} - set(models.unavailable()):
        assert models.get(name).tet_body_refused().startswith("body: ")
    assert {"hybmss", "corot-hex8"} <= set(lattice_models()) and not engines & set(lattice_models())
