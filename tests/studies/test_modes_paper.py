"""The reproduction's natural frequencies (:mod:`studies.paper.modes_study`, quick level) and their report
section (:mod:`reports.modes`) from stored rows only.

Theory for the quick beam (the bending experiment's 2×2×12 cantilever) at ν = 0, where its axial
modes are one-dimensional (no Poisson coupling: a field u_z uniform over each layer is exact):
the FEM's first axial mode approaches the clamped–free bar's f₁ = √(E/ρ) / (4L) (Hex2, error
O(h⁴)); corot-hex8 at rest is Hex1 with row-sum lumped mass, whose axial modes on N cells are the
spring–mass chain's, f₁ = √(E/(ρ h²)) sin(π / (4N)) / π.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    from studies.paper import modes_study
    from studies.sweep.store import Store

    out = tmp_path_factory.mktemp("modes")
    modes_study.run(Store(out), quick=True)
    return out, {n: pd.read_csv(out / "tables" / f"{n}.csv") for n in modes_study.TABLES}


def test_quick_tables_have_a_row_per_model_and_nu(quick):
    from studies.paper import modes_study

    _, t = quick
    names = modes_study.modal_models()
    assert {"hybmss", "hybmss-cf", "corot-hex8"} <= set(names) and "xpbd-nh" not in names
    for body, mesh in (("cube", "4x4x4"), ("beam", "2x2x12")):
        df = t[f"modes_{body}"]
        assert len(df) == len(names) * len(modes_study.NUS)
        assert set(zip(df["model"], df["nu"])) == {(m, nu) for m in names for nu in modes_study.NUS}
        assert (df["mesh"] == mesh).all() and (df["status"] == "ok").all()
        assert (df["fem_element"] == np.where(df["nu"] >= 0.45, "mixed", "hex2")).all()
        assert df[["bending_error_pct", "torsion_error_pct", "min_mac"]].notna().all(axis=None)
    beam = t["modes_beam"]
    assert beam["axial_error_pct"].notna().all()


def test_quick_beam_axial_mode_is_the_bar_and_the_lumped_chain(quick):
    from hybmss.experiments import SceneSpec

    _, t = quick
    scene = SceneSpec.default("bending", mesh=(2, 2, 12), nu=0.0).build()
    E, rho, h, N = scene.material.E, scene.material.rho, scene.body.le, scene.body.shape[2]
    bar = math.sqrt(E / rho) / (4 * N * h)
    chain = math.sqrt(E / (rho * h * h)) * math.sin(math.pi / (4 * N)) / math.pi
    row = t["modes_beam"][(t["modes_beam"]["model"] == "corot-hex8") & (t["modes_beam"]["nu"] == 0.0)].iloc[0]
    assert row["axial_f_ref_hz"] == pytest.approx(bar, rel=1e-4)
    assert row["axial_error_pct"] == pytest.approx(100 * (chain / row["axial_f_ref_hz"] - 1), abs=1e-7)
    pairs = t["modes_pairs"]
    first = pairs[(pairs["body"] == "beam") & (pairs["nu"] == 0.0) & (pairs["kind"] == "axial")]
    assert len(first) >= len(set(first["model"])) and (first["mac"] > 0.99).all()


ROWS = [  # model, nu, bending, torsion, axial, min MAC
    ("alpha", 0.0, 1.0, -2.0, 0.5, 0.999), ("alpha", 0.25, 1.5, -2.5, 0.4, 0.998),
    ("alpha", 0.499, 2.0, -3.0, 0.6, 0.997),
    ("beta", 0.0, 3.0, -4.0, 0.1, 0.99), ("beta", 0.25, 6.0, -4.0, 2.0, 0.98),
    ("beta", 0.499, 40.0, -4.0, 18.0, 0.95),
]


def _store(tmp_path: Path) -> Path:
    from studies.sweep.store import Store

    store = Store(tmp_path / "results")
    rows = [{"body": "beam", "mesh": "2x2x12", "nu": nu, "model": m, "fem_element": "hex2", "status": "ok",
             "bending_error_pct": b, "bending_f_ref_hz": 1.1, "torsion_error_pct": tq, "torsion_f_ref_hz": 6.0,
             "axial_error_pct": a, "axial_f_ref_hz": 10.0, "min_mac": mac, "model_time_s": 0.1, "fem_time_s": 0.5,
             "modes": 8} for m, nu, b, tq, a, mac in ROWS]
    store.write_table("modes_beam", pd.DataFrame(rows))
    return store.root


def test_report_section_from_stored_rows_imports_no_solver(tmp_path):
    root = _store(tmp_path)
    code = f"""
import json, sys
from reports.data import Results
from reports import modes
title, intro, items = modes.section(Results({str(root)!r}), {str(tmp_path / 'fig')!r})
solvers = sorted(m for m in sys.modules if m.split('.')[0] in ('hybmss', 'fem_reference')
                 or m in ('studies.sweep.mode_pairs', 'studies.paper.modes_study', 'studies.study'))
tabs = [i for k, i in items if k == 'table']
figs = [str(i.path) for k, i in items if k == 'figure']
print(json.dumps({{"title": title, "intro": intro, "solvers": solvers, "figs": figs,
                  "tables": [[t.id, t.rows] for t in tabs]}}))
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)})
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["solvers"] == []
    assert len(out["figs"]) == 1 and Path(out["figs"][0]).stat().st_size > 1000
    (tid, rows), = out["tables"]
    assert tid == "table_modes_beam" and len(rows) == len(ROWS)
    beta_top = rows[-1]
    assert [c[0] for c in beta_top[:2]] == ["beta", "0.499"] and beta_top[3] == ["40", "bad"]
    assert rows[0][3] == ["1", "good"] and rows[4][3] == ["6", "warn"]
    intro = out["intro"]
    assert "alpha keeps the first bending, torsion and axial frequencies within 5 %" in intro
    assert "the closest is alpha (at most 3 %, its torsion mode at ν = 0.499)" in intro
    assert "the farthest beta (+40 %, its bending mode at ν = 0.499)" in intro
