"""The one explicit time loop and its stepper protocol (:mod:`hybmss.stepper`).

- A model with its own dynamics, registered at run time, plugs in through ``stepper`` alone: a
  damped chain of linear springs along z (each lattice column a chain, plates on its ends), with
  a Numba kernel and its NumPy twin.  Its static answer has a closed form (a uniform stretch of
  every chain), which the one loop reaches in ``simulate_explicit``, in ``hybmss compare`` and in
  a small study, and reports at rest by the harness's own rest test.
- The loop's calls (about 0.1 s each) do not change an answer, bit for bit.
- SIGINT and SIGTERM stop a long explicit run or XPBD relaxation within a second or two (not after
  its kernel call).
"""

from __future__ import annotations

import json
import signal
import textwrap

import numpy as np
import pytest
from numba import njit

from hybmss import models
from hybmss._kernels import end_of_step, particle_state, plate_scratch
from hybmss.experiments import SceneSpec
from hybmss.explicit import find_bad, plate_arrays, ramp, simulate_explicit
from hybmss.models import ModelBase, Style
from hybmss.system import build



# ------------------------------------------------------------------------------ the plug-in
def chain_links(system) -> tuple[np.ndarray, np.ndarray]:
    """Particles ``a`` → ``b`` one cell apart along z (every column of the lattice a chain)."""
    grid = system.lattice.grid
    index = {tuple(g): i for i, g in enumerate(grid)}
    a, b = [], []
    for i, g in enumerate(grid):
        j = index.get((g[0], g[1], g[2] + 1))
        if j is not None:
            a.append(i)
            b.append(j)
    return np.array(a, dtype=np.int64), np.array(b, dtype=np.int64)


@njit(cache=False)
def _chain_run(W, X, a, b, k, invm, dt, damp, ramp_time, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp,
               pl_axis, pl_center, pl_angle, step0, nsteps, check_every, limit2):
    n = X.shape[1]
    x = W[:3 * n].reshape((3, n))
    v = W[3 * n:].reshape((3, n))
    R, u_old, u_new = plate_scratch(pl_ptr)
    f = np.empty((3, n))
    for it in range(nsteps):
        f[:, :] = 0.0
        for s in range(a.shape[0]):
            for d in range(3):
                t = k * ((x[d, b[s]] - X[d, b[s]]) - (x[d, a[s]] - X[d, a[s]]))
                f[d, a[s]] += t
                f[d, b[s]] -= t
        for d in range(3):
            for q in range(n):
                v[d, q] = (v[d, q] + dt * f[d, q] * invm[q]) * damp
                x[d, q] += dt * v[d, q]
        bad = end_of_step(W, np.int64(0), 3 * n, n, n, True, X, pl_nodes, pl_U1, pl_ptr, pl_mask, pl_kind, pl_disp,
                          pl_axis, pl_center, pl_angle, step0 + it, dt, ramp_time, R, u_old, u_new, it, nsteps,
                          check_every, limit2)
        if bad >= 0:
            return it + 1, bad
    return nsteps, -1


class ChainStepper:
    """Semi-implicit Euler of the chains: ``f_a = k (u_b − u_a)`` on both ends of a link (a
    linear spring of stiffness ``k = E le``, a column of cross-section le² of modulus E)."""

    solver = "chain-explicit"

    def __init__(self, system, dt, *, ramp_time, kernel="numba", precision="f64", threads=1):
        if precision != "f64" or threads != 1:
            raise ValueError("the chain runs in f64 on one thread")
        self.system, self.dt, self.ramp_time, self.kernel = system, float(dt), float(ramp_time), kernel
        self.k = system.scene.material.E * system.scene.body.le
        self.damp = 1.0 / (1.0 + system.scene.damping * self.dt)
        self.a, self.b = chain_links(system)
        self.info = {"kernel": kernel, "threads": 1, "precision": "f64", "links": len(self.a)}

    def load(self, x, v):
        self.W, self.xg, self.vg = particle_state(x, v)

    def forces(self, x):
        u = x - self.system.X
        t = self.k * (u[self.b] - u[self.a])
        f = np.zeros_like(u)
        np.add.at(f, self.a, t)
        np.add.at(f, self.b, -t)
        return f

    def advance(self, step0, n, check_every, limit2):
        S = self.system
        if self.kernel == "numba":
            done, bad = _chain_run(self.W, np.ascontiguousarray(S.X.T), self.a, self.b, self.k, 1.0 / S.mass,
                                   self.dt, self.damp, self.ramp_time, *plate_arrays(S).args(), np.int64(step0),
                                   np.int64(n), np.int64(check_every), float(limit2))
            return int(done), int(bad)
        x, v = self.xg.T, self.vg.T  # views of the state: updated in place
        fixed = S.fixed
        for i in range(n):
            P_old = S.prescribed(ramp((step0 + i) * self.dt, self.ramp_time))
            P_new = S.prescribed(ramp((step0 + i + 1) * self.dt, self.ramp_time))
            v[:] = (v + self.dt * self.forces(x) / S.mass[:, None]) * self.damp
            x += self.dt * v
            x[fixed] = P_new[fixed]
            v[fixed] = ((P_new - S.X) - (P_old - S.X))[fixed] / self.dt
            if (i + 1) % check_every == 0 or i == n - 1:
                bad = find_bad(x, S.X, limit2)
                if bad >= 0:
                    return i + 1, bad
        return n, -1

    def state(self):
        return self.xg.T.copy(), self.vg.T.copy()

    def internal_forces(self, x):
        return self.forces(x)

    def energy(self, x, v):
        du = (x - self.system.X)[self.b] - (x - self.system.X)[self.a]
        return {"springs": float(0.5 * self.k * np.sum(du * du)),
                "kinetic": float(0.5 * np.sum(self.system.mass[:, None] * v * v))}


