"""Closest points on a triangle mesh, vectorised (no spatial-index dependency).

Candidates are the k triangles with the nearest centroids (cKDTree); the exact closest point
on each candidate follows Ericson, Real-Time Collision Detection, 5.1.5. k = 16 is ample for
meshes whose triangles are of similar size around the query points.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["closest_point_on_triangles", "closest_points"]


def closest_point_on_triangles(points: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(k,3) closest point to each point on the triangle (a, b, c) of the same row."""
    ab, ac, ap = b - a, c - a, points - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp = points - b
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    cp = points - c
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    denominator = np.where(np.abs(va + vb + vc) > 1e-300, va + vb + vc, 1e-300)
    v, w = vb / denominator, vc / denominator
    result = a + ab * v[:, None] + ac * w[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        # edge regions
        t_ab = np.where(d1 - d3 != 0, d1 / (d1 - d3), 0.0)
        on_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        result = np.where(on_ab[:, None], a + ab * t_ab[:, None], result)
        t_ac = np.where(d2 - d6 != 0, d2 / (d2 - d6), 0.0)
        on_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        result = np.where(on_ac[:, None], a + ac * t_ac[:, None], result)
        t_bc = np.where((d4 - d3) + (d5 - d6) != 0, (d4 - d3) / ((d4 - d3) + (d5 - d6)), 0.0)
        on_bc = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
        result = np.where(on_bc[:, None], b + (c - b) * t_bc[:, None], result)
    # vertex regions
    result = np.where(((d1 <= 0) & (d2 <= 0))[:, None], a, result)
    result = np.where(((d3 >= 0) & (d4 <= d3))[:, None], b, result)
    result = np.where(((d6 >= 0) & (d5 <= d6))[:, None], c, result)
    return result


def closest_points(vertices: np.ndarray, triangles: np.ndarray, points: np.ndarray,
                   k: int = 16) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(closest points (p,3), distances (p,), triangle ids (p,)) of points on a triangle mesh."""
    points = np.atleast_2d(np.asarray(points, dtype=float))
    corners = vertices[triangles]
    k = min(k, len(triangles))
    _, candidates = cKDTree(corners.mean(axis=1)).query(points, k=k)
    candidates = candidates.reshape(len(points), k)
    flat = candidates.ravel()
    repeated = np.repeat(points, k, axis=0)
    closest = closest_point_on_triangles(repeated, corners[flat, 0], corners[flat, 1], corners[flat, 2])
    distance = np.linalg.norm(closest - repeated, axis=1).reshape(len(points), k)
    best = np.argmin(distance, axis=1)
    rows = np.arange(len(points))
    return (closest.reshape(len(points), k, 3)[rows, best], distance[rows, best], candidates[rows, best])
