"""``corot-hex8-sri``: the corotational hexahedra of :mod:`hybmss.models.corot_hex8` with selective
reduced integration (λ part of the Hooke matrix at the centre point only): no volumetric locking
as ν → ½."""

from __future__ import annotations

from .base import Style
from .corot_hex8 import CorotHex8Model


class CorotHex8SRI(CorotHex8Model):
    name = "corot-hex8-sri"
    label = "corotational linear Hex8 FEM, selective reduced integration (Hughes 1980)"
    style = Style("#17becf", "P", "--")
    order = 21
    sri = True


MODEL = CorotHex8SRI()
