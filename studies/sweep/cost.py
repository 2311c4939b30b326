"""Cost of a method: repeated timings with their spread, explicit cost at the stable step, and the
budget answer (the fastest method within an error budget, its lead, and whether the lead is a tie).

**Timing.**  A figure is the *best* (smallest) of ``repeats`` timed runs, taken after ``warmup``
untimed runs (compilation, caches): :func:`time_repeated` and :class:`Timing`, whose home is
:mod:`hybmss.timing` (imported here for the sweep's users).  Its noise is the *spread*, the
median's excess over the best::

    spread = (median − best) / best

(0.2: half the repeats took at least 20 % longer than the best).  A single timing has no spread
(``nan``): nothing says how far it is from its own repeat; with two, the median is their mean
and the spread half their relative range.  The median rather than the slowest repeat: on a shared
machine one repeat in a few is disturbed far beyond the others (a kernel loaded from the compile
cache by the first run of a worker, another job on the same core: ×100 seen on 0.01 s runs), and
the range would then call every comparison a tie; the interquartile ratio needs more repeats
(3–5 here) than it has quartiles.

**Explicit cost.**  An explicit step costs ``us_per_step`` µs whatever dt is; what a user pays is
the wall time of one simulated second at the largest step that is stable::

    dt_stable = SAFETY × dt_crit,   cost = us_per_step · 10⁻⁶ / dt_stable   (s per simulated s)

``dt_crit = 2/√λmax(M⁻¹K)`` is the limit at rest (:func:`hybmss.explicit.dt_crit`).
:data:`SAFETY` = ½, the step the stability study checks for every model (it must run the 10,000
steps of the compression protocol): the limit at rest is not the limit of a deformed body (the
stiffness under compression and of a Neo-Hookean law grows, so λmax does), and half the limit
keeps every model's run stable on the protocols of this project.  A model with no explicit limit
(``dt_crit`` = ∞: an implicit constraint solve such as XPBD) runs at the largest step its caller
allows (``dt_max``, e.g. one frame).

**Budget answer.**  For each error budget b, each method's cheapest row with ``error ≤ b`` stands
for it (a method may have rows at several resolutions); the method of least cost wins, the next
cheapest method is the runner-up and ``lead = cost(runner-up) / cost(winner)`` (≥ 1).  With
``s = max(spread(winner), spread(runner-up), TIMING_NOISE)``::

    tie  ⇔  lead < 1 + s

(a lead of 1.15 with a spread of 20 % is a tie: the runner-up's best time is nearer the winner's
best than a typical repeat of either method is to its own; a lead of 1.5 with a spread of exactly
0.5 is not).  :data:`TIMING_NOISE` bounds ``s`` from below: two runs' best times measured apart
vary from sweep to sweep by more than their own spreads (a lead of 1.05 is a tie whatever the
spreads).  When either
spread is unknown (a single timing) ``tie`` is undetermined (``<NA>``); with no runner-up it is
False.  Methods that meet no budget are listed once each, with their smallest error.  A row that
is no result (a run not at rest or failed: its ``failure`` reason is not empty) has no error: it
neither wins nor is runner-up, and a method with no result at all is listed as :data:`NO_RESULT`
with its reason, never with a number.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pandas as pd



def __getattr__(name: str):
    """``Timing`` and ``time_repeated`` from :mod:`hybmss.timing`, imported when first asked for: the
    report reads this module's budget answers without importing the solvers' package."""
    if name in ("Timing", "time_repeated"):
        from hybmss import timing

        return getattr(timing, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__all__ = ["NONE_WITHIN", "NO_BUDGET", "NO_RESULT", "SAFETY", "Timing", "budget_answer", "cost_per_simulated_second",
           "explicit_cost", "is_tie", "stable_dt", "time_repeated"]

SAFETY = 0.5
"""Fraction of the explicit limit at rest ``dt_crit`` taken as the stable step (module docstring)."""

NO_BUDGET = "meets no budget"
"""``answer`` of a method that meets none of the budgets."""
NONE_WITHIN = "none within budget"
"""``method`` of a budget that no method meets."""
NO_RESULT = "no result"
"""``answer`` of a method none of whose runs reached a result (not at rest, not converged, failed)."""


# ------------------------------------------------------------------------------ explicit cost
def stable_dt(dt_crit, safety: float = SAFETY, dt_max=math.inf):
    """``min(safety · dt_crit, dt_max)``: the step an explicit run takes (``dt_crit`` = ∞ for a
    model with no explicit limit: then ``dt_max``, which must be finite)."""
    dt = np.minimum(safety * np.asarray(dt_crit, dtype=float), dt_max)
    if np.any(~np.isfinite(dt) & ~np.isnan(dt)):
        raise ValueError("dt_max: inf with an unlimited dt_crit; give the largest step allowed (e.g. a frame)")
    return float(dt) if np.ndim(dt) == 0 else dt


def cost_per_simulated_second(us_per_step, dt):
    """Wall seconds per simulated second of steps costing ``us_per_step`` µs at step ``dt`` s."""
    c = np.asarray(us_per_step, dtype=float) * 1e-6 / np.asarray(dt, dtype=float)
    return float(c) if np.ndim(c) == 0 else c


def explicit_cost(us_per_step, dt_crit, simulated_s: float = 1.0, safety: float = SAFETY, dt_max=math.inf):
    """Wall seconds of ``simulated_s`` simulated seconds at :func:`stable_dt`: whole steps,
    ``ceil(simulated_s / dt) · us_per_step · 10⁻⁶`` (compare with a static solve's wall time
    when ``simulated_s`` is the time the explicit run needs to come to rest)."""
    dt = np.asarray(stable_dt(dt_crit, safety, dt_max), dtype=float)
    steps = np.ceil(simulated_s / dt * (1 - 1e-12))  # 1.0/0.1 is 10.000000000000002
    c = steps * np.asarray(us_per_step, dtype=float) * 1e-6
    return float(c) if np.ndim(c) == 0 else c


# ------------------------------------------------------------------------------ budget answer
TIMING_NOISE = 0.10
"""The least noise of a lead: two best times measured by different runs of one sweep (two workers,
each run sharing the machine with whatever the other computes) differ from one sweep to the next by
more than either run's own spread says.  Measured on two identical runs of the cylinder study
(``studies/examples/cylinder-squeeze-twist.toml``, fresh stores, 2 busy cores): over the 69 pairs
of candidates of one configuration whose lead was below 1.25, the lead's logarithm changed between
the two runs by a median of 0.043, a 90th percentile of 0.095, a 95th of 0.13 and at most 0.19,
while the runs' own spreads had a median of 0.01: a lead of 1.018 called no tie in one run was a
tie (1.004) in the next and 1.10 in a third.  0.10, the 90th percentile: a lead beyond it reverses
in about one rerun in twenty."""


def is_tie(lead: float, spread_a: float, spread_b: float):
    """``lead < 1 + max(spread_a, spread_b, TIMING_NOISE)``; ``pd.NA`` when a spread is unknown
    (``nan``: a single timing, whose noise nothing bounds)."""
    if not np.isfinite(lead):
        return False
    if np.isnan(spread_a) or np.isnan(spread_b):
        return pd.NA
    return bool(lead < 1.0 + max(spread_a, spread_b, TIMING_NOISE))


def budget_answer(df: pd.DataFrame, budgets, error: str = "error", cost: str = "cost",
                  spread: str = "spread", method: str = "method", keep: Sequence[str] = (),
                  failure: str | None = None) -> pd.DataFrame:
    """The fastest method within each budget of ``budgets`` (module docstring), from ``df``: one
    row per run (a method at one resolution) with its ``error``, ``cost`` (best time) and
    ``spread``.  Rows whose error or cost is not finite are left out.

    One row per budget (``answer`` "fastest" or :data:`NONE_WITHIN` as ``method``): ``budget``,
    ``method``, ``error``, ``cost``, ``spread``, ``runner_up`` (``""`` when alone),
    ``runner_up_error``, ``runner_up_cost``, ``runner_up_spread``, ``lead``, ``tie`` (nullable
    boolean), ``n_within`` (methods within the budget), and the ``keep`` columns of the winner
    (and ``runner_up_<col>``).  Then one row per method that meets no budget (``answer``
    :data:`NO_BUDGET`, ``budget`` nan, ``error`` its smallest error, ``cost`` that run's; both
    nan when none of its runs has a finite error and cost, e.g. all failed).

    ``failure``: a column of reasons why a row is no result (empty, None or NaN for a result).
    Such a row is left out whatever its error; a method with no result at all is listed once
    with ``answer`` :data:`NO_RESULT`, no error nor cost, and its first reason in a last column
    ``failure`` (``""`` in the other rows).  Without it the output is as before (no such column)."""
    err_v = df[error].astype(float)
    valid = np.isfinite(err_v) & np.isfinite(df[cost].astype(float))
    failed = pd.Series(False, index=df.index)
    if failure is not None:
        reason = df[failure].where(df[failure].notna(), "").astype(str).str.strip()
        failed = reason != ""
        valid &= ~failed
    ok = df[valid]
    out = []
    for b in budgets:
        within = (ok[ok[error] <= b].sort_values([cost, error], kind="stable")
                  .drop_duplicates(method, keep="first"))
        rec = {"budget": float(b), "answer": "fastest", "method": NONE_WITHIN, "error": math.nan,
               "cost": math.nan, "spread": math.nan, "runner_up": "", "runner_up_error": math.nan,
               "runner_up_cost": math.nan, "runner_up_spread": math.nan, "lead": math.nan,
               "tie": False, "n_within": len(within)}
        rec.update({k: None for k in keep})
        rec.update({f"runner_up_{k}": None for k in keep})
        if len(within):
            w = within.iloc[0]
            rec.update(method=w[method], error=float(w[error]), cost=float(w[cost]),
                       spread=float(w[spread]), **{k: w[k] for k in keep})
            if len(within) > 1:
                r = within.iloc[1]
                lead = float(r[cost]) / float(w[cost])
                rec.update(runner_up=r[method], runner_up_error=float(r[error]), runner_up_cost=float(r[cost]),
                           runner_up_spread=float(r[spread]), lead=lead,
                           tie=is_tie(lead, float(w[spread]), float(r[spread])),
                           **{f"runner_up_{k}": r[k] for k in keep})
        out.append(rec)
    bmax = max(budgets) if len(budgets) else -math.inf
    for m, g in df.groupby(method, sort=False):
        if failure is not None and failed[g.index].all():
            rec = {"budget": math.nan, "answer": NO_RESULT, "method": m, "error": math.nan, "cost": math.nan,
                   "spread": math.nan, "runner_up": "", "runner_up_error": math.nan, "runner_up_cost": math.nan,
                   "runner_up_spread": math.nan, "lead": math.nan, "tie": False, "n_within": 0,
                   **{k: None for k in keep}, **{f"runner_up_{k}": None for k in keep},
                   "failure": str(reason[g.index].iloc[0])}
            out.append(rec)
            continue
        g = g[g.index.isin(ok.index)]
        if (g[error] <= bmax).any():
            continue
        r = (g.sort_values([error, cost], kind="stable").iloc[0] if len(g)
             else pd.Series({error: math.nan, cost: math.nan, spread: math.nan, **{k: None for k in keep}}))
        rec = {"budget": math.nan, "answer": NO_BUDGET, "method": m, "error": float(r[error]),
               "cost": float(r[cost]), "spread": float(r[spread]), "runner_up": "",
               "runner_up_error": math.nan, "runner_up_cost": math.nan, "runner_up_spread": math.nan,
               "lead": math.nan, "tie": False, "n_within": 0, **{k: r[k] for k in keep}}
        rec.update({f"runner_up_{k}": None for k in keep})
        out.append(rec)
    res = pd.DataFrame(out, columns=["budget", "answer", "method", "error", "cost", "spread", "runner_up",
                                     "runner_up_error", "runner_up_cost", "runner_up_spread", "lead", "tie",
                                     "n_within", *keep, *[f"runner_up_{k}" for k in keep]]
                       + (["failure"] if failure is not None else []))
    if failure is not None:
        res["failure"] = res["failure"].astype(object).fillna("")  # all-NaN column: float64 otherwise
    res["tie"] = res["tie"].astype("boolean")
    return res
