"""XPBD with the stable Neo-Hookean constraints on the voxel grid: ``xpbd-nh`` (SPEC §10).

What a real-time physics user runs instead of a mass-spring system (Macklin, Müller, Chentanez
2016; Macklin & Müller 2021), built on the MSS's grid: nodes are the lattice particles, masses the
lumped ``ρ Vc/8`` per cell corner, the same plates and ramp.

Elements.  Each cube is split into tetrahedra **twice**, by the two complementary 5-tet splits:
split A has the central tetrahedron on the even corners (0, 3, 5, 6) (corner index
``c = di + 2 dj + 4 dk``, even ``di + dj + dk``) and one corner tetrahedron at each odd corner with
its three neighbours; split B the mirror (central tetrahedron on 1, 2, 4, 7).  Each of the 10
tetrahedra carries half its rest volume, so a cell has no preferred diagonal (the union is
invariant under the cube's symmetries that swap the two splits) and any affine deformation costs
exactly ``Vc ψ(F)``.  Per tetrahedron ``F = D_s D_m⁻¹`` (edge matrices of x and X from its first
vertex).

Constraints (Macklin & Müller 2021), per tetrahedron of weighted rest volume V:
``C_D = √tr(FᵀF)`` with compliance ``α_D = 1/(μ V)`` and ``C_H = det F − γ`` with
``α_H = 1/(λ V)``, ``γ = 1 + μ/λ``.  Together they store ``V (μ/2 tr(FᵀF) + λ/2 (J − γ)²)``,
stress-free at F = I.  **Lamé trap** (SPEC §10): linearized at F = I this energy has the Lamé
parameters ``μ_lin = μ`` and ``λ_lin = λ − μ``, so for a material of Lamé (λ₀, μ₀) the model takes
``μ = μ₀`` and ``λ = λ₀ + μ₀`` (always > 0 for ν ∈ (−1, ½)); ``hybmss moduli`` checks it.

One substep of size ``h`` (frame ``dt`` split into ``substeps``; "small steps", Macklin et al.
2019, is the accurate setting: the default is 10 substeps of one iteration each)::

    v ← (v + h g) / (1 + c h)                          (damping c of the scene, implicit as the MSS)
    x_prev ← x;  x ← x + h v;  prescribed components ← X + u(s(t + h))   (their w = 0)
    repeat `iterations` times, tetrahedra in order:  C_D then C_H:
        Δλ = (−C − α̃ λ) / (Σ_i ∇_i Cᵀ W_i ∇_i C + α̃),  α̃ = α/h²,  x_i ← x_i + W_i ∇_i C Δλ,  λ ← λ + Δλ
    v ← (x − x_prev) / h

with ``W_i = diag(1/m_i)`` except 0 on prescribed components (sliding plates prescribe only some),
multipliers reset every substep.  Explicit only.

Its static answer is the rest state of a damped run (:func:`solve_static`).  That state is not
exactly the minimizer of the energy: with one iteration per substep, a stationary point of the
iteration satisfies ``Σ_j ∇C_j C_j / (α_j + h² ∇C_jᵀ W ∇C_j) = 0``, i.e. each constraint acts with
the compliance ``α + h² ∇CᵀW∇C`` instead of α, a relative stiffness bias of order
``(h ω_e)²`` (ω_e an element's own frequency), which vanishes as the substeps shrink.
"""

from __future__ import annotations

import math
import time

import numpy as np

from .. import _kernels_xpbd
from ..explicit import ramp
from ..lattice import CORNERS
from ..result import Result
from ..scene import Material
from ..system import System
from .corot_hex8 import CorotHex8, frequency_range
from ._voxel_explicit import blowup_limit2, divergence, find_bad, plate_arrays, run_result

KERNELS = ("numba", "numpy")


