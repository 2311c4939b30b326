"""Bodies of a study file from a surface mesh file and from a labelled image (.npy, .vti): the
cells, the label regions and the pieces, against what the inputs say."""

from __future__ import annotations

import numpy as np

from study_files import small_study, write


def _labelled(tmp_path):
    """A 4 x 2 x 3 image, 1 cm voxels: label 1 for x < 2, label 2 for x >= 2, one empty corner."""
    image = np.ones((4, 2, 3), dtype=np.int32)
    image[2:] = 2
    image[3, 1, 2] = 0
    return image


def _doc(body, top_region):
    doc = small_study()
    doc["body"] = body
    doc["load_case"][0]["support"][1]["region"] = top_region
    doc["metrics"] = {"plate_force": ["top"]}
    return doc


def test_vti_mask_with_labels(tmp_path):
    import pyvista as pv

    from hybmss.lattice import Lattice
    from studies.study import Study

    image = _labelled(tmp_path)
    grid = pv.ImageData(dimensions=image.shape, spacing=(0.01, 0.01, 0.01))
    grid.point_data["labels"] = image.ravel(order="F")
    grid.save(tmp_path / "seg.vti")
    doc = _doc({"mask": "seg.vti", "cell_sizes": [0.01]}, {"label": 2, "face": "z+"})
    study = Study.from_toml(write(doc, tmp_path / "s.toml"))
    vox = study.voxels[0]
    assert vox.body.n_cells == np.count_nonzero(image) and vox.pieces()[1] == 1
    assert np.array_equal(vox.labels, image)
    top = study.tasks()[0].scene.build().plates[1]
    X = Lattice.from_body(vox.body).X
    sel = top.region.select(X, vox.body)
    # the z = 3 cm nodes of the label-2 cells: x in {2, 3, 4} cm, y in {0, 1, 2} cm, less the
    # corner (4, 2) that only the empty voxel touches
    assert sel.sum() == 3 * 3 - 1 and np.all(X[sel, 0] >= 0.02 - 1e-12) and np.allclose(X[sel, 2], 0.03)


def test_npy_mask_keeps_only_the_labels_asked(tmp_path):
    from studies.study import Study

    np.save(tmp_path / "seg.npy", _labelled(tmp_path))
    doc = _doc({"mask": "seg.npy", "spacing": [0.01, 0.01, 0.01], "labels": [1], "cell_sizes": [0.01]}, "z+")
    vox = Study.from_toml(write(doc, tmp_path / "s.toml")).voxels[0]
    assert vox.body.shape == (2, 2, 3) and vox.body.n_cells == 12 and set(np.unique(vox.labels)) == {1}


def test_surface_mesh_file_is_voxelized_by_its_cell_centres(tmp_path):
    """A closed sphere of radius 2 cm written as STL: the body is the 1 cm cells whose centre is
    inside it (the grid cropped to them), counted here from the centres directly."""
    import pyvista as pv

    from studies.study import Study

    ball = pv.Sphere(radius=0.02, theta_resolution=48, phi_resolution=48)
    ball.save(tmp_path / "ball.stl")
    doc = _doc({"mesh": "ball.stl", "cell_sizes": [0.01]}, "z+")
    doc["load_case"][0]["support"][1]["displacement"] = [0.0, 0.0, -0.0002]
    vox = Study.from_toml(write(doc, tmp_path / "s.toml")).voxels[0]
    # the grid starts at the surface's lowest corner; its cell centres lie 0.87, 1.66, 2.18 or
    # 2.6 cm from the centre (inside, inside, outside, outside a 2 cm ball, whatever the facets)
    start = np.asarray(ball.points).min(axis=0)
    g = [start[d] + (np.arange(4) + 0.5) * 0.01 for d in range(3)]
    C = np.stack(np.meshgrid(*g, indexing="ij"), -1).reshape(-1, 3)
    inside = np.linalg.norm(C, axis=1) < 0.02
    assert vox.body.n_cells == inside.sum() == 32
    centres = (np.argwhere(vox.body.mask) + 0.5) * 0.01 + np.asarray(vox.body.origin)
    assert np.all(np.linalg.norm(centres, axis=1) < 0.02)
