"""Numba helpers of the explicit kernels: plates, divergence check, the particle state.

The step itself (springs, volume term, integration) is generated per lattice by
:mod:`hybmss._stencil_gen` and works on one flat array ``W`` (its layout is described there).
This module holds what the generated driver calls between steps, on the same flat array:

1. plates: prescribed components ``x = X + u(s(t))`` (f64 stores x, f32 stores u) with the ramp
   s(t), ``v = Δu/dt``;
2. every ``check_every`` steps: a non-finite position or a displacement beyond the limit stops
   the run and names the node.

The models with kernels of their own (``hybmss/models/<name>/_kernels.py``) use the same helpers
on a particle-indexed state (:func:`particle_state`, :func:`kernel_state`).

Node q, component d of a region with base ``b`` (index of node 0, component 0) is
``W[b + d L + q]``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_OPTS = dict(cache=True, error_model="numpy", fastmath=False, nogil=True)


@njit(**_OPTS)
def ramp(t, T):
    """Load factor s(t) = ½ (1 − cos(π t / T)) for t < T, then 1 (s = 1 when T ≤ 0)."""
    if T <= 0.0 or t >= T:
        return 1.0
    if t <= 0.0:
        return 0.0
    return 0.5 * (1.0 - math.cos(math.pi * t / T))


@njit(inline="always")
def cofactor3(m00, m01, m02, m10, m11, m12, m20, m21, m22):
    """cof(M) of a 3×3 matrix, entries by rows: (i, j) is ``M[i+1, j+1] M[i+2, j+2] −
    M[i+1, j+2] M[i+2, j+1]`` (indices mod 3), so ``det M = Σ_j M[0, j] cof[0, j]`` and
    ``M⁻ᵀ = cof / det M`` (the lane kernels of xpbd-nh and the corotational rotations)."""
    return (m11 * m22 - m12 * m21, m12 * m20 - m10 * m22, m10 * m21 - m11 * m20,
            m21 * m02 - m22 * m01, m22 * m00 - m20 * m02, m20 * m01 - m21 * m00,
            m01 * m12 - m02 * m11, m02 * m10 - m00 * m12, m00 * m11 - m01 * m10)


@njit(**_OPTS)
def _rotation(axis, angle, R):
    k0, k1, k2 = axis[0], axis[1], axis[2]
    s = math.sin(angle)
    c1 = 1.0 - math.cos(angle)
    # R = I + sin K + (1 − cos) K², K the cross-product matrix of the unit axis
    K = np.array([[0.0, -k2, k1], [k2, 0.0, -k0], [-k1, k0, 0.0]])
    for i in range(3):
        for j in range(3):
            K2 = K[i, 0] * K[0, j] + K[i, 1] * K[1, j] + K[i, 2] * K[2, j]
            R[i, j] = (1.0 if i == j else 0.0) + s * K[i, j] + c1 * K2


@njit(**_OPTS)
def plate_displacement(X, nodes, U1, kind, axis, center, angle, disp, s, R, u):
    """u (3, len(nodes)) of one plate at load factor s: ``s · U1`` for motions linear in s
    (kind 0: clamped, translate, slide, affine), the exact rotation for kind 1 (same law as
    :meth:`hybmss.scene.Motion.displacement_at`)."""
    if kind == 1:
        _rotation(axis, s * angle, R)
        for i in range(nodes.shape[0]):
            q = nodes[i]
            r0 = X[0, q] - center[0]
            r1 = X[1, q] - center[1]
            r2 = X[2, q] - center[2]
            for d in range(3):
                u[d, i] = (R[d, 0] * r0 + R[d, 1] * r1 + R[d, 2] * r2) + center[d] - X[d, q] + s * disp[d]
    else:
        for i in range(nodes.shape[0]):
            for d in range(3):
                u[d, i] = s * U1[d, i]


def particle_state(x: np.ndarray, v: np.ndarray):
    """The state of a particle-indexed kernel: one flat array ``W = [x; v]`` (positions stored)
    with its two ``(3, n)`` views, laid out for :func:`apply_plates`, :func:`find_bad` and
    :func:`end_of_step` with ``xb = 0``, ``vb = 3n``, ``L = N = n``.  ``x``, ``v``: (n, 3)."""
    n = len(x)
    W = np.empty(6 * n)
    xg = W[:3 * n].reshape(3, n)
    vg = W[3 * n:].reshape(3, n)
    xg[:] = np.asarray(x).T
    vg[:] = np.asarray(v).T
    return W, xg, vg


PRECISIONS = ("f64", "f32")


def kernel_state(x: np.ndarray, v: np.ndarray, X: np.ndarray, precision: str = "f64"):
    """``(W, xg, vg, posmode)``: the flat state of :func:`particle_state` and its (3, n) views.

    ``f64`` stores positions x, float64 (``posmode`` True); ``f32`` stores displacements
    ``u = x − X`` and velocities in float32, as the lattice's float32 kernel
    (:mod:`hybmss._stencil_gen`): a position of a few metres keeps only ~1e-7 m in float32, a
    displacement 1e-7 of itself.  A kernel then evaluates its arithmetic in float64 from
    ``X + u``, so the float32 state is the only rounding.  ``x``, ``v``, ``X``: (n, 3)."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)}; got {precision!r}")
    if precision == "f64":
        W, xg, vg = particle_state(x, v)
        return W, xg, vg, True
    W64, _, _ = particle_state(np.asarray(x) - np.asarray(X), v)
    W = W64.astype(np.float32)
    n = len(x)
    return W, W[:3 * n].reshape(3, n), W[3 * n:].reshape(3, n), False


