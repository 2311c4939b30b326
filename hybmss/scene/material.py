"""The material and the model of a scene.

Isotropic linear elasticity from Young's modulus E and Poisson ratio ν:
``G = E / (2(1+ν))``, ``λ = E ν / ((1+ν)(1−2ν))``, ``K = E / (3(1−2ν))``, admissible for
ν in the open interval (−1, ½) (:data:`NU_OPEN_RANGE`).  The model is a registry name with its
parameters (:mod:`hybmss.models`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .. import models as registry
from .checks import _finite

NU_OPEN_RANGE = (-1.0, 0.5)
"""The Poisson ratios of a stable isotropic material, an open interval: ν → −1 loses the bulk
modulus, ν → ½ the shear modulus relative to it.  Every check of ν in the harness, its studies and
its report uses it (:func:`admissible_nu`); the solvers' narrower float64 range is
:data:`NU_RANGE`."""


def admissible_nu(nu: float) -> bool:
    """Whether ``nu`` lies in :data:`NU_OPEN_RANGE` (end points excluded)."""
    lo, hi = NU_OPEN_RANGE
    return lo < nu < hi


NEARLY_INCOMPRESSIBLE_NU = 0.45
"""From this Poisson ratio on a material counts as nearly incompressible: a displacement-only
element locks, so the FEM reference's ``element='auto'`` takes its mixed u–p element, and the
studies' size and cost estimates count that element (:func:`nearly_incompressible`)."""


def nearly_incompressible(nu: float) -> bool:
    """Whether ``nu`` ≥ :data:`NEARLY_INCOMPRESSIBLE_NU`."""
    return nu >= NEARLY_INCOMPRESSIBLE_NU


NU_RANGE = (-0.99, 0.49999)
"""Poisson ratios for which the Newton solvers (static, implicit) reach equilibrium in float64 and
the moduli come out right (tests/verification/test_moduli.py).  Beyond ν = 0.49999 the volume term
(κ > 1.6e4 E) drowns the plate reactions in its round-off; below ν = −0.99 the shear springs
(k > 50 E le) do, and finite-strain terms amplified by G/K make the measured E wrong by more than
1 % at a strain of 1e-4."""


def check_nu(nu: float) -> None:
    """Raise ``ValueError`` for a Poisson ratio outside :data:`NU_RANGE`."""
    lo, hi = NU_RANGE
    if not (lo <= nu <= hi):
        raise ValueError(f"nu={nu!r} is outside [{lo}, {hi}], the range in which the static and implicit "
                         "solvers reach an equilibrium in float64")


@dataclass(frozen=True)
class Material:
    """Isotropic linear-elastic constants: Young's modulus E (Pa), Poisson ratio ν, density ρ."""

    E: float
    nu: float
    rho: float = 1000.0

    def __post_init__(self):
        E = _finite("E", self.E)
        nu = _finite("nu", self.nu)
        rho = _finite("rho", self.rho)
        if E <= 0:
            raise ValueError(f"E (Young's modulus) must be > 0 Pa, got {E}")
        if not admissible_nu(nu):
            lo, hi = NU_OPEN_RANGE
            raise ValueError(f"nu (Poisson ratio) must lie in the open interval ({lo:g}, {hi:g}), got {nu}")
        if rho < 0:
            raise ValueError(f"rho (density) must be >= 0 kg/m^3, got {rho}")
        object.__setattr__(self, "E", E)
        object.__setattr__(self, "nu", nu)
        object.__setattr__(self, "rho", rho)

    @property
    def G(self) -> float:
        """Shear modulus G = E / (2(1+ν))."""
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def lam(self) -> float:
        """Lamé λ = E ν / ((1+ν)(1−2ν))."""
        return self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))

    @property
    def K(self) -> float:
        """Bulk modulus K = E / (3(1−2ν))."""
        return self.E / (3.0 * (1.0 - 2.0 * self.nu))


@dataclass(frozen=True, init=False)
class Model:
    """The model of a scene: its registry ``name`` and its parameters under their own names.

    ``Model("hybmss-fd")``, ``Model("hybmss", A=3.0, e_form=True)``: the parameters are validated
    by the model (:mod:`hybmss.models`) and missing or ``None`` ones take its defaults, so that
    ``to_dict`` (and the scene digest) records every parameter.  ``model.A`` reads a parameter;
    ``model.spec`` is the registered model object (name, style, solvers, calibration, ...).
    Without a name it is the registry's default model (:func:`hybmss.models.default_name`).
    """

    name: str
    params: object

    def __init__(self, name: str | None = None, **params):
        spec = registry.get(registry.default_name() if name is None else name)
        object.__setattr__(self, "name", spec.name)
        object.__setattr__(self, "params", spec.parameters(**params))

    @property
    def spec(self):
        return registry.get(self.name)

    def __getattr__(self, key):
        params = self.__dict__.get("params")
        if params is not None and not key.startswith("_") and hasattr(params, key):
            return getattr(params, key)
        raise AttributeError(f"model {self.__dict__.get('name')!r} has no parameter or attribute {key!r}")

    @property
    def variant(self) -> str:
        """Name of this model and parameter set in tables and legends."""
        return self.spec.variant(self.params)

    @property
    def conservative(self) -> bool:
        return self.spec.conservative

    def to_dict(self) -> dict:
        return {"name": self.name, **dataclasses.asdict(self.params)}

    def replace(self, **kw) -> "Model":
        """A copy with ``kw`` changed; a new ``name`` keeps the parameters that model also has."""
        name = kw.pop("name", self.name)
        keep = registry.get(name).parameter_names()
        carried = {k: v for k, v in dataclasses.asdict(self.params).items() if k in keep} \
            if name != self.name else dataclasses.asdict(self.params)
        if name != self.name:
            # parameters equal to the old model's defaults are not carried: they take the new one's
            defaults = dataclasses.asdict(self.spec.parameters())
            carried = {k: v for k, v in carried.items() if v != defaults.get(k)}
        return Model(name, **{**carried, **kw})

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in dataclasses.asdict(self.params).items())
        return f"Model({self.name!r}{', ' if args else ''}{args})"
