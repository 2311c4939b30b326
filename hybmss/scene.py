"""Scenes as plain, frozen data.

A :class:`Scene` says everything both solvers (the mass-spring system and the FEM reference)
need: the body (a set of cubic cells of edge ``le`` on a regular grid), the material
(E, ν, ρ), the model (by name, with its parameters), the plates (particle sets with a prescribed motion),
gravity and damping.  It holds no arrays that could be mutated: a voxel mask is stored as packed
bytes, so a scene is hashable and has a stable :meth:`Scene.digest`.

Variants of a scene come from :func:`dataclasses.replace`; every constructor validates its
values and raises :class:`ValueError` naming the parameter and its allowed range.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import dataclass, field

import numpy as np

from . import models as registry

MOTIONS = ("clamped", "translate", "rotate", "slide", "affine")


class SceneTypeError(TypeError, ValueError):
    """A scene field given a value of the wrong type (a ``TypeError``, and a ``ValueError`` like
    every other refusal of the constructors, so that one ``except ValueError`` catches both)."""


def _typename(value) -> str:
    return type(value).__name__


def _finite(name: str, value: float) -> float:
    if isinstance(value, (str, bytes, bool)) or value is None:
        raise SceneTypeError(f"{name} must be a finite number, got {value!r} ({_typename(value)})")
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise SceneTypeError(f"{name} must be a finite number, got {value!r} ({_typename(value)})") from None
    if not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return value


def _vec3(name: str, value) -> tuple[float, float, float]:
    if isinstance(value, (str, bytes)) or value is None:
        raise SceneTypeError(f"{name} must be 3 finite numbers, got {value!r} ({_typename(value)})")
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise SceneTypeError(f"{name} must be 3 finite numbers, got {value!r}") from None
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def _of_type(name: str, value, cls, convert=None):
    """``value`` if it is a ``cls``; ``convert(value)`` for a string when ``convert`` is given (a
    face name for a region, a kind for a motion); else :class:`SceneTypeError` naming ``name``."""
    if isinstance(value, cls):
        return value
    if convert is not None and isinstance(value, str):
        return convert(value)
    also = " or its name (a string)" if convert is not None else ""
    raise SceneTypeError(f"{name} must be a {cls.__name__}{also}, got {value!r} ({_typename(value)})")


# --------------------------------------------------------------------------------------------
# Body
# --------------------------------------------------------------------------------------------
def pieces(mask) -> tuple[np.ndarray, np.ndarray]:
    """The face-connected pieces of a voxel ``mask`` (cells sharing a face belong to one piece;
    cells touching along an edge or at a corner only do not: a hinge carries no load in a
    lattice of cubes): ``(labels, sizes)``, ``labels`` of the mask's shape (0 outside, ``k`` in
    piece ``k``), numbered by decreasing size, and ``sizes[k − 1]`` the cells of piece ``k``.
    A caller checking that each piece is supported selects the particles of ``labels == k``."""
    from scipy import ndimage

    mask = np.asarray(mask, dtype=bool)
    labels, n = ndimage.label(mask)  # the default structure of ndimage.label: face neighbours
    if n == 0:
        return labels, np.zeros(0, dtype=np.int64)
    sizes = np.bincount(labels.ravel(), minlength=n + 1)[1:]
    order = np.argsort(-sizes, kind="stable")  # old label order[k] + 1 becomes k + 1
    relabel = np.zeros(n + 1, dtype=labels.dtype)
    relabel[order + 1] = np.arange(1, n + 1)
    return relabel[labels], sizes[order].astype(np.int64)


def _pieces_text(sizes) -> str:
    shown = ", ".join(str(int(v)) for v in sizes[:6]) + (", ..." if len(sizes) > 6 else "")
    return f"{len(sizes)} pieces of {shown} cells"


@dataclass(frozen=True)
class Body:
    """A set of cubic cells of edge ``le`` on an ``nx × ny × nz`` grid.

    ``mask_bits`` is ``None`` for a full box, else the C-ordered boolean mask of active cells
    packed with :func:`numpy.packbits`.  Use :meth:`box` and :meth:`from_mask` to build one.
    """

    shape: tuple[int, int, int]
    le: float
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mask_bits: bytes | None = None

    def __post_init__(self):
        shape = tuple(int(n) for n in self.shape)
        if len(shape) != 3 or min(shape) < 1:
            raise ValueError(f"body shape must be 3 positive cell counts (nx, ny, nz), got {self.shape!r}")
        object.__setattr__(self, "shape", shape)
        le = _finite("le", self.le)
        if le <= 0:
            raise ValueError(f"le (cell edge) must be > 0, got {le}")
        object.__setattr__(self, "le", le)
        object.__setattr__(self, "origin", _vec3("origin", self.origin))
        if self.mask_bits is not None:
            mask = self.mask
            if not mask.any():
                raise ValueError("body is empty: the voxel mask has no active cell (need at least 1)")

    @classmethod
    def box(cls, nx: int, ny: int, nz: int, le: float, origin=(0.0, 0.0, 0.0)) -> "Body":
        """A full box of ``nx × ny × nz`` cells."""
        for name, n in (("nx", nx), ("ny", ny), ("nz", nz)):
            if int(n) < 1:
                raise ValueError(f"{name} must be >= 1 (body cannot be empty), got {n}")
        return cls((nx, ny, nz), le, origin)

    @classmethod
    def from_mask(cls, mask, le: float, origin=(0.0, 0.0, 0.0)) -> "Body":
        """A body from a boolean voxel array ``mask[i, j, k]`` (True = cell present), refused
        (``ValueError``) when its cells fall apart into several face-connected pieces
        (:func:`pieces`): no plate or load of one piece would hold another."""
        mask = np.asarray(mask, dtype=bool)
        if mask.ndim != 3 or mask.size == 0:
            raise ValueError(f"mask must be a non-empty 3D boolean array, got shape {mask.shape}")
        if not mask.any():
            raise ValueError("body is empty: the voxel mask has no active cell (need at least 1)")
        if mask.all():
            return cls(mask.shape, le, origin)
        _, sizes = pieces(mask)
        if len(sizes) > 1:
            raise ValueError(f"body falls apart into {_pieces_text(sizes)} (face-connected cells); "
                             "allowed: one piece (join them, or make each its own body)")
        return cls(mask.shape, le, origin, np.packbits(mask.ravel()).tobytes())

    @property
    def mask(self) -> np.ndarray:
        """Boolean array of active cells, shape ``(nx, ny, nz)``."""
        n = int(np.prod(self.shape))
        if self.mask_bits is None:
            return np.ones(self.shape, dtype=bool)
        bits = np.unpackbits(np.frombuffer(self.mask_bits, dtype=np.uint8), count=n)
        return bits.astype(bool).reshape(self.shape)

    @property
    def is_box(self) -> bool:
        return self.mask_bits is None

    @property
    def n_cells(self) -> int:
        return int(self.mask.sum())

    @property
    def cell_volume(self) -> float:
        return self.le**3

    @property
    def volume(self) -> float:
        return self.n_cells * self.cell_volume

    @property
    def size(self) -> tuple[float, float, float]:
        """Bounding-box edge lengths (m)."""
        return tuple(n * self.le for n in self.shape)  # type: ignore[return-value]

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = np.asarray(self.origin)
        return lo, lo + np.asarray(self.shape) * self.le

    def boundary_faces(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cell faces on the body's surface (no active cell across): ``(cell_ijk, axis, side)``,
        each (k,) or (k, 3); the face is the ``side`` (0: −, 1: +) face normal to ``axis``."""
        mask = self.mask
        pad = np.pad(mask, 1)
        ijk, axes, sides = [], [], []
        for axis in range(3):
            for side in (0, 1):
                shift = [slice(1, -1)] * 3
                shift[axis] = slice(2, None) if side else slice(0, -2)
                found = np.argwhere(mask & ~pad[tuple(shift)])
                ijk.append(found)
                axes.append(np.full(len(found), axis))
                sides.append(np.full(len(found), side))
        return (np.concatenate(ijk).astype(np.int64), np.concatenate(axes).astype(np.int64),
                np.concatenate(sides).astype(np.int64))

    def to_dict(self) -> dict:
        d = {"shape": list(self.shape), "le": self.le, "origin": list(self.origin)}
        if self.mask_bits is not None:
            d["mask_hex"] = self.mask_bits.hex()
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "Body":
        bits = bytes.fromhex(d["mask_hex"]) if d.get("mask_hex") else None
        return cls(tuple(d["shape"]), d["le"], tuple(d.get("origin", (0, 0, 0))), bits)


