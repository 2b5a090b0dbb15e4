"""Quality figures of a grid-shell (polymesh_quality, JSON-ready, see docs/formats.md): counts, cell
degrees and node valences, achieved size ratio and aspect (graded against the guiding field where
one is given), regularity, planarity, beam lengths, angles and closeness to the surface; and the
size ratio and aspect alone (size_and_aspect), which the Voronoi remesher's choice among candidate
grids weighs.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..mesh import PolyMesh, TriMesh
from .field import GuidingField

__all__ = ["polymesh_quality", "size_and_aspect"]


def _face_groups(polymesh: PolyMesh):
    """(face ids, (m, d, 3) node coordinates) for each face degree d."""
    degrees = polymesh.face_degrees
    for d in np.unique(degrees):
        ids = np.flatnonzero(degrees == d)
        loops = np.stack([polymesh.faces[i] for i in ids])
        yield ids, polymesh.nodes[loops]


def polymesh_quality(polymesh: PolyMesh, *, mesh: TriMesh | None = None, field: GuidingField | None = None) -> dict:
    """Quality figures of a grid-shell (JSON-ready), see docs/formats.md.

    Achieved size per cell: sqrt(area); aspect: sqrt of the ratio of the PCA eigenvalues of
    its nodes (a regular polygon, and a regular one stretched by a, give 1 and a); interior
    cells only. With a field, the achieved size ratio is the field's ratio D' to the power of
    the log-log slope of achieved against prescribed size (1 when cells follow the field
    exactly), so it compares with D even where the extremes of the field lie on the boundary;
    without one it is the 95th over the 5th percentile of the sizes (kept as size_ratio_p5_p95).
    The achieved aspect is the 95th percentile.
    """
    degrees = polymesh.face_degrees
    interior = ~polymesh.face_boundary
    interior_nodes = ~polymesh.boundary
    lengths = polymesh.beam_lengths
    mean_length = float(lengths.mean()) if len(lengths) else 0.0
    histogram = {int(d): int(c) for d, c in zip(*np.unique(degrees, return_counts=True))}
    n = polymesh.n_faces
    sizes, aspects, regularity = np.zeros(n), np.zeros(n), np.zeros(n)
    planarity, centroids = np.zeros(n), np.zeros((n, 3))
    smallest = 180.0
    for ids, p in _face_groups(polymesh):
        # (m faces, d nodes, 3)
        following = np.roll(p, -1, axis=1)
        sizes[ids], centroids[ids], centred, aspects[ids], vt = _cell_shapes(p)
        if p.shape[1] > 3:
            planarity[ids] = np.abs(np.einsum("mdi,mi->md", centred, vt[:, -1])).max(axis=1)
        # regularity: edge-length spread after un-stretching the cell's own anisotropy
        local = np.einsum("mdi,mki->mdk", centred, vt[:, :2])
        spread = np.sqrt(np.maximum(np.linalg.svd(local, compute_uv=False), 1e-300))
        unstretched = local / spread[:, None, :] * spread.mean(axis=1)[:, None, None]
        edges = np.linalg.norm(unstretched - np.roll(unstretched, -1, axis=1), axis=2)
        regularity[ids] = edges.std(axis=1) / np.maximum(edges.mean(axis=1), 1e-300)
        to_previous, to_next = np.roll(p, 1, axis=1) - p, following - p
        cosine = np.einsum("mdi,mdi->md", to_previous, to_next) / np.maximum(
            np.linalg.norm(to_previous, axis=2) * np.linalg.norm(to_next, axis=2), 1e-300)
        smallest = min(smallest, float(np.degrees(np.arccos(np.clip(cosine, -1, 1))).min()))
    pick = interior if interior.sum() >= 4 else np.ones(n, dtype=bool)
    lo, hi = np.percentile(sizes[pick], [5, 95])
    quality = {
        "n_nodes": int(polymesh.n_nodes), "n_beams": int(len(polymesh.edges)), "n_faces": int(polymesh.n_faces),
        "hexagon_share_interior": float(np.mean(degrees[interior] == 6)) if interior.any() else 0.0,
        "face_degree_histogram": histogram,
        "valence3_share_interior": (float(np.mean(polymesh.valence[interior_nodes] == 3))
                                    if interior_nodes.any() else 0.0),
        "achieved_size_ratio": float(hi / max(lo, 1e-300)),
        "achieved_max_aspect": float(np.percentile(aspects[pick], 95)),
        "regularity": float(np.mean(regularity)),
        "planarity_max_m": float(planarity.max()) if n else 0.0,
        "planarity_p95_m": float(np.percentile(planarity, 95)) if n else 0.0,
        "planarity_max_mm": float(1000 * planarity.max()) if n else 0.0,
        "planarity_max_rel": float(planarity.max() / max(mean_length, 1e-300)) if n else 0.0,
        "planarity_p95_rel": float(np.percentile(planarity, 95) / max(mean_length, 1e-300)) if n else 0.0,
        "shortest_beam_m": float(lengths.min()) if len(lengths) else 0.0,
        "mean_beam_length_m": mean_length, "total_length_m": float(lengths.sum()),
        "smallest_angle_deg": smallest,
    }
    if mesh is not None:
        distance = _distance_to_surface(mesh, polymesh.nodes)
        quality["closeness_max_rel"] = float(distance.max() / mesh.diagonal)
        quality["closeness_mean_rel"] = float(distance.mean() / mesh.diagonal)
    if mesh is not None and field is not None:
        quality["size_ratio_p5_p95"] = quality["achieved_size_ratio"]
        prescribed = _prescribed_sizes(centroids[pick], mesh, field)
        quality["field_size_span_cells"] = _span(prescribed)
        graded = _size_grading(sizes[pick], prescribed, field)
        if graded is not None:
            quality["size_correlation"], quality["size_grading_slope"], quality["achieved_size_ratio"] = graded
            from scipy.stats import spearmanr

            quality["size_rank_correlation"] = float(spearmanr(prescribed, sizes[pick]).statistic)
        else:
            quality["size_correlation"] = quality["size_rank_correlation"] = None
    return quality


def _cell_shapes(p: np.ndarray):
    """Cells of one degree, nodes p (m, d, 3): sizes sqrt(area) (m,), centroids (m, 3), centred
    nodes (m, d, 3), aspects (m,: sqrt of the ratio of the two largest PCA eigenvalues) and the
    PCA axes (m, 3, 3)."""
    following = np.roll(p, -1, axis=1)
    sizes = np.sqrt(0.5 * np.linalg.norm(np.cross(p, following).sum(axis=1), axis=1))
    centroids = p.mean(axis=1)
    centred = p - centroids[:, None, :]
    _, s, vt = np.linalg.svd(centred, full_matrices=False)
    s2 = np.maximum(s[:, :2], 1e-300)
    return sizes, centroids, centred, s2[:, 0] / s2[:, 1], vt


def _prescribed_sizes(centroids: np.ndarray, mesh: TriMesh, field: GuidingField) -> np.ndarray:
    """The field's size at the surface vertex nearest each cell centroid (m,)."""
    _, nearest = cKDTree(mesh.vertices).query(centroids)
    return field.size[nearest]


