"""Released transients of the [G20] cube and beam: every model's own integrator against the FEM's.

The bodies (:data:`BODIES`): the compression experiment's cube (5 m, clamped at z = 0 and held by its
top plate at rest) under a lateral gravity ``g_c`` along −y, which it sags in shear; the bending
experiment's cantilever (0.4 × 0.4 × 2.4 m, clamped at z = 0) under gravity ``g_b`` along −y.  The
gravities are those of a static deflection near 10⁻³ of the body's size (the cube's largest
displacement 5.1 mm, the beam's tip 3.1 mm at ν = 0.25): small motions, where the linear FEM is the
reference of every model.  Each at ν ∈ {0, 0.25, 0.45, 0.499} (E, ρ of its experiment).

Equations (:mod:`hybmss.released`, :mod:`fem_reference.transient`): each model's nodes obey
``m ẍ = f(x)`` from its own static answer under the load, the load removed at t = 0, stepped by its
own integrator at the step a user would pick (:func:`hybmss.released.user_step`: 0.9 of the
model's stability limit; an engine at 1/60 s frames cut into its substeps, with the parameters its
user picks for dynamics, MuJoCo's ``discrete``).  The FEM is ``M ü + K u = 0`` from its static
state (Hex2, consistent mass, Newmark average acceleration at a step whose own period error,
checked by halving, is below :data:`FEM_PERIOD_TOL`).  The tracked point is the lattice particle of
largest static displacement of the FEM; the run lasts ``periods + ½`` Rayleigh periods of the FEM.

Figures per model (:func:`studies.sweep.dynamics.metrics`): the first period's error
``100 (T/T_FEM − 1)`` %, the damping ratio ζ by the log decrement, the phase error after
``periods`` periods (rad), the L2 trajectory error over the static deflection, the wall time per
simulated second; beside them what the integrator alone does to a linear mode of the model's own
measured frequency ω (``z = ω h``, :func:`integrator_prediction`): semi-implicit Euler keeps the
amplitude and shortens the period, ``T_h/T = z / (2 arcsin(z/2))``; backward Euler (MuJoCo's
``discrete``, Newton's VBD converged) multiplies the mode by ``1/(1 + i z)`` per step: period
``2π h / atan z``, amplitude ``(1 + z²)^{−1/2}`` per step.

Runs are the runner's stored tasks (:class:`ReleasedRun`): the FEM references first (pooled with the
reproduction's runs by :func:`tasks`), then every model at the references' length and point; a
rerun finds both stored.  Tables: ``dynamics`` (a row per body, ν and model) and
``dynamics_traces`` (the tracked component's history of the FEM and every model at
:data:`TRACE_NU`, for the report's figure).

Sizes (:data:`LEVELS`): the full level runs the 4³ cube and the 2×2×12 beam over two periods, the
lattice models at every ν and the engines at ν = 0.25 (on the beam only those of
:data:`BEAM_ENGINES`); ``quick`` the 3³ cube and the 2×2×12 beam at ν = 0.25 with
two lattice models, over two periods (the cost budget of the reproduction: docs/dynamics.md).
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass

import numpy as np
import pandas as pd

from hybmss import models
from hybmss.experiments import SceneSpec
from hybmss.scene import Scene

from studies.sweep import roles
from studies.sweep.outcomes import expected_finding
from studies.sweep.runner import SolverSpec, Task, run_tasks

NUS = (0.0, 0.25, 0.45, 0.499)
TRACE_NU = 0.25
"""The ν of the trajectories' figure."""
FEM_PERIOD_TOL = 2e-3
"""The FEM transient's own period error bound (checked by halving its step)."""
BODIES = {
    # name: (experiment, gravity along -y (m/s^2))
    "cube": ("compression", 0.01),
    "beam": ("bending", 0.1),
}
LATTICE_MODELS = roles.RELEASED_MODELS
ENGINES = roles.RELEASED_ENGINES["cube"]
BEAM_ENGINES = roles.RELEASED_ENGINES["beam"]


@dataclass(frozen=True)
class Level:
    """The sizes of one level: meshes per body, ν, the models at every ν and the engines at
    ``engine_nus`` (``engines``: body -> the engines run on it), the periods a run lasts."""

    meshes: dict
    nus: tuple
    models: tuple
    engines: dict = dataclasses.field(default_factory=dict)
    engine_nus: tuple = ()
    periods: int = 3