# --------------------------------------------------------------------------------------------
# Material and model
# --------------------------------------------------------------------------------------------
NU_OPEN_RANGE = (-1.0, 0.5)
"""The Poisson ratios of a stable isotropic material, an open interval: ν → −1 loses the bulk
modulus, ν → ½ the shear modulus relative to it.  Every check of ν in the harness, its studies and
its report uses it (:func:`admissible_nu`); the solvers' narrower float64 range is
:data:`NU_RANGE`."""


def admissible_nu(nu: float) -> bool:
    """Whether ``nu`` lies in :data:`NU_OPEN_RANGE` (end points excluded)."""
    lo, hi = NU_OPEN_RANGE
    return lo < nu < hi


NEARLY_INCOMPRESSIBLE_NU = 0.45
"""From this Poisson ratio on a material counts as nearly incompressible: a displacement-only
element locks, so the FEM reference's ``element='auto'`` takes its mixed u–p element, and the
studies' size and cost estimates count that element (:func:`nearly_incompressible`)."""


def nearly_incompressible(nu: float) -> bool:
    """Whether ``nu`` ≥ :data:`NEARLY_INCOMPRESSIBLE_NU`."""
    return nu >= NEARLY_INCOMPRESSIBLE_NU


NU_RANGE = (-0.99, 0.49999)
"""Poisson ratios for which the Newton solvers (static, implicit) reach equilibrium in float64 and
the moduli come out right (tests/verification/test_moduli.py).  Beyond ν = 0.49999 the volume term
(κ > 1.6e4 E) drowns the plate reactions in its round-off; below ν = −0.99 the shear springs
(k > 50 E le) do, and finite-strain terms amplified by G/K make the measured E wrong by more than
1 % at a strain of 1e-4."""


