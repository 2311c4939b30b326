"""The engines people run (MuJoCo, Newton, PositionBasedDynamics: :mod:`hybmss.models.mujoco`,
:mod:`hybmss.models.newton`, :mod:`hybmss.models.pbd`) on the 10³ cube against the FEM.

**Closing table** (``engines_closing``): compression and shear of the 10³ cube at 5 % for
ν ∈ {0.25, 0.45, 0.499}; every engine model's static answer (the rest state of its damped run),
hybmss and corot-hex8 for context, and the linear FEM on the same cube (Hex2; mixed u–p Hex2×Hex1
for ν ≥ 0.45, ``element='auto'``, the reference of the publication tables at 5 %).  Per row: the
plate force (compression F_z, shear F_x) and the volume change with their relative errors
against the FEM, the static answer's wall time, and the run's status: a scene an engine cannot
represent (:class:`hybmss.models._engine_model.SceneNotRepresentable`) is a failure row with
its reason, never a gap.  The runs go through the runner's store (a rerun with the same code
reuses them).

**Step times** (``engines_timing``): the time per explicit step of each engine on the same cube
as a ratio to hybmss's (Numba, float64, one thread), measured in the same process one after the
other with the 1-minute load average (:func:`step_ratios`, also ``hybmss bench --model``); a
shared machine only ever adds time, so each figure is the best of ``repeats``.
"""

from __future__ import annotations

import math
import os
import time

import pandas as pd

from hybmss import models
from hybmss.experiments import SceneSpec, experiment

from studies.sweep import roles
from studies.sweep.outcomes import expected_finding
from studies.sweep.runner import Task, run_tasks
from studies.sweep.store import Store
from studies.study.experiment import configurations, engine_models

STUDY = "engines"
"""The driver study of :data:`studies.paper.reproduce.DRIVER_FILES` whose file
(``studies/data/studies/engines.toml``) declares the scenes, the models, the reference and the
tables (``engines_closing``, ``engines_timing`` with its repeats)."""
MESH = (10, 10, 10)
"""The cube of :func:`step_ratios` when none is given (``hybmss bench --model``)."""
TIMED_NU = 0.25
"""ν of the step timings (every engine represents it)."""
TARGET_S = {False: 0.5, True: 0.05}
"""Wall time of each timed run of :func:`step_ratios` in the table, full and quick."""


def _docs() -> list[dict]:
    from studies.paper.reproduce import DRIVER_STUDIES, load_study_file

    return [load_study_file(f) for f in DRIVER_STUDIES[STUDY].files]


def specs(quick: bool = False) -> list[SceneSpec]:
    """The scenes of the closing table, in the file's order (compression, then shear; by ν)."""
    return [c for d in _docs() for c in configurations(d, quick)]


def context_models(docs) -> tuple[str, ...]:
    """The models the file names beside the engines (``[[model]] name``), in its order."""
    return tuple(e["name"] for d in docs for e in d["model"] if "name" in e)


def tasks(quick: bool = False, names=None) -> list[Task]:
    """The closing table's runs (the file's): the static answer of each engine model and of the
    context models, and the FEM, on each scene of :func:`specs`; ``names``: only these models
    (and the FEM)."""
    from studies.paper.reproduce import DRIVER_STUDIES

    ts = DRIVER_STUDIES[STUDY](quick)
    return ts if names is None else [t for t in ts if t.solver.kind == "fem" or t.scene.model in tuple(names)]


def _rel(a, b) -> float | None:
    if a is None or b is None or not (math.isfinite(a) and math.isfinite(b)) or b == 0:
        return None
    return abs(a - b) / abs(b)


def closing_table(specs_, rows: list[dict], context=roles.ENGINE_CONTEXT) -> pd.DataFrame:
    """One row per (experiment, ν, model): force and volume change against the FEM of the scene,
    for every engine model and the ``context`` models."""
    by = {}
    for r in rows:
        by[(r["experiment"], float(r["nu"]), r.get("model") if not str(r["solver"]).startswith("fem") else "fem")] = r
    out = []
    for spec in specs_:
        fem = by.get((spec.experiment, float(spec.nu), "fem"), {})
        col = experiment(spec.experiment).answer
        Ff, dVf = fem.get(col), fem.get("volume_change")
        for m in engine_models() + tuple(context):
            r = by.get((spec.experiment, float(spec.nu), m))
            if r is None:  # a run not (yet) in the store: said, not left out
                r = {"status": "not run", "message": "not computed in this results folder"}
            ok = r.get("status", "ok") == "ok"
            F, dV = (r.get(col), r.get("volume_change")) if ok else (None, None)
            out.append({
                "experiment": spec.experiment, "mesh": "x".join(map(str, spec.mesh)), "nu": float(spec.nu),
                "model": m, "engine": m in engine_models(), "status": r.get("status", "ok"),
                "message": None if ok else r.get("message"),
                "force_N": F, "force_fem_N": Ff, "force_rel_error": _rel(F, Ff),
                "volume_change": dV, "volume_change_fem": dVf,
                "volume_change_rel_error": _rel(dV, dVf),
                "static_wall_s": r.get("wall_time_s") if ok else None,
                "steps": r.get("solver_iterations") if ok else None,
                "converged": r.get("converged") if ok else None,
            })
    return pd.DataFrame(out)


