"""Forces are the exact negative gradient of the energy and the Hessian its exact derivative
(central finite differences); rigid motions cost nothing; internal forces are self-equilibrated."""

import numpy as np
import pytest

from hybmss import models
from hybmss.forces import energy_forces, hessian, internal_forces
from hybmss.scene import Body, Material, Model, Scene, rotation_matrix
from hybmss.system import build

CONSERVATIVE = [Model(m.name) for m in models.all_models() if m.conservative]
"""Every registered model whose forces derive from an energy, with its defaults."""
VARIANTS = CONSERVATIVE + [Model("hybmss", A=3.0), Model("hybmss", volume_energy="squared")]


def _id(m):
    return "-".join(str(v) for v in m.to_dict().values())


def _system(model, nu, gravity=(0.0, 0.0, 0.0)):
    return build(Scene(Body.box(3, 3, 3, 0.5), Material(1e4, nu), model, gravity=gravity))


def _perturbed(S, seed, scale=0.06):
    rng = np.random.default_rng(seed)
    return S.X + rng.uniform(-scale, scale, size=S.X.shape)


@pytest.mark.parametrize("model", VARIANTS, ids=_id)
@pytest.mark.parametrize("nu", [-0.5, 0.0, 0.3, 0.499])
def test_force_and_hessian_match_finite_differences(model, nu):
    S = _system(model, nu, gravity=(0.0, 0.0, -10.0))
    x = _perturbed(S, seed=int(100 * (nu + 1)))
    e, f, _ = energy_forces(S, x)
    H = hessian(S, x).toarray()
    h = 1e-6 * 0.5
    n = x.size
    grad = np.empty(n)
    Hfd = np.empty((n, n))
    for i in range(n):
        xp = x.ravel().copy()
        xm = xp.copy()
        xp[i] += h
        xm[i] -= h
        ep, fp, _ = energy_forces(S, xp.reshape(-1, 3))
        em, fm, _ = energy_forces(S, xm.reshape(-1, 3))
        grad[i] = (ep - em) / (2 * h)
        Hfd[:, i] = -(fp - fm).ravel() / (2 * h)
    assert np.linalg.norm(grad + f.ravel()) <= 1e-6 * np.linalg.norm(f)
    assert np.linalg.norm(Hfd - H) <= 1e-6 * np.linalg.norm(H)
    np.testing.assert_allclose(H, H.T, atol=1e-9 * np.abs(H).max())


@pytest.mark.parametrize("model", CONSERVATIVE, ids=lambda m: m.name)
@pytest.mark.parametrize("angle", [30.0, 90.0, 180.0])
def test_rigid_motion_has_zero_energy_and_force(model, angle):
    S = _system(model, 0.45)
    R = rotation_matrix((1.0, 2.0, 0.5), np.radians(angle))
    x = S.X @ R.T + np.array([0.3, -1.2, 2.0])
    e, f, parts = energy_forces(S, x)
    k_max = S.spring_k.max()
    assert abs(e) <= 1e-20 * k_max + 1e-18
    assert np.abs(f).max() <= 1e-10 * k_max * 0.5
    assert all(abs(v) <= 1e-18 for v in parts.values())


@pytest.mark.parametrize("model", CONSERVATIVE, ids=lambda m: m.name)
def test_internal_forces_have_zero_resultant_and_moment(model):
    S = _system(model, 0.1)
    x = _perturbed(S, seed=7, scale=0.1)
    f = internal_forces(S, x)
    scale = np.abs(f).max()
    assert np.abs(f.sum(axis=0)).max() <= 1e-12 * scale * len(x)
    assert np.abs(np.cross(x, f).sum(axis=0)).max() <= 1e-12 * scale * len(x) * np.abs(x).max()


def test_only_needed_terms_are_built():
    mat = Material(1e4, 0.25)
    body = Body.box(2, 2, 2, 0.5)
    S = build(Scene(body, mat, Model("hybmss")))
    assert not S.has_volume  # kappa = 0 at nu = 1/4
    assert S.gravity is None
    S = build(Scene(body, Material(1e4, 0.3), Model("hybmss-fd")))
    assert S.has_volume and 1 not in set(S.spring_family)  # no face diagonals at A = 0
    S = build(Scene(body, Material(1e4, 0.3), Model("hybmss-cf"), gravity=(0, 0, -10)))
    assert not S.has_volume and S.gravity is not None
