"""The one explicit time loop of every model (:func:`simulate_explicit`): semi-implicit Euler,
``v ← (v + dt (f(x)/m + g)) / (1 + c dt)``, ``x ← x + dt v``, with the plates on their ramp, the
divergence checks, the history, the rest test, the timing and the result; the steps themselves
come from the model's stepper (:mod:`hybmss.stepper`)."""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np

from .. import models as registry
from ..result import Result
from ..scene import Scene
from ..stepper import Chunks, interruptible, timed
from ..system import System, build
from .divergence import BLOWUP_FACTOR, divergence_error
from .limits import dt_crit
from .plates import RAMP_LAW, initial_state, plate_reactions, ramp
from .rest import REST_RTOL, ResidualFloor, decay_rate, force_scale, free_residual, stepper_rest

SOLVER = "mss-explicit"
KERNELS = ("numba", "numpy", "engine")
"""Explicit kernels: the Numba stencil kernel, its NumPy twin, and ``engine``: the own compiled step
of an engine a model wraps (:mod:`hybmss.models.mujoco`, :mod:`hybmss.models.newton`,
:mod:`hybmss.models.pbd`), whose stepper runs in this loop like any other."""
PRECISIONS = ("f64", "f32")
REST_SAMPLE_S = 0.25
"""Simulated seconds between the rest tests of a run with ``until_rest`` (after the ramp).  The
cadence is fixed in simulated time, as is the residual floor's (:class:`_FloorWatch`), so that the
step at which a run stops, and so its answer, does not depend on how busy the machine is.  A test
is a force and energy evaluation (compiled for xpbd-nh, the model that has them): xpbd-nh runs to
rest with both watches spent 5 % of their stepping time in the tests and samples on the 2×2×12
beam under gravity (0.016 s against 0.32 s), 6–7 % on the 6³ and 10³ cubes, 14 % on the 5³ cube
(0.03 s), not counting the one settling."""

WARM_UP_STEPS = 100
"""Steps per kernel call of an explicit run's ``warm_up``."""
WARM_UP_THREADS = 0.1
"""Seconds of untimed steps that benchmarks run before timing several threads (``warm_up`` of
:func:`simulate_explicit`).  A core that was idle steps at about half speed for its first
~100 ms: without them, 1,000 two-thread steps took 1.555 s per 10k on the 15³ cube and 1.415 on
the 8×8×48 beam, no faster than one thread (1.83, 1.42); with them 1.017 and 0.834.  One thread
runs on the core that was busy all along and shows no such start."""


