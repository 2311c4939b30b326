"""The model protocol: what a model tells the harness about itself.

A model is one object, an instance of a :class:`ModelBase` subclass, held by the registry
(:mod:`hybmss.models`).  Everything the harness does with a model — building a system, picking
solvers and kernels, colouring it in a plot — asks this object; no code outside a model's own
module compares a model's name.  What part a model plays in the layers above (study roles, the
names publications give it, a sweep's cost estimates) is declared there, not here.

Declaring a model
-----------------
Class attributes (plain data):

- ``name``: the registry key, e.g. ``"hybmss-fd"`` (lower case, digits, ``-``, ``_``, ``.``);
- ``label``: one line for legends and ``--help``;
- ``style``: :class:`Style` (colour, marker, line style) of its plots;
- ``Parameters``: a frozen dataclass of its parameters with their defaults (a field's
  ``metadata`` may give ``help`` and ``choices`` for the command line); its
  ``__post_init__`` validates them and raises :class:`ValueError` naming the parameter and its
  allowed range (see :func:`check`).  :class:`NoParameters` for a model without any.  Parameter
  names must not be fields of the experiment specification (``E``, ``nu``, ``mesh``, ...);
- ``conservative``: True when every force derives from a potential energy (then static solves
  minimize it and implicit Euler applies);
- ``solvers``: the solver kinds it supports, a subset of :data:`SOLVER_KINDS`;
- ``kernels``: the explicit kernels that support it, a subset of :data:`KERNELS`;
- ``order``: position in listings (tables, legends); in-tree models use 0–99.

Methods (``p`` is the model's ``Parameters`` instance, ``material`` a
:class:`hybmss.scene.Material`, ``le`` the cell edge in m):

- ``constants(p, material, le) -> Constants``: spring family constants and volume stiffness κ
  (:class:`hybmss.calibrate.Constants`).  Zero constants drop the springs and the volume term,
  so a model that is not a spring lattice returns :data:`NO_SPRINGS` (the default);
- ``volume_energy(p) -> str``: form of the per-cell volume energy when κ ≠ 0
  (``"quadratic"`` or ``"squared"``, :data:`hybmss.models.hybmss.VOLUME_ENERGIES`);
- ``terms(p, scene, lattice, consts) -> tuple[ForceTerm, ...]``: force terms it adds beyond the
  springs and the volume energy (:mod:`hybmss.terms`: energy, forces and Hessian for a
  conservative term; forces and Jacobian for a non-conservative one).  Default: none;
- ``variant(p) -> str``: the name of this parameter set in tables and legends (default ``name``;
  e.g. ``"hybmss (E-form)"``), ``tag(p) -> str``, the same as one word for scene labels, and
  ``styles() -> dict``: the :class:`Style` of each variant name (default ``{name: style}``);
- ``study_variants(nu) -> tuple[dict, ...]``: the parameter sets the studies compare at Poisson
  ratio ``nu`` (default ``({},)``: the defaults only);
- ``dt_crit(system) -> float | None``: its critical explicit time step, or None to let the
  harness estimate it from the system's stiffness and masses (the default);
- ``stepper(system, dt, *, ramp_time, kernel, precision, threads)``: the object that advances
  its explicit dynamics (the protocol of :mod:`hybmss.stepper`: ``load``, ``advance``, ``state``,
  ``internal_forces``, ``energy``, ``info``).  None (the default) runs the harness's spring and
  volume lattice (:class:`hybmss.models.hybmss.stepper.LatticeStepper`); a model with its own dynamics (its own
  elements, a position-based integrator, an external engine) returns its own, and the one loop
  :func:`hybmss.explicit.simulate_explicit` runs it with the plates' ramp, damping, divergence
  and rest checks, history, timing and the :class:`hybmss.result.Result` of every model.  A
  ``precision`` or ``threads`` it does not have raises :class:`ValueError`;
  :func:`hybmss.explicit.dt_crit` returns the model's ``dt_crit`` when it has one.
- ``solve_static``: None (the default) to use the harness's Newton, or a method
  ``solve_static(self, scene, options=None, system=None)`` returning a
  :class:`hybmss.result.Result`, for a model that brings its own (e.g. a position-based integrator
  whose static answer is the rest state of a damped run); :func:`hybmss.solve.solve_static`
  hands the scene to it.  ``simulate_explicit`` refuses a kernel that is not in ``kernels``,
  ``solve_static`` a model without ``"static"`` in ``solvers``.

A model with no springs and one force term (a corotational hexahedral FEM) returns
:data:`NO_SPRINGS` and puts its element forces and tangent in ``terms``; a model with its own
integrator also sets ``solvers``/``kernels`` to what it provides.

Registering a model
-------------------
An in-tree model is a folder ``hybmss/models/<name>/`` (a package holding the model's module, its
kernels and their NumPy twins) or a single module ``hybmss/models/<name>.py`` whose top level
defines ``MODEL = MyModel()``, or ``MODELS = (...)`` for a family of variants; the registry finds
it.  Another package registers its model through the entry-point group
``hybmss.models`` (``[project.entry-points."hybmss.models"] my-model = "mypkg:MODEL"``) or by
calling :func:`hybmss.models.register`.  A scene then stores the model by ``name`` and its
parameters under their own names (:class:`hybmss.scene.Model`), so they enter the scene digest.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass
from typing import Callable, ClassVar

from ..calibrate import Constants
from ..terms import ForceTerm

SOLVER_KINDS = ("static", "explicit", "implicit")
"""Solver kinds of the harness: static equilibrium, explicit dynamics, implicit Euler."""

KERNELS = ("numba", "numpy", "engine")
"""Explicit kernels: the Numba stencil kernel, its NumPy twin, and ``engine``: the own compiled step
of an engine a model wraps (MuJoCo, Newton), the only kernel of such a model."""

NO_SPRINGS = Constants(ke=0.0, kf=0.0, kc=0.0, kappa=0.0, G_springs=0.0)
"""Constants of a model that is not a spring lattice: no springs, no volume term."""

_NAME = re.compile(r"^[a-z0-9][a-z0-9_.-]*$")


@dataclass(frozen=True)
class Style:
    """Plot style of a model: matplotlib colour, marker and line style."""

    color: str
    marker: str = "o"
    linestyle: str = "-"


@dataclass(frozen=True)
class NoParameters:
    """The parameters of a model that has none."""


def check(name: str, value, lo: float | None = None, hi: float | None = None, *,
          open_lo: bool = False, open_hi: bool = False) -> float:
    """``value`` as a finite float within [lo, hi] (bounds optional, open on request), else a
    :class:`ValueError` naming ``name`` and the allowed range."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    low_bad = lo is not None and (v <= lo if open_lo else v < lo)
    high_bad = hi is not None and (v >= hi if open_hi else v > hi)
    if low_bad or high_bad:
        if hi is None:
            rng = f"{'>' if open_lo else '>='} {lo:g}"
        elif lo is None:
            rng = f"{'<' if open_hi else '<='} {hi:g}"
        else:
            rng = f"lie in {'(' if open_lo else '['}{lo:g}, {hi:g}{')' if open_hi else ']'}"
        raise ValueError(f"{name} must be {rng}, got {v:g}")
    return v


