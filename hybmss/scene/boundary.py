"""Boundary conditions of a scene: prescribed motions, the regions that select particles, the
plates that move them and the dead surface loads.

A motion prescribes ``u(X, s)`` at load factor s ∈ [0, 1]: ``0`` (clamped), ``s d`` (translate,
slide on its components), ``R(s θ, a)(X − c) + c − X + s d`` (rotate, Rodrigues' R) or
``s (H (X − c) + d)`` (affine).  A load is a uniform traction ``t`` on the selected surface faces
(total force ``t × area``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .body import Body
from .checks import SceneTypeError, _finite, _of_type, _typename, _vec3

MOTIONS = ("clamped", "translate", "rotate", "slide", "affine")


@dataclass(frozen=True)
class Motion:
    """Prescribed motion of a plate's particles, as a function of the load factor s ∈ [0, 1].

    - ``clamped``: u = 0 in all components.
    - ``translate``: u = s · ``displacement`` in all components.
    - ``rotate``: rigid rotation by s · ``angle`` (rad) about ``axis`` through ``center``
      (``None``: the plate's reference centroid), plus s · ``displacement``; all components.
      The rotation is exact (finite), not linearized.
    - ``slide``: only the ``components`` listed are prescribed, to s · ``displacement``; the
      others are free (a frictionless plate).
    - ``affine``: u = s · (``gradient`` · (X − ``center``) + ``displacement``), all components;
      ``gradient`` is the 3×3 displacement gradient, row-major (``center`` None: the origin).
      Homogeneous deformations (patch tests, simple shear) are imposed this way.
    """

    kind: str = "clamped"
    displacement: tuple[float, float, float] = (0.0, 0.0, 0.0)
    angle: float = 0.0
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    center: tuple[float, float, float] | None = None
    components: tuple[int, ...] = (0, 1, 2)
    gradient: tuple[float, ...] | None = None

    def __post_init__(self):
        if not isinstance(self.kind, str):
            raise SceneTypeError(f"motion kind must be one of {', '.join(MOTIONS)} (a string); got {self.kind!r} "
                                 f"({_typename(self.kind)})")
        if self.gradient is not None:
            if isinstance(self.gradient, (str, bytes)):
                raise SceneTypeError(f"gradient must be 9 finite numbers (3x3 row-major), got {self.gradient!r}")
            try:
                g = np.asarray(self.gradient, dtype=float).reshape(-1)
            except (TypeError, ValueError):
                raise SceneTypeError(f"gradient must be 9 finite numbers (3x3 row-major), got {self.gradient!r}") \
                    from None
            if g.shape != (9,) or not np.all(np.isfinite(g)):
                raise ValueError(f"gradient must be 9 finite numbers (3x3 row-major), got {self.gradient!r}")
            object.__setattr__(self, "gradient", tuple(float(v) for v in g))
        elif self.kind == "affine":
            raise ValueError("an affine motion needs a gradient (3x3 displacement gradient)")
        if self.kind not in MOTIONS:
            raise ValueError(f"motion kind must be one of {', '.join(MOTIONS)}; got {self.kind!r}")
        object.__setattr__(self, "displacement", _vec3("displacement", self.displacement))
        object.__setattr__(self, "angle", _finite("angle", self.angle))
        axis = np.asarray(_vec3("axis", self.axis))
        if np.linalg.norm(axis) == 0:
            raise ValueError("axis must be a non-zero vector")
        object.__setattr__(self, "axis", tuple(float(a) for a in axis / np.linalg.norm(axis)))
        if self.center is not None:
            object.__setattr__(self, "center", _vec3("center", self.center))
        raw = self.components
        if isinstance(raw, (str, bytes)) or not hasattr(raw, "__iter__"):
            raise SceneTypeError(f"components must be a non-empty subset of (0, 1, 2) (integers), got {raw!r}")
        raw = tuple(raw)
        if not all(isinstance(c, (int, float, np.integer, np.floating)) and not isinstance(c, bool)
                   and float(c).is_integer() for c in raw):
            raise SceneTypeError(f"components must be a non-empty subset of (0, 1, 2) (integers), got {raw!r}")
        comps = tuple(sorted(set(int(c) for c in raw)))
        if not comps or any(c not in (0, 1, 2) for c in comps):
            raise ValueError(f"components must be a non-empty subset of (0, 1, 2), got {self.components!r}")
        if self.kind != "slide":
            comps = (0, 1, 2)
        object.__setattr__(self, "components", comps)

    @property
    def constrained(self) -> np.ndarray:
        """Boolean (3,) mask of prescribed components."""
        m = np.zeros(3, dtype=bool)
        m[list(self.components)] = True
        return m

    def displacement_at(self, X: np.ndarray, s: float = 1.0) -> np.ndarray:
        """Prescribed displacement (n, 3) of reference points ``X`` at load factor ``s``.

        Components that are not prescribed (``slide``) are returned as 0.
        """
        X = np.asarray(X, dtype=float).reshape(-1, 3)
        u = np.zeros_like(X)
        d = s * np.asarray(self.displacement)
        if self.kind == "clamped":
            return u
        if self.kind in ("translate", "slide"):
            u[:] = d
            if self.kind == "slide":
                u[:, ~self.constrained] = 0.0
            return u
        if self.kind == "affine":
            c = np.asarray(self.center) if self.center is not None else np.zeros(3)
            Hg = np.asarray(self.gradient).reshape(3, 3)
            return s * ((X - c) @ Hg.T) + d
        # rotate
        c = np.asarray(self.center) if self.center is not None else X.mean(axis=0)
        R = rotation_matrix(self.axis, s * self.angle)
        return (X - c) @ R.T + c - X + d


def rotation_matrix(axis, angle: float) -> np.ndarray:
    """Rodrigues' rotation matrix for a unit ``axis`` and ``angle`` (rad)."""
    k = np.asarray(axis, dtype=float)
    k = k / np.linalg.norm(k)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * (K @ K)


REGION_EXTRAS = ("cells", "patch")
"""Region fields added after the first ones: left out of a scene's JSON form (and so of its digest)
when unset, so the digests of scenes whose regions are faces and boxes do not change."""


@dataclass(frozen=True)
class Region:
    """Particles selected by reference position.

    ``face`` selects a face of the body's bounding box, e.g. ``"z+"`` (top), ``"z-"``
    (bottom), ``"x-"``.  ``lo``/``hi`` additionally restrict to a box (inclusive, with a tolerance
    of 1e-9 le).  With ``face=None`` only the box is used.

    ``cells`` (hex of the packed C-ordered boolean mask over the body's grid, as
    :attr:`Body.mask_bits`) selects the points of the closed boxes of those cells: the nodes of
    cells with one label of a segmentation.  ``patch`` = ``(nx, ny, nz, px, py, pz, radius,
    angle_deg)`` selects the points on the body's surface faces whose outward normal lies within
    ``angle_deg`` of ``n`` and that lie within ``radius`` of ``p``.  Both restrict whatever else is
    given, and both work on any point (lattice nodes, FEM nodes, face centres).
    """

    face: str | None = None
    lo: tuple[float, float, float] | None = None
    hi: tuple[float, float, float] | None = None
    cells: str | None = None
    patch: tuple[float, ...] | None = None

    def __post_init__(self):
        if self.face is not None and not isinstance(self.face, str):
            raise SceneTypeError(f"face must be one of x-, x+, y-, y+, z-, z+ (a string) or None; got {self.face!r} "
                                 f"({_typename(self.face)})")
        if self.face is not None and self.face not in {a + s for a in "xyz" for s in "+-"}:
            raise ValueError(f"face must be one of x-, x+, y-, y+, z-, z+; got {self.face!r}")
        if self.face is None and self.lo is None and self.hi is None and self.cells is None \
                and self.patch is None:
            raise ValueError("a region needs a face, a box (lo, hi), cells or a surface patch")
        if self.lo is not None:
            object.__setattr__(self, "lo", _vec3("lo", self.lo))
        if self.hi is not None:
            object.__setattr__(self, "hi", _vec3("hi", self.hi))
        if self.cells is not None:
            try:
                bytes.fromhex(self.cells)
            except (TypeError, ValueError):
                raise ValueError("cells must be the hex text of a packed cell mask") from None
        if self.patch is not None:
            object.__setattr__(self, "patch", _patch(self.patch))

    def select(self, X: np.ndarray, body: Body) -> np.ndarray:
        """Boolean mask over reference points ``X`` (n, 3) of ``body`` in this region."""
        X = np.asarray(X, dtype=float).reshape(-1, 3)
        tol = 1e-9 * body.le
        sel = np.ones(len(X), dtype=bool)
        if self.face is not None:
            ax = "xyz".index(self.face[0])
            lo, hi = body.bounds
            target = hi[ax] if self.face[1] == "+" else lo[ax]
            sel &= np.abs(X[:, ax] - target) <= tol
        if self.lo is not None:
            sel &= np.all(X >= np.asarray(self.lo) - tol, axis=1)
        if self.hi is not None:
            sel &= np.all(X <= np.asarray(self.hi) + tol, axis=1)
        if self.cells is not None:
            sel &= _in_cells(X, body, self.cell_mask(body))
        if self.patch is not None:
            sel &= _on_patch(X, body, self.patch)
        return sel

    def cell_mask(self, body: Body) -> np.ndarray:
        """The boolean cell mask of ``cells`` over ``body``'s grid."""
        n = int(np.prod(body.shape))
        bits = np.frombuffer(bytes.fromhex(self.cells), dtype=np.uint8)
        if len(bits) != (n + 7) // 8:
            raise ValueError(f"cells holds {8 * len(bits)} bits for a grid of {n} cells")
        return np.unpackbits(bits, count=n).astype(bool).reshape(body.shape)

    @staticmethod
    def of_cells(mask) -> "Region":
        """The region of the closed boxes of the cells of a boolean ``mask`` over a body's grid."""
        return Region(cells=np.packbits(np.asarray(mask, dtype=bool).ravel()).tobytes().hex())


def _patch(value) -> tuple[float, ...]:
    arr = np.asarray(value, dtype=float).reshape(-1)
    if arr.shape != (8,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"patch must be 8 finite numbers (normal, point, radius, angle_deg), got {value!r}")
    if np.linalg.norm(arr[:3]) == 0 or arr[6] <= 0 or not 0 < arr[7] < 180:
        raise ValueError(f"patch needs a non-zero normal, radius > 0 and angle_deg in (0, 180), got {value!r}")
    return tuple(float(v) for v in arr)


def _grid_coords(X: np.ndarray, body: Body) -> tuple[np.ndarray, float]:
    return (X - np.asarray(body.origin)) / body.le, 1e-9


def _lookup(mask: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """``mask[idx]`` for integer rows ``idx`` (n, 3), False outside the grid."""
    inside = np.all((idx >= 0) & (idx < np.asarray(mask.shape)), axis=1)
    out = np.zeros(len(idx), dtype=bool)
    i = idx[inside]
    out[inside] = mask[i[:, 0], i[:, 1], i[:, 2]]
    return out


def _in_cells(X: np.ndarray, body: Body, mask: np.ndarray) -> np.ndarray:
    """Points in the closed box of at least one cell of ``mask`` (a point on a shared face or
    corner is in each of the boxes that touch it)."""
    t, tol = _grid_coords(X, body)
    lo = np.ceil(t - 1 - tol).astype(np.int64)
    hi = np.floor(t + tol).astype(np.int64)
    out = np.zeros(len(X), dtype=bool)
    for pick in np.ndindex(2, 2, 2):
        idx = np.where(np.asarray(pick, dtype=bool), hi, lo)
        out |= _lookup(mask, idx)
    return out


def _on_patch(X: np.ndarray, body: Body, patch: tuple[float, ...]) -> np.ndarray:
    """Points within ``radius`` of the patch's point that lie on a surface face of ``body`` whose
    outward normal is within ``angle_deg`` of the patch's normal."""
    n = np.asarray(patch[:3]) / np.linalg.norm(patch[:3])
    near = np.linalg.norm(X - np.asarray(patch[3:6]), axis=1) <= patch[6] * (1 + 1e-9)
    t, tol = _grid_coords(X, body)
    ijk, axes, sides = body.boundary_faces()
    out = np.zeros(len(X), dtype=bool)
    for axis in range(3):
        for side in (0, 1):
            if math.degrees(math.acos(np.clip((2 * side - 1) * n[axis], -1, 1))) > patch[7] + 1e-9:
                continue
            pick = (axes == axis) & (sides == side)
            faces = np.zeros(body.shape, dtype=bool)
            faces[tuple(ijk[pick].T)] = True  # the cells whose `side` face normal to `axis` is on the surface
            plane = np.round(t[:, axis])
            on = np.abs(t[:, axis] - plane) <= tol
            lo = np.ceil(t - 1 - tol).astype(np.int64)
            hi = np.floor(t + tol).astype(np.int64)
            for pick2 in np.ndindex(2, 2):
                idx = np.where(np.insert(np.asarray(pick2, dtype=bool), axis, False), hi, lo)
                idx[:, axis] = plane.astype(np.int64) - side
                out |= on & _lookup(faces, idx)
    return out & near


@dataclass(frozen=True)
class Plate:
    """A named rigid plate: the particles of ``region`` follow ``motion``.

    ``Plate("bottom", "z-")`` is ``Plate("bottom", Region(face="z-"))`` and
    ``Plate("top", "z+", "clamped")`` gives the motion by its kind (the same scene and digest);
    any other type is refused here, not at the solve."""

    name: str
    region: Region
    motion: Motion = field(default_factory=Motion)

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise SceneTypeError(f"plate name must be a non-empty string, got {self.name!r}")
        object.__setattr__(self, "region", _of_type(f"plate {self.name!r}: region", self.region, Region,
                                                     lambda face: Region(face=face)))
        object.__setattr__(self, "motion", _of_type(f"plate {self.name!r}: motion", self.motion, Motion, Motion))


@dataclass(frozen=True)
class Load:
    """A uniform dead traction ``traction`` (Pa: force per unit reference area, fixed direction)
    on the body's surface faces whose centre lies in ``region``.

    ``region`` may be a face name (``Load("x+", (0, 0, -5))``).
    The mass-spring system gets the consistent load of bilinear faces (each selected cell face
    gives ``traction · le²/4`` to each of its 4 vertices); the FEM integrates ``∫ t · v dA``
    over the same faces.  The total force is ``traction × selected area``.
    """

    region: Region
    traction: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        object.__setattr__(self, "region", _of_type("load region", self.region, Region, lambda face: Region(face=face)))
        object.__setattr__(self, "traction", _vec3("traction", self.traction))

    def faces(self, body: Body) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The selected surface faces ``(cell_ijk, axis, side)`` of ``body``."""
        ijk, axis, side = body.boundary_faces()
        centre = ijk + 0.5
        centre[np.arange(len(ijk)), axis] += side - 0.5
        sel = self.region.select(np.asarray(body.origin) + centre * body.le, body)
        return ijk[sel], axis[sel], side[sel]
