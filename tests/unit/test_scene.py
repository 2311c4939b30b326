"""Scene data: validation with clear messages, hashing, round trips, the CLI's exit status."""

import dataclasses
import json

import numpy as np
import pytest

from hybmss.scene import Body, Material, Model, Motion, Plate, Region, Scene, parse_mesh
from hybmss.solve import ImplicitOptions


def _scene(**kw):
    base = dict(
        body=Body.box(2, 2, 2, 0.5),
        material=Material(1e4, 0.3),
        plates=(Plate("bottom", Region("z-")), Plate("top", Region("z+"), Motion("translate", (0, 0, -0.1)))),
    )
    base.update(kw)
    return Scene(**base)


@pytest.mark.parametrize(
    "make, words",
    [
        (lambda: Material(1e4, 0.5), ["nu", "(-1, 0.5)"]),
        (lambda: Material(1e4, -1.0), ["nu", "(-1, 0.5)"]),
        (lambda: Material(0.0, 0.3), ["E", "> 0"]),
        (lambda: Material(-5.0, 0.3), ["E", "> 0"]),
        (lambda: Material(1e4, 0.3, rho=-1.0), ["rho", ">= 0"]),
        (lambda: Material(float("nan"), 0.3), ["E", "finite"]),
        (lambda: Body.box(0, 2, 2, 0.5), ["nx", "empty"]),
        (lambda: Body.from_mask(np.zeros((2, 2, 2), bool), 0.5), ["empty"]),
        (lambda: Body.box(2, 2, 2, 0.0), ["le", "> 0"]),
        (lambda: Model("springy"), ["model", "hybmss"]),
        (lambda: Model("hybmss-fd", A=1.0), ["A", "hybmss-fd"]),
        (lambda: Model("hybmss", A=-1.0), ["A", ">= 0"]),
        (lambda: ImplicitOptions(dt=0.0), ["dt", "> 0"]),
        (lambda: ImplicitOptions(dt=-1e-3), ["dt", "> 0"]),
        (lambda: Motion("wiggle"), ["motion", "clamped"]),
        (lambda: Region("w+"), ["face"]),
        (lambda: _scene(damping=-1.0), ["damping", ">= 0"]),
        (lambda: parse_mesh("10x10"), ["mesh", "NXxNYxNZ"]),
    ],
)
def test_bad_input_names_parameter_and_range(make, words):
    with pytest.raises(ValueError) as err:
        make()
    for w in words:
        assert w in str(err.value)


def test_digest_is_stable_and_sensitive():
    a, b = _scene(), _scene()
    assert a.digest() == b.digest()
    assert a.with_material(nu=0.31).digest() != a.digest()
    assert dataclasses.replace(a, model=Model("hybmss-fd")).digest() != a.digest()


def test_round_trip_through_json():
    mask = np.ones((3, 1, 3), bool)
    mask[1:, :, 1:] = False  # L-shape
    sc = _scene(body=Body.from_mask(mask, 0.25), gravity=(0, 0, -10), damping=2.0)
    back = Scene.from_dict(json.loads(json.dumps(sc.to_dict())))
    assert back == sc
    assert back.digest() == sc.digest()
    assert back.body.n_cells == 5


def test_rotation_motion_is_exact():
    m = Motion("rotate", angle=np.pi / 2, axis=(0, 0, 1), center=(0, 0, 0))
    u = m.displacement_at(np.array([[1.0, 0.0, 0.3]]), 1.0)
    np.testing.assert_allclose(u + [1.0, 0.0, 0.3], [[0.0, 1.0, 0.3]], atol=1e-15)
    np.testing.assert_allclose(m.displacement_at(np.array([[1.0, 0.0, 0.3]]), 0.0), 0.0)


def test_slide_prescribes_only_its_components():
    m = Motion("slide", (1.0, 2.0, 3.0), components=(2,))
    assert m.constrained.tolist() == [False, False, True]
    np.testing.assert_allclose(m.displacement_at(np.zeros((1, 3)), 0.5), [[0, 0, 1.5]])
