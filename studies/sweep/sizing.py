"""Memory and time a solve would need, estimated from the mesh before it starts.

The command line refuses a run whose estimated peak memory exceeds :data:`MEMORY_FRACTION` of
this machine's physical memory or whose estimated time exceeds :data:`TIME_LIMIT_S` (an hour),
and says how much it would need (``--no-guard`` runs it anyway).  The estimates are fits to
measured peak resident sizes and wall times of 5 % compressions of a cube (2 cores, load ≈ 2):

- mass-spring static solve (Newton, sparse LU of the Hessian): 15³ particles 0.34 GB, 3.3 s;
  21³ particles 1.2 GB, 20 s — memory grows as P^1.5 and time as P^1.8 in the particles P;
- FEM Hex2, linear law: 14,739 dofs 0.43 GB, 3.1 s; 46,875 dofs 0.93 GB, 12.6 s (by refinement
  or by mesh alike) — about 22 kB per dof, time as dofs^1.3; finite-strain laws repeat the solve
  over load steps and Newton iterations;
- explicit dynamics: ≈ 5 ns per spring and step; peak memory of a timed run of the stencil kernel
  (``hybmss bench``, 20 steps) 0.85, 4.9 and 16.0 GB on 30³, 60³ and 90³ cells: about 21 kB per
  particle (2 kB, the arrays alone, was assumed before: a 200³ run it let through was killed for
  want of memory at 22.7 GB).

They are meant to tell a run that fits from one that is off by orders of magnitude, not to
predict to the percent.  A sweep of runs (``hybmss run``) is their sum over its workers, scaled by
what a whole sweep measured (:func:`sweep`, :data:`SWEEP_TIME_FACTOR`).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from hybmss.scene import nearly_incompressible

BASE_BYTES = 150e6
"""Interpreter, NumPy, SciPy, Numba and scikit-fem loaded."""

MEMORY_FRACTION = 0.8
"""Share of the physical memory a single run may plan to use."""

TIME_LIMIT_S = 3600.0
"""Estimated wall time above which a command refuses to start (an hour)."""

SWEEP_TIME_LIMIT_S = 4 * 3600.0
"""The same for a sweep of stored runs (``hybmss run``, four hours): it is stored run by run and an
interrupted sweep resumes where it stopped, so it may run longer than one solve (the full
reproduction: about 1.5 h on two cores)."""


def machine_memory() -> int:
    """Physical memory of this machine, bytes."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # not a POSIX system: assume 8 GiB
        return 8 * 2**30


@dataclass(frozen=True)
class Estimate:
    """Estimated peak memory (bytes) and wall time (s) of one solve."""

    what: str
    bytes: float
    seconds: float
    limit_s: float = TIME_LIMIT_S
    """The estimated time above which it is refused (:data:`TIME_LIMIT_S`, of a sweep
    :data:`SWEEP_TIME_LIMIT_S`)."""


def particles(shape) -> int:
    nx, ny, nz = (int(n) for n in shape)
    return (nx + 1) * (ny + 1) * (nz + 1)


def mss(shape, solver: str = "static", steps: int = 10_000, work: float = 1.0) -> Estimate:
    """A mass-spring solve of a box of ``shape`` cells (an upper bound for a voxel body in it);
    ``work`` multiplies the time (a model's sweeps per step: :func:`model_work`)."""
    P = float(particles(shape))
    if solver == "explicit":
        return Estimate("mass-spring explicit run", BASE_BYTES + 21e3 * P, 13.0 * P * steps * 5e-9 * work)
    ref = P / 9261.0
    bytes_ = BASE_BYTES + 120e3 * P * math.sqrt(ref)
    seconds = 20.0 * ref**1.8 * work
    if solver == "implicit":
        return Estimate("mass-spring implicit run", bytes_, seconds / 5.0 * steps)
    return Estimate("mass-spring static solve", bytes_, seconds)


def fem_dofs(shape, element: str = "hex2", refine: int = 1, nu: float = 0.25) -> int:
    n = [int(s) * int(refine) for s in shape]
    hex1 = math.prod(k + 1 for k in n)
    hex2 = math.prod(2 * k + 1 for k in n)
    if element == "auto":
        element = "mixed" if nearly_incompressible(nu) else "hex2"  # fem_reference's 'auto'
    if element == "hex1":
        return 3 * hex1
    return 3 * hex2 + (hex1 if element == "mixed" else 0)


def fem(shape, element: str = "hex2", refine: int = 1, law: str = "linear", nu: float = 0.25) -> Estimate:
    """A FEM reference solve of a box of ``shape`` cells split ``refine``³ times."""
    if element == "auto":
        element = "mixed" if nearly_incompressible(nu) else "hex2"  # fem_reference's 'auto'
    return fem_of(float(fem_dofs(shape, element, refine, nu)), element, law)


