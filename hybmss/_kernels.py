"""Numba stencil kernel of the explicit step (the only module that imports numba).

The lattice is regular, so every spring joins a grid node ``p`` to ``p + o`` for one of the 13
forward neighbour offsets ``o`` (SPEC §9 "Fast explicit kernel"), and a cell's 8 corners are
``p + coff[c]``.  All arrays live on the full ``(nx+1)(ny+1)(nz+1)`` grid, flattened in C order,
with one stiffness row per offset (zero where a spring is absent: free faces, voxel masks and the
wrap-around pairs of the flattening), so every inner loop is a unit-stride loop that LLVM
vectorizes (sqrt and division included, ``error_model='numpy'``).  Layouts (built by
:mod:`hybmss.explicit`):

- ``x, v, X``: (3, N) positions, velocities (at half steps), reference positions;
- ``K``: (n_off, N) spring constants of the active offsets ``offs`` (n_off,), rest lengths
  ``l0`` (n_off,) (one per offset: the grid is regular);
- ``kv``: (2, N) κ and rest volume of the cell whose lowest corner is p (κ = 0 where no cell);
- ``invm``: (N,) 1/m (0 at absent nodes, which therefore never move); ``gacc`` (3, N) gravity
  at present nodes.

One step (semi-implicit Euler, damping implicit, see :mod:`hybmss.explicit`):

1. stage A: per spring ``t = k (1 − l0/l) (x_b − x_a)``, stored per offset and added to the
   first node's force; per cell the averaged edge vectors, ``V' = a·(b×c)``, ``W'(V')`` and the
   four corner gradients ``G`` (the other four corners get their negatives);
2. stage B: per node ``f −= Σ_o t_o[p − o]`` and ``f += Σ_c ±G_c[p − coff_c]`` (shifted rows
   summed four at a time; a zero pad in front of the work rows keeps every shift in range),
   then ``v ← (v + dt (f/m + g)) / (1 + c dt)``, ``x ← x + dt v``;
3. plates: prescribed components ``x = X + u(s(t))`` with the ramp s(t), ``v = Δu/dt``;
4. every ``check_every`` steps: a non-finite position or a displacement beyond the limit stops
   the run and names the node.

Inner loops run over 0-based views (no wrap-around test on the index) with few store streams
(few run-time alias checks), so LLVM vectorizes them.  A term a scene does not need (volume, gravity, face diagonals) is skipped by
a test outside the inner loops, so ν = 1/4 costs what hybmss-cf costs.  ``run_parallel`` splits
stages A and B into node ranges with ``prange`` (two parallel regions per step: worth it only on
large lattices and idle cores).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

# fastmath stays off: it gained nothing measurable here (sqrt and division set the pace, and AVX2
# has no double-precision reciprocal estimate), and it would let LLVM drop the NaN tests of
# find_bad.  Without it the kernel and the NumPy twin differ only by summation order.
_OPTS = dict(cache=True, error_model="numpy", fastmath=False, nogil=True)


@njit(**_OPTS)
def ramp(t, T):
    """Load factor s(t) = ½ (1 − cos(π t / T)) for t < T, then 1 (s = 1 when T ≤ 0)."""
    if T <= 0.0 or t >= T:
        return 1.0
    if t <= 0.0:
        return 0.0
    return 0.5 * (1.0 - math.cos(math.pi * t / T))


# Every inner loop below runs over 0-based views (``for i in range(n)`` on slices), so that the
# index is provably non-negative, Numba emits no wrap-around test and LLVM vectorizes the loop.


@njit(**_OPTS)
def springs_stage(x, K, l0, offs, T, F, P, lo, hi):
    """Stage A, springs with first node a in [lo, hi): t = k (1 − l0/l)(x_b − x_a) into
    T[j, :, P + a], and F[a] = Σ_o t_o[a] (the forces on the first nodes; F[lo:hi] is
    overwritten).  The first P entries of T's rows are a zero pad (see stage B)."""
    N = x.shape[1]
    for d in range(3):
        f = F[d, lo:hi]
        for i in range(hi - lo):
            f[i] = 0.0
    for j in range(offs.shape[0]):
        o = offs[j]
        L = l0[j]
        end = min(hi, N - o)
        if end <= lo:
            continue
        n = end - lo
        xa0 = x[0, lo:end]
        xa1 = x[1, lo:end]
        xa2 = x[2, lo:end]
        xb0 = x[0, lo + o:end + o]
        xb1 = x[1, lo + o:end + o]
        xb2 = x[2, lo + o:end + o]
        k = K[j, lo:end]
        t0 = T[j, 0, P + lo:P + end]
        t1 = T[j, 1, P + lo:P + end]
        t2 = T[j, 2, P + lo:P + end]
        f0 = F[0, lo:end]
        f1 = F[1, lo:end]
        f2 = F[2, lo:end]
        for i in range(n):
            dx = xb0[i] - xa0[i]
            dy = xb1[i] - xa1[i]
            dz = xb2[i] - xa2[i]
            l = math.sqrt(dx * dx + dy * dy + dz * dz)
            c = k[i] * (1.0 - L / l)
            t0[i] = c * dx
            t1[i] = c * dy
            t2[i] = c * dz
            f0[i] += c * dx
            f1[i] += c * dy
            f2[i] += c * dz


