"""The result store heals: every kind of damage is reported, moved aside and recomputed, and the
tables built from the healed store equal the tables of the undamaged one; rows are strict JSON;
claims keep two processes from computing one run and never outlive their process."""

import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pandas as pd
import pytest

from reports.data import Results
from studies.sweep.runner import Runner, SolverSpec, Task
from studies.sweep.scenes import SceneSpec
from studies.sweep.store import Store, arrays_digest, code_version, dumps, loads
from studies.paper.tables import differences_table, runs_frame, volume_table


def tiny_tasks() -> list[Task]:
    """Compression of a 3³ cube at two ν: hybmss and hybmss-fd static, and the linear FEM."""
    tasks = []
    for nu in (0.0, 0.25):
        spec = SceneSpec.default("compression", mesh=(3, 3, 3), nu=nu, deformation=0.05)
        for model in ("hybmss", "hybmss-fd"):
            tasks.append(Task(spec.replace(model=model), SolverSpec("static"), "compression"))
        tasks.append(Task(spec, SolverSpec("fem", element="hex1", law="linear"), "compression"))
    return tasks


def tables(store: Store) -> dict[str, pd.DataFrame]:
    df = runs_frame(store)
    return {"volume": volume_table(df, "compression", "g20_table2_compression"),
            "differences": differences_table(df, store)}


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    root = tmp_path_factory.mktemp("base")
    store = Store(root)
    Runner(jobs=1, progress=False).run(tiny_tasks(), store)
    return root, tables(store)


def _keys():
    return [t.key() for t in tiny_tasks()]


