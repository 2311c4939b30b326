"""The engines on a body's own tetrahedra: a :class:`hybmss.tetbody.TetBody` (the conforming
tetrahedra of a user's surface) stepped by an engine on exactly those tetrahedra, instead of
voxels split into tetrahedra the engine's way.

A support is a :class:`TetHold`: a predicate on the nodes' reference positions and a
:class:`hybmss.scene.Motion` that prescribes all three components of the nodes it selects,
``x = X + u(X, s)`` at load factor ``s`` (the ramp of :func:`hybmss.explicit.ramp`).  The
masses are lumped, ``ρ V_t / 4`` of each tetrahedron on each of its vertices.

The static answer (:func:`rest_on_tets`) is the rest state of the engine's damped run, as for
the voxel bodies (:meth:`hybmss.models._engine_model.EngineModel.solve_static`): step
``cfl · 2/ω_max`` (ω_max of the engine's own forces), mass-proportional damping ``c = 2 ω₁`` and
a ramp ``T = 2π/ω₁``, ω₁ the lowest frequency of the free nodes of linear elasticity on the same
tetrahedra (P1, the lumped masses),

    K_ab = Σ_t V_t [λ ∇N_a ⊗ ∇N_b + μ ∇N_b ⊗ ∇N_a + μ (∇N_a · ∇N_b) I],    K φ = ω₁² M φ,

the small-strain limit every engine's law is mapped to.  A state is at rest when the free
nodes' force ``‖f_free‖`` is within ``rtol`` of the held nodes' ``‖f_held‖`` (or within a float32
engine's force resolution, or for an engine that ``settles``, only ``settle``/ω₁ after the
ramp); the run stops at ``T + 60/ω₁`` otherwise and says so (``converged`` False).  A support's
reaction is ``−Σ f`` of the engine's own forces on its nodes, its torque about their centroid
(:func:`hybmss.result.reaction_from_nodal`, reference positions).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sp

from ..result import Reaction, reaction_from_nodal
from ._engine_body import Nodes


@dataclass(frozen=True)
class TetHold:
    """A support of a tetrahedral body: every component of the nodes with ``where(X)`` (X (n, 3)
    -> bool (n,)) follows ``motion`` (:class:`hybmss.scene.Motion`; a rotation without a centre
    turns about the selected nodes' centroid)."""

    name: str
    where: Callable[[np.ndarray], np.ndarray]
    motion: object


def p1_stiffness(X: np.ndarray, tets: np.ndarray, lam: float, mu: float) -> sp.csr_matrix:
    """The linear-elastic P1 stiffness (3n × 3n) of the tetrahedra (module docstring)."""
    p = X[tets]
    D = np.stack((p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]), axis=-1)
    V = np.abs(np.linalg.det(D)) / 6.0
    g = np.linalg.inv(D)  # rows: gradients of the barycentric coordinates 1..3
    grad = np.concatenate((-g.sum(axis=1, keepdims=True), g), axis=1)  # (m, 4, 3)
    dot = np.einsum("tai,tbi->tab", grad, grad)
    Ke = (lam * np.einsum("tai,tbj->taibj", grad, grad) + mu * np.einsum("tbi,taj->taibj", grad, grad)
          + mu * np.einsum("tab,ij->taibj", dot, np.eye(3))) * V[:, None, None, None, None]
    dof = (3 * tets[:, :, None] + np.arange(3)).reshape(len(tets), 12)
    rows = np.repeat(dof, 12, axis=1).ravel()
    cols = np.tile(dof, (1, 12)).ravel()
    n = 3 * len(X)
    return sp.csr_matrix((Ke.reshape(len(tets), 144).ravel(), (rows, cols)), shape=(n, n))


