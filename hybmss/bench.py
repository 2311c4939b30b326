"""Speed of the explicit kernels on the compression cube of SPEC §6.

The scene: n×n×n cells of 0.5 m, E = 10⁴ Pa, ρ = 1000 kg/m³, bottom clamped, top plate moved
down by 5 % (ramp 1 s), dt = 1 ms.  :func:`time_config` times one configuration (model, ν,
mesh, kernel, threads, precision); :func:`run_bench` a matrix of them: every model of the
registry (:mod:`hybmss.models`) at ν = 0.499 plus the first ``performance`` model (hybmss) at
ν = 1/4 (no volume term: it must cost what hybmss-cf costs), float64 and float32, one and two
threads, on the 10³ and 30³ cubes (scenes built by :mod:`hybmss.experiments`).  Each
configuration runs as many steps as fit in half a second (at most 10,000; its row says how
many; ``s_per_10k_steps`` scales it), so the whole matrix takes minutes.  A configuration a
model does not support (a kernel it does not list; float32 for baudet2009, whose corrections run
in float64) has no row.

JIT compilation is excluded (a short warm-up run first); each figure is the best of
``repeats`` runs, since other processes on the machine only ever add time, and configurations
are timed round-robin so that a burst of load does not fall on one of them only.  Every row
carries the 1-minute load average when it was measured: figures taken under a load above the
number of cores are not the kernel's (two threads on a busy machine spin and can be 10–100×
slower).  ``ns_per_spring_step`` divides by the model's merged springs.  The ``static`` list
times the static Newton solve of the first cube of the run (:func:`static_bench`; the 10³ cube
by default).  A quick run (a smoke run of the whole matrix, not a measurement) uses the 3³ cube.
"""

from __future__ import annotations

import os

from . import models
from .experiments import SceneSpec
from .explicit import WARM_UP_THREADS, dt_crit, simulate_explicit
from .scene import Scene
from .solve import solve_static
from .system import build
from .timing import time_repeated

MESH = (10, 10, 10)
LE = 0.5
DT = 1e-3
NU = 0.499
MESHES = ((10, 10, 10), (30, 30, 30))
QUICK_MESH = (3, 3, 3)
"""The cube of a quick run: every configuration compiles a kernel of its own, in seconds."""
MAX_STEPS = 10_000
"""Most steps of a timed run (figures are per 10,000 steps)."""
TARGET_S = 0.5
"""Seconds a timed run aims at: each configuration runs as many steps (at least
:data:`MIN_STEPS`, at most :data:`MAX_STEPS`) as a short probe says fit in this, so a slow model
or a large mesh costs the matrix no more than a fast one."""
QUICK_TARGET_S = 0.02
CHECK_EVERY = 100
"""Steps between the divergence checks of a timed run (a check reads the positions once, about
1/1000 of the steps' work at this interval): the loop's calls of about 0.1 s are whole check
intervals, so that Ctrl-C stops ``hybmss bench`` within one (:mod:`hybmss.stepper`)."""

MIN_STEPS = 20
PROBE_STEPS = 10


def default_variants() -> list[tuple[str, float]]:
    """(model, ν) of the explicit rows: every registered model at ν = 0.499, the registry's
    default model at ν = 1/4 too."""
    return [(m, NU) for m in models.names()] + [(models.default_name(), 0.25)]


def compression_scene(model: str, nu: float, mesh=MESH, le: float = LE, d: float = 0.05) -> Scene:
    """SPEC §6 compression (:mod:`hybmss.experiments`): bottom clamped, top plate moved down by d·H."""
    return SceneSpec.default("compression", mesh=tuple(mesh), le=le, nu=nu, model=model, deformation=d).build()


def mesh_label(mesh) -> str:
    return "x".join(str(int(n)) for n in mesh)


def load_average() -> float | None:
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else None