@njit(**_OPTS)
def cells_stage(x, kv, coff, squared, ABC, CR, G, P, lo, hi):
    """Stage A, cells with lowest corner p in [lo, hi), in four unit-stride passes (each simple
    enough for LLVM to vectorize without alias trouble):

    1. averaged edge vectors ``ABC[3 d + i]`` (axis d, component i): ¼ Σ of the 4 parallel edges;
    2. ``CR[0:3] = b×c``, ``CR[3:6] = c×a``, ``CR[6:9] = a×b``, ``CR[9] = V' = a·(b×c)``;
    3. ``CR[9] ← W'(V')/4`` (``kv[0]`` = κ, 0 where no cell; ``kv[1]`` = rest volume);
    4. ``G[g, :, P + p] = CR[9]·(b×c + σ2 c×a + σ3 a×b)`` for (σ2, σ3) = (+,+), (+,−), (−,+),
       (−,−) (the first P entries of G's rows are a zero pad).
    """
    N = x.shape[1]
    end = min(hi, N - coff[7])
    if end <= lo:
        return
    n = end - lo
    # corners along axis d: the 4 edges go from p + e to p + e + coff[1 << d]
    for d in range(3):
        od = coff[1 << d]
        e1 = coff[1 << ((d + 1) % 3)]
        e2 = coff[1 << ((d + 2) % 3)]
        e3 = e1 + e2
        for c in range(3):
            xc = x[c]
            a0 = xc[lo:end]
            a1 = xc[lo + od:end + od]
            b0 = xc[lo + e1:end + e1]
            b1 = xc[lo + e1 + od:end + e1 + od]
            c0 = xc[lo + e2:end + e2]
            c1 = xc[lo + e2 + od:end + e2 + od]
            d0 = xc[lo + e3:end + e3]
            d1 = xc[lo + e3 + od:end + e3 + od]
            out = ABC[3 * d + c, lo:end]
            for i in range(n):
                out[i] = 0.25 * (((a1[i] - a0[i]) + (b1[i] - b0[i])) + ((c1[i] - c0[i]) + (d1[i] - d0[i])))
    # b×c, c×a, a×b component by component: one store stream per loop keeps LLVM's run-time
    # alias checks few enough for it to vectorize
    for r in range(3):  # cross product r: (b×c, c×a, a×b) = (A_{1}×A_{2}) with cyclic axes
        u = 3 * ((r + 1) % 3)
        w = 3 * ((r + 2) % 3)
        for c in range(3):
            c1 = (c + 1) % 3
            c2 = (c + 2) % 3
            _cross_component(CR[3 * r + c, lo:end], ABC[u + c1, lo:end], ABC[w + c2, lo:end],
                             ABC[u + c2, lo:end], ABC[w + c1, lo:end])
    W = CR[9, lo:end]
    _dot3(W, ABC[0, lo:end], ABC[1, lo:end], ABC[2, lo:end], CR[0, lo:end], CR[1, lo:end], CR[2, lo:end])
    kap = kv[0, lo:end]
    V0 = kv[1, lo:end]
    if squared:  # W = κ/2 Vc q², q = (V'² − Vc²)/(2 Vc²):  W' = κ q V'/Vc
        for i in range(n):
            V = W[i]
            q = (V * V - V0[i] * V0[i]) / (2.0 * V0[i] * V0[i])
            W[i] = 0.25 * kap[i] * q * V / V0[i]
    else:  # W = κ/2 Vc J², J = (V' − Vc)/Vc:  W' = κ J
        for i in range(n):
            W[i] = 0.25 * kap[i] * (W[i] - V0[i]) / V0[i]
    for c in range(3):
        A = CR[c, lo:end]
        B = CR[3 + c, lo:end]
        C = CR[6 + c, lo:end]
        _combine(G[0, c, P + lo:P + end], W, A, B, C, 1.0, 1.0)
        _combine(G[1, c, P + lo:P + end], W, A, B, C, 1.0, -1.0)
        _combine(G[2, c, P + lo:P + end], W, A, B, C, -1.0, 1.0)
        _combine(G[3, c, P + lo:P + end], W, A, B, C, -1.0, -1.0)


