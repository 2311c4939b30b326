"""The stored results folder as the report reads it: :mod:`studies.results` (the studies judge the
publication's claims from the same reader, so both see one set of rows)."""

from studies.results import (EXPERIMENT_ORDER, VTK_HEX_ORDER, Results, is_fem, mesh_size, paper_source,
                             paper_table, run_state)

__all__ = ["EXPERIMENT_ORDER", "VTK_HEX_ORDER", "Results", "is_fem", "mesh_size", "paper_source", "paper_table",
           "run_state"]
