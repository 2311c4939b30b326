"""Numerical stability on hard cases (issue "speed against error ... stability").

Six parts, each a table in the results store:

(a) ``dt_stability``: for ν ∈ {−0.9, −0.5, 0.45, 0.49, 0.499, 0.4999} and each variant, the
    explicit limit ``dt_crit = 2/√λmax(M⁻¹K)`` (:func:`hybmss.explicit.dt_crit`) against the
    largest dt that runs 10,000 steps of the compression scene (5 %, plates ramped over 1 s)
    without :class:`~hybmss.explicit.DivergenceError`, found by bisection to 1 % between
    ``½ dt_crit`` (must pass) and ``1.5 dt_crit`` (must fail).  Undamped (c = 0), as dt_crit is
    defined; with the implicit mass-proportional damping c the limit of one mode becomes
    ``ω dt < 2 √(1 + c dt/2)`` (derived from the step's 2×2 amplification matrix, trace
    ``1 + d − d ω² dt²``, determinant ``d = 1/(1 + c dt)``).  A model with no explicit limit
    (``explicit_limit`` False: xpbd-nh's implicit constraint solve) runs once at
    :data:`UNLIMITED_FACTOR` dt_crit for the same simulated time instead.
(b), (c) ``stability_extreme``: static Newton and the publication's explicit protocol (1 ms × 10,000
    steps, c = 2 s⁻¹, ramp 1 s) at 20 % and 50 % compression, 45° and 90° torsion, 50 % shear,
    ν ∈ {0, ¼, 0.499}, each variant, on a small cube; the status (converged, diverged,
    unstable = static equilibrium lost, error), the count of inverted cells (V' ≤ 0) of the final
    state, and the relative L2 nodal difference against the FEM (Neo-Hookean, Hex2, mixed u–p at
    ν ≥ 0.45, same mesh) where the FEM converges.
(d) ``limit_stretch``: tension of the beam at ν ∈ {0, −0.5}: the static solver is asked for 100 %
    stretch and stops where the equilibrium is lost (its :class:`StaticSolveError` fields give
    the last converged load factor and the smallest eigenvalue of the constrained Hessian there
    and beyond); the stretch at the loss lies between ``1 + s_last`` and ``1 + s_fail``.  For each
    variant, with the quadratic volume energy and with the ``squared`` alternative; plus whether
    the publication's 20 % tension at ν = 0 is reached (static and explicit protocol).
(e) ``stability_irregular``: irregular input — a lattice whose particles are jittered by 10 % of
    le at rest (uniform in each component, seeded; particles on the plates keep their z so the
    plates still select them), an L-shaped voxel body, a single cell, a one-cell-thick wall;
    5 % compression (the single cell: top sliding down, free sideways); cube 4³, L 4×3×4 minus a
    quadrant, wall 6×1×6.  The explicit protocol runs the jittered lattice on the NumPy twin (the
    stencil kernel needs regular rest lengths), for hybmss only, and the tiny bodies of the
    spring and volume lattice too (:data:`TINY_LATTICE_NODES`).  The jittered lattice
    is built with :func:`jittered_system` from the public :func:`hybmss.system.build`
    (``lattice=`` argument): rest lengths and rest volumes are those of the jittered positions,
    so the jittered body is at rest; its FEM reference is the regular body (the continuum the
    jittered lattice discretizes), compared particle by particle.
(f) ``damping_steps``: how many steps of the publication's protocol (c = 2 s⁻¹) bring the
    compression (5 %) of the 10³ cube within 0.1 % (relative L2 of the nodal displacement) of
    the static equilibrium, at each ν: explicit runs of increasing length (a grid of step counts;
    a run cut before rest is the protocol's state at that step and is measured as such), and the
    step where the error crosses the tolerance for good, interpolated log-linearly between the
    two checkpoints that bracket it (:func:`tolerance_crossing`).

(g) ``stability_engines``: the engines of the publication tables (the models of the ``tables``
    role with meshes of their own, :attr:`studies.sweep.roles.Part.meshes`) on their own coarse cube
    (:func:`studies.sweep.roles.mesh_for`; 2³ in the quick mode) at the hard cases of the publication's
    sweep: ν = 0.499 at 5 % and 20 %, and ν = ¼ at 20 %, compression and shear (quick: ν = 0.499 at
    20 % only).  Each engine's static answer is the rest state of its own damped run; per row the
    ``behaviour``: ``rest`` (its run reached rest, the rest criterion of every explicit model,
    :func:`hybmss.explicit.rest_report`), ``locks`` (at rest, but its plate force more than
    :data:`LOCK_RATIO` times the FEM's on the same mesh: volumetric locking of its elements),
    ``no rest`` (not at rest within its time budget), ``diverged``, or the refusal of a scene it
    cannot represent; its engine steps, wall time and plate force (compression F_z, shear F_x)
    against the FEM on the same mesh (linear at 5 %, Neo-Hookean at 20 %, mixed u–p at ν ≥ 0.45).
    In the full reproduction these are runs of the experiment tables (the same keys, stored
    once), so the part costs nothing of its own there; on the quick 2³ cube its ten runs take
    a few seconds together (the table's ``wall_time_s``, the solve's, and ``elapsed_s``, the run's with
    its build: 0.15–0.7 s a run at load average 5 on 2 cores, the two that did not come to rest
    included; newton-semi's first run in a process 11 s, Warp's import and kernels).

``stability`` is the extreme and irregular tables together.  Runs of (b)–(d) and (f) go through
:func:`studies.sweep.runner.run_tasks` (cached, parallel); (a) and (e)
call the solvers directly (bisection and custom systems).
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import pandas as pd

from hybmss import models
from hybmss.experiments import SceneSpec
from hybmss.scene import Material

from studies.sweep import roles
from studies.sweep.compare import diff_metrics
from studies.sweep.outcomes import expected_finding
from studies.sweep.runner import SolverSpec, Task, failure_row, run_tasks
from studies.sweep.store import Store

def stability_models() -> tuple[str, ...]:
    """The models of the stability study (registry order; the first is the reference model)."""
    return roles.in_role("stability")
NU_DT = (-0.9, -0.5, 0.45, 0.49, 0.499, 0.4999)
UNLIMITED_FACTOR = 20.0
"""A model with no explicit stability limit runs once at this many dt_crit (for the simulated time
of the protocol's steps at dt_crit) instead of the bisection."""
NU_EXTREME = (0.0, 0.25, 0.499)
NU_LIMIT = (0.0, -0.5)
DAMPING = 2.0
PROTOCOL = SolverSpec("explicit", dt=1e-3, steps=10_000, ramp_time=1.0)
STATIC = SolverSpec("static")
EXTREME_CASES = (
    ("compression", dict(deformation=0.20)),
    ("compression", dict(deformation=0.50)),
    ("torsion", dict(angle_deg=45.0)),
    ("torsion", dict(angle_deg=90.0)),
    ("shear", dict(deformation=0.50)),
)
DAMPING_TOL = 1e-3
DAMPING_GRID = (1000, 1500, 2000, 3000, 4000, 5000, 6000, 7000, 8000, 10_000, 12_000, 15_000, 20_000,
                30_000)


def _status(row: dict, inverted: int) -> str:
    if row.get("status") != "ok":
        return row.get("status", "error")
    return "inverted" if inverted > 0 else "converged"


def _inverted(store: Store, row: dict) -> int:
    if row.get("status") != "ok":
        return 0
    if "inverted_cells" in row and row["inverted_cells"] is not None and not (
            isinstance(row["inverted_cells"], float) and math.isnan(row["inverted_cells"])):
        return int(row["inverted_cells"])
    vols = store.arrays(row["key"]).get("cell_volumes")
    return int(np.count_nonzero(vols <= 0.0)) if vols is not None else 0


# ------------------------------------------------------------------------------ (a) dt
def bisect_dt(scene, steps: int = 10_000, rel_tol: float = 0.01, lo_factor: float = 0.5,
              hi_factor: float = 1.5, ramp_time: float = 1.0) -> dict:
    """dt_crit of ``scene`` and the largest dt (to ``rel_tol``) that runs ``steps`` steps."""
    from hybmss.explicit import DivergenceError, dt_crit, simulate_explicit
    from hybmss.system import build

    S = build(scene)
    dc = dt_crit(S)
    trials = []

    def runs(dt):
        try:
            simulate_explicit(scene, dt=dt, steps=steps, ramp_time=ramp_time, system=S,
                              dt_crit_value=dc, check_every=20)
            ok = True
        except DivergenceError:
            ok = False
        trials.append((dt, ok))
        return ok

    lo, hi = lo_factor * dc, hi_factor * dc
    out = {"kappa": S.kappa, "dt_crit": dc}
    if not models.get(scene.model.name).explicit_limit:
        # stable at any step (its substeps follow the accuracy rule, so a frame of k dt_crit costs k
        # times the substeps: a bisection towards a limit that does not exist would cost hours on 4³);
        # one run of the same simulated time at UNLIMITED_FACTOR dt_crit shows it
        big = UNLIMITED_FACTOR * dc
        try:
            simulate_explicit(scene, dt=big, steps=max(1, steps // int(UNLIMITED_FACTOR)), ramp_time=ramp_time,
                              system=S, dt_crit_value=dc, check_every=20)
            out.update(dt_stable=big, dt_unstable=float("nan"),
                       note=f"no stability limit: stable at {UNLIMITED_FACTOR:g} dt_crit (implicit constraint solve)")
        except DivergenceError:
            out.update(dt_stable=float("nan"), dt_unstable=big, note=f"diverges at {UNLIMITED_FACTOR:g} dt_crit")
        out["ratio"] = out["dt_stable"] / dc
        out["trials"] = 1
        return out
    if not runs(lo):
        out.update(dt_stable=float("nan"), dt_unstable=lo, note=f"diverges at {lo_factor} dt_crit")
    else:
        while runs(hi):
            lo, hi = hi, 2 * hi
            if hi > 20 * dc:
                break
        while hi - lo > rel_tol * dc:
            mid = 0.5 * (lo + hi)
            if runs(mid):
                lo = mid
            else:
                hi = mid
        out.update(dt_stable=lo, dt_unstable=hi, note="")
    out["ratio"] = out["dt_stable"] / dc
    out["trials"] = len(trials)
    return out


def _dt_row(job: tuple) -> dict:
    nu, model, mesh, steps = job
    spec = SceneSpec.default("compression", mesh=mesh, nu=nu, model=model, deformation=0.05)
    t0 = time.perf_counter()
    r = bisect_dt(spec.build(), steps=steps)
    return {"nu": nu, "variant": model, "mesh": "x".join(map(str, mesh)), "steps": steps, **r,
            "elapsed_s": time.perf_counter() - t0}


def dt_table(quick: bool = False, nus=NU_DT, variants=None, steps: int | None = None,
             workers: int | None = None, store: Store | None = None, runner=None) -> pd.DataFrame:
    """Part (a): one bisection per ν and variant, ``workers`` processes at a time (each is
    deterministic: the table does not depend on how they are spread), each kept in ``store``
    when one is given (:func:`studies.sweep.executors.map_stored`: a rerun computes only the missing;
    ``runner``: whose session's workers compute)."""
    from studies.sweep.executors import map_stored

    return pd.DataFrame(map_stored(store, "dt_stability", _dt_row, dt_jobs(quick, nus, variants, steps), workers,
                                   runner))


def dt_jobs(quick: bool = False, nus=NU_DT, variants=None, steps: int | None = None) -> list[tuple]:
    """The bisections of :func:`dt_table`: (ν, model, mesh, steps)."""
    mesh = (2, 2, 2) if quick else (4, 4, 4)
    steps = steps or (2000 if quick else 10_000)
    return [(nu, model, mesh, steps) for nu in nus for model in (variants if variants is not None else stability_models())]


# ------------------------------------------------------------------------------ (b, c) extreme
def _cube(quick: bool):
    return (3, 3, 3) if quick else (6, 6, 6)


def extreme_tasks(quick: bool = False, mesh=None) -> list[tuple[str, Task]]:
    mesh = tuple(mesh) if mesh is not None else _cube(quick)
    out = []
    cases = EXTREME_CASES[:3] if quick else EXTREME_CASES
    nus = (0.0, 0.499) if quick else NU_EXTREME
    for exp, kw in cases:
        for nu in nus:
            base = SceneSpec.default(exp, mesh=mesh, nu=nu, **kw)
            for model in stability_models():
                s = base.replace(model=model)
                out.append(("c", Task(s, STATIC, "stability")))
                out.append(("c", Task(s.replace(damping=DAMPING), PROTOCOL, "stability")))
            out.append(("fem", Task(base, SolverSpec("fem", element="auto", law="neo-hookean"), "stability")))
    return out


def _case_name(spec: SceneSpec) -> str:
    if spec.experiment == "torsion":
        return f"torsion {spec.angle_deg:g}°"
    return f"{spec.experiment} {100 * spec.deformation:g}%"


def extreme_table(store: Store, tasks: list[tuple[str, Task]], rows: list[dict]) -> pd.DataFrame:
    fem = {}
    for (kind, t), r in zip(tasks, rows):
        if kind == "fem":
            fem[(_case_name(t.scene), t.scene.nu)] = r
    out = []
    for (kind, t), r in zip(tasks, rows):
        if kind == "fem":
            continue
        inv = _inverted(store, r)
        f = fem.get((_case_name(t.scene), t.scene.nu))
        err = float("nan")
        if f is not None and f["status"] == "ok" and r["status"] == "ok":
            a, b = store.arrays(r["key"]), store.arrays(f["key"])
            err = diff_metrics(a["X"], a["u"], b["u"])["rel_l2"]
        out.append({
            "part": "b" if t.scene.experiment == "compression" else "c",
            "case": _case_name(t.scene), "mesh": "x".join(map(str, t.scene.mesh)), "nu": t.scene.nu,
            "variant": t.scene.variant, "solver": t.solver.label, "status": _status(r, inv),
            "inverted_cells": inv,
            "volume_change": r.get("volume_change", float("nan")) if r["status"] == "ok" else float("nan"),
            "load_steps": r.get("load_steps", float("nan")), "iterations": r.get("solver_iterations", float("nan")),
            "wall_time_s": r.get("wall_time_s", float("nan")),
            "fem": f["solver"] if f is not None else "", "fem_status": f["status"] if f is not None else "",
            "rel_l2_vs_fem": err, "message": r.get("message", ""),
        })
    return pd.DataFrame(out)


# ------------------------------------------------------------------------------ (g) engines
LOCK_RATIO = 1.5
"""An engine at rest whose plate force exceeds the same-mesh FEM's by more than this factor locks."""
ENGINE_CASES = (("compression", 0.499, 0.05), ("compression", 0.25, 0.20), ("compression", 0.499, 0.20),
                ("shear", 0.499, 0.05), ("shear", 0.25, 0.20), ("shear", 0.499, 0.20))
"""(experiment, ν, d) of part (g); the quick mode runs those at ν = 0.499 and 20 %."""
ENGINE_QUICK_CUBE = (2, 2, 2)
ENGINE_FORCE = {"compression": "force_z", "shear": "force_x"}


def engine_models() -> tuple[str, ...]:
    """The engines of part (g): the models of the ``tables`` role with meshes of their own."""
    return tuple(m for m in roles.in_role("tables") if roles.part(m).meshes)


def engine_tasks(quick: bool = False) -> list[tuple[str, Task]]:
    """Part (g)'s runs: each engine's static answer on its own cube, then the FEM of that mesh."""
    from studies.sweep.compare import default_law

    out, seen = [], set()
    cases = [c for c in ENGINE_CASES if not quick or (c[1] == 0.499 and c[2] == 0.20)]
    for exp, nu, d in cases:
        base = SceneSpec.default(exp, nu=nu, deformation=d)
        for model in engine_models():
            spec = base.replace(mesh=ENGINE_QUICK_CUBE) if quick else roles.mesh_for(model, base)
            out.append(("engine", Task(spec.replace(model=model), STATIC, "stability")))
            fem = ("fem", Task(spec, SolverSpec("fem", element="auto", law=default_law(spec)), "stability"))
            if (spec.experiment, spec.mesh, spec.nu, spec.deformation) not in seen:
                seen.add((spec.experiment, spec.mesh, spec.nu, spec.deformation))
                out.append(fem)
    return out


def engine_behaviour(row: dict, ratio: float | None) -> str:
    """``rest``, ``locks``, ``no rest``, ``diverged`` or the run's failure status (part (g))."""
    if row.get("status") == "ok":
        return "locks" if ratio is not None and abs(ratio) > LOCK_RATIO else "rest"
    msg = str(row.get("message") or "")
    if "did not come to rest" in msg:
        return "no rest"
    if "diverged" in msg or row.get("status") == "diverged":
        return "diverged"
    return str(row.get("status") or "error")


def engine_table(tasks: list[tuple[str, Task]], rows: list[dict]) -> pd.DataFrame:
    """Part (g)'s table: one row per engine and case (module docstring)."""
    def where(t):
        return (t.scene.experiment, t.scene.mesh, float(t.scene.nu), float(t.scene.deformation))

    fem = {where(t): r for (kind, t), r in zip(tasks, rows) if kind == "fem"}
    out = []
    for (kind, t), r in zip(tasks, rows):
        if kind == "fem":
            continue
        f = fem.get(where(t), {})
        col = ENGINE_FORCE[t.scene.experiment]
        ok = r.get("status") == "ok"
        F = r.get(col) if ok else None
        Ff = f.get(col) if f.get("status") == "ok" else None
        good = F is not None and Ff is not None and math.isfinite(F) and math.isfinite(Ff) and Ff != 0
        ratio = F / Ff if good else None
        out.append({
            "case": _case_name(t.scene), "experiment": t.scene.experiment, "mesh": "x".join(map(str, t.scene.mesh)),
            "nu": float(t.scene.nu), "deformation": float(t.scene.deformation), "model": t.scene.model,
            "behaviour": engine_behaviour(r, ratio), "status": r.get("status"),
            "steps": r.get("solver_iterations") if ok else None, "wall_time_s": r.get("wall_time_s"),
            "elapsed_s": r.get("elapsed_s"),
            "force_N": F, "force_fem_N": Ff, "force_ratio": ratio,
            "force_rel_error": (ratio - 1.0) if ratio is not None else None,
            "fem": f.get("solver", ""), "fem_status": f.get("status", "missing"),
            "message": None if ok else r.get("message"),
        })
    return pd.DataFrame(out)


# ------------------------------------------------------------------------------ (d) limit stretch
def failure_numbers(row: dict) -> dict:
    """Load factors and eigenvalues of a run that lost its equilibrium, from the fields of its
    :class:`hybmss.solve.StaticSolveError` (a row's ``failure_*`` fields,
    :func:`studies.sweep.runner.failure_row`; NaN where absent)."""

    def num(name):
        v = row.get(f"failure_{name}")
        return float("nan") if v is None else float(v)

    return {"s_last": num("load_factor"), "s_fail": num("next_load_factor"), "lambda_min": num("smallest_eigenvalue"),
            "lambda_min_next": num("next_smallest_eigenvalue")}


D_MAX = 1.0


def volume_forms(model: str, nu: float) -> tuple:
    """The volume-energy forms a model is compared in at ν: both where it has a volume term with
    a choice of form, else its only one (``None``: no such parameter)."""
    spec = models.get(model)
    if "volume_energy" not in spec.parameter_names():
        return (None,)
    kappa = spec.constants(spec.parameters(), Material(1e4, nu), 1.0).kappa
    return ("quadratic", "squared") if kappa != 0.0 else ("quadratic",)


def limit_tasks(quick: bool = False) -> list[tuple[tuple, Task]]:
    mesh = (2, 2, 12) if quick else (4, 4, 24)
    out = []
    for nu in NU_LIMIT:
        for model in stability_models():
            for ve in volume_forms(model, nu):
                base = SceneSpec.default("tension", mesh=mesh, nu=nu, model=model, volume_energy=ve)
                out.append((("limit", nu, model, ve), Task(base.replace(deformation=D_MAX), STATIC, "stability")))
                if nu == 0.0:
                    s20 = base.replace(deformation=0.20)
                    out.append((("static20", nu, model, ve), Task(s20, STATIC, "stability")))
                    out.append((("explicit20", nu, model, ve),
                                Task(s20.replace(damping=DAMPING), PROTOCOL, "stability")))
    return out


def limit_table(store: Store, tasks, rows) -> pd.DataFrame:
    by = {}
    for (what, nu, model, ve), r in zip([k for k, _ in tasks], rows):
        by.setdefault((nu, model, ve), {})[what] = r
    out = []
    for (nu, model, ve), d in by.items():
        r = d["limit"]
        p = failure_numbers(r)
        reached = r["status"] == "ok"
        spec = models.get(model)
        row = {"nu": nu, "variant": model, "volume_energy": ve, "d_max": D_MAX, "status": r["status"],
               # whether the model has a volume term at this ν (κ ≠ 0), as its calibration says
               "volume_term": spec.constants(spec.parameters(), Material(1e4, nu), 1.0).kappa != 0.0,
               **p,
               "stretch_lo": 1.0 + D_MAX * (1.0 if reached else p["s_last"]),
               "stretch_hi": float("nan") if reached else 1.0 + D_MAX * p["s_fail"],
               "volume_change_at_end": r.get("volume_change", float("nan")) if reached else float("nan"),
               "message": r.get("message", "")}
        for what in ("static20", "explicit20"):
            if what in d:
                inv = _inverted(store, d[what])
                row[f"{what}_status"] = _status(d[what], inv)
                # a run that reached no result (not at rest, failed) shows its status, not a value
                row[f"{what}_volume_change"] = (d[what].get("volume_change", float("nan"))
                                                if d[what].get("status") == "ok" else float("nan"))
                row[f"{what}_message"] = d[what].get("message", "")
        out.append(row)
    return pd.DataFrame(out)


# ------------------------------------------------------------------------------ (e) irregular
def jittered_system(scene, fraction: float = 0.1, seed: int = 0, keep_axis: int = 2):
    """:class:`hybmss.system.System` of ``scene`` whose particles sit at rest at the lattice
    positions plus a uniform jitter in ``[−fraction·le, fraction·le]`` per component (``seed``).
    Particles on the faces normal to ``keep_axis`` keep that coordinate, so face regions (plates)
    still select them.  Rest lengths and volumes are those of the jittered positions."""
    from hybmss.lattice import Lattice
    from hybmss.system import build

    lat = Lattice.from_body(scene.body)
    rng = np.random.default_rng(seed)
    d = rng.uniform(-fraction, fraction, size=lat.X.shape) * scene.body.le
    g = lat.grid[:, keep_axis]
    on_face = (g == 0) | (g == scene.body.shape[keep_axis])
    d[on_face, keep_axis] = 0.0
    jittered = dataclasses.replace(lat, X=lat.X + d)
    return build(scene, lattice=jittered)


def irregular_scenes(quick: bool = False, nu: float = 0.25, model: str | None = None) -> dict:
    """Name → (scene, builder of its system or None, FEM scene); ``model`` None: the registry's
    default model."""
    from hybmss.scene import Body, Material, Model, Motion, Plate, Region, Scene

    mat = Material(1e4, nu, 1000.0)
    mdl = Model(model)
    model = mdl.name
    n = 3 if quick else 4
    out = {}
    cube = SceneSpec.default("compression", mesh=(n, n, n), nu=nu, model=model).build()
    out["jittered 10% le"] = (cube, lambda sc: jittered_system(sc, 0.1, seed=0), cube)
    mask = np.ones((n, 2 if quick else 3, n), dtype=bool)
    mask[n // 2:, :, n // 2:] = False  # L in the x-z plane: the top half of one leg removed
    body = Body.from_mask(mask, 5.0 / n)
    H = body.size[2]
    lshape = Scene(body, mat, mdl, (Plate("bottom", Region("z-"), Motion("clamped")),
                                    Plate("top", Region("z+"), Motion("translate", (0, 0, -0.05 * H)))),
                   name="L-shape compression 5%")
    out["L-shape"] = (lshape, None, lshape)
    cell = Scene(Body.box(1, 1, 1, 1.0), mat, mdl,
                 (Plate("bottom", Region("z-"), Motion("clamped")),
                  Plate("top", Region("z+"), Motion("slide", (0, 0, -0.05), components=(2,)))),
                 name="single cell, top sliding 5%")
    out["single cell"] = (cell, None, cell)
    wall = Body.box(n + 2, 1, n + 2, 5.0 / n)
    Hw = wall.size[2]
    plate = Scene(wall, mat, mdl, (Plate("bottom", Region("z-"), Motion("clamped")),
                                   Plate("top", Region("z+"), Motion("translate", (0, 0, -0.05 * Hw)))),
                  name="one-cell-thick wall compression 5%")
    out["one-cell-thick wall"] = (plate, None, plate)
    return out


def irregular_table(quick: bool = False, workers: int | None = None, store: Store | None = None,
                    runner=None) -> pd.DataFrame:
    """Part (e): the rows of each ν computed ``workers`` processes at a time, kept in ``store``
    when one is given (as in :func:`dt_table`)."""
    from studies.sweep.executors import map_stored

    parts = map_stored(store, "stability_irregular", _irregular_rows, irregular_jobs(quick), workers, runner)
    return pd.DataFrame([r for rows in parts for r in rows])


def irregular_jobs(quick: bool = False) -> list[tuple]:
    """The jobs of :func:`irregular_table`: (quick, ν)."""
    return [(quick, nu) for nu in ((0.0, 0.499) if quick else NU_EXTREME)]


TINY_LATTICE_NODES = 200
"""Part (e)'s explicit runs of the harness's spring and volume lattice (hybmss, hybmss-fd,
hybmss-cf) with at most this many particles (the single cell, the L-shape, the wall: 8–100) take
the NumPy twin of the stencil kernel.  The stencil kernel is generated and compiled for each
lattice size and set of terms (2.1–3.9 s each, cold), while its 10,000 steps of these lattices
take 0.02–0.08 s; the twin takes 0.8 s, with the same answers to rounding (largest displacement
difference 1e-14 m, volume changes equal to 6 digits).  Each ν is a process of its own, so the
compiled kernels were compiled again by each.  The other models' Numba kernels do not depend on
the lattice's size (compiled once), and their NumPy twins are slow (xpbd-nh: 65 s on the wall)."""


def irregular_kernel(scene, builder) -> str:
    """The explicit kernel of a part (e) run: the NumPy twin for a jittered lattice (no stencil)
    or a tiny lattice of the harness's stepper (:data:`TINY_LATTICE_NODES`), else Numba."""
    from hybmss.models.hybmss.stepper import LatticeStepper
    from hybmss.system import build

    if builder is not None:
        return "numpy"
    S = build(scene)
    if S.n > TINY_LATTICE_NODES:
        return "numba"
    own = models.get(scene.model.name).stepper(S, PROTOCOL.dt, ramp_time=PROTOCOL.ramp_time, kernel="numpy")
    return "numpy" if own is None or isinstance(own, LatticeStepper) else "numba"


def _irregular_rows(job: tuple) -> list[dict]:
    """The rows of part (e) at one ν (``job``: (quick, ν))."""
    from fem_reference.solve import solve as fem_solve
    from hybmss.explicit import simulate_explicit
    from hybmss.solve import solve_static

    quick, nu = job
    rows = []
    steps = 2000 if quick else PROTOCOL.steps
    fem_cache = {}
    for model in stability_models():
        for name, (scene, builder, fem_scene) in irregular_scenes(quick, nu, model).items():
            if name not in fem_cache:
                try:
                    fem_cache[name] = (fem_solve(fem_scene, element="auto",
                                                 law="linear"), "ok", "")
                except Exception as exc:  # noqa: BLE001 - reported as a row
                    fem_cache[name] = (None, "error", f"{type(exc).__name__}: {exc}")
            fem, fem_status, _ = fem_cache[name]
            S = builder(scene) if builder is not None else None
            for solver in ("mss-static", "mss-explicit"):
                if solver == "mss-explicit" and builder is not None and model != stability_models()[0]:
                    continue  # the jittered lattice runs on the (slow) NumPy twin: reference model only
                t0 = time.perf_counter()
                row = {"part": "e", "case": name, "mesh": "x".join(map(str, scene.body.shape)), "nu": nu,
                       "variant": model, "solver": solver, "fem": fem.solver if fem else "",
                       "fem_status": fem_status}
                try:
                    if solver == "mss-static":
                        res = solve_static(scene, system=S)
                    else:
                        sc = dataclasses.replace(scene, damping=DAMPING)
                        Sx = builder(sc) if builder is not None else None
                        res = simulate_explicit(sc, dt=PROTOCOL.dt, steps=steps, ramp_time=1.0, system=Sx,
                                                kernel=irregular_kernel(sc, builder))
                    inv = int(np.count_nonzero(res.cell_volumes <= 0.0))
                    row.update(status="inverted" if inv else "converged", inverted_cells=inv,
                               volume_change=res.volume_change, iterations=res.iterations,
                               wall_time_s=res.wall_time_s, message="",
                               rel_l2_vs_fem=diff_metrics(res.X, res.u, fem.u)["rel_l2"] if fem else np.nan)
                    if "load_steps" in res.info:
                        row["load_steps"] = res.info["load_steps"]
                except Exception as exc:  # noqa: BLE001 - reported as a row
                    failed = failure_row(exc)  # the table keeps its columns: status and message
                    row.update(status=failed["status"], message=failed["message"], inverted_cells=0,
                               rel_l2_vs_fem=np.nan)
                row["elapsed_s"] = time.perf_counter() - t0
                rows.append(row)
    return rows


# ------------------------------------------------------------------------------ (f) damping
def damping_tasks(quick: bool = False, mesh=None) -> list[tuple[tuple, Task]]:
    mesh = tuple(mesh) if mesh is not None else ((3, 3, 3) if quick else (10, 10, 10))
    grid = (1000, 2000, 4000) if quick else DAMPING_GRID
    out = []
    for nu in NU_EXTREME:
        spec = SceneSpec.default("compression", mesh=mesh, nu=nu, deformation=0.05)
        out.append((("static", nu, 0), Task(spec, STATIC, "stability")))
        for n in grid:
            out.append((("explicit", nu, n), Task(spec.replace(damping=DAMPING),
                                                  dataclasses.replace(PROTOCOL, steps=n), "stability")))
    return out


def checkpoint_error(store: Store, row: dict, u_ref: np.ndarray) -> float:
    """Relative L2 distance of an explicit run's state after its steps from the static equilibrium:
    measured whether or not the run came to rest (a run cut at n steps is the protocol's state at
    step n); NaN for a run without a finite state (diverged, failed)."""
    if row["status"] not in ("ok", "not-converged"):
        return float("nan")
    u = store.arrays(row["key"]).get("u")
    if u is None or not np.all(np.isfinite(u)):
        return float("nan")
    return float(np.linalg.norm(u - u_ref) / np.linalg.norm(u_ref))


def tolerance_crossing(ns: np.ndarray, es: np.ndarray, tol: float) -> tuple[str, str]:
    """(steps at which the error falls below ``tol`` and stays there, the checkpoints that bracket
    it): interpolated log-linearly between the last checkpoint above ``tol`` and the first of the
    checkpoints that stay within it (the damped error decays exponentially); "≤ n" if the first
    checkpoint is within, "> n" if the last is not."""
    within = es <= tol
    first = next((i for i in range(len(ns)) if within[i:].all()), None)
    if first is None:
        return f"> {int(ns.max())}", ""
    if first == 0:
        return f"≤ {int(ns[0])}", f"≤ {int(ns[0])}"
    n1, n2, e1, e2 = ns[first - 1], ns[first], es[first - 1], es[first]
    if not (np.isfinite(e1) and e1 > 0 and e2 > 0):
        return str(int(n2)), f"{int(n1)}–{int(n2)}"
    n = n1 + (np.log(tol) - np.log(e1)) / (np.log(e2) - np.log(e1)) * (n2 - n1)
    return str(int(np.ceil(min(max(n, n1), n2)))), f"{int(n1)}–{int(n2)}"


def damping_table(store: Store, tasks, rows, tol: float = DAMPING_TOL) -> pd.DataFrame:
    by = {}
    for (kind, nu, n), r in zip([k for k, _ in tasks], rows):
        by.setdefault(nu, {})[(kind, n)] = r
    out = []
    for nu, d in by.items():
        st = d[("static", 0)]
        if st["status"] != "ok":
            out.append({"nu": nu, "status": "static failed", "message": st.get("message", "")})
            continue
        u_ref = store.arrays(st["key"])["u"]
        errs = [(n, checkpoint_error(store, r, u_ref))
                for (kind, n), r in sorted((k, v) for k, v in d.items() if k[0] == "explicit")]
        ns = np.array([e[0] for e in errs])
        es = np.array([e[1] for e in errs])
        steps, bracket = tolerance_crossing(ns, es, tol)
        at10k = dict(errs).get(10_000, float("nan"))
        out.append({"nu": nu, "damping": DAMPING, "dt": PROTOCOL.dt, "tol": tol,
                    "steps_to_tol": steps, "crossing_between": bracket,
                    "error_at_10000": at10k, "error_at_last": float(es[-1]), "last_steps": int(ns[-1]),
                    "errors": "; ".join(f"{n}:{e:.2e}" for n, e in errs), "status": "ok"})
    return pd.DataFrame(out)


# ------------------------------------------------------------------------------ driver
def _combined(store: Store) -> pd.DataFrame:
    """``stability``: the extreme (b, c) and irregular (e) tables, whichever exist."""
    parts = [pd.read_csv(store.root / "tables" / f"{n}.csv") for n in ("stability_extreme", "stability_irregular")
             if (store.root / "tables" / f"{n}.csv").exists()]
    df = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()
    store.write_table("stability", df)
    return df


def tasks(quick: bool = False) -> list[Task]:
    """The pooled runs of :func:`run` with its defaults (parts d, f, c; ``make reproduce-paper``
    computes them in the sweep's one pool, so that :func:`run` finds them stored)."""
    return [t for part in (limit_tasks(quick), damping_tasks(quick), extreme_tasks(quick), engine_tasks(quick))
            for _, t in part]


def calls(quick: bool = False) -> list:
    """The computations of :func:`run`'s parts (e) and (a) with its defaults, as the sweep's calls
    (:class:`studies.sweep.executors.Call`), which :func:`run` then finds stored."""
    from studies.sweep.executors import Call

    return ([Call("stability_irregular", _irregular_rows, job) for job in irregular_jobs(quick)]
            + [Call("dt_stability", _dt_row, job) for job in dt_jobs(quick)])


def run(store: Store, quick: bool = False, jobs: int | None = None, progress: bool = True, *,
        parts: str = "adfceg", damping_mesh=None, extreme_mesh=None, runner=None) -> dict:
    """Study driver (``EXTRA_STUDIES``): writes ``dt_stability`` (a), ``limit_stretch`` (d),
    ``damping_steps`` (f), ``stability_extreme`` (b, c), ``stability_irregular`` (e) and
    ``stability_engines`` (g), each as
    soon as its part is done, and ``stability``, the last two together.
    ``parts`` selects and orders the parts; ``damping_mesh`` replaces the 10³ cube of (f),
    ``extreme_mesh`` the 6³ cube of (b, c)."""
    pooled = {  # part: (its tasks, the table of their rows, the table's name, the progress bar's label)
        "d": (lambda: limit_tasks(quick), limit_table, "limit_stretch", "stability limit"),
        "f": (lambda: damping_tasks(quick, damping_mesh), damping_table, "damping_steps", "stability damping"),
        "c": (lambda: extreme_tasks(quick, extreme_mesh), extreme_table, "stability_extreme", "stability extreme"),
        "g": (lambda: engine_tasks(quick), lambda _store, ts, rows: engine_table(ts, rows), "stability_engines",
              "stability engines"),
    }
    tables = {}
    for part in parts:
        if part in pooled:
            make, table, name, desc = pooled[part]
            ts = make()
            rows = run_tasks([t for _, t in ts], store, jobs=jobs, progress=progress, desc=desc, runner=runner,
                             expected=expected_finding)
            tables[name] = table(store, ts, rows)
            store.write_table(name, tables[name])
        elif part == "a":
            tables["dt_stability"] = dt_table(quick, workers=jobs, store=store, runner=runner)
            store.write_table("dt_stability", tables["dt_stability"])
        elif part == "e":
            tables["stability_irregular"] = irregular_table(quick, workers=jobs, store=store, runner=runner)
            store.write_table("stability_irregular", tables["stability_irregular"])
        if part in "ce":
            tables["stability"] = _combined(store)
    return tables
