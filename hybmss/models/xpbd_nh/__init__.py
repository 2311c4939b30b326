"""XPBD with the stable Neo-Hookean constraints on the voxel grid: ``xpbd-nh`` (SPEC §10).

The folder holds the whole model: this module (the explicit stepper :class:`XpbdStepper`, the
static answer :func:`solve_static`, the registry's model), the elements, constraints and NumPy
twin (:mod:`hybmss.models.xpbd_nh.constraints`), the static relaxation
(:mod:`hybmss.models.xpbd_nh.relax`) and the Numba kernels (:mod:`hybmss.models.xpbd_nh._kernels`).

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
2019, is the accurate setting: by default as many substeps of one iteration each as make
``h ω_max ≤ 0.1``, ω_max the highest frequency of the body at rest)::

    v ← (v + h g) / (1 + c h)                          (damping c of the scene, implicit as the MSS)
    x_prev ← x;  x ← x + h v;  prescribed components ← X + u(s(t + h))   (their w = 0)
    repeat `iterations` times, tetrahedra in order, for their constraints C_D, C_H:
        Δλ = (−C − α̃ λ) / (Σ_i ∇_i Cᵀ W_i ∇_i C + α̃),  α̃ = α/h²,  x_i ← x_i + W_i ∇_i C Δλ,  λ ← λ + Δλ
    v ← (x − x_prev) / h

with ``W_i = diag(1/m_i)`` except 0 on prescribed components (sliding plates prescribe only some),
multipliers reset every substep.  The two constraints of a tetrahedron are solved together by
default (``coupled``: the 2×2 system of the update above with the coupling term ∇C_Dᵀ W ∇C_H);
solved one after the other (C_D then C_H at the updated positions, the textbook sequence), each is
far from satisfied at rest (C_D = √3) and their alternation leaves the unloaded body a pre-strain
of order (h ω)² (measured: 5e-4 le at h ω_max = 0.1 on a 2³ cube), which biases small-strain
moduli by percents; with the coupled solve the reference state is an exact fixed point.
Explicit only.  External loads (gravity, surface loads) act as accelerations of the particles
(:func:`external_acceleration`); a massless body (ρ = 0) has a static answer only
(:func:`massless_static`).

Substeps (XPBD is unconditionally stable: the rule is one of accuracy).  The rest state of the
iteration differs from the energy's minimizer by a relative bias ≈ κ (h ω_max)², with
κ ≈ 0.08 measured on the beam under gravity (2×2×12, E = 10 MPa, tip deflection; frames of
1/ω_max in 5, 10, 20 substeps: −1.2e-3, reference, +6.3e-4 relative, so ≈ 8e-4 at 10 by
Richardson in h²) and on the small-strain moduli (4e-4 … 9e-4 at h ω_max = 0.1).
``h ω_max ≤ 0.1`` (:data:`H_OMEGA`) keeps it below 1e-3 in the displacements of an explicit run,
a tenth of the smallest error budget (1 %) of the speed-against-error study; ω_max is the
highest frequency of the linear Hex8 stiffness of the same grid at rest (ARPACK,
:func:`frequencies`).

Its static answer is the rest state of the XPBD substep (:func:`solve_static`), reached by a
relaxation in pseudo-time steps H ≥ h with the same fixed point (:func:`relax_static`), and judged
at rest by :func:`hybmss.explicit.rest_report` (force residual and kinetic energy) like every other
answer.  That state is not exactly the minimizer of the energy: with one iteration per substep, a
stationary point of the iteration satisfies ``Σ_j ∇C_j C_j / (α_j + h² ∇C_jᵀ W ∇C_j) = 0``, i.e.
each constraint acts with the compliance ``α + h² ∇CᵀW∇C`` instead of α, a relative stiffness
bias of order ``(h ω_e)²`` (ω_e an element's own frequency), which vanishes as the substeps
shrink.  Measured by ``rest_report`` at ``h ω_max = 0.1``, the fixed point's free force residual
is up to 2.6e-2 of the force scale (2×2×12 beam stretched 20 % at ν = 0.499), 3.2–3.8e-3 on the
[B09] cantilevers, and it falls as h² (×1/4 per doubling of the substeps, the same relaxation steps
and time: the relaxation's cost does not depend on h), so the static answer takes
:data:`AUTO_SUBSTEPS_STATIC` substeps.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ...explicit import REST_RTOL, find_bad, plate_arrays, ramp, rest_report, simulate_explicit as _simulate_explicit
from ...result import Result
from ...scene import Material
from ...solve.errors import StaticSolveError
from ...stepper import ParticleStepper, with_dead_loads
from ...system import System, build
from ..base import ModelBase, Style, check
from ..corot_hex8 import CorotHex8, frequency_range, omega_max
from . import _kernels as _kernels_xpbd
from .constraints import (CELL_TETS, KERNELS, SPLIT_A, SPLIT_B, XpbdNH, cell_batches, cell_tetrahedra,
                          external_acceleration, inverse_masses, numpy_substep, xpbd_lame)
from .relax import RELAX_CHECK_FRAMES, RELAX_H_OMEGA, RELAX_ROUNDING, relax_static, rounding_floor

__all__ = ["AUTO_SUBSTEPS_STATIC", "CELL_TETS", "H_OMEGA", "KERNELS", "MODEL", "RELAX_CHECK_FRAMES", "RELAX_H_OMEGA",
           "RELAX_ROUNDING", "REST_TOL", "SPLIT_A", "SPLIT_B", "XpbdNH", "XpbdNHModel", "XpbdParameters",
           "XpbdStepper", "auto_substeps", "cell_batches", "cell_tetrahedra", "external_acceleration", "frequencies",
           "highest_frequency", "inverse_masses", "massless_static", "numpy_substep", "relax_static", "rest_scale",
           "rounding_floor", "simulate_explicit", "solve_scene", "solve_static", "xpbd_lame", "xpbd_term"]


def frequencies(system: System, material: Material | None = None) -> tuple[float, float]:
    """``(ω₁, ω_max)`` (rad/s) of the body at rest, from the linear Hex8 stiffness of the same grid
    and material (the small-strain limit of the constraints' energy on the same cells): they set
    the defaults of :func:`solve_static`."""
    mat = system.scene.material if material is None else material
    return frequency_range(system, CorotHex8(system.lattice, mat))


def highest_frequency(system: System) -> float:
    """``ω_max`` of :func:`frequencies` alone (no eigen solve for ω₁: what the substep rule and
    ``dt_crit`` need)."""
    return omega_max(system, CorotHex8(system.lattice, system.scene.material))


SETTLE_MAX_MOVE = 0.05
"""Largest move of :meth:`XpbdStepper.settle`, relative to the largest displacement: a run at rest
by the rest test is near its fixed point (the 4×4×24 beam under gravity, at rest at 4.25 s: 1.4 %
from it, the whole 10 s run 2e-6), a larger move is to another equilibrium (the 6³ cube
compressed by 20 % at ν = 0.499: 45 %, an asymmetric state; the run itself stays symmetric for
its 10 s), and the run goes on instead."""


class XpbdStepper(ParticleStepper):
    """The stepper (:mod:`hybmss.stepper`) of XPBD: a step of the loop is one frame ``dt`` of
    ``substeps`` substeps with ``iterations`` Gauss–Seidel sweeps, the two constraints of a
    tetrahedron solved together (``coupled``) or one after the other; damping ``c`` of the scene
    per substep.  The loop's ``check_every`` frames are ``check_every · substeps`` substeps.  With
    ``until_rest`` the stepper stops after the ramp once no node moved more than
    ``rest_tol · le`` over a check interval (``info['stopped_at_rest']``, ``info['t_rest']``).
    ``precision``: ``'f64'`` or ``'f32'`` (numba kernel only: float32 displacements and velocities,
    :func:`hybmss._kernels.kernel_state`).  One thread (Gauss–Seidel is sequential).

    ``rest_floor``: the rest state is the fixed point of a substep, whose force residual need not
    vanish (one sweep a substep leaves a bias that grows with the volume constraint's stiffness),
    so the time loop watches for a residual the rest test can never pass
    (:class:`hybmss.explicit.rest.ResidualFloor`, from :meth:`lowest_frequency`); and a run that
    has come to rest can be finished at that fixed point (:meth:`settle`)."""

    rest_floor = True

    def __init__(self, system: System, term: XpbdNH, dt: float, *, ramp_time: float, kernel: str = "numba",
                 precision: str = "f64", threads: int = 1, substeps: int = 10, iterations: int = 1,
                 coupled: bool = True, until_rest: bool = False, rest_tol: float = 1e-7):
        super().__init__(system, term, dt, ramp_time=ramp_time, kernel=kernel, precision=precision,
                         threads=threads, kernels=KERNELS)
        substeps, iterations = int(substeps), int(iterations)
        if substeps < 1 or iterations < 1:
            raise ValueError(f"substeps >= 1 and iterations >= 1 required, got {substeps}, {iterations}")
        self.substeps, self.iterations, self.coupled = substeps, iterations, bool(coupled)
        self.h = float(dt) / substeps
        self.damp = 1.0 / (1.0 + system.scene.damping * self.h)
        self.rest_after = int(math.ceil(ramp_time / self.h)) if until_rest else -1
        self.rest_disp = rest_tol * system.scene.body.le
        self.winv = inverse_masses(system)
        self.accel = external_acceleration(system)
        self._w1 = None  # ω₁, computed on first use (lowest_frequency)
        self.info.update({"substeps": substeps, "iterations": iterations, "h": self.h, "coupled": self.coupled,
                          "until_rest": bool(until_rest), "stopped_at_rest": False, "t_rest": None,
                          "rest_tol": rest_tol, "tet_split": "two complementary 5-tet splits at half weight"})
        if kernel == "numba":
            n = system.n
            self._gacc = np.zeros((3, n)) if self.accel is None else np.ascontiguousarray(self.accel.T)
            self._Xg, self._wg = np.ascontiguousarray(system.X.T), np.ascontiguousarray(self.winv.T)
            self._plates = plate_arrays(system)
            self._xprev, self._lamb = np.empty((3, n)), np.empty((len(term.tets), 2))
            self._B = np.empty(_kernels_xpbd.SLOTS * _kernels_xpbd.LANES)

    def lowest_frequency(self) -> float:
        """ω₁ (rad/s) of the body at rest (:func:`frequencies`)."""
        if self._w1 is None:
            self._w1 = float(frequencies(self.system)[0])
        return self._w1

    def settle(self) -> dict:
        """Move a damped run that is at rest (the time loop's ``until_rest``) to the state it tends
        to: the fixed point of this very substep (``h``, the scene's damping c), reached from the
        current state by :func:`relax_static` in pseudo-time steps ``H = max(h, RELAX_H_OMEGA/ω_max)``
        with the relaxation's own damping 2 ω₁ (the fixed point depends on neither), until no node
        moves more than :data:`REST_TOL` · le · :func:`rest_scale` over :data:`RELAX_CHECK_FRAMES`
        frames ``1/ω_max``.  Loads that state at rest and returns the relaxation's figures with
        ``refused`` False; leaves the state as it was and returns ``refused`` True (and ``why``) if
        the relaxation did not stop so or moved farther than :data:`SETTLE_MAX_MOVE`.  The
        remaining transient of the run decays as ``e^{−σ t}`` towards that point: on the 4×4×24
        beam under gravity (E = 10 MPa), the state of the whole 10 s protocol run is 2e-6 of the
        largest displacement from it."""
        S = self.system
        x, _ = self.state()
        w1, wmax = self.lowest_frequency(), highest_frequency(S)
        H = max(self.h, RELAX_H_OMEGA / wmax)
        r = relax_static(S, self.term, self.h, H, 2.0 * w1, 0.0, 40.0 / w1, RELAX_CHECK_FRAMES / wmax,
                         REST_TOL * rest_scale(S), iterations=self.iterations, coupled=self.coupled,
                         kernel=self.kernel, damping_h=float(S.scene.damping), x0=x)
        x_new = r.X + r.u
        move = float(np.abs(x_new - x).max() / max(np.abs(x - S.X).max(), np.finfo(float).tiny))
        out = {"settle_steps": int(r.info["steps"]), "settle_H": H, "settle_wall_s": float(r.wall_time_s),
               "settle_move": move, "refused": True}
        if not r.info["rest"]:
            return dict(out, why="the relaxation did not come to rest")
        if move > SETTLE_MAX_MOVE:
            return dict(out, why=f"its fixed point is {move:.3g} of the largest displacement away "
                                 f"(more than {SETTLE_MAX_MOVE:g}: another equilibrium)")
        self.load(x_new, np.zeros_like(x))
        return dict(out, refused=False)

    def _substeps(self, sub0, n, check_sub, limit2):
        """(substeps done, bad particle or −1, at rest) of ``n`` substeps from ``sub0``."""
        term, S = self.term, self.system
        if self.kernel == "numba":
            bnodes, bcount = term.batches()
            run = _kernels_xpbd.stepping(bnodes, self.iterations, self.coupled)[0]
            done, bad, rest = run(
                self._W, self._posmode, self._Xg, self._wg, term.tets, term.Dminv, term.Vt, term.mu, term.lam,
                term.gamma, self._gacc, self.accel is not None, self.h, self.damp, self.ramp_time,
                *self._plates.args(), np.int64(sub0), np.int64(n), np.int64(self.iterations), bool(self.coupled),
                np.int64(check_sub), float(limit2), np.int64(self.rest_after), float(self.rest_disp), self._xprev,
                self._lamb, bnodes, bcount, self._B)
            return int(done), int(bad), bool(rest)
        x, v, fixed = self._x, self._v, S.fixed
        x_check = x.copy()
        for k in range(n):
            step = sub0 + k
            target = S.prescribed(ramp((step + 1) * self.h, self.ramp_time))

            def set_plates(xx, target=target):
                xx[fixed] = target[fixed]

            numpy_substep(term, x, v, self.winv, self.h, self.damp, self.iterations, self.accel, set_plates,
                          self.coupled)
            if (k + 1) % check_sub == 0 or k == n - 1:
                bad = find_bad(x, S.X, limit2)
                if bad >= 0:
                    return k + 1, bad, False
                if self.rest_after >= 0 and step + 1 >= self.rest_after and (k + 1) % check_sub == 0:
                    if np.abs(x - x_check).max() <= self.rest_disp:
                        return k + 1, -1, True
                x_check = x.copy()
        return n, -1, False

    def advance(self, step0, n, check_every, limit2):
        m = self.substeps
        done, bad, rest = self._substeps(step0 * m, n * m, check_every * m, limit2)
        if rest:
            self.info["stopped_at_rest"] = True
            self.info["t_rest"] = (step0 * m + done) * self.h
        return -(-done // m), bad


def simulate_explicit(system: System, term: XpbdNH, dt: float = 1e-3, steps: int = 10_000, kernel: str = "numba",
                      ramp_time: float = 1.0, *, substeps: int = 10, iterations: int = 1, coupled: bool = True,
                      check_every: int = 10, until_rest: bool = False, rest_tol: float = 1e-7,
                      damping: float | None = None, record_every: int = 0, x0: np.ndarray | None = None,
                      v0: np.ndarray | None = None, precision: str = "f64") -> Result:
    """The XPBD run of ``steps`` frames of ``dt`` (:class:`XpbdStepper` with these options in the
    one loop :func:`hybmss.explicit.simulate_explicit`); damping is ``scene.damping`` unless
    ``damping`` is given."""
    if damping is not None:
        scene = dataclasses.replace(system.scene, damping=float(damping))
        system = dataclasses.replace(system, scene=scene)
    stepper = XpbdStepper(system, term, dt, ramp_time=ramp_time, kernel=kernel, precision=precision,
                          substeps=substeps, iterations=iterations, coupled=coupled, until_rest=until_rest,
                          rest_tol=rest_tol)
    return _simulate_explicit(system.scene, dt, steps, kernel, ramp_time, record_every=record_every, system=system,
                              x0=x0, v0=v0, check_every=check_every, precision=precision, stepper=stepper)


REST_TOL = 1e-7
"""Rest criterion of :func:`solve_static`: no node moved more than ``REST_TOL · le`` over 10
frames of ``dt = 1/ω_max`` (of pseudo-time for the relaxation).  The remaining motion then decays
as ``e^{−ω₁ t}`` from an amplitude of about ``REST_TOL · le · ω_max / (10 ω₁)``: on the beam under
gravity (2×2×12, E = 10 and 2 MPa) the tip deflection is within 3e-7 and 4e-6 of the answer at
1e-9 (25 % and 37 % more substeps), far below the substep bias (module docstring)."""

def rest_scale(system: System) -> float:
    """The rest criterion's length in cell edges: 1, or the largest plate displacement at full load
    when it is smaller (a rest state at small strain, as for the moduli, is then located relative
    to its own displacements: at 1e-4 strain the criterion of one cell edge left E_eff 2e-4 to
    7e-4 away from its converged value)."""
    le = system.scene.body.le
    fixed = system.fixed
    if not fixed.any():
        return 1.0
    d = float(np.abs((system.prescribed(1.0) - system.X)[fixed]).max())
    return min(1.0, d / le) if d > 0.0 else 1.0



def solve_static(system: System, term: XpbdNH, dt: float | None = None, substeps: int | None = None,
                 iterations: int = 1, coupled: bool = True, rest_tol: float | None = None, damping: float | None = None,
                 ramp_time: float | None = None, max_time: float | None = None, kernel: str = "numba",
                 pseudo_step: float | None = None, damping_h: float | None = 0.0,
                 rest_rtol: float = REST_RTOL) -> Result:
    """The rest state of the XPBD substep ``h = dt/substeps`` (the static answer of an
    explicit-only model), judged at rest by :func:`hybmss.explicit.rest_report` like every other
    answer that reports ``converged``.

    Defaults from ``(ω₁, ω_max)`` of :func:`frequencies`: damping ``c = 2 ω₁`` (critical for the
    slowest mode; every other mode's amplitude decays as ``e^{−ω₁ t}``), ramp ``T = 2π/ω₁``, frame
    ``dt = 1/ω_max`` with :data:`AUTO_SUBSTEPS_STATIC` substeps, at most ``T + 40/ω₁`` of
    simulated time.  The state is reached by :func:`relax_static` in pseudo-time steps
    ``H = pseudo_step / ω_max`` (default :data:`RELAX_H_OMEGA`; never below h; ``pseudo_step = 0``
    runs the XPBD dynamics itself, H = h): same rest state, ``h/H`` of the substeps, whatever h.
    ``damping_h``: the substep's own damping c_h (default 0: the undamped substep, whose rest state
    feels the whole load; ``None``: c, the rest state of the damped run, whose substeps damp the
    external accelerations by ``1/(1 + c h)``).  The relaxation stops once no node moves more than
    ``rest_tol · le · rest_scale`` over :data:`RELAX_CHECK_FRAMES` frames (default
    :data:`REST_TOL`, :func:`rest_scale`); ``converged`` is True only if it stopped so and the
    state is at rest by ``rest_report`` with ``rest_rtol`` (``info['rest']``; the fixed point's
    free force residual, of relative size ≈ (h ω)², is the substep bias: module docstring)."""
    w1, wmax = frequencies(system)
    if w1 <= 0.0:
        raise ValueError("the body has a zero-energy mode (not held by its plates): no rest state to reach")
    T = 2.0 * math.pi / w1 if ramp_time is None else float(ramp_time)
    c = 2.0 * w1 if damping is None else float(damping)
    dt = 1.0 / wmax if dt is None else float(dt)
    t_max = T + 40.0 / w1 if max_time is None else float(max_time)
    rest_tol = REST_TOL if rest_tol is None else float(rest_tol)
    substeps = AUTO_SUBSTEPS_STATIC if substeps is None else int(substeps)
    h = dt / substeps
    q = RELAX_H_OMEGA if pseudo_step is None else float(pseudo_step)
    H = max(h, q / wmax)
    r = relax_static(system, term, h, H, c, T, t_max, RELAX_CHECK_FRAMES * dt, rest_tol * rest_scale(system),
                     iterations=iterations, coupled=coupled, kernel=kernel, damping_h=damping_h)
    x = r.X + r.u
    f_int = with_dead_loads(system, term.forces(x))  # every force but gravity; the relaxation applies loads whole
    rest = rest_report(system, f_int, r.energy, float(r.info["load_factor"]), rest_rtol, x)
    stopped = bool(r.info["rest"])
    if not stopped:
        why = f"the relaxation still moved more than {r.info['rest_disp']:.3g} m over its last check interval"
        rest = dict(rest, at_rest=False,
                    not_at_rest_because="; ".join(w for w in (rest["not_at_rest_because"], why) if w))
    info = dict(r.info, static_from="rest state of the XPBD substep, by a relaxation in pseudo-time steps H "
                "(relax_static), judged by rest_report", omega_1=w1, omega_max=wmax, load_steps=0, dt=dt,
                substeps=substeps, stopped_at_rest=stopped, rest=rest)
    return Result(solver=r.solver, scene_digest=r.scene_digest, X=r.X, u=r.u, volume=r.volume,
                  volume0=r.volume0, reactions=r.reactions, energy=r.energy, iterations=r.iterations,
                  wall_time_s=r.wall_time_s, converged=bool(rest["at_rest"]), cell_volumes=r.cell_volumes,
                  info=info)


# ------------------------------------------------------------------------------ the registry's model
@dataclass(frozen=True)
class XpbdParameters:
    """- ``substeps``: substeps per frame dt; 0 (the default) takes as many as make
      ``h ω_max ≤ 0.1`` ("small steps": Macklin et al. 2019), ω_max the highest frequency of the
      body at rest (:func:`frequencies`), at least 1.
    - ``iterations``: Gauss–Seidel sweeps per substep (≥ 1).
    - ``sequential``: solve the two constraints of a tetrahedron one after the other (the textbook
      sequence, which leaves an O(h²) pre-strain at rest) instead of together (a 2×2 system: the
      unloaded body then rests exactly at its reference state)."""

    substeps: int = 0
    iterations: int = 1
    sequential: bool = False

    def __post_init__(self):
        for name, lo in (("substeps", 0.0), ("iterations", 1.0)):
            v = check(name, getattr(self, name), lo)
            if v != int(v):
                raise ValueError(f"{name} must be an integer >= {lo:g}, got {getattr(self, name)!r}")
            object.__setattr__(self, name, int(v))
        if self.sequential not in (True, False):
            raise ValueError(f"sequential must be true or false, got {self.sequential!r}")
        object.__setattr__(self, "sequential", bool(self.sequential))


H_OMEGA = 0.1
"""Largest ``h ω_max`` of the automatic substeps."""
AUTO_SUBSTEPS_STATIC = 80
"""Substeps of the static answer's frames ``dt = 1/ω_max``: ``h ω_max = 0.0125``.  The fixed
point's free force residual (:func:`hybmss.explicit.rest_report`, relative to its force scale)
on the 38 xpbd-nh static scenes of the quick reproduction and the three [B09] cantilevers is at
most 2.6e-2 at 10 substeps, 1.6e-3 at 40, 4.0e-4 at 80 (a factor 2.5 inside the rest tolerance
1e-3), falling as 1/substeps² with the same relaxation steps and time.  At 160 the rounding of the
relaxation's update (``over = (H/h)²`` = 6400) reaches the motion test of small-strain scenes
(:func:`rounding_floor`): E_eff of ``hybmss moduli`` at ν = 0.499 moved from −1.7e-5 to +8.6e-6,
G_eff to −6.2e-5, against 3e-6 at lower ν."""


def auto_substeps(system: System, dt: float) -> int:
    """Substeps per frame ``dt`` that make ``h ω_max ≤`` :data:`H_OMEGA` (at least 1)."""
    return max(1, int(math.ceil(dt * highest_frequency(system) / H_OMEGA - 1e-9)))


def massless_static(system: System) -> System:
    """The system whose relaxation gives the static answer of a body without mass (ρ = 0): unit
    density and no weight.  The rest state of :func:`relax_static` does not depend on a uniform
    density (scaling every mass by c scales h² and 1/ω by c and √c, leaving ``h² W``,
    ``α/(h² ∇CᵀW∇C)``, ``c_h h`` and the load's ``h² f/m`` unchanged); ``system`` itself if it
    has mass."""
    if system.scene.material.rho > 0:
        return system
    return dataclasses.replace(system, mass=system.lattice.masses_per_density * 1.0, gravity=None)


def xpbd_term(system: System) -> XpbdNH:
    """The constraint set of a system built for ``xpbd-nh``."""
    for t in system.terms:
        if isinstance(t, XpbdNH):
            return t
    raise ValueError("the system has no XPBD constraints (its model is not xpbd-nh)")


def solve_scene(scene, options=None, system: System | None = None) -> Result:
    """The static answer with the signature of :func:`hybmss.solve.solve_static`: the rest state
    of a damped run (:func:`solve_static`, defaults from the body's frequencies; ``options`` of the
    Newton solvers do not apply).  Raises :class:`hybmss.solve.StaticSolveError` if the run does
    not come to rest in its time budget."""
    S = massless_static(system if system is not None else build(scene))
    p = scene.model.params
    r = solve_static(S, xpbd_term(S), substeps=p.substeps or None, iterations=p.iterations, coupled=not p.sequential)
    if not r.converged:
        raise StaticSolveError(
            f"xpbd-nh scene {scene.name or '(unnamed)'}: the relaxation did not reach rest within "
            f"{r.info['t_end']:.4g} s of pseudo-time ({r.info['rest']['not_at_rest_because']}); raise the substeps "
            f"(the fixed point's residual falls as 1/substeps²), the damping or the time budget",
            cause="rest-state", time=float(r.info['t_end']))
    return r


class XpbdNHModel(ModelBase):
    """``xpbd-nh``: XPBD with the stable Neo-Hookean constraints (module docstring)."""

    name = "xpbd-nh"
    label = "XPBD, stable Neo-Hookean constraints, small steps (Macklin & Mueller 2021)"
    style = Style("#d62728", "X", ":")
    Parameters = XpbdParameters
    conservative = False  # its static answer is the rest state of the iteration, not an energy minimum
    explicit_limit = False  # constraints solved implicitly: any frame is stable, substeps keep it accurate
    solvers = ("static", "explicit")
    kernels = ("numba", "numpy")
    order = 22

    def terms(self, p, scene, lattice, consts):
        return (XpbdNH(lattice, scene.material),)

    def dt_crit(self, system) -> float:
        """The limit ``2/ω_max`` of the explicit scheme on the same grid and material (linear Hex8
        at rest): XPBD itself has no such limit (its constraints are solved implicitly)."""
        return 2.0 / highest_frequency(system)

    def stepper(self, system, dt, *, ramp_time, kernel="numba", precision="f64", threads=1):
        """:class:`XpbdStepper` with the substeps (0: :func:`auto_substeps`), iterations and solve of
        the scene's model parameters."""
        p = system.scene.model.params
        return XpbdStepper(system, xpbd_term(system), dt, ramp_time=ramp_time, kernel=kernel, precision=precision,
                           threads=threads, substeps=p.substeps or auto_substeps(system, dt),
                           iterations=p.iterations, coupled=not p.sequential)

    solve_static = staticmethod(solve_scene)


MODEL = XpbdNHModel()
