"""The stored results as the report reads them: the results folder (:class:`studies.sweep.results.Results`)
with the tables the studies derive from its runs and tables, the publications' values and the
thresholds the claims are judged by.  The report formats these and computes nothing of its own.

The derived tables (:data:`DERIVED`) are written by :func:`write_derived` beside ``claims.csv``
after every study's tables; a folder stored without them (an older one) has them derived on read,
once, by the same functions, so that it reads as a new one.
"""

from __future__ import annotations

import pandas as pd

from studies.paper.claims import (E_FEM_PP, MIDDLE_LAYER_TOL, NOT, PAPER_PP, PARTLY, PROTOCOL_FAILURES, REL_PCT,
                                  REPRODUCED, SUPPORTED, e_threshold, thresholds)
from studies.paper.comparisons import b09_frame, b09_models, b09_normalisation, b09_particles, middle_layer_frame
from studies.paper.equilibria import NONUNIQUE_PCT, equilibria
from studies.paper.values import paper_source, paper_table
from studies.paper.verdict import TIE_COST, TIE_PP
from studies.sweep.cost import TIMING_NOISE
from studies.sweep.results import EXPERIMENT_ORDER, VTK_HEX_ORDER, Results, mesh_size, run_state
from studies.sweep.results import printed_match as printed
from studies.sweep.roles import ENGINE_LAWS
from studies.sweep.store import Store

__all__ = ["DERIVED", "E_FEM_PP", "ENGINE_LAWS", "EXPERIMENT_ORDER", "MIDDLE_LAYER_TOL", "NONUNIQUE_PCT", "NOT",
           "PAPER_PP", "PARTLY", "PROTOCOL_FAILURES", "REL_PCT", "REPRODUCED", "SUPPORTED", "StoredResults", "TIE_COST",
           "TIE_PP", "TIMING_NOISE", "VTK_HEX_ORDER", "b09_models", "e_threshold", "mesh_size", "paper_source",
           "paper_table", "printed", "run_state", "thresholds", "write_derived"]


def _b09_comparison(results: Results) -> pd.DataFrame:
    """Our [B09] error statistics beside [B09]'s, one row per experiment, mesh and model."""
    return b09_frame(results.table("baudet_cantilever"), results.table("baudet_lshape"), paper_table("b09_errors"))


def _b09_normalisation(results: Results) -> pd.DataFrame:
    """[B09]'s SD beside ours read two ways (:func:`studies.paper.comparisons.b09_normalisation`)."""
    f = results.table("b09_comparison")
    return b09_normalisation(f) if f is not None else pd.DataFrame()


def _b09_published(results: Results) -> pd.DataFrame:
    """[B09]'s published table with the particles of each of its lattices (``n_particles``)."""
    paper = paper_table("b09_errors")
    if paper is None:
        return pd.DataFrame()
    return paper.assign(n_particles=[b09_particles(e, m) for e, m in zip(paper["experiment"], paper["mesh"])])


#: the tables the studies derive from the stored runs and tables for the report, in the order they
#: are derived (a later one may read an earlier one)
DERIVED = {
    "equilibria": equilibria,
    "middle_layer": middle_layer_frame,
    "b09_comparison": _b09_comparison,
    "b09_normalisation": _b09_normalisation,
    "b09_published": _b09_published,
}


class StoredResults(Results):
    """A results folder whose derived tables (:data:`DERIVED`) are read as stored, or derived on
    read (once) where the folder has none."""

    def __init__(self, root, all_versions: bool = False):
        super().__init__(root, all_versions)
        self._derived: dict[str, pd.DataFrame | None] = {}

    def table(self, name: str) -> pd.DataFrame | None:
        t = super().table(name)
        if t is not None or name not in DERIVED:
            return t
        if name not in self._derived:
            self._derived[name] = None  # a derivation that reads itself finds nothing
            df = DERIVED[name](self)
            self._derived[name] = df if df is not None and not df.empty else None
        return self._derived[name]


def write_derived(store: Store) -> list[str]:
    """Derive :data:`DERIVED` from ``store``'s runs and tables and store each non-empty one under
    ``tables/``; the names written."""
    results = Results(store.root)
    written = []
    for name, derive in DERIVED.items():
        df = derive(results)
        if df is not None and not df.empty:
            store.write_table(name, df)
            written.append(name)
            results = Results(store.root)  # the next derivation reads what this one wrote
    return written
