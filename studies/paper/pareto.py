"""Speed against error: time to a solution against its error w.r.t. a converged FEM reference.

For each experiment (compression, tension, shear, torsion, bending) and configuration
(ν ∈ {0, ¼, 0.499} × d ∈ {5 %, 20 %}; torsion θ ∈ {1°, 45°}; bending at the publication's
ν = ¼, E ∈ {10, 2} MPa) the candidates are

- the models of the ``pareto`` role (:func:`pareto_models`: the mass-spring variants hybmss,
  hybmss-fd and hybmss-cf, the corotational hexahedra corot-hex8 and corot-hex8-sri, the XPBD
  Neo-Hookean tetrahedra xpbd-nh) with each solver: static Newton, implicit
  Euler to rest (dt = 0.25 s, at most 40 steps = 10 s, plates ramped over 1 s, c = 2 s⁻¹) and the
  publication's explicit protocol (dt = 1 ms × 10,000 steps, c = 2 s⁻¹, ramp 1 s; xpbd-nh's run
  ends at the fixed point of its substep once it is at rest: :data:`PROTOCOL`), at the base
  resolution and its refinements (the finest beam has no explicit run of hybmss-cf, as in the
  reproduction study); implicit for hybmss at the base resolution only (a Newton solve per step
  makes it the most expensive solver);
- the engines of the ``pareto`` role (:mod:`studies.paper.engines`): their static answer (the rest state
  of their damped run) at the base resolution only, not the beam under gravity, and only where the
  base is not finer than the engine's own mesh (:attr:`studies.sweep.roles.Part.meshes`; cost: mujoco-quadratic's
  27-node cells on the full level's 5³ cube took 2.6–12 s a run, 35 s for compression's six, three
  timed runs each, about half of the engines' time in make reproduce-paper; it keeps its rows at the
  quick level's 2³);
- the FEM itself: Hex1 at every resolution (cube also ×3), Hex2 and mixed u–p at the resolutions
  coarser than the reference's, with the reference's law.

Resolutions (:data:`LEVELS`; base → MSS refinements → reference):

- ``full`` (default, ``make reproduce-paper``): cube 5³ → 10³ → reference 10³; beam 2×2×12 →
  4×4×24, 8×8×48 → reference 8×8×48.  The 10³ cube and the 4×4×24 and 8×8×48 beams are the
  reproduction study's meshes, so its reference and the runs it shares (static runs of its models,
  explicit runs of the ``explicit-tables`` models) are computed once.
- ``medium``: cube 3³ → 6³ → reference 6³; beam 1×1×6 → 2×2×12, 4×4×24 → reference 4×4×24
  (the former default: a ranking of 3³–6³ meshes is one of timings of a few milliseconds).
- ``quick`` (tests): cube 2³ → 4³, beam 1×1×6 → 2×2×12, ν = ¼, 5 %, 1°, E = 10 MPa, linear law.

``run(..., experiments=..., nus=..., level=...)`` restricts the configurations (the bending ones
keep ν = ¼) or picks the level.

**Reference.**  The finest FEM that fits the time budget: Hex2 (mixed u–p Hex2×Hex1 for
ν ≥ 0.45, ``element='auto'``; Hex2 for the beam under gravity) at the reference resolution, with
the law of :func:`studies.sweep.compare.default_law` (linear up to 5 %, Neo-Hookean above, Neo-Hookean
for the beam under gravity).  Its discretization error is estimated by Richardson from the same
element one level coarser (ratio 2): ``‖u_ref − u_coarse‖ / ((2^p − 1) ‖u_ref‖)`` with p = 2
assumed (the clamped edges limit the smoothness; Hex2's nominal order is higher, so the estimate
is conservative).  Errors below about this estimate are not resolved.  At ν = 0 compression and
tension are homogeneous (no lateral strain), every FEM is exact and the estimate is ~1e-15.

**Errors** (:data:`MEASURES`), each against the reference, each seeing ν:

- ``error_force``: relative error of the loaded plate's reaction along its motion (F_z of
  compression and tension, F_x of shear, T_z of torsion; of the beam under gravity its tip
  deflection, the clamp's reactions being the weight for every model);
- ``error_volume``: ``|e − e*| / s``, the volume change e against the reference's e*, in units
  of the imposed strain s (:func:`strain_scale`: d; the torsion's corner shear strain; the beam's
  bending strain at the clamp); near ν = ½, e* ≈ 0 and a model whose ν is ¼ is off by about
  (1 − 2·¼) s;
- ``error_field`` (also ``error_u``): relative L2 of the nodal displacement at the shared coarse
  points, the particles of the base lattice that no plate prescribes.  Every resolution is an
  integer multiple of the base, so each run has a particle (or a FEM vertex) at every shared
  point: values are sampled, never interpolated.  Alone it is blind to ν where the imposed motion
  dominates the field: it let hybmss-cf, whose ν is always ¼, win budgets at ν = 0.499.

**Cost** (:mod:`studies.sweep.cost`).  Every candidate is first timed by its own run, the one its
errors come from; only where two candidates are within the timing noise of each other (a budget
answer's winner and runner-up with ``lead < 1 +`` :data:`NOISE`, :func:`near_ties`) are they
repeated (:func:`repeat_pairs`), and a lead beyond the noise is no tie.  An explicit candidate
that cannot come to rest in its step budget is not run (:mod:`studies.sweep.rest_bound`: stored as not
at rest, with the steps it needs).  Static, implicit and FEM runs: ``time_s``, the best of the run
and, where repeated, :data:`REPEATS` − 1 repeats of it (each its own stored run), with its spread; the solver's
``wall_time_s`` (assembly included; FEM: meshing, assembly and solve), single-threaded, runs
executed two at a time on a shared machine: read ratios, not absolute figures.  Explicit runs:
the error is that of the publication's protocol run (at rest, the static equilibrium of the same
energy); the cost is ``cost_explicit_s``, the wall time of one simulated second at the stable step
``½ dt_crit`` (:data:`studies.sweep.cost.SAFETY`), from the time per step of the protocol run itself,
or where repeated the best of :data:`REPEATS` short runs of :data:`TIMING_STEPS` steps (timing runs,
:attr:`SolverSpec.timing`: not at rest, as asked; counted apart from results, findings and failures).
xpbd-nh has no explicit limit: its frame is the same ½ dt_crit (its dt_crit: 2/ω_max of the same
grid), split into the substeps its accuracy rule chooses (h ω_max ≤ 0.1: 10 substeps), each costing the best time per substep of its short runs
(:func:`unlimited_frame`).

**No result, no value.**  A candidate whose run reached no result (``at_rest`` False: an explicit
run that did not come to rest by :func:`hybmss.explicit.rest_report`, the runner's status
"not-converged"; a static solve that did not converge; a failed run) has no error and no
``time_s`` (NaN in the CSV); ``failure`` says why (:func:`studies.sweep.runner.no_result_because`,
``""`` for a result), nor any measured cost (:data:`NO_RESULT_COSTS`: a cost of no result).  It
is on no Pareto front, wins no budget and is no runner-up; a method with no result at all is
listed in the budget table as :data:`studies.sweep.cost.NO_RESULT` with that reason.

**Budget answer** (:func:`budget_table`): per configuration, error measure and cost, the fastest
method within 1, 5 and 10 %, its runner-up, the lead and whether the lead is a tie
(:func:`studies.sweep.cost.budget_answer`: ``lead < 1 +`` the larger spread, at least
:data:`studies.sweep.cost.TIMING_NOISE`).
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pandas as pd

from studies.sweep import roles
from studies.sweep.compare import default_law
from hybmss import models
from hybmss.experiments import SceneSpec

from studies.sweep import cost
from studies.sweep.outcomes import expected_finding
from studies.sweep.runner import SolverSpec, Task, no_result_because, run_tasks
from studies.sweep.store import Store

EXPERIMENTS = ("compression", "tension", "shear", "torsion", "bending")
NUS = (0.0, 0.25, 0.499)
def pareto_models() -> tuple[str, ...]:
    """The models compared (registry order; the first is the reference model, also run implicitly)."""
    return roles.in_role("pareto")
DAMPING = 2.0
PROTOCOL = SolverSpec("explicit", dt=1e-3, steps=10_000, ramp_time=1.0, until_rest=True)
"""The publication's explicit protocol; an xpbd-nh run that comes to rest ends at the fixed point
of its substep, the state the rest of its 10 s tends to (``until_rest``,
:meth:`hybmss.models.xpbd_nh.XpbdStepper.settle`)."""
IMPLICIT = SolverSpec("implicit", dt=0.25, steps=40, ramp_time=1.0)
STATIC = SolverSpec("static")
BUDGETS = (0.01, 0.05, 0.10)
ORDER_ASSUMED = 2.0
DEFAULT_LEVEL = "full"
"""The level of ``make reproduce-paper`` (meshes up to the 10³ cube and the 8×8×48 beam)."""
REPEATS = {"quick": 3, "medium": 3, "full": 3}
"""Timed runs of every candidate per level: the run itself and ``REPEATS − 1`` repeats
(:attr:`SolverSpec.repeat`); the best is its time, the median's excess over it its spread."""
NOISE = 2.5
"""The timing noise assumed before any repeat: two candidates whose single timings differ by less
than this factor (lead < 1 + NOISE) are repeated :data:`REPEATS` times to tell them apart; a lead
beyond it is no tie (:func:`near_ties`).  2.5: the 90th percentile of the spreads of the quick
study's 122 timed candidates when every one was repeated (median 0.15, 95th 4.4: the short runs
of a loaded machine: one candidate in ten had a spread above it)."""
TIMING_STEPS = {"quick": 50, "medium": 1000, "full": 1000}
"""Steps of the short explicit runs timed for the cost of a step (the step's cost does not depend
on the state, so the protocol's 10,000 steps need not be repeated)."""
MEASURES = ("force", "volume", "field")
"""Error measures of the budget answer (columns ``error_<measure>``, module docstring)."""
COST_KINDS = {"static": "time_s", "explicit": "cost_explicit_s"}
"""The two costs of the budget answer: wall time to an equilibrium (static Newton, implicit Euler
to rest, the FEM) and wall time per simulated second at the stable step (explicit)."""


