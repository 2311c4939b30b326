"""The Newton solvers of the mass-spring system, in named steps.

- :mod:`~hybmss.solve.static`: load stepping and :func:`solve_static` (solver ``mss-static``);
- :mod:`~hybmss.solve.implicit`: implicit Euler, :func:`simulate_implicit` (``mss-implicit``);
- :mod:`~hybmss.solve.newton`: the Newton iteration (evaluate, tangent, factor or shift, line
  search, chord steps);
- :mod:`~hybmss.solve.linalg`: tangents, factorizations and fill-reducing orderings;
- :mod:`~hybmss.solve.stability`: eigenpairs, saddle and fold checks, zero-energy modes, and the
  error a lost equilibrium raises;
- :mod:`~hybmss.solve.errors`: :class:`StaticSolveError`, its numbers as fields;
- :mod:`~hybmss.solve.common`: norms, force scales, plate reactions, the result.

The Poisson-ratio range of the solvers is :data:`hybmss.scene.NU_RANGE`.
"""

from ..scene import NU_RANGE, check_nu
from .common import plate_reactions
from .errors import StaticSolveError
from .implicit import ImplicitOptions, simulate_implicit
from .stability import FOLD_MARGIN, smallest_eigenpair, smallest_eigenvalue
from .static import StaticOptions, solve_static

__all__ = ["FOLD_MARGIN", "NU_RANGE", "ImplicitOptions", "StaticOptions", "StaticSolveError", "check_nu",
           "plate_reactions", "simulate_implicit", "smallest_eigenpair", "smallest_eigenvalue", "solve_static"]
