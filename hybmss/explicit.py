"""Explicit dynamics: semi-implicit (symplectic) Euler, as in [G20] (SPEC §5).

Equations of motion ``m_a ẍ_a = f_a(x) + m_a g − c m_a ẋ_a`` (springs, volume term and any
variant forces in ``f``; ``c`` is :attr:`Scene.damping`, 1/s).  One step of size ``dt``::

    v ← (v + dt (f(x)/m + g)) / (1 + c dt)
    x ← x + dt v

**Damping** (mass-proportional, −c m v) is taken *implicitly* (at the new velocity): this is the
exact backward-Euler update of the linear term, costs the same as the explicit form
``(1 − c dt) v``, never reverses or amplifies a velocity whatever c dt (the explicit form does
for c dt > 2), and leaves the undamped scheme (c = 0) exactly symplectic Euler.  Mass-proportional
damping slows every mode by the same rate c (a mode of frequency ω has damping ratio c/(2ω)), so
it settles the slow modes of a soft body without touching its stiffness.

Velocities live at half steps (``v`` after step n is v_{n+½}); the reported kinetic energy
``½ Σ m |v|²`` uses that velocity, and ``energy['kinetic_centred'] = ½ Σ m v_{n−½}·v_{n+½}`` is
the time-centred form for which the discrete energy of a linear (small-displacement, undamped)
system is exactly conserved by this scheme: it is the one to check energy drift with.

**Plates** follow their prescribed motion, in their constrained components only, with the load
factor ramped smoothly from rest: ``s(t) = ½ (1 − cos(π t / T))`` for ``t < T = ramp_time``,
then ``s = 1``; s, ṡ and the plate velocity start at 0 (no initial jolt).  After each step the
prescribed components are set to ``X + u(s(t_{n+1}))`` and their velocity to
``(u(s(t_{n+1})) − u(s(t_n)))/dt``.  Free components of sliding plates integrate normally.

**Stability.**  The scheme is stable for ``dt < dt_crit = 2/√λmax(M⁻¹K)``
(:func:`dt_crit`, exact Hessian at rest on the free degrees of freedom, Lanczos).  A run that
leaves the physical range raises :class:`DivergenceError`; it never returns NaN.

Two kernels give the same trajectory: ``'numba'`` (the stencil kernel of
:mod:`hybmss._kernels`) and ``'numpy'`` (the readable twin built on :mod:`hybmss.forces`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np

from .forces import energy_forces, hessian, internal_forces
from .result import Result, reaction_from_nodal
from .scene import Scene
from . import _cpu
from .baudet import Corrections, GridCorrections
from .system import System, build
from .terms import DeadLoad

SOLVER = "mss-explicit"
KERNELS = ("numba", "numpy", "engine")
"""Explicit kernels: the Numba stencil kernel, its NumPy twin, and ``engine``: the own compiled step
of an engine a model wraps (:mod:`hybmss.models.mujoco`, :mod:`hybmss.models.newton`)."""
RAMP_LAW = "s(t) = 0.5 (1 - cos(pi t / T)) for t < T, then 1"
REST_RTOL = 1e-3
"""Default tolerance of the rest criterion of an explicit run (:func:`rest_report`)."""
BLOWUP_FACTOR = 10.0
"""A displacement beyond this many body sizes (largest bounding-box edge) counts as divergence."""
WARM_UP_STEPS = 100
"""Steps per kernel call of an explicit run's ``warm_up``."""
WARM_UP_THREADS = 0.1
"""Seconds of untimed steps that benchmarks run before timing several threads (``warm_up`` of
:func:`simulate_explicit`).  A core that was idle steps at about half speed for its first
~100 ms: without them, 1,000 two-thread steps took 1.555 s per 10k on the 15³ cube and 1.415 on
the 8×8×48 beam, no faster than one thread (1.83, 1.42); with them 1.017 and 0.834.  One thread
runs on the core that was busy all along and shows no such start."""

OFFSETS = np.array(
    [(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) > (0, 0, 0)],
    dtype=np.int64,
)
"""The 13 forward neighbour offsets (lexicographically positive) of the stencil."""


class DivergenceError(RuntimeError):
    """An explicit run left the physical range (non-finite values or a runaway displacement).

    Attributes: ``step`` (1-based step at which it was detected), ``particle`` (index),
    ``grid`` (its integer grid coordinates), ``displacement`` (its |u|, m; nan or inf if not
    finite), ``positions`` (n, 3) when detected, ``dt`` and ``dt_crit``.  The particle is the
    first with a non-finite position, else the one with the largest displacement.
    """

    def __init__(self, message, *, step, particle, grid, displacement, dt, dt_crit, positions=None):
        super().__init__(message)
        self.positions = positions
        self.step = step
        self.particle = particle
        self.grid = grid
        self.displacement = displacement
        self.dt = dt
        self.dt_crit = dt_crit


def ramp(t: float, T: float) -> float:
    """Load factor s(t) = ½ (1 − cos(π t/T)) for t < T, then 1 (s ≡ 1 when T ≤ 0)."""
    if T <= 0.0 or t >= T:
        return 1.0
    if t <= 0.0:
        return 0.0
    return 0.5 * (1.0 - math.cos(math.pi * t / T))


