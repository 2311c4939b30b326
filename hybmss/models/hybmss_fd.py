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
    published = {"G20": "hybmss-fd"}
    studies = tuple(r for r in HybMSS.studies if r != "b09")

    def run_cost(self, scene, kind: str) -> float:
        """Static: 16× a conservative model's (without face diagonals the cells have zero-energy
        modes and Newton follows an indefinite path; 8×8×48 beam at ν = 0.499: 12 s at 5 %,
        60–180 s at 20 %)."""
        return super().run_cost(scene, kind) * (16.0 if kind == "static" else 1.0)


MODEL = HybMSSFD()
