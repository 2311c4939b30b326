"""What every figure of the report shares: the :class:`Figure` record, the shared legend, the ν axis
(log of the gap to ½, so that 0.49 and 0.499 are apart) and saving a figure."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np



@dataclass
class Figure:
    id: str
    title: str
    path: Path
    caption: str


def shared_legend(fig, axes, ncol=None, **kw):
    """One legend for a grid of axes: each label once, in order of appearance, in at most ``ncol``
    columns."""
    handles, labels = [], []
    for ax in axes.flat:
        for h, l in zip(*ax.get_legend_handles_labels()):
            if l not in labels:
                handles.append(h)
                labels.append(l)
    fig.legend(handles, labels, ncol=max(1, min(ncol or len(labels), len(labels))), frameon=False, **kw)


def nu_to_log_gap(nu):
    """−log10(½ − ν): the x coordinate of a ν axis, on which 0.45, 0.49, 0.499 and 0.4999 are one
    decade apart (a linear ν axis squeezes them into one point)."""
    return -np.log10(0.5 - np.minimum(np.asarray(nu, dtype=float), 0.5 - 1e-12))


def log_gap_to_nu(x):
    return 0.5 - 10.0 ** (-np.asarray(x, dtype=float))


LABEL_GAP_DECADES = 0.4
"""ν tick labels closer than this on the log(½ − ν) axis overlap: they are turned upright."""


def nu_axis(ax, nus):
    """The Poisson ratios of the results on a log(½ − ν) x axis, labelled in ν."""
    ax.set_xscale("function", functions=(nu_to_log_gap, log_gap_to_nu))
    nus = sorted(set(float(v) for v in nus))
    ax.set_xlabel("ν (axis: log(½ − ν))")
    ax.set_xticks(nus)
    gaps = np.diff(nu_to_log_gap(nus)) if len(nus) > 1 else np.array([1.0])
    crowded = len(nus) > 4 or bool((gaps < LABEL_GAP_DECADES).any())
    ax.set_xticklabels([f"{v:g}" for v in nus], rotation=90 if crowded else 0, fontsize=7 if crowded else None)
    ax.xaxis.set_minor_locator(__import__("matplotlib").ticker.NullLocator())
    lo, hi = nu_to_log_gap(min(nus)), nu_to_log_gap(max(nus))
    pad = 0.06 * max(hi - lo, 0.5)
    ax.set_xlim(log_gap_to_nu(lo - pad), log_gap_to_nu(hi + pad))


ERROR_FLOOR_PCT = 1e-3
"""Relative errors below this (%) are drawn at it (triangles pointing down): exact cases (10⁻¹³ %)
would otherwise stretch a log axis over ten empty decades."""


def clipped(values, floor: float = ERROR_FLOOR_PCT):
    """(values clipped from below at ``floor``, mask of the clipped ones)."""
    v = np.asarray(values, dtype=float)
    return np.maximum(v, floor), v < floor


def save_figure(plt, fig, path: Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=150, bbox_inches="tight", pad_inches=0.04)
    plt.close(fig)
    return path
