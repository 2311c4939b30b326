"""Dead surface tractions of a Scene (``Scene.loads``) as FEM load vectors.

A :class:`hybmss.scene.Load` selects the body's surface cell faces whose centre lies in its
region and applies the uniform traction ``t`` (Pa) there.  The FEM integrates ``∫ t · v dA``
over the mesh facets that lie in the selected cell faces (a refined mesh splits each cell face
into ``r²`` facets; a facet belongs to the cell face whose centre the test uses, so the FEM and
the mass-spring system load exactly the same surface).
"""

from __future__ import annotations

import numpy as np
from skfem import FacetBasis, LinearForm

from hybmss.scene import Scene

from .space import ELEMENTS, Space


@LinearForm
def _unit(v, w):
    return v


def load_facets(scene: Scene, load, mesh) -> np.ndarray:
    """Boundary facets of ``mesh`` inside the cell faces selected by ``load``."""
    body = scene.body
    facets = mesh.boundary_facets()
    pts = mesh.p[:, mesh.facets[:, facets]]  # (3, 4, k)
    mid = pts.mean(axis=1).T  # (k, 3)
    axis = np.argmin(np.ptp(pts, axis=1), axis=0)  # the constant coordinate: facet normal
    rel = (mid - np.asarray(body.origin)) / body.le
    centre = np.floor(rel) + 0.5
    k = np.arange(len(facets))
    centre[k, axis] = np.round(rel[k, axis])  # on the cell-face plane
    sel = load.region.select(np.asarray(body.origin) + centre * body.le, body)
    return facets[sel]


def load_vector(scene: Scene, space: Space) -> np.ndarray:
    """``∫ t · v dA`` of all of ``scene.loads`` in the vector dofs of ``space`` (n_vector,)."""
    mesh = space.fmesh.mesh
    elem, order = ELEMENTS[space.element]
    out = np.zeros(space.n_vector)
    for load in scene.loads:
        facets = load_facets(scene, load, mesh)
        if len(facets) == 0:
            raise ValueError(f"a load selects no surface face of the body: {load.region}")
        fb = FacetBasis(mesh, elem(), facets=facets, intorder=order)
        w = _unit.assemble(fb)  # ∫ N_s dA per scalar dof (same numbering as the space)
        out += (w[:, None] * np.asarray(load.traction)[None, :]).ravel()
    return out
