"""One solve of a scene by a solver specification, and the scalar outputs of its result.

:func:`solve_scene` is the one dispatch from a :class:`studies.sweep.runner.SolverSpec` to a
solver, used by the runner and by the command line alike:

- ``static``: Newton's load stepping, ``x*`` with ``f_int(x*) + f_ext = 0`` on the free
  components (:func:`hybmss.solve.solve_static`, with its :class:`hybmss.solve.StaticOptions`);
- ``implicit``: backward Euler, ``M (v_{n+1} − v_n)/dt = f(x_{n+1})``, to rest;
- ``explicit``: symplectic Euler, ``v_{n+1} = v_n + dt M⁻¹ f(x_n)``, ``x_{n+1} = x_n + dt v_{n+1}``,
  in the kernel's precision: an engine's own (Newton's is float32), the lattice kernels' float64;
  with ``until_rest``, a run whose rest state is the fixed point of its step ends there once at rest;
- ``fem``: the finite-element reference (:func:`fem_reference.solve.solve`).

:func:`measure` reads what SPEC §8 compares off a result: the volume change ``V/V0 − 1``, the
plate reaction ``−Σ f`` over the plate's particles, and for the beam the tip deflection.
"""

from __future__ import annotations

import numpy as np

from studies.sweep.scenes import SceneSpec


def explicit_precision(model, kernel: str) -> str:
    """The precision an explicit run computes in: an engine's own (its first of ``precisions``:
    Newton's float32), the lattice kernels' float64."""
    return getattr(model, "precisions", ("f64",))[0] if kernel == "engine" else "f64"


def default_kernel(model) -> str:
    """The kernel of an explicit run of ``model`` when none is asked for: the compiled lattice
    kernel (numba) if the model has one, else its first (an engine's own)."""
    return "numba" if "numba" in model.kernels else model.kernels[0]


def solve_scene(scene, s, static_options=None):
    """Solve the :class:`hybmss.scene.Scene` ``scene`` with the solver specification ``s``
    (:class:`studies.sweep.runner.SolverSpec`); ``static_options``: the static solver's
    (:class:`hybmss.solve.StaticOptions`, None: its defaults)."""
    if s.kind == "static":
        from hybmss.solve import solve_static

        return solve_static(scene, static_options)
    if s.kind == "implicit":
        from hybmss.solve import ImplicitOptions, simulate_implicit

        return simulate_implicit(scene, ImplicitOptions(dt=s.dt, steps=s.steps, ramp_time=s.ramp_time))
    if s.kind == "explicit":
        from hybmss.explicit import simulate_explicit

        return simulate_explicit(scene, dt=s.dt, steps=s.steps, kernel=s.kernel, ramp_time=s.ramp_time,
                                 precision=explicit_precision(scene.model.spec, s.kernel),
                                 until_rest=bool(getattr(s, "until_rest", False)))
    from fem_reference.solve import solve as fem_solve

    return fem_solve(scene, element=s.element, law=s.law, refine=s.refine)


def measure(spec: SceneSpec, result) -> dict:
    """Scalar outputs of one result (SPEC §8): volume change, plate reaction, tip deflection.
    The solver's iteration count is ``solver_iterations``: ``iterations`` is a model parameter's
    name (xpbd-nh's), and a row keeps the scene's fields under their own names."""
    row = {
        "volume_change": float(result.volume_change),
        "max_displacement": float(result.max_displacement),
        "converged": bool(result.converged),
        "solver_iterations": int(result.iterations),
        "wall_time_s": float(result.wall_time_s),
    }
    plate = "bottom" if spec.experiment == "bending" else "top"
    if plate in result.reactions:
        r = result.reactions[plate]
        row.update({f"force_{c}": float(v) for c, v in zip("xyz", r.force)})
        row.update({f"torque_{c}": float(v) for c, v in zip("xyz", r.torque)})
    if spec.experiment == "bending":
        row["tip_deflection"] = tip_deflection(result.X, result.u)
        row["euler_bernoulli_tip"] = spec.euler_bernoulli_tip()
    for k in ("inverted_cells", "kappa", "dt_crit", "load_steps", "volume_avg_edges", "volume_lnJ",
              "newton_iterations", "steps", "stable", "saddle_escapes", "min_eigenvalue"):
        if k in result.info:
            v = result.info[k]
            row[k] = v if isinstance(v, bool) else (
                float(v) if isinstance(v, (int, float, np.floating, np.integer)) else v)
    return row


def centre_line(X: np.ndarray) -> np.ndarray:
    """Indices of the particles on the beam's centre line (x = w/2, y = h/2), sorted by z; for an
    odd number of cells across, the two nearest lines are averaged by the caller."""
    cx, cy = (X[:, 0].min() + X[:, 0].max()) / 2, (X[:, 1].min() + X[:, 1].max()) / 2
    d = np.hypot(X[:, 0] - cx, X[:, 1] - cy)
    sel = np.flatnonzero(d <= d.min() + 1e-9)
    return sel[np.argsort(X[sel, 2], kind="stable")]


def neutral_axis(X: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(z, mean vertical displacement u_y) along the beam's centre line."""
    sel = centre_line(X)
    z = np.round(X[sel, 2], 12)
    zs = np.unique(z)
    uy = np.array([u[sel][z == v, 1].mean() for v in zs])
    return zs, uy


def tip_deflection(X: np.ndarray, u: np.ndarray) -> float:
    """Signed vertical displacement of the free end's centre (m)."""
    z, uy = neutral_axis(X, u)
    return float(uy[np.argmax(z)])
