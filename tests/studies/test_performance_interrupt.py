"""The performance study's timed runs stop at Ctrl-C: an hours-long timed run of the study's own
timing function ends with KeyboardInterrupt within seconds of SIGINT (its kernel calls last about
0.1 s; one call of all its steps ran to its end first)."""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

LONG_TIMING = textwrap.dedent("""
    import sys
    from studies import performance
    performance.variants = lambda: (("hybmss", 0.3),)  # one kernel to load
    performance.time_mesh("compression", (10, 10, 10), 1e-3, 5, 1, threads=(1,))  # compiled or loaded
    print("timing", flush=True)
    try:
        performance.time_mesh("compression", (10, 10, 10), 1e-3, 10**9, 1, threads=(1,))  # hours
    except KeyboardInterrupt:
        print("interrupted", flush=True)
        sys.exit(42)
""")


def _as_from_a_shell():
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_sigint_stops_a_timed_performance_run_within_seconds():
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.Popen([sys.executable, "-c", LONG_TIMING], env=env, preexec_fn=_as_from_a_shell,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "timing", p.stderr.read()
        time.sleep(1.5)  # into the timed run (the warm-up of 5 steps takes milliseconds)
        t0 = time.perf_counter()
        p.send_signal(signal.SIGINT)
        ready, _, _ = select.select([p.stdout], [], [], 60.0)
        said = p.stdout.readline().strip() if ready else "(nothing within 60 s)"
        took = time.perf_counter() - t0
        _, err = p.communicate(timeout=300)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert said == "interrupted" and p.returncode == 42, err[-2000:]
    assert took < 3.0, f"stopped {took:.2f} s after the signal"


def test_a_short_timed_run_is_one_kernel_call_a_long_one_calls_of_half_a_second():
    """What is timed stays one call where it was short (the figures of 1,000 steps of the cubes and
    beams), and a long run is called in pieces of about CALL_SECONDS, never under 100 steps."""
    from studies.performance import CALL_SECONDS, check_steps

    assert check_steps(1000, 30e-6) == 1000  # 30 ms: one call
    assert check_steps(10**9, 30e-6) == int(CALL_SECONDS / 30e-6)  # about 0.5 s a call
    assert check_steps(10**9, 1.0) == 100  # a very slow step: the floor
    assert check_steps(50, 1.0) == 50
