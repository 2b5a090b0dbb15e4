"""The mesh the Voronoi remesher (engine/remeshing/voronoi.py) clusters: the surface as it is when it has at
least VERTICES_PER_CELL vertices per cell, else refined (1-to-4) until it has
REFINED_VERTICES_PER_CELL, with every vertex's metric (the field's tangent part plus a small normal
part so that it is invertible), 1 / h^2 and area, its edges, boundary loops and corners (boundary
vertices where the boundary turns by more than CORNER_ANGLE_DEG, kept as nodes of the grid).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..mesh import TriMesh, chain_loops
from ..remeshing.field import GuidingField

__all__ = ["VERTICES_PER_CELL", "REFINED_VERTICES_PER_CELL", "MAX_FINE_VERTICES", "CORNER_ANGLE_DEG",
           "NORMAL_REGULARISATION", "surface_corners"]

#: Fewest surface vertices per cell the clustering works with; a surface with fewer is refined
#: until it has REFINED_VERTICES_PER_CELL (node positions are then finer; refining is cheap there).
VERTICES_PER_CELL = 24
REFINED_VERTICES_PER_CELL = 48
#: Largest refined mesh (vertices) the remesher builds.
MAX_FINE_VERTICES = 400_000
#: Boundary turning angle above which a surface vertex is a corner kept as a node, degrees.
CORNER_ANGLE_DEG = 30.0
#: Normal part of the vertex metric, relative to its tangent part's mean (keeps S1 invertible).
NORMAL_REGULARISATION = 0.1


# ----------------------------------------------------------------------------- surface topology

def _edges_of(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unique sorted edges (e, 2), per face corner j the id of edge (j, j+1) (m, 3), and the
    number of faces of each edge (e,)."""
    following = np.roll(faces, -1, axis=1)
    key = (np.minimum(faces, following) * n_vertices + np.maximum(faces, following)).ravel()
    unique, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    edges = np.stack([unique // n_vertices, unique % n_vertices], axis=1)
    return edges, inverse.reshape(faces.shape), counts


def _edge_ids(edges: np.ndarray, n_vertices: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Ids of the edges (a_i, b_i) in the sorted edge list."""
    keys = edges[:, 0] * n_vertices + edges[:, 1]
    return np.searchsorted(keys, np.minimum(a, b) * n_vertices + np.maximum(a, b))


def _boundary_loops(faces: np.ndarray, face_edges: np.ndarray, counts: np.ndarray) -> list[np.ndarray]:
    """Boundary loops following the faces' orientation, longest first."""
    border = counts[face_edges] == 1
    start = faces[border]
    end = np.roll(faces, -1, axis=1)[border]
    return chain_loops(start, end)


def _loop_corners(vertices: np.ndarray, loops: list[np.ndarray], angle_deg: float) -> np.ndarray:
    corners = []
    for loop in loops:
        p = vertices[loop]
        incoming = p - np.roll(p, 1, axis=0)
        outgoing = np.roll(p, -1, axis=0) - p
        cosine = np.einsum("ij,ij->i", incoming, outgoing) / np.maximum(
            np.linalg.norm(incoming, axis=1) * np.linalg.norm(outgoing, axis=1), 1e-300)
        corners.extend(loop[cosine < np.cos(np.radians(angle_deg))].tolist())
    return np.array(sorted(corners), dtype=np.int64)


def surface_corners(mesh: TriMesh, angle_deg: float = CORNER_ANGLE_DEG) -> np.ndarray:
    """Vertex ids of boundary vertices where the boundary turns by more than ``angle_deg``."""
    return _loop_corners(mesh.vertices, mesh.boundary_loops, angle_deg)


def _subdivide(vertices: np.ndarray, faces: np.ndarray, per_vertex: list[np.ndarray]):
    """One 1-to-4 midpoint subdivision; per-vertex arrays averaged at the new vertices (the old
    vertices keep their ids)."""
    edges, face_edges, _ = _edges_of(faces, len(vertices))
    mid = len(vertices) + face_edges
    new_vertices = np.vstack([vertices, 0.5 * (vertices[edges[:, 0]] + vertices[edges[:, 1]])])
    new_arrays = [np.concatenate([a, 0.5 * (a[edges[:, 0]] + a[edges[:, 1]])]) for a in per_vertex]
    a, b, c = faces[:, 0], faces[:, 1], faces[:, 2]
    ab, bc, ca = mid[:, 0], mid[:, 1], mid[:, 2]
    new_faces = np.concatenate([np.stack([a, ab, ca], 1), np.stack([ab, b, bc], 1), np.stack([ca, bc, c], 1),
                                np.stack([ab, bc, ca], 1)])
    return new_vertices, new_faces, new_arrays


@dataclass
class _Fine:
    """The clustered mesh: the surface, refined where needed (its first vertices are the surface's)."""

    vertices: np.ndarray
    faces: np.ndarray
    metric: np.ndarray       # (n, 3, 3) tangent metric + normal regularisation
    normals: np.ndarray
    inverse_h2: np.ndarray   # 1 / h^2 = sqrt(det) of the tangent metric
    areas: np.ndarray
    edges: np.ndarray
    face_edges: np.ndarray
    on_boundary: np.ndarray  # (e,) edge used by one face
    loops: list
    corners: np.ndarray      # vertex ids (of the surface, kept in the fine mesh)
    n_surface_vertices: int
    boundary_vertices: np.ndarray            # ids of the vertices on the boundary loops
    adjacency: object = None                 # engine.remeshing.clustering.MeshAdjacency, built on first use
    graph: sp.csr_matrix | None = None       # metric edge lengths, same order as the adjacency
    moments: np.ndarray | None = None        # centred vertex moments of the clustering, on first use
    tree: cKDTree | None = None              # of the vertices, on first use
    mirrors: dict = field(default_factory=dict)  # symmetry planes -> mirror maps (geometry.mirror_seeds)


def _refine(mesh: TriMesh, field: GuidingField, n_cells: int) -> _Fine:
    """The mesh to cluster: the surface when it has VERTICES_PER_CELL vertices per cell, else
    subdivided until it has REFINED_VERTICES_PER_CELL (within MAX_FINE_VERTICES); vertex metrics
    (tangent + normal regularisation), 1 / h^2, areas, edges, boundary loops and corners."""
    vertices, faces = mesh.vertices, mesh.faces
    tangent = field.metric()
    normals = np.asarray(field.normals, dtype=float)
    if len(vertices) < VERTICES_PER_CELL * n_cells:
        while len(vertices) < REFINED_VERTICES_PER_CELL * n_cells and 4 * len(vertices) <= MAX_FINE_VERTICES:
            vertices, faces, (tangent, normals) = _subdivide(vertices, faces, [tangent, normals])
    normals = normals / np.maximum(np.linalg.norm(normals, axis=1), 1e-300)[:, None]
    # sqrt(det) of the rank-2 tangent metric (its second invariant) = 1 / h^2
    trace = np.einsum("nii->n", tangent)
    second = 0.5 * (trace**2 - np.einsum("nij,nji->n", tangent, tangent))
    inverse_h2 = np.sqrt(np.maximum(second, 1e-300))
    metric = tangent + (NORMAL_REGULARISATION * 0.5 * trace)[:, None, None] * np.einsum("ni,nj->nij", normals, normals)
    edges, face_edges, counts = _edges_of(faces, len(vertices))
    cross = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    face_area = 0.5 * np.linalg.norm(cross, axis=1)
    areas = np.bincount(faces.ravel(), weights=np.repeat(face_area / 3.0, 3), minlength=len(vertices))
    loops = _boundary_loops(faces, face_edges, counts)
    corners = _loop_corners(vertices, loops, CORNER_ANGLE_DEG)
    corners = corners[corners < mesh.n_vertices]
    return _Fine(vertices=vertices, faces=faces, metric=metric, normals=normals, inverse_h2=inverse_h2, areas=areas,
                 edges=edges, face_edges=face_edges, on_boundary=counts == 1, loops=loops, corners=corners,
                 n_surface_vertices=mesh.n_vertices,
                 boundary_vertices=np.unique(np.concatenate(loops)) if loops else np.zeros(0, dtype=np.int64))

