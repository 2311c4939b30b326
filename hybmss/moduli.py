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

A float32 engine's states (a ``resolution_N`` in their rest report) are equilibria only to their
free-force residual r: the answer carries ``equilibrium_error`` (:func:`float32_errors`: what the
residuals and the positions' rounding leave uncertain in E_eff, ν_eff, G_eff) and
``resolvable_strain`` (the smallest strain at which that is within :data:`PRECISION`, the errors
scaling as 1/ε); with ``judge=True`` an answer outside it is refused with that strain.
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


PRECISION = 1e-3
"""Largest equilibrium error of a float32 engine's moduli answer (relative in E and G, absolute in
ν) that ``judge=True`` accepts: the precision the moduli are compared at."""


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
    return r.reactions["top"].force[2], lateral, r


def float32_errors(material: Material, strain: float, uniaxial: tuple, shear, H: float, V: float) -> dict | None:
    """The equilibrium error of a moduli answer read from float32 states (None when no state has a
    ``resolution_N``: a float64 model).  With r₁, r₂ the free-force residuals (N) of the two
    uniaxial states and r_s the shear state's, A = H²:

    - E_eff = (4F₁ − F₂)/(2εA): an unbalanced free force r may end on either plate, so
      ``δE/E = (4r₁ + r₂)/(2εAE)``;
    - ν_eff from the faces' mean lateral displacements, each position rounded to
      ``ulp(|X|max)/2``: ``δν = 5 ulp/(2εH)``;
    - G_eff = σ̄_xz/γ, σ̄ = (1/V) Σ R ⊗ x over the held nodes: a residual r_s over the height H,
      ``δG/G = r_s H/(VγG)``.

    Returns ``{"equilibrium_error": {...}, "resolvable_strain": ε · max(errors)/PRECISION,
    "resolved": max(errors) <= PRECISION}``."""
    rests = [r.info.get("rest") or {} for r in (*uniaxial, shear)]
    if not any(float(rr.get("resolution_N", 0.0)) > 0.0 for rr in rests):
        return None
    r1, r2, rs = (float(rr["residual_N"]) for rr in rests)
    ulp = float(np.spacing(np.float32(np.abs(uniaxial[0].X).max())))
    err = {"E_eff": (4.0 * r1 + r2) / (2.0 * strain * H * H * material.E),
           "nu_eff": 5.0 * ulp / (2.0 * strain * H),
           "G_eff": rs * H / (V * strain * material.G)}
    worst = max(err.values())
    return {"equilibrium_error": err, "residuals_N": [r1, r2, rs], "resolvable_strain": strain * worst / PRECISION,
            "resolved": bool(worst <= PRECISION)}


def _unresolved(variant: str, strain: float, f32: dict) -> MeasurementError:
    """The refusal of a float32 answer whose equilibrium error exceeds :data:`PRECISION`."""
    e, lo_hi = f32["equilibrium_error"], STRAIN_RANGE
    need = f32["resolvable_strain"]
    step = 10.0 ** (math.floor(math.log10(need)) - 1)
    need = math.ceil(need / step) * step  # two digits, rounded up
    where = (f"the smallest strain it resolves is {need:.2g}: use --strain {need:.2g} or larger" if need <= lo_hi[1]
             else f"it would need strain {need:.2g}, above the allowed {lo_hi[1]:g}")
    return MeasurementError(
        f"{variant}'s float32 states resolve the moduli at strain {strain:g} only to E_eff +/-{100 * e['E_eff']:.2g} %, "
        f"nu_eff +/-{e['nu_eff']:.2g}, G_eff +/-{100 * e['G_eff']:.2g} % (free-force residuals "
        f"{', '.join(f'{r:.2g}' for r in f32['residuals_N'])} N), more than the {PRECISION:g} a modulus is judged "
        f"at; {where}")


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


def check_strain(strain: float) -> None:
    """``ValueError`` for a strain outside :data:`STRAIN_RANGE`."""
    lo, hi = STRAIN_RANGE
    if not (lo <= strain <= hi):
        raise ValueError(f"strain={strain!r} is outside [{lo:g}, {hi:g}]: moduli are measured from the response "
                         "to a small nonzero tension")


def measure_moduli(model: Model, material: Material, strain: float = 1e-4, n: int = 2, judge: bool = False) -> dict:
    """``{"E_eff", "nu_eff", "G_eff"}`` of ``model`` built for ``material``.  ``ValueError`` for a
    strain outside :data:`STRAIN_RANGE` or ν outside :data:`hybmss.scene.NU_RANGE`;
    :class:`MeasurementError` (``judge``) for a state that is not an equilibrium or moduli out of
    bounds."""
    check_strain(strain)
    check_nu(material.nu)
    le = 1.0
    H = n * le
    A = H * H
    base = uniaxial_scene(model, material, strain, n, le)
    F1, lat1, u1 = _uniaxial(base, judge)
    F2, lat2, u2 = _uniaxial(uniaxial_scene(model, material, 2.0 * strain, n, le), judge)
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
    f32 = float32_errors(material, strain, (u1, u2), sh, H, shear.body.volume)
    if f32 is not None:
        m.update(f32)
        if judge and not f32["resolved"]:
            raise _unresolved(model.variant, strain, f32)
    return check_moduli(m, model.variant) if judge else m
