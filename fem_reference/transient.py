"""The FEM transient of a scene: the body at static equilibrium under its load, released at t = 0.

Equation of motion on the free dofs (the plates hold their dofs at their static values):

    M ü + f_int(u) = 0,      u(0) = u_s,  u̇(0) = 0,

with ``u_s`` the static equilibrium under the scene's load (gravity ``ρ g`` and surface tractions,
from the existing static references :class:`~fem_reference.linear.LinearElasticity` and
:class:`~fem_reference.hyperelastic.Hyperelasticity`), the load removed at t = 0; ``M = ∫ ρ N_a N_b``
the consistent mass (each of the three components); ``f_int = K u`` (small strain,
``K = λ K_λ + μ K_μ``) or ``∫ P(F) : ∇v dX`` (Neo-Hookean, total Lagrangian).

Time integration: Newmark's average acceleration (β = ¼, γ = ½, the trapezoidal rule)::

    u_{n+1} = u_n + Δt v_n + Δt²/4 (a_n + a_{n+1})
    v_{n+1} = v_n + Δt/2 (a_n + a_{n+1})
    M a_{n+1} + f_int(u_{n+1}) = 0

i.e. ``(K + 4/Δt² M) u_{n+1} = M (4/Δt² u_n + 4/Δt v_n + a_n)`` for the linear law (one
factorization per run), and Newton on ``R(u) = M (4/Δt² (u − u_n) − 4/Δt v_n − a_n) + f_int(u)``
with the tangent ``4/Δt² M + K_T(u)`` for the Neo-Hookean law.  The scheme is unconditionally
stable and, for a linear system, conserves ``E = ½ vᵀ M v + ½ uᵀ K u`` exactly; it adds no
damping, and a mode of frequency ω has the period ``T_num / T = ωΔt / (2 arctan(ωΔt/2))``
(:func:`newmark_period_ratio`).  The displacement elements are Hex1 and Hex2; the mixed element
has no transient here.
"""

from __future__ import annotations

import math
import time
from functools import cached_property

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from hybmss.scene import Scene
from hybmss.trajectory import Trajectory

from .dirichlet import plate_dirichlet
from .linear import LinearElasticity
from .solve import operators

NEWTON_RTOL = 1e-10
"""Newton tolerance of a Neo-Hookean step, relative to the force of the released load (plus the
static solver's absolute floor ``1e-12 μ V^(2/3)``)."""
NEWTON_MAXITER = 25


def newmark_period_ratio(omega_dt):
    """``T_num / T`` of average acceleration for a mode with ``ω Δt``: ``ωΔt / (2 arctan(ωΔt/2))``."""
    x = np.asarray(omega_dt, dtype=float)
    return x / (2.0 * np.arctan(0.5 * x))


def newmark_step_for(omega: float, period_tol: float) -> float:
    """The largest ``Δt`` whose period elongation of a mode ``ω`` is at most ``period_tol``
    (from :func:`newmark_period_ratio`, ≈ 1 + (ωΔt)²/12: bisection on ωΔt in (0, π))."""
    lo, hi = 0.0, math.pi
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if newmark_period_ratio(mid) - 1.0 <= period_tol:
            lo = mid
        else:
            hi = mid
    return lo / omega


def nearest_particle(scene_or_lattice_X: np.ndarray, point) -> int:
    """Index of the lattice particle nearest ``point`` (the named point of a transient)."""
    X = np.asarray(scene_or_lattice_X, dtype=float)
    return int(np.argmin(np.linalg.norm(X - np.asarray(point, dtype=float), axis=1)))


