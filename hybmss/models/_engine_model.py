"""What the engine models share (:mod:`hybmss.models.mujoco`, :mod:`hybmss.models.newton`,
:mod:`hybmss.models.pbd`): the engine's body as the stepper of the one explicit loop
(:meth:`EngineModel.stepper`, :func:`hybmss.explicit.simulate_explicit`), the static answer (the
rest state of the engine's damped run, in the same loop: :class:`UntilRest`), the refusals common
to every engine, and the engine imported only when a run needs it (:meth:`EngineModel.make_body`).

Versions: each engine folder declares ``REQUIRES`` (module, distribution, version range with an
upper bound: the versions its law was read and measured at; pyproject's ``engines`` extra lists
the same).  An engine that is missing or outside its range leaves its models unavailable
(:func:`engine_models`, the registry's ``unavailable()``).  Within the range, the first run of a
model at an engine version measures its law on one cell (:meth:`EngineModel.check_law`:
uniaxial strain and simple shear against linear elasticity in (E, ν), cached per model and
version in :func:`law_cache_file`); a deviation refuses the model with the reason.

What the loop does for an engine and what it cannot: the ramp, the plates' targets after every
step, the mass-proportional damping ``v/(1 + c h)`` after the engine's step (MuJoCo refuses joint
damping on a flex; Newton's and the library's own damping are not mass-proportional), the
divergence and rest checks, the history (energies: kinetic only, no engine exposes its strain
energy), the timing and Ctrl-C (between calls of about 0.1 s, whole check intervals) are the
loop's; the engine steps the free nodes, and the plates are set by the harness on the engine's
state after each step (no engine here has a kinematic plate that follows the scene's ramp).
``kernel`` is ``"engine"``, ``threads`` 1, ``precision`` the engine's; others are refused."""

from __future__ import annotations

import dataclasses
import importlib.metadata
import importlib.util
import json
import math
import os
import re
import tempfile

import numpy as np

from ..solve.errors import StaticSolveError
from .base import ModelBase, NoParameters

INSTALL = "pip install 'hybmss[engines]'"
"""The command that installs every engine with the versions the engine models were measured on."""


def installed(*packages: str) -> bool:
    """Whether every one of ``packages`` is installed (found, not imported)."""
    try:
        return all(importlib.util.find_spec(p) is not None for p in packages)
    except (ImportError, ValueError):
        return False


def _release(version: str) -> tuple[int, ...]:
    """The release numbers of a version string (``"1.19.0rc1"`` → ``(1, 19, 0)``)."""
    out = []
    for part in version.split("."):
        digits = re.match(r"\d*", part).group()
        if not digits:
            break
        out.append(int(digits))
        if len(digits) < len(part):
            break
    return tuple(out)


def in_range(version: str, spec: str) -> bool:
    """Whether ``version`` satisfies ``spec``, clauses ``>=A`` and ``<B`` joined by commas (the
    forms the engines' requirements use), compared on release numbers (padded with zeros)."""
    v = _release(version)
    for clause in filter(None, (c.strip() for c in spec.split(","))):
        op, bound = (clause[:2], clause[2:]) if clause.startswith(">=") else (clause[:1], clause[1:])
        b = _release(bound)
        n = max(len(v), len(b))
        a, b = v + (0,) * (n - len(v)), b + (0,) * (n - len(b))
        if (op == ">=" and a < b) or (op == "<" and a >= b) or op not in (">=", "<"):
            return False
    return True


def missing_engine(requires: tuple[tuple[str, str, str], ...]) -> str | None:
    """Why an engine's models cannot run, or None: a package of ``requires`` ((module,
    distribution, version range), e.g. ``("warp", "warp-lang", ">=1.19,<1.20")``) that is not
    installed, or installed at a version outside the range the models' laws were read and
    measured at; the reason ends with the install command."""
    for module, dist, spec in requires:
        pin = f"'{dist}{spec}'"
        if not installed(module):
            return f"the {dist} package is not installed; {INSTALL} (or pip install {pin})"
        try:
            version = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            return f"the {dist} package has no version metadata (expected {spec}); {INSTALL} (or pip install {pin})"
        if not in_range(version, spec):
            return (f"{dist} {version} is installed, the models' laws were read and measured at {dist}{spec}; "
                    f"{INSTALL} (or pip install {pin})")
    return None


