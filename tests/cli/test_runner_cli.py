"""``hybmss run`` as a user runs it: Ctrl-C (SIGINT to the process group, once and twice) on a
two-worker sweep stops at once and keeps the finished runs; two ``run`` processes on one folder
compute each run once; options that are not allowed exit 2 with one line before any work."""

import json
import os
import signal
import subprocess
import sys
import time

import psutil
import pytest

from studies.sweep.store import Store


def hybmss(*args) -> list[str]:
    return [sys.executable, "-m", "studies", *args]


def wait_for_rows(store: Store, n: int, p: subprocess.Popen, timeout: float = 180) -> None:
    deadline = time.monotonic() + timeout
    while len(store.keys()) < n:
        assert p.poll() is None, p.stderr.read()
        assert time.monotonic() < deadline, "no run stored"
        time.sleep(0.05)


def _terminal_sigint() -> None:
    """SIGINT as at a terminal.  A command started in the background of a non-interactive shell
    (as a CI job may run this suite) inherits SIGINT ignored, and Python then installs no
    KeyboardInterrupt handler: such a ``run`` rightly keeps going, like any nohup'd job."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize("executor, signals", [("local", 2), pytest.param("dask", 1, marks=pytest.mark.slow),
                                               pytest.param("local", "SIGTERM", marks=pytest.mark.slow)])
def test_sigint_stops_the_sweep_and_keeps_finished_runs(executor, signals, tmp_path):
    """Ctrl-C (SIGINT to the process group, once or twice), or SIGTERM to the command alone (as
    `timeout` or a job scheduler sends it): the workers are stopped, finished runs kept."""
    store = Store(tmp_path)
    p = subprocess.Popen(hybmss("run", "--study", "compression", "--quick", "--jobs", "2", "--executor", executor,
                                "--out", str(tmp_path), "--no-progress"),
                         stderr=subprocess.PIPE, text=True, start_new_session=True, preexec_fn=_terminal_sigint)
    try:
        wait_for_rows(store, 2, p)
        workers = [c for c in psutil.Process(p.pid).children(recursive=True)
                   if "resource_tracker" not in " ".join(c.cmdline())]
        assert len(workers) >= 2
        if signals == "SIGTERM":
            os.kill(p.pid, signal.SIGTERM)
        for _ in range(0 if signals == "SIGTERM" else signals):  # Ctrl-C: SIGINT to the process group
            os.killpg(p.pid, signal.SIGINT)
            time.sleep(0.05)
        rc = p.wait(timeout=60)  # prompt: no run is waited for, nothing hangs
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    _, alive = psutil.wait_procs(workers, timeout=10)
    for w in alive:  # a worker left running would also hold the stderr pipe open
        w.kill()
    assert alive == []  # the pool is shut down
    err = p.stderr.read()
    # 130 from the handler; a second SIGINT landing while the interpreter exits ends it by the
    # signal itself (the same status to a shell)
    assert rc in (130, -signal.SIGINT), err
    assert "Traceback" not in err and "interrupted" in err
    rows, damaged = store.scan()
    assert damaged == [] and 2 <= len(rows) < 44  # finished runs kept, the rest abandoned
    assert not list(store.runs.glob(".*.tmp"))


GATED = """\
import pathlib, sys, time
from studies.cli.parser import main
pathlib.Path(sys.argv[1]).touch()  # imported: ready
while not pathlib.Path(sys.argv[2]).exists():
    time.sleep(0.01)
