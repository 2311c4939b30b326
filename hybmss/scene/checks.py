"""Checks of scene values: the constructors' validators (a field's type and range, named in the
error), the face-connected pieces of a voxel mask, the schema of a scene's JSON form
(:func:`scene_dict_error`) and the support checks a static solve needs before any work
(:func:`free_rigid_modes`, :func:`unsupported`, :func:`plates_cross`).  Their ``scene`` is a
:class:`hybmss.scene.Scene`, not named in their annotations: :mod:`.scene` imports this module,
and an import of it here, even for type checkers only, would close an import circle (every
import statement counts, tests/unit/test_imports.py).

A rigid mode is free when the held components do not prevent it: with the rigid modes
``R = [e_x, e_y, e_z, e_x × r, e_y × r, e_z × r]`` restricted to the held (particle, component)
rows, the free modes are the null space of ``R`` (``r`` measured from the held particles'
centroid, scaled by the body's size)."""

from __future__ import annotations

import json
import math

import numpy as np


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


def free_rigid_modes(scene) -> list[tuple[int, list[str]]]:
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


def unsupported(scene) -> str | None:
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


def plates_cross(scene) -> str | None:
    """Why the plates of ``scene`` would pass through each other (``None`` if they do not): two
    plates prescribing the same component whose particles lie, at rest, wholly on either side of a
    coordinate plane, and whose prescribed motions bring the first to or past the second at a load
    factor s in [0, 1] (a top plate pushed below a clamped floor: a body compressed through itself,
    which no material law can answer)."""
    body = scene.body
    X = np.asarray(body.origin) + _corner_nodes(body.mask) * body.le
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