def check_nu(nu: float) -> None:
    """Raise ``ValueError`` for a Poisson ratio outside :data:`NU_RANGE`."""
    lo, hi = NU_RANGE
    if not (lo <= nu <= hi):
        raise ValueError(f"nu={nu!r} is outside [{lo}, {hi}], the range in which the static and implicit "
                         "solvers reach an equilibrium in float64")


@dataclass(frozen=True)
class Material:
    """Isotropic linear-elastic constants: Young's modulus E (Pa), Poisson ratio ν, density ρ."""

    E: float
    nu: float
    rho: float = 1000.0

    def __post_init__(self):
        E = _finite("E", self.E)
        nu = _finite("nu", self.nu)
        rho = _finite("rho", self.rho)
        if E <= 0:
            raise ValueError(f"E (Young's modulus) must be > 0 Pa, got {E}")
        if not admissible_nu(nu):
            lo, hi = NU_OPEN_RANGE
            raise ValueError(f"nu (Poisson ratio) must lie in the open interval ({lo:g}, {hi:g}), got {nu}")
        if rho < 0:
            raise ValueError(f"rho (density) must be >= 0 kg/m^3, got {rho}")
        object.__setattr__(self, "E", E)
        object.__setattr__(self, "nu", nu)
        object.__setattr__(self, "rho", rho)

    @property
    def G(self) -> float:
        """Shear modulus G = E / (2(1+ν))."""
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def lam(self) -> float:
        """Lamé λ = E ν / ((1+ν)(1−2ν))."""
        return self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))

    @property
    def K(self) -> float:
        """Bulk modulus K = E / (3(1−2ν))."""
        return self.E / (3.0 * (1.0 - 2.0 * self.nu))


