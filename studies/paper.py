"""The publication's published values, kept as data with their source ([G20])."""

from __future__ import annotations

from importlib import resources

import pandas as pd


def load(name: str) -> pd.DataFrame:
    """One of ``g20_table2_compression``, ``g20_table3_tension``, ``g20_table6_meshes``,
    ``g20_performance`` (CSV files in ``studies/data``; the first line names the source)."""
    with resources.files("studies").joinpath("data", f"{name}.csv").open() as fh:
        return pd.read_csv(fh, comment="#")


def source(name: str) -> str:
    with resources.files("studies").joinpath("data", f"{name}.csv").open() as fh:
        return fh.readline().lstrip("# ").strip()
