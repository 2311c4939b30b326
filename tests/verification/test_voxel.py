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


# ----------------------------------------------------------------------------- column parity
def _octahedron(r):
    """|x| + |y| + |z| = r, outward-oriented: its vertices and edges lie on grid lines."""
    V = r * np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    T = [(0, 2, 4), (2, 1, 4), (1, 3, 4), (3, 0, 4), (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5)]
    return V, np.array(T)


def _torus(u_res=100, v_res=100):
    pv = pytest.importorskip("pyvista")
    return pv.ParametricTorus(u_res=u_res, v_res=v_res)  # R = 1, r = 0.5; 19,602 triangles at 100 x 100


@pytest.mark.parametrize("case", ["box", "box-offset", "ico2", "ico3", "torus-coarse"])
def test_parity_mask_is_the_winding_number_mask(case):
    from hybmss.voxelize import surface_triangles, voxel_mask

    V, T, les = {
        "box": (*_box_surface((0, 0, 0), (0.3, 0.2, 0.4)), (0.1, 0.03, 0.07)),
        "box-offset": (*_box_surface((0.013, -0.2, 0.1), (0.33, 0.2, 0.47)), (0.03, 0.05)),
        "ico2": (*_icosphere(0.1, 2), (0.05, 0.013)),
        "ico3": (*_icosphere(0.1, 3), (0.02,)),
        "torus-coarse": (*surface_triangles(_torus(20, 20)), (0.1,)) if case == "torus-coarse" else (None, None, ()),
    }[case]
    for le in les:
        parity, o1 = voxel_mask(V, T, le)
        winding, o2 = voxel_mask(V, T, le, method="winding")
        assert o1 == o2 and parity.any()
        assert np.array_equal(parity, winding), f"{case} le={le}: {(parity != winding).sum()} cells differ"


def test_parity_falls_back_to_the_winding_number_on_grid_lines():
    """An octahedron whose vertices and edges lie exactly on column lines (the grid's centres at
    multiples of 0.25): parity alone would miss or double the crossings there."""
    from hybmss.voxelize import column_parity, voxel_mask

    V, T = _octahedron(0.9)
    o, le, shape = (-1.125,) * 3, 0.25, (9, 9, 9)
    _, ambiguous = column_parity(V, T, le, o, shape)
    assert ambiguous[4, 4] and ambiguous[4, :].sum() >= 5 and ambiguous[:, 4].sum() >= 5
    parity, _ = voxel_mask(V, T, le, o, shape)
    winding, _ = voxel_mask(V, T, le, o, shape, method="winding")
    assert np.array_equal(parity, winding)
    c = -1.125 + (np.indices(shape) + 0.5) * 0.25  # cell centres; none lies on the surface
    assert np.array_equal(parity, np.abs(c).sum(axis=0) < 0.9)


def test_open_surface_takes_the_winding_number():
    from hybmss.voxelize import is_closed, voxel_mask

    V, T = _icosphere(0.1, 2)
    T = T[1:]  # one triangle missing: a hole
    assert not is_closed(T)
    parity, _ = voxel_mask(V, T, 0.02)
    winding, _ = voxel_mask(V, T, 0.02, method="winding")
    assert np.array_equal(parity, winding)


def test_voxelized_sphere_volume_within_the_staircase_bound():
    """Cells whose centre lies in a body P: every point of P farther than h = √3/2 le inside its
    surface has its cell's centre in P, and no counted cell reaches beyond h outside it.  For a
    sphere polyhedron between the inscribed radius r_in (nearest face plane) and R:
    4/3 π (r_in − h)³ <= N le³ <= 4/3 π (R + h)³."""
    pv = pytest.importorskip("pyvista")
    R = 0.1
    sphere = pv.Sphere(radius=R, theta_resolution=60, phi_resolution=60)
    V = np.asarray(sphere.points)
    F = np.asarray(sphere.faces).reshape(-1, 4)[:, 1:]
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    ok = np.linalg.norm(n, axis=1) > 0
    r_in = np.min(np.abs(np.einsum("ij,ij->i", n[ok], V[F[ok, 0]])) / np.linalg.norm(n[ok], axis=1))
    assert 0.99 * R < r_in < R
    for le in (0.04, 0.02, 0.01, 0.005):
        b = voxelize(sphere, le)
        h = np.sqrt(3) / 2 * le
        lo, hi = 4 / 3 * np.pi * max(r_in - h, 0.0) ** 3, 4 / 3 * np.pi * (R + h) ** 3
        assert lo <= b.volume <= hi
    assert b.volume == pytest.approx(4 / 3 * np.pi * R**3, rel=0.02)  # le = R/20


def test_voxelize_takes_meshio_and_pyvista_meshes():
    pv = pytest.importorskip("pyvista")
    meshio = pytest.importorskip("meshio")
    V, T = _icosphere(0.1, 2)
    ref = voxelize((V, T), 0.02)
    assert voxelize(meshio.Mesh(V, [("triangle", T)]), 0.02) == ref
    poly = pv.PolyData(V, np.column_stack([np.full(len(T), 3), T]).ravel())
    assert voxelize(poly, 0.02) == ref
    grid = pv.ImageData(dimensions=(4, 3, 5), spacing=(0.1, 0.1, 0.1)).cast_to_unstructured_grid()
    b = voxelize(grid, 0.1)  # a volume mesh: its outer surface (quads, triangulated)
    assert b.is_box and b.shape == (3, 2, 4)
    with pytest.raises(ValueError, match="surface must be"):
        voxelize(42, 0.1)


def test_torus_voxelizes_fast():
    """The 19,602-triangle torus (R = 1, r = 0.5) into cells of 0.15: the winding number takes
    ~25 s of CPU; ray parity well under a second (a loose bound of 2 s on a loaded machine)."""
    import time

    from hybmss.voxelize import surface_triangles

    torus = _torus()
    assert len(surface_triangles(torus)[1]) == 19602
    t0 = time.process_time()
    b = voxelize(torus, 0.15)
    cpu = time.process_time() - t0
    assert cpu < 2.0
    # volume 2π² R r² within the staircase bound of the test above (a tube of half-width h)
    h = np.sqrt(3) / 2 * 0.15
    assert 2 * np.pi**2 * (0.5 - h) ** 2 <= b.volume <= 2 * np.pi**2 * (0.5 + h) ** 2


def test_disconnected_mask_is_refused_and_pieces_are_sized():
    from hybmss.voxelize import pieces

    mask = np.zeros((5, 3, 3), bool)
    mask[:2] = True  # 18 cells
    mask[4, 0, 0] = True  # 1 cell, two cells away
    mask[3, 2, 2] = True  # 1 cell, adjacent to neither
    labels, sizes = pieces(mask)
    assert list(sizes) == [18, 1, 1] and labels.max() == 3 and (labels[:2] == 1).all()
    with pytest.raises(ValueError, match=r"falls apart into 3 pieces of 18, 1, 1 cells"):
        Body.from_mask(mask, 0.1)
    edge_only = np.zeros((2, 2, 1), bool)
    edge_only[0, 0, 0] = edge_only[1, 1, 0] = True  # cells sharing an edge only
    assert list(pieces(edge_only)[1]) == [1, 1]
    with pytest.raises(ValueError, match="2 pieces"):
        Body.from_mask(edge_only, 0.1)
    ring = np.ones((3, 3, 1), bool)
    ring[1, 1, 0] = False  # a ring is one piece
    assert Body.from_mask(ring, 0.1).n_cells == 8
