"""What a run came to, from its result or its stored row: the outputs of a result that are not
finite (such a result is no result), a run's warnings on one line (kept in its row), and whether
a run without result is a time-stepping run not at rest within its step budget (a finding of the
study that chose the budget, counted apart from the failures)."""

from __future__ import annotations

import numpy as np

TIME_STEPPING = ("mss-explicit", "mss-implicit")
"""The solver labels of the runs that stop after their step budget, at rest or not."""


def not_at_rest(row: dict | None) -> bool:
    """A time-stepping run that did not come to rest within its step budget: a finding of the
    study that chose the budget (no result, but no program failure either)."""
    return row is not None and row.get("status") == "not-converged" and row.get("solver") in TIME_STEPPING


def expected_not_at_rest(task, row: dict | None) -> bool:
    """The publication's studies' expectation: a run without result is expected when it is a
    time-stepping run not at rest (:func:`not_at_rest`: explicit candidates of the speed-against-error
    and stability studies given a step budget on purpose); any other is a failure."""
    return not_at_rest(row)


def non_finite(res) -> str:
    """The outputs of a result that are not finite numbers (displacements, reactions, volume
    change), named on one line; ``""`` when every one is finite.  Such a result is no result."""
    bad = []
    if not np.isfinite(np.asarray(res.u, dtype=float)).all():
        bad.append("displacements")
    for name, r in res.reactions.items():
        values = np.concatenate([np.asarray(r.force, dtype=float), np.asarray(r.torque, dtype=float)])
        if not np.isfinite(values).all():
            bad.append(f"reaction of {name}")
    if not np.isfinite(float(res.volume_change)):
        bad.append("volume change")
    return ", ".join(bad)


def warning_lines(caught) -> str:
    """The distinct warnings of a run, each with its count, on one line (``"; "`` between)."""
    counts: dict[str, int] = {}
    for w in caught:
        text = f"{w.category.__name__}: {' '.join(str(w.message).split())}"
        counts[text] = counts.get(text, 0) + 1
    return "; ".join(f"{t} (x{n})" for t, n in counts.items())