def simulate_explicit(scene: Scene, dt: float = 1e-3, steps: int = 10_000, kernel: str = "numba",
                      ramp_time: float = 1.0, threads: int = 1, record_every: int = 0, system: System | None = None,
                      *, x0: np.ndarray | None = None, v0: np.ndarray | None = None,
                      dt_crit_value: float | None = None, compute_dt_crit: bool = True, check_every: int = 10,
                      precision: str = "f64", damping: float | None = None, rest_rtol: float = REST_RTOL,
                      compile_first: bool = True, warm_up: float = 0.0, stepper=None,
                      until_rest: bool = False) -> Result:
    """Integrate ``scene`` for ``steps`` steps of ``dt`` with the stepper of its model: the one
    explicit time loop of every model (module docstring; the protocol: :mod:`hybmss.stepper`).

    - ``kernel``: ``'numba'`` (compiled kernel) or ``'numpy'`` (readable twin); same trajectory.
    - ``ramp_time``: T (s) of the plate ramp ``s(t) = ½(1 − cos(π t/T))``, then 1 (0: no ramp).
    - ``threads``: kernel threads (each on its own node range, all steps at once with a spinning
      barrier per step); 1 (the default) runs the serial kernel.  Two threads pay only when the second core
      is idle: spinning threads on a busy core make every step far slower.  A model whose kernel
      is serial refuses more than one.
    - ``precision``: ``'f64'`` or ``'f32'`` (numba kernel only: float32 displacements, about
      twice as fast, position error ~1e-6 of the largest displacement after 10,000 steps).
    - ``damping``: the mass-proportional damping c (1/s) of this run, replacing
      ``scene.damping`` (the result's scene digest is that of the scene with this damping).
    - ``rest_rtol``: tolerance of the rest criterion reported in ``info['rest']`` and
      ``converged`` (see :func:`rest_report`), the same for every model.
    - ``compile_first``: generate and compile (or load) the kernel before the timed span.
    - ``warm_up``: seconds of untimed steps before the timed span, from the same initial state,
      which is then loaded again (benchmarks: a core that was idle steps at about half speed for
      its first ~100 ms; two threads on the 15³ cube took 0.20 ms per step for their first 500
      steps, then 0.106).
    - ``record_every``: if > 0, ``info['history']`` holds t, the stepper's energies and the
      largest displacement every that many steps (and at t = 0).
    - ``x0``/``v0``: initial positions and (half-step) velocities (n, 3); default rest.
      Prescribed components start at their prescribed value with zero velocity.
    - ``dt_crit_value``: a known dt_crit; otherwise it is computed (``compute_dt_crit``) and
      reported in ``info['dt_crit']``, or computed lazily only when the run diverges.
    - ``check_every``: steps between divergence checks (and always at the last step): a
      non-finite position or a displacement > 10× the largest body edge raises
      :class:`DivergenceError` naming the step, the particle and the likely cause.
    - ``until_rest``: a damped run whose stepper can ``settle`` (its rest state the fixed point of
      its own step, e.g. XPBD: :meth:`hybmss.models.xpbd_nh.XpbdStepper.settle`) stops stepping
      once its state passes the rest test (:func:`hybmss.explicit.rest.rest_report` with
      ``rest_rtol``, tested every :data:`REST_SAMPLE_S` of simulated time after the ramp and at
      the last step) and is
      moved to that fixed point, the state the rest of the run tends to (``info['rest_stop_t']``,
      ``info['settle']``); if the stepper refuses (no fixed point found, or one too far away: another
      equilibrium) or the fixed point is not at rest by the same test, the run goes on from where
      it stopped (``info['settle_refused_t']``, ``info['settle']['why']``).  No effect on other steppers or without damping.
    - ``stepper``: a stepper built for ``system`` and ``dt`` (default: the model's,
      ``scene.model.spec.stepper``, or the lattice's when it has none: :func:`hybmss.models.lattice_stepper`), e.g. with
      options of its own.

    The steps run in calls of about 0.1 s (whole check intervals; :class:`hybmss.stepper.Chunks`),
    between which SIGINT and SIGTERM stop the run with :class:`KeyboardInterrupt`; the answer does
    not depend on the calls.

    Reactions: for each plate, ``−Σ (f_int + m g)`` over its particles (prescribed components
    only; torque about its current centroid; ``f_int`` the stepper's ``internal_forces``).  At
    rest this is the force the plate exerts on the body; while the body still moves it misses the
    plate particles' own ``m a``, and the difference between plate reactions and external loads is
    the body's inertia.  ``wall_time_s`` is the time stepping alone (no set-up, dt_crit or
    post-processing; the numba kernel's first call also compiles unless it is cached);
    ``info['cpu_time_s']`` is the process CPU time of the same span (all threads), steadier than
    wall time on a busy machine.
    """
    model = scene.model.spec
    _check_options(model, kernel, precision, warm_up)
    if damping is not None:
        scene, system = _with_damping(scene, system, damping)
    dt, steps, threads = _check_run(kernel, precision, dt, steps, ramp_time, threads)
    t_setup = time.perf_counter()
    run = _prepare(scene, system, model, dt, ramp_time, check_every)
    st = _stepper(run, stepper, ramp_time=float(ramp_time), kernel=kernel, precision=precision, threads=threads)
    run.nodes = _nodes(run.system, st, x0, v0)
    x, v = initial_state(run.nodes, x0, v0, ramp_time)
    if dt_crit_value is None and compute_dt_crit:
        dt_crit_value = _critical_step(run, st)
    run.dt_c = dt_crit_value
    warm_s = _start(run, st, x, v, compile_first, warm_up)
    setup_s = time.perf_counter() - t_setup - run.dt_crit_s - warm_s
    history = _History(run.nodes, st, dt) if record_every > 0 else None
    watches = [w for w in (_residual_floor(run, st, steps, float(ramp_time), rest_rtol),
                           _rest_watch(run, st, until_rest, float(ramp_time), rest_rtol)) if w is not None]
    done, wall, cpu = _march(run, st, steps, int(record_every), history, watches)
    timing = {"cpu_time_s": cpu, "setup_s": setup_s, "warm_up_s": warm_s, "dt_crit_s": run.dt_crit_s}
    return _final(run, st, scene, done, wall, ramp_time, rest_rtol, timing, history)