@dataclass(frozen=True, init=False)
class Model:
    """The model of a scene: its registry ``name`` and its parameters under their own names.

    ``Model("hybmss-fd")``, ``Model("hybmss", A=3.0, e_form=True)``: the parameters are validated
    by the model (:mod:`hybmss.models`) and missing or ``None`` ones take its defaults, so that
    ``to_dict`` (and the scene digest) records every parameter.  ``model.A`` reads a parameter;
    ``model.spec`` is the registered model object (name, style, solvers, calibration, ...).
    Without a name it is the registry's default model (:func:`hybmss.models.default_name`).
    """

    name: str
    params: object

    def __init__(self, name: str | None = None, **params):
        spec = registry.get(registry.default_name() if name is None else name)
        object.__setattr__(self, "name", spec.name)
        object.__setattr__(self, "params", spec.parameters(**params))

    @property
    def spec(self):
        return registry.get(self.name)

    def __getattr__(self, key):
        params = self.__dict__.get("params")
        if params is not None and not key.startswith("_") and hasattr(params, key):
            return getattr(params, key)
        raise AttributeError(f"model {self.__dict__.get('name')!r} has no parameter or attribute {key!r}")

    @property
    def variant(self) -> str:
        """Name of this model and parameter set in tables and legends."""
        return self.spec.variant(self.params)

    @property
    def conservative(self) -> bool:
        return self.spec.conservative

    def to_dict(self) -> dict:
        return {"name": self.name, **dataclasses.asdict(self.params)}

    def replace(self, **kw) -> "Model":
        """A copy with ``kw`` changed; a new ``name`` keeps the parameters that model also has."""
        name = kw.pop("name", self.name)
        keep = registry.get(name).parameter_names()
        carried = {k: v for k, v in dataclasses.asdict(self.params).items() if k in keep} \
            if name != self.name else dataclasses.asdict(self.params)
        if name != self.name:
            # parameters equal to the old model's defaults are not carried: they take the new one's
            defaults = dataclasses.asdict(self.spec.parameters())
            carried = {k: v for k, v in carried.items() if v != defaults.get(k)}
        return Model(name, **{**carried, **kw})

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in dataclasses.asdict(self.params).items())
        return f"Model({self.name!r}{', ' if args else ''}{args})"


# --------------------------------------------------------------------------------------------
# Plates (prescribed-displacement boundary conditions)
# --------------------------------------------------------------------------------------------
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


# --------------------------------------------------------------------------------------------
# Scene
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Scene:
    """Everything a solver needs, as plain data.

    ``gravity`` is the acceleration vector (m/s²).  ``damping`` is the mass-proportional damping
    coefficient c (1/s) of the dynamic solvers: the damping force on particle a is
    ``−c m_a v_a`` (static solves ignore it).
    """

    body: Body
    material: Material
    model: Model = field(default_factory=Model)
    plates: tuple[Plate, ...] = ()
    gravity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    damping: float = 0.0
    name: str = ""
    loads: tuple[Load, ...] = ()
    """Dead surface tractions (:class:`Load`); optional, omitted from :meth:`to_dict` when empty
    so the digests of scenes without loads do not change."""

    def __post_init__(self):
        _of_type("body", self.body, Body)
        _of_type("material", self.material, Material)
        object.__setattr__(self, "model", _of_type("model", self.model, Model, Model))
        if not isinstance(self.name, str):
            raise SceneTypeError(f"scene name must be a string, got {self.name!r} ({_typename(self.name)})")
        for what, cls in (("plates", Plate), ("loads", Load)):
            items = getattr(self, what)
            if isinstance(items, (str, bytes, cls)) or not hasattr(items, "__iter__"):
                raise SceneTypeError(f"{what} must be a sequence of {cls.__name__}, got {items!r}")
            items = tuple(items)
            for i, item in enumerate(items):
                _of_type(f"{what}[{i}]", item, cls)
            object.__setattr__(self, what, items)
        object.__setattr__(self, "gravity", _vec3("gravity", self.gravity))
        damping = _finite("damping", self.damping)
        if damping < 0:
            raise ValueError(f"damping must be >= 0 (1/s), got {damping}")
        object.__setattr__(self, "damping", damping)
        names = [p.name for p in self.plates]
        if len(set(names)) != len(names):
            raise ValueError(f"plate names must be unique, got {names}")

    @property
    def has_gravity(self) -> bool:
        return any(g != 0.0 for g in self.gravity) and self.material.rho > 0

    def to_dict(self) -> dict:
        """JSON-ready nested dict (stable key order)."""
        d = dataclasses.asdict(self)
        d["body"] = self.body.to_dict()
        d["model"] = self.model.to_dict()
        if not self.loads:
            del d["loads"]
        for item in (*d["plates"], *d.get("loads", ())):
            for k in REGION_EXTRAS:
                if item["region"][k] is None:
                    del item["region"][k]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "Scene":
        plates = tuple(
            Plate(
                p["name"],
                Region(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in p["region"].items()}),
                Motion(
                    **{k: (tuple(v) if isinstance(v, list) else v) for k, v in p["motion"].items()}
                ),
            )
            for p in d.get("plates", ())
        )
        return cls(
            body=Body.from_dict(d["body"]),
            material=Material(**d["material"]),
            model=Model(**d["model"]),
            plates=plates,
            gravity=tuple(d.get("gravity", (0, 0, 0))),
            damping=d.get("damping", 0.0),
            name=d.get("name", ""),
            loads=tuple(
                Load(Region(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in ld["region"].items()}),
                     tuple(ld["traction"]))
                for ld in d.get("loads", ())
            ),
        )

    def digest(self) -> str:
        """SHA-256 of the canonical JSON form: equal scenes have equal digests."""
        text = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()

    def with_material(self, **kw) -> "Scene":
        return dataclasses.replace(self, material=dataclasses.replace(self.material, **kw))

    def with_model(self, **kw) -> "Scene":
        return dataclasses.replace(self, model=self.model.replace(**kw))