# ------------------------------------------------------------------------------ stability limit
def dt_crit(system_or_scene: System | Scene) -> float:
    """Explicit stability limit ``2/√λmax(M⁻¹K)`` from the exact Hessian at rest.

    Only free degrees of freedom (not prescribed, with mass) count.  λmax is the largest
    eigenvalue of the symmetric ``M^{-1/2} K M^{-1/2}`` (Lanczos, dense for small systems).
    Returns ``inf`` when nothing is free or K has no positive eigenvalue.
    """
    import scipy.sparse as sp

    system = system_or_scene if isinstance(system_or_scene, System) else build(system_or_scene)
    own = system.scene.model.spec.dt_crit(system)
    if own is not None:  # the model's own limit (hybmss.models.base)
        return float(own)
    m3 = np.repeat(system.mass, 3)
    free = (~system.fixed).ravel() & (m3 > 0)
    if not free.any():
        return math.inf
    H = hessian(system, system.X).tocsr()[free][:, free]
    s = sp.diags(1.0 / np.sqrt(m3[free]))
    A = (s @ H @ s).tocsr()
    A = 0.5 * (A + A.T)
    if A.shape[0] <= 1500:
        lmax = float(np.linalg.eigvalsh(A.toarray())[-1])
    else:
        from scipy.sparse.linalg import eigsh

        lmax = float(eigsh(A, k=1, which="LA", tol=1e-8, return_eigenvectors=False, v0=lanczos_start(A.shape[0]))[0])
    return 2.0 / math.sqrt(lmax) if lmax > 0 else math.inf


# ------------------------------------------------------------------------------ stencil layout
PRECISIONS = ("f64", "f32")


