"""Damage a stored row can suffer beyond truncation and swaps (tests/studies/test_runner_store.py):
a row nested too deeply to parse, a field of the wrong type, a value edited by hand (the row's own
checksum), another code version at a current key.  Each is named by the report's reader, moved
aside with its reason and recomputed, and the tables of the healed store equal the undamaged
ones; a damaged computed result likewise."""

import json
import shutil

import pandas as pd
import pytest

from reports.data import Results
from studies.sweep.executors import map_stored
from studies.sweep.runner import Runner, SolverSpec, Task
from studies.sweep.scenes import SceneSpec
from studies.sweep.store import ROW_FIELD, DamagedRun, Store, dumps, loads, row_digest
from studies.paper.tables import runs_frame, volume_table


def tiny_tasks() -> list[Task]:
    """Compression of a 3³ cube at ν = 0.25: hybmss static and the linear Hex1 FEM."""
    spec = SceneSpec.default("compression", mesh=(3, 3, 3), nu=0.25, deformation=0.05)
    return [Task(spec, SolverSpec("static"), "compression"),
            Task(spec, SolverSpec("fem", element="hex1", law="linear"), "compression")]


def volume(store: Store) -> pd.DataFrame:
    return volume_table(runs_frame(store), "compression", "g20_table2_compression")


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    root = tmp_path_factory.mktemp("base")
    store = Store(root)
    Runner(jobs=1, progress=False).run(tiny_tasks(), store)
    return root, volume(store)


def _edit(path, change, rehash: bool = False):
    row = json.loads(path.read_text())
    change(row)
    if rehash:
        row[ROW_FIELD] = row_digest(row)
    path.write_text(json.dumps(row, indent=1, sort_keys=True))


def _damage(store: Store, kind: str) -> str:
    key = tiny_tasks()[0].key()
    js = store.runs / f"{key}.json"
    if kind == "nested json":
        js.write_text("[" * 100_000 + "]" * 100_000)
    elif kind == "nonfinite holds a string":
        _edit(js, lambda r: r.update(nonfinite="nan"), rehash=True)
    elif kind == "nonfinite maps to a word":
        _edit(js, lambda r: r.update(nonfinite={"volume_change": "lots"}), rehash=True)
    elif kind == "info holds a list":
        _edit(js, lambda r: r.update(info=[1, 2]), rehash=True)
    elif kind == "value edited":
        _edit(js, lambda r: r.update(volume_change=r["volume_change"] * 1.01))
    elif kind == "code version edited":
        _edit(js, lambda r: r.update(code_version="0123456789abcdef"))
    elif kind == "code version edited, checksum removed":
        _edit(js, lambda r: (r.update(code_version="0123456789abcdef"), r.pop(ROW_FIELD)))
    elif kind == "checksum removed":
        _edit(js, lambda r: r.pop(ROW_FIELD))
    return key


DAMAGE = ["nested json", "nonfinite holds a string", "nonfinite maps to a word", "info holds a list",
          "value edited", "code version edited", "code version edited, checksum removed", "checksum removed"]


@pytest.mark.parametrize("kind", DAMAGE)
def test_damaged_row_is_named_moved_aside_and_recomputed(kind, base, tmp_path, capsys):
    root, want = base
    shutil.copytree(root, tmp_path / "r")
    store = Store(tmp_path / "r")
    key = _damage(store, kind)
    with pytest.raises(DamagedRun):
        store.check(key)
    if kind != "code version edited, checksum removed":  # an older version's row to the reader
        res = Results(store.root)
        assert [d.key for d in res.damaged] == [key]
        assert key not in set(res.rows["key"])
    runner = Runner(jobs=1, progress=False)
    rows = runner.run(tiny_tasks(), store)
    s = runner.summary
    assert (s.computed, s.stored, len(s.damaged)) == (1, len(rows) - 1, 1)
    assert key in capsys.readouterr().err
    reasons = [p.read_text() for p in store.damaged_dir.glob(f"{key}.*.reason.txt")]
    assert len(reasons) == 1 and key in reasons[0]
    assert store.scan()[1] == [] and Results(store.root).damaged == []
    pd.testing.assert_frame_equal(volume(store), want)


def test_the_checksum_covers_every_field_and_not_the_layout(base):
    root, _ = base
    store = Store(root)
    key = tiny_tasks()[0].key()
    row = loads((store.runs / f"{key}.json").read_text())
    assert row[ROW_FIELD] == row_digest(row)
    assert row_digest(json.loads(json.dumps(row, indent=4))) == row[ROW_FIELD]  # layout: the same
    for field in row:
        if field != ROW_FIELD:
            edited = {**row, field: "edited"}
            assert row_digest(edited) != row[ROW_FIELD], field


def square(x):
    return x * x


@pytest.mark.parametrize("damage", ["[" * 100_000 + "]" * 100_000, '{"key": 1}', "not json"])
def test_a_damaged_computed_result_is_computed_again(damage, tmp_path, capsys):
    store = Store(tmp_path)
    assert map_stored(store, "sq", square, [3, 4], workers=1) == [9, 16]
    key = store.computed_key("sq", 3)
    (store.computed / "sq" / f"{key}.json").write_text(damage)
    assert map_stored(store, "sq", square, [3, 4], workers=1) == [9, 16]
    assert "damaged" in capsys.readouterr().out
    assert len(list(store.damaged_dir.glob(f"{key}.*.reason.txt"))) == 1
    assert store.load_computed("sq", key) == (True, 9)
