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


def free_residual(system: System, f_int: np.ndarray) -> float:
    """``‖f_free‖₂``: the force (internal, gravity) left on the free degrees of freedom."""
    f = f_int if system.gravity is None else f_int + system.mass[:, None] * system.gravity[None, :]
    return float(np.linalg.norm(f[~system.fixed]))


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
    residual = free_residual(system, f_int)
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


def decay_rate(c: float, w1: float) -> float:
    """Slowest decay rate (1/s) of the envelope of a linear mode of frequency ``w1`` or higher under
    mass-proportional damping ``c``: ``c/2`` when ``w1 ≥ c/2`` (every mode underdamped or critical,
    amplitude ``∝ e^(−c t/2)``), else the overdamped slowest root ``c/2 − √(c²/4 − ω₁²)``."""
    half = 0.5 * float(c)
    w1 = float(w1)
    if half <= 0.0 or w1 <= 0.0:
        return 0.0
    return half if w1 >= half else half - math.sqrt(half * half - w1 * w1)


FLOOR_WINDOW = 2.0
"""Length of a window of :class:`ResidualFloor` in e-folds of the slowest envelope (``2/σ``): the
transient's largest value falls by ``q = e^(−2)`` from one window to the next, so a flat residual
``m`` proves a floor of at least ``(1 − q)/(1 + q) m = 0.76 m``."""
FLOOR_SAMPLES = 16
"""Samples of the force residual per window of :class:`ResidualFloor`.  A window's extremes are
those of its samples: with 16 a sine of the window's length is seen within 2 % of its amplitude."""
FLOOR_MARGIN = 1.25
"""How far above the rest tolerance the bound on the residual at the end of the budget must be
for :class:`ResidualFloor` to stop a run (the force scale the tolerance multiplies moves a little
with the state)."""


class ResidualFloor:
    """Whether the free force residual of a damped explicit run has a floor that the rest test's
    tolerance can never pass within the budget, so that the rest of the run cannot answer.

    A stepper whose rest state is the fixed point of its own step rather than the equilibrium of
    its force law (XPBD: one Gauss–Seidel sweep a substep leaves a bias, larger the stiffer the
    volume constraint) ends at a state whose force residual ``r*`` need not vanish.  After the
    load ramp, the residual is ``r(t) = |f* + K e(t)|`` with ``e`` the transient, whose envelope
    decays at least as ``e^(−σ t)`` (:func:`decay_rate` of the damping and the lowest frequency).
    Over consecutive windows of :data:`FLOOR_WINDOW`/σ (a factor ``q = e^(−2)``) with the sampled extremes
    ``max_{k−1}`` and ``min_k`` of the relative residual, the triangle inequality gives

    - ``r* ≥ L = (min_k − q max_{k−1}) / (1 + q)`` (the transient at its largest in window k is at
      most ``q`` times its largest in window k−1, itself at most ``max_{k−1} + r*``);
    - a transient at the end of the budget, ``j`` windows later, of at most
      ``q^j q (max_{k−1} + min_k) / (1 − q)``.

    When ``L`` minus that last bound exceeds :data:`FLOOR_MARGIN` times the tolerance, the
    residual at the end of the budget is above the tolerance whatever the run does until then:
    :meth:`update` returns True (stop: not at rest).  A residual that decays as a transient does
    (by ``q`` a window) gives ``L ≤ 0`` and never stops a run; a run without damping is never
    stopped.  Measured on xpbd-nh stretched 5 % at ν = 0.499 (4×4×24 beam, 9 substeps of 1 ms
    frames): the relative residual falls to 0.0102–0.0105 by t = 3 s and stays there (10× the
    tolerance 1e-3) while the kinetic energy still falls 40-fold by t = 4 s.
    """

    def __init__(self, T: float, sigma: float, rtol: float, t_end: float):
        self.T, self.rtol, self.t_end = float(T), float(rtol), float(t_end)
        self.window = FLOOR_WINDOW / float(sigma) if sigma > 0.0 else math.inf
        self.q = math.exp(-FLOOR_WINDOW)
        self.k = -1  # current window
        self.cur: list[float] = []
        self.last: list[float] | None = None  # samples of the window before
        self.bound: float | None = None

    @property
    def active(self) -> bool:
        """Whether the budget holds the two windows and a third after the ramp that a verdict needs."""
        return math.isfinite(self.window) and self.t_end - self.T >= 3.0 * self.window

    def sample_times(self) -> float:
        """Simulated time between samples."""
        return self.window / FLOOR_SAMPLES

    def update(self, t: float, relative_residual: float) -> bool:
        if not self.active or t < self.T:
            return False
        k = int((t - self.T) / self.window)
        if k != self.k:
            full = len(self.cur) >= FLOOR_SAMPLES - 1
            self.last = self.cur if full and k == self.k + 1 else None
            self.cur, self.k = [], k
        self.cur.append(float(relative_residual))
        if self.last is None or len(self.cur) < FLOOR_SAMPLES - 1:
            return False
        # window k complete enough: its minimum against the window before's maximum
        mx, mn, q = max(self.last), min(self.cur), self.q
        lower = (mn - q * mx) / (1.0 + q)
        windows_left = max(0.0, (self.t_end - t) / self.window)
        left = q ** windows_left * q * (mx + mn) / (1.0 - q)
        self.bound = lower - left
        return self.bound > FLOOR_MARGIN * self.rtol