def _aligned_zeros(n: int, dtype) -> np.ndarray:
    """Zeroed 1-D array of ``n`` entries whose data starts on a 64-byte boundary."""
    item = np.dtype(dtype).itemsize
    buf = np.zeros(n + 64 // item, dtype=dtype)
    off = (-buf.ctypes.data % 64) // item
    return buf[off:off + n]


def lanczos_start(n: int) -> np.ndarray:
    """A fixed start vector for ARPACK (its default is random: ω_max, hence dt_crit, dt and the
    substeps timed by it, would differ in their last bits between runs)."""
    return np.random.default_rng(0).standard_normal(n)


def initial_state(system: System, x0, v0, ramp_time: float) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities (n, 3) at t = 0: ``x0``/``v0`` (default: rest, zero velocity),
    with the plates' prescribed components at the start of their ramp and at rest."""
    x = system.X.copy() if x0 is None else np.array(x0, dtype=float).reshape(system.n, 3)
    v = np.zeros((system.n, 3)) if v0 is None else np.array(v0, dtype=float).reshape(system.n, 3)
    P0 = system.prescribed(ramp(0.0, ramp_time))
    x[system.fixed] = P0[system.fixed]
    v[system.fixed] = 0.0
    return x, v


@dataclass(frozen=True, eq=False)
class PlateArrays:
    """Plates of a system in the layout of :func:`hybmss._kernels.apply_plates`: node numbers of
    the kernel (particle indices, or grid indices of the stencil kernel), the displacement at full
    load ``U1`` (3, n), and per plate its prescribed components, motion kind and parameters."""

    nodes: np.ndarray
    U1: np.ndarray
    ptr: np.ndarray
    mask: np.ndarray
    kind: np.ndarray
    disp: np.ndarray
    axis: np.ndarray
    center: np.ndarray
    angle: np.ndarray

    def args(self) -> tuple:
        return (self.nodes, self.U1, self.ptr, self.mask, self.kind, self.disp, self.axis, self.center,
                self.angle)


def plate_arrays(system: System, node: np.ndarray | None = None) -> PlateArrays:
    """The plates of ``system`` for the kernels, particle ``a`` being kernel node ``node[a]``
    (``None``: the particle index).  Raises ``ValueError`` for a motion neither linear in the load
    factor nor a rotation (the kernels know only those two)."""
    le = system.scene.body.le
    nodes, U1, ptr, mask, kind, disp, axis, center, angle = [], [], [0], [], [], [], [], [], []
    for plate, ps in zip(system.scene.plates, system.plates):
        m = plate.motion
        Xp = system.X[ps.particles]
        u1 = m.displacement_at(Xp, 1.0)
        if m.kind != "rotate" and not np.allclose(m.displacement_at(Xp, 0.5), 0.5 * u1, rtol=1e-12,
                                                  atol=1e-12 * le):
            raise ValueError(f"plate {plate.name!r}: the numba kernels need a motion linear in the load factor "
                             f"or a rotation, got {m.kind!r}; use kernel='numpy'")
        nodes.append(ps.particles if node is None else node[ps.particles])
        U1.append(u1.T)
        ptr.append(ptr[-1] + len(ps.particles))
        mask.append(ps.constrained)
        kind.append(1 if m.kind == "rotate" else 0)
        disp.append(m.displacement)
        axis.append(m.axis)
        center.append(m.center if m.center is not None else Xp.mean(axis=0))
        angle.append(m.angle)
    n_pl = len(system.plates)
    return PlateArrays(
        nodes=np.concatenate(nodes).astype(np.int64) if nodes else np.zeros(0, dtype=np.int64),
        U1=np.ascontiguousarray(np.concatenate(U1, axis=1)) if U1 else np.zeros((3, 0)),
        ptr=np.asarray(ptr, dtype=np.int64),
        mask=np.asarray(mask, dtype=np.bool_).reshape(n_pl, 3),
        kind=np.asarray(kind, dtype=np.int64),
        disp=np.asarray(disp, dtype=float).reshape(n_pl, 3),
        axis=np.asarray(axis, dtype=float).reshape(n_pl, 3),
        center=np.asarray(center, dtype=float).reshape(n_pl, 3),
        angle=np.asarray(angle, dtype=float),
    )


def hold_clamped(plates: PlateArrays) -> tuple[PlateArrays, np.ndarray]:
    """``plates`` without the clamped ones (every component prescribed, no motion) whose nodes
    no other plate moves, and those nodes.  A node given ``1/m = 0`` and no gravity keeps its
    position and zero velocity through the kernel's own update, so it needs no plate write."""
    n_pl = len(plates.kind)
    own = [plates.nodes[plates.ptr[i]:plates.ptr[i + 1]] for i in range(n_pl)]
    held = [i for i in range(n_pl) if plates.kind[i] == 0 and plates.mask[i].all()
            and not plates.U1[:, plates.ptr[i]:plates.ptr[i + 1]].any()]
    for i in list(held):
        others = [own[j] for j in range(n_pl) if j != i]
        if others and np.isin(own[i], np.concatenate(others)).any():
            held.remove(i)
    if not held:
        return plates, np.zeros(0, dtype=np.int64)
    keep = [i for i in range(n_pl) if i not in held]
    cols = [np.arange(plates.ptr[i], plates.ptr[i + 1]) for i in keep]
    cols = np.concatenate(cols) if cols else np.zeros(0, dtype=np.int64)
    ptr = np.concatenate([[0], np.cumsum([len(own[i]) for i in keep])]).astype(np.int64)
    kept = PlateArrays(nodes=plates.nodes[cols], U1=np.ascontiguousarray(plates.U1[:, cols]), ptr=ptr,
                       mask=plates.mask[keep].reshape(len(keep), 3), kind=plates.kind[keep],
                       disp=plates.disp[keep].reshape(len(keep), 3), axis=plates.axis[keep].reshape(len(keep), 3),
                       center=plates.center[keep].reshape(len(keep), 3), angle=plates.angle[keep])
    return kept, np.concatenate([own[i] for i in held]).astype(np.int64)


@dataclass(eq=False)
class Stencil:
    """A system laid out on its full grid for the generated kernel (:mod:`hybmss._stencil_gen`),
    with the run parameters (dt, damping factor, ramp time, precision, threads).

    ``K`` (n_off, N), ``kv`` (2, N), ``invm``, ``gacc`` are the float64 grid arrays the flat state
    ``W`` is filled from; ``F0`` (3, N) the dead loads; ``corrections`` the [B09] grid layout
    (:class:`hybmss.baudet.GridCorrections`) or None."""

    shape: tuple[int, int, int]
    flat: np.ndarray  # (n,) grid index of each particle
    Xg: np.ndarray  # (3, N) reference positions of the grid nodes
    K: np.ndarray  # (n_off, N)
    l0: np.ndarray  # (n_off,)
    offs: np.ndarray  # (n_off,) flat offsets
    offsets: np.ndarray  # (n_off, 3) grid offsets
    kv: np.ndarray  # (2, N): κ of the cell whose lowest corner is p (0: no cell), its rest volume
    coff: np.ndarray  # (8,) flat corner offsets
    squared: bool
    has_volume: bool
    invm: np.ndarray  # (N,)
    gacc: np.ndarray  # (3, N)
    has_gravity: bool
    F0: np.ndarray | None  # (3, N) dead loads
    corrections: object  # GridCorrections or None
    V0: float
    dt: float
    damp: float
    ramp_time: float
    precision: str
    threads: int
    pl_nodes: np.ndarray
    pl_U1: np.ndarray  # (3, total plate nodes): u at s = 1 of motions linear in s
    pl_ptr: np.ndarray
    pl_mask: np.ndarray
    pl_kind: np.ndarray
    pl_disp: np.ndarray
    pl_axis: np.ndarray
    pl_center: np.ndarray
    pl_angle: np.ndarray
    le: float = 0.0
    W: np.ndarray | None = None
    parity: int = 0

    @property
    def N(self) -> int:
        return int(np.prod(self.shape))

    @property
    def dtype(self):
        return np.float32 if self.precision == "f32" else np.float64

    @property
    def config(self):
        from ._stencil_gen import Config

        return Config(shape=tuple(self.shape), offsets=tuple(tuple(int(c) for c in o) for o in self.offsets),
                      has_volume=bool(self.has_volume), squared=bool(self.squared),
                      has_gravity=bool(self.has_gravity),
                      has_external=self.F0 is not None or self.corrections is not None,
                      baudet=self.corrections is not None, precision=self.precision,
                      threads=int(self.threads), le=float(self.le))

    @property
    def layout(self):
        from ._stencil_gen import layout

        return layout(self.config)

    def module(self):
        """The compiled kernel of this stencil (generated and compiled on first use, then cached)."""
        from ._stencil_gen import kernel_module

        return kernel_module(self.config)

    def _rows(self, name: str, k: int = 3) -> np.ndarray:
        lay = self.layout
        b = lay.regions[name] * lay.L
        return self.W[b:b + k * lay.L].reshape(k, lay.L)

    def load(self, x: np.ndarray, v: np.ndarray) -> None:
        """Fill the flat state from particle positions and velocities (n, 3)."""
        lay = self.layout
        F, N, L = lay.F, lay.N, lay.L
        self.W = _aligned_zeros(lay.size, self.dtype)
        # every entry of a position row, pads included, holds a finite point of the lattice
        # continued beyond the grid (absent and pad nodes never move and join no spring)
        q = np.arange(-F, L - F)
        gi = np.stack([q // lay.s0, (q % lay.s0) // lay.s1, q % lay.s1]).astype(float)
        Xext = np.asarray(self.Xg[:, 0:1]) + gi * self.le
        Xext[:, F:F + N] = self.Xg
        xg = self.Xg.copy()
        xg[:, self.flat] = x.T
        vg = np.zeros((3, N))
        vg[:, self.flat] = v.T
        posmode = self.precision == "f64"
        for name in ("XA0", "XB0") if self.threads > 1 else ("XA0",):
            rows = self._rows(name)
            rows[:] = Xext if posmode else 0.0
            rows[:, F:F + N] = xg if posmode else xg - self.Xg
        self._rows("V0")[:, F:F + N] = vg
        for j in range(len(self.offs)):
            self._rows(f"K{j}", 1)[0, F:F + N] = self.K[j]
        if self.has_volume:
            self._rows("KAP", 1)[0, F:F + N] = self.kv[0]
        self._rows("IM", 1)[0, F:F + N] = self.invm
        if self.has_gravity:
            self._rows("GA0")[:, F:F + N] = self.gacc
        if self.F0 is not None and self.corrections is None:
            self._rows("FE0")[:, F:F + N] = self.F0
        self.parity = 0

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """Particle positions and velocities (n, 3), float64."""
        lay = self.layout
        F, N = lay.F, lay.N
        xg = self._rows("XA0" if self.parity == 0 else "XB0")[:, F:F + N].astype(float)
        if self.precision == "f32":
            xg = xg + self.Xg
        vg = self._rows("V0")[:, F:F + N].astype(float)
        return np.ascontiguousarray(xg[:, self.flat].T), np.ascontiguousarray(vg[:, self.flat].T)

    def advance(self, step0: int, nsteps: int, check_every: int, limit2: float) -> tuple[int, int]:
        """Run ``nsteps`` steps from global step ``step0`` in place.  Returns (steps done, bad grid
        node or −1).  Several threads run all the steps at once, one operating-system thread each
        and a spinning barrier per step (:mod:`hybmss._cpu`); the [B09] corrections, or threads
        that did not all run at once, take one Numba parallel region per step."""
        mod = self.module()
        args = self._args(step0, nsteps, check_every, limit2)
        T = int(self.threads)
        done = bad = None
        if T > 1 and self.corrections is None:
            done, bad = self._run_threads(mod, args)
        if done is None and T > 1:  # one parallel region per step
            import numba

            old = numba.get_num_threads()
            numba.set_num_threads(min(T, numba.config.NUMBA_NUM_THREADS))
            try:
                done, bad = mod.run(*args)
            finally:
                numba.set_num_threads(old)
        elif done is None:
            done, bad = mod.run(*args)
        self.parity = (self.parity + int(done)) % 2 if self.threads > 1 else 0
        return int(done), int(bad)

    def _args(self, step0: int, nsteps: int, check_every: int, limit2: float) -> tuple:
        """Arguments of the generated ``run`` (``thread`` takes ``[2:19]`` of them)."""
        dtype = self.dtype
        prm = np.array(list(self.l0) + [self.dt, self.damp, self.V0], dtype=dtype)
        corr = self.corrections
        N = self.N
        if corr is not None:
            kc, coff, le, c = corr.kc, corr.coff, float(corr.le), float(corr.c)
            F0 = self.F0 if self.F0 is not None else np.zeros((3, N))
        else:
            kc, coff, le, c = np.zeros((2, 1)), np.zeros(8, dtype=np.int64), 0.0, 0.0
            F0 = np.zeros((3, 1))
        P = np.zeros((3, 3, N if corr is not None else 1))
        Fc = np.zeros((3, N if corr is not None else 1))
        return (self.W, prm, self.Xg, self.pl_nodes, self.pl_U1, self.pl_ptr, self.pl_mask, self.pl_kind,
                self.pl_disp, self.pl_axis, self.pl_center, self.pl_angle, np.int64(step0), np.int64(nsteps),
                np.int64(max(1, check_every)), float(limit2), np.int64(self.parity), float(self.dt),
                float(self.ramp_time), F0, kc, coff, le, c, P, Fc)

    def _run_threads(self, mod, args, absent: tuple = ()) -> tuple[int | None, int | None]:
        """All steps of :meth:`advance` on ``threads`` threads at once
        (:func:`hybmss._stencil_gen.run_threads`: one spinning barrier per step).  (None, None)
        with the state restored if the threads did not all run at once (a thread waited in vain at
        a barrier): the caller then runs one parallel region per step.  ``absent``: threads not
        started (see ``run_threads``)."""
        from ._stencil_gen import run_threads

        T = int(self.threads)
        sync = np.zeros(_cpu.SLOTS, dtype=np.int64)
        out = np.zeros(2 * T, dtype=np.int64)
        saved = self.W.copy()
        W, prm = args[0], args[1]
        run_threads(mod, self.layout, (W, prm, sync, out, *args[2:19]), absent)
        if sync[_cpu.ABORT] != 0:
            self.W[:] = saved
            return None, None
        done = int(out[:T].min())
        bad = int(out[T:].max())
        return done, bad


def _external_forces(system: System):
    """(dead loads (n, 3) or None, the [B09] correction term or None) of ``system.terms``;
    ValueError for a term the generated kernel cannot hold."""
    dead, corr, other = None, None, []
    for t in system.terms:
        if isinstance(t, DeadLoad):  # constant forces: the explicit run applies them whole
            dead = t.f if dead is None else dead + t.f
        elif t.name == Corrections.name:
            corr = t
        else:
            other.append(t.name)
    if other:
        raise ValueError(f"the numba kernel holds springs, volume term, gravity, dead loads and the [B09] "
                         f"corrections, not the force terms {', '.join(other)}; use kernel='numpy'")
    return dead, corr


def stencil(system: System, dt: float, ramp_time: float, precision: str = "f64", threads: int = 1,
            damping: float | None = None) -> Stencil:
    """Lay ``system`` out on its grid.  Raises ``ValueError`` for what the stencil cannot hold
    (force terms other than dead loads and the [B09] corrections; non-regular rest lengths;
    baudet2009 in float32)."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)}; got {precision!r}")
    dead, corr = _external_forces(system)
    if corr is not None and precision != "f64":
        raise ValueError("the [B09] corrections of baudet2009 run in float64 only; use precision='f64'")
    lat = system.lattice
    scene = system.scene
    le = scene.body.le
    shape = tuple(int(n) + 1 for n in scene.body.shape)
    N = int(np.prod(shape))
    strides = np.array([shape[1] * shape[2], shape[2], 1], dtype=np.int64)
    flat = lat.grid @ strides
    gi = np.indices(shape).reshape(3, -1).astype(float)
    Xg = np.asarray(scene.body.origin, dtype=float)[:, None] + gi * le
    if not np.allclose(Xg[:, flat], system.X.T, rtol=0.0, atol=1e-12 * max(1.0, float(np.abs(Xg).max()))):
        raise ValueError("particles are not on the regular grid; the stencil kernel needs a regular lattice")
    Xg[:, flat] = system.X.T

    # springs: one row of constants per forward offset
    d = lat.grid[system.spring_b] - lat.grid[system.spring_a]
    code = (d + 1) @ np.array([9, 3, 1])
    table = -np.ones(27, dtype=np.int64)
    table[(OFFSETS + 1) @ np.array([9, 3, 1])] = np.arange(len(OFFSETS))
    j = table[code]
    if (j < 0).any():
        raise ValueError("a spring does not join grid neighbours; the stencil kernel cannot hold it")
    Kall = np.zeros((len(OFFSETS), N))
    np.add.at(Kall, (j, flat[system.spring_a]), system.spring_k)
    l0_all = le * np.linalg.norm(OFFSETS, axis=1)
    if not np.allclose(system.spring_l0, l0_all[j], rtol=1e-12, atol=0.0):
        raise ValueError("rest lengths differ from the grid's; the stencil kernel needs a regular lattice")
    active = np.flatnonzero(np.any(Kall != 0.0, axis=1))
    K = np.ascontiguousarray(Kall[active])

    corners = np.array([[(c >> 0) & 1, (c >> 1) & 1, (c >> 2) & 1] for c in range(8)])
    coff = corners @ strides
    kv = np.zeros((2, N))
    kv[1] = 1.0
    V0 = le**3
    if system.has_volume:
        p = flat[system.vol_cells[:, 0]]
        kv[0, p] = system.kappa
        kv[1, p] = system.vol_V0
        V0 = float(system.vol_V0[0])
        if not np.allclose(system.vol_V0, V0, rtol=1e-12, atol=0.0):
            raise ValueError("rest cell volumes differ; the stencil kernel needs a regular lattice")

    if (system.mass <= 0).any():
        raise ValueError("explicit dynamics needs rho > 0 (every particle must have mass)")
    invm = np.zeros(N)
    invm[flat] = 1.0 / system.mass
    gacc = np.zeros((3, N))
    if system.gravity is not None:
        gacc[:, flat] = system.gravity[:, None]
    F0 = None
    if dead is not None:
        F0 = np.zeros((3, N))
        F0[:, flat] = np.asarray(dead, dtype=float).T
    gcorr = GridCorrections.from_system(system) if corr is not None else None

    plates, held = hold_clamped(plate_arrays(system, flat))
    invm[held] = 0.0
    gacc[:, held] = 0.0
    c = system.scene.damping if damping is None else float(damping)
    return Stencil(
        shape=shape,
        flat=flat,
        Xg=Xg,
        K=K,
        l0=l0_all[active],
        offs=OFFSETS[active] @ strides,
        offsets=OFFSETS[active],
        kv=kv,
        coff=coff,
        squared=system.volume_energy == "squared",
        has_volume=system.has_volume,
        invm=invm,
        gacc=gacc,
        has_gravity=system.gravity is not None,
        F0=F0,
        corrections=gcorr,
        V0=V0,
        dt=float(dt),
        damp=1.0 / (1.0 + c * dt),
        ramp_time=float(ramp_time),
        precision=precision,
        threads=int(threads),
        pl_nodes=plates.nodes,
        pl_U1=plates.U1,
        pl_ptr=plates.ptr,
        pl_mask=plates.mask,
        pl_kind=plates.kind,
        pl_disp=plates.disp,
        pl_axis=plates.axis,
        pl_center=plates.center,
        pl_angle=plates.angle,
        le=float(le),
    )


# ------------------------------------------------------------------------------ NumPy twin
def numpy_step(system: System, x, v, dt, damp, x_old, x_new):
    """One step of the readable twin on particle arrays (n, 3), in place.

    ``x_old``/``x_new`` are :meth:`System.prescribed` at s(t_n) and s(t_{n+1}).
    """
    _, f, _ = energy_forces(system, x)  # springs + volume + m g (+ variant forces)
    if system.gravity is not None:  # same grouping as the kernel: f_int/m + g
        f = f - system.mass[:, None] * system.gravity[None, :]
        acc = f / system.mass[:, None] + system.gravity[None, :]
    else:
        acc = f / system.mass[:, None]
    v[:] = (v + dt * acc) * damp
    x += dt * v
    fixed = system.fixed
    x[fixed] = x_new[fixed]
    v[fixed] = ((x_new - system.X) - (x_old - system.X))[fixed] / dt


def _numpy_advance(system, x, v, dt, damp, ramp_time, step0, nsteps, check_every, limit2):
    has_plates = len(system.plates) > 0
    P_old = system.prescribed(ramp(step0 * dt, ramp_time)) if has_plates else None
    for n in range(nsteps):
        step = step0 + n
        if has_plates:
            P_new = system.prescribed(ramp((step + 1) * dt, ramp_time))
        else:
            P_new = None
        if has_plates:
            numpy_step(system, x, v, dt, damp, P_old, P_new)
        else:
            numpy_step(system, x, v, dt, damp, system.X, system.X)
        P_old = P_new
        if (n + 1) % check_every == 0 or n == nsteps - 1:
            u2 = np.einsum("ij,ij->i", x - system.X, x - system.X)
            bad = np.flatnonzero(~np.isfinite(u2))
            if len(bad):
                return n + 1, int(bad[0])
            i = int(np.argmax(u2))
            if u2[i] > limit2:
                return n + 1, i
    return nsteps, -1


# ------------------------------------------------------------------------------ the run
def _divergence(system, x, particle, step, dt, limit, dt_c, check_every):
    grid = tuple(int(g) for g in system.lattice.grid[particle])
    u = x[particle] - system.X[particle]
    unorm = float(np.hypot.reduce(u))  # no overflow of the squares: a run away can reach 1e200 m
    if not np.all(np.isfinite(u)):
        what = "has a non-finite position"
    else:
        what = (f"moved {unorm:.3g} m, more than {BLOWUP_FACTOR:g}× the body size "
                f"({limit:.3g} m)")
    if dt_c is None:
        try:
            dt_c = dt_crit(system)
        except Exception:  # the message must still be raised
            dt_c = float("nan")
    if math.isnan(dt_c):
        cause = (f"unknown (dt_crit could not be computed); check dt={dt:g} s against the explicit "
                 "stability limit 2/√λmax(M⁻¹K)")
    elif dt > dt_c:
        cause = f"time step dt={dt:g} s exceeds the explicit stability limit dt_crit≈{dt_c:.4g} s"
    else:
        cause = (
            f"dt={dt:g} s is below the stability limit dt_crit≈{dt_c:.4g} s at rest, so the motion "
            "itself ran away: large deformation (inverted cells, a plate ramp too fast) or a volume "
            "energy with κ < 0 (ν < 1/4) that rewards dilation"
        )
    msg = (f"explicit run diverged at step {step} (t = {step * dt:.6g} s; checked every "
           f"{check_every} steps): particle {particle} "
           f"(grid {grid}) {what}. Likely cause: {cause}.")
    return DivergenceError(msg, step=step, particle=int(particle), grid=grid, displacement=unorm,
                           dt=dt, dt_crit=dt_c, positions=x)


def _energies(system, x, v_half, dt, damp):
    """Potential terms, kinetic ½ m |v_{n+½}|² and the time-centred ½ m v_{n+½}·v_{n+3/2}."""
    _, f, parts = energy_forces(system, x)
    m = system.mass[:, None]
    v_next = (v_half + dt * f / m) * damp
    v_next[system.fixed] = v_half[system.fixed]
    out = {k: float(val) for k, val in parts.items()}
    out["kinetic"] = float(0.5 * np.sum(m * v_half * v_half))
    out["kinetic_centred"] = float(0.5 * np.sum(m * v_half * v_next))
    return out


def force_scale(system: System, f_int: np.ndarray) -> float:
    """Force scale of a state: the largest plate reaction ``|Σ f|`` over a plate's particles,
    the weight ``|Σ m g|``, the total dead load, and ``1e-12 E le²`` (a floor for a body that
    nothing loads; the same scale as the static solver's, plus that floor)."""
    f = f_int if system.gravity is None else f_int + system.mass[:, None] * system.gravity[None, :]
    scale = 0.0
    for p in system.plates:
        scale = max(scale, float(np.linalg.norm(f[p.particles].sum(axis=0))))
    if system.gravity is not None:
        scale = max(scale, float(np.linalg.norm(system.mass.sum() * system.gravity)))
    for t in system.terms:
        if isinstance(t, DeadLoad):
            scale = max(scale, float(np.linalg.norm(t.f.sum(axis=0))))
    return max(scale, 1e-12 * system.scene.material.E * system.scene.body.le**2)


def rest_report(system: System, f_int: np.ndarray, energy: dict, load_factor: float,
                rtol: float = REST_RTOL) -> dict:
    """Whether an explicit run ended at rest, and the figures behind the verdict.

    At rest means all three of: the load ramp is complete (``load_factor == 1``); the force
    residual on the free degrees of freedom ``‖f_free‖₂ ≤ rtol · scale`` (:func:`force_scale`);
    the kinetic energy ``≤ rtol² · max(|elastic energy|, scale · le)``.  A vibration of relative
    amplitude a about the equilibrium has residual ~ a · scale and kinetic energy up to
    ~ a² · elastic energy, so both tests ask for a ≲ rtol.  An undamped run rarely passes: set
    a damping c of the order of the slowest mode's frequency to settle it.
    """
    f = f_int if system.gravity is None else f_int + system.mass[:, None] * system.gravity[None, :]
    free = ~system.fixed
    residual = float(np.linalg.norm(f[free]))
    scale = force_scale(system, f_int)
    elastic = float(energy.get("springs", 0.0) + energy.get("volume", 0.0))
    e_scale = max(abs(elastic), scale * system.scene.body.le)
    ke = float(energy["kinetic"])
    ramp_done = load_factor >= 1.0
    ok_res = residual <= rtol * scale
    ok_ke = ke <= rtol * rtol * e_scale
    at_rest = bool(ramp_done and ok_res and ok_ke)
    why = []
    if not ramp_done:
        why.append(f"the load ramp is at s = {load_factor:.3g} < 1 (run longer than ramp_time)")
    if not ok_res:
        why.append(f"force residual {residual:.3g} N > {rtol:g} x scale {scale:.3g} N")
    if not ok_ke:
        why.append(f"kinetic energy {ke:.3g} J > {rtol:g}^2 x {e_scale:.3g} J")
    return {
        "at_rest": at_rest,
        "criterion": (f"load ramp complete, free force residual <= {rtol:g} x force scale, "
                      f"kinetic energy <= {rtol:g}^2 x max(|elastic energy|, scale x le)"),
        "rtol": float(rtol),
        "residual_N": residual,
        "force_scale_N": scale,
        "relative_residual": residual / scale,
        "kinetic_energy_J": ke,
        "elastic_energy_J": elastic,
        "relative_kinetic_energy": ke / e_scale,
        "load_factor": float(load_factor),
        "not_at_rest_because": "; ".join(why) if why else None,
    }


def simulate_explicit(
    scene: Scene,
    dt: float = 1e-3,
    steps: int = 10_000,
    kernel: str = "numba",
    ramp_time: float = 1.0,
    threads: int = 1,
    record_every: int = 0,
    system: System | None = None,
    *,
    x0: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    dt_crit_value: float | None = None,
    compute_dt_crit: bool = True,
    check_every: int = 10,
    precision: str = "f64",
    damping: float | None = None,
    rest_rtol: float = REST_RTOL,
    compile_first: bool = True,
    warm_up: float = 0.0,
) -> Result:
    """Integrate ``scene`` with semi-implicit Euler for ``steps`` steps of ``dt`` (module docstring).

    - ``kernel``: ``'numba'`` (stencil kernel) or ``'numpy'`` (readable twin); same trajectory.
    - ``ramp_time``: T (s) of the plate ramp ``s(t) = ½(1 − cos(π t/T))``, then 1 (0: no ramp).
    - ``threads``: kernel threads (each on its own node range, all steps at once with a spinning
      barrier per step); 1 (the default) runs the serial kernel.  Two threads pay only when the second core
      is idle: spinning threads on a busy core make every step far slower.
    - ``precision``: ``'f64'`` or ``'f32'`` (numba kernel only: float32 displacements, about
      twice as fast, position error ~1e-6 of the largest displacement after 10,000 steps).
    - ``damping``: the mass-proportional damping c (1/s) of this run, replacing
      ``scene.damping`` (the result's scene digest is that of the scene with this damping).
    - ``rest_rtol``: tolerance of the rest criterion reported in ``info['rest']`` and
      ``converged`` (see :func:`rest_report`).
    - ``compile_first``: generate and compile (or load) the kernel before the timed span.
    - ``warm_up``: seconds of untimed steps of the numba kernel before the timed span, from the
      same initial state, which is then loaded again (benchmarks: a core that was idle steps at
      about half speed for its first ~100 ms; two threads on the 15³ cube took 0.20 ms per step
      for their first 500 steps, then 0.106).
    - ``record_every``: if > 0, ``info['history']`` holds t, energies and the largest
      displacement every that many steps (and at t = 0).
    - ``x0``/``v0``: initial positions and (half-step) velocities (n, 3); default rest.
      Prescribed components start at their prescribed value with zero velocity.
    - ``dt_crit_value``: a known dt_crit; otherwise it is computed (``compute_dt_crit``) and
      reported in ``info['dt_crit']``, or computed lazily only when the run diverges.
    - ``check_every``: steps between divergence checks (and always at the last step): a
      non-finite position or a displacement > 10× the largest body edge raises
      :class:`DivergenceError` naming the step, the particle and the likely cause.

    Reactions: for each plate, ``−Σ (f_int + m g)`` over its particles (prescribed components
    only; torque about its current centroid).  At rest this is the force the plate exerts on the
    body; while the body still moves it misses the plate particles' own ``m a``, and the
    difference between plate reactions and external loads is the body's inertia.
    ``wall_time_s`` is the time stepping alone (no set-up, dt_crit or post-processing; the
    numba kernel's first call also compiles unless it is cached); ``info['cpu_time_s']`` is the
    process CPU time of the same span (all threads), steadier than wall time on a busy machine.
    """
    if kernel not in KERNELS:
        raise ValueError(f"kernel must be one of {', '.join(KERNELS)}; got {kernel!r}")
    model = scene.model.spec
    if kernel not in model.kernels:
        raise ValueError(f"model {model.name} has no {kernel} kernel (its kernels: {', '.join(model.kernels)}); "
                         f"use kernel={model.kernels[0]!r}")
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)}; got {precision!r}")
    if not (warm_up >= 0 and math.isfinite(warm_up)):
        raise ValueError(f"warm_up must be >= 0 s, got {warm_up}")
    if damping is not None:
        damping = float(damping)
        if not (damping >= 0 and math.isfinite(damping)):
            raise ValueError(f"damping must be >= 0 (1/s), got {damping}")
        scene = dataclasses.replace(scene, damping=damping)
        if system is not None:
            system = dataclasses.replace(system, scene=scene)
    if model.simulate_explicit is not None:  # a model with its own integrator (hybmss.models.base)
        return model.simulate_explicit(scene, dt=dt, steps=steps, kernel=kernel, ramp_time=ramp_time,
                                       threads=threads, record_every=record_every, system=system, x0=x0, v0=v0,
                                       dt_crit_value=dt_crit_value, compute_dt_crit=compute_dt_crit,
                                       check_every=check_every, precision=precision)
    dt = float(dt)
    if not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"dt must be > 0 s, got {dt}")
    steps = int(steps)
    if steps < 0:
        raise ValueError(f"steps must be >= 0, got {steps}")
    if not (ramp_time >= 0 and math.isfinite(ramp_time)):
        raise ValueError(f"ramp_time must be >= 0 s, got {ramp_time}")
    threads = int(threads)
    if threads < 1:
        raise ValueError(f"threads must be >= 1, got {threads}")
    t_setup = time.perf_counter()
    warm_s = 0.0
    sys_ = system if system is not None else build(scene)
    if (sys_.mass <= 0).any():
        raise ValueError("explicit dynamics needs rho > 0 (every particle must have mass)")
    damp = 1.0 / (1.0 + sys_.scene.damping * dt)
    limit = BLOWUP_FACTOR * max(scene.body.size)
    limit2 = limit * limit
    check_every = max(1, int(check_every))

    x, v = initial_state(sys_, x0, v0, ramp_time)

    dt_c = dt_crit_value
    t_dc = 0.0
    if dt_c is None and compute_dt_crit:
        t0 = time.perf_counter()
        dt_c = dt_crit(sys_)
        t_dc = time.perf_counter() - t0

    if kernel == "numba":
        st = stencil(sys_, dt, ramp_time, precision=precision, threads=threads)
        st.load(x, v)
        node_to_particle = sys_.lattice.node_id.ravel()

        def advance(step0, n):
            k, bad = st.advance(step0, n, check_every, limit2)
            return k, (int(node_to_particle[bad]) if bad >= 0 else -1)

        state = st.state
        if compile_first:  # compile (or load from the cache) outside the timed span: a 0-step run
            st.advance(0, 0, check_every, limit2)
        if warm_up > 0.0:
            t_warm, k = time.perf_counter(), 0
            while time.perf_counter() - t_warm < warm_up:
                done, bad = st.advance(k, WARM_UP_STEPS, WARM_UP_STEPS, limit2)
                k += done
                if bad >= 0:
                    break
            st.load(x, v)
            warm_s = time.perf_counter() - t_warm
    else:
        if threads != 1:
            raise ValueError("the numpy kernel runs on one thread (threads=1)")
        if precision != "f64":
            raise ValueError("the numpy kernel runs in float64 (precision='f64')")

        def advance(step0, n):
            return _numpy_advance(sys_, x, v, dt, damp, ramp_time, step0, n, check_every, limit2)

        def state():
            return x.copy(), v.copy()

    setup_s = time.perf_counter() - t_setup - t_dc - warm_s
    history = None
    if record_every > 0:
        history = {"t": [], "max_displacement": []}

        def record(step):
            xs, vs = state()
            e = _energies(sys_, xs, vs, dt, damp)
            history["t"].append(step * dt)
            history["max_displacement"].append(float(np.linalg.norm(xs - sys_.X, axis=1).max()))
            for k, val in e.items():
                history.setdefault(k, []).append(val)

        record(0)
    chunk = int(record_every) if record_every > 0 else max(steps, 1)

    wall = cpu = 0.0
    done = 0
    while done < steps:
        n = min(chunk, steps - done)
        c0 = time.process_time()
        t0 = time.perf_counter()
        k, bad = advance(done, n)
        wall += time.perf_counter() - t0
        cpu += time.process_time() - c0
        if bad >= 0:
            xs, _ = state()
            raise _divergence(sys_, xs, bad, done + k, dt, limit, dt_c, check_every)
        done += n
        if history is not None:
            record(done)

    t_post = time.perf_counter()
    xs, vs = state()
    energy = _energies(sys_, xs, vs, dt, damp)
    lat = sys_.lattice
    vols = lat.cell_volumes(xs)
    V0 = float(lat.cell_volumes(sys_.X).sum())
    f_int = internal_forces(sys_, xs)
    reactions = {}
    for ps in sys_.plates:
        idx = ps.particles
        r = -f_int[idx]
        if sys_.gravity is not None:
            r = r - sys_.mass[idx, None] * sys_.gravity[None, :]
        r = r * ps.constrained[None, :]
        reactions[ps.name] = reaction_from_nodal(xs[idx], r)
    s_end = ramp(steps * dt, ramp_time)
    rest = rest_report(sys_, f_int, energy, s_end, rest_rtol)
    info = {
        "kernel": kernel,
        "threads": threads,
        "precision": precision,
        "rest": rest,
        "dt": dt,
        "steps": steps,
        "t_end": steps * dt,
        "dt_crit": None if dt_c is None else float(dt_c),
        "damping": float(sys_.scene.damping),
        "damping_scheme": "mass-proportional -c m v, implicit: v = (v + dt a) / (1 + c dt)",
        "ramp_time": float(ramp_time),
        "ramp_law": RAMP_LAW,
        "load_factor": s_end,
        "cpu_time_s": cpu,
        "setup_s": setup_s,
        "warm_up_s": warm_s,
        "dt_crit_s": t_dc,
        "postprocess_s": time.perf_counter() - t_post,
        "max_speed": float(np.linalg.norm(vs, axis=1).max()) if len(vs) else 0.0,
        "inverted_cells": int(np.count_nonzero(vols <= 0.0)),
        "kappa": float(sys_.kappa),
    }
    if history is not None:
        info["history"] = history
    return Result(
        solver=SOLVER,
        scene_digest=scene.digest(),
        X=sys_.X.copy(),
        u=xs - sys_.X,
        volume=float(vols.sum()),
        volume0=V0,
        reactions=reactions,
        energy=energy,
        iterations=steps,
        wall_time_s=wall,
        converged=rest["at_rest"],
        cell_volumes=vols,
        info=info,
    )
