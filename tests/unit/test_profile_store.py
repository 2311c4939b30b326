"""The reproduction's profile (benchmarks.profile_store) from a store written here: the seconds it
sums are those of the rows, grouped as stated, and its command keeps the CLI contract."""

import json

import pytest

from benchmarks import profile_store
from studies.sweep.store import Store

ROWS = [  # (study, model, kind, status, elapsed_s, skipped)
    ("tension", "xpbd-nh", "explicit", "not-converged", 84.0, False),
    ("tension", "xpbd-nh", "static", "ok", 16.0, False),
    ("tension", "hybmss", "static", "ok", 4.0, False),
    ("pareto", "hybmss", "explicit", "not-converged", 0.0, True),
    ("pareto", "hybmss", "explicit", "ok", 2.5, False),
    ("pareto", "corot-hex8", "static", "diverged", 1.5, False),
]


@pytest.fixture()
def store_dir(tmp_path):
    store = Store(tmp_path / "results")
    for i, (study, model, kind, status, s, skipped) in enumerate(ROWS):
        row = {"study": study, "model": model, "solver_kind": kind, "status": status, "elapsed_s": s,
               "label": f"run {i}", "solver": kind}
        if skipped:
            row["skipped"] = True
        store.save(f"{i:024x}", row)
    return tmp_path


def test_sums_per_study_model_and_bound(store_dir):
    p = profile_store.profile(store_dir, workers=2)
    by = {g["study"]: g for g in p["by_study"]}
    assert p["runs"] == len(ROWS)
    assert by["tension"]["cpu_s"] == pytest.approx(104.0)
    assert by["tension"]["not_at_rest_s"] == pytest.approx(84.0)
    assert by["pareto"] == {**by["pareto"], "runs": 3, "computed": 2, "skipped": 1, "not_at_rest": 1, "failed": 1}
    assert by["tension"]["share"] == pytest.approx(104.0 / 108.0)
    assert [g["study"] for g in p["by_study"]] == ["tension", "pareto"]  # costliest first
    pm = {(g["study"], g["model"]): g["cpu_s"] for g in p["by_study_model"]}
    assert pm[("tension", "xpbd-nh")] == pytest.approx(100.0)
    assert p["bound"]["per_worker_s"] == pytest.approx(54.0)
    assert p["bound"]["longest_s"] == pytest.approx(84.0)
    assert p["longest"][0]["label"] == "run 0"


def test_command_json_and_bad_folder(store_dir, tmp_path, capsys):
    assert profile_store.main([str(store_dir), "--json"]) == 0
    out = json.loads(capsys.readouterr().out, parse_constant=lambda c: pytest.fail(c))
    assert out["bound"]["cpu_s"] == pytest.approx(108.0)
    assert profile_store.main([str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("dir:")
