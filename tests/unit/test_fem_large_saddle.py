"""A mixed u–p saddle point above the direct limit of ``method='auto'`` is solved by eliminating the
pressure with a CHOLMOD factor of the displacement block (not block-preconditioned MINRES), and
Newton reaches the equilibrium of the whole saddle point's SuperLU factorization.

The limit is lowered to 1 non-zero so that a 2×2×2 mesh stands for the large meshes.  Tolerance:
both Newton solves stop at ``‖R‖ ≤ 1e-10 ‖f‖``; their displacements differ by ``K⁻¹ δR``, the
tangent's condition number times ``2e-10`` relative at most — below 1e-8 for a mesh of a few
elements (as the chord-step test of ``test_fem_reuse.py``).
"""

import numpy as np
import pytest

from fem_reference import linalg
from fem_reference.dirichlet import plate_dirichlet
from fem_reference.hyperelastic import Hyperelasticity
from fem_reference.mesh import build_mesh
from hybmss.scene import Body, Material, Motion, Plate, Region, Scene

pytestmark = pytest.mark.skipif(linalg.cholmod is None, reason="cvxopt (CHOLMOD) is not installed")


def _twist(nu: float) -> Scene:
    motion = Motion("rotate", angle=np.radians(30.0), axis=(0.0, 0.0, 1.0), center=(0.5, 0.5, 1.0))
    return Scene(Body.box(2, 2, 2, 0.5), Material(1e4, nu, 1000.0),
                 plates=(Plate("bottom", Region("z-")), Plate("top", Region("z+"), motion)))


def test_large_saddle_point_eliminates_the_pressure(monkeypatch):
    sc = _twist(0.49)
    ops = Hyperelasticity(build_mesh(sc.body, 1), "mixed", "neo-hookean")
    d = plate_dirichlet(sc, ops.space)
    whole, log_w = ops.solve(sc.material, d, rtol=1e-10, method="direct")  # SuperLU of the saddle point
    monkeypatch.setattr(linalg, "DIRECT_MAX_NNZ_SADDLE", 1)
    large, log_l = ops.solve(sc.material, d, rtol=1e-10, method="auto")
    assert log_w.converged and log_l.converged
    assert whole.stats.method == "direct" and large.stats.method == "cholmod-schur"
    assert np.abs(large.U - whole.U).max() <= 1e-8 * np.abs(whole.U).max()
    assert np.abs(large.p - whole.p).max() <= 1e-8 * np.abs(whole.p).max()
    D = d.dofs
    assert np.abs(large.r[D] - whole.r[D]).max() <= 1e-8 * np.abs(whole.r[D]).max()


def test_displacement_block_beyond_cholmod_keeps_minres(monkeypatch):
    """Above CHOLMOD's limit, with too little memory available for the factor, the saddle point goes
    to MINRES (no factor of that size)."""
    monkeypatch.setattr(linalg, "available_memory", lambda: 0.0)
    sc = _twist(0.49)
    ops = Hyperelasticity(build_mesh(sc.body, 1), "mixed", "neo-hookean")
    d = plate_dirichlet(sc, ops.space)
    monkeypatch.setattr(linalg, "DIRECT_MAX_NNZ_SADDLE", 1)
    monkeypatch.setattr(linalg, "DIRECT_MAX_NNZ_CHOLMOD", 1)
    K = ops.space.tangent(np.broadcast_to(np.einsum("ik,JL->iJkL", np.eye(3), np.eye(3)),
                                          ops.space.dx.shape + (3, 3, 3, 3)))
    B = ops.space.coupling(ops.pspace, np.broadcast_to(np.eye(3)[:, :, None, None], (3, 3) + ops.space.dx.shape))
    C = ops.pressure_mass / sc.material.lam
    stats = linalg.SolveStats()
    f = np.zeros(ops.space.n_vector)
    uD = d.values(1.0)
    linalg.solve_saddle(K, B, C, f, np.zeros(ops.pspace.n_scalar), d.dofs, uD, ops.nullspace,
                        1.0 / sc.material.G + 1.0 / sc.material.lam, stats=stats, order=ops.order,
                        separator=ops.separator)
    assert stats.method == "amg-minres"
