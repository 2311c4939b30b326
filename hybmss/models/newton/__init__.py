"""NVIDIA Newton's soft bodies (on Warp) as models: ``newton-semi`` (``SolverSemiImplicit``,
explicit), ``newton-vbd`` (``SolverVBD``, implicit Euler by vertex block descent) and
``newton-xpbd`` (``SolverXPBD``, refused: below), on Warp's ``cpu`` device.

The engine runs its own code from its own package (``newton`` ≥ 1.8, ``warp-lang``; imported only
when the model runs: :mod:`hybmss.models.newton.engine`, which also says how a scene becomes a
Newton model).

Material law, from the engine's source (``newton/_src/solvers/semi_implicit/kernels_particle.py``,
kernel ``eval_tetrahedra``, launched by ``eval_tetrahedra_forces`` in ``SolverSemiImplicit.step``):
per tetrahedron of rest volume V, ``F = D_s D_m⁻¹`` and the first Piola stress
``P = k_mu F (1 − 1/(I_C + 1)) + k_lambda (J − α) cof F``, α = 1 + k_mu/k_lambda − k_mu/(4 k_lambda):
the stable Neo-Hookean of Smith et al. 2018, energy ``μ/2 (I_C − 3) − μ/2 log(I_C + 1) +
λ/2 (J − α)²`` (μ = k_mu, λ = k_lambda), stress-free at F = I.  Linearized at F = I:
``P ≈ 2 (3μ/4) ε + (λ − 5μ/8) tr ε I``, so its small-strain Lamé parameters are ``3 k_mu/4`` and
``k_lambda − 5 k_mu/8``.  ``ModelBuilder.add_tetrahedron`` calls k_mu and k_lambda "the Lamé
parameters": given the material's (λ₀, μ₀) as they are, a body would be 25 % soft in shear.  The
model therefore takes ``k_mu = 4 μ₀/3``, ``k_lambda = λ₀ + 5 μ₀/6``
(:func:`hybmss.models.newton.engine.lame`), and ``hybmss moduli --strain 3e-3`` checks it (E, ν, G
to 3e-4 at ν ∈ {0, 0.25, 0.45}).  At the default strain 1e-4 the float32 state does not resolve
the moduli (E_eff 1.3 % high at ν = 0.45, within its equilibrium error of 2.5 %): the command
refuses a strain below the smallest it resolves to 1e-3, ~2.5e-3 (:func:`hybmss.moduli.float32_errors`).  ν must leave ``k_lambda > 0``: ν > −5/14.

Refused before any work: surface loads, ν ≤ −5/14, two threads, ``precision`` other than f32
(Warp's particle state is float32).

``newton-vbd``, from ``newton/_src/solvers/vbd/particle_vbd_kernels.py``, function
``evaluate_volumetric_neo_hookean_force_and_hessian`` (called per adjacent tetrahedron by
``accumulate_elasticity_force_and_hessian`` in each of ``SolverVBD.step``'s iterations): with
``μ_NH = k_mu``, ``λ_NH = k_lambda + k_mu``, α = 1 + μ_NH/λ_NH, ``P = μ_NH F + λ_NH (J − α) cof F``
(energy ``μ_NH/2 (I_C − 3) + λ_NH/2 (J − α)²``, no log term), linearized at F = I:
``P ≈ k_mu (H + Hᵀ) + k_lambda tr H I``: its Lamé parameters are k_mu and k_lambda as they are
(:func:`hybmss.models.newton.engine.lame_vbd`), a law unlike ``SolverSemiImplicit``'s for the same
builder values; λ_NH = λ + μ > 0 for every ν in (−1, ½).  Measured with the solver's own force
evaluation on one cell under homogeneous strains ±1e-3: λ, μ, E, ν to 3e-5.  Plates: a node whose
three components are prescribed is a kinematic particle (mass 0: ``forward_step`` and the sweep
leave it where it is put, at its target of the step's end before each step); a node held in some
components only cannot be one (the sweep solves a 3×3 block per vertex), and set after the step it
stays off equilibrium (6 % of the plate force measured on the moduli cube): ``slide`` plates are
refused, so ``hybmss moduli`` (its frictionless plates) is refused too.  Iterations: at rest
(v = 0, inertia target = x + h² g) a sweep leaves a vertex unmoved exactly where its force
vanishes, so the rest state does not depend on the iteration count (1, 2, 10, 40 iterations: the
shear reaction at strain 3e-3 equal to the same-mesh linear FEM's within 8e-5, the float32
resolution 5.6e-4); 10 (Newton's default).  Reactions: Newton's
``evaluate_volumetric_neo_hookean_force_and_hessian`` force on each vertex (damping 0), summed by a
Warp kernel of :mod:`hybmss.models.newton.engine`.  A correction below one unit in the last place of
a float32 position is lost, so the sweeps stop at the force resolution: at strain 1e-4 the
reactions carry up to 5e-3 (3e-3 measured) against the same-mesh FEM.

``newton-xpbd`` is refused for every scene: ``newton/_src/solvers/xpbd/kernels.py``, kernel
``solve_tetrahedra`` (launched per iteration by ``SolverXPBD.step``), solves two scalar constraints
per tetrahedron, ``C_dev = tr(FᵀF) − 3`` with compliance ``1/(V k_mu)`` and ``C_vol = det F − 1``
with ``1/(V k_lambda)``: the energy ``V (k_mu/2 C_dev² + k_lambda/2 C_vol²)``.  C_dev = 2 tr ε +
O(ε²) is the deviatoric constraint only by name: at small strain the law is ``λ_eff = 4 k_mu +
k_lambda``, ``μ_eff = 0`` (simple shear: C_dev = γ², an energy quartic in γ); and the kernel skips
a tetrahedron with k_lambda ≤ 0 (ν ≤ 0 with k_lambda = λ).  Measured with its own constraint
forces (:func:`hybmss.models.newton.engine.xpbd_constraint_forces`) on one cell, k_mu = μ, k_lambda
= λ, γ = 1e-3: μ_eff = 2e-6 μ, λ_eff = 4μ + λ to 1e-5.  No (k_mu, k_lambda) gives a shear modulus.
"""

