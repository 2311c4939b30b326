"""Trajectory metrics on synthetic damped sinusoids of known period, damping and phase."""

import math

import numpy as np
import pytest

from hybmss.trajectory import Trajectory
from studies.sweep.dynamics import metrics, oscillation, trajectory_oscillation

T, ZETA, A, OFFSET = 0.37, 0.02, 1.5, 0.3


def damped(t, period=T, zeta=ZETA, amp=A, offset=OFFSET, phase=0.4):
    wd = 2 * math.pi / period
    wn = wd / math.sqrt(1 - zeta**2)
    return offset + amp * np.exp(-zeta * wn * t) * np.cos(wd * t + phase)


def traj(t, x, axis=1, status="ok", reason="", wall=1.0):
    u = np.zeros((len(t), 3))
    u[:, axis] = x
    return Trajectory("synthetic", t, u, (0.0, 0.0, 0.0), float(t[1] - t[0]), wall, status=status, reason=reason)


# samples not commensurate with the period (the sampling phase drifts from cycle to cycle)
t = np.linspace(0.0, 10.3 * T, 2713)


@pytest.mark.parametrize("zeta", [0.0, 0.002, 0.02, 0.1])
def test_period_and_damping_of_a_clean_signal(zeta):
    o = oscillation(t, damped(t, zeta=zeta))
    assert o.ok
    assert o.period == pytest.approx(T, rel=1e-5)
    assert o.zeta == pytest.approx(zeta, abs=1e-5 + 1e-3 * zeta)


def test_noisy_signal():
    """Noise of 1 % of the amplitude: the hysteresis band keeps one crossing per passage."""
    rng = np.random.default_rng(3)
    x = damped(t) + 0.015 * rng.standard_normal(len(t))
    o = oscillation(t, x)
    assert len(o.crossings) == len(oscillation(t, damped(t)).crossings) == 21  # 10.3 periods from phase 0.4
    assert o.period == pytest.approx(T, rel=3e-3)
    assert o.zeta == pytest.approx(ZETA, rel=0.15)


def test_no_oscillation_and_divergence_give_reasons():
    o = oscillation(t, OFFSET + np.exp(-t))  # overdamped decay: no crossing
    assert not o.ok and o.period is None and "does not oscillate" in o.reason
    x = damped(t)
    x[400] = np.inf
    o = oscillation(t, x)
    assert not o.ok and o.reason.startswith("diverged") and f"{t[400]:.4g}" in o.reason
    assert "does not oscillate" in oscillation(t, np.full(len(t), 2.0)).reason
    stopped = traj(t, x, status="diverged", reason="particle 3 beyond 10 body sizes")
    assert "particle 3" in trajectory_oscillation(stopped).reason


def test_metrics_against_a_reference():
    """A model 2 % slower than the reference and damped at ζ = 0.01: period error 2 %, the
    phase lag after N periods 2π N · 0.02 / 1.02 (crossing 2N − 1 of each), and the L2 error of
    the known difference."""
    ref = traj(t, damped(t, zeta=0.0, offset=0.0, phase=0.0), wall=0.5)
    tm = np.linspace(0.0, 10.3 * T, 5000)
    model = traj(tm, damped(tm, period=1.02 * T, zeta=0.01, offset=0.0, phase=0.0), wall=2.0)
    m = metrics(model, ref, periods=3)
    assert m["reason"] == ""
    assert m["period_error"] == pytest.approx(0.02, abs=1e-5)
    assert m["zeta"] == pytest.approx(0.01, abs=1e-5) and abs(m["zeta_ref"]) < 1e-6
    # crossing k of cos(ωt) at (2k+1)T/4: the shift at k = 2N − 1 is (2k+1)/4 · 0.02 T
    assert m["phase_error_rad"] == pytest.approx(2 * math.pi * (4 * 3 - 1) / 4 * 0.02, rel=1e-4)
    assert m["l2_error"] > 0.1  # 2 % of a period over 10 periods: a large phase drift
    exact = np.sqrt(np.trapezoid((np.interp(t, tm, model.u[:, 1]) - ref.u[:, 1]) ** 2, t) / t[-1]) / A
    assert m["l2_error"] == pytest.approx(exact, rel=1e-9)
    assert m["wall_per_simulated_s"] == pytest.approx(2.0 / tm[-1])
    same = metrics(ref, ref)
    assert same["period_error"] == 0.0 and same["l2_error"] == 0.0 and same["phase_error_rad"] == 0.0


def test_metrics_of_a_failed_run_are_none_with_the_reason():
    ref = traj(t, damped(t))
    flat = traj(t, np.zeros(len(t)))
    m = metrics(flat, ref)
    assert m["period"] is None and m["l2_error"] is None and "does not oscillate" in m["reason"]
    with pytest.raises(ValueError, match="reference"):
        metrics(ref, flat)
