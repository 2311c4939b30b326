"""Speed against error: time to a solution against its error w.r.t. a converged FEM reference.

For each experiment (compression, tension, shear, torsion, bending) and configuration
(ν ∈ {0, ¼, 0.499} × d ∈ {5 %, 20 %}; torsion θ ∈ {1°, 45°}; bending at the publication's
ν = ¼, E ∈ {10, 2} MPa) the candidates are

- the mass-spring variants (hybmss, hybmss-fd, hybmss-cf) with each solver: static Newton, implicit
  Euler to rest (dt = 0.25 s, at most 40 steps = 10 s, plates ramped over 1 s, c = 2 s⁻¹) and the
  publication's explicit protocol (dt = 1 ms × 10,000 steps, c = 2 s⁻¹, ramp 1 s), at the base
  resolution and its refinements (the finest beam has no explicit run of hybmss-cf, as in the
  reproduction study); implicit for hybmss at the base resolution only (a Newton solve per step
  makes it the most expensive solver);
- the engines of the ``pareto`` role (:mod:`studies.engines`): their static answer (the rest state
  of their damped run) at the base resolution only, not the beam under gravity (cost);
- the FEM itself: Hex1 at every resolution (cube also ×3), Hex2 and mixed u–p at the resolutions
  coarser than the reference's, with the reference's law.

Resolutions (:data:`LEVELS`; base → MSS refinements → reference):

- ``medium`` (default): cube 3³ → 6³ → reference 6³; beam 1×1×6 → 2×2×12, 4×4×24 → reference
  4×4×24.  The beam runs at 4×4×24 (reference, MSS static and explicit) are those of the
  reproduction study, so ``make reproduce-paper`` computes them once.
- ``full``: cube 5³ → 10³ → reference 10³; beam 2×2×12 → 4×4×24, 8×8×48 → reference 8×8×48 (also
  shared with the reproduction study; the Hex2 Neo-Hookean references of the beam under gravity
  are the long pole, tens of minutes on a loaded 2-core machine).
- ``quick`` (tests): cube 2³ → 4³, beam 1×1×6 → 2×2×12, ν = ¼, 5 %, 1°, E = 10 MPa, linear law.

``run(..., experiments=..., nus=..., level=...)`` restricts the configurations (the bending ones
keep ν = ¼) or picks the level.

**Reference.**  The finest FEM that fits the time budget: Hex2 (mixed u–p Hex2×Hex1 for
ν ≥ 0.45, ``element='auto'``; Hex2 for the beam under gravity) at the reference resolution, with
the law of :func:`studies.compare.default_law` (linear up to 5 %, Neo-Hookean above, Neo-Hookean
for the beam under gravity).  Its discretization error is estimated by Richardson from the same
element one level coarser (ratio 2): ``‖u_ref − u_coarse‖ / ((2^p − 1) ‖u_ref‖)`` with p = 2
assumed (the clamped edges limit the smoothness; Hex2's nominal order is higher, so the estimate
is conservative).  Errors below about this estimate are not resolved.  At ν = 0 compression and
tension are homogeneous (no lateral strain), every FEM is exact and the estimate is ~1e-15.

**Error.**  Relative L2 of the nodal displacement at the shared coarse points: the particles of
the base lattice that no plate prescribes (medium: cube 32, beam 20 points; full: cube 144, beam
99 points).  Every
resolution is an integer multiple of the base, so each run has a particle (or a FEM vertex) at
every shared point: values are sampled, never interpolated.  Also a scalar per experiment:
volume change (error |e − e*| in units of the imposed strain d), shear force F_x, torque T_z,
tip deflection (relative errors).

**Time.**  The solver-reported ``wall_time_s`` of each run (static and implicit: assembly
included; explicit: the stepping only; FEM: meshing, assembly and solve), single-threaded, runs
executed two at a time on a shared machine: read ratios, not absolute figures.
"""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd

from . import roles
from .compare import default_law
from hybmss import models
from hybmss.experiments import SceneSpec

from .runner import SolverSpec, Task, run_tasks
from .store import Store

EXPERIMENTS = ("compression", "tension", "shear", "torsion", "bending")
NUS = (0.0, 0.25, 0.499)
def pareto_models() -> tuple[str, ...]:
    """The models compared (registry order; the first is the reference model, also run implicitly)."""
    return roles.in_role("pareto")
DAMPING = 2.0
PROTOCOL = SolverSpec("explicit", dt=1e-3, steps=10_000, ramp_time=1.0)
IMPLICIT = SolverSpec("implicit", dt=0.25, steps=40, ramp_time=1.0)
STATIC = SolverSpec("static")
BUDGETS = (0.01, 0.05, 0.10)
ORDER_ASSUMED = 2.0


