"""The stepper of the spring and volume lattice (:class:`LatticeStepper`): semi-implicit Euler
``v ← (v + dt (f(x)/m + g)) / (1 + c dt)``, ``x ← x + dt v`` on the lattice's springs, volume
term and force terms, with two kernels that give the same trajectory: the generated stencil kernel
(:class:`Stencil`, :func:`stencil`; :mod:`hybmss._stencil_gen`, helpers in :mod:`hybmss._kernels`;
a force term it does not generate contributes a :class:`StencilStage`) and its readable NumPy twin
(:func:`numpy_step` on :mod:`hybmss.forces`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ... import _cpu
from ...explicit.divergence import find_bad
from ...explicit.loop import PRECISIONS, SOLVER
from ...explicit.plates import hold_clamped, plate_arrays, ramp
from ...forces import energy_forces, internal_forces
from ...system import System
from ...terms import DeadLoad

NODE_SHIFT = 0.5
"""Where a grid node that is not a particle (a pad of the kernel's flat state, a grid node outside
the body) sits: its lattice point plus ``NODE_SHIFT · le`` along each axis, the centre of a cell
(:meth:`Stencil.load`), out of reach of a particle moved by whole cell edges."""

OFFSETS = np.array(
    [(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) > (0, 0, 0)],
    dtype=np.int64,
)
"""The 13 forward neighbour offsets (lexicographically positive) of the stencil."""


def _aligned_zeros(n: int, dtype) -> np.ndarray:
    """Zeroed 1-D array of ``n`` entries whose data starts on a 64-byte boundary."""
    item = np.dtype(dtype).itemsize
    buf = np.zeros(n + 64 // item, dtype=dtype)
    off = (-buf.ctypes.data % 64) // item
    return buf[off:off + n]


@dataclass(eq=False)
class Stencil:
    """A system laid out on its full grid for the generated kernel (:mod:`hybmss._stencil_gen`),
    with the run parameters (dt, damping factor, ramp time, precision, threads).

    ``K`` (n_off, N), ``kv`` (2, N), ``invm``, ``gacc`` are the float64 grid arrays the flat state
    ``W`` is filled from; ``F0`` (3, N) the dead loads; ``stage`` the :class:`StencilStage` of a
    force term the stencil does not generate, or None."""

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
    stage: "StencilStage | None"
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
        from ..._stencil_gen import Config

        return Config(shape=tuple(self.shape), offsets=tuple(tuple(int(c) for c in o) for o in self.offsets),
                      has_volume=bool(self.has_volume), squared=bool(self.squared),
                      has_gravity=bool(self.has_gravity),
                      has_external=self.F0 is not None or self.stage is not None,
                      stage=None if self.stage is None else self.stage.function, precision=self.precision,
                      threads=int(self.threads), le=float(self.le))

    @property
    def layout(self):
        from ..._stencil_gen import layout

        return layout(self.config)

    def module(self):
        """The compiled kernel of this stencil (generated and compiled on first use, then cached)."""
        from ..._stencil_gen import kernel_module

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
        # every entry of a position row that is not a particle (pads, absent grid nodes) holds a
        # finite point: the centre of the cell above its point of the lattice continued beyond the
        # grid (NODE_SHIFT).  Such nodes never move and join no spring (K = 0), but the kernel
        # still evaluates k (1 - l0/l) for them, and a particle reaching their point exactly
        # (l = 0) would make it 0 * inf = nan; a lattice point is reached exactly by a plate
        # translated by a whole cell edge (the 10x10x10 shear at 20 % at t = 0.5 s), a cell centre
        # only by a motion of half an edge along all three axes at once.
        q = np.arange(-F, L - F)
        gi = np.stack([q // lay.s0, (q % lay.s0) // lay.s1, q % lay.s1]).astype(float)
        shift = NODE_SHIFT * self.le
        Xext = np.asarray(self.Xg[:, 0:1]) + gi * self.le + shift
        absent = np.ones(N, dtype=bool)
        absent[self.flat] = False
        xg = self.Xg.copy()
        xg[:, absent] += shift
        xg[:, self.flat] = x.T
        vg = np.zeros((3, N))
        vg[:, self.flat] = v.T
        posmode = self.precision == "f64"
        for name in ("XA0", "XB0") if self.threads > 1 else ("XA0",):
            rows = self._rows(name)
            rows[:] = Xext if posmode else shift
            rows[:, F:F + N] = xg if posmode else xg - self.Xg
        self._rows("V0")[:, F:F + N] = vg
        for j in range(len(self.offs)):
            self._rows(f"K{j}", 1)[0, F:F + N] = self.K[j]
        if self.has_volume:
            self._rows("KAP", 1)[0, F:F + N] = self.kv[0]
        self._rows("IM", 1)[0, F:F + N] = self.invm
        if self.has_gravity:
            self._rows("GA0")[:, F:F + N] = self.gacc
        if self.F0 is not None and self.stage is None:
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
        and a spinning barrier per step (:mod:`hybmss._cpu`); a force stage, or threads
        that did not all run at once, take one Numba parallel region per step."""
        mod = self.module()
        args = self._args(step0, nsteps, check_every, limit2)
        T = int(self.threads)
        done = bad = None
        if T > 1 and self.stage is None:
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
        if self.stage is not None:
            F0 = self.F0 if self.F0 is not None else np.zeros((3, self.N))
            stage_args = self.stage.args()
        else:
            F0, stage_args = np.zeros((3, 1)), ()
        return (self.W, prm, self.Xg, self.pl_nodes, self.pl_U1, self.pl_ptr, self.pl_mask, self.pl_kind,
                self.pl_disp, self.pl_axis, self.pl_center, self.pl_angle, np.int64(step0), np.int64(nsteps),
                np.int64(max(1, check_every)), float(limit2), np.int64(self.parity), float(self.dt),
                float(self.ramp_time), F0, stage_args)

    def _run_threads(self, mod, args, absent: tuple = ()) -> tuple[int | None, int | None]:
        """All steps of :meth:`advance` on ``threads`` threads at once
        (:func:`hybmss._stencil_gen.run_threads`: one spinning barrier per step).  (None, None)
        with the state restored if the threads did not all run at once (a thread waited in vain at
        a barrier): the caller then runs one parallel region per step.  ``absent``: threads not
        started (see ``run_threads``)."""
        from ..._stencil_gen import run_threads

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


