"""``hybmss study`` on the command-line contract: one strict JSON object with --json, exit 2
for options not allowed (before any work, nothing written), the study's summary in text."""

from __future__ import annotations

import json

STUDY = """
[study]
name = "tiny"
budgets = [0.5]
repeats = 1
[body]
box = [0.02, 0.02, 0.02]
cell_sizes = [0.01]
[material]
E = 3000.0
nu = 0.3
[[load_case]]
name = "press"
  [[load_case.support]]
  name = "bottom"
  region = "z-"
  [[load_case.support]]
  name = "top"
  region = "z+"
  motion = "translate"
  displacement = [0.0, 0.0, -0.0002]
[[model]]
name = "hybmss"
[reference]
element = "hex2"
[metrics]
plate_force = ["top"]
"""


def _const(name):
    raise ValueError(f"non-strict JSON constant {name}")


def test_json_is_one_strict_object(tmp_path, cli_in_process):
    (tmp_path / "tiny.toml").write_text(STUDY)
    proc = cli_in_process("study", tmp_path / "tiny.toml", "--out", tmp_path / "out", "--jobs", "1", "--json",
                          "--no-report", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    obj = json.loads(proc.stdout, parse_constant=_const)
    assert obj["status"] == "ok" and obj["runs"] == 2 and obj["report"] is None
    assert obj["budget"][0]["load_case"] == "press" and len(proc.stdout.strip().splitlines()) == 1
    assert obj["budget"][0]["method"] == "hybmss" and obj["budget"][0]["tie"] is False  # alone: no runner-up
    text = cli_in_process("study", tmp_path / "tiny.toml", "--out", tmp_path / "out", "--no-report", "--no-progress")
    assert text.returncode == 0 and "2 already stored" in text.stdout and "press: u_rel_l2 <= 0.5: hybmss at 0.01 m" in text.stdout


def test_options_not_allowed(tmp_path, cli_in_process):
    (tmp_path / "tiny.toml").write_text(STUDY)
    (tmp_path / "afile").write_text("")
    for args, word in ((("--jobs", "0"), "--jobs"), (("--out", tmp_path / "afile"), "afile"),
                       (("--out", ""), "--out")):
        proc = cli_in_process("study", tmp_path / "tiny.toml", *args, "--json")
        assert proc.returncode == 2 and word in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
        assert json.loads(proc.stdout)["status"] == "invalid"
    missing = cli_in_process("study", tmp_path / "nothere.toml", "--out", tmp_path / "o2")
    assert missing.returncode == 2 and "FILE" in missing.stderr and not (tmp_path / "o2").exists()
