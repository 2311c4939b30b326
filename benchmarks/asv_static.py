"""asv: the static MSS solve and the FEM references by mesh, and the MSS error against the FEM.

``time_static`` is the Newton solve of the compression (cube) or tension (beam) scene at 5 %
(hybmss, ν = 0.3); ``time_fem_hex1`` / ``time_fem_hex2`` the linear FEM references on the same
mesh (Hex2 on the 10³ cube and the beam only: minutes beyond); ``track_static_rel_l2_vs_fem`` the
relative L2 difference of the MSS displacements from the Hex2 reference (Hex1 where Hex2 is not
run), ``track_static_reaction_vs_fem`` the relative difference of the top plate's force.
"""

from __future__ import annotations

from fem_reference.solve import solve as fem_solve
from hybmss.solve import solve_static
from hybmss.system import build

from .asv_common import MESHES, rel_l2, scene

HEX2_MESHES = ("10x10x10", "beam-8x8x48")


def _reference_element(mesh: str) -> str:
    return "hex2" if mesh in HEX2_MESHES else "hex1"


class Static:
    params = (MESHES,)
    param_names = ["mesh"]
    timeout = 1800

    def setup_cache(self):
        out = {}
        for mesh in MESHES:
            sc = scene(mesh)
            ref = fem_solve(sc, element=_reference_element(mesh), law="linear")
            mss = solve_static(sc)
            out[mesh] = {"rel_l2": rel_l2(mss.u, ref.u),
                         "reaction": abs(mss.reactions["top"].force[2] / ref.reactions["top"].force[2] - 1.0)}
        return out

    def setup(self, cache, mesh):
        self.scene = scene(mesh)
        self.system = build(self.scene)
        solve_static(self.scene, system=self.system)  # warm-up (pattern caches)

    def time_static(self, cache, mesh):
        solve_static(self.scene, system=self.system)

    def track_static_rel_l2_vs_fem(self, cache, mesh):
        return cache[mesh]["rel_l2"]

    track_static_rel_l2_vs_fem.unit = "relative"

    def track_static_reaction_vs_fem(self, cache, mesh):
        return cache[mesh]["reaction"]

    track_static_reaction_vs_fem.unit = "relative"


class FEM:
    params = (MESHES, ["hex1", "hex2"])
    param_names = ["mesh", "element"]
    timeout = 1800

    def setup(self, mesh, element):
        if element == "hex2" and mesh not in HEX2_MESHES:
            raise NotImplementedError("Hex2 on this mesh takes minutes")
        self.scene = scene(mesh)

    def time_fem_linear(self, mesh, element):
        fem_solve(self.scene, element=element, law="linear")