def parse_mesh(text: str) -> tuple[int, int, int]:
    """Parse ``"10x10x10"`` into ``(10, 10, 10)``."""
    parts = str(text).lower().split("x")
    try:
        dims = tuple(int(p) for p in parts)
    except ValueError:
        raise ValueError(f"mesh must look like NXxNYxNZ (e.g. 10x10x10), got {text!r}") from None
    if len(dims) != 3 or min(dims) < 1:
        raise ValueError(f"mesh must be three positive integers NXxNYxNZ, got {text!r}")
    return dims  # type: ignore[return-value]


# --------------------------------------------------------------------------------------------
# Checking a scene read from a file
# --------------------------------------------------------------------------------------------
def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _numbers(n: int | None, integer: bool = False):
    def ok(v):
        return (isinstance(v, list) and (n is None or len(v) == n) and (n is not None or len(v) > 0)
                and all(_number(x) and (not integer or float(x) == int(x)) for x in v))
    what = f"a list of {n if n is not None else 'one or more'} {'integers' if integer else 'numbers'}"
    return ok, what


_NUMBER = (_number, "a number")
_TEXT = (lambda v: isinstance(v, str), "a string")
_VEC3 = _numbers(3)
_REGION = {"face": (lambda v: v is None or isinstance(v, str), "a face name (x-, ..., z+) or null"),
           "lo": (lambda v: v is None or _VEC3[0](v), "3 numbers or null"),
           "hi": (lambda v: v is None or _VEC3[0](v), "3 numbers or null"),
           "cells": (lambda v: v is None or isinstance(v, str), "hex text or null"),
           "patch": (lambda v: v is None or _numbers(8)[0](v), "8 numbers or null")}
_SCENE_SCHEMA = {
    "body": ({"shape": _numbers(3, integer=True), "le": _NUMBER, "origin": _VEC3, "mask_hex": _TEXT},
             ("shape", "le")),
    "material": ({"E": _NUMBER, "nu": _NUMBER, "rho": _NUMBER}, ("E", "nu")),
    "model": None,  # its name and the model's own parameters (plain values)
    "plates": ([{"name": _TEXT, "region": (_REGION, ()),
                 "motion": ({"kind": _TEXT, "displacement": _VEC3, "angle": _NUMBER, "axis": _VEC3,
                             "center": (lambda v: v is None or _VEC3[0](v), "3 numbers or null"),
                             "components": _numbers(None, integer=True),
                             "gradient": (lambda v: v is None or _numbers(9)[0](v), "9 numbers or null")}, ())},
                ("name", "region", "motion")], ()),
    "gravity": _VEC3,
    "damping": _NUMBER,
    "name": _TEXT,
    "loads": ([{"region": (_REGION, ()), "traction": _VEC3}, ("region", "traction")], ()),
}


