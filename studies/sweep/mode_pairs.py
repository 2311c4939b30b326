"""A model's lowest natural frequencies paired with the FEM's, row by row, with the kind of each
FEM mode and the wall time of the model's eigen-solve (cost beside error).

The eigenproblems are :func:`hybmss.modes.lattice_modes` (``K φ = ω² M φ``: the model's tangent at
rest, its lumped masses) and :func:`fem_reference.modal.modes` (the same body and supports); each
FEM mode is paired with one of the model's lowest 2k modes by MAC (:func:`hybmss.modes.match`), and
its error is ``100 (f_model / f_ref − 1)`` % (none when the pair's MAC is below :data:`MAC_MIN`: the
model has no counterpart among those modes).

**Kind of a mode** (:func:`mode_kinds`), from its shape ``u`` at the lattice particles, cut into
the layers of equal z (the axis of the [G20] beam and of the cube's plates).  In each layer the
in-plane motion is split into its mean translation ``t`` and a rigid rotation about the layer's
centroid, ``θ = Σ r × (u − t) / Σ |r|²`` (r: in-plane position from the centroid).  Summed over
the layers, the shares of ``Σ |u|²`` are

    lateral  = Σ n_l |t_l|²,     torsion = Σ θ_l² Σ |r|²,     axial = Σ u_z²,

and a mode is ``bending`` (layers translate sideways: the beam's bending, the cube's shear),
``torsion`` or ``axial`` by the largest share when it is at least :data:`KIND_SHARE`, ``other``
otherwise.  The first mode of a kind is the lowest FEM mode of that kind.
"""

from __future__ import annotations

import time

import numpy as np

KINDS = ("bending", "torsion", "axial")
KIND_SHARE = 0.5
"""Share of ``Σ |u|²`` a kind must hold to name a mode."""
MAC_MIN = 0.5
"""A FEM mode whose paired model mode has a lower MAC has no counterpart among the model's lowest
2k: its row keeps the pair's frequency and MAC but no error (``status`` ``unpaired``)."""
NO_TANGENT = "no modal answer: the model has no tangent stiffness (its static answer is its own solver's)"


def mode_kinds(shapes: np.ndarray, X: np.ndarray) -> list[str]:
    """The kind (module docstring) of each shape of ``shapes`` (k, n, 3) at the points ``X`` (n, 3)."""
    z = np.round(X[:, 2] / max(np.ptp(X[:, 2]), 1e-300), 9)
    layers = [np.flatnonzero(z == v) for v in np.unique(z)]
    out = []
    for u in np.asarray(shapes, float):
        total = float(np.sum(u * u))
        lateral = torsion = 0.0
        for idx in layers:
            r = X[idx, :2] - X[idx, :2].mean(axis=0)
            t = u[idx, :2].mean(axis=0)
            lateral += len(idx) * float(t @ t)
            rr = float(np.sum(r * r))
            if rr > 0:
                d = u[idx, :2] - t
                theta = float(np.sum(r[:, 0] * d[:, 1] - r[:, 1] * d[:, 0])) / rr
                torsion += theta * theta * rr
        shares = np.array([lateral, torsion, float(np.sum(u[:, 2] ** 2))]) / max(total, 1e-300)
        best = int(np.argmax(shares))
        out.append(KINDS[best] if shares[best] >= KIND_SHARE else "other")
    return out


def fem_modes(scene, k: int, element: str, refine: int = 1, mass: str = "consistent") -> dict:
    """The FEM's lowest ``k`` modes of ``scene`` at the lattice particles, their kinds and the
    solve's wall time."""
    from fem_reference.modal import at_particles, modes
    from hybmss.lattice import Lattice

    t0 = time.perf_counter()
    fm = modes(scene, k, element, refine, mass=mass)
    wall = time.perf_counter() - t0
    shapes = at_particles(fm)
    return {"freq": fm.freq, "shapes": shapes, "kinds": mode_kinds(shapes, Lattice.from_body(scene.body).X),
            "element": element, "refine": int(refine), "mass": mass, "time_s": wall}


def model_rows(scene, fem: dict) -> list[dict]:
    """One row per FEM mode: the paired model mode's frequency, error (%), MAC and the wall time of
    the model's eigen-solve; one row without numbers (``status``, ``message``) for a model without
    tangent stiffness or whose solve fails."""
    from hybmss.modes import has_tangent, lattice_modes, match
    from hybmss.system import build

    spec = scene.model.spec
    if not has_tangent(spec):
        return [{"mode": None, "kind": None, "status": "no modal answer", "message": NO_TANGENT}]
    k = len(fem["freq"])
    try:
        system = build(scene)
        n_free = int((~system.fixed).sum())
        t0 = time.perf_counter()
        lm = lattice_modes(scene, min(2 * k, n_free - 1), system)
        wall = time.perf_counter() - t0
    except (ValueError, RuntimeError, ArithmeticError) as exc:  # ARPACK's errors are RuntimeErrors
        return [{"mode": None, "kind": None, "status": "failed", "message": " ".join(str(exc).split())}]
    m = match(fem["freq"], fem["shapes"], lm.freq, lm.shapes)
    rows = []
    for j, c in enumerate(m["matched"]):
        mac = m["matched_mac"][j]
        paired = c is not None and mac >= MAC_MIN
        err = m["error"][j] if paired else None
        why = "" if paired else (f"no mode among the model's lowest {len(lm.freq)} resembles it (MAC "
                                 f"{0.0 if mac is None else mac:.2g} < {MAC_MIN:g})")
        rows.append({"mode": j + 1, "kind": fem["kinds"][j], "f_ref_hz": float(fem["freq"][j]),
                     "f_model_hz": None if c is None else float(lm.freq[c]),
                     "model_mode": None if c is None else c + 1,
                     "error_pct": None if err is None else 100.0 * err, "mac": mac,
                     "model_time_s": wall, "fem_time_s": fem["time_s"], "status": "ok" if paired else "unpaired",
                     "message": why})
    return rows


def first_of_kinds(rows: list[dict]) -> dict:
    """``<kind>_error_pct`` of the first mode of each kind, ``min_mac`` over the rows, from the mode
    rows of one model (:func:`model_rows`); None where a kind is not among them or its first mode
    has no counterpart (MAC below :data:`MAC_MIN`)."""
    out = {}
    for kind in KINDS:
        hit = next((r for r in rows if r.get("kind") == kind), None)
        out[f"{kind}_error_pct"] = None if hit is None else hit["error_pct"]
        out[f"{kind}_f_ref_hz"] = None if hit is None else hit["f_ref_hz"]
    macs = [r["mac"] for r in rows if r.get("mac") is not None]
    out["min_mac"] = min(macs) if macs else None
    return out