LEVELS = {
    "quick": {"cube": ((2, 2, 2), (1, 2), (1, 2), 2), "beam": ((1, 1, 6), (1, 2), (1, 2), 2)},
    "medium": {"cube": ((3, 3, 3), (1, 2), (1, 2, 3), 2), "beam": ((1, 1, 6), (1, 2, 4), (1, 2, 4), 4)},
    "full": {"cube": ((5, 5, 5), (1, 2), (1, 2, 3), 2), "beam": ((2, 2, 12), (1, 2, 4), (1, 2, 4), 4)},
}
"""Per level and body kind: base mesh, MSS resolution factors, Hex1 factors, reference factor.
``medium`` is the study of ``make reproduce-paper``; ``full`` the same design on finer bases."""


def level_name(quick: bool, level: str | None = None) -> str:
    return level or ("quick" if quick else DEFAULT_LEVEL)


def bases(quick: bool, level: str | None = None) -> dict:
    return LEVELS[level_name(quick, level)]


def configs(quick: bool, experiments=EXPERIMENTS, nus=None, level: str | None = None) -> list[SceneSpec]:
    """Base-mesh scene specs (model hybmss) of every configuration."""
    b = bases(quick, level)
    nus = tuple(nus) if nus is not None else ((0.25,) if quick else NUS)
    out = []
    for exp in experiments:
        mesh = b["beam" if exp in ("tension", "bending") else "cube"][0]
        if exp == "bending":
            for E in ((1e7,) if quick else (1e7, 2e6)):
                out.append(SceneSpec.default("bending", mesh=mesh, E=E, nu=0.25, gravity=10.0))
        elif exp == "torsion":
            for nu, a in itertools.product(nus, (1.0,) if quick else (1.0, 45.0)):
                out.append(SceneSpec.default("torsion", mesh=mesh, nu=nu, angle_deg=a))
        else:
            for nu, d in itertools.product(nus, (0.05,) if quick else (0.05, 0.20)):
                out.append(SceneSpec.default(exp, mesh=mesh, nu=nu, deformation=d))
    return out


