"""A model's released transient: its own static equilibrium under the load, released at t = 0 and
stepped by its own integrator.

Equations of motion of the model's nodes, the load (gravity, surface tractions) removed and the
plates held::

    m_a ẍ_a = f_a(x) − c m_a ẋ_a,     x(0) = x_s,  ẋ(0) = 0,

``x_s`` the model's static answer under the load (:func:`hybmss.solve.solve_static`: Newton for
the lattice models, the rest state of the engine's damped run for an engine), ``f`` the model's
own forces and ``c`` the mass-proportional damping of the released run: the model's own, zero
unless given (not the damping the harness uses to bring an explicit run to rest).  The steps are
the model's stepper (:mod:`hybmss.stepper`): semi-implicit Euler of the spring and volume lattice
(:class:`hybmss.explicit.LatticeStepper`), the model's own (corotational hexahedra, XPBD) or the
engine's step (MuJoCo, Newton, PBD), each at the step ``dt`` it is given; the displacement of the
lattice particle nearest a named point is read every ``record_every`` steps.  The wall time is that
of the stepping alone; a fast run is stepped again from the release in one call, unrecorded
(:data:`RETIME_BELOW_S`), so that its cost is not that of the recording.

:func:`user_step` is the step a user would pick: a fraction :data:`USER_CFL` of the model's
stability limit for the harness's models; a real-time frame :data:`FRAME` = 1/60 s cut into the
fewest equal substeps within that fraction of the limit for an engine (stable at any step: the
frame cut into :data:`UNLIMITED_SUBSTEPS`: XPBD, MuJoCo's ``discrete``).  A model named without
parameters runs with those its engine's user picks for dynamics (:func:`released_model`).
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from .explicit import BLOWUP_FACTOR, dt_crit, initial_state, particles
from .models.hybmss.stepper import LatticeStepper
from .scene import Model, Scene
from .system import build
from .trajectory import Trajectory

USER_CFL = 0.9
"""Step of a model's explicit run as a fraction of its stability limit ``dt_crit`` (the fraction the
harness's engine runs use)."""
FRAME = 1.0 / 60.0
"""A real-time frame (s): an engine's step is this frame cut into substeps."""
UNLIMITED_SUBSTEPS = 10
"""Substeps of a frame for a scheme with no stability limit (XPBD: only accuracy bounds the step)."""
RETIME_BELOW_S = 10.0
"""A run whose recorded stepping took less than this is run again from the release in one call,
unrecorded, for its wall time (the recording's many short calls would dominate a fast model's)."""


def released_model(model) -> Model:
    """The model of a released transient: a :class:`hybmss.scene.Model` as given, a name with the
    parameters its engine's user picks for dynamics (the model's ``released_parameters``: MuJoCo's
    ``discrete`` integrator), else its defaults."""
    if isinstance(model, Model):
        return model
    spec = Model(str(model)).spec
    return Model(str(model), **dict(getattr(spec, "released_parameters", {})))


def with_model(scene: Scene, model) -> Scene:
    """``scene`` with ``model`` (a name or a :class:`hybmss.scene.Model`)."""
    return dataclasses.replace(scene, model=model if isinstance(model, Model) else Model(str(model)))


def released_scene(scene: Scene, damping: float = 0.0) -> Scene:
    """The scene after the release: no gravity, no surface load, the plates as they are, the
    mass-proportional damping ``damping`` (1/s)."""
    return dataclasses.replace(scene, gravity=(0.0, 0.0, 0.0), loads=(), damping=float(damping))


def _stepper(system, dt: float, kernel: str | None, precision: str | None):
    spec = system.scene.model.spec
    kernel = kernel or spec.kernels[0]
    precision = precision or getattr(spec, "precisions", ("f64",))[0]
    st = spec.stepper(system, dt, ramp_time=0.0, kernel=kernel, precision=precision, threads=1)
    return st if st is not None else LatticeStepper(system, dt, ramp_time=0.0, kernel=kernel, precision=precision)


def user_step(scene: Scene, engine: bool | None = None) -> tuple[float, int]:
    """``(dt, substeps)``: the step a user would pick for ``scene``'s model (module docstring);
    ``substeps`` is the number of steps per :data:`FRAME` (1 for the harness's models)."""
    spec = scene.model.spec
    engine = spec.kernels == ("engine",) if engine is None else engine
    system = build(released_scene(scene))
    limit = None
    if spec.explicit_limit:
        st = _stepper(system, 1e-6, None, None) if engine else None
        own = getattr(st, "dt_crit", None)
        limit = own() if own is not None else dt_crit(system)
        limit = None if math.isinf(limit) else limit  # an integrator stable at any step
    if not engine:
        if limit is None:
            return FRAME / UNLIMITED_SUBSTEPS, 1
        return USER_CFL * limit, 1
    n = UNLIMITED_SUBSTEPS if limit is None else max(1, math.ceil(FRAME / (USER_CFL * limit)))
    return FRAME / n, n


