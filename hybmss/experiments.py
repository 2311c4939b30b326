"""The experiments ([G20] §6, SPEC §6): one scene builder for every command, study and benchmark.

A :class:`SceneSpec` holds an experiment's parameters as the publication states them (mesh, E,
ν, ρ, model and its parameters, deformation d, torsion angle, gravity); :meth:`SceneSpec.build`
turns it into the :class:`hybmss.scene.Scene` that the mass-spring solvers and the FEM reference
both run.  ``hybmss compare``, ``hybmss fem``, ``hybmss bench``, the benchmarks and the studies
all build their scenes here, so equal parameters give scenes of equal digest.

Geometry and loading:

- ``compression``, ``shear``, ``torsion``: cube of 5 m (10×10×10 cells of 0.5 m), bottom face
  (z = 0) clamped.  Compression moves the top plate down by d·H; shear moves it along x by d·H.
- **Torsion** rotates the top plate by ``angle_deg`` degrees about the vertical axis through the
  top face's centre (an exact rotation); ``deformation`` plays no part in it.  [G20] does not
  define "d" for torsion; its table runs θ = 1° and 45°.
- ``tension``: beam 0.4 × 0.4 × 2.4 m along z (meshes 4×4×24, 8×8×48), end z = 0 clamped, end
  z = L pulled by d·L.
- ``bending``: the same beam, end z = 0 clamped, gravity g = 10 m/s² along −y (the vertical of this
  scene), E = 10 MPa or 2 MPa, ν = 0.25, ρ = 1000 kg/m³ ([G20] gives no density).
- ``uniaxial``: homogeneous uniaxial stress (sliding plates, free sides), strain d = 1e-4, for
  effective moduli (:func:`uniaxial_scene`; :func:`shear_scene` is its simple-shear companion).

Each experiment is declared once in :data:`REGISTRY` (an :class:`Experiment`): its load
parameter (``deformation``, ``angle_deg``, ``gravity``), its answer quantity (the stored run's
column its tables compare: ``force_z``, ``force_x``, ``torque_z``, ``tip_deflection``) and its
scene builder; the parameters' ranges, the study files' ``[load]`` keys and the tables read it.

ρ = 1000 kg/m³ everywhere unless said (the publication gives none for the cube).  ``le``
(cell edge) follows from the body's size and the mesh unless given.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from typing import Callable
from functools import cached_property

import numpy as np

from . import models
from .scene import NU_OPEN_RANGE, NU_RANGE, Body, Material, Model, Motion, Plate, Region, Scene

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


def uniaxial_scene(model: Model, material: Material, strain: float = 1e-4, n: int = 2, le: float = 1.0) -> Scene:
    """Uniaxial stress: ``n³`` cells between two frictionless plates (only u_z prescribed), the top
    one pulled by ``strain · H``; one corner pinned in x and y and a second one in y."""
    H = n * le
    plates = (
        Plate("bottom", Region("z-"), Motion("slide", components=(2,))),
        Plate("top", Region("z+"), Motion("slide", (0.0, 0.0, strain * H), components=(2,))),
        Plate("pin", Region(lo=(0, 0, 0), hi=(0, 0, 0)), Motion("slide", components=(0, 1))),
        Plate("pin_x", Region(lo=(H, 0, 0), hi=(H, 0, 0)), Motion("slide", components=(1,))),
    )
    return Scene(Body.box(n, n, n, le), material, model, plates, name="uniaxial")


def shear_scene(model: Model, material: Material, gamma: float = 1e-4, n: int = 3, le: float = 1.0) -> Scene:
    """Simple shear: every boundary particle follows ``u = γ (z − z0) e_x``."""
    grad = (0.0, 0.0, gamma, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    motion = Motion("affine", gradient=grad)
    plates = tuple(Plate(f, Region(f), motion) for f in ("x-", "x+", "y-", "y+", "z-", "z+"))
    return Scene(Body.box(n, n, n, le), material, model, plates, name="simple-shear")


@dataclass(frozen=True)
class Experiment:
    """One experiment, declared once: ``load``, the :class:`SceneSpec` field that sets how hard it
    is loaded (its magnitude says whether the load is large); ``answer``, the column of a stored
    run (:func:`studies.sweep.runner.result_row`) that the experiment's tables compare, with its
    ``answer_label`` and ``answer_unit``; ``plate``, the support whose reaction is read; ``beam``,
    whether its body is the beam (else the cube); ``build``, its scene builder
    ``build(spec, model, material, le) -> Scene``."""

    name: str
    load: str
    answer: str
    answer_label: str
    answer_unit: str
    plate: str
    beam: bool
    build: Callable[["SceneSpec", Model, Material, float], Scene]

    def load_text(self, spec: "SceneSpec") -> str:
        """The load of ``spec`` as a table's label writes it (``d=5%``, ``θ=1°``, ``E=1e+07``)."""
        if self.load == "angle_deg":
            return f"θ={spec.angle_deg:g}°"
        if self.load == "gravity":
            return f"E={spec.E:g}"
        return f"d={100 * spec.deformation:g}%"