@dataclass
class _Run:
    """What the time loop of one explicit run needs besides its stepper: the system, the step, the
    divergence bound and check interval, and the critical step (given, computed or None)."""

    system: System
    model: object
    dt: float
    limit: float
    limit2: float
    check_every: int
    dt_c: float | None = None
    dt_crit_s: float = 0.0
    nodes: System | None = None
    """The system on the stepper's nodes (:func:`_nodes`): ``system`` unless the stepper has its own."""


def _stepper(run: _Run, given, **kw):
    """The run's stepper: ``given``, else the model's own (``model.stepper``), else, for a model
    that has none (a variant of the spring and volume lattice), the lattice's
    (:func:`hybmss.models.lattice_stepper`)."""
    if given is not None:
        return given
    st = run.model.stepper(run.system, run.dt, **kw)
    if st is None:  # the model is a variant of the lattice
        st = registry.lattice_stepper(run.system, run.dt, **kw)
    return st


def _critical_step(run: _Run, st) -> float | None:
    """The run's ``dt_crit``: the stepper's own (an engine's), else :func:`dt_crit` of the system;
    ``None`` for a model with no explicit limit.  Its seconds go to ``run.dt_crit_s``."""
    if not run.model.explicit_limit:
        return None
    t0 = time.perf_counter()
    own = getattr(st, "dt_crit", None)  # a stepper that knows its own limit (an engine's)
    value = own() if own is not None else dt_crit(run.system)
    run.dt_crit_s = time.perf_counter() - t0
    return value


def _check_options(model, kernel: str, precision: str, warm_up: float) -> None:
    """Refuse a kernel, precision or warm-up that the run cannot have, before any work."""
    if kernel not in KERNELS:
        raise ValueError(f"kernel must be one of {', '.join(KERNELS)}; got {kernel!r}")
    if kernel not in model.kernels:
        raise ValueError(f"model {model.name} has no {kernel} kernel (its kernels: {', '.join(model.kernels)}); "
                         f"use kernel={model.kernels[0]!r}")
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)}; got {precision!r}")
    if not (warm_up >= 0 and math.isfinite(warm_up)):
        raise ValueError(f"warm_up must be >= 0 s, got {warm_up}")


def _with_damping(scene: Scene, system: System | None, damping: float):
    """The scene (and its system, if built) with the mass-proportional damping ``damping``."""
    damping = float(damping)
    if not (damping >= 0 and math.isfinite(damping)):
        raise ValueError(f"damping must be >= 0 (1/s), got {damping}")
    scene = dataclasses.replace(scene, damping=damping)
    if system is not None:
        system = dataclasses.replace(system, scene=scene)
    return scene, system


def _check_run(kernel: str, precision: str, dt, steps, ramp_time, threads) -> tuple[float, int, int]:
    """``dt``, ``steps`` and ``threads`` as numbers the loop can run, else a :class:`ValueError`."""
    if precision != "f64" and kernel == "numpy":
        raise ValueError(f"precision {precision} needs kernel='numba' (the NumPy twin runs in f64)")
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
    return dt, steps, threads


def _prepare(scene: Scene, system: System | None, model, dt: float, ramp_time: float, check_every: int) -> _Run:
    """The system of the run (built unless given; every particle must have mass) and its
    divergence bound: a displacement beyond :data:`BLOWUP_FACTOR` body sizes."""
    sys_ = system if system is not None else build(scene)
    if (sys_.mass <= 0).any():
        raise ValueError("explicit dynamics needs rho > 0 (every particle must have mass)")
    limit = BLOWUP_FACTOR * max(scene.body.size)
    return _Run(sys_, model, dt, limit, limit * limit, max(1, int(check_every)))


def _nodes(system: System, st, x0, v0) -> System:
    """The system on the stepper's nodes: its ``node_system()`` when it has one (an engine whose
    nodes are not the lattice particles, e.g. 27-node cells), else ``system``.  A start state
    ``x0``/``v0`` is given on the lattice particles: refused for a stepper with other nodes."""
    own = getattr(st, "node_system", None)
    if own is None:
        return system
    nodes = own()
    if (x0 is not None or v0 is not None) and nodes.n != system.n:
        raise ValueError(f"x0, v0: {system.scene.model.spec.name} has nodes that are not lattice particles "
                         f"({nodes.n} nodes, {system.n} particles); start from rest")
    return nodes


