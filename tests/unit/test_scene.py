"""Scene data: validation with clear messages, hashing, round trips, the CLI's exit status."""

import dataclasses
import json

import numpy as np
import pytest

from hybmss.scene import Body, Load, Material, Model, Motion, Plate, Region, Scene, parse_mesh
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
        (lambda: Plate("bottom", "w-"), ["face", "x-, x+"]),
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


@pytest.mark.parametrize(
    "make, words",
    [
        (lambda: Plate("bottom", 3), ["plate 'bottom'", "region", "Region", "3 (int)"]),
        (lambda: Plate("bottom", ("z-",)), ["region", "Region"]),
        (lambda: Plate("top", "z+", 1.0), ["plate 'top'", "motion", "Motion", "(float)"]),
        (lambda: Plate(3, "z-"), ["plate name", "string"]),
        (lambda: Region(face=2), ["face", "(int)"]),
        (lambda: Region(face=["z-"]), ["face", "(list)"]),
        (lambda: Region(lo="abc", hi=(1, 1, 1)), ["lo", "3 finite numbers"]),
        (lambda: Motion(kind=None), ["motion kind", "(NoneType)"]),
        (lambda: Motion("translate", "up"), ["displacement", "3 finite numbers"]),
        (lambda: Motion("rotate", angle="90"), ["angle", "finite number", "(str)"]),
        (lambda: Motion("slide", components="z"), ["components", "integers"]),
        (lambda: Motion("slide", components=(2.5,)), ["components", "integers"]),
        (lambda: Motion("slide", components=(True,)), ["components", "integers"]),
        (lambda: Motion("affine", gradient="eye"), ["gradient", "9 finite"]),
        (lambda: Load(Region("x+"), traction="down"), ["traction", "3 finite numbers"]),
        (lambda: Load(None, (0, 0, 1)), ["load region", "Region"]),
        (lambda: _scene(plates=(Region("z-"),)), ["plates[0]", "Plate"]),
        (lambda: _scene(plates=Plate("bottom", "z-")), ["plates", "sequence of Plate"]),
        (lambda: _scene(loads=("x+",)), ["loads[0]", "Load"]),
        (lambda: _scene(body=(2, 2, 2)), ["body", "Body"]),
        (lambda: _scene(material=1e4), ["material", "Material"]),
        (lambda: _scene(model=3), ["model", "Model"]),
        (lambda: _scene(name=None), ["scene name", "string"]),
        (lambda: Material("1e4", 0.3), ["E", "(str)"]),
    ],
)
def test_wrong_types_are_refused_at_construction(make, words):
    """A wrong type is refused where it is given (a TypeError, and a ValueError like every
    refusal), never later in a solver as an AttributeError."""
    with pytest.raises(TypeError) as err:
        make()
    assert isinstance(err.value, ValueError)
    for w in words:
        assert w in str(err.value)


def test_face_and_kind_names_are_the_same_plate():
    """``Plate("bottom", "z-")`` is the plate of ``Region(face="z-")``: equal, same digest."""
    a = _scene(plates=(Plate("bottom", "z-"), Plate("top", "z+", "clamped")), loads=(Load("x+", (0, 0, -1.0)),),
               model="hybmss")
    b = _scene(plates=(Plate("bottom", Region("z-")), Plate("top", Region(face="z+"), Motion("clamped"))),
               loads=(Load(Region("x+"), (0.0, 0.0, -1.0)),), model=Model("hybmss"))
    assert a == b and a.digest() == b.digest()
    assert isinstance(a.plates[0].region, Region) and isinstance(a.plates[1].motion, Motion)
    from hybmss.solve import solve_static

    r = solve_static(_scene(plates=(Plate("bottom", "z-"), Plate("top", "z+", Motion("translate", (0, 0, -0.01))))))
    top, bottom = r.reactions["top"].force[2], r.reactions["bottom"].force[2]
    assert r.converged and abs(top) > 0 and top == pytest.approx(-bottom, rel=1e-6)


