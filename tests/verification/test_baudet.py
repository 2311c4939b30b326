"""The [B09] variant baudet2009: correction forces, their Numba twin, the equilibrium solver,
effective moduli and the cantilever experiment."""

import dataclasses

import numpy as np
import pytest

from hybmss.models.baudet2009.corrections import Corrections, GridCorrections, cell_transmitted_forces, correction_jacobian
from hybmss.forces import spring_energy_forces
from hybmss.moduli import measure_moduli, uniaxial_scene
from hybmss.scene import Body, Material, Model, Motion, Plate, Region, Scene
from hybmss.solve import solve_static
from hybmss.system import build


def _voxel_system(nu=0.3):
    mask = np.ones((3, 2, 4), dtype=bool)
    mask[1:, :, 2:] = False
    scene = Scene(Body.from_mask(mask, 0.1), Material(1000.0, nu), Model("baudet2009"))
    return build(scene)


def _random_state(S, amplitude=0.01, seed=0):
    rng = np.random.default_rng(seed)
    return S.X + amplitude * rng.standard_normal(S.X.shape)


@pytest.mark.parametrize("nu", [pytest.param(0.0, marks=pytest.mark.slow), 0.3, pytest.param(0.49, marks=pytest.mark.slow)])
def test_numba_twin_agrees_with_numpy(nu):
    S = _voxel_system(nu)
    x = _random_state(S)
    f_np = S.term("baudet2009_corrections").forces(x)
    f_nb = GridCorrections.from_system(S).forces(x)
    assert np.abs(f_nb - f_np).max() <= 1e-10 * np.abs(f_np).max()


def test_corrections_conserve_momentum_and_vanish_at_rest():
    S = _voxel_system()
    corr = S.term("baudet2009_corrections")
    assert np.abs(corr.forces(S.X)).max() < 1e-12 * corr.kx * corr.le
    x = _random_state(S)
    f = corr.forces(x)
    scale = np.abs(f).max()
    assert np.abs(f.sum(axis=0)).max() < 1e-12 * scale * len(f)
    assert np.abs(np.cross(x, f).sum(axis=0)).max() < 1e-12 * scale * len(f)


def test_corrections_are_not_a_gradient():
    """The Jacobian is not symmetric (curl ≠ 0) and the forces do work around a closed loop,
    unlike the springs (a gradient field) around the same loop."""
    S = _voxel_system()
    x0 = _random_state(S, 0.005)
    J = correction_jacobian(x0, S.term("baudet2009_corrections")).toarray()
    asym = np.abs(J - J.T).max() / np.abs(J).max()
    assert asym > 1e-2

    # the loop: a square of side δ in the plane of the two dofs with the largest asymmetry
    i, j = np.unravel_index(np.argmax(np.abs(J - J.T)), J.shape)
    delta = 5e-4

    def work(force):
        t = np.linspace(0.0, 1.0, 401)
        corners = [(0, 0), (1, 0), (1, 1), (0, 1), (0, 0)]
        W = 0.0
        for (a0, b0), (a1, b1) in zip(corners[:-1], corners[1:]):
            vals = []
            for s in t:
                x = x0.copy().ravel()
                x[i] += delta * (a0 + s * (a1 - a0))
                x[j] += delta * (b0 + s * (b1 - b0))
                f = force(x.reshape(-1, 3)).ravel()
                vals.append(f[i] * delta * (a1 - a0) + f[j] * delta * (b1 - b0))
            W += np.trapezoid(vals, t)
        return W

    W_corr = work(S.term("baudet2009_corrections").forces)
    W_spr = work(lambda x: spring_energy_forces(x, S.spring_a, S.spring_b, S.spring_k, S.spring_l0)[1])
    expected = (J[j, i] - J[i, j]) * delta**2  # Stokes: ∮ f·dx = ∬ (∂f_j/∂x_i − ∂f_i/∂x_j)
    assert W_corr == pytest.approx(expected, rel=0.1)
    assert abs(W_spr) < 1e-3 * abs(W_corr)


def test_static_solver_runs_the_residual_mode():
    scene = uniaxial_scene(Model("baudet2009"), Material(1e4, 0.3), strain=1e-3)
    r = solve_static(scene)
    assert r.converged and r.info["equilibrium"].startswith("force-residual Newton")
    assert r.info["relative_residual"] < 1e-8
    assert "stable" not in r.info and r.info["stability"].startswith("not certified")
    # the lateral faces are free: every cell transmits no force across them (T_y = T_z = 0)
    T = cell_transmitted_forces(r.x, build(scene).term("baudet2009_corrections"))
    assert np.abs(T[:, :2]).max() < 1e-6 * np.abs(T[:, 2]).max()


@pytest.mark.parametrize("nu", [0.0, 0.25, 0.3, 0.45, 0.49])
def test_moduli_E_and_nu_right_and_G_as_theory_says(nu):
    """E and ν are right in uniaxial tension (the 1 % asked; here far better).  G: the inner
    diagonals alone give C_44 = 4 kd/(3 le) = E/(2(1+ν)) = G and the corrections vanish to first
    order in simple shear (no normal force), so theory says G_eff = G: the error is reported as
    G_eff/G − 1 and asserted to be ~0, measured from the plate reactions (no energy)."""
    mat = Material(1e4, nu)
    m = measure_moduli(Model("baudet2009"), mat)
    assert m["E_eff"] == pytest.approx(mat.E, rel=1e-2)
    assert m["nu_eff"] == pytest.approx(nu, rel=1e-2, abs=1e-6)
    assert m["E_eff"] == pytest.approx(mat.E, rel=1e-6)
    assert m["nu_eff"] == pytest.approx(nu, rel=1e-6, abs=1e-7)
    assert m["G_eff"] / mat.G - 1.0 == pytest.approx(0.0, abs=1e-5)


