"""Results a study computes outside runs (the stability bisections, its irregular-input rows, the
[B09] tables) are kept like runs: each job is stored as soon as it finishes, a finished job is not
computed again, an interrupted study resumes, a damaged result is moved aside and recomputed, and
a stored result comes back exactly (NaN, ±inf, DataFrames included)."""

import json
import math
import multiprocessing
import os
import time

import numpy as np
import pandas as pd
import pytest

from studies.sweep import store as store_module
from studies.sweep.executors import SweepError, map_local, map_stored
from studies.sweep.store import Store, decode, dumps, encode, loads


def job(item):
    """A job that leaves a marker per call (``calls``) and fails while ``dir/fail`` names it."""
    folder, i = item
    fail = os.path.join(folder, "fail")
    if os.path.exists(fail) and open(fail).read().strip() == str(i):
        raise RuntimeError(f"job {i} failed")
    with open(os.path.join(folder, f"call-{i}-{time.monotonic_ns()}"), "w"):
        pass
    return {"i": i, "square": np.int64(i * i), "third": np.float64(i / 3.0), "nan": float("nan"),
            "neg_inf": -math.inf, "values": np.arange(i + 1, dtype=float), "label": f"job {i}"}


def calls(folder) -> list[int]:
    return sorted(int(n.split("-")[1]) for n in os.listdir(folder) if n.startswith("call-"))


def expected(i):
    return {"i": i, "square": i * i, "third": i / 3.0, "nan": float("nan"), "neg_inf": -math.inf,
            "values": [float(v) for v in range(i + 1)], "label": f"job {i}"}


def same(a, b) -> bool:
    """Equal, NaN equal to NaN."""
    return json.dumps(encode(a), sort_keys=True) == json.dumps(encode(b), sort_keys=True)


def test_values_come_back_exactly():
    frame = pd.DataFrame({"n": [1, 2, 3], "x": [0.1, float("nan"), math.inf], "s": ["a", "b", None],
                          "ok": [True, False, True]})
    obj = {"frame": frame, "row": {"x": -math.inf, "y": 1e-300, "z": [1, 2.5, float("nan")]},
           "scalars": [np.float64(0.3), np.int32(7), np.bool_(True)]}
    text = dumps(encode(obj))
    assert "NaN" not in text and "Infinity" not in text  # strict JSON
    back = decode(loads(text))
    pd.testing.assert_frame_equal(back["frame"], frame)
    assert back["row"]["x"] == -math.inf and back["row"]["y"] == 1e-300 and math.isnan(back["row"]["z"][2])
    assert back["scalars"] == [0.3, 7, True] and type(back["scalars"][1]) is int


def test_a_stored_row_keeps_its_column_order(tmp_path):
    store = Store(tmp_path)
    row = {"nu": 0.3, "variant": "hybmss", "dt_crit": 1e-3, "a_last": float("nan")}
    back = store.save_computed("demo", "k", [row])
    assert list(back[0]) == list(row) and list(store.load_computed("demo", "k")[1][0]) == list(row)


def test_each_job_is_computed_once_and_an_interrupted_map_resumes(tmp_path):
    folder = str(tmp_path / "marks")
    os.mkdir(folder)
    store = Store(tmp_path / "results")
    items = [(folder, i) for i in range(4)]
    with open(os.path.join(folder, "fail"), "w") as fh:
        fh.write("2")
    with pytest.raises(RuntimeError, match="job 2 failed"):
        map_stored(store, "demo", job, items, workers=1)
    assert calls(folder) == [0, 1]  # stored as they finished, before the failure
    os.remove(os.path.join(folder, "fail"))
    out = map_stored(store, "demo", job, items, workers=1)
    assert calls(folder) == [0, 1, 2, 3]  # only the missing ones computed
    assert all(same(out[i], expected(i)) for i in range(4))
    again = map_stored(store, "demo", job, items, workers=1)
    assert calls(folder) == [0, 1, 2, 3] and same(again, out)
    # another computation name, job or code version is another key
    keys = {store.computed_key("demo", items[0]), store.computed_key("other", items[0]),
            store.computed_key("demo", items[1])}
    assert len(keys) == 3


