"""Self-assessment: mesh-refinement studies, observed order and Richardson error estimates.

A reference is solved on the Scene's grid refined by factors ``r = 1, 2, (3)``; element size
``h = le / r``.  For a scalar output ``Q(h) ≈ Q* + C h^p``:

- observed order from three refinements ``h₁ > h₂ > h₃``: the root ``p`` of
  ``(h₁^p − h₂^p) / (h₂^p − h₃^p) = (Q₁ − Q₂) / (Q₂ − Q₃)`` (for a constant ratio
  ``t = h₁/h₂ = h₂/h₃`` this is ``p = ln((Q₁ − Q₂)/(Q₂ − Q₃)) / ln t``); undefined when the
  differences change sign (non-monotone convergence);
- Richardson extrapolation from the two finest: ``Q* ≈ Q₃ + (Q₃ − Q₂) / ((h₂/h₃)^p − 1)``
  and the discretization error estimate of the finest solution ``|Q* − Q₃|`` (and of the
  coarsest, ``r = 1``, solution ``|Q* − Q₁|``, the error of a reference on the MSS grid).

``p`` is the observed order when defined and within ``[0.5, 2 × expected]``, else the
expected order of the element (Hex1: 2, Hex2 and mixed: 3 for displacement-like outputs
of smooth solutions; clamped edges lower it, which the observed order shows).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.optimize import brentq

from hybmss.result import Result
from hybmss.scene import Scene

from .solve import resolve_element, solve

EXPECTED_ORDER = {"hex1": 2.0, "hex2": 3.0, "mixed": 3.0}


def observed_order(h, q) -> float | None:
    """Observed order of convergence from the last three ``(h, q)`` pairs (``h`` decreasing)."""
    h = np.asarray(h, float)[-3:]
    q = np.asarray(q, float)[-3:]
    if len(q) < 3:
        return None
    d1, d2 = q[0] - q[1], q[1] - q[2]
    scale = max(np.abs(q).max(), 1e-300)
    if abs(d2) <= 1e-14 * scale or d1 * d2 <= 0:
        return None
    ratio = d1 / d2

    def phi(p):
        return (h[0] ** p - h[1] ** p) / (h[1] ** p - h[2] ** p) - ratio

    lo, hi = 1e-3, 30.0
    if phi(lo) * phi(hi) > 0:
        return None
    return float(brentq(phi, lo, hi, xtol=1e-12))


def richardson(h_coarse: float, q_coarse: float, h_fine: float, q_fine: float, p: float) -> float:
    """Extrapolated value ``Q₂ + (Q₂ − Q₁) / ((h₁/h₂)^p − 1)``."""
    return q_fine + (q_fine - q_coarse) / ((h_coarse / h_fine) ** p - 1.0)


@dataclass(frozen=True)
class OutputConvergence:
    """Convergence of one scalar output."""

    name: str
    refinements: tuple[int, ...]
    values: tuple[float, ...]
    observed_order: float | None
    order_used: float
    extrapolated: float
    error_finest: float
    error_coarsest: float

    @property
    def relative_error_finest(self) -> float:
        return self.error_finest / max(abs(self.extrapolated), 1e-300)

    @property
    def relative_error_coarsest(self) -> float:
        return self.error_coarsest / max(abs(self.extrapolated), 1e-300)

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "refinements": list(self.refinements),
            "values": list(self.values),
            "observed_order": self.observed_order,
            "order_used": self.order_used,
            "extrapolated": self.extrapolated,
            "error_finest": self.error_finest,
            "error_coarsest": self.error_coarsest,
            "relative_error_finest": self.relative_error_finest,
            "relative_error_coarsest": self.relative_error_coarsest,
        }


@dataclass(frozen=True, eq=False)
class ConvergenceStudy:
    """Results on each refinement and the convergence of each output."""

    refinements: tuple[int, ...]
    results: tuple[Result, ...]
    outputs: dict[str, OutputConvergence] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {
            "refinements": list(self.refinements),
            "solver": self.results[-1].solver,
            "wall_time_s": [r.wall_time_s for r in self.results],
            "outputs": {k: v.to_dict() for k, v in self.outputs.items()},
        }

    def table(self) -> str:
        head = f"{'output':<28}" + "".join(f"{'r=' + str(r):>15}" for r in self.refinements)
        head += f"{'order':>8}{'extrapolated':>15}{'rel.err r=1':>13}{'rel.err fine':>13}"
        lines = [head]
        for o in self.outputs.values():
            order = "-" if o.observed_order is None else f"{o.observed_order:.2f}"
            lines.append(
                f"{o.name:<28}" + "".join(f"{v:>15.7g}" for v in o.values)
                + f"{order:>8}{o.extrapolated:>15.7g}{o.relative_error_coarsest:>13.2e}"
                + f"{o.relative_error_finest:>13.2e}"
            )
        return "\n".join(lines)


def default_outputs(scene: Scene) -> dict[str, Callable[[Result], float]]:
    """Volume, max displacement, strain energy and each plate's force (and torque) components."""
    out: dict[str, Callable[[Result], float]] = {
        "volume": lambda r: r.volume,
        "volume_mss_formula": lambda r: r.info["volume_mss_formula"],
        "max_displacement": lambda r: r.max_displacement,
        "strain_energy": lambda r: r.energy["strain"],
    }
    for plate in scene.plates:
        for i, ax in enumerate("xyz"):
            out[f"{plate.name}.F{ax}"] = (lambda r, n=plate.name, i=i: r.reactions[n].force[i])
        if plate.motion.kind == "rotate":
            for i, ax in enumerate("xyz"):
                out[f"{plate.name}.T{ax}"] = (lambda r, n=plate.name, i=i: r.reactions[n].torque[i])
    return out


