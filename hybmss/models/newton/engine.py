"""A scene as a Newton model (``newton`` ≥ 1.8 on ``warp-lang``), stepped by Newton's
``SolverSemiImplicit`` or ``SolverVBD`` on Warp's ``cpu`` device (laws: :mod:`hybmss.models.newton`).

Imported only when a ``newton-*`` model runs (importing Warp and Newton takes ~10 s, the first
use of its kernels compiles them into Warp's kernel cache, ~8 s per module, reported apart as
``compile_time_s``).

Scene translation
-----------------
- **Nodes**: one Newton particle per lattice particle (``ModelBuilder.add_particle``), mass the
  lumped ``ρ Vc/8`` per cell corner (set per particle), radius 0, no contact (no particle grid, no
  shapes).
- **Mesh**: Newton's own split of a grid cell, the one ``ModelBuilder.add_soft_grid`` makes
  (:data:`SPLIT_ODD` / :data:`SPLIT_EVEN`: 5 tetrahedra, the central one alternating with the
  parity of the cell's index so that neighbouring cells' faces match), each
  ``ModelBuilder.add_tetrahedron`` with its rest pose from the reference positions.
- **Plates**: after every ``solver.step`` the prescribed components are set to their targets at the
  new time and their velocities to the target's change over the step (the integrator is explicit
  and per particle, so this is the harness's scheme with its plates).  ``SolverVBD``: the plate
  nodes are kinematic particles (mass 0) put at their targets of the step's end before the step
  (its sweep solves the free nodes against them); the lumped mass stays in the harness's nodes
  (the reactions' weight term).
- **Damping**: the scene's mass-proportional c applied to Newton's step as the harness applies it
  (``v ← v'/(1 + c h)``, the position with it); the element damping ``k_damp`` is 0.  Gravity is
  Newton's (``ModelBuilder(gravity=...)``).
- **Precision**: Warp's particle state is float32: a position carries ~6e-8 of its size, and the
  forces of a rounded state are off by up to :meth:`NewtonBody.force_resolution`, derived from
  ε₃₂, the positions' magnitude and the engine's own stiffness (1e-2 N on a 1 m cube of
  E = 1e4 Pa in 0.5 m cells, 1 N at E = 1e6 Pa, 0.68 N for the former 100 m from the origin).  No
  state has a smaller free-force residual, so the rest criterion takes at least that resolution
  (:func:`hybmss.explicit.stepper_rest`), and a reaction carries an error of that order (the
  moduli answer's equilibrium error, :func:`hybmss.moduli.float32_errors`).

Readouts: the elastic force on a node is Newton's own tetrahedron kernel
(``newton/_src/solvers/semi_implicit/kernels_particle.py``, ``eval_tetrahedra_forces``, the
launch ``SolverSemiImplicit.step`` makes) into a cleared ``particle_f``; for ``SolverVBD`` its
``evaluate_volumetric_neo_hookean_force_and_hessian`` per tetrahedron and vertex (the force its
sweep balances), summed by :func:`_vbd_tet_forces`.
"""

from __future__ import annotations

import math
import time

import numpy as np

import warp as wp

wp.config.log_level = wp.LOG_WARNING  # no greeting nor module-load lines on stdout (a --json command's)


def _init_quietly() -> None:
    """``wp.init()`` with file descriptor 2 on /dev/null: on a machine without an NVIDIA driver Warp's
    native CUDA probe (warp/native/cuda_util.cpp) prints "Warp CUDA warning: Could not find or load
    the NVIDIA CUDA driver" to the process's stderr, once per process, a line that is not the
    command's (a sweep's workers would each add one).  Errors still raise; the device that ran is
    in each run's info."""
    import os
    import sys

    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            wp.init()
    finally:
        os.dup2(saved, 2)
        os.close(saved)


_init_quietly()

import newton  # noqa: E402
from newton._src.solvers.semi_implicit.kernels_particle import eval_tetrahedra_forces  # noqa: E402
from newton._src.solvers.vbd.particle_vbd_kernels import (  # noqa: E402
    evaluate_volumetric_neo_hookean_force_and_hessian)
from newton._src.solvers.xpbd.kernels import solve_tetrahedra  # noqa: E402

from ...system import System  # noqa: E402
from .._engine_body import EngineBody  # noqa: E402

ENGINE = "newton"
VERSION = f"newton {newton.__version__}, warp {wp.__version__}"

