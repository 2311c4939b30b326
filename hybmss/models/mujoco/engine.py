"""A scene as a MuJoCo model, stepped by MuJoCo (``mujoco`` ≥ 4.0, the C library of its wheel).

Imported only when a ``mujoco-*`` model runs (:mod:`hybmss.models.mujoco` names the models
without importing the engine).

Scene translation (the same for the three element kinds)
--------------------------------------------------------
- **Nodes.**  Every degree of freedom of the flex is a body of its own carrying three slide joints
  along the world axes (MuJoCo's fastest layout: diagonal mass matrix, 3×3 stiffness blocks), with
  no pin: the plates are imposed by the harness on the joints (below), so that the plate nodes
  keep their joints and the engine's own elastic force on them can be read.
  ``tet``: the nodes are the lattice particles.  ``trilinear``: the nodes of the interpolation grid
  (``cellcount`` = the lattice's cells, so the 8-node cells are the voxels and the nodes are the
  lattice particles).  ``quadratic``: the 27-node cells of the same grid, nodes on the half-step
  grid ((2n+1) per axis).
- **Mesh.**  The flex vertices are the lattice particles.  Its tetrahedra are MuJoCo's own split
  of a grid cell, the one ``<flexcomp type="grid" dim="3">`` generates (:data:`SPLIT`: six
  tetrahedra around the diagonal from local corner (0,1,1) to (1,0,0), the same in every cell):
  what a MuJoCo user gets for a voxel body.  For ``tet`` they carry the elasticity; for the
  interpolated kinds they are the collision and volume mesh and the cells carry the elasticity.
  A body that is not a box is refused by the interpolated kinds (their grid spans the bounding box).
- **Masses.**  ``tet``, ``trilinear``: the lumped ``ρ Vc/8`` per cell corner (the harness's masses).
  ``quadratic``: each eighth of a cell gives ``ρ Vc/64`` to each of its 8 corners on the half-step
  grid (positive lumped masses of the right total; a row-sum lumping of the 27-node mass matrix
  has negative corner masses).
- **Plates.**  A prescribed component of a node is set after every ``mj_step`` to its target at
  the new time (``X + u(s(t))``, the scene's ramp) and its velocity to the target's change over
  the step: with the ``Euler`` integrator the update of a free node depends only on the positions
  of the step's start (diagonal mass and damping matrices), so this is the harness's own explicit
  scheme with its plates.  A node is on a plate when ``Plate.region`` selects its reference
  position (mid-side nodes of the quadratic cells included); a rotation about the plate's centroid
  turns about the centroid of its lattice particles.
- **Integrator.**  MuJoCo's ``<option integrator>`` (:mod:`hybmss.models.mujoco`: ``Euler``,
  ``RK4``, ``discrete``).  With ``RK4`` (intermediate stages) and ``discrete`` (an implicit solve
  coupling every node through ``K``) a plate node would move within the step as a free node of
  mass ``m`` before being reset; its joints carry an armature :data:`PLATE_ARMATURE` × the
  largest node mass instead, so that within the step it moves ``m_free/armature`` ≤ 1e-9 times what
  a free node would (held, to that fraction).  ``Euler`` has none: its free nodes' update depends
  only on the step's start (diagonal mass matrix), the MJCF is the one of the static runs.
- **Damping and gravity.**  MuJoCo refuses joint damping on flex bodies (its elastic damping is
  Rayleigh's, proportional to the stiffness), so the scene's mass-proportional damping c is applied
  to MuJoCo's step as the harness's explicit scheme applies it: after ``mj_step`` (``v' = v + h a``,
  ``x' = x + h v'``) the velocity becomes ``v'/(1 + c h)`` and the position moves with it.
  Gravity is MuJoCo's.  Surface loads (tractions) are refused.

Readouts
--------
The elastic force on a node is MuJoCo's ``qfrc_spring`` at its joints after ``mj_forward`` (the
flex elasticity, nothing recomputed); the reaction of a plate ``−Σ (f + m g)`` over its nodes'
prescribed components (as every explicit model); the displacement field the flex vertices'
positions (``flexvert_xpos``: the lattice particles, interpolated for the grid kinds); the volume
that of the deformed tetrahedra of the flex.

Instability
-----------
``mj_step`` checks the state (``mj_checkPos``, ``mj_checkVel``, ``mj_checkAcc``): a NaN, an
infinity or a value above ``mjMAXVAL`` in ``qpos``, ``qvel`` or ``qacc`` counts a warning in
``data.warning`` (``mjWARN_BADQPOS``, ``mjWARN_BADQVEL``, ``mjWARN_BADQACC``, the dof in
``lastinfo``) and resets the state to the model's reference, the run going on from rest.  The
body reads these counters after every step and turns the first into a
:class:`hybmss.explicit.DivergenceError` (its cause and a remedy); MuJoCo's own text of every
warning goes to ``info['engine_warnings']`` (a handler installed while MuJoCo compiles and steps),
never to the process's stderr nor to a ``MUJOCO_LOG.TXT`` in the working directory.
"""

