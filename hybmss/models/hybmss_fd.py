"""``hybmss-fd``: the hybrid model without face diagonals (A = 0): edges and inner diagonals
for G, volume energy for ν ([G20] "HybMSS-FD")."""

from __future__ import annotations

from dataclasses import dataclass, field

from .base import Style
from .hybmss import HybMSS, HybridParameters


@dataclass(frozen=True)
class NoFaceDiagonalParameters(HybridParameters):
    """As :class:`~hybmss.models.hybmss.HybridParameters`, with ``A`` fixed to 0."""

    A: float = field(default=0.0, metadata={"help": "face/inner diagonal stiffness ratio kf/kc (0: none)"})

    def __post_init__(self):
        super().__post_init__()
        if self.A != 0.0:
            raise ValueError(f"A must be 0 for model hybmss-fd (no face diagonals), got {self.A:g}")


class HybMSSFD(HybMSS):
    name = "hybmss-fd"
    label = "hybrid MSS without face diagonals [G20]"
    style = Style("#ff7f0e", "s")
    Parameters = NoFaceDiagonalParameters
    order = 1


MODEL = HybMSSFD()
