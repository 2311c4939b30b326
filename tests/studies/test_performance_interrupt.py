"""The performance study's timed runs stop at Ctrl-C: an hours-long timed run of the study's own
timing function ends with KeyboardInterrupt within seconds of SIGINT (its kernel calls last about
0.1 s; one call of all its steps ran to its end first)."""

from __future__ import annotations

import signal
import textwrap


LONG_TIMING = textwrap.dedent("""
    import sys
    from studies.paper import performance
    performance.variants = lambda: (("hybmss", 0.3),)  # one kernel to load
    performance.time_mesh("compression", (10, 10, 10), 1e-3, 5, 1, threads=(1,))  # compiled or loaded
    print("timing", flush=True)
    try:
        performance.time_mesh("compression", (10, 10, 10), 1e-3, 10**9, 1, threads=(1,))  # hours
    except KeyboardInterrupt:
        print("interrupted", flush=True)
        sys.exit(42)
""")


def test_sigint_stops_a_timed_performance_run_within_seconds(signal_a_run):
    # 1.5 s: into the timed run (the warm-up of 5 steps takes milliseconds)
    said, took, rc, err = signal_a_run(LONG_TIMING, "timing", signal.SIGINT, after=1.5, wait=60.0)
    assert said == "interrupted" and rc == 42, err[-2000:]
    assert took < 3.0, f"stopped {took:.2f} s after the signal"


def test_a_short_timed_run_is_one_kernel_call_a_long_one_calls_of_half_a_second():
    """What is timed stays one call where it was short (the figures of 1,000 steps of the cubes and
    beams), and a long run is called in pieces of about CALL_SECONDS, never under 100 steps."""
    from studies.paper.performance import CALL_SECONDS, check_steps

    assert check_steps(1000, 30e-6) == 1000  # 30 ms: one call
    assert check_steps(10**9, 30e-6) == int(CALL_SECONDS / 30e-6)  # about 0.5 s a call
    assert check_steps(10**9, 1.0) == 100  # a very slow step: the floor
    assert check_steps(50, 1.0) == 50
