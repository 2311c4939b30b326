"""Quick versions of the performance, speed-against-error and stability studies: their
qualitative facts on tiny meshes."""

from __future__ import annotations

import numpy as np
import pytest

from studies.paper import pareto

from studies.paper import performance

from studies.sweep import runner

from studies.paper import stability
from studies.sweep.runner import SolverSpec, Task, run_tasks
from studies.sweep.scenes import SceneSpec
from studies.sweep.store import Store


@pytest.fixture(scope="module")
def dt_rows():
    return stability.dt_table(quick=True, nus=(0.25, 0.45, 0.49, 0.499, 0.4999), variants=("hybmss",),
                              steps=2000)


def test_dt_crit_shrinks_as_nu_tends_to_half(dt_rows):
    dc = dt_rows.sort_values("nu")["dt_crit"].to_numpy()
    assert np.all(np.diff(dc) < 0)
    assert dc[-1] < 0.2 * dc[0]


def test_bisected_dt_is_close_to_the_eigenvalue_estimate(dt_rows):
    ratio = dt_rows["ratio"].to_numpy()
    assert np.all((ratio >= 0.5) & (ratio <= 1.05)), dt_rows[["nu", "dt_crit", "dt_stable", "ratio"]]


def test_a_model_without_explicit_limit_runs_once_at_twenty_dt_crit():
    """xpbd-nh (constraints solved implicitly) is shown stable by one run at 20 dt_crit instead of
    a bisection towards a limit it does not have; that run does tell the two kinds apart: the
    mass-spring model diverges there."""
    from hybmss.explicit import DivergenceError, simulate_explicit

    rows = stability.dt_table(quick=True, nus=(0.45,), variants=("xpbd-nh",), steps=400)
    (r,) = rows.to_dict("records")
    assert r["trials"] == 1 and r["ratio"] == stability.UNLIMITED_FACTOR and "no stability limit" in r["note"]
    sc = SceneSpec.default("compression", mesh=(2, 2, 2), nu=0.45, deformation=0.05).build()
    with pytest.raises(DivergenceError):
        simulate_explicit(sc, dt=stability.UNLIMITED_FACTOR * r["dt_crit"] * 0.9, steps=20, ramp_time=1.0)


def test_divergence_is_a_row_not_an_exception(tmp_path):
    spec = SceneSpec.default("compression", mesh=(2, 2, 2), nu=0.499)
    task = Task(spec, SolverSpec("explicit", dt=0.5, steps=200, ramp_time=1.0), "test")
    (row,) = run_tasks([task], Store(tmp_path), jobs=1, progress=False)
    assert row["status"] == "diverged"
    assert "dt_crit" in row["message"] and "exceeds" in row["message"]


@pytest.mark.slow
def test_pareto_table_covers_every_experiment(tmp_path):
    tables = pareto.run(Store(tmp_path), quick=True, jobs=2, progress=False)
    df = tables["pareto"]
    for exp in pareto.EXPERIMENTS:
        sub = df[(df["experiment"] == exp) & np.isfinite(df["error_u"])]
        assert len(sub) > 0, exp
        assert sub["pareto"].any(), exp
    refs = tables["pareto_references"]
    assert (refs["reference_status"] == "ok").all()
    assert np.all(np.isfinite(refs["reference_error_estimate"]))
    # a refinement of the MSS brings it closer to the converged reference
    st = df[(df["method"] == "hybmss static") & (df["experiment"] == "compression")].sort_values("factor")
    assert st["error_u"].iloc[-1] < st["error_u"].iloc[0]
    budget = tables["budget"]
    assert set(budget["budget"].dropna()) == set(pareto.BUDGETS)
    # every experiment has its load, volume and field errors against the reference
    for m in pareto.MEASURES:
        assert df.groupby("experiment")[f"error_{m}"].apply(lambda e: np.isfinite(e).any()).all(), m


