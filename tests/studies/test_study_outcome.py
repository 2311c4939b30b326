"""``hybmss study`` tells what its runs came to: a run without result is a failure (exit 3, one
stderr line, the same count in every place) unless the study file expects that kind of no result;
a budget no model meets, or a model without any error, is a line of the answer, not a crash; a
result out of double precision's range is never published as an infinite number."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from study_files import changed, small_study, write

ROOT = Path(__file__).resolve().parents[2]


def _no_constant(name):
    raise ValueError(f"non-strict JSON constant {name}")


def _study(tmp_path, edit, name="s.toml") -> Path:
    return write(changed(small_study(), edit), tmp_path / name)


def _json(proc) -> dict:
    assert len(proc.stdout.strip().splitlines()) == 1, proc.stdout
    return json.loads(proc.stdout, parse_constant=_no_constant)


def _cut_explicit(doc, expect=None):
    """A second model, explicit, cut at 5 steps: far from rest."""
    doc["model"].append({"name": "hybmss", "label": "cut", "solver": {"kind": "explicit", "dt": 1e-4, "steps": 5}})
    if expect is not None:
        doc["model"][-1]["expect_no_result"] = expect


def test_a_failed_run_exits_3_with_one_count_everywhere(tmp_path, cli_in_process):
    """Self-weight of 1e9 m/s² on the block: the static solve fails.  Exit 3 (was 0 with
    "status": "ok" and failed 0 beside summary.failed 1), one stderr line, the counts agree."""
    f = _study(tmp_path, lambda d: d["load_case"][0].update(gravity=[0.0, 0.0, -1e9]))
    args = ("study", f, "--out", tmp_path / "out", "--jobs", "1", "--no-report", "--no-progress")
    proc = cli_in_process(*args, "--json")
    assert proc.returncode == 3, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and "1 of 2 runs" in proc.stderr
    obj = _json(proc)
    assert obj["status"] == "failed" and obj["failed"] == obj["summary"]["failed"] == len(obj["failures"]) == 1
    assert obj["expected"] == obj["summary"]["expected"] == 0 and obj["results"] == 1
    assert obj["failures"][0].startswith("hybmss 0.01 m press: unstable")
    again = cli_in_process(*args)  # stored: the same failure, counted again, the same exit
    assert again.returncode == 3 and "1 of 2 runs" in again.stderr and len(again.stderr.strip().splitlines()) == 1


def test_a_run_not_at_rest_fails_unless_the_file_expects_it(tmp_path, cli_in_process):
    plain = _study(tmp_path, _cut_explicit, "plain.toml")
    proc = cli_in_process("study", plain, "--out", tmp_path / "o1", "--jobs", "1", "--no-report", "--no-progress",
                          "--json")
    assert proc.returncode == 3 and "not at rest after 5 steps" in proc.stderr
    assert _json(proc)["failed"] == 1

    expected = _study(tmp_path, lambda d: _cut_explicit(d, ["not-at-rest"]), "expected.toml")
    out = tmp_path / "o2"
    proc = cli_in_process("study", expected, "--out", out, "--jobs", "1", "--no-report", "--no-progress", "--json")
    assert proc.returncode == 0, proc.stderr
    obj = _json(proc)
    assert obj["failed"] == obj["summary"]["failed"] == 0 and obj["failures"] == []
    assert obj["expected"] == obj["summary"]["expected"] == 1 and obj["runs"] == obj["summary"]["runs"] == 3
    assert obj["expected_no_result"] == ["cut 0.01 m press: not-converged: not at rest after 5 steps"]
    row = [b for b in obj["budget"] if b["method"] == "cut"]
    assert len(row) == 1 and row[0]["answer"] == "no result" and "not at rest after 5 steps" in row[0]["failure"]
    text = cli_in_process("study", expected, "--out", out, "--no-report", "--no-progress")
    assert text.returncode == 0
    assert "0 failed, 1 without result as expected (small, not at rest within its step budget: 1)" in text.stdout
    assert "press: cut no result (not-converged: not at rest after 5 steps)" in text.stdout

    wrong = _study(tmp_path, lambda d: _cut_explicit(d, ["diverged"]), "wrong.toml")  # another kind: a failure
    proc = cli_in_process("study", wrong, "--out", out, "--no-report", "--no-progress")
    assert proc.returncode == 3


def test_expect_no_result_is_checked_before_work(tmp_path, cli_in_process):
    f = _study(tmp_path, lambda d: _cut_explicit(d, ["not at rest"]))
    proc = cli_in_process("study", f, "--out", tmp_path / "out", "--no-progress")
    assert proc.returncode == 2 and "model[1].expect_no_result" in proc.stderr
    assert "(did you mean not-at-rest?)" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_a_budget_no_model_meets_and_a_model_without_error(tmp_path, cli_in_process):
    """Budget 1e-9: no model meets it.  A study that measures no displacement error (E = 1e300
    under self-weight did: its displacement was 0 to double precision; the file check now refuses
    that E): the budget has no error to rank (the summary raised TypeError on its None)."""
    tight = _study(tmp_path, lambda d: d["study"].update(budgets=[1e-9]), "tight.toml")
    proc = cli_in_process("study", tight, "--out", tmp_path / "o1", "--jobs", "1", "--no-report", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert "press: u_rel_l2 <= 1e-09: no model meets it" in proc.stdout
    assert "press: hybmss meets no budget (smallest error" in proc.stdout

    from studies.cli.study import _budget_line

    row = {"answer": "meets no budget", "error": None, "load_case": "press", "method": "hybmss"}
    assert _budget_line(row) == "  press: hybmss meets no budget (no error measured)"


def test_no_infinite_number_is_published():
    """E = 1e300 compressed 1 % (which the file check now refuses) gave plate forces of about
    4e294 N, finite; their norm squared overflowed, and the table said -inf (status ok).  The
    error measures scale their vectors before squaring: finite, and the same as at forces 1e-290
    times as large (the measures are homogeneous of degree 0)."""
    from studies.study.metrics import published_relative, relative, scaled

    a, b = np.array([1.0e293, 0.0, -4.2e294]), np.array([0.0, 2.0e292, -4.0e294])
    big = (relative(a, b), scaled(a, b, 4.0e294), published_relative(a, b, 4.0e294, 0.0))
    small = (relative(a * 1e-290, b * 1e-290), scaled(a * 1e-290, b * 1e-290, 4.0e4),
             published_relative(a * 1e-290, b * 1e-290, 4.0e4, 0.0))
    assert np.isfinite(big).all() and np.allclose(big, small, rtol=1e-12)
    assert np.isclose(big[0], np.linalg.norm(a / 1e294 - b / 1e294) / np.linalg.norm(b / 1e294))


def test_library_logs_stay_off_stderr(tmp_path):
    """A mesh file VTK cannot read: VTK's errors came through pyvista's logging as nine lines
    before the one line of the refusal.  A real process (pytest's own log handler would hide them)."""
    (tmp_path / "bad.stl").write_bytes(b"not an stl\x00\x01")
    f = _study(tmp_path, lambda d: d["body"].update(mesh="bad.stl") or d["body"].pop("box"))
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "MPLBACKEND": "Agg"}
    proc = subprocess.run([sys.executable, "-m", "studies", "study", str(f), "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "body.mesh" in proc.stderr


def test_the_report_gives_the_same_counts(tmp_path, cli_in_process):
    from reports.study import build_study_report
    from studies.study import Study

    def both(d):
        d["load_case"][0].update(gravity=[0.0, 0.0, -1e9])  # the static run fails, the explicit one diverges
        _cut_explicit(d, ["not-at-rest", "diverged"])
    f = _study(tmp_path, both)
    out = tmp_path / "out"
    proc = cli_in_process("study", f, "--out", out, "--jobs", "1", "--no-report", "--no-progress", "--json")
    assert proc.returncode == 3
    obj = _json(proc)
    assert (obj["runs"], obj["results"], obj["failed"], obj["expected"]) == (3, 1, 1, 1), obj["failures"]
    page = build_study_report(Study.from_toml(f), out).read_text()
    assert "1 of 3 runs reached a result, 1 failed, 1 reached none as the study file expects" in page
    assert "failed: hybmss 0.01 m press: unstable: StaticSolveError" in page
    assert "no result, as the study file expects: cut 0.01 m press: diverged: DivergenceError" in page
