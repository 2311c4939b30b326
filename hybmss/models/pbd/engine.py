"""A scene as a PositionBasedDynamics simulation model (``pypbd`` ≥ 2.2), stepped by the
library's ``TimeStepController`` with its XPBD FEM tetrahedron constraints.

Imported only when a ``pbd-*`` model runs.  The bindings keep one current ``Simulation`` (a
singleton of the library: its gravity, its time step controller and the ``TimeManager``'s step
that the XPBD constraints read); each body owns its ``SimulationModel`` and makes it the current
one, with its step, before it steps.

Scene translation
-----------------
- **Nodes**: one PBD particle per lattice particle (``SimulationModel.addTetModel``), mass the
  lumped ``ρ Vc/8`` per cell corner (``ParticleData.setMass``), divided by the engine's mass unit
  :attr:`PbdBody.mass_unit` (below).
- **Mesh**: the library's own split of a grid cell, the one ``SimulationModel::addRegularTetModel``
  makes (:data:`SPLIT_ODD` / :data:`SPLIT_EVEN`: 5 tetrahedra, the central one alternating with
  the parity of ``i + j + k`` so that neighbouring cells' faces match), each oriented to a
  positive volume (the constraint switches to its inversion handling below 20 % of the rest
  volume, measured with that orientation).
- **Plates**: a node whose three components a plate prescribes is a kinematic particle (mass 0),
  set to its target at the new time before every step (``ParticleData.setPosition``); a node with
  some components prescribed (a sliding plate) keeps its mass, and after every step its prescribed
  components are set to their targets and their velocities to the target's change over the step
  (the projection of a position-based step onto the plate).
- **Gravity and damping**: the bindings expose no setter for the simulation's gravity (it stays
  the library's default ``(0, −9.81, 0)``).  Before every step each free node's velocity becomes
  ``v/(1 + c h) + h (g − g_pbd)``: the scene's mass-proportional damping c, and the scene's
  gravity g in place of the library's g_pbd, which its semi-implicit Euler step adds back.
- **Steps**: one substep and one constraint iteration per ``TimeStepController.step`` (XPBD's
  multipliers restart each step); the harness's step is the library's time step.
- **Length unit**: ``PositionBasedDynamics::init_FEMTetraConstraint`` adds no constraint for a
  tetrahedron below 1e-6 in volume (in the engine's units): the engine runs in the cell size as its
  length unit (or less: :func:`length_unit`), so that a body of millimetre cells is not one without
  stiffness (measured: in metres a cylinder at 4 mm cells did not deform under a 10 % squeeze).
- **Mass unit**: ``XPBD::solve_FEMTetraConstraint`` skips a tetrahedron when
  ``Σ w_i |∇U'_i|² + C² α < 1e-6`` (an absolute threshold in the engine's units; ``C² α =
  2 U'/(E h²)``): in SI units at strain 1e-4 (E = 1e4 Pa, 0.5 m cells, h = 1e-3 s) every
  tetrahedron is skipped and the body does not deform (measured).  Both terms scale with the mass
  unit (``w`` as 1/M, E as 1/M), the motion not at all, so the engine runs in a mass unit
  :attr:`PbdBody.mass_unit` that puts the threshold at a strain below 1e-10.

- **Units**: the engine runs in its own length unit and mass unit (above) and a time unit of
  :data:`TIME_UNIT_STEPS` steps (E enters as ``E L τ²/M``, velocities as ``v τ/L``; XPBD's
  compliance ``1/(E h²)`` and so its answer do not depend on τ): the library's own gravity,
  9.81 engine units, is then ``9.81 L/τ²`` in the scene (4e-5 g at h = 1e-6 s, L = 4 mm), compensated all the same.
- **Rest runs**: the per-node kicks cost four times the library's step (the bindings set one
  velocity per call), so a run for a rest state only (the static answer) of a scene without
  gravity applies them every :data:`REST_SYNC_STEPS` steps (:meth:`PbdBody.for_rest`),
  compounded: ``v (1 + c h)^-m`` and half the compensation of the library's gravity before a group
  of m steps, the other half after it, a group ending with every call of the loop, so that where
  the loop looks the velocities have had every step's impulse (within a call, a group's second
  half and the next group's first are one pass over the nodes: the same operations in the same
  order, half the binding calls).  The library's gravity moves a
  node off its path by less than ``9.81 L (m h / τ)²``, 2.5e-11 L; the compounded damping changes
  the path while the body moves (1.5 % of the displacement on a 2×2×2 cube during its ramp), not
  the rest state (6e-8 of the displacement, tests/verification/test_engine_pbd.py).  With the scene's gravity every step has its kicks (its
  offset would be ``|g| (m h)²``, 0.25 m on a soft 1 m cube).  Measured: the 4 mm cylinder twisted
  by 30° at ν = 0.49 at rest in 10 s instead of 35 (29,106 steps, at the fixed wait of
  SETTLE), its reactions equal to 9 digits.

Readouts: the library exposes no force (its XPBD constraints' multipliers are not bound).  The
force of a tetrahedron's constraint, at XPBD's fixed point ``C + α̃ λ = 0`` (α̃ = 1/(E h²)),
is ``λ ∇C / h² = −E C ∇C = −E ∇U'``, the gradient of the library's energy ``E U'``:
:func:`svk_forces` evaluates it with the library's own formulas
(``PositionBasedDynamics::computeGreenStrainAndPiolaStress``, ``computeGradCGreen``), checked
against one projection of the engine (tests/verification/test_engine_pbd.py).
"""

