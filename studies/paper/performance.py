"""Performance of the explicit kernel: [G20] Figs 11–12 and Table 6.

Wall time of ``steps`` (1,000; fewer on the largest grids, :func:`timed_steps`) semi-implicit
Euler steps of

- the compression scene on the cubes 10³, 15³, 20³, 30³ (dt = 1 ms, the publication's);
- the beam under gravity (the bending scene, E = 10 MPa) on 4×4×24, 8×8×48, 10×10×60,
  16×16×96 ([G20] ran 300,000 steps; the per-step figure is what compares).  The stiff beam
  needs a smaller step than 1 ms: ``dt = ½ dt_crit`` of the finest beam (the cost of a step does
  not depend on dt);

for the variants :func:`variants`: every model of the ``performance`` role that [G20] reports
(``published``; hybmss, hybmss-fd and hybmss-cf) at ν = 0.3 (≠ ¼, so the volume term is present)
and [G20]'s proposed model at ν = ¼ (κ = 0: :func:`hybmss.system.build` drops the volume term,
so it should cost what the springs-only lattice costs), with the numba stencil kernel on 1 and 2
threads.  Times are divided by those of [G20]'s model without face diagonals (the ``baseline``
of its ratios) and of its springs-only lattice on the same mesh and thread count; the
publication's ratios (``studies/data/g20_performance.csv``) are joined by its names for the models.

**Timing protocol.**  The machine is shared, so every figure is the best of ``repeats`` runs,
each of ``steps`` steps or, where ``repeats`` of them would span less than :data:`MIN_SPAN`,
of the multiple of ``steps`` that does (:func:`run_steps`: a first round of ``steps`` measures
a step), and the variants of one mesh and thread count are timed round-robin (variant 1, 2, 3, 4, then
again) so that the ratios compare runs made in the same minute.  Every timed run on several
threads follows :data:`hybmss.explicit.WARM_UP_THREADS` of untimed steps, so that it is not
timed while the second core wakes up.  ``wall_time_s`` of
:func:`hybmss.explicit.simulate_explicit` is the stepping alone (no set-up, no dt_crit).

**Bandwidth ceiling.**  The memory bandwidth is measured in the same run with NumPy on arrays
far larger than the caches: ``np.copyto(b, a)`` (2 streams of 8 B per element) and
``np.add(a, b, out=c)`` (3 streams); the best of several trials of either is the ceiling.  The
bytes one step must move follow the stencil kernel's streaming model (8-byte words per grid node
of the ``(nx+1)(ny+1)(nz+1)`` grid, each array counted once per pass that reads or writes it,
caches ignored): springs ``7 n_off`` (K read, T written then read back, ×3 components) +
``22`` (x read twice, v read and written, x written, F written then read, 1/m) ; volume
``+ 64`` (κ and V₀, averaged edges ABC written and read, cross products and W written and
read, 12 corner gradients written and read); gravity ``+ 3``.  ``n_off`` = 13 with face
diagonals, 7 without.  Small meshes fit in the caches, so their fraction can exceed 1: the
ceiling is DRAM bandwidth.
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from hybmss.explicit import WARM_UP_THREADS

from studies.paper import values as paper

from studies.paper import publications

from studies.sweep import roles
from studies.sweep.scenes import SceneSpec
from studies.sweep.store import Store

PUBLICATION = "G20"

CUBES = ((10, 10, 10), (15, 15, 15), (20, 20, 20), (30, 30, 30))
BEAMS = ((4, 4, 24), (8, 8, 48), (10, 10, 60), (16, 16, 96))
QUICK_CUBES = ((4, 4, 4),)
QUICK_BEAMS = ((2, 2, 12),)
"""The meshes of ``--quick``: one of each body.  Each mesh costs its own kernels (per variant and
thread count, :func:`compile_kernels`): with two of each body the quick study compiled 24 kernels
in 38.9 s of its 48.8 s (cold cache, 2 workers), the timing itself 8.5 s; the reproduction's
scaling against the mesh is the full study's."""
NU_OTHER = 0.3
NU_QUARTER = 0.25
THREADS = (1, 2)
QUICK_THREADS = (1,)
"""The thread counts of ``--quick``: one.  Its lattices have two blocks of 64 nodes, so on two
threads each thread would recompute the other's block as its halo: a figure of the barrier, not
of the kernel.  Its two-thread kernels were 8 of the 10 it compiled (about 40 s of CPU on 2
workers, cold, of a quick study of 29 s); the one-thread ones are those the quick runs compiled."""
BEAM_E = 1e7
CUBE_DT = 1e-3
WORD = 8  # bytes (float64)
MIN_SPAN = 0.5
"""Seconds of stepping each figure spans at least (short runs get more steps, :func:`run_steps`)."""
MAX_NODE_STEPS = 10_000_000
"""Grid nodes × steps of one timed run at most (:func:`timed_steps`): the 30³ cube and the
16×16×96 beam (~3·10⁴ nodes) run 300 steps instead of 1,000, about 0.4 s on one thread (three
rounds still span over 1 s)."""
MAX_REPEATS = 25
"""A figure spans at most the steps of this many runs of ``steps`` (:func:`run_steps`)."""
CALL_SECONDS = 0.5
"""Seconds of stepping per kernel call of a timed run, at most about (:func:`check_steps`): a run
longer than that is called in pieces, between which Ctrl-C stops it; a shorter one (most of
them) is one call, as before.  Each further call costs a divergence check (one pass over the
nodes) and, on two threads, a start of the threads."""
MIN_CHECK_STEPS = 100


