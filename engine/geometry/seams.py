"""Stitching the seams of a surface meshed in parts (T-junctions).

A roof modelled as several faces and meshed face by face (SketchUp, Revit and many IFC or OBJ
exports) meets itself along seams whose two sides are divided differently: a vertex of one side
lies on an edge of the other (a T-junction) instead of being shared. Welding coincident vertices
joins such parts at a few points only, and what is left is neither one surface nor separate ones.

``weld_seams`` first joins the boundary vertices of different parts (edge-connected pieces of the
mesh) that lie within ``SEAM_SAG`` of their boundary edges' length of each other: a seam left
unjoined at a modeller's tolerance (Rhino's 1 mm on a roof modelled in metres). ``stitch_seams``
then finds every boundary vertex that lies on a boundary edge of another part, within ``SEAM_SAG``
of that edge's length (a curved seam's vertices stand off the other side's chords by their sag),
and splits the edge's triangle at those vertices, so the two sides share every vertex and edge of
the seam. Stitched vertices are not moved; a welded one takes its partner's place.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..mesh import unique_rows

__all__ = ["SEAM_SAG", "join_seams", "weld_seams", "stitch_seams"]

#: Largest distance of a vertex from another part's boundary edge, relative to the edge's length,
#: at which it is taken to lie on that edge: the sag of a chord of length L on a radius R is
#: L^2 / (8 R), 2.5 % of L where L = R / 5, coarser than any roof is tessellated.
SEAM_SAG = 0.025
#: A vertex is inside an edge when it projects this far (relative) from both ends.
_END = 1e-3


def _parts(edge_id: np.ndarray) -> np.ndarray:
    """Label per face of the pieces connected through shared edges; edge_id (m, 3): each corner's edge."""
    m = len(edge_id)
    owner = np.repeat(np.arange(m), 3)
    incidence = sp.csr_matrix((np.ones(3 * m), (owner, edge_id.ravel())), shape=(m, int(edge_id.max()) + 1))
    return connected_components(incidence @ incidence.T, directed=False)[1]


def _borders(faces: np.ndarray):
    """The boundary's directed edges k = 3 * face + corner, their ends a -> b, each edge's part, the
    boundary vertices and the parts each belongs to; None when there is nothing to join: no
    boundary, or a single part."""
    directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=-1).reshape(-1, 2)
    _, inverse, counts = unique_rows(np.sort(directed, axis=1), return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    border = np.flatnonzero(counts[inverse] == 1)
    if len(border) == 0:
        return None
    part = _parts(inverse.reshape(faces.shape))
    if part.max() == 0:
        return None
    a, b = directed[border, 0], directed[border, 1]
    edge_part = part[border // 3]
    border_vertices = np.unique(directed[border])
    pairs = np.unique(np.c_[np.r_[a, b], np.r_[edge_part, edge_part]], axis=0)
    vertex_parts: dict[int, set[int]] = {int(v): set() for v in border_vertices}
    for v, p in pairs.tolist():
        vertex_parts[v].add(p)
    return border, a, b, edge_part, border_vertices, vertex_parts


def join_seams(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int]:
    """(vertices, faces, representative per input vertex, vertices welded, vertices stitched): the
    seams welded (``weld_seams``), the faces renumbered and those left with a repeated corner
    dropped, then stitched (``stitch_seams``); the boundary is found once unless welding changed it."""
    found = _borders(faces)
    representative, welded = _weld(vertices, found)
    if welded:
        faces = representative[faces]
        faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])]
        found = _borders(faces)
    vertices, faces, stitched = _stitch(vertices, faces, found)
    return vertices, faces, representative, welded, stitched


def weld_seams(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, int]:
    """(representative per vertex, vertices welded): boundary vertices of different parts closer than
    SEAM_SAG of their shorter boundary edge (an unjoined seam left at a modeller's tolerance, a
    millimetre where the mesh's edges are decimetres) share the lowest id of the group."""
    return _weld(vertices, _borders(faces))