class Chain(ModelBase):
    name = "test-chain"
    label = "linear spring chains along z (a plug-in with its own dynamics)"
    style = Style("#000000")
    conservative = False
    solvers = ("explicit",)
    kernels = ("numba", "numpy")
    studies = ()

    def stepper(self, system, dt, **kw):
        return ChainStepper(system, dt, **kw)

    def dt_crit(self, system):
        """Gershgorin: λmax(M⁻¹K) ≤ max_a (Σ_b |K_ab|)/m_a ≤ 4 k / min m."""
        k = system.scene.material.E * system.scene.body.le
        return float(np.sqrt(system.mass.min() / k))


@pytest.fixture
def chain():
    models.register(Chain())
    yield
    models.unregister("test-chain")


MESH, DT, STEPS, RAMP, DAMPING = (2, 2, 4), 0.01, 3000, 1.0, 5.0
"""A 2×2×4 cube of 1.25 m cells (k = 1.25e4 N/m, ω_max < 15 /s: dt_crit > 0.13 s); the slowest
chain mode (ω₁ ≈ 3.9 /s) decays at ≈ 0.9 /s with c = 5 /s: at rest after 30 s to ~1e-11."""


def _spec():
    return SceneSpec.default("compression", mesh=MESH, model="test-chain", damping=DAMPING)


def closed_form(spec):
    """Every chain compressed uniformly: ``u_z = −d z``, top reaction ``−(chains) k d le``."""
    scene = spec.build()
    S = build(scene)
    d, le, E = spec.deformation, scene.body.le, spec.E
    chains = (MESH[0] + 1) * (MESH[1] + 1)
    u = np.zeros_like(S.X)
    u[:, 2] = -d * (S.X[:, 2] - S.X[:, 2].min())
    return u, -chains * E * le * le * d


def test_a_plugged_in_stepper_reaches_the_closed_form_at_rest(chain):
    spec = _spec()
    u, Fz = closed_form(spec)
    r = simulate_explicit(spec.build(), dt=DT, steps=STEPS, ramp_time=RAMP)
    assert r.solver == "chain-explicit" and r.info["links"] == 3 * 3 * 4
    assert r.converged and r.info["rest"]["at_rest"]
    assert np.abs(r.u - u).max() <= 1e-6 * np.abs(u).max()
    assert r.reactions["top"].force[2] == pytest.approx(Fz, rel=1e-6)
    assert r.info["dt_crit"] > 10 * DT
    # the NumPy twin gives the same trajectory; a short run is not at rest, and says so
    a = simulate_explicit(spec.build(), dt=DT, steps=80, ramp_time=RAMP, kernel="numba")
    b = simulate_explicit(spec.build(), dt=DT, steps=80, ramp_time=RAMP, kernel="numpy")
    assert np.abs(a.u - b.u).max() <= 1e-12 * np.abs(a.u).max()
    assert not a.converged and "ramp" in a.info["rest"]["not_at_rest_because"]


def test_a_plugged_in_stepper_runs_in_compare_and_in_a_study(chain, cli_in_process, tmp_path):
    from studies.sweep.runner import SolverSpec, Task, run_tasks
    from studies.sweep.store import Store

    spec = _spec()
    _, Fz = closed_form(spec)
    p = cli_in_process("compare", "compression", "--mesh", "2x2x4", "--model", "test-chain", "--damping", DAMPING,
                "--solver", "explicit", "--dt", DT, "--steps", STEPS, "--ramp-time", RAMP, "--fem", "hex1", "--json")
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["scene"]["model"] == "test-chain" and out["mss"]["converged"]
    assert out["mss"]["reaction_force"][2] == pytest.approx(Fz, rel=1e-6)

    task = Task(spec, SolverSpec("explicit", dt=DT, steps=STEPS, ramp_time=RAMP), "chain")
    rows = run_tasks([task], Store(tmp_path), jobs=1, progress=False)
    assert rows[0]["status"] == "ok" and rows[0]["converged"]
    assert rows[0]["force_z"] == pytest.approx(Fz, rel=1e-6)


