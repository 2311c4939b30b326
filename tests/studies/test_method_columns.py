"""A stored row says what its method is in columns (model, variant, solver kind, FEM element, law,
refine): rows stored without them get them from their solver label on read, once, and the report
finds a table's FEM reference column by those columns, never by its name."""

from __future__ import annotations

import pandas as pd
import pytest

from studies.sweep.results import METHOD_COLUMNS, Results, method_frame
from studies.sweep.runner import SolverSpec

SPECS = [SolverSpec("fem", element="hex2", law="neo-hookean"), SolverSpec("fem", element="hex2", law="linear", refine=2),
         SolverSpec("fem", element="auto", law="svk"), SolverSpec("static"), SolverSpec("explicit", dt=1e-4, steps=10)]


def _row(spec: SolverSpec, stored_columns: bool) -> dict:
    row = {"solver": spec.label, "model": "" if spec.kind == "fem" else "hybmss",
           "variant": "" if spec.kind == "fem" else "hybmss"}
    if stored_columns:  # as the runner stores a row today
        row.update({f"solver_{k}": v for k, v in spec.relevant().items()})
    return row


@pytest.mark.parametrize("stored_columns", [False, True])
def test_rows_carry_the_solver_of_their_spec(stored_columns):
    """The columns are the spec's own fields whether the row stored them or only its label."""
    df = method_frame(pd.DataFrame([_row(s, stored_columns) for s in SPECS]))
    for spec, (_, r) in zip(SPECS, df.iterrows()):
        assert r["solver_kind"] == spec.kind
        assert bool(r["is_fem"]) == (spec.kind == "fem")
        if spec.kind == "fem":
            assert (r["solver_element"], r["solver_law"], r["solver_refine"]) == (spec.element, spec.law, spec.refine)
            assert r["method"] == spec.label
        else:
            assert (r["solver_element"], r["solver_law"], r["solver_refine"]) == ("", "", 1)
            assert r["method"] == f"hybmss {spec.kind}"


def test_a_stored_column_is_not_overwritten_by_the_label():
    """A row's stored solver columns are its truth; the label fills only what a row lacks."""
    row = {"solver": "fem-hex2-linear", "model": "", "variant": "", "solver_kind": "fem", "solver_element": "hex1",
           "solver_law": "svk", "solver_refine": 3}
    r = method_frame(pd.DataFrame([row])).iloc[0]
    assert (r["solver_element"], r["solver_law"], r["solver_refine"]) == ("hex1", "svk", 3)


class _Rows(Results):
    """A :class:`Results` over given rows (no folder)."""

    def __init__(self, rows):
        self._given = method_frame(pd.DataFrame(rows))

    @property
    def rows(self):
        return self._given


def test_reference_column_is_found_by_its_columns():
    """The FEM column of a law is the scene's own mesh's (refine 1), whatever the column order, and a
    model's column never is one, even if its variant's name reads like a FEM label."""
    rows = [_row(SolverSpec("fem", element="hex2", law="linear", refine=2), False),
            _row(SolverSpec("fem", element="hex2", law="linear"), False),
            {"solver": "mss-static", "model": "fem-like", "variant": "fem-hex2-linear", "solver_kind": "static"}]
    res = _Rows(rows)
    cols = list(res.methods.index)
    assert set(METHOD_COLUMNS) - {"method"} <= set(res.methods.columns)
    assert res.fem_with_law(cols, "linear") == "fem-hex2-linear"
    assert res.fem_with_law(["fem-hex2-linear static"], "linear") is None
    assert not res.is_fem("fem-hex2-linear static") and res.variant("fem-hex2-linear static") == "fem-hex2-linear"
