"""A finer refinement of the FEM reference started from the coarser one's solution.

- ``FemMesh.elements_at`` finds, for points inside, on faces, edges and vertices of an L-shaped
  body's cells, an element whose box holds the point, and refuses a point outside;
- the prolongation of a field of the coarser space to the finer nodes is exact for the fields the
  coarser space holds (a quadratic for Hex2, a trilinear one for the Hex1 pressure), also between
  meshes that do not nest (refine 2 → 3);
- ``solve_levels``: a finite-strain level started from the coarser solution reaches the equilibrium of
  the same level solved from the undeformed state (both to Newton's tolerance: 1e-8 of the field
  and the reactions, as the other solver-path comparisons) in fewer Newton iterations; from a start
  far from the solution it reaches it too, and a start that inverts elements is not used.
"""

import numpy as np
import pytest

from fem_reference import linalg
from fem_reference.dirichlet import plate_dirichlet
from fem_reference.hyperelastic import Hyperelasticity
from fem_reference.mesh import build_mesh
from fem_reference.prolong import prolong, prolongation
from fem_reference.solve import solve, solve_levels
from hybmss.scene import Body, Material, Motion, Plate, Region, Scene


def _l_body(le=0.5):
    mask = np.ones((3, 2, 3), bool)
    mask[2, :, 2] = False
    mask[0, 1, 0] = False
    return Body.from_mask(mask, le, origin=(0.1, -0.2, 0.3))


def test_elements_at_finds_a_cell_that_holds_each_point():
    fm = build_mesh(_l_body(), 2)
    rng = np.random.default_rng(1)
    lo = fm.points[fm.mesh.t].min(axis=0)  # (ne, 3) lowest corner of each element
    inside = lo[rng.integers(0, len(lo), 50)] + rng.random((50, 3)) * fm.h
    corners = fm.points  # every vertex: on faces, edges and corners of cells
    faces = lo + np.array([0.5, 0.0, 0.5]) * fm.h
    for pts in (inside, corners, faces):
        e = fm.elements_at(pts)
        assert np.all(e >= 0)
        assert np.all(pts >= lo[e] - 1e-12) and np.all(pts <= lo[e] + fm.h + 1e-12)
    with pytest.raises(ValueError, match="outside"):
        fm.elements_at(np.array([[0.1 + 2.9 * 0.5 * 0.99, -0.2 + 0.25, 0.3 + 2.5 * 0.5]]))  # the cut corner


@pytest.mark.parametrize("rc, rf", [(1, 2), (1, 3), (2, 3)])
def test_prolongation_is_exact_for_the_fields_of_the_coarser_space(rc, rf):
    body = _l_body()
    c, f = (Hyperelasticity(build_mesh(body, r), "mixed") for r in (rc, rf))

    def quadratic(x):
        return 1.0 + x[:, 0] ** 2 - 2.0 * x[:, 1] * x[:, 2] + 0.5 * x[:, 2] ** 2 + x[:, 0] * x[:, 1] * x[:, 2] ** 2

    def trilinear(x):
        return 2.0 + x[:, 0] - x[:, 1] * x[:, 2] + 3.0 * x[:, 0] * x[:, 1] * x[:, 2]

    x, y = c.space.points, f.space.points
    U = np.stack([quadratic(x), trilinear(x), -quadratic(x)], axis=1)
    Uf, pf = prolong(c, f, U, trilinear(c.pspace.points))
    expect = np.stack([quadratic(y), trilinear(y), -quadratic(y)], axis=1)
    assert np.abs(Uf - expect).max() <= 1e-12 * np.abs(expect).max()
    assert np.abs(pf - trilinear(f.pspace.points)).max() <= 1e-12 * 10
    # a field the coarser space does not hold (a cubic) is not reproduced: the test can fail
    P = prolongation(c.space, f.space)
    assert np.abs(P @ x[:, 0] ** 3 - y[:, 0] ** 3).max() > 1e-6


