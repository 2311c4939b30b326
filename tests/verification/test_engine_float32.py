"""A float32 engine's answers (``newton-semi``, Warp's float32 particle state) within what float32
resolves.

- Rest tolerance: the force resolution ``‖K‖₂ · ulp(|X|max)/2 · √(3N)`` bounds the change of the
  engine's own forces under any rounding of the positions (tried: the rounding aligned with K's
  stiffest mode, found from the engine's forces by finite differences, the worst case), and it
  grows with the positions' magnitude (a body 100 m from the origin: ulp × 64).  The 10³ cube at
  ν = 0.499 compressed by 5 % comes to rest within it (slow).
- Moduli: the answer's equilibrium error (:func:`hybmss.moduli.float32_errors`) bounds its
  deviation from the input E, ν, G at strains 1e-4 and 3e-6 (where float32 does not resolve it:
  ``resolved`` false, the smallest resolvable strain above 1e-3) and the command refuses such a
  strain (exit 3) naming the smallest strain; at 3e-3 the answer is resolved and within 1e-3.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("newton")

from hybmss import Body, Material, Model, Motion, Plate, Region, Scene  # noqa: E402
from hybmss.moduli import PRECISION, measure_moduli  # noqa: E402
from hybmss.system import build  # noqa: E402

E, NU = 1e4, 0.45


def cube(n=2, le=0.5, nu=0.3, origin=(0.0, 0.0, 0.0), dz=1e-4) -> Scene:
    return Scene(Body.box(n, n, n, le, origin=origin), Material(E, nu, 1000.0), Model("newton-semi"),
                 (Plate("bottom", Region("z-")), Plate("top", Region("z+"), Motion("translate", (0, 0, dz)))))


def body_of(scene):
    from hybmss.models.newton.engine import NewtonBody

    return NewtonBody(build(scene), "semi", 1e-4, 1.0)


def test_resolution_bounds_the_worst_rounding():
    """The rounding δx = ±ulp/2 with the signs of one of K's three stiffest modes (K by central differences of
    the engine's forces, in float64 of the float32 forces) changes the free forces by less than
    the resolution, and by more than a quarter of it (measured: 0.44; the bound is not loose)."""
    b = body_of(cube())
    X = b.nodes.X
    n = X.size
    h = 1e-3 * b.system.scene.body.le
    K = np.empty((n, n))
    for j in range(n):
        d = np.zeros(n)
        d[j] = h
        K[:, j] = -(b.internal_forces(X + d.reshape(-1, 3)) - b.internal_forces(X - d.reshape(-1, 3))).ravel() / (2 * h)
    w, V = np.linalg.eigh(0.5 * (K + K.T))
    ulp = float(np.spacing(np.float32(np.abs(X).max())))
    free = ~b.nodes.fixed
    worst = 0.0
    for k in (-1, -2, -3):  # ±1 ulp (representable at every |x| <= |X|max), halved: forces are linear in δx
        dx = ulp * np.sign(V[:, k]).reshape(-1, 3)
        df = b.internal_forces(X + dx) - b.internal_forces(X)
        worst = max(worst, 0.5 * float(np.linalg.norm(df[free])))
    assert worst <= b.resolution_N
    assert worst >= 0.25 * b.resolution_N
    assert b.stiffness_max() == pytest.approx(w[-1], rel=2e-2)


def test_resolution_grows_with_the_positions_magnitude():
    """The same cube 100 m from the origin: ulp(101)/ulp(1) = 64 times the resolution (the
    stiffness is the same to float32 noise)."""
    near, far = body_of(cube()), body_of(cube(origin=(100.0, 100.0, 100.0)))
    ratio = np.spacing(np.float32(101.0)) / np.spacing(np.float32(1.0))
    assert ratio == 64
    assert far.resolution_N / near.resolution_N == pytest.approx(ratio, rel=0.1)


@pytest.mark.slow
def test_nearly_incompressible_compression_comes_to_rest():
    """The 10³ cube (0.5 m cells) at ν = 0.499 compressed by 5 %: at rest within its float32
    resolution (its residual ~50 N; the top reaction against the linear estimate E_c ε A with
    the constrained modulus of a laterally free block bounded by E ε A from below)."""
    from hybmss.solve import solve_static

    r = solve_static(cube(10, 0.5, 0.499, dz=-0.25))
    rest = r.info["rest"]
    assert r.converged and rest["residual_N"] <= rest["resolution_N"]
    assert -r.reactions["top"].force[2] > E * 0.05 * 25.0


@pytest.mark.parametrize("strain", (1e-4, 3e-6))
def test_unresolved_moduli_are_flagged(strain):
    m = measure_moduli(Model("newton-semi"), Material(E, NU, 1000.0), strain=strain)
    err = m["equilibrium_error"]
    mat = Material(E, NU)
    assert abs(m["E_eff"] / E - 1) <= err["E_eff"]
    assert abs(m["nu_eff"] - NU) <= err["nu_eff"]
    assert abs(m["G_eff"] / mat.G - 1) <= err["G_eff"]
    assert not m["resolved"] and 1e-3 < m["resolvable_strain"] < 1e-2


def test_resolved_moduli_at_3e_3():
    m = measure_moduli(Model("newton-semi"), Material(E, NU, 1000.0), strain=3e-3, judge=True)
    assert m["resolved"] and max(m["equilibrium_error"].values()) <= PRECISION
    assert m["E_eff"] / E - 1 == pytest.approx(0.0, abs=PRECISION)
    assert m["nu_eff"] == pytest.approx(NU, abs=PRECISION)
    assert m["G_eff"] / Material(E, NU).G - 1 == pytest.approx(0.0, abs=PRECISION)


def test_command_refuses_an_unresolved_strain(capsys):
    """Strain 3e-6: exit 3, one line naming the smallest strain; 3e-3: the answer with its
    float32 equilibrium error."""
    from studies.cli.parser import main

    assert main(["moduli", "--model", "newton-semi", "--nu", "0.45", "--strain", "3e-6"]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "float32" in err[0] and "smallest strain it resolves is" in err[0]
    assert main(["moduli", "--model", "newton-semi", "--nu", "0.45", "--strain", "3e-3"]) == 0
    assert "float32 equilibrium error: E_eff +/-" in capsys.readouterr().out
