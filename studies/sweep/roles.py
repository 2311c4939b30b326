"""What part each model plays in the studies: its study roles, the names publications give it and
the estimate that orders a sweep's runs.

The model core (:mod:`hybmss.models`) knows nothing of studies; this module is the studies' one
table of the registered models' parts.  Each model's :class:`Part`:

- ``roles``: the study roles it takes part in, a subset of :data:`STUDY_ROLES`.  A model joins a
  role only when its solvers allow it too (:func:`takes_part`: the explicit rows, the stability
  and performance studies need the explicit solver, the other roles the static one);
- ``published``: the publications that report the model, each with the name its tables give it
  (``{"G20": "hybmss-fd"}``: a column, or a ``model`` value, of that publication's tables in
  ``studies/data``).  The studies join the published values with its runs by this name, and the
  publication's data file of models (``studies/data/<key>_models.csv``) says what part the name
  plays in the publication's claims (:mod:`studies.paper.publications`);
- ``run_cost(scene, kind) -> float``: a rough cost per cell of a run, only to order a sweep's runs
  (longest first; :func:`default_run_cost` unless the model's own differs);
- ``meshes``: the meshes its rows run on in place of the publication's, by body kind
  (``{"cube": (4, 4, 4), "beam": (2, 2, 12)}``; empty: the publication's), each with the FEM on
  the same mesh: the engines', whose damped runs to rest cost far more than a Newton solve
  (:func:`mesh_for`); in the quick mode (the tests') such a model runs the first case of each
  experiment only (ν = 1/4, 5 %, 1°: :func:`studies.paper.reproduce.quick_case`);
- ``quick``: whether it runs in the quick mode at all (False: a model whose runs take minutes
  even on the quick meshes).

A model of another package takes the default part (every role its solvers allow, no publication,
the default cost) unless its package declares one: an entry point of the group
:data:`ENTRY_POINT_GROUP` named like the model (``[project.entry-points."hybmss.studies"]
my-model = "mypkg:PART"``, ``PART = studies.sweep.roles.Part(roles=("tables", "pareto"))``), or, for a
model registered at run time, :func:`declare`.
"""

from __future__ import annotations

import importlib.metadata
import math
from dataclasses import dataclass, field
from typing import Callable

STUDY_ROLES = ("tables", "explicit-tables", "torsion-sweep", "bending", "regression", "stability",
               "pareto", "performance", "b09")
"""Roles a model can take in the studies: the per-experiment error ``tables`` (static runs), their
explicit rows (``explicit-tables``), the ``torsion-sweep`` of torque against angle, the cantilever
under its weight (``bending``), the CI ``regression`` cases, the ``stability`` study, speed against
error (``pareto``), explicit time per step (``performance``) and the [B09] cantilever and L-shape
(``b09``)."""

NEEDS = {"explicit-tables": "explicit", "performance": "explicit", "stability": "explicit"}
"""The solver kind a role needs of a model (the others: ``static``)."""

ENTRY_POINT_GROUP = "hybmss.studies"
"""Entry-point group through which another package declares the :class:`Part` of its model."""


def default_run_cost(scene, kind: str) -> float:
    """A rough cost per cell of a run of ``kind`` (``static``, ``explicit``, ``implicit``) of
    ``scene``, in the sweep's units (8×8×48 beam: about 3,800 per second; only to order the runs
    of a sweep, longest first): a static Newton solve at 5 % costs 1, larger plate displacements
    more load steps (``(d / 5 %)²`` above 5 %); an explicit run of the publication's protocol 0.5."""
    if kind == "explicit":
        return 0.5
    d = abs(float(getattr(scene, "deformation", 0.0) or 0.0))
    return max(1.0, d / 0.05) ** 2


def _no_face_diagonals_cost(scene, kind: str) -> float:
    """Static: 16× a conservative model's (without face diagonals the cells have zero-energy
    modes and Newton follows an indefinite path; 8×8×48 beam at ν = 0.499: 12 s at 5 %,
    60–180 s at 20 %)."""
    return default_run_cost(scene, kind) * (16.0 if kind == "static" else 1.0)