def _damage(store: Store, kind: str) -> str:
    """Apply one kind of damage; return the key it hits."""
    mss, fem = _keys()[0], _keys()[2]
    js, npz = store.runs / f"{mss}.json", store.runs / f"{mss}.npz"
    if kind == "truncated json":
        js.write_bytes(js.read_bytes()[: len(js.read_bytes()) // 2])
    elif kind == "empty json":
        js.write_bytes(b"")
    elif kind == "{} as a row":
        js.write_text("{}")
    elif kind == "row of another run":
        shutil.copy(store.runs / f"{fem}.json", js)
    elif kind == "truncated npz":
        npz.write_bytes(npz.read_bytes()[:-200])
    elif kind == "npz of another run":
        shutil.copy(store.runs / f"{_keys()[3]}.npz", npz)  # hybmss at the other nu
    elif kind == "npz missing":
        npz.unlink()
    return mss


DAMAGE = ["truncated json", "empty json", "{} as a row", "row of another run", "truncated npz",
          "npz of another run", "npz missing"]


@pytest.mark.parametrize("kind", DAMAGE)
def test_damaged_run_is_reported_moved_aside_and_recomputed(kind, base, tmp_path, capsys):
    root, want = base
    shutil.copytree(root, tmp_path / "r")
    store = Store(tmp_path / "r")
    key = _damage(store, kind)
    # the report's reader names the damaged run instead of dropping it silently
    res = Results(store.root)
    assert [d.key for d in res.damaged] == [key]
    assert key not in set(res.rows["key"])
    runner = Runner(jobs=1, progress=False)
    rows = runner.run(tiny_tasks(), store)
    s = runner.summary
    assert (s.computed, s.stored, len(s.damaged)) == (1, len(rows) - 1, 1)
    assert key in capsys.readouterr().err  # reported on stderr
    moved = sorted(p.name for p in store.damaged_dir.iterdir())
    assert any(n.startswith(key) and n.endswith(".reason.txt") for n in moved)
    assert store.scan()[1] == []  # nothing damaged is left
    got = tables(store)
    for name in want:
        pd.testing.assert_frame_equal(got[name], want[name])
    assert Results(store.root).damaged == []


def test_npz_of_another_run_would_change_the_differences(base, tmp_path):
    """The swap the checksum catches matters: with the other run's arrays the nodal difference
    against the FEM changes (the table computed from the damaged files is wrong)."""
    root, want = base
    shutil.copytree(root, tmp_path / "r")
    store = Store(tmp_path / "r")
    key = _damage(store, "npz of another run")
    with np.load(store.runs / f"{key}.npz") as z:
        swapped = {k: z[k] for k in z.files}
    assert arrays_digest(swapped) != store.row(key)["arrays_sha256"]
    row = want["differences"][want["differences"]["mss_key"] == key].iloc[0]
    fem = np.load(store.runs / f"{row['fem_key']}.npz")["u"]
    rel = np.linalg.norm(swapped["u"] - fem) / np.linalg.norm(fem)
    assert abs(rel - row["rel_l2"]) > 1e-3


def test_orphan_temporary_file_is_removed(base, tmp_path):
    """A temporary file left by a process killed while writing is deleted by the next sweep;
    nothing is recomputed."""
    root, _ = base
    shutil.copytree(root, tmp_path / "r")
    store = Store(tmp_path / "r")
    key = _keys()[0]
    orphan = store.runs / f".{key}.json.abc123.tmp"
    orphan.write_text('{"key": "')
    runner = Runner(jobs=1, progress=False)
    runner.run(tiny_tasks(), store)
    assert runner.summary.orphans == 1 and runner.summary.computed == 0
    assert not orphan.exists()
    assert not list(store.runs.glob(".*.tmp"))


def test_rows_are_strict_json_and_keep_their_nan(tmp_path):
    store = Store(tmp_path)
    key = "a" * 24
    row = {"status": "ok", "x": float("nan"), "y": float("inf"), "z": -np.inf, "w": np.float64(2.5),
           "info": {"r": float("nan"), "s": "text"}, "A": None}
    store.save(key, row, {"u": np.arange(3.0)})
    text = (store.runs / f"{key}.json").read_text()
    loads(text)  # strict: NaN and Infinity are rejected by the parser
    stored = json.loads(text)
    assert stored["x"] is None and stored["y"] is None and stored["info"]["r"] is None
    back = store.row(key)
    assert np.isnan(back["x"]) and back["y"] == np.inf and back["z"] == -np.inf
    assert np.isnan(back["info"]["r"]) and back["A"] is None and back["w"] == 2.5
    with pytest.raises(ValueError):
        loads('{"a": NaN}')
    assert "NaN" not in dumps({"a": float("nan")})


def test_lock_of_a_killed_process_does_not_block(tmp_path):
    """A run claimed by a process that was then killed (SIGKILL) is computed by the next sweep:
    the claim died with its process, though its lock file is still there."""
    store = Store(tmp_path)
    task = tiny_tasks()[0]
    code = textwrap.dedent(f"""
        import sys, time
        from studies.sweep.store import Store
        claim = Store({str(tmp_path)!r}).claim({task.key()!r})
        print("claimed" if claim else "refused", flush=True)
        time.sleep(60)
    """)
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "claimed"
        assert store.claim(task.key()) is None  # held by a live process
        os.kill(p.pid, signal.SIGKILL)
        p.wait(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    assert (store.locks / f"{task.key()}.lock").exists()
    runner = Runner(jobs=1, progress=False)
    (row,) = runner.run([task], store)
    assert row["status"] == "ok" and runner.summary.computed == 1
    assert not list(store.locks.iterdir())  # released claims leave no lock file


def test_out_that_cannot_be_a_folder_is_refused_before_work(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    for out, words in ((f, "is a file"), (f / "sub", "not a folder"), ("/dev/null/results", "not a folder")):
        with pytest.raises(ValueError, match=words):
            Runner(jobs=1, progress=False).run(tiny_tasks()[:1], Store(out))
    with pytest.raises(ValueError, match="folder path is required"):
        Store("")
    assert f.read_text() == "x"


@pytest.mark.parametrize("kw, words", [
    (dict(jobs=0), "jobs 0"), (dict(jobs=-1), "jobs -1"), (dict(executor="ssh"), "executor 'ssh'"),
    (dict(scheduler="tcp://h:8786"), "needs executor dask")])
def test_runner_arguments_are_checked(kw, words):
    with pytest.raises(ValueError, match=words):
        Runner(**kw)


def test_results_of_other_solver_code_are_not_stored(tmp_path, monkeypatch):
    """A worker whose hybmss differs from this process's (its rows name another code version)
    stops the sweep instead of storing its results under this code's keys."""
    import studies.sweep.runner as runner_mod
    from studies.sweep.executors import SweepError

    real = runner_mod.compute

    def other_version(task, key=None):
        row, arrays = real(task, key)
        return {**row, "env_code_version": "0" * 16}, arrays

    monkeypatch.setattr(runner_mod, "compute", other_version)
    store = Store(tmp_path)
    with pytest.raises(SweepError, match="code version"):
        Runner(jobs=1, progress=False).run(tiny_tasks()[:1], store)
    assert store.keys() == [] and not list(store.locks.iterdir())


def test_interrupt_leaves_no_temporary_file_of_a_killed_writer(tmp_path, monkeypatch):
    """Ctrl-C while a worker writes: the worker is killed and its temporary file is left behind;
    the interrupted sweep deletes it before it returns (not only the next sweep)."""
    import studies.sweep.runner as runner_mod
    from studies.sweep.runner import Interrupted

    store = Store(tmp_path)

    def killed_while_writing(task, key=None):
        store.runs.mkdir(parents=True, exist_ok=True)
        (store.runs / f".{key}.npz.k6n8qeef.tmp").write_bytes(b"PK\x03")  # a half-written run
        raise KeyboardInterrupt

    monkeypatch.setattr(runner_mod, "compute", killed_while_writing)
    with pytest.raises(Interrupted):
        Runner(jobs=1, progress=False).run(tiny_tasks()[:1], store)
    assert not list(store.runs.glob(".*.tmp"))
    assert store.keys() == [] and not list(store.locks.iterdir())


def test_rows_and_tables_of_another_code_version_are_left_out(base, tmp_path):
    """A row stored under another code hash is not among the store's rows, the tables built from
    them nor the report's rows (unless asked for every version); a table written by another code
    version is not read by the report."""
    root, want = base
    shutil.copytree(root, tmp_path / "r")
    store = Store(tmp_path / "r")
    key = _keys()[0]
    row = store.row(key)
    assert row["code_version"] == code_version("mss")
    stale = {**row, "key": "e" * 24, "code_version": "0" * 16}
    store.save(stale["key"], stale, store.arrays(key))
    fem = store.row(_keys()[2])
    assert fem["code_version"] == code_version("fem")  # a FEM row keeps the FEM side's version
    keys = {r["key"] for r in store.rows()}
    assert "e" * 24 not in keys and keys == set(_keys())
    assert {r["key"] for r in store.rows(all_versions=True)} == keys | {"e" * 24}
    got = tables(store)
    pd.testing.assert_frame_equal(got["volume"], want["volume"])
    res = Results(store.root)
    assert set(res.rows["key"]) == keys
    assert set(Results(store.root, all_versions=True).rows["key"]) == keys | {"e" * 24}
    # tables: the one written by this code is read, one of another version is not
    store.write_table("mine", pd.DataFrame({"a": [1]}))
    store.write_table("old", pd.DataFrame({"a": [2]}))
    (store.root / "tables" / "old.version").write_text("0" * 16 + "\n")
    res = Results(store.root)
    assert res.table("mine") is not None and res.table("old") is None
    assert "old" in res.other_version_tables and "old" not in res.table_names()
    assert Results(store.root, all_versions=True).table("old") is not None


# CPU seconds of single runs of `make reproduce-paper`, measured on the 2-core machine (load 2,
# two workers, fresh caches): the longest runs and, for contrast, short ones.
MEASURED_S = {
    ("tension", (8, 8, 48), "hybmss-fd-Eform", 0.499, 0.2, "static"): 134.8,
    ("tension", (8, 8, 48), "xpbd-nh", 0.499, 0.05, "explicit"): 120.3,
    ("tension", (8, 8, 48), "hybmss-fd", 0.499, 0.2, "static"): 48.4,
    ("tension", (8, 8, 48), "xpbd-nh", 0.499, 0.05, "static"): 37.0,
    ("tension", (8, 8, 48), "xpbd-nh", 0.25, 0.05, "explicit"): 9.6,
    ("tension", (8, 8, 48), "hybmss", 0.499, 0.05, "static"): 0.5,
    ("compression", (10, 10, 10), "hybmss", 0.25, 0.05, "explicit"): 0.1,
    ("compression", (10, 10, 10), "hybmss", 0.25, 0.05, "static"): 0.1,
}


def test_sweep_starts_with_its_longest_runs():
    """The expected costs that order a sweep (longest first, so that no core idles behind a long
    run at the end) rank the measured runs of the reproduction as their measured times do."""
    from studies.paper.reproduce import STUDIES, tasks_for
    from studies.sweep.runner import _expected_cost

    found = {}
    for t in tasks_for(list(STUDIES), False):
        sc = t.scene
        name = sc.model + ("-Eform" if dict(sc.params).get("e_form") else "")
        k = (sc.experiment, tuple(sc.mesh), name, sc.nu, sc.deformation, t.solver.kind)
        if k in MEASURED_S:
            found[k] = _expected_cost(t)
    assert set(found) == set(MEASURED_S)
    by_time = sorted(MEASURED_S, key=MEASURED_S.get, reverse=True)
    by_cost = sorted(found, key=found.get, reverse=True)
    long = [k for k in by_time if MEASURED_S[k] >= 30.0]
    assert set(by_cost[:len(long)]) == set(long)
    assert by_time[0] in by_cost[:2] and by_time[1] in by_cost[:3]


def test_a_row_keeps_its_scene_under_the_specifications_own_names(base):
    """A stored run records its scene as :meth:`SceneSpec.to_dict` names it (no ``scene_``
    prefix), lists those fields, and the scene it records rebuilds the very scene that was run
    (same digest); the tables name the same quantities the same way."""
    from studies.paper.tables import spec_of

    root, tabs = base
    store = Store(root)
    for task in tiny_tasks():
        row = store.row(task.key())
        scene = task.scene.to_dict()
        assert {k: row[k] for k in scene} == scene
        assert row["scene_fields"].split() == list(scene)
        assert not [k for k in row if k.startswith("scene_") and k != "scene_fields"]
        assert spec_of(row).build().digest() == task.scene.build().digest()
        assert row["solver_iterations"] >= 1 and "iterations" not in row or "iterations" in scene
    assert set(Results(root).scene_columns()) == {k for t in tiny_tasks() for k in t.scene.to_dict()}
    assert {"mesh", "nu", "deformation"} <= set(tabs["volume"].columns)
    assert {"experiment", "mesh", "nu", "E", "deformation", "angle_deg"} <= set(tabs["differences"].columns)


def test_the_code_version_hashes_the_solvers_sources():
    """Each side's version is a hash of its solver's files: the MSS side reads every module of
    hybmss, the FEM side those of fem_reference and hybmss's scene, lattice and result, and no
    side is the hash of nothing."""
    import hashlib

    from studies.sweep.store import SOURCE_ROOT, source_files

    mss = {f.relative_to(SOURCE_ROOT).as_posix() for f in source_files("mss")}
    fem = {f.relative_to(SOURCE_ROOT).as_posix() for f in source_files("fem")}
    assert {"hybmss/lattice.py", "hybmss/explicit/loop.py", "hybmss/models/hybmss/stepper.py"} <= mss
    assert {"fem_reference/solve.py", "hybmss/lattice.py", "hybmss/result.py"} <= fem
    assert not any(f.startswith("fem_reference/") for f in mss)
    nothing = hashlib.sha256().hexdigest()[:16]
    assert nothing not in {code_version("mss"), code_version("fem"), code_version()}


def test_a_run_records_the_processors_model_not_only_its_architecture(tmp_path):
    """The timings depend on the processor: a row names its model (Linux's ``model name``, not the
    numeric ``model`` line before it), and falls back to the architecture where nothing says more."""
    from studies.sweep.store import cpu_model

    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nvendor_id\t: GenuineIntel\nmodel\t\t: 106\n"
                    "model name\t: Intel(R) Xeon(R)   Processor @ 2.80GHz\nflags\t\t: fpu avx512f\n")
    assert cpu_model(str(info)) == "Intel(R) Xeon(R) Processor @ 2.80GHz"
    import platform

    if platform.system() != "Darwin":  # there the brand string comes from sysctl
        assert cpu_model(str(tmp_path / "absent")) == (platform.processor() or platform.machine())
    if os.path.exists("/proc/cpuinfo") and "model name" in open("/proc/cpuinfo").read():
        from studies.sweep.store import environment

        assert environment()["processor"] not in (platform.machine(), "")
