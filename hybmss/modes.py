"""Natural frequencies and mode shapes of a model's lattice at rest, and mode matching by MAC.

Small vibrations about the rest state ``x = X`` of a model whose static solve is the harness's
Newton (:func:`has_tangent`: it gives its tangent stiffness) obey

    K φ = ω² M φ,        K = ∂(−f)/∂x at x = X,        M = diag(m_i) ⊗ I₃,        f = ω / 2π,

on the free components (those no plate constrains; held ones vibrate with zero amplitude).
``K`` is the model's tangent (:func:`hybmss.forces.stiffness`: springs, volume energy and the
model's force terms; at rest the springs carry no tension, so it has no geometric part), ``m_i``
its lumped particle masses.  Gravity and loads do not enter: the body vibrates unstressed.  A
non-conservative model's tangent need not be symmetric; at rest it is (checked to 1e-9 of its
largest entry) and its symmetric part is used.  The k lowest pairs come from ARPACK in
shift-invert mode with ``σ = −10⁻⁶ E / (ρ L²)`` (L: the body's longest side) just below zero,
so a lattice with zero-energy modes (``hybmss-fd``'s hourglass modes) reports them at f ≈ 0.
Modes are mass-normalised, ``φᵀ M φ = 1``.

Modal assurance criterion of two shapes ``a``, ``b`` sampled on the same nodes (``W`` an optional
weighting, e.g. a mass matrix; ``I`` otherwise):

    MAC(a, b) = (aᵀ W b)² / ((aᵀ W a) (bᵀ W b))   ∈ [0, 1],

1 for parallel shapes, 0 for W-orthogonal ones.  Within a group of modes of equal frequency (a
square section's bending pairs) any rotation of the shapes is a valid basis, so a shape is
matched to the group by its subspace MAC ``‖Qᵀ a‖² / ‖a‖²`` (Q an orthonormal basis of the
group's shapes), which is the MAC for a group of one (:func:`match`).

A product ``aᵀ W b`` of n terms computed in floating point is exact to ``n ε |a|ᵀ |W b|``
(ε the unit round-off; the a-priori bound of a dot product); a product within that bound cannot
be told from zero, and its MAC is reported as 0 (:func:`_zero_to_roundoff`), not as the 1e-30 or
so of digits that depend on the order of the summation (shapes orthogonal by symmetry: a cube's
axial mode against its bending modes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.optimize import linear_sum_assignment

from .forces import stiffness
from .scene import Scene
from .system import System, build

SHIFT = 1e-6
"""σ = −SHIFT · E / (ρ L²): the shift of the shift-invert iteration."""
SYMMETRY_TOL = 1e-9
"""Largest asymmetry of the tangent at rest, relative to its largest entry."""
DEGENERATE_RTOL = 1e-5
"""Reference frequencies closer than this (relative) form one group in :func:`match`."""


@dataclass(frozen=True, eq=False)
class LatticeModes:
    """The lowest natural frequencies (Hz, ascending) of a lattice and its mode shapes
    ``shapes`` (k, n_particles, 3), mass-normalised, zero on the held components."""

    freq: np.ndarray
    shapes: np.ndarray
    model: str


def has_tangent(model) -> bool:
    """Whether ``model`` (a :class:`hybmss.models.ModelBase`) gives a tangent stiffness: its static
    solve is the harness's Newton on :func:`hybmss.forces.stiffness`."""
    return "static" in model.solvers and model.solve_static is None


def shift(scene: Scene) -> float:
    L = max(scene.body.shape) * scene.body.le
    m = scene.material
    return -SHIFT * m.E / (max(m.rho, 1e-300) * L * L)


def lattice_modes(scene: Scene, k: int = 6, system: System | None = None, kernel: str = "numba") -> LatticeModes:
    """The lowest ``k`` natural frequencies and mode shapes of ``scene``'s model (module docstring);
    ``kernel``: the Hessian's (``numba`` or its twin ``numpy``)."""
    model = scene.model.spec
    if not has_tangent(model):
        raise ValueError(f"model {model.name} has no tangent stiffness (its static answer is its own "
                         "solver's); allowed: the models solved by the harness's Newton")
    if scene.material.rho <= 0:
        raise ValueError(f"rho must be > 0 for natural frequencies, got {scene.material.rho:g}")
    S = build(scene) if system is None else system
    K = stiffness(S, S.X, 1.0, kernel).tocsr()
    asym = abs(K - K.T).max() if K.nnz else 0.0
    if asym > SYMMETRY_TOL * abs(K).max():
        raise ValueError(f"model {model.name}: the tangent at rest is not symmetric (asymmetry "
                         f"{asym / abs(K).max():.3g} of its largest entry)")
    free = ~S.fixed.ravel()
    n = int(free.sum())
    if not 1 <= k < n:
        raise ValueError(f"k (number of modes) must lie in [1, {n - 1}] for this lattice's {n} free "
                         f"components, got {k}")
    Kff = (0.5 * (K + K.T))[free][:, free].tocsc()
    m = np.repeat(S.mass, 3)[free]
    # a start vector of its own: ARPACK's comes from a generator whose state persists between the
    # calls of a process, so the basis it returned for a degenerate frequency (and the pairing of
    # the cube's mode pairs) depended on which solves the process had made before
    v0 = np.random.default_rng(0).standard_normal(n)
    w, V = spla.eigsh(Kff, k=k, M=sp.diags(m).tocsc(), sigma=shift(scene), which="LM", mode="normal", tol=0.0,
                      v0=v0)
    order = np.argsort(w)
    w, V = w[order], V[:, order]
    V = V / np.sqrt(np.einsum("ik,i,ik->k", V, m, V))
    full = np.zeros((3 * S.n, k))
    full[free] = V
    freq = np.sqrt(np.clip(w, 0.0, None)) / (2.0 * np.pi)
    return LatticeModes(freq, np.ascontiguousarray(full.T.reshape(k, S.n, 3)), model.name)