from __future__ import annotations


from .._engine_model import EngineModel, SceneNotRepresentable, engine_models
from ..base import Style

STATIC_REST_RTOL = 1e-3
"""Rest tolerance of the static answer (the explicit runs' default, :data:`hybmss.explicit.REST_RTOL`):
below it the free-force residual of a float32 state is its force resolution
(:meth:`hybmss.models.newton.engine.NewtonBody.force_resolution`), reached once the run has
settled (:data:`hybmss.models._engine_model.SETTLE`)."""



def _engine():
    from . import engine
    return engine


REQUIRES = (("newton", "newton", ">=1.8,<1.9"), ("warp", "warp-lang", ">=1.19,<2"))
"""The engine and the versions its laws were read and measured at: the engine imports Newton's
private kernels (``newton._src.solvers``), which may change in any minor version."""


class NewtonModel(EngineModel):
    """Newton's tetrahedra with one of its solvers (module docstring)."""

    requires = REQUIRES
    solver: str = "semi"
    engine = "Newton"
    precisions = ("f32",)
    static_rest_rtol = STATIC_REST_RTOL

    def make_body(self, system, dt: float, ramp_time: float, **kw):
        return _engine().NewtonBody(system, self.solver, dt, ramp_time, **kw)

    def tet_body_refused(self) -> str:
        if self.solver not in ("semi", "vbd"):
            return f"body: {self.name} cannot run on a tetrahedral body (its semi-implicit and VBD solvers can)"
        return ""

    def make_tet_body(self, body, material, holds, dt: float, ramp_time: float, *, damping: float = 0.0):
        if self.tet_body_refused():
            raise SceneNotRepresentable(self.tet_body_refused())
        self.check_law()
        return _engine().NewtonBody.on_tets(body, material, holds, self.solver, dt, ramp_time, damping=damping)

    def check_scene(self, scene) -> None:
        if not scene.material.nu > -5.0 / 14.0:
            raise SceneNotRepresentable(f"nu must lie in (-5/14, 0.5) for {self.name} (its k_lambda = lambda + "
                                        f"5 mu/6 must be > 0), got {scene.material.nu:g}")


class NewtonVBD(NewtonModel):
    name = "newton-vbd"
    solver = "vbd"
    label = "Newton (Warp) SolverVBD, Neo-Hookean tetrahedra"
    style = Style("#4d7a00", "v", "--")
    order = 46

    def check_scene(self, scene) -> None:
        # its λ_NH = λ + μ > 0 for every ν in (-1, 0.5): no ν is refused
        for plate in scene.plates:
            if not plate.motion.constrained.all():
                raise SceneNotRepresentable(
                    f"plates: {self.name} cannot represent the {plate.motion.kind} plate {plate.name!r} (some "
                    "components free): SolverVBD moves a node as a whole (one 3x3 block solve per vertex), so a "
                    "node held in some components is off equilibrium in the others (measured: a residual of 6 % "
                    "of the plate force); use plates that prescribe all three components")


class NewtonXPBD(NewtonModel):
    name = "newton-xpbd"
    solver = "xpbd"
    label = "Newton (Warp) SolverXPBD tetrahedra: refused (no small-strain shear stiffness)"
    style = Style("#a3d65c", "<", "--")
    order = 47

    def check_scene(self, scene) -> None:
        raise SceneNotRepresentable(
            f"model: {self.name} cannot represent a shear modulus (SolverXPBD's solve_tetrahedra constrains "
            "C = tr(F^T F) - 3 with compliance 1/(V k_mu): an energy quadratic in C, quartic in a shear strain, "
            "so G_eff = 0 at small strain); use newton-semi or newton-vbd")


class NewtonSemi(NewtonModel):
    name = "newton-semi"
    solver = "semi"
    label = "Newton (Warp) SolverSemiImplicit, stable Neo-Hookean tetrahedra"
    style = Style("#76b900", "^", "--")
    order = 45


MODELS, UNAVAILABLE = engine_models(REQUIRES, (NewtonSemi(), NewtonVBD(), NewtonXPBD()))