def _xpbd_cost(scene, kind: str) -> float:
    """Its substeps (explicit) and iterations to rest (static) grow as ``ω_max``, ω_max of the
    volumetric waves, ``∝ √((λ + 2μ)/μ)``: 2.5 (static) and 8 (explicit) times that per cell
    (8×8×48 beam at ν = 0.499: about 16 s to rest, 90 s for the explicit protocol)."""
    nu = min(float(scene.nu), 0.4999)
    return (8.0 if kind == "explicit" else 2.5) * math.sqrt(2.0 * (1.0 - nu) / (1.0 - 2.0 * nu))


@dataclass(frozen=True)
class Part:
    """A model's part in the studies (module docstring)."""

    roles: tuple[str, ...] = STUDY_ROLES
    published: dict[str, str] = field(default_factory=dict)
    run_cost: Callable[..., float] = default_run_cost
    meshes: dict = field(default_factory=dict)
    quick: bool = True

    def __post_init__(self):
        object.__setattr__(self, "roles", tuple(self.roles))
        if set(self.meshes) - {"cube", "beam"}:
            raise ValueError(f"meshes must be keyed by cube or beam; got {sorted(self.meshes)}")
        bad = [r for r in self.roles if r not in STUDY_ROLES]
        if bad:
            raise ValueError(f"study roles must be among {', '.join(STUDY_ROLES)}; got {bad[0]!r}")
        if not isinstance(self.published, dict) or not all(
                isinstance(k, str) and isinstance(v, str) for k, v in self.published.items()):
            raise ValueError("published must map publication keys to names (str -> str)")
        if not callable(self.run_cost):
            raise ValueError("run_cost must be a function (scene, kind) -> float")


_ALL_BUT_REGRESSION = tuple(r for r in STUDY_ROLES if r != "regression")
"""The competitors' roles: the ``regression`` baseline guards the mass-spring variants' errors
against getting worse; the corotational hexahedra and XPBD are pinned tighter by their own tests
(patch test, rigid rotation, equality with scikit-fem Hex1 to 1e-6, exact moduli; closed-form
Neo-Hookean stretch, the Lamé map at small strain, the substep bias), which fail on any change a
baseline would catch, and XPBD's rest runs would add the longest cases to CI."""

_ENGINE_ROLES = ("tables", "bending", "pareto")
_ENGINE_MESHES = {"cube": (5, 5, 5), "beam": (2, 2, 12)}
_ENGINE_MESHES_SMALL = {"cube": (2, 2, 2), "beam": (1, 1, 6)}


ENGINE_CONTEXT = ("hybmss", "corot-hex8")
"""Models shown beside the engines in their closing study (:mod:`studies.paper.engines`): the mass-spring
model and the corotational Hex8 FEM on the same cube."""