def step_ratios(names, mesh=MESH, nu: float = TIMED_NU, steps: int | None = None, repeats: int = 3,
                target_s: float = 0.5) -> list[dict]:
    """Time per explicit step of each model of ``names`` and of the registry's default model, hybmss (Numba, float64, one thread)
    on the compression cube ``mesh`` at ν, best of ``repeats`` runs of ``steps`` steps (default:
    as many as fit in ``target_s`` after a probe, at least 20), interleaved model by model (a
    round runs every model once, so that a burst of load on the shared machine does not fall on
    one model only and each ratio compares runs of the same minute);
    ``ratio_to_hybmss`` per row, the 1-minute load average of each best run.  An engine steps at
    ``dt`` = 0.5 × its own ``dt_crit`` (its step time does not depend on dt), hybmss at 1 ms."""
    from hybmss.bench import compression_scene, load_average
    from hybmss.explicit import simulate_explicit
    from hybmss.system import build

    cfgs = []
    ref = models.default_name()
    for name in (ref,) + tuple(n for n in names if n != ref):
        spec = models.get(name)
        scene = compression_scene(name, nu, mesh=mesh)
        system = build(scene)
        engine = spec.kernels == ("engine",)
        kw = dict(kernel="engine" if engine else "numba",
                  precision=getattr(spec, "precisions", ("f64",))[0] if engine else "f64")
        st = spec.stepper(system, 1.0, ramp_time=1.0, **kw) if engine else None
        dt = 0.5 * st.dt_crit() if engine else 1e-3

        def run(n, scene=scene, system=system, dt=dt, kw=kw):
            return simulate_explicit(scene, dt=dt, steps=n, system=system, compute_dt_crit=False,
                                     check_every=min(n, 100), **kw)

        t0 = time.perf_counter()
        run(2)  # compiles (Numba) or builds and compiles (the engine) outside the timings
        first = time.perf_counter() - t0
        n = steps
        if n is None:
            n = 4
            while True:
                w = run(n).wall_time_s
                if w >= 0.1 * target_s or n >= 10_000:
                    break
                n *= 4
            n = int(min(10_000, max(20, target_s * n / max(w, 1e-9))))
        cfgs.append({"model": name, "run": run, "steps": n, "first_use_s": first, "best": (math.inf, None, None)})
    for _ in range(max(1, int(repeats))):
        for c in cfgs:
            r = c["run"](c["steps"])
            if r.wall_time_s < c["best"][0]:
                c["best"] = (r.wall_time_s, load_average(), r.info)
    base = cfgs[0]["best"][0] / cfgs[0]["steps"]
    rows = []
    for c in cfgs:
        wall, load, info = c["best"]
        per = wall / c["steps"]
        engine_s = info.get("step_time_s") if info else None
        rows.append({"model": c["model"], "mesh": "x".join(map(str, mesh)), "nu": float(nu), "steps": c["steps"],
                     "s_per_step": per, "ratio_to_hybmss": per / base,
                     "engine_calls_s_per_step": (engine_s / c["steps"]) if engine_s is not None else None,
                     "first_use_s": c["first_use_s"], "device": info.get("device") if info else None,
                     "engine_version": info.get("engine_version") if info else None,
                     "load_avg": load, "cores": os.cpu_count()})
    return rows


def closing_hook(h) -> pd.DataFrame:
    """Table hook ``engines-closing`` (:class:`studies.paper.reproduce.HookInput`)."""
    return closing_table(h.configurations, list(h.rows), context_models(h.docs))


def timing_hook(h) -> pd.DataFrame:
    """Table hook ``engines-timing``: :func:`step_ratios` of the engines that represent the
    timed scene, on the file's first mesh, best of the entry's ``repeats``."""
    mesh = h.configurations[0].mesh
    ok = [m for m in engine_models() if _represents(m, mesh)]
    return pd.DataFrame(step_ratios(ok, mesh=mesh, repeats=h.repeats or 1, target_s=TARGET_S[bool(h.quick)]))


def run(store: Store, quick: bool = False, jobs: int | None = None, progress: bool = True, *, runner=None,
        timing: bool = True, names=None) -> dict:
    """Study driver (``ON_REQUEST_STUDIES``): writes the tables of the engines study file,
    ``engines_closing`` and (with ``timing``) ``engines_timing`` (``names``: the models of
    :func:`tasks`)."""
    from studies.paper.reproduce import file_study_tables

    ts = tasks(quick, names)
    rows = run_tasks(ts, store, jobs=jobs, progress=progress, desc="engines", runner=runner,
                     expected=expected_finding)
    tables = file_study_tables(STUDY, ts, rows, quick, skip=() if timing else ("engines-timing",), store=store)
    for name, t in tables.items():
        store.write_table(name, t)
    return tables


def _represents(name: str, mesh) -> bool:
    """Whether the engine model ``name`` represents the timed compression scene (no refusal)."""
    from hybmss.bench import compression_scene

    try:
        models.get(name)._check(compression_scene(name, TIMED_NU, mesh=mesh))
        return True
    except ValueError:
        return False
