"""``hybmss moduli``: a model's effective Young's modulus, Poisson ratio and shear modulus, from
static homogeneous tests (:func:`hybmss.moduli.measure_moduli`: ``E_eff = σ/ε`` and
``ν_eff = −ε_lat/ε`` of a uniaxial stretch, ``G_eff = τ/γ`` of a simple shear), beside the input's
``E``, ``ν`` and ``G = E / (2 (1 + ν))``."""

from __future__ import annotations

from hybmss.experiments import DEFAULTS, SceneSpec
from hybmss.scene import Material, Model

from studies.sweep import sizing
from studies.cli.common import InputError, SolveFailure, flag, given_scene_options, guard, run_work, show, \
    work_flags, working
from studies.cli.options import Options, add_model_options, add_no_guard, add_scene_options, number

HELP = "effective E, nu, G of a model (static homogeneous tests)"


def add_options(parser, opts: Options) -> None:
    """The options of ``hybmss moduli``."""
    add_scene_options(parser, opts, names=("model", "E", "nu", "rho"))
    add_model_options(parser, opts)
    opts.add(parser, "--strain", type=number, default=DEFAULTS["uniaxial"]["deformation"],
             help=f"test strain (allowed [1e-06, 0.01]; default {DEFAULTS['uniaxial']['deformation']:g})")
    add_no_guard(parser, opts)


def moduli(args):
    from hybmss.moduli import MeasurementError, check_strain, measure_moduli
    from hybmss.scene import check_nu

    given = given_scene_options(args)
    base = SceneSpec("uniaxial")
    name = given.pop("model", base.model)
    mat_p = {k: given.pop(k, getattr(base, k)) for k in ("E", "nu", "rho")}
    try:
        model = Model(name, **given)  # a parameter the model does not have: exit 2
    except TypeError as exc:
        raise InputError(f"model {name}: {exc}") from None
    try:
        mat = Material(**mat_p)
    except ValueError as exc:  # "nu (Poisson ratio) must lie in ..."
        field = str(exc).split(" ", 1)[0]
        raise InputError(f"{flag(field)} = {show(mat_p.get(field))} is not allowed: {exc}") from None
    # two uniaxial tests of a 2³ cube and a shear test of a 3³ one
    guard(sizing.total("moduli tests", [sizing.mss((3, 3, 3), "static", work=run_work(args, "static"))] * 3),
          f"--model {name}{work_flags(args)}", args=args)
    for option, value, check in (("--strain", args.strain, check_strain), ("--nu", mat.nu, check_nu)):
        try:  # what measure_moduli refuses, refused before its work: "strain=0 is outside [1e-06, 0.01]: ..."
            check(value)
        except ValueError as exc:
            raise InputError(f"{option} = {show(value)} is not allowed: {exc}") from None
    try:
        with working():
            m = measure_moduli(model, mat, strain=args.strain, judge=True)
    except MeasurementError as exc:
        raise SolveFailure(str(exc)) from None
    G = mat.G
    extra = "".join(f", {k} = {v}" for k, v in model.to_dict().items() if k != "name")
    table = "\n".join([
        f"model {model.variant}{extra}, E = {mat.E:g} Pa, nu = {mat.nu:g}",
        f"  E_eff  = {m['E_eff']:.6g} Pa   (input {mat.E:g}, rel. error {m['E_eff'] / mat.E - 1:+.2e})",
        f"  nu_eff = {m['nu_eff']:.6g}      (input {mat.nu:g}, error {m['nu_eff'] - mat.nu:+.2e})",
        f"  G_eff  = {m['G_eff']:.6g} Pa   (E/(2(1+nu)) = {G:.6g}, rel. error {m['G_eff'] / G - 1:+.2e})",
    ] + ([f"  float32 equilibrium error: E_eff +/-{m['equilibrium_error']['E_eff']:.2e}, nu_eff "
          f"+/-{m['equilibrium_error']['nu_eff']:.2e}, G_eff +/-{m['equilibrium_error']['G_eff']:.2e} (resolved from "
          f"strain {m['resolvable_strain']:.2g} on)"] if "equilibrium_error" in m else []))
    return {**model.to_dict(), "model": model.name, "variant": model.variant, "E": mat.E, "nu": mat.nu, **m}, table