def test_springs_alone_miss_nu():
    """Without the corrections (same springs) ν_eff is the spring lattice's, not the target:
    S_y = 0 gives ν_spr = b/(a + 2b) = 1/(4ν + 3) (0.238 at ν = 0.3)."""
    S = dataclasses.replace(build(uniaxial_scene(Model("baudet2009"), Material(1e4, 0.3))), terms=())
    assert S.conservative  # springs only: a conservative system again
    scene = uniaxial_scene(Model("baudet2009"), Material(1e4, 0.3))
    r = solve_static(scene, system=S)
    n, le = scene.body.shape[0], scene.body.le
    lateral = (r.u[np.isclose(r.X[:, 0], n * le), 0].mean() - r.u[np.isclose(r.X[:, 0], 0), 0].mean()) / (n * le)
    assert -lateral / 1e-4 == pytest.approx(1.0 / (4 * 0.3 + 3.0), rel=1e-3)


def test_cantilever_error_decreases_with_refinement_for_both_variants():
    from studies.paper.baudet import MODELS, cantilever_scene, displacement_error
    from fem_reference.solve import solve as fem_solve

    ref = fem_solve(cantilever_scene(4, "hybmss"), element="hex2", refine=1)  # h = 25 mm
    for model in MODELS:
        errs = []
        for n in (1, 2):
            r = solve_static(cantilever_scene(n, model))
            errs.append(displacement_error(r.X, r.u, ref.X, ref.u))
        assert errs[1]["err_mean_pct"] < 0.6 * errs[0]["err_mean_pct"], (model, errs)
        assert errs[1]["err_max_pct"] < 0.6 * errs[0]["err_max_pct"], (model, errs)


def test_explicit_numpy_kernel_runs_the_corrections():
    """Explicit dynamics sees the corrections through ``System.terms`` (NumPy kernel);
    with damping it settles on the equilibrium of the force-residual solver."""
    from hybmss.explicit import simulate_explicit

    scene = Scene(Body.box(2, 1, 1, 0.1), Material(1000.0, 0.3, 100.0), Model("baudet2009"),
                  plates=(Plate("clamp", Region("x-"), Motion("clamped")),
                          Plate("pull", Region("x+"), Motion("translate", (2e-4, 0.0, 0.0)))),
                  damping=20.0)
    st = solve_static(scene)
    ex = simulate_explicit(scene, dt=2e-3, steps=3000, kernel="numpy", ramp_time=0.5)
    assert np.abs(ex.u - st.u).max() < 1e-3 * np.abs(st.u).max()


def test_implicit_euler_refuses_non_conservative_forces():
    from hybmss.solve import simulate_implicit

    scene = uniaxial_scene(Model("baudet2009"), Material(1e4, 0.3))
    with pytest.raises(ValueError, match="has no implicit solver"):
        simulate_implicit(scene)


def test_equilibrium_never_accepts_an_inverted_lattice():
    """A plate moved through a whole layer in one step leaves the lattice inverted with every
    spring at rest (zero force): the solver must not return that state."""
    scene = Scene(Body.box(2, 2, 4, 1.0), Material(1e4, 0.45), Model("baudet2009"),
                  plates=(Plate("bottom", Region("z-"), Motion("clamped")),
                          Plate("top", Region("z+"), Motion("translate", (0.0, 0.0, -1.2)))))
    r = solve_static(scene)
    assert r.info["inverted_cells"] == 0
    assert r.reactions["top"].force[2] < 0  # the plate pushes down on a compressed body
    assert 0.0 < abs(r.volume_change) < 0.3


@pytest.mark.slow
def test_study_driver_writes_its_tables(tmp_path):
    from studies.paper.baudet import run
    from studies.sweep.store import Store

    run(Store(tmp_path), quick=True, progress=False)
    for name in ("baudet_moduli", "baudet_cantilever", "baudet_lshape", "baudet_volume"):
        assert (tmp_path / "tables" / f"{name}.csv").exists()
    # the volume table reads the stored static runs: the value of a direct solve of the same scene
    import pandas as pd

    from studies.paper.reproduce import cube
    from studies.sweep.scenes import SceneSpec

    vol = pd.read_csv(tmp_path / "tables" / "baudet_volume.csv")
    row = vol[(vol["experiment"] == "compression") & (vol["nu"] == 0.25) & (vol["d_pct"] == 5.0)].iloc[0]
    r = solve_static(SceneSpec.default("compression", mesh=cube(True), nu=0.25, deformation=0.05)
                     .replace(model="baudet2009").build())
    assert row["baudet2009_state"] == "ok" and row["baudet2009_e_pct"] == pytest.approx(100 * abs(r.volume_change),
                                                                                       rel=1e-12)
    assert row["paper_fem_e_pct"] == 3.1 and len(vol) == 12  # [G20] Table 2; 6 rows of each table