_V = (0, 1, 5, 4, 2, 3, 7, 6)
"""Newton's corner ``v0 … v7`` of a grid cell (``add_soft_grid``) in the harness's corner index
``c = di + 2 dj + 4 dk``."""
SPLIT_ODD = tuple(tuple(_V[a] for a in t) for t in ((0, 1, 4, 3), (2, 3, 6, 1), (5, 4, 1, 6), (7, 6, 3, 4),
                                                  (4, 1, 6, 3)))
SPLIT_EVEN = tuple(tuple(_V[a] for a in t) for t in ((1, 2, 5, 0), (3, 0, 7, 2), (4, 7, 0, 5), (6, 5, 2, 7),
                                                   (5, 2, 7, 0)))
"""Newton's 5-tetrahedron splits of a cell of odd / even ``i ^ j ^ k`` (harness corners)."""


def cell_tets(cells: np.ndarray, cell_ijk: np.ndarray) -> np.ndarray:
    """(5 m, 4) vertex indices of Newton's tetrahedra of the cells (m, 8) at grid indices (m, 3)."""
    cells = np.asarray(cells)
    odd = ((cell_ijk[:, 0] & 1) ^ (cell_ijk[:, 1] & 1) ^ (cell_ijk[:, 2] & 1)).astype(bool)
    loc = np.where(odd[:, None, None], np.array(SPLIT_ODD)[None], np.array(SPLIT_EVEN)[None])  # (m, 5, 4)
    return cells[np.arange(len(cells))[:, None, None], loc].reshape(-1, 4)


def lame(material) -> tuple[float, float]:
    """``(k_mu, k_lambda)`` of Newton's tetrahedron law for the material's (λ₀, μ₀): its energy
    ``μ/2 (I_C − 3) − μ/2 log(I_C + 1) + λ/2 (J − α)²``, α = 1 + 3μ/(4λ), has the small-strain
    Lamé parameters ``μ_lin = 3μ/4`` and ``λ_lin = λ − 5μ/8`` (Smith et al. 2018), so
    ``k_mu = 4μ₀/3`` and ``k_lambda = λ₀ + 5μ₀/6``."""
    mu0, lam0 = float(material.G), float(material.lam)
    return 4.0 * mu0 / 3.0, lam0 + 5.0 * mu0 / 6.0


def lame_vbd(material) -> tuple[float, float]:
    """``(k_mu, k_lambda)`` of ``SolverVBD``'s tetrahedron law for the material's (λ₀, μ₀): its
    ``evaluate_volumetric_neo_hookean_force_and_hessian`` takes ``μ_NH = k_mu``, ``λ_NH = k_lambda
    + k_mu``, ``P = μ_NH F + λ_NH (J − α) cof F``, α = 1 + μ_NH/λ_NH, whose linearization at F = I
    is ``μ_NH (H + Hᵀ) + (λ_NH − μ_NH) tr H I``: the Lamé parameters are k_mu and k_lambda as they
    are."""
    return float(material.G), float(material.lam)


@wp.kernel
def _vbd_tet_forces(pos: wp.array[wp.vec3], tet_indices: wp.array2d[wp.int32], tet_poses: wp.array[wp.mat33],
                    tet_materials: wp.array2d[float], f_out: wp.array[wp.vec3]):
    # SolverVBD's own force of a tetrahedron on one of its vertices (no damping: pos_prev = pos)
    t, v = wp.tid()
    f, h = evaluate_volumetric_neo_hookean_force_and_hessian(t, v, pos, pos, tet_indices, tet_poses[t],
                                                             tet_materials[t, 0], tet_materials[t, 1], 0.0, 1.0)
    wp.atomic_add(f_out, tet_indices[t, v], f)


def xpbd_constraint_forces(model, x: np.ndarray, dt: float = 1e-7) -> np.ndarray:
    """(N, 3) forces of ``SolverXPBD``'s tetrahedron constraints at positions ``x``: one launch of
    its ``solve_tetrahedra`` from zero multipliers with unit inverse masses and no relaxation, the
    corrections ``Δx_i = Δλ ∇_i C`` over ``dt²`` (the constraint force ``λ ∇C / dt²``); ``dt`` so
    short that ``Σ w |∇C|² dt²`` is ~1e-9 of the compliance ``1/(V k)``: the force is ``−∇U`` of
    the constraints' energy ``U = V (k_mu/2 C_dev² + k_lambda/2 C_vol²)``."""
    n, m = len(x), int(model.tet_count)
    q = wp.array(np.asarray(x, dtype=np.float32), dtype=wp.vec3, device="cpu")
    delta = wp.zeros(n, dtype=wp.vec3, device="cpu")
    lam_in, lam_out = wp.zeros(2 * m, dtype=float, device="cpu"), wp.zeros(2 * m, dtype=float, device="cpu")
    wp.launch(solve_tetrahedra, dim=m, device="cpu",
              inputs=[q, wp.zeros(n, dtype=wp.vec3, device="cpu"), wp.ones(n, dtype=float, device="cpu"),
                      model.tet_indices, model.tet_poses, wp.zeros(m, dtype=float, device="cpu"),
                      model.tet_materials, float(dt), 1.0, lam_in],
              outputs=[lam_out, delta])
    return delta.numpy().astype(np.float64) / (dt * dt)


