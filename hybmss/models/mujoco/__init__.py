"""MuJoCo's deformable flex bodies (``<flex dim="3">``) as models: ``mujoco-tet``,
``mujoco-trilinear``, ``mujoco-quadratic`` (one per element kind).

The engine runs its own code from its own package (``mujoco`` ≥ 4.0, imported only when one of
these models runs: :mod:`hybmss.models.mujoco.engine`, which also says how a scene becomes an MJCF).

Material law, from the engine's source (github.com/google-deepmind/mujoco, ``src/engine``) and
its documentation shipped in the wheel (``mujoco/doc/XMLreference.rst``, ``flex/elasticity``;
``doc/modeling.rst``, "Parametrization types"), measured here (tests/verification/test_engine_mujoco.py):

- ``mujoco-tet`` (``dof="full"``, linear tetrahedra): Saint Venant–Kirchhoff.
  ``engine_elasticity.h``: ``mj_stretchElongation`` takes each of the tetrahedron's 6 edges'
  ``l² − l0²`` (the Green strain in edge coordinates), ``mj_stretchTension`` contracts it with the
  element's precomputed metric (``mjModel.flex_stiffness``, 21 numbers of a symmetric 6×6 plus 3
  for a stable Neo-Hookean variant, zero here: checked), ``mj_stretchForce`` scatters
  ``−tension · (x_i − x_j)`` to the vertices; ``engine_passive.c`` adds it to ``qfrc_spring``.
  The metric is the documented energy density ``μ tr(ε²) + λ/2 tr(ε)²`` with
  ``μ = E/(2(1+ν))``, ``λ = Eν/((1+ν)(1−2ν))``: at small strain linear elasticity in E, ν, no
  Lamé shift.  Measured: a homogeneous uniaxial strain ε gives the nominal stress
  (λ + 2μ) ε (1 + 3ε/2 + O(ε²)), the SVK law's ``(1 + ε)(λ + 2μ)(ε + ε²/2)``.
- ``mujoco-trilinear`` / ``mujoco-quadratic`` (``dof="trilinear"``/``"quadratic"``, 8-/27-node
  cells of an interpolation grid equal to the voxels): ``engine_passive.c`` (the ``flex_interp``
  branch) applies the cell's constant stiffness (``flex_stiffness``, 24² / 81² numbers per cell)
  in the cell's rotated frame (``K_rot``): corotational linear.  Measured: a rigid rotation of
  0.3 rad gives forces below 1e-12 N, a stretch's forces are linear in it to round-off; at small
  strain the linear Hex8 / Hex27 element in E, ν.
- ν: the documented range is [0, ½); a negative ν is refused (``ValueError`` naming ``nu``).

What the models refuse (before any work): surface loads (``Scene.loads``: MuJoCo has no surface
traction on a flex; the harness would have to make nodal forces of them itself), a negative ν,
a body that is not a box for the interpolated kinds (their grid spans the bounding box), more
than one thread, float32.
"""

from __future__ import annotations

import importlib.util
import math
import warnings

from ..base import ModelBase, NoParameters, Style

KINDS = ("tet", "trilinear", "quadratic")
STATIC_REST_RTOL = 1e-7
"""Rest tolerance of the static answer (:func:`hybmss.explicit.rest_report`'s ``rtol``): the
free force residual below 1e-7 of the force scale, so that the state is the equilibrium to
well below the 1e-3 of the same-mesh checks."""
CFL = 0.9
"""Step of the static run as a fraction of the stability limit ``2/ω_max``."""


def available() -> bool:
    """Whether the ``mujoco`` package is installed (found, not imported)."""
    try:
        return importlib.util.find_spec("mujoco") is not None
    except (ImportError, ValueError):
        return False


def _engine():
    from . import engine
    return engine