from __future__ import annotations

import functools
import importlib.metadata
import time

import numpy as np

import pypbd

from ...explicit import ramp
from ...system import System
from .._engine_body import EngineBody, tet_volumes

ENGINE = "pypbd"
VERSION = f"pypbd {importlib.metadata.version('pypbd')}"


@functools.lru_cache(maxsize=1)
def openmp_runtime():
    """The OpenMP runtime the library's wheel ships beside it (``pypbd.libs/libgomp-*.so*``, a
    ``ctypes.CDLL``; the library's constraint projection is an OpenMP loop that otherwise takes
    every core), ``None`` when there is none to find."""
    import ctypes
    import glob
    import os

    libs = glob.glob(os.path.join(os.path.dirname(pypbd.__file__), "pypbd.libs", "libgomp*.so*"))
    return ctypes.CDLL(libs[0]) if libs else None


def one_thread() -> None:
    """Step the library on the calling thread alone (the model's ``threads`` 1): its OpenMP loop
    on two cores of a 2-core machine took 2.2× the CPU of one thread and 1.15× its wall time
    (measured on the 2 mm cylinder's twist at ν = 0.3, 16,632 steps; the states equal bit for bit),
    and in a pool of one run per core it takes the other run's core."""
    lib = openmp_runtime()
    if lib is not None:
        lib.omp_set_num_threads(1)
G_PBD = np.array([0.0, -9.81, 0.0])
"""The library's gravity (``Simulation::m_gravitation``), not settable through the bindings."""
TIME_UNIT_STEPS = 1e7
"""The engine's time unit in steps (module docstring, **Units**)."""
REST_SYNC_STEPS = 16
"""Steps between the damping and gravity kicks of a run for a rest state (:meth:`PbdBody.for_rest`)."""
XPBD_FEM = 3
VOLUME_FLOOR = 1e-3
"""Smallest tetrahedron volume in the engine's length unit (:attr:`PbdBody.length_unit`):
``PositionBasedDynamics::init_FEMTetraConstraint`` drops a tetrahedron whose rest volume is below
1e-6 (its ``eps``, in the engine's units) and adds no constraint for it (measured: none of the 451
tetrahedra of a cylinder R 1 cm meshed at 6 mm in SI units)."""
"""``SimulationModel::addSolidConstraints`` method 3: ``XPBD_FEMTetConstraint`` per tetrahedron."""
GATE = 1e-6
"""``eps`` of ``XPBD.cpp``: a tetrahedron with ``Σ w |∇U'|² + C² α`` below it is skipped."""
GATE_STRAIN = 1e-10
"""Strain below which the engine's threshold :data:`GATE` may skip a tetrahedron (mass unit)."""

# the library's corners p0 … p7 of a cell (addRegularTetModel: p0 (i,j,k), p1 +k, p3 +i, p2 +i+k,
# p4 +j, p5 +j+k, p7 +i+j, p6 +i+j+k) in the harness's corner index c = di + 2 dj + 4 dk
_P = (0, 4, 5, 1, 2, 6, 7, 3)
SPLIT_ODD = tuple(tuple(_P[a] for a in t) for t in ((2, 1, 6, 3), (6, 3, 4, 7), (4, 1, 6, 5), (3, 1, 4, 0),
                                                  (6, 1, 4, 3)))
