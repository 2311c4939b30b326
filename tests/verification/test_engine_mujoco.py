"""MuJoCo's flex bodies (``mujoco-tet``, ``mujoco-trilinear``, ``mujoco-quadratic``) against
scikit-fem on the very same mesh, their small-strain moduli, the balance of their plate
reactions, and what they refuse.

- Same mesh, same element: a 2×2×2 cube clamped at the bottom, its top translated by 1e-4 of the
  height (and sheared); the engine's plate reaction equals that of the linear FEM on the engine's
  own mesh to 1e-3: ``ElementTetP1`` on MuJoCo's tetrahedra (assembled here with scikit-fem),
  Hex1 and Hex2 on its cells (:func:`fem_reference.solve.solve`, ``refine=1``).
- ``hybmss moduli`` (:func:`hybmss.moduli.measure_moduli`) returns the input E, ν and
  G = E/(2(1+ν)) to 1e-4 at ν ∈ {0, 0.25, 0.45}.
- The plate reactions balance the weight (closed form ρ V g) to 1e-3.
- Refused before any work: a negative ν, surface loads, a body that is not a box (grid kinds),
  two threads.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")

from hybmss import Body, Material, Model, Motion, Plate, Region, Scene  # noqa: E402
from hybmss.moduli import measure_moduli  # noqa: E402
from hybmss.solve import solve_static  # noqa: E402
from hybmss.system import build  # noqa: E402

KINDS = ("mujoco-tet", "mujoco-trilinear", "mujoco-quadratic")
E, LE, N = 1e4, 0.5, 2
H = N * LE
STRAIN = 1e-4


def cube(name: str, nu: float, motion: Motion, rho: float = 1000.0, **kw) -> Scene:
    return Scene(body=Body.box(N, N, N, le=LE), material=Material(E=E, nu=nu, rho=rho), model=Model(name),
                 plates=(Plate("bottom", Region("z-")), Plate("top", Region("z+"), motion)), **kw)


MOTIONS = {"stretch": Motion("translate", (0.0, 0.0, STRAIN * H)),
           "shear": Motion("translate", (STRAIN * H, 0.0, 0.0))}


def engine_tets(scene: Scene) -> np.ndarray:
    """MuJoCo's tetrahedra (its grid split) of the scene's lattice: the mesh of the same-mesh
    reference (the ``tet_p1_reaction`` fixture)."""
    from hybmss.models.mujoco.engine import cell_tets

    return cell_tets(build(scene).lattice.cells)


@pytest.mark.parametrize("motion", sorted(MOTIONS))
@pytest.mark.parametrize("name", KINDS)
def test_same_mesh_linear_fem(name, motion, tet_p1_reaction):
    nu = 0.3
    sc = cube(name, nu, MOTIONS[motion], rho=0.0)
    r = solve_static(sc)
    got = np.asarray(r.reactions["top"].force)
    if name == "mujoco-tet":
        ref = tet_p1_reaction(sc, engine_tets(sc))
    else:
        from fem_reference.solve import solve as fem_solve
        fem = fem_solve(sc, element="hex1" if name == "mujoco-trilinear" else "hex2", law="linear")
        ref = np.asarray(fem.reactions["top"].force)
    scale = np.abs(ref).max()
    assert r.converged and r.info["rest"]["at_rest"]
    assert np.abs(got - ref).max() <= 1e-3 * scale, (name, motion, got, ref)
    assert r.info["reaction_balance"]["relative"] <= 1e-3


@pytest.mark.parametrize("nu", (0.0, 0.25, 0.45))
@pytest.mark.parametrize("name", KINDS)
def test_moduli(name, nu):
    m = measure_moduli(Model(name), Material(E=E, nu=nu, rho=1000.0))
    assert m["E_eff"] == pytest.approx(E, rel=1e-4)
    assert m["nu_eff"] == pytest.approx(nu, abs=1e-4)
    assert m["G_eff"] == pytest.approx(E / (2 * (1 + nu)), rel=1e-4)


@pytest.mark.parametrize("name", KINDS)
def test_reactions_balance_weight(name):
    rho, g = 1000.0, 9.81
    sc = Scene(body=Body.box(N, N, N, le=LE), material=Material(E=1e6, nu=0.3, rho=rho), model=Model(name),
               plates=(Plate("bottom", Region("z-")),), gravity=(0.0, 0.0, -g))
    r = solve_static(sc)
    weight = rho * H**3 * g
    assert r.reactions["bottom"].force[2] == pytest.approx(weight, rel=1e-3)
    assert r.info["reaction_balance"]["relative"] <= 1e-3
    assert r.u[:, 2].min() < 0.0


@pytest.mark.parametrize("name", KINDS)
def test_refuses_what_it_cannot_represent(name):
    from hybmss.explicit import simulate_explicit
    from hybmss.scene import Load

    from hybmss.solve import StaticSolveError

    with pytest.raises(ValueError, match="nu"):
        solve_static(cube(name, -0.2, MOTIONS["stretch"]))
    with pytest.raises(StaticSolveError, match="nu"):  # a failed row of a sweep, not a crash
        solve_static(cube(name, -0.2, MOTIONS["stretch"]))
    with pytest.raises(ValueError, match="loads"):
        solve_static(cube(name, 0.3, MOTIONS["stretch"], loads=(Load(Region("z+"), (0.0, 0.0, -1.0)),)))
    with pytest.raises(ValueError, match="threads"):
        simulate_explicit(cube(name, 0.3, MOTIONS["stretch"]), dt=1e-4, steps=10, threads=2, kernel="engine")
    if name != "mujoco-tet":
        mask = np.ones((2, 2, 2), dtype=bool)
        mask[1, 1, 1] = False
        sc = Scene(body=Body.from_mask(mask, le=LE), material=Material(E=E, nu=0.3, rho=1000.0), model=Model(name),
                   plates=(Plate("bottom", Region("z-")),))
        with pytest.raises(ValueError, match="body"):
            solve_static(sc)


def test_explicit_run_reaches_rest():
    """The explicit protocol (MuJoCo's steps, the harness's ramp and damping) ends at the static
    answer: its reaction equals the static one's to 1e-3 when rest_report finds it at rest."""
    from hybmss.explicit import simulate_explicit

    sc = cube("mujoco-trilinear", 0.3, MOTIONS["stretch"])
    st = solve_static(sc)
    i = st.info  # the static run's step, damping (2 ω₁) and ramp; run 30/ω₁ past the ramp
    steps = int((i["ramp_time"] + 30.0 / i["omega_1"]) / i["dt"])
    r = simulate_explicit(sc, dt=i["dt"], steps=steps, ramp_time=i["ramp_time"], damping=i["damping"],
                          kernel="engine")
    assert r.converged, r.info["rest"]
    assert r.reactions["top"].force[2] == pytest.approx(st.reactions["top"].force[2], rel=1e-3)
    assert r.info["step_time_s"] > 0 and r.info["device"] == "cpu"


