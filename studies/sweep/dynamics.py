"""Metrics of a released transient: first period, numerical damping, phase and trajectory errors.

From one point's displacement history ``x(t)`` (a :class:`hybmss.trajectory.Trajectory`, the
component along which the reference moves most):

- **period** ``T``: the signal oscillates about a level ``x̄`` (first its mean, then the level its
  half-cycle extrema decay to, :func:`centre`); its crossings of ``x̄`` are found
  with a hysteresis band of ``BAND`` × the amplitude (noise does not add crossings) and located by
  linear interpolation at the last sign change before the signal leaves the band; ``T`` is twice the
  slope of the least-squares line through the crossing times against their index (for a damped
  sinusoid ``x = A e^{−ζωt} cos(ω_d t)`` the crossings are exactly ``T_d/2`` apart);
- **damping ratio** ``ζ`` by the logarithmic decrement: the peak ``|x − x̄|`` of every half cycle
  between two crossings (a parabola through the largest sample and its neighbours), ``ln A_k``
  fitted linearly in ``t_k``: slope ``−σ``, decrement per period ``δ = σ T``, and
  ``ζ = δ / √(4π² + δ²)`` (exact for a damped sinusoid).  It is the decay of that component: energy
  passed to another mode (e.g. the other bending plane of a mesh whose tetrahedral split couples
  the two) counts as damping here;
- **phase error after N periods**: ``2π (t_m − t_r) / T_r`` between the crossings of index
  ``2N − 1`` of the model and the reference (each fitted line's value there), radians;
- **L2 trajectory error**: ``√(∫ |u_m − u_r|² dt / t_span) / max |u_r|``, the model interpolated at
  the reference's samples over their common span; ``max |u_r|`` is the static deflection under the
  released load, the scale the load defines.

A trajectory that is not finite, stopped early or crosses its mean fewer than
:data:`MIN_CROSSINGS` times gives no metrics and a reason.  Pure NumPy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hybmss.trajectory import Trajectory

BAND = 0.05
"""Hysteresis band of the crossing detector, as a fraction of the signal's largest |x − x̄|."""
MIN_CROSSINGS = 3
"""Crossings needed for a period (one full period and one more half)."""


@dataclass(frozen=True)
class Oscillation:
    """The first-mode figures of one signal, or ``reason`` why there are none (then all ``None``)."""

    period: float | None = None
    zeta: float | None = None
    amplitude: float | None = None
    crossings: np.ndarray | None = None
    reason: str = ""

    @property
    def ok(self) -> bool:
        return not self.reason


def finite_reason(t: np.ndarray, x: np.ndarray) -> str:
    """Why samples are unusable (non-finite), or ``''``."""
    bad = ~np.isfinite(x).reshape(len(t), -1).all(axis=1)
    if bad.any():
        return f"diverged: non-finite displacement at t = {float(t[np.argmax(bad)]):.4g} s"
    return ""


def crossings(t: np.ndarray, y: np.ndarray, band: float) -> np.ndarray:
    """Times at which ``y`` changes sign, counted once per passage from below ``−band`` to above
    ``+band`` (or back): the last sign change before leaving the band, linearly interpolated."""
    out = []
    side = 0  # -1 below the band, +1 above, 0 not yet outside
    last_change = None
    for i in range(1, len(y)):
        if (y[i - 1] < 0.0) != (y[i] < 0.0):
            last_change = i
        s = 1 if y[i] > band else -1 if y[i] < -band else 0
        if s == 0:
            continue
        if side != 0 and s != side and last_change is not None:
            j = last_change
            out.append(t[j - 1] + (t[j] - t[j - 1]) * y[j - 1] / (y[j - 1] - y[j]))
        side = s
    return np.asarray(out)


