"""The rest test of an explicit run: at rest when the load ramp is complete, the free force
residual ``‖f_free‖₂ ≤ rtol · scale`` and the kinetic energy
``≤ rtol² · max(|elastic energy|, scale · le)``, the force scale being the largest plate wrench,
the weight or the dead load (:func:`force_scale`)."""

from __future__ import annotations

import math

import numpy as np

from ..system import System
from ..terms import DeadLoad

REST_RTOL = 1e-3
"""Default tolerance of the rest criterion of an explicit run (:func:`rest_report`)."""


ELASTIC_PARTS = ("springs", "volume", "strain")
"""Energy parts of a stepper (:mod:`hybmss.stepper`) that count as elastic energy in :func:`rest_report`."""


def plate_wrench_scale(x: np.ndarray, f: np.ndarray) -> float:
    """Force scale of the forces ``f`` (k, 3) on one plate's particles at ``x`` (k, 3): the larger
    of their net force ``|Σ f|`` and their moment about the particles' centroid over the
    particles' radius of gyration ``|Σ (x − x̄) × f| / √(mean |x − x̄|²)``.  The second is the net
    force of a couple's forces were they aligned (for forces ∝ the lever arm, as in torsion, it
    is ``√(k Σ |f|²)`` ≥ ``Σ |f|``), so a plate that only twists or bends is measured against
    the forces it carries: a top plate twisted by 1° carries ~1e3 N·m but a net force of
    ~θ² (6 N on the 4×4×4 cube of 5 m at ν = 0)."""
    net = float(np.linalg.norm(f.sum(axis=0)))
    r = x - x.mean(axis=0)
    gyration = math.sqrt(float(np.mean(np.einsum("ij,ij->i", r, r))))
    if gyration <= 0.0:
        return net
    return max(net, float(np.linalg.norm(np.cross(r, f).sum(axis=0))) / gyration)


def force_scale(system: System, f_int: np.ndarray, x: np.ndarray | None = None) -> float:
    """Force scale of a state at positions ``x`` (default: the reference positions): the largest
    plate reaction over the plates (:func:`plate_wrench_scale`: net force or moment over the
    plate's radius of gyration), the weight ``|Σ m g|``, the total dead load, and
    ``1e-12 E le²`` (a floor for a body that nothing loads)."""
    f = f_int if system.gravity is None else f_int + system.mass[:, None] * system.gravity[None, :]
    x = system.X if x is None else np.asarray(x)
    scale = 0.0
    for p in system.plates:
        scale = max(scale, plate_wrench_scale(x[p.particles], f[p.particles]))
    if system.gravity is not None:
        scale = max(scale, float(np.linalg.norm(system.mass.sum() * system.gravity)))
    for t in system.terms:
        if isinstance(t, DeadLoad):
            scale = max(scale, float(np.linalg.norm(t.f.sum(axis=0))))
    return max(scale, 1e-12 * system.scene.material.E * system.scene.body.le**2)


def rest_report(system: System, f_int: np.ndarray, energy: dict, load_factor: float,
                rtol: float = REST_RTOL, x: np.ndarray | None = None) -> dict:
    """Whether an explicit run ended at rest, and the figures behind the verdict.

    At rest means all three of: the load ramp is complete (``load_factor == 1``); the force
    residual on the free degrees of freedom ``‖f_free‖₂ ≤ rtol · scale`` (:func:`force_scale` at
    the positions ``x``, default the reference positions);
    the kinetic energy ``≤ rtol² · max(|elastic energy|, scale · le)``.  A vibration of relative
    amplitude a about the equilibrium has residual ~ a · scale and kinetic energy up to
    ~ a² · elastic energy, so both tests ask for a ≲ rtol.  An undamped run rarely passes: set
    a damping c of the order of the slowest mode's frequency to settle it.
    """
    f = f_int if system.gravity is None else f_int + system.mass[:, None] * system.gravity[None, :]
    free = ~system.fixed
    residual = float(np.linalg.norm(f[free]))
    scale = force_scale(system, f_int, x)
    elastic = float(sum(energy.get(k, 0.0) for k in ELASTIC_PARTS))
    e_scale = max(abs(elastic), scale * system.scene.body.le)
    ke = float(energy["kinetic"])
    ramp_done = load_factor >= 1.0
    ok_res = residual <= rtol * scale
    ok_ke = ke <= rtol * rtol * e_scale
    at_rest = bool(ramp_done and ok_res and ok_ke)
    why = []
    if not ramp_done:
        why.append(f"the load ramp is at s = {load_factor:.3g} < 1 (run longer than ramp_time)")
    if not ok_res:
        why.append(f"force residual {residual:.3g} N > {rtol:g} x scale {scale:.3g} N")
    if not ok_ke:
        why.append(f"kinetic energy {ke:.3g} J > {rtol:g}^2 x {e_scale:.3g} J")
    return {
        "at_rest": at_rest,
        "criterion": (f"load ramp complete, free force residual <= {rtol:g} x force scale, "
                      f"kinetic energy <= {rtol:g}^2 x max(|elastic energy|, scale x le)"),
        "rtol": float(rtol),
        "residual_N": residual,
        "force_scale_N": scale,
        "relative_residual": residual / scale,
        "kinetic_energy_J": ke,
        "elastic_energy_J": elastic,
        "relative_kinetic_energy": ke / e_scale,
        "load_factor": float(load_factor),
        "not_at_rest_because": "; ".join(why) if why else None,
    }


def stepper_rest(nodes: System, st, f_int: np.ndarray, energy: dict, load_factor: float, rtol: float,
                 x: np.ndarray | None = None) -> dict:
    """:func:`rest_report` of a stepper's state on its nodes; a stepper with a force resolution
    (``force_resolution_N`` > 0: a float32 engine, whose state cannot have a smaller residual)
    is judged with a tolerance of at least that resolution over the force scale (reported as
    ``resolution_N``)."""
    rest = rest_report(nodes, f_int, energy, load_factor, rtol, x)
    res = float(getattr(st, "force_resolution_N", 0.0))
    if res > 0.0:
        rest = rest_report(nodes, f_int, energy, load_factor, max(rtol, res / rest["force_scale_N"]), x)
        rest["resolution_N"] = res
    return rest