def _scaled(spec: SceneSpec, factor: int) -> SceneSpec:
    return spec.replace(mesh=tuple(n * factor for n in spec.mesh))


def config_label(spec: SceneSpec) -> str:
    if spec.experiment == "torsion":
        load = f"θ={spec.angle_deg:g}°"
    elif spec.experiment == "bending":
        load = f"E={spec.E:g}"
    else:
        load = f"d={100 * spec.deformation:g}%"
    return f"{spec.experiment} ν={spec.nu:g} {load}"


def _fem_element_name(element: str, nu: float) -> str:
    """'auto' where it resolves to ``element`` (so the run is shared with the reproduction)."""
    from fem_reference.solve import resolve_element

    return "auto" if resolve_element("auto", nu) == element else element


def _ref_element(spec: SceneSpec) -> str:
    return "hex2" if spec.experiment == "bending" else "auto"


def repeat_pairs(meta: dict, task: Task, lv: str) -> list[tuple[dict, Task]]:
    """The timing runs of a candidate (``meta``, ``task``) at level ``lv``: the repeats of its time
    (:attr:`SolverSpec.repeat` 1 … :data:`REPEATS` − 1); of an explicit run, :data:`REPEATS` short
    runs of :data:`TIMING_STEPS` steps timing its steps."""
    solver = task.solver
    if solver.kind == "explicit":
        timing, ks = (dataclasses.replace(solver, steps=TIMING_STEPS[lv], until_rest=False, timing=True),
                      range(REPEATS[lv]))
    else:
        timing, ks = solver, range(1, REPEATS[lv])
    return [({**meta, "role": "timing", "repeat": k}, Task(task.scene, dataclasses.replace(timing, repeat=k), "pareto"))
            for k in ks]