# ------------------------------------------------------------------------------ bandwidth
def measure_bandwidth(n_bytes: int = 256 * 2**20, trials: int = 5) -> dict:
    """Memory bandwidth (GB/s) of NumPy streaming kernels on arrays of ``n_bytes`` each:
    ``copy`` (np.copyto, 2 streams) and ``add`` (c = a + b, 3 streams); best of ``trials``."""
    n = n_bytes // WORD
    a = np.ones(n)
    b = np.full(n, 2.0)
    c = np.empty(n)
    best = {"copy": 0.0, "add": 0.0}
    for _ in range(trials):
        t0 = time.perf_counter()
        np.copyto(b, a)
        dt = time.perf_counter() - t0
        best["copy"] = max(best["copy"], 2 * n * WORD / dt / 1e9)
        t0 = time.perf_counter()
        np.add(a, b, out=c)
        dt = time.perf_counter() - t0
        best["add"] = max(best["add"], 3 * n * WORD / dt / 1e9)
    best["ceiling"] = max(best["copy"], best["add"])
    best["array_MB"] = n_bytes / 2**20
    return best


def last_level_cache_bytes(root: str = "/sys/devices/system/cpu/cpu0/cache") -> int | None:
    """Size in bytes of this machine's last-level CPU cache (the highest level Linux's sysfs lists
    for CPU 0, e.g. ``index3/size`` "32768K"), None where it lists none.  A timed mesh whose step
    streams more than this (:func:`bytes_per_step`) is bound by DRAM traffic, which a virtual
    machine shares with its neighbours."""
    import glob
    import os

    best = None
    for d in glob.glob(os.path.join(root, "index*")):
        try:
            with open(os.path.join(d, "level")) as fh:
                level = int(fh.read())
            with open(os.path.join(d, "size")) as fh:
                size = fh.read().strip().upper()
            n = int(size[:-1]) * {"K": 2**10, "M": 2**20, "G": 2**30}[size[-1]] if size[-1] in "KMG" else int(size)
        except (OSError, ValueError, KeyError, IndexError):
            continue
        if best is None or level > best[0]:
            best = (level, n)
    return best[1] if best else None


def bytes_per_step(n_grid: int, n_off: int, has_volume: bool, has_gravity: bool) -> int:
    """Bytes one explicit step streams under the model of the module docstring."""
    words = 7 * n_off + 22 + (64 if has_volume else 0) + (3 if has_gravity else 0)
    return int(words * WORD * n_grid)


# ------------------------------------------------------------------------------ variants
def variants() -> tuple[tuple[str, float], ...]:
    """(model, ν) of every timed variant: the ``performance`` models [G20] reports at
    :data:`NU_OTHER`, then its proposed model at ν = ¼ (registry order)."""
    timed = [m for m in roles.in_role("performance") if publications.published_name(m, PUBLICATION)]
    out = [(m, NU_OTHER) for m in timed]
    proposed = publications.model_in(PUBLICATION, "proposed")
    if proposed in timed:
        out.append((proposed, NU_QUARTER))
    return tuple(out)


