"""The map between a fine surface mesh and a coarser mesh of the same surface.

``SurfaceMap`` carries values between the two:

- fine -> coarse: a fine vertex's load goes to the corners of the coarse triangle under it, in
  proportion to its barycentric coordinates (the transpose of the interpolation, so forces are
  conserved exactly and moments to the meshes' distance apart);
- coarse -> fine: vertex values are interpolated at the closest point of the coarse mesh;
  face values are those of the coarse triangle under the fine face's centroid;
- ``nearest``: each fine vertex's nearest coarse vertex (a boundary vertex's the nearest coarse
  boundary vertex), where supports go.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..mesh import TriMesh
from .proximity import closest_points

__all__ = ["SurfaceMap", "surface_map"]

#: Closest-point queries are made in chunks of this many points to bound memory, each among the
#: triangles with the CANDIDATES nearest centroids (the coarse mesh's triangles are of one size:
#: 8 found the same points as 16 on a 1.28 million-vertex saddle, in a fifth of the time).
_CHUNK = 100_000
CANDIDATES = 8


@dataclass(frozen=True)
class SurfaceMap:
    """Where each fine vertex and face lies on the coarse mesh.

    vertex_faces (n,), vertex_weights (n, 3): the coarse triangle under each fine vertex and the
    barycentric coordinates of its closest point there; nearest (n,): the nearest coarse vertex
    (boundary to boundary); face_faces (m,): the coarse triangle under each fine face's centroid.
    """

    fine: TriMesh
    coarse: TriMesh
    vertex_faces: np.ndarray
    vertex_weights: np.ndarray
    nearest: np.ndarray
    face_faces: np.ndarray

    def to_coarse(self, values: np.ndarray) -> np.ndarray:
        """Fine vertex loads (n, ...) gathered on the coarse vertices (the interpolation's transpose)."""
        values = np.asarray(values, dtype=float)
        out = np.zeros((self.coarse.n_vertices, *values.shape[1:]))
        corners = self.coarse.faces[self.vertex_faces]
        for k in range(3):
            weight = self.vertex_weights[:, k].reshape(-1, *([1] * (values.ndim - 1)))
            np.add.at(out, corners[:, k], weight * values)
        return out

    def to_fine(self, values: np.ndarray) -> np.ndarray:
        """Coarse vertex values (nc, ...) interpolated at the fine vertices (n, ...)."""
        values = np.asarray(values, dtype=float)
        corners = self.coarse.faces[self.vertex_faces]
        out = np.zeros((self.fine.n_vertices, *values.shape[1:]))
        for k in range(3):
            out += self.vertex_weights[:, k].reshape(-1, *([1] * (values.ndim - 1))) * values[corners[:, k]]
        return out


def _barycentric(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(p, 3) barycentric coordinates of points lying on the triangles (p, 3, 3)."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    v0, v1, v2 = b - a, c - a, points - a
    d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
    d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
    denominator = np.where(np.abs(d00 * d11 - d01 * d01) > 1e-300, d00 * d11 - d01 * d01, 1e-300)
    v = (d11 * d20 - d01 * d21) / denominator
    w = (d00 * d21 - d01 * d20) / denominator
    weights = np.clip(np.c_[1.0 - v - w, v, w], 0.0, 1.0)
    return weights / weights.sum(axis=1, keepdims=True)


def _under(coarse: TriMesh, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(triangle ids, closest points) of points on the coarse mesh, in chunks."""
    faces = np.empty(len(points), dtype=np.int64)
    closest = np.empty_like(points)
    for start in range(0, len(points), _CHUNK):
        part = slice(start, start + _CHUNK)
        closest[part], _, faces[part] = closest_points(coarse.vertices, coarse.faces, points[part], k=CANDIDATES)
    return faces, closest


def surface_map(fine: TriMesh, coarse: TriMesh) -> SurfaceMap:
    """The map between ``fine`` and ``coarse``, a coarser mesh of the same surface."""
    vertex_faces, closest = _under(coarse, fine.vertices)
    weights = _barycentric(closest, coarse.vertices[coarse.faces[vertex_faces]])
    face_faces, _ = _under(coarse, fine.vertices[fine.faces].mean(axis=1))
    _, nearest = cKDTree(coarse.vertices).query(fine.vertices)
    fine_border, coarse_border = np.flatnonzero(fine.boundary_vertices), np.flatnonzero(coarse.boundary_vertices)
    if len(fine_border) and len(coarse_border):
        _, on_border = cKDTree(coarse.vertices[coarse_border]).query(fine.vertices[fine_border])
        nearest[fine_border] = coarse_border[on_border]
    return SurfaceMap(fine=fine, coarse=coarse, vertex_faces=vertex_faces, vertex_weights=weights,
                      nearest=np.asarray(nearest, dtype=np.int64), face_faces=face_faces)
