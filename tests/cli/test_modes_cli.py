"""``hybmss modes``: a model's natural frequencies beside the FEM's, and its refusals.

corot-hex8 at rest is the linear Hex8 element with the lattice's lumped masses, so against the
FEM's Hex1 with lumped mass on the same mesh every frequency error is 0 and every MAC 1
(independent of either code's numbers)."""

from __future__ import annotations

import json

import pytest


def _strict(text: str) -> dict:
    def refuse(name):
        raise ValueError(f"{name} in JSON")

    return json.loads(text, parse_constant=refuse)


def _refused(proc, fragment):
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("hybmss: ") and "Traceback" not in proc.stderr
    assert fragment in proc.stderr, proc.stderr
    assert _strict(proc.stdout)["status"] == "invalid"


def test_corot_hex8_against_fem_hex1_lumped_is_exact(cli_in_process, tmp_path):
    p = cli_in_process("modes", "bending", "--mesh", "2x2x6", "--model", "corot-hex8", "-k", "5",
                       "--element", "hex1", "--mass", "lumped", "--json", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    out = _strict(p.stdout)
    assert out["status"] == "ok" and out["model"] == "corot-hex8" and out["fem"]["element"] == "hex1"
    assert len(out["modes"]) == 5 and len(out["mac"]) == 5 and len(out["mac"][0]) == 10
    for r in out["modes"]:
        assert abs(r["relative_error"]) < 1e-9 and abs(r["relative_error_by_order"]) < 1e-9
        assert r["mac"] == pytest.approx(1.0, abs=1e-9)
    assert out["model_freq_hz"] == pytest.approx(out["fem"]["freq_hz"], rel=1e-9)


def test_text_output_and_auto_element(cli_in_process, tmp_path):
    p = cli_in_process("modes", "bending", "--mesh", "1x1x4", "--nu", "0.49", "-k", "3", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "against FEM mixed" in p.stdout and p.stdout.count("\n") >= 6


@pytest.mark.parametrize("argv, fragment", [
    (("-k", "0"), "-k/--modes"),
    (("-k", "101"), "-k = 101 is not allowed"),
    (("--mesh", "1x1x2", "-k", "30"), "24 free components"),
    (("--model", "xpbd-nh"), "--model = xpbd-nh is not allowed"),
    (("--model", "mujoco-tet"), "no tangent stiffness"),
    (("--model", "nope"), "--model"),
    (("--element", "mixed", "--nu", "0"), "--element = mixed is not allowed"),
    (("--mass", "diagonal"), "--mass"),
])
def test_refusals(cli_in_process, tmp_path, argv, fragment):
    _refused(cli_in_process("modes", "bending", *argv, "--json", cwd=tmp_path), fragment)


def test_needs_a_scene(cli_in_process, tmp_path):
    _refused(cli_in_process("modes", "--json", cwd=tmp_path), "modes needs an experiment")


def test_scene_json_and_a_free_body(cli_in_process, tmp_path):
    from hybmss.scene import Body, Material, Model, Plate, Region, Scene

    held = Scene(Body.box(1, 1, 3, 0.5), Material(1e6, 0.3, 500.0), plates=(Plate("clamp", Region("z-")),),
                 model=Model("hybmss"))
    free = Scene(Body.box(1, 1, 3, 0.5), Material(1e6, 0.3, 500.0), plates=(), model=Model("hybmss"))
    for name, sc in (("held.json", held), ("free.json", free)):
        (tmp_path / name).write_text(json.dumps(sc.to_dict()))
    p = cli_in_process("modes", "--scene-json", tmp_path / "held.json", "-k", "2", "--json", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    out = _strict(p.stdout)
    assert out["scene_digest"] == held.digest() and len(out["model_freq_hz"]) == 2
    _refused(cli_in_process("modes", "--scene-json", tmp_path / "free.json", "--json", cwd=tmp_path),
             "rigid-body motion not prevented")
    _refused(cli_in_process("modes", "bending", "--scene-json", tmp_path / "held.json", "--json", cwd=tmp_path),
             "--scene-json is not allowed with")
