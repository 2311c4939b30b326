"""The stepper protocol: what a model gives the one explicit time loop, and how that loop is cut.

:func:`hybmss.explicit.simulate_explicit` owns everything an explicit run does around the
arithmetic of a step: the plates' ramp and their reactions, damping's parameter, the divergence
and rest checks, the history, the timing and the :class:`~hybmss.result.Result`.  A model
supplies the arithmetic through ``model.stepper(system, dt, *, ramp_time, kernel, precision,
threads)`` (:class:`hybmss.models.base.ModelBase`; the default is the harness's spring and volume
lattice, :class:`hybmss.models.hybmss.stepper.LatticeStepper`).  It returns an object with

- ``load(x, v)``: set the state from positions and (half-step) velocities (n, 3), float64; the
  plates' prescribed components already hold their values at the start of the run;
- ``advance(step0, n, check_every, limit2) -> (steps_done, bad)``: run ``n`` steps of ``dt``
  from the global step ``step0`` (the plates at the load factor ``s((step0 + k) dt)`` of
  :func:`hybmss.explicit.ramp`, damping ``1/(1 + c dt)`` of the scene's ``c``), checking every
  ``check_every`` steps counted from this call's first step, and at its last, that no particle
  is non-finite or moved more than ``√limit2``; ``bad`` is such a particle (an index of
  ``system.X``) or −1.  The answer must depend on the step index only, not on how the steps are
  split into calls: the loop cuts a run into calls of about :data:`CHUNK_SECONDS` (whole check
  intervals) to stay interruptible.  A stepper that stops early by its own rule returns
  ``steps_done < n`` with ``bad = −1`` and the loop ends there;
- ``state() -> (x, v)``: the current positions and velocities (n, 3), float64 copies;
- ``internal_forces(x) -> (n, 3)``: the force its own law puts on the particles at ``x``, without
  gravity (plate reactions and the rest test of :func:`hybmss.explicit.rest_report`);
- ``energy(x, v) -> dict``: ``'kinetic'`` ``½ Σ m |v|²`` and its potential parts (``'springs'``,
  ``'volume'``, ``'strain'``, ...);
- ``info``: a dict of what the run reports about the stepper (``kernel``, ``precision``,
  ``threads``, and its own parameters); a ``solver`` attribute names the result's solver.

Optional, for a stepper whose state is not the lattice's (an engine's: :mod:`hybmss.models._engine_body`):

- ``node_system() -> System``: the system on its own nodes (positions, masses, prescribed
  components, plates): the loop's initial state, plate reactions, rest test, history and
  divergence checks use it (``x0``/``v0`` on other nodes than the particles are refused);
- ``vertices(x) -> (n, 3)``: the lattice particles' positions at node positions ``x`` (the
  result's displacements and cell volumes);
- ``dt_crit() -> float``: its own stability limit (``info['dt_crit']``), from its own forces;
- ``force_resolution_N``: the force its state resolves (a float32 engine): the rest test's
  tolerance is at least that over the force scale (:func:`hybmss.explicit.stepper_rest`);
- ``readout(x, v, f, reactions, rest) -> dict``: figures of its own for ``info`` (e.g. the
  balance of the reactions), with ``volume``/``volume0`` replacing the averaged-edge cell volume
  (kept as ``info['volume_cells']``).

A model with its own dynamics (a position-based integrator, an external engine) plugs in here and
gets the harness's checks for free; ``converged`` of every explicit run means at rest by
:func:`hybmss.explicit.rest_report`.

Interrupts.  A Numba kernel does not return to Python until it is done, so Python's handling of
Ctrl-C waits for it.  The loop runs in calls of about :data:`CHUNK_SECONDS` (:class:`Chunks`) inside
:class:`interruptible`, which turns SIGINT and SIGTERM into a flag checked between calls:
either stops a run with :class:`KeyboardInterrupt` within a call's time.
"""

from __future__ import annotations

import signal
import threading
import time

import numpy as np

CHUNK_SECONDS = 0.1
"""Work per kernel call of a long run (s): the longest a signal waits for the loop to see it."""


