"""Numba kernel of ``xpbd-nh``: XPBD substeps with the stable Neo-Hookean constraints.

Layouts as in :mod:`hybmss._kernels` on particle arrays: ``x, v, X`` (3, n); ``winv`` (3, n) the
inverse mass per component (0 on prescribed components); tetrahedra ``tets`` (T, 4) with the
inverse rest edge matrices ``Dminv`` (T, 3, 3) and their weighted rest volumes ``Vt`` (T,).

One substep of size h (see :mod:`hybmss.models.xpbd_nh` for the method):

1. ``v ← (v + h g) / (1 + c h)``; ``x_prev = x``; ``x ← x + h v``; the plates' prescribed
   components move to ``X + u(s(t + h))`` (:func:`hybmss._kernels.apply_plates`);
2. ``iterations`` Gauss–Seidel sweeps over the tetrahedra in order, each projecting its
   deviatoric constraint ``C_D = √tr(FᵀF)`` (compliance ``1/(μ V)``) and hydrostatic one
   ``C_H = det F − γ`` (``1/(λ V)``) together (one 2×2 solve, ``coupled``) or C_D then C_H,
   with multipliers reset at the start of the substep;
3. ``v = (x − x_prev)/h``.

Precision: the state ``W`` holds float64 positions or float32 displacements (``posmode`` False,
:mod:`hybmss.models._voxel_explicit`); the constraint arithmetic is float64 in both.

The readable twin is :func:`hybmss.models.xpbd_nh.numpy_substep` (same order, plain Python).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._kernels import apply_plates, find_bad, plate_scratch, ramp

_OPTS = dict(cache=True, error_model="numpy", fastmath=False, nogil=True)


@njit(**_OPTS)
def _gradients(x, posmode, i0, i1, i2, i3, Dm, kind, gamma, F, P, Gr):
    """C and its node gradients Gr (3, 4) of constraint ``kind`` (0: C_D, 1: C_H) of a tetrahedron
    (``F`` is left holding its deformation gradient)."""
    deformation_gradient(x, posmode, i0, i1, i2, i3, Dm, F)
    if kind == 1:
        return _hydrostatic_from(F, Dm, gamma, P, Gr)
    C = math.sqrt(F[0, 0] ** 2 + F[0, 1] ** 2 + F[0, 2] ** 2 + F[1, 0] ** 2 + F[1, 1] ** 2 + F[1, 2] ** 2
                  + F[2, 0] ** 2 + F[2, 1] ** 2 + F[2, 2] ** 2)
    for a in range(3):
        s = 0.0
        for j in range(3):
            gj = (F[a, 0] * Dm[j, 0] + F[a, 1] * Dm[j, 1] + F[a, 2] * Dm[j, 2]) / C
            Gr[a, j + 1] = gj
            s += gj
        Gr[a, 0] = -s
    return C


@njit(**_OPTS)
def deformation_gradient(x, posmode, i0, i1, i2, i3, Dm, F):
    """``F = D_s D_m⁻¹`` of a tetrahedron, in float64: ``x`` holds positions (``posmode``) or
    displacements (then ``F = I + D_u D_m⁻¹``, as ``D_X D_m⁻¹ = I``)."""
    for a in range(3):
        e1 = x[a, i1] - x[a, i0]
        e2 = x[a, i2] - x[a, i0]
        e3 = x[a, i3] - x[a, i0]
        for b in range(3):
            F[a, b] = e1 * Dm[0, b] + e2 * Dm[1, b] + e3 * Dm[2, b]
    if not posmode:
        F[0, 0] += 1.0
        F[1, 1] += 1.0
        F[2, 2] += 1.0


@njit(**_OPTS)
def _hydrostatic_from(F, Dm, gamma, P, Gr):
    """C_H and its gradients Gr (3, 4) from a deformation gradient F already computed (``P``
    is left holding cof F)."""
    P[0, 0] = F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]
    P[0, 1] = F[1, 2] * F[2, 0] - F[1, 0] * F[2, 2]
    P[0, 2] = F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]
    P[1, 0] = F[2, 1] * F[0, 2] - F[2, 2] * F[0, 1]
    P[1, 1] = F[2, 2] * F[0, 0] - F[2, 0] * F[0, 2]
    P[1, 2] = F[2, 0] * F[0, 1] - F[2, 1] * F[0, 0]
    P[2, 0] = F[0, 1] * F[1, 2] - F[0, 2] * F[1, 1]
    P[2, 1] = F[0, 2] * F[1, 0] - F[0, 0] * F[1, 2]
    P[2, 2] = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
    C = F[0, 0] * P[0, 0] + F[0, 1] * P[0, 1] + F[0, 2] * P[0, 2] - gamma
    for a in range(3):
        s = 0.0
        for j in range(3):
            gj = P[a, 0] * Dm[j, 0] + P[a, 1] * Dm[j, 1] + P[a, 2] * Dm[j, 2]
            Gr[a, j + 1] = gj
            s += gj
        Gr[a, 0] = -s
    return C


@njit(**_OPTS)
def _wdot(Wl, A, B):
    """Σ_i A_iᵀ W_i B_i over the tetrahedron's nodes (``Wl`` (3, 4) their inverse masses)."""
    s = 0.0
    for k in range(4):
        for a in range(3):
            s += Wl[a, k] * A[a, k] * B[a, k]
    return s