LEVELS = {
    "quick": {"cube": ((2, 2, 2), (1, 2), (1, 2), 2), "beam": ((1, 1, 6), (1, 2), (1, 2), 2)},
    "medium": {"cube": ((3, 3, 3), (1, 2), (1, 2, 3), 2), "beam": ((1, 1, 6), (1, 2, 4), (1, 2, 4), 4)},
    "full": {"cube": ((5, 5, 5), (1, 2), (1, 2, 3), 2), "beam": ((2, 2, 12), (1, 2, 4), (1, 2, 4), 4)},
}
"""Per level and body kind: base mesh, MSS resolution factors, Hex1 factors, reference factor.
``medium`` is the study of ``make reproduce-paper``; ``full`` the same design on finer bases."""


def bases(quick: bool, level: str | None = None) -> dict:
    return LEVELS[level or ("quick" if quick else "medium")]


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


def tasks_for(spec: SceneSpec, quick: bool, level: str | None = None) -> list[tuple[dict, Task]]:
    """(meta, task) pairs of one configuration: reference, its coarse partner, candidates."""
    kind = "beam" if spec.is_beam else "cube"
    _, mss_factors, fem_factors, ref_f = bases(quick, level)[kind]
    law = "linear" if quick else default_law(spec)
    cfg = config_label(spec)
    out = []

    def add(role, factor, s, solver, method):
        meta = {"config": cfg, "experiment": spec.experiment, "role": role, "factor": factor,
                "method": method, "mesh": "x".join(map(str, s.mesh)), "base": spec}
        out.append((meta, Task(s, solver, "pareto")))

    ref_el = _ref_element(spec)
    add("reference", ref_f, _scaled(spec, ref_f), SolverSpec("fem", element=ref_el, law=law), "reference")
    add("partner", ref_f // 2, _scaled(spec, ref_f // 2), SolverSpec("fem", element=ref_el, law=law),
        "reference partner")
    finest = max(mss_factors)
    for f in mss_factors:
        s = _scaled(spec, f)
        for model in pareto_models():
            engine = bool(roles.part(model).meshes)  # its static answer at the base resolution only
            if engine and (f != 1 or spec.experiment == "bending" or (quick and not roles.part(model).quick)):
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


def all_tasks(quick: bool = False, experiments=EXPERIMENTS, nus=None, level: str | None = None
              ) -> list[tuple[dict, Task]]:
    return [p for spec in configs(quick, experiments, nus, level) for p in tasks_for(spec, quick, level)]


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


def scalar_of(spec: SceneSpec, row: dict) -> tuple[str, float]:
    exp = spec.experiment
    if exp in ("compression", "tension"):
        return "volume_change", row.get("volume_change", np.nan)
    if exp == "shear":
        return "force_x", row.get("force_x", np.nan)
    if exp == "torsion":
        return "torque_z", row.get("torque_z", np.nan)
    return "tip_deflection", row.get("tip_deflection", np.nan)


def scalar_error(spec: SceneSpec, q: float, q_ref: float) -> float:
    if spec.experiment in ("compression", "tension"):
        return abs(q - q_ref) / spec.deformation
    return abs(q - q_ref) / abs(q_ref) if q_ref else np.nan