def mac(A: np.ndarray, B: np.ndarray, W=None) -> np.ndarray:
    """(ka, kb) MAC of every shape in ``A`` (ka, ...) against every shape in ``B`` (kb, ...),
    sampled on the same nodes; ``W``: weighting matrix of the flattened shapes (module docstring)."""
    a = np.asarray(A, float).reshape(len(A), -1)
    b = np.asarray(B, float).reshape(len(B), -1)
    Wb = b if W is None else (W @ b.T).T
    Wa = a if W is None else (W @ a.T).T
    cross = _zero_to_roundoff(a @ Wb.T, a, Wb)
    return cross**2 / np.outer(np.einsum("ij,ij->i", a, Wa), np.einsum("ij,ij->i", b, Wb))


def _zero_to_roundoff(products: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``products`` (= ``a @ b.T``, rows of ``a`` and ``b`` of length n) with every entry whose
    magnitude is within the dot product's round-off bound ``n ε |a| @ |b|.T`` set to 0."""
    bound = a.shape[1] * np.finfo(float).eps * (np.abs(a) @ np.abs(b).T)
    return np.where(np.abs(products) <= bound, 0.0, products)


def groups(freq: np.ndarray, rtol: float = DEGENERATE_RTOL) -> np.ndarray:
    """(k,) group index of each frequency (ascending): consecutive ones within ``rtol`` share one."""
    g = np.zeros(len(freq), dtype=np.int64)
    for i in range(1, len(freq)):
        same = abs(freq[i] - freq[i - 1]) <= rtol * max(abs(freq[i]), abs(freq[i - 1]))
        g[i] = g[i - 1] if same else g[i - 1] + 1
    return g


def subspace_mac(ref: np.ndarray, shapes: np.ndarray, group: np.ndarray) -> np.ndarray:
    """(n_groups, k) ``‖Qᵀ a‖² / ‖a‖²`` of every shape ``a`` against each group of ``ref``."""
    r = np.asarray(ref, float).reshape(len(ref), -1)
    a = np.asarray(shapes, float).reshape(len(shapes), -1)
    out = np.empty((int(group.max()) + 1, len(a)))
    for gi in range(len(out)):
        Q, _ = np.linalg.qr(r[group == gi].T)
        out[gi] = np.sum(_zero_to_roundoff(a @ Q, a, Q.T) ** 2, axis=1) / np.einsum("ij,ij->i", a, a)
    return out


def match(f_ref: np.ndarray, ref: np.ndarray, f: np.ndarray, shapes: np.ndarray) -> dict:
    """Pair each reference mode with one mode of ``shapes`` (a one-to-one assignment maximising the
    summed subspace MAC, :func:`subspace_mac`), both sampled on the same nodes.

    Returns plain lists: ``mac`` (the MAC matrix, reference rows), ``matched`` (the mode paired
    with each reference mode, or ``None`` when there are fewer modes), ``matched_mac``,
    ``error`` (``f[matched] / f_ref − 1``) and ``error_by_order`` (``f[i] / f_ref[i] − 1``);
    a relative error is ``None`` where the reference frequency is not positive."""
    f_ref, f = np.asarray(f_ref, float), np.asarray(f, float)
    g = groups(f_ref)
    smac = subspace_mac(ref, shapes, g)
    score = smac[g]  # (k_ref, k)
    rows, cols = linear_sum_assignment(-score)
    matched = [None] * len(f_ref)
    for r, c in zip(rows, cols):
        matched[r] = int(c)

    def rel(a, b):
        return float(a / b - 1.0) if b > 0 else None

    return {
        "mac": mac(ref, shapes).tolist(),
        "matched": matched,
        "matched_mac": [None if c is None else float(score[j, c]) for j, c in enumerate(matched)],
        "error": [None if c is None else rel(f[c], f_ref[j]) for j, c in enumerate(matched)],
        "error_by_order": [rel(f[i], f_ref[i]) if i < len(f) else None for i in range(len(f_ref))],
        "groups": g.tolist(),
    }
