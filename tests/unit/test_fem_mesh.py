"""Meshes of voxel bodies, node ↔ particle matching, and the vectorized assembly."""

import numpy as np
import pytest
from skfem import Basis, BilinearForm, ElementHex1, ElementHex2, ElementVector
from skfem.helpers import ddot, div, sym_grad

from fem_reference.mesh import build_mesh, match_points
from fem_reference.space import Space
from hybmss.lattice import Lattice
from hybmss.scene import Body


def l_shape(le=0.5):
    mask = np.ones((3, 2, 2), dtype=bool)
    mask[1:, :, 1] = False
    return Body.from_mask(mask, le, origin=(0.1, -0.2, 0.3))


@pytest.mark.parametrize("r", [1, 2, 3])
def test_box_mesh_counts_and_particles(r):
    body = Body.box(3, 2, 4, 0.25)
    fm = build_mesh(body, r)
    nx, ny, nz = (3 * r, 2 * r, 4 * r)
    assert fm.mesh.t.shape[1] == nx * ny * nz
    assert fm.mesh.p.shape[1] == (nx + 1) * (ny + 1) * (nz + 1)
    X = Lattice.from_body(body).X
    assert np.array_equal(fm.points[fm.particle_nodes], X)
    assert fm.h == pytest.approx(0.25 / r)


def test_mask_mesh_volume_and_matching():
    body = l_shape()
    for r in (1, 2):
        fm = build_mesh(body, r)
        space = Space.create(fm, "hex1")
        assert space.integrate(np.ones_like(space.dx)) == pytest.approx(body.volume, rel=1e-14)
        lat = Lattice.from_body(body)
        assert np.array_equal(fm.points[fm.particle_nodes], lat.X)
        # Elements are positively oriented (all Jacobians > 0).
        assert np.all(space.dx > 0)


def test_match_points_rejects_missing():
    pts = np.array([[0.0, 0, 0], [1, 0, 0]])
    assert list(match_points(pts, pts[::-1], 1e-9)) == [1, 0]
    with pytest.raises(ValueError, match="no mesh node"):
        match_points(pts, np.array([[0.5, 0, 0]]), 1e-9)


def test_refine_rejects_zero():
    with pytest.raises(ValueError, match="refine"):
        build_mesh(Body.box(1, 1, 1, 1.0), 0)


@pytest.mark.parametrize("element", ["hex1", "hex2"])
def test_vector_dof_layout_matches_skfem(element):
    fm = build_mesh(l_shape(), 1)
    space = Space.create(fm, element)
    elem = ElementHex1() if element == "hex1" else ElementHex2()
    vb = Basis(fm.mesh, ElementVector(elem), intorder=3 if element == "hex1" else 5)
    assert np.array_equal(vb.element_dofs, space.vedofs)
    for c in range(3):
        assert np.allclose(vb.doflocs[:, c::3].T, space.points)


@pytest.mark.parametrize("element,order", [("hex1", 3), pytest.param("hex2", 5, marks=pytest.mark.slow)])
def test_assembly_equals_skfem_forms(element, order):
    """K_λ, K_μ and a tangent with the linear-elastic A equal scikit-fem BilinearForms."""
    fm = build_mesh(l_shape(), 1)
    space = Space.create(fm, element)
    elem = ElementHex1() if element == "hex1" else ElementHex2()
    vb = Basis(fm.mesh, ElementVector(elem), intorder=order)
    Kmu = BilinearForm(lambda u, v, w: 2 * ddot(sym_grad(u), sym_grad(v))).assemble(vb)
    Klam = BilinearForm(lambda u, v, w: div(u) * div(v)).assemble(vb)
    assert space.uniform_dN is not None and space._uniform_weights is not None  # the uniform path
    Kl, Km = space.elasticity_parts()
    scale = abs(Kmu).max()
    Kl_g, Km_g = space._general_elasticity_parts()  # the per-element path gives the same matrices
    assert abs(Kl_g - Klam).max() <= 1e-13 * scale
    assert abs(Km_g - Kmu).max() <= 1e-13 * scale
    assert abs(Kl - Klam).max() <= 1e-13 * scale
    assert abs(Km - Kmu).max() <= 1e-13 * scale
    lam, mu = 1.7, 0.6
    I = np.eye(3)
    A = lam * np.einsum("ij,kl->ijkl", I, I) + mu * (np.einsum("ik,jl->ijkl", I, I) + np.einsum("il,jk->ijkl", I, I))
    At = space.tangent(np.broadcast_to(A, space.dx.shape + (3, 3, 3, 3)))
    assert abs(At - (lam * Klam + mu * Kmu)).max() <= 1e-13 * scale
