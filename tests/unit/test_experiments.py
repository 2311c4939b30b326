"""One scene builder (hybmss/experiments.py) for every command: ``hybmss fem`` and ``hybmss
compare`` with the same arguments build the same scene; torsion's angle has one definition."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hybmss.experiments import EXPERIMENTS, SceneSpec
from hybmss.scene import Model

# Regression baseline of scene digests, recorded before the model registry existed: stored runs
# and the regression baseline are keyed by these digests, so the same experiment must hash the
# same (baudet2009 scenes changed on purpose: they recorded A, e_form and volume_energy, which that
# model never used).
DIGESTS = {
    ("compression", "hybmss", ()): "88286c2000071325e796d81488331858a6e75505fa023593f1cce850f0876e5b",
    ("tension", "hybmss-fd", ()): "a1949dca607762b5299d0efdee504e17c33edd0dcfa589dfb932b98b260cdcfb",
    ("shear", "hybmss-cf", ()): "aafa2fc18a57217a933de89efb3e9615e474fbb912becf7417be4c93faf4cec6",
    ("torsion", "hybmss", (("e_form", True),)): "762365b5e73085ba0002df9ba3af3cdfccc6056ed5344fdb5b29e82a87d0d649",
    ("bending", "hybmss", (("volume_energy", "squared"),)):
        "b0892e2d540e8b89680f743b6dc98aa481f228af0a7f3536cf77554c7345772b",
    ("uniaxial", "hybmss", (("A", 2.0),)): "43185009cef914caa0a824fbf13a4033d02dac855e6ca8fe192ca70fe8f4e5e7",
}


@pytest.mark.parametrize("case", list(DIGESTS), ids=lambda c: f"{c[0]}-{c[1]}")
def test_scene_digests_of_the_existing_models_are_unchanged(case):
    experiment, model, params = case
    spec = SceneSpec.default(experiment, model=model, nu=0.3, **dict(params))
    assert spec.build().digest() == DIGESTS[case]


LOADS = {"compression": ["--deformation", "0.1"], "tension": ["--deformation", "0.1"],
         "shear": ["--deformation", "0.1"], "torsion": ["--angle", "7"], "bending": ["--gravity", "9"]}


@pytest.mark.parametrize("experiment", [e for e in EXPERIMENTS if e != "uniaxial"])
def test_fem_and_compare_build_the_same_scene(experiment):
    from studies.cli import parser as cli
    from studies.cli import common as cli_common

    parser, opts = cli.build_parser()

    def spec(*argv, solvers):
        return cli_common.scene_spec(parser.parse_args(opts.join_values(list(argv))), experiment, solvers)

    common = ["--mesh", "2x2x4", "--E", "2e4", "--nu", "0.3"] + LOADS[experiment]
    fem = spec("fem", "--scene", experiment, *common, solvers=("fem",)).build()
    cmp = spec("compare", experiment, *common, solvers=("static", "fem")).build()
    assert fem.digest() == cmp.digest()
    # and with every option left to the experiment's defaults
    fem = spec("fem", "--scene", experiment, solvers=("fem",)).build()
    cmp = spec("compare", experiment, solvers=("static", "fem")).build()
    assert fem.digest() == cmp.digest() == SceneSpec.default(experiment).build().digest()


def test_torsion_angle_is_angle_deg_only():
    """The top plate turns by exactly ``angle_deg`` (an exact rotation): the top corners move on a
    circle about the axis through the top face's centre, by the chord 2 r sin(θ/2)."""
    spec = SceneSpec.default("torsion", mesh=(2, 2, 2), angle_deg=30.0, deformation=0.4)
    scene = spec.build()
    top = scene.plates[1]
    X = np.array([[0.0, 0.0, 5.0], [5.0, 5.0, 5.0]])
    u = top.motion.displacement_at(X, 1.0)
    r = math.hypot(2.5, 2.5)
    assert np.linalg.norm(u, axis=1) == pytest.approx([2 * r * math.sin(math.radians(15.0))] * 2, rel=1e-12)
    assert spec.replace(deformation=0.0).build().digest() == scene.digest()  # d plays no part in torsion


def test_spec_routes_model_parameters_and_records_them():
    spec = SceneSpec.default("compression", model="hybmss", e_form=True, A=None)
    assert spec.params == (("e_form", True),)
    d = spec.to_dict()
    assert (d["A"], d["e_form"], d["volume_energy"], d["variant"]) == (1.0, True, "quadratic", "hybmss (E-form)")
    assert spec.build().model == Model("hybmss", e_form=True)
    assert spec.replace(model="hybmss-fd").build().model == Model("hybmss-fd", e_form=True)
    assert spec.replace(model="baudet2009").params == ()  # parameters it does not have are not carried
    with pytest.raises(ValueError, match="has no parameter 'A'"):
        SceneSpec.default("compression", model="baudet2009", A=1.0)
    json.dumps(d)  # plain data


def test_euler_bernoulli_from_the_spec_matches_the_closed_form():
    """Tip of a clamped beam under its weight: q L⁴/(8 E I), q = ρ g l h (distributed load)."""
    spec = SceneSpec.default("bending", mesh=(4, 4, 24), E=1e7, gravity=10.0)
    q, I, L = 1000.0 * 10.0 * 0.4 * 0.4, 0.4 * 0.4**3 / 12, 2.4
    assert spec.euler_bernoulli_tip() == pytest.approx(-q * L**4 / (8 * 1e7 * I), rel=1e-12)


# ------------------------------------------------------------------------------- the registry
LOAD_FIELDS = ("deformation", "angle_deg", "gravity")
CHANGED = {"deformation": 0.07, "angle_deg": 3.0, "gravity": 7.0}


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_each_experiment_is_loaded_by_its_declared_load_parameter_only(name):
    """The registry's load parameter is the one field of the three that changes the scene (and
    the one the specification's checks and a study file's ``[load]`` accept for it)."""
    from hybmss.experiments import experiment

    e = experiment(name)
    base = SceneSpec.default(name, mesh=(2, 2, 4))
    for f in LOAD_FIELDS:
        changed = base.replace(**{f: CHANGED[f]}).build().digest() != base.build().digest()
        assert changed == (f == e.load), (name, f)
        assert SceneSpec.uses(f, name) == (f == e.load), (name, f)


def test_the_registered_answer_of_compression_is_the_force_that_theory_gives():
    """At ν = 0 a cube pressed between a clamped base and a clamped plate is in uniaxial stress:
    the plate's reaction is E·A·d (the linear FEM's exactly, up to the solver's tolerance); the
    registry's answer names the stored row's column that holds it."""
    from hybmss.experiments import experiment
    from studies.sweep.runner import SolverSpec, measure, solve_scene

    spec = SceneSpec.default("compression", mesh=(2, 2, 2), E=1e4, nu=0.0, deformation=0.02)
    row = measure(spec, solve_scene(spec.build(), SolverSpec("fem", element="hex2", law="linear")))
    side = spec.cell_edge * 2
    assert abs(row[experiment("compression").answer]) == pytest.approx(1e4 * side**2 * 0.02, rel=1e-8)


def test_an_unknown_experiment_names_the_registered_ones():
    from hybmss.experiments import experiment

    with pytest.raises(ValueError, match="compression, tension, shear, torsion, bending"):
        experiment("twist")