class ReleasedFem:
    """The FEM of ``scene`` (element ``hex1``/``hex2``, law ``linear`` or ``neo-hookean``): its
    static state under the load and its mass, built once; :meth:`run` steps the release with a
    given ``Δt``."""

    def __init__(self, scene: Scene, element: str = "hex2", law: str = "linear", refine: int = 1):
        if element not in ("hex1", "hex2"):
            raise ValueError(f"element must be hex1 or hex2 for the FEM transient, got {element!r}")
        if law not in ("linear", "neo-hookean"):
            raise ValueError(f"law must be linear or neo-hookean for the FEM transient, got {law!r}")
        if scene.material.rho <= 0:
            raise ValueError(f"rho must be > 0 for a transient, got {scene.material.rho:g}")
        if not scene.has_gravity and not scene.loads:
            raise ValueError("the scene has no load (gravity or surface load) to release")
        self.scene, self.element, self.law = scene, element, law
        self.ops = operators(scene, element, law, refine)
        self.space = self.ops.space
        self.dirichlet = plate_dirichlet(scene, self.space)
        if len(self.dirichlet.dofs) == 0:
            raise ValueError("the plates select no FEM node: check their regions")
        n = self.space.n_vector
        self.free = np.ones(n, dtype=bool)
        self.free[self.dirichlet.dofs] = False
        self.M = sp.kron(self.space.mass(scene.material.rho), sp.identity(3), format="csr")
        self.zero = np.zeros(n)

    @cached_property
    def load(self) -> np.ndarray:
        """The released load vector ``f`` (n_vector,): gravity and surface tractions."""
        from .loads import load_vector

        g = self.scene.gravity if self.scene.has_gravity else (0.0, 0.0, 0.0)
        f = self.space.body_load(self.scene.material.rho * np.asarray(g, float))
        return f + load_vector(self.scene, self.space) if self.scene.loads else f

    @cached_property
    def static(self) -> np.ndarray:
        """``u_s`` (n_vector,): the static equilibrium under the load (the start of the release)."""
        scene, mat = self.scene, self.scene.material
        g = scene.gravity if scene.has_gravity else (0.0, 0.0, 0.0)
        traction = None
        if scene.loads:
            from .loads import load_vector

            traction = load_vector(scene, self.space)
        if isinstance(self.ops, LinearElasticity):
            sol = self.ops.solve(mat, self.dirichlet, g, load=traction)
        else:
            sol, _ = self.ops.solve(mat, self.dirichlet, g, load=traction)
        return sol.U.reshape(-1).copy()

    @cached_property
    def K(self) -> sp.csr_matrix | None:
        """The small-strain stiffness (linear law), else ``None``."""
        if not isinstance(self.ops, LinearElasticity):
            return None
        Klam, Kmu = self.ops.parts
        return (self.scene.material.lam * Klam + self.scene.material.G * Kmu).tocsr()

    def internal(self, U: np.ndarray, tangent: bool = False):
        """``(f_int(U), K_T or None, strain energy)``; ``None`` for an inverted element."""
        if self.K is not None:
            f = self.K @ U
            return f, (self.K if tangent else None), 0.5 * float(U @ f)
        st = self.ops._evaluate(U, None, 0.0, self.zero, self.scene.material, tangent)
        if st is None:
            return None
        return st["fint"], st.get("K"), self.space.integrate(st["psi"])

    @cached_property
    def omega_rayleigh(self) -> float:
        """Rayleigh quotient of the static shape, ``ω² ≈ u_sᵀ f_int(u_s) / u_sᵀ M u_s`` (an upper
        bound of ω₁² for the linear law, and close to it when the load excites mostly the first mode)."""
        u = self.static
        f, _, _ = self.internal(u)
        return math.sqrt(max(float(u @ f), 0.0) / float(u @ (self.M @ u)))

    def particle_dof(self, point) -> tuple[int, tuple[float, float, float]]:
        """Scalar dof of the lattice particle nearest ``point`` and that particle's position."""
        X = self.ops.fmesh.lattice.X
        k = nearest_particle(X, point)
        return int(self.space.particle_dofs[k]), tuple(float(c) for c in X[k])

    def run(self, dt: float, t_end: float, point, record_every: int = 1, u0: np.ndarray | None = None) -> Trajectory:
        """Release from :attr:`static` (or from the displacement ``u0`` (n_vector,), e.g. a mode
        shape, with the held dofs at their static values) and step ``Δt`` up to ``t_end``; the
        displacement of the lattice particle nearest ``point`` every ``record_every`` steps (and at t = 0)."""
        dt, t_end = float(dt), float(t_end)
        if not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be > 0 s, got {dt}")
        if not (t_end >= dt and math.isfinite(t_end)):
            raise ValueError(f"t_end must be >= dt = {dt:g} s, got {t_end}")
        dof, X = self.particle_dof(point)
        steps = int(round(t_end / dt))
        every = max(1, int(record_every))
        start = self.static.copy()
        if u0 is not None:
            start[self.free] = np.asarray(u0, dtype=float).reshape(-1)[self.free]
        stepper = _LinearNewmark(self, dt, start) if self.K is not None else _NewtonNewmark(self, dt, start)
        ts, us, es = [0.0], [stepper.U[3 * dof:3 * dof + 3].copy()], [stepper.energy()]
        t0 = time.perf_counter()
        status, reason = "ok", ""
        for k in range(1, steps + 1):
            why = stepper.step()
            if why:
                status, reason = "failed", f"step {k} (t = {k * dt:.4g} s): {why}"
                break
            if k % every == 0 or k == steps:
                ts.append(k * dt)
                us.append(stepper.U[3 * dof:3 * dof + 3].copy())
                es.append(stepper.energy())
        wall = time.perf_counter() - t0
        info = {"element": self.element, "law": self.law, "refine": int(self.ops.fmesh.refine),
                "scheme": "newmark average acceleration (beta=1/4, gamma=1/2), consistent mass",
                "omega_rayleigh": self.omega_rayleigh, "n_dofs": int(self.space.n_vector), "steps": len(ts) - 1,
                "newton_iterations": int(getattr(stepper, "iterations", 0))}
        return Trajectory(f"fem-{self.element}-{self.law}", np.array(ts), np.array(us), X, dt, wall,
                          np.array(es), status, reason, info)


