"""What every section reads and returns: the :class:`Context` of one build (the stored results and
what the build drew from them) and a :class:`Section` (its tables and figures, in order)."""

from __future__ import annotations

import base64
import html
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from ..data import Results


@dataclass
class Section:
    id: str
    title: str
    intro: str = ""
    items: list = field(default_factory=list)  # ("table", Table) | ("figure", dict)
    screen_only: bool = False


@dataclass
class Context:
    """One build's inputs of the sections: the stored results, the figures drawn from them
    (id -> :class:`reports.figures.Figure`), the 3D renders, the VTU files written, the stored
    headline comparison and claims, and the folder of the figures."""

    results: Results
    figs: dict
    renders: list
    vtu_files: list
    head: pd.DataFrame
    claims: pd.DataFrame
    fig_dir: Path

    def add_figures(self, s: Section, *ids: str) -> None:
        """Append the figures ``ids`` that were drawn to ``s``, in that order."""
        s.items += [("figure", fig_item(self.figs[i])) for i in ids if i in self.figs]


def add_tables(s: Section, *tables) -> None:
    """Append the tables that are not None to ``s``, in that order."""
    s.items += [("table", t) for t in tables if t is not None]


def b64(path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(Path(path).read_bytes()).decode("ascii")


def fig_item(f, number: str = "") -> dict:
    return {"id": f.id if hasattr(f, "id") else f.path.stem, "title": f.title if hasattr(f, "title") else "",
            "src": b64(f.path), "caption": f.caption, "number": number, "file": f"figures/{f.path.name}"}


def escape(text: str) -> str:
    return html.escape(str(text), quote=False)


def from_parts(sid: str, parts) -> Section | None:
    """The section of a module that returns ``(title, intro, items)`` or None (:mod:`reports.modes`,
    :mod:`reports.engines`), its figures embedded."""
    if parts is None:
        return None
    title, intro, items = parts
    return Section(sid, title, intro, [(k, fig_item(i) if k == "figure" else i) for k, i in items])
