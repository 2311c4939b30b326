import contextlib
import io
import os
import subprocess
import traceback

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")


def run_cli(*argv, cwd=None) -> subprocess.CompletedProcess:
    """``hybmss argv`` through the console script's entry point (:func:`studies.cli.parser.main`) in
    this process, run in ``cwd``: its exit status (``main``'s return value), stdout and stderr,
    as :func:`subprocess.run` gives them for the real script.  An exception escaping ``main``
    (the script would print a traceback) comes back in stderr with status -1."""
    from studies.cli import parser as cli

    out, err = io.StringIO(), io.StringIO()
    here = os.getcwd()
    if cwd is not None:
        os.chdir(cwd)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                status = cli.main([str(a) for a in argv])
            except BaseException:  # noqa: BLE001 - the caller's checks report it as a traceback
                err.write(traceback.format_exc())
                status = -1
    finally:
        os.chdir(here)
    return subprocess.CompletedProcess(["hybmss", *argv], status, out.getvalue(), err.getvalue())


@pytest.fixture(scope="session")
def cli_in_process():
    """:func:`run_cli`: refusals checked without an interpreter start each."""
    return run_cli


def _as_from_a_shell():
    """The child's signals as a shell starts a command: not ignored (a test may leave SIGINT
    ignored here, the state a sweep's worker takes, and an ignored signal is inherited)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _signal_a_run(code: str, ready: str, sig, after: float = 1.0, wait: float = 30.0):
    """Start ``python -c code`` as a shell would (SIGINT not ignored), wait for its line ``ready``,
    send ``sig`` ``after`` seconds later and return ``(said, took, returncode, stderr)``: the next
    line it printed within ``wait`` s and how long after the signal it came."""
    import select
    import sys
    import time
    from pathlib import Path

    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    p = subprocess.Popen([sys.executable, "-c", code], env=env, preexec_fn=_as_from_a_shell,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        first = p.stdout.readline().strip()
        assert first == ready, p.stderr.read()
        time.sleep(after)
        t0 = time.perf_counter()
        p.send_signal(sig)
        got, _, _ = select.select([p.stdout], [], [], wait)
        said = p.stdout.readline().strip() if got else f"(nothing within {wait:g} s)"
        took = time.perf_counter() - t0
        _, err = p.communicate(timeout=300)  # the interpreter's exit (numba's teardown) may be slow on a busy machine
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    return said, took, p.returncode, err


@pytest.fixture(scope="session")
def signal_a_run():
    """:func:`_signal_a_run`: a long run in a process of its own, stopped by a signal."""
    return _signal_a_run