SETTLED_CHECKS = 2
"""Consecutive checks (1/ω₁ apart) whose change is within the rest tolerance (:class:`Settling`).  A mode whose
period divides the interval is caught at the same phase at every check and still seen through its
decay (e^-1 an interval); caught at its zero crossings, where the displacement cannot see it, its
velocity is largest and the rest test's kinetic energy bounds it."""
SETTLED_EARLIEST = 5.0
"""Time after the ramp, in 1/ω₁, before which no state counts as settled (the ramp's transient
decays by e^-5 first)."""


class Settling:
    """Whether a damped run (damping 2 ω₁, load ramp of ``T``) whose rest test has a floor (a
    float32 engine's force resolution, XPBD's bias: its residual cannot tell the slowest mode from
    rest) has settled at time ``t``: from ``T`` + :data:`SETTLED_EARLIEST`/ω₁ on, once the largest
    node displacement over each of the last :data:`SETTLED_CHECKS` intervals of 1/ω₁ is within
    ``rtol`` of the largest displacement, and in any case from ``T + settle/ω₁`` (``settle`` =
    :data:`hybmss.models._engine_model.SETTLE`).

    ``rtol`` is the rest test's own (:func:`rest_report`): it asks the residual for a vibration of
    relative amplitude ≲ rtol; this asks the same of the slowest mode, which moves too slowly for
    the residual to see.  With the damping 2 ω₁ every mode decays at least as e^(−ω₁ t), so what
    is left of the motion is of the order of the last change.  Measured on the 4 mm cylinder
    twisted 30° at ν = 0.49 (rtol 1e-3) against the fixed wait of 20/ω₁: pbd-xpbd-fem in 12,936
    steps instead of 29,106, its state within 3.4e-4 of the displacement; newton-vbd 468 instead of
    972, within 1.4e-4; newton-semi 432 instead of 972, within 3.9e-4.  newton-vbd (float32, 10
    Gauss–Seidel iterations a step) on the 2 mm cylinder squeezed 10 % at ν = 0.49 jitters by
    5e-5 … 2.6e-4 of the displacement from one check to the next from 5/ω₁ after the ramp to the
    end of the fixed wait: a floor no wait lowers.
    ``update`` is called at every check from ``T`` on, 1/ω₁ apart (shorter intervals, the last
    call of a loop's chunk, are skipped)."""

    def __init__(self, X: np.ndarray, T: float, w1: float, settle: float, rtol: float):
        self.rtol = float(rtol)
        self.X = np.asarray(X, dtype=float)
        self.interval = 1.0 / float(w1)
        self.earliest = float(T) + SETTLED_EARLIEST / float(w1)
        self.latest = float(T) + float(settle) / float(w1)
        self.prev: np.ndarray | None = None
        self.t_prev = -math.inf
        self.quiet = 0

    def update(self, t: float, x: np.ndarray) -> bool:
        x = np.asarray(x, dtype=float)
        if t - self.t_prev >= 0.99 * self.interval:
            if self.prev is not None:
                u = float(np.abs(x - self.X).max())
                moved = float(np.abs(x - self.prev).max())
                self.quiet = self.quiet + 1 if u > 0.0 and moved <= self.rtol * u else 0
            self.prev, self.t_prev = x.copy(), float(t)
        return t >= self.latest or (t >= self.earliest and self.quiet >= SETTLED_CHECKS)
