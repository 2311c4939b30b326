"""The reproduction's released transients (:mod:`studies.paper.dynamics_study`) on a tiny level, its
report section (:mod:`reports.dynamics`) from the stored rows, and a rerun that computes nothing.

Independent figures: a linear mode ``ẍ = −ω² x`` stepped with ``h`` is multiplied per step by the
eigenvalue ``G`` of the scheme's 2×2 step matrix (computed here numerically, not from the module's
formulas): semi-implicit Euler ``[[1, h], [−ω²h, 1 − ω²h²]]`` acting on (x, v) after the velocity
update, backward Euler ``[[1, h], [−ω²h, 1]]⁻¹``.  The period is ``2π h / |arg G|`` and the log
decrement per period ``−ln|G| · 2π / |arg G|``.  hybmss-cf steps by semi-implicit Euler, so its
released period is its own lattice's first mode (:func:`hybmss.modes.lattice_modes`) at that
period and it keeps its amplitude; mujoco-trilinear steps by MuJoCo's ``discrete`` (backward Euler
for a linear mode), so its ζ is backward Euler's at its ω h.
"""

from __future__ import annotations

import html
import math

import numpy as np
import pytest

LEVEL_MODELS = ("hybmss-cf", "mujoco-trilinear")


def _tiny_level():
    from studies.paper.dynamics_study import Level

    return Level({"beam": (1, 1, 6)}, (0.25,), LEVEL_MODELS, periods=3)


def step_eigenvalue(scheme: str, omega: float, h: float) -> complex:
    """The eigenvalue of the larger modulus of one step of ``scheme`` for ``ẍ = −ω² x``."""
    w2 = omega * omega
    if scheme == "symplectic":
        A = np.array([[1.0 - w2 * h * h, h], [-w2 * h, 1.0]])  # v' = v − ω²h x, x' = x + h v'
    else:
        A = np.linalg.inv(np.array([[1.0, -h], [w2 * h, 1.0]]))  # x' = x + h v', v' = v − ω²h x'
    ev = np.linalg.eigvals(A)
    return complex(ev[np.argmax(np.abs(ev) + 1e-15 * np.angle(ev))])


def period_and_zeta(scheme: str, omega: float, h: float) -> tuple[float, float]:
    G = step_eigenvalue(scheme, omega, h)
    arg = abs(math.atan2(G.imag, G.real))
    delta = -math.log(abs(G)) * 2.0 * math.pi / arg
    return 2.0 * math.pi * h / arg, delta / math.sqrt(4.0 * math.pi**2 + delta**2)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    from studies.paper import dynamics_study
    from studies.sweep.runner import Runner
    from studies.sweep.store import Store

    from hybmss import models

    missing = [m for m in LEVEL_MODELS if m not in models.names()]
    if missing:
        pytest.skip(f"models not available: {missing}")
    root = tmp_path_factory.mktemp("dynamics")
    runner = Runner(jobs=1, progress=False)
    tables = dynamics_study.run(Store(root), progress=False, runner=runner, lv=_tiny_level())
    return root, tables, runner


def _row(tables, model):
    df = tables["dynamics"]
    (i,) = np.flatnonzero(df["model"] == model)
    return df.iloc[i]


@pytest.mark.parametrize("scheme", ["symplectic", "backward"])
def test_integrator_prediction_is_the_step_matrix_eigenvalue(scheme):
    from studies.paper.dynamics_study import integrator_prediction

    for z in (0.01, 0.3, 1.2):
        T, zeta = period_and_zeta(scheme, 1.0, z)
        dT, dz = integrator_prediction(scheme, 1.0, z)
        assert dT == pytest.approx(T / (2 * math.pi) - 1.0, rel=1e-9, abs=1e-13)
        assert dz == pytest.approx(zeta, rel=1e-9, abs=1e-13)


