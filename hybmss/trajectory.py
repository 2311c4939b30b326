"""The displacement history of one named point of a body: what a released transient returns.

A :class:`Trajectory` is plain data shared by every solver of a transient (the mass-spring
models and engines in :mod:`hybmss.released`, the FEM in :mod:`fem_reference.transient`): the
sample times ``t`` (s), the point's displacement ``u(t)`` (k, 3, m), its reference position, the
step and the wall time of the stepping.  A run that stopped early (diverged, failed) keeps the
samples it had and says why in ``status`` and ``reason``; the metrics of
:mod:`studies.sweep.dynamics` give none for it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

STATUSES = ("ok", "diverged", "failed")


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Samples ``u[k] = u(t[k])`` of one point's displacement.

    ``solver``: what produced it; ``dt``: the integrator's step (s); ``point``: the reference
    position of the point (m); ``wall_time_s``: the stepping alone (no set-up, no static state);
    ``energy``: total mechanical energy at the samples (J) when the solver has one, else ``None``;
    ``info``: anything else (JSON-serializable)."""

    solver: str
    t: np.ndarray
    u: np.ndarray
    point: tuple[float, float, float]
    dt: float
    wall_time_s: float
    energy: np.ndarray | None = None
    status: str = "ok"
    reason: str = ""
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.status not in STATUSES:
            raise ValueError(f"status must be one of {', '.join(STATUSES)}; got {self.status!r}")
        t = np.asarray(self.t, dtype=float)
        u = np.asarray(self.u, dtype=float).reshape(len(t), 3)
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "u", u)

    @property
    def t_end(self) -> float:
        return float(self.t[-1]) if len(self.t) else 0.0

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def wall_per_simulated_second(self) -> float | None:
        """Wall time of the stepping per simulated second, or ``None`` without a simulated span."""
        return self.wall_time_s / self.t_end if self.t_end > 0 else None

    def component(self, axis: int) -> np.ndarray:
        """The displacement history along ``axis`` (0, 1, 2)."""
        return self.u[:, int(axis)]