@pytest.mark.parametrize("damage", ["truncated", "altered value", "another job's file", "empty"])
def test_damaged_result_is_moved_aside_and_recomputed(damage, tmp_path, capsys):
    folder = str(tmp_path / "marks")
    os.mkdir(folder)
    store = Store(tmp_path / "results")
    items = [(folder, i) for i in range(3)]
    map_stored(store, "demo", job, items, workers=1)
    k1, k2 = store.computed_key("demo", items[1]), store.computed_key("demo", items[2])
    path = store.computed / "demo" / f"{k1}.json"
    text = path.read_text()
    if damage == "truncated":
        path.write_text(text[: len(text) // 2])
    elif damage == "altered value":
        doc = loads(text)
        doc["result"]["third"] = 0.5
        path.write_text(dumps(doc))
    elif damage == "another job's file":
        path.write_text((store.computed / "demo" / f"{k2}.json").read_text())
    else:
        path.write_text("")
    out = map_stored(store, "demo", job, items, workers=1)
    assert calls(folder) == [0, 1, 1, 2]  # the damaged one again, the others not
    assert same(out[1], expected(1))
    assert "damaged stored result moved aside" in capsys.readouterr().out
    assert any(p.name.startswith(k1) for p in store.damaged_dir.iterdir())


def test_orphan_of_a_killed_writer_is_removed(tmp_path):
    folder = str(tmp_path / "marks")
    os.mkdir(folder)
    store = Store(tmp_path / "results")
    map_stored(store, "demo", job, [(folder, 0)], workers=1)
    key = store.computed_key("demo", (folder, 0))
    orphan = store.computed / "demo" / f".{key}.json.abc123.tmp"
    orphan.write_text('{"key": "')
    out = map_stored(store, "demo", job, [(folder, 0)], workers=1)
    assert not orphan.exists() and calls(folder) == [0] and same(out[0], expected(0))


def test_another_code_version_computes_again(tmp_path, monkeypatch):
    folder = str(tmp_path / "marks")
    os.mkdir(folder)
    store = Store(tmp_path / "results")
    map_stored(store, "demo", job, [(folder, 0)], workers=1)
    monkeypatch.setattr(store_module, "code_version", lambda side="all": "another")
    map_stored(store, "demo", job, [(folder, 0)], workers=1)
    assert calls(folder) == [0, 0]


def sleeper(item):
    if item == "fail":
        time.sleep(1.0)  # let the other worker start its long job
        raise ValueError("failed at once")
    time.sleep(120.0)
    return item


@pytest.mark.slow
def test_a_failure_in_the_pool_kills_the_other_workers_at_once():
    t0 = time.monotonic()
    with pytest.raises(ValueError, match="failed at once"):
        map_local(sleeper, ["long", "fail"], workers=2)
    assert time.monotonic() - t0 < 60.0  # not the 120 s the long job would take
    assert not [p for p in multiprocessing.active_children() if p.is_alive()]


def test_pool_results_are_stored_in_item_order(tmp_path):
    folder = str(tmp_path / "marks")
    os.mkdir(folder)
    store = Store(tmp_path / "results")
    items = [(folder, i) for i in range(5)]
    out = map_stored(store, "demo", job, items, workers=2)
    assert [r["i"] for r in out] == list(range(5)) and calls(folder) == list(range(5))
    assert all(same(out[i], expected(i)) for i in range(5))
    assert len(list((store.computed / "demo").glob("*.json"))) == 5


def test_a_dead_worker_is_one_line(tmp_path):
    with pytest.raises(SweepError, match="worker process died"):
        map_local(os._exit, [3, 3], workers=2)


def test_moduli_table_rows_are_measured_once_and_kept(tmp_path, monkeypatch):
    """The moduli table's rows are measured on workers and kept in the store: equal to a serial
    measurement, row by row (E_eff, ν_eff and G_eff of a lattice under its own homogeneous tests),
    and a second table is read from the store without measuring (a measurement now raises)."""
    from studies.paper import tables

    nus = (0.3,)
    store = Store(tmp_path / "results")
    stored = tables.moduli_table(nus=nus, store=store)
    serial = pd.DataFrame([tables._moduli_row((m.to_dict(), 0.3)) for m in tables.moduli_variants(nus)])
    pd.testing.assert_frame_equal(stored, serial)
    assert (stored["status"] == "ok").sum() >= 3

    def no_measurement(*a, **k):
        raise AssertionError("measured again")

    monkeypatch.setattr(tables, "measure_moduli", no_measurement)  # in this process: one worker
    pd.testing.assert_frame_equal(tables.moduli_table(nus=nus, store=store, workers=1), stored)
