"""Voxel bodies beyond boxes (L-shape, boolean masks, closed surfaces read with meshio) and
dead surface loads, on the MSS and the FEM."""

import numpy as np
import pytest

from hybmss.scene import Body, Load, Material, Model, Motion, Plate, Region, Scene
from hybmss.solve import solve_static
from hybmss.system import build
from hybmss.voxelize import l_shape, voxelize, winding_number


def _box_surface(lo, hi):
    """A closed, outward-oriented triangulated box."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    V = np.array([[(hi if (c >> d) & 1 else lo)[d] for d in range(3)] for c in range(8)])
    quads = [(0, 2, 6, 4), (1, 5, 7, 3), (0, 4, 5, 1), (2, 3, 7, 6), (0, 1, 3, 2), (4, 6, 7, 5)]
    T = [t for q in quads for t in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))]
    return V, np.array(T)


def _icosphere(radius=1.0, level=2):
    t = (1 + 5**0.5) / 2
    V = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    F = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
         (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
         (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    V = [np.array(v, float) / np.linalg.norm(v) for v in V]
    for _ in range(level):
        cache, F2 = {}, []

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = V[a] + V[b]
                V.append(m / np.linalg.norm(m))
                cache[key] = len(V) - 1
            return cache[key]

        for a, b, c in F:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            F2 += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        F = F2
    return radius * np.array(V), np.array(F)


def test_l_shape_mask():
    b = l_shape(2, 0.05)
    assert b.shape == (4, 2, 4) and b.n_cells == 3 * 8
    m = b.mask
    assert m[:2].all() and m[2:, :, 2:].all() and not m[2:, :, :2].any()


def test_winding_number_inside_outside_both_orientations():
    V, T = _box_surface((0, 0, 0), (1, 2, 3))
    pts = np.array([[0.5, 1.0, 1.5], [1.5, 1.0, 1.5], [0.5, 1.0, -0.2], [0.01, 0.01, 0.01]])
    w = winding_number(pts, V, T)
    assert np.allclose(np.abs(w), [1, 0, 0, 1], atol=1e-9)
    assert np.allclose(winding_number(pts, V, T[:, ::-1]), -w, atol=1e-12)


def test_voxelize_box_surface_gives_the_box():
    V, T = _box_surface((0, 0, 0), (0.3, 0.2, 0.4))
    b = voxelize((V, T), 0.1)
    assert b.is_box and b.shape == (3, 2, 4)


def test_voxelize_sphere_read_with_meshio(tmp_path):
    meshio = pytest.importorskip("meshio")
    V, T = _icosphere(0.1, level=3)
    path = tmp_path / "sphere.obj"
    meshio.write(path, meshio.Mesh(V, [("triangle", T)]))
    b = voxelize(path, 0.02)
    assert not b.is_box
    # cell count close to the ball's volume (polyhedral sphere, voxel staircase)
    assert b.volume == pytest.approx(4 / 3 * np.pi * 0.1**3, rel=0.12)
    m = b.mask
    assert m[m.shape[0] // 2, m.shape[1] // 2, m.shape[2] // 2] and not m[0, 0, 0]


def _lshape_scene(model, n=2):
    return Scene(l_shape(n, 0.1 / n), Material(1000.0, 0.3), Model(model),
                 plates=(Plate("base", Region("z-"), Motion("clamped")),),
                 loads=(Load(Region("x+"), (0.0, 0.0, -0.5)),), name="l-shape")


def test_scene_loads_round_trip_and_keep_old_digests():
    s = _lshape_scene("hybmss")
    assert Scene.from_dict(s.to_dict()) == s
    assert Scene.from_dict(s.to_dict()).digest() == s.digest()
    plain = Scene(Body.box(1, 1, 1, 1.0), Material(1.0, 0.3))
    assert "loads" not in plain.to_dict()
    assert s.digest() != Scene.from_dict({**s.to_dict(), "loads": []}).digest()


def test_dead_load_nodal_forces_sum_to_traction_times_area():
    S = build(_lshape_scene("hybmss", n=2))
    dead = S.term("dead_load").f
    assert np.allclose(dead.sum(axis=0), [0.0, 0.0, -0.5 * 0.1 * 0.1])
    loaded = np.flatnonzero(np.abs(dead).sum(axis=1) > 0)
    assert np.allclose(S.X[loaded, 0], 0.2)


@pytest.mark.parametrize("model", ["hybmss", "baudet2009"])
def test_l_shape_runs_on_mss_and_fem(model):
    from fem_reference.solve import solve as fem_solve

    scene = _lshape_scene(model)
    r = solve_static(scene)
    f = fem_solve(scene, element="hex2", refine=1)
    total = np.array([0.0, 0.0, -0.5 * 0.01])
    assert np.allclose(r.reactions["base"].force, -total, atol=1e-9)
    assert np.allclose(f.reactions["base"].force, -total, atol=1e-9)
    assert np.allclose(f.info["surface_load"], total)
    # same deflection shape, within the coarse lattice's discretization error
    tip = np.argmin(r.u[:, 2])
    assert r.u[tip, 2] < 0 and f.u[tip, 2] < 0
    assert r.u[tip, 2] == pytest.approx(f.u[tip, 2], rel=0.4)


def test_fem_load_is_the_same_on_refined_meshes():
    from fem_reference.loads import load_vector
    from fem_reference.mesh import build_mesh
    from fem_reference.space import Space

    scene = _lshape_scene("hybmss")
    for r in (1, 2):
        space = Space.create(build_mesh(scene.body, r), "hex2")
        f = load_vector(scene, space).reshape(-1, 3)
        assert np.allclose(f.sum(axis=0), [0.0, 0.0, -0.005])
        loaded = np.abs(f).sum(axis=1) > 1e-12 * np.abs(f).max()
        assert np.allclose(space.points[loaded, 0], 0.2)


@pytest.mark.parametrize("model", ["hybmss", "baudet2009"])
def test_voxelized_body_runs_on_mss_and_fem(model):
    from fem_reference.solve import solve as fem_solve

    V, T = _icosphere(0.1, level=2)
    body = voxelize((V, T), 0.05)
    scene = Scene(body, Material(1000.0, 0.3, 1.0), Model(model),
                  plates=(Plate("bottom", Region("z-"), Motion("clamped")),), gravity=(0.0, 0.0, -9.81))
    r = solve_static(scene)
    f = fem_solve(scene, element="hex2", refine=1)
    weight = 1.0 * 9.81 * body.volume
    assert r.reactions["bottom"].force[2] == pytest.approx(weight, rel=1e-8)
    assert f.reactions["bottom"].force[2] == pytest.approx(weight, rel=1e-8)
    assert r.u[:, 2].min() < 0 and f.u[:, 2].min() < 0


def test_fem_finite_strain_takes_the_dead_load_too():
    from fem_reference.solve import solve as fem_solve

    scene = _lshape_scene("hybmss")
    lin = fem_solve(scene, element="hex2", law="linear")
    nh = fem_solve(scene, element="hex2", law="neo-hookean")
    assert np.allclose(nh.reactions["base"].force, [0.0, 0.0, 0.005], atol=1e-9)
    assert nh.u[:, 2].min() == pytest.approx(lin.u[:, 2].min(), rel=0.03)
