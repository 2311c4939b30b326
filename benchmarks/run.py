"""``python -m benchmarks.run``: the quick performance study of the explicit kernel.

Times 1,000-step runs (fewer with ``--steps``) of the compression cube and the beam under gravity
for hybmss-fd, hybmss-cf and hybmss (ν = 0.3 and ν = ¼) on small meshes, one and two threads,
and prints the per-step figures, the ratios to hybmss-fd next to the publication's 1.4 and 2.1,
and the fraction of the memory bandwidth measured in the same run (see
:mod:`studies.paper.performance` for the protocol and the bytes-per-step model).  ``--full`` runs the
meshes of [G20] Table 6 (several minutes).  ``--fem`` also runs ``benchmarks.bench_fem --quick``.
"""

from __future__ import annotations

import argparse
import sys


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.run", description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="the publication's meshes (slow)")
    parser.add_argument("--steps", type=int, default=None, help="steps per timed run (default 200 quick, 1000 full)")
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="thread counts (default 1 2)")
    parser.add_argument("--fem", action="store_true", help="also run the FEM reference benchmark (quick)")
    args = parser.parse_args(argv)

    from studies.paper.performance import format_table, run_performance, summary

    df, bw = run_performance(quick=not args.full, steps=args.steps, threads=tuple(args.threads))
    print(f"memory bandwidth (NumPy, {bw['array_MB']:.0f} MB arrays): copy {bw['copy']:.1f} GB/s, "
          f"add {bw['add']:.1f} GB/s")
    print(format_table(df))
    print()
    print(summary(df).to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    if args.fem:
        from benchmarks import bench_fem

        return bench_fem.main(["--quick"]) or 0
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
