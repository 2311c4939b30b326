"""The stored results folder as the report reads it (:mod:`studies.paper.stored`): the runs, the tables
the studies wrote (the derived ones derived on read for a folder stored without them), the
publications' values and the thresholds of the claims.  The report's one import of the studies
(with :mod:`reports.study`'s of the study-file format): everything else in :mod:`reports` reads
from here and formats."""

from studies.paper.stored import (DERIVED as DERIVED_TABLES, E_FEM_PP, ENGINE_LAWS, EXPERIMENT_ORDER, MIDDLE_LAYER_TOL, NONUNIQUE_PCT, NOT,
                                  PAPER_PP, PARTLY, PROTOCOL_FAILURES, REL_PCT, REPRODUCED, SUPPORTED, TIE_COST,
                                  TIE_PP, TIMING_NOISE, VTK_HEX_ORDER, StoredResults as Results, b09_models, e_threshold, mesh_size,
                                  paper_source, paper_table, printed, run_state, thresholds)

__all__ = ["DERIVED_TABLES", "E_FEM_PP", "ENGINE_LAWS", "EXPERIMENT_ORDER", "MIDDLE_LAYER_TOL", "NONUNIQUE_PCT", "NOT", "PAPER_PP",
           "PARTLY", "PROTOCOL_FAILURES", "REL_PCT", "REPRODUCED", "SUPPORTED", "TIE_COST", "TIE_PP", "TIMING_NOISE",
           "VTK_HEX_ORDER",
           "Results", "b09_models", "e_threshold", "mesh_size", "paper_source", "paper_table", "printed", "run_state",
           "thresholds"]
