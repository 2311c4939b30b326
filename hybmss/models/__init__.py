"""The model registry.

Every model the harness knows is one object on the protocol of :mod:`hybmss.models.base`.  The
registry holds

- the in-tree models: every module or folder (package) of this package whose name does not start
  with ``_`` (and is not ``base``) defines ``MODEL``, or ``MODELS`` (a tuple, for a family of
  variants such as the corotational hexahedra or an engine's models);
- the models of other packages, declared in the entry-point group :data:`ENTRY_POINT_GROUP`
  (``importlib.metadata``); an entry point names a model object or a class to instantiate;
- models added at run time with :func:`register` (and removed with :func:`unregister`).

A module may also define ``UNAVAILABLE`` (name → reason): models it would define whose engine
is missing or at a version outside the one they were measured at (:mod:`hybmss.models._engine_model`).
They are not among :func:`names`; :func:`unavailable` lists them, and :func:`get` refuses them
with the reason and the install command (a :class:`ValueError`: exit 2 of a command).

Modules and entry points are loaded at the first look-up, so importing :mod:`hybmss.scene` does
not load every model.  :func:`names` and :func:`all_models` list models in their declared
``order``, then by name.
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.metadata
import pkgutil

from .base import KERNELS, NO_SPRINGS, SOLVER_KINDS, ModelBase, NoParameters, Style, check

__all__ = ["ENTRY_POINT_GROUP", "KERNELS", "NO_SPRINGS", "SOLVER_KINDS", "ModelBase", "NoParameters", "REGISTRY",
           "Registry", "Style", "LATTICE", "all_models", "check", "default_name", "get", "lattice_stepper", "names",
           "parameter_fields", "register", "unavailable", "unregister"]

ENTRY_POINT_GROUP = "hybmss.models"

class Registry:
    """Models by name; in-tree modules and entry points are loaded at the first look-up."""

    def __init__(self, package: str, path):
        self._package, self._path = package, path
        self._models: dict[str, ModelBase] = {}
        self._unavailable: dict[str, str] = {}
        self._discovered = False

    def register(self, model, *, replace: bool = False) -> ModelBase:
        if isinstance(model, type):
            model = model()
        if not isinstance(model, ModelBase):
            raise TypeError(f"a model must be a hybmss.models.ModelBase, got {type(model).__name__}")
        model.validate()
        old = self._models.get(model.name)
        if old is not None and type(old) is not type(model) and not replace:
            raise ValueError(f"model {model.name!r} is already registered ({type(old).__module__}); "
                             f"pass replace=True to replace it")
        self._models[model.name] = model
        return model

    def unregister(self, name: str) -> None:
        self.discover()
        self._models.pop(name, None)

    def discover(self) -> None:
        if self._discovered:
            return
        self._discovered = True
        for info in sorted(pkgutil.iter_modules(self._path), key=lambda m: m.name):
            if info.name.startswith("_") or info.name == "base":
                continue
            mod = importlib.import_module(f"{self._package}.{info.name}")
            for model in (mod.MODELS if hasattr(mod, "MODELS") else (mod.MODEL,)):
                self.register(model)
            self._unavailable.update(getattr(mod, "UNAVAILABLE", {}))
        for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
            try:
                obj = ep.load()
            except Exception as exc:
                raise RuntimeError(f"model plug-in {ep.name!r} ({ep.value}) failed to load: {exc}") from exc
            model = self.register(obj)
            if model.name != ep.name:
                raise RuntimeError(f"model plug-in entry point {ep.name!r} names model {model.name!r}; "
                                   "the entry point's name must be the model's name")

    def get(self, name: str) -> ModelBase:
        self.discover()
        try:
            return self._models[name]
        except (KeyError, TypeError):
            pass
        if isinstance(name, str) and name in self._unavailable:
            raise ValueError(f"model {name} is unavailable: {self._unavailable[name]}") from None
        raise ValueError(f"model must be one of {', '.join(self.names())}; got {name!r}") from None

    def unavailable(self) -> dict[str, str]:
        """Models of the in-tree folders that cannot run here (not registered), with the reason."""
        self.discover()
        return {k: v for k, v in self._unavailable.items() if k not in self._models}

    def all(self) -> tuple[ModelBase, ...]:
        self.discover()
        return tuple(sorted(self._models.values(), key=lambda m: (m.order, m.name)))

    def names(self) -> tuple[str, ...]:
        return tuple(m.name for m in self.all())


REGISTRY = Registry(__name__, __path__)
"""The harness's one registry."""


def register(model, *, replace: bool = False) -> ModelBase:
    """Add ``model`` (an instance, or a class to instantiate) to the registry and return it.
    A model of another class under a registered name needs ``replace=True``."""
    return REGISTRY.register(model, replace=replace)


def unregister(name: str) -> None:
    """Remove the model ``name`` (a no-op if it is not registered)."""
    REGISTRY.unregister(name)


def get(name: str) -> ModelBase:
    """The model registered as ``name``; :class:`ValueError` listing the known names if none."""
    return REGISTRY.get(name)


def unavailable() -> dict[str, str]:
    """The models whose engine is missing or at an unsupported version: name → reason, ending with
    the install command (not among :func:`names`; :func:`get` refuses them with it)."""
    return REGISTRY.unavailable()


def all_models() -> tuple[ModelBase, ...]:
    """Every registered model, in its declared ``order``, then by name."""
    return REGISTRY.all()


def names() -> tuple[str, ...]:
    """Names of :func:`all_models`."""
    return REGISTRY.names()


def default_name() -> str:
    """The model a scene or command takes when none is named: the first of :func:`names` (the
    lowest declared ``order``)."""
    return names()[0]


LATTICE = "hybmss"
"""The model whose stepper (:class:`hybmss.models.hybmss.stepper.LatticeStepper`) steps the spring
and volume lattice of every model that has no stepper of its own (``stepper`` returns None: the
lattice's variants, [B09]'s cells, a plug-in's springs)."""


def lattice_stepper(system, dt: float, **kw):
    """The stepper of the spring and volume lattice for ``system`` and ``dt`` (the :data:`LATTICE`
    model's; ``kw``: ``ramp_time``, ``kernel``, ``precision``, ``threads``)."""
    return get(LATTICE).stepper(system, dt, **kw)


def parameter_fields() -> dict[str, dataclasses.Field]:
    """Every parameter name of the registered models and its dataclass field (the first model
    declaring it, in registry order): type, default and ``metadata`` (``help``, ``choices``), from
    which a command line builds its model options."""
    out: dict[str, dataclasses.Field] = {}
    for m in all_models():
        for f in dataclasses.fields(m.Parameters):
            out.setdefault(f.name, f)
    return out