# ------------------------------------------------------------------------------ calls
@pytest.mark.parametrize("model, kernel", [("hybmss", "numba"), ("corot-hex8", "numba"), ("hybmss-fd", "numpy"),
                                           ("mujoco-trilinear", "engine")])
def test_the_calls_of_the_loop_do_not_change_the_answer(monkeypatch, model, kernel):
    """Calls of one check interval each (no time budget) and calls of up to 10 s: the same
    positions, bit for bit, with a record every 35 steps (not a multiple of the check interval)."""
    import hybmss.stepper as stepper

    scene = SceneSpec.default("shear", mesh=(3, 3, 3), model=model, damping=2.0).build()
    if kernel == "engine":
        pytest.importorskip("mujoco")
    kw = dict(dt=2e-3, steps=230 if kernel == "numba" else 40, ramp_time=0.1, kernel=kernel, check_every=10,
              record_every=35)
    monkeypatch.setattr(stepper, "CHUNK_SECONDS", 10.0)
    long = simulate_explicit(scene, **kw)
    monkeypatch.setattr(stepper, "CHUNK_SECONDS", 0.0)
    short = simulate_explicit(scene, **kw)
    assert np.abs(long.u).max() > 0
    assert np.array_equal(long.u, short.u)
    assert long.info["history"]["t"] == short.info["history"]["t"]


# ------------------------------------------------------------------------------ interrupts
LONG_RUN = textwrap.dedent("""
    import sys
    from hybmss.experiments import SceneSpec
    from hybmss.explicit import simulate_explicit
    scene = SceneSpec.default("compression", mesh=(6, 6, 6), damping=1.0).build()
    simulate_explicit(scene, dt=1e-3, steps=20, compute_dt_crit=False)  # compiled or loaded
    print("stepping", flush=True)
    try:
        simulate_explicit(scene, dt=1e-3, steps=10**9, compute_dt_crit=False)
    except KeyboardInterrupt:
        print("interrupted", flush=True)
        sys.exit(42)
""")


LONG_RELAXATION = textwrap.dedent("""
    import sys
    from hybmss.experiments import SceneSpec
    from hybmss.models.xpbd_nh import frequencies, relax_static, xpbd_term
    from hybmss.system import build
    S = build(SceneSpec.default("compression", mesh=(4, 4, 4), model="xpbd-nh").build())
    T = xpbd_term(S)
    _, wmax = frequencies(S)
    h = 0.1 / wmax
    kw = dict(h=h, H=5 * h, damping=0.3 * wmax, ramp_time=1.0, check_time=5 * h, rest_tol=0.0)
    relax_static(S, T, max_time=20 * 5 * h, **kw)  # compiled or loaded
    print("stepping", flush=True)
    try:
        relax_static(S, T, max_time=1e9 * 5 * h, **kw)
    except KeyboardInterrupt:
        print("interrupted", flush=True)
        sys.exit(42)
""")


ENGINE_RUN = textwrap.dedent("""
    import sys
    from hybmss.experiments import SceneSpec
    from hybmss.explicit import simulate_explicit
    scene = SceneSpec.default("compression", mesh=(6, 6, 6), damping=1.0, model="mujoco-tet").build()
    simulate_explicit(scene, dt=1e-3, steps=20, compute_dt_crit=False, kernel="engine")
    print("stepping", flush=True)
    try:
        simulate_explicit(scene, dt=1e-3, steps=10**9, compute_dt_crit=False, kernel="engine")
    except KeyboardInterrupt:
        print("interrupted", flush=True)
        sys.exit(42)
""")

SCRIPTS = {"explicit run": LONG_RUN, "xpbd-nh relaxation": LONG_RELAXATION, "mujoco-tet explicit run": ENGINE_RUN}


@pytest.mark.parametrize("script", list(SCRIPTS))
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_stops_a_long_run_within_seconds(sig, script, signal_a_run):
    """An exit check, not a speed test: an explicit run of 10⁹ steps (of the lattice, or of
    MuJoCo's flex: an engine's steps run in the same loop), or the XPBD static relaxation of 10⁹
    iterations (hours), stops within 3 s of the signal (the calls take about 0.1 s) with
    KeyboardInterrupt."""
    if script.startswith("mujoco"):
        pytest.importorskip("mujoco")
    said, took, rc, err = signal_a_run(SCRIPTS[script], "stepping", sig)
    assert said == "interrupted" and rc == 42, err[-2000:]
    assert took < 3.0, f"stopped {took:.2f} s after the signal"
    print(f"{script}, {signal.Signals(sig).name}: KeyboardInterrupt {took:.2f} s after the signal")
