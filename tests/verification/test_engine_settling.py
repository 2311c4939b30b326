"""When a damped rest run whose rest test has a floor has settled (:class:`hybmss.explicit.Settling`):
on synthetic motions whose answer is known, and on an engine's rest run (pbd-xpbd-fem, float64,
XPBD's bias below its residual test) against the same run held to the fixed wait of
:data:`hybmss.models._engine_model.SETTLE`."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hybmss.explicit import SETTLED_CHECKS, SETTLED_EARLIEST, Settling

W1, T = 2.0, 2.0 * math.pi / 2.0
RTOL = 1e-3
X = np.zeros((4, 3))
U = np.array([1.0, 0.0, 0.0])


def first_settled(motion, settle: float = 20.0) -> float:
    """The first check time (1/ω₁ apart from the ramp's end on) at which ``motion(t)`` (4, 3) is settled."""
    s = Settling(X, T, W1, settle, RTOL)
    for k in range(200):
        t = T + k / W1
        if s.update(t, motion(t)):
            return (t - T) * W1
    return math.inf


def decaying(a: float, w: float):
    """The static displacement U on node 0 plus a mode of relative amplitude a, frequency w, decaying as e^(-ω₁ t)."""
    def x(t):
        out = X.copy()
        out[0] = U * (1.0 + a * math.exp(-W1 * (t - T)) * math.cos(w * (t - T)))
        return out
    return x


def test_a_still_body_settles_at_the_earliest_time():
    assert first_settled(decaying(0.0, 0.0)) == pytest.approx(SETTLED_EARLIEST)


def test_a_decaying_mode_settles_once_its_change_is_within_tolerance():
    """A mode decaying as e^(-ω₁ t) (slow, not oscillating) changes by a (1 - e^-1) e^-(k-1) over the
    interval ending at check k: settled at the SETTLED_CHECKS-th check whose change is within tolerance."""
    a = 2.0
    k = math.ceil(1.0 + math.log(a * (1.0 - math.exp(-1.0)) / RTOL)) + SETTLED_CHECKS - 1
    assert first_settled(decaying(a, 0.0)) == pytest.approx(max(k, SETTLED_EARLIEST))


def test_a_mode_the_checks_alias_is_seen_through_its_decay():
    """A mode whose period is the check interval looks still at every check but for its decay."""
    a = 0.2
    slow = first_settled(decaying(a, 0.0))
    assert first_settled(decaying(a, 2.0 * math.pi * W1)) == pytest.approx(slow)


def test_an_undamped_motion_waits_for_the_latest_time():
    def x(t):
        out = X.copy()
        out[0] = U * (1.0 + 1e-2 * math.cos(0.5 * W1 * (t - T)))
        return out
    assert first_settled(x, settle=20.0) == pytest.approx(20.0)


def test_shorter_intervals_are_not_counted():
    """The last call of a loop's chunk may end before a full interval: its change is not a check."""
    s = Settling(X, T, W1, 20.0, RTOL)
    x = decaying(0.2, 0.0)
    times = [T + k / W1 for k in range(int(SETTLED_EARLIEST) + 1)] + [T + (SETTLED_EARLIEST + 0.01) / W1]
    quiet = [s.update(t, x(t)) for t in times]
    assert not any(quiet) and s.quiet == 0


@pytest.mark.slow
def test_pbd_rest_state_settles_to_the_fixed_waits_state(monkeypatch):
    """pbd-xpbd-fem's rest run on a 2×2×4 column stretched 1 % (float64: XPBD's bias, not rounding,
    is its floor): settled in fewer steps than the fixed wait of SETTLE/ω₁, its state within
    its rest tolerance (1e-3) of the largest displacement of that run's."""
    pytest.importorskip("pypbd")
    import hybmss.explicit.rest as rest
    from hybmss import Body, Material, Model, Motion, Plate, Region, Scene
    from hybmss.solve import solve_static

    scene = Scene(body=Body.box(2, 2, 4, le=0.25), material=Material(E=1e4, nu=0.3, rho=1000.0),
                  model=Model("pbd-xpbd-fem"),
                  plates=(Plate("bottom", Region("z-")), Plate("top", Region("z+"), Motion("translate", (0, 0, 0.01)))))
    fast = solve_static(scene)
    monkeypatch.setattr(rest, "SETTLED_CHECKS", 10**6)
    fixed = solve_static(scene)
    w1 = fast.info["omega_1"]
    assert fast.info["t_end"] < fixed.info["t_end"] - 5.0 / w1
    from hybmss.models.pbd import STATIC_REST_RTOL

    assert np.abs(fast.u - fixed.u).max() <= STATIC_REST_RTOL * np.abs(fixed.u).max()
