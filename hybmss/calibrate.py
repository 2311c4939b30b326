"""Spring constants and volume stiffness of the cubic spring lattices (SPEC §2–4): the formulas
the models of :mod:`hybmss.models` calibrate with.

Hybrid model ([G20] §5.2–5.3).  Linearized springs give the stiffness tensor
``C_ijkl = (1/Vc) Σ_α (k_α/l_α²) r_αi r_αj r_αk r_αl``, which obeys the Cauchy relations
(λ = G).  Isotropy of the cubic cell requires ``ke = 8/3 kc + kf``, and then
``G = (4/3 kc + kf)/le``.  With ``A = kf/kc``::

    G  = E / (2(1+ν))
    kc = 3 G le / (4 + 3A)        kf = A kc        ke = G le (8 + 3A) / (4 + 3A)

The per-cell volume energy ``W_v = Vc κ/2 ((V'−Vc)/Vc)²`` adds κ to λ, so that
``λ = G + κ`` and ``κ = G (4ν − 1)/(1 − 2ν)``.

**[G20] eq. 5.12** also writes ``kc = 6 E le/(5(4+3A))``, ``ke = 2 E le (8+3A)/(5(4+3A))``.
That form assumes E = 5G/2, true only for a pure spring lattice (ν = 1/4); combined with κ it
gives wrong moduli at any other ν.  It is available as ``Model("hybmss", e_form=True)`` only to test how
the publication's tables were produced.

``hybmss-cf`` has springs only, so its Poisson ratio is 1/4 whatever ν is asked; its springs are
calibrated to reproduce E (G = 2E/5), i.e. the E-form, which is exact for it.

``baudet2009`` ([B09]): edges ``kx = E le (4ν+1)/(8(1+ν))`` and inner diagonals
``kd = 3 E le/(8(1+ν))``, both *per cell*: [B09] derives them on a single cube, whose 12 edges
and 4 inner diagonals belong to it alone.  Checked against that derivation: with the cube
stretched by ε along x and ν ε laterally, the x-face carries ``4 kx le ε + (4/3) kd le (1−2ν) ε
= E le² ε`` (E right), and the inner diagonals give ``C_44 = 4 kd/(3 le) = G`` (edges carry no
shear).  A lattice keeps every cell's own share, so an edge shared by 4 cells gets 4 kx: the
edge family constant is ``ke = 4 kx`` (each cell gives ke/4 = kx, SPEC §1) and ``kc = kd``
(an inner diagonal belongs to one cell); then any homogeneous deformation of a body costs the
sum of the single cubes.  No face diagonals, κ = 0; the lateral correction forces (not an
energy) are in :mod:`hybmss.models.baudet2009.corrections`.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Constants:
    """What a model's ``constants(params, material, le)`` returns: the spring constant of each
    family of the cubic lattice and the volume stiffness, for cells of edge ``le``.

    - ``ke`` (N/m): an edge spring (length ``le``) shared by four cells, as in the interior.
      Each cell gives each of its 12 edges ``ke/4`` (Kirchhoff's law, :mod:`hybmss.lattice`):
      an edge on a flat free face gets ``ke/2``, on a free lattice edge ``ke/4``.
    - ``kf`` (N/m): a face-diagonal spring (length ``√2 le``) shared by two cells; each cell gives
      each of its 12 face diagonals ``kf/2``, so a diagonal on a free face gets ``kf/2``.  0: none.
    - ``kc`` (N/m): an inner-diagonal spring (length ``√3 le``), one cell's own; each cell has 4.
      A family whose constant is 0 has no spring at all (it is left out of the system).
    - ``kappa`` (Pa): volume stiffness κ of the per-cell volume energy, ``W_v = Vc κ/2 J²`` with
      ``J = (V' − Vc)/Vc`` (``volume_energy="quadratic"``; ``"squared"`` takes ``J = (V'² −
      Vc²)/(2 Vc²)``), V' the averaged-edge volume ``a·(b×c)``; it adds κ to λ.  Negative for
      ν < 1/4 (the hybrid model's κ = G(4ν − 1)/(1 − 2ν)); 0: no volume term.
    - ``G_springs`` (Pa): the small-strain shear modulus the springs alone give a box of these
      cells, recorded for checks (:func:`hybrid_springs`: ``(4/3 kc + kf)/le``); no force reads
      it; NaN when the lattice has no such closed form (:func:`b09_springs`).

    ``by_family`` orders the spring constants as the lattice's families (edge, face, inner).
    :func:`hybrid_springs` builds the isotropic hybrid set for a shear modulus and ``A = kf/kc``.
    """

    ke: float
    kf: float
    kc: float
    kappa: float
    G_springs: float

    @property
    def by_family(self) -> tuple[float, float, float]:
        return (self.ke, self.kf, self.kc)


def kappa_from(material) -> float:
    """κ = G (4ν − 1)/(1 − 2ν) = E (4ν − 1)/(2(1+ν)(1−2ν)) (SPEC §3)."""
    nu = material.nu
    return material.G * (4.0 * nu - 1.0) / (1.0 - 2.0 * nu)


def kappa_e_form(material) -> float:
    """κ written in terms of E, ``E (4ν − 1)/(2(1+ν)(1−2ν))`` (the E-form's volume stiffness)."""
    nu = material.nu
    return material.E * (4.0 * nu - 1.0) / (2.0 * (1.0 + nu) * (1.0 - 2.0 * nu))


def G_e_form(material) -> float:
    """G = 2E/5 of [G20] eq. 5.12 (E = 5G/2: exact only for springs alone, ν = 1/4)."""
    return 2.0 * material.E / 5.0


def hybrid_springs(G: float, A: float, le: float, kappa: float) -> Constants:
    """Isotropic cubic-cell springs for shear modulus ``G`` and ratio ``A = kf/kc``:
    ``kc = 3 G le/(4 + 3A)``, ``kf = A kc``, ``ke = G le (8 + 3A)/(4 + 3A)``."""
    kc = 3.0 * G * le / (4.0 + 3.0 * A)
    kf = A * kc
    ke = G * le * (8.0 + 3.0 * A) / (4.0 + 3.0 * A)
    return Constants(ke=ke, kf=kf, kc=kc, kappa=kappa, G_springs=G)


def b09_springs(material, le: float) -> Constants:
    """[B09]'s per-cell edges ``kx`` and inner diagonals ``kd`` as family constants: an interior
    edge is shared by four cells, each giving ``kx`` (weight 1 = four cells × 1/4): ``ke = 4 kx``."""
    E, nu = material.E, material.nu
    kx = E * le * (4.0 * nu + 1.0) / (8.0 * (1.0 + nu))
    kd = 3.0 * E * le / (8.0 * (1.0 + nu))
    return Constants(ke=4.0 * kx, kf=0.0, kc=kd, kappa=0.0, G_springs=float("nan"))


def constants(model, material, le: float) -> Constants:
    """Spring constants and κ of the scene model ``model`` (:class:`hybmss.scene.Model`) for
    ``material`` on cells of edge ``le``: the model's own calibration."""
    return model.spec.constants(model.params, material, le)