def particles(st, x: np.ndarray) -> np.ndarray:
    """The lattice particles' positions at the stepper's node positions ``x``: its
    ``vertices(x)`` when it has nodes of its own, else ``x``."""
    own = getattr(st, "vertices", None)
    return x if own is None else own(x)


def _start(run: _Run, st, x, v, compile_first: bool, warm_up: float) -> float:
    """Load the initial state into ``st``; compile its kernel outside the timed span (a 0-step
    call) when ``compile_first``; then ``warm_up`` seconds of untimed steps (:func:`_warm_up`),
    whose seconds it returns."""
    st.load(x, v)
    if compile_first:  # compile (or load from the cache) outside the timed span: a 0-step call
        st.advance(0, 0, run.check_every, run.limit2)
    return _warm_up(st, x, v, warm_up, run.limit2) if warm_up > 0.0 else 0.0


def _warm_up(st, x, v, seconds: float, limit2: float) -> float:
    """Untimed steps for ``seconds`` from the initial state, which is then loaded again; the
    seconds it took."""
    t_warm, k = time.perf_counter(), 0
    with interruptible():
        while time.perf_counter() - t_warm < seconds:
            interruptible.check()
            done, bad = st.advance(k, WARM_UP_STEPS, WARM_UP_STEPS, limit2)
            k += done
            if bad >= 0 or done < WARM_UP_STEPS:
                break
    st.load(x, v)
    return time.perf_counter() - t_warm


class _History:
    """``info['history']``: t, the largest displacement and the stepper's energies at chosen steps."""

    def __init__(self, system: System, st, dt: float):
        self.system, self.st, self.dt = system, st, dt
        self.data = {"t": [], "max_displacement": []}
        self.record(0)

    def record(self, step: int) -> None:
        xs, vs = self.st.state()
        e = self.st.energy(xs, vs)
        self.data["t"].append(step * self.dt)
        self.data["max_displacement"].append(float(np.linalg.norm(xs - self.system.X, axis=1).max()))
        for k, val in e.items():
            self.data.setdefault(k, []).append(val)


def _residual_floor(run: _Run, st, steps: int, ramp_time: float, rtol: float) -> "_FloorWatch | None":
    """The watch of :class:`hybmss.explicit.rest.ResidualFloor` for a stepper whose rest state may
    keep a force residual (``rest_floor``, e.g. XPBD) in a damped run long enough for a verdict;
    ``None`` otherwise."""
    c = float(run.system.scene.damping)
    if not getattr(st, "rest_floor", False) or c <= 0.0:
        return None
    watch = _FloorWatch(c, float(ramp_time), rtol, steps * run.dt, run.dt, run.check_every)
    return watch if watch.floor.active else None


def _rest_watch(run: _Run, st, until_rest: bool, ramp_time: float, rtol: float) -> "_RestWatch | None":
    """The watch that finishes a damped run at rest (``until_rest``) for a stepper that can
    ``settle``; ``None`` otherwise."""
    if not until_rest or float(run.system.scene.damping) <= 0.0 or not hasattr(st, "settle"):
        return None
    return _RestWatch(ramp_time, rtol, run.dt, run.check_every)