def _weld(vertices: np.ndarray, found) -> tuple[np.ndarray, int]:
    representative = np.arange(len(vertices))
    if found is None:
        return representative, 0
    _, a, b, _, border_vertices, vertex_parts = found
    length = np.linalg.norm(vertices[b] - vertices[a], axis=1)
    shortest = np.full(len(vertices), np.inf)
    np.minimum.at(shortest, a, length)
    np.minimum.at(shortest, b, length)
    reach = SEAM_SAG * shortest[border_vertices]
    close = cKDTree(vertices[border_vertices]).query_pairs(float(reach.max()), output_type="ndarray")
    if not len(close):
        return representative, 0
    i, j = border_vertices[close[:, 0]], border_vertices[close[:, 1]]
    near = np.linalg.norm(vertices[i] - vertices[j], axis=1) <= SEAM_SAG * np.minimum(shortest[i], shortest[j])
    apart = np.array([not (vertex_parts[int(x)] & vertex_parts[int(y)]) for x, y in zip(i, j)], dtype=bool)
    keep = near & apart if len(i) else near
    if not keep.any():
        return representative, 0
    graph = sp.csr_matrix((np.ones(int(keep.sum())), (i[keep], j[keep])), shape=(len(vertices), len(vertices)))
    _, group = connected_components(graph, directed=False)
    lowest = np.full(group.max() + 1, len(vertices))
    np.minimum.at(lowest, group, np.arange(len(vertices)))
    representative = lowest[group]
    return representative, int(np.count_nonzero(representative != np.arange(len(vertices))))


def stitch_seams(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """(vertices, faces, vertices stitched): ``faces`` (m, 3) with each triangle that has other parts'
    boundary vertices on its boundary edges split at them (fanned from the opposite corner, or from
    a new centre vertex, appended to ``vertices``, where more than one of its edges is split)."""
    return _stitch(vertices, faces, _borders(faces))


def _stitch(vertices: np.ndarray, faces: np.ndarray, found) -> tuple[np.ndarray, np.ndarray, int]:
    if found is None:
        return vertices, faces, 0
    border, a, b, edge_part, border_vertices, vertex_parts = found
    length = np.linalg.norm(vertices[b] - vertices[a], axis=1)
    tree = cKDTree(vertices[border_vertices])
    nearby = tree.query_ball_point(0.5 * (vertices[a] + vertices[b]), 0.5 * length * (1 + SEAM_SAG))
    splits: dict[int, list[tuple[float, int]]] = {}
    for k, found in enumerate(nearby):
        if not found:
            continue
        candidates = border_vertices[np.asarray(found)]
        candidates = candidates[(candidates != a[k]) & (candidates != b[k])]
        if not len(candidates):
            continue
        direction = (vertices[b[k]] - vertices[a[k]]) / max(length[k], 1e-300)
        t = (vertices[candidates] - vertices[a[k]]) @ direction / max(length[k], 1e-300)
        off = np.linalg.norm(vertices[candidates] - vertices[a[k]] - np.outer(t * length[k], direction), axis=1)
        inside = (t > _END) & (t < 1 - _END) & (off <= SEAM_SAG * length[k])
        for v, at in zip(candidates[inside].tolist(), t[inside].tolist()):
            if edge_part[k] not in vertex_parts[v]:
                splits.setdefault(int(border[k]), []).append((at, v))
    if not splits:
        return vertices, faces, 0
    by_face: dict[int, dict[int, list[int]]] = {}
    for k, points in splits.items():
        by_face.setdefault(k // 3, {})[k % 3] = [v for _, v in sorted(points)]
    new_faces: list[list[int]] = []
    new_vertices: list[np.ndarray] = []
    n = len(vertices)
    for f, edges in by_face.items():
        corners = faces[f].tolist()
        if len(edges) == 1:
            (j, inside), = edges.items()
            chain = [corners[j], *inside, corners[(j + 1) % 3]]
            apex = corners[(j + 2) % 3]
            new_faces += [[chain[i], chain[i + 1], apex] for i in range(len(chain) - 1)]
        else:
            loop = []
            for j in range(3):
                loop += [corners[j], *edges.get(j, [])]
            centre = n + len(new_vertices)
            new_vertices.append(vertices[corners].mean(axis=0))
            new_faces += [[centre, loop[i], loop[(i + 1) % len(loop)]] for i in range(len(loop))]
    kept = np.ones(len(faces), dtype=bool)
    kept[list(by_face)] = False
    stitched = len({v for points in splits.values() for _, v in points})
    out_vertices = np.r_[vertices, np.array(new_vertices).reshape(-1, 3)]
    return out_vertices, np.r_[faces[kept], np.array(new_faces, dtype=np.int64).reshape(-1, 3)], stitched