def analyze(
    refinements, values, expected_order: float, name: str = ""
) -> OutputConvergence:
    """Observed order and Richardson estimates for one output's ``values`` on ``refinements``."""
    r = np.asarray(refinements, float)
    q = np.asarray(values, float)
    h = 1.0 / r
    p_obs = observed_order(h, q) if len(q) >= 3 else None
    p = p_obs if (p_obs is not None and 0.5 <= p_obs <= 2 * expected_order) else expected_order
    if len(q) >= 2:
        q_ext = richardson(h[-2], q[-2], h[-1], q[-1], p)
    else:
        q_ext = float(q[-1])
    return OutputConvergence(
        name=name,
        refinements=tuple(int(x) for x in refinements),
        values=tuple(float(x) for x in q),
        observed_order=p_obs,
        order_used=float(p),
        extrapolated=float(q_ext),
        error_finest=float(abs(q_ext - q[-1])),
        error_coarsest=float(abs(q_ext - q[0])),
    )


def convergence(
    scene: Scene,
    refinements=(1, 2, 3),
    outputs: dict[str, Callable[[Result], float]] | None = None,
    element: str = "auto",
    law: str = "linear",
    expected_order: float | None = None,
    drop_zero: bool = True,
    **solve_kwargs,
) -> ConvergenceStudy:
    """Solve ``scene`` on each refinement and analyze each output.

    ``outputs`` maps names to functions of a :class:`Result` (default: :func:`default_outputs`);
    with ``drop_zero``, reaction components below 1e-9 of the largest one (zero by symmetry) are
    left out.
    Extra keyword arguments go to :func:`fem_reference.solve.solve`.
    """
    refinements = tuple(sorted(int(r) for r in refinements))
    if len(refinements) < 2 or refinements[0] < 1:
        raise ValueError(f"need at least two refinement factors >= 1, got {refinements}")
    element = resolve_element(element, scene.material.nu)
    outputs = default_outputs(scene) if outputs is None else outputs
    p_exp = EXPECTED_ORDER[element] if expected_order is None else float(expected_order)
    results = tuple(solve(scene, element=element, law=law, refine=r, **solve_kwargs) for r in refinements)
    values = {name: [fn(res) for res in results] for name, fn in outputs.items()}
    if drop_zero:
        # Reaction components that vanish by symmetry are round-off: leave them out.
        for kind in (".F", ".T"):
            comp = {k: v for k, v in values.items() if kind in k}
            ref = max((abs(x) for v in comp.values() for x in v), default=0.0)
            for k, v in comp.items():
                if max(abs(x) for x in v) <= 1e-9 * ref:
                    del values[k]
    analyzed = {name: analyze(refinements, v, p_exp, name) for name, v in values.items()}
    return ConvergenceStudy(refinements, results, analyzed)