def lowest_frequency(nodes: Nodes, tets: np.ndarray, material) -> float:
    """ω₁ (rad/s) of the P1 stiffness with the lumped masses on the free components."""
    from scipy.sparse.linalg import eigsh

    K = p1_stiffness(nodes.X, tets, material.lam, material.G)
    free = np.flatnonzero(~nodes.fixed.ravel())
    Kf = K[free][:, free]
    Mf = sp.diags(np.repeat(nodes.mass, 3)[free])
    w2 = eigsh(Kf, k=1, M=Mf, sigma=0.0, which="LM", return_eigenvectors=False)[0]
    return math.sqrt(max(float(w2), 0.0))


@dataclass(frozen=True, eq=False)
class TetRest:
    """The rest state of an engine on a tetrahedral body: node reference positions ``X`` and
    displacements ``u`` (n, 3), the engine's own elastic forces ``f`` on them (n, 3), each hold's :class:`~hybmss.result.Reaction`, whether the run
    came to rest, its equilibrium error ``‖f_free‖/‖f_held‖``, the steps, the times and what
    the engine says of itself."""

    X: np.ndarray
    u: np.ndarray
    f: np.ndarray
    reactions: dict[str, Reaction]
    converged: bool
    equilibrium_error: float
    steps: int
    dt: float
    wall_time_s: float
    info: dict


def rest_on_tets(model, body, material, holds, *, settle: float, rtol: float | None = None) -> TetRest:
    """The rest state of ``model``'s engine (an :class:`~hybmss.models._engine_model.EngineModel`
    with :meth:`make_tet_body`) on the tetrahedra of ``body`` under ``holds`` (module docstring);
    ``settle``: :data:`hybmss.models._engine_model.SETTLE` (:class:`hybmss.explicit.Settling`)."""
    from ..explicit import Settling

    t_start = time.perf_counter()
    rtol = model.static_rest_rtol if rtol is None else float(rtol)
    probe = model.make_tet_body(body, material, holds, 1.0, 1.0, damping=0.0)
    wmax = probe.omega_max()
    w1 = lowest_frequency(probe.nodes, np.asarray(body.tets), material)
    if not (w1 > 0 and wmax > 0):
        raise ValueError("the tetrahedral body has a zero-energy mode (not held by its supports)")
    dt = model.cfl * 2.0 / wmax
    T = 2.0 * math.pi / w1
    eng = model.make_tet_body(body, material, holds, dt, T, damping=2.0 * w1)
    eng.compile_time_s += probe.compile_time_s
    eng.for_rest()
    X = eng.nodes.X
    eng.load(X, np.zeros_like(X))
    held = eng.nodes.fixed.all(axis=1)
    check = max(1, int(round(1.0 / (w1 * dt))))
    n_max = int(math.ceil((T + 60.0 / w1) / dt))
    settling = Settling(X, T, w1, settle, rtol)
    wait = eng.resolution_N > 0.0 or model.settles
    step, at_rest, err = 0, False, math.inf
    while step < n_max and not at_rest:
        done, bad = eng.advance(step, min(check, n_max - step), check)
        step += done
        if bad >= 0:
            raise FloatingPointError(f"{model.name} diverged at node {bad} (step {step}, dt {dt:.3g} s)")
        t = step * dt
        if t < T:
            continue
        x, _ = eng.state()
        f = eng.internal_forces(x)
        scale = float(np.linalg.norm(f[held]))
        res = float(np.linalg.norm(f[~held]))
        err = res / scale if scale > 0 else math.inf
        settled = settling.update(t, x) if wait else True
        at_rest = res <= max(rtol * scale, eng.resolution_N) and settled
    x, _ = eng.state()
    f = eng.internal_forces(x)
    reactions = {ps.name: reaction_from_nodal(X[ps.particles], -f[ps.particles]) for ps in eng.nodes.plates}
    info = {**eng.describe(), "omega_1": w1, "omega_max": wmax, "ramp_time": T, "damping": 2.0 * w1,
            "resolution_N": eng.resolution_N, "compile_time_s": eng.compile_time_s,
            "step_time_s": eng.step_time_s, "engine_warnings": list(eng.warnings)}
    return TetRest(X.copy(), x - X, f, reactions, bool(at_rest), err, step, dt, time.perf_counter() - t_start, info)
