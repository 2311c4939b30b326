"""What the engine models share (:mod:`hybmss.models.mujoco`, :mod:`hybmss.models.newton`,
:mod:`hybmss.models.pbd`): the
explicit run and the static answer (the rest state of the engine's damped run) on the protocol of
:mod:`hybmss.models.base`, the refusals common to every engine, and the engine imported only when
a run needs it (:meth:`EngineModel.make_body`)."""

from __future__ import annotations

import dataclasses
import importlib.util
import math
import warnings

from ..solve.errors import StaticSolveError
from .base import ModelBase, NoParameters

def installed(*packages: str) -> bool:
    """Whether every one of ``packages`` is installed (found, not imported)."""
    try:
        return all(importlib.util.find_spec(p) is not None for p in packages)
    except (ImportError, ValueError):
        return False


def models_if_installed(module: str, packages: tuple[str, ...], make, missing: str) -> tuple:
    """``make()`` (the models of an engine folder) when every one of ``packages`` is installed;
    else ``()`` and one warning line ``missing`` (no source line under it): the models are left
    out and nothing else changes."""
    if installed(*packages):
        return tuple(make())
    warnings.warn_explicit(missing, RuntimeWarning, module, 0, module=module)
    return ()


class SceneNotRepresentable(ValueError, StaticSolveError):
    """What an engine cannot represent, refused before any work: a :class:`ValueError` naming the
    parameter (exit 2 of a command), and a :class:`hybmss.solve.StaticSolveError` for a sweep
    that records a failed solve as a row (the studies' moduli table runs every model at ν < 0)."""


SETTLE = 20.0
"""Time after the ramp, in 1/ω₁, before a float32 engine's state within its force resolution
counts as at rest (the slowest mode, critically damped, decayed by e^-20)."""


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
    """Whether the static run waits :data:`SETTLE`/ω₁ after the ramp before a state counts as at rest
    even for a float64 engine (one whose rest state leaves a residual floor under the law its forces
    are read with: XPBD's O((h ω)²) bias)."""

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

    def _check(self, scene, threads: int = 1, precision: str | None = None) -> None:
        self.check_scene(scene)
        if scene.loads:
            raise SceneNotRepresentable(f"loads: {self.name} cannot represent surface tractions ({self.engine} has "
                                        "no surface load on its body); use plates or gravity")
        if int(threads) != 1:
            raise ValueError(f"threads must be 1 for {self.name} (the engine steps on one thread), got {threads}")
        if precision is not None and precision not in self.precisions:
            raise ValueError(f"precision must be {' or '.join(self.precisions)} for {self.name} ({self.engine} "
                             f"computes in it), got {precision!r}")

    def simulate_explicit(self, scene, dt: float = 1e-3, steps: int = 10_000, kernel: str = "engine",
                          ramp_time: float = 1.0, threads: int = 1, record_every: int = 0, system=None, *,
                          x0=None, v0=None, dt_crit_value=None, compute_dt_crit: bool = True, check_every: int = 10,
                          precision: str = "f64", rest_rtol: float | None = None):
        """``steps`` engine steps of ``dt`` with the scene's plates, ramp, damping and gravity;
        ``converged`` by :func:`hybmss.explicit.rest_report`."""
        from ..explicit import REST_RTOL
        from ..system import build
        from ..explicit import BLOWUP_FACTOR, _divergence
        self._check(scene, threads, precision)
        if record_every:
            raise ValueError(f"record_every must be 0 for {self.name} (no trajectory recording)")
        if scene.material.rho <= 0:
            raise ValueError(f"rho must be > 0 for an explicit {self.name} run (the engine's nodes need mass), "
                             f"got {scene.material.rho:g}")
        dt, steps, check_every = float(dt), int(steps), max(1, int(check_every))
        S = system if system is not None else build(scene)
        body = self.make_body(S, dt, ramp_time)
        X = body.nodes.X
        if (x0 is not None or v0 is not None) and len(X) != S.n:
            raise ValueError(f"x0, v0: {self.name} has nodes that are not lattice particles; start from rest")
        x = X if x0 is None else x0
        v = 0.0 * X if v0 is None else v0
        body.load(x, v)
        dt_c = None
        if dt_crit_value is not None:
            dt_c = float(dt_crit_value)
        elif compute_dt_crit:
            w = body.omega_max()
            dt_c = 2.0 / w if w > 0 else math.inf
        done = 0
        while done < steps:
            k = min(check_every, steps - done)
            _, bad = body.advance(done, k)
            done += k
            if bad >= 0:
                xs, _ = body.state()
                raise _divergence(S, body.vertices(), min(bad, S.n - 1), done, dt,
                                  BLOWUP_FACTOR * max(scene.body.size), dt_c, check_every, self)
        r = body.result(f"{self.name}-explicit", done, REST_RTOL if rest_rtol is None else rest_rtol,
                        {"dt": dt, "steps": done, "dt_crit": dt_c, "damping": float(scene.damping),
                         "ramp_time": float(ramp_time), "kernel": "engine", "engine_name": self.engine,
                         "until_rest": False})
        return r

    def solve_static(self, scene, options=None, system=None):
        """The rest state of the engine's damped run (defaults from the body's frequencies: step
        :attr:`cfl` × 2/ω_max with ω_max of the engine's own forces, damping 2 ω₁, ramp 2π/ω₁,
        ω₁ of the linear Hex8 stiffness of the same grid), stopped when
        :func:`hybmss.explicit.rest_report` finds it at rest with ``rtol`` :attr:`static_rest_rtol`
        (for a float32 engine: within its force resolution, :data:`SETTLE`/ω₁ after the ramp),
        checked every 1/ω₁; :class:`hybmss.solve.StaticSolveError` if it is not within
        ``T + 60/ω₁``.  A massless body (ρ = 0) runs with unit density and no weight (the rest
        state does not depend on a uniform density)."""
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
        body.load(body.nodes.X, 0.0 * body.nodes.X)
        check = max(1, int(round(1.0 / (w1 * dt))))
        n_max = int(math.ceil((T + 60.0 / w1) / dt))
        done, rest = 0, None
        while done < n_max:
            _, bad = body.advance(done, check)
            done += check
            if bad >= 0:
                raise StaticSolveError(f"{self.name} scene {scene.name or '(unnamed)'}: the damped run diverged "
                                       f"(node {bad}); the step {dt:.3g} s is too long for this scene")
            if done * dt >= T:
                x, v = body.state()
                rest = body.rest(x, v, body.internal_forces(x), self.static_rest_rtol)
                # within the force resolution of a float32 engine only once the slowest mode has
                # decayed by e^-20 (critical damping 2 ω₁): the residual has reached that floor
                floor = rest.get("resolution_N", 0.0) > 0.0 or self.settles
                settled = not floor or done * dt >= T + SETTLE / w1
                if rest["at_rest"] and settled:
                    break
        r = body.result(f"{self.name}-rest", done, self.static_rest_rtol,
                        {"dt": dt, "omega_1": w1, "omega_max": wmax, "damping": c, "ramp_time": T,
                         "t_end": done * dt, "kernel": "engine", "engine_name": self.engine, "until_rest": True,
                         "load_steps": 0,
                         "static_from": f"rest state of {self.engine}'s damped run (rest_report)"})
        if not r.converged:
            raise StaticSolveError(
                f"{self.name} scene {scene.name or '(unnamed)'}: the damped run did not come to rest within "
                f"{done * dt:.4g} s ({r.info['rest']['not_at_rest_because']}); raise the damping or the time budget",
                cause="rest-state", time=float(done * dt))
        return r