def read_state(xg: np.ndarray, vg: np.ndarray, X: np.ndarray, posmode: bool) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities (n, 3), float64, of the views of :func:`kernel_state`."""
    x = xg.T.astype(np.float64)
    if not posmode:
        x = x + X
    return np.ascontiguousarray(x), np.ascontiguousarray(vg.T, dtype=np.float64)


@njit(**_OPTS)
def prescribe(W, xb, vb, L, posmode, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis, pl_center,
              pl_angle, step, dt, ramp_time, R, u_old, u_new, qlo, qhi):
    """The plates' prescribed components for step ``step`` → ``step + 1``, on the nodes
    ``qlo ≤ q < qhi`` only (a thread's own range)."""
    if pl_ptr.shape[0] > 1:
        s_old = ramp(step * dt, ramp_time)
        s_new = ramp((step + 1) * dt, ramp_time)
        apply_plates(W, xb, vb, L, posmode, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis,
                     pl_center, pl_angle, s_old, s_new, dt, R, u_old, u_new, qlo, qhi)


@njit(**_OPTS)
def apply_plates(W, xb, vb, L, posmode, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis,
                 pl_center, pl_angle, s_old, s_new, dt, R, u_old, u_new, qlo, qhi):
    """Prescribed components of every plate at load factor ``s_new`` (velocity from ``s_old``),
    on the nodes ``qlo ≤ q < qhi``."""
    for ip in range(pl_ptr.shape[0] - 1):
        a, b = pl_ptr[ip], pl_ptr[ip + 1]
        if pl_kind[ip] == 0:  # u = s · U1, v = U1 Δs/dt: no work arrays, no division (most plates)
            rate = (s_new - s_old) / dt
            for d in range(3):
                if pl_mask[ip, d]:
                    for i in range(a, b):
                        q = pl_nodes[i]
                        if q < qlo or q >= qhi:
                            continue
                        u1 = pl_U1[d, i]
                        W[xb + d * L + q] = (X[d, q] + s_new * u1) if posmode else s_new * u1
                        W[vb + d * L + q] = rate * u1
            continue
        nodes = pl_nodes[a:b]
        U1 = pl_U1[:, a:b]
        n = nodes.shape[0]
        uo = u_old[:, :n]
        un = u_new[:, :n]
        plate_displacement(X, nodes, U1, pl_kind[ip], pl_axis[ip], pl_center[ip], pl_angle[ip], pl_disp[ip], s_old, R, uo)
        plate_displacement(X, nodes, U1, pl_kind[ip], pl_axis[ip], pl_center[ip], pl_angle[ip], pl_disp[ip], s_new, R, un)
        for d in range(3):
            if pl_mask[ip, d]:
                for i in range(n):
                    q = nodes[i]
                    if q < qlo or q >= qhi:
                        continue
                    W[xb + d * L + q] = (X[d, q] + un[d, i]) if posmode else un[d, i]
                    W[vb + d * L + q] = (un[d, i] - uo[d, i]) / dt


@njit(**_OPTS)
def find_bad(W, xb, L, N, posmode, X, limit2):
    """A node whose position is not finite, else the node of largest displacement if its square
    exceeds ``limit2``, else −1."""
    worst = -1
    wmax = limit2
    for p in range(N):
        d0 = float(W[xb + p])
        d1 = float(W[xb + L + p])
        d2 = float(W[xb + 2 * L + p])
        if posmode:
            d0 -= X[0, p]
            d1 -= X[1, p]
            d2 -= X[2, p]
        s = d0 * d0 + d1 * d1 + d2 * d2
        if not np.isfinite(s):
            return p
        if s > wmax:
            worst = p
            wmax = s
    return worst


@njit(**_OPTS)
def plate_scratch(pl_ptr):
    """Work arrays of :func:`apply_plates`: a rotation and two (3, largest plate) buffers."""
    nmax = 1
    for ip in range(pl_ptr.shape[0] - 1):
        nmax = max(nmax, pl_ptr[ip + 1] - pl_ptr[ip])
    return np.empty((3, 3)), np.empty((3, nmax)), np.empty((3, nmax))


@njit(**_OPTS)
def end_of_step(W, xb, vb, L, N, posmode, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis,
                pl_center, pl_angle, step, dt, ramp_time, R, u_old, u_new, n, nsteps, check_every, limit2):
    """Prescribe the plates for step ``step`` → ``step + 1`` (positions at ``xb``) and, every
    ``check_every`` steps and at the last one, return the index of a diverged node (−1: none)."""
    prescribe(W, xb, vb, L, posmode, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis, pl_center,
              pl_angle, step, dt, ramp_time, R, u_old, u_new, 0, N)
    if (n + 1) % check_every == 0 or n == nsteps - 1:
        return find_bad(W, xb, L, N, posmode, X, limit2)
    return -1