class _RestWatch:
    """Tests the state by the rest verdict (:func:`hybmss.explicit.rest.stepper_rest`) every
    ``every`` steps once the ramp is complete; at the first pass the stepper settles to the fixed
    point of its step, and the run stops if that state passes the same test (otherwise the state
    before is loaded again, the watch turns off and the run goes on).  The interval is
    :data:`REST_SAMPLE_S` of simulated time, whatever the tests cost: an interval that grew with
    their wall-clock cost made the stopping step, and so the answer, depend on the machine's load
    (the same xpbd-nh run stopped after 6,500 steps in one reproduction and after 8,000 in another,
    its forces 1e-7 apart).

    The last step of the budget is tested whether or not the interval divides it: a run that
    ends at rest ends at its fixed point.  Without that test, whether the last state was settled
    depended on the interval: the 10³ cube sheared 20 % at ν = 0.499 (xpbd-nh, 2 substeps, at
    rest by t = 10 s) ended with a plate force of 185.24 N unsettled in one reproduction and
    185.49 N settled in the next."""

    def __init__(self, T: float, rtol: float, dt: float, check_every: int):
        self.T, self.rtol = T, rtol
        self.every = max(check_every, int(round(REST_SAMPLE_S / dt)) // check_every * check_every)
        self.off = False

    def next_stop(self, done: int) -> int:
        return (done // self.every + 1) * self.every

    def _rest(self, run: _Run, st, s: float) -> tuple[bool, np.ndarray, np.ndarray]:
        xs, vs = st.state()
        rest = stepper_rest(run.nodes, st, st.internal_forces(xs), st.energy(xs, vs), s, self.rtol, xs)
        return bool(rest["at_rest"]), xs, vs

    def stop(self, run: _Run, st, done: int) -> bool:
        t = done * run.dt
        s = ramp(t, self.T)
        if s < 1.0:
            return False
        at_rest, xs, vs = self._rest(run, st, s)
        if not at_rest:
            return False
        self.off = True  # one settling per run, whatever it gives
        settled = st.settle()  # the stepper's state is its fixed point unless it refused
        if not settled["refused"]:
            if self._rest(run, st, s)[0]:
                st.info.update(rest_stop_t=t, settle=settled)
                return True
            st.load(xs, vs)
            settled = dict(settled, refused=True, why="its fixed point is not at rest")
        st.info.update(settle_refused_t=t, settle=settled)
        return False


class _FloorWatch:
    """A :class:`ResidualFloor` of damping ``c`` sampled every ``every`` steps (a multiple of the
    check interval).  Its windows first assume every mode underdamped (``σ = c/2``); the first
    time that predicts a floor, the stepper's lowest frequency decides (an eigen solve, paid only
    by a run about to stop): if the slowest mode is overdamped, the watch starts again with its
    slower rate, otherwise the run stops.  Its samples are taken on this cadence of simulated time
    whatever they cost, so that where a run stops does not depend on the machine's load."""

    def __init__(self, c: float, T: float, rtol: float, t_end: float, dt: float, check_every: int):
        self.c, self.T, self.rtol, self.t_end, self.dt, self.check = c, T, rtol, t_end, dt, check_every
        self.confirmed, self.off = False, False
        self._start(0.5 * c)

    def _start(self, sigma: float) -> None:
        self.floor = ResidualFloor(self.T, sigma, self.rtol, self.t_end)
        per = int(round(self.floor.sample_times() / self.dt)) // self.check * self.check
        self.every = max(self.check, per)

    def next_stop(self, done: int) -> int:
        return (done // self.every + 1) * self.every

    def stop(self, run: _Run, st, done: int) -> bool:
        """Sample the residual after ``done`` steps; True when the run is to stop."""
        t = done * run.dt
        if t < self.floor.T:
            return False
        xs, _ = st.state()
        f = st.internal_forces(xs)
        rel = free_residual(run.nodes, f) / force_scale(run.nodes, f, xs)
        if not self.floor.update(t, rel):
            return False
        if not self.confirmed:
            self.confirmed = True
            sigma = decay_rate(self.c, st.lowest_frequency())
            if sigma < 0.5 * self.c:  # an overdamped slowest mode: longer windows, from now on
                self._start(sigma)
                self.floor.T = max(self.floor.T, t)
                return False
        st.info.update(floor_stop_t=t, floor_window_s=self.floor.window, floor_bound=self.floor.bound)
        return True


def _march(run: _Run, st, steps: int, record_every: int, history: _History | None,
           watches: list | None = None) -> tuple[int, float, float]:
    """Advance ``st`` by ``steps`` steps in calls of about 0.1 s (:class:`hybmss.stepper.Chunks`),
    stopping at SIGINT/SIGTERM between calls, recording every ``record_every`` steps; a diverged
    state raises :class:`DivergenceError`.  Returns the steps done (fewer when the stepper stops
    by its own rule, or when a watch stops the run: :class:`_FloorWatch`, a force residual the rest
    test cannot pass within the budget; :class:`_RestWatch`, a state at rest settled to its fixed
    point), and the wall and CPU seconds of the calls.  A watch that turned itself off is dropped."""
    span = record_every if record_every > 0 else max(steps, 1)
    wall = cpu = 0.0
    done, stopped = 0, False
    chunks = Chunks(run.check_every)
    watches = list(watches or ())
    with interruptible():
        while done < steps and not stopped:
            end = min(done + span, steps)  # a span: up to the next record; checks counted from its start
            while done < end:
                interruptible.check()
                n = chunks.next(end - done)
                watches = [w for w in watches if not w.off]
                for w in watches:
                    n = min(n, w.next_stop(done) - done)
                (k, bad), w_s, c = timed(st.advance, done, n, run.check_every, run.limit2)
                chunks.took(n, w_s)
                wall += w_s
                cpu += c
                if bad >= 0:
                    xs, _ = st.state()
                    raise divergence_error(run.system, particles(st, xs), min(bad, run.system.n - 1), done + k, run.dt,
                                      run.limit, run.dt_c, run.check_every, run.model)
                done += k
                if k < n:  # the stepper stopped by its own rule
                    stopped = True
                    break
                if any(done % w.every == 0 and w.stop(run, st, done) for w in watches):
                    stopped = True
                    break
            if history is not None:
                history.record(done)
        if not stopped and done == steps:
            for w in watches:
                if not w.off and isinstance(w, _RestWatch) and done % w.every != 0:
                    w.stop(run, st, done)  # the last state is tested too (see _RestWatch)
    return done, wall, cpu


def _final(run: _Run, st, scene: Scene, done: int, wall: float, ramp_time: float, rest_rtol: float,
           timing: dict, history: _History | None) -> Result:
    """The final state's energies, forces, rest verdict and ``info`` (the stepper's, the run's
    protocol and ``timing``), then its :class:`Result` (:func:`_result`)."""
    t_post = time.perf_counter()
    xs, vs = st.state()
    energy = st.energy(xs, vs)
    f_int = st.internal_forces(xs)
    s_end = ramp(done * run.dt, ramp_time)
    rest = stepper_rest(run.nodes, st, f_int, energy, s_end, rest_rtol, xs)
    info = dict(st.info)
    info.update(_run_info(run, done, ramp_time, s_end, rest))
    info.update(timing)
    return _result(run, st, scene, xs, vs, f_int, energy, info, history, done, wall, t_post)


def _run_info(run: _Run, done: int, ramp_time: float, s_end: float, rest: dict) -> dict:
    """The protocol of the run in ``info``: model, rest verdict, step, damping and ramp."""
    return {
        "model": run.model.name,
        "rest": rest,
        "dt": run.dt,
        "steps": done,
        "t_end": done * run.dt,
        "dt_crit": None if run.dt_c is None else float(run.dt_c),
        "damping": float(run.system.scene.damping),
        "damping_scheme": "mass-proportional -c m v, implicit: v = (v + dt a) / (1 + c dt)",
        "ramp_time": float(ramp_time),
        "ramp_law": RAMP_LAW,
        "load_factor": s_end,
    }


def _result(run: _Run, st, scene: Scene, xs, vs, f_int, energy: dict, info: dict, history: _History | None,
            done: int, wall: float, t_post: float) -> Result:
    """The :class:`Result` of the final state: displacements, cell volumes, plate reactions from
    the stepper's own forces, ``converged`` = at rest."""
    sys_ = run.system
    lat = sys_.lattice
    xp = particles(st, xs)
    vols = lat.cell_volumes(xp)
    volume, V0 = float(vols.sum()), float(lat.cell_volumes(sys_.X).sum())
    reactions = plate_reactions(run.nodes, xs, f_int)
    readout = getattr(st, "readout", None)  # the stepper's own figures of the state (an engine's)
    own = readout(xs, vs, f_int, reactions, info["rest"]) if readout is not None else {}
    if "volume" in own:  # its own volume of the deformed body (e.g. an engine's elements)
        info["volume_cells"] = volume
        volume, V0 = float(own.pop("volume")), float(own.pop("volume0"))
    info.update(own)
    info.update({
        "postprocess_s": time.perf_counter() - t_post,
        "max_speed": float(np.linalg.norm(vs, axis=1).max()) if len(vs) else 0.0,
        "inverted_cells": int(np.count_nonzero(vols <= 0.0)),
        "kappa": float(sys_.kappa),
    })
    if history is not None:
        info["history"] = history.data
    return Result(
        solver=getattr(st, "solver", SOLVER),
        scene_digest=scene.digest(),
        X=sys_.X.copy(),
        u=xp - sys_.X,
        volume=volume,
        volume0=V0,
        reactions=reactions,
        energy=energy,
        iterations=done,
        wall_time_s=wall,
        converged=bool(info["rest"]["at_rest"]),
        cell_volumes=vols,
        info=info,
    )
