"""The kind of a mode shape and the pairing rows (:mod:`studies.sweep.mode_pairs`).

Kinds, on fields built by hand on a 3×3×4-node lattice: each layer translating sideways is
bending, each layer turning rigidly about its centre line torsion, u = (0, 0, w(z)) axial, an
in-plane radial breathing (neither a translation nor a turn of any layer) other.  Pairing: corot-hex8
at rest is the FEM's Hex1 with lumped mass (tests/verification/test_model_modes.py), so its rows
against that FEM have errors of 0 and MACs of 1; a FEM shape replaced by noise has no counterpart."""

from __future__ import annotations

import numpy as np
import pytest

from hybmss.lattice import Lattice
from hybmss.scene import Body, Material, Model, Plate, Region, Scene
from studies.sweep.mode_pairs import MAC_MIN, first_of_kinds, fem_modes, mode_kinds, model_rows


def _grid():
    g = np.stack(np.meshgrid(np.arange(3.0), np.arange(3.0), np.arange(4.0), indexing="ij"), -1).reshape(-1, 3)
    return g


def test_kinds_of_shapes_built_by_hand():
    X = _grid()
    z = X[:, 2:3]
    r = X[:, :2] - 1.0
    bend = np.hstack([z**2, 0.3 * z**2, 0.0 * z])
    twist = np.hstack([-r[:, 1:2] * z, r[:, 0:1] * z, 0.0 * z])
    axial = np.hstack([0.0 * z, 0.0 * z, np.sin(z)])
    breathe = np.hstack([r * z, 0.0 * z])
    assert mode_kinds(np.array([bend, twist, axial, breathe]), X) == ["bending", "torsion", "axial", "other"]
    rng = np.random.default_rng(0)  # a small perturbation keeps the kind
    noisy = axial + 0.05 * rng.standard_normal(axial.shape)
    assert mode_kinds(noisy[None], X) == ["axial"]


def _scene(model):
    return Scene(Body.box(2, 2, 6, 0.25), Material(1e7, 0.3, 1000.0), plates=(Plate("clamp", Region("z-")),),
                 model=Model(model))


def test_rows_against_the_equal_fem_and_a_shape_without_counterpart():
    sc = _scene("corot-hex8")
    fem = fem_modes(sc, 6, "hex1", mass="lumped")
    rows = model_rows(sc, fem)
    assert [r["mode"] for r in rows] == list(range(1, 7)) and all(r["status"] == "ok" for r in rows)
    np.testing.assert_allclose([r["error_pct"] for r in rows], 0.0, atol=1e-8)
    np.testing.assert_allclose([r["mac"] for r in rows], 1.0, atol=1e-10)
    assert fem["kinds"][:2] == ["bending", "bending"] and "torsion" in fem["kinds"]
    t = fem["kinds"].index("torsion")  # a mode of its own frequency (the bending ones come in pairs)
    noise = np.random.default_rng(1).standard_normal(fem["shapes"][t].shape)
    noise[Lattice.from_body(sc.body).X[:, 2] == 0.0] = 0.0
    fem["shapes"] = fem["shapes"].copy()
    fem["shapes"][t] = noise
    rows = model_rows(sc, fem)
    assert rows[t]["status"] == "unpaired" and rows[t]["error_pct"] is None and rows[t]["mac"] < MAC_MIN
    assert all(r["status"] == "ok" for i, r in enumerate(rows) if i != t)
    summary = first_of_kinds(rows)
    assert summary["torsion_error_pct"] is None and summary["min_mac"] == pytest.approx(rows[t]["mac"])
    assert summary["bending_error_pct"] == pytest.approx(0.0, abs=1e-8)


def test_a_model_without_tangent_has_one_row_without_numbers():
    sc = _scene("corot-hex8")
    fem = fem_modes(sc, 3, "hex1", mass="lumped")
    (row,) = model_rows(_scene("xpbd-nh"), fem)
    assert row["status"] == "no modal answer" and row["mode"] is None and "f_model_hz" not in row
