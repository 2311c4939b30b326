"""The natural-frequency study on two processes writes the tables of a serial run: the same rows in
the same order, the same FEM frequencies and the same first bending, torsion and axial errors.
(The pairs of a model's degenerate modes, e.g. the 4³ cube's 10th and 11th at ν = 0, differ from
one serial run to the next: the eigen-solver's basis of a degenerate space is arbitrary; those
rows are compared by their identity only.  The solves' wall times differ.)"""

import pandas as pd

from studies.paper import modes_study
from studies.sweep.store import Store

PAIR_KEYS = ["body", "experiment", "mesh", "nu", "model", "fem_element", "mode", "f_ref_hz"]


def _same(a: pd.DataFrame, b: pd.DataFrame, cols, rtol: float = 1e-6) -> None:
    pd.testing.assert_frame_equal(a[cols].reset_index(drop=True), b[cols].reset_index(drop=True),
                                  check_exact=False, rtol=rtol, atol=1e-9)


def test_two_processes_write_the_serial_tables(tmp_path):
    serial = {}  # the serial loop over ν of each body (pair_rows), as a single process computes it
    for body in modes_study.BODIES:
        serial[body] = pd.DataFrame(modes_study.pair_rows(body, quick=True))
    pooled = modes_study.run(Store(tmp_path / "pooled"), quick=True, jobs=2)
    assert set(pooled) == set(modes_study.TABLES)
    _same(pd.concat(list(serial.values()), ignore_index=True), pooled["modes_pairs"], PAIR_KEYS)
    for body, rows in serial.items():
        a, b = modes_study.summary(rows), pooled[f"modes_{body}"]
        assert list(a.columns) == list(b.columns) and len(a) == len(b) > 0, body
        # errors in % to 1e-4 of themselves: the tables print 4 digits (the eigen-solves agree to ~1e-8)
        _same(a, b, [c for c in a.columns if not c.endswith("time_s")], rtol=1e-4)