def tasks_for(spec: SceneSpec, quick: bool, level: str | None = None, with_repeats: bool = False
              ) -> list[tuple[dict, Task]]:
    """(meta, task) pairs of one configuration: reference, its coarse partner, candidates (and,
    ``with_repeats``, every candidate's timing runs: :func:`repeat_pairs`; :func:`run` adds them
    only where two candidates are within noise of each other)."""
    kind = "beam" if spec.is_beam else "cube"
    _, mss_factors, fem_factors, ref_f = bases(quick, level)[kind]
    law = "linear" if quick else default_law(spec)
    cfg = config_label(spec)
    out = []

    lv = level_name(quick, level)

    def add(role, factor, s, solver, method):
        meta = {"config": cfg, "experiment": spec.experiment, "role": role, "factor": factor,
                "method": method, "mesh": "x".join(map(str, s.mesh)), "base": spec, "repeat": 0}
        # an explicit candidate is of use only at rest: not run when its budget cannot reach it
        out.append((meta, Task(s, solver, "pareto", answer_only=role == "candidate" and solver.kind == "explicit")))
        if role == "candidate" and with_repeats:
            out.extend(repeat_pairs(meta, Task(s, solver, "pareto"), lv))

    ref_el = _ref_element(spec)
    add("reference", ref_f, _scaled(spec, ref_f), SolverSpec("fem", element=ref_el, law=law), "reference")
    add("partner", ref_f // 2, _scaled(spec, ref_f // 2), SolverSpec("fem", element=ref_el, law=law),
        "reference partner")
    finest = max(mss_factors)
    for f in mss_factors:
        s = _scaled(spec, f)
        for model in pareto_models():
            engine = bool(roles.part(model).meshes)  # its static answer at the base resolution only
            if engine and (f != 1 or spec.experiment == "bending" or (quick and not roles.part(model).quick)
                           or roles.mesh_for(model, s) != s):  # a base finer than the engine's own mesh
                continue
            sm = s.replace(model=model)
            add("candidate", f, sm, STATIC, f"{model} static")
            if engine:
                continue
            if f < finest or model in roles.in_role("explicit-tables") or quick:
                add("candidate", f, sm.replace(damping=DAMPING), PROTOCOL, f"{model} explicit")
            if f == 1 and model == pareto_models()[0] and models.get(model).supports("implicit"):
                add("candidate", f, sm.replace(damping=DAMPING), IMPLICIT, f"{model} implicit")
    for f in sorted(set(fem_factors) | set(mss_factors)):
        s = _scaled(spec, f)
        for el in ("hex1", "hex2", "mixed"):
            if (el == "hex1" and f not in fem_factors) or (el != "hex1" and f >= ref_f):
                continue
            if el == "mixed" and spec.nu <= 0.0:  # the u–p form needs λ > 0
                continue
            name = el if spec.experiment == "bending" else _fem_element_name(el, spec.nu)
            add("candidate", f, s, SolverSpec("fem", element=name, law=law), f"fem-{el}-{law}")
    return out


def all_tasks(quick: bool = False, experiments=EXPERIMENTS, nus=None, level: str | None = None,
              with_repeats: bool = False) -> list[tuple[dict, Task]]:
    return [p for spec in configs(quick, experiments, nus, level)
            for p in tasks_for(spec, quick, level, with_repeats)]


# ------------------------------------------------------------------------------ metrics
def _keys(X: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(X) * 1e6).astype(np.int64)


