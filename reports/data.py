"""The stored results folder as the report reads it: :mod:`studies.sweep.results` (the studies judge the
publication's claims from the same reader, so both see one set of rows)."""

from studies.paper.values import paper_source, paper_table
from studies.sweep.results import (EXPERIMENT_ORDER, VTK_HEX_ORDER, Results, is_fem, mesh_size,
                                   run_state)

__all__ = ["EXPERIMENT_ORDER", "VTK_HEX_ORDER", "Results", "is_fem", "mesh_size", "paper_source", "paper_table",
           "run_state"]