class MujocoModel(ModelBase):
    """A MuJoCo flex of one element kind (module docstring)."""

    kind: str = "tet"
    Parameters = NoParameters
    conservative = False  # its static answer is the rest state of the engine's damped run
    solvers = ("static", "explicit")
    kernels = ("numba",)
    """The harness's default kernel name only: MuJoCo runs its own compiled step
    (``info['engine']``)."""
    studies = ()
    """No study role yet: the studies' sweeps and tables are unchanged by installing the engine."""

    def _check(self, scene, threads: int = 1, precision: str = "f64") -> None:
        if scene.material.nu < 0:
            raise ValueError(f"nu must lie in [0, 0.5) for {self.name} (MuJoCo's documented range of poisson), "
                             f"got {scene.material.nu:g}")
        if scene.loads:
            raise ValueError(f"loads: {self.name} cannot represent surface tractions (MuJoCo has no surface load on "
                             "a flex); use plates or gravity")
        if self.kind != "tet" and not bool(scene.body.mask.all()):
            raise ValueError(f"body: {self.name} needs a box-shaped body (its interpolation grid spans the bounding "
                             "box); use mujoco-tet for other shapes")
        if int(threads) != 1:
            raise ValueError(f"threads must be 1 for {self.name} (the engine steps on one thread), got {threads}")
        if precision != "f64":
            raise ValueError(f"precision must be f64 for {self.name} (MuJoCo computes in double), got {precision!r}")

    def simulate_explicit(self, scene, dt: float = 1e-3, steps: int = 10_000, kernel: str = "numba",
                          ramp_time: float = 1.0, threads: int = 1, record_every: int = 0, system=None, *,
                          x0=None, v0=None, dt_crit_value=None, compute_dt_crit: bool = True, check_every: int = 10,
                          precision: str = "f64", rest_rtol: float | None = None):
        """``steps`` MuJoCo steps of ``dt`` (Euler integrator) with the scene's plates, ramp,
        damping and gravity; ``converged`` by :func:`hybmss.explicit.rest_report`."""
        from ...explicit import REST_RTOL
        from ...system import build
        from .._voxel_explicit import divergence
        self._check(scene, threads, precision)
        if record_every:
            raise ValueError(f"record_every must be 0 for {self.name} (no trajectory recording)")
        if scene.material.rho <= 0:
            raise ValueError(f"rho must be > 0 for an explicit {self.name} run (MuJoCo bodies need mass), "
                             f"got {scene.material.rho:g}")
        dt, steps, check_every = float(dt), int(steps), max(1, int(check_every))
        S = system if system is not None else build(scene)
        body = _engine().MujocoBody(S, self.kind, dt, ramp_time)
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
                raise divergence(S, body.vertices(), min(bad, S.n - 1), done, dt, dt_c, check_every, self.name)
        r = body.result(f"{self.name}-explicit", done, REST_RTOL if rest_rtol is None else rest_rtol,
                        {"dt": dt, "steps": done, "dt_crit": dt_c, "damping": float(scene.damping),
                         "ramp_time": float(ramp_time), "kernel": "mujoco", "until_rest": False})
        return r

    def solve_static(self, scene, options=None, system=None):
        """The rest state of MuJoCo's damped run (defaults from the body's frequencies: step
        :data:`CFL` × 2/ω_max with ω_max of the engine's own forces, damping 2 ω₁, ramp 2π/ω₁,
        ω₁ of the linear Hex8 stiffness of the same grid), stopped when
        :func:`hybmss.explicit.rest_report` finds it at rest with ``rtol`` :data:`STATIC_REST_RTOL`,
        checked every 1/ω₁; :class:`hybmss.solvers.StaticSolveError` if it is not within
        ``T + 60/ω₁``.  A massless body (ρ = 0) runs with unit density and no weight (the rest
        state does not depend on a uniform density)."""
        from ...solvers import StaticSolveError
        from ...system import build
        from ..corot_hex8 import CorotHex8, frequency_range
        self._check(scene)
        S = system if system is not None else build(scene)
        massless = scene.material.rho <= 0
        S1 = S if not massless else __import__("dataclasses").replace(S, mass=S.lattice.masses_per_density * 1.0,
                                                                     gravity=None)
        w1, _ = frequency_range(S1, CorotHex8(S1.lattice, scene.material))
        if w1 <= 0:
            raise ValueError("the body has a zero-energy mode (not held by its plates): no rest state to reach")
        eng = _engine()
        density = 1.0 if massless else None
        probe = eng.MujocoBody(S1, self.kind, 1.0, 1.0, damping=0.0, density=density, gravity=S1.gravity)
        wmax = probe.omega_max()
        dt = CFL * 2.0 / wmax
        T = 2.0 * math.pi / w1
        c = 2.0 * w1
        body = eng.MujocoBody(S1, self.kind, dt, T, damping=c, density=density, gravity=S1.gravity)
        body.compile_time_s += probe.compile_time_s
        body.load(body.nodes.X, 0.0 * body.nodes.X)
        check = max(1, int(round(1.0 / (w1 * dt))))
        n_max = int(math.ceil((T + 60.0 / w1) / dt))
        done, rest = 0, None
        from ...explicit import rest_report, ramp
        while done < n_max:
            _, bad = body.advance(done, check)
            done += check
            if bad >= 0:
                raise StaticSolveError(f"{self.name} scene {scene.name or '(unnamed)'}: the damped run diverged "
                                       f"(node {bad}); the step {dt:.3g} s is too long for this scene")
            if done * dt >= T:
                x, v = body.state()
                rest = rest_report(body.node_system(), body.internal_forces(x), body.energy(x, v),
                                   ramp(done * dt, T), STATIC_REST_RTOL)
                if rest["at_rest"]:
                    break
        r = body.result(f"{self.name}-rest", done, STATIC_REST_RTOL,
                        {"dt": dt, "omega_1": w1, "omega_max": wmax, "damping": c, "ramp_time": T,
                         "t_end": done * dt, "kernel": "mujoco", "until_rest": True,
                         "static_from": "rest state of MuJoCo's damped run (rest_report)"})
        if not r.converged:
            raise StaticSolveError(
                f"{self.name} scene {scene.name or '(unnamed)'}: the damped run did not come to rest within "
                f"{done * dt:.4g} s ({r.info['rest']['not_at_rest_because']}); raise the damping or the time budget")
        return r


class MujocoTet(MujocoModel):
    name = "mujoco-tet"
    kind = "tet"
    label = "MuJoCo flex, linear tetrahedra (St Venant-Kirchhoff)"
    style = Style("#17becf", "v", "--")
    order = 40


class MujocoTrilinear(MujocoModel):
    name = "mujoco-trilinear"
    kind = "trilinear"
    label = "MuJoCo flex, trilinear 8-node cells (corotational linear)"
    style = Style("#bcbd22", "s", "--")
    order = 41


class MujocoQuadratic(MujocoModel):
    name = "mujoco-quadratic"
    kind = "quadratic"
    label = "MuJoCo flex, quadratic 27-node cells (corotational linear)"
    style = Style("#8c564b", "D", "--")
    order = 42


if available():
    MODELS = (MujocoTet(), MujocoTrilinear(), MujocoQuadratic())
else:
    # one line (no source line under it): the models are left out, nothing else changes
    warnings.warn_explicit("the mujoco package is not installed: the mujoco-* models are left out "
                           "(pip install 'mujoco>=4.0')", RuntimeWarning, "hybmss.models.mujoco", 0,
                           module=__name__)
    MODELS = ()
