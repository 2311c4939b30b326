"""The ``fem`` subcommand through its real command line."""

import argparse
import json

import pytest

from fem_reference.cli import main, register


def test_fem_json_compression(capsys):
    assert main(["fem", "--mesh", "2x2x2", "--le", "0.5", "--nu", "0.3", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["solver"] == "fem-hex2-linear"
    assert out["reactions"]["top"]["force"][2] < 0 < out["reactions"]["bottom"]["force"][2]
    assert out["scene"]["body"]["shape"] == [2, 2, 2]


@pytest.mark.parametrize("scene", ["tension", "shear", "torsion", "bending"])
def test_fem_scenes_table(capsys, scene):
    assert main(["fem", "--scene", scene, "--mesh", "1x1x2", "--le", "0.2", "--element", "hex1"]) == 0
    assert "fem-hex1-linear" in capsys.readouterr().out


def test_fem_finite_strain_mixed(capsys):
    assert main(["fem", "--mesh", "2x2x2", "--nu", "0.49", "--law", "neo-hookean", "-d", "0.2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["solver"] == "fem-mixed-neo-hookean" and out["converged"]


@pytest.mark.parametrize(
    "argv",
    [["--nu", "0.5"], ["--mesh", "4x4"], ["--le", "-1"], ["--refine", "0"], ["--element", "hex3"],
     ["--scene-json", "/nonexistent.json"], ["--E", "-3"], ["--convergence", "1"]],
)
def test_bad_arguments_exit_2_one_line(capsys, argv):
    with pytest.raises(SystemExit) as exc:
        main(["fem", "--mesh", "1x1x1"] + argv if argv[0] != "--mesh" else ["fem"] + argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "error" in err


def test_scene_json_roundtrip(tmp_path, capsys):
    from hybmss.scene import Body, Material, Motion, Plate, Region, Scene

    sc = Scene(Body.box(1, 1, 2, 0.5), Material(1e4, 0.2), plates=(
        Plate("b", Region("z-")), Plate("t", Region("z+"), Motion("rotate", angle=0.1))))
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(sc.to_dict()))
    assert main(["fem", "--scene-json", str(path), "--element", "hex1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["scene_digest"] == sc.digest()


def test_fem_convergence_json(capsys):
    assert main(["fem", "--mesh", "1x1x2", "--le", "0.5", "--element", "hex1", "--convergence", "1,2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["refinements"] == [1, 2] and "top.Fz" in out["outputs"]
    assert out["finest"]["solver"] == "fem-hex1-linear"


def test_register_adds_fem_subcommand():
    p = argparse.ArgumentParser(prog="x")
    sub = p.add_subparsers(dest="command")
    register(sub)
    args = p.parse_args(["fem", "--mesh", "3x3x3", "--law", "svk"])
    assert args.mesh == (3, 3, 3) and args.law == "svk" and callable(args.func)