def scene_dict_error(d) -> str | None:
    """Why ``d`` is not the JSON form of a scene (:meth:`Scene.to_dict`): the first unknown or
    missing field or value of the wrong type, with its path (``plates[0].motion.angle``); ``None``
    if every field has its type.  A value nested deeper than a scene's fields is a wrong type, so
    the check never recurses further than the schema (a scene's values are checked by the
    constructors)."""
    def walk(value, schema, path):
        if isinstance(schema, tuple) and len(schema) == 2 and isinstance(schema[0], dict):
            fields, required = schema
            if not isinstance(value, dict):
                return f"{path or 'the file'}: expected an object, got {_kind(value)}"
            for k in value:
                if k not in fields:
                    return f"{path + '.' if path else ''}{k}: not a field (allowed: {', '.join(fields)})"
            for k in required:
                if k not in value:
                    return f"missing key {(path + '.' if path else '') + k!r}"
            for k, v in value.items():
                if fields[k] is None:
                    continue
                err = walk(v, fields[k], f"{path + '.' if path else ''}{k}")
                if err:
                    return err
            return None
        if isinstance(schema, tuple) and len(schema) == 2 and isinstance(schema[0], list):
            (item, required), _ = schema[0], schema[1]
            if not isinstance(value, list):
                return f"{path}: expected a list, got {_kind(value)}"
            for i, v in enumerate(value):
                err = walk(v, (item, required), f"{path}[{i}]")
                if err:
                    return err
            return None
        ok, what = schema
        return None if ok(value) else f"{path}: expected {what}, got {_kind(value)}"

    err = walk(d, (_SCENE_SCHEMA, ("body", "material", "model")), "")
    if err:
        return err
    model = d["model"]
    if not isinstance(model, dict) or not isinstance(model.get("name"), str):
        return "model: expected an object with a model name, got " + _kind(model)
    for k, v in model.items():
        if not (v is None or isinstance(v, (str, bool)) or _number(v)):
            return f"model.{k}: expected a number, true/false, a string or null, got {_kind(v)}"
    return None


def _kind(v) -> str:
    if isinstance(v, (dict, list)):
        return f"a JSON {'object' if isinstance(v, dict) else 'list'}"
    return f"{json.dumps(v)[:40]}"


RIGID_MODES = ("translation along x", "translation along y", "translation along z",
               "rotation about x", "rotation about y", "rotation about z")


def _corner_nodes(mask: np.ndarray) -> np.ndarray:
    """Grid indices (n, 3) of the particles of a voxel mask: every corner of an active cell."""
    corners = np.zeros(tuple(n + 1 for n in mask.shape), dtype=bool)
    for di in (0, 1):
        for dj in (0, 1):
            for dk in (0, 1):
                corners[di:di + mask.shape[0], dj:dj + mask.shape[1], dk:dk + mask.shape[2]] |= mask
    return np.argwhere(corners)


def _free_modes(X: np.ndarray, held: np.ndarray, size: float) -> list[str]:
    """The rigid motions of particles ``X`` (n, 3) that the held components ``held`` (n, 3) do
    not prevent: the null space of the rigid modes (3 translations, 3 rotations about the held
    particles' centroid, scaled by ``size``) restricted to the held components.  Returns the
    names of the coordinate modes in it, and for the rest of its dimension how many other
    combinations."""
    rows = np.argwhere(held)
    if len(rows) == 0:
        return list(RIGID_MODES)
    c = X[np.any(held, axis=1)].mean(axis=0)
    r = (X[rows[:, 0]] - c) / size
    comp = rows[:, 1]
    R = np.zeros((len(rows), 6))
    R[np.arange(len(rows)), comp] = 1.0
    for k in range(3):  # (e_k × r)_comp
        e = np.zeros(3)
        e[k] = 1.0
        R[:, 3 + k] = np.cross(e, r)[np.arange(len(rows)), comp]
    sv = np.linalg.svd(R, compute_uv=False)
    tol = 1e-9 * max(1.0, float(sv[0]))
    dim = 6 - int(np.sum(sv > tol))
    if dim == 0:
        return []
    named = [RIGID_MODES[i] for i in range(6) if np.linalg.norm(R[:, i]) <= tol]
    if len(named) < dim:
        n = dim - len(named)
        named.append(f"{n} other combination{'s' if n > 1 else ''} of translation and rotation")
    return named


