"""Hyperelastic laws in total Lagrangian form (SPEC §9).

With the deformation gradient ``F = I + ∇u``, ``J = det F``, ``C = FᵀF``, ``E = ½(C − I)``:

- compressible Neo-Hookean  ``ψ = μ/2 (I₁ − 3) − μ ln J + λ/2 (ln J)²``,  ``I₁ = tr C``;
- St Venant–Kirchhoff        ``ψ = λ/2 (tr E)² + μ E:E``.

Both are written ``ψ = W₀(F) + λ/2 g(F)²`` with a volumetric measure ``g`` (``ln J`` for
Neo-Hookean, ``tr E`` for SVK).  The displacement formulation uses ψ directly; the mixed u–p
formulation replaces ``λ/2 g²`` by ``p g − p²/(2λ)`` (maximizing over p gives back ``p = λ g``
and ψ), so the same law is reproduced exactly when ``p`` is resolved.

Each function returns fields with the tensor indices last: ``F[..., i, J]``.

- ``W₀, P₀ = ∂W₀/∂F, A₀ = ∂²W₀/∂F∂F`` (``A₀[..., i, J, k, L]``);
- ``g, G = ∂g/∂F, H = ∂²g/∂F∂F``.

Derivatives (``F⁻¹`` written ``f``):
Neo-Hookean ``P₀ = μ(F − F⁻ᵀ)``, ``A₀ = μ δ_ik δ_JL + μ f_Li f_Jk``;
``g = ln J``, ``G = F⁻ᵀ``, ``H = −f_Li f_Jk``.
SVK ``W₀ = μ E:E``, ``P₀ = 2μ F E``, ``A₀ = 2μ δ_ik E_JL + μ((FFᵀ)_ik δ_JL + F_iL F_kJ)``;
``g = tr E``, ``G = F``, ``H = δ_ik δ_JL``.
At ``F = I`` both tangents reduce to the linear-elastic ``λ δ_iJ δ_kL + μ(δ_ik δ_JL + δ_iL δ_Jk)``.
"""

from __future__ import annotations

import numpy as np

LAWS = ("neo-hookean", "svk")

_I = np.eye(3)
_II = np.einsum("ik,jl->ijkl", _I, _I)  # δ_ik δ_JL


def kinematics(law: str, F: np.ndarray, tangent: bool = True, J: np.ndarray | None = None):
    """What both parts of ``law`` take from ``F``, computed once for the two: for Neo-Hookean
    ``(J, F⁻¹, f_Li f_Jk)`` (the last, the product in both tangents, only with ``tangent``);
    ``None`` for SVK, whose parts use ``F`` alone.  ``J``: ``det F`` if the caller has it."""
    if law != "neo-hookean":
        return None
    J = np.linalg.det(F) if J is None else J
    Finv = np.linalg.inv(F)
    ff = np.einsum("...Li,...Jk->...iJkL", Finv, Finv) if tangent else None
    return J, Finv, ff


def deviatoric(law: str, F: np.ndarray, mu: float, tangent: bool = True, kin=None):
    """``(W₀, P₀, A₀)`` of ``law`` at ``F[..., 3, 3]`` (``A₀`` is ``None`` without ``tangent``);
    ``kin``: :func:`kinematics` of ``F`` (computed here if not given)."""
    if law == "neo-hookean":
        J, Finv, ff = kinematics(law, F, tangent) if kin is None else kin
        FinvT = np.swapaxes(Finv, -1, -2)
        I1 = np.einsum("...iJ,...iJ->...", F, F)
        W0 = 0.5 * mu * (I1 - 3.0) - mu * np.log(J)
        P0 = mu * (F - FinvT)
        if not tangent:
            return W0, P0, None
        A0 = mu * _II + mu * ff
        return W0, P0, A0
    if law == "svk":
        C = np.einsum("...kI,...kJ->...IJ", F, F)
        E = 0.5 * (C - _I)
        W0 = mu * np.einsum("...IJ,...IJ->...", E, E)
        P0 = 2.0 * mu * np.einsum("...iI,...IJ->...iJ", F, E)
        if not tangent:
            return W0, P0, None
        FFt = np.einsum("...iI,...kI->...ik", F, F)
        A0 = (
            2.0 * mu * np.einsum("ik,...JL->...iJkL", _I, E)
            + mu * np.einsum("...ik,JL->...iJkL", FFt, _I)
            + mu * np.einsum("...iL,...kJ->...iJkL", F, F)
        )
        return W0, P0, A0
    raise ValueError(f"law must be one of {', '.join(LAWS)}; got {law!r}")


def volumetric(law: str, F: np.ndarray, tangent: bool = True, kin=None):
    """``(g, G, H)``: the volumetric measure of ``law`` and its first two derivatives
    (``H`` is ``None`` without ``tangent``); ``kin`` as for :func:`deviatoric`."""
    if law == "neo-hookean":
        J, Finv, ff = kinematics(law, F, tangent) if kin is None else kin
        g = np.log(J)
        G = np.swapaxes(Finv, -1, -2)
        if not tangent:
            return g, G, None
        H = -ff
        return g, G, H
    if law == "svk":
        g = 0.5 * (np.einsum("...iJ,...iJ->...", F, F) - 3.0)
        G = F.copy()
        if not tangent:
            return g, G, None
        H = np.broadcast_to(_II, F.shape[:-2] + (3, 3, 3, 3))
        return g, G, H
    raise ValueError(f"law must be one of {', '.join(LAWS)}; got {law!r}")


def energy_density(law: str, F: np.ndarray, lam: float, mu: float) -> np.ndarray:
    """``ψ(F)`` of the displacement formulation."""
    kin = kinematics(law, F, tangent=False)
    W0, _, _ = deviatoric(law, F, mu, tangent=False, kin=kin)
    g, _, _ = volumetric(law, F, tangent=False, kin=kin)
    return W0 + 0.5 * lam * g**2


def first_piola(law: str, F: np.ndarray, lam: float, mu: float) -> np.ndarray:
    """``P = ∂ψ/∂F``."""
    kin = kinematics(law, F, tangent=False)
    _, P0, _ = deviatoric(law, F, mu, tangent=False, kin=kin)
    g, G, _ = volumetric(law, F, tangent=False, kin=kin)
    return P0 + lam * g[..., None, None] * G
