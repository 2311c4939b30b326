"""Finite-element spaces on a :class:`~fem_reference.mesh.FemMesh` and vectorized assembly.

A :class:`Space` wraps a scalar scikit-fem :class:`~skfem.Basis` (``ElementHex1`` or the
27-node Lagrange ``ElementHex2``) with an explicit quadrature order (SPEC §9: the default
order for Hex2 is far higher than needed and slow).  Vector fields use three components per
scalar dof, interleaved as scikit-fem's ``ElementVector`` does: vector dof ``3 s + c`` is
component ``c`` of scalar dof ``s``.

Element matrices are built from the basis values and gradients at the quadrature points with
NumPy contractions (one ``einsum`` over all elements), then scattered once into a sparse matrix.
This is the same integral as a scikit-fem ``BilinearForm`` but avoids its loop over the
81 × 81 local dof pairs of a vector Hex2 element, which dominates the time of the
finite-strain tangent (assembled at every Newton iteration).

With ``dN[n, J, e, q]`` the gradient of local basis function ``n`` in element ``e`` at
quadrature point ``q`` and ``dx[e, q]`` the quadrature weight times the Jacobian:

- linear elasticity, ``a(u, v) = ∫ λ div u div v + 2μ ε(u):ε(v) dx`` is split into
  ``K_λ = ∫ div u div v`` and ``K_μ = ∫ 2 ε(u):ε(v)`` so ``K = λ K_λ + μ K_μ``;
- a general tangent ``∫ ∇v : A : ∇du dx`` with a fourth-order field ``A[e, q, i, J, k, L]``;
- the coupling ``∫ q G : ∇v dx`` with a second-order field ``G[i, J, e, q]`` and a scalar
  (pressure) space for ``q``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from skfem import Basis, ElementHex1, ElementHex2

from .mesh import FemMesh

ELEMENTS = {"hex1": (ElementHex1, 3), "hex2": (ElementHex2, 5)}
"""Element name → (scikit-fem element, quadrature order).  Order 3 is 2 Gauss points per
direction (exact for the Hex1 stiffness on cubes), order 5 is 3 points (exact for Hex2)."""

COMPILED_PATTERN_KEYS = 100_000
"""Element entries (nodes per element squared × elements) above which :attr:`Space._uniform_pattern`
is built by the compiled :func:`fem_reference._pattern.block_pattern`: the Hex2 8×8×48 beam's
2.2e6 in 0.27 s instead of the NumPy twin's 3.0 s (one sort of them all), for 2.8 s of
compilation once per machine; below, the twin takes under 0.15 s and nothing is compiled (the
quick reproduction's meshes)."""
_CHUNK = 256  # elements per block in the tangent contraction (bounds temporary memory)


@dataclass(frozen=True, eq=False)
class Space:
    """A scalar Lagrange space on a mesh, with cached quadrature data.

    Attributes
    ----------
    fmesh : the :class:`FemMesh`.
    element : ``"hex1"`` or ``"hex2"``.
    basis : the scalar scikit-fem basis.
    """

    fmesh: FemMesh
    element: str
    basis: Basis

    @classmethod
    def create(cls, fmesh: FemMesh, element: str, intorder: int | None = None) -> "Space":
        if element not in ELEMENTS:
            raise ValueError(f"element must be one of {', '.join(ELEMENTS)}; got {element!r}")
        elem, order = ELEMENTS[element]
        basis = Basis(fmesh.mesh, elem(), intorder=order if intorder is None else int(intorder))
        return cls(fmesh, element, basis)

    # ---------------------------------------------------------------- data
    @property
    def n_scalar(self) -> int:
        return int(self.basis.N)

    @property
    def n_vector(self) -> int:
        return 3 * self.n_scalar

    @property
    def edofs(self) -> np.ndarray:
        """(nn, ne) scalar dofs of each element."""
        return self.basis.element_dofs

    @cached_property
    def vedofs(self) -> np.ndarray:
        """(3 nn, ne) vector dofs of each element, local order (n, c) → 3 n + c."""
        e = self.edofs
        return (3 * e[:, None, :] + np.arange(3)[None, :, None]).reshape(-1, e.shape[1])

    @cached_property
    def points(self) -> np.ndarray:
        """(n_scalar, 3) reference position of each scalar dof (Lagrange node)."""
        return np.ascontiguousarray(self.basis.doflocs.T)

    @cached_property
    def N(self) -> np.ndarray:
        """(nn, ne, nq) basis values at the quadrature points."""
        return np.stack([np.asarray(b[0]) for b in self.basis.basis])

    @cached_property
    def dN(self) -> np.ndarray:
        """(nn, 3, ne, nq) basis gradients at the quadrature points."""
        return np.stack([b[0].grad for b in self.basis.basis])

    @property
    def dx(self) -> np.ndarray:
        """(ne, nq) quadrature weights times |det J|."""
        return self.basis.dx

    @property
    def vertex_dofs(self) -> np.ndarray:
        """Scalar dof of each mesh vertex (Hex1 and Hex2 number vertices first)."""
        return self.basis.nodal_dofs[0]

    @cached_property
    def particle_dofs(self) -> np.ndarray:
        """Scalar dof of each lattice particle."""
        return self.vertex_dofs[self.fmesh.particle_nodes]

    # ---------------------------------------------------------------- fields
    def grad(self, U: np.ndarray) -> np.ndarray:
        """Displacement gradient ``∇u[i, J, e, q]`` of nodal vectors ``U`` (n_scalar, 3)."""
        Ue = U[self.edofs]  # (nn, ne, 3)
        return np.einsum("nei,nJeq->iJeq", Ue, self.dN, optimize=True)

    def value(self, P: np.ndarray) -> np.ndarray:
        """Scalar field ``p[e, q]`` of nodal values ``P`` (n_scalar,)."""
        return np.einsum("ne,neq->eq", P[self.edofs], self.N, optimize=True)

    def integrate(self, f: np.ndarray) -> float:
        """``∫ f dx`` of a quadrature field ``f[e, q]``."""
        return float(np.sum(f * self.dx))

    # ---------------------------------------------------------------- assembly
    def _pattern(self, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """CSR pattern ``(indptr, indices, position)`` of a vector-space matrix whose entries
        (in C order of the broadcast ``rows``, ``cols`` arrays of vector dofs) add to
        ``data[position]``."""
        n = self.n_vector
        key = (rows.astype(np.int64) * n + cols).ravel()
        uniq, position = np.unique(key, return_inverse=True)
        r = uniq // n
        indptr = np.searchsorted(r, np.arange(n + 1)).astype(np.int64)
        indices = (uniq - r * n).astype(np.int32)
        return indptr, indices, position.astype(np.intp).ravel()

    @cached_property
    def _vector_pattern(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pattern of element blocks ``Ke[e, a, b]`` (dofs ``vedofs[a, e]``, ``vedofs[b, e]``).

        Built once per space, so a tangent is assembled with one ``np.bincount`` over the element
        blocks instead of a COO → CSR conversion (sort and duplicate summation) per call.
        """
        r = self.vedofs.T
        return self._pattern(r[:, :, None], r[:, None, :])

    @cached_property
    def _uniform_pattern(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pattern of element blocks ordered ``K[n, m, e, i, k]`` (vector dofs ``3 s + c`` of
        scalar dofs ``s = edofs[n, e]``, ``edofs[m, e]``, components ``i``, ``k``): compiled
        (:func:`fem_reference._pattern.block_pattern`) on a mesh of more than
        :data:`COMPILED_PATTERN_KEYS` element entries, else by its NumPy twin :meth:`_block_pattern`
        (the same arrays)."""
        e = self.edofs
        if e.shape[0] ** 2 * e.shape[1] <= COMPILED_PATTERN_KEYS:
            return self._block_pattern()
        from ._pattern import block_pattern

        return block_pattern(np.ascontiguousarray(e, dtype=np.int64), int(self.n_scalar))

    def _block_pattern(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:attr:`_uniform_pattern` with NumPy, from the scalar pattern (9× fewer keys to sort than
        the vector one, :meth:`_pattern`): scalar entry ``(a, b)`` at rank ``r`` in row ``a`` (of
        ``deg(a)`` entries) holds the 3×3 block ``(3a + i, 3b + k)`` at CSR position
        ``9 indptr(a) + 3 i deg(a) + 3 r + k``."""
        e = self.edofs.astype(np.int64)  # (nn, ne)
        N = self.n_scalar
        key = (e[:, None, :] * N + e[None, :, :]).ravel()  # (n, m, e)
        uniq, pos = np.unique(key, return_inverse=True)
        rs = uniq // N
        ptr = np.searchsorted(rs, np.arange(N + 1)).astype(np.int64)
        deg = np.diff(ptr)
        a = np.broadcast_to(e[:, None, :], (e.shape[0],) + e.shape).ravel()
        base = 9 * ptr[a] + 3 * (pos.ravel() - ptr[a])  # (n, m, e)
        ik = (3 * np.arange(3)[:, None] * deg[a][:, None, None] + np.arange(3)[None, None, :])  # i, k
        position = (base[:, None, None] + ik).ravel()
        lengths = np.repeat(3 * deg, 3)  # entries of vector row 3a + i
        indptr = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
        row_s = np.repeat(np.arange(3 * N) // 3, lengths)
        offset = np.arange(int(indptr[-1])) - np.repeat(indptr[:-1], lengths)
        cols3 = (3 * (uniq - rs * N)[:, None] + np.arange(3)).ravel()  # (scalar entry, k)
        indices = cols3[3 * ptr[row_s] + offset].astype(np.int32)
        return indptr, indices, position.astype(np.intp)

    @cached_property
    def uniform_dN(self) -> np.ndarray | None:
        """(nn, 3, nq) basis gradients shared by every element, or ``None`` when the elements
        differ (the voxel meshes are uniform grids of equal cubes: every element is a translate
        of the first)."""
        dN = self.dN
        d0 = dN[:, :, :1, :]
        if np.allclose(dN, d0, rtol=1e-12, atol=1e-12 * float(np.abs(d0).max())):
            return np.ascontiguousarray(d0[:, :, 0, :])
        return None

    @cached_property
    def _uniform_B(self) -> np.ndarray:
        """``B[(n, m), (q, J, L)] = ∂_J N_n ∂_L N_m`` at the quadrature points (uniform meshes)."""
        d = self.uniform_dN
        nn, _, nq = d.shape
        return np.ascontiguousarray(np.einsum("nJq,mLq->nmqJL", d, d).reshape(nn * nn, nq * 9))

    def scatter_blocks(self, Ke: np.ndarray, pattern=None) -> sp.csr_matrix:
        """Sparse vector-space matrix from element blocks ``Ke[e, a, b]`` (vector dofs ``vedofs``),
        or ordered as ``pattern`` (one of the cached patterns) says."""
        indptr, indices, position = self._vector_pattern if pattern is None else pattern
        data = np.bincount(position, weights=np.ascontiguousarray(Ke).ravel(), minlength=len(indices))
        n = self.n_vector
        K = sp.csr_matrix((data, indices, indptr), shape=(n, n))
        K.has_sorted_indices = True
        return K

    def _scatter(self, Ke: np.ndarray, rows: np.ndarray, cols: np.ndarray, shape) -> sp.csr_matrix:
        """Sparse matrix from element blocks ``Ke[a, b, e]`` with dofs ``rows[a, e]``, ``cols[b, e]``."""
        I = np.broadcast_to(rows[:, None, :], Ke.shape).ravel()
        J = np.broadcast_to(cols[None, :, :], Ke.shape).ravel()
        return sp.coo_matrix((Ke.ravel(), (I, J)), shape=shape).tocsr()

    def elasticity_parts(self) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        """``(K_λ, K_μ)`` with ``K_λ = ∫ div u div v`` and ``K_μ = ∫ 2 ε(u):ε(v)``.

        Assemble once per mesh and element; ``K = λ K_λ + μ K_μ`` for any material.  On a
        uniform mesh (:attr:`uniform_dN`, equal weights ``dx``) every element has the same
        blocks: they are computed once and scattered through :attr:`_uniform_pattern` (the
        8×8×48 beam in Hex2, 84,099 dofs: 0.8 s instead of 5.2 s, the same matrices to 1e-14).
        """
        if self.uniform_dN is not None and self._uniform_weights is not None:
            return self._uniform_elasticity_parts()
        return self._general_elasticity_parts()

    def _general_elasticity_parts(self) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        """:meth:`elasticity_parts` of any mesh (element geometry taken per element)."""
        dN, dx = self.dN, self.dx
        nn, ne = dN.shape[0], dN.shape[2]
        G = np.einsum("nceq,mdeq,eq->ncmde", dN, dN, dx, optimize=True)  # ∫ ∂_c N_n ∂_d N_m
        Klam = G  # (n, c, m, d): div u div v couples component c of n with d of m
        trace = np.einsum("nkmke->nme", G)
        eye = np.eye(3)
        Kmu = (
            eye[None, :, None, :, None] * trace[:, None, :, None, :]
            + G.transpose(0, 3, 2, 1, 4)
        )
        shape = (self.n_vector, self.n_vector)
        r = self.vedofs
        Klam = self._scatter(Klam.reshape(3 * nn, 3 * nn, ne), r, r, shape)
        Kmu = self._scatter(Kmu.reshape(3 * nn, 3 * nn, ne), r, r, shape)
        return Klam, Kmu

    @cached_property
    def _uniform_weights(self) -> np.ndarray | None:
        """(nq,) quadrature weights times |det J| shared by every element, or ``None``."""
        dx = self.dx
        if np.allclose(dx, dx[:1], rtol=1e-12, atol=0.0):
            return np.ascontiguousarray(dx[0])
        return None

    def _uniform_elasticity_parts(self) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        """:meth:`elasticity_parts` of a uniform mesh: the element's blocks
        ``G[n, c, m, d] = ∫ ∂_c N_n ∂_d N_m`` once, ``K_λ`` block ``(n, m)[c, d] = G[n, c, m, d]``,
        ``K_μ`` block ``(n, m)[c, d] = δ_cd Σ_k G[n, k, m, k] + G[n, d, m, c]``, the same for
        every element."""
        d, w = self.uniform_dN, self._uniform_weights
        G = np.einsum("ncq,mdq,q->ncmd", d, d, w)
        trace = np.einsum("nkmk->nm", G)
        Kmu = np.eye(3)[None, :, None, :] * trace[:, None, :, None] + G.transpose(0, 3, 2, 1)
        ne = self.dx.shape[0]
        out = []
        for Ke in (G, Kmu):
            blocks = Ke.transpose(0, 2, 1, 3)  # (n, m, c, d): the order of _uniform_pattern, element axis added
            out.append(self.scatter_blocks(np.broadcast_to(blocks[:, :, None], blocks.shape[:2] + (ne, 3, 3)),
                                           self._uniform_pattern))
        return out[0], out[1]

    @cached_property
    def dNq(self) -> np.ndarray:
        """(ne, nq, nn, 3) basis gradients, points first (for batched matrix products)."""
        return np.ascontiguousarray(self.dN.transpose(2, 3, 0, 1))

    def tangent(self, A: np.ndarray) -> sp.csr_matrix:
        """``∫ ∇v : A : ∇du dx`` for a field ``A[e, q, i, J, k, L]`` (vector space).

        Element block ``K[(n,i),(m,k)] = Σ_q dx Σ_JL ∂_J N_n A_iJkL ∂_L N_m``.  On a uniform
        mesh (:attr:`uniform_dN`) this is one matrix product of the constant
        ``B[(n,m), (q,J,L)]`` with the weighted field ``A[(q,J,L), (e,i,k)]`` for all elements;
        otherwise two batched matrix products per block of elements (:meth:`tangent_general`).
        """
        if self.uniform_dN is None:
            return self.tangent_general(A)
        dx = self.dx
        ne, nq = dx.shape
        Aw = np.empty((nq, 3, 3, ne, 3, 3))  # (q, J, L, e, i, k)
        np.multiply(A.transpose(1, 3, 5, 0, 2, 4), dx.T[:, None, None, :, None, None], out=Aw)
        K = self._uniform_B @ Aw.reshape(nq * 9, ne * 9)  # ((n,m), (e,i,k))
        return self.scatter_blocks(K, self._uniform_pattern)

    def tangent_general(self, A: np.ndarray) -> sp.csr_matrix:
        """:meth:`tangent` for any mesh (element geometry taken per element)."""
        dNq, dx = self.dNq, self.dx
        ne, nq, nn, _ = dNq.shape
        Ke = np.empty((ne, 3 * nn, 3 * nn))
        for s in range(0, ne, _CHUNK):
            sl = slice(s, min(s + _CHUNK, ne))
            b = sl.stop - sl.start
            Aw = A[sl] * dx[sl][:, :, None, None, None, None]
            Ar = Aw.transpose(0, 1, 3, 2, 4, 5).reshape(b, nq, 3, 27)  # (e, q, J, (i,k,L))
            T = np.matmul(dNq[sl], Ar)  # (e, q, n, (i,k,L))
            T = T.reshape(b, nq, nn, 3, 3, 3).transpose(0, 4, 2, 3, 1, 5).reshape(b, 3, 3 * nn, 3 * nq)
            W = dNq[sl].transpose(0, 1, 3, 2).reshape(b, 1, 3 * nq, nn)  # (e, (q,L), m)
            K = np.matmul(T, W)  # (e, k, (n,i), m)
            Ke[sl] = K.reshape(b, 3, 3 * nn, nn).transpose(0, 2, 3, 1).reshape(b, 3 * nn, 3 * nn)
        return self.scatter_blocks(Ke)

    def vector_load(self, P: np.ndarray) -> np.ndarray:
        """``∫ P : ∇v dx`` for a field ``P[i, J, e, q]`` (e.g. the first Piola stress)."""
        fe = np.einsum("nJeq,iJeq,eq->nie", self.dN, P, self.dx, optimize=True)
        return np.bincount(self.vedofs.ravel(), weights=fe.reshape(-1, fe.shape[-1]).ravel(),
                           minlength=self.n_vector)

    def body_load(self, b: np.ndarray) -> np.ndarray:
        """``∫ b · v dx`` for a constant body force density ``b`` (3,)."""
        w = np.einsum("neq,eq->ne", self.N, self.dx)  # ∫ N_n per element
        fe = w[:, None, :] * np.asarray(b, float)[None, :, None]  # (nn, 3, ne)
        out = np.zeros(self.n_vector)
        np.add.at(out, self.vedofs.ravel(), fe.reshape(-1, fe.shape[-1]).ravel())
        return out

    def coupling(self, pspace: "Space", G: np.ndarray) -> sp.csr_matrix:
        """``B[q, v] = ∫ q G : ∇v dx`` (rows: pressure dofs, columns: vector dofs)."""
        Be = np.einsum("peq,nJeq,iJeq,eq->pnie", pspace.N, self.dN, G, self.dx, optimize=True)
        npn, nn, ne = Be.shape[0], Be.shape[1], Be.shape[-1]
        return self._scatter(
            Be.reshape(npn, 3 * nn, ne), pspace.edofs, self.vedofs, (pspace.n_scalar, self.n_vector)
        )

    def scalar_load(self, f: np.ndarray) -> np.ndarray:
        """``∫ f q dx`` for a quadrature field ``f[e, q]`` (scalar space)."""
        fe = np.einsum("neq,eq->ne", self.N, f * self.dx)
        out = np.zeros(self.n_scalar)
        np.add.at(out, self.edofs.ravel(), fe.ravel())
        return out

    def mass(self, c: np.ndarray | float = 1.0) -> sp.csr_matrix:
        """``∫ c p q dx`` (scalar space), ``c`` a constant or a quadrature field."""
        w = self.dx * c
        Me = np.einsum("peq,req,eq->pre", self.N, self.N, w, optimize=True)
        return self._scatter(Me, self.edofs, self.edofs, (self.n_scalar, self.n_scalar))
