"""Source of the explicit stencil kernel, generated per lattice and compiled by Numba.

The kernel of :mod:`hybmss._kernels` is fast only if LLVM vectorizes its square roots and
divisions (8 doubles or 16 floats per AVX-512 instruction).  It does so when every array access
is ``W[C + a]``: one flat array ``W`` holding all state, ``C`` a literal integer and ``a`` a
loop index known to be non-negative, inside loops of literal length.  LLVM then needs no
run-time alias checks and Numba no negative-index wrap test.  So the kernel source is written
for one lattice size, one set of terms, one precision and one thread count, and compiled.

Layout of ``W`` (:class:`Layout`): regions of ``L`` entries, each with a front pad of ``F``
entries (F ≥ the largest flat offset ``H = s0 + s1 + 1``) and a back pad of ``F``; node q of
region r is ``W[r L + F + q]``.  Regions, in order: two position buffers (``XA``, ``XB``, three
rows each; steps alternate between them, so a thread never reads a position another thread is
writing), velocities ``V`` (3), one spring-constant row per active offset ``K_j``, κ per cell
``KAP`` (volume term only), ``1/m`` ``IM``, gravity ``GA`` (3, only with gravity), external
forces ``FE`` (3, only when the system has forces the kernel does not generate), and the partial
sums ``R``: three rows for each offset o of ``roff`` (o = 0 first), shared by the threads.

One step is one pass over blocks of 64 nodes.  Loop 1 over the cell bases p of a block computes
what base p gives to node p + o: ``R_0[p] = Σ_j t_j[p] + G_0[p]`` and, for o > 0,
``R_o[p] = −t_o[p] ± G_c[p]`` (the spring tension ``t = k (1 − l0/l) d`` of the spring p → p + o
and the volume gradient of the corner c at offset o of the cell whose lowest corner is p).
Loop 2 over the nodes q of the block gathers ``f[q] = Σ_o R_o[q − o]`` (every base q − o ≤ q
was done in this block or an earlier one) and integrates ``v ← (v + dt (f/m + g)) damp``,
``x ← x + dt v`` into the other position buffer.  With T threads, thread t owns the blocks
``[b_t, b_{t+1})`` and first recomputes the halo bases ``[b_t − H, b_t)`` (loop 1 only) instead
of waiting for the thread below: no barrier inside a step, and the same arithmetic per node
whatever T (threads agree bit for bit).  The thread below writes the same values to the same
halo entries of R (same code, same inputs, no position written within a step), so one set of R
rows serves all threads and one function ``thread``, its blocks given as arguments, serves every
thread.  :func:`run_threads` runs all the steps at once on T operating-system threads: thread
t sets the plates of its own nodes after its step and meets the others at one spinning barrier
(:mod:`hybmss._cpu`), so a step costs no thread start-up; ``run`` (a force stage, or
threads that did not all run at once) opens a Numba parallel region per step.

A force term the stencil does not generate (not a spring, the volume term, gravity or a dead load)
may contribute its own **stage** (:class:`hybmss.models.hybmss.stepper.StencilStage`): a Numba function
``stage(W, xb, feb, L, N, F0, args)`` that writes the term's forces at the positions of region
base ``xb`` plus the dead loads ``F0`` (3, N) into the external-force rows at ``feb``, before
every step; ``args`` is a tuple of its own arrays and constants.  The generated ``run`` imports
it by name (``Config.stage``) and calls it; the generator knows nothing of the term.
Every thread computes with subnormals flushed to zero (:func:`hybmss._cpu.flush_subnormals`).

Precision ``f64`` stores positions x and evaluates the formulas of :mod:`hybmss.forces`.
Precision ``f32`` stores displacements u = x − X (positions of a few metres keep only ~1e-7 m
in float32, displacements keep 1e-7 of themselves) and avoids the cancellations of small
strains: a spring of rest vector D (a literal) has ``g = l² − l0² = 2 D·Δu + |Δu|²``, ``l = √(l0² + g)``
and ``k (1 − l0/l) = k g/(l (l + l0))``; a cell ``det(le I + Δ) − le³ = le² tr Δ +
le M₂(Δ) + det Δ`` (M₂ the sum of the principal 2×2 minors of the averaged edge increments Δ).
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import sys
import tempfile
from dataclasses import dataclass

import numpy as np

from ._cpu import MESSAGE, SLOTS

BLOCK = 64
"""Nodes per block of the two loops (a multiple of the vector width of either precision)."""

LOOP1_SHARE = 0.75
"""Share of loop 1 (the partial sums, with every square root and division) in the time of a
block's step, for :meth:`Layout.bounds`.  On the 10³ cube (21 blocks, a halo of 3) the split
12 | 9 that it gives took 0.298 s per 10k steps (f64, two threads, median of six runs
alternating with the even split, load 1.0) against 0.317 s for 11 | 10; 13 | 8 was slower
again.  On 30³ (466 blocks, a halo of 16) 239 | 227 gains 2–4 % over 233 | 233."""

GENERATOR_VERSION = 9
"""Bumped whenever the generated source changes meaning (it is part of the cache key)."""

# corner c of a cell (grid offset (c & 1, c >> 1 & 1, c >> 2 & 1)) gets sign · G[slot] of the cell
# whose lowest corner is p = q − coff[c] (see the module docstring of hybmss._kernels)
CORNER_SLOT = (0, 3, 2, 1, 1, 2, 3, 0)
CORNER_SIGN = (1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0)
SLOT_SIGNS = ((1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0))


def _round_up(n: int, m: int) -> int:
    return -(-n // m) * m


@dataclass(frozen=True)
class Config:
    """Everything the generated source depends on (its cache key)."""

    shape: tuple[int, int, int]  # grid nodes per axis
    offsets: tuple[tuple[int, int, int], ...]  # active spring offsets (grid), lexicographically > 0
    has_volume: bool
    squared: bool
    has_gravity: bool
    has_external: bool  # external-force rows FE (dead loads, a force stage's forces)
    stage: str | None  # "module:function" of a force term's stage: FE recomputed every step
    precision: str  # "f64" or "f32"
    threads: int
    le: float  # lattice spacing (f32: the rest vectors D are literals)

    def key(self) -> str:
        return hashlib.sha1(repr((GENERATOR_VERSION, self)).encode()).hexdigest()[:20]


@dataclass(frozen=True)
class Layout:
    """Region offsets of the flat state array (see the module docstring)."""

    cfg: Config
    N: int
    s0: int
    s1: int
    H: int
    F: int
    L: int
    nblocks: int
    roff: tuple[int, ...]  # flat offsets of the partial sums, 0 first
    regions: dict  # name -> region index

    def base(self, name: str) -> int:
        """Index in W of node 0 of region ``name``."""
        return self.regions[name] * self.L + self.F

    @property
    def size(self) -> int:
        return len(self.regions) * self.L

    def bounds(self) -> list[int]:
        """Block boundaries [b_0 = 0, …, b_T = nblocks) of the threads, for equal work: every
        thread but the first also runs loop 1 over its halo (``⌈H/BLOCK⌉`` blocks), which costs
        :data:`LOOP1_SHARE` of a block's step, so the threads above the first get fewer blocks."""
        T, n = self.cfg.threads, self.nblocks
        halo = LOOP1_SHARE * -(-self.H // BLOCK)
        per_thread = (n + halo * (T - 1)) / T
        b = [0]
        for t in range(1, T):
            b.append(min(n, max(b[-1], int(t * per_thread - halo * (t - 1) + 0.5))))
        return b + [n]


def layout(cfg: Config) -> Layout:
    n0, n1, n2 = cfg.shape
    s0, s1 = n1 * n2, n2
    N = n0 * n1 * n2
    H = s0 + s1 + 1
    F = _round_up(H, BLOCK)
    nblocks = -(-N // BLOCK)
    L = F + nblocks * BLOCK + F
    flat = [o[0] * s0 + o[1] * s1 + o[2] for o in cfg.offsets]
    # distinct grid offsets can share a flat offset on a thin grid (n1 = 2: (1, −1, k) and (0, 1, k));
    # at any base at most one of them is a spring (the other joins across the flattening, k = 0),
    # and both reach the same node, so they share one row of partial sums
    roff = [0]
    for o in flat:
        if o not in roff:
            roff.append(o)
    if cfg.has_volume:
        for c in range(1, 8):
            o = (c & 1) * s0 + ((c >> 1) & 1) * s1 + ((c >> 2) & 1)
            if o not in roff:
                roff.append(o)
    names = ["XA0", "XA1", "XA2"] + (["XB0", "XB1", "XB2"] if cfg.threads > 1 else []) + ["V0", "V1", "V2"]
    names += [f"K{j}" for j in range(len(flat))]
    if cfg.has_volume:
        names.append("KAP")
    names.append("IM")
    if cfg.has_gravity:
        names += ["GA0", "GA1", "GA2"]
    if cfg.has_external:
        names += ["FE0", "FE1", "FE2"]
    for o in roff:
        names += [f"R_{o}_{d}" for d in range(3)]
    return Layout(cfg, N, s0, s1, H, F, L, nblocks, tuple(roff), {n: i for i, n in enumerate(names)})


# ------------------------------------------------------------------------------ source
class _Src:
    def __init__(self):
        self.lines: list[str] = []

    def __call__(self, indent: int, text: str):
        self.lines.append("    " * indent + text)


def _lit(v: float, f32: bool) -> str:
    return f"np.float32({float(v)!r})" if f32 else repr(float(v))


def _loop1(S: _Src, ind: int, lay: Layout, xr: str):
    """Partial sums of the bases ``a`` (one block), from the position rows ``xr`` (XA or XB)."""
    cfg = lay.cfg
    f32 = cfg.precision == "f32"
    X = [lay.base(f"{xr}{d}") for d in range(3)]

    def pos(d, o):  # position (f64) or displacement (f32) component d of node a + o
        return f"W[{X[d] + o} + a]"

    contrib = {o: [[] for _ in range(3)] for o in lay.roff}
    _springs(S, ind, lay, pos, contrib)
    if cfg.has_volume:
        _volume(S, ind, lay, pos, contrib)
    for o in lay.roff:
        for d in range(3):
            terms = contrib[o][d]
            expr = _tree(terms) if terms else _lit(0.0, f32)
            S(ind, f"W[{lay.base(f'R_{o}_{d}')} + a] = {expr}")


def _springs(S: _Src, ind: int, lay: Layout, pos, contrib: dict):
    """The tensions ``t_j = k (1 − l0/l) d`` of the springs from base ``a`` (f32: ``k g/(l (l + l0))``
    with ``g = l² − l0²``), added to the partial sums ``contrib`` of offsets 0 (+) and o (−)."""
    cfg = lay.cfg
    f32 = cfg.precision == "f32"
    for j, (gi, gj, gk) in enumerate(cfg.offsets):
        o = gi * lay.s0 + gj * lay.s1 + gk
        D = (gi * cfg.le, gj * cfg.le, gk * cfg.le)
        for d in range(3):
            S(ind, f"e{d} = {pos(d, o)} - {pos(d, 0)}")
        if f32:
            # l² − l0² = 2 D·e + |e|² (no cancellation), l = |D + e|
            dot = " + ".join(f"{_lit(2.0 * D[d], True)} * e{d}" for d in range(3) if D[d] != 0.0)
            S(ind, f"g = ({dot}) + (e0 * e0 + e1 * e1 + e2 * e2)")
            for d in range(3):
                if D[d] != 0.0:
                    S(ind, f"e{d} = e{d} + {_lit(D[d], True)}")
            S(ind, f"l = np.sqrt(l0s_{j} + g)")  # |D + e|² = l0² + g
            S(ind, f"ck = W[{lay.base(f'K{j}')} + a] * g / (l * (l + l0_{j}))")
        else:
            S(ind, "l = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)")
            S(ind, f"ck = W[{lay.base(f'K{j}')} + a] * (1.0 - l0_{j} / l)")
        for d in range(3):
            S(ind, f"t{j}_{d} = ck * e{d}")
            contrib[0][d].append(f"t{j}_{d}")
            contrib[o][d].append(f"-t{j}_{d}")


def _volume(S: _Src, ind: int, lay: Layout, pos, contrib: dict):
    """The volume gradients ``G_c`` of the cell whose lowest corner is ``a``, from its averaged
    edge vectors and their cofactors, added to the partial sums ``contrib`` of its corners'
    offsets (sign and slot per corner: :data:`CORNER_SIGN`, :data:`CORNER_SLOT`)."""
    cfg = lay.cfg
    f32 = cfg.precision == "f32"
    s0, s1 = lay.s0, lay.s1
    le = cfg.le
    # averaged edge vectors A[d] (axis d, components) = ¼ Σ of the 4 parallel edges
    for ax in range(3):
        od = (s0, s1, 1)[ax]
        e1 = (s0, s1, 1)[(ax + 1) % 3]
        e2 = (s0, s1, 1)[(ax + 2) % 3]
        for c in range(3):
            terms = [f"({pos(c, b + od)} - {pos(c, b)})" for b in (0, e1, e2, e1 + e2)]
            S(ind, f"m{ax}{c} = {_lit(0.25, f32)} * (({terms[0]} + {terms[1]}) + ({terms[2]} + {terms[3]}))")
    # m = Δ (f32: increments of the rest edges le·I) or the edge vectors themselves (f64)
    if f32:
        # det(le I + Δ) − le³ = le² tr Δ + le M₂ + det Δ
        S(ind, "tr = m00 + m11 + m22")
        S(ind, "M2 = (m00 * m11 - m01 * m10) + (m00 * m22 - m02 * m20) + (m11 * m22 - m12 * m21)")
        S(ind, "dd = m00 * (m11 * m22 - m12 * m21) - m01 * (m10 * m22 - m12 * m20) + m02 * (m10 * m21 - m11 * m20)")
        S(ind, f"dV = {_lit(le * le, True)} * tr + {_lit(le, True)} * M2 + dd")
        for ax in range(3):
            S(ind, f"m{ax}{ax} = m{ax}{ax} + {_lit(le, True)}")
    # b×c, c×a, a×b (rows of the cofactor matrix)
    for r in range(3):
        u, w = (r + 1) % 3, (r + 2) % 3
        for c in range(3):
            c1, c2 = (c + 1) % 3, (c + 2) % 3
            S(ind, f"k{r}{c} = m{u}{c1} * m{w}{c2} - m{u}{c2} * m{w}{c1}")
    kap = f"W[{lay.base('KAP')} + a]"
    if f32:
        if cfg.squared:
            S(ind, f"wp = {_lit(0.25, True)} * {kap} * (dV * (dV + V0 + V0)) / (V0 * V0 + V0 * V0) * (V0 + dV) / V0")
        else:
            S(ind, f"wp = {_lit(0.25, True)} * {kap} * dV / V0")
    else:
        S(ind, "vv = m00 * k00 + m01 * k01 + m02 * k02")
        if cfg.squared:
            S(ind, f"wp = 0.25 * {kap} * ((vv * vv - V0 * V0) / (2.0 * V0 * V0)) * vv / V0")
        else:
            S(ind, f"wp = 0.25 * {kap} * (vv - V0) / V0")
    for g, (sb, sc) in enumerate(SLOT_SIGNS):
        for c in range(3):
            ob = "+" if sb > 0 else "-"
            oc = "+" if sc > 0 else "-"
            S(ind, f"G{g}_{c} = wp * ((k0{c} {ob} k1{c}) {oc} k2{c})")
    for cn in range(8):
        o = (cn & 1) * s0 + ((cn >> 1) & 1) * s1 + ((cn >> 2) & 1)
        sg = "" if CORNER_SIGN[cn] > 0 else "-"
        for d in range(3):
            contrib[o][d].append(f"{sg}G{CORNER_SLOT[cn]}_{d}")


def _tree(terms: list[str]) -> str:
    """Pairwise sum (fixed order, shallow dependency chains)."""
    if len(terms) == 1:
        return terms[0]
    h = len(terms) // 2
    return f"({_tree(terms[:h])} + {_tree(terms[h:])})"


def _loop2(S: _Src, ind: int, lay: Layout, xr: str, xw: str):
    cfg = lay.cfg
    B = lay.base
    for d in range(3):
        terms = [f"W[{B(f'R_{o}_{d}') - o} + q]" for o in lay.roff]
        if cfg.has_external:
            terms.append(f"W[{B(f'FE{d}')} + q]")
        S(ind, f"f{d} = {_tree(terms)}")
    S(ind, f"im = W[{B('IM')} + q]")
    for d in range(3):
        acc = f"f{d} * im" + (f" + W[{B(f'GA{d}')} + q]" if cfg.has_gravity else "")
        S(ind, f"v{d} = (W[{B(f'V{d}')} + q] + dtk * ({acc})) * damp")
        S(ind, f"W[{B(f'V{d}')} + q] = v{d}")
        S(ind, f"W[{B(f'{xw}{d}')} + q] = W[{B(f'{xr}{d}')} + q] + dtk * v{d}")


def _constants(S: _Src, ind: int, cfg: Config):
    """The step's scalars from ``prm``: rest lengths, time step, damping factor, rest volume."""
    nl = len(cfg.offsets)
    for j in range(nl):
        S(ind, f"l0_{j} = prm[{j}]")
        if cfg.precision == "f32":
            S(ind, f"l0s_{j} = l0_{j} * l0_{j}")
    S(ind, f"dtk = prm[{nl}]")
    S(ind, f"damp = prm[{nl + 1}]")
    S(ind, f"V0 = prm[{nl + 2}]")


def _step(S: _Src, ind: int, lay: Layout, xr: str, xw: str, lo="0", hi=None, halo="0"):
    """One step over the blocks ``[lo, hi)`` and the halo ``[halo, lo)`` below them (loop 1 only),
    reading the positions in buffer ``xr`` and writing them to ``xw``; needs the names of
    :func:`_constants`.  ``lo``, ``hi``, ``halo``: literals or names of the thread's range."""
    hi = str(lay.nblocks) if hi is None else hi
    S(ind, f"for blk in range({halo}, {hi}):")
    if halo.isdigit():
        S(ind + 1, f"b = blk * {BLOCK}")
    else:  # a run-time range: the mask (2^40 nodes) tells LLVM that b ≥ 0, so that Numba's
        # negative-index wrap test folds away and the loops are vectorized
        S(ind + 1, f"b = (blk * {BLOCK}) & 0xFFFFFFFFFF")
    S(ind + 1, f"for i in range({BLOCK}):")
    S(ind + 2, "a = b + i")
    _loop1(S, ind + 2, lay, xr)
    if halo != lo:
        S(ind + 1, f"if blk >= {lo}:")
        ind2 = ind + 2
    else:
        ind2 = ind + 1
    S(ind2, f"for i in range({BLOCK}):")
    S(ind2 + 1, "q = b + i")
    _loop2(S, ind2 + 1, lay, xr, xw)


def thread_ranges(lay: Layout) -> list[tuple[int, int, int]]:
    """(lo, hi, halo) blocks of each thread: it computes the partial sums of the blocks
    ``[halo, hi)`` and integrates the nodes of ``[lo, hi)``.  The halo ``[halo, lo)`` is the
    bases below its range whose partial sums reach its nodes; the thread below computes the same
    values there (same code, same inputs), so no thread waits for another within a step.  A
    thread left without blocks (fewer blocks than threads) has no halo either."""
    b = lay.bounds()
    return [(lo, hi, max(0, lo - -(-lay.H // BLOCK)) if hi > lo else lo)
            for lo, hi in zip(b[:-1], b[1:])]


def _i(v) -> str:
    """An integer argument of a shared helper (:mod:`hybmss._kernels`) as a run-time ``int64``.

    Numba types a literal argument by its value and compiles the callee anew for each: the
    helpers were compiled once per lattice (half of a one-thread kernel's 4 s of compiling).
    They run once per step on the plates' nodes, so the constants gain them nothing."""
    return f"np.int64({v})"


def _b(v) -> str:
    """A boolean argument of a shared helper as a run-time ``bool`` (see :func:`_i`)."""
    return f"np.bool_({v})"


def _parallel_step(S: _Src, lay: Layout, buffers: tuple):
    """``step_0``, ``step_1`` (one step over a thread's blocks, reading one buffer of ``buffers``
    and writing the other) and ``step(W, prm, parity)``: one step of all the threads in a Numba
    parallel region, each on its blocks of :func:`thread_ranges`."""
    for parity, (xr, xw) in enumerate(buffers):
        S(0, "")
        S(0, "@njit(**_OPTS)")
        S(0, f"def step_{parity}(W, prm, lo, hi, halo):")
        _constants(S, 1, lay.cfg)
        _step(S, 1, lay, xr, xw, "lo", "hi", "halo")
    S(0, "")
    S(0, "@njit(parallel=True, **_OPTS)")
    S(0, "def step(W, prm, parity):")
    S(1, f"for t in prange({lay.cfg.threads}):")
    S(2, "fp = flush_subnormals()")
    for t, (lo, hi, halo) in enumerate(thread_ranges(lay)):
        S(2, f"{'if' if t == 0 else 'elif'} t == {t}:")
        S(3, f"lo, hi, halo = {lo}, {hi}, {halo}")
    S(2, "if parity == 0:")
    S(3, "step_0(W, prm, lo, hi, halo)")
    S(2, "else:")
    S(3, "step_1(W, prm, lo, hi, halo)")
    S(2, "restore_fp_mode(fp)")


def source(cfg: Config) -> str:
    """Python source of the kernel module for ``cfg``: ``run`` (a span of steps with the plates
    and the divergence checks), with several threads ``thread`` (one thread's part of ``run``,
    all the threads at once, :func:`run_threads`), and ``step(W, prm, parity)`` (one step, all threads,
    for ``run`` with several threads: a force stage, or threads that could not run at once).
    The threads share one step body per parity: their block ranges are arguments.

    Compiling is mostly Numba's type inference and lowering of the step bodies, so a kernel
    holds as few as it can: one in ``run`` (one thread), one per buffer parity in ``thread``
    (shared by the threads, where each thread had its own pair).  The body is written out in the
    function that runs it rather than called, since Numba links a callee into each caller and
    optimizes and compiles the whole again; ``thread`` is started on operating-system threads
    rather than in a ``prange`` for the same reason.  The two-thread kernel of the 10³ cube took
    22.9 s of CPU to compile, then 8.7 s (one thread: 6.0 s, then 4.9 s), now 6.4 s (3.0 s) with
    the shared helpers' arguments typed at run time (:func:`_i`)."""
    lay = layout(cfg)
    S = _Src()
    S(0, f'"""Generated by hybmss._stencil_gen for {cfg!r}."""')
    S(0, "import math")
    S(0, "import numpy as np")
    S(0, "from numba import njit, prange")
    S(0, "from hybmss._kernels import end_of_step, find_bad, plate_scratch, prescribe")
    if cfg.stage is not None:
        module, function = cfg.stage.split(":")
        S(0, f"from {module} import {function} as force_stage")
    S(0, "from hybmss._cpu import atomic_load, atomic_store, barrier, flush_subnormals, restore_fp_mode")
    S(0, "_OPTS = dict(cache=True, error_model='numpy', fastmath=False, nogil=True, boundscheck=False)")
    T = cfg.threads
    # one thread updates the positions in place (loop 1 of a block reads only nodes at or above
    # the block, which loop 2 has not reached yet); several threads alternate two buffers
    buffers = (("XA", "XA"),) if T == 1 else (("XA", "XB"), ("XB", "XA"))
    if T > 1:
        _parallel_step(S, lay, buffers)
    S(0, "")
    B = lay.base
    S(0, "@njit(**_OPTS)")
    S(0, "def run(W, prm, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis, pl_center, pl_angle,")
    S(0, "        step0, nsteps, check_every, limit2, parity0, dt, ramp_time, F0, stage_args):")
    S(1, '"""Advance ``nsteps`` steps from global step ``step0``, the current positions in buffer')
    S(1, '``parity0`` (0: XA).  Returns (steps done, bad node or -1)."""')
    if T == 1:
        _constants(S, 1, cfg)
    S(1, "R, u_old, u_new = plate_scratch(pl_ptr)")
    S(1, "fp = flush_subnormals()")
    S(1, "for n in range(nsteps):")
    S(2, f"par = (parity0 + n) % {len(buffers)}")
    if cfg.stage is not None:
        xr = f"{B('XA0')} if par == 0 else {B('XB0')}" if T > 1 else f"{B('XA0')}"
        S(2, f"force_stage(W, {_i(xr)}, {_i(B('FE0'))}, {_i(lay.L)}, {_i(lay.N)}, F0, stage_args)")
    if T == 1:
        _step(S, 2, lay, "XA", "XA")
    else:
        S(2, "step(W, prm, par)")
    S(2, f"xb = {B('XB0')} if par == 0 else {B('XA0')}" if T > 1 else f"xb = {B('XA0')}")
    S(2, f"bad = end_of_step(W, {_i('xb')}, {_i(B('V0'))}, {_i(lay.L)}, {_i(lay.N)}, "
         f"{_b(cfg.precision == 'f64')}, X, pl_nodes, pl_U1, "
         "pl_ptr, pl_mask, pl_kind, pl_disp, pl_axis, pl_center, pl_angle, step0 + n, dt, ramp_time, R, u_old, "
         "u_new, n, nsteps, check_every, limit2)")
    S(2, "if bad >= 0:")
    S(3, "restore_fp_mode(fp)")
    S(3, "return n + 1, bad")
    S(1, "restore_fp_mode(fp)")
    S(1, "return nsteps, -1")
    if T > 1 and cfg.stage is None:
        _thread_function(S, lay)
    return "\n".join(S.lines) + "\n"


THREAD_ARGS = ("W, prm, S, out, tid, lo, hi, halo, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp, "
               "pl_axis, pl_center, pl_angle, step0, nsteps, check_every, limit2, parity0, dt, ramp_time")
"""Arguments of ``thread``: ``S`` the barrier's state (:mod:`hybmss._cpu`), ``out`` (2 T,) int64
the steps done (``out[tid]``) and the diverged node or −1 (``out[T + tid]``), ``tid`` the thread,
``lo, hi, halo`` its blocks (:func:`thread_ranges`), then those of ``run`` from ``X`` to
``ramp_time``."""


def _thread_function(S: _Src, lay: Layout):
    """``thread``: one thread's part of every step, the plates of its nodes, and one barrier per
    step (all T must run at once, each on its own core: :func:`run_threads`)."""
    cfg = lay.cfg
    B = lay.base
    T = cfg.threads
    posmode = cfg.precision == "f64"
    S(0, "")
    S(0, "@njit(**_OPTS)")
    S(0, f"def thread({THREAD_ARGS}):")
    S(1, '"""Thread ``tid``: blocks [lo, hi) of every step (and the halo [halo, lo)), then the plates of its nodes."""')
    _constants(S, 1, cfg)
    S(1, "R, u_old, u_new = plate_scratch(pl_ptr)")
    S(1, "fp = flush_subnormals()")
    S(1, "for n in range(nsteps):")
    S(2, "par = (parity0 + n) % 2")
    S(2, "if par == 0:")
    _step(S, 3, lay, "XA", "XB", "lo", "hi", "halo")
    S(3, f"xb = {B('XB0')}")
    S(2, "else:")
    _step(S, 3, lay, "XB", "XA", "lo", "hi", "halo")
    S(3, f"xb = {B('XA0')}")
    S(2, f"prescribe(W, {_i('xb')}, {_i(B('V0'))}, {_i(lay.L)}, {_b(posmode)}, X, pl_nodes, pl_U1, pl_ptr, "
         "pl_mask, pl_kind, "
         f"pl_disp, pl_axis, pl_center, pl_angle, step0 + n, dt, ramp_time, R, u_old, u_new, "
         f"lo * {BLOCK}, hi * {BLOCK})")
    S(2, f"if not barrier(S, {T}):")
    S(3, "break")
    S(2, "if (n + 1) % check_every == 0 or n == nsteps - 1:")
    S(3, "if tid == 0:")
    S(4, f"atomic_store(S, {MESSAGE}, find_bad(W, {_i('xb')}, {_i(lay.L)}, {_i(lay.N)}, {_b(posmode)}, X, limit2))")
    S(3, f"if not barrier(S, {T}):")
    S(4, "break")
    S(3, f"bad = atomic_load(S, {MESSAGE})")
    S(3, "if bad >= 0:")
    S(4, "out[tid] = n + 1")
    S(4, f"out[{T} + tid] = bad")
    S(4, "restore_fp_mode(fp)")
    S(4, "return")
    S(1, "restore_fp_mode(fp)")
    S(1, "out[tid] = nsteps")
    S(1, f"out[{T} + tid] = -1")


def run_threads(mod, lay: Layout, args: tuple, absent: tuple = ()) -> None:
    """Run ``thread`` of the kernel module ``mod`` (of layout ``lay``) for every thread at once, on
    T operating-system threads (the calling one included).  ``args``: those of
    :data:`THREAD_ARGS` without ``tid, lo, hi, halo``.

    The function holds no GIL, so the threads run in parallel; it is compiled (or loaded from the
    cache) before any starts, since a thread that waits at the barrier for one still compiling
    gives up.  They are started here rather than in a Numba parallel region because a ``prange``
    over them is one more function that links, optimizes and compiles the step bodies again.
    ``absent``: threads not started (the others give up at the barrier: how a partner that never
    comes is handled).  Raises what a thread raised."""
    import threading

    ranges = thread_ranges(lay)
    names = THREAD_ARGS.split(", ")
    nsteps = names.index("nsteps") - names.index("X")  # its place in ``tail``
    head, tail = args[:4], args[4:]

    def call(t, tail):
        mod.thread(*head, np.int64(t), *(np.int64(v) for v in ranges[t]), *tail)

    if not mod.thread.signatures:  # zero steps: compiles, touches no state
        call(0, (*tail[:nsteps], np.int64(0), *tail[nsteps + 1:]))
    errors = []

    def work(t):
        try:
            call(t, tail)
        except BaseException as exc:  # noqa: BLE001 (handed to the calling thread)
            errors.append(exc)

    started = [threading.Thread(target=work, args=(t,), daemon=True)
               for t in range(1, len(ranges)) if t not in absent]
    for th in started:
        th.start()
    if 0 not in absent:
        work(0)
    for th in started:
        th.join()
    if errors:
        raise errors[0]

def cache_dir() -> str:
    """Folder of the generated modules (and Numba's cache of them): ``$HYBMSS_KERNEL_CACHE``, else
    ``$XDG_CACHE_HOME/hybmss/kernels``, else ``~/.cache/hybmss/kernels``, else a temporary folder."""
    d = os.environ.get("HYBMSS_KERNEL_CACHE")
    if not d:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        d = os.path.join(base, "hybmss", "kernels")
    try:
        os.makedirs(d, exist_ok=True)
        return d
    except OSError:
        d = os.path.join(tempfile.gettempdir(), "hybmss-kernels")
        os.makedirs(d, exist_ok=True)
        return d


_MODULES: dict = {}


def kernel_module(cfg: Config):
    """The compiled kernel module of ``cfg`` (written to :func:`cache_dir` once, atomically, and
    imported; Numba caches its machine code beside it)."""
    key = cfg.key()
    mod = _MODULES.get(key)
    if mod is None:
        mod = _MODULES[key] = import_generated(f"hybmss_stencil_{key}", source(cfg))
    return mod


def import_generated(name: str, src: str):
    """The module ``name`` of source ``src``, written to :func:`cache_dir` (atomically, unless the
    file there already holds ``src``) and imported from there, so that Numba's cache of its
    functions (``cache=True``) lies beside it.  ``name`` must change with ``src`` (a hash of it)."""
    d = cache_dir()
    path = os.path.join(d, name + ".py")
    try:
        with open(path, encoding="utf-8") as fh:
            same = fh.read() == src
    except OSError:
        same = False
    if not same:
        fd, tmp = tempfile.mkstemp(dir=d, suffix=".tmp")
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(src)
        os.replace(tmp, path)
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def instruction_mix(cfg: Config, args: tuple) -> dict:
    """Square roots and divisions in the machine code of the function that runs the steps of
    ``cfg`` (``run`` for one thread, ``thread`` for several; ``args`` those of ``run``), by kind
    and register: ``{("sqrt" | "div", "scalar" | "xmm" | "ymm" | "zmm"): count}``.  Compiled
    afresh (a kernel loaded from Numba's cache has no assembly to show): load-independent
    evidence that LLVM vectorized the loops."""
    import re

    from numba import njit, typeof

    mod = kernel_module(cfg)
    if cfg.threads == 1:
        fn, a = mod.run, args
    else:
        lo, hi, halo = thread_ranges(layout(cfg))[0]
        fn, a = mod.thread, (args[0], args[1], np.zeros(SLOTS, dtype=np.int64), np.zeros(2 * cfg.threads, dtype=np.int64),
                             *(np.int64(v) for v in (0, lo, hi, halo)), *args[2:19])
    fn = njit(error_model="numpy", fastmath=False, boundscheck=False)(fn.py_func)
    sig = tuple(typeof(v) for v in a)
    fn.compile(sig)
    asm = fn.inspect_asm(sig)
    out = {}
    for op, name in (("sqrt", "vsqrt"), ("div", "vdiv")):
        out[(op, "scalar")] = len(re.findall(rf"\b{name}s[sd]\b", asm))
        for reg in ("xmm", "ymm", "zmm"):
            out[(op, reg)] = len(re.findall(rf"\b{name}p[sd]\s+[^\n]*%{reg}", asm))
    return out