def _twist(nu: float) -> Scene:
    motion = Motion("rotate", angle=np.radians(25.0), axis=(0.0, 0.0, 1.0), center=(0.5, 0.5, 1.5))
    return Scene(Body.box(2, 2, 3, 0.5), Material(1e4, nu, 1000.0),
                 plates=(Plate("bottom", Region("z-")), Plate("top", Region("z+"), motion)))


@pytest.mark.parametrize("nu", [0.3, 0.49])
def test_a_level_started_from_the_coarser_one_reaches_the_same_equilibrium(nu):
    sc = _twist(nu)
    coarse, fine = solve_levels(sc, (1, 2), law="neo-hookean")
    alone = solve(sc, law="neo-hookean", refine=2)
    assert fine.info["started_from_refine"] == 1 and "started_from_refine" not in coarse.info
    assert fine.converged and alone.converged
    assert np.abs(fine.u - alone.u).max() <= 1e-8 * np.abs(alone.u).max()
    for name in ("top", "bottom"):
        ref = np.abs(alone.reactions[name].torque).max()
        assert np.abs(np.subtract(fine.reactions[name].torque, alone.reactions[name].torque)).max() <= 1e-8 * ref
    assert fine.iterations < alone.iterations
    assert fine.info["newton"]["steps"] == 1


def test_a_start_far_from_the_solution_still_reaches_it():
    sc = _twist(0.3)
    ops = Hyperelasticity(build_mesh(sc.body, 1), "hex2", "neo-hookean")
    d = plate_dirichlet(sc, ops.space)
    alone, log_a = ops.solve(sc.material, d, rtol=1e-10)
    far = -3.0 * alone.U  # the twist turned back three times over
    inverted = np.zeros_like(alone.U)
    inverted[:, 2] = -3.0 * ops.space.points[:, 2]  # every element turned inside out: not a start
    for start in (far, inverted):
        started, log = ops.solve(sc.material, d, rtol=1e-10, start=(start, None))
        assert log.converged
        assert np.abs(started.U - alone.U).max() <= 1e-8 * np.abs(alone.U).max()
    assert log.iterations == log_a.iterations  # the inverted start was not used: the same path


def test_a_saddle_point_beyond_cholmod_limit_is_eliminated_when_its_factor_fits(monkeypatch):
    monkeypatch.setattr(linalg, "DIRECT_MAX_NNZ_CHOLMOD", 1)
    monkeypatch.setattr(linalg, "available_memory", lambda: 1e12)
    assert linalg._schur_fits(10**6)
    monkeypatch.setattr(linalg, "available_memory", lambda: 100.0 * linalg.SCHUR_BYTES_PER_NNZ / linalg.AVAILABLE_FRACTION)
    assert linalg._schur_fits(100) and not linalg._schur_fits(101)


def test_the_mixed_element_reuses_its_factorization_further_from_the_solution(monkeypatch):
    """Chord steps of the mixed element from CHORD_NEAR_MIXED of the force scale on: the same
    equilibrium as with chord steps only from CHORD_NEAR (1e-8 of the field and the torques), with
    fewer factorizations."""
    from fem_reference import hyperelastic

    sc = _twist(0.49)
    runs = {}
    for near in (hyperelastic.CHORD_NEAR, hyperelastic.CHORD_NEAR_MIXED):
        monkeypatch.setattr(hyperelastic, "CHORD_NEAR_MIXED", near)
        runs[near] = list(solve_levels(sc, (1, 2), law="neo-hookean"))[-1]
    strict, loose = runs[hyperelastic.CHORD_NEAR], runs[max(runs)]
    assert strict.converged and loose.converged
    assert np.abs(loose.u - strict.u).max() <= 1e-8 * np.abs(strict.u).max()
    ref = np.abs(strict.reactions["top"].torque).max()
    assert np.abs(np.subtract(loose.reactions["top"].torque, strict.reactions["top"].torque)).max() <= 1e-8 * ref
    fresh = {k: r.info["linear_solver"]["iterations"] for k, r in runs.items()}
    assert fresh[max(runs)] < fresh[min(runs)]  # 1 and 2 measured