@njit(**_OPTS)
def _cross_component(out, p, q, r, s):
    for i in range(out.shape[0]):
        out[i] = p[i] * q[i] - r[i] * s[i]


@njit(**_OPTS)
def _dot3(out, a0, a1, a2, b0, b1, b2):
    for i in range(out.shape[0]):
        out[i] = a0[i] * b0[i] + a1[i] * b1[i] + a2[i] * b2[i]


@njit(**_OPTS)
def _combine(out, w, A, B, C, sB, sC):
    """out = w ((A ± B) ± C) (the signs are ±1: exact)."""
    for i in range(out.shape[0]):
        out[i] = w[i] * ((A[i] + sB * B[i]) + sC * C[i])


# Corner c of a cell gets the force f_c = sign · G[slot] of the cell (its lowest corner p = q − coff[c]):
# G0 = σ(+,+,+) corner 7, G1 = (+,+,−) corner 3, G2 = (+,−,+) corner 5, G3 = (+,−,−) corner 1 with a
# minus sign; the corners with di = 0 have σ = −(those): f_0 = +G0, f_4 = +G1, f_2 = +G2, f_6 = +G3.
# Corners 0..3 take slots (0, 3, 2, 1), corners 4..7 slots (1, 2, 3, 0), signs (+, −, +, −) both.


