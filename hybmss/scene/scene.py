"""The scene: body, material, model, plates, loads, gravity and damping as one frozen value
with a stable digest (SHA-256 of its canonical JSON form).  The damping force on particle a is
``−c m_a v_a``."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass, field

from .body import Body
from .boundary import REGION_EXTRAS, Load, Motion, Plate, Region
from .checks import SceneTypeError, _finite, _of_type, _typename, _vec3
from .material import Material, Model


@dataclass(frozen=True)
class Scene:
    """Everything a solver needs, as plain data.

    ``gravity`` is the acceleration vector (m/s²).  ``damping`` is the mass-proportional damping
    coefficient c (1/s) of the dynamic solvers: the damping force on particle a is
    ``−c m_a v_a`` (static solves ignore it).
    """

    body: Body
    material: Material
    model: Model = field(default_factory=Model)
    plates: tuple[Plate, ...] = ()
    gravity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    damping: float = 0.0
    name: str = ""
    loads: tuple[Load, ...] = ()
    """Dead surface tractions (:class:`Load`); optional, omitted from :meth:`to_dict` when empty
    so the digests of scenes without loads do not change."""

    def __post_init__(self):
        _of_type("body", self.body, Body)
        _of_type("material", self.material, Material)
        object.__setattr__(self, "model", _of_type("model", self.model, Model, Model))
        if not isinstance(self.name, str):
            raise SceneTypeError(f"scene name must be a string, got {self.name!r} ({_typename(self.name)})")
        for what, cls in (("plates", Plate), ("loads", Load)):
            items = getattr(self, what)
            if isinstance(items, (str, bytes, cls)) or not hasattr(items, "__iter__"):
                raise SceneTypeError(f"{what} must be a sequence of {cls.__name__}, got {items!r}")
            items = tuple(items)
            for i, item in enumerate(items):
                _of_type(f"{what}[{i}]", item, cls)
            object.__setattr__(self, what, items)
        object.__setattr__(self, "gravity", _vec3("gravity", self.gravity))
        damping = _finite("damping", self.damping)
        if damping < 0:
            raise ValueError(f"damping must be >= 0 (1/s), got {damping}")
        object.__setattr__(self, "damping", damping)
        names = [p.name for p in self.plates]
        if len(set(names)) != len(names):
            raise ValueError(f"plate names must be unique, got {names}")

    @property
    def has_gravity(self) -> bool:
        return any(g != 0.0 for g in self.gravity) and self.material.rho > 0

    def to_dict(self) -> dict:
        """JSON-ready nested dict (stable key order)."""
        d = dataclasses.asdict(self)
        d["body"] = self.body.to_dict()
        d["model"] = self.model.to_dict()
        if not self.loads:
            del d["loads"]
        for item in (*d["plates"], *d.get("loads", ())):
            for k in REGION_EXTRAS:
                if item["region"][k] is None:
                    del item["region"][k]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "Scene":
        plates = tuple(
            Plate(
                p["name"],
                Region(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in p["region"].items()}),
                Motion(
                    **{k: (tuple(v) if isinstance(v, list) else v) for k, v in p["motion"].items()}
                ),
            )
            for p in d.get("plates", ())
        )
        return cls(
            body=Body.from_dict(d["body"]),
            material=Material(**d["material"]),
            model=Model(**d["model"]),
            plates=plates,
            gravity=tuple(d.get("gravity", (0, 0, 0))),
            damping=d.get("damping", 0.0),
            name=d.get("name", ""),
            loads=tuple(
                Load(Region(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in ld["region"].items()}),
                     tuple(ld["traction"]))
                for ld in d.get("loads", ())
            ),
        )

    def digest(self) -> str:
        """SHA-256 of the canonical JSON form: equal scenes have equal digests."""
        text = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()

    def with_material(self, **kw) -> "Scene":
        return dataclasses.replace(self, material=dataclasses.replace(self.material, **kw))
