"""PositionBasedDynamics' XPBD FEM tetrahedra (``pbd-xpbd-fem``, through ``pypbd``) against
scikit-fem on the very same mesh, its small-strain moduli, the law its forces are read with
(checked against one projection of the engine), the balance of its plate reactions, and what it
refuses.

XPBD's rest state carries an O((h ω_max)²) bias (:mod:`hybmss.models.pbd`): 3e-4 of the force
scale at h ω_max = 0.1, measured (the static run takes 0.06); the same-mesh reactions hold to 1e-3 at strain
1e-4 (1.4e-4 stretch, 6e-5 shear measured), the moduli to 1e-3 (4e-4 measured, E at ν = 0.45).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pypbd")

from hybmss import Body, Material, Model, Motion, Plate, Region, Scene  # noqa: E402
from hybmss.moduli import measure_moduli  # noqa: E402
from hybmss.solve import solve_static  # noqa: E402
from hybmss.system import build  # noqa: E402

NAME = "pbd-xpbd-fem"
E, LE, N = 1e4, 0.5, 2
H = N * LE
STRAIN = 1e-4


def cube(nu: float, motion: Motion, rho: float = 1000.0, le: float = LE, **kw) -> Scene:
    return Scene(body=Body.box(N, N, N, le=le), material=Material(E=E, nu=nu, rho=rho), model=Model(NAME),
                 plates=(Plate("bottom", Region("z-")), Plate("top", Region("z+"), motion)), **kw)


def motion(kind: str, eps: float, le: float = LE) -> Motion:
    h = N * le
    return Motion("translate", (0.0, 0.0, eps * h) if kind == "stretch" else (eps * h, 0.0, 0.0))


def engine_tets(scene: Scene) -> np.ndarray:
    """The library's tetrahedra (its 5-tet grid split) of the scene's lattice: the mesh of the same-mesh
    reference (the ``tet_p1_reaction`` fixture)."""
    from hybmss.models.pbd.engine import cell_tets

    S = build(scene)
    return cell_tets(S.lattice.cells, S.lattice.cell_ijk, S.X)


@pytest.mark.parametrize("kind", ("stretch", "shear"))
def test_same_mesh_linear_fem(kind, tet_p1_reaction):
    """At strain 1e-4 the reaction equals the linear FEM's on the library's tetrahedra to 1e-3
    (the XPBD bias and the O(ε) St Venant–Kirchhoff term), the plates balance to 1e-3."""
    same_mesh_check(kind, LE, tet_p1_reaction)


def test_millimetre_cells(tet_p1_reaction):
    """The same at 4 mm cells (tetrahedra of 1e-8 m³): the library drops a tetrahedron below 1e-6
    of its length unit cubed, so in metres the body had no stiffness and did not move."""
    same_mesh_check("stretch", 0.004, tet_p1_reaction)


def same_mesh_check(kind: str, le: float, tet_p1_reaction) -> None:
    sc = cube(0.3, motion(kind, STRAIN, le), rho=0.0, le=le)
    r = solve_static(sc)
    got = np.asarray(r.reactions["top"].force)
    ref = tet_p1_reaction(sc, engine_tets(sc))
    assert r.converged
    assert np.abs(got - ref).max() <= 1e-3 * np.abs(ref).max(), (kind, got, ref)
    assert r.info["reaction_balance"]["relative"] <= 1e-3


def test_a_rest_run_kicks_every_few_steps_and_reaches_the_same_rest_state():
    """A run for its rest state (``for_rest``: damping and gravity compensation every 16 steps)
    ends where the run with every step's kicks ends, to 1e-6 of the displacement (6e-8 measured;
    1.5e-2 apart during the ramp)."""
    from hybmss.models.pbd.engine import PbdBody

    S = build(cube(0.3, Motion("translate", (1e-4, 0.0, 1e-4))))
    ends = []
    for rest in (False, True):
        dt = 0.06 / PbdBody(S, "xpbd-fem", 1e-3, 0.5, damping=20.0).omega_max()
        b = PbdBody(S, "xpbd-fem", dt, 0.5, damping=20.0)
        if rest:
            b.for_rest()
            assert b.sync_every > 1
        b.load(b.nodes.X, np.zeros_like(b.nodes.X))
        b.advance(0, 4000, 400)
        ends.append(b.state()[0])
    u = np.abs(ends[0] - S.X).max()
    assert u > 0.5e-4
    assert np.abs(ends[1] - ends[0]).max() <= 1e-6 * u


@pytest.mark.skipif((__import__("os").cpu_count() or 1) < 2, reason="one core: OpenMP takes one thread anyway")
def test_the_library_steps_on_one_thread():
    """The library's OpenMP loop runs on the calling thread alone once a body steps (the model's
    ``threads`` 1), not on every core: the runtime shipped in its wheel says so."""
    from hybmss.models.pbd.engine import PbdBody, openmp_runtime

    lib = openmp_runtime()
    if lib is None:
        pytest.skip("the library's wheel ships no OpenMP runtime")
    S = build(cube(0.3, Motion("translate", (1e-4, 0.0, 1e-4))))
    b = PbdBody(S, "xpbd-fem", 1e-5, 0.5, damping=20.0)
    b.load(b.nodes.X, np.zeros_like(b.nodes.X))
    b.advance(0, 2)
    assert lib.omp_get_max_threads() == 1


def test_a_rest_run_in_one_call_is_the_run_in_calls_of_one_group_each_bit_for_bit():
    """Within one call of the loop the half kick after a group of steps and the next group's first
    half are given in one pass over the nodes (the bindings' per-node calls cost more than the
    library's step): the same operations in the same order as calls of one group each, which
    give every half kick in its own pass."""
    from hybmss.models.pbd.engine import PbdBody

    S = build(cube(0.3, Motion("translate", (1e-4, 0.0, 1e-4))))
    dt = 0.06 / PbdBody(S, "xpbd-fem", 1e-3, 0.5, damping=20.0).omega_max()
    ends = []
    for calls in (1, 40):
        b = PbdBody(S, "xpbd-fem", dt, 0.5, damping=20.0)
        b.for_rest()
        b.load(b.nodes.X, np.zeros_like(b.nodes.X))
        n = 40 * b.sync_every
        for c in range(calls):
            b._steps(c * n // calls, n // calls)
        ends.append(b.state())
    assert np.abs(ends[0][0] - S.X).max() > 1e-6
    assert np.array_equal(ends[0][0], ends[1][0]) and np.array_equal(ends[0][1], ends[1][1])


@pytest.mark.parametrize("nu", (pytest.param(0.0, marks=pytest.mark.slow), 0.25,
                                pytest.param(0.45, marks=pytest.mark.slow)))
def test_moduli(nu):
    """E, ν, G at strain 1e-4 to 1e-3 (about a minute a value, several at ν = 0.45: h ω_max is
    fixed and ω_max/ω₁ grows with λ; ν = 0 and 0.45 run with the slow tests)."""
    m = measure_moduli(Model(NAME), Material(E=E, nu=nu, rho=1000.0), strain=STRAIN)
    assert m["E_eff"] == pytest.approx(E, rel=1e-3)
    assert m["nu_eff"] == pytest.approx(nu, abs=1e-3)
    assert m["G_eff"] == pytest.approx(E / (2 * (1 + nu)), rel=1e-3)


def test_forces_are_the_engines_projection():
    """One step of the engine from rest at a stretched and sheared state (no gravity, no damping,
    h ω_max ≈ 2e-3): each free node moves by ``h² f / m`` to 1e-3, f the forces the model reads
    (the library's St Venant–Kirchhoff with μ = E/(2(1+ν)), λ = Eν/((1+ν)(1−2ν))), so the
    readout is the engine's constraint force."""
    from hybmss.models.pbd.engine import PbdBody

    sc = Scene(body=Body.box(2, 1, 1, le=LE), material=Material(E=E, nu=0.3, rho=1000.0), model=Model(NAME),
               plates=(Plate("bottom", Region("z-")),))
    S = build(sc)
    probe = PbdBody(S, "xpbd-fem", 1.0, 1.0, damping=0.0, gravity=None)
    h = 1e-3 / probe.omega_max()
    body = PbdBody(S, "xpbd-fem", h, 1e-9, damping=0.0, gravity=None)
    X = body.nodes.X
    x = X.copy()
    x[:, 2] *= 1.0 + 1e-3
    x[:, 0] += 5e-4 * X[:, 2]
    body.load(x, 0.0 * X)
    body.advance(0, 1)
    moved = body.state()[0] - x
    want = h**2 * body.internal_forces(x) / body.nodes.mass[:, None]
    free = body.free
    assert np.abs(moved[free] - want[free]).max() <= 1e-3 * np.abs(want[free]).max()


def test_reactions_balance_weight():
    rho, g = 1000.0, 9.81
    sc = Scene(body=Body.box(N, N, N, le=LE), material=Material(E=1e6, nu=0.3, rho=rho), model=Model(NAME),
               plates=(Plate("bottom", Region("z-")),), gravity=(0.0, 0.0, -g))
    r = solve_static(sc)
    weight = rho * H**3 * g
    assert r.reactions["bottom"].force[2] == pytest.approx(weight, rel=1e-3)
    # the library's own gravity (−y, not settable) is replaced by the scene's: no sideways weight
    # (7.6e-6 measured: the XPBD bias on the split's asymmetric tetrahedra)
    assert np.abs(r.reactions["bottom"].force[:2]).max() <= 1e-4 * weight
    assert r.u[:, 2].min() < 0.0


def test_refuses_what_it_cannot_represent():
    from hybmss.explicit import simulate_explicit
    from hybmss.scene import Load
    from hybmss.solve import StaticSolveError

    for nu in (-0.1, 0.495):  # the constraint makes no correction outside [0, 0.49]
        with pytest.raises(ValueError, match="nu"):
            solve_static(cube(nu, motion("stretch", STRAIN)))
        with pytest.raises(StaticSolveError, match="nu"):
            solve_static(cube(nu, motion("stretch", STRAIN)))
    with pytest.raises(ValueError, match="loads"):
        solve_static(cube(0.3, motion("stretch", STRAIN), loads=(Load(Region("z+"), (0.0, 0.0, -1.0)),)))
    with pytest.raises(ValueError, match="threads"):
        simulate_explicit(cube(0.3, motion("stretch", STRAIN)), dt=1e-4, steps=10, threads=2, kernel="engine")
    with pytest.raises(ValueError, match="precision"):
        simulate_explicit(cube(0.3, motion("stretch", STRAIN)), dt=1e-4, steps=10, precision="f32",
                          kernel="engine")


def test_missing_engine_leaves_its_models_out():
    """Without pypbd the registry lists no such model among its names but as unavailable with the
    install command, writes nothing to stderr, and a command naming one is refused (exit 2) with the
    install command, never a traceback."""
    import subprocess
    import sys

    block = ("import sys\n"
             "class Block:\n"
             "    def find_spec(self, name, path=None, target=None):\n"
             "        if name.split('.')[0] == 'pypbd':\n"
             "            raise ModuleNotFoundError(name)\n"
             "sys.meta_path.insert(0, Block())\n")
    p = subprocess.run([sys.executable, "-c", block + "import hybmss.models as m; print(','.join(m.names()))"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    names = p.stdout.strip().split(",")
    assert not any(n.startswith("pbd-") for n in names) and "mujoco-tet" in names
    assert p.stderr.strip() == "", p.stderr
    code = block + "import hybmss.models as m; print(m.unavailable()['pbd-xpbd-fem'])"
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert "pypbd" in p.stdout and "pip install 'hybmss[engines]'" in p.stdout, p.stdout + p.stderr
    code = block + "from studies.cli.parser import main; sys.exit(main(['moduli', '--model', 'pbd-xpbd-fem']))"
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and "hybmss[engines]" in p.stderr, p.stderr


def test_explicit_run_reaches_rest():
    """The explicit protocol (the library's steps, the harness's ramp and damping) ends at the
    static answer: the same reaction to 1e-3 once rest_report finds it at rest."""
    from hybmss.explicit import simulate_explicit

    sc = cube(0.3, motion("stretch", STRAIN))
    st = solve_static(sc)
    i = st.info
    steps = int((i["ramp_time"] + 30.0 / i["omega_1"]) / i["dt"])
    r = simulate_explicit(sc, dt=i["dt"], steps=steps, ramp_time=i["ramp_time"], damping=i["damping"],
                          kernel="engine")
    assert r.converged, r.info["rest"]
    assert r.reactions["top"].force[2] == pytest.approx(st.reactions["top"].force[2], rel=1e-3)
    assert r.info["engine"] == "pypbd" and r.info["device"] == "cpu" and r.info["mass_unit_kg"] > 1.0
