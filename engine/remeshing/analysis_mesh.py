"""A coarser triangle mesh of a fine surface, for analyses that need its shape but not its detail.

A roof exported from a scan or a fine CAD tessellation can have a million triangles; the shell
analysis that guides the grid needs tens of thousands (its forces are smoothed over cells metres
across), and on the full mesh it needs tens of GB. The copy is the remesher's own uniform
Voronoi grid of the surface (engine/remeshing/voronoi.py, an isotropic field of constant size)
with each cell fanned into triangles from its centre (the clustering without Lloyd steps: on a
1.28 million-triangle saddle at 8 333 cells, 98.5 % hexagons in 8 s, against 98.8 % in 26 s with
20): hexagons give six nearly equilateral triangles, and the boundary and its corners are
followed as the grid follows them. Quadric decimation was tried first and rejected: on surfaces
with a flat direction (a cylinder, a plane) it makes triangles as long as the roof
(docs/decisions.md).
"""

from __future__ import annotations

import numpy as np

from ..geometry.proximity import closest_points
from ..mesh import TriMesh
from .field import GuidingField
from .voronoi import RemeshSettings, remesh

__all__ = ["TRIANGLES_PER_CELL", "analysis_mesh"]

#: Triangles a cell of the uniform grid is fanned into, on average (a hexagon's six).
TRIANGLES_PER_CELL = 6


def _uniform_field(mesh: TriMesh) -> GuidingField:
    """Size 1 and no anisotropy everywhere (the direction is any tangent)."""
    normals = mesh.vertex_normals
    direction = np.cross(normals, [0.0, 0.0, 1.0])
    direction = np.where(np.linalg.norm(direction, axis=1)[:, None] < 1e-6, np.cross(normals, [1.0, 0.0, 0.0]),
                         direction)
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    return GuidingField(size=np.ones(mesh.n_vertices), anisotropy=np.ones(mesh.n_vertices), direction=direction,
                        normals=normals)


def analysis_mesh(mesh: TriMesh, triangles: int) -> TriMesh:
    """A triangle mesh of ``mesh``'s surface with about ``triangles`` triangles, or ``mesh`` itself
    when it has no more than that."""
    if mesh.n_faces <= triangles:
        return mesh
    cells = max(4, triangles // TRIANGLES_PER_CELL)
    grid = remesh(mesh, _uniform_field(mesh), RemeshSettings(n_cells=cells, lloyd_iterations=0)).polymesh
    loops = grid.faces
    sizes = np.array([len(loop) for loop in loops])
    centres = np.array([grid.nodes[loop].mean(axis=0) for loop in loops])
    centres, _, _ = closest_points(mesh.vertices, mesh.faces, centres)
    corner = np.concatenate(loops)
    following = np.concatenate([np.roll(loop, -1) for loop in loops])
    centre_ids = len(grid.nodes) + np.repeat(np.arange(len(loops)), sizes)
    faces = np.c_[centre_ids, corner, following]
    return TriMesh(vertices=np.r_[grid.nodes, centres], faces=faces, name=f"{mesh.name} (analysis copy)")