def baseline() -> str | None:
    """The model the time ratios divide by: [G20]'s model without face diagonals."""
    return publications.model_in(PUBLICATION, "no-face-diagonals")


# ------------------------------------------------------------------------------ scenes
def _spec(kind: str, mesh, model: str, nu: float) -> SceneSpec:
    if kind == "compression":
        return SceneSpec.default("compression", mesh=mesh, nu=nu, model=model, deformation=0.05, damping=2.0)
    return SceneSpec.default("bending", mesh=mesh, nu=nu, model=model, E=BEAM_E, gravity=10.0, damping=2.0)


def beam_dt(meshes) -> float:
    """½ dt_crit of the finest beam: dt_crit (∝ le at fixed material) is computed on the
    coarsest beam for each variant, the smallest is scaled to the finest le."""
    from hybmss.explicit import dt_crit

    coarse = min(meshes, key=lambda m: m[2])
    fine = max(meshes, key=lambda m: m[2])
    dts = [dt_crit(_spec("beam", coarse, m, nu).build()) for m, nu in variants()]
    return 0.5 * min(dts) * coarse[2] / fine[2]


# ------------------------------------------------------------------------------ compiling
def kernel_cached(key: str) -> bool:
    """Whether the generated kernel ``key`` is in the kernel cache with Numba's index of its
    machine code beside it (:func:`hybmss._stencil_gen.cache_dir`; with ``NUMBA_CACHE_DIR`` set
    the index is elsewhere and this says False).  A kernel said cached that is not is compiled by
    its first timed figure's untimed 0-step call, outside the timed span."""
    import os

    from hybmss._stencil_gen import cache_dir

    d = cache_dir()
    name = f"hybmss_stencil_{key}"
    if os.environ.get("NUMBA_CACHE_DIR") or not os.path.exists(os.path.join(d, name + ".py")):
        return False
    index = os.path.join(d, "__pycache__")
    return os.path.isdir(index) and any(f.startswith(name + ".") and f.endswith(".nbi") for f in os.listdir(index))


def _compile_one(job: tuple) -> tuple:
    """Compile (into the on-disk kernel cache) the kernel of one configuration: two steps of it."""
    from hybmss.explicit import simulate_explicit

    kind, mesh, model, nu, threads, dt = job
    simulate_explicit(_spec(kind, mesh, model, nu).build(), dt=dt, steps=2, threads=threads,
                      compute_dt_crit=False)
    return job


def compile_kernels(jobs: list[tuple], threads=THREADS, workers: int | None = None, progress: bool = False,
                    runner=None) -> int:
    """Compile the generated kernel of every configuration the timings will run, ``workers``
    processes at a time, before any is timed: each (mesh, offsets, terms, threads) has its own
    kernel (:mod:`hybmss._stencil_gen`), about 3 s of compilation on one thread and 6 s on two
    (the 10³ cube at ν = 0.499), most of it Numba's type inference of the step bodies.  The
    timings then load them from the cache.  A kernel already in the cache (:func:`kernel_cached`)
    is not loaded again here.  ``jobs``: (kind, mesh, dt); ``runner``: whose session's workers
    compile (:func:`studies.sweep.executors.map_local`); returns the kernels compiled."""
    from studies.sweep.executors import map_local

    todo = compile_jobs(jobs, threads)
    if not todo:
        return 0
    if progress:
        print(f"performance: compiling {len(todo)} kernels", flush=True)
    map_local(_compile_one, todo, workers, runner)
    return len(todo)


def compile_jobs(jobs: list[tuple], threads=THREADS) -> list[tuple]:
    """The jobs of :func:`_compile_one` for the kernels of ``jobs`` ((kind, mesh, dt)) on
    ``threads`` that are not in the kernel cache, one per kernel, the longest (two threads, large
    meshes) first, so that no worker is left with one at the end."""
    from hybmss.explicit import stencil
    from hybmss.system import build

    todo = {}
    for kind, mesh, dt in jobs:
        for model, nu in variants():
            S = build(_spec(kind, mesh, model, nu).build())
            for th in threads:
                key = stencil(S, dt, 1.0, threads=th).config.key()
                if not kernel_cached(key):
                    todo.setdefault(key, (kind, mesh, model, nu, th, dt))
    return sorted(todo.values(), key=lambda j: (-j[4], -int(np.prod(j[1]))))