class ModelBase:
    """Base class of every model (see the module docstring for the protocol)."""

    name: ClassVar[str]
    label: ClassVar[str] = ""
    style: ClassVar[Style] = Style("#7f7f7f")
    Parameters: ClassVar[type] = NoParameters
    conservative: ClassVar[bool] = True
    explicit_limit: ClassVar[bool] = True
    """Whether its explicit scheme has a stability limit (``dt_crit``); False: stable at any step
    (constraints solved implicitly: only accuracy bounds the step)."""
    solvers: ClassVar[tuple[str, ...]] = SOLVER_KINDS
    kernels: ClassVar[tuple[str, ...]] = KERNELS
    order: ClassVar[int] = 100
    solve_static: ClassVar[Callable | None] = None

    # ------------------------------------------------------------------ parameters
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(f.name for f in dataclasses.fields(self.Parameters))

    def parameters(self, **given):
        """The validated ``Parameters`` of this model; ``None`` values take the default."""
        names = self.parameter_names()
        unknown = [k for k in given if k not in names]
        if unknown:
            have = ", ".join(names) if names else "none"
            raise ValueError(f"model {self.name} has no parameter {unknown[0]!r} (its parameters: {have})")
        return self.Parameters(**{k: v for k, v in given.items() if v is not None})

    def supports(self, solver: str, kernel: str | None = None) -> bool:
        """Whether the solver kind (and, for explicit runs, the kernel) supports this model."""
        return solver in self.solvers and (kernel is None or solver != "explicit" or kernel in self.kernels)

    # ------------------------------------------------------------------ physics
    def constants(self, p, material, le: float) -> Constants:
        return NO_SPRINGS

    def volume_energy(self, p) -> str:
        return "quadratic"

    def terms(self, p, scene, lattice, consts: Constants) -> tuple[ForceTerm, ...]:
        return ()

    def dt_crit(self, system) -> float | None:
        return None

    def stepper(self, system, dt: float, *, ramp_time: float, kernel: str = "numba", precision: str = "f64",
                threads: int = 1):
        """The explicit stepper of ``system``, or None (the default) for the harness's spring and
        volume lattice (:class:`hybmss.models.hybmss.stepper.LatticeStepper`)."""
        return None

    # ------------------------------------------------------------------ naming
    def variant(self, p) -> str:
        return self.name

    def tag(self, p) -> str:
        return self.name

    def styles(self) -> dict[str, Style]:
        """Plot style of each variant name it can produce (default: ``{name: style}``)."""
        return {self.name: self.style}

    def study_variants(self, nu: float) -> tuple[dict, ...]:
        return ({},)

    # ------------------------------------------------------------------ checks
    def validate(self) -> None:
        """Raise :class:`ValueError` if the declaration breaks the protocol."""
        name = getattr(self, "name", None)
        if not isinstance(name, str) or not _NAME.match(name):
            raise ValueError(f"model name must match {_NAME.pattern}, got {name!r}")
        if not dataclasses.is_dataclass(self.Parameters):
            raise ValueError(f"model {name}: Parameters must be a frozen dataclass")
        for what, got, allowed in (("solvers", self.solvers, SOLVER_KINDS), ("kernels", self.kernels, KERNELS)):
            bad = [g for g in got if g not in allowed]
            if bad:
                raise ValueError(f"model {name}: {what} must be among {', '.join(allowed)}; got {bad[0]!r}")
        if not self.conservative and "implicit" in self.solvers:
            raise ValueError(f"model {name}: implicit Euler needs a conservative model")
        self.parameters()  # the defaults must be valid

    def __repr__(self) -> str:
        return f"<model {getattr(self, 'name', '?')}>"