LEVELS = {
    "full": Level({"cube": (4, 4, 4), "beam": (2, 2, 12)}, NUS, LATTICE_MODELS,
                  {"cube": ENGINES, "beam": BEAM_ENGINES}, (0.25,), 2),
    "quick": Level({"cube": (3, 3, 3), "beam": (2, 2, 12)}, (0.25,), roles.RELEASED_QUICK, {}, (), 2),
}
FEM = SolverSpec("fem", element="hex2", law="linear")
MODEL = SolverSpec("explicit")
"""The solver field of a model's released run (its own integrator; the fields beyond ``kind`` are
not used)."""
TABLES = ("dynamics", "dynamics_traces")
TRACE_SAMPLES = 400
"""Samples per trajectory in ``dynamics_traces`` at most (every k-th sample)."""


def body_scene(body: str, mesh, nu: float, model: str) -> Scene:
    """The loaded scene of ``body`` (module docstring) with ``model``."""
    experiment, g = BODIES[body]
    if body == "beam":
        return SceneSpec.default(experiment, mesh=tuple(mesh), nu=nu, gravity=g, model=model).build()
    scene = SceneSpec.default(experiment, mesh=tuple(mesh), nu=nu, deformation=0.0, model=model).build()
    return dataclasses.replace(scene, gravity=(0.0, -g, 0.0))


class ReleasedRunError(RuntimeError):
    """A released run that stopped early (``row_status``: the trajectory's status)."""

    def __init__(self, message: str, status: str):
        super().__init__(message)
        self.row_status = "diverged" if status == "diverged" else "error"


@dataclass(frozen=True)
class ReleasedRun:
    """A scene holder of the runner: the released transient of ``body`` at ``nu`` with ``model``
    (``"fem"``: the reference), lasting ``periods + ½`` of the FEM's Rayleigh periods; a model's
    run has the reference's ``t_end`` (s), tracked ``point`` and first ``period`` (its sampling)."""

    body: str
    mesh: tuple
    nu: float
    model: str
    periods: int
    t_end: float | None = None
    point: tuple | None = None
    period: float | None = None

    experiment = "released"

    def build(self) -> Scene:
        return body_scene(self.body, self.mesh, self.nu, models.default_name() if self.model == "fem" else self.model)

    @property
    def key_extra(self) -> dict:
        """What else changes the stored answer: the released run's length, point, tolerance."""
        return {"released": self.body, "periods": self.periods, "t_end": self.t_end, "point": self.point,
                "period": self.period, "fem_period_tol": FEM_PERIOD_TOL}

    @property
    def label(self) -> str:
        return f"released {self.body} {'x'.join(map(str, self.mesh))} nu={self.nu:g} {self.model}"

    def to_dict(self) -> dict:
        s = self.build()
        return {"experiment": self.experiment, "body": self.body, "mesh": "x".join(map(str, self.mesh)),
                "nu": float(self.nu), "E": s.material.E, "rho": s.material.rho, "gravity": BODIES[self.body][1],
                "model": self.model, "variant": self.model, "periods": self.periods}

    def solve(self, solver: SolverSpec):
        return _fem_run(self) if self.model == "fem" else _model_run(self)


def _result(run: ReleasedRun, scene: Scene, X, u, traj, info: dict):
    """The runner's :class:`hybmss.result.Result` of a released run: the static state it released
    (``X``, ``u`` at the lattice particles), the trajectory as the arrays ``t`` and ``trajectory``."""
    from hybmss.result import Result

    V = float(scene.body.volume)
    info = {**info, "t_end": traj.t_end, "point_x": traj.point[0], "point_y": traj.point[1],
            "point_z": traj.point[2], "dt": traj.dt, "wall_per_simulated_s": traj.wall_per_simulated_second(),
            "arrays": {"t": traj.t, "trajectory": traj.u}}
    return Result(f"released-{run.model}", scene.digest(), np.asarray(X), np.asarray(u), V, V, {}, {},
                  int(len(traj.t) - 1), float(traj.wall_time_s), True, None, info)


def _fem_run(run: ReleasedRun):
    from fem_reference.transient import ReleasedFem

    from studies.sweep.dynamics import trajectory_oscillation
    from studies.sweep.transients import fem_transient, largest_static_point

    scene = run.build()
    fem = ReleasedFem(scene, FEM.element, FEM.law, FEM.refine)
    tr = fem_transient(scene, largest_static_point(fem), run.periods + 0.5, FEM_PERIOD_TOL, FEM.element, FEM.law,
                       FEM.refine, fem=fem)
    if not tr.ok:
        raise ReleasedRunError(f"the FEM transient stopped: {tr.reason}", tr.status)
    X = fem.ops.fmesh.lattice.X
    u = fem.static.reshape(-1, 3)[fem.space.particle_dofs]
    check = tr.info["dt_check"]
    info = {"period": trajectory_oscillation(tr).period, "fem_dt": check["dt"], "omega_rayleigh": tr.info["omega_rayleigh"],
            "fem_period_error_estimate": check["period_error_estimate"], "halvings": check["halvings"],
            "n_dofs": tr.info["n_dofs"], "integrator": "Newmark average acceleration"}
    return _result(run, scene, X, u, tr, info)


