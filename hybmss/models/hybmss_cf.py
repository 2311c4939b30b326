"""``hybmss-cf``: the cubic spring lattice alone, no volume energy.  Springs alone give ν = 1/4
whatever ν is asked, so they are calibrated to reproduce E (G = 2E/5, the E-form, exact for it)."""

from __future__ import annotations

from ..calibrate import G_e_form, hybrid_springs
from .base import Style
from .hybmss import HybMSS


class HybMSSCF(HybMSS):
    name = "hybmss-cf"
    label = "cubic spring lattice, no volume energy (nu = 1/4)"
    style = Style("#2ca02c", "^")
    order = 2

    def constants(self, p, material, le):
        return hybrid_springs(G_e_form(material), p.A, le, 0.0)

    def study_variants(self, nu: float) -> tuple[dict, ...]:
        return ({},)


MODEL = HybMSSCF()