def engine_models(requires: tuple[tuple[str, str, str], ...], models: tuple) -> tuple[tuple, dict[str, str]]:
    """``(MODELS, UNAVAILABLE)`` of an engine folder: its ``models`` when :func:`missing_engine`
    finds nothing, else none and each model's name with the reason (the registry lists them as
    unavailable and refuses them with it).  Nothing is imported."""
    reason = missing_engine(requires)
    if reason is None:
        return tuple(models), {}
    return (), {m.name: reason for m in models}


def requirement_lines(requires: tuple[tuple[str, str, str], ...]) -> tuple[str, ...]:
    """The pip requirements (``dist`` + range) of ``requires``: the ``engines`` extra's lines."""
    return tuple(dist + spec for _, dist, spec in requires)


class SceneNotRepresentable(ValueError, StaticSolveError):
    """What an engine cannot represent, refused before any work: a :class:`ValueError` naming the
    parameter (exit 2 of a command), and a :class:`hybmss.solve.StaticSolveError` for a sweep
    that records a failed solve as a row (the studies' moduli table runs every model at ν < 0),
    whose ``row_status`` is ``"not-representable"``."""

    row_status = "not-representable"

    def __init__(self, message: str):
        StaticSolveError.__init__(self, message)


class EngineUnavailable(SceneNotRepresentable):
    """An engine model whose law check failed at the installed engine version (exit 2; a study's
    row ``unavailable``)."""

    row_status = "unavailable"


LAW_STRAIN = 1e-3
"""Strain of the law check (:meth:`EngineModel.law_errors`)."""
LAW_RTOL = 1e-2
"""Largest relative deviation of the law check's stresses from linear elasticity in (E, ν): above
the finite-strain terms at :data:`LAW_STRAIN` (SVK: 1.5e-3), far below a wrong Lamé mapping (25 %)."""


def law_cache_file() -> str:
    """The cache of the law checks: ``$HYBMSS_ENGINE_CACHE``, else
    ``$XDG_CACHE_HOME/hybmss/engine-laws.json``, else ``~/.cache/hybmss/engine-laws.json``."""
    path = os.environ.get("HYBMSS_ENGINE_CACHE")
    if path:
        return path
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "hybmss", "engine-laws.json")


def _read_cache(path: str) -> dict:
    try:
        with open(path, encoding="utf-8") as fh:
            data = json.load(fh)
        return data if isinstance(data, dict) else {}
    except (OSError, ValueError):
        return {}


def _write_cache(path: str, data: dict) -> None:
    """Atomically (concurrent workers); a cache that cannot be written is skipped."""
    try:
        os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=os.path.dirname(path) or ".", suffix=".tmp")
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(data, fh, indent=1, sort_keys=True)
        os.replace(tmp, path)
    except OSError:
        pass


def engine_version(requires: tuple[tuple[str, str, str], ...]) -> str:
    """The installed versions of ``requires`` (``"newton 1.8.0, warp-lang 1.19.0"``)."""
    return ", ".join(f"{dist} {importlib.metadata.version(dist)}" for _, dist, _ in requires)


SETTLE = 20.0
"""Time after the ramp, in 1/ω₁, from which a float32 engine's state within its force resolution
counts as at rest even if it has not settled before (:class:`hybmss.explicit.Settling`: the
slowest mode, critically damped, decayed by e^-20)."""