def test_sample_refuses_points_off_the_lattice():
    X = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    u = np.array([[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    assert pareto.sample(X, u, X[::-1])[0, 0] == 2.0
    with pytest.raises(ValueError):
        pareto.sample(X, u, np.array([[0.5, 0.0, 0.0]]))


def test_limit_stretch_at_nu_zero_is_reported_with_its_cause():
    from hybmss.solve import StaticSolveError, solve_static

    spec = SceneSpec.default("tension", mesh=(1, 1, 6), nu=0.0, deformation=1.0)
    with pytest.raises(StaticSolveError) as err:
        solve_static(spec.build())
    assert err.value.cause in ("limit-point", "indefinite-at-rest")
    assert "kappa" in str(err.value) or "positive definite" in str(err.value)
    # the runner's row of the same run: classified by type, its numbers stored as fields
    row, _ = runner.compute(Task(spec, SolverSpec("static"), "stability"))
    assert row["status"] == "unstable" and row["message"].startswith("StaticSolveError: ")
    p = stability.failure_numbers(row)
    assert 0.05 < p["s_last"] < p["s_fail"] < 0.5
    assert (p["s_last"], p["s_fail"]) == (err.value.load_factor, err.value.next_load_factor)
    assert f"failed at load factor s={p['s_fail']:.6g} (last converged s={p['s_last']:.6g})" in row["message"]


def test_jittered_lattice_is_at_rest_and_solvable():
    from hybmss.forces import energy_forces
    from hybmss.solve import solve_static

    scene = SceneSpec.default("compression", mesh=(2, 2, 2), nu=0.3).build()
    S = stability.jittered_system(scene, 0.1, seed=1)
    from hybmss.lattice import Lattice

    regular = Lattice.from_body(scene.body).X
    shift = np.abs(S.X - regular)
    assert 0 < shift.max() <= 0.1 * scene.body.le + 1e-12
    _, f, _ = energy_forces(S, S.X)
    assert np.abs(f).max() < 1e-9 * scene.material.E * scene.body.le**2
    res = solve_static(scene, system=S)
    assert res.converged and np.all(res.cell_volumes > 0)


def test_irregular_scenes_build():
    from hybmss.system import build

    for name, (scene, builder, _) in stability.irregular_scenes(quick=True, nu=0.3).items():
        S = builder(scene) if builder is not None else build(scene)
        assert S.n > 0 and (~S.fixed).any(), name


def test_irregular_runs_take_the_numpy_twin_only_where_the_stencil_would_be_compiled_for_them():
    """Part (e): the harness's lattice on a tiny body runs on the NumPy twin (a stencil kernel is
    compiled per lattice size, seconds against milliseconds of stepping), with the stencil
    kernel's answer to rounding; a model whose Numba kernel does not depend on the size keeps it,
    and so does a lattice above :data:`stability.TINY_LATTICE_NODES`."""
    from hybmss.explicit import simulate_explicit

    scenes = stability.irregular_scenes(quick=True, nu=0.3, model="hybmss")
    cell, builder, _ = scenes["single cell"]
    assert stability.irregular_kernel(cell, builder) == "numpy"
    assert stability.irregular_kernel(*scenes["jittered 10% le"][:2]) == "numpy"
    for model in ("hybmss-fd", "hybmss-cf"):
        assert stability.irregular_kernel(stability.irregular_scenes(True, 0.3, model)["L-shape"][0], None) == "numpy"
    for model in ("xpbd-nh", "corot-hex8"):
        assert stability.irregular_kernel(stability.irregular_scenes(True, 0.3, model)["single cell"][0], None) == "numba"
    big = SceneSpec.default("compression", mesh=(6, 6, 6), nu=0.3, model="hybmss").build()
    assert stability.irregular_kernel(big, None) == "numba"
    runs = [simulate_explicit(cell, dt=1e-3, steps=300, ramp_time=0.2, kernel=k) for k in ("numpy", "numba")]
    scale = np.abs(runs[1].u).max()
    assert scale > 1e-3 and np.abs(runs[0].u - runs[1].u).max() <= 1e-12 * scale


@pytest.mark.slow
def test_performance_quick_table():
    df, bw = performance.run_performance(quick=True, steps=20, repeats=1, threads=(1,), min_span=0.0,
                                         bandwidth_MB=16)
    assert bw["ceiling"] > 0
    timed = performance.variants()
    assert len(df) == (len(performance.QUICK_CUBES) + len(performance.QUICK_BEAMS)) * len(timed)
    # the [G20] models of the performance role at ν = 0.3, and the proposed one at ν = 1/4
    assert {m for m, _ in timed} == {"hybmss", "hybmss-fd", "hybmss-cf"} and ("hybmss", 0.25) in timed
    quarter = df[(df["variant"] == "hybmss") & (df["nu"] == 0.25)]
    assert not quarter["volume_term"].any()  # κ = 0: the volume term is not built
    other = df[(df["variant"] == "hybmss") & (df["nu"] != 0.25)]
    assert other["volume_term"].all()
    assert (df["bytes_per_step"] > 0).all() and np.isfinite(df["fraction_of_bandwidth"]).all()
    s = performance.summary(df)
    base = s[s["variant"] == "hybmss-fd"]
    assert (base["ratio_to_baseline"] == 1.0).all() and (s["baseline"] == "hybmss-fd").all()
    # the publication's ratios ([G20] Sec. 6: cf/fd 1.4, hybmss/fd 2.1) sit beside the ν = 0.3 rows only
    paper = s.dropna(subset=["paper_ratio_to_baseline"])
    assert dict(zip(paper["variant"], paper["paper_ratio_to_baseline"])) == {"hybmss": 2.1, "hybmss-cf": 1.4}
    assert (paper["nu"] == 0.3).all()


def test_timed_steps_cap_the_largest_grids_only():
    """The publication's meshes below the node-step cap keep their steps; above it a run is cut
    to whole hundreds within the cap (never below 100 steps, never more than asked)."""
    for mesh in performance.CUBES + performance.BEAMS:
        nodes = int(np.prod([n + 1 for n in mesh]))
        n = performance.timed_steps(mesh, 1000)
        if 1000 * nodes <= performance.MAX_NODE_STEPS:
            assert n == 1000, mesh
        else:
            assert 100 <= n < 1000 and n % 100 == 0 and n * nodes <= performance.MAX_NODE_STEPS, mesh
    assert performance.timed_steps((30, 30, 30), 1000) == 300
    assert performance.timed_steps((200, 200, 200), 1000) == 100  # the floor
    assert performance.timed_steps((2, 2, 12), 20) == 20
