"""Shared references of the verification tests."""

from __future__ import annotations

import numpy as np
import pytest


def _tet_p1_reaction(scene, tets: np.ndarray, plate: str = "top") -> np.ndarray:
    """Reaction on ``plate`` of linear elasticity with scikit-fem's ElementTetP1 on the
    tetrahedra ``tets`` (rows of 4 particle indices of the scene's lattice; any orientation), the
    scene's plates imposed as Dirichlet conditions at full load: the same-mesh reference of an
    engine's tetrahedra."""
    from scipy.sparse.linalg import spsolve
    from skfem import Basis, ElementTetP1, ElementVector, MeshTet, asm
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    from hybmss.models._engine_body import tet_volumes
    from hybmss.system import build

    S = build(scene)
    tets = np.array(tets, dtype=np.int64)
    neg = tet_volumes(S.X, tets) < 0
    tets[neg] = tets[neg][:, [0, 1, 3, 2]]
    basis = Basis(MeshTet(S.X.T.copy(), tets.T.copy()), ElementVector(ElementTetP1()))
    K = asm(linear_elasticity(*lame_parameters(scene.material.E, scene.material.nu)), basis)
    u = np.zeros(basis.N)
    dof = np.arange(3 * S.n).reshape(S.n, 3)  # nodal dofs of ElementVector(P1): node-major x, y, z
    fixed = dof[S.fixed]
    u[fixed] = (S.prescribed(1.0) - S.X)[S.fixed]
    free = np.setdiff1d(np.arange(basis.N), fixed)
    u[free] = spsolve(K[free][:, free].tocsc(), -K[free][:, fixed] @ u[fixed])
    return (K @ u)[dof][S.plate(plate).particles].sum(axis=0)


@pytest.fixture(scope="session")
def tet_p1_reaction():
    """:func:`_tet_p1_reaction`: ``(scene, tets, plate='top') -> reaction (3,)``."""
    return _tet_p1_reaction