def _model_run(run: ReleasedRun):
    from hybmss.released import released_model, released_transient, static_state, user_step, with_model

    from studies.sweep.transients import samples_every

    scene = run.build()
    model = released_model(run.model)
    loaded = with_model(scene, model)
    dt, sub = user_step(loaded)
    x_s = static_state(loaded)
    tr = released_transient(scene, model, dt, run.t_end, run.point, start=x_s,
                            record_every=samples_every(dt, sub, run.period))
    if not tr.ok:
        raise ReleasedRunError(f"{run.model}: {tr.reason}", tr.status)
    from hybmss.lattice import Lattice

    X = Lattice.from_body(scene.body).X
    return _result(run, scene, X, x_s - X, tr, {"substeps": sub, "integrator": tr.info.get("integrator")})


# ------------------------------------------------------------------------------ tasks
def level(quick: bool) -> Level:
    return LEVELS["quick" if quick else "full"]


def fem_tasks(lv: Level) -> list[Task]:
    """The FEM reference of every body and ν of the level."""
    nus = sorted(set(lv.nus) | set(lv.engine_nus))
    return [Task(ReleasedRun(b, tuple(m), float(nu), "fem", lv.periods), FEM, "dynamics")
            for b, m in lv.meshes.items() for nu in nus]


def tasks(quick: bool = False) -> list[Task]:
    """The runs the reproduction pools with its others: the FEM references (the models' runs take
    their length and point, and run in :func:`run`)."""
    return fem_tasks(level(quick))


def model_names(lv: Level, nu: float, body: str) -> tuple[str, ...]:
    engines = lv.engines.get(body, ())
    names = lv.models + (engines if any(math.isclose(nu, v) for v in lv.engine_nus) else ())
    return tuple(n for n in names if n in models.names())


def model_tasks(lv: Level, refs: list[Task], rows: list[dict]) -> list[Task]:
    """Every model of the level at each reference that has a result, at its length and point."""
    out = []
    for t, r in zip(refs, rows):
        if r.get("status") != "ok":
            continue
        i = r["info"]
        point = (i["point_x"], i["point_y"], i["point_z"])
        for name in model_names(lv, t.scene.nu, t.scene.body):
            run = dataclasses.replace(t.scene, model=name, t_end=i["t_end"], point=point, period=i["period"])
            out.append(Task(run, MODEL, "dynamics"))
    return out


# ------------------------------------------------------------------------------ figures
def integrator_family(name) -> str:
    """``symplectic`` (semi-implicit Euler: the lattice models, MuJoCo's Euler, Newton's
    semi-implicit), ``backward`` (backward Euler: MuJoCo's discrete, Newton's VBD) or ``other``
    (XPBD: its compliance solve has no closed form here)."""
    s = str(name or "").lower()
    if "semi-implicit" in s or "semiimplicit" in s or s == "euler":
        return "symplectic"
    if s == "discrete" or "vbd" in s or "backward" in s:
        return "backward"
    return "other"


def integrator_prediction(family: str, omega: float, h: float) -> tuple[float | None, float | None]:
    """``(T_h/T − 1, ζ)`` the integrator alone gives a linear mode ``ẍ = −ω² x`` at the step ``h``
    (module docstring); ``(None, None)`` for another family or an unstable step."""
    z = omega * h
    if family == "symplectic":
        return (z / (2.0 * math.asin(z / 2.0)) - 1.0, 0.0) if z < 2.0 else (None, None)
    if family == "backward":
        a = math.atan(z)
        delta = 0.5 * math.log1p(z * z) * (2.0 * math.pi / a)  # −ln|G| per step × steps per period
        return z / a - 1.0, delta / math.sqrt(4.0 * math.pi**2 + delta**2)
    return None, None


def _trajectory(store, key: str, row: dict, solver: str):
    from hybmss.trajectory import Trajectory

    a = store.arrays(key)
    i = row["info"]
    return Trajectory(solver, a["t"], a["trajectory"], (i["point_x"], i["point_y"], i["point_z"]), i["dt"],
                      float(row["wall_time_s"]))


