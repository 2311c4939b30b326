"""``hybmss modes``: one model's lowest natural frequencies beside the FEM reference's.

The model's lattice (:func:`hybmss.modes.lattice_modes`: its tangent at rest, lumped masses) and
the FEM (:func:`fem_reference.modal.modes`: the element of ``--element``, ``auto`` as in
``compare``, consistent or lumped mass) of the same body and supports, k modes each.  The FEM's
shapes are taken at the lattice particles (nodal values) and each FEM mode is paired with one
of the model's lowest 2k modes by MAC (:func:`hybmss.modes.match`: a lattice with spurious low
modes, e.g. hourglass-like ones, still finds its counterpart of a FEM mode); the frequency error
of a mode is ``f_model / f_fem − 1`` of the pair (and, apart, of the k lowest in ascending order).
The MAC matrix has the FEM's k modes as rows and the model's 2k as columns.
"""

from __future__ import annotations

import time

from hybmss import models
from hybmss.scene import NEARLY_INCOMPRESSIBLE_NU, plates_cross, unsupported

from studies.sweep import sizing
from studies.cli.common import SCENES, SOLVER_DEFAULTS, InputError, guard, mesh_flags, scene_spec, show, stored_scene, \
    working
from studies.cli.options import ELEMENTS, Options, add_model_options, add_no_guard, add_scene_options, positive_int

HELP = "one model's lowest natural frequencies beside the FEM reference's: errors per mode and MAC"

K_MAX = 100
"""Most modes one call computes."""
MASSES = ("consistent", "lumped")


def add_options(parser, opts: Options) -> None:
    """The options of ``hybmss modes``."""
    opts.add(parser, "scene", nargs="?", choices=SCENES, default=None, help="experiment (or --scene-json)")
    opts.add(parser, "--scene-json", default=None, metavar="FILE",
             help="the body and supports of a stored Scene (Scene.to_dict JSON) instead of an experiment")
    add_scene_options(parser, opts)
    add_model_options(parser, opts)
    opts.add(parser, "-k", "--modes", dest="k", type=positive_int, default=6,
             help=f"number of modes (integer in [1, {K_MAX}]; default 6)")
    g = parser.add_argument_group("FEM reference")
    opts.add(g, "--element", "--fem", choices=ELEMENTS, default="auto",
             help=f"hex1, hex2, mixed (Hex2 x Hex1 u-p, pressure condensed) or auto (mixed for nu >= "
                  f"{NEARLY_INCOMPRESSIBLE_NU:g}, else hex2; default)")
    opts.add(g, "--refine", type=positive_int, default=None,
             help=f"split each cell into r^3 elements (integer >= 1; default {SOLVER_DEFAULTS['refine']})")
    opts.add(g, "--mass", choices=MASSES, default="consistent",
             help="the FEM's mass matrix: consistent (default) or lumped (row sums)")
    add_no_guard(parser, opts)


def _scene(args):
    """The scene of ``modes`` and its experiment spec (``None`` for ``--scene-json``), checked."""
    if args.scene_json:
        scene = stored_scene(args)
        why = unsupported(scene) or plates_cross(scene)
        if why:
            raise InputError(f"--scene-json = {args.scene_json} is not allowed: {why}")
        return scene, None
    if not args.scene:
        raise InputError("modes needs an experiment (bending, compression, ...) or --scene-json FILE; none was given")
    spec = scene_spec(args, args.scene, ("static", "fem"))
    return spec.build(), spec


def _check(args, scene) -> str:
    """Refuse a model without tangent, a k out of range, the mixed element at ν ≤ 0; the element."""
    from hybmss.modes import has_tangent

    model = scene.model.spec
    if not has_tangent(model):
        allowed = ", ".join(n for n in models.names() if has_tangent(models.get(n)))
        raise InputError(f"--model = {model.name} is not allowed: it has no tangent stiffness (its static answer "
                         f"is its own solver's); allowed: {allowed}")
    if not 1 <= args.k <= K_MAX:
        raise InputError(f"-k = {args.k} is not allowed: the number of modes must lie in [1, {K_MAX}]")
    if scene.material.rho <= 0:
        raise InputError(f"--rho = {show(scene.material.rho)} is not allowed: natural frequencies need a mass; "
                         "allowed: > 0")
    from fem_reference.solve import resolve_element

    element = resolve_element(args.element, scene.material.nu)
    if element == "mixed" and scene.material.lam <= 0:
        raise InputError(f"--element = mixed is not allowed at nu = {show(scene.material.nu)}: the mixed u-p "
                         "element needs nu > 0; allowed: hex1, hex2")
    return element


