"""FEM reference (scikit-fem): the same Scene in, the same Result schema out.

- :mod:`~fem_reference.mesh`: hexahedral mesh of the voxel body, refinement, node ↔ particle map;
- :mod:`~fem_reference.space`: Hex1/Hex2 spaces with explicit quadrature, vectorized assembly;
- :mod:`~fem_reference.linear`: small-strain elasticity, displacement and mixed u–p;
- :mod:`~fem_reference.laws`, :mod:`~fem_reference.hyperelastic`: Neo-Hookean and SVK,
  total Lagrangian Newton with load stepping;
- :mod:`~fem_reference.dirichlet`: plates → prescribed dofs, reactions;
- :mod:`~fem_reference.loads`: dead surface tractions (``Scene.loads``) as load vectors;
- :mod:`~fem_reference.linalg`: direct (nested-dissection order; CHOLMOD's Cholesky, the mixed
  element's pressure eliminated on its Schur complement, or SuperLU) / AMG-preconditioned solves,
  chosen by size and separator;
- :mod:`~fem_reference.convergence`: refinement studies, observed order, Richardson error;
- :mod:`~fem_reference.modal`: natural frequencies and mode shapes (consistent or lumped mass);
- :mod:`~fem_reference.tet`: small-strain elasticity on tetrahedral bodies (P1, P2, P2–P1),
  supports by node predicates, refinement with Richardson estimates, the field at any point;
- :mod:`~fem_reference.solve`: ``solve(scene, element, law, refine) -> Result``.

The ``hybmss fem`` subcommand (:mod:`studies.cli.parser`) runs it on one scene.
"""

from .solve import operators, solve

__all__ = ["operators", "solve"]
