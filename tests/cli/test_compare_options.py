"""``hybmss compare`` on a stored scene, its ``--no-<flag>`` and ``--load-steps`` options, the two
volume formulas it names and the relative errors it gives, checked against closed forms."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hybmss.experiments import SceneSpec, uniaxial_scene
from hybmss.scene import Body, Material, Model, Motion, Plate, Scene
from studies.cli import parser as cli
from studies.cli import common, compare


def parse(*argv):
    parser, opts = cli.build_parser()
    return parser.parse_args(opts.join_values(list(argv)))


def _write(tmp_path, scene: Scene, name="scene.json"):
    path = tmp_path / name
    path.write_text(json.dumps(scene.to_dict()))
    return str(path)


def _refused(proc, fragment):
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("hybmss: ") and "Traceback" not in proc.stderr
    assert fragment in proc.stderr, proc.stderr


# ------------------------------------------------------------------------------ --no-<flag>
BOOLEANS = [name for name, (f, _) in common.model_parameters().items() if isinstance(f.default, bool)]


@pytest.mark.parametrize("name", BOOLEANS)
def test_every_boolean_model_parameter_has_a_no_flag(name):
    flag = common.flag(name)
    no = "--no-" + flag[2:]
    for command in (["compare", "compression"], ["fem"], ["moduli"]):
        assert getattr(parse(*command, flag), name) is True
        assert getattr(parse(*command, no), name) is False
        assert getattr(parse(*command), name) is None  # neither: the model's own default
    assert no in cli.build_parser()[1].flags


def test_no_flag_reaches_the_scene_and_is_refused_by_a_model_without_it(cli_in_process, tmp_path):
    assert BOOLEANS, "the models declare boolean parameters (e_form, sequential)"
    on = common.scene_spec(parse("compare", "compression", "--e-form"), "compression", ("static", "fem"))
    off = common.scene_spec(parse("compare", "compression", "--no-e-form"), "compression", ("static", "fem"))
    assert on.build().model.e_form is True and off.build().model.e_form is False
    p = cli_in_process("compare", "compression", "--model", "baudet2009", "--no-e-form", cwd=tmp_path)
    _refused(p, "--e-form = False is not allowed")


# ------------------------------------------------------------------------------ --scene-json
def test_scene_json_compare_of_a_uniaxial_block_against_closed_forms(cli_in_process, tmp_path):
    """A free-sliding block (frictionless plates, two pins) stretched by ε = 1e-3: the linear FEM
    is exactly homogeneous, u = (−νεx, −νεy, εz), so its ∫det F and its averaged-edge volume
    are both (1 + ε)(1 − νε)² − 1, its own (linearized) ∫ div u is ε (1 − 2ν) and its plate force
    E ε A; the MSS (hybmss) is right to O(ε)
    relative (its springs are finite-strain)."""
    E, nu, eps, n, le = 1e4, 0.3, 1e-3, 2, 0.5
    scene = uniaxial_scene(Model("hybmss"), Material(E, nu, 1000.0), strain=eps, n=n, le=le)
    path = _write(tmp_path, scene)
    p = cli_in_process("compare", "--scene-json", path, "--element", "hex1", "--law", "linear", "--json",
                       cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    dv = (1 + eps) * (1 - nu * eps) ** 2 - 1
    m, f, e = out["mss"], out["fem"], out["relative_errors"]
    assert out["scene_digest"] == scene.digest()
    assert f["volume_formula"] == "div_u" and m["volume_formula"] == "avg_edges"  # the linear law's own volume
    assert set(out["volume_formulas"]) == {"avg_edges", "det_F", "div_u"}
    assert out["units"]["volume_change"] == "fraction dV/V0"
    assert f["volume_change"] == pytest.approx(eps * (1 - 2 * nu), rel=1e-8)  # ∫ div u / V0 = tr ε
    assert f["volume_change_det_F"] == pytest.approx(dv, rel=1e-8)
    assert f["volume_change_avg_edges"] == pytest.approx(dv, rel=1e-8)
    assert m["volume_change_avg_edges"] == pytest.approx(dv, rel=5 * eps)
    area = (n * le) ** 2
    assert f["reactions"]["top"]["force"][2] == pytest.approx(E * eps * area, rel=1e-8)  # pulling up
    assert m["reactions"]["top"]["force"][2] == pytest.approx(E * eps * area, rel=5 * eps)
    # the relative errors are those of the numbers printed beside them
    Fm, Ff = (np.asarray(s["reactions"]["top"]["force"]) for s in (m, f))
    assert e["force"]["top"] == pytest.approx(np.linalg.norm(Fm - Ff) / np.linalg.norm(Ff), rel=1e-12)
    assert e["volume_change_avg_edges"] == pytest.approx((m["volume_change_avg_edges"] - dv) / abs(dv), rel=1e-6)
    assert abs(e["volume_change_avg_edges"]) < 5 * eps and abs(e["force"]["top"]) < 5 * eps
    assert 0 <= e["displacement_l2"] < 5 * eps and 0 <= e["displacement_max"] < 5 * eps
    # the text shows the same numbers, in the same unit (fractions)
    t = cli_in_process("compare", "--scene-json", path, "--element", "hex1", "--law", "linear", cwd=tmp_path)
    assert t.returncode == 0 and "volume change, averaged-edge" in t.stdout and "∫det F" in t.stdout
    assert f"{f['volume_change_det_F']:.6g}" in t.stdout and "%" not in t.stdout.split("\n", 2)[1]
    # fem names the same formulas, in the same unit (it once labelled the linear law's div u as det F, in %)
    t = cli_in_process("fem", "--scene-json", path, "--element", "hex1", "--law", "linear", cwd=tmp_path)
    assert t.returncode == 0 and "%" not in t.stdout
    assert f"∫det F: {dv:+.6g}" in t.stdout and f"∫(1 + div u) (the linear law's own): {eps * (1 - 2 * nu):+.6g}" \
        in t.stdout


def test_scene_json_compare_is_the_experiment_compare(cli_in_process, tmp_path):
    spec = SceneSpec.default("compression", mesh=(2, 2, 2))
    path = _write(tmp_path, spec.build())
    law = "linear"
    a = cli_in_process("compare", "compression", "--mesh", "2x2x2", "--law", law, "--json", cwd=tmp_path)
    b = cli_in_process("compare", "--scene-json", path, "--law", law, "--json", cwd=tmp_path)
    assert a.returncode == 0 and b.returncode == 0, (a.stderr, b.stderr)
    a, b = json.loads(a.stdout), json.loads(b.stdout)
    assert a["scene_digest"] == b["scene_digest"]
    for side in ("mss", "fem"):
        for k in ("volume_change", "volume_change_avg_edges", "max_displacement", "reactions"):
            assert a[side][k] == b[side][k]
    assert a["relative_errors"] == b["relative_errors"] and a["diff"] == b["diff"]


# ------------------------------------------------------------------------------ --load-steps
def test_load_steps_are_taken_and_give_the_same_equilibrium(cli_in_process, tmp_path):
    args = ("compare", "compression", "--mesh", "2x2x2", "--deformation", "0.2", "--json")
    a = cli_in_process(*args, cwd=tmp_path)
    b = cli_in_process(*args, "--load-steps", "6", cwd=tmp_path)
    assert a.returncode == 0 and b.returncode == 0, (a.stderr, b.stderr)
    a, b = json.loads(a.stdout)["mss"], json.loads(b.stdout)["mss"]
    assert b["load_steps"] >= 6 > a["load_steps"]
    # the same stable equilibrium, to the solver's tolerance (rtol 1e-8 of the plate force)
    assert b["reactions"]["top"]["force"][2] == pytest.approx(a["reactions"]["top"]["force"][2], rel=1e-6)
    assert b["volume_change"] == pytest.approx(a["volume_change"], rel=1e-6)


# ------------------------------------------------------------------------------ refusals
def test_compare_refusals(cli_in_process, tmp_path):
    block = uniaxial_scene(Model("hybmss"), Material(1e4, 0.3, 1000.0), strain=1e-3, n=2, le=0.5)
    path = _write(tmp_path, block)
    loose = Scene(Body.box(2, 2, 2, 0.5), Material(1e4, 0.3, 1000.0), Model("hybmss"),
                  plates=(Plate("floor", "z-", Motion("slide", components=(2,))),), gravity=(0, 0, -9.81))
    free = _write(tmp_path, loose, "free.json")
    run = lambda *a: cli_in_process(*a, cwd=tmp_path)  # noqa: E731
    _refused(run("compare"), "compare needs an experiment (compression")
    _refused(run("compare", "compression", "--scene-json", path), "--scene-json is not allowed with the experiment")
    _refused(run("compare", "--scene-json", path, "--E", "5"), "--scene-json is not allowed with --E")
    _refused(run("compare", "--scene-json", free), "not supported (rigid-body motion not prevented)")
    _refused(run("compare", "--scene-json", free, "--json"), "translation along x, translation along y, rotation about z")
    _refused(run("compare", "--scene-json", free, "--solver", "explicit"), "not supported (rigid-body motion")
    _refused(run("fem", "--scene-json", free), "not supported (rigid-body motion not prevented)")
    _refused(run("compare", "--scene-json", str(tmp_path / "missing.json")), "cannot read it")
    _refused(run("compare", "compression", "--solver", "explicit", "--load-steps", "3"),
             "--load-steps = 3 is not allowed: the explicit solver does not use it")
    _refused(run("compare", "compression", "--model", "xpbd-nh", "--load-steps", "3"),
             "model xpbd-nh has its own static solver")
    _refused(run("compare", "compression", "--load-steps", "0"), "expected an integer >= 1, got '0'")
    # nothing was written
    assert sorted(p.name for p in tmp_path.iterdir()) == ["free.json", "scene.json"]


def test_relative_errors_of_known_numbers():
    """|F_mss − F_fem|/|F_fem| of (0, 3, 4) against (0, 0, 4) is 3/4; volume errors are signed;
    a zero reference gives no number."""
    side = lambda F, dv, dvF=None: {"reactions": {"top": {"force": F}},  # noqa: E731
                                    "volume_change_avg_edges": dv, "volume_change_det_F": dvF}
    u_fem = np.array([[0.0, 0.0, 2.0], [0.0, 0.0, 1.0]])
    u_mss = np.array([[0.0, 0.0, 2.2], [0.0, 0.0, 1.0]])
    e = compare.relative_errors(side([0, 3, 4], -0.011), side([0, 0, 4], -0.010, -0.020), u_mss, u_fem)
    assert e["force"]["top"] == pytest.approx(0.75)
    assert e["volume_change_avg_edges"] == pytest.approx(-0.1) and e["volume_change_vs_det_F"] == pytest.approx(0.45)
    assert e["displacement_max"] == pytest.approx(0.1) and e["displacement_l2"] == pytest.approx(0.2 / np.sqrt(5))
    e = compare.relative_errors(side([0, 0, 1], 0.0), side([0, 0, 0], 0.0, 0.0), u_mss, u_fem)
    assert e["force"]["top"] is None and e["volume_change_avg_edges"] is None


def test_compare_help_states_the_units(cli_in_process):
    p = cli_in_process("compare", "--help")
    assert p.returncode == 0
    for words in ("fractions in the text and in --json alike", "averaged-edge volume", "det F", "--no-e-form",
                  "--load-steps", "--scene-json"):
        assert words in " ".join(p.stdout.split()), words