class _Config:
    """One timed configuration: its scene, system and a warmed-up kernel."""

    def __init__(self, model, nu, mesh, kernel, threads, precision, steps, target_s=TARGET_S, shared=None):
        self.model, self.nu, self.mesh = model, float(nu), tuple(mesh)
        self.kernel, self.threads, self.precision = kernel, int(threads), precision
        # the scene, system and dt_crit of (model, ν, mesh), shared by its configurations
        shared = {} if shared is None else shared
        key = (model, self.nu, self.mesh)
        if key not in shared:
            scene = compression_scene(model, nu, mesh=self.mesh)
            shared[key] = [scene, build(scene), None]
        self.scene, self.system, self.dc = shared[key]
        self.best = (float("inf"), float("inf"), None)
        # warm-up: compiles (or loads from cache) the kernel outside the timings, and refuses a
        # configuration the model does not have before any dt_crit is computed for it
        self._run(2)
        if self.dc is None:
            self.dc = shared[key][2] = dt_crit(self.system)
        if steps is None:  # as many steps as fit in target_s, from probes of a tenth of it
            n = PROBE_STEPS if kernel == "numba" else 1
            while True:
                probe = self._run(n).wall_time_s
                if probe >= 0.1 * target_s or n >= MAX_STEPS:
                    break
                n *= 4
            least = MIN_STEPS if kernel == "numba" else 2  # the NumPy twin of xpbd-nh takes 2 s a step on 10³
            steps = int(min(MAX_STEPS, max(least, target_s * n / max(probe, 1e-9))))
            steps = steps if steps < 100 else steps // 10 * 10
        self.steps = int(steps)

    def _run(self, n, warm_up=0.0):
        return simulate_explicit(self.scene, dt=DT, steps=n, kernel=self.kernel, threads=self.threads,
                                 precision=self.precision, system=self.system, dt_crit_value=self.dc,
                                 compute_dt_crit=False, check_every=min(max(n, 1), CHECK_EVERY), warm_up=warm_up)

    def time_once(self):
        """One timed run; the best so far is kept.  :func:`run_bench` calls it round-robin, every
        configuration once per round (module docstring)."""
        r = self._run(self.steps, warm_up=WARM_UP_THREADS if self.threads > 1 else 0.0)
        self.substeps = int(r.info.get("substeps", 1))
        if r.wall_time_s < self.best[0]:
            self.best = (r.wall_time_s, r.info["cpu_time_s"], load_average())

    def row(self) -> dict:
        wall, cpu, load = self.best
        springs = int(len(self.system.spring_k))
        return {
            "model": self.model,
            "nu": self.nu,
            "mesh": mesh_label(self.mesh),
            "kernel": self.kernel,
            "precision": self.precision,
            "threads": self.threads,
            "steps": self.steps,
            "wall_time_s": wall,
            "cpu_time_s": cpu,
            "s_per_10k_steps": wall * 10_000 / self.steps,
            "springs": springs,
            "ns_per_spring_step": wall / self.steps / springs * 1e9 if springs else None,  # None: no springs
            "dt_crit_s": self.dc,
            "substeps": getattr(self, "substeps", 1),  # per step of dt: position-based models
            "load_avg": load,
        }


def time_config(model: str | None = None, nu: float = NU, mesh=MESH, threads: int = 1, precision: str = "f64",
                kernel: str = "numba", steps: int | None = None, repeats: int = 3) -> dict:
    """Best-of-``repeats`` row of one configuration (see :func:`run_bench` for the fields);
    ``model`` None is the registry's default model."""
    model = models.default_name() if model is None else model
    cfg = _Config(model, nu, mesh, kernel, threads, precision, steps)
    for _ in range(max(1, int(repeats))):
        cfg.time_once()
    return cfg.row()