from __future__ import annotations

import contextlib
import math
import time

import numpy as np

import mujoco

from ...system import System
from .._engine_body import EngineBody, Nodes, positive

ENGINE = "mujoco"
VERSION = mujoco.__version__

SPLIT = ((0, 2, 1, 6), (0, 1, 4, 6), (1, 2, 3, 6), (1, 3, 7, 6), (1, 5, 4, 6), (1, 7, 5, 6))
"""MuJoCo's split of a grid cell into 6 tetrahedra, in the harness's corner index
``c = di + 2 dj + 4 dk`` (read from the elements of a compiled ``<flexcomp type="grid" dim="3">``)."""

ORDER = {"tet": 1, "trilinear": 1, "quadratic": 2}
"""Node grid step per cell edge of each element kind (1: lattice nodes, 2: half-step grid)."""

PLATE_ARMATURE = 1e9
"""Armature of a plate node's joints, in units of the largest node mass, under ``RK4`` and
``discrete`` (module docstring)."""
STABILITY = {"Euler": 2.0, "RK4": 2.0 * 2.0 ** 0.5, "discrete": float("inf")}
"""The integrators' stability limits on ``ω h`` for a linear mode (the symplectic Euler's 2,
RK4's 2√2 on the imaginary axis, backward Euler's none)."""

UNSTABLE = {int(mujoco.mjtWarning.mjWARN_BADQACC): ("mjWARN_BADQACC", "acceleration"),
            int(mujoco.mjtWarning.mjWARN_BADQVEL): ("mjWARN_BADQVEL", "velocity"),
            int(mujoco.mjtWarning.mjWARN_BADQPOS): ("mjWARN_BADQPOS", "position")}
"""The warnings of ``mj_step``'s state checks after which MuJoCo resets the state: index in
``data.warning`` → (name, the quantity found NaN, infinite or huge)."""


@contextlib.contextmanager
def warnings_into(sink: list):
    """MuJoCo's warning text into ``sink`` (``mju_user_warning``) for the block, the previous
    handler back after it: without a handler MuJoCo prints to stderr and appends to
    ``MUJOCO_LOG.TXT`` in the working directory."""
    old = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda msg: sink.append(str(msg).strip()))
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(old)


def cell_tets(cells: np.ndarray) -> np.ndarray:
    """(6 m, 4) vertex indices of MuJoCo's tetrahedra of the cells (m, 8)."""
    return np.asarray(cells, dtype=np.int64)[:, np.array(SPLIT)].reshape(-1, 4)


def mjcf(system: System, kind: str, nodes: Nodes, dt: float, gravity, integrator: str = "Euler") -> str:
    """The MJCF of the scene (module docstring)."""
    lat = system.lattice
    tets = cell_tets(lat.cells)
    if kind == "tet":
        return mjcf_tets(system.scene.material, nodes, tets, float(system.scene.body.le), dt, gravity, integrator)
    f = lambda v: repr(float(v))
    n = system.scene.body.shape
    vert = " ".join(f(v) for v in lat.X.ravel())
    extra = (f'dof="{kind}" cellcount="{n[0]} {n[1]} {n[2]}" body="{" ".join(["world"] * lat.n_particles)}" '
             f'vertex="{vert}" node="{" ".join(f"n{a}" for a in range(len(nodes.X)))}"')
    return _document(system.scene.material, nodes, tets, float(system.scene.body.le), dt, gravity, integrator, extra)


def mjcf_tets(material, nodes: Nodes, tets: np.ndarray, le: float, dt: float, gravity,
              integrator: str = "Euler") -> str:
    """The MJCF of a flex whose vertices are the nodes, each a body of its own, with the
    tetrahedra ``tets`` (vertex order as MuJoCo reads it) carrying the elasticity; ``le`` the
    length of the nodes' rotational inertia (immaterial: slide joints only)."""
    extra = f'body="{" ".join(f"n{a}" for a in range(len(nodes.X)))}"'
    return _document(material, nodes, tets, le, dt, gravity, integrator, extra)


