"""Force terms: what a model adds to a system beyond its springs and volume energy.

Every solver sees a scene's forces as the lattice's springs and volume energy (arrays of
:class:`hybmss.system.System`) plus a tuple of :class:`ForceTerm` objects.  A term is either

- **conservative**: it has a potential energy ``E(x)``; ``forces(x) = −∇E(x)`` and
  ``stiffness(x) = ∇²E(x)`` (symmetric).  Static and implicit solvers minimize the total energy;
- **non-conservative**: forces only (the [B09] correction forces); ``stiffness(x)`` is the
  Jacobian of ``−forces`` (not symmetric).  Static solvers then find a zero of the force residual
  and implicit solvers are not available.

``scaled`` says whether the term follows the load factor ``s`` of load stepping (gravity and dead
loads do; internal forces do not): a scaled term contributes ``s · forces(x)`` and ``s · E(x)``.

Positions ``x`` are (n, 3) arrays; forces are (n, 3); stiffness is a ``(3n, 3n)`` sparse matrix.
A non-conservative term's ``energy`` raises ``TypeError`` (it has none).

:class:`hybmss.system.System` holds its terms in ``System.terms``; :mod:`hybmss.forces` adds them
to the springs and volume energy (:func:`hybmss.forces.energy_forces`,
:func:`hybmss.forces.stiffness`), and :func:`all_conservative` tells a solver whether a total
energy exists (energy minimization) or only a force residual (residual mode of the static Newton).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
import scipy.sparse as sp


@runtime_checkable
class ForceTerm(Protocol):
    """One additive force contribution of a system (see the module docstring)."""

    name: str
    conservative: bool
    scaled: bool

    def energy(self, x: np.ndarray) -> float:
        """Potential energy at ``x`` (conservative terms only)."""
        ...

    def forces(self, x: np.ndarray) -> np.ndarray:
        """Forces (n, 3) at ``x``."""
        ...

    def stiffness(self, x: np.ndarray) -> sp.spmatrix:
        """``∂(−forces)/∂x`` at ``x``: the Hessian of the energy for a conservative term."""
        ...


class DeadLoad:
    """Constant nodal forces ``f`` (n, 3) of fixed direction (surface tractions): potential
    ``−Σ f·x``, no stiffness; follows the load factor."""

    name = "dead_load"
    conservative = True
    scaled = True

    def __init__(self, f: np.ndarray):
        self.f = np.asarray(f, dtype=float)

    def energy(self, x: np.ndarray) -> float:
        return -float(np.sum(self.f * x))

    def forces(self, x: np.ndarray) -> np.ndarray:
        return self.f

    def stiffness(self, x: np.ndarray) -> sp.spmatrix:
        N = self.f.size
        return sp.csr_matrix((N, N))


def all_conservative(terms) -> bool:
    """True when every term of ``terms`` has an energy (the system then has a total potential)."""
    return all(t.conservative for t in terms)
