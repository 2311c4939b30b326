"""Tetrahedral bodies: orientation check, degenerate/inverted refusal, volume of the mesh and of its surface."""

import sys

import numpy as np
import pytest
import pyvista as pv
from skfem import MeshTet

from hybmss.tetbody import TetMeshError, enclosed_volume, make_body, mesh_surface, signed_volumes, surface_triangles


def _box_tets(n=2):
    m = MeshTet.init_tensor(*(np.linspace(0.0, 1.0, n + 1),) * 3)
    return m.p.T.copy(), m.t.T.copy()


def test_signed_volume_of_unit_corner_tet():
    X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    assert signed_volumes(X, np.array([[0, 1, 2, 3]]))[0] == pytest.approx(1 / 6, rel=1e-15)
    assert signed_volumes(X, np.array([[0, 2, 1, 3]]))[0] == pytest.approx(-1 / 6, rel=1e-15)


def test_consistently_negative_mesh_is_swapped():
    X, T = _box_tets()
    T = np.where(signed_volumes(X, T)[:, None] > 0, T, T[:, [0, 2, 1, 3]])  # all positive first
    body = make_body(X, T[:, [1, 0, 2, 3]], h=0.5)  # every tet mirrored
    assert body.swapped == len(T)
    assert (body.volumes > 0).all()
    assert body.volume == pytest.approx(1.0, rel=1e-14)


def test_one_inverted_tet_is_refused_with_its_count():
    X, T = _box_tets()
    T = np.where(signed_volumes(X, T)[:, None] > 0, T, T[:, [0, 2, 1, 3]])
    T[5] = T[5, [1, 0, 2, 3]]
    with pytest.raises(TetMeshError, match=rf"0 degenerate .* and 1 inverted of {len(T)} tetrahedra"):
        make_body(X, T, h=0.5)


def test_degenerate_tet_is_refused_with_its_count():
    X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.3, 0.3, 1e-9]], float)
    T = np.array([[0, 1, 2, 3], [0, 1, 2, 4]])  # the second is flat: |V| = 1.7e-10 << 1e-6 h^3
    with pytest.raises(TetMeshError, match=r"1 degenerate"):
        make_body(X, T, h=1.0)


def test_surface_volume_is_the_inscribed_polygon_prism():
    R, H, N = 0.01, 0.04, 64
    P, T = surface_triangles(pv.Cylinder(center=(0, 0, H / 2), direction=(0, 0, 1), radius=R, height=H,
                                         resolution=N))
    exact = 0.5 * N * R**2 * np.sin(2 * np.pi / N) * H
    assert enclosed_volume(P, T) == pytest.approx(exact, rel=1e-6)  # float32 points of pyvista


def test_cube_mesh_volume_equals_surface_volume():
    body = mesh_surface(pv.Cube(center=(0.5, 0.5, 0.5)), 0.3)
    assert (body.volumes > 0).all() and body.n_tets > 50
    assert body.surface_volume == pytest.approx(1.0, rel=1e-12)
    assert body.volume == pytest.approx(1.0, rel=1e-12)


def test_cylinder_mesh_volume_below_surface_by_order_h2(tmp_path):
    R, H = 0.01, 0.04
    stl = tmp_path / "cyl.stl"
    pv.Cylinder(center=(0, 0, H / 2), direction=(0, 0, 1), radius=R, height=H, resolution=128).save(stl)
    errors = []
    for h in (0.004, 0.002):
        body = mesh_surface(stl, h)
        assert (body.volumes > 0).all()
        errors.append(body.volume_error)
    # an inscribed mesh: smaller than the surface, by a chordal error ~ h^2 / (8 R) per unit area
    assert -0.03 < errors[0] < errors[1] < 0
    assert 2.5 < errors[0] / errors[1] < 6.5


def test_missing_mesher_says_how_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "gmsh", None)
    with pytest.raises(ImportError, match=r"pip install 'hybmss\[tet\]'"):
        mesh_surface(pv.Cube(), 0.3)


def test_size_must_be_positive():
    with pytest.raises(ValueError, match="h must be a positive length"):
        mesh_surface(pv.Cube(), 0.0)
