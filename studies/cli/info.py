"""``hybmss info``: the lattice counts of a scene's body, in closed form (SPEC Table 6)."""

from __future__ import annotations

from studies.cli.common import SCENES, scene_spec, show
from studies.cli.options import Options, add_scene_options

HELP = "lattice counts of a scene's body (SPEC Table 6)"


def add_options(parser, opts: Options) -> None:
    """The options of ``hybmss info``."""
    opts.add(parser, "--scene", choices=SCENES, default="compression", help="scene whose body is counted "
             "(default compression)")
    add_scene_options(parser, opts, names=("mesh", "le"))


def box_counts(shape) -> dict:
    """Lattice counts of a full box of ``nx × ny × nz`` cells in closed form (no arrays): particles
    on the grid's vertices, one spring per grid edge, two merged diagonals per grid face, four
    inner diagonals per cell; [G20] Table 6 adds 12 unmerged face diagonals per cell."""
    nx, ny, nz = (int(n) for n in shape)
    cells = nx * ny * nz
    edge = nx * (ny + 1) * (nz + 1) + (nx + 1) * ny * (nz + 1) + (nx + 1) * (ny + 1) * nz
    faces = nx * ny * (nz + 1) + nx * (ny + 1) * nz + (nx + 1) * ny * nz
    face, inner = 2 * faces, 4 * cells
    return {
        "volumes": cells,
        "vertices": (nx + 1) * (ny + 1) * (nz + 1),
        "springs": {"edge": edge, "face_diagonal": face, "inner_diagonal": inner, "total": edge + face + inner},
        "paper_springs_no_fd": edge + inner,
        "paper_springs_with_fd": edge + inner + 12 * cells,
    }


def info(args):
    spec = scene_spec(args, args.scene, ("static",), solved=False)
    counts = box_counts(spec.mesh)
    s = counts["springs"]
    mesh = show(spec.mesh)
    table = "\n".join([
        f"{spec.experiment} body, mesh {mesh}, le = {spec.cell_edge:g} m",
        f"  volumes (cells)        {counts['volumes']:>14,}",
        f"  vertices (particles)   {counts['vertices']:>14,}",
        f"  edge springs           {s['edge']:>14,}",
        f"  face-diagonal springs  {s['face_diagonal']:>14,}   (merged)",
        f"  inner-diagonal springs {s['inner_diagonal']:>14,}",
        f"  springs, total         {s['total']:>14,}",
        f"  [G20] Table 6, no FD   {counts['paper_springs_no_fd']:>14,}",
        f"  [G20] Table 6, with FD {counts['paper_springs_with_fd']:>14,}   (12 unmerged face diagonals per cell)",
    ])
    return {"mesh": mesh, "le": spec.cell_edge, **counts}, table