@pytest.mark.parametrize("plates, free", [
    ((), ["translation along x", "translation along y", "translation along z", "rotation about x",
          "rotation about y", "rotation about z"]),
    # a frictionless floor holds z, and the rotations that lift an edge of it
    ((Plate("floor", "z-", Motion("slide", components=(2,))),),
     ["translation along x", "translation along y", "rotation about z"]),
    # one clamped corner: the body turns about it
    ((Plate("pin", Region(lo=(0, 0, 0), hi=(0, 0, 0))),), ["rotation about x", "rotation about y", "rotation about z"]),
    # a clamped line of particles along x: a hinge
    ((Plate("hinge", Region(lo=(0, 0, 0), hi=(1.0, 0, 0))),), ["rotation about x"]),
    # the uniaxial test's floor and two pins hold everything
    ((Plate("floor", "z-", Motion("slide", components=(2,))),
      Plate("pin", Region(lo=(0, 0, 0), hi=(0, 0, 0)), Motion("slide", components=(0, 1))),
      Plate("pin_x", Region(lo=(1.0, 0, 0), hi=(1.0, 0, 0)), Motion("slide", components=(1,)))), []),
    ((Plate("base", "z-"),), []),
])
def test_free_rigid_modes_are_named(plates, free):
    from hybmss.scene import free_rigid_modes, unsupported

    scene = _scene(plates=plates, gravity=(0, 0, -9.81))
    found = free_rigid_modes(scene)
    assert (found[0][1] if found else []) == free
    assert (unsupported(scene) is None) == (not free)


def test_static_solve_refuses_an_unsupported_body_before_work():
    """Without plates the constrained Hessian is singular at rest: once reported as a negative
    bulk or shear modulus; now refused up front, naming the free modes."""
    from hybmss.solve import solve_static

    for plates in ((), (Plate("floor", "z-", Motion("slide", components=(2,))),)):
        with pytest.raises(ValueError, match="not supported .rigid-body motion not prevented.") as err:
            solve_static(_scene(plates=plates, gravity=(0, 0, -9.81)))
        assert "translation along x" in str(err.value) and "modulus" not in str(err.value)


def test_each_piece_must_be_held():
    """Two pieces (a body built from its bits, past the mask check): the one without a plate is named."""
    from hybmss.scene import free_rigid_modes

    mask = np.zeros((4, 1, 2), bool)
    mask[:1, :, :] = True  # 2 cells on x = 0
    mask[2:, :, :1] = True  # 2 cells at the bottom of x = 2..3, a cell away
    body = Body(mask.shape, 1.0, (0, 0, 0), np.packbits(mask.ravel()).tobytes())
    scene = Scene(body, Material(1e4, 0.3), plates=(Plate("wall", "x-"),))
    assert free_rigid_modes(scene) == [(2, ["translation along x", "translation along y", "translation along z",
                                            "rotation about x", "rotation about y", "rotation about z"])]


@pytest.mark.parametrize("nu", [-0.9, -0.3, 0.0, 0.25, 0.45, 0.499])
def test_moduli_agree_with_the_isotropic_identities(nu):
    """G, λ and K of a material satisfy the identities of isotropic elasticity that do not pass
    through their formulas: K = λ + 2G/3, E = 9KG/(3K + G), ν = (3K − 2G)/(2(3K + G))."""
    m = Material(2.0e5, nu)
    G, lam, K = m.G, m.lam, m.K
    assert K == pytest.approx(lam + 2.0 * G / 3.0, rel=1e-12)
    assert 9.0 * K * G / (3.0 * K + G) == pytest.approx(m.E, rel=1e-12)
    assert (3.0 * K - 2.0 * G) / (2.0 * (3.0 * K + G)) == pytest.approx(nu, rel=1e-9, abs=1e-12)