class Chunks:
    """Sizes of the calls of a span of steps: whole multiples of ``align`` steps (counted from the
    span's start) of about ``seconds`` of work each, from the time the previous calls took.  The
    first call is one ``align``; each next one grows at most ``GROWTH`` times."""

    GROWTH = 8

    def __init__(self, align: int, seconds: float | None = None):
        self.align = max(1, int(align))
        self.seconds = float(CHUNK_SECONDS if seconds is None else seconds)
        self.n = self.align

    def next(self, remaining: int) -> int:
        """Steps of the next call with ``remaining`` steps left in the span."""
        return min(self.n, remaining)

    def took(self, n: int, seconds: float) -> None:
        """Record that a call of ``n`` steps took ``seconds``."""
        if n <= 0:
            return
        want = self.GROWTH * n if seconds <= 0.0 else int(self.seconds * n / seconds)
        want = min(want, self.GROWTH * max(n, self.n))
        self.n = max(self.align, want // self.align * self.align)


class interruptible:
    """Context in which SIGINT and SIGTERM set a flag (main thread only; a signal a process
    ignores stays ignored, another handler is called after the flag is seen): :meth:`check`
    raises :class:`KeyboardInterrupt` once one arrived.  Nested contexts share the outer one."""

    _active = 0
    _got: int | None = None
    _previous: dict = {}

    def __enter__(self) -> "interruptible":
        cls = interruptible
        if cls._active == 0 and threading.current_thread() is threading.main_thread():
            cls._got, cls._previous = None, {}
            for sig in (signal.SIGINT, signal.SIGTERM):
                old = signal.getsignal(sig)
                if old in (signal.SIG_IGN, None):
                    continue
                cls._previous[sig] = old
                signal.signal(sig, _flag)
        cls._active += 1
        return self

    def __exit__(self, *exc) -> None:
        cls = interruptible
        cls._active -= 1
        if cls._active == 0:
            previous, cls._previous = cls._previous, {}
            for sig, old in previous.items():
                signal.signal(sig, old)
            got, cls._got = cls._got, None
            if got is not None and exc[0] is None:
                _raise(got, previous)

    @staticmethod
    def check() -> None:
        """Raise :class:`KeyboardInterrupt` (or call the handler in place before) if a signal came."""
        got = interruptible._got
        if got is not None:
            interruptible._got = None
            _raise(got, interruptible._previous)


def _flag(signum, frame) -> None:
    interruptible._got = signum


def _raise(signum: int, previous: dict) -> None:
    old = previous.get(signum, signal.SIG_DFL)
    if callable(old) and old is not signal.default_int_handler:
        old(signum, None)
    raise KeyboardInterrupt(f"stopped by signal {signal.Signals(signum).name}")


class ParticleStepper:
    """Base of the stepper of a model's own force ``term`` (with ``forces(x)``, ``energy(x)`` and a
    ``name``) on the lattice's particles: its state in the layout of
    :func:`hybmss._kernels.kernel_state` for a Numba kernel (float64 positions or float32
    displacements) and as (n, 3) arrays for the NumPy twin; ``internal_forces`` and ``energy`` the
    term's (its NumPy twin), plus the kinetic energy.  A subclass writes ``advance``."""

    def __init__(self, system, term, dt: float, *, ramp_time: float, kernel: str = "numba",
                 precision: str = "f64", threads: int = 1, kernels: tuple[str, ...] = ("numba", "numpy")):
        if kernel not in kernels:
            raise ValueError(f"kernel must be one of {', '.join(kernels)}; got {kernel!r}")
        if precision != "f64" and kernel != "numba":
            raise ValueError(f"precision {precision} needs kernel='numba' (the NumPy twin runs in f64)")
        one_thread(threads, term.name)
        self.system, self.term, self.kernel, self.precision = system, term, kernel, precision
        self.dt, self.ramp_time = float(dt), float(ramp_time)
        self.solver = f"{term.name}-explicit"
        self.info = {"kernel": kernel, "threads": 1, "precision": precision}

    def load(self, x, v):
        if self.kernel == "numba":
            from ._kernels import kernel_state

            self._W, self._xg, self._vg, self._posmode = kernel_state(x, v, self.system.X, self.precision)
        else:
            self._x, self._v = np.array(x, dtype=float), np.array(v, dtype=float)

    def state(self):
        if self.kernel == "numba":
            from ._kernels import read_state

            return read_state(self._xg, self._vg, self.system.X, self._posmode)
        return self._x.copy(), self._v.copy()

    def internal_forces(self, x):
        """Every force but gravity, as :func:`hybmss.forces.internal_forces` for the lattice: the
        term's and the dead loads (surface loads, applied whole in an explicit run)."""
        return with_dead_loads(self.system, self.term.forces(x))

    def energy(self, x, v):
        return {"strain": self.term.energy(x), "kinetic": float(0.5 * np.sum(self.system.mass[:, None] * v * v))}


def with_dead_loads(system, f: np.ndarray, load: float = 1.0) -> np.ndarray:
    """``f`` plus ``load`` times the system's dead loads (:class:`hybmss.terms.DeadLoad`), ``f``
    itself without any."""
    from .terms import DeadLoad

    loads = [t.f for t in system.terms if isinstance(t, DeadLoad)]
    if not loads:
        return f
    return f + load * sum(loads)


def one_thread(threads, model: str) -> None:
    """A stepper whose kernel is serial refuses ``threads`` other than 1 with a
    :class:`ValueError` (rather than a run on one thread reported as two)."""
    if int(threads) != 1:
        raise ValueError(f"threads must be 1 for {model} (its kernel is serial), got {threads}")


def timed(fn, *args):
    """``(fn(*args), wall seconds, CPU seconds)``."""
    c0, t0 = time.process_time(), time.perf_counter()
    out = fn(*args)
    return out, time.perf_counter() - t0, time.process_time() - c0