class _Newmark:
    """State ``(U, V, A)`` of average acceleration on the full vector dofs (held dofs fixed)."""

    def __init__(self, fem: ReleasedFem, dt: float, start: np.ndarray):
        self.fem, self.dt = fem, dt
        self.c0, self.c1 = 4.0 / dt**2, 4.0 / dt
        self.U = start.copy()
        self.V = np.zeros_like(self.U)
        self.A = np.zeros_like(self.U)
        self.free = fem.free
        self.Mff = fem.M[self.free][:, self.free].tocsc()
        f, _, self.strain = fem.internal(self.U)
        self.A[self.free] = spla.spsolve(self.Mff, -f[self.free])  # released: M a₀ = −f_int(u_s)

    def energy(self) -> float:
        return 0.5 * float(self.V @ (self.fem.M @ self.V)) + self.strain

    def finish(self, U_new: np.ndarray, strain: float) -> None:
        A_new = self.c0 * (U_new - self.U) - self.c1 * self.V - self.A
        A_new[~self.free] = 0.0
        self.V = self.V + 0.5 * self.dt * (self.A + A_new)
        self.U, self.A, self.strain = U_new, A_new, strain


class _LinearNewmark(_Newmark):
    """One factorization of ``K + 4/Δt² M`` on the free dofs."""

    def __init__(self, fem: ReleasedFem, dt: float, start: np.ndarray):
        super().__init__(fem, dt, start)
        f = self.free
        K = fem.K
        self.lu = spla.splu((K[f][:, f] + self.c0 * fem.M[f][:, f]).tocsc())
        self.KfD = K[f][:, ~f]
        self.uD = self.U[~f].copy()

    def step(self) -> str:
        f = self.free
        rhs = self.fem.M @ (self.c0 * self.U + self.c1 * self.V + self.A)
        U_new = self.U.copy()
        U_new[f] = self.lu.solve(rhs[f] - self.KfD @ self.uD)
        if not np.all(np.isfinite(U_new)):
            return "non-finite displacement"
        self.finish(U_new, 0.5 * float(U_new @ (self.fem.K @ U_new)))
        return ""


class _NewtonNewmark(_Newmark):
    """Newton on the dynamic residual per step (Neo-Hookean law)."""

    iterations = 0

    def __init__(self, fem: ReleasedFem, dt: float, start: np.ndarray):
        super().__init__(fem, dt, start)
        body = fem.scene.body
        # the static solver's tolerance: relative to the load's force, plus its absolute floor
        self.tol = NEWTON_RTOL * float(np.linalg.norm(fem.load[self.free])) \
            + 1e-12 * fem.scene.material.G * body.volume ** (2.0 / 3.0)

    def step(self) -> str:
        fem, f, M = self.fem, self.free, self.fem.M
        U = self.U + self.dt * self.V + 0.25 * self.dt**2 * self.A  # predictor: a_{n+1} = a_n
        inertia0 = self.c0 * self.U + self.c1 * self.V + self.A
        for _ in range(NEWTON_MAXITER):
            ev = fem.internal(U, tangent=True)
            if ev is None:
                return "an element inverted (det F <= 0)"
            fint, KT, strain = ev
            R = (M @ (self.c0 * U - inertia0) + fint)[f]
            if np.linalg.norm(R) <= self.tol:
                self.finish(U, strain)
                return ""
            self.iterations += 1
            J = (KT[f][:, f] + self.c0 * M[f][:, f]).tocsc()
            U = U.copy()
            U[f] -= spla.spsolve(J, R)
        return f"Newton did not converge in {NEWTON_MAXITER} iterations"