def free_rigid_modes(scene: Scene) -> list[tuple[int, list[str]]]:
    """The rigid-body motions the plates of ``scene`` do not prevent, per face-connected piece of
    its body (:func:`pieces`): ``[(cells of the piece, [mode names]), ...]`` for the pieces that
    are not held, empty when every piece is.  Rotations are about axes through the held
    particles' centroid (a plate's rotation about any other parallel axis is the same mode plus a
    translation).  A static equilibrium of a body with a free mode is not unique (and under a load
    along it does not exist): the static solver refuses it before any work."""
    body = scene.body
    mask = body.mask
    labels, sizes = pieces(mask) if not body.is_box else (mask.astype(np.int64), np.array([mask.size]))
    out = []
    for k, n_cells in enumerate(sizes, start=1):
        ijk = _corner_nodes(labels == k)
        X = np.asarray(body.origin) + ijk * body.le
        held = np.zeros(X.shape, dtype=bool)
        for p in scene.plates:
            sel = p.region.select(X, body)
            held[np.ix_(np.flatnonzero(sel), np.flatnonzero(p.motion.constrained))] = True
        free = _free_modes(X, held, max(body.size))
        if free:
            out.append((int(n_cells), free))
    return out


def unsupported(scene: Scene) -> str | None:
    """Why ``scene`` cannot have a static equilibrium because its plates leave it free to move as
    a rigid body (:func:`free_rigid_modes`), in one line; ``None`` when every piece is held."""
    free = free_rigid_modes(scene)
    if not free:
        return None
    n_pieces = 1 if scene.body.is_box else len(pieces(scene.body.mask)[1])
    where = []
    for n_cells, modes in free:
        piece = f"the piece of {n_cells} cells" if n_pieces > 1 else "the body"
        where.append(f"{piece} is free in {', '.join(modes)}")
    plates = (f"its plates {', '.join(repr(p.name) for p in scene.plates)} do not hold {'it' if len(where) == 1 else 'them'}"
              if scene.plates else "it has no plate")
    return (f"scene {scene.name or '(unnamed)'} is not supported (rigid-body motion not prevented): "
            f"{'; '.join(where)} ({plates}), so a static equilibrium is not unique or does not exist; allowed: "
            "plates that hold every rigid-body mode, e.g. Plate('base', 'z-', 'clamped'), or slide plates with pins "
            "as the uniaxial test has")


PLATE_PATH_SAMPLES = 65
"""Load factors at which :func:`plates_cross` compares the plates' positions (0 to 1)."""


def plates_cross(scene: Scene) -> str | None:
    """Why the plates of ``scene`` would pass through each other (``None`` if they do not): two
    plates prescribing the same component whose particles lie, at rest, wholly on either side of a
    coordinate plane, and whose prescribed motions bring the first to or past the second at a load
    factor s in [0, 1] (a top plate pushed below a clamped floor: a body compressed through itself,
    which no material law can answer)."""
    body = scene.body
    m = body.mask
    corners = np.zeros(tuple(n + 1 for n in body.shape), dtype=bool)
    for di in (0, 1):
        for dj in (0, 1):
            for dk in (0, 1):
                corners[di:di + m.shape[0], dj:dj + m.shape[1], dk:dk + m.shape[2]] |= m
    X = np.asarray(body.origin) + np.argwhere(corners) * body.le
    held = [(p, X[p.region.select(X, body)]) for p in scene.plates]
    held = [(p, Xp) for p, Xp in held if len(Xp)]
    tol = 1e-9 * body.le
    for a, Xa in held:
        for b, Xb in held:
            if a is b:
                continue
            for k in range(3):
                if not (a.motion.constrained[k] and b.motion.constrained[k]):
                    continue
                if Xa[:, k].min() <= Xb[:, k].max() + tol:  # not wholly above b along k
                    continue
                for s in np.linspace(0.0, 1.0, PLATE_PATH_SAMPLES)[1:]:
                    top = (Xa + a.motion.displacement_at(Xa, s))[:, k].min()
                    floor = (Xb + b.motion.displacement_at(Xb, s))[:, k].max()
                    if top <= floor + tol:
                        return (f"plate {a.name!r} reaches plate {b.name!r} along {'xyz'[k]} at load factor "
                                f"{s:.3g} (gap {top - floor + 0:.3g} m of {Xa[:, k].min() - Xb[:, k].max():.3g} "
                                "m at rest): the body would be pressed through itself")
    return None
