"""What the subcommands of ``hybmss`` share: their two failures (:class:`InputError`, exit status
2; :class:`SolveFailure`, exit status 3), the scene options read into a checked
:class:`~hybmss.experiments.SceneSpec` (:func:`scene_spec`) or a stored scene (:func:`load_scene`),
the size and time guard (:func:`guard`), the work of a command once its input is checked
(:func:`working`) and the check of a solver's result (:func:`check_result`).
Inputs are checked before any work starts; the solvers are imported when a command runs, so an
invocation that is refused costs no more than importing NumPy."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import sys

from hybmss import models
from hybmss.experiments import EXPERIMENTS, ParameterError, SceneSpec
from hybmss.scene import Scene, scene_dict_error

from studies.sweep import sizing
from studies.sweep.runner import SolverSpec


SCENES = tuple(e for e in EXPERIMENTS if e != "uniaxial")
"""Experiments the ``fem`` and ``compare`` subcommands solve (``uniaxial`` is ``moduli``'s)."""

MSS_SOLVERS = ("static", "explicit", "implicit")

SOLVER_DEFAULTS = {f.name: f.default for f in dataclasses.fields(SolverSpec)}


class InputError(ValueError):
    """Input that is not allowed (exit status 2)."""


class SolveFailure(RuntimeError):
    """A valid simulation that failed (exit status 3); the message says the cause and remedy.
    ``result``: what was done all the same (a study's counts, tables and report), the fields of
    the ``--json`` object beside ``status`` and ``message``."""

    def __init__(self, message: str, result: dict | None = None):
        super().__init__(message)
        self.result = result


@contextlib.contextmanager
def working():
    """The work of a command, entered once its input is checked.  Exit status 2 says the input
    was refused before any work started; a ``ValueError`` raised by the work (a solver's, NumPy's
    or SciPy's on a state they cannot handle) is a valid simulation that failed: exit status 3,
    its type and message on the line (``--debug`` shows where).  A refusal raised in it (an
    :class:`InputError` that needs the lattice built, as ``modes -k``; a study file's
    :class:`~studies.study.errors.StudyError`, some of whose keys are checked against the built
    body) stays one."""
    try:
        yield
    except InputError:
        raise
    except ValueError as exc:
        study = sys.modules.get("studies.study.errors")  # imported by whatever raised one
        if study is not None and isinstance(exc, study.StudyError):
            raise
        raise SolveFailure(f"{type(exc).__name__} during the solve: {' '.join(str(exc).split())}; the input was "
                           "accepted but the solvers could not handle it: --debug shows where") from exc


def model_choices() -> tuple[str, ...]:
    """The models a user can name (the registry's, and those it lists as unavailable: naming one is
    refused with the reason and the install command)."""
    return tuple(models.names()) + tuple(models.unavailable())


def model_parameters() -> dict[str, tuple[dataclasses.Field, tuple[str, ...]]]:
    """Every registered model's parameters (:func:`hybmss.models.parameter_fields`): name → (its
    field, with ``help`` and ``choices`` metadata; the models that have it)."""
    owners = {name: tuple(m.name for m in models.all_models() if name in m.parameter_names())
              for name in models.parameter_fields()}
    return {name: (f, owners[name]) for name, f in models.parameter_fields().items()}


def flag(name: str) -> str:
    """The command-line flag of scene parameter ``name``."""
    return "--" + name.replace("_", "-")


def show(v) -> str:
    if isinstance(v, tuple):
        return "x".join(map(str, v))
    return f"{v:g}" if isinstance(v, float) else str(v)


def given_scene_options(args) -> dict:
    """The scene and model parameters set on the command line (``None`` = not given)."""
    names = [f.name for f in SceneSpec.parameters()] + list(model_parameters())
    return {n: getattr(args, n) for n in names if getattr(args, n, None) is not None}


def scene_spec(args, experiment: str, solvers: tuple[str, ...], solved: bool = True) -> SceneSpec:
    """The :class:`SceneSpec` of the options, checked (:meth:`SceneSpec.check`); refuses an option
    that this experiment and these solvers do not use (it would be silently ignored)."""
    given = given_scene_options(args)
    meta = {f.name: f.metadata for f in SceneSpec.parameters()}
    for name in given:
        if any(SceneSpec.uses(name, experiment, s) for s in solvers):
            continue
        m = meta.get(name, {"experiments": None, "solvers": MSS_SOLVERS})
        if m["experiments"] is not None and experiment not in m["experiments"]:
            why = f"{experiment} does not use it; used by: {', '.join(e for e in m['experiments'] if e in SCENES)}"
        else:
            why = (f"the {' and '.join(solvers)} solver{'s do' if len(solvers) > 1 else ' does'} not use it; "
                   f"used by: {', '.join(m['solvers'])}")
        raise InputError(f"{flag(name)} = {show(given[name])} is not allowed: {why}")
    try:
        spec = SceneSpec.default(experiment, **given)
        return spec.check(solved)
    except ParameterError as exc:
        raise InputError(f"{flag(exc.name)} = {show(exc.value)} is not allowed: "
                         f"{str(exc).split(': ', 1)[1]}") from None
    except ValueError as exc:  # a model parameter the model does not have: "model X has no parameter 'A' ..."
        text = str(exc)
        if "has no parameter '" not in text:
            raise
        name = text.split("has no parameter '", 1)[1].split("'", 1)[0]
        raise InputError(f"{flag(name)} = {show(given.get(name))} is not allowed: {text}") from None
    except TypeError as exc:  # a model parameter of the wrong kind
        raise InputError(f"model {given.get('model') or models.default_name()}: {exc}") from None


def check_newton_nu(model_name: str, solver: str, nu: float, where: str | None = None) -> None:
    """Refuse a Poisson ratio outside :data:`hybmss.scene.NU_RANGE` where the harness's Newton
    solvers answer (the implicit solver, and the static one of a model without its own), as a
    study file's runs are (:mod:`studies.study.checks`); ``where`` names the input that set it
    (default ``--nu``)."""
    from hybmss.scene import check_nu

    if solver == "implicit" or (solver == "static" and models.get(model_name).solve_static is None):
        try:
            check_nu(nu)
        except ValueError as exc:
            raise InputError(f"{where or '--nu = ' + show(nu)} is not allowed: {' '.join(str(exc).split())}") from None


def check_solver(model_name: str, solver: str) -> None:
    """Refuse a solver kind the scene's model does not support (its ``solvers``)."""
    model = models.get(model_name)
    if not model.supports(solver):
        raise InputError(f"--solver = {solver} is not allowed: model {model.name} does not support it; "
                         f"allowed: {', '.join(model.solvers)}")


def stored_scene(args):
    """The scene of ``--scene-json``, refused beside an experiment or scene options (the stored
    scene defines them)."""
    given = given_scene_options(args)
    if args.scene or given:
        extra = ", ".join([f"the experiment {args.scene}"] * bool(args.scene) + [flag(n) for n in given])
        raise InputError(f"--scene-json is not allowed with {extra}: the stored scene defines them")
    return load_scene(args.scene_json)


def load_scene(path: str) -> Scene:
    """The Scene stored in the JSON file ``path``, checked as thoroughly as the command-line options:
    strict JSON, every field known and of its type (:func:`hybmss.scene.scene_dict_error`), every
    value in its range (the constructors)."""
    def refuse(why: str):
        return InputError(f"--scene-json = {path} is not allowed: {' '.join(str(why).split())}; allowed: a "
                          "Scene JSON object (Scene.to_dict)")

    try:
        with open(path, "rb") as fh:
            data = json.loads(fh.read().decode("utf-8"), parse_constant=_not_strict)
    except OSError as exc:
        raise InputError(f"--scene-json = {path} is not allowed: cannot read it ({exc.strerror}); "
                         "allowed: a readable Scene JSON file") from None
    except RecursionError:
        raise refuse("nested too deeply to be a scene") from None
    except (ValueError, UnicodeDecodeError) as exc:  # JSONDecodeError and NaN/Infinity are ValueErrors
        raise refuse(f"not JSON ({exc})") from None
    if not isinstance(data, dict):
        raise refuse(f"it holds a JSON {type(data).__name__}")
    why = scene_dict_error(data)
    if why:
        raise refuse(f"not a scene ({why})")
    try:
        return Scene.from_dict(data)
    except (KeyError, TypeError, AttributeError, ValueError, RecursionError) as exc:
        what = f"missing key {exc}" if isinstance(exc, KeyError) else str(exc)
        raise refuse(f"not a scene ({what})") from None


def _not_strict(name):
    raise ValueError(f"{name} is not a number in strict JSON")


def guard(est: sizing.Estimate, what: str, estimate=None, args=None) -> None:
    """Refuse a run whose estimated memory does not fit this machine or whose estimated time is
    over :data:`studies.sweep.sizing.TIME_LIMIT_S`, unless ``args.no_guard``."""
    if getattr(args, "no_guard", False):
        return
    if not sizing.fits(est):
        raise InputError(f"{what} is too large: {sizing.refusal(est, estimate)}")
    if not sizing.in_time(est):
        raise InputError(f"{what} is too long: {sizing.refusal(est)}")


def work_flags(args) -> str:
    """The given model options that set a run's work (:func:`run_work`), as flags."""
    return "".join(f" {flag(n)} {show(getattr(args, n))}" for n in ("iterations", "substeps")
                   if getattr(args, n, None) is not None)


def run_work(args, solver: str) -> float:
    """:func:`studies.sweep.sizing.model_work` of the model parameters given on the command line."""
    return sizing.model_work({n: getattr(args, n, None) for n in ("iterations", "substeps")}, solver)


def mesh_flags(spec: SceneSpec | None, shape, refine=None) -> str:
    """``--mesh NXxNYxNZ`` (and ``--refine r`` above 1): the settings a refusal names."""
    mesh = f"--mesh {show(tuple(shape))}"
    return mesh + (f" --refine {refine}" if refine and refine != 1 else "")


def check_result(res, what: str) -> None:
    """A result that is not what was asked (not converged, a dynamic run not at rest, non-finite
    outputs) is a failure."""
    rest = res.info.get("rest")
    if isinstance(rest, dict) and not rest.get("at_rest") and res.info.get("floor_stop_t") is not None:
        raise SolveFailure(f"the {what} ({res.solver}) keeps a force residual of at least "
                           f"{res.info['floor_bound']:.2g} of the force scale, above the rest "
                           f"tolerance {rest.get('rtol', 0.0):g} (stopped at t = {res.info['floor_stop_t']:.3g} s: no longer run "
                           "can pass): raise --substeps or --iterations")
    if isinstance(rest, dict) and not rest.get("at_rest"):
        steps = res.info.get("steps", res.iterations)
        why = " ".join(str(rest.get("not_at_rest_because") or "").split())
        raise SolveFailure(f"the {what} ({res.solver}) is not at rest after {steps} steps: raise --steps or "
                           f"--damping" + (f" ({why})" if why else ""))
    if not res.converged:
        why = " ".join(str(res.info.get("warning") or res.info.get("message") or "did not converge").split())
        raise SolveFailure(f"the {what} ({res.solver}) did not converge: {why}; try a smaller load or a finer mesh")
    bad = [k for k in ("volume_change", "max_displacement") if not math.isfinite(float(getattr(res, k)))]
    if bad:
        raise SolveFailure(f"the {what} ({res.solver}) produced non-finite {', '.join(bad)}; "
                           "the state is degenerate: try a smaller load or a finer mesh")
