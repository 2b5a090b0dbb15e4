"""The pieces of the local/global iterations of :mod:`engine.remeshing.optimize`.

Local steps: each cell's regular target (the regular polygon of the cell's target area fitted in the
cell's un-stretched principal frame, stretched back) and planar target (its nodes projected onto its
best-fit plane), and the target areas that keep the field's grading (:func:`graded_areas`); each
node's closest point on the reference surface and on its boundary, and the closeness band. The
global step's operators: the mean-free rows of the cells, the mean of a node's neighbours, and the
basis of the displacements the constraints admit.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..geometry.proximity import closest_point_on_triangles
from ..mesh import TriMesh, node_adjacency

__all__ = ["HEXAGON_SIDE", "cells_by_degree", "cell_ids_by_degree", "cell_adjacency", "graded_areas", "cell_areas",
           "cell_frames", "planar_targets", "unstretched_cells", "regular_targets", "ClosestSurfacePoints",
           "ClosestBoundaryPoints", "into_band", "centering_rows", "stacked_targets", "neighbour_mean",
           "free_dof_basis"]


#: Side of the regular hexagon of unit area (a side is this times the square root of the area).
HEXAGON_SIDE = float(np.sqrt(2.0 / (3.0 * np.sqrt(3.0))))


# ----------------------------------------------------------------------------- local steps

def cells_by_degree(faces: tuple[np.ndarray, ...]) -> dict[int, np.ndarray]:
    """Faces grouped by degree: {k: (f_k, k) node ids}."""
    groups: dict[int, list[np.ndarray]] = {}
    for face in faces:
        groups.setdefault(len(face), []).append(face)
    return {k: np.array(v, dtype=np.int64) for k, v in sorted(groups.items())}


def cell_ids_by_degree(faces: tuple[np.ndarray, ...]) -> dict[int, np.ndarray]:
    """Face ids grouped by degree, in the order of :func:`cells_by_degree`: {k: (f_k,) face ids}."""
    ids: dict[int, list[int]] = {}
    for i, face in enumerate(faces):
        ids.setdefault(len(face), []).append(i)
    return {k: np.array(v, dtype=np.int64) for k, v in sorted(ids.items())}


def cell_adjacency(faces: tuple[np.ndarray, ...]) -> sp.csr_matrix:
    """(f, f) 0/1 matrix of the cells that share a beam."""
    owner = np.repeat(np.arange(len(faces)), [len(f) for f in faces])
    directed = np.concatenate([np.stack([f, np.roll(f, -1)], axis=-1) for f in faces])
    key = np.sort(directed, axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    key, owner = key[order], owner[order]
    same = np.all(key[1:] == key[:-1], axis=1)
    a, b = owner[:-1][same], owner[1:][same]
    f = len(faces)
    adjacency = sp.csr_matrix((np.ones(2 * len(a)), (np.r_[a, b], np.r_[b, a])), shape=(f, f))
    adjacency.data[:] = 1.0
    return adjacency


def graded_areas(areas: np.ndarray, sizes: np.ndarray | None, interior: np.ndarray,
                 adjacency: sp.csr_matrix, *, min_side: float = 0.0,
                 quantile: float = 0.2) -> tuple[np.ndarray, float, float]:
    """(target areas (f,), the grid's grading slope, the targets' slope): the area each cell's
    regularity target takes.

    ``areas`` are the cells' areas as given (the remesher's grading), ``sizes`` the field's target
    size h at each cell (None: the cells' own sqrt(area)). The grid's grading slope sigma is the
    log-log slope of sqrt(area) against h over the interior cells (1 where the remesher follows the
    field). An interior cell's target follows the field among its neighbours: h^(2 sigma) times the
    area its neighbourhood (the cells around it and itself) has per unit of h^(2 sigma), so the
    local cell count keeps its area and the size follows the field instead of the remesher's noise.
    Boundary cells (cut by the boundary) keep their area.

    ``min_side``: the shortest beam the joints take (m). Where the smallest interior cells (their
    ``quantile``) would have a regular hexagon's side shorter than that, the grading is compressed
    monotonically, sizes going as h^s with s < sigma over the whole grid (total area kept), until
    they do not: the order of the sizes, which is the field's grading, stays. Where even equal
    sizes would not do, the grid is too fine for its joints whatever its grading (the remesh
    coarsens such grids, the optimize stage reports them): the grading is then not compressed.
    """
    areas = np.asarray(areas, dtype=float)
    n = len(areas)
    h = np.sqrt(areas) if sizes is None else np.asarray(sizes, dtype=float)
    interior = np.asarray(interior, dtype=bool)
    pick = interior if interior.sum() >= 4 else np.ones(n, dtype=bool)
    log_h = np.log(h[pick])
    sigma = 1.0
    if sizes is not None and np.ptp(log_h) > 1e-6:
        sigma = float(np.clip(0.5 * np.polyfit(log_h, np.log(areas[pick]), 1)[0], 0.0, 1.0))
    local = areas.copy()
    if sizes is not None and interior.sum() >= 2:
        inner = interior.astype(float)
        ring = adjacency + sp.eye(n, format="csr")
        weight = h ** (2 * sigma)
        budget, demand = ring @ (areas * inner), ring @ (weight * inner)
        ok = interior & (demand > 0)
        local[ok] = weight[ok] * budget[ok] / demand[ok]
        local[ok] *= areas[ok].sum() / local[ok].sum()  # the interior cells' area as given
    total = float(areas.sum())
    h_ref = float(np.exp(np.mean(log_h)))

    def compressed(slope: float) -> np.ndarray:
        out = local * (h / h_ref) ** (2 * (slope - sigma))
        return out * (total / max(float(out.sum()), 1e-300))

    def margin(slope: float) -> float:
        side = np.sqrt(compressed(slope)[pick]) * HEXAGON_SIDE
        return float(np.quantile(side, quantile)) - min_side

    slope = sigma
    if min_side > 0 and margin(sigma) < 0 <= margin(0.0):
        lo, hi = 0.0, sigma  # margin(lo) >= 0 > margin(hi)
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if margin(mid) < 0 else (mid, hi)
        slope = lo
    return compressed(slope), sigma, slope


def cell_areas(points: np.ndarray) -> np.ndarray:
    """(f,) areas of (f,k,3) cells (the vector area's length: the area projected on the best-fit plane), m2."""
    return 0.5 * np.linalg.norm(np.cross(points, np.roll(points, -1, axis=1)).sum(axis=1), axis=1)


def cell_frames(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centroids (f,3), in-plane axes (f,2,3) and normals (f,3) of (f,k,3) point sets (PCA)."""
    centroid = points.mean(axis=1)
    _, _, vt = np.linalg.svd(points - centroid[:, None], full_matrices=False)
    return centroid, vt[:, :2], vt[:, 2]


def planar_targets(points: np.ndarray) -> np.ndarray:
    """(f,k,3) nodes of (f,k,3) cells projected onto each cell's best-fit plane, m."""
    points = np.asarray(points, dtype=float)
    centroid, _, normal = cell_frames(points)
    offset = np.einsum("fki,fi->fk", points - centroid[:, None], normal)
    return points - offset[..., None] * normal[:, None]


def unstretched_cells(points: np.ndarray):
    """In-plane principal coordinates of (f,k,3) cells divided by the sqrt-eigenvalue spreads:
    (unstretched (f,k,2), spread (f,2), vectors (f,2,2), axes (f,2,3), centroid (f,3))."""
    k = points.shape[1]
    centroid, axes, _ = cell_frames(points)
    local = np.einsum("fki,fji->fkj", points - centroid[:, None], axes)
    covariance = np.einsum("fki,fkj->fij", local, local) / k
    values, vectors = np.linalg.eigh(covariance)
    spread = np.sqrt(np.maximum(values, 1e-300))
    principal = np.einsum("fki,fij->fkj", local, vectors)
    return principal / spread[:, None, :], spread, vectors, axes, centroid


def regular_targets(points: np.ndarray, max_stretch: float = np.inf, areas: np.ndarray | None = None) -> np.ndarray:
    """(f,k,3) targets of (f,k,3) cells: the regular k-gon of equal area best fitting each cell
    after un-stretching it by its PCA axes, stretched back by at most ``max_stretch`` (the ratio
    of the two principal spreads, kept at their product, so the area stays). A regular cell, and
    a regular cell stretched affinely within ``max_stretch``, is its own target (either
    orientation); a sliver's target is the regular cell stretched ``max_stretch`` times."""
    points = np.asarray(points, dtype=float)
    f, k, _ = points.shape
    unstretched, spread, vectors, axes, centroid = unstretched_cells(points)
    if np.isfinite(max_stretch):
        mean = np.sqrt(spread[:, 0] * spread[:, 1])
        ratio = np.minimum(spread[:, 1] / np.maximum(spread[:, 0], 1e-300), max(float(max_stretch), 1.0))
        spread = np.stack([mean / np.sqrt(ratio), mean * np.sqrt(ratio)], axis=1)
    angle = 2 * np.pi * np.arange(k) / k
    template = np.broadcast_to(np.stack([np.cos(angle), np.sin(angle)], axis=1), (f, k, 2))
    signed = 0.5 * np.sum(unstretched[:, :, 0] * np.roll(unstretched[:, :, 1], -1, axis=1)
                          - np.roll(unstretched[:, :, 0], -1, axis=1) * unstretched[:, :, 1], axis=1)
    template = np.where((signed < 0)[:, None, None], template * [1.0, -1.0], template)
    unit_area = 0.5 * k * np.sin(2 * np.pi / k)
    if areas is None:
        scale = np.sqrt(np.abs(signed) / unit_area)
    else:  # the given area: in the un-stretched frame, divided by the spreads' product
        scale = np.sqrt(np.asarray(areas, float) / (spread[:, 0] * spread[:, 1]) / unit_area)
    # best rotation of the template onto the cell (2-D Procrustes, node j <-> template corner j)
    dot = np.einsum("fki,fki->f", template, unstretched)
    cross = np.einsum("fk,fk->f", template[:, :, 0], unstretched[:, :, 1]) - np.einsum(
        "fk,fk->f", template[:, :, 1], unstretched[:, :, 0])
    phi = np.arctan2(cross, dot)
    c, s = np.cos(phi)[:, None], np.sin(phi)[:, None]
    rotated = np.stack([c * template[:, :, 0] - s * template[:, :, 1],
                        s * template[:, :, 0] + c * template[:, :, 1]], axis=2)
    fitted = rotated * scale[:, None, None]
    back = np.einsum("fkj,fij->fki", fitted * spread[:, None, :], vectors)
    return centroid[:, None] + np.einsum("fkj,fji->fki", back, axes)


# ----------------------------------------------------------------------------- closest points

class ClosestSurfacePoints:
    """Closest points on a triangle mesh with the candidate index built once."""

    def __init__(self, mesh: TriMesh, candidates: int = 16):
        self.corners = mesh.vertices[mesh.faces]
        self.normals = mesh.face_normals
        self.diagonal = float(mesh.diagonal)
        self.tree = cKDTree(self.corners.mean(axis=1))
        self.k = min(candidates, len(mesh.faces))

    def _nearest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(closest points (p,3), distances (p,), triangle ids (p,))."""
        p = len(points)
        _, cand = self.tree.query(points, k=self.k)
        cand = np.asarray(cand).reshape(p, self.k)
        flat = cand.ravel()
        repeated = np.repeat(points, self.k, axis=0)
        q = closest_point_on_triangles(repeated, self.corners[flat, 0], self.corners[flat, 1], self.corners[flat, 2])
        distance = np.linalg.norm(q - repeated, axis=1).reshape(p, self.k)
        best = np.argmin(distance, axis=1)
        rows = np.arange(p)
        return q.reshape(p, self.k, 3)[rows, best], distance[rows, best], cand[rows, best]

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(closest points (p,3), distances (p,))."""
        q, distance, _ = self._nearest(points)
        return q, distance

    def closest_normals(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(closest points (p,3), unit normals of the triangles they lie on (p,3))."""
        q, _, triangle = self._nearest(points)
        return q, self.normals[triangle]


class ClosestBoundaryPoints:
    """Closest points on the surface's boundary polylines and the segment directions there."""

    def __init__(self, mesh: TriMesh, candidates: int = 16):
        segments = [np.stack([mesh.vertices[loop], mesh.vertices[np.roll(loop, -1)]], axis=1)
                    for loop in mesh.boundary_loops]
        self.segments = np.concatenate(segments) if segments else np.zeros((0, 2, 3))
        if len(self.segments):
            self.tree = cKDTree(self.segments.mean(axis=1))
        self.k = min(candidates, len(self.segments))

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(closest points (p,3), unit direction of the segment they lie on (p,3))."""
        p = len(points)
        _, cand = self.tree.query(points, k=self.k)
        cand = np.asarray(cand).reshape(p, self.k)
        a, b = self.segments[cand, 0], self.segments[cand, 1]
        d = b - a
        length2 = np.maximum(np.einsum("pki,pki->pk", d, d), 1e-300)
        t = np.clip(np.einsum("pki,pki->pk", points[:, None] - a, d) / length2, 0.0, 1.0)
        q = a + t[..., None] * d
        best = np.argmin(np.einsum("pki,pki->pk", q - points[:, None], q - points[:, None]), axis=1)
        rows = np.arange(p)
        direction = d[rows, best] / np.sqrt(length2[rows, best])[:, None]
        return q[rows, best], direction


def into_band(points: np.ndarray, closest: np.ndarray, distance: np.ndarray, band: float) -> np.ndarray:
    """(p,3) closeness targets: the points themselves within ``band`` (m) of the surface, else the
    point at distance ``band`` on the way to their closest surface point."""
    factor = np.minimum(1.0, band / np.maximum(distance, 1e-300))
    return closest + (points - closest) * factor[:, None]


# ----------------------------------------------------------------------------- operators

def centering_rows(groups: dict[int, np.ndarray], n: int) -> sp.csr_matrix:
    """Rows x_j - mean of its cell for every cell corner, stacked over the degree groups (r, n)."""
    rows, cols, vals, offset = [], [], [], 0
    for k, faces in groups.items():
        f = len(faces)
        row = offset + np.arange(f * k).reshape(f, k)
        rows.append(np.repeat(row.ravel(), k))
        cols.append(np.repeat(faces, k, axis=0).ravel())
        vals.append(np.tile((np.eye(k) - 1.0 / k).ravel(), f))
        offset += f * k
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(offset, n))


def stacked_targets(groups: dict[int, np.ndarray], targets: dict[int, np.ndarray]) -> np.ndarray:
    """Mean-free targets (r,3) of every cell corner, in the row order of centering_rows."""
    return np.concatenate([(targets[k] - targets[k].mean(axis=1, keepdims=True)).reshape(-1, 3) for k in groups])


def neighbour_mean(edges: np.ndarray, n: int) -> sp.csr_matrix:
    """(n, n) operator: mean of each node's neighbours (a node without neighbours: itself)."""
    adjacency = node_adjacency(edges, n)
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    lonely = degree == 0
    return (sp.diags(1.0 / np.maximum(degree, 1.0)) @ adjacency + sp.diags(lonely.astype(float))).tocsr()


def free_dof_basis(n: int, interior: np.ndarray, sliding: np.ndarray, tangents: np.ndarray) -> sp.csr_matrix:
    """(3n, m) basis of the admissible displacements: 3 DOFs per free interior node, one along
    the boundary tangent per sliding node, none for fixed nodes (x flattened node-major)."""
    free = np.flatnonzero(interior)
    slide = np.flatnonzero(sliding)
    rows = np.r_[(3 * free[:, None] + np.arange(3)).ravel(), (3 * slide[:, None] + np.arange(3)).ravel()]
    cols = np.r_[np.arange(3 * len(free)), 3 * len(free) + np.repeat(np.arange(len(slide)), 3)]
    vals = np.r_[np.ones(3 * len(free)), tangents[slide].ravel()]
    return sp.csr_matrix((vals, (rows, cols)), shape=(3 * n, 3 * len(free) + len(slide)))
