"""One palette and one typographic style for every figure of the report.

Colours are keyed by model family so that a model has the same colour in every plot, render
caption and table legend: hybmss blue, hybmss-fd orange, hybmss-cf green, hybmss (E-form)
purple, FEM references in greys/black, Euler–Bernoulli red, the publication's values brown.
"""

from __future__ import annotations

from contextlib import contextmanager

COLORS = {
    "hybmss": "#1f77b4",
    "hybmss-fd": "#ff7f0e",
    "hybmss-cf": "#2ca02c",
    "hybmss (E-form)": "#9467bd",
    "baudet2009": "#8c564b",
    "fem": "#222222",
    "fem-linear": "#222222",
    "fem-neo-hookean": "#555555",
    "fem-svk": "#8a8a8a",
    "Euler-Bernoulli": "#d62728",
    "paper": "#8c564b",
}

MARKERS = {"hybmss": "o", "hybmss-fd": "s", "hybmss-cf": "^", "hybmss (E-form)": "D", "baudet2009": "v",
           "fem": "x", "fem-linear": "x", "fem-neo-hookean": "+", "fem-svk": "1"}

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
    if "(E-form)" in m:
        return "hybmss (E-form)"
    head = m.split()[0] if m else m
    return head if head in COLORS else "hybmss"


def color(method: str) -> str:
    return COLORS[family(method)]


def marker(method: str) -> str:
    return MARKERS.get(family(method), "o")


def linestyle(method: str) -> str:
    fam = family(method)
    if fam in LINESTYLES:
        return LINESTYLES[fam]
    return "--" if "explicit" in str(method) else "-"


@contextmanager
def style():
    """matplotlib rc context of the report's figures (Agg backend)."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    with plt.rc_context(RC):
        yield plt
