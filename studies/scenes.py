"""The publication's experiments ([G20] §6, SPEC §6) as declarative scene specifications.

A :class:`SceneSpec` holds the experiment's parameters as the publication states them
(mesh, E, ν, ρ, model, deformation d, torsion angle); :meth:`SceneSpec.build` turns it into a
:class:`hybmss.scene.Scene` that both the mass-spring solver and the FEM reference run.

Geometry and loading:

- ``compression``, ``shear``, ``torsion``: cube of 5 m (10×10×10 cells of 0.5 m), bottom face
  (z = 0) clamped.  Compression moves the top plate down by d·H; shear moves it along x by d·H;
  torsion rotates it about the vertical axis through the top face's centre by θ.  [G20] does not
  define "d" for torsion; the table runs θ = 1° and 45° (θ = d·√2 rad would make the top corners
  move by d·side; both conventions are available through ``angle_deg``).
- ``tension``: beam 0.4 × 0.4 × 2.4 m along z (meshes 4×4×24, 8×8×48), end z = 0 clamped, end
  z = L pulled by d·L.
- ``bending``: the same beam, end z = 0 clamped, gravity g = 10 m/s² along −y (the vertical of this
  scene), E = 10 MPa or 2 MPa, ν = 0.25, ρ = 1000 kg/m³ ([G20] gives no density).
- ``uniaxial``: homogeneous uniaxial stress (sliding plates, free sides), strain 1e-4, for
  effective moduli.

ρ = 1000 kg/m³ everywhere unless said (the publication gives none for the cube).
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass

import numpy as np

from hybmss.scene import Body, Material, Model, Motion, Plate, Region, Scene

EXPERIMENTS = ("compression", "tension", "shear", "torsion", "bending", "uniaxial")

CUBE_SIDE = 5.0
BEAM_WIDTH = 0.4
BEAM_LENGTH = 2.4

DEFAULTS = {
    "compression": dict(mesh=(10, 10, 10), E=1e4, nu=0.25, deformation=0.05),
    "tension": dict(mesh=(4, 4, 24), E=1e4, nu=0.25, deformation=0.05),
    "shear": dict(mesh=(10, 10, 10), E=1e4, nu=0.25, deformation=0.05),
    "torsion": dict(mesh=(10, 10, 10), E=1e4, nu=0.25, deformation=0.0, angle_deg=1.0),
    "bending": dict(mesh=(4, 4, 24), E=1e7, nu=0.25, deformation=0.0, gravity=10.0),
    "uniaxial": dict(mesh=(2, 2, 2), E=1e4, nu=0.25, deformation=1e-4),
}


@dataclass(frozen=True)
class Range:
    """An interval of allowed values, ``lo`` and ``hi`` included unless ``*_open``."""

    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    hi_open: bool = False

    def __contains__(self, value: float) -> bool:
        v = float(value)
        if not math.isfinite(v):
            return False
        above = v > self.lo if self.lo_open else v >= self.lo
        below = v < self.hi if self.hi_open else v <= self.hi
        return above and below

    def __str__(self) -> str:
        def end(x):
            return "inf" if x == math.inf else "-inf" if x == -math.inf else f"{x:g}"

        return f"{'(' if self.lo_open or self.lo == -math.inf else '['}{end(self.lo)}, " \
               f"{end(self.hi)}{')' if self.hi_open or self.hi == math.inf else ']'}"


FINITE = Range()

MSS_SOLVERS = ("static", "explicit", "implicit")
"""The mass-spring solvers (the FEM reference is ``fem``): the model parameters are theirs only."""


def param(default, help: str, unit: str = "", ranges=None, experiments=None, flags=(), solvers=None):
    """A :class:`SceneSpec` field with what a user needs to set it: ``help`` and ``unit``; the
    allowed values ``ranges`` (a :class:`Range`, or a dict experiment → Range; ``None``: checked
    by the scene's own types); ``experiments`` that use it (``None``: every one); ``solvers`` that
    use it (``None``: every one); extra command-line ``flags``."""
    return dataclasses.field(default=default, metadata={
        "help": help, "unit": unit, "ranges": ranges, "experiments": experiments, "flags": tuple(flags),
        "solvers": solvers})


class ParameterError(ValueError):
    """A scene parameter outside its allowed range: ``name``, ``value`` and ``allowed``."""

    def __init__(self, name: str, value, allowed: str, why: str = ""):
        self.name, self.value, self.allowed = name, value, allowed
        super().__init__(f"{name} = {value!r} is not allowed: {why + '; ' if why else ''}allowed: {allowed}")


@dataclass(frozen=True)
class SceneSpec:
    """Parameters of one experiment run (everything a row of a results table needs).

    Each field's metadata (:func:`param`) says what it means, its unit, the values a user may
    ask for (:meth:`check`) and which experiments use it (:meth:`uses`); the command line's
    scene options are generated from these fields.
    """

    experiment: str
    mesh: tuple[int, int, int] = param((10, 10, 10), "cells NXxNYxNZ")
    E: float = param(1e4, "Young's modulus", "Pa", Range(0.0, lo_open=True))
    nu: float = param(0.25, "Poisson ratio (the static and implicit mass-spring solvers and moduli take "
                      "[-0.99, 0.49999])", "", Range(-1.0, 0.5, lo_open=True, hi_open=True))
    rho: float = param(1000.0, "density", "kg/m^3", Range(0.0))
    model: str = param("hybmss", "mass-spring model", solvers=MSS_SOLVERS)
    A: float | None = param(None, "face/inner diagonal stiffness ratio kf/kc (default: the model's)", "",
                            Range(0.0), solvers=MSS_SOLVERS)
    e_form: bool = param(False, "spring constants from [G20] eq. 5.12 (assumes E = 5G/2)", solvers=MSS_SOLVERS)
    volume_energy: str = param("quadratic", "volume-energy form", solvers=MSS_SOLVERS)
    deformation: float = param(0.05, "plate displacement / height d (0.05 = 5 %)", "", {
        "compression": Range(0.0, 1.0, hi_open=True), "tension": Range(0.0), "shear": FINITE,
        "uniaxial": Range(-0.1, 0.1)}, experiments=("compression", "tension", "shear", "uniaxial"),
        flags=("-d",))
    angle_deg: float = param(0.0, "torsion angle of the top plate", "degrees",
                             Range(-180.0, 180.0, lo_open=True, hi_open=True), experiments=("torsion",),
                             flags=("--angle",))
    gravity: float = param(0.0, "gravity along -y", "m/s^2", FINITE, experiments=("bending",))
    damping: float = param(0.0, "mass-proportional damping c of the dynamic solvers", "1/s", Range(0.0),
                           solvers=("explicit", "implicit"))

    def __post_init__(self):
        if self.experiment not in EXPERIMENTS:
            raise ValueError(f"scene must be one of {', '.join(EXPERIMENTS)}; got {self.experiment!r}")
        object.__setattr__(self, "mesh", tuple(int(n) for n in self.mesh))

    @classmethod
    def default(cls, experiment: str, **overrides) -> "SceneSpec":
        if experiment not in EXPERIMENTS:
            raise ValueError(f"scene must be one of {', '.join(EXPERIMENTS)}; got {experiment!r}")
        params = dict(DEFAULTS[experiment])
        params.update({k: v for k, v in overrides.items() if v is not None})
        return cls(experiment, **params)

    @staticmethod
    def parameters() -> tuple[dataclasses.Field, ...]:
        """The fields a user sets (every field but ``experiment``), with their :func:`param` metadata."""
        return tuple(f for f in dataclasses.fields(SceneSpec) if f.name != "experiment")

    @staticmethod
    def uses(name: str, experiment: str, solver: str | None = None) -> bool:
        """Whether parameter ``name`` changes an ``experiment`` solved by ``solver``."""
        meta = {f.name: f.metadata for f in SceneSpec.parameters()}[name]
        if meta["experiments"] is not None and experiment not in meta["experiments"]:
            return False
        return solver is None or meta["solvers"] is None or solver in meta["solvers"]

    def check(self) -> "SceneSpec":
        """Refuse values a user may not ask for (:class:`ParameterError`, a ``ValueError`` naming
        the parameter, its value and the allowed range); returns ``self``.

        Beyond each field's range: a scene with a plate on each end needs two cell layers along z
        (with one, every particle lies on a plate and nothing is left to solve); the torsion range
        is below half a turn because a plate rotation is defined by its end position, so θ and
        θ − 360° are the same boundary condition.  The model and material are built to check
        their own constraints (A of ``hybmss-fd``, ν, …).
        """
        for f in self.parameters():
            rng = f.metadata["ranges"]
            if isinstance(rng, dict):
                rng = rng.get(self.experiment)
            value = getattr(self, f.name)
            if rng is None or value is None or not self.uses(f.name, self.experiment):
                continue
            if value not in rng:
                unit = f" {f.metadata['unit']}" if f.metadata["unit"] else ""
                raise ParameterError(f.name, value, f"{rng}{unit}", f"{self.experiment}: {f.metadata['help']}")
        if self.experiment in ("compression", "tension", "shear", "torsion") and self.mesh[2] < 2:
            raise ParameterError("mesh", "x".join(map(str, self.mesh)), "NZ >= 2",
                                 f"{self.experiment} moves a plate on each end, so one cell layer leaves "
                                 "nothing to solve")
        Model(self.model, A=self.A, e_form=self.e_form, volume_energy=self.volume_energy)
        Material(self.E, self.nu, self.rho)
        return self

    def replace(self, **kw) -> "SceneSpec":
        return dataclasses.replace(self, **kw)

    # ---------------------------------------------------------------- geometry
    @property
    def is_beam(self) -> bool:
        return self.experiment in ("tension", "bending")

    @property
    def le(self) -> float:
        if self.is_beam:
            return BEAM_LENGTH / self.mesh[2]
        if self.experiment == "uniaxial":
            return 1.0
        return CUBE_SIDE / self.mesh[2]

    @property
    def label(self) -> str:
        mesh = "x".join(map(str, self.mesh))
        load = f"θ={self.angle_deg:g}°" if self.experiment == "torsion" else (
            f"E={self.E:g}" if self.experiment == "bending" else f"d={100 * self.deformation:g}%")
        form = "-Eform" if self.e_form else ""
        return f"{self.experiment} {mesh} {self.model}{form} ν={self.nu:g} {load}"

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["mesh"] = "x".join(map(str, self.mesh))
        return d

    def key(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)

    def build(self) -> Scene:
        """The :class:`Scene` of this run."""
        le = self.le
        nx, ny, nz = self.mesh
        body = Body.box(nx, ny, nz, le)
        model = Model(self.model, A=self.A, e_form=self.e_form, volume_energy=self.volume_energy)
        mat = Material(self.E, self.nu, self.rho)
        H = nz * le
        bottom = Plate("bottom", Region("z-"), Motion("clamped"))
        g = (0.0, 0.0, 0.0)
        ex = self.experiment
        if ex == "compression":
            plates = (bottom, Plate("top", Region("z+"), Motion("translate", (0.0, 0.0, -self.deformation * H))))
        elif ex == "tension":
            plates = (bottom, Plate("top", Region("z+"), Motion("translate", (0.0, 0.0, self.deformation * H))))
        elif ex == "shear":
            plates = (bottom, Plate("top", Region("z+"), Motion("translate", (self.deformation * H, 0.0, 0.0))))
        elif ex == "torsion":
            center = (nx * le / 2.0, ny * le / 2.0, H)
            plates = (bottom, Plate("top", Region("z+"), Motion(
                "rotate", angle=math.radians(self.angle_deg), axis=(0.0, 0.0, 1.0), center=center)))
        elif ex == "bending":
            plates = (bottom,)
            g = (0.0, -self.gravity, 0.0)
        else:  # uniaxial
            from hybmss.moduli import uniaxial_scene

            return dataclasses.replace(uniaxial_scene(model, mat, self.deformation, nx, le),
                                       name=self.label)
        return Scene(body, mat, model, plates, gravity=g, damping=self.damping, name=self.label)

    # ---------------------------------------------------------------- theory
    def euler_bernoulli(self, z: np.ndarray) -> np.ndarray:
        """[G20] eq. for the clamped beam under its weight: deflection (along −g) at distance z
        from the clamp, ``y = ρ g l h /(24 E I) (4 L z³ − 6 L² z² − z⁴)``, ``I = l h³/12``."""
        lw = hh = BEAM_WIDTH
        L = BEAM_LENGTH
        I = lw * hh**3 / 12.0
        return self.rho * self.gravity * lw * hh / (24.0 * self.E * I) * (4 * L * z**3 - 6 * L**2 * z**2 - z**4)

    def euler_bernoulli_tip(self) -> float:
        return float(self.euler_bernoulli(np.array([BEAM_LENGTH]))[0])
