"""FEM reference on tetrahedra against closed forms: the uniaxial patch test (exact for P1, P2, P2-P1),
a bar hanging under its own weight (quadratic: exact for P2, P1's nodal error approaching h^2), the torsion
of a circular shaft (T = G J theta / L, converging at h^2 on refined meshes projected onto the cylinder),
the Richardson estimate of that convergence, and sampling the field at arbitrary points."""

import numpy as np
import pytest
import pyvista as pv
from skfem import MeshTet

from fem_reference.tet import (TET_FORMULATIONS, Support, TetProblem, as_mesh, clamp, rotate, tet_convergence,
                               translate)
from hybmss.scene import Material
from hybmss.tetbody import mesh_surface

R, H, THETA = 0.01, 0.04, 0.01


def _box(nx, ny, nz, L):
    return MeshTet.init_tensor(np.linspace(0, 1, nx + 1), np.linspace(0, 1, ny + 1), np.linspace(0, L, nz + 1))


@pytest.mark.parametrize("formulation,nu", [("p1", 0.3), ("p2", 0.3), ("mixed", 0.3), ("mixed", 0.4999)])
def test_uniaxial_stress_patch_test_is_exact(formulation, nu):
    mat, eps, L = Material(1000.0, nu, 0.0), 1e-3, 2.0
    exact = lambda x: np.array([-nu * eps * x[0], -nu * eps * x[1], eps * x[2]])  # noqa: E731
    body = mesh_surface(pv.Box((0, 1, 0, 1, 0, L)), 0.45)  # unstructured
    pr = TetProblem(as_mesh(body), formulation)
    sol = pr.solve(mat, [Support("bottom", lambda x: x[2] < 1e-9, exact),
                         Support("top", lambda x: x[2] > L - 1e-9, exact)])
    assert np.abs(sol.U - exact(pr.basis.doflocs).T).max() < 1e-12 * eps * L
    F = sol.reactions["top"].force
    assert F[2] == pytest.approx(mat.E * eps * 1.0, rel=1e-10)  # sigma_zz A
    assert abs(F[0]) + abs(F[1]) < 1e-10 * F[2]
    assert sol.energy == pytest.approx(0.5 * mat.E * eps**2 * L, rel=1e-10)


def _hanging(nu=0.3):
    """Bar [0,1]^2 x [0,L] held at z = L, gravity -z: sigma_zz = rho g z, the rest zero (Timoshenko)."""
    mat, g, L = Material(1e4, nu, 1000.0), 9.81, 4.0
    c = mat.rho * g / mat.E
    exact = lambda x: np.array([-nu * c * x[0] * x[2], -nu * c * x[1] * x[2],  # noqa: E731
                                0.5 * c * (x[2] ** 2 - L**2) + 0.5 * nu * c * (x[0] ** 2 + x[1] ** 2)])
    sup = [Support("top", lambda x: x[2] > L - 1e-9, exact)]
    energy = (mat.rho * g) ** 2 * L**3 / (6 * mat.E)  # A = 1
    return mat, L, exact, sup, energy


def test_hanging_bar_exact_for_p2_and_p1_approaching_h2():
    mat, L, exact, sup, energy = _hanging()
    gravity = (0.0, 0.0, -9.81)
    pr = TetProblem(_box(1, 1, 4, L), "p2")
    sol = pr.solve(mat, sup, gravity)
    scale = np.abs(exact(pr.basis.doflocs)).max()
    assert np.abs(sol.U - exact(pr.basis.doflocs).T).max() < 1e-10 * scale
    assert sol.energy == pytest.approx(energy, rel=1e-10)
    mesh, err = _box(2, 2, 8, L), []
    for _ in range(4):
        s = TetProblem(mesh, "p1").solve(mat, sup, gravity)
        # the support carries the weight exactly at any h (discrete equilibrium of a rigid translation)
        assert s.reactions["top"].force[2] == pytest.approx(mat.rho * 9.81 * L, rel=1e-10)
        pr = TetProblem(mesh, "p1")
        err.append(np.abs(s.U - exact(pr.basis.doflocs).T).max() / scale)  # nodal error
        mesh = mesh.refined()
    # P1 cannot hold the quadratic u_z that cancels the shear of u_x = -nu c x z: on coarse meshes it
    # locks as in bending; the local order of each halving of h rises towards 2
    orders = np.log2(np.asarray(err[:-1]) / np.asarray(err[1:]))
    assert (np.diff(orders) > 0).all() and 1.6 < orders[-1] < 2.3, (err, orders)
    assert err[-1] < 0.03


def _project_on_cylinder(mesh: MeshTet) -> MeshTet:
    """Boundary nodes of the lateral surface (and the rims) moved radially onto r = R."""
    p = mesh.p.copy()
    b = mesh.boundary_nodes()
    r, z = np.hypot(p[0, b], p[1, b]), p[2, b]
    e = mesh.edges
    h = float(np.linalg.norm(p[:, e[0]] - p[:, e[1]], axis=0).mean())
    lateral = ((z > 1e-6 * H) & (z < H * (1 - 1e-6))) | (r > R - h / 4)
    p[:2, b[lateral]] *= R / r[lateral]
    return MeshTet(p, mesh.t)