SPLIT_EVEN = tuple(tuple(_P[a] for a in t) for t in ((0, 2, 5, 1), (7, 2, 0, 3), (5, 2, 7, 6), (7, 0, 5, 4),
                                                   (0, 2, 7, 5)))
"""The library's 5-tetrahedron splits of a cell of odd / even ``i + j + k`` (harness corners)."""


def cell_tets(cells: np.ndarray, cell_ijk: np.ndarray, X: np.ndarray) -> np.ndarray:
    """(5 m, 4) vertex indices of the library's tetrahedra of the cells (m, 8) at grid indices
    (m, 3), each ordered to a positive volume at the positions X."""
    cells = np.asarray(cells)
    odd = (np.asarray(cell_ijk).sum(axis=1) % 2).astype(bool)
    loc = np.where(odd[:, None, None], np.array(SPLIT_ODD)[None], np.array(SPLIT_EVEN)[None])
    tets = cells[np.arange(len(cells))[:, None, None], loc].reshape(-1, 4)
    neg = tet_volumes(X, tets) < 0.0
    tets[neg] = tets[neg][:, [0, 1, 3, 2]]
    return tets


def length_unit(h: float, X: np.ndarray, tets: np.ndarray) -> float:
    """The engine's length unit for tetrahedra ``tets`` of size ``h`` at ``X``: ``h``, or less so
    that the smallest is at least :data:`VOLUME_FLOOR` (in metres a 4 mm cell's tetrahedra, 1e-8 m³,
    are below the library's 1e-6 and it adds no constraint: the body has no stiffness)."""
    V = np.abs(tet_volumes(X, tets))
    return min(float(h), (float(V.min()) / VOLUME_FLOOR) ** (1.0 / 3.0))


def lame_per_E(nu: float) -> tuple[float, float]:
    """``(μ/E, λ/E)`` of ``XPBD::solve_FEMTetraConstraint``: ``1/(2(1+ν))`` and
    ``ν/((1+ν)(1−2ν))``, the textbook map (its compliance is 1/E)."""
    return 0.5 / (1.0 + nu), nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


def svk_forces(x: np.ndarray, tets: np.ndarray, Dminv: np.ndarray, V: np.ndarray, mu: float, lam: float) -> np.ndarray:
    """Forces (N, 3) ``−∂U/∂x`` of the library's energy per tetrahedron ``V (μ |ε|² + λ/2 tr(ε)²)``,
    ε the Green strain of ``F = [x0−x3, x1−x3, x2−x3] Dm⁻¹``: ``H = V P Dm⁻ᵀ``, P = F (2μ ε + λ tr ε I)
    (``computeGreenStrainAndPiolaStress``, ``computeGradCGreen``)."""
    p = x[tets]
    Ds = np.stack((p[:, 0] - p[:, 3], p[:, 1] - p[:, 3], p[:, 2] - p[:, 3]), axis=-1)  # columns
    F = Ds @ Dminv
    eps = 0.5 * (np.einsum("tki,tkj->tij", F, F) - np.eye(3))
    tr = np.trace(eps, axis1=1, axis2=2)
    S = 2.0 * mu * eps + lam * tr[:, None, None] * np.eye(3)
    H = V[:, None, None] * (F @ S) @ np.transpose(Dminv, (0, 2, 1))  # gradient wrt x0, x1, x2 (columns)
    f = np.zeros_like(x)
    g = np.transpose(H, (0, 2, 1))  # (t, 3 vertices, 3 components)
    for a in range(3):
        np.add.at(f, tets[:, a], -g[:, a])
    np.add.at(f, tets[:, 3], g.sum(axis=1))
    return f


