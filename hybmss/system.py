"""A scene assembled into arrays: the mass-spring system a solver integrates.

:func:`build` keeps only the force terms the scene needs (SPEC "model only what a scene
needs"): springs of zero stiffness are dropped (no face diagonals when A = 0), the volume term
is built only when κ ≠ 0 (not at ν = 1/4 nor for a model without one), gravity only when g ≠ 0.
The model (:mod:`hybmss.models`) gives the spring constants, κ, the volume-energy form and the
force terms it adds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .calibrate import Constants
from .lattice import CORNERS, Lattice
from .scene import Scene
from .terms import DeadLoad, ForceTerm, all_conservative


@dataclass(frozen=True, eq=False)
class PlateSet:
    """Particles of one plate and the components it prescribes."""

    name: str
    particles: np.ndarray
    constrained: np.ndarray  # (3,) bool


@dataclass(frozen=True, eq=False)
class System:
    """Arrays of one scene.  ``x`` arguments of the force functions are (n, 3) positions."""

    scene: Scene
    lattice: Lattice
    consts: Constants
    X: np.ndarray
    mass: np.ndarray
    spring_a: np.ndarray
    spring_b: np.ndarray
    spring_k: np.ndarray
    spring_l0: np.ndarray
    spring_family: np.ndarray
    vol_cells: np.ndarray  # (m_v, 8) cells carrying a volume term (empty when κ = 0)
    vol_V0: np.ndarray  # (m_v,) rest volume a·(b×c)
    kappa: float
    volume_energy: str
    gravity: np.ndarray | None  # (3,) or None when g = 0
    plates: tuple[PlateSet, ...]
    fixed: np.ndarray  # (n, 3) bool: prescribed components
    terms: tuple[ForceTerm, ...] = ()
    """What the model adds beyond springs and volume energy (:mod:`hybmss.terms`)."""

    @property
    def n(self) -> int:
        return len(self.X)

    @property
    def has_volume(self) -> bool:
        return len(self.vol_cells) > 0

    @property
    def conservative(self) -> bool:
        """True when every force has a potential (all ``terms`` conservative)."""
        return all_conservative(self.terms)

    def term(self, name: str) -> ForceTerm | None:
        """The term called ``name``, or None."""
        for t in self.terms:
            if t.name == name:
                return t
        return None

    def prescribed(self, s: float = 1.0) -> np.ndarray:
        """Target positions (n, 3) of the prescribed components at load factor ``s``
        (free components hold the reference position)."""
        x = self.X.copy()
        for plate, p in zip(self.scene.plates, self.plates):
            u = plate.motion.displacement_at(self.X[p.particles], s)
            idx = p.particles
            for d in np.flatnonzero(p.constrained):
                x[idx, d] = self.X[idx, d] + u[:, d]
        return x

    def plate(self, name: str) -> PlateSet:
        for p in self.plates:
            if p.name == name:
                return p
        raise KeyError(f"unknown plate {name!r}; plates: {[p.name for p in self.plates]}")


def build(scene: Scene, lattice: Lattice | None = None) -> System:
    """Assemble ``scene`` into a :class:`System`."""
    lat = lattice if lattice is not None else Lattice.from_body(scene.body)
    le = scene.body.le
    model, params = scene.model.spec, scene.model.params
    c = model.constants(params, scene.material, le)
    X = lat.X.astype(float)
    mass = scene.material.rho * lat.masses_per_density

    k_family = np.asarray(c.by_family)
    k = lat.weight * k_family[lat.family]
    keep = k != 0.0
    a, b = lat.springs[keep, 0], lat.springs[keep, 1]
    l0 = np.linalg.norm(X[b] - X[a], axis=1)

    if c.kappa != 0.0:
        vol_cells = np.ascontiguousarray(lat.cells)  # one layout for the kernels (compiled once)
        vol_V0 = lat.cell_volumes(X)
    else:
        vol_cells = np.zeros((0, 8), dtype=np.int64)
        vol_V0 = np.zeros(0)

    g = np.asarray(scene.gravity, dtype=float)
    gravity = g if scene.has_gravity else None

    plates = []
    fixed = np.zeros((len(X), 3), dtype=bool)
    for plate in scene.plates:
        sel = np.flatnonzero(plate.region.select(X, scene.body))
        if len(sel) == 0:
            raise ValueError(f"plate {plate.name!r} selects no particle of the body")
        cons = plate.motion.constrained
        plates.append(PlateSet(plate.name, sel, cons))
        fixed[np.ix_(sel, np.flatnonzero(cons))] = True

    return System(
        terms=_terms(scene, lat, model.terms(params, scene, lat, c)),
        scene=scene,
        lattice=lat,
        consts=c,
        X=X,
        mass=mass,
        spring_a=a.astype(np.int64),
        spring_b=b.astype(np.int64),
        spring_k=k[keep],
        spring_l0=l0,
        spring_family=lat.family[keep],
        vol_cells=vol_cells,
        vol_V0=vol_V0,
        kappa=float(c.kappa),
        volume_energy=model.volume_energy(params),
        gravity=gravity,
        plates=tuple(plates),
        fixed=fixed,
    )


def _terms(scene: Scene, lat: Lattice, model_terms) -> tuple[ForceTerm, ...]:
    """``System.terms`` of a scene: the dead loads of ``Scene.loads`` (:class:`DeadLoad`) and the
    force terms its model adds (:meth:`hybmss.models.ModelBase.terms`)."""
    terms: list[ForceTerm] = []
    if scene.loads:
        terms.append(DeadLoad(dead_loads(scene, lat)))
    return tuple(terms) + tuple(model_terms)


def dead_loads(scene: Scene, lat: Lattice) -> np.ndarray:
    """Nodal forces (n, 3) of ``scene.loads``: each selected surface face of a cell gives
    ``traction · le²/4`` to each of its 4 vertices (consistent load of a bilinear face)."""
    f = np.zeros((lat.n_particles, 3))
    area = scene.body.le**2
    for load in scene.loads:
        ijk, axis, side = load.faces(scene.body)
        for a in range(3):
            for s_ in (0, 1):
                sel = (axis == a) & (side == s_)
                if not sel.any():
                    continue
                corners = CORNERS[CORNERS[:, a] == s_]  # the 4 corners of that face
                g = ijk[sel][:, None, :] + corners[None]
                nodes = lat.node_id[g[..., 0], g[..., 1], g[..., 2]].ravel()
                np.add.at(f, nodes, 0.25 * area * np.asarray(load.traction)[None, :])
    return f