ENGINE_LAWS = {
    "mujoco-tet": ("MuJoCo 4.0.1 flex, dof=\"full\": linear tetrahedra (6 per voxel, MuJoCo's grid split)",
     "St Venant–Kirchhoff: edge Green strains l² − l0² contracted with the element metric "
     "(engine_elasticity.h: mj_stretchElongation, mj_stretchTension); young, poisson → μ = E/(2(1+ν)), "
     "λ = Eν/((1+ν)(1−2ν)) as documented, no shift",
     "joint damping on a flex (refused by MuJoCo: the loop applies −c m v after mj_step); surface tractions; ν < 0"),
    "mujoco-trilinear": ("MuJoCo 4.0.1 flex, dof=\"trilinear\": 8-node cells = the voxels",
     "constant cell stiffness (flex_stiffness) applied in the cell's rotated frame (engine_passive.c, "
     "flex_interp branch): corotational linear Hex8 in E, ν",
     "a body that is not a box (its interpolation grid spans the bounding box); as mujoco-tet"),
    "mujoco-quadratic": ("MuJoCo 4.0.1 flex, dof=\"quadratic\": 27-node cells",
     "corotational linear Hex27; masses ρVc/64 per node of each cell eighth (row-sum lumping of the 27-node "
     "mass matrix has negative corner masses)", "as mujoco-trilinear"),
    "newton-semi": ("Newton 1.8.0 on Warp 1.19.0 (cpu, float32), SolverSemiImplicit, tetrahedra",
     "stable Neo-Hookean whose small-strain Lamé parameters are (3 k_mu/4, k_lambda − 5 k_mu/8) "
     "(newton/_src/solvers/semi_implicit kernels, eval_tetrahedra): the builder's k_mu, k_lambda are not μ, λ; "
     "the model passes k_mu = 4μ/3, k_lambda = λ + 5μ/6",
     "the builder's documented Lamé mapping (k_mu = μ) gives μ 25 % low; ν ≤ −5/14 (k_lambda ≤ 0); float32 "
     "resolves forces to ~1e-4 of the plate force (the rest test's floor)"),
    "newton-vbd": ("Newton 1.8.0, SolverVBD (vertex block descent, 3×3 block per vertex)",
     "μ/2 (I_C − 3) + (λ+μ)/2 (J − α)², builder Lamé as they are",
     "slide plates (a node held in some components is off equilibrium in the others: 6 % residual "
     "measured), hence no moduli measurement"),
    "newton-xpbd": ("Newton 1.8.0, SolverXPBD", "constraints tr(FᵀF) − 3 and det F − 1 (solve_tetrahedra)",
     "linear elasticity: an energy quadratic in tr(FᵀF) − 3 is quartic in a shear strain, μ_eff = 1.9e-6 μ "
     "measured with its own kernel; every scene refused; tetrahedra with k_lambda ≤ 0 silently skipped"),
    "pbd-xpbd-fem": ("PositionBasedDynamics (pypbd 2.2.2), XPBD_FEMTetConstraint, 1 substep, 1 iteration",
     "St Venant–Kirchhoff with textbook Lamé, compliance 1/E",
     "ν < 0 or ν > 0.49: the constraint silently makes no correction (refused here); an absolute threshold of "
     "1e-6 on the constraint switches every tetrahedron off at small strain in SI units (the model runs in a "
     "1e12 kg mass unit)"),
}
"""What the report says of each engine model (reports/engines.py): engine and element, its law and (E, ν)
mapping as derived from the engine's source in the model's folder, and what it cannot represent
(refused before any work), each measured by tests/verification/test_engine_*.py."""


def _engine_cost(scene, kind: str) -> float:
    """An engine's damped run to rest: its steps grow as ω_max/ω₁ ∝ √((λ + 2μ)/μ) (the volumetric
    waves against the slowest mode); 4³ cube at ν = 1/4: a few seconds."""
    nu = min(float(scene.nu), 0.4999)
    return 4.0 * math.sqrt(2.0 * (1.0 - nu) / (1.0 - 2.0 * nu))


