import contextlib
import io
import os
import subprocess
import traceback

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")


def run_cli(*argv, cwd=None) -> subprocess.CompletedProcess:
    """``hybmss argv`` through the console script's entry point (:func:`studies.cli.main`) in
    this process, run in ``cwd``: its exit status (``main``'s return value), stdout and stderr,
    as :func:`subprocess.run` gives them for the real script.  An exception escaping ``main``
    (the script would print a traceback) comes back in stderr with status -1."""
    from studies import cli

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
