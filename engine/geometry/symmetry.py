"""Mirror symmetry of a grid: node partners through the symmetry planes, symmetrisation, deviation.

A plane is a (point, normal) pair (engine.remeshing.field.FieldSettings.symmetry_planes, m). A node's partner
through a plane is the node nearest its mirror image, kept where the two are each other's partner
and the image lies within ``reach`` of it; a node that is its own partner lies on the plane.
Symmetrising moves each pair to the mean of one node and the other's mirror image (a node on the
plane is projected onto it); held nodes (corners, supports) stay and their partners take their
mirror image. The deviation through a plane is the largest distance from a node's mirror image to
the nearest node, over the mean beam length.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial import cKDTree

from ..mesh import PolyMesh

__all__ = ["SYMMETRY_TOLERANCE", "Plane", "reflect", "mirror_partners", "symmetrise_points", "symmetrise_directions",
           "symmetry_deviation", "symmetry_record", "symmetrised_grid", "mirror_gap"]

Plane = tuple[Sequence[float], Sequence[float]]

#: Largest deviation from symmetry (over the mean beam length) a grid with symmetry planes may have.
SYMMETRY_TOLERANCE = 0.01
#: Passes over the planes when symmetrising (two perpendicular planes need one; others converge).
PASSES = 3


def _unit(plane: Plane) -> tuple[np.ndarray, np.ndarray]:
    point, normal = np.asarray(plane[0], dtype=float), np.asarray(plane[1], dtype=float)
    return point, normal / np.linalg.norm(normal)


def reflect(points: np.ndarray, plane: Plane) -> np.ndarray:
    """(n, 3) mirror images of ``points`` (m) through ``plane``."""
    point, normal = _unit(plane)
    points = np.asarray(points, dtype=float)
    return points - 2.0 * np.outer((points - point) @ normal, normal)


def mirror_partners(points: np.ndarray, planes: Sequence[Plane], reach: float) -> np.ndarray:
    """(n_planes, n) for each plane the index of each point's partner (the point nearest its mirror
    image, mutual and within ``reach``, m), -1 where there is none."""
    points = np.asarray(points, dtype=float)
    tree = cKDTree(points)
    partners = np.full((len(planes), len(points)), -1, dtype=np.int64)
    for p, plane in enumerate(planes):
        distance, nearest = tree.query(reflect(points, plane))
        mutual = (distance <= reach) & (nearest[nearest] == np.arange(len(points)))
        partners[p, mutual] = nearest[mutual]
    return partners


def symmetrise_points(points: np.ndarray, planes: Sequence[Plane], partners: np.ndarray,
                      held: np.ndarray | None = None) -> np.ndarray:
    """``points`` (m) with each partner pair (mirror_partners) moved to their mirrored mean and the
    points that are their own partner projected onto the plane; a held point stays, its partner
    takes its mirror image."""
    x = np.array(points, dtype=float)
    held = np.zeros(len(x), dtype=bool) if held is None else np.asarray(held, dtype=bool)
    for _ in range(PASSES if len(planes) > 1 else 1):
        for plane, partner in zip(planes, partners):
            i = np.flatnonzero(partner >= 0)
            j = partner[i]
            own = np.where(held[i], 1.0, np.where(held[j], 0.0, 0.5))
            x[i] = own[:, None] * x[i] + (1.0 - own[:, None]) * reflect(x[j], plane)
    return x


def symmetrise_directions(vectors: np.ndarray, planes: Sequence[Plane], partners: np.ndarray) -> np.ndarray:
    """(n, 3) unit ``vectors`` (one per point: normals) with each partner pair's (mirror_partners)
    turned to the mean of one and the other's mirror image, and a point's that is its own partner
    turned into the plane; vectors without partners stay."""
    v = np.array(vectors, dtype=float)
    for _ in range(PASSES if len(planes) > 1 else 1):
        for plane, partner in zip(planes, partners):
            i = np.flatnonzero(partner >= 0)
            mirrored = reflect(v[partner[i]], ((0.0, 0.0, 0.0), plane[1]))  # a direction: through the origin
            mean = 0.5 * (v[i] + mirrored)
            length = np.linalg.norm(mean, axis=1)
            keep = length > 1e-9  # opposite vectors (a vertical plane's normal on it) stay
            v[i[keep]] = mean[keep] / length[keep, None]
    return v


def symmetry_deviation(points: np.ndarray, planes: Sequence[Plane], length: float) -> list[float]:
    """Per plane, the largest distance from a point's mirror image to the nearest point, over
    ``length`` (the mean beam length, m)."""
    tree = cKDTree(np.asarray(points, dtype=float))
    return [float(tree.query(reflect(points, plane))[0].max() / max(length, 1e-300)) for plane in planes]


def mirror_gap(vertices: np.ndarray, plane: Plane) -> float:
    """The largest distance (m) from a vertex's mirror image through ``plane`` to the nearest vertex:
    0 for a surface meshed symmetrically, up to about an edge for a symmetric surface meshed
    otherwise, and as large as the surface's own asymmetry beyond that."""
    vertices = np.asarray(vertices, dtype=float)
    return float(cKDTree(vertices).query(reflect(vertices, plane))[0].max())


