"""The machine's ledger of large factorizations (:mod:`fem_reference.memory`): a solve admitted by
the memory available counts what the other processes planned and have not allocated, waits while
it would fit once their plans end, and a Newton solve that holds its factor is not asked again.

The figures are bytes chosen so that each case sits on one side of its bound; the other process is
a real one (``sleep``), whose resident memory (a few MB) is what it "allocated" of its plan.
"""

import os
import subprocess
import sys

import numpy as np
import pytest

from fem_reference import linalg, memory

GB = 1e9


@pytest.fixture
def ledger(tmp_path, monkeypatch):
    monkeypatch.setenv("HYBMSS_MEMORY_LEDGER", str(tmp_path))
    return tmp_path


@pytest.fixture
def other():
    """A live process of another id (its plans are somebody else's)."""
    p = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    yield p
    p.kill()
    p.wait()


def _plan_of(folder, pid: int, nbytes: float, k: int = 0):
    path = folder / f"{pid}-{k}.plan"
    path.write_text(repr(float(nbytes)))
    return path


def test_others_plans_count_less_what_they_hold_and_ended_ones_are_removed(ledger, other):
    _plan_of(ledger, other.pid, 6 * GB)
    _plan_of(ledger, other.pid, 1 * GB, 1)
    mine = memory.Plan(5 * GB)
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = _plan_of(ledger, dead.pid, 9 * GB)
    unfinished = ledger / f"{dead.pid}-1.plan.tmp"  # a plan it was writing when it ended
    unfinished.write_text("1.0")
    [(planned, held)] = memory.others()
    assert planned == 7 * GB and 0 < held < 1 * GB  # its two plans, its resident memory
    assert not stale.exists() and not unfinished.exists()
    assert os.path.exists(mine.path)
    mine.release()
    assert not os.path.exists(mine.path)


def test_a_plan_ends_with_its_owner_object(ledger):
    plan = memory.Plan(1.0)
    path = plan.path
    del plan
    assert not os.path.exists(path)


def test_admission_counts_the_others_pending_memory(ledger, other):
    _plan_of(ledger, other.pid, 6 * GB)
    held = memory.resident(other.pid)
    free = 10 * GB
    room = 0.8 * (free - (6 * GB - held))
    fits = memory.admit(room * 0.99, lambda: free, 0.8, wait=False)
    assert fits is not None
    assert memory.admit(room * 1.01, lambda: free, 0.8, wait=False) is None


def test_admission_waits_for_a_plan_in_the_way_and_then_goes_on(ledger, other):
    blocking = _plan_of(ledger, other.pid, 6 * GB)
    waits = []

    def sleep(s):  # the other solve ends while this one waits
        waits.append(s)
        blocking.unlink()

    plan = memory.admit(5 * GB, lambda: 10 * GB, 0.8, sleep=sleep)
    assert plan is not None and waits == [memory.WAIT_POLL_S]


def test_admission_does_not_wait_for_what_never_fits(ledger, other):
    _plan_of(ledger, other.pid, 6 * GB)

    def sleep(s):
        raise AssertionError("waited for memory that cannot come")

    held = memory.resident(other.pid)
    assert memory.admit(0.8 * (10 * GB + held) * 1.01, lambda: 10 * GB, 0.8, sleep=sleep) is None
    memory_free = memory.admit(1.0, lambda: 10 * GB, 0.8, sleep=sleep)  # small: fits beside it
    assert memory_free is not None


@pytest.mark.skipif(linalg.cholmod is None, reason="cvxopt (CHOLMOD) is not installed")
def test_newton_keeps_the_factor_it_holds_when_memory_runs_low(ledger, monkeypatch):
    """After the first factorization the memory available drops (the factor is in it): the next
    Newton iterations keep the Schur elimination instead of asking again and falling to MINRES."""
    from fem_reference.dirichlet import plate_dirichlet
    from fem_reference.hyperelastic import Hyperelasticity
    from fem_reference.mesh import build_mesh
    from hybmss.scene import Body, Material, Motion, Plate, Region, Scene

    motion = Motion("rotate", angle=np.radians(30.0), axis=(0.0, 0.0, 1.0), center=(0.5, 0.5, 1.0))
    sc = Scene(Body.box(2, 2, 2, 0.5), Material(1e4, 0.49, 1000.0),
               plates=(Plate("bottom", Region("z-")), Plate("top", Region("z+"), motion)))
    ops = Hyperelasticity(build_mesh(sc.body, 1), "mixed", "neo-hookean")
    d = plate_dirichlet(sc, ops.space)
    monkeypatch.setattr(linalg, "DIRECT_MAX_NNZ_SADDLE", 1)
    monkeypatch.setattr(linalg, "DIRECT_MAX_NNZ_CHOLMOD", 1)
    asked = []

    def available():  # room for the first factor only
        asked.append(1)
        return 1e15 if len(asked) == 1 else 0.0

    def no_minres(*a, **k):
        raise AssertionError("fell back to MINRES with its factor in hand")

    factorizations = []
    schur = linalg._schur_solve

    def counted(*a, **k):
        factorizations.append(1)
        return schur(*a, **k)

    monkeypatch.setattr(linalg, "available_memory", available)
    monkeypatch.setattr(linalg, "_saddle_minres", no_minres)
    monkeypatch.setattr(linalg, "_schur_solve", counted)
    sol, log = ops.solve(sc.material, d, rtol=1e-10)
    assert log.converged and len(factorizations) >= 3  # fresh tangents after the first
    assert sol.stats.method == "cholmod-schur"
    assert len(asked) == 1
    del sol, log
    assert not list(ledger.glob("*.plan"))  # the plan ended with the solve's factor