def modes(args):
    scene, spec = _scene(args)
    element = _check(args, scene)
    refine = SOLVER_DEFAULTS["refine"] if args.refine is None else args.refine
    shape, nu = scene.body.shape, scene.material.nu
    guard(sizing.fem(shape, element, refine, "linear", nu), mesh_flags(spec, shape, refine),
          lambda sh: sizing.fem(sh, element, refine, "linear", nu), args)
    from fem_reference.modal import at_particles
    from fem_reference.modal import modes as fem_modes
    from hybmss.modes import lattice_modes, match
    from hybmss.system import build

    system = build(scene)
    n_free = int((~system.fixed).sum())
    if args.k >= n_free:
        raise InputError(f"-k = {args.k} is not allowed: this lattice has {n_free} free components; allowed: "
                         f"[1, {n_free - 1}]")
    with working():
        t0 = time.perf_counter()
        lm = lattice_modes(scene, min(2 * args.k, n_free - 1), system)  # spare modes for the pairing
        t1 = time.perf_counter()
        fm = fem_modes(scene, args.k, element, refine, mass=args.mass)
        t2 = time.perf_counter()
        m = match(fm.freq, at_particles(fm), lm.freq, lm.shapes)
    rows = [{"mode": j + 1, "f_fem_hz": float(fm.freq[j]),
             "model_mode": None if c is None else c + 1,
             "f_model_hz": None if c is None else float(lm.freq[c]),
             "relative_error": m["error"][j], "mac": m["matched_mac"][j],
             "f_model_by_order_hz": float(lm.freq[j]), "relative_error_by_order": m["error_by_order"][j]}
            for j, c in enumerate(m["matched"])]
    out = {"scene": spec.to_dict() if spec is not None else scene.to_dict(), "scene_digest": scene.digest(),
           "model": scene.model.name, "k": args.k,
           "fem": {"element": element, "refine": refine, "mass": args.mass, "freq_hz": fm.freq.tolist()},
           "model_freq_hz": lm.freq[:args.k].tolist(), "model_modes_paired_from": len(lm.freq),
           "modes": rows, "mac": m["mac"], "fem_groups": m["groups"],
           "about": "small vibrations about the rest state: the plates hold their constrained components at "
                    "rest; gravity, loads and plate motions do not enter",
           "units": {"frequency": "Hz", "relative_error": "fraction f_model / f_fem - 1", "mac": "[0, 1]"},
           "wall_time_s": {"model": t1 - t0, "fem": t2 - t1}}
    label = spec.label if spec is not None else f"scene {scene.name or args.scene_json}"
    return out, format_modes(out, label)


def _g(v, spec=".5g") -> str:
    return "–" if v is None else format(v, spec)


def format_modes(out: dict, label: str) -> str:
    """The text of ``modes``: the same numbers as its JSON."""
    f = out["fem"]
    lines = [f"{label}   model {out['model']} against FEM {f['element']} (refine {f['refine']}, {f['mass']} mass)",
             "frequencies in Hz; error = f_model / f_fem - 1 of the mode paired by MAC (a fraction)",
             f"{'mode':>4} {'FEM':>12} {'model':>12} {'pair':>5} {'error':>10} {'MAC':>8}   "
             f"{'in order':>12} {'error':>10}"]
    for r in out["modes"]:
        lines.append(f"{r['mode']:>4} {r['f_fem_hz']:>12.6g} {_g(r['f_model_hz'], '.6g'):>12} "
                     f"{_g(r['model_mode'], 'd'):>5} {_g(r['relative_error'], '+.4f'):>10} {_g(r['mac'], '.4f'):>8}   "
                     f"{r['f_model_by_order_hz']:>12.6g} {_g(r['relative_error_by_order'], '+.4f'):>10}")
    w = out["wall_time_s"]
    lines.append(f"wall time: model {w['model']:.3g} s, FEM {w['fem']:.3g} s")
    return "\n".join(lines)
