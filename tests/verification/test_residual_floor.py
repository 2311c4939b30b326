"""When a damped explicit run's force residual has a floor its rest test can never pass
(:class:`hybmss.explicit.rest.ResidualFloor`): on synthetic residuals whose end value is known (the
verdict must never stop a run that would end at rest), and on xpbd-nh, whose rest state keeps a
residual at ν = 0.499, against the same run taken to the end of its budget."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hybmss.experiments import SceneSpec
from hybmss.explicit.rest import FLOOR_SAMPLES, FLOOR_WINDOW, ResidualFloor, decay_rate
from hybmss.models import xpbd_nh
from studies.sweep.runner import SolverSpec, Task, solve

RTOL = 1e-3
T_RAMP, T_END = 1.0, 10.0


@pytest.mark.parametrize("c, w1", [(2.0, 5.0), (2.0, 1.0), (2.0, 0.4), (10.0, 1.0), (0.5, 3.0)])
def test_decay_rate_is_the_slowest_root_of_the_damped_oscillator(c, w1):
    roots = np.roots([1.0, c, w1 * w1])  # s² + c s + ω² = 0: the mode's exponents
    assert decay_rate(c, w1) == pytest.approx(min(-r.real for r in roots), rel=1e-9)


def verdict(residual, sigma: float):
    """(stop time or None, the floor's bound there) of a ResidualFloor fed ``residual(t)`` at its sampling."""
    f = ResidualFloor(T_RAMP, sigma, RTOL, T_END)
    dt = f.sample_times()
    for i in range(int((T_END - T_RAMP) / dt) + 1):
        t = T_RAMP + i * dt
        if f.update(t, residual(t)):
            return t, f.bound
    return None, f.bound


def signal(rng, floor: float, sigma: float):
    """A residual ‖f* + Σ a_i e^(−σ_i t) cos(ω_i t + φ_i)‖ in three dimensions: a floor vector of
    norm ``floor`` and 1-3 transients decaying at σ_i ≥ σ, of random directions, frequencies from
    a tenth to twenty times σ (slower than a window, and faster) and amplitudes up to 100 rtol."""
    fstar = rng.normal(size=3)
    fstar *= floor / np.linalg.norm(fstar)
    modes = [(rng.normal(size=3) * rng.uniform(0.0, 100 * RTOL), sigma * rng.uniform(1.0, 2.0),
              sigma * rng.uniform(0.1, 20.0), rng.uniform(0, 2 * math.pi)) for _ in range(rng.integers(1, 4))]

    def r(t):
        v = fstar.copy()
        for a, s, w, p in modes:
            v += a * math.exp(-s * (t - T_RAMP)) * math.cos(w * (t - T_RAMP) + p)
        return float(np.linalg.norm(v))
    return r


def test_no_synthetic_residual_is_stopped_unless_it_ends_above_the_tolerance():
    rng = np.random.default_rng(7)
    stopped = wrong = 0
    for _ in range(3000):
        floor = RTOL * rng.choice([0.0, 0.5, 0.9, 1.0, 1.3, 2.0, 5.0, 20.0])
        r = signal(rng, floor, 1.0)
        t, _ = verdict(r, 1.0)
        if t is not None:
            stopped += 1
            wrong += r(T_END) <= RTOL
    assert wrong == 0
    assert stopped > 500  # the rule does stop runs (with floors of 2, 5, 20 rtol)


@pytest.mark.parametrize("floor", [3.0, 5.0, 20.0])
def test_a_floor_well_above_the_tolerance_stops_the_run_after_two_windows(floor):
    def r(t):  # the floor with a transient of half its size, ringing
        return floor * RTOL * abs(1.0 + 0.5 * math.exp(-(t - T_RAMP)) * math.cos(3.0 * (t - T_RAMP)))
    t, bound = verdict(r, 1.0)
    assert t is not None and t <= T_RAMP + 2 * FLOOR_WINDOW + 1e-9
    assert RTOL < bound <= r(T_END)


def test_a_pure_transient_or_an_undamped_run_is_never_stopped():
    r = signal(np.random.default_rng(5), 0.0, 1.0)
    assert r(T_RAMP) > 10 * RTOL and r(T_END) < RTOL
    assert verdict(r, 1.0)[0] is None
    assert verdict(lambda t: 10 * RTOL, 0.0)[0] is None  # σ = 0: no window, no verdict


def test_a_window_short_of_samples_gives_no_verdict():
    f = ResidualFloor(T_RAMP, 1.0, RTOL, T_END)
    dt = 2 * f.sample_times()  # half the samples a window needs
    assert not any(f.update(T_RAMP + i * dt, 10 * RTOL) for i in range(int((T_END - T_RAMP) / dt)))
    assert FLOOR_SAMPLES >= 8


def explicit(nu: float, d: float, floor_watch: bool, monkeypatch):
    monkeypatch.setattr(xpbd_nh.XpbdStepper, "rest_floor", floor_watch)
    sc = SceneSpec.default("tension", mesh=(1, 1, 6), nu=nu, deformation=d, model="xpbd-nh", damping=2.0)
    return solve(Task(sc, SolverSpec("explicit", dt=1e-3, steps=10_000, ramp_time=1.0)))


@pytest.mark.parametrize("d", [0.05, 0.2])
def test_xpbd_at_nu_0499_stops_at_its_floor_with_the_verdict_of_the_full_run(d, monkeypatch):
    early, full = explicit(0.499, d, True, monkeypatch), explicit(0.499, d, False, monkeypatch)
    assert not full.converged and not early.converged
    assert early.info["steps"] < 6_000 and early.info["floor_stop_t"] == pytest.approx(early.info["t_end"])
    # the bound it stopped on holds at the end of the budget, and is above the tolerance
    assert RTOL < early.info["floor_bound"] <= full.info["rest"]["relative_residual"]
    assert "floor_stop_t" not in full.info
    assert "force residual" in early.info["rest"]["not_at_rest_because"]


def test_the_watch_leaves_a_run_that_comes_to_rest_bit_for_bit(monkeypatch):
    watched, plain = explicit(0.45, 0.05, True, monkeypatch), explicit(0.45, 0.05, False, monkeypatch)
    assert watched.converged and watched.info["steps"] == 10_000
    assert "floor_stop_t" not in watched.info
    assert np.array_equal(watched.u, plain.u)


def test_a_flat_residual_gets_the_closed_form_bound_less_what_a_transient_could_still_remove():
    """A constant residual m: the floor is at least (1 − q)/(1 + q) m, less the transient that could
    be left at the budget's end, q^j · q (2 m)/(1 − q) for the j windows still to run."""
    m, q = 10 * RTOL, math.exp(-FLOOR_WINDOW)
    f = ResidualFloor(T_RAMP, 1.0, RTOL, T_RAMP + 3 * FLOOR_WINDOW)  # the shortest budget with a verdict
    dt = f.sample_times()
    t = next(T_RAMP + i * dt for i in range(1000) if f.update(T_RAMP + i * dt, m))
    j = (f.t_end - t) / f.window
    assert f.bound == pytest.approx((1 - q) / (1 + q) * m - q**j * q * 2 * m / (1 - q), rel=1e-12)


def test_the_command_line_and_the_equilibria_table_name_the_floor_and_its_remedy(monkeypatch):
    """A run stopped at its floor is a failure whose remedy is the substep's (more substeps or
    iterations lower XPBD's bias), not a longer run; the equilibria table says where it stopped."""
    import pandas as pd

    from studies.cli.common import SolveFailure, check_result
    from studies.paper.equilibria import _message

    from studies.sweep.runner import compute

    early = explicit(0.499, 0.05, True, monkeypatch)
    with pytest.raises(SolveFailure, match="raise --substeps or --iterations") as err:
        check_result(early, "explicit solve")
    assert "--steps" not in str(err.value)
    sc = SceneSpec.default("tension", mesh=(1, 1, 6), nu=0.499, deformation=0.05, model="xpbd-nh", damping=2.0)
    row, _ = compute(Task(sc, SolverSpec("explicit", dt=1e-3, steps=10_000, ramp_time=1.0)))  # the stored row
    assert row["status"] == "not-converged"
    assert f"stopped at t = {early.info['t_end']:.3g} s of 10 s" in _message(pd.Series(row), False)
    plain = explicit(0.499, 0.05, False, monkeypatch)
    with pytest.raises(SolveFailure, match="raise --steps or --damping"):
        check_result(plain, "explicit solve")
