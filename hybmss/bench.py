"""Speed of the explicit kernels on the compression cube of SPEC §6 (issue 2, "Speed").

The scene: 10×10×10 cells of 0.5 m, E = 10⁴ Pa, ρ = 1000 kg/m³, bottom clamped, top plate moved
down by 5 % (ramp 1 s), dt = 1 ms.  Variants: hybmss-fd, hybmss-cf and hybmss at ν = 0.499
(hybmss-cf ignores ν: its springs alone give ν = 1/4), and hybmss at ν = 1/4 (no volume term:
it must cost what hybmss-cf costs).  Each runs with the Numba kernel on 1 and 2 threads and with
the NumPy twin, which runs fewer steps (its row says how many; ``s_per_10k_steps`` scales it).

JIT compilation is excluded (a short warm-up run first); each figure is the best of
``repeats`` runs, since other processes on the machine only ever add time.  ``ns_per_spring_step``
divides by the model's merged springs (the count of ``hybmss info``'s ``springs.total``).
The ``static`` list times the static Newton solve of the same cube (:func:`static_bench`).
"""

from __future__ import annotations

from .explicit import dt_crit, simulate_explicit
from .scene import Body, Material, Model, Motion, Plate, Region, Scene
from .system import build

MESH = (10, 10, 10)
LE = 0.5
DT = 1e-3
VARIANTS = (("hybmss-fd", 0.499), ("hybmss-cf", 0.499), ("hybmss", 0.499), ("hybmss", 0.25))


def compression_scene(model: str, nu: float, mesh=MESH, le: float = LE, d: float = 0.05) -> Scene:
    """SPEC §6 compression: bottom clamped, top plate moved down by d·H."""
    H = mesh[2] * le
    return Scene(
        Body.box(*mesh, le),
        Material(1e4, nu, 1000.0),
        Model(model),
        plates=(
            Plate("bottom", Region("z-")),
            Plate("top", Region("z+"), Motion("translate", (0.0, 0.0, -d * H))),
        ),
        name=f"compression-{model}-nu{nu}",
    )


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
    import os

    if quick:
        steps, numpy_steps = min(steps, 1000), min(numpy_steps, 50)
    if repeats is None:
        repeats = 1 if quick else 3
    mesh = "x".join(str(n) for n in MESH)
    configs, meta = [], []
    for model, nu in VARIANTS:
        scene = compression_scene(model, nu)
        system = build(scene)
        dc = dt_crit(system)
        for kernel in kernels:
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


STATIC_CASES = (("hybmss", 0.25, 0.05), ("hybmss", 0.499, 0.05), ("hybmss-fd", 0.3, 0.05), ("hybmss", 0.25, 0.20))


def static_bench(quick: bool = False, repeats: int | None = None) -> list[dict]:
    """Wall time of the static Newton solve of the compression cube (best of ``repeats``, after a
    warm-up of the sparsity pattern cache)."""
    import time

    from .solvers import solve_static

    reps = repeats or (1 if quick else 3)
    cases = STATIC_CASES[:1] if quick else STATIC_CASES
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
        import os

        out.append(f"(1-min load average {rows[0]['load_avg']:.2f} on {os.cpu_count()} cores at the end)")
    combos = sorted({(r["kernel"], r["threads"]) for r in rows})
    if combos:
        out += ["", "ratios (time per step; [G20] C++: cf/fd 1.4, hybmss/fd 2.1)"]
        for kernel, th in combos:
            cf = _ratio(rows, kernel, th, ("hybmss-cf", 0.499), ("hybmss-fd", 0.499))
            hy = _ratio(rows, kernel, th, ("hybmss", 0.499), ("hybmss-fd", 0.499))
            q = _ratio(rows, kernel, th, ("hybmss", 0.25), ("hybmss-cf", 0.499))
            parts = [f"  {kernel} {th} thread(s):"]
            for label, val in (("hybmss-cf/hybmss-fd", cf), ("hybmss/hybmss-fd", hy),
                               ("hybmss(nu=0.25)/hybmss-cf", q)):
                if val is not None:
                    parts.append(f"{label} {val:.2f}")
            out.append("  ".join(parts))
        for model, nu in VARIANTS:
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