class EngineModel(ModelBase):
    """A model whose body another engine steps (subclass: ``engine``, ``make_body``, ``check_scene``)."""

    engine: str = "engine"
    precisions: tuple[str, ...] = ("f64",)
    """The ``precision`` values the engine computes in (the harness's option, refused otherwise)."""
    static_rest_rtol: float = 1e-7
    """Rest tolerance of the static answer (:func:`hybmss.explicit.rest_report`'s ``rtol``)."""
    cfl: float = 0.9
    """Step of the static run as a fraction of the stability limit ``2/ω_max``."""
    settles: bool = False
    """Whether the static run waits until the body has settled (:class:`hybmss.explicit.Settling`)
    before a state counts as at rest even for a float64 engine (one whose rest state leaves a
    residual floor under the law its forces are read with: XPBD's O((h ω)²) bias)."""

    requires: tuple[tuple[str, str, str], ...] = ()
    """The engine's packages and version ranges (the folder's ``REQUIRES``)."""
    law_checked: bool = True
    """Whether :meth:`check_law` measures the engine's law (False: forces not read from the engine)."""

    Parameters = NoParameters
    conservative = False  # its static answer is the rest state of the engine's damped run
    solvers = ("static", "explicit")
    kernels = ("engine",)
    """The engine's own compiled step (``info['engine']``): the harness's kernels do not run it."""

    def make_body(self, system, dt: float, ramp_time: float, **kw):
        """The engine's body of ``system`` (an :class:`hybmss.models._engine_body.EngineBody`)."""
        raise NotImplementedError

    def check_scene(self, scene) -> None:
        """Raise :class:`SceneNotRepresentable` naming what of ``scene`` the engine cannot represent."""

    def tet_body_refused(self) -> str:
        """Why the model cannot run on a tetrahedral body (``""``: it can)."""
        return f"body: {self.name} cannot run on a tetrahedral body"

    def make_tet_body(self, body, material, holds, dt: float, ramp_time: float, *, damping: float = 0.0):
        """The engine's body on the tetrahedra of a :class:`hybmss.tetbody.TetBody` with the supports
        ``holds`` (:class:`hybmss.models._engine_tet.TetHold`), after the law check;
        :class:`SceneNotRepresentable` for a model whose elements are not tetrahedra."""
        raise SceneNotRepresentable(self.tet_body_refused())

    def solve_tets(self, body, material, holds, *, rtol: float | None = None):
        """The rest state of the engine's damped run on a tetrahedral body
        (:func:`hybmss.models._engine_tet.rest_on_tets`)."""
        from ._engine_tet import rest_on_tets

        return rest_on_tets(self, body, material, holds, settle=SETTLE, rtol=rtol)

    def law_errors(self) -> dict[str, float]:
        """The law check: the engine's own forces on one unit cell (E = 1e4 Pa, ν = 0.3, the bottom
        held) under a homogeneous uniaxial strain ε = :data:`LAW_STRAIN` (nominal stress −Σ f_z over
        the top nodes, expected (λ + 2μ) ε) and a simple shear γ = ε (−Σ f_x, expected μ γ):
        the relative deviation of each from linear elasticity in (E, ν)."""
        from .. import Body, Material, Model, Plate, Region, Scene
        from ..system import build

        sc = Scene(body=Body.box(1, 1, 1, le=1.0), material=Material(E=1e4, nu=0.3, rho=1000.0),
                   model=Model(self.name), plates=(Plate("bottom", Region("z-")),))
        body = self.make_body(build(sc), 1e-3, 1.0)
        X, mat, eps = body.nodes.X, sc.material, LAW_STRAIN
        top = np.isclose(X[:, 2], 1.0)
        x = X.copy()
        x[:, 2] *= 1.0 + eps
        stretch = -body.internal_forces(x)[top, 2].sum() / ((mat.lam + 2.0 * mat.G) * eps)
        x = X.copy()
        x[:, 0] += eps * X[:, 2]
        shear = -body.internal_forces(x)[top, 0].sum() / (mat.G * eps)
        return {"uniaxial": abs(float(stretch) - 1.0), "shear": abs(float(shear) - 1.0)}

    def check_law(self) -> None:
        """:class:`EngineUnavailable` if :meth:`law_errors` at the installed engine version exceeds
        :data:`LAW_RTOL`; measured once per model and version, cached in :func:`law_cache_file`."""
        if not self.law_checked or not self.requires:
            return
        version = engine_version(self.requires)
        key = f"{self.name} | {version}"
        path = law_cache_file()
        cache = _read_cache(path)
        errors = cache.get(key)
        if not isinstance(errors, dict):
            errors = self.law_errors()
            _write_cache(path, {**_read_cache(path), key: errors})
        bad = {k: v for k, v in errors.items() if not v <= LAW_RTOL}
        if bad:
            raise EngineUnavailable(
                f"model {self.name} is unavailable: its law check at {version} found "
                + ", ".join(f"the {k} stress {100 * v:.3g} % off" for k, v in bad.items())
                + f" linear elasticity in (E, nu) at strain {LAW_STRAIN:g} (allowed {100 * LAW_RTOL:g} %; cached "
                f"in {path}): the engine's law changed; {INSTALL}")

    def _check(self, scene, threads: int = 1, precision: str | None = None) -> None:
        self.check_scene(scene)
        self.check_law()
        if scene.loads:
            raise SceneNotRepresentable(f"loads: {self.name} cannot represent surface tractions ({self.engine} has "
                                        "no surface load on its body); use plates or gravity")
        if int(threads) != 1:
            raise ValueError(f"threads must be 1 for {self.name} (the engine steps on one thread), got {threads}")
        if precision is not None and precision not in self.precisions:
            raise ValueError(f"precision must be {' or '.join(self.precisions)} for {self.name} ({self.engine} "
                             f"computes in it), got {precision!r}")

    def stepper(self, system, dt: float, *, ramp_time: float, kernel: str = "engine", precision: str = "f64",
                threads: int = 1):
        """The engine's body of ``system`` (:class:`hybmss.models._engine_body.EngineBody`) as the
        stepper of the one explicit loop, after the refusals of what the engine cannot represent
        (:meth:`check_scene`, surface loads, threads, precision, a massless body)."""
        scene = system.scene
        self._check(scene, threads, precision)
        if scene.material.rho <= 0:
            raise ValueError(f"rho must be > 0 for an explicit {self.name} run (the engine's nodes need mass), "
                             f"got {scene.material.rho:g}")
        body = self.make_body(system, dt, ramp_time)
        body.solver = f"{self.name}-explicit"
        body.info = {"kernel": "engine", "engine_name": self.engine, "until_rest": False}
        return body

    def solve_static(self, scene, options=None, system=None):
        """The rest state of the engine's damped run in the one loop
        (:func:`hybmss.explicit.simulate_explicit`; defaults from the body's frequencies: step
        :attr:`cfl` × 2/ω_max with ω_max of the engine's own forces, damping 2 ω₁, ramp 2π/ω₁,
        ω₁ of the linear Hex8 stiffness of the same grid), stopped when
        :func:`hybmss.explicit.rest_report` finds it at rest with ``rtol`` :attr:`static_rest_rtol`
        (for a float32 engine: within its force resolution, once settled: :class:`hybmss.explicit.Settling`),
        checked every 1/ω₁; :class:`hybmss.solve.StaticSolveError` if it is not within
        ``T + 60/ω₁``.  A massless body (ρ = 0) runs with unit density and no weight (the rest
        state does not depend on a uniform density)."""
        from ..explicit import DivergenceError, Settling, simulate_explicit
        from ..system import build
        from .corot_hex8 import CorotHex8, frequency_range
        self._check(scene)
        S = system if system is not None else build(scene)
        massless = scene.material.rho <= 0
        S1 = S if not massless else dataclasses.replace(S, mass=S.lattice.masses_per_density * 1.0,
                                                                     gravity=None)
        w1, _ = frequency_range(S1, CorotHex8(S1.lattice, scene.material))
        if w1 <= 0:
            raise ValueError("the body has a zero-energy mode (not held by its plates): no rest state to reach")
        density = 1.0 if massless else None
        probe = self.make_body(S1, 1.0, 1.0, damping=0.0, density=density, gravity=S1.gravity)
        wmax = probe.omega_max()
        dt = self.cfl * 2.0 / wmax
        T = 2.0 * math.pi / w1
        c = 2.0 * w1
        body = self.make_body(S1, dt, T, damping=c, density=density, gravity=S1.gravity)
        body.compile_time_s += probe.compile_time_s
        body.for_rest()
        body.solver = f"{self.name}-rest"
        body.info = {"kernel": "engine", "engine_name": self.engine, "until_rest": True}
        check = max(1, int(round(1.0 / (w1 * dt))))
        n_max = int(math.ceil((T + 60.0 / w1) / dt))
        settling = Settling(body.nodes.X, T, w1, SETTLE, self.static_rest_rtol)
        st = UntilRest(body, self.static_rest_rtol, T, settling, self.settles)
        try:
            r = simulate_explicit(S1.scene, dt=dt, steps=n_max, kernel="engine", ramp_time=T, system=S1,
                                  dt_crit_value=2.0 / wmax, check_every=check, precision=self.precisions[0],
                                  rest_rtol=self.static_rest_rtol, stepper=st)
        except DivergenceError as e:
            raise StaticSolveError(f"{self.name} scene {scene.name or '(unnamed)'}: the damped run diverged "
                                   f"(node {e.particle}); the step {dt:.3g} s is too long for this scene",
                                   cause="diverged", step=int(e.step), time=float(e.step * dt)) from None
        r.info.update({"damping": c, "omega_1": w1, "omega_max": wmax, "load_steps": 0, "until_rest": True,
                       "static_from": f"rest state of {self.engine}'s damped run (rest_report)"})
        if not r.converged:
            raise StaticSolveError(
                f"{self.name} scene {scene.name or '(unnamed)'}: the damped run did not come to rest within "
                f"{r.info['t_end']:.4g} s ({r.info['rest']['not_at_rest_because']}); raise the damping or the time "
                "budget", cause="rest-state", time=float(r.info["t_end"]))
        return r


