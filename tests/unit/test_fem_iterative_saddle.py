"""The iterative path of the mixed u–p Newton solver (MINRES with AMG on the displacement block,
taken by ``method='amg'`` and by systems above the direct limit) reaches the equilibrium of the
direct path, solving each Newton system only to Newton's forcing term and reusing the AMG
hierarchy across Newton iterations.

Tolerance of the field comparison: both solves stop at ``‖R‖ ≤ rtol · ‖f‖`` (``rtol = 1e-10``);
their displacements differ by ``K⁻¹ δR``, at most the condition number of the tangent times
``2 · rtol`` relative — below 1e-8 for these meshes of a few elements (as the chord-step test).
"""

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from fem_reference import linalg
from fem_reference.dirichlet import plate_dirichlet
from fem_reference.hyperelastic import LINEAR_RTOL_MIN, Hyperelasticity
from fem_reference.mesh import build_mesh
from hybmss.scene import Body, Material, Motion, Plate, Region, Scene

RTOL = 1e-10


def _twist(nu: float, angle_deg: float) -> Scene:
    body = Body.box(2, 2, 2, 0.5)
    motion = Motion("rotate", angle=np.radians(angle_deg), axis=(0.0, 0.0, 1.0), center=(0.5, 0.5, 1.0))
    return Scene(body, Material(1e4, nu, 1000.0),
                 plates=(Plate("bottom", Region("z-")), Plate("top", Region("z+"), motion)))


@pytest.mark.parametrize("nu", [0.49])
def test_minres_path_same_equilibrium_as_direct(nu, monkeypatch):
    sc = _twist(nu, 30.0)
    ops = Hyperelasticity(build_mesh(sc.body, 1), "mixed", "neo-hookean")
    d = plate_dirichlet(sc, ops.space)
    direct, log_d = ops.solve(sc.material, d, steps=5, rtol=RTOL, method="direct")

    builds, tolerances = [0], []
    amg, minres = linalg._amg, spla.minres

    def counted_amg(*a, **k):
        builds[0] += 1
        return amg(*a, **k)

    def recorded_minres(*a, **k):
        tolerances.append(k["rtol"])
        return minres(*a, **k)

    monkeypatch.setattr(linalg, "_amg", counted_amg)
    monkeypatch.setattr(linalg.spla, "minres", recorded_minres)
    it, log_i = ops.solve(sc.material, d, steps=5, rtol=RTOL, method="amg")
    assert log_d.converged and log_i.converged
    assert it.stats.method == "amg-minres"
    scale = np.abs(direct.U).max()
    assert np.abs(it.U - direct.U).max() <= 1e-8 * scale
    assert np.abs(it.p - direct.p).max() <= 1e-8 * np.abs(direct.p).max()
    D = d.dofs
    assert np.abs(it.r[D] - direct.r[D]).max() <= 1e-8 * np.abs(direct.r[D]).max()
    # every Newton system far from the solution is solved only to the forcing term ...
    assert max(tolerances) > 10 * LINEAR_RTOL_MIN * 1e-3
    # ... and the AMG of the displacement block serves more than one of them
    assert builds[0] < len(tolerances)