@njit(**_OPTS)
def _move(x, tets, t, Wl, A, da, B, db):
    for k in range(4):
        q = tets[t, k]
        for a in range(3):
            x[a, q] += Wl[a, k] * (A[a, k] * da + B[a, k] * db)


@njit(**_OPTS)
def project_all(x, posmode, winv, tets, Dminv, Vt, mu, lam, gamma, h, iterations, coupled, lamb):
    """``iterations`` Gauss–Seidel sweeps (multipliers ``lamb`` (T, 2) reset first).  ``coupled``:
    both constraints of a tetrahedron in one 2×2 solve; else C_D then C_H, one after the other.
    ``x``: positions (``posmode``) or displacements (the float32 state, :func:`run`); the
    constraint arithmetic is float64 either way.  The compliances ``α̃ = 1/(μ V h²)``, ``1/(λ V h²)`` are
    products of precomputed inverses (one division per tetrahedron)."""
    F = np.empty((3, 3))
    P = np.empty((3, 3))
    GD = np.empty((3, 4))
    GH = np.empty((3, 4))
    Wl = np.empty((3, 4))
    nt = tets.shape[0]
    for t in range(nt):
        lamb[t, 0] = 0.0
        lamb[t, 1] = 0.0
    ih2 = 1.0 / (h * h)
    imu = 1.0 / mu
    ilam = 1.0 / lam
    for it in range(iterations):
        for t in range(nt):
            i0 = tets[t, 0]
            i1 = tets[t, 1]
            i2 = tets[t, 2]
            i3 = tets[t, 3]
            Dm = Dminv[t]
            iv = ih2 / Vt[t]
            aD = imu * iv
            aH = ilam * iv
            for k in range(4):
                q = tets[t, k]
                for a in range(3):
                    Wl[a, k] = winv[a, q]
            if coupled:  # one F for both constraints, written out (the hot loop)
                for a in range(3):
                    x0 = x[a, i0]
                    e1 = x[a, i1] - x0
                    e2 = x[a, i2] - x0
                    e3 = x[a, i3] - x0
                    for b in range(3):
                        F[a, b] = e1 * Dm[0, b] + e2 * Dm[1, b] + e3 * Dm[2, b]
                if not posmode:
                    F[0, 0] += 1.0
                    F[1, 1] += 1.0
                    F[2, 2] += 1.0
                s2 = 0.0
                for a in range(3):
                    for b in range(3):
                        s2 += F[a, b] * F[a, b]
                CD = math.sqrt(s2)
                ic = 1.0 / CD
                P[0, 0] = F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]
                P[0, 1] = F[1, 2] * F[2, 0] - F[1, 0] * F[2, 2]
                P[0, 2] = F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]
                P[1, 0] = F[2, 1] * F[0, 2] - F[2, 2] * F[0, 1]
                P[1, 1] = F[2, 2] * F[0, 0] - F[2, 0] * F[0, 2]
                P[1, 2] = F[2, 0] * F[0, 1] - F[2, 1] * F[0, 0]
                P[2, 0] = F[0, 1] * F[1, 2] - F[0, 2] * F[1, 1]
                P[2, 1] = F[0, 2] * F[1, 0] - F[0, 0] * F[1, 2]
                P[2, 2] = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
                CH = F[0, 0] * P[0, 0] + F[0, 1] * P[0, 1] + F[0, 2] * P[0, 2] - gamma
                a11 = aD
                a12 = 0.0
                a22 = aH
                for a in range(3):
                    sD = 0.0
                    sH = 0.0
                    for j in range(3):
                        gd = (F[a, 0] * Dm[j, 0] + F[a, 1] * Dm[j, 1] + F[a, 2] * Dm[j, 2]) * ic
                        gh = P[a, 0] * Dm[j, 0] + P[a, 1] * Dm[j, 1] + P[a, 2] * Dm[j, 2]
                        GD[a, j + 1] = gd
                        GH[a, j + 1] = gh
                        sD += gd
                        sH += gh
                    GD[a, 0] = -sD
                    GH[a, 0] = -sH
                    for k in range(4):
                        w = Wl[a, k]
                        a11 += w * GD[a, k] * GD[a, k]
                        a12 += w * GD[a, k] * GH[a, k]
                        a22 += w * GH[a, k] * GH[a, k]
                b1 = -CD - aD * lamb[t, 0]
                b2 = -CH - aH * lamb[t, 1]
                idet = 1.0 / (a11 * a22 - a12 * a12)
                d1 = (a22 * b1 - a12 * b2) * idet
                d2 = (a11 * b2 - a12 * b1) * idet
                for k in range(4):
                    q = tets[t, k]
                    for a in range(3):
                        x[a, q] += Wl[a, k] * (GD[a, k] * d1 + GH[a, k] * d2)
                lamb[t, 0] += d1
                lamb[t, 1] += d2
            else:
                CD = _gradients(x, posmode, i0, i1, i2, i3, Dm, 0, gamma, F, P, GD)
                d1 = (-CD - aD * lamb[t, 0]) / (aD + _wdot(Wl, GD, GD))
                _move(x, tets, t, Wl, GD, d1, GD, 0.0)
                lamb[t, 0] += d1
                CH = _gradients(x, posmode, i0, i1, i2, i3, Dm, 1, gamma, F, P, GH)
                d2 = (-CH - aH * lamb[t, 1]) / (aH + _wdot(Wl, GH, GH))
                _move(x, tets, t, Wl, GH, d2, GH, 0.0)
                lamb[t, 1] += d2


