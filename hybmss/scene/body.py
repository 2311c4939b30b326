"""The body of a scene: a set of cubic cells of edge ``le`` on a regular ``nx × ny × nz`` grid
(cell volume ``le³``, body volume ``n_cells · le³``), stored as packed bits so it is hashable."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .checks import _finite, _pieces_text, _vec3, pieces


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