def run_bench(steps: int | None = None, kernels=("numba", "numpy"), quick: bool = False,
              threads=(1, 2), numpy_steps: int | None = None, repeats: int | None = None,
              meshes=None, precisions=("f64", "f32"), variants=None, static: bool = True,
              target_s: float | None = None, static_models=None) -> dict:
    """Time the explicit kernels; returns ``{"explicit": [row, ...], "static": [...],
    "not_run": [...]}`` (the configurations a model refused, with its reason).

    Each row: ``model, nu, mesh, kernel, precision, threads, steps`` (steps actually run),
    ``wall_time_s`` (best of ``repeats``), ``cpu_time_s`` (process CPU time of the best run, all
    threads), ``s_per_10k_steps``, ``springs``, ``ns_per_spring_step``, ``dt_crit_s`` and
    ``load_avg`` (the 1-minute load average at the best run).  Each configuration runs the steps
    that fit in ``target_s`` (default :data:`TARGET_S`; at most :data:`MAX_STEPS`); ``steps`` fixes the Numba steps of
    every configuration and ``numpy_steps`` those of the NumPy twin (first mesh only, one
    thread, float64).  Models whose kernel is serial have no two-thread rows.  The static rows
    solve the first mesh, for the models ``static_models`` (:func:`static_cases`).  ``quick``: the :data:`QUICK_MESH` cube only, float64, one thread,
    runs of :data:`QUICK_TARGET_S`, one repeat (a smoke run, not a measurement).

    The configurations are timed in ``repeats`` rounds, each configuration once per round, rather
    than each one's repeats back to back (:func:`hybmss.timing.time_repeated`, as the static
    rows are): a burst of load on the shared machine then falls on every configuration rather
    than on one only, and the ratios of :func:`format_bench` compare runs made in the same minute.
    """
    if quick:  # one small mesh, one thread, float64: each configuration compiles a kernel of its own
        meshes, threads, precisions = meshes or (QUICK_MESH,), (1,), ("f64",)
    meshes = tuple(tuple(m) for m in (meshes or MESHES))
    variants = tuple(variants) if variants is not None else tuple(default_variants())
    if repeats is None:
        repeats = 1 if quick else 3
    configs = []

    target = target_s or (QUICK_TARGET_S if quick else TARGET_S)

    skipped, shared = {}, {}

    def add(*cfg):
        if not models.get(cfg[0]).supports("explicit", cfg[3]):
            return
        try:
            configs.append(_Config(*cfg, target_s=target, shared=shared))
        except ValueError as exc:  # a precision, kernel or thread count the model does not have
            skipped.setdefault((cfg[0], str(exc)), []).append(f"{mesh_label(cfg[2])} {cfg[5]} {cfg[4]} thr")

    for mesh in meshes:
        for model, nu in variants:
            for kernel in kernels:
                if kernel == "numpy":
                    if mesh != meshes[0]:
                        continue
                    add(model, nu, mesh, "numpy", 1, "f64", numpy_steps)
                    continue
                for prec in precisions:
                    for th in threads:
                        add(model, nu, mesh, kernel, th, prec, steps)
    for _ in range(repeats):
        for cfg in configs:
            cfg.time_once()
    rows = [c.row() for c in configs]
    return {"explicit": rows, "static": static_bench(quick=quick, repeats=repeats, mesh=meshes[0], names=static_models) if static else [],
            "cores": os.cpu_count(),
            "not_run": [{"model": m, "reason": why, "configurations": c} for (m, why), c in skipped.items()]}


def static_cases(names=None) -> list[tuple[str, float, float]]:
    """(model, ν, d) of the static rows of the models ``names`` (default: every registered model
    with a static solver, in the registry's order, but those an engine runs, kernel ``engine``:
    their static answer is a run of the engine's own step, timed in its results' ``info``): the
    first at ν = 1/4 and 0.499 (5 %) and at 20 %, every other one at ν = 0.3 (5 %)."""
    names = list(names) if names is not None else [m.name for m in models.all_models()
                                                   if m.supports("static") and "engine" not in m.kernels]
    return ([(names[0], 0.25, 0.05), (names[0], 0.499, 0.05)] + [(m, 0.3, 0.05) for m in names[1:]]
            + [(names[0], 0.25, 0.20)])


def static_bench(quick: bool = False, repeats: int | None = None, mesh=None, names=None) -> list[dict]:
    """Wall time of the static Newton solve of the compression cube ``mesh`` (default the 10³
    cube, :data:`QUICK_MESH` when ``quick``; best of ``repeats`` after one untimed solve that
    fills the sparsity pattern cache, :func:`hybmss.timing.time_repeated`) of the models ``names``
    (:func:`static_cases`).  ``quick``: the first case of :func:`static_cases` only."""
    reps = repeats or (1 if quick else 3)
    mesh = tuple(mesh) if mesh is not None else (QUICK_MESH if quick else MESH)
    cases = static_cases(names)[:1] if quick else static_cases(names)
    rows = []
    for model, nu, d in cases:
        scene = compression_scene(model, nu, mesh=mesh, d=d)
        system = build(scene)
        last = []

        def solve(scene=scene, system=system):
            last[:] = [solve_static(scene, system=system)]

        timing = time_repeated(solve, repeats=reps, warmup=1)  # the warm-up fills the pattern cache
        res = last[0]
        rows.append({"scene": f"compression d={100 * d:g}% {model} nu={nu:g}", "mesh": mesh_label(mesh),
                     "wall_time_s": timing.best, "newton_iterations": res.iterations,
                     "load_steps": res.info["load_steps"]})
    return rows


def _pick(rows, **key):
    for r in rows:
        if all(r.get(k) == v for k, v in key.items()):
            return r
    return None


