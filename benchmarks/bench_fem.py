"""Speed of the FEM references (issue 3): the 10×10×10 cube and the 8×8×48 beam.

``python -m benchmarks.bench_fem [--quick] [--json] [--only NAME ...]`` times, per body,
Hex1, Hex2 and mixed linear solves and a Neo-Hookean solve at 20 % deformation (cube:
bonded compression; beam 0.4 × 0.4 × 2.4 m: tension), including assembly (wall time, and the
process CPU time, which is less sensitive to other load on the machine; BLAS threads can make it
exceed the wall time).  The mixed element runs at ν = 0.499 (its purpose), the others at
ν = 0.25; the cube also has a mixed Neo-Hookean compression at ν = 0.499.  ``beam-bending``
is the Neo-Hookean Hex2 cantilever of the reproduction (4×4×24, clamped at z = 0, gravity
10 m/s² along −y, E = 2 MPa: large rotations).  ``--quick`` uses 4×4×4 and 2×2×12 meshes.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time

import numpy as np

from hybmss.experiments import SceneSpec
from hybmss.scene import Scene


def _scene(kind: str, mesh, le: float, nu: float, d: float) -> Scene:
    """The cube's compression or the beam's tension (:mod:`hybmss.experiments`), E = 1e4 Pa."""
    experiment = "compression" if kind == "cube" else "tension"
    return SceneSpec.default(experiment, mesh=mesh, le=le, E=1e4, nu=nu, deformation=d).build()


def cases(quick: bool = False):
    """(name, scene, solve keyword arguments) of every benchmark case."""
    bodies = {"cube": ((4, 4, 4), 1.25) if quick else ((10, 10, 10), 0.5),
              "beam": ((2, 2, 12), 0.2) if quick else ((8, 8, 48), 0.05)}
    out = []
    for kind, (mesh, le) in bodies.items():
        out += [
            (f"{kind}-hex1", _scene(kind, mesh, le, 0.25, 0.05), dict(element="hex1", law="linear")),
            (f"{kind}-hex2", _scene(kind, mesh, le, 0.25, 0.05), dict(element="hex2", law="linear")),
            (f"{kind}-mixed", _scene(kind, mesh, le, 0.499, 0.05), dict(element="mixed", law="linear")),
            (f"{kind}-neo-hookean-20%", _scene(kind, mesh, le, 0.25, 0.20), dict(element="hex2", law="neo-hookean")),
        ]
        if kind == "cube":
            out.append((f"{kind}-mixed-neo-hookean-20%", _scene(kind, mesh, le, 0.499, 0.20),
                        dict(element="mixed", law="neo-hookean")))
    bmesh, ble = ((2, 2, 12), 0.2) if quick else ((4, 4, 24), 0.1)
    out.append(("beam-bending-neo-hookean", _bending(bmesh, ble), dict(element="hex2", law="neo-hookean")))
    return out


def _bending(mesh, le: float) -> Scene:
    return SceneSpec.default("bending", mesh=mesh, le=le, E=2e6, nu=0.25, gravity=10.0).build()


def run(quick: bool = False, only=None, progress=None) -> dict:
    """Run the cases; ``progress(row)`` is called after each one."""
    from fem_reference import solve

    rows = []
    for name, scene, kw in cases(quick):
        if only and name not in only:
            continue
        t0, c0 = time.perf_counter(), time.process_time()
        res = solve(scene, **kw)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        top = res.reactions["top"].force[2] if "top" in res.reactions else res.reactions["bottom"].force[1]
        rows.append({
            "case": name,
            "mesh": "x".join(map(str, scene.body.shape)),
            "solver": res.solver,
            "nu": scene.material.nu,
            "dofs": res.info["n_dofs"],
            "linear_solver": res.info["linear_solver"]["method"],
            "linear_iterations": res.info["linear_solver"]["iterations"],
            "newton_iterations": res.iterations,
            "newton_steps": res.info.get("newton", {}).get("steps", 0),
            "rejected_steps": res.info.get("newton", {}).get("rejected_steps", 0),
            "time_s": wall,
            "cpu_s": cpu,
            "volume_change": res.volume_change,
            "top_force_z": top,
        })
        if progress is not None:
            progress(rows[-1])
    return {
        "benchmark": "fem",
        "quick": quick,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "rows": rows,
    }


HEADER = (f"{'case':<28}{'mesh':>9}{'nu':>7}{'dofs':>9}{'solver':>12}{'lin.it':>8}{'newton':>7}"
          f"{'steps':>7}{'time s':>9}{'cpu s':>8}{'dV/V %':>10}{'F_top N':>13}")
"""``F_top``: z force of the top plate (bending: y force of the clamp)."""


def format_row(r: dict) -> str:
    return (
        f"{r['case']:<28}{r['mesh']:>9}{r['nu']:>7g}{r['dofs']:>9,}{r['linear_solver']:>12}"
        f"{r['linear_iterations']:>8}{r['newton_iterations']:>7}"
        f"{'%d/%d' % (r['newton_steps'], r['rejected_steps']):>7}{r['time_s']:>9.2f}{r['cpu_s']:>8.1f}"
        f"{100 * r['volume_change']:>10.4f}{r['top_force_z']:>13.6g}"
    )


def format_table(d: dict) -> str:
    return "\n".join([HEADER] + [format_row(r) for r in d["rows"]])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.bench_fem", description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small meshes (seconds)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--only", nargs="*", default=None, help="case names to run")
    args = p.parse_args(argv)
    if args.json:
        d = run(quick=args.quick, only=args.only)
        json.dump(d, sys.stdout, default=float)
        sys.stdout.write("\n")
        return 0
    print(HEADER, flush=True)
    run(quick=args.quick, only=args.only, progress=lambda r: print(format_row(r), flush=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