def timed_meshes(quick: bool = False, cubes=None, beams=None) -> list[tuple]:
    """(kind, mesh, dt) of every timed mesh: ``cubes`` and ``beams`` (the default lists of
    ``quick``) at dt = 1 ms and :func:`beam_dt`."""
    cubes = tuple(cubes) if cubes is not None else (QUICK_CUBES if quick else CUBES)
    beams = tuple(beams) if beams is not None else (QUICK_BEAMS if quick else BEAMS)
    dt_b = beam_dt(beams) if beams else CUBE_DT
    return [("compression", m, CUBE_DT) for m in cubes] + [("beam", m, dt_b) for m in beams]


def calls(quick: bool = False) -> list:
    """The kernels :func:`run` compiles, as the sweep's calls
    (:class:`studies.sweep.executors.Call`; compiled into the kernel cache, which :func:`run`
    then finds them in)."""
    from studies.sweep.executors import Call

    threads = QUICK_THREADS if quick else THREADS
    return [Call(None, _compile_one, job) for job in compile_jobs(timed_meshes(quick), threads)]


# ------------------------------------------------------------------------------ timing
def timed_steps(mesh, steps: int) -> int:
    """Steps of one timed run on ``mesh`` (cells per axis): ``steps``, or fewer (in hundreds, at
    least 100) where the grid has so many nodes that ``steps`` would exceed :data:`MAX_NODE_STEPS`."""
    nodes = int(np.prod([n + 1 for n in mesh]))
    if steps * nodes <= MAX_NODE_STEPS:
        return steps
    return min(steps, max(100, 100 * (MAX_NODE_STEPS // (100 * nodes))))


def check_steps(steps: int, step_s: float) -> int:
    """Steps between the divergence checks of a timed run of ``steps`` steps of about ``step_s``
    seconds each: the loop calls the kernel in whole multiples of them, so a run is one call when
    it lasts under :data:`CALL_SECONDS`, else calls of about that long (at least
    :data:`MIN_CHECK_STEPS` steps)."""
    per_call = int(CALL_SECONDS / max(float(step_s), 1e-9))
    return max(1, min(int(steps), max(MIN_CHECK_STEPS, per_call)))


def run_steps(steps: int, t_est: float, repeats: int, min_span: float = MIN_SPAN) -> int:
    """Steps of each of the ``repeats`` timed runs of a figure whose run of ``steps`` steps took
    about ``t_est`` seconds: ``steps`` when ``repeats`` such runs span ``min_span``, else the
    smallest multiple ``k · steps`` with which they do (at most the span of :data:`MAX_REPEATS`
    runs of ``steps``).  A short run is lengthened rather than repeated more often: each run
    has its set-up, final state and (two threads) warm-up outside the timed span, which cost
    more than the stepping of the smallest meshes."""
    if repeats * t_est >= min_span:
        return int(steps)
    k = int(np.ceil(min_span / (repeats * max(t_est, 1e-6))))
    return int(steps) * max(1, min(k, int(np.ceil(MAX_REPEATS / repeats))))


def _time_threads(systems: dict, dt: float, steps: int, repeats: int, th: int, min_span: float) -> dict:
    """``{variant: (steps, [seconds, ...])}`` on ``th`` threads: a first round of ``steps``
    steps, whose slowest run sets the steps of the rounds (:func:`run_steps`); it is the first
    of the ``repeats`` rounds when they keep ``steps``, else only the measure of a step.  Each
    round runs every variant once (round-robin) rather than each variant's repeats back to back
    (:func:`hybmss.timing.time_repeated`): a burst of load on the shared machine then falls on
    every variant of a round, and the ratios between variants compare runs of the same minute."""
    from hybmss.explicit import simulate_explicit

    step_s = {}

    def timed_run(v, n):
        scene, S = systems[v]
        t = simulate_explicit(scene, dt=dt, steps=n, threads=th, system=S, compute_dt_crit=False,
                              check_every=check_steps(n, step_s[v]),
                              warm_up=WARM_UP_THREADS if th > 1 else 0.0).wall_time_s
        step_s[v] = min(step_s[v], t / n)  # the warm-up's 5 steps overstate a step up to 4x
        return t

    for v, (scene, S) in systems.items():  # warm-up (loads the cached compiled kernels), a first figure
        step_s[v] = simulate_explicit(scene, dt=dt, steps=5, threads=th, system=S,
                                      compute_dt_crit=False).wall_time_s / 5
    first = {v: timed_run(v, steps) for v in systems}  # round-robin, as every round
    n = run_steps(steps, max(first.values()), repeats, min_span)
    times = {v: [first[v]] if n == steps else [] for v in systems}
    for _ in range(repeats - (1 if n == steps else 0)):
        for v in systems:
            times[v].append(timed_run(v, n))
    return {v: (n, ts) for v, ts in times.items()}


def time_mesh(kind: str, mesh, dt: float, steps: int, repeats: int, threads=THREADS,
              min_span: float = MIN_SPAN) -> list[dict]:
    """Best-of-``repeats`` wall time of at least ``steps`` steps (:func:`run_steps`) for every
    variant and thread count on one mesh (variants timed round-robin)."""
    from hybmss.explicit import stencil
    from hybmss.system import build

    systems = {}
    for model, nu in variants():
        scene = _spec(kind, mesh, model, nu).build()
        systems[(model, nu)] = (scene, build(scene))
    rows = []
    for th in threads:
        for (model, nu), (n, ts) in _time_threads(systems, dt, steps, repeats, th, min_span).items():
            scene, S = systems[(model, nu)]
            st = stencil(S, dt, 1.0)
            counts = S.lattice.counts()
            rows.append({
                "scene": kind,
                "mesh": "x".join(map(str, mesh)),
                "variant": model,
                "nu": nu,
                "label": f"{model} ν={nu:g}",
                "threads": th,
                "steps": n,
                "dt": dt,
                "best_s": float(min(ts)),
                "median_s": float(np.median(ts)),
                "repeats": len(ts),
                "volumes": counts["volumes"],
                "vertices": counts["vertices"],
                "springs": int(len(S.spring_k)),
                "springs_paper_no_fd": counts["paper_springs_no_fd"],
                "springs_paper_with_fd": counts["paper_springs_with_fd"],
                "volume_term": bool(S.has_volume),
                "gravity_term": S.gravity is not None,
                "stencil_offsets": int(len(st.offs)),
                "grid_nodes": st.N,
                "bytes_per_step": bytes_per_step(st.N, len(st.offs), S.has_volume, S.gravity is not None),
            })
    return rows


def _ratios_to(df: pd.DataFrame, model: str | None, nu: float) -> np.ndarray:
    """``best_s`` of each row over that of ``model`` at ``nu`` on the same scene, mesh, threads."""
    key = ["scene", "mesh", "threads"]
    ref = df[(df["variant"] == model) & (df["nu"] == nu)].set_index(key)["best_s"]
    return df["best_s"].to_numpy() / ref.reindex(pd.MultiIndex.from_frame(df[key])).to_numpy()


def _derive(df: pd.DataFrame, bandwidth: dict) -> pd.DataFrame:
    published = paper.load("g20_performance")
    df = df.copy()
    df["per_step_us"] = 1e6 * df["best_s"] / df["steps"]
    df["per_10k_steps_s"] = 1e4 * df["best_s"] / df["steps"]
    df["springs_per_s"] = df["springs"] * df["steps"] / df["best_s"]
    df["cells_per_s"] = df["volumes"] * df["steps"] / df["best_s"]
    df["achieved_GBps"] = df["bytes_per_step"] * df["steps"] / df["best_s"] / 1e9
    df["bandwidth_GBps"] = bandwidth["ceiling"]
    df["fraction_of_bandwidth"] = df["achieved_GBps"] / bandwidth["ceiling"]
    base, springs = baseline(), publications.model_in(PUBLICATION, "springs-only")
    df["baseline"], df["springs_only"] = base or "", springs or ""
    df["ratio_to_baseline"] = _ratios_to(df, base, NU_OTHER)
    df["ratio_to_springs_only"] = _ratios_to(df, springs, NU_OTHER)
    # the relative spread of one figure (median vs best) is the noise of the comparison
    df["noise"] = df["median_s"] / df["best_s"] - 1.0
    other = df["nu"] != NU_QUARTER
    df["paper_ratio_to_baseline"] = np.nan
    df["paper_per_10k_steps_s"] = np.nan
    cube10 = (df["scene"] == "compression") & (df["mesh"] == "10x10x10") & (df["threads"] == 1)
    for p in published.itertuples():
        timed = df["variant"] == publications.model_named(PUBLICATION, p.name)
        at = other if p.nu == "other" else ~other
        if p.quantity == "time_ratio_per_step" and publications.model_named(PUBLICATION, p.over) == base:
            df.loc[timed & at, "paper_ratio_to_baseline"] = p.value
        elif p.quantity == "time_10k_steps":
            df.loc[timed & at & cube10, "paper_per_10k_steps_s"] = p.value
    return df


SUMMARY_COLUMNS = ["scene", "mesh", "threads", "volumes", "variant", "nu", "label", "per_step_us", "baseline",
                   "ratio_to_baseline", "paper_ratio_to_baseline", "springs_only", "ratio_to_springs_only", "noise"]


def summary(df: pd.DataFrame) -> pd.DataFrame:
    """Per mesh, thread count and variant: time per step, its ratio to the baseline (and the
    publication's) and to the springs-only lattice, and the noise of the figure."""
    return df[SUMMARY_COLUMNS].reset_index(drop=True)


def run_performance(quick: bool = False, steps: int | None = None, repeats: int | None = None,
                    threads=None, progress: bool = False, min_span: float = MIN_SPAN,
                    bandwidth_MB: int | None = None, cubes=None, beams=None,
                    workers: int | None = None, runner=None) -> tuple[pd.DataFrame, dict]:
    """Time every mesh (``cubes``/``beams`` replace the default lists; the kernels compiled first
    on ``workers`` processes or ``runner``'s, :func:`compile_kernels`; ``threads`` replaces :data:`THREADS`, or
    :data:`QUICK_THREADS` with ``quick``); returns (table, bandwidth)."""
    threads = tuple(threads) if threads is not None else (QUICK_THREADS if quick else THREADS)
    steps = steps or (200 if quick else 1000)
    repeats = repeats or (2 if quick else 3)
    n_bytes = (bandwidth_MB or (64 if quick else 256)) * 2**20
    bw = measure_bandwidth(n_bytes, trials=3 if quick else 5)
    rows = []
    jobs = timed_meshes(quick, cubes, beams)
    compile_kernels(jobs, threads, workers, progress, runner)
    for kind, mesh, dt in jobs:
        if progress:
            print(f"performance: {kind} {'x'.join(map(str, mesh))}", flush=True)
        rows += time_mesh(kind, mesh, dt, timed_steps(mesh, steps), repeats, threads, min_span)
    bw2 = measure_bandwidth(n_bytes, trials=3 if quick else 5)
    bandwidth = {k: max(bw[k], bw2[k]) for k in bw}
    llc = last_level_cache_bytes()
    bandwidth["llc_MB"] = llc / 2**20 if llc else float("nan")
    return _derive(pd.DataFrame(rows), bandwidth), bandwidth


def format_table(df: pd.DataFrame) -> str:
    cols = ["scene", "mesh", "label", "threads", "per_step_us", "ratio_to_baseline", "paper_ratio_to_baseline",
            "per_10k_steps_s", "paper_per_10k_steps_s", "springs_per_s", "cells_per_s",
            "achieved_GBps", "fraction_of_bandwidth"]
    with pd.option_context("display.width", 200, "display.max_columns", 30, "display.float_format",
                           "{:.4g}".format):
        return df[cols].to_string(index=False)


def run(store: Store, quick: bool = False, jobs: int | None = None, progress: bool = True,
        runner=None) -> pd.DataFrame:
    """Study driver (``EXTRA_STUDIES``): the kernels compiled on ``runner``'s workers (or ``jobs``
    processes), the timings serial in this process."""
    df, bw = run_performance(quick=quick, progress=progress, workers=jobs, runner=runner)
    store.write_table("performance", df)
    store.write_table("performance_summary", summary(df))
    store.write_table("bandwidth", pd.DataFrame([bw]))
    return df
