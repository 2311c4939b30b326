"""The body of a study: a box, a closed surface mesh (a file, or one that pyvista ships offline)
or a segmented image (a mask with its spacing and labels), voxelized at each cell size.

Each cell size gives one :class:`Voxels`: the :class:`hybmss.scene.Body` and the label of every
cell of its grid (0 outside), from which mask-label regions are drawn.  A mesh is voxelized by
:mod:`hybmss.voxelize` (the cells whose centre is inside); a mask is sampled at the cell centres
(the image voxel that holds the centre)."""

from __future__ import annotations

import contextlib
import math
import logging
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from hybmss.scene import Body, pieces

from studies.study.checks import check_digits, check_extent, check_volume, check_winding, mask_measures, surface_measures
from studies.study.keys import Table, close

SOURCES = ("box", "mesh", "pyvista", "mask", "experiment")
BODY_KEYS = ("origin", "scale", "spacing", "labels", "cell_sizes", "tet_sizes", "quick")
"""The keys of [body] other than its source."""
MESH_SUFFIXES = (".stl", ".obj", ".ply", ".vtk", ".vtp")
MASK_SUFFIXES = (".npy", ".vti")
PYVISTA_SURFACES = ("nut", "ant", "airplane", "sphere")
"""Closed-or-not surfaces that ``pyvista.examples`` ships in its wheel (read offline); the file
check refuses one that is not closed."""


@dataclass(frozen=True)
class Voxels:
    """One resolution of the body: ``body`` and the cell labels ``labels`` over its grid."""

    le: float
    body: Body
    labels: np.ndarray

    def pieces(self) -> tuple[np.ndarray, int]:
        """Face-connected pieces of the body (:func:`hybmss.scene.pieces`): (piece number of each
        cell, 0 outside; count)."""
        labels, sizes = pieces(self.body.mask)
        return labels, len(sizes)


@dataclass(frozen=True)
class BodySource:
    """Where the body comes from (``kind`` one of :data:`SOURCES` but ``experiment``)."""

    kind: str
    size: tuple[float, float, float] | None = None
    path: str | None = None
    scale: float = 1.0
    spacing: tuple[float, float, float] | None = None
    labels: tuple[int, ...] | None = None
    origin: tuple[float, float, float] | None = None

    def voxels(self, le: float) -> Voxels:
        if self.kind == "box":
            n = [int(round(s / le)) for s in self.size]
            origin = self.origin or (0.0, 0.0, 0.0)
            return Voxels(le, Body.box(*n, le, origin), np.ones(n, dtype=np.int64))
        if self.kind == "mask":
            return self._from_image(le)
        return self._from_surface(le)

    def _from_surface(self, le: float) -> Voxels:
        from hybmss.voxelize import voxel_mask

        vertices, triangles = read_surface(self.path, self.scale)
        mask, origin = voxel_mask(vertices, triangles, le)
        if self.origin is not None:
            origin = self.origin
        return cropped(le, mask, mask.astype(np.int64), origin)

    def _from_image(self, le: float) -> Voxels:
        image, spacing, image_origin = read_image(self.path, self.spacing)
        extent = np.asarray(image.shape) * spacing
        shape = np.maximum(1, np.floor(extent / le + 1e-9).astype(int))
        centres = [(np.arange(n) + 0.5) * le for n in shape]
        idx = [np.minimum((c / s).astype(int), m - 1) for c, s, m in zip(centres, spacing, image.shape)]
        labels = image[np.ix_(*idx)].astype(np.int64)
        keep = np.isin(labels, self.labels) if self.labels else labels != 0
        labels = np.where(keep, labels, 0)
        origin = self.origin or tuple(float(v) for v in image_origin)
        return cropped(le, keep, labels, origin)


def cropped(le: float, mask: np.ndarray, labels: np.ndarray, origin) -> Voxels:
    """The body of the cells of ``mask`` on the grid cropped to their bounding box (so that a
    bounding-box face of the body is a face of its cells)."""
    if not mask.any():
        raise ValueError("no cell of the grid lies in the body")
    found = np.argwhere(mask)
    lo, hi = found.min(axis=0), found.max(axis=0) + 1
    box = tuple(slice(a, b) for a, b in zip(lo, hi))
    shifted = tuple(np.asarray(origin, dtype=float) + lo * le)
    inner = mask[box]
    if len(pieces(inner)[1]) > 1:  # Body.from_mask refuses pieces; the study holds each one or refuses
        return Voxels(le, Body(inner.shape, le, shifted, np.packbits(inner.ravel()).tobytes()), labels[box])
    return Voxels(le, Body.from_mask(inner, le, shifted), labels[box])


