"""Speed of the explicit kernels on the compression cube of SPEC §6 (issue 2, "Speed").

The scene: 10×10×10 cells of 0.5 m, E = 10⁴ Pa, ρ = 1000 kg/m³, bottom clamped, top plate moved
down by 5 % (ramp 1 s), dt = 1 ms, built by :mod:`hybmss.experiments`.  Variants: every model of
the ``performance`` role of the registry at ν = 0.499 (hybmss-cf ignores ν: its springs alone give
ν = 1/4), and the first of them (hybmss) at ν = 1/4 (no volume term: it must cost what hybmss-cf
costs).  Each runs with the Numba kernel on 1 and 2 threads and with the NumPy twin (the kernels
the model supports), the twin running fewer steps (its row says how many; ``s_per_10k_steps``
scales it).

JIT compilation is excluded (a short warm-up run first); each figure is the best of
``repeats`` runs, since other processes on the machine only ever add time.  ``ns_per_spring_step``
divides by the model's merged springs (the count of ``hybmss info``'s ``springs.total``).
The ``static`` list times the static Newton solve of the same cube (:func:`static_bench`).
"""

from __future__ import annotations

import os
import time

from . import models
from .experiments import SceneSpec
from .explicit import dt_crit, simulate_explicit
from .scene import Scene
from .solvers import solve_static
from .system import build

MESH = (10, 10, 10)
LE = 0.5
DT = 1e-3


def variants() -> list[tuple[str, float]]:
    """(model, ν) of the explicit rows: the ``performance`` models at ν = 0.499, the first at 1/4."""
    names = models.in_role("performance")
    return [(m, 0.499) for m in names] + [(names[0], 0.25)]


def compression_scene(model: str, nu: float, mesh=MESH, le: float = LE, d: float = 0.05) -> Scene:
    """SPEC §6 compression (:mod:`hybmss.experiments`): bottom clamped, top plate moved down by d·H."""
    return SceneSpec.default("compression", mesh=mesh, le=le, nu=nu, model=model, deformation=d).build()


def _run(cfg):
    scene, system, kernel, th, n, dc = cfg
    r = simulate_explicit(scene, dt=DT, steps=n, kernel=kernel, threads=th, system=system,
                          dt_crit_value=dc)
    return r.wall_time_s, r.info["cpu_time_s"]


def run_bench(steps: int = 10_000, kernels=("numba", "numpy"), quick: bool = False,
              threads=(1, 2), numpy_steps: int = 500, repeats: int | None = None) -> dict:
    """Time the explicit kernels; returns ``{"explicit": [row, ...], "static": []}``.

    Each row: ``model, nu, mesh, kernel, threads, steps`` (steps actually run),
    ``wall_time_s`` (best of ``repeats``), ``cpu_time_s`` (process CPU time of the best run),
    ``s_per_10k_steps``, ``springs``, ``ns_per_spring_step``, ``dt_crit_s`` and ``load_avg``
    (the machine's 1-minute load average when measured: figures taken under load > cores are
    not the kernel's).  Configurations are timed round-robin, so a burst of load from other
    processes does not fall on one of them only.  ``quick`` runs 1,000 Numba and 50 NumPy steps
    once (a smoke run, not a measurement).
    """
    if quick:
        steps, numpy_steps = min(steps, 1000), min(numpy_steps, 50)
    if repeats is None:
        repeats = 1 if quick else 3
    mesh = "x".join(str(n) for n in MESH)
    configs, meta = [], []
    for model, nu in variants():
        scene = compression_scene(model, nu)
        system = build(scene)
        dc = dt_crit(system)
        for kernel in [k for k in kernels if models.get(model).supports("explicit", k)]:
            n = steps if kernel == "numba" else min(steps, numpy_steps)
            for th in (threads if kernel == "numba" else (1,)):
                # warm-up: compiles (or loads from cache) the kernel outside the timings
                simulate_explicit(scene, dt=DT, steps=2, kernel=kernel, threads=th, system=system,
                                  dt_crit_value=dc)
                configs.append((scene, system, kernel, int(th), int(n), dc))
                meta.append((model, nu, int(len(system.spring_k))))
    best = [(float("inf"), float("inf"))] * len(configs)
    for _ in range(repeats):
        for i, cfg in enumerate(configs):
            wall, cpu = _run(cfg)
            if wall < best[i][0]:
                best[i] = (wall, cpu)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    rows = []
    for (scene, system, kernel, th, n, dc), (model, nu, springs), (wall, cpu) in zip(configs, meta, best):
        rows.append({
            "model": model,
            "nu": nu,
            "mesh": mesh,
            "kernel": kernel,
            "threads": th,
            "steps": n,
            "wall_time_s": wall,
            "cpu_time_s": cpu,
            "s_per_10k_steps": wall * 10_000 / n,
            "springs": springs,
            "ns_per_spring_step": wall / n / springs * 1e9,
            "dt_crit_s": dc,
            "load_avg": load,
        })
    return {"explicit": rows, "static": static_bench(quick=quick, repeats=repeats)}