def _document(material, nodes: Nodes, tets: np.ndarray, le: float, dt: float, gravity, integrator: str,
              extra: str) -> str:
    f = lambda v: repr(float(v))
    bodies = []
    held = nodes.fixed.reshape(-1, 3) if integrator != "Euler" else np.zeros((len(nodes.X), 3), dtype=bool)
    armature = f' armature="{f(PLATE_ARMATURE * float(np.max(nodes.mass)))}"'
    for a, (x, m) in enumerate(zip(nodes.X, nodes.mass)):
        I = f(m * le * le * 1e-2)
        joints = "".join(f'<joint type="slide" axis="{ax}"{armature if h else ""}/>'
                         for ax, h in zip(("1 0 0", "0 1 0", "0 0 1"), held[a]))
        bodies.append(f'<body name="n{a}" pos="{f(x[0])} {f(x[1])} {f(x[2])}"><inertial pos="0 0 0" mass="{f(m)}" '
                      f'diaginertia="{I} {I} {I}"/>{joints}</body>')
    element = " ".join(map(str, np.asarray(tets).ravel()))
    g = "0 0 0" if gravity is None else " ".join(f(v) for v in gravity)
    flex = f'<flex name="body" dim="3" radius="0" element="{element}" {extra}>'
    return (f'<mujoco model="hybmss"><option timestep="{f(dt)}" gravity="{g}" integrator="{integrator}">'
            f'<flag contact="disable"/></option><worldbody>{"".join(bodies)}</worldbody>'
            f'<deformable>{flex}<elasticity young="{f(material.E)}" poisson="{f(material.nu)}"/>'
            f'<contact contype="0" conaffinity="0" selfcollide="none"/></flex></deformable></mujoco>')