def sample(X: np.ndarray, u: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Values of ``u`` at the particles of ``X`` that coincide with ``points`` (to 1 µm)."""
    lookup = {tuple(k): i for i, k in enumerate(_keys(X))}
    try:
        idx = np.array([lookup[tuple(k)] for k in _keys(points)])
    except KeyError as exc:
        raise ValueError("a shared point is not a particle of this result (meshes are not nested)") from exc
    return np.asarray(u)[idx]


def shared_points(spec: SceneSpec) -> np.ndarray:
    """Base-lattice particles that no plate prescribes."""
    from hybmss.lattice import Lattice

    scene = spec.build()
    X = Lattice.from_body(scene.body).X
    held = np.zeros(len(X), dtype=bool)
    for plate in scene.plates:
        held |= plate.region.select(X, scene.body)
    return X[~held]


def force_of(spec: SceneSpec, row: dict) -> tuple[str, float]:
    """The load measure of an experiment: the loaded plate's reaction along its motion (F_z of
    compression and tension, F_x of shear, T_z of torsion); of the beam under gravity, its tip
    deflection (the clamp's reactions are the body's weight and its moment for every model)."""
    exp = spec.experiment
    name = {"compression": "force_z", "tension": "force_z", "shear": "force_x",
            "torsion": "torque_z"}.get(exp, "tip_deflection")
    v = row.get(name, np.nan)
    return name, np.nan if v is None else float(v)


def strain_scale(spec: SceneSpec) -> float:
    """The imposed strain the volume error is measured in: d (compression, tension, shear); the
    torsion's largest shear strain θ r / H (r the half-diagonal of the a × a section, at the
    corners); the beam's Euler–Bernoulli bending strain at the clamp, κ h/2 = 2 δ_EB h / L²."""
    from hybmss.lattice import Lattice

    ext = np.ptp(Lattice.from_body(spec.build().body).X, axis=0)
    if spec.experiment == "torsion":
        return float(np.radians(spec.angle_deg) * np.hypot(ext[0], ext[1]) / 2 / ext[2])
    if spec.experiment == "bending":
        return float(2 * abs(spec.euler_bernoulli_tip()) * ext[1] / ext[2] ** 2)
    return float(abs(spec.deformation))


def relative_error(q: float, q_ref: float) -> float:
    return abs(q - q_ref) / abs(q_ref) if q_ref and np.isfinite(q_ref) else np.nan


def _times(rows: list[dict]) -> list[float]:
    return [float(r["wall_time_s"]) for r in rows
            if r.get("status") in ("ok", "not-converged") and np.isfinite(r.get("wall_time_s", np.nan))
            and r["wall_time_s"] > 0]


def unlimited_frame(spec: SceneSpec) -> tuple[float, float, int]:
    """(dt_crit, frame, substeps) of a model with no explicit limit: its frame is the stable step of
    the others, ½ dt_crit (``dt_crit`` its own: :func:`hybmss.explicit.dt_crit`), split into the
    substeps its stepper chooses for that frame (xpbd-nh: its accuracy rule h ω_max ≤ 0.1)."""
    from hybmss.explicit import dt_crit
    from hybmss.system import build

    system = build(spec.build())
    dc = float(dt_crit(system))
    frame = cost.stable_dt(dc)
    stepper = models.get(spec.model).stepper(system, frame, ramp_time=1.0)
    return dc, frame, int(getattr(stepper, "substeps", 1))


def unlimited_frames(pairs, runner=None) -> dict:
    """:func:`unlimited_frame` of every explicit candidate of a model without an explicit limit
    (xpbd-nh: an eigen solve each, 60 of them in ``make reproduce-paper``), computed on the
    workers of ``runner``'s session (:func:`studies.sweep.executors.map_local`); none without such
    workers (:func:`pareto_frame` then computes each where it is needed, in this process)."""
    if runner is None or runner.local_workers() is None:
        return {}
    from studies.sweep.executors import map_local

    scenes = list(dict.fromkeys(
        t.scene for m, t in pairs
        if m["role"] == "candidate" and t.solver.kind == "explicit" and not models.get(t.scene.model).explicit_limit))
    return dict(zip(scenes, map_local(unlimited_frame, scenes, runner=runner)))