def _clamped_base() -> Plate:
    return Plate("bottom", Region("z-"), Motion("clamped"))


def _top_moved(spec: "SceneSpec", model: Model, mat: Material, le: float, along: int, sign: float) -> Scene:
    nx, ny, nz = spec.mesh
    move = [0.0, 0.0, 0.0]
    move[along] = sign * (spec.deformation * (nz * le))
    plates = (_clamped_base(), Plate("top", Region("z+"), Motion("translate", tuple(move))))
    return Scene(Body.box(nx, ny, nz, le), mat, model, plates, damping=spec.damping, name=spec.label)


def _compression(spec, model, mat, le) -> Scene:
    """The top plate moved down by d·H."""
    return _top_moved(spec, model, mat, le, 2, -1.0)


def _tension(spec, model, mat, le) -> Scene:
    """The end z = L pulled by d·L."""
    return _top_moved(spec, model, mat, le, 2, 1.0)


def _shear(spec, model, mat, le) -> Scene:
    """The top plate moved along x by d·H."""
    return _top_moved(spec, model, mat, le, 0, 1.0)


def _torsion(spec, model, mat, le) -> Scene:
    """The top plate turned by ``angle_deg`` about the vertical axis through its centre."""
    nx, ny, nz = spec.mesh
    center = (nx * le / 2.0, ny * le / 2.0, nz * le)
    top = Plate("top", Region("z+"), Motion("rotate", angle=math.radians(spec.angle_deg), axis=(0.0, 0.0, 1.0),
                                            center=center))
    return Scene(Body.box(nx, ny, nz, le), mat, model, (_clamped_base(), top), damping=spec.damping, name=spec.label)


def _bending(spec, model, mat, le) -> Scene:
    """The end z = 0 clamped, gravity along −y."""
    nx, ny, nz = spec.mesh
    return Scene(Body.box(nx, ny, nz, le), mat, model, (_clamped_base(),), gravity=(0.0, -spec.gravity, 0.0),
                 damping=spec.damping, name=spec.label)


def _uniaxial(spec, model, mat, le) -> Scene:
    return dataclasses.replace(uniaxial_scene(model, mat, spec.deformation, spec.mesh[0], le), name=spec.label)


REGISTRY: dict[str, Experiment] = {e.name: e for e in (
    Experiment("compression", "deformation", "force_z", "plate force F_z", "N", "top", False, _compression),
    Experiment("tension", "deformation", "force_z", "plate force F_z", "N", "top", True, _tension),
    Experiment("shear", "deformation", "force_x", "plate force F_x", "N", "top", False, _shear),
    Experiment("torsion", "angle_deg", "torque_z", "plate torque T_z", "N m", "top", False, _torsion),
    Experiment("bending", "gravity", "tip_deflection", "tip deflection", "m", "bottom", True, _bending),
    Experiment("uniaxial", "deformation", "force_z", "plate force F_z", "N", "top", False, _uniaxial),
)}
"""Every experiment a :class:`SceneSpec` names, in the order of the publication's tables."""

