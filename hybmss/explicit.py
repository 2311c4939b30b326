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

import math
import time
from dataclasses import dataclass

import numpy as np

from .forces import energy_forces, hessian, internal_forces
from .result import Result, reaction_from_nodal
from .scene import Scene
from .system import System, build

SOLVER = "mss-explicit"
KERNELS = ("numba", "numpy")
RAMP_LAW = "s(t) = 0.5 (1 - cos(pi t / T)) for t < T, then 1"
BLOWUP_FACTOR = 10.0
"""A displacement beyond this many body sizes (largest bounding-box edge) counts as divergence."""

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

        lmax = float(eigsh(A, k=1, which="LA", tol=1e-8, return_eigenvectors=False)[0])
    return 2.0 / math.sqrt(lmax) if lmax > 0 else math.inf


# ------------------------------------------------------------------------------ stencil layout
@dataclass(eq=False)
class Stencil:
    """A system laid out on its full grid for the stencil kernel (see :mod:`hybmss._kernels`),
    with the run parameters (dt, damping factor, ramp time)."""

    shape: tuple[int, int, int]
    flat: np.ndarray  # (n,) grid index of each particle
    Xg: np.ndarray  # (3, N)
    K: np.ndarray  # (n_off, N)
    l0: np.ndarray  # (n_off,)
    offs: np.ndarray  # (n_off,) flat offsets
    offsets: np.ndarray  # (n_off, 3) grid offsets
    groups: np.ndarray  # (n_g, 4, 2) (T row, flat offset) four at a time, padded with the zero row
    kv: np.ndarray  # (2, N): κ of the cell whose lowest corner is p (0: no cell), its rest volume
    coff: np.ndarray  # (8,) flat corner offsets
    squared: bool
    has_volume: bool
    invm: np.ndarray  # (N,)
    gacc: np.ndarray  # (3, N)
    has_gravity: bool
    dt: float
    damp: float
    ramp_time: float
    pl_nodes: np.ndarray
    pl_U1: np.ndarray  # (3, total plate nodes): u at s = 1 of motions linear in s
    pl_ptr: np.ndarray
    pl_mask: np.ndarray
    pl_kind: np.ndarray
    pl_disp: np.ndarray
    pl_axis: np.ndarray
    pl_center: np.ndarray
    pl_angle: np.ndarray

    @property
    def N(self) -> int:
        return int(np.prod(self.shape))

    def scratch(self):
        """Zeroed work arrays (T, ABC, CR, G, F) of the kernel.  T and G rows have a zero pad of
        P = coff[7] entries in front, T an extra all-zero row; entries never written stay 0."""
        N, P = self.N, int(self.coff[7])
        return (np.zeros((len(self.offs) + 1, 3, P + N)), np.zeros((9, N)), np.zeros((10, N)),
                np.zeros((4, 3, P + N)), np.zeros((3, N)))

    def to_grid(self, y: np.ndarray, fill: np.ndarray | None = None) -> np.ndarray:
        """(n, 3) particle array → (3, N) grid array (absent nodes from ``fill`` or 0)."""
        g = np.zeros((3, self.N)) if fill is None else fill.copy()
        g[:, self.flat] = y.T
        return g

    def from_grid(self, g: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(g[:, self.flat].T)


def stencil(system: System, dt: float, ramp_time: float) -> Stencil:
    """Lay ``system`` out on its grid.  Raises ``ValueError`` for what the stencil cannot hold
    (force terms of ``system.terms``, non-regular rest lengths)."""
    if system.terms:
        raise ValueError(
            f"the numba kernel has no force terms ({', '.join(t.name for t in system.terms)}); "
            "use kernel='numpy'"
        )
    lat = system.lattice
    scene = system.scene
    le = scene.body.le
    shape = tuple(int(n) + 1 for n in scene.body.shape)
    N = int(np.prod(shape))
    strides = np.array([shape[1] * shape[2], shape[2], 1], dtype=np.int64)
    flat = lat.grid @ strides
    gi = np.indices(shape).reshape(3, -1).astype(float)
    Xg = np.asarray(scene.body.origin, dtype=float)[:, None] + gi * le
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
    if system.has_volume:
        p = flat[system.vol_cells[:, 0]]
        kv[0, p] = system.kappa
        kv[1, p] = system.vol_V0

    if (system.mass <= 0).any():
        raise ValueError("explicit dynamics needs rho > 0 (every particle must have mass)")
    invm = np.zeros(N)
    invm[flat] = 1.0 / system.mass
    gacc = np.zeros((3, N))
    if system.gravity is not None:
        gacc[:, flat] = system.gravity[:, None]

    nodes, U1, ptr, mask, kind, disp, axis, center, angle = [], [], [0], [], [], [], [], [], []
    for plate, ps in zip(scene.plates, system.plates):
        m = plate.motion
        Xp = system.X[ps.particles]
        u1 = m.displacement_at(Xp, 1.0)
        if m.kind != "rotate" and not np.allclose(m.displacement_at(Xp, 0.5), 0.5 * u1, rtol=1e-12,
                                                  atol=1e-12 * le):
            raise ValueError(f"plate {plate.name!r}: the stencil kernel needs a motion linear in the "
                             f"load factor or a rotation, got {m.kind!r}; use kernel='numpy'")
        nodes.append(flat[ps.particles])
        U1.append(u1.T)
        ptr.append(ptr[-1] + len(ps.particles))
        mask.append(ps.constrained)
        kind.append(1 if m.kind == "rotate" else 0)
        disp.append(m.displacement)
        axis.append(m.axis)
        center.append(m.center if m.center is not None else system.X[ps.particles].mean(axis=0))
        angle.append(m.angle)
    n_pl = len(scene.plates)
    return Stencil(
        shape=shape,
        flat=flat,
        Xg=Xg,
        K=K,
        l0=l0_all[active],
        offs=OFFSETS[active] @ strides,
        groups=_groups(OFFSETS[active] @ strides),
        offsets=OFFSETS[active],
        kv=kv,
        coff=coff,
        squared=system.volume_energy == "squared",
        has_volume=system.has_volume,
        invm=invm,
        gacc=gacc,
        has_gravity=system.gravity is not None,
        dt=float(dt),
        damp=1.0 / (1.0 + system.scene.damping * dt),
        ramp_time=float(ramp_time),
        pl_nodes=np.concatenate(nodes).astype(np.int64) if nodes else np.zeros(0, dtype=np.int64),
        pl_U1=np.ascontiguousarray(np.concatenate(U1, axis=1)) if U1 else np.zeros((3, 0)),
        pl_ptr=np.asarray(ptr, dtype=np.int64),
        pl_mask=np.asarray(mask, dtype=np.bool_).reshape(n_pl, 3),
        pl_kind=np.asarray(kind, dtype=np.int64),
        pl_disp=np.asarray(disp, dtype=float).reshape(n_pl, 3),
        pl_axis=np.asarray(axis, dtype=float).reshape(n_pl, 3),
        pl_center=np.asarray(center, dtype=float).reshape(n_pl, 3),
        pl_angle=np.asarray(angle, dtype=float),
    )


def _groups(offs: np.ndarray) -> np.ndarray:
    """(T row, offset) pairs four at a time; the padding entries read T's all-zero last row."""
    n = len(offs)
    ng = -(-n // 4)
    g = np.zeros((ng * 4, 2), dtype=np.int64)
    g[:, 0] = n  # the zero row
    g[:n, 0] = np.arange(n)
    g[:n, 1] = offs
    return g.reshape(ng, 4, 2)


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
    unorm = float(np.linalg.norm(u))
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
) -> Result:
    """Integrate ``scene`` with semi-implicit Euler for ``steps`` steps of ``dt`` (module docstring).

    - ``kernel``: ``'numba'`` (stencil kernel) or ``'numpy'`` (readable twin); same trajectory.
    - ``ramp_time``: T (s) of the plate ramp ``s(t) = ½(1 − cos(π t/T))``, then 1 (0: no ramp).
    - ``threads``: numba threads (prange over node ranges); 1 runs the serial kernel.
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
    if model.simulate_explicit is not None:  # a model with its own integrator (hybmss.models.base)
        return model.simulate_explicit(scene, dt=dt, steps=steps, kernel=kernel, ramp_time=ramp_time,
                                       threads=threads, record_every=record_every, system=system, x0=x0, v0=v0,
                                       dt_crit_value=dt_crit_value, compute_dt_crit=compute_dt_crit,
                                       check_every=check_every)
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
    sys_ = system if system is not None else build(scene)
    if (sys_.mass <= 0).any():
        raise ValueError("explicit dynamics needs rho > 0 (every particle must have mass)")
    damp = 1.0 / (1.0 + sys_.scene.damping * dt)
    limit = BLOWUP_FACTOR * max(scene.body.size)
    limit2 = limit * limit
    check_every = max(1, int(check_every))

    x = sys_.X.copy() if x0 is None else np.array(x0, dtype=float).reshape(sys_.n, 3)
    v = np.zeros((sys_.n, 3)) if v0 is None else np.array(v0, dtype=float).reshape(sys_.n, 3)
    P0 = sys_.prescribed(ramp(0.0, ramp_time))
    x[sys_.fixed] = P0[sys_.fixed]
    v[sys_.fixed] = 0.0

    dt_c = dt_crit_value
    t_dc = 0.0
    if dt_c is None and compute_dt_crit:
        t0 = time.perf_counter()
        dt_c = dt_crit(sys_)
        t_dc = time.perf_counter() - t0

    if kernel == "numba":
        from . import _kernels

        st = stencil(sys_, dt, ramp_time)
        scratch = st.scratch()
        xg = st.to_grid(x, st.Xg)
        vg = st.to_grid(v)

        node_to_particle = sys_.lattice.node_id.ravel()

        def advance(step0, n):
            k, bad = _kernels.advance(st, xg, vg, step0, n, check_every, limit2, scratch, threads)
            return k, (int(node_to_particle[bad]) if bad >= 0 else -1)

        def state():
            return st.from_grid(xg), st.from_grid(vg)
    else:
        if threads != 1:
            raise ValueError("the numpy kernel runs on one thread (threads=1)")

        def advance(step0, n):
            return _numpy_advance(sys_, x, v, dt, damp, ramp_time, step0, n, check_every, limit2)

        def state():
            return x.copy(), v.copy()

    setup_s = time.perf_counter() - t_setup - t_dc
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
    info = {
        "kernel": kernel,
        "threads": threads,
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
        converged=True,
        cell_volumes=vols,
        info=info,
    )
