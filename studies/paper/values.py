"""The publications' values, kept as data with their source ([G20], [B09]).

Nothing here imports the solvers, so the report reads the published tables through it.  How the
harness's models meet the publications' names for them is :mod:`studies.paper.publications`.
"""

from __future__ import annotations

from importlib import resources

import pandas as pd

def load(name: str) -> pd.DataFrame:
    """One of the CSV files in ``studies/data`` (``g20_table2_compression``, ``g20_models``,
    ``g20_performance``, ``b09_errors``, ...; the first line names the source)."""
    with resources.files("studies").joinpath("data", f"{name}.csv").open() as fh:
        return pd.read_csv(fh, comment="#")


def source(name: str) -> str:
    with resources.files("studies").joinpath("data", f"{name}.csv").open() as fh:
        return fh.readline().lstrip("# ").strip()


def paper_table(name: str) -> pd.DataFrame | None:
    """A table of the publication from ``studies/data`` (``None`` if absent)."""
    try:
        return load(name)
    except (FileNotFoundError, OSError, ModuleNotFoundError):
        return None


def paper_source(name: str) -> str:
    try:
        text = source(name)
        return text[len("Source:"):].strip() if text.startswith("Source:") else text
    except (FileNotFoundError, OSError, ModuleNotFoundError):
        return ""