@pytest.fixture(scope="module")
def shaft():
    body = mesh_surface(pv.Cylinder(center=(0, 0, H / 2), direction=(0, 0, 1), radius=R, height=H,
                                    resolution=128), R / 1.2)
    sup = [clamp("bottom", lambda x: x[2] < 1e-6 * H),
           rotate("top", lambda x: x[2] > H * (1 - 1e-6), THETA, (0, 0, 1), (0, 0, H))]
    return _project_on_cylinder(as_mesh(body)), sup


@pytest.mark.parametrize("formulation,nu", [pytest.param("p2", 0.3, marks=pytest.mark.slow), ("mixed", 0.4999)])
def test_torsion_of_a_circular_shaft_converges_at_h2(shaft, formulation, nu):
    mesh, sup = shaft
    mat = Material(1000.0, nu, 0.0)
    T_exact = mat.G * np.pi * R**4 / 2 * THETA / H
    h, err = [], []
    for _ in range(2 if formulation == "mixed" else 3):
        pr = TetProblem(mesh, formulation)
        s = pr.solve(mat, sup)
        h.append(pr.h)
        err.append(abs(s.reactions["top"].torque[2] / T_exact - 1))
        assert abs(s.reactions["bottom"].torque[2] + s.reactions["top"].torque[2]) < 1e-3 * T_exact  # about centroids near the axis
        mesh = _project_on_cylinder(mesh.refined())
    # P2 holds the exact field theta z (-y, x) / L: the error is the faceted boundary's, O(h^2)
    slope = np.polyfit(np.log(h), np.log(err), 1)[0]
    assert 1.8 < slope < 2.3, (err, slope)
    assert err[-1] < 0.035


def test_torsion_richardson_estimate_brackets_the_closed_form(shaft):
    mesh, sup = shaft
    mat = Material(1000.0, 0.3, 0.0)
    T_exact = mat.G * np.pi * R**4 / 2 * THETA / H
    sols, conv = tet_convergence(mesh, "p1", mat, sup, {"T": lambda s: s.reactions["top"].torque[2]},
                                 levels=3, project=_project_on_cylinder)
    o = conv["T"]
    assert len(sols) == 3 and o.refinements == (1, 2, 4)
    true_finest = abs(o.values[-1] - T_exact)
    # the estimate is of the size of the true error of the finest mesh, and the extrapolation is closer
    assert 0.5 * true_finest < o.error_finest < 2.0 * true_finest
    assert abs(o.extrapolated - T_exact) < 0.5 * true_finest


def test_budget_stops_the_refinement(shaft):
    mesh, sup = shaft
    outputs = {"T": lambda s: s.reactions["top"].torque[2]}
    sols, conv = tet_convergence(mesh, "p1", Material(1000.0, 0.3, 0.0), sup, outputs, levels=4, budget=1.0,
                                 project=_project_on_cylinder)
    assert len(sols) == 2 and conv["T"].refinements == (1, 2)


@pytest.mark.parametrize("formulation", TET_FORMULATIONS)
def test_sampling_reproduces_a_linear_field_exactly(formulation):
    body = mesh_surface(pv.Cylinder(center=(0, 0, H / 2), direction=(0, 0, 1), radius=R, height=H,
                                    resolution=32), R / 1.5)
    pr = TetProblem(as_mesh(body), formulation)
    A = np.array([[0.1, -0.2, 0.3], [0.05, 0.2, -0.1], [-0.3, 0.1, 0.15]])
    b = np.array([1e-3, -2e-3, 5e-4])
    field = lambda X: X @ A.T + b  # noqa: E731
    sol = pr.solve(Material(1000.0, 0.3, 0.0), [translate("all", lambda x: np.ones(x.shape[1], bool), (0, 0, 0))])
    sol.U = field(pr.basis.doflocs.T)  # the interpolant of the linear field (exact in P1 and P2)
    rng = np.random.default_rng(1)
    nodes = body.X[body.tets[:40]]  # (40, 4, 3): points inside 40 tets and the nodes themselves
    w = rng.dirichlet(np.ones(4), size=40)
    pts = np.concatenate([np.einsum("ek,ekc->ec", w, nodes), body.X])
    assert np.abs(sol.sample(pts) - field(pts)).max() < 1e-14
    with pytest.raises(ValueError, match="1 of 2 points lie outside"):
        sol.sample(np.array([[0.0, 0.0, H / 2], [2 * R, 0.0, H / 2]]))


def test_p1_locks_in_torsion_near_incompressibility_where_the_mixed_element_does_not(shaft):
    mesh, sup = shaft
    mesh = _project_on_cylinder(mesh.refined())
    mat = Material(1000.0, 0.4999, 0.0)
    T_exact = mat.G * np.pi * R**4 / 2 * THETA / H
    err = {f: TetProblem(mesh, f).solve(mat, sup).reactions["top"].torque[2] / T_exact - 1 for f in ("p1", "mixed")}
    # P1's constant-strain tets cannot shear without changing volume: several times too stiff
    assert err["p1"] > 1.0 and abs(err["mixed"]) < 0.05, err
