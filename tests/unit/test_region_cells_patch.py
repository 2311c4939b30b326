"""Regions drawn from cells (a mask label) and surface patches, and the scene digests of the
regions that have neither (their JSON form keeps exactly face, lo and hi)."""

from __future__ import annotations

import numpy as np

from hybmss.lattice import Lattice
from hybmss.scene import Body, Load, Material, Motion, Plate, Region, Scene


def test_cells_region_selects_the_nodes_of_its_cells():
    body = Body.box(3, 2, 2, 0.5)
    X = Lattice.from_body(body).X
    mask = np.zeros(body.shape, dtype=bool)
    mask[2, 1, 1] = True
    mask[0, 0, 0] = True
    sel = Region.of_cells(mask).select(X, body)
    corners = {(i + a, j + b, k + c) for i, j, k in np.argwhere(mask) for a in (0, 1) for b in (0, 1) for c in (0, 1)}
    expected = np.array([tuple(np.round(x / 0.5).astype(int)) in corners for x in X])
    assert sel.sum() == 16 and np.array_equal(sel, expected)


def test_patch_on_a_box_top_is_its_top_face_within_the_radius():
    body = Body.box(4, 4, 2, 1.0)
    X = Lattice.from_body(body).X
    top = Region("z+").select(X, body)
    wide = Region(patch=(0, 0, 1, 2, 2, 2, 10.0, 30.0)).select(X, body)
    assert np.array_equal(wide, top)
    near = Region(patch=(0, 0, 1, 2, 2, 2, 1.0, 30.0)).select(X, body)
    assert np.array_equal(near, top & (np.linalg.norm(X - [2, 2, 2], axis=1) <= 1.0)) and near.sum() == 5
    # a normal 45 degrees from every face normal of a box: no face within 30 degrees
    assert not Region(patch=(1, 0, 1, 2, 2, 2, 10.0, 30.0)).select(X, body).any()


def test_patch_selects_the_surface_faces_of_a_load():
    body = Body.box(2, 2, 2, 1.0)
    load = Load(Region(patch=(0, 0, 1, 1, 1, 2, 10.0, 30.0)), (0.0, 0.0, -1.0))
    ijk, axis, side = load.faces(body)
    assert len(ijk) == 4 and set(axis) == {2} and set(side) == {1}


def test_regions_without_cells_or_patch_keep_their_json_form():
    scene = Scene(Body.box(2, 2, 2, 1.0), Material(1.0, 0.3),
                  plates=(Plate("a", Region("z-"), Motion()), Plate("b", Region(lo=(0, 0, 0), hi=(1, 1, 0)), Motion())),
                  loads=(Load(Region("z+"), (0.0, 0.0, -1.0)),))
    d = scene.to_dict()
    assert all(set(p["region"]) == {"face", "lo", "hi"} for p in d["plates"] + d["loads"])
    with_cells = Scene(scene.body, scene.material, plates=(Plate("a", Region.of_cells(scene.body.mask), Motion()),))
    assert Scene.from_dict(with_cells.to_dict()).digest() == with_cells.digest()