@dataclass(frozen=True, eq=False)
class StencilStage:
    """A force term's own stage in the generated stencil kernel (:mod:`hybmss._stencil_gen`).

    A term the stencil does not generate provides it by a method ``stencil_stage(system)``:
    ``function`` names a Numba function ``stage(W, xb, feb, L, N, F0, args)`` as
    ``"module:name"`` (it writes the dead loads ``F0`` plus the term's forces at the positions of
    the rows at ``xb`` into the external-force rows at ``feb``, before every step), ``args()``
    returns the tuple ``args`` (its arrays, constants and scratch, fresh for each kernel call) and
    ``precisions`` the precisions it supports."""

    function: str
    args: object  # () -> tuple
    precisions: tuple[str, ...] = ("f64",)


def _external_forces(system: System, precision: str):
    """(dead loads (n, 3) or None, the :class:`StencilStage` of a term or None) of
    ``system.terms``; ValueError for a term the generated kernel cannot hold."""
    dead, stages, other = None, [], []
    for t in system.terms:
        if isinstance(t, DeadLoad):  # constant forces: the explicit run applies them whole
            dead = t.f if dead is None else dead + t.f
        elif hasattr(t, "stencil_stage"):
            stages.append(t)
        else:
            other.append(t.name)
    if other or len(stages) > 1:
        raise ValueError(f"the numba kernel holds springs, volume term, gravity, dead loads and one force term "
                         f"with a stencil stage, not the force terms {', '.join(other + [t.name for t in stages])}; "
                         "use kernel='numpy'")
    stage = stages[0].stencil_stage(system) if stages else None
    if stage is not None and precision not in stage.precisions:
        raise ValueError(f"the stencil stage of {stages[0].name} runs in {', '.join(stage.precisions)} only; "
                         f"use precision={stage.precisions[0]!r}")
    return dead, stage