EXPERIMENTS = tuple(REGISTRY)


def experiment(name: str) -> Experiment:
    """The registered experiment ``name`` (``ValueError`` naming the registered ones)."""
    _check_experiment(name)
    return REGISTRY[name]


def loaded_by(load: str) -> tuple[str, ...]:
    """The experiments whose load parameter is the :class:`SceneSpec` field ``load``."""
    return tuple(e.name for e in REGISTRY.values() if e.load == load)



def _check_experiment(experiment: str) -> None:
    if experiment not in EXPERIMENTS:
        raise ValueError(f"scene must be one of {', '.join(EXPERIMENTS)}; got {experiment!r}")


@dataclass(frozen=True)
class Range:
    """An interval of allowed values, ``lo`` and ``hi`` included unless ``*_open``."""

    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    hi_open: bool = False

    def __contains__(self, value) -> bool:
        v = float(value)
        if not math.isfinite(v):
            return False
        above = v > self.lo if self.lo_open else v >= self.lo
        below = v < self.hi if self.hi_open else v <= self.hi
        return above and below

    def __str__(self) -> str:
        def end(x):
            return "inf" if x == math.inf else "-inf" if x == -math.inf else f"{x:g}"

        left = "(" if self.lo_open or self.lo == -math.inf else "["
        right = ")" if self.hi_open or self.hi == math.inf else "]"
        return f"{left}{end(self.lo)}, {end(self.hi)}{right}"


FINITE = Range()

MSS_SOLVERS = ("static", "explicit", "implicit")
"""The mass-spring solvers (the FEM reference is ``fem``)."""


