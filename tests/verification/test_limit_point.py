"""The static solver's location of a lost equilibrium (a limit point of a κ < 0 beam in tension).

The bracket it reports is checked against evaluations that do not use the bracketing: the
equilibrium at its lower end exists and is stable (a dense eigen solve of its Hessian), the plain
load-step halving (``limit_resolution=None``) finds no equilibrium at its upper end, and the
bracket of that plain halving lies within this one (to the stated resolution)."""

import numpy as np
import pytest

from hybmss.experiments import SceneSpec
from hybmss.forces import stiffness
from hybmss.solve import StaticOptions, StaticSolveError, solve_static
from hybmss.system import build

D = 0.2
MESH = (2, 2, 12)
PLAIN = StaticOptions(limit_resolution=None)


def _scene(deformation, model="hybmss", nu=0.0, mesh=MESH):
    return SceneSpec.default("tension", mesh=mesh, nu=nu, deformation=deformation, model=model).build()


def _failure(scene, options=None):
    with pytest.raises(StaticSolveError) as err:
        solve_static(scene, options)
    e = err.value
    assert e.cause == "limit-point" and "kappa" in str(e) and "limit point" in str(e)
    return {"s_last": e.load_factor, "s_fail": e.next_load_factor, "lambda_min": e.smallest_eigenvalue,
            "lambda_min_next": e.next_smallest_eigenvalue}


def _lambda_min(scene, r):
    S = build(scene)
    free = ~S.fixed.ravel()
    H = stiffness(S, r.X + r.u)[free][:, free].toarray()
    return float(np.linalg.eigvalsh(H)[0])


@pytest.mark.slow
def test_lost_equilibrium_is_bracketed_to_the_stated_resolution():
    p = _failure(_scene(D))
    s_lo, s_hi = p["s_last"], p["s_fail"]
    # the first step (the whole load) pointed at the limit point: 1 % of it
    assert 0.5 < s_lo < s_hi <= 1.0
    assert s_hi - s_lo <= 0.01 * 1.0

    # lower end: a stable equilibrium (smallest eigenvalue of the dense Hessian > 0), whose
    # smallest eigenvalue is the one the error reports (the scene moved by D s_lo at full load)
    lower = _scene(D * s_lo)
    r = solve_static(lower, PLAIN)
    lam = _lambda_min(lower, r)
    assert r.converged and lam > 0.0
    assert p["lambda_min"] == pytest.approx(lam, rel=1e-4)
    # upper end: the plain halving finds no equilibrium there either
    q = _failure(_scene(D * s_hi), PLAIN)
    assert q["s_last"] < 1.0

    # the plain halving's own (finer) bracket lies within this one
    old = _failure(_scene(D), PLAIN)
    assert s_lo - 1e-6 <= old["s_last"] < old["s_fail"] <= s_hi + 1e-6


def test_a_bifurcation_passed_on_the_path_is_not_reported_as_lost():
    """hybmss-fd at ν = 0.2 in 5 % tension: predicted states turn indefinite (its soft modes), so
    the bracketing starts, but an equilibrium exists at every load; the result is the plain
    halving's equilibrium."""
    sc = _scene(0.05, model="hybmss-fd", nu=0.2, mesh=(4, 4, 24))
    r = solve_static(sc)
    ref = solve_static(sc, PLAIN)
    assert r.converged and r.info["load_steps"] > ref.info["load_steps"]  # the bracketing ran
    assert np.abs(r.u - ref.u).max() <= 1e-6 * np.abs(ref.u).max()


def test_a_newton_failure_on_a_definite_hessian_inside_a_bracket_steps_on():
    """hybmss-fd at ν = −0.5 (κ < 0, squared volume energy) stretched 100 %: the predictor from
    rest suspects a fold at every load of the first step, and Newton fails at the narrowed
    bracket's upper end (1/128) although the Hessian is positive definite at both of its ends: no
    evidence of a fold.  The load then steps on from the last equilibrium, to the real limit
    point: the dense Hessian at the lower end is positive definite, and the plain halving (no
    bracketing) brackets the same point, more coarsely."""
    sc = SceneSpec.default("tension", mesh=(4, 4, 24), nu=-0.5, deformation=1.0, model="hybmss-fd",
                           volume_energy="squared").build()
    p = _failure(sc)
    s_lo, s_hi = p["s_last"], p["s_fail"]
    assert s_lo > 1.0 / 128 and p["lambda_min"] > 0.0 > p["lambda_min_next"]
    assert s_hi - s_lo <= 0.01 * 1.0 / 128
    lower = SceneSpec.default("tension", mesh=(4, 4, 24), nu=-0.5, deformation=1.0 * s_lo, model="hybmss-fd",
                              volume_energy="squared").build()
    r = solve_static(lower, PLAIN)
    assert r.converged and _lambda_min(lower, r) > 0.0
    old = _failure(sc, PLAIN)  # the plain halving's coarser bracket holds this one
    assert old["s_last"] - 1e-9 <= s_lo < s_hi <= old["s_fail"] + 1e-9