def timing_columns(solver: SolverSpec, row: dict, repeats: list[dict], frame=None) -> dict:
    """Static, implicit and FEM: ``time_s`` (best of the run and its repeats), ``time_median_s``,
    ``time_spread``, ``time_repeats``.  Explicit: ``time_s`` the protocol run's wall time (one
    run); ``us_per_step`` (best of the short timed runs, per step or, with substeps, per substep;
    ``step_spread``), ``dt_crit``, ``dt_stable`` (:func:`studies.sweep.cost.stable_dt`) and
    ``cost_explicit_s``: wall seconds per simulated second at ``dt_stable``.  A model with no
    explicit limit needs ``frame`` = :func:`unlimited_frame`: its cost is ``substeps / frame``
    substeps per simulated second."""
    out = {"time_s": np.nan, "time_median_s": np.nan, "time_spread": np.nan, "time_repeats": 0,
           "us_per_step": np.nan, "step_spread": np.nan, "dt_crit": np.nan, "dt_stable": np.nan,
           "cost_explicit_s": np.nan, "explicit_spread": np.nan}
    if solver.kind != "explicit":
        ts = _times([row, *repeats])
        if ts:
            out.update(cost.Timing.from_samples(ts).as_dict("time"))
        return out
    ts = _times([row])
    out["time_s"] = ts[0] if ts else np.nan
    def per_step(r):
        return (1e6 * float(r["wall_time_s"]) / float(r.get("steps") or solver.steps)
                / float((r.get("info") or {}).get("substeps") or 1))

    per = [per_step(r) for r in repeats if _times([r])]
    if not per and ts:  # no timing runs: the time per step of the run itself (one timing, no spread)
        per = [per_step(row)]
    dc = row.get("dt_crit", np.nan)
    dc = np.nan if dc is None else float(dc)
    if models.get(row["model"]).explicit_limit and np.isfinite(dc):  # the lattice's, no result of the run
        out.update(dt_crit=dc, dt_stable=cost.stable_dt(dc))
    if not per:
        return out
    t = cost.Timing.from_samples(per)
    out.update(us_per_step=t.best, step_spread=t.spread, explicit_spread=t.spread)
    if models.get(row["model"]).explicit_limit:
        if np.isfinite(dc):
            dt = cost.stable_dt(dc)
            out.update(dt_crit=dc, dt_stable=dt, cost_explicit_s=cost.cost_per_simulated_second(t.best, dt))
    elif frame is not None:
        dc, dt, substeps = frame
        out.update(dt_crit=dc, dt_stable=dt / substeps,
                   cost_explicit_s=cost.cost_per_simulated_second(t.best, dt / substeps))
    return out


NO_RESULT_COSTS = ("elapsed_s", "time_s", "time_median_s", "time_spread", "us_per_step", "step_spread",
                   "explicit_spread", "cost_explicit_s")
"""The measured costs a candidate that reached no result does not show (NaN): a cost of no result."""


