"""What the engine models share: the engine's nodes of a scene, its plates on them, and the
stepper protocol of :mod:`hybmss.stepper` on them, so that an engine's explicit run (and its
static answer, the rest state of a damped run) is a run of the one loop
:func:`hybmss.explicit.simulate_explicit` (ramp, plates' reactions, damping's parameter,
divergence and rest checks, history, timing, Ctrl-C and the :class:`~hybmss.result.Result`),
whatever engine steps it (:mod:`hybmss.models.mujoco`, :mod:`hybmss.models.newton`,
:mod:`hybmss.models.pbd`).

A subclass builds its engine in ``__init__`` (after :meth:`EngineBody.setup`) and provides
``load(x, v)``, ``_steps(step0, n)`` (``n`` engine steps from the global step ``step0``, the
plates at their targets after each), ``state() -> (x, v)``, ``internal_forces(x)`` (the engine's
own force on each node), ``vertices(x)`` (the lattice particles' positions at node positions
``x``, as the engine places them), ``tets`` (the engine's tetrahedra on the lattice particles,
for the volume) and ``describe()`` (what ``info`` says about the engine).  What the loop needs
beyond the protocol: ``node_system()`` (the system on the engine's nodes: the 27-node cells have
nodes that are not lattice particles), ``force_resolution_N`` (a float32 engine's floor of the
rest test), ``dt_crit()`` (from the engine's own forces) and ``readout(...)`` (the engine's
element volumes, the balance of the reactions, the step and compile times).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..explicit import BLOWUP_FACTOR, ramp
from ..system import PlateSet, System


def tet_volumes(x: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volumes of the tetrahedra ``tets`` at positions ``x``."""
    p = x[tets]
    return np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6.0