IN_TREE = {
    "hybmss": Part(STUDY_ROLES, {"G20": "hybmss"}),
    "hybmss-fd": Part(tuple(r for r in STUDY_ROLES if r != "b09"), {"G20": "hybmss-fd"}, _no_face_diagonals_cost),
    "hybmss-cf": Part(("tables", "regression", "stability", "pareto", "performance"), {"G20": "hybmss-cf"}),
    "baudet2009": Part(("tables", "b09"), {"B09": "baudet2009"}),
    "corot-hex8": Part(_ALL_BUT_REGRESSION),
    "corot-hex8-sri": Part(_ALL_BUT_REGRESSION),
    "xpbd-nh": Part(_ALL_BUT_REGRESSION, run_cost=_xpbd_cost),
    # the engines (hybmss/models/mujoco, newton, pbd): static rows of the five experiments
    # (``tables``: compression, tension, shear, torsion; their stability hard cases, part (g) of
    # studies/paper/stability.py, are runs of those tables; ``bending``: the cantilever under its weight)
    # and of the speed-against-error study (``pareto``: the base resolution only where it is not
    # finer than their own mesh, no beam under gravity), on coarse meshes of their own
    # (studies.study.experiment: ``mesh_for``) each with the study's FEM references on the same mesh.
    # The 5³ cube and the 2×2×12 beam are the speed-against-error study's base meshes: its runs of
    # the same scenes are the tables' runs (one key, stored once), so the tables add only the FEM
    # of those meshes and mujoco-quadratic's runs (2³, 1×1×6: 27-node cells) to make
    # reproduce-paper; the quick mode runs ν = 1/4 at 5 % and 1° (bending: E = 10 MPa) on the quick
    # meshes.  A damped run to rest of the cantilever under its weight takes about 3,000 engine
    # steps (its slowest mode is the beam's first bending mode, ω₁ ~ 10× below the cube's, while
    # the step stays at the cells' ω_max): 5-13 s a run on the 2×2×12 beam, eight runs.  No explicit
    # protocol (their stable step at ν = 0.499 is below its 1 ms), no stability bisection.  The
    # moduli table runs every studied model, the [B09] tables those on the publications' meshes.
    # newton-vbd (0.18 s a step on the 1×1×6 beam: Gauss-Seidel colours; its 30 table runs were
    # estimated at 3,500 s, more than the rest of the reproduction) and pbd-xpbd-fem (per-node
    # Python calls of the library's bindings: 0.06 s a step on the 2³ cube, ~1,600 steps to rest)
    # have no role in make reproduce-paper: they run in the closing study (--study engines);
    # newton-xpbd is refused by every scene (no small-strain shear stiffness): its failure rows say so.
    "mujoco-tet": Part(_ENGINE_ROLES, meshes=_ENGINE_MESHES, run_cost=_engine_cost),
    "mujoco-trilinear": Part(_ENGINE_ROLES, meshes=_ENGINE_MESHES, run_cost=_engine_cost),
    "mujoco-quadratic": Part(_ENGINE_ROLES, meshes=_ENGINE_MESHES_SMALL, run_cost=_engine_cost),
    "newton-semi": Part(_ENGINE_ROLES, meshes=_ENGINE_MESHES, run_cost=_engine_cost),
    "newton-vbd": Part((), meshes=_ENGINE_MESHES_SMALL, run_cost=_engine_cost, quick=False),
    "newton-xpbd": Part((), meshes=_ENGINE_MESHES_SMALL, run_cost=_engine_cost),
    "pbd-xpbd-fem": Part((), meshes=_ENGINE_MESHES_SMALL, run_cost=_engine_cost, quick=False),
}
"""The part of each in-tree model (a model not listed here, or declared by its package, takes the
default :class:`Part`)."""


RELEASED_MODELS = ("hybmss", "hybmss-fd", "hybmss-cf", "baudet2009", "corot-hex8", "corot-hex8-sri", "xpbd-nh")
"""The models released at every ν in the dynamics study (:mod:`studies.paper.dynamics_study`), each
with its own integrator at its user step."""
RELEASED_ENGINES = {"cube": ("mujoco-tet", "mujoco-trilinear", "newton-semi", "newton-vbd", "pbd-xpbd-fem"),
                    "beam": ("mujoco-tet", "mujoco-trilinear", "newton-semi")}
"""The engines released at ν = 1/4 in the dynamics study, per body.  mujoco-quadratic's nodes are
not the lattice particles (no released state on its own nodes) and newton-xpbd cannot represent a
shear modulus (both refuse in one line before any work).  newton-vbd and pbd-xpbd-fem take 25-100 s
of a 2-core machine each for the beam's two and a half periods (measured: 163 and 270 CPU s at load
8, five times every lattice model's beam runs together): the cube only."""
RELEASED_QUICK = ("hybmss-cf", "corot-hex8")
"""The models the dynamics study's quick level releases (one symplectic lattice model, one FEM)."""
RELEASED_DIVERGES = {"baudet2009": 0.45}
"""Models whose released run at the user step (0.9 of the harness's stability limit) diverges from
this ν on (measured: baudet2009 at ν = 0.45 and 0.499 on both bodies); their rows say so, and the
runner counts them as runs without result as expected, not as failures."""

