"""``python -m benchmarks.static_goals``: CPU time of the static mass-spring solver on the
publication's cases, against its goals (≤ 0.3 s on the 10³ cube, ≤ 1 s on the 8×8×48 beam for a
case that converges, ≤ 10 s to locate and report a lost equilibrium).

Each case is solved once (``--repeat N``: best of N) after a warm-up on a small mesh (Numba
compilation), timed with ``time.process_time`` (CPU of this process: the machine may be shared)
and ``time.perf_counter``; the load average is printed before and after.  ``--save FILE.npz``
stores every case's displacements, top-plate force and counts, ``--compare FILE.npz`` prints the
difference of this run from a stored one (the same answers before and after a change of the
solver), ``-k TEXT`` runs the cases whose name contains TEXT.
"""

from __future__ import annotations

import argparse
import re
import sys
import time

import numpy as np

from hybmss.experiments import SceneSpec
from hybmss.solve import StaticSolveError, solve_static
from studies.paper.publications import models_of

CUBE, BEAM = (10, 10, 10), (8, 8, 48)
CUBE_GOAL, BEAM_GOAL, LOST_GOAL = 0.3, 1.0, 10.0
_G20 = models_of("G20").set_index("role")["model"]
HYB, FD, CF = _G20["proposed"], _G20["no-face-diagonals"], _G20["springs-only"]
"""[G20]'s three mass-spring models, by their part in its claims (studies/data/g20_models.csv)."""
B09 = models_of("B09").set_index("role")["model"]["proposed"]
"""[B09]'s model (residual mode: non-conservative corrections)."""
LOST_MODELS = (HYB, FD)
"""The models whose ν = 0 beam loses its equilibrium in 20 % tension (the report's stability study)."""
WARM_UP_MODELS = (HYB, FD, B09)


def cases() -> list[tuple[str, SceneSpec, float]]:
    """(name, spec, goal in s) of every measured case."""
    out = []
    for d in (0.05, 0.20):
        for model, nu in ((HYB, 0.25), (HYB, 0.499), (FD, 0.25), (FD, 0.499), (CF, 0.25), (CF, 0.499), (B09, 0.25)):
            spec = SceneSpec.default("compression", mesh=CUBE, model=model, nu=nu, deformation=d)
            out.append((f"cube10 compression {d:.0%} {model} nu={nu:g}", spec, CUBE_GOAL))
    for model, nu, d in ((HYB, 0.499, 0.05), (FD, 0.499, 0.05), (FD, 0.499, 0.20)):
        spec = SceneSpec.default("tension", mesh=BEAM, model=model, nu=nu, deformation=d)
        out.append((f"beam8x8x48 tension {d:.0%} {model} nu={nu:g}", spec, BEAM_GOAL))
    for model in LOST_MODELS:
        spec = SceneSpec.default("tension", mesh=BEAM, model=model, nu=0.0, deformation=0.20)
        out.append((f"beam8x8x48 tension 20% {model} nu=0 (lost)", spec, LOST_GOAL))
    return out


def _warm_up() -> None:
    for model in WARM_UP_MODELS:
        solve_static(SceneSpec.default("compression", mesh=(2, 2, 2), model=model, nu=0.3).build())


def run_case(spec: SceneSpec, repeat: int = 1) -> dict:
    """The outcome row (answer, counts, ``cpu`` and ``wall`` seconds) of the solve of least CPU
    time among ``repeat`` solves of ``spec``, each of a scene built afresh outside the timed span.
    Not :func:`hybmss.timing.time_repeated`, which keeps the best wall time of one callable: the
    goals are CPU times (the machine may be shared), the row keeps the wall time and the answer
    of that same solve, and a lost equilibrium (:class:`StaticSolveError`) is a timed outcome too."""
    best = None
    for _ in range(repeat):
        scene = spec.build()
        c0, w0 = time.process_time(), time.perf_counter()
        try:
            res = solve_static(scene)
            row = {"outcome": "ok", "u": res.u, "force": float(res.reactions["top"].force[2]),
                   "iterations": int(res.iterations), "load_steps": int(res.info["load_steps"])}
        except StaticSolveError as exc:
            msg = str(exc)
            m = re.search(r"failed at load factor s=([0-9.eE+-]+) \(last converged s=([0-9.eE+-]+)\)", msg)
            row = {"outcome": "lost" if "limit point" in msg else "failed", "u": None, "force": float("nan"),
                   "iterations": -1, "load_steps": -1,
                   "bracket": (float(m.group(2)), float(m.group(1))) if m else None}
        row["cpu"], row["wall"] = time.process_time() - c0, time.perf_counter() - w0
        if best is None or row["cpu"] < best["cpu"]:
            best = row
    return best


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.static_goals", description=__doc__.splitlines()[0])
    parser.add_argument("-k", default="", help="run only the cases whose name contains this text")
    parser.add_argument("--repeat", type=int, default=1, help="best of N solves per case (default 1)")
    parser.add_argument("--save", default=None, help="store the answers in this .npz file")
    parser.add_argument("--compare", default=None, help="compare the answers with this stored .npz file")
    args = parser.parse_args(argv)

    ref = dict(np.load(args.compare, allow_pickle=True)) if args.compare else None
    _warm_up()
    print(f"load average before: {open('/proc/loadavg').read().strip()}")
    head = f"{'case':52s} {'CPU s':>7s} {'wall s':>7s} {'goal s':>6s} {'met':>4s} {'iter':>5s} {'steps':>5s} {'F_top N':>13s}  outcome"
    if ref is not None:
        head += "   |du|/|u| vs stored, dF/F, CPU ratio"
    print(head)
    saved = {}
    for name, spec, goal in cases():
        if args.k not in name:
            continue
        r = run_case(spec, args.repeat)
        outcome = r["outcome"]
        if r.get("bracket"):
            outcome += f" in s=({r['bracket'][0]:.4f}, {r['bracket'][1]:.4f})"
        line = (f"{name:52s} {r['cpu']:7.2f} {r['wall']:7.2f} {goal:6.1f} {'yes' if r['cpu'] <= goal else 'no':>4s} "
                f"{r['iterations']:5d} {r['load_steps']:5d} {r['force']:13.6g}  {outcome}")
        key = re.sub(r"[^A-Za-z0-9]+", "_", name)
        if ref is not None and f"{key}__cpu" in ref:
            u0 = ref[f"{key}__u"]
            if r["u"] is not None and u0.shape == r["u"].shape:
                du = float(np.abs(r["u"] - u0).max() / max(np.abs(u0).max(), 1e-300))
                dF = abs(r["force"] / float(ref[f"{key}__force"]) - 1.0)
                line += f"   {du:.2e}, {dF:.2e}"
            else:
                line += f"   stored: {ref[f'{key}__outcome']} {ref[f'{key}__bracket']}"
            line += f", {r['cpu'] / float(ref[f'{key}__cpu']):.2f}"
        print(line, flush=True)
        saved.update({f"{key}__u": r["u"] if r["u"] is not None else np.zeros(0),
                      f"{key}__force": r["force"], f"{key}__cpu": r["cpu"],
                      f"{key}__iterations": r["iterations"], f"{key}__outcome": outcome,
                      f"{key}__bracket": np.array(r.get("bracket") or (np.nan, np.nan))})
        if args.save:  # after every case: an interrupted run keeps what it measured
            np.savez(args.save, **saved)
    print(f"load average after: {open('/proc/loadavg').read().strip()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