class MujocoBody(EngineBody):
    """A scene's body stepped by MuJoCo: the stepper protocol of the explicit loop
    (``load``, ``advance``, ``state``, ``internal_forces``, ``energy``) on the engine's nodes.

    ``density``: the masses' density (``ρ``, or 1 for the static answer of a massless body, whose
    rest state does not depend on a uniform density); ``gravity`` (3,) or None."""

    def __init__(self, system: System, kind: str, dt: float, ramp_time: float, *, damping: float | None = None,
                 density: float | None = None, gravity="scene", integrator: str = "Euler"):
        self._kinds(kind, integrator)
        self.setup(system, 2 if kind == "quadratic" else 1, dt, ramp_time, damping, density, gravity)
        self.tets = positive(system.X, cell_tets(system.lattice.cells))
        self._compile(mjcf(system, kind, self.nodes, self.dt, self.gravity, integrator))

    @classmethod
    def on_tets(cls, body, material, holds, dt: float, ramp_time: float, *, damping: float = 0.0,
                density: float | None = None, integrator: str = "Euler") -> "MujocoBody":
        """The ``tet`` flex on the tetrahedra of a :class:`hybmss.tetbody.TetBody` as they are
        (positive orientation; MuJoCo's forces do not depend on it: the same rest state with two
        vertices of every tetrahedron swapped, measured on the patch test); ``holds``
        (:class:`hybmss.models._engine_tet.TetHold`) prescribe every component of their nodes."""
        self = cls.__new__(cls)
        self._kinds("tet", integrator)
        self.setup_tets(body, material, holds, dt, ramp_time, damping, density)
        self.tets = np.asarray(body.tets, dtype=np.int64)
        xml = mjcf_tets(material, self.nodes, self.tets, self.length(), self.dt, None, integrator)
        self._compile(xml)
        return self

    def _kinds(self, kind: str, integrator: str) -> None:
        if kind not in ORDER:
            raise ValueError(f"element kind must be one of {', '.join(ORDER)}; got {kind!r}")
        if integrator not in STABILITY:
            raise ValueError(f"integrator must be one of {', '.join(STABILITY)}; got {integrator!r}")
        self.kind, self.integrator = kind, integrator

    def _compile(self, xml: str) -> None:
        t0 = time.perf_counter()
        with warnings_into(self.warnings):
            self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        self.probe = mujoco.MjData(self.model)
        self.compile_time_s = time.perf_counter() - t0
        n = len(self.nodes.X)
        if self.model.nv != 3 * n:
            raise RuntimeError(f"the MuJoCo model has {self.model.nv} degrees of freedom, expected {3 * n}")

    def describe(self) -> dict:
        return {"engine": ENGINE, "engine_version": VERSION, "element": self.kind, "device": "cpu", "threads": 1,
                "integrator": self.integrator, "precision": "f64",
                "tet_split": self.split}

    split = "MuJoCo's grid split: 6 tetrahedra around the diagonal (0,1,1)-(1,0,0) of each cell"

    def dt_crit(self) -> float:
        """The integrator's stability limit ``STABILITY[integrator] / ω_max`` on the engine's own
        forces (:data:`STABILITY`; ``inf`` for ``discrete``)."""
        s = STABILITY[self.integrator]
        if math.isinf(s):
            return math.inf
        w = self.omega_max()
        return s / w if w > 0 else math.inf

    def _set_plates(self, step: int) -> None:
        u, v = self.plate_targets(step)
        self.data.qpos[self.fixed_dofs] = u
        self.data.qvel[self.fixed_dofs] = v

    # ------------------------------------------------------------------ stepper protocol
    def load(self, x: np.ndarray, v: np.ndarray, step0: int = 0) -> None:
        """Set the node positions and velocities (N, 3) at step ``step0``."""
        self.step = int(step0)
        self.data.qpos[:] = (np.asarray(x, dtype=float) - self.nodes.X).ravel()
        self.data.qvel[:] = np.asarray(v, dtype=float).ravel()
        self.data.time = self.step * self.dt
        with warnings_into(self.warnings):
            mujoco.mj_forward(self.model, self.data)

    def _steps(self, step0: int, n: int) -> None:
        """``n`` steps from ``step0``: MuJoCo's ``mj_step``, the scene's damping, then the plates
        at the new time."""
        m, d = self.model, self.data
        damp = 1.0 / (1.0 + self.damping * self.dt)
        spent = 0.0
        checks = [d.warning[i] for i in UNSTABLE]
        with warnings_into(self.warnings):
            for k in range(step0, step0 + n):
                t0 = time.perf_counter()
                mujoco.mj_step(m, d)
                spent += time.perf_counter() - t0
                if any(w.number for w in checks):
                    self.step_time_s += spent
                    raise self.reset_error(k + 1)
                if damp != 1.0:  # v <- v/(1 + c h), and the position step with it
                    v1 = d.qvel * damp
                    d.qpos[:] -= self.dt * (d.qvel - v1)
                    d.qvel[:] = v1
                self._set_plates(k + 1)
        self.step_time_s += spent
        self.step = step0 + n

    def reset_error(self, step: int):
        """The :class:`hybmss.explicit.DivergenceError` of a state MuJoCo found unstable (and
        reset) at ``step``: which check, which node, the likely cause and a remedy."""
        from ...explicit import DivergenceError

        i = next(i for i in UNSTABLE if self.data.warning[i].number)
        name, what = UNSTABLE[i]
        node = int(self.data.warning[i].lastinfo) // 3
        lat = self.system.lattice if self.system is not None else None
        grid = tuple(int(g) for g in lat.grid[node]) if self.kind != "quadratic" and lat is not None else None
        dt_c = self.dt_crit()
        cause = (f"the step {self.dt:.4g} s exceeds the stability limit 2/omega_max = {dt_c:.4g} s of MuJoCo's "
                 f"own forces; use a step below it" if self.dt > dt_c else
                 "the deformation ran away below the stability limit (inverted elements, a plate ramp too fast); "
                 "use a longer ramp or a smaller load")
        msg = (f"{ENGINE} found a NaN, infinite or huge {what} at node {node} at step {step} "
               f"(t = {step * self.dt:.6g} s, {name}) and reset its state to rest: the run is unstable; {cause}")
        return DivergenceError(msg, step=step, particle=node, grid=grid, displacement=float("nan"), dt=self.dt,
                               dt_crit=dt_c)

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """Node positions and velocities (N, 3)."""
        return self.nodes.X + self.data.qpos.reshape(-1, 3), self.data.qvel.reshape(-1, 3).copy()

    def internal_forces(self, x: np.ndarray) -> np.ndarray:
        """MuJoCo's elastic force on every node (N, 3) at node positions ``x``: ``qfrc_spring``
        after ``mj_forward`` (the flex elasticity)."""
        p = self.probe
        p.qpos[:] = (np.asarray(x, dtype=float) - self.nodes.X).ravel()
        p.qvel[:] = 0.0
        with warnings_into(self.warnings):
            mujoco.mj_forward(self.model, p)
        return p.qfrc_spring.reshape(-1, 3).copy()

    def vertices(self, x: np.ndarray | None = None) -> np.ndarray:
        """Positions (n, 3) of the flex vertices (the lattice particles) at node positions ``x``
        (default: the current state), as MuJoCo places them."""
        d = self.data
        if x is not None:
            d = self.probe
            d.qpos[:] = (np.asarray(x, dtype=float) - self.nodes.X).ravel()
            mujoco.mj_kinematics(self.model, d)
            mujoco.mj_flex(self.model, d)
        return np.asarray(d.flexvert_xpos, dtype=float).copy()

