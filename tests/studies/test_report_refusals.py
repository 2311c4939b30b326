"""``python -m reports build`` answers in one line, never a traceback: an output folder that cannot
be written is refused (exit 2) before any work; a damaged stored row is left out of the report,
which says so on stderr and in its last line."""

import json
import shutil

import pytest

from reports.__main__ import main
from studies.sweep.runner import Runner, SolverSpec, Task
from studies.sweep.scenes import SceneSpec
from studies.sweep.store import Store


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    root = tmp_path_factory.mktemp("results")
    spec = SceneSpec.default("compression", mesh=(3, 3, 3), nu=0.25, deformation=0.05)
    tasks = [Task(spec, SolverSpec("static"), "compression"),
             Task(spec, SolverSpec("fem", element="hex1", law="linear"), "compression")]
    Runner(jobs=1, progress=False).run(tasks, Store(root))
    return root, tasks[0].key()


def build(capsys, *argv):
    status = main(["build", "--no-pdf", "--quiet", *map(str, argv)])
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    return status, out, err


@pytest.mark.parametrize("where", ["file", "under a file"])
def test_an_output_folder_that_cannot_be_written_is_refused_before_work(where, results, tmp_path, capsys):
    root, _ = results
    (tmp_path / "f").write_text("x")
    out = tmp_path / "f" if where == "file" else tmp_path / "f" / "report"
    status, stdout, err = build(capsys, "--results", root, "--out", out)
    assert status == 2 and stdout == ""
    assert len(err.strip().splitlines()) == 1 and "--out" in err and "allowed" in err


@pytest.mark.parametrize("damage", ["nested", "nonfinite holds a string", "value edited"])
def test_a_damaged_row_is_left_out_and_said(damage, results, tmp_path, capsys):
    root, key = results
    shutil.copytree(root, tmp_path / "r")
    js = tmp_path / "r" / "runs" / f"{key}.json"
    if damage == "nested":
        js.write_text("[" * 100_000 + "]" * 100_000)
    else:
        row = json.loads(js.read_text())
        if damage == "value edited":
            row["volume_change"] *= 1.5
        else:
            row["nonfinite"] = "nan"
        js.write_text(json.dumps(row))
    status, stdout, err = build(capsys, "--results", tmp_path / "r", "--out", tmp_path / "report")
    assert status == 0
    assert key in err and "damaged run left out" in err
    assert stdout.strip().endswith("1 damaged run(s) left out (see the warnings)")
    html = (tmp_path / "report" / "index.html").read_text()
    assert key in html  # the report names it too