def read_surface(path: str, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Points (scaled) and triangles of a surface file read with pyvista
    (:func:`hybmss.voxelize.surface_triangles`)."""
    import pyvista as pv

    from hybmss.voxelize import surface_triangles

    with quiet_vtk():
        points, triangles = surface_triangles(pv.read(path))
    return np.asarray(points, dtype=float) * scale, np.asarray(triangles, dtype=np.int64)


@contextlib.contextmanager
def quiet_vtk():
    """VTK's reports on a file it cannot read (logged and warned by pyvista, many lines) kept off
    stderr: the reader's failure is the study file's refused key, one line."""
    previous = logging.root.manager.disable
    logging.disable(logging.CRITICAL)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield
    finally:
        logging.disable(previous)


def is_closed(path: str) -> bool:
    from hybmss.voxelize import clean_surface, is_closed as closed

    return closed(clean_surface(*read_surface(path))[1])


def read_image(path: str, spacing=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Integer image, its spacing (given, else the file's) and origin, from .npy or .vti."""
    if str(path).lower().endswith(".npy"):
        image = np.load(path, allow_pickle=False)
        return image, np.asarray(spacing, dtype=float), np.zeros(3)
    import pyvista as pv

    with quiet_vtk():
        grid = pv.read(path)
    name = grid.array_names[0]
    values = np.asarray(grid[name])
    dims = np.asarray(grid.dimensions)
    if len(values) != np.prod(dims):
        dims = dims - 1  # cell data
    image = values.reshape(tuple(dims), order="F")
    own = np.asarray(grid.spacing, dtype=float)
    return image, np.asarray(spacing, dtype=float) if spacing is not None else own, np.asarray(grid.origin)


def pyvista_example(name: str) -> str:
    from pyvista import examples

    return os.path.join(os.path.dirname(examples.__file__), f"{name}.ply")


def read_source(t: Table) -> tuple[BodySource | None, str]:
    """The body's source from table ``body`` (None for an ``experiment`` body) and its kind."""
    given = [k for k in SOURCES if t.has(k)]
    source_typo(t)
    if len(given) != 1:
        raise t.error("box" if not given else given[1], t.data.get(given[1]) if len(given) > 1 else "(missing)",
                      f"exactly one body source: {', '.join(SOURCES)}")
    kind = given[0]
    if kind == "experiment":
        return None, kind
    origin = t.numbers("origin", 3)
    scale = t.number("scale", 1.0, lo=0.0, lo_open=True)
    if kind == "box":
        size = t.numbers("box", 3, lo=0.0, lo_open=True)
        return BodySource("box", size=tuple(size), origin=_tuple(origin)), kind
    if kind == "mask":
        path = t.file_path("mask", MASK_SUFFIXES)
        spacing = t.numbers("spacing", 3, lo=0.0, lo_open=True, required=path.suffix == ".npy")
        labels = t.raw("labels")
        if labels is not None and (not isinstance(labels, list) or not labels or not all(
                isinstance(v, int) and not isinstance(v, bool) and v != 0 for v in labels)):
            raise t.error("labels", labels, "a non-empty list of non-zero integer labels")
        src = BodySource("mask", path=str(path), spacing=_tuple(spacing), labels=tuple(labels or ()) or None,
                         origin=_tuple(origin))
        _check_image(t, src)
        return src, kind
    if kind == "mesh":
        path = str(t.file_path("mesh", MESH_SUFFIXES))
    else:
        name = t.text("pyvista", choices=PYVISTA_SURFACES)
        path = pyvista_example(name)
    _check_closed(t, kind, path)
    return BodySource(kind, path=path, scale=scale, origin=_tuple(origin)), kind


def source_typo(t: Table) -> None:
    """Refuse an unknown key of [body] close to a source (``bxo``) when no source is given, or
    close to ``experiment`` (an experiment body has a ``mesh`` list too), naming it, before the
    rest of the body is read as another kind's."""
    sourced = any(t.has(k) for k in SOURCES)
    for k in t.data:
        hint = close(k, SOURCES)
        if k not in SOURCES and k not in BODY_KEYS and hint and (not sourced or close(k, ["experiment"])):
            raise t.error(k, t.data[k], f"not a key of [body]; a body source is one of {', '.join(SOURCES)}{hint}")


def _tuple(v):
    return None if v is None else tuple(v)


def _check_closed(t: Table, key: str, path: str) -> None:
    try:
        closed = is_closed(path)
    except Exception as exc:  # noqa: BLE001 - an unreadable file is a refused key
        raise t.error(key, t.data[key], f"a surface mesh pyvista can read ({type(exc).__name__})") from None
    if not closed:
        raise t.error(key, t.data[key], "a closed surface (every edge shared by two triangles)")


def _check_image(t: Table, src: BodySource) -> None:
    try:
        image, spacing, _ = read_image(src.path, src.spacing)
    except Exception as exc:  # noqa: BLE001 - an unreadable file is a refused key
        raise t.error("mask", t.data["mask"], f"a 3D integer image (.npy or .vti) ({type(exc).__name__})") from None
    if image.ndim != 3 or not (np.issubdtype(image.dtype, np.integer) or image.dtype == bool):
        raise t.error("mask", t.data["mask"], f"a 3D integer or boolean image (got {image.ndim}D {image.dtype})")
    if src.labels and not np.isin(src.labels, image).all():
        missing = sorted(set(src.labels) - set(np.unique(image).tolist()))
        raise t.error("labels", list(src.labels), f"labels present in the image (missing {missing})")
    if image.size == 0 or not np.any(image):
        raise t.error("mask", t.data["mask"], f"an image with voxels in the body (shape {list(image.shape)}, "
                      "none non-zero)")


def cell_sizes(t: Table, src: BodySource) -> list[float]:
    """The cell sizes, coarse to fine; for a box each must divide every edge."""
    sizes = t.numbers("cell_sizes", required=True, lo=0.0, lo_open=True)
    if sorted(sizes, reverse=True) != sizes or len(set(sizes)) != len(sizes):
        raise t.error("cell_sizes", sizes, "distinct cell sizes, coarse to fine (decreasing)")
    if src is not None and src.kind == "mask":
        image, spacing, _ = read_image(src.path, src.spacing)
        check_extent(t, sizes, image.shape, spacing)
    if src is not None and src.kind == "box":
        for le in sizes:
            n = np.asarray(src.size) / le
            if np.any(np.abs(n - np.round(n)) > 1e-6 * n) or np.any(np.round(n) < 1):
                raise t.error("cell_sizes", sizes, f"cell sizes that divide every box edge {list(src.size)} "
                              f"({le:g} does not)")
    return sizes


def folder_of(path) -> Path:
    return Path(path).resolve().parent


def body_checks(t: Table, src: BodySource, sizes, voxels) -> None:
    """The voxel body is the body the file gave (:mod:`studies.study.checks`): a surface that does
    not cross itself, and at every cell size a voxel volume within the shell around the source's
    volume (a surface's enclosed volume, a mask's voxels)."""
    from hybmss.voxelize import clean_surface

    for vox in voxels:
        check_digits(t, "origin" if t.has("origin") else src.kind, vox)
    if src.kind == "box":
        return
    if src.kind == "mask":
        image, spacing, _ = read_image(src.path, src.spacing)
        keep = np.isin(image, src.labels) if src.labels else image != 0
        volume, area = mask_measures(keep, spacing)
        h = float(np.max(spacing))
    else:
        vertices, triangles = clean_surface(*read_surface(src.path, src.scale))
        check_winding(t, src.kind, vertices, triangles, min(sizes))
        (volume, area), h = surface_measures(vertices, triangles), 0.0
    for vox in voxels:
        check_volume(t, sizes, vox, volume, area, h)


def grid_shape(source, le: float) -> tuple[int, int, int]:
    """The grid of cells of edge ``le`` that holds the body of ``source`` (before it is cropped)."""
    if source.kind == "box":
        return tuple(int(round(s / le)) for s in source.size)
    if source.kind == "mask":
        image, spacing, _ = read_image(source.path, source.spacing)
        extent = np.asarray(image.shape) * spacing
        return tuple(int(max(1, math.floor(e / le + 1e-9))) for e in extent)
    vertices, _ = read_surface(source.path, source.scale)
    extent = vertices.max(axis=0) - vertices.min(axis=0)
    return tuple(int(max(1, math.ceil(e / le - 1e-9))) for e in extent)
