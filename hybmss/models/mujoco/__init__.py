"""MuJoCo's deformable flex bodies (``<flex dim="3">``) as models: ``mujoco-tet``,
``mujoco-trilinear``, ``mujoco-quadratic`` (one per element kind).

The engine runs its own code from its own package (``mujoco`` ≥ 4.0, imported only when one of
these models runs: :mod:`hybmss.models.mujoco.engine`, which also says how a scene becomes an MJCF).

Material law, from the engine's source (github.com/google-deepmind/mujoco, ``src/engine``) and
its documentation shipped in the wheel (``mujoco/doc/XMLreference.rst``, ``flex/elasticity``;
``doc/modeling.rst``, "Parametrization types"), measured here (tests/verification/test_engine_mujoco.py):

- ``mujoco-tet`` (``dof="full"``, linear tetrahedra): Saint Venant–Kirchhoff.
  ``engine_elasticity.h``: ``mj_stretchElongation`` takes each of the tetrahedron's 6 edges'
  ``l² − l0²`` (the Green strain in edge coordinates), ``mj_stretchTension`` contracts it with the
  element's precomputed metric (``mjModel.flex_stiffness``, 21 numbers of a symmetric 6×6 plus 3
  for a stable Neo-Hookean variant, zero here: checked), ``mj_stretchForce`` scatters
  ``−tension · (x_i − x_j)`` to the vertices; ``engine_passive.c`` adds it to ``qfrc_spring``.
  The metric is the documented energy density ``μ tr(ε²) + λ/2 tr(ε)²`` with
  ``μ = E/(2(1+ν))``, ``λ = Eν/((1+ν)(1−2ν))``: at small strain linear elasticity in E, ν, no
  Lamé shift.  Measured: a homogeneous uniaxial strain ε gives the nominal stress
  (λ + 2μ) ε (1 + 3ε/2 + O(ε²)), the SVK law's ``(1 + ε)(λ + 2μ)(ε + ε²/2)``.
- ``mujoco-trilinear`` / ``mujoco-quadratic`` (``dof="trilinear"``/``"quadratic"``, 8-/27-node
  cells of an interpolation grid equal to the voxels): ``engine_passive.c`` (the ``flex_interp``
  branch) applies the cell's constant stiffness (``flex_stiffness``, 24² / 81² numbers per cell)
  in the cell's rotated frame (``K_rot``): corotational linear.  Measured: a rigid rotation of
  0.3 rad gives forces below 1e-12 N, a stretch's forces are linear in it to round-off; at small
  strain the linear Hex8 / Hex27 element in E, ν.
- ν: the documented range is [0, ½); a negative ν is refused (``ValueError`` naming ``nu``).

Integrator (the parameter ``integrator``; ``doc/computation/index.rst``, "Integrators", and
``doc/modeling.rst``, "Deformables", in the wheel), for a linear mode ``ẍ = −ω² x`` of step ``h``:

- ``Euler`` (the default, the static rest runs): semi-implicit Euler, ``v' = v + h M⁻¹ f(q)``,
  ``q' = q + h v'`` (no joint damping, so no implicit factor): the flex's elastic forces explicit,
  stable for ``ω h < 2``, period ``T = 2π h / (2 arcsin(ω h / 2))``, no numerical damping;
- ``RK4``: the classical fourth-order Runge–Kutta on ``(q, v)``; stable for ``ω h ≤ 2√2``, its
  amplification ``R(z) = 1 + z + z²/2 + z³/6 + z⁴/24`` at ``z = ±iωh`` (period and decay of
  ``arg R``, ``|R|``: damping ``(ωh)⁶/144`` per step to leading order);
- ``discrete``: ``(M + h D + h² K) a = f(q) − h K v``, ``v' = v + h a``, ``q' = q + h v'`` with ``K``
  the flex elasticity's stiffness (implicit in position, one Newton step): for a linear mode
  exactly backward Euler, amplification ``g = 1/(1 + iωh)``, unconditionally stable, period
  ``2π h / atan(ωh)``, decay ``|g| = (1 + ω²h²)^(−1/2)`` per step;
- ``implicit``, ``implicitfast``: implicit in velocity only (``M + h D``, no ``K``); MuJoCo 4.0
  refuses flex elasticity under them at its first step ("flex elasticity is no longer integrated
  implicitly under integrator='implicit' and 'implicitfast': set integrator='discrete'"), so they
  are refused here before any work (``ValueError`` naming ``integrator``).

What the models refuse (before any work): surface loads (``Scene.loads``: MuJoCo has no surface
traction on a flex; the harness would have to make nodal forces of them itself), a negative ν,
a body that is not a box for the interpolated kinds (their grid spans the bounding box), more
than one thread, float32.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .._engine_model import EngineModel, SceneNotRepresentable, engine_models
from ..base import Style

KINDS = ("tet", "trilinear", "quadratic")
STATIC_REST_RTOL = 1e-7
"""Rest tolerance of the static answer (:func:`hybmss.explicit.rest_report`'s ``rtol``): the
free force residual below 1e-7 of the force scale, so that the state is the equilibrium to
well below the 1e-3 of the same-mesh checks."""
CFL = 0.9
"""Step of the static run as a fraction of the stability limit ``2/ω_max``."""



INTEGRATORS = ("Euler", "RK4", "discrete")
"""MuJoCo's integrators that step flex elasticity (module docstring)."""
REFUSED_INTEGRATORS = ("implicit", "implicitfast")
RELEASED_INTEGRATOR = "discrete"
"""The integrator a user picks for a flex body's dynamics: the one MuJoCo's documentation
recommends for flex elasticity ("Deformables": the only one implicit in its stiffness)."""


@dataclass(frozen=True)
class MujocoParameters:
    """- ``integrator``: MuJoCo's ``<option integrator>`` (module docstring), one of
      :data:`INTEGRATORS`; ``Euler`` by default."""

    integrator: str = field(default="Euler", metadata={"help": "MuJoCo's integrator", "choices": INTEGRATORS})

    def __post_init__(self):
        if self.integrator in REFUSED_INTEGRATORS:
            raise ValueError(f"integrator must be one of {', '.join(INTEGRATORS)} for a MuJoCo flex, got "
                             f"{self.integrator!r}: MuJoCo 4.0 does not integrate flex elasticity under implicit "
                             "or implicitfast (its error: set integrator='discrete', or 'Euler' with a small step)")
        if self.integrator not in INTEGRATORS:
            raise ValueError(f"integrator must be one of {', '.join(INTEGRATORS)}, got {self.integrator!r}")


def _engine():
    from . import engine
    return engine


REQUIRES = (("mujoco", "mujoco", ">=4.0,<4.1"),)
"""The engine and the versions its laws were read and measured at (module docstring): MuJoCo
changes its flex elements between minor versions (``flex_stiffness``, the interpolated kinds)."""


class MujocoModel(EngineModel):
    """A MuJoCo flex of one element kind (module docstring)."""

    requires = REQUIRES
    Parameters = MujocoParameters
    released_parameters = {"integrator": RELEASED_INTEGRATOR}
    """The parameters of its released transients (:func:`hybmss.released.released_model`)."""
    kind: str = "tet"
    engine = "MuJoCo"
    precisions = ("f64",)
    static_rest_rtol = STATIC_REST_RTOL
    cfl = CFL

    def make_body(self, system, dt: float, ramp_time: float, **kw):
        integrator = getattr(system.scene.model.params, "integrator", "Euler")
        return _engine().MujocoBody(system, self.kind, dt, ramp_time, integrator=integrator, **kw)

    def tet_body_refused(self) -> str:
        if self.kind != "tet":
            return (f"body: {self.name} keeps boxes (its {self.kind} interpolation grid spans a voxel box) and "
                    "cannot run on a tetrahedral body; use mujoco-tet")
        return ""

    def make_tet_body(self, body, material, holds, dt: float, ramp_time: float, *, damping: float = 0.0):
        if self.tet_body_refused():
            raise SceneNotRepresentable(self.tet_body_refused())
        if not 0.0 <= material.nu < 0.5:
            raise SceneNotRepresentable(f"nu must lie in [0, 0.5) for {self.name}, got {material.nu:g}")
        self.check_law()
        return _engine().MujocoBody.on_tets(body, material, holds, dt, ramp_time, damping=damping)

    def variant(self, p) -> str:
        return self.name if p.integrator == "Euler" else f"{self.name} ({p.integrator})"

    def tag(self, p) -> str:
        return self.name if p.integrator == "Euler" else f"{self.name}-{p.integrator}"

    def styles(self) -> dict:
        return {self.variant(MujocoParameters(i)): self.style for i in INTEGRATORS}

    def check_scene(self, scene) -> None:
        if scene.material.nu < 0:
            raise SceneNotRepresentable(f"nu must lie in [0, 0.5) for {self.name} (MuJoCo's documented range of "
                                        f"poisson), got {scene.material.nu:g}")
        if self.kind != "tet" and not bool(scene.body.mask.all()):
            raise SceneNotRepresentable(f"body: {self.name} needs a box-shaped body (its interpolation grid spans "
                                        "the bounding box); use mujoco-tet for other shapes")


class MujocoTet(MujocoModel):
    name = "mujoco-tet"
    kind = "tet"
    label = "MuJoCo flex, linear tetrahedra (St Venant-Kirchhoff)"
    style = Style("#17becf", "v", "--")
    order = 40


class MujocoTrilinear(MujocoModel):
    name = "mujoco-trilinear"
    kind = "trilinear"
    label = "MuJoCo flex, trilinear 8-node cells (corotational linear)"
    style = Style("#bcbd22", "s", "--")
    order = 41


class MujocoQuadratic(MujocoModel):
    name = "mujoco-quadratic"
    kind = "quadratic"
    label = "MuJoCo flex, quadratic 27-node cells (corotational linear)"
    style = Style("#8c564b", "D", "--")
    order = 42


MODELS, UNAVAILABLE = engine_models(REQUIRES, (MujocoTet(), MujocoTrilinear(), MujocoQuadratic()))