@njit(**_OPTS)
def accumulate_integrate(x, v, F, T, groups, G, coff, has_volume, invm, gacc, has_gravity, dt, damp,
                         P, lo, hi):
    """Stage B on nodes [lo, hi): F[q] −= Σ_o t_o[q − o] (forces on second nodes) and
    F[q] += Σ_c ±G[q − coff_c] (cell corners), then ``v ← (v + dt (F/m + g)) damp``,
    ``x ← x + dt v``.

    ``groups`` (n_g, 4, 2) lists (T row, offset) four at a time (padded with the all-zero row of
    T and offset 0), so each pass sums four shifted rows; the zero pad of P entries in front of
    every row makes every shift q − o ≥ 0 a valid index (reads before the first node give 0).
    """
    n = hi - lo
    for d in range(3):
        f = F[d, lo:hi]
        for g in range(groups.shape[0]):
            r0, r1, r2, r3 = groups[g, 0, 0], groups[g, 1, 0], groups[g, 2, 0], groups[g, 3, 0]
            a = P + lo - groups[g, 0, 1]
            b = P + lo - groups[g, 1, 1]
            c = P + lo - groups[g, 2, 1]
            e = P + lo - groups[g, 3, 1]
            t0 = T[r0, d, a:a + n]
            t1 = T[r1, d, b:b + n]
            t2 = T[r2, d, c:c + n]
            t3 = T[r3, d, e:e + n]
            for i in range(n):
                f[i] -= (t0[i] + t1[i]) + (t2[i] + t3[i])
        if has_volume:
            s = P + lo
            g0 = G[0, d, s:s + n]
            g3 = G[3, d, s - coff[1]:s - coff[1] + n]
            g2 = G[2, d, s - coff[2]:s - coff[2] + n]
            g1 = G[1, d, s - coff[3]:s - coff[3] + n]
            for i in range(n):
                f[i] += (g0[i] - g3[i]) + (g2[i] - g1[i])
            g1 = G[1, d, s - coff[4]:s - coff[4] + n]
            g2 = G[2, d, s - coff[5]:s - coff[5] + n]
            g3 = G[3, d, s - coff[6]:s - coff[6] + n]
            g0 = G[0, d, s - coff[7]:s - coff[7] + n]
            for i in range(n):
                f[i] += (g1[i] - g2[i]) + (g3[i] - g0[i])
        xd = x[d, lo:hi]
        vd = v[d, lo:hi]
        im = invm[lo:hi]
        if has_gravity:
            ga = gacc[d, lo:hi]
            for i in range(n):
                vd[i] = (vd[i] + dt * (f[i] * im[i] + ga[i])) * damp
                xd[i] += dt * vd[i]
        else:
            for i in range(n):
                vd[i] = (vd[i] + dt * (f[i] * im[i])) * damp
                xd[i] += dt * vd[i]


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


@njit(**_OPTS)
def apply_plates(x, v, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis, pl_center,
                 pl_angle, s_old, s_new, dt, R, u_old, u_new):
    for ip in range(pl_ptr.shape[0] - 1):
        nodes = pl_nodes[pl_ptr[ip]:pl_ptr[ip + 1]]
        U1 = pl_U1[:, pl_ptr[ip]:pl_ptr[ip + 1]]
        n = nodes.shape[0]
        uo = u_old[:, :n]
        un = u_new[:, :n]
        plate_displacement(X, nodes, U1, pl_kind[ip], pl_axis[ip], pl_center[ip], pl_angle[ip], pl_disp[ip], s_old, R, uo)
        plate_displacement(X, nodes, U1, pl_kind[ip], pl_axis[ip], pl_center[ip], pl_angle[ip], pl_disp[ip], s_new, R, un)
        for d in range(3):
            if pl_mask[ip, d]:
                for i in range(n):
                    q = nodes[i]
                    x[d, q] = X[d, q] + un[d, i]
                    v[d, q] = (un[d, i] - uo[d, i]) / dt


@njit(**_OPTS)
def find_bad(x, X, limit2):
    """A node whose position is not finite, else the node of largest displacement if its square
    exceeds ``limit2``, else −1."""
    worst = -1
    wmax = limit2
    for p in range(x.shape[1]):
        d0 = x[0, p] - X[0, p]
        d1 = x[1, p] - X[1, p]
        d2 = x[2, p] - X[2, p]
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
def end_of_step(x, v, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis, pl_center, pl_angle,
                step, dt, ramp_time, R, u_old, u_new, n, nsteps, check_every, limit2):
    """Prescribe the plates for step ``step`` → ``step + 1`` and, every ``check_every`` steps and at the
    last one, return the index of a diverged node (−1: none)."""
    if pl_ptr.shape[0] > 1:
        s_old = ramp(step * dt, ramp_time)
        s_new = ramp((step + 1) * dt, ramp_time)
        apply_plates(x, v, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis,
                     pl_center, pl_angle, s_old, s_new, dt, R, u_old, u_new)
    if (n + 1) % check_every == 0 or n == nsteps - 1:
        return find_bad(x, X, limit2)
    return -1


