"""newton-vbd's dynamics: at its default 10 iterations a step is implicit Euler's, and the
damping a released cantilever shows is that of its two bending modes beating.

``SolverVBD`` (newton/_src/solvers/vbd) starts each step at the inertial prediction
``y = x + h v`` and runs colour-by-colour block Gauss–Seidel Newton sweeps on
``½ |x − y|²_M / h² + E(x)``; converged, that is backward Euler, ``v' = (x' − x)/h``.  For
``ẍ = −ω² x`` backward Euler multiplies a mode by ``g = 1/(1 + iωh)``: period ``2π h / atan(ωh)``,
damping ratio ``ζ = δ/√(4π² + δ²)``, ``δ = −ln|g| · T/h``.

- Started in its first mode (the linearized stiffness of its own forces by central differences,
  float32: step 1e-3 of the cell edge, symmetric to 4e-5; the nodes' lumped masses) the measured
  period and ζ are backward Euler's at ``ω₁h``: the period to 1e-3 (measured 1e-4: the start holds
  ~1e-3 of other modes), ζ to 3 % (measured 1 % from 5 to 100 iterations; 1 iteration: ζ 0.0097,
  period 22 % long, not converged).
- Released from its linear static state under gravity along y, the tip's y motion is the sum of
  the modes with backward Euler's factor each; the two bending modes (ω 14.13 and 14.74 rad/s on
  the 1×1×6 body: the 5-tetrahedra split's bending axes are not x and y) share it about equally
  and beat, so the log decrement of y reads ζ ≈ 2.5 × mode 1's.  The measured ζ equals that of
  the modal superposition to 3 %.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg as sla

pytest.importorskip("newton")
pytest.importorskip("warp")

from hybmss.released import released_scene  # noqa: E402
from hybmss.scene import Body, Material, Plate, Scene  # noqa: E402
from hybmss.system import build  # noqa: E402
from studies.sweep.dynamics import oscillation  # noqa: E402

H = 1.0 / 600.0
"""The step (s): a tenth of a 1/60 s frame (ω₁h = 0.024 on the 1×1×6 body, 0.08 on the 1×1×3)."""


def setup(nz: int = 3):
    sc = Scene(Body.box(1, 1, nz, 0.1), Material(1e6, 0.3, 1000.0), plates=(Plate("base", "z-"),),
               gravity=(0.0, -10.0, 0.0), model="newton-vbd")
    S = build(released_scene(sc))
    spec = sc.model.spec
    body = spec.make_body(S, H, 0.0, damping=0.0)
    X = body.nodes.X
    free = np.flatnonzero(~body.nodes.fixed.ravel())
    eps = 1e-4
    K = np.zeros((X.size, X.size))
    for j in free:
        d = np.zeros(X.size)
        d[j] = eps
        K[:, j] = -(body.internal_forces(X + d.reshape(-1, 3)) - body.internal_forces(X - d.reshape(-1, 3))).ravel()
    K = K[np.ix_(free, free)] / (2 * eps)
    m = np.repeat(body.nodes.mass, 3)[free]
    w2, V = sla.eigh(0.5 * (K + K.T), np.diag(m))
    tip = int(np.argmax(X[:, 2]))
    return sc, S, spec, X, free, K, m, np.sqrt(np.maximum(w2, 0.0)), V, tip


def backward_euler(w: float, h: float) -> tuple[float, float]:
    z = w * h
    T = 2 * math.pi * h / math.atan(z)
    delta = 0.5 * math.log1p(z * z) * T / h
    return T, delta / math.sqrt(4 * math.pi**2 + delta**2)


def march(spec, S, x0, h, steps, tip, axis):
    """The tip's ``axis`` displacement from ``x0`` at rest, the model's own iterations (10)."""
    body = spec.make_body(S, h, 0.0, damping=0.0)
    assert body.describe()["iterations"] == 10
    body.load(x0, np.zeros_like(x0))
    X = body.nodes.X
    out = [x0[tip, axis] - X[tip, axis]]
    for k in range(steps):
        body.advance(k, 1, 1, math.inf)
        out.append(body.state()[0][tip, axis] - X[tip, axis])
    return h * np.arange(steps + 1), np.array(out)


def test_first_mode_is_stepped_by_backward_euler():
    sc, S, spec, X, free, K, m, w, V, tip = setup()
    phi = np.zeros(X.size)
    phi[free] = V[:, 0]
    phi = phi.reshape(-1, 3)
    axis = int(np.argmax(np.abs(phi[tip])))
    T, zeta = backward_euler(w[0], H)
    t, x = march(spec, S, X + 1e-3 * phi / np.abs(phi[tip]).max(), H, int(6 * T / H), tip, axis)
    o = oscillation(t, x)
    assert o.period == pytest.approx(T, rel=1e-3)
    assert o.zeta == pytest.approx(zeta, rel=0.03)


def test_released_damping_is_the_bending_modes_beating():
    sc, S, spec, X, free, K, m, w, V, tip = setup(6)
    g = np.zeros(X.size)
    g[1::3] = -10.0
    u = np.zeros(X.size)
    u[free] = np.linalg.solve(0.5 * (K + K.T), m * g[free])
    row = int(np.searchsorted(free, 3 * tip + 1))
    share = (V.T @ (m * u[free])) * V[row]  # each mode's part of the tip's y at the release
    t_end = 6 * 2 * math.pi / w[0]
    steps = int(t_end / H)
    pred = np.zeros(steps + 1)
    for wi, a in zip(w, share):
        A = np.linalg.inv(np.array([[1.0, -H], [wi * wi * H, 1.0]]))  # backward Euler's step
        ev, EV = np.linalg.eig(A)
        c = np.linalg.solve(EV, np.array([1.0, 0.0]))
        pred += a * np.real((EV[0] * c)[None, :] * ev[None, :] ** np.arange(steps + 1)[:, None]).sum(axis=1)
    t, y = march(spec, S, X + u.reshape(-1, 3), H, steps, tip, 1)
    o, op = oscillation(t, y), oscillation(t, pred)
    zeta1 = backward_euler(w[0], H)[1]
    assert abs(share[1]) > 0.2 * abs(share[0])  # the second bending mode carries part of y
    assert op.zeta > 1.5 * zeta1  # the beating reads as damping beyond mode 1's
    assert o.zeta == pytest.approx(op.zeta, rel=0.03)
    assert o.period == pytest.approx(op.period, rel=1e-3)
