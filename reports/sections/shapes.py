"""Deformed shapes (Figs 3, 4, 7, 9): the 3D renders of where the MSS departs from the FEM."""

from __future__ import annotations

from .. import render as rendermod
from .base import Context, Section, b64


def section(ctx: Context) -> Section | None:
    if not ctx.renders:
        return None
    s = Section("shapes", "Deformed shapes (Figs 3, 4, 7, 9): where the MSS departs from the FEM",
                rendermod.largest_differences_sentence(ctx.renders))
    for r in ctx.renders:
        n = rendermod.FIGURE_NUMBERS.get(r.experiment, "")
        s.items.append(("figure", {"id": r.path.stem, "title": f"{r.experiment.capitalize()}, {r.load} (cf. Fig. {n})",
                                   "src": b64(r.path), "caption": r.caption, "number": str(n),
                                   "file": f"figures/{r.path.name}"}))
    return s