class Parts:
    """The parts of the registered models: :data:`IN_TREE`, those declared through the entry-point
    group (read at the first look-up) and those given to :meth:`declare`."""

    def __init__(self, in_tree: dict[str, Part]):
        self._parts = dict(in_tree)
        self._declared: dict[str, Part] = {}
        self._discovered = False

    def discover(self) -> None:
        if self._discovered:
            return
        self._discovered = True
        for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
            try:
                part = ep.load()
            except Exception as exc:
                raise RuntimeError(f"study part {ep.name!r} ({ep.value}) failed to load: {exc}") from exc
            if not isinstance(part, Part):
                raise RuntimeError(f"study part {ep.name!r} ({ep.value}) must be a studies.sweep.roles.Part, "
                                   f"got {type(part).__name__}")
            self._parts[ep.name] = part

    def declare(self, name: str, part: Part) -> None:
        if not isinstance(part, Part):
            raise TypeError(f"a study part must be a studies.sweep.roles.Part, got {type(part).__name__}")
        self._declared[name] = part

    def withdraw(self, name: str) -> None:
        self._declared.pop(name, None)

    def get(self, name: str) -> Part:
        self.discover()
        return self._declared.get(name) or self._parts.get(name) or Part()


PARTS = Parts(IN_TREE)
"""The studies' one table of parts."""


def declare(name: str, part: Part) -> None:
    """Give the model ``name`` (registered at run time) its part in the studies."""
    PARTS.declare(name, part)


def withdraw(name: str) -> None:
    """Undo :func:`declare` (the model takes its default or entry-point part again)."""
    PARTS.withdraw(name)


def part(model: str) -> Part:
    """The part of the registered model ``model``."""
    return PARTS.get(model)


def takes_part(model: str, role: str) -> bool:
    """Whether the model ``model`` joins the study role ``role``: declared, and its solvers allow it."""
    from hybmss import models  # read here: the report imports this module's tables without the registry
    return role in part(model).roles and NEEDS.get(role, "static") in models.get(model).solvers


def in_role(role: str) -> tuple[str, ...]:
    """Names of the models that take part in the study role ``role``, in the registry's order."""
    from hybmss import models  # read here: the report imports this module's tables without the registry
    if role not in STUDY_ROLES:
        raise ValueError(f"study role must be one of {', '.join(STUDY_ROLES)}; got {role!r}")
    return tuple(n for n in models.names() if takes_part(n, role))


def studied() -> tuple[str, ...]:
    """Names of the models that take part in any study role (a model listed with no role, such as an
    engine whose study resolutions are not chosen yet, is left out of every study), in the
    registry's order."""
    from hybmss import models  # read here: the report imports this module's tables without the registry
    return tuple(n for n in models.names() if part(n).roles)


def mesh_for(model: str, spec):
    """The scene spec ``spec`` on the mesh the model's part gives its body kind (:attr:`Part.meshes`),
    or ``spec`` itself (no override, or a publication mesh coarser than it)."""
    own = part(model).meshes.get("beam" if spec.is_beam else "cube")
    if own is None or all(a <= b for a, b in zip(spec.mesh, own)):
        return spec
    return spec.replace(mesh=tuple(own))


def published(model: str) -> dict[str, str]:
    """The publications that report ``model``, each with its name for it."""
    return part(model).published


def run_cost(scene, kind: str) -> float:
    """The run-cost estimate of ``scene``'s model (:func:`default_run_cost` unless it has its own)."""
    return part(scene.model).run_cost(scene, kind)
