"""What the engine models share: the engine's nodes of a scene, its plates on them, and the
readouts of a state (reactions, mean stress, rest report, the balance of the reactions, the
:class:`~hybmss.result.Result`), whatever engine steps it (:mod:`hybmss.models.mujoco`,
:mod:`hybmss.models.newton`, :mod:`hybmss.models.pbd`).

A subclass builds its engine in ``__init__`` (after :meth:`EngineBody.setup`) and provides
``load(x, v)``, ``advance(step0, n) -> (done, bad)``, ``state() -> (x, v)``,
``internal_forces(x)`` (the engine's own force on each node), ``vertices(x=None)`` (the lattice
particles' positions as the engine places them), ``tets`` (the engine's tetrahedra on the lattice
particles, for the volume) and ``describe()`` (what ``info`` says about the engine).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..explicit import BLOWUP_FACTOR, ramp, rest_report
from ..result import Result, reaction_from_nodal
from ..system import PlateSet, System


def tet_volumes(x: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volumes of the tetrahedra ``tets`` at positions ``x``."""
    p = x[tets]
    return np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6.0


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



class EngineBody:
    """The engine-independent part of a body stepped by an engine (module docstring)."""

    fd_step = 1e-7
    """Finite-difference step of :meth:`omega_max`, in cell edges."""
    resolution_N = 0.0
    """Force resolution of the engine's state (N): the change of the free nodes' force norm under
    position changes of one unit in the last place (0: a float64 engine, negligible).  A rest
    state cannot have a smaller residual, so :meth:`rest` accepts one within it."""

    def setup(self, system: System, order: int, dt: float, ramp_time: float, damping: float | None,
              density: float | None, gravity) -> None:
        self.system = system
        self.dt, self.ramp_time = float(dt), float(ramp_time)
        rho = system.scene.material.rho if density is None else float(density)
        self.gravity = system.gravity if isinstance(gravity, str) else gravity
        self.damping = float(system.scene.damping if damping is None else damping)
        self.nodes = engine_nodes(system, order, rho)
        self.fixed_dofs = np.flatnonzero(self.nodes.fixed.ravel())
        self.step = 0
        self.step_time_s = 0.0
        self.compile_time_s = 0.0
        self.warnings: list[str] = []

    # ------------------------------------------------------------------ prescribed motion
    def prescribed(self, s: float) -> np.ndarray:
        """Target node positions (N, 3) at load factor ``s`` (free components at reference)."""
        X = self.nodes.X
        x = X.copy()
        for plate, ps, c in zip(self.system.scene.plates, self.nodes.plates, self.nodes.centers):
            motion = plate.motion if c is None else dataclasses.replace(plate.motion, center=c)
            u = motion.displacement_at(X[ps.particles], s)
            for d in np.flatnonzero(ps.constrained):
                x[ps.particles, d] = X[ps.particles, d] + u[:, d]
        return x

    def plate_targets(self, step: int) -> tuple[np.ndarray, np.ndarray]:
        """Displacements and velocities (flat, on :attr:`fixed_dofs`) of the prescribed
        components at ``step``: the target ``u(s(t))`` and its change over the last step / dt."""
        t = step * self.dt
        now = (self.prescribed(ramp(t, self.ramp_time)) - self.nodes.X).ravel()[self.fixed_dofs]
        before = (self.prescribed(ramp(t - self.dt, self.ramp_time)) - self.nodes.X).ravel()[self.fixed_dofs]
        return now, (now - before) / self.dt

    def bad_node(self) -> int:
        x, _ = self.state()
        u = x - self.nodes.X
        u2 = np.einsum("ij,ij->i", u, u)
        bad = np.flatnonzero(~np.isfinite(u2))
        if len(bad):
            return int(bad[0])
        limit = BLOWUP_FACTOR * max(self.system.scene.body.size)
        i = int(np.argmax(u2))
        return i if u2[i] > limit * limit else -1

    def energy(self, x: np.ndarray, v: np.ndarray) -> dict:
        """Kinetic energy of the nodes (MuJoCo exposes no flex strain energy)."""
        return {"kinetic": float(0.5 * np.sum(self.nodes.mass[:, None] * np.asarray(v) ** 2))}

    # ------------------------------------------------------------------ frequencies
    def omega_max(self, iterations: int = 60) -> float:
        """Highest frequency (rad/s) of ``M⁻¹K`` at rest on the free components, K from MuJoCo's
        own forces (finite differences of ``qfrc_spring`` about the reference), by power
        iteration (Rayleigh quotient of the last iterate, a lower bound converging from below)."""
        free = ~self.nodes.fixed.ravel()
        minv = np.repeat(1.0 / self.nodes.mass, 3)
        X = self.nodes.X
        f0 = self.internal_forces(X).ravel()
        rng = np.random.default_rng(0)
        v = rng.standard_normal(3 * len(X)) * free
        lam = 0.0
        eps = self.fd_step * float(self.system.scene.body.le)
        for _ in range(iterations):
            v /= np.abs(v).max()
            Kv = (f0 - self.internal_forces(X + eps * v.reshape(-1, 3)).ravel()) / eps
            w = minv * Kv * free
            lam = float(np.dot(v, Kv) / np.dot(v, v / minv)) if np.any(v) else 0.0
            v = w
        return math.sqrt(max(lam, 0.0))

    # ------------------------------------------------------------------ readouts
    def node_system(self) -> System:
        """The system seen on the engine's nodes (masses, prescribed components, plates): what
        :func:`hybmss.explicit.rest_report` needs."""
        return dataclasses.replace(self.system, X=self.nodes.X, mass=self.nodes.mass, fixed=self.nodes.fixed,
                                   plates=self.nodes.plates, gravity=self.gravity, terms=())

    def reactions(self, x: np.ndarray, f: np.ndarray) -> dict:
        """Plate reactions ``−Σ (f + m g)`` over each plate's nodes, prescribed components only."""
        out = {}
        for ps in self.nodes.plates:
            r = -f[ps.particles]
            if self.gravity is not None:
                r = r - self.nodes.mass[ps.particles, None] * np.asarray(self.gravity)[None, :]
            out[ps.name] = reaction_from_nodal(x[ps.particles], r * ps.constrained[None, :])
        return out

    def mean_stress(self, x: np.ndarray, f: np.ndarray) -> list:
        """Mean stress (3×3, Pa) from the forces on the held nodes (average-stress theorem for a
        body in equilibrium, ``σ̄ = (1/V) Σ_a R_a ⊗ x_a``, R = −f on the nodes with a prescribed
        component), for bodies without weight."""
        held = self.nodes.fixed.any(axis=1)
        sig = np.einsum("ai,aj->ij", -f[held], x[held]) / self.system.scene.body.volume
        return sig.tolist()

    def rest(self, x: np.ndarray, v: np.ndarray, f: np.ndarray, rtol: float) -> dict:
        """:func:`hybmss.explicit.rest_report` of the state on the engine's nodes; for an engine
        with a force resolution (:attr:`resolution_N`) the tolerance is at least that resolution
        over the force scale (``resolution_N`` in the report)."""
        S = self.node_system()
        energy = self.energy(x, v)
        load = ramp(self.step * self.dt, self.ramp_time)
        rest = rest_report(S, f, energy, load, rtol)
        if self.resolution_N > 0.0:
            rest = rest_report(S, f, energy, load, max(rtol, self.resolution_N / rest["force_scale_N"]))
            rest["resolution_N"] = self.resolution_N
        return rest

    def result(self, solver: str, steps: int, rest_rtol: float, info: dict) -> Result:
        """The :class:`~hybmss.result.Result` of the current state: displacements at the lattice
        particles, the engine's reactions, the flex's deformed volume, the rest report and the
        balance of the plate reactions against the weight."""
        x, v = self.state()
        f = self.internal_forces(x)
        xv = self.vertices()
        energy = self.energy(x, v)
        rest = self.rest(x, v, f, rest_rtol)
        reactions = self.reactions(x, f)
        total = sum(np.asarray(r.force) for r in reactions.values())
        weight = (self.nodes.mass.sum() * np.asarray(self.gravity)) if self.gravity is not None else np.zeros(3)
        imbalance = float(np.linalg.norm(total + weight))
        lat = self.system.lattice
        vol = tet_volumes(xv, self.tets)
        info = dict(info)
        info.update({
            **self.describe(), "nodes": int(len(self.nodes.X)),
            "compile_time_s": self.compile_time_s, "step_time_s": self.step_time_s,
            "rest": rest, "converged_criterion": "hybmss.explicit.rest_report",
            "reaction_balance": {"imbalance_N": imbalance, "force_scale_N": rest["force_scale_N"],
                                 "relative": imbalance / rest["force_scale_N"]},
            "mean_stress": self.mean_stress(x, f) if self.gravity is None else None,
            "inverted_tets": int(np.count_nonzero(vol <= 0.0)),
            "max_speed": float(np.linalg.norm(v, axis=1).max()) if len(v) else 0.0,
            "engine_warnings": list(self.warnings),
        })
        X = self.system.X
        return Result(solver=solver, scene_digest=self.system.scene.digest(), X=X.copy(), u=xv - X,
                      volume=float(vol.sum()), volume0=float(tet_volumes(X, self.tets).sum()), reactions=reactions,
                      energy=energy, iterations=int(steps), wall_time_s=float(self.step_time_s),
                      converged=bool(rest["at_rest"]), cell_volumes=lat.cell_volumes(xv), info=info)