def test_symplectic_model_period_is_its_lattice_mode_at_the_step(tiny):
    """hybmss-cf's released period is 2π/ω₁ of its own lattice lengthened... shortened by
    semi-implicit Euler at its step, and its amplitude does not decay."""
    from hybmss.modes import lattice_modes
    from hybmss.released import released_scene
    from studies.paper.dynamics_study import body_scene

    _, tables, _ = tiny
    r = _row(tables, "hybmss-cf")
    assert r["status"] == "ok" and r["family"] == "symplectic"
    scene = released_scene(body_scene("beam", (1, 1, 6), 0.25, "hybmss-cf"))
    omega1 = 2.0 * math.pi * float(lattice_modes(scene, 2).freq[0])
    T_h, zeta = period_and_zeta("symplectic", omega1, float(r["dt_s"]))
    assert zeta == 0.0 or abs(zeta) < 1e-12
    assert r["period_s"] == pytest.approx(T_h, rel=2e-3)
    assert abs(r["zeta"]) < 2e-3
    # the error against the FEM is measured against the FEM's own period
    assert r["period_error_pct"] == pytest.approx(100.0 * (r["period_s"] / r["period_ref_s"] - 1.0), rel=1e-9)


def test_backward_euler_engine_damps_as_its_amplification_factor(tiny):
    """mujoco-trilinear (MuJoCo's discrete: backward Euler for a linear mode) decays by
    |1/(1 + iωh)| per step at its own measured ω."""
    _, tables, _ = tiny
    r = _row(tables, "mujoco-trilinear")
    assert r["status"] == "ok" and r["family"] == "backward"
    assert r["substeps"] >= 1 and r["dt_s"] == pytest.approx(1.0 / 60.0 / r["substeps"])
    omega = 2.0 * math.pi / float(r["period_s"])
    _, zeta = period_and_zeta("backward", omega, float(r["dt_s"]))
    assert zeta > 1e-3
    assert r["zeta"] == pytest.approx(zeta, rel=0.15)


def test_fem_reference_within_its_own_tolerance(tiny):
    from studies.paper.dynamics_study import FEM_PERIOD_TOL

    _, tables, _ = tiny
    df = tables["dynamics"]
    assert (df["fem_period_error_pct"] <= 100.0 * FEM_PERIOD_TOL).all()
    assert set(df["model"]) == set(LEVEL_MODELS)


def test_rerun_computes_nothing(tiny):
    from studies.paper import dynamics_study
    from studies.sweep.runner import Runner
    from studies.sweep.store import Store

    root, tables, first = tiny
    assert first.summary.computed == 1 + len(LEVEL_MODELS)
    again = Runner(jobs=1, progress=False)
    out = dynamics_study.run(Store(root), progress=False, runner=again, lv=_tiny_level())
    assert again.summary.computed == 0 and again.summary.stored == 1 + len(LEVEL_MODELS)
    cols = ["model", "period_s", "zeta", "l2_error", "wall_per_simulated_s"]
    assert out["dynamics"][cols].equals(tables["dynamics"][cols])


def test_report_section_renders_from_stored_rows(tiny, tmp_path):
    from reports import dynamics
    from reports.data import Results

    root, tables, _ = tiny
    title, intro, items = dynamics.section(Results(str(root)), tmp_path / "fig")
    figs = [i for k, i in items if k == "figure"]
    tabs = [i for k, i in items if k == "table"]
    assert [f.id for f in figs] == ["dynamics_trajectories", "dynamics_cost"]
    assert all(f.path.stat().st_size > 1000 for f in figs)
    (tab,) = tabs
    assert tab.id == "table_dynamics_beam" and len(tab.rows) == len(LEVEL_MODELS)
    be = _row(tables, "mujoco-trilinear")
    assert "Backward Euler (mujoco-trilinear" in intro
    assert f"ζ {be['zeta']:.3g} against the {be['integrator_zeta']:.3g}" in intro
    se = _row(tables, "hybmss-cf")
    assert "Semi-implicit (symplectic) Euler (hybmss-cf" in intro
    assert (f"shortens the period by {-se['integrator_period_pct']:.2g} % of the measured "
            f"{se['period_error_pct']:+.3g} %") in intro
    df = tables["dynamics"]
    closest = df.loc[df["period_error_pct"].abs().idxmin()]
    assert f"the closest first period is {closest['model']}'s" in html.unescape(intro)
