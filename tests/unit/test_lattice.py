"""Lattice topology (SPEC §1, Table 6) and Kirchhoff weights."""

import numpy as np
import pytest

from hybmss.calibrate import constants
from hybmss.forces import spring_energy_forces
from hybmss.lattice import EDGE, FACE, INNER, Lattice
from hybmss.scene import Body, Material, Model, Scene
from hybmss.system import build

# [G20] Table 6: volumes, vertices, springs without / with face diagonals
TABLE6 = {
    (10, 10, 10): (1000, 1331, 7630, 19630),
    (15, 15, 15): (3375, 4096, 25020, 65520),
    (20, 20, 20): (8000, 9261, 58460, 154460),
    (30, 30, 30): (27000, 29791, 194490, 518490),
    (4, 4, 24): (384, 625, 3136, 7744),
    (8, 8, 48): (3072, 3969, 23232, 60096),
    (10, 10, 60): (6000, 7381, 44680, 116680),
    (16, 16, 96): (24576, 28033, 178816, 473728),
}


@pytest.mark.parametrize("mesh", list(TABLE6))
def test_table6_counts(mesh):
    c = Lattice.from_body(Body.box(*mesh, le=0.1)).counts()
    assert (c["volumes"], c["vertices"], c["paper_springs_no_fd"], c["paper_springs_with_fd"]) == TABLE6[mesh]


def test_counts_closed_form_for_a_box():
    nx, ny, nz = 3, 4, 5
    c = Lattice.from_body(Body.box(nx, ny, nz, 1.0)).counts()["springs"]
    edges = nx * (ny + 1) * (nz + 1) + (nx + 1) * ny * (nz + 1) + (nx + 1) * (ny + 1) * nz
    faces = 2 * (nx * ny * (nz + 1) + nx * (ny + 1) * nz + (nx + 1) * ny * nz)
    assert (c["edge"], c["face_diagonal"], c["inner_diagonal"]) == (edges, faces, 4 * nx * ny * nz)


def test_kirchhoff_weights_and_masses():
    lat = Lattice.from_body(Body.box(3, 3, 3, 0.5))
    w_edge = set(np.round(lat.weight[lat.family == EDGE], 12))
    assert w_edge == {0.25, 0.5, 1.0}
    assert set(np.round(lat.weight[lat.family == FACE], 12)) == {0.5, 1.0}
    assert set(lat.weight[lat.family == INNER]) == {1.0}
    m = lat.masses_per_density
    assert m.sum() == pytest.approx(27 * 0.125)
    assert m.min() == pytest.approx(0.125 / 8) and m.max() == pytest.approx(0.125)


@pytest.mark.parametrize("A", [0.0, 1.0, 3.0])
def test_homogeneous_energy_equals_continuum(A):
    """With Kirchhoff weights the spring energy of an affine deformation is Σ_cells Vc W(ε) with the
    Cauchy-symmetric spring tensor (λ = μ = G): checked on a 3×2×4 box to O(ε³)."""
    mat = Material(1e4, 0.25)
    sc = Scene(Body.box(3, 2, 4, 0.5), mat, Model("hybmss-cf", A=A))
    S = build(sc)
    rng = np.random.default_rng(1)
    H = rng.normal(size=(3, 3))
    eps = 1e-5
    x = S.X + eps * S.X @ H.T
    e, _ = spring_energy_forces(x, S.spring_a, S.spring_b, S.spring_k, S.spring_l0)
    strain = 0.5 * (H + H.T) * eps
    G = constants(sc.model, mat, 0.5).G_springs
    w = G * np.sum(strain * strain) + 0.5 * G * np.trace(strain) ** 2
    assert e == pytest.approx(w * sc.body.volume, rel=1e-4)


def test_voxel_mask_lattice():
    mask = np.ones((2, 2, 2), bool)
    mask[1, 1, 1] = False
    lat = Lattice.from_body(Body.from_mask(mask, 1.0))
    assert lat.n_cells == 7
    assert lat.n_particles == 27 - 1  # the far corner (2,2,2) belongs to no cell
    np.testing.assert_allclose(lat.cell_volumes(lat.X), 1.0)


def test_cell_volume_of_affine_map_is_det():
    lat = Lattice.from_body(Body.box(2, 2, 2, 0.5))
    F = np.array([[1.1, 0.2, 0.0], [0.0, 0.9, 0.1], [0.05, 0.0, 1.2]])
    np.testing.assert_allclose(lat.cell_volumes(lat.X @ F.T), np.linalg.det(F) * 0.125, rtol=1e-13)


def test_constants_fields_mean_what_their_documentation_says():
    """The shares the Constants docstring and the README's plug-in section state, on two cells
    side by side (2 x 1 x 1): an edge of the shared face belongs to 2 cells (k = 2 · ke/4), one on
    the outside to 1 (ke/4); the shared face's diagonals get 2 · kf/2 = kf, the others kf/2; inner
    diagonals kc.  Every field is documented in both places."""
    import dataclasses
    from pathlib import Path

    from hybmss.calibrate import Constants

    mat = Material(1e4, 0.3)
    sc = Scene(Body.box(2, 1, 1, 0.5), mat, Model("hybmss", A=1.5))
    c = constants(sc.model, mat, 0.5)
    S = build(sc)
    length = np.linalg.norm(S.X[S.spring_b] - S.X[S.spring_a], axis=1)
    mid = np.isclose(S.X[S.spring_a, 0], 0.5) & np.isclose(S.X[S.spring_b, 0], 0.5)  # in the plane x = le
    for fam, l0, n, n_shared, k_in, k_out in ((0, 0.5, 20, 4, c.ke / 2, c.ke / 4),
                                              (1, 0.5 * np.sqrt(2), 22, 2, c.kf, c.kf / 2)):
        sel = S.spring_family == fam
        assert sel.sum() == n and (sel & mid).sum() == n_shared and np.allclose(length[sel], l0)
        assert np.allclose(S.spring_k[sel & mid], k_in) and np.allclose(S.spring_k[sel & ~mid], k_out)
    inner = S.spring_family == 2
    assert inner.sum() == 8 and np.allclose(S.spring_k[inner], c.kc)
    assert c.G_springs == pytest.approx((4 / 3 * c.kc + c.kf) / 0.5) == pytest.approx(mat.G)
    assert S.kappa == c.kappa == pytest.approx(mat.G * (4 * 0.3 - 1) / (1 - 2 * 0.3))
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    plugin = readme[readme.index("## Add a model"):]
    for f in dataclasses.fields(Constants):
        assert f"``{f.name}``" in Constants.__doc__ and f"`{f.name}`" in plugin, f.name