def _span(sizes: np.ndarray) -> float:
    """95th over 5th percentile of sizes: the grading the measured cells can show. It can be far
    below the field's max/min where the field varies only within a cell of the boundary, whose cut
    cells the figures leave out (the real roofs' fields vary most next to their supports)."""
    lo, hi = np.percentile(sizes, [5, 95])
    return float(hi / max(lo, 1e-300))


def _size_grading(sizes: np.ndarray, prescribed: np.ndarray, field: GuidingField):
    """(correlation of achieved and prescribed size, log-log slope, achieved size ratio D'^slope)
    of cells, or None where the field's size (or the cells') does not vary."""
    if not (np.std(prescribed) > 1e-9 * prescribed.mean() and np.std(sizes) > 0):
        return None
    correlation = float(np.corrcoef(prescribed, sizes)[0, 1])
    # grading actually achieved: the field's ratio to the power of the log-log slope
    slope = np.polyfit(np.log(prescribed), np.log(sizes), 1)[0]
    return correlation, float(slope), float((field.size.max() / field.size.min()) ** slope)


def size_and_aspect(polymesh: PolyMesh, mesh: TriMesh, field: GuidingField) -> tuple[float, float]:
    """The grid's achieved size ratio and aspect, as polymesh_quality reports them."""
    n = polymesh.n_faces
    sizes, aspects, centroids = np.zeros(n), np.zeros(n), np.zeros((n, 3))
    for ids, p in _face_groups(polymesh):
        sizes[ids], centroids[ids], _, aspects[ids], _ = _cell_shapes(p)
    interior = ~polymesh.face_boundary
    pick = interior if interior.sum() >= 4 else np.ones(n, dtype=bool)
    lo, hi = np.percentile(sizes[pick], [5, 95])
    graded = _size_grading(sizes[pick], _prescribed_sizes(centroids[pick], mesh, field), field)
    size_ratio = graded[2] if graded is not None else float(hi / max(lo, 1e-300))
    return size_ratio, float(np.percentile(aspects[pick], 95))


def _distance_to_surface(mesh: TriMesh, points: np.ndarray) -> np.ndarray:
    from ..geometry.proximity import closest_points

    return closest_points(mesh.vertices, mesh.faces, points)[1]
