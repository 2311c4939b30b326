"""The rule that does not run an explicit candidate which cannot come to rest in its step budget
(studies.sweep.rest_bound): its decay on a damped single-mode body against the closed form and the
scheme itself, the threshold on a real scene (one step below it is not run, at it the run is
computed), and the row of a run not computed counted as an expected non-answer."""

import math

import numpy as np
import pytest

from hybmss.experiments import SceneSpec
from studies.sweep import rest_bound
from studies.sweep.runner import Runner, SolverSpec, Task, no_result_because
from studies.sweep.store import Store

RTOL = 1e-3


def _rest_step(omega, c, dt, n_max=200_000):
    """First step at which a single mode suddenly loaded to the static displacement 1 passes the
    rest test (force residual |ω² e| <= rtol ω², kinetic energy ½ v² <= rtol² ½ ω²), stepping
    the harness's scheme v <- (v - dt ω² e) / (1 + c dt), e <- e + dt v from e = -1, v = 0."""
    e, v = -1.0, 0.0
    for n in range(1, n_max):
        v = (v - dt * omega**2 * e) / (1.0 + c * dt)
        e = e + dt * v
        if abs(e) <= RTOL and 0.5 * v * v <= RTOL**2 * 0.5 * omega**2:
            return n
    return n_max


@pytest.mark.parametrize("omega", [0.3, 0.8, 3.0, 20.0, 150.0])
def test_single_mode_decay_against_the_scheme_and_the_closed_form(omega):
    """c = 2 s⁻¹, dt = 1 ms.  Underdamped (ω > c/2 = 1): every step multiplies the amplitude by
    √d = (1 + c dt)^-½, the decay rate c/2 whatever ω; overdamped: the larger root of
    λ² − (1 + d − d ω² dt²) λ + d (the step matrix's eigenvalues, taken here from numpy).  The
    bound never exceeds the step at which the scheme passes the rest test, and is within 20 % of it."""
    c, dt = 2.0, 1e-3
    d = 1.0 / (1.0 + c * dt)
    A = np.array([[1.0 - d * (omega * dt) ** 2, d * dt], [-d * omega**2 * dt, d]])  # (e, v) -> next
    assert rest_bound.step_factor(omega, c, dt) == pytest.approx(max(abs(np.linalg.eigvals(A))), rel=1e-9)
    if omega > c / 2:
        assert rest_bound.step_factor(omega, c, dt) == pytest.approx(math.sqrt(d), rel=1e-12)
        closed = math.log(1 / (2 * RTOL)) / (0.5 * math.log(1 + c * dt))  # 6,220 steps: 6.2 s = 2/c ln(500)
        assert rest_bound.decay_steps(omega, c, dt, 1.0, RTOL) == math.ceil(closed)
    bound = rest_bound.steps_to_rest(dt, 0.0, omega, c, a0=1.0, rtol=RTOL)
    actual = _rest_step(omega, c, dt)
    assert bound <= actual <= 1.2 * bound, (bound, actual)


def test_ramp_steps_in_the_rest_tests_arithmetic():
    """The rest test asks for a complete ramp, n dt >= T (hybmss.explicit.ramp at n dt)."""
    from hybmss.explicit import ramp

    for dt, T in [(1e-3, 1.0), (1e-3, 0.1), (7e-4, 0.3), (0.25, 1.0)]:
        n = rest_bound.ramp_steps(dt, T)
        assert ramp(n * dt, T) == 1.0 and ramp((n - 1) * dt, T) < 1.0
    assert rest_bound.ramp_steps(1e-3, 0.0) == 0


def test_a_candidate_below_the_threshold_is_not_run_one_at_it_runs(tmp_path):
    """Compression of the 2³ cube, plates ramped over 0.1 s at dt = 1 ms: the ramp alone needs 100
    steps.  99 steps, of use only at rest: not run, stored as not at rest with the steps needed
    and the budget, counted as an expected non-answer and as not run; 100 steps: computed.  The
    same 99 steps asked for their state (not answer-only) is computed, and is indeed not at rest."""
    spec = SceneSpec.default("compression", mesh=(2, 2, 2), nu=0.25, deformation=0.05).replace(damping=2.0)
    solver = SolverSpec("explicit", dt=1e-3, steps=99, ramp_time=0.1)
    below = Task(spec, solver, "pareto", answer_only=True)
    at = Task(spec, SolverSpec("explicit", dt=1e-3, steps=100, ramp_time=0.1), "pareto", answer_only=True)
    runner = Runner(jobs=1, progress=False)
    store = Store(tmp_path)
    r_below, r_at = runner.run([below, at], store)
    assert r_below["skipped"] is True and r_below["status"] == "not-converged"
    assert "wall_time_s" not in r_below
    assert no_result_because(r_below) == ("not-converged: not at rest after 99 steps: not run, it needs at least "
                                          "100 steps to come to rest (the load ramp of 0.1 s at dt 0.001 s) "
                                          "and its budget is 99")
    assert "skipped" not in r_at and r_at["wall_time_s"] > 0 and r_at["steps"] == 100
    s = runner.summary
    assert (s.runs, s.computed, s.skipped, s.failed) == (2, 1, 1, 0)
    assert s.expected >= 1 and s.expected_by["pareto, not at rest within its step budget"] == s.expected
    assert "1 of them not run" in s.line()
    # asked for its state, the same run is computed (another key: another store) and not at rest
    (state,) = Runner(jobs=1, progress=False).run([Task(spec, solver, "stability")], Store(tmp_path / "s"))
    assert "skipped" not in state and state["status"] == "not-converged" and state["steps"] == 99
