"""MuJoCo's state read honestly: the volume and the inverted count of its tetrahedra, and the
state checks after which MuJoCo resets a run.

- Orientation: the tetrahedra of the readouts have a positive signed volume at rest, so a body
  under a homogeneous deformation ``x = F X`` reports the exact volume ``det F · V0`` (linear
  tetrahedra are exact under it) and no inverted tetrahedron; a static answer (stretch 1e-3 of a
  2×2×2 cube) reports none and a volume within the strain of the body's.
- Instability: a step far above the stability limit makes MuJoCo find a huge acceleration and
  reset its state; the run fails (:class:`hybmss.explicit.DivergenceError`, exit 3) at that
  step, naming MuJoCo's check and the remedy, and MuJoCo writes nothing to stderr nor a
  ``MUJOCO_LOG.TXT`` in the working directory.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")

from hybmss import Body, Material, Model, Motion, Plate, Region, Scene  # noqa: E402
from hybmss.solve import solve_static  # noqa: E402
from hybmss.system import build  # noqa: E402

KINDS = ("mujoco-tet", "mujoco-trilinear", "mujoco-quadratic")


def cube(name: str, n: int = 2, E: float = 1e4, lift: float = 1e-3) -> Scene:
    le = 1.0 / n
    return Scene(body=Body.box(n, n, n, le=le), material=Material(E=E, nu=0.3, rho=1000.0), model=Model(name),
                 plates=(Plate("bottom", Region("z-")), Plate("top", Region("z+"), Motion("translate", (0, 0, lift)))))


@pytest.mark.parametrize("name", KINDS)
def test_homogeneous_deformation_exact_volume(name):
    """x = F X (stretch, shear, det F = 1.0612): the engine's tetrahedra report det F · V0 to
    round-off, none inverted; their volume at rest is the body's, 1 m³."""
    from hybmss.models._engine_body import tet_volumes
    from hybmss.models.mujoco.engine import MujocoBody

    S = build(cube(name))
    body = MujocoBody(S, name.split("-")[1], 1e-3, 1.0)
    F = np.array([[1.02, 0.05, 0.0], [0.0, 0.97, 0.01], [0.03, 0.0, 1.07]])
    vol = tet_volumes(body.vertices(body.nodes.X @ F.T), body.tets)
    assert tet_volumes(S.X, body.tets).sum() == pytest.approx(1.0, rel=1e-12)
    assert vol.sum() == pytest.approx(np.linalg.det(F), rel=1e-12)
    assert np.all(vol > 0)


def test_static_answer_positive_volume():
    """mujoco-tet's static answer (top lifted by 1e-3 of the height): 0 inverted tetrahedra and a
    volume within 2 × 1e-3 of the body's 1 m³ (a stretch of 1e-3 changes it by less)."""
    r = solve_static(cube("mujoco-tet"))
    assert r.info["inverted_tets"] == 0
    assert r.volume0 == pytest.approx(1.0, rel=1e-12)
    assert abs(r.volume - 1.0) < 2e-3


def test_reset_is_a_failure(tmp_path, monkeypatch, capfd):
    """A step 160× the stability limit (E = 1e9 Pa, h = 0.05 s): MuJoCo finds a huge acceleration
    at its second step and resets; the run fails there (not 'moved' nor at rest later), names
    mjWARN_BADQACC and a shorter step; no stderr line, no MUJOCO_LOG.TXT."""
    from hybmss.explicit import DivergenceError, simulate_explicit

    monkeypatch.chdir(tmp_path)
    sc = cube("mujoco-tet", E=1e9, lift=0.1)
    with pytest.raises(DivergenceError, match="mjWARN_BADQACC") as e:
        simulate_explicit(sc, dt=0.05, steps=200, ramp_time=0.1, kernel="engine")
    assert e.value.step <= 3 and "reset" in str(e.value) and "use a step below it" in str(e.value)
    assert e.value.dt_crit < 0.05 / 100
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
    assert capfd.readouterr().err == ""


def test_reset_seen_by_the_stepper(tmp_path, monkeypatch):
    """Stepped directly (no divergence check of the loop's), the reset still fails: after it
    MuJoCo's state is back at rest and would pass the loop's displacement bound."""
    from hybmss.explicit import DivergenceError
    from hybmss.models.mujoco.engine import MujocoBody

    monkeypatch.chdir(tmp_path)
    body = MujocoBody(build(cube("mujoco-tet", E=1e9, lift=0.1)), "tet", 0.05, 0.1)
    body.load(body.nodes.X, np.zeros_like(body.nodes.X))
    with pytest.raises(DivergenceError, match="reset its state"):
        body.advance(0, 20, 20)
    assert any("QACC" in w for w in body.warnings)
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
