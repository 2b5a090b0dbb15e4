"""Splitting a triangle mesh's long edges, conformingly, until none is longer than a length.

A CAD tessellation of a roof's straight or flat parts has triangles as long as the roof; the
Voronoi clustering that builds a grid from the mesh's vertices cannot place a cell boundary where
there is no vertex, and uniform 1-to-4 subdivision multiplies the vertices everywhere to refine the
long direction. Here each round splits every edge longer than the length at its midpoint, and each
triangle by the pattern of its split edges (one: two triangles; two: three; three: four), so that
neighbours stay conforming; rounds repeat until no edge is too long. Vertices are only added, on
the mesh's own edges (the surface does not change), and the first ones keep their ids.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SLIVER_QUALITY", "SLIVER_SHARE", "triangle_quality", "sliver_share", "split_long_edges"]

#: Most rounds (each halves the longest edges): 2^20 covers any roof at any length.
_ROUNDS = 20
#: A triangle of quality (triangle_quality) under this is a sliver: about 6 times longer than wide.
#: Flat facets that thin are far too stiff: the Scordelis-Lo roof meshed 64 x 8 (quality 0.15)
#: deflects 0.21 instead of 0.30, 64 x 2 (0.04) 0.05.
SLIVER_QUALITY = 0.3
#: Share of a surface's area in slivers above which it is meshed again into well-shaped triangles
#: (CAD tessellations of straight or flat parts: triangles as long as the roof, too stiff as shell
#: facets, and no vertex inside them to carry the guiding field). Splitting their long edges does
#: not do it: the pieces at each sliver's far corner stay slivers, as many as before.
SLIVER_SHARE = 0.1


def triangle_quality(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(m,) 4 sqrt(3) area / sum of squared edges: 1 for an equilateral triangle, about sqrt(3) / k
    for a right triangle k times longer than wide, 0 for a degenerate one."""
    corners = vertices[faces]
    squares = (np.linalg.norm(corners - np.roll(corners, -1, axis=1), axis=2) ** 2).sum(axis=1)
    doubled = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    return 2.0 * np.sqrt(3.0) * doubled / np.maximum(squares, 1e-300)


def sliver_share(vertices: np.ndarray, faces: np.ndarray) -> float:
    """The share of the mesh's area in triangles of quality under SLIVER_QUALITY."""
    corners = vertices[faces]
    area = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    return float(area[triangle_quality(vertices, faces) < SLIVER_QUALITY].sum() / max(area.sum(), 1e-300))


def _one_round(vertices: np.ndarray, faces: np.ndarray, longest: float) -> tuple[np.ndarray, np.ndarray, bool]:
    following = np.roll(faces, -1, axis=1)
    n = len(vertices)
    key = np.minimum(faces, following) * n + np.maximum(faces, following)
    unique, face_edge = np.unique(key.ravel(), return_inverse=True)
    face_edge = face_edge.reshape(faces.shape)
    a, b = unique // n, unique % n
    split = np.linalg.norm(vertices[b] - vertices[a], axis=1) > longest
    if not split.any():
        return vertices, faces, False
    middle = np.full(len(unique), -1, dtype=np.int64)
    middle[split] = n + np.arange(int(split.sum()))
    vertices = np.r_[vertices, 0.5 * (vertices[a[split]] + vertices[b[split]])]
    marked = split[face_edge]                      # (m, 3): edge j runs from corner j to corner j + 1
    mids = middle[face_edge]
    count = marked.sum(axis=1)
    out = [faces[count == 0]]
    # one split edge: roll it to edge 0 and halve the triangle from the opposite corner
    rows = np.flatnonzero(count == 1)
    shift = np.argmax(marked[rows], axis=1)
    order = (np.arange(3)[None, :] + shift[:, None]) % 3
    v, m = faces[rows[:, None], order], mids[rows[:, None], order]
    out += [np.c_[v[:, 0], m[:, 0], v[:, 2]], np.c_[m[:, 0], v[:, 1], v[:, 2]]]
    # two: roll the edge left whole to edge 0; a corner triangle and the rest cut in two
    rows = np.flatnonzero(count == 2)
    shift = np.argmin(marked[rows], axis=1)
    order = (np.arange(3)[None, :] + shift[:, None]) % 3
    v, m = faces[rows[:, None], order], mids[rows[:, None], order]
    out += [np.c_[v[:, 2], m[:, 2], m[:, 1]], np.c_[v[:, 0], v[:, 1], m[:, 1]], np.c_[v[:, 0], m[:, 1], m[:, 2]]]
    # three: four triangles
    rows = np.flatnonzero(count == 3)
    v, m = faces[rows], mids[rows]
    out += [np.c_[v[:, 0], m[:, 0], m[:, 2]], np.c_[v[:, 1], m[:, 1], m[:, 0]], np.c_[v[:, 2], m[:, 2], m[:, 1]],
            np.c_[m[:, 0], m[:, 1], m[:, 2]]]
    return vertices, np.concatenate(out), True


def split_long_edges(vertices: np.ndarray, faces: np.ndarray, longest: float,
                     max_vertices: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) with every edge no longer than ``longest`` (m), each face's orientation kept;
    rounds stop early where the next would pass ``max_vertices``."""
    vertices = np.asarray(vertices, dtype=float)
    faces = np.asarray(faces, dtype=np.int64)
    for _ in range(_ROUNDS):
        more_vertices, more_faces, changed = _one_round(vertices, faces, longest)
        if not changed or (max_vertices is not None and len(more_vertices) > max_vertices):
            break
        vertices, faces = more_vertices, more_faces
    return vertices, faces