def fem_of(dofs: float, element: str = "hex2", law: str = "linear", what: str = "FEM solve") -> Estimate:
    """A FEM solve of ``dofs`` unknowns: per unknown as measured for Hex1, for Hex2 (an upper
    bound for tetrahedral P2, whose rows couple fewer unknowns) and for the mixed u-p element
    (its Newton solve with the Schur elimination of a large saddle point: 10.5 GB peak for the
    426,000 unknowns of the 2 mm cylinder's 20×20×40 box at refine 2)."""
    per_dof = {"hex1": 8e3, "mixed": 25e3}.get(element, 22e3)
    seconds = 12.6 * (dofs / 46875.0) ** 1.3 * (1.0 if law == "linear" else 15.0)
    return Estimate(f"{what} ({int(dofs):,} dofs)", BASE_BYTES + per_dof * dofs, seconds)


def model_work(params: dict, solver: str = "static") -> float:
    """How many times its default work per step a model's parameters ask for: the projection
    sweeps per substep (``iterations``) and, in an explicit run, the substeps per frame over the
    default 10 (``substeps``; 0 is the automatic choice).  1 for a model without them."""
    work = max(1.0, float(params.get("iterations") or 1))
    if solver == "explicit":
        work *= max(1.0, float(params.get("substeps") or 0) / 10.0)
    return work


def total(what: str, estimates) -> Estimate:
    """Runs one after the other: the largest memory, the sum of the times."""
    estimates = list(estimates)
    return Estimate(what, max((e.bytes for e in estimates), default=BASE_BYTES),
                    sum(e.seconds for e in estimates))


SWEEP_TIME_FACTOR = 1.0
"""Measured wall time of a sweep over the sum of its runs' estimates per worker: the 3,638 pooled
runs of the full reproduction (the budget study at its real sizes, three timed repeats) come to
89 min per worker on two workers and took 87 min (two cores shared with other work, load average
2–7; an idle machine takes less, so the guard errs on the long side).  It was 27/60 when the
reproduction had 1,512 pooled runs and took 23–28 min."""


def sweep(what: str, estimates, workers: int) -> Estimate:
    """Runs shared by ``workers`` processes, each computing one at a time: the memory of every
    worker at the largest run's peak, the sum of the times over the workers (times
    :data:`SWEEP_TIME_FACTOR`)."""
    estimates = list(estimates)
    workers = max(1, int(workers))
    peak = max((e.bytes for e in estimates), default=BASE_BYTES)
    return Estimate(what, BASE_BYTES + workers * peak,
                    SWEEP_TIME_FACTOR * sum(e.seconds for e in estimates) / workers, SWEEP_TIME_LIMIT_S)


def task(spec, solver) -> Estimate:
    """One run of a study: scene ``spec`` (:class:`hybmss.experiments.SceneSpec`) solved by
    ``solver`` (:class:`studies.sweep.runner.SolverSpec`)."""
    if solver.kind == "fem":
        return fem(spec.mesh, solver.element, solver.refine, solver.law, spec.nu)
    steps = getattr(solver, "steps", None) or 10_000
    return mss(spec.mesh, solver.kind, steps, model_work(dict(spec.params), solver.kind))


def limit() -> float:
    return MEMORY_FRACTION * machine_memory()


def fits(est: Estimate) -> bool:
    """True if the estimated memory fits this machine (:data:`MEMORY_FRACTION`)."""
    return est.bytes <= limit()


def in_time(est: Estimate) -> bool:
    """True if the estimated time is within its limit (:data:`TIME_LIMIT_S`; of a sweep
    :data:`SWEEP_TIME_LIMIT_S`)."""
    return est.seconds <= est.limit_s


def size(b: float) -> str:
    for unit, k in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20)):
        if b >= k:
            return f"{b / k:.3g} {unit}"
    return f"{b:.0f} B"


def duration(s: float) -> str:
    for unit, k in (("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if s >= k:
            return f"{s / k:.3g} {unit}"
    return f"{s:.2g} s"


def largest_cube(estimate) -> int:
    """The largest n such that ``estimate((n, n, n))`` fits (0 if none)."""
    lo, hi = 0, 1
    while fits(estimate((hi, hi, hi))):
        lo, hi = hi, hi * 2
        if hi > 1 << 20:
            return lo
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if fits(estimate((mid, mid, mid))) else (lo, mid)
    return lo


def refusal(est: Estimate, estimate=None) -> str:
    """The one-line reason a run of this estimate is refused."""
    cube = ""
    if fits(est) and not in_time(est):
        return (f"the {est.what} would take about {duration(est.seconds)} (and about {size(est.bytes)} of "
                f"memory); allowed: up to {duration(est.limit_s)} (--no-guard runs it anyway)")
    if estimate is not None:
        n = largest_cube(estimate)
        cube = f" (a cube of at most {n}^3 cells at these settings)" if n else " (no mesh fits at these settings)"
    return (f"the {est.what} would need about {size(est.bytes)} of memory and about {duration(est.seconds)}; "
            f"allowed: up to {size(limit())} ({MEMORY_FRACTION:.0%} of this machine's {size(machine_memory())})"
            f"{cube} (--no-guard runs it anyway)")