class PbdBody(EngineBody):
    """A scene's body stepped by the library's ``TimeStepController`` with XPBD FEM tetrahedra
    (module docstring); the stepper protocol of :class:`hybmss.models._engine_body.EngineBody`."""

    def __init__(self, system: System, method: str, dt: float, ramp_time: float, *, damping: float | None = None,
                 density: float | None = None, gravity="scene"):
        if method != "xpbd-fem":
            raise ValueError(f"method must be xpbd-fem, got {method!r}")
        self.method = method
        self.setup(system, 1, dt, ramp_time, damping, density, gravity)
        lat = system.lattice
        self.tets = cell_tets(lat.cells, lat.cell_ijk, self.nodes.X)
        self.length_unit = length_unit(system.scene.body.le, self.nodes.X, self.tets)
        self._build(system.scene.material)

    split = "the library's addRegularTetModel split: 5 tetrahedra, alternating with i + j + k"

    @classmethod
    def on_tets(cls, body, material, holds, dt: float, ramp_time: float, *, damping: float = 0.0,
                density: float | None = None, method: str = "xpbd-fem") -> "PbdBody":
        """The library's tet model on the nodes and tetrahedra of a :class:`hybmss.tetbody.TetBody`
        (``addTetModel``, positive orientation); ``holds``
        (:class:`hybmss.models._engine_tet.TetHold`) prescribe every component of their nodes."""
        if method != "xpbd-fem":
            raise ValueError(f"method must be xpbd-fem, got {method!r}")
        self = cls.__new__(cls)
        self.method = method
        self.setup_tets(body, material, holds, dt, ramp_time, damping, density)
        self.tets = np.asarray(body.tets, dtype=np.int64).copy()
        self.split = "the tetrahedra of the body's own mesh"
        self.length_unit = length_unit(float(body.h), self.nodes.X, self.tets)
        self._build(material)
        return self

    def _build(self, material) -> None:
        X = self.nodes.X
        p = X[self.tets]
        Dm = np.stack((p[:, 0] - p[:, 3], p[:, 1] - p[:, 3], p[:, 2] - p[:, 3]), axis=-1)
        self.Dminv = np.linalg.inv(Dm)
        self.V = np.abs(tet_volumes(X, self.tets))
        self.E, self.nu = float(material.E), float(material.nu)
        mu_, lam_ = lame_per_E(self.nu)
        self.mu, self.lam = self.E * mu_, self.E * lam_
        # mass unit: C² α = 2 U'/(E h²) ≥ V ε² /(3 E h²) (U' ≥ V μ' ε², μ' ≥ 1/3) exceeds GATE for
        # ε ≥ GATE_STRAIN once multiplied by M (the engine's E is E L/M, its volumes V/L³ in its length unit L)
        L = self.length_unit
        self.mass_unit = max(1.0, GATE * 3.0 * self.E * L * self.dt**2 / (self.V.min() / L**3 * GATE_STRAIN**2))
        t0 = time.perf_counter()
        self.sim = pypbd.Simulation.getCurrent()  # never getModel(): it may point to a freed body's model
        self.model = pypbd.SimulationModel()
        self.model.init()
        self.sim.setModel(self.model)
        tm = self.model.addTetModel([np.array(v, dtype=float) / L for v in X], self.tets.ravel().tolist())
        M = self.mass_unit
        tau = self.time_unit = TIME_UNIT_STEPS * self.dt
        self.velocity_unit = L / tau
        Eu = self.E * L * tau**2 / M  # E in the engine's units (pressure: M / (L tau²))
        self.model.addSolidConstraints(tm, XPBD_FEM, Eu, self.nu, Eu, False, False)
        self.pd = self.model.getParticles()
        fixed = self.nodes.fixed
        self.held = np.flatnonzero(fixed.all(axis=1))  # kinematic particles (mass 0)
        self.partial = np.flatnonzero(fixed.any(axis=1) & ~fixed.all(axis=1))  # reset after each step
        self.free = np.flatnonzero(~fixed.all(axis=1))
        held = set(self.held.tolist())
        for i, m in enumerate(self.nodes.mass):
            self.pd.setMass(i, 0.0 if i in held else float(m) / M)
        ts = self.sim.getTimeStep()
        ts.setValueUInt(pypbd.TimeStepController.NUM_SUB_STEPS, 1)
        ts.setValueUInt(pypbd.TimeStepController.MAX_ITERATIONS, 1)
        self.compile_time_s = time.perf_counter() - t0
        self._targets: dict = {}
        self._held_s = None  # the load factor the kinematic particles were last set at
        self.sync_every = 1
        self.kick = np.zeros(3) if self.gravity is None else np.asarray(self.gravity, dtype=float)
        self.kick = self.dt / tau * (self.kick * tau**2 / L - G_PBD)

    def describe(self) -> dict:
        return {"engine": ENGINE, "engine_version": VERSION, "element": "tet", "device": "cpu", "threads": 1,
                "integrator": "TimeStepController (XPBD, 1 substep, 1 iteration)", "precision": "f64",
                "method": self.method, "mass_unit_kg": self.mass_unit, "length_unit_m": self.length_unit,
                "time_unit_s": self.time_unit,
                "tet_split": self.split}

    def _target(self, s: float) -> np.ndarray:
        """:meth:`prescribed` at load factor ``s``, kept for the last two values (constant after the ramp)."""
        hit = self._targets.get(s)
        if hit is None:
            if len(self._targets) > 1:
                self._targets.pop(next(iter(self._targets)))
            hit = self._targets[s] = self.prescribed(s)
        return hit

    def _current(self) -> None:
        one_thread()  # OpenMP's thread count is the calling thread's: set where the steps are taken
        self.sim.setModel(self.model)
        pypbd.TimeManager.getCurrent().setTimeStepSize(self.dt / self.time_unit)

    def load(self, x: np.ndarray, v: np.ndarray, step0: int = 0) -> None:
        self.step = int(step0)
        self._held_s = None
        for i in range(len(self.nodes.X)):
            self.pd.setPosition(i, np.asarray(x[i], dtype=float) / self.length_unit)
            self.pd.setVelocity(i, np.asarray(v[i], dtype=float) / self.velocity_unit)

    def for_rest(self) -> None:
        """Run for a rest state only: without the scene's gravity, the damping and the library's
        gravity's compensation every :data:`REST_SYNC_STEPS` steps (module docstring, **Rest runs**)."""
        if self.gravity is None:
            self.sync_every = REST_SYNC_STEPS

    def _steps(self, step0: int, n: int) -> None:
        self._current()
        damp = 1.0 / (1.0 + self.damping * self.dt)
        ts, pd, kick, L = self.sim.getTimeStep(), self.pd, self.kick, self.length_unit
        spent = 0.0
        group = 0  # steps left in the current group of the kicks (they end with the call)
        owed = None  # the half kick after a group, given in one pass with the next group's first half
        free = self.free.tolist()
        for k in range(step0, step0 + n):
            s = ramp((k + 1) * self.dt, self.ramp_time)
            target = self._target(s)
            if s != self._held_s:  # kinematic particles stay where they were set
                for i in self.held:
                    pd.setPosition(int(i), target[i] / L)
                self._held_s = s
            if group == 0:
                group = min(self.sync_every, step0 + n - k)
                if group == 1:
                    d, m, rest = damp, kick, None
                else:  # half the kicks before the group, half after: its mean velocity unbiased
                    d, m, rest = damp**group, 0.5 * group * kick, 0.5 * group * kick
                if owed is None:
                    for i in free:
                        pd.setVelocity(i, pd.getVelocity(i) * d + m)
                else:  # the same operations, in the same order, as two passes
                    for i in free:
                        pd.setVelocity(i, (pd.getVelocity(i) + owed) * d + m)
                    owed = None
            group -= 1
            t0 = time.perf_counter()
            ts.step(self.model)
            spent += time.perf_counter() - t0
            if group == 0 and rest is not None:
                if len(self.partial) or k == step0 + n - 1:  # before the partial nodes' reset; the call's end
                    for i in free:
                        pd.setVelocity(i, pd.getVelocity(i) + rest)
                else:
                    owed = rest
            if len(self.partial):
                vel = (target - self._target(ramp(k * self.dt, self.ramp_time))) / self.dt
                for i in self.partial:
                    i = int(i)
                    c = self.nodes.fixed[i]
                    q, w = np.array(pd.getPosition(i)), np.array(pd.getVelocity(i))
                    q[c], w[c] = target[i, c] / L, vel[i, c] / self.velocity_unit
                    pd.setPosition(i, q)
                    pd.setVelocity(i, w)
        self.step_time_s += spent
        self.step = step0 + n

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        x = np.array(np.asarray(self.pd.getVertices()), dtype=float) * self.length_unit
        v = np.array([np.asarray(self.pd.getVelocity(i)) for i in range(len(x))], dtype=float).reshape(-1, 3)
        v *= self.velocity_unit
        return x, v

    def internal_forces(self, x: np.ndarray) -> np.ndarray:
        return svk_forces(np.asarray(x, dtype=float), self.tets, self.Dminv, self.V, self.mu, self.lam)

    def vertices(self, x: np.ndarray | None = None) -> np.ndarray:
        return self.state()[0] if x is None else np.asarray(x, dtype=float).copy()