def _grid(system: System) -> tuple[tuple[int, int, int], np.ndarray, np.ndarray, np.ndarray]:
    """The full grid of ``system``'s body: its node shape (cells + 1 per axis), strides, the flat
    grid index of each particle and the reference positions (3, N) of the grid nodes (the
    particles' own where they are).  Raises ``ValueError`` for particles off the regular grid."""
    scene = system.scene
    le = scene.body.le
    shape = tuple(int(n) + 1 for n in scene.body.shape)
    strides = np.array([shape[1] * shape[2], shape[2], 1], dtype=np.int64)
    flat = system.lattice.grid @ strides
    gi = np.indices(shape).reshape(3, -1).astype(float)
    Xg = np.asarray(scene.body.origin, dtype=float)[:, None] + gi * le
    if not np.allclose(Xg[:, flat], system.X.T, rtol=0.0, atol=1e-12 * max(1.0, float(np.abs(Xg).max()))):
        raise ValueError("particles are not on the regular grid; the stencil kernel needs a regular lattice")
    Xg[:, flat] = system.X.T
    return shape, strides, flat, Xg


def _springs(system: System, flat: np.ndarray, N: int, le: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The springs as one row of constants per forward offset that holds one: ``(K (n_off, N),
    rest lengths (n_off,), grid offsets (n_off, 3))``.  Raises ``ValueError`` for a spring that
    does not join grid neighbours or a rest length that is not the grid's."""
    lat = system.lattice
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
    return np.ascontiguousarray(Kall[active]), l0_all[active], OFFSETS[active]


def _volumes(system: System, flat: np.ndarray, N: int, le: float,
             strides: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The volume term on the grid: ``(flat offsets of a cell's 8 corners, kv (2, N): κ and rest
    volume of the cell whose lowest corner is each node, the one rest volume)``.  Raises
    ``ValueError`` for rest cell volumes that differ."""
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
    return coff, kv, V0


def _masses(system: System, flat: np.ndarray, N: int, dead) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """``(1/m (N,), gravity's acceleration (3, N), dead loads (3, N) or None)`` on the grid.
    Raises ``ValueError`` for a particle without mass."""
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
    return invm, gacc, F0


def stencil(system: System, dt: float, ramp_time: float, precision: str = "f64", threads: int = 1,
            damping: float | None = None) -> Stencil:
    """Lay ``system`` out on its grid.  Raises ``ValueError`` for what the stencil cannot hold
    (force terms other than dead loads and one with a :class:`StencilStage`; non-regular rest
    lengths; a stage in a precision it does not support)."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)}; got {precision!r}")
    dead, stage = _external_forces(system, precision)
    le = system.scene.body.le
    shape, strides, flat, Xg = _grid(system)
    N = int(np.prod(shape))
    K, l0, offsets = _springs(system, flat, N, le)
    coff, kv, V0 = _volumes(system, flat, N, le, strides)
    invm, gacc, F0 = _masses(system, flat, N, dead)
    plates, held = hold_clamped(plate_arrays(system, flat))
    invm[held] = 0.0
    gacc[:, held] = 0.0
    c = system.scene.damping if damping is None else float(damping)
    return Stencil(
        shape=shape,
        flat=flat,
        Xg=Xg,
        K=K,
        l0=l0,
        offs=offsets @ strides,
        offsets=offsets,
        kv=kv,
        coff=coff,
        squared=system.volume_energy == "squared",
        has_volume=system.has_volume,
        invm=invm,
        gacc=gacc,
        has_gravity=system.gravity is not None,
        F0=F0,
        stage=stage,
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


def numpy_advance(system: System, step, x, v, dt, ramp_time, step0, nsteps, check_every, limit2):
    """The ``advance`` of a NumPy twin (:mod:`hybmss.stepper`): ``nsteps`` calls of
    ``step(x, v, P_old, P_new)`` (one step in place, the plates' prescribed positions
    :meth:`System.prescribed` at s(t_n) and s(t_{n+1}); ``None`` without plates) from global step
    ``step0``, and the divergence check every ``check_every`` steps and at the last."""
    has_plates = len(system.plates) > 0
    P_old = system.prescribed(ramp(step0 * dt, ramp_time)) if has_plates else None
    for n in range(nsteps):
        P_new = system.prescribed(ramp((step0 + n + 1) * dt, ramp_time)) if has_plates else None
        step(x, v, P_old, P_new)
        P_old = P_new
        if (n + 1) % check_every == 0 or n == nsteps - 1:
            bad = find_bad(x, system.X, limit2)
            if bad >= 0:
                return n + 1, bad
    return nsteps, -1


# ------------------------------------------------------------------------------ the lattice's stepper
class LatticeStepper:
    """The stepper (:mod:`hybmss.stepper`) of the spring and volume lattice and its force terms:
    the generated stencil kernel (``kernel='numba'``, :class:`Stencil`) or its readable NumPy
    twin (:func:`numpy_step`), the same trajectory."""

    solver = SOLVER

    def __init__(self, system: System, dt: float, *, ramp_time: float, kernel: str = "numba",
                 precision: str = "f64", threads: int = 1):
        self.system, self.dt, self.ramp_time = system, float(dt), float(ramp_time)
        self.damp = 1.0 / (1.0 + system.scene.damping * self.dt)
        self.info = {"kernel": kernel, "threads": int(threads), "precision": precision}
        if kernel == "numba":
            self.stencil = stencil(system, dt, ramp_time, precision=precision, threads=threads)
            self._node_to_particle = system.lattice.node_id.ravel()
        else:
            if threads != 1:
                raise ValueError("the numpy kernel runs on one thread (threads=1)")
            if precision != "f64":
                raise ValueError("the numpy kernel runs in float64 (precision='f64')")
            self.stencil = None

    def load(self, x, v):
        if self.stencil is not None:
            self.stencil.load(x, v)
        else:
            self.x, self.v = np.array(x, dtype=float), np.array(v, dtype=float)

    def _numpy_step(self, x, v, P_old, P_new):
        X = self.system.X
        numpy_step(self.system, x, v, self.dt, self.damp, X if P_old is None else P_old, X if P_new is None else P_new)

    def advance(self, step0, n, check_every, limit2):
        if self.stencil is None:
            return numpy_advance(self.system, self._numpy_step, self.x, self.v, self.dt, self.ramp_time, step0, n,
                                 check_every, limit2)
        k, bad = self.stencil.advance(step0, n, check_every, limit2)
        return k, (int(self._node_to_particle[bad]) if bad >= 0 else -1)

    def state(self):
        if self.stencil is not None:
            return self.stencil.state()
        return self.x.copy(), self.v.copy()

    def internal_forces(self, x):
        return internal_forces(self.system, x)

    def energy(self, x, v):
        """Potential terms, kinetic ½ m |v_{n+½}|² and the time-centred ½ m v_{n+½}·v_{n+3/2}."""
        system = self.system
        _, f, parts = energy_forces(system, x)
        m = system.mass[:, None]
        v_next = (v + self.dt * f / m) * self.damp
        v_next[system.fixed] = v[system.fixed]
        out = {k: float(val) for k, val in parts.items()}
        out["kinetic"] = float(0.5 * np.sum(m * v * v))
        out["kinetic_centred"] = float(0.5 * np.sum(m * v * v_next))
        return out
