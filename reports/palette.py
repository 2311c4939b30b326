"""One palette and one typographic style for every figure of the report.

Colours are keyed by family so that a model has the same colour in every plot, render caption
and table legend, and no two models (nor a model and a reference) share a colour: a declared
colour or marker already taken is replaced by a spare (:func:`unique_styles`); an explicit run is
drawn with another line style than the static one of its model.  A model's style (colour, marker, line style) is the model's own: the studies
store it with the results (``tables/models.csv``, one row per variant name) and the report uses it
inside :func:`models`.  FEM references are greys/black, Euler–Bernoulli red, the publication's
values brown; a method of no stored model is :data:`OTHER` (grey, never another model's colour).
"""

from __future__ import annotations

from contextlib import contextmanager
from contextvars import ContextVar

OTHER = "other"
"""Family of a method whose model has no stored style."""

_MODELS: ContextVar[dict] = ContextVar("model_styles", default={})

COLORS = {
    OTHER: "#9a9a9a",
    "fem": "#222222",
    "fem-linear": "#222222",
    "fem-neo-hookean": "#555555",
    "fem-svk": "#8a8a8a",
    "Euler-Bernoulli": "#d62728",
    "paper": "#8c564b",
}

MARKERS = {OTHER: "P", "fem": "x", "fem-linear": "x", "fem-neo-hookean": "+", "fem-svk": "1"}

LINESTYLES = {"fem-linear": "-", "fem-neo-hookean": "--", "fem-svk": ":", "Euler-Bernoulli": "-."}

#: colour map of the deformed-shape renders (|u|, m)
CMAP = "viridis"

RC = {
    "font.size": 9,
    "axes.titlesize": 9.5,
    "axes.labelsize": 9,
    "legend.fontsize": 8,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "font.family": "DejaVu Sans",
    "axes.grid": True,
    "grid.alpha": 0.3,
    "grid.linewidth": 0.5,
    "lines.linewidth": 1.4,
    "lines.markersize": 4.5,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "savefig.dpi": 150,
    "figure.dpi": 100,
}


SPARE_COLORS = ("#e377c2", "#bcbd22", "#17becf", "#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#393b79",
                "#637939", "#8c6d31", "#843c39", "#7b4173", "#3182bd", "#e6550d", "#31a354", "#756bb1",
                "#636363", "#aec7e8", "#ffbb78", "#98df8a", "#ff9896", "#c5b0d5", "#c49c94", "#f7b6d2",
                "#dbdb8d", "#9edae5", "#6b6ecf", "#b5cf6b", "#e7ba52", "#d6616b", "#ce6dbd", "#de9ed6")
"""Colours given, in this order, to a variant whose declared colour another variant (or a reference,
:data:`COLORS`) already has."""
SPARE_MARKERS = ("o", "s", "^", "v", "D", "X", "<", ">", "p", "H", "d", "8", "P", "*", "h")
"""Markers given to a variant whose declared marker an earlier variant already has, while one is free."""


def unique_styles(records) -> dict:
    """``variant -> (color, marker, linestyle)`` from the models' declared styles (in the table's
    order), each variant with a colour of its own (never a reference's, :data:`COLORS`) and, while
    :data:`SPARE_MARKERS` has one left, a marker of its own: a later variant whose declared colour or
    marker is taken gets the first free spare."""
    used_c = {c.lower() for c in COLORS.values()}
    used_m = set(MARKERS.values())
    out = {}
    for r in records:
        color, marker = str(r["color"]), str(r["marker"])
        if color.lower() in used_c:
            color = next((c for c in SPARE_COLORS if c.lower() not in used_c), color)
        if marker in used_m:
            marker = next((m for m in SPARE_MARKERS if m not in used_m), marker)
        used_c.add(color.lower())
        used_m.add(marker)
        out[str(r["variant"])] = (color, marker, str(r["linestyle"]))
    return out


@contextmanager
def models(table):
    """Use the model styles of ``table`` (rows ``variant, color, marker, linestyle``: the
    results' ``models`` table), made unique (:func:`unique_styles`), inside the ``with`` block."""
    styles = unique_styles(table.to_dict("records")) if table is not None else {}
    token = _MODELS.set(styles)
    try:
        yield styles
    finally:
        _MODELS.reset(token)


def _model_family(m: str) -> str:
    """The longest stored variant name that ``m`` is or starts with (then a space), else OTHER."""
    best = ""
    for v in _MODELS.get():
        if (m == v or m.startswith(v + " ")) and len(v) > len(best):
            best = v
    return best or OTHER


def family(method: str) -> str:
    """Palette key of a method name of the tables (``"hybmss static"``, ``"fem-auto-linear"``,
    ``"hybmss (E-form) mss-explicit"``, ``"Euler-Bernoulli"``, ``"paper hybmss"``)."""
    m = str(method).strip()
    if m.startswith("paper"):
        return "paper"
    if m.startswith("fem"):
        for law in ("neo-hookean", "svk", "linear"):
            if m.endswith(law) or f"-{law}" in m:
                return f"fem-{law}"
        return "fem"
    if m.startswith("Euler"):
        return "Euler-Bernoulli"
    return _model_family(m)


def color(method: str) -> str:
    fam = family(method)
    return COLORS[fam] if fam in COLORS else _MODELS.get()[fam][0]


def marker(method: str) -> str:
    fam = family(method)
    return MARKERS.get(fam, "o") if fam in COLORS else _MODELS.get()[fam][1]


def linestyle(method: str) -> str:
    fam = family(method)
    if fam in LINESTYLES:
        return LINESTYLES[fam]
    own = _MODELS.get()[fam][2] if fam not in COLORS else "-"
    if "explicit" in str(method):  # never the static method's line
        return ":" if own == "--" else "--"
    return own


@contextmanager
def style():
    """matplotlib rc context of the report's figures (Agg backend)."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    with plt.rc_context(RC):
        yield plt