def static_cases() -> list[tuple[str, float, float]]:
    """(model, ν, d) of the static rows: the first ``performance`` model at ν = 1/4 and 0.499 (5 %)
    and at 20 %, every other one at ν = 0.3 (5 %)."""
    names = models.in_role("performance")
    return ([(names[0], 0.25, 0.05), (names[0], 0.499, 0.05)] + [(m, 0.3, 0.05) for m in names[1:]]
            + [(names[0], 0.25, 0.20)])


def static_bench(quick: bool = False, repeats: int | None = None) -> list[dict]:
    """Wall time of the static Newton solve of the compression cube (best of ``repeats``, after a
    warm-up of the sparsity pattern cache)."""
    reps = repeats or (1 if quick else 3)
    cases = static_cases()[:1] if quick else static_cases()
    rows = []
    for model, nu, d in cases:
        scene = compression_scene(model, nu, d=d)
        system = build(scene)
        solve_static(scene, system=system)  # warm-up
        best, res = float("inf"), None
        for _ in range(reps):
            t0 = time.perf_counter()
            res = solve_static(scene, system=system)
            best = min(best, time.perf_counter() - t0)
        rows.append({"scene": f"compression d={100 * d:g}% {model} nu={nu:g}", "mesh": "x".join(map(str, MESH)),
                     "wall_time_s": best, "newton_iterations": res.iterations,
                     "load_steps": res.info["load_steps"]})
    return rows


def _ratio(rows, kernel, threads, num, den):
    def get(model, nu):
        for r in rows:
            if (r["model"], r["nu"], r["kernel"], r["threads"]) == (model, nu, kernel, threads):
                return r["s_per_10k_steps"]
        return None

    a, b = get(*num), get(*den)
    return None if a is None or b is None else a / b


def format_bench(d: dict) -> str:
    """Readable table of :func:`run_bench`'s result, with the ratios of [G20] Figs 11–12."""
    rows = d.get("explicit", [])
    out = ["explicit dynamics, compression cube (dt = 1 ms; time per 10,000 steps)", ""]
    head = f"{'model':<10} {'nu':>6} {'mesh':>9} {'kernel':>6} {'thr':>3} {'steps':>6} " \
           f"{'wall s':>8} {'cpu s':>8} {'s/10k':>8} {'springs':>7} {'ns/spr/step':>11} {'dt_crit s':>9}"
    out += [head, "-" * len(head)]
    for r in rows:
        out.append(
            f"{r['model']:<10} {r['nu']:>6g} {r['mesh']:>9} {r['kernel']:>6} {r['threads']:>3} "
            f"{r['steps']:>6} {r['wall_time_s']:>8.3f} {r.get('cpu_time_s', float('nan')):>8.3f} "
            f"{r['s_per_10k_steps']:>8.3f} "
            f"{r.get('springs', 0):>7} {r.get('ns_per_spring_step', float('nan')):>11.2f} "
            f"{r.get('dt_crit_s', float('nan')):>9.4g}"
        )
    if rows and "load_avg" in rows[0]:
        out.append(f"(1-min load average {rows[0]['load_avg']:.2f} on {os.cpu_count()} cores at the end)")
    combos = sorted({(r["kernel"], r["threads"]) for r in rows})
    seen = {(r["model"], r["nu"]) for r in rows}
    pairs = [v for v in variants() if v in seen]
    if combos:
        out += ["", "ratios of the time per step to the fastest variant of each kernel "
                    "([G20] C++: hybmss-cf/hybmss-fd 1.4, hybmss/hybmss-fd 2.1)"]
        for kernel, th in combos:
            own = [(r["s_per_10k_steps"], r["model"], r["nu"]) for r in rows
                   if (r["kernel"], r["threads"]) == (kernel, th)]
            base = min(own)
            parts = [f"  {kernel} {th} thread(s):"]
            for model, nu in pairs:
                val = _ratio(rows, kernel, th, (model, nu), base[1:])
                if val is not None:
                    parts.append(f"{model}(nu={nu:g})/{base[1]}(nu={base[2]:g}) {val:.2f}")
            out.append("  ".join(parts))
        for model, nu in pairs:
            pick = {}
            for r in rows:
                if (r["model"], r["nu"]) == (model, nu):
                    pick[(r["kernel"], r["threads"])] = r["s_per_10k_steps"]
            parts = []
            if ("numba", 1) in pick and ("numba", 2) in pick:
                parts.append(f"speed-up of 2 threads over 1: {pick[('numba', 1)] / pick[('numba', 2)]:.2f}")
            if ("numba", 1) in pick and ("numpy", 1) in pick:
                parts.append(f"numba over numpy: {pick[('numpy', 1)] / pick[('numba', 1)]:.0f}")
            if parts:
                out.append(f"  {model} nu={nu:g}: " + ";  ".join(parts))
    static = d.get("static", [])
    if static:
        out += ["", "static solves"]
        for r in static:
            out.append(f"  {r.get('scene', '')} {r.get('mesh', '')}: {r['wall_time_s']:.3f} s"
                       f"  ({r.get('newton_iterations', '?')} Newton iterations, {r.get('load_steps', '?')} load steps)")
    return "\n".join(out)