@njit(**_OPTS)
def moved_since(x, xcheck):
    """Largest component change of ``x`` (3, n) since ``xcheck``, which then takes ``x``'s values."""
    moved = 0.0
    for d in range(3):
        for q in range(x.shape[1]):
            moved = max(moved, abs(x[d, q] - xcheck[d, q]))
            xcheck[d, q] = x[d, q]
    return moved


@njit(**_OPTS)
def run(W, posmode, X, winv, tets, Dminv, Vt, mu, lam, gamma, gacc, has_gravity, h, damp, ramp_time, pl_nodes,
        pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis, pl_center, pl_angle, sub0, nsub, iterations,
        coupled, check_every, limit2, rest_after, rest_disp, xprev, lamb):
    """Advance ``nsub`` substeps from global substep ``sub0``.  Every ``check_every`` substeps: a
    diverged node stops the run; after substep ``rest_after`` (the end of the ramp; −1: never) the
    run also stops once no node moved more than ``rest_disp`` over the last ``check_every``
    substeps.  ``W``: the state of :func:`hybmss._kernels.particle_state`.  Returns (substeps
    done, bad node or −1, 1 if at rest else 0).

    ``posmode``: ``W`` holds positions (float64).  Else it holds float32 displacements from ``X``
    and velocities: each substep runs on a float64 copy of the state and is rounded back at its
    end, so that the velocity ``(x − x_prev)/h`` is not the rounding of x divided by h (which
    would feed ~ulp(u)/h of noise into the motion every substep).  ``xprev`` (3, n) float64."""
    n = X.shape[1]
    Wk = np.empty(W.shape[0])
    for i in range(W.shape[0]):
        Wk[i] = W[i]
    x = Wk[:3 * n].reshape((3, n))
    v = Wk[3 * n:].reshape((3, n))
    R, u_old, u_new = plate_scratch(pl_ptr)
    xcheck = x.copy()
    done = nsub
    bad = -1
    rest = 0
    for k in range(nsub):
        step = sub0 + k
        for d in range(3):
            for q in range(n):
                if has_gravity:
                    v[d, q] = (v[d, q] + h * gacc[d, q]) * damp
                else:
                    v[d, q] = v[d, q] * damp
                xprev[d, q] = x[d, q]
                x[d, q] += h * v[d, q]
        if pl_ptr.shape[0] > 1:
            apply_plates(Wk, 0, 3 * n, n, posmode, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis,
                         pl_center, pl_angle, ramp(step * h, ramp_time), ramp((step + 1) * h, ramp_time), h, R,
                         u_old, u_new, 0, n)
        project_all(x, posmode, winv, tets, Dminv, Vt, mu, lam, gamma, h, iterations, coupled, lamb)
        for d in range(3):
            for q in range(n):
                v[d, q] = (x[d, q] - xprev[d, q]) / h
        if not posmode:  # the stored state is float32
            for i in range(W.shape[0]):
                W[i] = Wk[i]
                Wk[i] = W[i]
        if (k + 1) % check_every == 0 or k == nsub - 1:
            bad = find_bad(Wk, 0, n, n, posmode, X, limit2)
            if bad >= 0:
                done = k + 1
                break
            if rest_after >= 0 and step + 1 >= rest_after and (k + 1) % check_every == 0:
                if moved_since(x, xcheck) <= rest_disp:
                    done = k + 1
                    rest = 1
                    break
            else:
                xcheck[:, :] = x
    if posmode:
        for i in range(W.shape[0]):
            W[i] = Wk[i]
    return done, bad, rest


