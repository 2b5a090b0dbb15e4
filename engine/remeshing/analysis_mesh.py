"""A well-shaped triangle mesh of a surface, for analyses that need its shape but not its facets.

A roof exported from a scan or a fine CAD tessellation can have a million triangles; the shell
analysis that guides the grid needs tens of thousands (its forces are smoothed over cells metres
across), and on the full mesh it needs tens of GB. A coarse CAD tessellation has the opposite
fault: slivers as long as the roof's straight or flat parts, far too stiff as flat shell facets.

The copy is the remesher's own uniform Voronoi grid of the surface (engine/remeshing/voronoi.py,
an isotropic field of constant size) with each cell fanned into triangles from its centre (the
clustering without Lloyd steps: on a 1.28 million-triangle saddle at 8 333 cells, 98.5 %
hexagons in 8 s, against 98.8 % in 26 s with 20): hexagons give six nearly equilateral
triangles, and the boundary and its corners are followed as the grid follows them. Edges longer
than a third of a cell are split first (engine.geometry.edge_split), so that the clustering has
vertices to draw cell boundaries through along a sliver's length. Quadric decimation was tried
first and rejected: on surfaces with a flat direction (a cylinder, a plane) it makes triangles as
long as the roof (docs/decisions.md).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..geometry.edge_split import SLIVER_SHARE, sliver_share, split_long_edges
from ..geometry.fine_mesh import MAX_FINE_VERTICES
from ..geometry.proximity import closest_points
from ..mesh import TriMesh
from .field import GuidingField, tangent_basis
from .voronoi import RemeshSettings, remesh

__all__ = ["TRIANGLES_PER_CELL", "SLIVER_COPY_TRIANGLES", "copy_triangles", "analysis_mesh"]

#: Triangles a cell of the uniform grid is fanned into, on average (a hexagon's six).
TRIANGLES_PER_CELL = 6
#: Triangles of the copy of a surface of slivers (fewer where the project allows fewer).
SLIVER_COPY_TRIANGLES = 20_000


def _uniform_field(mesh: TriMesh) -> GuidingField:
    """Size 1 and no anisotropy everywhere (the direction is any tangent)."""
    normals = mesh.vertex_normals
    return GuidingField(size=np.ones(mesh.n_vertices), anisotropy=np.ones(mesh.n_vertices),
                        direction=tangent_basis(normals)[0], normals=normals)


def copy_triangles(mesh: TriMesh, max_triangles: int) -> int | None:
    """The triangles of the copy ``mesh``'s shell is to be analysed on, or None to analyse it as it is:
    ``max_triangles`` for a finer mesh; min(SLIVER_COPY_TRIANGLES, max_triangles) for one with more
    than SLIVER_SHARE of its area in slivers."""
    if mesh.n_faces > max_triangles:
        return max_triangles
    if sliver_share(mesh.vertices, mesh.faces) > SLIVER_SHARE:
        return min(SLIVER_COPY_TRIANGLES, max_triangles)
    return None


def analysis_mesh(mesh: TriMesh, triangles: int) -> TriMesh:
    """A well-shaped triangle mesh of ``mesh``'s surface with about ``triangles`` triangles."""
    cells = max(4, triangles // TRIANGLES_PER_CELL)
    # a vertex every third of a cell at least: the clustering draws cell boundaries through vertices
    spacing = np.sqrt(mesh.area / cells) / 3.0
    vertices, faces = split_long_edges(mesh.vertices, mesh.faces, spacing, max_vertices=MAX_FINE_VERTICES)
    dense = TriMesh(vertices=vertices, faces=faces, name=mesh.name) if len(faces) > mesh.n_faces else mesh
    grid = remesh(dense, _uniform_field(dense), RemeshSettings(n_cells=cells, lloyd_iterations=0)).polymesh
    loops = grid.faces
    sizes = np.array([len(loop) for loop in loops])
    centres = np.array([grid.nodes[loop].mean(axis=0) for loop in loops])
    centres, _, _ = closest_points(dense.vertices, dense.faces, centres)
    corner = np.concatenate(loops)
    following = np.concatenate([np.roll(loop, -1) for loop in loops])
    centre_ids = len(grid.nodes) + np.repeat(np.arange(len(loops)), sizes)
    copy = TriMesh(vertices=np.r_[grid.nodes, centres], faces=np.c_[centre_ids, corner, following], name=mesh.name)
    return _with_flags(copy, mesh)


def _with_flags(copy: TriMesh, mesh: TriMesh) -> TriMesh:
    """``copy`` with the support flags of ``mesh``: each flagged vertex flags its nearest vertex of the
    copy, boundary to boundary. Supports stay points where they were points: an edge between two
    flagged vertices is not held in between, neither in ``mesh``'s own analysis nor in the copy's."""
    if not mesh.flagged.any():
        return copy
    flags = np.zeros(copy.n_vertices, dtype=bool)
    for ours, theirs in ((copy.boundary_vertices, mesh.boundary_vertices),
                         (~copy.boundary_vertices, ~mesh.boundary_vertices)):
        marked = theirs & mesh.flagged
        if ours.any() and marked.any():
            _, nearest = cKDTree(copy.vertices[ours]).query(mesh.vertices[marked])
            flags[np.flatnonzero(ours)[nearest]] = True
    return TriMesh(vertices=copy.vertices, faces=copy.faces, flagged=flags, name=copy.name)
