"""Effective elastic moduli of a model variant, measured with the static solver (SPEC §8).

- Uniaxial stress: a cube of ``n³`` cells between two frictionless plates (``slide``, only u_z
  prescribed), lateral faces free, one corner pinned in x and y and a second corner in y (no
  rigid motion).  The top plate pulls by ε H and 2ε H; with the plate forces F(ε), F(2ε),
  ``E_eff = (4 F(ε) − F(2ε)) / (2 ε A)`` (Richardson: cancels the O(ε²) geometric term), and
  ``ν_eff`` likewise from the mean lateral displacement of the x faces.  Only tension is used:
  under compression the zero-energy modes of ``hybmss-fd`` buckle (its homogeneous compressed
  state is a saddle of the energy).
- Simple shear: every boundary particle follows ``u = γ (z − z0) e_x``; interior particles are
  free.  For a homogeneous state the stored energy is ``W = ½ G γ² V`` (det F = 1 exactly), so
  ``G_eff = 2 W / (γ² V)``.  A non-conservative model (``baudet2009``'s corrections) has no
  energy: its G_eff is the mean shear stress from the plate reactions over γ
  (:func:`shear_stress_from_reactions`).

For ``hybmss`` and ``hybmss-fd`` these equal E, ν and E/(2(1+ν)) for every ν in (−1, ½)
(SPEC §8); ``hybmss-cf`` gives ν_eff = 1/4; the E-form of [G20] eq. 5.12 does not.
"""

from __future__ import annotations

import numpy as np

from .experiments import shear_scene, uniaxial_scene
from .forces import internal_forces
from .scene import Material, Model, Scene
from .solvers import check_nu, solve_static
from .system import build

STRAIN_RANGE = (1e-6, 1e-2)
"""Strains at which :func:`measure_moduli` measures: a modulus is the response to a nonzero
strain (0 has the rest state as its answer and no modulus); below 1e-6 the plate reactions
near ν = ½ sink into round-off, above 1 % the finite-strain terms left by the Richardson step
exceed 1e-4 of E (ν = 0.3)."""


def _uniaxial(scene: Scene):
    r = solve_static(scene)
    n, le = scene.body.shape[0], scene.body.le
    X, u = r.X, r.u
    xm = np.isclose(X[:, 0], 0.0)
    xp = np.isclose(X[:, 0], n * le)
    lateral = (u[xp, 0].mean() - u[xm, 0].mean()) / (n * le)
    return r.reactions["top"].force[2], lateral


def shear_stress_from_reactions(scene: Scene, result) -> float:
    """Mean shear stress σ̄_xz (Pa) of a body held by plates, from the forces R_a the plates
    exert on their particles (average-stress theorem for a body in equilibrium:
    ``σ̄ = (1/V) Σ_a R_a ⊗ x_a``), symmetrized.  Valid for any force law, conservative or not."""
    S = build(scene)
    x = result.x
    R = -internal_forces(S, x)
    held = S.fixed.any(axis=1)
    sig = np.einsum("ai,aj->ij", R[held], x[held]) / scene.body.volume
    return float(0.5 * (sig[0, 2] + sig[2, 0]))


def measure_moduli(model: Model, material: Material, strain: float = 1e-4, n: int = 2) -> dict:
    """``{"E_eff", "nu_eff", "G_eff"}`` of ``model`` built for ``material``.  ``ValueError`` for a
    strain outside :data:`STRAIN_RANGE` or ν outside :data:`hybmss.solvers.NU_RANGE`."""
    lo, hi = STRAIN_RANGE
    if not (lo <= strain <= hi):
        raise ValueError(f"strain={strain!r} is outside [{lo:g}, {hi:g}]: moduli are measured from the response "
                         "to a small nonzero tension")
    check_nu(material.nu)
    le = 1.0
    H = n * le
    A = H * H
    base = uniaxial_scene(model, material, strain, n, le)
    F1, lat1 = _uniaxial(base)
    F2, lat2 = _uniaxial(uniaxial_scene(model, material, 2.0 * strain, n, le))
    E_eff = (4.0 * F1 - F2) / (2.0 * strain * A)
    nu_eff = -(4.0 * lat1 - lat2) / (2.0 * strain)
    shear = shear_scene(model, material, strain, 3, le)
    sh = solve_static(shear)
    if not model.conservative:  # no energy: G from the plate reactions
        G_eff = shear_stress_from_reactions(shear, sh) / strain
    else:
        W = sh.energy.get("springs", 0.0) + sh.energy.get("volume", 0.0)
        G_eff = 2.0 * W / (strain**2 * sh.volume0)
    return {"E_eff": float(E_eff), "nu_eff": float(nu_eff), "G_eff": float(G_eff)}
