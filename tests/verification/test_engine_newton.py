"""Newton's ``SolverSemiImplicit`` soft tetrahedra (``newton-semi``) against scikit-fem on the very
same mesh, its small-strain moduli, the balance of its plate reactions, and what it refuses.

Newton's particle state is float32: forces change by its force resolution
(:meth:`hybmss.models.newton.engine.NewtonBody.force_resolution`) under one-ulp moves, and the
moduli, Richardson's differences of two small reactions, lose digits to it at strain 1e-4 (E_eff
1.3 % high at ν = 0.45, measured): they are measured at strain 3e-3, where they hold to 1e-3
(3e-4 measured).  The same-mesh reactions hold to 1e-3 at strain 1e-4.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("newton")
pytest.importorskip("warp")

from hybmss import Body, Material, Model, Motion, Plate, Region, Scene  # noqa: E402
from hybmss.moduli import measure_moduli  # noqa: E402
from hybmss.solve import solve_static  # noqa: E402
from hybmss.system import build  # noqa: E402

NAME = "newton-semi"
E, LE, N = 1e4, 0.5, 2
H = N * LE
STRAIN = 3e-3


def cube(nu: float, motion: Motion, rho: float = 1000.0, name: str = NAME, **kw) -> Scene:
    return Scene(body=Body.box(N, N, N, le=LE), material=Material(E=E, nu=nu, rho=rho), model=Model(name),
                 plates=(Plate("bottom", Region("z-")), Plate("top", Region("z+"), motion)), **kw)


def motion(kind: str, eps: float) -> Motion:
    return Motion("translate", (0.0, 0.0, eps * H) if kind == "stretch" else (eps * H, 0.0, 0.0))


def engine_tets(scene: Scene) -> np.ndarray:
    """Newton's tetrahedra (its 5-tet grid split) of the scene's lattice: the mesh of the same-mesh
    reference (the ``tet_p1_reaction`` fixture)."""
    from hybmss.models.newton.engine import cell_tets

    lat = build(scene).lattice
    return cell_tets(lat.cells, lat.cell_ijk)


@pytest.mark.parametrize("kind", ("stretch", "shear"))
def test_same_mesh_linear_fem(kind, tet_p1_reaction):
    """At strain 1e-4 the reaction equals the linear FEM's on Newton's tetrahedra to 1e-3
    (measured 1.3e-4 stretch, 3.6e-4 shear: the float32 state, the O(ε) Neo-Hookean term)."""
    sc = cube(0.3, motion(kind, 1e-4), rho=0.0)
    r = solve_static(sc)
    got = np.asarray(r.reactions["top"].force)
    ref = tet_p1_reaction(sc, engine_tets(sc))
    assert r.converged
    assert np.abs(got - ref).max() <= 1e-3 * np.abs(ref).max(), (kind, got, ref)
    # the plates balance to 1e-3 or to the float32 force resolution (1.0e-3 measured in shear)
    rest = r.info["rest"]
    assert r.info["reaction_balance"]["relative"] <= max(1e-3, rest["resolution_N"] / rest["force_scale_N"])


@pytest.mark.parametrize("nu", (0.0, 0.25, 0.45))
def test_moduli(nu):
    m = measure_moduli(Model(NAME), Material(E=E, nu=nu, rho=1000.0), strain=STRAIN)
    assert m["E_eff"] == pytest.approx(E, rel=1e-3)
    assert m["nu_eff"] == pytest.approx(nu, abs=1e-3)
    assert m["G_eff"] == pytest.approx(E / (2 * (1 + nu)), rel=1e-3)


def test_lame_map_of_the_law():
    """Newton's own forces on one cell under a uniaxial strain ε = 1e-3 (lateral faces held): the
    nominal stress is (λ₀ + 2μ₀) ε to O(ε) with k_mu = 4μ₀/3, k_lambda = λ₀ + 5μ₀/6; the
    Lamé parameters given as they are (the builder's wording) would be 25 % soft in shear."""
    from hybmss.models.newton.engine import NewtonBody

    nu, eps = 0.3, 1e-3
    sc = Scene(body=Body.box(1, 1, 1, le=1.0), material=Material(E=E, nu=nu, rho=1000.0), model=Model(NAME),
               plates=(Plate("bottom", Region("z-")),))
    body = NewtonBody(build(sc), "semi", 1e-3, 1.0)
    X = body.nodes.X
    x = X.copy()
    x[:, 2] *= 1.0 + eps
    stress = -body.internal_forces(x)[np.isclose(X[:, 2], 1.0), 2].sum()
    m = sc.material
    assert stress == pytest.approx((m.lam + 2 * m.G) * eps, rel=3e-3)
    assert body.k_mu == pytest.approx(4 * m.G / 3) and body.k_lambda == pytest.approx(m.lam + 5 * m.G / 6)


def test_reactions_balance_weight():
    rho, g = 1000.0, 9.81
    sc = Scene(body=Body.box(N, N, N, le=LE), material=Material(E=1e6, nu=0.3, rho=rho), model=Model(NAME),
               plates=(Plate("bottom", Region("z-")),), gravity=(0.0, 0.0, -g))
    r = solve_static(sc)
    weight = rho * H**3 * g
    assert r.reactions["bottom"].force[2] == pytest.approx(weight, rel=1e-3)
    assert r.u[:, 2].min() < 0.0


def test_refuses_what_it_cannot_represent():
    from hybmss.explicit import simulate_explicit
    from hybmss.scene import Load

    from hybmss.solve import StaticSolveError

    with pytest.raises(ValueError, match="nu"):
        solve_static(cube(-0.4, motion("stretch", STRAIN)))
    with pytest.raises(StaticSolveError, match="nu"):  # a failed row of a sweep, not a crash
        solve_static(cube(-0.4, motion("stretch", STRAIN)))
    with pytest.raises(ValueError, match="loads"):
        solve_static(cube(0.3, motion("stretch", STRAIN), loads=(Load(Region("z+"), (0.0, 0.0, -1.0)),)))
    with pytest.raises(ValueError, match="threads"):
        simulate_explicit(cube(0.3, motion("stretch", STRAIN)), dt=1e-4, steps=10, threads=2, precision="f32",
                          kernel="engine")
    with pytest.raises(ValueError, match="precision"):
        simulate_explicit(cube(0.3, motion("stretch", STRAIN)), dt=1e-4, steps=10, kernel="engine")


@pytest.mark.parametrize("name", (NAME, "newton-vbd"))
def test_explicit_run_reaches_rest(name):
    """The explicit protocol (Newton's steps, the harness's ramp and damping) ends at the static
    answer: the same reaction to 1e-3 once rest_report finds it at rest."""
    from hybmss.explicit import simulate_explicit

    sc = cube(0.3, motion("stretch", STRAIN), name=name)
    st = solve_static(sc)
    i = st.info
    steps = int((i["ramp_time"] + 30.0 / i["omega_1"]) / i["dt"])
    r = simulate_explicit(sc, dt=i["dt"], steps=steps, ramp_time=i["ramp_time"], damping=i["damping"],
                          precision="f32", kernel="engine")
    assert r.converged, r.info["rest"]
    assert r.reactions["top"].force[2] == pytest.approx(st.reactions["top"].force[2], rel=1e-3)
    assert r.info["device"] == "cpu" and r.info["precision"] == "f32" and r.info["compile_time_s"] > 0


def test_cli_json_is_one_object_on_stdout():
    """``hybmss moduli --model newton-semi --json``: Warp's greeting and module-load lines stay off
    stdout, which holds the one strict-JSON object."""
    import json
    import os
    import subprocess
    import sys

    p = subprocess.run([sys.executable, "-m", "studies.cli.parser", "moduli", "--model", NAME, "--strain", str(STRAIN),
                        "--nu", "0.25", "--json"], capture_output=True, text=True, timeout=600, env=dict(os.environ))
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["status"] == "ok" and out["G_eff"] == pytest.approx(E / 2.5, rel=1e-3)


def test_missing_engine_leaves_its_models_out():
    """Without newton the registry lists no such model among its names but as unavailable with the
    install command, writes nothing to stderr, and a command naming one is refused (exit 2) with the
    install command, never a traceback."""
    import subprocess
    import sys

    block = ("import sys\n"
             "class Block:\n"
             "    def find_spec(self, name, path=None, target=None):\n"
             "        if name.split('.')[0] == 'newton':\n"
             "            raise ModuleNotFoundError(name)\n"
             "sys.meta_path.insert(0, Block())\n")
    p = subprocess.run([sys.executable, "-c", block + "import hybmss.models as m; print(','.join(m.names()))"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert "newton" not in p.stdout and "mujoco-tet" in p.stdout
    assert p.stderr.strip() == "", p.stderr
    code = block + "import hybmss.models as m; print(m.unavailable()['newton-semi'])"
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert "newton" in p.stdout and "pip install 'hybmss[engines]'" in p.stdout, p.stdout + p.stderr
    code = block + "from studies.cli.parser import main; sys.exit(main(['moduli', '--model', 'newton-semi']))"
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and "hybmss[engines]" in p.stderr, p.stderr


# ---------------------------------------------------------------------------- newton-vbd, newton-xpbd
def homogeneous_stress(forces, X: np.ndarray, H: np.ndarray) -> np.ndarray:
    """Nominal stress of a unit-volume body under the homogeneous displacement gradient H from the
    engine's own nodal forces (virtual work: ``P = −Σ_a f_a ⊗ X_a / V``)."""
    return -np.einsum("ai,aj->ij", forces(X + X @ H.T), X)


def law_moduli(forces, X: np.ndarray, eps: float = 1e-3) -> tuple[float, float]:
    """(λ, μ) of a law at small strain from central differences (±ε: the O(ε²) terms cancel) of its
    stress under uniaxial strain (λ = P_xx/ε) and simple shear (μ = P_xz/γ)."""
    Hz, Hs = np.zeros((3, 3)), np.zeros((3, 3))
    Hz[2, 2], Hs[0, 2] = eps, eps
    Pz = (homogeneous_stress(forces, X, Hz) - homogeneous_stress(forces, X, -Hz)) / (2 * eps)
    Ps = (homogeneous_stress(forces, X, Hs) - homogeneous_stress(forces, X, -Hs)) / (2 * eps)
    assert Pz[2, 2] - Pz[0, 0] == pytest.approx(2 * Ps[0, 2], rel=1e-3, abs=1e-5 * abs(Pz[2, 2]))  # isotropic
    return Pz[0, 0], Ps[0, 2]


def one_cell_body(name: str, nu: float):
    from hybmss.models.newton.engine import NewtonBody

    sc = Scene(body=Body.box(1, 1, 1, le=1.0), material=Material(E=E, nu=nu, rho=1000.0), model=Model(name),
               plates=(Plate("bottom", Region("z-")),))
    return sc.material, NewtonBody(build(sc), "vbd", 1e-3, 1.0)


@pytest.mark.parametrize("nu", (0.0, 0.25, 0.45))
def test_vbd_moduli_of_its_law(nu):
    """SolverVBD's own force evaluation (its evaluate_volumetric_neo_hookean_force_and_hessian) on
    one cell's five tetrahedra under homogeneous strains of 1e-3: λ and μ are the material's, so
    E, ν, G hold to 1e-4 (measured 2e-5: float32 positions of a 1 m cell carry 6e-8, 6e-5 of the
    strain, mostly cancelled by the central difference)."""
    m, body = one_cell_body("newton-vbd", nu)
    lam, mu = law_moduli(body.internal_forces, body.nodes.X)
    E_eff, nu_eff = mu * (3 * lam + 2 * mu) / (lam + mu), lam / (2 * (lam + mu))
    assert E_eff == pytest.approx(E, rel=1e-4)
    assert nu_eff == pytest.approx(nu, abs=1e-4)
    assert mu == pytest.approx(m.G, rel=1e-4)
    assert body.k_mu == m.G and body.k_lambda == m.lam  # the builder's Lamé parameters as they are


@pytest.mark.parametrize("nu", (0.0, 0.25, 0.45))
@pytest.mark.parametrize("kind", ("stretch", "shear"))
def test_vbd_same_mesh_linear_fem(kind, nu, tet_p1_reaction):
    """At strain 1e-4 the reaction equals the linear FEM's on Newton's tetrahedra within the
    engine's certified rest residual: 1e-3, or the float32 force resolution over the force scale
    where larger (4.7e-3 stretch, 1.2e-2 shear at ν = 0; measured differences 2.9e-3, 3.2e-3):
    VBD updates positions, and a correction below one unit in the last place of a position is
    lost, so its sweeps stop at that residual (a longer settling leaves it unchanged)."""
    sc = Scene(body=Body.box(N, N, N, le=LE), material=Material(E=E, nu=nu, rho=0.0), model=Model("newton-vbd"),
               plates=(Plate("bottom", Region("z-")), Plate("top", Region("z+"), motion(kind, 1e-4))))
    r = solve_static(sc)
    got = np.asarray(r.reactions["top"].force)
    ref = tet_p1_reaction(sc, engine_tets(sc))
    rest = r.info["rest"]
    tol = max(1e-3, rest["resolution_N"] / rest["force_scale_N"])
    assert r.converged and r.info["integrator"] == "SolverVBD"
    assert np.abs(got - ref).max() <= tol * np.abs(ref).max(), (kind, nu, got, ref, tol)
    # the imbalance adds the two plates' errors, each within the residual (4.9e-3 measured at ν = 0)
    assert r.info["reaction_balance"]["relative"] <= 2 * tol


def test_vbd_reactions_balance_weight():
    rho, g = 1000.0, 9.81
    sc = Scene(body=Body.box(N, N, N, le=LE), material=Material(E=1e6, nu=0.3, rho=rho), model=Model("newton-vbd"),
               plates=(Plate("bottom", Region("z-")),), gravity=(0.0, 0.0, -g))
    r = solve_static(sc)
    weight = rho * H**3 * g
    assert r.converged
    assert r.reactions["bottom"].force[2] == pytest.approx(weight, rel=1e-3)
    assert r.u[:, 2].min() < 0.0


def test_vbd_refuses_sliding_plates():
    """A node held in some components only (slide plates, as the moduli command uses) cannot be a
    kinematic particle of SolverVBD, and set after its step it stays off equilibrium: refused."""
    from hybmss.solve import StaticSolveError

    sc = Scene(body=Body.box(N, N, N, le=LE), material=Material(E=E, nu=0.3, rho=1000.0), model=Model("newton-vbd"),
               plates=(Plate("bottom", Region("z-"), Motion("slide", components=(2,))),
                       Plate("top", Region("z+"), Motion("slide", (0.0, 0.0, 1e-3), components=(2,))),
                       # the pins of the uniaxial test: held as a rigid body, so it is SolverVBD that refuses
                       Plate("pin", Region(lo=(0, 0, 0), hi=(0, 0, 0)), Motion("slide", components=(0, 1))),
                       Plate("pin_x", Region(lo=(N * LE, 0, 0), hi=(N * LE, 0, 0)), Motion("slide", components=(1,)))))
    with pytest.raises(ValueError, match="newton-vbd cannot represent"):
        solve_static(sc)
    with pytest.raises(StaticSolveError, match="plates"):
        measure_moduli(Model("newton-vbd"), Material(E=E, nu=0.3, rho=1000.0))


@pytest.mark.parametrize("nu", (0.0, 0.25, 0.45))
def test_xpbd_law_has_no_small_strain_shear_stiffness(nu):
    """SolverXPBD's own constraint forces (its solve_tetrahedra, from zero multipliers, over dt²)
    with the builder's Lamé parameters k_mu = μ, k_lambda = λ: its constraints C = tr(FᵀF) − 3
    and det F − 1 give a small-strain law of λ_eff = 4 k_mu + k_lambda and μ_eff = 0 (measured
    2e-6 μ at γ = 1e-3, the γ² of a quartic energy); with k_lambda = 0 (ν = 0) the kernel skips
    the tetrahedron altogether."""
    from hybmss.models.newton.engine import xpbd_constraint_forces

    m, body = one_cell_body("newton-vbd", nu)
    lam, mu = law_moduli(lambda x: xpbd_constraint_forces(body.model, x), body.nodes.X)
    assert abs(mu) <= 1e-5 * m.G
    assert lam == pytest.approx(4 * m.G + m.lam if nu > 0 else 0.0, rel=1e-4, abs=1e-6 * m.G)


def test_xpbd_is_refused():
    from hybmss.solve import StaticSolveError

    sc = cube(0.3, motion("stretch", STRAIN))
    with pytest.raises(ValueError, match="model: newton-xpbd cannot represent a shear modulus"):
        solve_static(Scene(body=sc.body, material=sc.material, model=Model("newton-xpbd"), plates=sc.plates))
    with pytest.raises(StaticSolveError, match="shear modulus"):
        measure_moduli(Model("newton-xpbd"), Material(E=E, nu=0.3, rho=1000.0))
