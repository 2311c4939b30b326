"""Supports and tractions of a load case: their regions (a bounding-box face, a box, a face
restricted to a box, a mask label, a surface patch) and motions, read from the file as plain
data and turned into :class:`hybmss.scene.Plate` and :class:`hybmss.scene.Load` per resolution."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from hybmss.scene import Load, Motion, Plate, Region

from studies.study.keys import Table, close, is_number

FACES = tuple(a + s for a in "xyz" for s in "-+")
MOTIONS = ("clamped", "slide", "translate", "rotate")
PATCH_ANGLE_DEG = 30.0
"""A patch takes the surface faces whose outward normal is within this angle of its normal."""


@dataclass(frozen=True)
class RegionSpec:
    """A region as the file gives it: ``face``, ``box`` (two corners), ``label`` or ``patch``
    (normal, point, radius)."""

    face: str | None = None
    box: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    label: int | None = None
    patch: tuple[float, ...] | None = None

    def region(self, labels: np.ndarray) -> Region:
        """The :class:`Region` on a grid whose cell labels are ``labels``."""
        lo, hi = self.box if self.box else (None, None)
        cells = None
        if self.label is not None:
            cells = Region.of_cells(labels == self.label).cells
        patch = None if self.patch is None else (*self.patch, PATCH_ANGLE_DEG)
        return Region(self.face, lo, hi, cells, patch)


def read_region(t: Table, name: str, has_labels: bool) -> RegionSpec:
    value = t.raw(name, required=True)
    if isinstance(value, str):
        if value not in FACES:
            raise t.error(name, value, f"a bounding-box face ({', '.join(FACES)}) or a table with face, box, "
                          f"label or patch{close(value, FACES)}")
        return RegionSpec(face=value)
    r = t.sub(name)
    face = r.text("face", choices=FACES)
    box = r.raw("box")
    if box is not None:
        if not (isinstance(box, list) and len(box) == 2 and all(
                isinstance(c, list) and len(c) == 3 and all(is_number(v) for v in c) for c in box)):
            raise r.error("box", box, "two corners [[x0, y0, z0], [x1, y1, z1]] (m)")
        if any(a > b for a, b in zip(*box)):
            raise r.error("box", box, "corners with x0 <= x1, y0 <= y1, z0 <= z1")
        box = (tuple(map(float, box[0])), tuple(map(float, box[1])))
    label = r.raw("label")
    if label is not None:
        if not has_labels:
            raise r.error("label", label, "a label region needs a mask body ([body] mask = ...)")
        if not isinstance(label, int) or isinstance(label, bool) or label == 0:
            raise r.error("label", label, "a non-zero integer label of the mask")
    patch = _patch(r)
    r.done()
    if face is None and box is None and label is None and patch is None:
        raise t.error(name, value, "a region: a face, a box, a label or a patch")
    return RegionSpec(face, box, label, patch)


def _patch(r: Table):
    p = r.sub("patch")
    if p is None:
        return None
    normal = p.numbers("normal", 3, required=True)
    if not any(normal):
        raise p.error("normal", normal, "a non-zero vector")
    point = p.numbers("point", 3, required=True)
    radius = p.number("radius", required=True, lo=0.0, lo_open=True)
    p.done()
    return (*normal, *point, radius)


@dataclass(frozen=True)
class SupportSpec:
    name: str
    region: RegionSpec
    motion: Motion

    def plate(self, labels: np.ndarray) -> Plate:
        return Plate(self.name, self.region.region(labels), self.motion)


@dataclass(frozen=True)
class TractionSpec:
    region: RegionSpec
    traction: tuple[float, float, float]

    def load(self, labels: np.ndarray) -> Load:
        return Load(self.region.region(labels), self.traction)


def read_support(t: Table, has_labels: bool) -> SupportSpec:
    name = t.text("name", required=True)
    if not re.fullmatch(r"[ -~]*[!-~][ -~]*", name):
        raise t.error("name", name, "a name of printable ASCII characters (it names table columns)")
    region = read_region(t, "region", has_labels)
    kind = t.text("motion", "clamped", choices=MOTIONS)
    displacement = t.numbers("displacement", 3, default=[0.0, 0.0, 0.0])
    comps = t.raw("components")
    if kind == "slide":
        if not (isinstance(comps, list) and comps and all(c in ("x", "y", "z") for c in comps)
                and len(set(comps)) == len(comps)):
            raise t.error("components", comps, 'a non-empty list of distinct components ("x", "y", "z")')
    elif comps is not None:
        raise t.error("components", comps, "only a slide support takes components")
    rotate = {k: t.raw(k) for k in ("angle_deg", "axis", "center")}
    if kind == "rotate":
        angle = t.number("angle_deg", required=True, lo=-180.0, hi=180.0, lo_open=True, hi_open=True)
        axis = t.numbers("axis", 3, default=[0.0, 0.0, 1.0])
        if not any(axis):
            raise t.error("axis", axis, "a non-zero vector")
        center = t.numbers("center", 3)
        motion = Motion("rotate", tuple(displacement), math.radians(angle), tuple(axis),
                        None if center is None else tuple(center))
    else:
        extra = [k for k, v in rotate.items() if v is not None]
        if extra:
            raise t.error(extra[0], rotate[extra[0]], "only a rotate support takes angle_deg, axis and center")
        if kind == "clamped" and any(displacement):
            raise t.error("displacement", displacement, "none for a clamped support (use translate)")
        motion = Motion(kind, tuple(displacement),
                        components=tuple("xyz".index(c) for c in comps) if kind == "slide" else (0, 1, 2))
    t.done()
    return SupportSpec(name, region, motion)


def read_traction(t: Table, has_labels: bool) -> TractionSpec:
    region = read_region(t, "region", has_labels)
    traction = t.numbers("traction", 3, required=True)
    t.done()
    return TractionSpec(region, tuple(traction))


def rigid_modes(X: np.ndarray) -> np.ndarray:
    """The six rigid motions (3 translations, 3 small rotations about the centroid) at points
    ``X``: array (n, 3, 6)."""
    c = X - X.mean(axis=0)
    modes = np.zeros((len(X), 3, 6))
    for k in range(3):
        modes[:, k, k] = 1.0
    for k in range(3):  # rotation about axis k: e_k × (X − c)
        e = np.zeros(3)
        e[k] = 1.0
        modes[:, :, 3 + k] = np.cross(e, c)
    return modes


def held_modes(X: np.ndarray, selections: list[tuple[np.ndarray, tuple[int, ...]]]) -> int:
    """How many of the six rigid motions of the points ``X`` the supports stop: the rank of the
    rigid modes restricted to each support's nodes (a boolean row selection) and prescribed
    components.  Six: the body cannot move as a rigid body."""
    if not len(X):
        return 0
    modes = rigid_modes(X)
    rows = [modes[sel][:, list(comps), :].reshape(-1, 6) for sel, comps in selections if sel.any()]
    if not rows:
        return 0
    A = np.concatenate(rows)
    scale = np.abs(X - X.mean(axis=0)).max() or 1.0
    A[:, 3:] /= scale
    return int(np.linalg.matrix_rank(A, tol=1e-9 * np.abs(A).max()))