@njit(**_OPTS)
def relax(W, X, winv, tets, Dminv, Vt, mu, lam, gamma, gdisp, has_gravity, h, over, beta, H, ramp_time, pl_nodes,
          pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis, pl_center, pl_angle, k0, nk, iterations, coupled,
          check_every, limit2, rest_after, rest_disp, xprev, y, lamb):
    """``nk`` iterations, from iteration ``k0``, of the relaxation to the rest state of the substep
    ``h`` (:func:`hybmss.models.xpbd_nh.relax_static`), float64 positions ``W[:3n]``::

        y = x + β (x − x_prev);  z = y + gdisp  (gdisp = damp h² g on free components)
        prescribed components of z at the load s((k + 1) H);  p = project_h(z)
        x_new = y + over · (p − y)  on free components (p on prescribed ones)

    A fixed point (x = x_prev) has ``project_h(x + gdisp) = x``: the rest state of the XPBD
    substep, whatever ``over`` and ``β``.  Checks as in :func:`run`, every ``check_every``
    iterations.  ``W`` (6n,): positions, then a scratch for the plates' velocities.  Returns
    (iterations done, bad node or −1, 1 if at rest else 0)."""
    n = X.shape[1]
    x = W[:3 * n].reshape((3, n))
    R, u_old, u_new = plate_scratch(pl_ptr)
    xcheck = x.copy()
    done = nk
    bad = -1
    rest = 0
    for k in range(nk):
        it = k0 + k
        for d in range(3):
            for q in range(n):
                yq = x[d, q] + beta * (x[d, q] - xprev[d, q])
                xprev[d, q] = x[d, q]
                y[d, q] = yq
                x[d, q] = yq + gdisp[d, q] if has_gravity else yq
        if pl_ptr.shape[0] > 1:
            apply_plates(W, 0, 3 * n, n, True, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis,
                         pl_center, pl_angle, ramp(it * H, ramp_time), ramp((it + 1) * H, ramp_time), H, R,
                         u_old, u_new, 0, n)
        project_all(x, True, winv, tets, Dminv, Vt, mu, lam, gamma, h, iterations, coupled, lamb)
        for d in range(3):
            for q in range(n):
                if winv[d, q] != 0.0:
                    x[d, q] = y[d, q] + over * (x[d, q] - y[d, q])
        if (k + 1) % check_every == 0 or k == nk - 1:
            bad = find_bad(W, 0, n, n, True, X, limit2)
            if bad >= 0:
                done = k + 1
                break
            if rest_after >= 0 and it + 1 >= rest_after and (k + 1) % check_every == 0:
                if moved_since(x, xcheck) <= rest_disp:
                    done = k + 1
                    rest = 1
                    break
            else:
                xcheck[:, :] = x
    return done, bad, rest
