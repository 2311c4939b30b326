"""``hybmss``: the hybrid mass-spring model of [G20] — edge, face-diagonal and inner-diagonal
springs calibrated for G, plus a per-cell volume energy of stiffness κ for ν (SPEC §2–3).

The folder holds the model (this module, the registry's ``MODEL``) and the stepper of its spring
and volume lattice (:mod:`hybmss.models.hybmss.stepper`: the generated stencil kernel and its
NumPy twin), which the variants (``hybmss-fd``, ``hybmss-cf``, [B09]'s cells, plug-ins) share."""

from __future__ import annotations

from dataclasses import dataclass, field

from ...calibrate import G_e_form, hybrid_springs, kappa_e_form, kappa_from
from ..base import ModelBase, Style, check
from .stepper import LatticeStepper

VOLUME_ENERGIES = ("quadratic", "squared")
"""Volume-energy forms: ``quadratic`` is κ/2 Vc ((V'−Vc)/Vc)² ([G20] eq. 5.8);
``squared`` is κ/2 Vc ((V'²−Vc²)/(2Vc²))², the alternative [G20] mentions."""


@dataclass(frozen=True)
class HybridParameters:
    """- ``A``: face-diagonal to inner-diagonal stiffness ratio kf/kc (SPEC §2), ≥ 0.
    - ``e_form``: spring constants from [G20] eq. 5.12 in terms of E (assumes E = 5G/2, exact
      only at ν = 1/4); kept to test how the publication's tables were produced.  The default
      builds them from G = E/(2(1+ν)), right at every ν.
    - ``volume_energy``: ``quadratic`` ([G20]) or ``squared`` (the alternative it mentions)."""

    A: float = field(default=1.0, metadata={"help": "face/inner diagonal stiffness ratio kf/kc (>= 0)"})
    e_form: bool = field(default=False, metadata={"help": "spring constants from [G20] eq. 5.12 (E = 5G/2)"})
    volume_energy: str = field(default="quadratic", metadata={"help": "form of the per-cell volume energy",
                                                              "choices": VOLUME_ENERGIES})

    def __post_init__(self):
        object.__setattr__(self, "A", check("A (face/inner diagonal stiffness ratio)", self.A, 0.0))
        if self.e_form not in (True, False):
            raise ValueError(f"e_form must be true or false, got {self.e_form!r}")
        object.__setattr__(self, "e_form", bool(self.e_form))
        if self.volume_energy not in VOLUME_ENERGIES:
            raise ValueError(f"volume_energy must be one of {', '.join(VOLUME_ENERGIES)}; "
                             f"got {self.volume_energy!r}")


class HybMSS(ModelBase):
    name = "hybmss"
    label = "hybrid MSS [G20]: springs for G, volume energy for nu"
    style = Style("#1f77b4", "o")
    Parameters = HybridParameters
    order = 0
    E_FORM_STYLE = Style("#9467bd", "D")

    def constants(self, p, material, le):
        if p.e_form:
            return hybrid_springs(G_e_form(material), p.A, le, kappa_e_form(material))
        return hybrid_springs(material.G, p.A, le, kappa_from(material))

    def volume_energy(self, p) -> str:
        return p.volume_energy

    def stepper(self, system, dt: float, *, ramp_time: float, kernel: str = "numba", precision: str = "f64",
                threads: int = 1):
        """The lattice's stepper (:class:`.stepper.LatticeStepper`); the explicit loop also runs it for
        every model that has no stepper of its own."""
        return LatticeStepper(system, dt, ramp_time=ramp_time, kernel=kernel, precision=precision, threads=threads)

    def variant(self, p) -> str:
        return f"{self.name} (E-form)" if p.e_form else self.name

    def styles(self) -> dict:
        return {self.name: self.style, f"{self.name} (E-form)": self.E_FORM_STYLE}

    def tag(self, p) -> str:
        return f"{self.name}-Eform" if p.e_form else self.name

    def study_variants(self, nu: float) -> tuple[dict, ...]:
        """The G-form, and the E-form of [G20] eq. 5.12 where it differs (ν ≠ 1/4)."""
        return ({},) if nu == 0.25 else ({}, {"e_form": True})


MODEL = HybMSS()
