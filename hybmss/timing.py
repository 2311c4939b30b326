"""Repeated wall-clock timing of one computation: :func:`time_repeated` calls it ``warmup`` times
untimed (compilation, caches), then ``repeats`` times each timed with :func:`time.perf_counter`;
the :class:`Timing` of the durations gives the *best* (smallest: other processes on a shared
machine only ever add time), the median and the *spread*, the median's excess over the best::

    spread = (median − best) / best

(``nan`` for a single duration).  Configurations compared with one another are timed
round-robin instead (:func:`hybmss.bench.run_bench`, :func:`studies.paper.performance.time_mesh`),
so that a burst of load falls on all of them; :mod:`studies.sweep.cost` says how a spread makes
two costs a tie."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Timing:
    """Repeated durations (s) of one computation: :attr:`best`, :attr:`median`, :attr:`spread`
    (the median's excess over the best, module docstring) and :attr:`repeats`."""

    samples: tuple[float, ...]

    def __post_init__(self):
        s = tuple(float(x) for x in self.samples)
        if not s:
            raise ValueError("samples: empty; a timing needs at least one duration")
        bad = [x for x in s if not (math.isfinite(x) and x > 0)]
        if bad:
            raise ValueError(f"samples: {bad[0]!r} is not a duration; allowed: finite and > 0 s")
        object.__setattr__(self, "samples", s)

    @classmethod
    def from_samples(cls, samples: Sequence[float]) -> "Timing":
        """The timing of durations measured elsewhere (e.g. the wall times of stored runs)."""
        return cls(tuple(samples))

    @property
    def repeats(self) -> int:
        return len(self.samples)

    @property
    def best(self) -> float:
        return min(self.samples)

    @property
    def median(self) -> float:
        return float(np.median(self.samples))

    @property
    def spread(self) -> float:
        """``(median − best) / best``; ``nan`` for a single duration."""
        if len(self.samples) < 2:
            return math.nan
        return (self.median - self.best) / self.best

    def as_dict(self, prefix: str = "time") -> dict:
        """``{prefix}_s`` (best), ``{prefix}_median_s``, ``{prefix}_spread``, ``{prefix}_repeats``."""
        return {f"{prefix}_s": self.best, f"{prefix}_median_s": self.median,
                f"{prefix}_spread": self.spread, f"{prefix}_repeats": self.repeats}


def time_repeated(fn: Callable[[], object], repeats: int = 5, warmup: int = 1,
                  budget_s: float | None = None) -> Timing:
    """Call ``fn()`` ``warmup`` times untimed, then ``repeats`` times each timed with
    :func:`time.perf_counter`; with ``budget_s``, the timed calls stop once together they took
    that long (at least one: a run of 30 s is timed once, its repeats would add a minute and a
    spread of a few per cent)."""
    if repeats < 1 or warmup < 0 or (budget_s is not None and not budget_s > 0):
        raise ValueError(f"repeats={repeats}, warmup={warmup}, budget_s={budget_s}: allowed repeats >= 1, "
                         "warmup >= 0, budget_s > 0 or None")
    for _ in range(warmup):
        fn()
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
        if budget_s is not None and sum(out) >= budget_s:
            break
    return Timing.from_samples(out)
