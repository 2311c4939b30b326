"""``[metrics] modes = k`` of a study file through ``hybmss study``: the table
``<name>_modes_<load case>.csv`` held to closed form, and the refusals of a k not allowed.

Theory: a 1×1×N column of hybmss-cf cells at ν = 1/4 with its lateral components held is the
fixed–free spring–mass chain (per cell the axial stiffness Σ k cos²θ = (λ + 2μ) le, each interior
layer of particles ρ le³, the free end ρ le³ / 2; tests/verification/test_model_modes.py):
ω_j = 2 √(k/m) sin(θ_j / 2), θ_j = (2j − 1)π / (2N).  The continuum it discretizes, a bar of
length L whose lateral motion is held (constrained modulus λ + 2μ), clamped at one end and free at
the other, has f_i = (2i − 1) / (4L) √((λ + 2μ) / ρ): the FEM's modes approach it (Hex2, error
O(h⁴)).  A model without tangent stiffness (xpbd-nh) has one row without numbers.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from study_files import small_study, write

E, NU, RHO, LE, N, K = 1e7, 0.25, 1000.0, 0.5, 12, 3


def column_study() -> dict:
    return {
        "study": {"name": "column", "title": "column of cells", "budgets": [0.05], "repeats": 1},
        "body": {"box": [LE, LE, N * LE], "cell_sizes": [LE]},
        "material": {"E": E, "nu": NU, "rho": RHO},
        "load_case": [{"name": "hang", "gravity": [0.0, 0.0, -9.81], "support": [
            {"name": "clamp", "region": "z-", "motion": "clamped"},
            {"name": "lateral", "region": {"box": [[-1.0, -1.0, -1.0], [9.0, 9.0, 99.0]]}, "motion": "slide",
             "components": ["x", "y"]}]}],
        "model": [{"name": "hybmss-cf"}, {"name": "xpbd-nh"}],
        "reference": {"element": "hex2", "law": "linear", "refine": 1},
        "metrics": {"plate_force": ["clamp"], "modes": K},
    }


@pytest.fixture(scope="module")
def column(tmp_path_factory, cli_in_process):
    tmp = tmp_path_factory.mktemp("column")
    out = tmp / "out"
    proc = cli_in_process("study", write(column_study(), tmp / "column.toml"), "--out", out, "--jobs", "1",
                          "--no-progress", "--no-report")
    assert proc.returncode == 0, proc.stderr
    table = pd.read_csv(out / "tables" / "column_modes_hang.csv")
    table.attrs["out"] = out
    return table


def test_column_modes_are_the_chain_and_the_bar(column):
    lam, mu = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))
    k, m = (lam + 2 * mu) * LE, RHO * LE**3
    j = np.arange(1, K + 1)
    chain = 2 * np.sqrt(k / m) * np.sin((2 * j - 1) * np.pi / (2 * N) / 2) / (2 * np.pi)
    bar = (2 * j - 1) / (4 * N * LE) * math.sqrt((lam + 2 * mu) / RHO)
    rows = column[column["model"] == "hybmss-cf"].sort_values("mode")
    assert list(rows["mode"]) == list(j) and (rows["status"] == "ok").all()
    np.testing.assert_allclose(rows["f_model_hz"], chain, rtol=1e-9)
    np.testing.assert_allclose(rows["f_ref_hz"], bar, rtol=2e-3)
    np.testing.assert_allclose(rows["error_pct"], 100 * (rows["f_model_hz"] / rows["f_ref_hz"] - 1), rtol=1e-12)
    assert (rows["mac"] > 0.999).all() and (rows["kind"] == "axial").all()
    assert (rows["model_time_s"] > 0).all() and (rows["fem_time_s"] > 0).all()


def test_a_model_without_tangent_has_no_modal_answer(column):
    row = column[column["model"] == "xpbd-nh"]
    assert len(row) == 1 and row["status"].iloc[0] == "no modal answer"
    assert row[["f_model_hz", "error_pct", "mac", "f_ref_hz"]].isna().all(axis=None)


@pytest.mark.parametrize("value,allowed", [(0, ">= 1 and <= 100"), (101, ">= 1 and <= 100"), (2.5, "an integer"),
                                           (True, "an integer"), ("6", "an integer"), (12, "[1, 11]")])
def test_modes_not_allowed_is_refused_naming_the_key(tmp_path, cli_in_process, value, allowed):
    doc = small_study()
    doc["body"]["cell_sizes"] = [0.02]  # 1 x 1 x 2 cells: 12 nodes, 8 on the two plates: 12 free components
    doc["metrics"]["modes"] = value
    out = tmp_path / "out"
    proc = cli_in_process("study", write(doc, tmp_path / "study.toml"), "--out", out, "--no-progress")
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "metrics.modes" in lines[0] and "is not allowed" in lines[0], lines
    assert allowed in lines[0], lines[0]
    assert not out.exists()


def test_the_study_report_shows_the_stored_table(column):
    from reports.study_modes import modes_html

    page = modes_html(column.attrs["out"], "column", "hang")
    assert page.count("<tr>") == 1 + len(column) and "no modal answer" in page
    assert f"{column['f_model_hz'].iloc[0]:.4g}" in page
    assert modes_html(column.attrs["out"], "column", "other") is None