def symmetry_record(points: np.ndarray, planes: Sequence[Plane], length: float) -> dict:
    """The JSON-ready record of a grid's symmetry: the planes, the deviation per plane (over the mean
    beam length), the tolerance and whether the grid is within it."""
    deviation = symmetry_deviation(points, planes, length)
    return {"planes": [{"point": [float(v) for v in p], "normal": [float(v) for v in n]} for p, n in planes],
            "deviation": deviation, "tolerance": SYMMETRY_TOLERANCE,
            "symmetric": bool(max(deviation) <= SYMMETRY_TOLERANCE)}


#: A node's partner lies within this share of the mean beam length of its mirror image.
PARTNER_REACH = 0.25


def _axis_beams(polymesh: PolyMesh, planes: Sequence[Plane], reach: float) -> np.ndarray:
    """Ids of the beams across the intersection of two planes whose ends are each other's image
    through both planes (within ``reach``, m): four cells meet there, and a symmetric grid has one
    node on the intersection instead."""
    if len(planes) < 2 or not len(polymesh.edges):
        return np.zeros(0, dtype=np.int64)
    a, b = polymesh.edges.T
    image = reflect(reflect(polymesh.nodes[a], planes[0]), planes[1])
    return np.flatnonzero(np.linalg.norm(image - polymesh.nodes[b], axis=1) <= reach)


def symmetrised_grid(polymesh: PolyMesh, planes: Sequence[Plane]) -> PolyMesh:
    """``polymesh`` with its nodes symmetrised (symmetrise_points; partners within PARTNER_REACH of
    the mean beam, found again after each pass; corners held: supports are boundary nodes like
    others here). Where four cells meet on a plane a symmetric grid has one node, the extraction
    two: beams across the planes' intersection (_axis_beams) and beams shorter than the reach with
    an end that has no partner are collapsed first."""
    from ..remeshing.collapse import collapse_beams

    if not planes or not len(polymesh.edges):
        return polymesh
    reach = PARTNER_REACH * float(polymesh.beam_lengths.mean())
    across = _axis_beams(polymesh, planes, reach)
    if len(across):
        polymesh, _ = collapse_beams(polymesh, across)
    for _ in range(PASSES):
        partners = mirror_partners(polymesh.nodes, planes, reach)
        single = np.any(partners < 0, axis=0)
        short = np.flatnonzero((polymesh.beam_lengths < reach) & single[polymesh.edges].any(axis=1))
        if len(short):
            polymesh, collapsed = collapse_beams(polymesh, short[np.argsort(polymesh.beam_lengths[short])])
            if collapsed:
                partners = mirror_partners(polymesh.nodes, planes, reach)
        polymesh = polymesh.replace_nodes(symmetrise_points(polymesh.nodes, planes, partners, polymesh.corners))
    return polymesh