def pareto_frame(store: Store, pairs, rows, quick: bool = False) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Tidy table of candidates with errors, and the reference table (one row per config)."""
    specs = {m["config"]: m["base"] for m, _ in pairs}
    groups: dict[str, list] = {}
    for (meta, task), row in zip(pairs, rows):
        groups.setdefault(meta["config"], []).append((meta, task, row))
    out, refs = [], []
    for cfg, items in groups.items():
        spec = specs[cfg]
        pts = shared_points(spec)
        ref = next((m, t, r) for m, t, r in items if m["role"] == "reference")
        part = next((m, t, r) for m, t, r in items if m["role"] == "partner")
        ref_ok = ref[2]["status"] == "ok"
        u_ref = sample(store.arrays(ref[2]["key"])["X"], store.arrays(ref[2]["key"])["u"], pts) if ref_ok else None
        ref_err = np.nan
        if ref_ok and part[2]["status"] == "ok":
            a = store.arrays(part[2]["key"])
            u_p = sample(a["X"], a["u"], pts)
            ref_err = float(np.linalg.norm(u_ref - u_p) / np.linalg.norm(u_ref) / (2 ** ORDER_ASSUMED - 1))
        sname, q_ref = scalar_of(spec, ref[2]) if ref_ok else ("", np.nan)
        refs.append({"config": cfg, "experiment": spec.experiment, "nu": spec.nu,
                     "reference": ref[2]["solver"], "reference_mesh": ref[0]["mesh"],
                     "reference_status": ref[2]["status"], "reference_time_s": ref[2].get("wall_time_s", np.nan),
                     "reference_error_estimate": ref_err, "partner_mesh": part[0]["mesh"],
                     "shared_points": len(pts), "scalar": sname, "scalar_reference": q_ref})
        for meta, task, row in items:
            if meta["role"] != "candidate":
                continue
            rec = {**{k: v for k, v in meta.items() if k != "base"}, "nu": spec.nu, "load": cfg.split(" ", 2)[2], "solver": task.solver.label,
                   "variant": task.scene.variant if task.solver.kind != "fem" else "fem",
                   "status": row["status"], "time_s": row.get("wall_time_s", np.nan),
                   "elapsed_s": row.get("elapsed_s", np.nan), "message": row.get("message", ""),
                   "reference_error_estimate": ref_err}
            if row["status"] == "ok" and ref_ok:
                a = store.arrays(row["key"])
                u = sample(a["X"], a["u"], pts)
                rec["error_u"] = float(np.linalg.norm(u - u_ref) / np.linalg.norm(u_ref))
                _, q = scalar_of(spec, row)
                rec["scalar"] = sname
                rec["scalar_value"] = q
                rec["scalar_reference"] = q_ref
                rec["error_scalar"] = scalar_error(spec, q, q_ref)
                vols = a.get("cell_volumes")
                rec["inverted_cells"] = int(np.count_nonzero(vols <= 0)) if vols is not None else 0
            else:
                rec["error_u"] = np.nan
            out.append(rec)
    df = pd.DataFrame(out)
    df["pareto"] = False
    for cfg, g in df.groupby("config"):
        ok = g[np.isfinite(g["error_u"]) & np.isfinite(g["time_s"])].sort_values(["time_s", "error_u"])
        best = np.inf
        for i, r in ok.iterrows():
            if r["error_u"] < best:
                df.loc[i, "pareto"] = True
                best = r["error_u"]
    return df, pd.DataFrame(refs)


def budget_table(df: pd.DataFrame, budgets=BUDGETS) -> pd.DataFrame:
    """For each configuration and error budget: the cheapest run within it, the next cheapest
    run of another method within it (``next_method``, ``next_mesh``, ``next_time_s``) and the
    lead ``next_time_s / time_s``; and per experiment, the cheapest method (variant, solver,
    resolution) within budget in *every* configuration.  A method is a model with a solver, or
    a FEM element with its law; its cheapest resolution within the budget represents it."""
    out = []
    ok = df[np.isfinite(df["error_u"]) & np.isfinite(df["time_s"])]
    for cfg, g in ok.groupby("config", sort=False):
        for b in budgets:
            w = g[g["error_u"] <= b].sort_values("time_s", kind="stable").drop_duplicates("method")
            base = {"experiment": g["experiment"].iloc[0], "config": cfg, "budget": b}
            if w.empty:
                best = g.sort_values("error_u").iloc[0]
                out.append({**base, "method": "none within budget", "mesh": "", "time_s": np.nan,
                            "error_u": np.nan, "most_accurate": f"{best['method']} {best['mesh']}",
                            "most_accurate_error": best["error_u"]})
                continue
            r = w.iloc[0]
            rec = {**base, "method": r["method"], "mesh": r["mesh"], "time_s": r["time_s"],
                   "error_u": r["error_u"], "reference_error_estimate": r["reference_error_estimate"],
                   "next_method": "none", "next_mesh": "", "next_time_s": np.nan, "lead": np.nan}
            if len(w) > 1:
                n = w.iloc[1]
                rec.update(next_method=n["method"], next_mesh=n["mesh"], next_time_s=n["time_s"],
                           lead=float(n["time_s"]) / float(r["time_s"]))
            out.append(rec)
    # across configurations a FEM element counts as one method whatever the reference's law
    ok = ok.assign(method=ok["method"].str.replace(r"^(fem-(?:hex1|hex2|mixed))-.*$", r"\1 (reference law)",
                                                   regex=True))
    for exp, g in ok.groupby("experiment", sort=False):
        n_cfg = df[df["experiment"] == exp]["config"].nunique()
        for b in budgets:
            agg = (g.assign(within=g["error_u"] <= b)
                    .groupby(["method", "factor"])
                    .agg(n=("within", "sum"), worst=("error_u", "max"), time_s=("time_s", "max"),
                         mesh=("mesh", "first")))
            agg = agg[agg["n"] == n_cfg].sort_values("time_s")
            base = {"experiment": exp, "config": "all configurations", "budget": b}
            if agg.empty:
                out.append({**base, "method": "none within budget in every configuration", "mesh": "",
                            "time_s": np.nan, "error_u": np.nan})
            else:
                (method, factor), r = agg.index[0], agg.iloc[0]
                out.append({**base, "method": method, "mesh": f"base×{factor} ({r['mesh']}…)",
                            "time_s": r["time_s"], "error_u": r["worst"]})
    return pd.DataFrame(out)


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
                     runner=runner)
    df, refs = pareto_frame(store, pairs, rows, quick)
    tables = {"pareto": df, "pareto_front": df[df["pareto"]].sort_values(["config", "time_s"]),
              "pareto_references": refs, "budget": budget_table(df)}
    for name, t in tables.items():
        store.write_table(name, t)
    return tables