def positive(X: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """The tetrahedra ``tets`` with the vertices of each ordered to a positive signed volume
    (:func:`tet_volumes`) at the reference positions ``X`` (the last two swapped where it is
    negative): the orientation the readouts' volume and inverted count take."""
    tets = np.array(tets, dtype=np.int64)
    neg = tet_volumes(X, tets) < 0.0
    tets[neg] = tets[neg][:, [0, 1, 3, 2]]
    return tets


@dataclasses.dataclass
class Nodes:
    """The engine's nodes: reference positions (N, 3), masses (N,), the vertex of each lattice
    particle (tet: itself), prescribed components (N, 3) and each plate's nodes."""

    X: np.ndarray
    mass: np.ndarray
    fixed: np.ndarray
    plates: tuple[PlateSet, ...]
    centers: tuple  # rotation centre of each plate (lattice centroid), None for other motions


def engine_nodes(system: System, order: int, density: float) -> Nodes:
    """The nodes of a grid of ``order`` nodes per cell edge (1: the lattice particles, with the
    lumped masses ``ρ Vc/8`` per cell corner; 2: the half-step grid of 27-node cells, each eighth
    of a cell giving ``ρ Vc/64`` to each of its corners) for the system's body, density ``density``."""
    lat = system.lattice
    le = float(system.scene.body.le)
    if order == 1:
        X = system.X.copy()
        mass = density * lat.masses_per_density
    else:
        p = int(order)
        lo = np.asarray(system.scene.body.bounds[0], dtype=float)
        q = np.asarray(system.scene.body.shape) * p + 1
        g = np.stack(np.meshgrid(*(np.arange(k) for k in q), indexing="ij"), axis=-1).reshape(-1, 3)
        X = lo + g * (le / p)
        mass = np.zeros(len(X))
        idx = lambda a: (a[..., 0] * q[1] + a[..., 1]) * q[2] + a[..., 2]
        corners = np.array([[(c >> 0) & 1, (c >> 1) & 1, (c >> 2) & 1] for c in range(8)])
        sub = np.stack(np.meshgrid(*(np.arange(k - 1) for k in q), indexing="ij"), axis=-1).reshape(-1, 3)
        for c in corners:
            np.add.at(mass, idx(sub + c), density * le**3 / 64.0)
    fixed = np.zeros((len(X), 3), dtype=bool)
    plates, centers = [], []
    for plate, ps in zip(system.scene.plates, system.plates):
        sel = np.flatnonzero(plate.region.select(X, system.scene.body))
        cons = plate.motion.constrained
        fixed[np.ix_(sel, np.flatnonzero(cons))] = True
        plates.append(PlateSet(plate.name, sel, cons))
        rot = plate.motion.kind == "rotate" and plate.motion.center is None
        centers.append(tuple(system.X[ps.particles].mean(axis=0)) if rot else None)
    return Nodes(X, mass, fixed, tuple(plates), tuple(centers))

def tet_nodes(body, holds, density: float) -> Nodes:
    """The engine's nodes of a :class:`hybmss.tetbody.TetBody`: its nodes, the lumped masses
    ``ρ V/4`` per tetrahedron vertex, each hold (:class:`hybmss.models._engine_tet.TetHold`)'s
    nodes with their three components prescribed."""
    X = np.asarray(body.X, dtype=float)
    mass = np.zeros(len(X))
    np.add.at(mass, body.tets.ravel(), np.repeat(density * np.abs(body.volumes) / 4.0, 4))
    fixed = np.zeros((len(X), 3), dtype=bool)
    plates, centers = [], []
    for h in holds:
        sel = np.flatnonzero(np.asarray(h.where(X), dtype=bool))
        if len(sel) == 0:
            raise ValueError(f"hold {h.name!r} selects no node of the body")
        fixed[sel] = True
        plates.append(PlateSet(h.name, sel, np.ones(3, dtype=bool)))
        rot = h.motion.kind == "rotate" and h.motion.center is None
        centers.append(tuple(X[sel].mean(axis=0)) if rot else None)
    return Nodes(X, mass, fixed, tuple(plates), tuple(centers))


class EngineBody:
    """The engine-independent part of a body stepped by an engine (module docstring)."""

    fd_step = 1e-7
    """Finite-difference step of :meth:`omega_max`, in cell edges."""
    resolution_N = 0.0
    """Force resolution of the engine's state (N): the largest change of the free nodes' force norm
    under the rounding of the positions to the engine's precision (0: a float64 engine, negligible;
    float32: ``‖K‖₂ · ulp(|X|max)/2 · √(3N)``, :meth:`hybmss.models.newton.engine.NewtonBody.force_resolution`).
    A rest state cannot have a smaller residual, so the rest test accepts one within it."""

    def setup(self, system: System, order: int, dt: float, ramp_time: float, damping: float | None,
              density: float | None, gravity) -> None:
        self.system = system
        self.dt, self.ramp_time = float(dt), float(ramp_time)
        rho = system.scene.material.rho if density is None else float(density)
        self.gravity = system.gravity if isinstance(gravity, str) else gravity
        self.damping = float(system.scene.damping if damping is None else damping)
        self._start(engine_nodes(system, order, rho))

    def setup_tets(self, body, material, holds, dt: float, ramp_time: float, damping: float,
                   density: float | None) -> None:
        """:meth:`setup` for the nodes of a :class:`hybmss.tetbody.TetBody` (no system: the
        engine's own tetrahedra are the body's), the masses ``ρ V/4`` of each tetrahedron on its
        vertices, each :class:`hybmss.models._engine_tet.TetHold` prescribing every component of
        the nodes it selects; no gravity."""
        self.system, self.tetbody, self.material = None, body, material
        self.holds = tuple(holds)
        self.dt, self.ramp_time = float(dt), float(ramp_time)
        self.gravity = None
        self.damping = float(damping)
        self._start(tet_nodes(body, self.holds, material.rho if density is None else float(density)))

    def _start(self, nodes) -> None:
        """The engine's nodes, their held components, and the step, timings and warnings at zero."""
        self.nodes = nodes
        self.fixed_dofs = np.flatnonzero(self.nodes.fixed.ravel())
        self._held: dict = {}
        self.step = 0
        self.step_time_s = 0.0
        self.compile_time_s = 0.0
        self.warnings: list[str] = []

    def extent(self) -> float:
        """The body's largest size (m): the scale of the divergence check."""
        if self.system is None:
            return float(np.ptp(self.nodes.X, axis=0).max())
        return float(max(self.system.scene.body.size))

    def length(self) -> float:
        """The body's element length (m): the scale of the finite-difference steps."""
        return float(self.tetbody.h) if self.system is None else float(self.system.scene.body.le)

    def motions(self) -> tuple:
        """The motion of each plate (:class:`hybmss.scene.Motion`), in the order of ``nodes.plates``."""
        if self.system is None:
            return tuple(h.motion for h in self.holds)
        return tuple(plate.motion for plate in self.system.scene.plates)

    # ------------------------------------------------------------------ prescribed motion
    def prescribed(self, s: float) -> np.ndarray:
        """Target node positions (N, 3) at load factor ``s`` (free components at reference)."""
        X = self.nodes.X
        x = X.copy()
        for motion, ps, c in zip(self.motions(), self.nodes.plates, self.nodes.centers):
            motion = motion if c is None else dataclasses.replace(motion, center=c)
            u = motion.displacement_at(X[ps.particles], s)
            for d in np.flatnonzero(ps.constrained):
                x[ps.particles, d] = X[ps.particles, d] + u[:, d]
        return x

    def plate_targets(self, step: int) -> tuple[np.ndarray, np.ndarray]:
        """Displacements and velocities (flat, on :attr:`fixed_dofs`) of the prescribed
        components at ``step``: the target ``u(s(t))`` and its change over the last step / dt."""
        t = step * self.dt
        now = self._held_displacement(ramp(t, self.ramp_time))
        before = self._held_displacement(ramp(t - self.dt, self.ramp_time))
        return now, (now - before) / self.dt

    def _held_displacement(self, s: float) -> np.ndarray:
        """``prescribed(s) − X`` on :attr:`fixed_dofs`, kept for the last two load factors (a
        step's target is the next step's start; after the ramp s = 1 throughout): the same
        numbers, computed once (read only)."""
        hit = self._held.get(s)
        if hit is None:
            if len(self._held) > 1:
                self._held.pop(next(iter(self._held)))
            hit = self._held[s] = (self.prescribed(s) - self.nodes.X).ravel()[self.fixed_dofs]
        return hit

    # ------------------------------------------------------------------ stepper protocol
    solver = "engine-explicit"
    """Name of the result's solver (the model sets ``<model>-explicit`` or ``<model>-rest``)."""

    def advance(self, step0: int, n: int, check_every: int = 0, limit2: float | None = None) -> tuple[int, int]:
        """``n`` engine steps from the global step ``step0`` (:meth:`_steps`), checking every
        ``check_every`` steps (0: at the end only) that no node is non-finite or moved more than
        ``√limit2`` (default :data:`hybmss.explicit.BLOWUP_FACTOR` body sizes).  Returns
        ``(steps done, first bad node or −1)``; stops at the check that finds one."""
        check = n if check_every <= 0 else int(check_every)
        done = 0
        while done < n:
            k = min(check, n - done)
            self._steps(step0 + done, k)
            done += k
            bad = self.bad_node(limit2)
            if bad >= 0:
                return done, bad
        return done, -1

    def _steps(self, step0: int, n: int) -> None:
        raise NotImplementedError

    def for_rest(self) -> None:
        """Told that the run is for its rest state only (its path between the loop's checks is not
        read): an engine may then step more cheaply (:meth:`hybmss.models.pbd.engine.PbdBody.for_rest`)."""

    @property
    def force_resolution_N(self) -> float:
        """:attr:`resolution_N`, under the name the loop reads (:func:`hybmss.explicit.stepper_rest`)."""
        return self.resolution_N

    def dt_crit(self) -> float:
        """The explicit stability limit ``2/ω_max`` of the engine's own forces (:meth:`omega_max`)."""
        w = self.omega_max()
        return 2.0 / w if w > 0 else math.inf

    def bad_node(self, limit2: float | None = None) -> int:
        """The first node with a non-finite displacement, else the one that moved farthest if that
        is more than ``√limit2`` (default :data:`hybmss.explicit.BLOWUP_FACTOR` body sizes), else −1."""
        x, _ = self.state()
        u = x - self.nodes.X
        u2 = np.einsum("ij,ij->i", u, u)
        bad = np.flatnonzero(~np.isfinite(u2))
        if len(bad):
            return int(bad[0])
        if limit2 is None:
            limit2 = (BLOWUP_FACTOR * self.extent()) ** 2
        i = int(np.argmax(u2))
        return i if u2[i] > limit2 else -1

    def energy(self, x: np.ndarray, v: np.ndarray) -> dict:
        """Kinetic energy of the nodes (MuJoCo exposes no flex strain energy)."""
        return {"kinetic": float(0.5 * np.sum(self.nodes.mass[:, None] * np.asarray(v) ** 2))}

    # ------------------------------------------------------------------ frequencies
    def omega_max(self, iterations: int = 60) -> float:
        """Highest frequency (rad/s) of ``M⁻¹K`` at rest on the free components, K from the
        engine's own forces (finite differences about the reference), by power iteration
        (Rayleigh quotient of the last iterate, a lower bound converging from below)."""
        free = ~self.nodes.fixed.ravel()
        return math.sqrt(max(self._largest_eigenvalue(np.repeat(1.0 / self.nodes.mass, 3), free, iterations), 0.0))

    def stiffness_max(self, iterations: int = 60) -> float:
        """Largest eigenvalue (N/m) of the engine's stiffness K at rest on every component
        (``‖K‖₂``: the largest change of the force vector's norm per unit change of the positions'),
        by power iteration as :meth:`omega_max`."""
        n = 3 * len(self.nodes.X)
        return max(self._largest_eigenvalue(np.ones(n), np.ones(n, dtype=bool), iterations), 0.0)

    def _largest_eigenvalue(self, minv: np.ndarray, free: np.ndarray, iterations: int) -> float:
        """Largest eigenvalue of ``diag(minv) K`` on the components ``free`` by power iteration."""
        X = self.nodes.X
        f0 = self.internal_forces(X).ravel()
        rng = np.random.default_rng(0)
        v = rng.standard_normal(3 * len(X)) * free
        lam = 0.0
        eps = self.fd_step * self.length()
        for _ in range(iterations):
            v /= np.abs(v).max()
            Kv = (f0 - self.internal_forces(X + eps * v.reshape(-1, 3)).ravel()) / eps
            w = minv * Kv * free
            lam = float(np.dot(v, Kv) / np.dot(v, v / minv)) if np.any(v) else 0.0
            v = w
        return lam

    # ------------------------------------------------------------------ readouts
    def node_system(self) -> System:
        """The system seen on the engine's nodes (masses, prescribed components, plates): what
        :func:`hybmss.explicit.rest_report` needs."""
        return dataclasses.replace(self.system, X=self.nodes.X, mass=self.nodes.mass, fixed=self.nodes.fixed,
                                   plates=self.nodes.plates, gravity=self.gravity, terms=())

    def mean_stress(self, x: np.ndarray, f: np.ndarray) -> list:
        """Mean stress (3×3, Pa) from the forces on the held nodes (average-stress theorem for a
        body in equilibrium, ``σ̄ = (1/V) Σ_a R_a ⊗ x_a``, R = −f on the nodes with a prescribed
        component), for bodies without weight."""
        held = self.nodes.fixed.any(axis=1)
        sig = np.einsum("ai,aj->ij", -f[held], x[held]) / self.system.scene.body.volume
        return sig.tolist()

    def readout(self, x: np.ndarray, v: np.ndarray, f: np.ndarray, reactions: dict, rest: dict) -> dict:
        """The engine's own figures of the state at node positions ``x`` with its forces ``f``
        (for the loop's :class:`~hybmss.result.Result`): the volume of its deformed tetrahedra
        (``volume``, ``volume0``; the loop keeps the harness's averaged-edge cell formula as
        ``volume_cells``), the balance of the plate reactions against the weight, the mean stress,
        inverted tetrahedra, the engine's description, compile and step times, warnings."""
        xv = self.vertices(x)
        total = sum(np.asarray(r.force) for r in reactions.values())
        weight = (self.nodes.mass.sum() * np.asarray(self.gravity)) if self.gravity is not None else np.zeros(3)
        imbalance = float(np.linalg.norm(total + weight))
        vol = tet_volumes(xv, self.tets)
        return {
            "volume": float(vol.sum()), "volume0": float(tet_volumes(self.system.X, self.tets).sum()),
            "volume_from": "the engine's deformed tetrahedra",
            **self.describe(), "nodes": int(len(self.nodes.X)),
            "compile_time_s": self.compile_time_s, "step_time_s": self.step_time_s,
            "converged_criterion": "hybmss.explicit.rest_report",
            "reaction_balance": {"imbalance_N": imbalance, "force_scale_N": rest["force_scale_N"],
                                 "relative": imbalance / rest["force_scale_N"]},
            "mean_stress": self.mean_stress(x, f) if self.gravity is None else None,
            "inverted_tets": int(np.count_nonzero(vol <= 0.0)),
            "engine_warnings": list(self.warnings),
        }