def _row(task: Task, row: dict, ref, ref_row: dict, store, periods: int) -> dict:
    """One row of ``dynamics``: the model's figures against the reference (module docstring)."""
    from studies.sweep.dynamics import metrics
    from studies.sweep.runner import no_result_because

    run, fi = task.scene, ref_row["info"]
    head = {"body": run.body, "mesh": "x".join(map(str, run.mesh)), "nu": run.nu, "model": run.model,
            "fem_dt_s": fi["fem_dt"], "fem_period_error_pct": 100.0 * fi["fem_period_error_estimate"],
            "fem_wall_per_simulated_s": fi["wall_per_simulated_s"], "phase_periods": periods}
    why = no_result_because(row)
    if why:
        return {**head, "status": row.get("status"), "reason": why}
    info = row["info"]
    m = metrics(_trajectory(store, task.key(), row, run.model), ref, periods)
    fam = integrator_family(info.get("integrator"))
    pred_T, pred_z = (None, None)
    if m["period"]:
        pred_T, pred_z = integrator_prediction(fam, 2.0 * math.pi / m["period"], info["dt"])
    pct = (lambda v: None if v is None else 100.0 * v)
    return {**head, "integrator": info.get("integrator"), "family": fam, "dt_s": info["dt"],
            "substeps": info.get("substeps"), "omega_h": None if not m["period"] else 2 * math.pi * info["dt"] / m["period"],
            "period_s": m["period"], "period_ref_s": m["period_ref"], "period_error_pct": pct(m["period_error"]),
            "integrator_period_pct": pct(pred_T), "zeta": m["zeta"], "integrator_zeta": pred_z,
            "zeta_ref": m["zeta_ref"], "phase_error_rad": m["phase_error_rad"], "l2_error": m["l2_error"],
            "wall_per_simulated_s": m["wall_per_simulated_s"], "status": "ok" if not m["reason"] else "error",
            "reason": m["reason"]}


def _traces(store, task: Task, row: dict, axis: int) -> list[dict]:
    a = store.arrays(task.key())
    t, u = a["t"], a["trajectory"][:, axis]
    k = max(1, int(math.ceil(len(t) / TRACE_SAMPLES)))
    run = task.scene
    return [{"body": run.body, "mesh": "x".join(map(str, run.mesh)), "nu": run.nu, "model": run.model,
             "t_s": float(ti), "u_m": float(ui)} for ti, ui in zip(t[::k], u[::k])]


def tables(store, lv: Level, refs, ref_rows, runs, run_rows) -> dict[str, pd.DataFrame]:
    """``dynamics`` and ``dynamics_traces`` from the stored runs (module docstring)."""
    from studies.sweep.dynamics import dominant_axis

    by_ref = {(t.scene.body, t.scene.nu): (t, r) for t, r in zip(refs, ref_rows)}
    rows, traces, refs_ok = [], [], {}
    for (body, nu), (t, r) in by_ref.items():
        if r.get("status") == "ok":
            refs_ok[(body, nu)] = _trajectory(store, t.key(), r, "fem")
            if math.isclose(nu, TRACE_NU):
                traces += _traces(store, t, r, dominant_axis(refs_ok[(body, nu)]))
        else:
            rows.append({"body": body, "mesh": "x".join(map(str, t.scene.mesh)), "nu": nu, "model": "fem",
                         "status": r.get("status"), "reason": r.get("message")})
    for t, r in zip(runs, run_rows):
        key = (t.scene.body, t.scene.nu)
        rows.append(_row(t, r, refs_ok[key], by_ref[key][1], store, lv.periods))
        if math.isclose(t.scene.nu, TRACE_NU) and r.get("status") == "ok":
            traces += _traces(store, t, r, dominant_axis(refs_ok[key]))
    return {"dynamics": pd.DataFrame(rows), "dynamics_traces": pd.DataFrame(traces)}


def run(store, quick: bool = False, jobs: int | None = None, progress: bool = True, *, runner=None,
        lv: Level | None = None) -> dict:
    """Study driver (``EXTRA_STUDIES``): the references, then the models' runs (both stored tasks
    of the runner), then the tables ``dynamics`` and ``dynamics_traces``; ``lv`` replaces the
    level's sizes."""
    lv = level(quick) if lv is None else lv
    load0 = os.getloadavg()[0]
    refs = fem_tasks(lv)
    ref_rows = run_tasks(refs, store, jobs=jobs, progress=progress, desc="dynamics references", runner=runner)
    runs = model_tasks(lv, refs, ref_rows)
    run_rows = run_tasks(runs, store, jobs=jobs, progress=progress, desc="dynamics", runner=runner,
                         expected=expected_finding)
    out = tables(store, lv, refs, ref_rows, runs, run_rows)
    out["dynamics"]["load_average"] = f"{load0:.2f}-{os.getloadavg()[0]:.2f}"
    for name, t in out.items():
        store.write_table(name, t)
    return out