def pareto_frame(store: Store, pairs, rows, quick: bool = False, frames: dict | None = None,
                 measured: dict | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Tidy table of candidates with errors and costs, and the reference table (one row per config).
    ``frames``: :func:`unlimited_frame` of each scene already computed (an eigen-solve each), kept
    by the caller across calls and filled here.  ``measured``: likewise the errors of each stored
    run against its configuration's reference (keyed by the runs' keys, which name their results:
    a repeat adds timings, never changes an error), so that the driver's later calls, after
    repeats, read no arrays again."""
    frames = {} if frames is None else frames
    measured = {} if measured is None else measured

    def frame_of(scene):
        if scene not in frames:
            frames[scene] = unlimited_frame(scene)
        return frames[scene]

    specs = {m["config"]: m["base"] for m, _ in pairs}
    groups: dict[str, list] = {}
    timing: dict[tuple, list] = {}
    for (meta, task), row in zip(pairs, rows):
        if meta["role"] == "timing":
            timing.setdefault((meta["config"], meta["method"], meta["mesh"]), []).append(row)
        else:
            groups.setdefault(meta["config"], []).append((meta, task, row))
    out, refs = [], []
    for cfg, items in groups.items():
        spec = specs[cfg]
        ref = next((m, t, r) for m, t, r in items if m["role"] == "reference")
        part = next((m, t, r) for m, t, r in items if m["role"] == "partner")
        ref_ok = ref[2]["status"] == "ok"
        ref_key = (cfg, ref[2]["key"], part[2]["key"])
        if ref_key not in measured:
            pts = shared_points(spec)
            a_ref = store.arrays(ref[2]["key"]) if ref_ok else None
            u_ref = sample(a_ref["X"], a_ref["u"], pts) if ref_ok else None
            ref_err = np.nan
            if ref_ok and part[2]["status"] == "ok":
                a = store.arrays(part[2]["key"])
                u_p = sample(a["X"], a["u"], pts)
                ref_err = float(np.linalg.norm(u_ref - u_p) / np.linalg.norm(u_ref) / (2 ** ORDER_ASSUMED - 1))
            measured[ref_key] = (pts, u_ref, ref_err)
        pts, u_ref, ref_err = measured[ref_key]
        fname, f_ref = force_of(spec, ref[2]) if ref_ok else ("", np.nan)
        e_ref = float(ref[2].get("volume_change", np.nan)) if ref_ok else np.nan
        scale = strain_scale(spec)
        refs.append({"config": cfg, "experiment": spec.experiment, "nu": spec.nu,
                     "reference": ref[2]["solver"], "reference_mesh": ref[0]["mesh"],
                     "reference_status": ref[2]["status"], "reference_time_s": ref[2].get("wall_time_s", np.nan),
                     "reference_error_estimate": ref_err, "partner_mesh": part[0]["mesh"],
                     "shared_points": len(pts), "force_quantity": fname, "force_reference": f_ref,
                     "volume_change_reference": e_ref, "strain_scale": scale})
        for meta, task, row in items:
            if meta["role"] != "candidate":
                continue
            rec = {**{k: v for k, v in meta.items() if k not in ("base", "repeat")}, "nu": spec.nu,
                   "load": cfg.split(" ", 2)[2], "solver": task.solver.label,
                   "variant": task.scene.variant if task.solver.kind != "fem" else "fem",
                   "kind": "explicit" if task.solver.kind == "explicit" else "static",
                   "status": row["status"], "elapsed_s": row.get("elapsed_s", np.nan),
                   "message": row.get("message", ""), "reference_error_estimate": ref_err,
                   **timing_columns(task.solver, row, timing.get((cfg, meta["method"], meta["mesh"]), []),
                                    frame=None if task.solver.kind != "explicit" or models.get(
                                        task.scene.model).explicit_limit else frame_of(task.scene)),
                   "force_quantity": fname, "force_reference": f_ref, "volume_change_reference": e_ref,
                   "strain_scale": scale}
            for m in MEASURES:
                rec[f"error_{m}"] = np.nan
            rec["at_rest"] = row["status"] == "ok"
            rec["failure"] = no_result_because(row)
            if not rec["at_rest"]:  # no time to a solution, nor a cost of one
                rec.update({k: np.nan for k in NO_RESULT_COSTS})
            if rec["at_rest"] and ref_ok:
                run_key = (ref_key, row["key"])
                if run_key not in measured:
                    a = store.arrays(row["key"])
                    u = sample(a["X"], a["u"], pts)
                    _, f = force_of(spec, row)
                    e = float(row.get("volume_change", np.nan))
                    vols = a.get("cell_volumes")
                    measured[run_key] = dict(
                        error_field=float(np.linalg.norm(u - u_ref) / np.linalg.norm(u_ref)),
                        force_value=f, volume_change=e, error_force=relative_error(f, f_ref),
                        error_volume=abs(e - e_ref) / scale,
                        inverted_cells=int(np.count_nonzero(vols <= 0)) if vols is not None else 0)
                rec.update(measured[run_key])
            rec["error_u"] = rec["error_field"]
            out.append(rec)
    df = pd.DataFrame(out)
    df["pareto"] = False
    for cfg, g in df.groupby("config"):
        ok = g[g["at_rest"] & np.isfinite(g["error_u"]) & np.isfinite(g["time_s"])].sort_values(["time_s", "error_u"])
        best = np.inf
        for i, r in ok.iterrows():
            if r["error_u"] < best:
                df.loc[i, "pareto"] = True
                best = r["error_u"]
    return df, pd.DataFrame(refs)


def _digest(df: pd.DataFrame) -> tuple:
    """The values of ``df`` (its index included), exactly, as a hashable key."""
    return (tuple(df.columns), tuple(df.index),
            tuple((str(v.dtype), v.tobytes()) if v.dtype != object else tuple(map(repr, v)) for v in
                  (df[c].to_numpy() for c in df.columns)))


def budget_table(df: pd.DataFrame, budgets=BUDGETS, answers: dict | None = None) -> pd.DataFrame:
    """For each configuration, error measure (:data:`MEASURES`) and cost (:data:`COST_KINDS`): the
    budget answer of :func:`studies.sweep.cost.budget_answer` (the fastest method within each budget, its
    runner-up, the lead and whether it is a tie; the methods that meet no budget).  A method is a
    model with a solver, or a FEM element with its law; its cheapest resolution within a budget
    stands for it (``mesh``).  Static cost: ``time_s`` with ``time_spread``; explicit:
    ``cost_explicit_s`` (s per simulated second at the stable step) with ``explicit_spread``.
    ``answers``: the answers of earlier calls, kept by the caller and filled here, keyed by the
    rows each was made of (the driver's calls after repeats answer again only where a repeat
    changed a time)."""
    spreads = {"static": "time_spread", "explicit": "explicit_spread"}
    answers = {} if answers is None else answers
    out = []
    for cfg, g in df.groupby("config", sort=False):
        for kind, col in COST_KINDS.items():
            sub = g[g["kind"] == kind] if "kind" in g else g
            if sub.empty:
                continue
            for m in MEASURES:
                err = f"error_{m}"
                if err not in sub:
                    continue
                used = [c for c in ("method", "mesh", err, col, spreads[kind], "failure") if c in sub]
                key = (cfg, kind, m, tuple(budgets), _digest(sub[used]))
                if key not in answers:
                    a = cost.budget_answer(sub, budgets, error=err, cost=col, spread=spreads[kind], method="method",
                                           keep=("mesh",), failure="failure" if "failure" in sub else None)
                    # a lead beyond the noise is no tie, measured spread or not (:func:`near_ties`)
                    a.loc[a["tie"].isna() & (a["lead"] >= 1.0 + NOISE), "tie"] = False
                    answers[key] = a
                a = answers[key].copy()
                a.insert(0, "cost_kind", kind)
                a.insert(0, "measure", m)
                a.insert(0, "nu", g["nu"].iloc[0])
                a.insert(0, "config", cfg)
                a.insert(0, "experiment", g["experiment"].iloc[0])
                out.append(a)
    return pd.concat(out, ignore_index=True) if out else pd.DataFrame()


def near_ties(budget: pd.DataFrame, noise: float = NOISE) -> set[tuple[str, str, str]]:
    """(config, method, mesh) of every winner and runner-up of a budget answer whose lead is
    within the timing noise, ``lead < 1 + noise``: the candidates whose time needs repeats to tell
    them apart (their spreads then decide the tie, :func:`studies.sweep.cost.is_tie`)."""
    if budget.empty:
        return set()
    near = budget[(budget["answer"] == "fastest") & (budget["runner_up"] != "") & (budget["lead"] < 1.0 + noise)]
    return ({(r.config, r.method, r.mesh) for r in near.itertuples()}
            | {(r.config, r.runner_up, r.runner_up_mesh) for r in near.itertuples()})


def tasks(quick: bool = False) -> list[Task]:
    """The runs of :func:`run` with its defaults (``make reproduce-paper`` computes them in the
    sweep's one pool, so that :func:`run` finds them stored)."""
    return [t for _, t in all_tasks(quick)]


def run(store: Store, quick: bool = False, jobs: int | None = None, progress: bool = True, *,
        experiments=EXPERIMENTS, nus=None, level: str | None = None, runner=None) -> dict:
    """Study driver (``EXTRA_STUDIES``): writes ``pareto``, ``pareto_front``,
    ``pareto_references`` and ``budget``."""
    pairs = all_tasks(quick, experiments, nus, level)
    rows = run_tasks([t for _, t in pairs], store, jobs=jobs, progress=progress, desc="pareto",
                     runner=runner, expected=expected_finding)
    lv, timed, measured, answers = level_name(quick, level), set(), {}, {}
    frames = unlimited_frames(pairs, runner)
    while True:  # repeats only where two candidates are within noise (a new best may make a new pair)
        df, refs = pareto_frame(store, pairs, rows, quick, frames, measured)
        budget = budget_table(df, answers=answers)
        want = near_ties(budget) - timed
        if not want:
            break
        extra = [p for m, t in pairs if m["role"] == "candidate" and (m["config"], m["method"], m["mesh"]) in want
                 for p in repeat_pairs(m, t, lv)]
        timed |= want
        rows += run_tasks([t for _, t in extra], store, jobs=jobs, progress=progress, desc="pareto repeats",
                          runner=runner, expected=expected_finding)
        pairs += extra
    tables = {"pareto": df, "pareto_front": df[df["pareto"]].sort_values(["config", "time_s"]),
              "pareto_references": refs, "budget": budget}
    for name, t in tables.items():
        store.write_table(name, t)
    return tables
