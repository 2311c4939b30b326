"""Bender's PositionBasedDynamics library (``pypbd``, its Python bindings) as a model:
``pbd-xpbd-fem`` (its XPBD FEM tetrahedron constraint, ``solidSimulationMethod`` 3).

The engine runs its own code from its own package (``pypbd`` ≥ 2.2, imported only when the model
runs: :mod:`hybmss.models.pbd.engine`, which also says how a scene becomes a PBD model): its step
moves the nodes.  Its forces are not the engine's: the bindings expose no force nor constraint
multiplier, so the forces the harness reads (plate reactions, the rest test's residual, the
stiffness of the static step) are its re-implementation of the library's formulas
(:func:`hybmss.models.pbd.engine.svk_forces`, checked against one projection of the engine).  The
wheel declares ``pygame`` and ``pyopengl`` (its demos' GUI) as requirements; the bindings import
neither and run headless.

Material law, from the library's source (github.com/InteractiveComputerGraphics/
PositionBasedDynamics): ``SimulationModel::addSolidConstraints`` (method 3) adds one
``XPBD_FEMTetConstraint`` per tetrahedron with ``stiffness`` = Young's modulus E and the Poisson
ratio ν; ``Simulation/Constraints.cpp`` ``XPBD_FEMTetConstraint::solvePositionConstraint`` calls
``XPBD::solve_FEMTetraConstraint`` (``PositionBasedDynamics/XPBD.cpp``) with the rest volume and
``Dm⁻¹`` of ``PositionBasedDynamics::init_FEMTetraConstraint``.  There: ``μ' = 1/(2(1+ν))``,
``λ' = ν/((1+ν)(1−2ν))`` (Lamé parameters over E), the energy over E
``U' = V (μ' |ε|² + λ'/2 tr(ε)²)`` with ε the Green strain (``computeGreenStrainAndPiolaStress``):
St Venant–Kirchhoff, the constraint ``C = √(2U')`` with compliance ``α = 1/(E h²)``, so that
``U = E U'``; at small strain linear elasticity in E, ν with no Lamé shift.  ν outside
[0, 0.49] makes the solve return without a correction (the body silently has no stiffness:
measured at ν = 0.495); a tetrahedron below 20 % of its rest volume takes the inversion-handling
variant.

XPBD's rest state is the equilibrium of the tetrahedra's forces each weighted by
``1/(1 + r_t)``, ``r_t = E h² Σ w_i |∇U'_i|²/(2U')`` ~ (h ω)² (one iteration, multipliers reset
each step, Gauss–Seidel order): its static answer is biased by O((h ω_max)²), so the static run
takes the step :data:`CFL` × 2/ω_max and the rest tolerance :data:`STATIC_REST_RTOL`, and
waits until the slowest mode has settled (``settles``).  Measured on a 2×2×2 cube (0.5 m cells,
strain 1e-4): the free-force residual of the settled state is 3e-4 of the force scale at
h ω_max = 0.1, 5e-5 at 0.04 (∝ (h ω)²; 9.3e-4 at 0.1 on the 3×3×3 simple shear), the plate reaction within 1.5e-4 of scikit-fem's
ElementTetP1 on the same tetrahedra at ν ∈ {0, 0.3, 0.45}.

Refused before any work: surface loads, ν outside [0, 0.49], two threads, float32.
"""

from __future__ import annotations


from .._engine_model import EngineModel, SceneNotRepresentable, engine_models
from ..base import Style

NU_MAX = 0.49
"""``XPBD::solve_FEMTetraConstraint`` skips its correction for ν < 0 or ν > 0.49."""
STATIC_REST_RTOL = 1e-3
"""Rest tolerance of the static answer (the explicit runs' default): above XPBD's bias at
:data:`CFL` (free-force residual of its fixed point under the library's law, measured below
5e-4 of the force scale on the test cubes)."""
CFL = 0.03
"""Step of the static run as a fraction of ``2/ω_max`` (h ω_max = 0.06): at 0.1 the settled
residual of the 3×3×3 simple-shear scene of ``hybmss moduli`` is 9.3e-4 of its force scale,
at the rest tolerance's edge."""



def _engine():
    from . import engine
    return engine


REQUIRES = (("pypbd", "pypbd", ">=2.2,<2.3"),)
"""The library and the versions its constraint's law (and :func:`hybmss.models.pbd.engine.svk_forces`,
its formulas re-implemented) were read and measured at."""


class PbdModel(EngineModel):
    """The library's tetrahedra with one of its solid methods (module docstring)."""

    requires = REQUIRES
    law_checked = False  # its forces are the harness's svk_forces: a law check would measure the harness
    method: str = "xpbd-fem"
    engine = "PositionBasedDynamics"
    precisions = ("f64",)
    static_rest_rtol = STATIC_REST_RTOL
    cfl = CFL
    settles = True

    def make_body(self, system, dt: float, ramp_time: float, **kw):
        return _engine().PbdBody(system, self.method, dt, ramp_time, **kw)

    def tet_body_refused(self) -> str:
        return ""

    def make_tet_body(self, body, material, holds, dt: float, ramp_time: float, *, damping: float = 0.0):
        if not 0.0 <= material.nu <= NU_MAX:
            raise SceneNotRepresentable(f"nu must lie in [0, {NU_MAX}] for {self.name}, got {material.nu:g}")
        return _engine().PbdBody.on_tets(body, material, holds, dt, ramp_time, damping=damping, method=self.method)

    def check_scene(self, scene) -> None:
        nu = scene.material.nu
        if not 0.0 <= nu <= NU_MAX:
            raise SceneNotRepresentable(f"nu must lie in [0, {NU_MAX}] for {self.name} (its XPBD FEM constraint "
                                        f"makes no correction outside it), got {nu:g}")


class PbdXpbdFem(PbdModel):
    """The library's XPBD FEM step; its forces are the harness's re-implementation (``svk_forces``)."""

    name = "pbd-xpbd-fem"
    method = "xpbd-fem"
    label = "PositionBasedDynamics (pypbd) XPBD FEM tetrahedra, St Venant-Kirchhoff (forces re-implemented)"
    style = Style("#e377c2", "P", "-.")
    order = 46


MODELS, UNAVAILABLE = engine_models(REQUIRES, (PbdXpbdFem(),))