sys.exit(main(sys.argv[3:]))
"""
"""The ``hybmss`` command (:func:`studies.cli.parser.main`), started once the file ``argv[2]`` exists."""


@pytest.mark.slow
def test_two_run_processes_compute_each_run_once(tmp_path):
    """Both processes start their sweeps together (each waits, after its imports, for a go): the
    second cannot find every run computed by the first, however the machine schedules their
    interpreter starts."""
    out, gate = tmp_path / "results", tmp_path / "go"
    args = ["run", "--study", "bending", "--quick", "--jobs", "1", "--out", str(out), "--no-progress", "--json"]
    ready = [tmp_path / f"ready{i}" for i in range(2)]
    procs = [subprocess.Popen([sys.executable, "-c", GATED, str(r), str(gate), *args], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for r in ready]
    deadline = time.monotonic() + 180
    while not all(r.exists() for r in ready):
        assert all(p.poll() is None for p in procs), [p.stderr.read() for p in procs]
        assert time.monotonic() < deadline, "the processes did not start"
        time.sleep(0.01)
    gate.touch()
    outs = [p.communicate(timeout=300) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [e for _, e in outs]
    res = [json.loads(o) for o, _ in outs]
    runs = res[0]["runs"]
    # the quick bending study's tasks (its models, their own meshes' engines and the FEM references)
    from studies.paper import reproduce
    assert runs == len({t.key() for t in reproduce.tasks_for(["bending"], True)}) > 14
    assert all(r["runs"] == runs for r in res)
    assert sum(r["computed"] for r in res) == runs  # each run computed by exactly one of them
    assert all(r["computed"] + r["stored"] + r["by_other"] == runs for r in res)
    assert all(r["computed"] > 0 for r in res)  # the second process took runs of its own
    rows, damaged = Store(out).scan()
    assert len(rows) == runs and damaged == []


@pytest.mark.parametrize("args, words", [
    (["--jobs", "0"], "jobs 0"), (["--out", ""], "--out ''"), (["--out", "/dev/null/r"], "/dev/null"),
    (["--all", "--study", "bending"], "--all and --study"), (["--scheduler", "tcp://h:1"], "needs executor dask")])
def test_run_options_not_allowed_exit_2_with_one_line(args, words, tmp_path, cli_in_process):
    # through the command's entry point in this process (tests/test_cli_contract.py runs such
    # refusals through the real script too)
    out = [] if "--out" in args else ["--out", str(tmp_path / "r")]
    p = cli_in_process("run", "--quick", *out, *args, cwd=tmp_path)
    assert p.returncode == 2 and p.stdout == ""
    assert len(p.stderr.strip().splitlines()) == 1 and words in p.stderr, p.stderr
    assert list(tmp_path.iterdir()) == []  # refused before any work


def test_run_out_on_a_file_exits_2(tmp_path, cli_in_process):
    f = tmp_path / "results"
    f.write_text("not a folder")
    p = cli_in_process("run", "--quick", "--study", "bending", "--out", str(f), cwd=tmp_path)
    assert p.returncode == 2 and "is a file" in p.stderr and len(p.stderr.strip().splitlines()) == 1
    assert f.read_text() == "not a folder" and list(tmp_path.iterdir()) == [f]


def test_run_guard_refuses_a_sweep_that_does_not_fit_before_any_work(cli_in_process, tmp_path):
    """Every worker may hold the sweep's largest run (the full reproduction: a 1.9 GiB FEM solve),
    so 10,000 workers would need about 19 TiB: exit 2, one line with the estimate, nothing
    written; the full reproduction on 2 workers fits and is not refused as too long (its 3,638 runs
    took 87 min: over a single command's hour, within a sweep's limit)."""
    from studies.sweep import sizing
    from studies.cli.run import sweep_estimate

    out = tmp_path / "res"
    r = cli_in_process("run", "--all", "--jobs", "10000", "--out", out, "--no-progress")
    assert r.returncode == 2, r.stderr
    line = r.stderr.strip()
    assert "\n" not in line and "10000 worker(s)" in line and "TiB of memory" in line and "--no-guard" in line
    assert not out.exists()
    full = sweep_estimate(None, False, Store(out), 2)
    assert sizing.fits(full) and 60 * 60 < full.seconds < 120 * 60
    assert sizing.in_time(full) and full.limit_s == sizing.SWEEP_TIME_LIMIT_S > sizing.TIME_LIMIT_S


def test_run_guard_counts_only_runs_not_stored_and_no_guard_insists(cli_in_process, tmp_path, monkeypatch):
    """Over the time limit (here lowered to 1 ms) the sweep is refused; the runs already stored
    are not counted (a stored study leaves nothing to estimate), and --no-guard runs it anyway."""
    import studies.paper.reproduce as reproduce
    from studies.sweep import sizing
    from studies.cli.run import sweep_estimate

    out = tmp_path / "res"
    store = Store(out)
    est = sweep_estimate(["bending"], True, store, 1)
    n = len({t.key() for t in reproduce.tasks_for(["bending"], True)})
    assert est.seconds > 0 and est.what.startswith(f"sweep of {n} runs")
    monkeypatch.setattr(sizing, "SWEEP_TIME_LIMIT_S", 1e-3)
    r = cli_in_process("run", "--study", "bending", "--quick", "--jobs", "1", "--out", out, "--no-progress")
    assert r.returncode == 2 and "too long" in r.stderr and "--no-guard" in r.stderr, r.stderr
    calls = []
    monkeypatch.setattr(reproduce, "run_studies", lambda *a, **k: calls.append(k))
    r = cli_in_process("run", "--study", "bending", "--quick", "--jobs", "1", "--out", out, "--no-progress",
                       "--no-guard")
    assert r.returncode == 0 and len(calls) == 1, r.stderr
    for t in reproduce.tasks_for(["bending"], True):  # as if stored: nothing left to estimate
        store.runs.mkdir(parents=True, exist_ok=True)
        (store.runs / f"{t.key()}.json").write_text("{}")
    assert sweep_estimate(["bending"], True, store, 1).seconds == 0.0