VBD_ITERATIONS = 10
"""``SolverVBD``'s iterations per step: its own default (``iterations=None`` → 10)."""


class NewtonBody(EngineBody):
    """A scene's body stepped by Newton's ``SolverSemiImplicit`` (module docstring); the stepper
    protocol of :class:`hybmss.models._engine_body.EngineBody`."""

    fd_step = 1e-4
    """Finite-difference step of :meth:`omega_max` (of the cell edge): float32 positions resolve
    ~1e-7 of it."""

    def __init__(self, system: System, solver: str, dt: float, ramp_time: float, *, damping: float | None = None,
                 density: float | None = None, gravity="scene", iterations: int = VBD_ITERATIONS):
        if solver not in ("semi", "vbd"):
            raise ValueError(f"solver must be semi or vbd, got {solver!r}")
        self.solver_name = solver
        self.setup(system, 1, dt, ramp_time, damping, density, gravity)
        lat = system.lattice
        self.tets = cell_tets(lat.cells, lat.cell_ijk)
        self._build(system.scene.material, dt, iterations)

    split = "Newton's add_soft_grid split: 5 tetrahedra, alternating with the cell's parity"

    @classmethod
    def on_tets(cls, body, material, holds, solver: str, dt: float, ramp_time: float, *, damping: float = 0.0,
                density: float | None = None, iterations: int = VBD_ITERATIONS) -> "NewtonBody":
        """Newton's particles at the nodes of a :class:`hybmss.tetbody.TetBody` and one
        ``add_tetrahedron`` per tetrahedron of it (its rest pose from the nodes); ``holds``
        (:class:`hybmss.models._engine_tet.TetHold`) prescribe every component of their nodes."""
        if solver not in ("semi", "vbd"):
            raise ValueError(f"solver must be semi or vbd, got {solver!r}")
        self = cls.__new__(cls)
        self.solver_name = solver
        self.setup_tets(body, material, holds, dt, ramp_time, damping, density)
        self.tets = np.asarray(body.tets, dtype=np.int64)
        self.split = "the tetrahedra of the body's own mesh"
        self._build(material, dt, iterations)
        return self

    def _build(self, material, dt: float, iterations: int) -> None:
        vbd = self.solver_name == "vbd"
        k_mu, k_lambda = lame_vbd(material) if vbd else lame(material)
        # SolverVBD moves every particle of nonzero mass (a 3x3 block each): a node whose three
        # components are prescribed is its kinematic particle (mass 0), a slide node stays free
        # and has its prescribed components set after each step
        self.kinematic = self.nodes.fixed.all(axis=1) if vbd else np.zeros(len(self.nodes.X), dtype=bool)
        t0 = time.perf_counter()
        g = (0.0, 0.0, 0.0) if self.gravity is None else tuple(float(v) for v in self.gravity)
        b = newton.ModelBuilder(gravity=g)
        for x, m, kin in zip(self.nodes.X, self.nodes.mass, self.kinematic):
            b.add_particle(wp.vec3(*map(float, x)), wp.vec3(0.0, 0.0, 0.0), mass=0.0 if kin else float(m),
                           radius=0.0)
        for t in self.tets:
            b.add_tetrahedron(*map(int, t), k_mu=k_mu, k_lambda=k_lambda, k_damp=0.0)
        if vbd:
            b.color()  # SolverVBD's Gauss-Seidel sweeps go colour by colour
        self.model = b.finalize(device="cpu")
        self.model.particle_grid = None
        if vbd:
            self.iterations = int(iterations)
            self.engine_solver = newton.solvers.SolverVBD(self.model, iterations=self.iterations)
        else:
            self.engine_solver = newton.solvers.SolverSemiImplicit(self.model)
        self.control = self.model.control()
        self.s0, self.s1, self.probe = self.model.state(), self.model.state(), self.model.state()
        self.internal_forces(self.nodes.X)  # compiles the force kernel
        self.engine_solver.step(self.probe, self.model.state(), self.control, None, float(dt))  # and the step's
        self.compile_time_s = time.perf_counter() - t0
        self.k_mu, self.k_lambda = k_mu, k_lambda
        self.resolution_N = self.force_resolution()

    def force_resolution(self) -> float:
        """The free-force residual a float32 state cannot go below (N), derived: every position
        component is a float32 of magnitude at most ``|X|max``, so it carries a rounding
        ``|δx_i| ≤ ulp(|X|max)/2`` (``ulp(a) = 2^⌊log2 a⌋ ε₃₂``, ε₃₂ = 2⁻²³), and the forces at the
        rounded state differ from those at the exact one by ``‖K δx‖ ≤ ‖K‖₂ ‖δx‖ ≤
        ‖K‖₂ · ulp(|X|max)/2 · √(3N)``, ‖K‖₂ the engine's own stiffness at rest
        (:meth:`~hybmss.models._engine_body.EngineBody.stiffness_max`, N nodes).  Measured: 1.5–2×
        the largest change of 4 random ±1-ulp perturbations, above the residual the 10³ ν = 0.499
        compression comes to rest at (48.6 N, bound 71.6 N)."""
        X = self.nodes.X
        ulp = float(np.spacing(np.float32(np.abs(X).max())))
        return self.stiffness_max() * 0.5 * ulp * math.sqrt(3 * len(X))

    def describe(self) -> dict:
        return {"engine": ENGINE, "engine_version": VERSION, "element": "tet", "device": "cpu", "threads": 1,
                "integrator": "SolverVBD" if self.solver_name == "vbd" else "SolverSemiImplicit", "precision": "f32",
                "k_mu": self.k_mu, "k_lambda": self.k_lambda,
                **({"iterations": self.iterations} if self.solver_name == "vbd" else {}),
                "tet_split": self.split}

    def load(self, x: np.ndarray, v: np.ndarray, step0: int = 0) -> None:
        self.step = int(step0)
        self.s0.particle_q.assign(np.asarray(x, dtype=np.float32))
        self.s0.particle_qd.assign(np.asarray(v, dtype=np.float32))

    def _steps(self, step0: int, n: int) -> None:
        damp = 1.0 / (1.0 + self.damping * self.dt)
        spent = 0.0
        fx = self.fixed_dofs
        vbd = self.solver_name == "vbd"
        for k in range(step0, step0 + n):
            if vbd:  # the kinematic particles at their targets of the step's end before it
                u, _ = self.plate_targets(k + 1)
                q = self.s0.particle_q.numpy().reshape(-1)
                q[fx] = (self.nodes.X.ravel()[fx] + u).astype(np.float32)
            t0 = time.perf_counter()
            self.s0.clear_forces()
            self.engine_solver.step(self.s0, self.s1, self.control, None, self.dt)
            spent += time.perf_counter() - t0
            self.s0, self.s1 = self.s1, self.s0
            q = self.s0.particle_q.numpy().reshape(-1)  # views of the CPU arrays
            qd = self.s0.particle_qd.numpy().reshape(-1)
            if damp != 1.0:
                v1 = qd * np.float32(damp)
                q -= np.float32(self.dt) * (qd - v1)
                qd[:] = v1
            u, v = self.plate_targets(k + 1)
            q[fx] = (self.nodes.X.ravel()[fx] + u).astype(np.float32)
            qd[fx] = v.astype(np.float32)
        self.step_time_s += spent
        self.step = step0 + n

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        return (self.s0.particle_q.numpy().astype(np.float64).reshape(-1, 3),
                self.s0.particle_qd.numpy().astype(np.float64).reshape(-1, 3))

    def internal_forces(self, x: np.ndarray) -> np.ndarray:
        p = self.probe
        p.particle_q.assign(np.asarray(x, dtype=np.float32))
        p.particle_qd.zero_()
        p.clear_forces()
        if self.solver_name == "vbd":
            m = self.model
            wp.launch(_vbd_tet_forces, dim=(m.tet_count, 4), inputs=[p.particle_q, m.tet_indices, m.tet_poses,
                                                                      m.tet_materials], outputs=[p.particle_f],
                      device="cpu")
        else:
            eval_tetrahedra_forces(self.model, p, self.control, p.particle_f)
        return p.particle_f.numpy().astype(np.float64).reshape(-1, 3)

    def vertices(self, x: np.ndarray | None = None) -> np.ndarray:
        return self.state()[0] if x is None else np.asarray(x, dtype=float).copy()
