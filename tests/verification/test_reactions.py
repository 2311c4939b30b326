"""Plate reactions (force and torque) of every solver kind and model family against closed forms:
the weight ρ g V a clamp carries at rest, the balance of forces and moments of all plates and the
body load, and the small-angle torque of the corotational model against the FEM on the same mesh."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fem_reference.solve import solve as fem_solve
from hybmss.explicit import dt_crit, simulate_explicit
from hybmss.scene import Body, Material, Model, Motion, Plate, Region, Scene
from hybmss.solve import ImplicitOptions, simulate_implicit, solve_static

RHO, G = 1000.0, np.array([0.0, -3.0, -10.0])
N, LE = 2, 0.1


def _hanging(model: str, **params) -> Scene:
    """A 2×2×2 cube of 0.1 m cells clamped at z = 0 under a slanted gravity."""
    return Scene(Body.box(N, N, N, LE), Material(1e6, 0.3, RHO), Model(model, **params),
                 plates=(Plate("clamp", Region("z-")),), gravity=tuple(G))


def _weight_fractions() -> tuple[float, float]:
    """Closed-form lumped masses (ρ V_c / 8 per cell corner) of the clamped layer and of the rest
    of an n×n×n cube: the bottom nodes carry half of the bottom cell layer, 1/(2n) of the body."""
    M = RHO * (N * LE) ** 3
    return M / (2 * N), M - M / (2 * N)


def _expected_reaction(r) -> np.ndarray:
    """The clamp's force at rest, −(weight of everything): ``−M g``.  An XPBD run's rest state
    feels the free particles' weight through its substep damping c_h, ``g/(1 + c_h h)``
    (hybmss.models.xpbd_nh; the static answer's substep is undamped, c_h = 0), while the clamped
    particles' own weight rests on the clamp whole."""
    m_plate, m_free = _weight_fractions()
    return -(m_plate + _d_h(r) * m_free) * G


def _d_h(r) -> float:
    """The damping factor ``1/(1 + c_h h)`` of an XPBD substep (1 for the other models)."""
    if "h" not in r.info:
        return 1.0
    return 1.0 / (1.0 + r.info.get("damping_h", r.info["damping"]) * r.info["h"])


def _run(kind: str, model: str, **params):
    scene = _hanging(model, **params)
    if kind == "static":
        return solve_static(scene)
    # explicit: heavily damped (c = 200/s, the slowest mode's ω is ~200/s), no ramp, to rest
    return simulate_explicit(dataclasses.replace(scene, damping=200.0), dt=0.5 * dt_crit(scene), steps=2000,
                             ramp_time=0.0)


@pytest.mark.parametrize("kind", ["static", "explicit"])
@pytest.mark.parametrize("model", ["corot-hex8", "corot-hex8-sri", "xpbd-nh", "hybmss", "baudet2009"])
def test_the_clamp_carries_the_whole_weight_at_rest(model, kind):
    """Σ of the clamp's reaction = ρ g V (the clamped particles' own weight included: without it the
    reaction is short by a quarter here), and its torque about the clamp's centroid c balances the
    moment of the weight, −Σ m (x − c) × g over the deformed positions."""
    r = _run(kind, model)
    R = r.reactions["clamp"]
    W = np.linalg.norm(RHO * (N * LE) ** 3 * G)
    tol = 1e-3 if model == "xpbd-nh" else 1e-7  # XPBD: O((h ω)²) substep bias beyond the damping factor
    np.testing.assert_allclose(R.force, _expected_reaction(r), rtol=0, atol=tol * W)
    # the moment about c of the weight (XPBD: the free particles' weight seen through 1/(1 + c h))
    m = _lumped_masses(r.X)
    assert m.sum() == pytest.approx(sum(_weight_fractions()), rel=1e-12)
    on_clamp = np.isclose(r.X[:, 2], 0.0)
    m = np.where(on_clamp, m, m * _d_h(r))
    c = np.asarray(R.center)
    np.testing.assert_allclose(c[:2], [N * LE / 2, N * LE / 2], rtol=0, atol=1e-12)
    T = -np.cross(r.x - c, m[:, None] * G[None, :]).sum(axis=0)
    # corotational element forces carry a moment of second order in the strain (~2e-3 here):
    # Σ u_c × (K_e u)_c of each cell, measured 3e-6 of W·H
    ttol = 1e-5 if model.startswith("corot") else tol
    np.testing.assert_allclose(R.torque, T, rtol=0, atol=ttol * W * N * LE)


def _lumped_masses(X: np.ndarray) -> np.ndarray:
    """ρ V_c / 8 per cell corner on a full box: ρ le³ times ½ per axis on which the node is on a face."""
    g = np.rint(X / LE)
    return RHO * LE**3 * np.prod(np.where((g == 0) | (g == N), 0.5, 1.0), axis=1)
