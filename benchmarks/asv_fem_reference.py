"""asv: a user study's FEM reference — a voxelized cylinder (R 1 cm, H 4 cm, 4 mm cells: the
160 whose centres are inside), clamped at its base and its top turned by 30° about the axis,
Neo-Hookean, ν = 0.3 (Hex2) and 0.49 (mixed u–p, Hex2 × Hex1), each cell split into
``refine³`` elements.

``time_reference`` solves it as a study's reference does (``method='auto'``): CHOLMOD, for the
mixed element a CHOLMOD factor of the displacement block and CG on the pressure Schur complement,
also at refine 3 (119,614 unknowns for ν = 0.49), where the saddle point is above the direct
limit and went to block-preconditioned MINRES before.  ``time_reference_minres`` is that MINRES
path (``method='amg'``, refine 1 only: 86 times the Schur path's CPU time there, 57 s);
``track_newton_iterations`` counts the Newton iterations of ``time_reference``.  Compare commits
with ``asv continuous``; one solve is ``python -m benchmarks.asv_fem_reference NU REFINE METHOD
[OUT.npz]`` (wall and CPU seconds, Newton and linear iterations, load average; the displacement
and the top plate's force and torque saved to ``OUT.npz`` to compare two commits' fields).
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

from fem_reference.solve import solve as fem_solve
from hybmss.scene import NEARLY_INCOMPRESSIBLE_NU, Body, Material, Motion, Plate, Region, Scene

RADIUS, HEIGHT, CELL = 0.01, 0.04, 0.004


def cylinder(cell: float = CELL) -> Body:
    """The cells of a ``cell``-sized grid whose centres are inside the cylinder (axis z)."""
    n = int(round(2 * RADIUS / cell)) + 1
    nz = int(round(HEIGHT / cell))
    c = (np.arange(n) + 0.5) * cell - n * cell / 2
    inside = (c[:, None] ** 2 + c[None, :] ** 2) <= RADIUS**2
    mask = np.repeat(inside[:, :, None], nz, axis=2)
    return Body.from_mask(mask, cell, origin=(-n * cell / 2, -n * cell / 2, 0.0))


def twist(nu: float, angle_deg: float = 30.0) -> Scene:
    motion = Motion("rotate", angle=np.radians(angle_deg), axis=(0.0, 0.0, 1.0), center=(0.0, 0.0, HEIGHT))
    return Scene(cylinder(), Material(1e6, nu, 1000.0),
                 plates=(Plate("base", Region("z-")), Plate("top", Region("z+"), motion)))


class FEMReference:
    params = ([0.3, 0.49], [1, 2, 3])
    param_names = ["nu", "refine"]
    timeout = 3600
    number, repeat = 1, 1

    def setup(self, nu, refine):
        self.scene = twist(nu)

    def time_reference(self, nu, refine):
        fem_solve(self.scene, law="neo-hookean", refine=refine)

    def time_reference_minres(self, nu, refine):
        if nu < NEARLY_INCOMPRESSIBLE_NU or refine > 1:
            raise NotImplementedError("the MINRES path is timed on the mixed element at refine 1 only")
        fem_solve(self.scene, law="neo-hookean", refine=refine, method="amg")

    def track_newton_iterations(self, nu, refine):
        return fem_solve(self.scene, law="neo-hookean", refine=refine).iterations

    track_newton_iterations.unit = "iterations"


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    nu, refine, method = float(argv[0]), int(argv[1]), argv[2] if len(argv) > 2 else "auto"
    sc = twist(nu)
    t0, c0 = time.perf_counter(), time.process_time()
    res = fem_solve(sc, law="neo-hookean", refine=refine, method=method)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    lin = res.info["linear_solver"]
    print(f"nu={nu} refine={refine} method={method} dofs={res.info['n_dofs']} wall={wall:.2f}s cpu={cpu:.2f}s "
          f"newton={res.iterations} linear={lin['method']}:{lin['iterations']}/{lin['solves']} "
          f"load={os.getloadavg()[0]:.2f}")
    if len(argv) > 3:
        np.savez(argv[3], u=res.u, top=res.reactions["top"].force, torque=res.reactions["top"].torque,
                 wall=wall, cpu=cpu)
    return 0


if __name__ == "__main__":
    sys.exit(main())