def format_bench(d: dict) -> str:
    """Readable table of :func:`run_bench`'s result, with the ratios measured in the same run:
    float32 / float64, two threads / one, Numba / NumPy, each model over the fastest one and over
    the reference model (the registry's default model, hybmss) at the same ν (float64, one
    thread; [G20] C++: hybmss-cf/hybmss-fd 1.4, hybmss/hybmss-fd 2.1)."""
    rows = d.get("explicit", [])
    out = ["explicit dynamics, compression cube (dt = 1 ms; time per 10,000 steps, best of the repeats)", ""]
    head = (f"{'model':<10} {'nu':>6} {'mesh':>9} {'kernel':>6} {'prec':>4} {'thr':>3} {'steps':>6} "
            f"{'wall s':>8} {'cpu s':>8} {'s/10k':>8} {'ns/spr/step':>11} {'load':>5}")
    out += [head, "-" * len(head)]
    for r in rows:
        load = r.get("load_avg")
        out.append(
            f"{r['model']:<10} {r['nu']:>6g} {r['mesh']:>9} {r['kernel']:>6} {r.get('precision', 'f64'):>4} "
            f"{r['threads']:>3} {r['steps']:>6} {r['wall_time_s']:>8.3f} {r.get('cpu_time_s', float('nan')):>8.3f} "
            f"{r['s_per_10k_steps']:>8.3f} {(r.get('ns_per_spring_step') or float('nan')):>11.2f} "
            f"{load if load is not None else float('nan'):>5.2f}"
        )
    loads = [r["load_avg"] for r in rows if r.get("load_avg") is not None]
    if loads:
        out.append(f"(1-min load average {min(loads):.2f}-{max(loads):.2f} on {d.get('cores') or os.cpu_count()} "
                   "cores during the runs: above the core count, figures are not the kernel's)")
    out += ["", "ratios in this run (time per step)"]
    reference = models.default_name()
    meshes = sorted({r["mesh"] for r in rows}, key=lambda m: int(m.split("x")[0]))
    for mesh in meshes:
        own = [(r["s_per_10k_steps"], r["model"], r["nu"]) for r in rows if r["mesh"] == mesh
               and (r["kernel"], r.get("precision", "f64"), r["threads"]) == ("numba", "f64", 1)]
        fastest = min(own) if own else None
        for model, nu in sorted({(r["model"], r["nu"]) for r in rows if r["mesh"] == mesh}):
            base = dict(mesh=mesh, model=model, nu=nu, kernel="numba")
            parts = []
            for th in (1, 2):
                a, b = _pick(rows, **base, precision="f32", threads=th), _pick(rows, **base, precision="f64", threads=th)
                if a and b:
                    parts.append(f"f32/f64 ({th} thr) {a['s_per_10k_steps'] / b['s_per_10k_steps']:.2f}")
            for prec in ("f64", "f32"):
                a, b = _pick(rows, **base, precision=prec, threads=1), _pick(rows, **base, precision=prec, threads=2)
                if a and b:
                    parts.append(f"speed-up 2 thr/1 ({prec}) {a['s_per_10k_steps'] / b['s_per_10k_steps']:.2f}")
            a = _pick(rows, **base, precision="f64", threads=1)
            b = _pick(rows, mesh=mesh, model=model, nu=nu, kernel="numpy")
            if a and b:
                parts.append(f"numba/numpy {a['s_per_10k_steps'] / b['s_per_10k_steps']:.3f}")
            if a and fastest and (model, nu) != fastest[1:]:
                parts.append(f"/{fastest[1]}(nu={fastest[2]:g}) {a['s_per_10k_steps'] / fastest[0]:.2f}")
            ref = _pick(rows, mesh=mesh, model=reference, nu=nu, kernel="numba", precision="f64", threads=1)
            if a and ref and model != reference and (not fastest or fastest[1:] != (reference, nu)):
                parts.append(f"/{reference}(nu={nu:g}) {a['s_per_10k_steps'] / ref['s_per_10k_steps']:.2f}")
            if a and a.get("substeps", 1) > 1:
                parts.append(f"{a['substeps']} substeps per step")
            if parts:
                out.append(f"  {mesh} {model} nu={nu:g}: " + ";  ".join(parts))
    for r in d.get("not_run", []):
        out.append(f"  not run: {r['model']} {', '.join(r['configurations'])}: {r['reason']}")
    static = d.get("static", [])
    if static:
        out += ["", "static solves"]
        for r in static:
            out.append(f"  {r.get('scene', '')} {r.get('mesh', '')}: {r['wall_time_s']:.3f} s"
                       f"  ({r.get('newton_iterations', '?')} Newton iterations, {r.get('load_steps', '?')} load steps)")
    return "\n".join(out)
