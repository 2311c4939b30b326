"""The engines on a body's own tetrahedra (hybmss.models._engine_tet): the gmsh tetrahedra of a
cylinder surface, stepped by mujoco-tet, newton-semi, newton-vbd and pbd-xpbd-fem to rest.

- Patch test: every boundary node held at an affine displacement u = G X (strain 1e-3).  A
  homogeneous deformation gradient is an exact equilibrium of any hyperelastic law on any mesh
  (the constant stress of each tetrahedron gives interior nodes forces that cancel), so the
  interior nodes must come to rest at G X: the tolerance is the engines' rest tolerance
  (<= 1e-3 of the force scale) carried to the displacements, 1 % of the displacement scale
  |G| L.  The forces the engine puts on the held nodes are those of linear elasticity (scikit-fem's
  P1 stiffness K on the same tetrahedra, K u) up to the finite-strain terms of its law, O(|G|):
  within 10 |G| in relative L2 (a wrong Lame map is 25 % off).
- The squeezed cylinder (bottom clamped, top moved 1e-3 of the height): the engine's rest state
  against scikit-fem's P1 solution on the same tetrahedra (the same discrete problem at small
  strain), field and reaction within 10 x the strain.
- MuJoCo's interpolated kinds keep boxes: refused with one line.
"""

import numpy as np
import pytest
import pyvista as pv

from fem_reference.tet import TetProblem, as_mesh, clamp, translate
from hybmss.models import get
from hybmss.models._engine_model import SceneNotRepresentable
from hybmss.models._engine_tet import TetHold
from hybmss.scene import Material
from hybmss.scene.boundary import Motion
from hybmss.tetbody import mesh_surface

pytest.importorskip("gmsh")

R, H = 0.01, 0.04
ENGINES = (("mujoco-tet", "mujoco"), ("newton-semi", "newton"), ("newton-vbd", "newton"), ("pbd-xpbd-fem", "pypbd"))


@pytest.fixture(scope="module")
def body():
    surf = pv.Cylinder(center=(0, 0, H / 2), direction=(0, 0, 1), radius=R, height=H, resolution=48)
    return mesh_surface(surf, 0.006)


def _boundary(body):
    faces = np.sort(np.concatenate([body.tets[:, f] for f in ([0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3])]), axis=1)
    uniq, count = np.unique(faces, axis=0, return_counts=True)
    mask = np.zeros(body.n_nodes, dtype=bool)
    mask[uniq[count == 1].ravel()] = True
    return mask


def _model(name, module):
    pytest.importorskip(module)
    return get(name)


@pytest.mark.parametrize("name,module", ENGINES)
def test_engine_reproduces_a_homogeneous_deformation_on_a_tet_mesh(body, name, module):
    model = _model(name, module)
    eps = 1e-3
    G = eps * np.array([[1.0, 0.3, 0.0], [0.0, -0.5, 0.2], [0.1, 0.0, 0.7]])
    mat = Material(E=1e4, nu=0.3, rho=1000.0)
    bnd = _boundary(body)
    assert (~bnd).sum() >= 5  # interior nodes to test
    motion = Motion(kind="affine", gradient=tuple(G.ravel()), center=(0.0, 0.0, 0.0))
    r = model.solve_tets(body, mat, [TetHold("surface", lambda X: bnd, motion)])
    assert r.converged
    exact = body.X @ G.T
    scale = np.linalg.norm(G, 2) * H
    assert np.abs(r.u - exact)[~bnd].max() < 1e-2 * scale
    pr = TetProblem(as_mesh(body), "p1")
    Klam, Kmu = pr.parts
    f_lin = ((mat.lam * Klam + mat.G * Kmu) @ exact.ravel()).reshape(-1, 3)[bnd]
    diff = np.linalg.norm(-r.f[bnd] - f_lin) / np.linalg.norm(f_lin)  # the supports' forces on the body
    assert diff < 10 * eps


@pytest.mark.parametrize("name,module", ENGINES[:2])
def test_engine_on_a_cylinder_matches_the_tet_fem_on_its_mesh(body, name, module):
    model = _model(name, module)
    strain = 1e-3
    mat = Material(E=1e4, nu=0.3, rho=1000.0)
    z0, z1 = body.X[:, 2].min(), body.X[:, 2].max()
    tol = 1e-6 * (z1 - z0)
    d = -strain * (z1 - z0)
    bottom = lambda X: X[:, 2] < z0 + tol  # noqa: E731
    top = lambda X: X[:, 2] > z1 - tol  # noqa: E731
    r = model.solve_tets(body, mat, [TetHold("bottom", bottom, Motion(kind="clamped")),
                                     TetHold("top", top, Motion(kind="translate", displacement=(0.0, 0.0, d)))])
    assert r.converged
    sol = TetProblem(as_mesh(body), "p1").solve(mat, [clamp("bottom", lambda x: bottom(x.T)),
                                                      translate("top", lambda x: top(x.T), (0.0, 0.0, d))])
    field = np.linalg.norm(r.u - sol.U) / np.linalg.norm(sol.U)
    assert field < 10 * strain
    F_ref = sol.reactions["top"].force[2]
    assert abs(r.reactions["top"].force[2] - F_ref) < 10 * strain * abs(F_ref)


@pytest.mark.parametrize("name", ("mujoco-trilinear", "mujoco-quadratic"))
def test_mujoco_box_kinds_refuse_a_tet_body(body, name):
    model = _model(name, "mujoco")
    with pytest.raises(SceneNotRepresentable) as e:
        model.solve_tets(body, Material(E=1e4, nu=0.3, rho=1000.0),
                         [TetHold("bottom", lambda X: X[:, 2] < 1e-9, Motion(kind="clamped"))])
    msg = str(e.value)
    assert "\n" not in msg and "keeps boxes" in msg and "mujoco-tet" in msg
