"""The publications' values, kept as data with their source ([G20], [B09]).

Nothing here imports the solvers, so the report reads the published tables through it.  How the
harness's models meet the publications' names for them is :mod:`studies.publications`.
"""

from __future__ import annotations

from importlib import resources

import numpy as np
import pandas as pd

def load(name: str) -> pd.DataFrame:
    """One of the CSV files in ``studies/data`` (``g20_table2_compression``, ``g20_models``,
    ``g20_performance``, ``b09_errors``, ...; the first line names the source)."""
    with resources.files("studies").joinpath("data", f"{name}.csv").open() as fh:
        return pd.read_csv(fh, comment="#")


def source(name: str) -> str:
    with resources.files("studies").joinpath("data", f"{name}.csv").open() as fh:
        return fh.readline().lstrip("# ").strip()


def printed(values, value) -> np.ndarray | bool:
    """Whether stored parameter ``values`` are the publication's printed ``value``.

    The publications print rounded parameters (ν = 0.499, d = 0.05, θ = 45°): a stored value
    matches a printed one within ``numpy.isclose``'s default tolerance (relative 1e-5, absolute
    1e-8).  This is the harness's one tolerant match; stored runs are matched with each other by
    their exact stored values."""
    return np.isclose(np.asarray(values, dtype=float), float(value))