@pytest.mark.parametrize("name, law", [("mujoco-tet", "svk"), ("mujoco-trilinear", "corotational"),
                                       ("mujoco-quadratic", "corotational")])
def test_law_of_the_element(name, law):
    """MuJoCo's own forces on one cell under a uniaxial strain ε = 1e-2 (lateral faces held):
    the nominal stress is (λ + 2μ) ε (1 + ε)(1 + ε/2) for St Venant–Kirchhoff (Green strain),
    (λ + 2μ) ε for the corotational linear cells (no rotation in this state); and a rigid
    rotation of 0.3 rad gives no force."""
    from hybmss.models.mujoco.engine import MujocoBody
    from hybmss.scene import rotation_matrix

    nu, eps = 0.3, 1e-2
    sc = Scene(body=Body.box(1, 1, 1, le=1.0), material=Material(E=E, nu=nu, rho=1000.0), model=Model(name),
               plates=(Plate("bottom", Region("z-")),))
    body = MujocoBody(build(sc), name.split("-")[1], 1e-3, 1.0)
    X = body.nodes.X
    lam, mu = sc.material.lam, sc.material.G
    x = X.copy()
    x[:, 2] *= 1.0 + eps
    f = body.internal_forces(x)
    top = np.isclose(X[:, 2], 1.0)
    stress = -f[top, 2].sum()
    expect = (lam + 2 * mu) * eps * ((1 + eps) * (1 + eps / 2) if law == "svk" else 1.0)
    assert stress == pytest.approx(expect, rel=1e-9)
    R = rotation_matrix((1.0, 2.0, 0.5), 0.3)
    assert np.abs(body.internal_forces(X @ R.T)).max() <= 1e-9 * E


def test_missing_engine_leaves_its_models_out():
    """Without the mujoco package the registry lists no such model among its names but as unavailable with the
    install command, writes nothing to stderr, and a command naming one is refused (exit 2) with the
    install command, never a traceback."""
    import subprocess
    import sys

    block = ("import sys\n"
             "class Block:\n"
             "    def find_spec(self, name, path=None, target=None):\n"
             "        if name == 'mujoco' or name.startswith('mujoco.'):\n"
             "            raise ModuleNotFoundError(name)\n"
             "sys.meta_path.insert(0, Block())\n")
    code = block + "import hybmss.models as m; print(','.join(m.names()))"
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert "mujoco" not in p.stdout and "xpbd-nh" in p.stdout
    assert p.stderr.strip() == "", p.stderr
    code = block + "import hybmss.models as m; print(m.unavailable()['mujoco-tet'])"
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert "mujoco" in p.stdout and "pip install 'hybmss[engines]'" in p.stdout, p.stdout + p.stderr
    code = block + "from studies.cli.parser import main; sys.exit(main(['moduli', '--model', 'mujoco-tet']))"
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and "hybmss[engines]" in p.stderr, p.stderr
