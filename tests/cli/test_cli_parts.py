"""Parts of the command line checked in process: options generated from the scene specification,
negative values, strict JSON, closed-form lattice counts and the size guard's dof counts."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from studies.cli import parser as cli

from studies.cli import common, info, options

from studies.sweep import sizing
from studies.sweep.compare import default_law
from hybmss.experiments import DEFAULTS, SceneSpec


def parse(*argv):
    parser, opts = cli.build_parser()
    return parser.parse_args(opts.join_values(list(argv)))


VALUES = {"mesh": ("3x4x5", (3, 4, 5)), "model": ("hybmss-cf", "hybmss-cf"), "volume_energy": ("squared", "squared"),
          "e_form": (None, True), "sequential": (None, True), "integrator": ("RK4", "RK4")}
MSS_ONLY = {"model"} | set(common.model_parameters())


@pytest.mark.parametrize("field", [f.name for f in SceneSpec.parameters()] + list(common.model_parameters()))
def test_every_scene_and_model_parameter_is_one_option_of_fem_and_compare(field):
    text, value = VALUES.get(field, ("-0.125", -0.125))
    flag = common.flag(field)
    extra = [] if text is None else [text]
    for argv in (["compare", "torsion", flag, *extra], ["fem", flag, *extra]):
        args = parse(*argv)
        assert getattr(args, field) == value  # a negative value is read as the option's value
        others = {k: v for k, v in common.given_scene_options(args).items()}
        assert others == {field: value}  # the others are not given: the experiment's defaults apply


def test_defaults_come_from_the_scene_specification():
    args = parse("compare", "bending")
    spec = common.scene_spec(args, "bending", ("static", "fem"))
    assert spec == SceneSpec.default("bending")
    assert (spec.E, spec.gravity, spec.mesh) == (DEFAULTS["bending"]["E"], 10.0, DEFAULTS["bending"]["mesh"])


def test_join_values_only_for_options_taking_a_value():
    _, opts = cli.build_parser()
    assert opts.join_values(["--E", "-1e4", "--json"]) == ["--E=-1e4", "--json"]
    assert opts.join_values(["--mesh", "-1x2x2"]) == ["--mesh=-1x2x2"]
    assert opts.join_values(["--E", "--json"]) == ["--E", "--json"]  # a missing value stays missing
    assert opts.join_values(["--json", "-d"]) == ["--json", "-d"]


def test_strict_json_has_no_nan():
    obj = {"a": float("nan"), "b": [np.float64(np.inf), np.int64(3)], "c": np.array([1.0, np.nan]),
           "d": (True, None, "x")}
    out = cli.dump(obj)
    assert json.loads(out) == {"a": None, "b": [None, 3], "c": [1.0, None], "d": [True, None, "x"]}


@pytest.mark.parametrize("shape", [(1, 1, 1), (2, 3, 4), (5, 1, 2)])
def test_box_counts_match_the_lattice(shape):
    from hybmss.lattice import Lattice
    from hybmss.scene import Body

    assert info.box_counts(shape) == Lattice.from_body(Body.box(*shape, 0.5)).counts()


@pytest.mark.parametrize("element,nu", [("hex1", 0.25), ("hex2", 0.25), ("auto", 0.3), ("mixed", 0.3)])
def test_size_guard_counts_the_fem_dofs(element, nu):
    from fem_reference.solve import solve

    scene = SceneSpec.default("tension", mesh=(1, 1, 2), nu=nu).build()
    res = solve(scene, element=element, law="linear", refine=2)
    assert res.info["n_dofs"] == sizing.fem_dofs((1, 1, 2), element, 2, nu)


def test_size_guard_refuses_what_does_not_fit_and_only_that():
    assert sizing.fits(sizing.fem((10, 10, 10))) and sizing.fits(sizing.mss((10, 10, 10)))
    big = sizing.fem((200, 200, 200))
    assert not sizing.fits(big) and big.bytes > 1e12
    n = sizing.largest_cube(lambda s: sizing.fem(s))
    assert sizing.fits(sizing.fem((n, n, n))) and not sizing.fits(sizing.fem((n + 1, n + 1, n + 1)))
    assert "would need about" in sizing.refusal(big)


def test_fem_choices_are_the_fem_reference_s():
    from fem_reference.solve import ELEMENT_CHOICES, LAW_CHOICES

    assert set(options.ELEMENTS) == set(ELEMENT_CHOICES) and set(options.LAWS) == set(LAW_CHOICES)


def test_the_publications_scenes_pass_the_checks():
    from studies.paper.reproduce import STUDIES, tasks_for

    for quick in (True, False):
        for task in tasks_for(list(STUDIES), quick):
            task.scene.check()


@pytest.mark.parametrize("experiment,field,value", [("compression", "deformation", 0.2), ("shear", "deformation", 0.03),
                                                    ("torsion", "angle_deg", 30.0), ("torsion", "angle_deg", 2.0)])
def test_default_law_does_not_depend_on_the_sign(experiment, field, value):
    spec = SceneSpec.default(experiment, **{field: value})
    assert default_law(spec) == default_law(spec.replace(**{field: -value}))


def test_parameter_errors_name_the_range():
    with pytest.raises(ValueError, match=r"angle_deg = 360.*\(-180, 180\) degrees"):
        SceneSpec.default("torsion", angle_deg=360.0).check()
    with pytest.raises(ValueError, match=r"deformation = 1.*\[0, 1\)"):
        SceneSpec.default("compression", deformation=1.0).check()
    assert math.isfinite(SceneSpec.default("compression", deformation=0.99).check().deformation)


def test_help_ranges_are_the_solvers(capsys):
    from hybmss.moduli import STRAIN_RANGE
    from hybmss.solve import NU_RANGE

    for argv in (["moduli", "--help"], ["compare", "--help"]):
        assert cli.main(argv) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert f"[{NU_RANGE[0]:g}, {NU_RANGE[1]:g}]" in text
    assert f"[{STRAIN_RANGE[0]:g}, {STRAIN_RANGE[1]:g}]" in text


def test_model_options_come_from_the_registry():
    from hybmss import models

    assert common.model_choices() == tuple(models.names())
    for m in models.all_models():
        for name in m.parameter_names():
            assert name in common.model_parameters() and m.name in common.model_parameters()[name][1]
