"""One palette and one typographic style for every figure of the report.

Colours are keyed by family so that a model has the same colour in every plot, render caption
and table legend.  A model's style (colour, marker, line style) is the model's own: the studies
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


@contextmanager
def models(table):
    """Use the model styles of ``table`` (rows ``variant, color, marker, linestyle``: the
    results' ``models`` table) inside the ``with`` block."""
    styles = {}
    if table is not None:
        for r in table.to_dict("records"):
            styles[str(r["variant"])] = (str(r["color"]), str(r["marker"]), str(r["linestyle"]))
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
    if "explicit" in str(method):
        return "--"
    return _MODELS.get()[fam][2] if fam not in COLORS else "-"


@contextmanager
def style():
    """matplotlib rc context of the report's figures (Agg backend)."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    with plt.rc_context(RC):
        yield plt