def _split(central: tuple[int, ...]) -> list[tuple[int, ...]]:
    """A 5-tet split of the cube: the central tetrahedron on ``central`` and, at each other
    corner, the tetrahedron with its three edge neighbours."""
    tets = [tuple(central)]
    for c in range(8):
        if c in central:
            continue
        tets.append((c,) + tuple(c ^ (1 << d) for d in range(3)))
    return tets


SPLIT_A = _split((0, 3, 5, 6))
SPLIT_B = _split((1, 2, 4, 7))
CELL_TETS = np.array(SPLIT_A + SPLIT_B, dtype=np.int64)
"""(10, 4) local corners of a cell's tetrahedra: the two complementary 5-tet splits."""


def cell_tetrahedra(le: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(local corners (10, 4) positively oriented, D_m⁻¹ (10, 3, 3), weighted volumes (10,))``
    of one cell of edge ``le``: each split carries half the cell."""
    P = CORNERS * float(le)
    tets = CELL_TETS.copy()
    Dinv, V = [], []
    for t in tets:
        D = (P[t[1:]] - P[t[0]]).T
        if np.linalg.det(D) < 0:
            t[[2, 3]] = t[[3, 2]]
            D = (P[t[1:]] - P[t[0]]).T
        Dinv.append(np.linalg.inv(D))
        V.append(0.5 * np.linalg.det(D) / 6.0)
    return tets, np.array(Dinv), np.array(V)


def xpbd_lame(material: Material) -> tuple[float, float, float]:
    """``(μ, λ, γ)`` of the constraints for a material of Lamé (λ₀, μ₀): μ = μ₀, λ = λ₀ + μ₀,
    γ = 1 + μ/λ (module docstring, "Lamé trap")."""
    mu = float(material.G)
    lam = float(material.lam) + mu
    return mu, lam, 1.0 + mu / lam


class XpbdNH:
    """The constraints of a body.  As a :class:`hybmss.terms.ForceTerm` it is the energy the
    constraints store, ``Σ_t V_t (μ/2 (tr FᵀF − 3) + λ/2 (J − γ)² − λ/2 (1 − γ)²)`` (zero at rest),
    with its exact forces; reactions and moduli are read from these forces at the rest state.
    No stiffness: the model is explicit only."""

    name = "xpbd-nh"
    conservative = True
    scaled = False

    def __init__(self, lattice, material: Material):
        self.le = float(lattice.body.le)
        self.X = np.asarray(lattice.X, dtype=float)
        local, Dinv, V = cell_tetrahedra(self.le)
        cells = np.asarray(lattice.cells, dtype=np.int64)
        m = len(cells)
        self.tets = np.ascontiguousarray(cells[:, local].reshape(-1, 4))
        self.Dminv = np.ascontiguousarray(np.tile(Dinv, (m, 1, 1)))
        self.Vt = np.ascontiguousarray(np.tile(V, m))
        self.mu, self.lam, self.gamma = xpbd_lame(material)

    def deformation_gradients(self, x: np.ndarray) -> np.ndarray:
        xt = np.asarray(x)[self.tets]
        Ds = np.swapaxes(xt[:, 1:] - xt[:, :1], 1, 2)
        return Ds @ self.Dminv

    def energy(self, x: np.ndarray) -> float:
        F = self.deformation_gradients(x)
        J = np.linalg.det(F)
        psi = (0.5 * self.mu * (np.einsum("tij,tij->t", F, F) - 3.0) + 0.5 * self.lam * (J - self.gamma) ** 2
               - 0.5 * self.lam * (1.0 - self.gamma) ** 2)
        return float(np.dot(self.Vt, psi))

    def forces(self, x: np.ndarray) -> np.ndarray:
        """``−∇E`` (n, 3): per tetrahedron ``P = μ F + λ (J − γ) cof F``, node forces
        ``−V P D_m⁻ᵀ`` (node 0: minus their sum)."""
        F = self.deformation_gradients(x)
        J = np.linalg.det(F)
        cof = J[:, None, None] * np.swapaxes(np.linalg.inv(F), 1, 2)
        P = self.mu * F + (self.lam * (J - self.gamma))[:, None, None] * cof
        H = -self.Vt[:, None, None] * (P @ np.swapaxes(self.Dminv, 1, 2))  # column j: node j+1
        fe = np.concatenate([-H.sum(axis=2)[:, None, :], np.swapaxes(H, 1, 2)], axis=1)  # (T, 4, 3)
        f = np.zeros_like(np.asarray(x, dtype=float))
        np.add.at(f, self.tets.ravel(), fe.reshape(-1, 3))
        return f

    def stiffness(self, x: np.ndarray):
        raise NotImplementedError("xpbd-nh is explicit only: it has no static tangent")


# ------------------------------------------------------------------------------ NumPy twin
def _constraint(F: np.ndarray, kind: int, gamma: float) -> tuple[float, np.ndarray]:
    """C and ∂C/∂F of the deviatoric (0) or hydrostatic (1) constraint."""
    if kind == 0:
        C = math.sqrt(float(np.sum(F * F)))
        return C, F / C
    cof = np.empty((3, 3))
    for a in range(3):
        a1, a2 = (a + 1) % 3, (a + 2) % 3
        for b in range(3):
            b1, b2 = (b + 1) % 3, (b + 2) % 3
            cof[a, b] = F[a1, b1] * F[a2, b2] - F[a1, b2] * F[a2, b1]
    return float(np.sum(F[0] * cof[0])) - gamma, cof


def _tet_constraint(term: XpbdNH, x: np.ndarray, t: int, kind: int) -> tuple[float, np.ndarray]:
    """C and its node gradients (4, 3) of constraint ``kind`` of tetrahedron ``t``."""
    xt = x[term.tets[t]]
    F = (xt[1:] - xt[0]).T @ term.Dminv[t]
    C, dC = _constraint(F, kind, term.gamma)
    G = dC @ term.Dminv[t].T  # column j: gradient at node j+1
    return C, np.vstack([-G.sum(axis=1), G.T])


def numpy_substep(term: XpbdNH, x, v, winv, h, damp, iterations, gravity, set_plates, coupled=True):
    """One substep of the readable twin on (n, 3) arrays, in place (module docstring).
    ``set_plates(x)`` moves the prescribed components to their targets at t + h."""
    if gravity is not None:
        v += h * gravity[None, :]
    v *= damp
    x_prev = x.copy()
    x += h * v
    set_plates(x)
    lamb = np.zeros((len(term.tets), 2))
    for _ in range(iterations):
        for t, nodes in enumerate(term.tets):
            w = winv[nodes]
            alpha = 1.0 / (np.array([term.mu, term.lam]) * term.Vt[t] * h * h)
            if coupled:  # both constraints of the tetrahedron in one 2×2 solve
                CD, gD = _tet_constraint(term, x, t, 0)
                CH, gH = _tet_constraint(term, x, t, 1)
                A = np.array([[alpha[0] + np.sum(w * gD * gD), np.sum(w * gD * gH)],
                              [np.sum(w * gH * gD), alpha[1] + np.sum(w * gH * gH)]])
                b = np.array([-CD, -CH]) - alpha * lamb[t]
                det = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
                d = np.array([A[1, 1] * b[0] - A[0, 1] * b[1], A[0, 0] * b[1] - A[0, 1] * b[0]]) / det
                x[nodes] += w * (gD * d[0] + gH * d[1])
                lamb[t] += d
            else:  # C_D, then C_H at the updated positions
                for kind in (0, 1):
                    C, g = _tet_constraint(term, x, t, kind)
                    d = (-C - alpha[kind] * lamb[t, kind]) / (float(np.sum(w * g * g)) + alpha[kind])
                    x[nodes] += w * g * d
                    lamb[t, kind] += d
    v[:] = (x - x_prev) / h


# ------------------------------------------------------------------------------ runs
def inverse_masses(system: System) -> np.ndarray:
    """(n, 3) 1/m per component, 0 on prescribed components."""
    w = np.repeat((1.0 / system.mass)[:, None], 3, axis=1)
    w[system.fixed] = 0.0
    return w


def frequencies(system: System, material: Material | None = None) -> tuple[float, float]:
    """``(ω₁, ω_max)`` (rad/s) of the body at rest, from the linear Hex8 stiffness of the same grid
    and material (the small-strain limit of the constraints' energy on the same cells): they set
    the defaults of :func:`solve_static`."""
    mat = system.scene.material if material is None else material
    return frequency_range(system, CorotHex8(system.lattice, mat))


def simulate_explicit(system: System, term: XpbdNH, dt: float = 1e-3, steps: int = 10_000, kernel: str = "numba",
                      ramp_time: float = 1.0, *, substeps: int = 10, iterations: int = 1, coupled: bool = True,
                      check_every: int = 10, until_rest: bool = False, rest_tol: float = 1e-9,
                      damping: float | None = None) -> Result:
    """XPBD run of ``steps`` frames of ``dt``, each of ``substeps`` substeps with ``iterations``
    Gauss–Seidel sweeps, the two constraints of a tetrahedron solved together (``coupled``) or
    one after the other.  Damping is ``scene.damping`` unless ``damping`` is given.  Divergence is
    checked every ``check_every`` frames; with ``until_rest`` the run stops after the ramp once no
    node moved more than ``rest_tol · le`` over ``check_every`` frames (``info['rest']``,
    ``info['t_rest']``).  ``wall_time_s`` is the stepping alone."""
    if kernel not in KERNELS:
        raise ValueError(f"kernel must be one of {', '.join(KERNELS)}; got {kernel!r}")
    dt, steps, substeps, iterations = float(dt), int(steps), int(substeps), int(iterations)
    if not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"dt must be > 0 s, got {dt}")
    if steps < 0 or substeps < 1 or iterations < 1:
        raise ValueError(f"steps >= 0, substeps >= 1 and iterations >= 1 required, got {steps}, {substeps}, "
                         f"{iterations}")
    if (system.mass <= 0).any():
        raise ValueError("explicit dynamics needs rho > 0 (every particle must have mass)")
    c = system.scene.damping if damping is None else float(damping)
    h = dt / substeps
    damp = 1.0 / (1.0 + c * h)
    limit2 = blowup_limit2(system)
    check_sub = max(1, int(check_every)) * substeps
    nsub = steps * substeps
    rest_after = int(math.ceil(ramp_time / h)) if until_rest else -1
    rest_disp = rest_tol * system.scene.body.le
    x = system.X.copy()
    v = np.zeros((system.n, 3))
    winv = inverse_masses(system)
    at_rest = 0

    t0 = time.perf_counter()
    if kernel == "numba":
        xg, vg = np.ascontiguousarray(x.T), np.ascontiguousarray(v.T)
        gacc = np.zeros_like(xg)
        if system.gravity is not None:
            gacc[:] = system.gravity[:, None]
        done, bad, at_rest = _kernels_xpbd.run(
            xg, vg, np.ascontiguousarray(system.X.T), np.ascontiguousarray(winv.T), term.tets, term.Dminv, term.Vt,
            term.mu, term.lam, term.gamma, gacc, system.gravity is not None, h, damp, float(ramp_time),
            *plate_arrays(system).args(), np.int64(0), np.int64(nsub), np.int64(iterations), bool(coupled),
            np.int64(check_sub),
            float(limit2), np.int64(rest_after), float(rest_disp), np.empty_like(xg), np.empty((len(term.tets), 2)))
        x, v = xg.T.copy(), vg.T.copy()
    else:
        fixed = system.fixed
        done, bad = nsub, -1
        x_check = x.copy()
        for k in range(nsub):
            target = system.prescribed(ramp((k + 1) * h, ramp_time))

            def set_plates(xx, target=target):
                xx[fixed] = target[fixed]

            numpy_substep(term, x, v, winv, h, damp, iterations, system.gravity, set_plates, coupled)
            if (k + 1) % check_sub == 0 or k == nsub - 1:
                bad = find_bad(x, system.X, limit2)
                if bad >= 0:
                    done = k + 1
                    break
                if rest_after >= 0 and k + 1 >= rest_after and (k + 1) % check_sub == 0:
                    if np.abs(x - x_check).max() <= rest_disp:
                        done, at_rest = k + 1, 1
                        break
                x_check = x.copy()
    wall = time.perf_counter() - t0
    if bad >= 0:
        raise divergence(system, x, bad, -(-done // substeps), dt, None, check_every, term.name)
    frames = -(-done // substeps)
    info = {"kernel": kernel, "dt": dt, "steps": frames, "substeps": substeps, "iterations": iterations,
            "h": h, "coupled": bool(coupled), "t_end": done * h, "damping": c, "ramp_time": float(ramp_time),
            "load_factor": ramp(done * h, ramp_time), "model": term.name, "until_rest": bool(until_rest),
            "rest": bool(at_rest), "t_rest": done * h if at_rest else None, "rest_tol": rest_tol,
            "tet_split": "two complementary 5-tet splits at half weight"}
    return run_result(system, f"{term.name}-explicit", x, v, term.forces(x), {"strain": term.energy(x)}, frames,
                      wall, info)


def solve_static(system: System, term: XpbdNH, dt: float | None = None, substeps: int = 10, iterations: int = 1,
                 coupled: bool = True, rest_tol: float = 1e-9, damping: float | None = None, ramp_time: float | None = None,
                 max_time: float | None = None, kernel: str = "numba") -> Result:
    """The rest state of a damped run (the static answer of an explicit-only model).

    Defaults from ``(ω₁, ω_max)`` of :func:`frequencies`: damping ``c = 2 ω₁`` (critical for the
    slowest mode; every other mode's amplitude decays as ``e^{−ω₁ t}``), ramp ``T = 2π/ω₁``, frame
    ``dt = 1/ω_max`` (half the explicit limit 2/ω_max of the MSS-like scheme; with 10 substeps
    ``h ω_max = 0.1``), at most ``T + 40/ω₁`` of simulated time.  ``info['t_rest']`` and
    ``wall_time_s`` say how long it took to get there; ``converged`` is False if the run ended
    before coming to rest (no node moving more than ``rest_tol · le`` over 10 frames)."""
    w1, wmax = frequencies(system)
    if w1 <= 0.0:
        raise ValueError("the body has a zero-energy mode (not held by its plates): no rest state to reach")
    T = 2.0 * math.pi / w1 if ramp_time is None else float(ramp_time)
    c = 2.0 * w1 if damping is None else float(damping)
    dt = 1.0 / wmax if dt is None else float(dt)
    t_max = T + 40.0 / w1 if max_time is None else float(max_time)
    r = simulate_explicit(system, term, dt=dt, steps=int(math.ceil(t_max / dt)), kernel=kernel, ramp_time=T,
                          substeps=substeps, iterations=iterations, coupled=coupled, until_rest=True, rest_tol=rest_tol,
                          damping=c)
    info = dict(r.info, static_from="rest state of a damped run", omega_1=w1, omega_max=wmax)
    return Result(solver=f"{term.name}-rest", scene_digest=r.scene_digest, X=r.X, u=r.u, volume=r.volume,
                  volume0=r.volume0, reactions=r.reactions, energy=r.energy, iterations=r.iterations,
                  wall_time_s=r.wall_time_s, converged=bool(r.info["rest"]), cell_volumes=r.cell_volumes,
                  info=info)
