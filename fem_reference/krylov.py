"""Flexible GMRES for a few iterations with a preconditioner that may change between applications.

For ``A x = b`` from ``x₀ = 0``, iteration ``j`` applies the preconditioner to the last Arnoldi
vector, ``z_j = M_j(v_j)``, orthogonalizes ``A z_j`` against ``v₀ … v_j`` (modified Gram-Schmidt:
``A Z_j = V_{j+1} H_j``) and takes ``x = Z_j y`` with ``y`` minimizing ``‖β e₁ − H_j y‖``, which
is the residual norm ``‖b − A x‖`` (Saad, SIAM J. Sci. Comput. 14, 1993).
"""

from __future__ import annotations

import numpy as np

LINEAR_RTOL_FLOOR = 1e-12
"""Tightest relative residual :func:`fgmres` is asked for (round-off of the weighted residual)."""


def fgmres(matvec, precond, b: np.ndarray, rtol: float, maxiter: int):
    """Flexible GMRES (right preconditioning by ``precond``, which may change between calls) for
    ``matvec(x) = b`` from ``x = 0``: ``(x, iterations)`` once ``‖b − matvec(x)‖ ≤ rtol ‖b‖``, or
    ``(None, iterations)`` after ``maxiter`` iterations or as soon as the contraction per iteration
    so far, kept up for the iterations left, would not reach ``rtol``.  The least-squares problem
    of the Hessenberg matrix is solved afresh each iteration (``maxiter`` is small)."""
    beta = float(np.linalg.norm(b))
    if beta == 0.0:
        return np.zeros_like(b), 0
    V, Z = [b / beta], []
    H = np.zeros((maxiter + 1, maxiter))
    res_prev = beta
    for j in range(maxiter):
        Z.append(precond(V[j]))
        v = matvec(Z[j])
        for i in range(j + 1):  # modified Gram-Schmidt
            H[i, j] = V[i] @ v
            v = v - H[i, j] * V[i]
        H[j + 1, j] = np.linalg.norm(v)
        e1 = np.zeros(j + 2)
        e1[0] = beta
        y = np.linalg.lstsq(H[: j + 2, : j + 1], e1, rcond=None)[0]
        res = float(np.linalg.norm(e1 - H[: j + 2, : j + 1] @ y))
        if res <= rtol * beta:
            return np.column_stack(Z) @ y, j + 1
        left = maxiter - j - 1
        if H[j + 1, j] == 0.0 or left == 0 or res * (res / res_prev) ** left > rtol * beta:
            return None, j + 1
        V.append(v / H[j + 1, j])
        res_prev = res
    return None, maxiter
