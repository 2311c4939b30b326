"""A solution on one refinement of a body, carried to a finer one: the start of the finer solve.

The meshes of a body refined ``r_c`` and ``r_f > r_c`` times cover the same cells, so every node of
the finer space lies in an element of the coarser one.  The coarse field, a piecewise polynomial
(Hex2 displacements, Hex1 pressures), evaluated at the finer nodes (the element of each node looked up on the
refined grid, :meth:`~fem_reference.mesh.FemMesh.elements_at`, then scikit-fem's inverse mapping
and basis, as its :meth:`~skfem.CellBasis.probes` does with a search that needs memory of nodes
times elements) is a field of the finer space: exactly the same function when
the finer mesh nests the coarser one (``r_f`` a multiple of ``r_c``), its interpolant otherwise.

The finite-strain Newton solve of the finer level starts from it at the full load
(:meth:`fem_reference.hyperelastic.Hyperelasticity.solve`, ``start``): the coarser solution is
within its discretization error of the finer one, inside Newton's quadratic basin, where the
load stepping from the undeformed state needs several steps of several iterations each.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .space import Space


def prolongation(coarse: Space, fine: Space) -> sp.csr_matrix:
    """``(fine.n_scalar, coarse.n_scalar)``: the values at the finer space's nodes of a scalar field
    of the coarser space (the two spaces on meshes of the same body)."""
    basis = coarse.basis
    x = np.ascontiguousarray(fine.points.T)
    cells = coarse.fmesh.elements_at(fine.points)
    local = basis.mapping.invF(x[:, :, None], tind=cells)
    values = np.concatenate([np.ravel(basis.elem.gbasis(basis.mapping, local, k, tind=cells)[0])
                             for k in range(basis.Nbfun)])
    rows = np.tile(np.arange(x.shape[1]), basis.Nbfun)
    cols = basis.element_dofs[:, cells].ravel()
    P = sp.csr_matrix((values, (rows, cols)), shape=(x.shape[1], basis.N))
    P.data[np.abs(P.data) < 1e-14] = 0.0
    P.eliminate_zeros()
    return P


def prolong(coarse, fine, U: np.ndarray, p: np.ndarray | None = None):
    """The state ``(U, p)`` of discretization ``coarse`` (a :class:`~fem_reference.linear.
    Discretization`: ``U`` (n_scalar, 3) or interleaved (n_vector,), ``p`` its pressures or
    ``None``) as a state of the finer ``fine``: ``(U_f (n_scalar_f, 3), p_f or None)``."""
    U = np.asarray(U, float).reshape(-1, 3)
    Uf = prolongation(coarse.space, fine.space) @ U
    pf = None
    if p is not None and fine.mixed:
        pf = prolongation(coarse.pspace, fine.pspace) @ np.asarray(p, float)
    return Uf, pf
