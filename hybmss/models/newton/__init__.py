"""NVIDIA Newton's soft bodies (on Warp) as a model: ``newton-semi`` (``SolverSemiImplicit``,
explicit, on Warp's ``cpu`` device).

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
to 3e-4 at ν ∈ {0, 0.25, 0.45}; at the default strain 1e-4 the float32 state leaves E_eff 1.3 %
high at ν = 0.45).  ν must leave ``k_lambda > 0``: ν > −5/14.

Refused before any work: surface loads, ν ≤ −5/14, two threads, ``precision`` other than f32
(Warp's particle state is float32).
"""

from __future__ import annotations

import importlib.util
import warnings

from .._engine_model import EngineModel, SceneNotRepresentable
from ..base import Style

STATIC_REST_RTOL = 1e-3
"""Rest tolerance of the static answer (the explicit runs' default, :data:`hybmss.explicit.REST_RTOL`):
below it the free-force residual of a float32 state is its force resolution
(:meth:`hybmss.models.newton.engine.NewtonBody.force_resolution`), reached once the run has
settled (:data:`hybmss.models._engine_model.SETTLE`)."""


def available() -> bool:
    """Whether the ``newton`` and ``warp`` packages are installed (found, not imported)."""
    try:
        return importlib.util.find_spec("newton") is not None and importlib.util.find_spec("warp") is not None
    except (ImportError, ValueError):
        return False


def _engine():
    from . import engine
    return engine


class NewtonModel(EngineModel):
    """Newton's tetrahedra with one of its solvers (module docstring)."""

    solver: str = "semi"
    engine = "Newton"
    precisions = ("f32",)
    static_rest_rtol = STATIC_REST_RTOL

    def make_body(self, system, dt: float, ramp_time: float, **kw):
        return _engine().NewtonBody(system, self.solver, dt, ramp_time, **kw)

    def check_scene(self, scene) -> None:
        if not scene.material.nu > -5.0 / 14.0:
            raise SceneNotRepresentable(f"nu must lie in (-5/14, 0.5) for {self.name} (its k_lambda = lambda + "
                                        f"5 mu/6 must be > 0), got {scene.material.nu:g}")


class NewtonSemi(NewtonModel):
    name = "newton-semi"
    solver = "semi"
    label = "Newton (Warp) SolverSemiImplicit, stable Neo-Hookean tetrahedra"
    style = Style("#76b900", "^", "--")
    order = 45


if available():
    MODELS = (NewtonSemi(),)
else:
    # one line (no source line under it): the model is left out, nothing else changes
    warnings.warn_explicit("the newton package (or warp-lang) is not installed: the newton-* models are left out "
                           "(pip install 'newton>=1.8')", RuntimeWarning, "hybmss.models.newton", 0,
                           module=__name__)
    MODELS = ()