def param(default, help: str, unit: str = "", ranges=None, experiments=None, flags=(), solvers=None):
    """A :class:`SceneSpec` field with what a user needs to set it: ``help`` and ``unit``; the
    values a user may ask for, ``ranges`` (a :class:`Range`, a dict experiment → Range, or
    ``None``: checked by the scene's own types); the ``experiments`` and ``solvers`` that use it
    (``None``: every one); extra command-line ``flags``.  A callable ``default`` is a factory,
    called when the field is not given (:func:`field_default` reads either)."""
    meta = {"help": help, "unit": unit, "ranges": ranges, "experiments": experiments, "flags": tuple(flags),
            "solvers": solvers}
    if callable(default):
        return dataclasses.field(default_factory=default, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def field_default(f: dataclasses.Field):
    """The default of a :class:`SceneSpec` field (its factory's value for a factory)."""
    return f.default_factory() if f.default is dataclasses.MISSING else f.default


class ParameterError(ValueError):
    """A scene parameter outside its allowed range: ``name``, ``value`` and ``allowed``."""

    def __init__(self, name: str, value, allowed: str, why: str = ""):
        self.name, self.value, self.allowed = name, value, allowed
        super().__init__(f"{name} = {value!r} is not allowed: {why + '; ' if why else ''}allowed: {allowed}")


@dataclass(frozen=True)
class SceneSpec:
    """Parameters of one experiment run (everything a row of a results table needs).

    ``params`` holds the model's parameters given explicitly, as sorted ``(name, value)`` pairs
    (the others take the model's defaults); :meth:`default` and :meth:`replace` accept them as
    keywords (``SceneSpec.default("compression", model="hybmss", e_form=True)``).
    :meth:`to_dict` records every parameter of the model, defaults included, under its own name.
    """

    experiment: str
    mesh: tuple[int, int, int] = param((10, 10, 10), "cells NXxNYxNZ")
    E: float = param(1e4, "Young's modulus", "Pa", Range(0.0, lo_open=True))
    nu: float = param(0.25, "Poisson ratio (the static and implicit mass-spring solvers and moduli take "
                      f"[{NU_RANGE[0]:g}, {NU_RANGE[1]:g}])", "", Range(*NU_OPEN_RANGE, lo_open=True, hi_open=True))
    rho: float = param(1000.0, "density", "kg/m^3", Range(0.0))
    model: str = param(models.default_name, "mass-spring model", solvers=MSS_SOLVERS)
    params: tuple[tuple[str, object], ...] = ()
    deformation: float = param(0.05, "plate displacement / height d (0.05 = 5 %)", "", {
        "compression": Range(0.0, 1.0, hi_open=True), "tension": Range(0.0), "shear": FINITE,
        "uniaxial": Range(-0.1, 0.1)}, experiments=loaded_by("deformation"),
        flags=("-d",))
    angle_deg: float = param(0.0, "torsion angle of the top plate", "degrees",
                             Range(-180.0, 180.0, lo_open=True, hi_open=True), experiments=loaded_by("angle_deg"),
                             flags=("--angle",))
    gravity: float = param(0.0, "gravity along -y", "m/s^2", FINITE, experiments=loaded_by("gravity"))
    damping: float = param(0.0, "mass-proportional damping c of the dynamic solvers", "1/s", Range(0.0),
                           solvers=("explicit", "implicit"))
    le: float | None = param(None, "cell edge (default: the body's size / mesh)", "m", Range(0.0, lo_open=True))

    def __post_init__(self):
        _check_experiment(self.experiment)
        object.__setattr__(self, "mesh", tuple(int(n) for n in self.mesh))
        params = tuple(sorted((str(k), v) for k, v in dict(self.params).items() if v is not None))
        clash = [k for k, _ in params if k in _FIELDS]
        if clash:
            raise ValueError(f"model {self.model} parameter {clash[0]!r} clashes with a scene field")
        object.__setattr__(self, "params", params)
        models.get(self.model).parameters(**dict(params))  # validates the name and the values

    @classmethod
    def default(cls, experiment: str, **overrides) -> "SceneSpec":
        """The experiment's defaults with ``overrides`` (``None`` values keep the default;
        keywords that are not fields are the model's parameters)."""
        _check_experiment(experiment)
        values = dict(DEFAULTS[experiment])
        values.update({k: v for k, v in overrides.items() if v is not None and k in _FIELDS})
        params = {**dict(values.pop("params", ())), **{k: v for k, v in overrides.items() if k not in _FIELDS}}
        values.pop("experiment", None)
        return cls(experiment, **values, params=tuple(params.items()))

    def replace(self, **kw) -> "SceneSpec":
        """A copy with fields and model parameters changed; a new ``model`` keeps the given
        parameters that it also has."""
        fields = {k: v for k, v in kw.items() if k in _FIELDS}
        params = dict(self.params)
        if "model" in fields and fields["model"] != self.model:
            names = models.get(fields["model"]).parameter_names()
            params = {k: v for k, v in params.items() if k in names}
        params.update({k: v for k, v in kw.items() if k not in _FIELDS})
        return dataclasses.replace(self, **fields, params=tuple(params.items()))

    # ---------------------------------------------------------------- what a user may ask for
    @staticmethod
    def parameters() -> tuple[dataclasses.Field, ...]:
        """The fields a user sets (all but ``experiment`` and the model's ``params``, which its
        model declares), with their :func:`param` metadata."""
        return tuple(f for f in dataclasses.fields(SceneSpec) if f.name not in ("experiment", "params"))

    @staticmethod
    def uses(name: str, experiment: str, solver: str | None = None) -> bool:
        """Whether parameter ``name`` changes an ``experiment`` solved by ``solver``; a model's
        parameter is the mass-spring solvers' only."""
        meta = {f.name: f.metadata for f in SceneSpec.parameters()}.get(name)
        if meta is None:
            return solver is None or solver in MSS_SOLVERS
        if meta["experiments"] is not None and experiment not in meta["experiments"]:
            return False
        return solver is None or meta["solvers"] is None or solver in meta["solvers"]

    def check(self, solved: bool = True) -> "SceneSpec":
        """Refuse values a user may not ask for (:class:`ParameterError`, a ``ValueError`` naming
        the parameter, its value and the allowed range); returns ``self``.

        Beyond each field's range: a scene with a plate on each end needs two cell layers along z
        (with one, every particle lies on a plate and nothing is left to solve); torsion stays
        below half a turn because a plate rotation is defined by its end position, so θ and
        θ − 360° are the same boundary condition; compression stops short of the floor (d < 1).
        The material is built to check its own constraints (the model checks its parameters
        when the spec is made).  ``solved=False`` checks the values only (a body to count, not a
        scene to solve: one cell layer is allowed).
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
        if solved and self.experiment in ("compression", "tension", "shear", "torsion") and self.mesh[2] < 2:
            raise ParameterError("mesh", "x".join(map(str, self.mesh)), "NZ >= 2",
                                 f"{self.experiment} moves a plate on each end, so one cell layer leaves "
                                 "nothing to solve")
        Material(self.E, self.nu, self.rho)
        return self

    # ---------------------------------------------------------------- model
    @property
    def scene_model(self) -> Model:
        """The :class:`hybmss.scene.Model` of this run."""
        return Model(self.model, **dict(self.params))

    @property
    def variant(self) -> str:
        """Name of the model and its parameter set in tables and legends."""
        return self.scene_model.variant

    def param(self, name: str):
        """The value (given or default) of the model parameter ``name``."""
        return getattr(self.scene_model.params, name)

    # ---------------------------------------------------------------- geometry
    @property
    def is_beam(self) -> bool:
        return REGISTRY[self.experiment].beam

    @property
    def cell_edge(self) -> float:
        if self.le is not None:
            return float(self.le)
        if self.is_beam:
            return BEAM_LENGTH / self.mesh[2]
        if self.experiment == "uniaxial":
            return 1.0
        return CUBE_SIDE / self.mesh[2]

    @property
    def label(self) -> str:
        mesh = "x".join(map(str, self.mesh))
        load = REGISTRY[self.experiment].load_text(self)
        model = self.scene_model
        return f"{self.experiment} {mesh} {model.spec.tag(model.params)} ν={self.nu:g} {load}"

    def to_dict(self) -> dict:
        """Every field and every model parameter (under its own name), and the variant name."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "params"}
        d["mesh"] = "x".join(map(str, self.mesh))
        model = self.scene_model
        d.update({k: v for k, v in model.to_dict().items() if k != "name"})
        d["variant"] = model.variant
        return d

    def key(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)

    def build(self) -> Scene:
        """The :class:`Scene` of this run (built once per specification)."""
        return self._scene

    @cached_property
    def _scene(self) -> Scene:
        model = self.scene_model
        return REGISTRY[self.experiment].build(self, model, Material(self.E, self.nu, self.rho), self.cell_edge)

    # ---------------------------------------------------------------- theory
    def beam_section(self) -> tuple[float, float, float]:
        """Width l (along x), height h (along y, the bending plane) and length L of the beam, m."""
        nx, ny, nz = self.mesh
        le = self.cell_edge
        return nx * le, ny * le, nz * le

    def neutral_axis(self) -> tuple[float, float]:
        """(x, y) of the beam's neutral axis (the centre of its cross-section), m."""
        lw, hh, _ = self.beam_section()
        return lw / 2.0, hh / 2.0

    def euler_bernoulli(self, z: np.ndarray) -> np.ndarray:
        """[G20] eq. for the clamped beam under its weight: deflection (along −g) at distance z
        from the clamp, ``y = ρ g l h /(24 E I) (4 L z³ − 6 L² z² − z⁴)``, ``I = l h³/12``."""
        lw, hh, L = self.beam_section()
        I = lw * hh**3 / 12.0
        z = np.asarray(z, dtype=float)
        return self.rho * self.gravity * lw * hh / (24.0 * self.E * I) * (4 * L * z**3 - 6 * L**2 * z**2 - z**4)

    def euler_bernoulli_tip(self) -> float:
        return float(self.euler_bernoulli(np.array([self.beam_section()[2]]))[0])


_FIELDS = frozenset(f.name for f in dataclasses.fields(SceneSpec))