def static_state(scene: Scene) -> np.ndarray:
    """The model's static answer under ``scene``'s load: positions of the lattice particles (n, 3)."""
    from .solve import solve_static

    r = solve_static(scene)
    if not r.converged:
        raise RuntimeError(f"{scene.model.name}: the static state under the load did not converge")
    return r.X + r.u


def released_transient(scene: Scene, model, dt: float, t_end: float, point, *, record_every: int = 1,
                       damping: float = 0.0, kernel: str | None = None, precision: str | None = None,
                       start: np.ndarray | None = None) -> Trajectory:
    """The released transient of ``scene`` with ``model`` (module docstring), stepped with ``dt``
    up to ``t_end``; the displacement of the lattice particle nearest ``point`` at t = 0 and every
    ``record_every`` steps.  ``start``: the particles' positions at the release (default: the
    model's static state under the load, :func:`static_state`).  A run that diverges keeps its
    samples with ``status='diverged'`` and the reason."""
    dt, t_end = float(dt), float(t_end)
    if not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"dt must be > 0 s, got {dt}")
    if not (t_end >= dt and math.isfinite(t_end)):
        raise ValueError(f"t_end must be >= dt = {dt:g} s, got {t_end}")
    loaded = with_model(scene, released_model(model))
    if not loaded.has_gravity and not loaded.loads and start is None:
        raise ValueError("the scene has no load (gravity or surface load) to release")
    system = build(released_scene(loaded, damping))
    st = _stepper(system, dt, kernel, precision)
    nodes = st.node_system() if hasattr(st, "node_system") else system
    if nodes.n != system.n:
        raise ValueError(f"model {loaded.model.name}: its nodes are not the lattice particles ({nodes.n} nodes, "
                         f"{system.n} particles); a released state on its own nodes is not available")
    x_s = static_state(loaded) if start is None else np.asarray(start, dtype=float)
    x, v = initial_state(nodes, x_s, None, 0.0)
    st.load(x, v)
    if hasattr(st, "advance"):
        st.advance(0, 0, 1, math.inf)  # compile (or load the cached kernel) before the timed span
    k = int(np.argmin(np.linalg.norm(system.X - np.asarray(point, dtype=float), axis=1)))
    steps = int(round(t_end / dt))
    tr = _march(st, system, loaded, k, dt, steps, max(1, int(record_every)))
    if tr.ok and tr.wall_time_s < RETIME_BELOW_S:  # the cost without the recording's calls
        st.load(x, v)
        t0 = time.perf_counter()
        st.advance(0, steps, 10, math.inf)
        wall = time.perf_counter() - t0
        tr.info.update(wall_recorded_s=tr.wall_time_s, timed="one call of every step, no recording")
        tr = dataclasses.replace(tr, wall_time_s=wall)
    return tr


def integrator(st) -> str:
    """The stepper's scheme: the engine's own name for it, else the harness's."""
    describe = getattr(st, "describe", None)
    if describe is not None and "integrator" in describe():
        return str(describe()["integrator"])
    name = type(st).__name__
    return {"LatticeStepper": "semi-implicit Euler (lattice)", "CorotStepper": "semi-implicit Euler (corot-hex8)",
            "XpbdStepper": "XPBD (xpbd-nh)"}.get(name, name)


def _energy(st, x, v) -> float:
    e = st.energy(x, v)
    kinetic = e.get("kinetic_centred", e.get("kinetic", 0.0))
    return float(kinetic + sum(val for key, val in e.items() if not key.startswith("kinetic")))


def _march(st, system, scene: Scene, k: int, dt: float, steps: int, every: int) -> Trajectory:
    """Step ``st`` ``steps`` times, recording particle ``k`` every ``every`` steps."""
    X = system.X
    limit = BLOWUP_FACTOR * max(scene.body.size)
    check = min(every, 10)
    x, v = st.state()
    ts, us, es = [0.0], [particles(st, x)[k] - X[k]], [_energy(st, x, v)]
    wall, done, status, reason = 0.0, 0, "ok", ""
    while done < steps:
        n = min(every, steps - done)
        t0 = time.perf_counter()
        got, bad = st.advance(done, n, check, limit * limit)
        wall += time.perf_counter() - t0
        done += got
        x, v = st.state()
        if bad >= 0 or not np.all(np.isfinite(x)):
            status = "diverged"
            reason = (f"node {max(bad, 0)} non-finite or beyond {BLOWUP_FACTOR:g} body sizes by t = {done * dt:.4g} s "
                      f"(step {dt:.3g} s)")
            break
        ts.append(done * dt)
        us.append(particles(st, x)[k] - X[k])
        es.append(_energy(st, x, v))
        if got < n:
            status, reason = "failed", f"the stepper stopped at step {done}"
            break
    info = {"model": scene.model.name, "kernel": st.info.get("kernel"), "precision": st.info.get("precision"),
            "steps": done, "integrator": integrator(st),
            "damping": float(system.scene.damping)}
    return Trajectory(f"{scene.model.name}-released", np.array(ts), np.array(us),
                      tuple(float(c) for c in X[k]), dt, wall, np.array(es), status, reason, info)
