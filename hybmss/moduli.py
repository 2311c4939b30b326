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
  (:func:`shear_stress_from_reactions`); a model that brings its own static answer on nodes other
  than the lattice particles (MuJoCo's 27-node cells) reports that mean stress itself
  (``info['mean_stress']``).

For ``hybmss`` and ``hybmss-fd`` these equal E, ν and E/(2(1+ν)) for every ν in (−1, ½)
(SPEC §8); ``hybmss-cf`` gives ν_eff = 1/4; the E-form of [G20] eq. 5.12 does not.

With ``judge=True`` (the command line's ``hybmss moduli``) a measurement is judged before it is
returned (:class:`MeasurementError` otherwise; the studies tabulate unstable materials as such): each of the
three states must be near an equilibrium (the largest net force on a free particle at most
:data:`EQUILIBRIUM_TOL` of the largest plate force: a relaxation that stopped where it started is
not one), and the moduli must lie within the bounds of a stable isotropic solid (E > 0, G > 0,
−1 < ν < ½).
"""

from __future__ import annotations

import math

import numpy as np

from .experiments import shear_scene, uniaxial_scene
from .forces import internal_forces
from .scene import NU_OPEN_RANGE, Material, Model, Scene, admissible_nu, check_nu
from .solve import solve_static
from .system import build

STRAIN_RANGE = (1e-6, 1e-2)
"""Strains at which :func:`measure_moduli` measures: a modulus is the response to a nonzero
strain (0 has the rest state as its answer and no modulus); below 1e-6 the plate reactions
near ν = ½ sink into round-off, above 1 % the finite-strain terms left by the Richardson step
exceed 1e-4 of E (ν = 0.3)."""


EQUILIBRIUM_TOL = 0.5
"""Largest net force on a free particle, relative to the largest force on a held one, of a state a
modulus is read from.  Measured: Newton's equilibria 1e-10 and less; xpbd-nh's rest states, which
are equilibria of its energy only to O((h ω)²) for a substep h, 8e-4 (10 substeps, h ω_max = 0.1),
9e-3 (3) and 0.29 (1 substep, h ω_max = 1: the shear test); a relaxation that never moved
(``substeps = 1e12``: a substep of 1e-13 s projects nothing) 0.99999."""


class MeasurementError(RuntimeError):
    """A measurement that is not one (not an equilibrium, or moduli no stable solid has)."""


def equilibrium_error(scene: Scene, result) -> float:
    """``max |f_free| / max |f_held|`` of ``result``'s state, f the internal forces of ``scene``'s
    system (0 at an exact equilibrium)."""
    S = build(scene)
    f = internal_forces(S, result.x)
    held = np.abs(f[S.fixed]).max() if S.fixed.any() else 0.0
    free = np.abs(f[~S.fixed]).max() if (~S.fixed).any() else 0.0
    return float(free / held) if held > 0.0 else (0.0 if free == 0.0 else math.inf)


def _judged(scene: Scene, result, what: str, judge: bool = True):
    if not judge:
        return result
    if not result.converged:
        raise MeasurementError(f"the {what} test of {scene.model.variant} did not reach equilibrium "
                               f"({result.solver}); no modulus measured")
    err = equilibrium_error(scene, result)
    if not err <= EQUILIBRIUM_TOL:
        raise MeasurementError(
            f"the {what} test of {scene.model.variant} ({result.solver}, {result.iterations} steps) stopped "
            f"{'where it started' if err > 0.9 else 'away from equilibrium'}: net forces on free particles "
            f"{100 * err:.3g} % of the plate forces (allowed <= {100 * EQUILIBRIUM_TOL:g} %); no modulus measured: "
            "check the model's parameters (substeps, iterations)")
    return result


def check_moduli(m: dict, variant: str) -> dict:
    """``m`` if its moduli are those of a stable isotropic solid, else :class:`MeasurementError`."""
    bad = [k for k in ("E_eff", "nu_eff", "G_eff") if not math.isfinite(m[k])]
    if bad:
        raise MeasurementError(f"{variant}: non-finite {', '.join(bad)}; no modulus measured")
    why = []
    if not m["E_eff"] > 0.0:
        why.append(f"E_eff = {m['E_eff']:.6g} Pa (a stable solid has E > 0)")
    if not m["G_eff"] > 0.0:
        why.append(f"G_eff = {m['G_eff']:.6g} Pa (a stable solid has G > 0)")
    if not admissible_nu(m["nu_eff"]):
        lo, hi = NU_OPEN_RANGE
        why.append(f"nu_eff = {m['nu_eff']:.6g} (a stable isotropic solid has nu in the open interval "
                   f"({lo:g}, {hi:g}))")
    if why:
        raise MeasurementError(f"{variant} measured {'; '.join(why)}: not a material, the model's "
                               "answer is wrong at these parameters")
    return m


def _uniaxial(scene: Scene, judge: bool = False):
    r = _judged(scene, solve_static(scene), "uniaxial", judge)
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


def measure_moduli(model: Model, material: Material, strain: float = 1e-4, n: int = 2, judge: bool = False) -> dict:
    """``{"E_eff", "nu_eff", "G_eff"}`` of ``model`` built for ``material``.  ``ValueError`` for a
    strain outside :data:`STRAIN_RANGE` or ν outside :data:`hybmss.scene.NU_RANGE`;
    :class:`MeasurementError` (``judge``) for a state that is not an equilibrium or moduli out of
    bounds."""
    lo, hi = STRAIN_RANGE
    if not (lo <= strain <= hi):
        raise ValueError(f"strain={strain!r} is outside [{lo:g}, {hi:g}]: moduli are measured from the response "
                         "to a small nonzero tension")
    check_nu(material.nu)
    le = 1.0
    H = n * le
    A = H * H
    base = uniaxial_scene(model, material, strain, n, le)
    F1, lat1 = _uniaxial(base, judge)
    F2, lat2 = _uniaxial(uniaxial_scene(model, material, 2.0 * strain, n, le), judge)
    E_eff = (4.0 * F1 - F2) / (2.0 * strain * A)
    nu_eff = -(4.0 * lat1 - lat2) / (2.0 * strain)
    shear = shear_scene(model, material, strain, 3, le)
    sh = _judged(shear, solve_static(shear), "shear", judge)
    if sh.info.get("mean_stress") is not None:  # a model whose nodes are not all lattice particles
        sig = sh.info["mean_stress"]  # (its own average-stress readout, as below, over its held nodes)
        G_eff = 0.5 * (sig[0][2] + sig[2][0]) / strain
    elif not model.conservative:  # no energy: G from the plate reactions
        G_eff = shear_stress_from_reactions(shear, sh) / strain
    else:
        W = sh.energy.get("springs", 0.0) + sh.energy.get("volume", 0.0)
        G_eff = 2.0 * W / (strain**2 * sh.volume0)
    m = {"E_eff": float(E_eff), "nu_eff": float(nu_eff), "G_eff": float(G_eff)}
    return check_moduli(m, model.variant) if judge else m