class UntilRest:
    """An engine body's stepper that stops at the first check (every ``check_every`` steps of the
    loop) from time ``T`` on at which :func:`hybmss.explicit.stepper_rest` finds it at rest with
    ``rtol``; a float32 engine (a force resolution) or one whose rest state leaves a residual
    floor under its forces' law (``always_settle``) counts as at rest only once it has settled
    (``settling``, a :class:`hybmss.explicit.Settling`: its nodes still within its tolerance over
    the last checks, at the latest from :data:`SETTLE`/ω₁ after the ramp on).  Everything else is
    the body's."""

    def __init__(self, body, rtol: float, T: float, settling, always_settle: bool):
        self.body, self.rtol, self.T, self.settling = body, float(rtol), float(T), settling
        self.always_settle = bool(always_settle)
        self.at_rest = False

    def __getattr__(self, name):
        return getattr(self.body, name)

    def advance(self, step0: int, n: int, check_every: int, limit2: float) -> tuple[int, int]:
        from ..explicit import ramp, stepper_rest
        body = self.body
        done = 0
        while done < n and not self.at_rest:
            k, bad = body.advance(step0 + done, min(check_every, n - done), check_every, limit2)
            done += k
            if bad >= 0:
                return done, bad
            t = (step0 + done) * body.dt
            if t < self.T:
                continue
            x, v = body.state()
            rest = stepper_rest(body.node_system(), body, body.internal_forces(x), body.energy(x, v),
                                ramp(t, body.ramp_time), self.rtol, x)
            floor = rest.get("resolution_N", 0.0) > 0.0 or self.always_settle
            settled = self.settling.update(t, x) if floor else True
            self.at_rest = bool(rest["at_rest"] and settled)
        return done, -1