def half_cycle_peaks(t: np.ndarray, y: np.ndarray, tc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Time and size of the largest ``|y|`` between consecutive crossings ``tc`` (a parabola through
    the largest sample and its neighbours)."""
    times, peaks = [], []
    for a, b in zip(tc[:-1], tc[1:]):
        idx = np.flatnonzero((t > a) & (t < b))
        if len(idx) == 0:
            continue
        i = idx[np.argmax(np.abs(y[idx]))]
        if 0 < i < len(y) - 1:
            y0, y1, y2 = np.abs(y[i - 1:i + 2])
            den = y0 - 2.0 * y1 + y2
            s = 0.5 * (y0 - y2) / den if den < 0 else 0.0
            s = float(np.clip(s, -1.0, 1.0))
            times.append(t[i] + s * (t[i + 1] - t[i]))
            peaks.append(y1 - 0.25 * (y0 - y2) * s)
        else:
            times.append(t[i])
            peaks.append(abs(y[i]))
    return np.asarray(times), np.asarray(peaks)


def oscillation(t, x) -> Oscillation:
    """Period, damping ratio and amplitude of the signal ``x(t)`` (module docstring)."""
    t, x = np.asarray(t, dtype=float), np.asarray(x, dtype=float)
    why = finite_reason(t, x)
    if why:
        return Oscillation(reason=why)
    if len(t) < 4:
        return Oscillation(reason=f"does not oscillate: {len(t)} samples")
    y = x - x.mean()
    amp = float(np.abs(y).max())
    if amp == 0.0:
        return Oscillation(reason="does not oscillate: the signal is constant")
    tc = crossings(t, y, BAND * amp)
    for _ in range(3):  # re-centre on the equilibrium the half cycles' extrema decay to, and find them again
        if len(tc) < MIN_CROSSINGS + 1:
            break
        y = y - centre(t, y, tc)
        tc = crossings(t, y, BAND * amp)
    if len(tc) < MIN_CROSSINGS:
        return Oscillation(reason=f"does not oscillate: {len(tc)} crossings of its mean in {t[-1] - t[0]:.4g} s "
                                  f"(a period needs {MIN_CROSSINGS})")
    k = np.arange(len(tc))
    half = np.polyfit(k, tc, 1)[0]
    T = 2.0 * float(half)
    tp, ap = half_cycle_peaks(t, y, tc)
    keep = ap > 0
    zeta = None
    if keep.sum() >= 2:
        sigma = -float(np.polyfit(tp[keep], np.log(ap[keep]), 1)[0])
        delta = sigma * T
        zeta = delta / math.sqrt(4.0 * math.pi**2 + delta**2)
    return Oscillation(T, zeta, float(np.abs(y).max()), tc)


def centre(t: np.ndarray, y: np.ndarray, tc: np.ndarray) -> float:
    """The level ``c`` about which the signed half-cycle extrema ``e_k`` of ``y`` decay
    geometrically, ``e_{k+1} − c = −r (e_k − c)`` (a damped sinusoid's extrema are ``T_d/2``
    apart, each ``r = e^{−σ T_d/2}`` times the last): the least-squares line
    ``e_{k+1} = −r e_k + c (1 + r)``; the mean of the extrema with fewer than three of them."""
    tp, ap = half_cycle_peaks(t, y, tc)
    if len(ap) < 2:
        return 0.0
    sign = np.sign(np.interp(tp, t, y))
    e = sign * ap
    if len(e) < 3:
        return float(e.mean())
    slope, icpt = np.polyfit(e[:-1], e[1:], 1)
    r = -float(slope)
    return float(icpt / (1.0 + r)) if r > 0 else float(e.mean())


def dominant_axis(traj: Trajectory) -> int:
    """The component along which the point moves most (the released load's direction)."""
    u = traj.u[np.all(np.isfinite(traj.u), axis=1)]
    return int(np.argmax(np.ptp(u, axis=0))) if len(u) else 0


def trajectory_oscillation(traj: Trajectory, axis: int | None = None) -> Oscillation:
    """:func:`oscillation` of a trajectory's component ``axis`` (default: :func:`dominant_axis`);
    none for a run that stopped early."""
    if not traj.ok:
        return Oscillation(reason=f"{traj.status}: {traj.reason}")
    why = finite_reason(traj.t, traj.u)
    if why:
        return Oscillation(reason=why)
    return oscillation(traj.t, traj.component(dominant_axis(traj) if axis is None else axis))


def l2_error(traj: Trajectory, ref: Trajectory) -> float:
    """``√(∫ |u − u_ref|² dt / span) / max |u_ref|`` over the common span (module docstring)."""
    end = min(traj.t[-1], ref.t[-1])
    sel = ref.t <= end + 1e-12 * max(end, 1.0)
    tr = ref.t[sel]
    um = np.stack([np.interp(tr, traj.t, traj.u[:, c]) for c in range(3)], axis=1)
    d2 = np.sum((um - ref.u[sel]) ** 2, axis=1)
    span = tr[-1] - tr[0]
    scale = float(np.linalg.norm(ref.u, axis=1).max())
    return math.sqrt(float(np.trapezoid(d2, tr)) / span) / scale


def phase_error(model: Oscillation, ref: Oscillation, periods: int) -> float | None:
    """``2π (t_m − t_r) / T_r`` at crossing ``2N − 1`` of the fitted crossing lines, or ``None``
    when either has fewer than two crossings."""
    k = 2 * int(periods) - 1

    def at(o: Oscillation) -> float | None:
        if o.crossings is None or len(o.crossings) < 2:
            return None
        c = np.polyfit(np.arange(len(o.crossings)), o.crossings, 1)
        return float(np.polyval(c, k))

    tm, tr = at(model), at(ref)
    if tm is None or tr is None:
        return None
    return 2.0 * math.pi * (tm - tr) / ref.period


def metrics(traj: Trajectory, ref: Trajectory, periods: int = 3) -> dict:
    """The model's figures against the reference: ``period_error`` (T/T_ref − 1), ``zeta`` and
    ``zeta_ref``, ``phase_error_rad`` after ``periods`` periods, ``l2_error``, the wall time per
    simulated second, and ``reason`` (``''`` when the figures exist; else they are ``None``)."""
    axis = dominant_axis(ref)
    o_ref = trajectory_oscillation(ref, axis)
    if not o_ref.ok:
        raise ValueError(f"the reference has no first period: {o_ref.reason}")
    out = {"solver": traj.solver, "dt": traj.dt, "period_ref": o_ref.period, "zeta_ref": o_ref.zeta,
           "wall_per_simulated_s": traj.wall_per_simulated_second(), "period": None, "period_error": None,
           "zeta": None, "phase_error_rad": None, "l2_error": None, "reason": ""}
    o = trajectory_oscillation(traj, axis)
    if not o.ok:
        out["reason"] = o.reason
        return out
    out.update(period=o.period, period_error=o.period / o_ref.period - 1.0, zeta=o.zeta,
               phase_error_rad=phase_error(o, o_ref, periods), l2_error=l2_error(traj, ref))
    return out
