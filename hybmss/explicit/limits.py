"""The explicit stability limit: symplectic Euler is stable for ``dt < dt_crit = 2/√λmax(M⁻¹K)``,
λmax the largest eigenvalue of ``M^{-1/2} K M^{-1/2}`` on the free degrees of freedom (the exact
Hessian K at rest), or the model's own limit when it declares one."""

from __future__ import annotations

import math

import numpy as np

from ..forces import hessian
from ..scene import Scene
from ..system import System, build

DENSE_EIG_MAX = 64
"""Largest matrix whose eigenvalues :func:`lambda_max` takes densely: above it ARPACK (sparse
products, no BLAS threads; a dense ``eigvalsh`` of a few hundred rows takes seconds when BLAS
threads share a busy machine)."""
EIGSH_TOL = 1e-10
"""Relative tolerance of ARPACK's largest eigenvalue in :func:`lambda_max`."""


def lambda_max(A) -> float:
    """Largest eigenvalue of the symmetric sparse matrix ``A``: dense up to :data:`DENSE_EIG_MAX`
    rows, else ARPACK (tolerance :data:`EIGSH_TOL`) from the fixed :func:`lanczos_start`."""
    from scipy.sparse.linalg import eigsh

    if A.shape[0] <= DENSE_EIG_MAX:
        return float(np.linalg.eigvalsh(A.toarray())[-1])
    return float(eigsh(A, k=1, which="LA", tol=EIGSH_TOL, return_eigenvectors=False,
                       v0=lanczos_start(A.shape[0]))[0])


def scaled_free_stiffness(system: System, K):
    """``M^{-1/2} K M^{-1/2}`` on the free degrees of freedom (not prescribed, with mass),
    symmetrized: its eigenvalues are the squared frequencies ω² of ``M⁻¹K``.  ``K``: (3n, 3n)."""
    import scipy.sparse as sp

    m3 = np.repeat(system.mass, 3)
    free = (~system.fixed).ravel() & (m3 > 0)
    Kf = sp.csr_matrix(K)[free][:, free]
    s = sp.diags(1.0 / np.sqrt(m3[free]))
    A = (s @ Kf @ s).tocsr()
    return 0.5 * (A + A.T)


def critical_step(system: System, K) -> float:
    """``2/√λmax(M⁻¹K)`` on the free degrees of freedom (:func:`scaled_free_stiffness`); ``inf``
    when nothing is free or K has no positive eigenvalue."""
    A = scaled_free_stiffness(system, K)
    if A.shape[0] == 0:
        return math.inf
    lmax = lambda_max(A)
    return 2.0 / math.sqrt(lmax) if lmax > 0 else math.inf


def dt_crit(system_or_scene: System | Scene) -> float:
    """Explicit stability limit: the model's own ``dt_crit`` when it declares one
    (:class:`hybmss.models.base.ModelBase`), else ``2/√λmax(M⁻¹K)`` of the exact Hessian at rest
    (:func:`critical_step`: free degrees of freedom only, λmax by :func:`lambda_max`)."""
    system = system_or_scene if isinstance(system_or_scene, System) else build(system_or_scene)
    own = system.scene.model.spec.dt_crit(system)
    if own is not None:  # the model's own limit (hybmss.models.base)
        return float(own)
    return critical_step(system, hessian(system, system.X))


def lanczos_start(n: int) -> np.ndarray:
    """A fixed start vector for ARPACK (its default is random: ω_max, hence dt_crit, dt and the
    substeps timed by it, would differ in their last bits between runs)."""
    return np.random.default_rng(0).standard_normal(n)