@njit(**_OPTS)
def run_serial(x, v, X, K, l0, offs, groups, kv, coff, squared, has_volume, invm, gacc, has_gravity,
               dt, damp, ramp_time, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis,
               pl_center, pl_angle, step0, nsteps, check_every, limit2, T, ABC, CR, G, F):
    """Advance ``nsteps`` steps from global step ``step0``.  Returns (steps done, bad node or −1)."""
    N = x.shape[1]
    P = coff[7]
    R, u_old, u_new = plate_scratch(pl_ptr)
    for n in range(nsteps):
        springs_stage(x, K, l0, offs, T, F, P, 0, N)
        if has_volume:
            cells_stage(x, kv, coff, squared, ABC, CR, G, P, 0, N)
        accumulate_integrate(x, v, F, T, groups, G, coff, has_volume, invm, gacc, has_gravity, dt, damp, P, 0, N)
        bad = end_of_step(x, v, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis, pl_center,
                          pl_angle, step0 + n, dt, ramp_time, R, u_old, u_new, n, nsteps, check_every, limit2)
        if bad >= 0:
            return n + 1, bad
    return nsteps, -1


@njit(parallel=True, **_OPTS)
def run_parallel(x, v, X, K, l0, offs, groups, kv, coff, squared, has_volume, invm, gacc, has_gravity,
                 dt, damp, ramp_time, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis,
                 pl_center, pl_angle, step0, nsteps, check_every, limit2, T, ABC, CR, G, F, bounds):
    """As :func:`run_serial`, stages A and B split over the node ranges ``bounds`` with prange."""
    nchunks = bounds.shape[0] - 1
    P = coff[7]
    R, u_old, u_new = plate_scratch(pl_ptr)
    for n in range(nsteps):
        for ch in prange(nchunks):
            lo = bounds[ch]
            hi = bounds[ch + 1]
            springs_stage(x, K, l0, offs, T, F, P, lo, hi)
            if has_volume:
                cells_stage(x, kv, coff, squared, ABC, CR, G, P, lo, hi)
        for ch in prange(nchunks):
            accumulate_integrate(x, v, F, T, groups, G, coff, has_volume, invm, gacc, has_gravity, dt,
                                 damp, P, bounds[ch], bounds[ch + 1])
        bad = end_of_step(x, v, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis, pl_center,
                          pl_angle, step0 + n, dt, ramp_time, R, u_old, u_new, n, nsteps, check_every, limit2)
        if bad >= 0:
            return n + 1, bad
    return nsteps, -1


def chunk_bounds(N: int, nchunks: int) -> np.ndarray:
    """Node ranges [b[i], b[i+1]) splitting 0..N into ``nchunks`` parts aligned to 8 nodes."""
    step = -(-N // nchunks)
    step = -(-step // 8) * 8
    b = np.minimum(np.arange(nchunks + 1, dtype=np.int64) * step, N)
    b[-1] = N
    return b


def advance(st, x, v, step0, nsteps, check_every, limit2, scratch, threads=1):
    """Run ``nsteps`` steps of the stencil ``st`` (a :class:`hybmss.explicit.Stencil`) on the grid
    state ``x, v`` (3, N), in place.  Returns (steps done, bad node or −1)."""
    T, ABC, CR, G, F = scratch
    args = (x, v, st.Xg, st.K, st.l0, st.offs, st.groups, st.kv, st.coff, st.squared, st.has_volume,
            st.invm, st.gacc, st.has_gravity, st.dt, st.damp, st.ramp_time, st.pl_nodes, st.pl_U1, st.pl_ptr,
            st.pl_mask, st.pl_kind, st.pl_disp, st.pl_axis, st.pl_center, st.pl_angle,
            np.int64(step0), np.int64(nsteps), np.int64(max(1, check_every)), float(limit2), T, ABC, CR, G, F)
    if threads <= 1:
        done, bad = run_serial(*args)
    else:
        import numba

        old = numba.get_num_threads()
        numba.set_num_threads(min(int(threads), numba.config.NUMBA_NUM_THREADS))
        try:
            done, bad = run_parallel(*args, chunk_bounds(x.shape[1], int(threads)))
        finally:
            numba.set_num_threads(old)
    return int(done), int(bad)
