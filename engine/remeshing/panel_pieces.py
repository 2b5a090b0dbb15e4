"""Planar panels for cells that are not: a cell is glazed with convex planar pieces split along
node-to-node diagonals, and adds no beam.

On a doubly curved surface a hexagon whose nodes follow the surface is not planar, and on
anticlastic regions a planar hexagon cannot be convex. The beam grid keeps the statics-aware cells;
the glazing is a property of the panels. A cell within the planarity tolerance and convex in its
best-fit plane is one panel; otherwise the diagonal whose two parts are flattest (largest node
distance from their best-fit planes, then the most even split) cuts it, recursively; a diagonal
that would cut off a sliver (a triangle of three nearly aligned nodes, no panel to glaze) is taken
only where no other will do. A triangle is always planar and convex, so the split always ends.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from shapely.geometry import LineString, Polygon

from ..mesh import PolyMesh, best_fit_plane

__all__ = ["PanelPiece", "planar_pieces", "panel_pieces", "piece_flatness"]

#: A triangle whose height over its longest side is under this is a sliver, not a panel.
SLIVER = 0.05


@dataclass(frozen=True)
class PanelPiece:
    """One panel: the cell it glazes, its index among that cell's pieces (0 for a whole cell) and
    its node loop (ids of the grid's nodes)."""

    cell: int
    piece: int
    loop: np.ndarray


def _plane_coordinates(points: np.ndarray, plane: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(k,2) coordinates of points in their best-fit plane (``plane``: that plane if known)."""
    centroid, normal = best_fit_plane(points) if plane is None else plane
    n0, n1, n2 = (float(c) for c in normal)
    u = np.array([0.0, n2, -n1])                      # normal x (1, 0, 0)
    if n1 * n1 + n2 * n2 < 0.01:
        u = np.array([-n2, 0.0, n0])                  # normal x (0, 1, 0)
    u /= np.sqrt(u @ u)
    v = np.array([n1 * u[2] - n2 * u[1], n2 * u[0] - n0 * u[2], n0 * u[1] - n1 * u[0]])
    relative = points - centroid
    return np.stack([relative @ u, relative @ v], axis=1)


def piece_flatness(points: np.ndarray) -> tuple[float, bool]:
    """(largest node distance from the best-fit plane (m), convex in that plane) of a node loop."""
    if len(points) == 3:
        return 0.0, True
    return _flatness(points)[:2]


def _flatness(points: np.ndarray) -> tuple[float, bool, np.ndarray]:
    """piece_flatness of a loop of 4 or more nodes, and the nodes' coordinates in that plane (k, 2)."""
    plane = best_fit_plane(points)
    centroid, normal = plane
    distance = float(np.abs((points - centroid) @ normal).max())
    local = _plane_coordinates(points, plane)
    following = np.concatenate([local[1:], local[:1]])
    edge = following - local
    next_edge = np.concatenate([edge[1:], edge[:1]])
    turn = edge[:, 0] * next_edge[:, 1] - edge[:, 1] * next_edge[:, 0]
    area = 0.5 * float(np.sum(local[:, 0] * following[:, 1] - following[:, 0] * local[:, 1]))
    scale = float(np.einsum("ij,ij->", edge, edge)) / len(points)
    convex = bool(np.all(turn * np.sign(area) >= -1e-9 * scale))
    return distance, convex, local


def _flatness_of_loops(nodes: np.ndarray, loops: list[np.ndarray]) -> list[tuple[float, bool, bool]]:
    """(``piece_flatness``, whether it is a sliver: a triangle whose height over its longest side is
    under SLIVER) of each node loop, the loops of one length at a time: one batched SVD for the
    best-fit planes of all of them (a 1500-cell optimize stage made 17 000 single ones over its
    non-planar cells' candidate diagonals, and measured 18 000 triangles one by one)."""
    out: list[tuple[float, bool, bool]] = [(0.0, True, False)] * len(loops)
    by_length: dict[int, list[int]] = {}
    for i, loop in enumerate(loops):
        by_length.setdefault(len(loop), []).append(i)
    for k, members in by_length.items():
        points = nodes[np.stack([loops[i] for i in members])]                 # (m, k, 3)
        if k == 3:                                                            # flat, convex; a sliver?
            sides = np.roll(points, -1, axis=1) - points
            longest = np.einsum("mij,mij->mi", sides, sides).max(axis=1)
            twice_area = np.linalg.norm(np.cross(sides[:, 0], sides[:, 1]), axis=1)
            for i, thin in zip(members, (twice_area < SLIVER * np.maximum(longest, 1e-300)).tolist()):
                out[i] = (0.0, True, thin)
            continue
        centroid = points.mean(axis=1)
        relative = points - centroid[:, None, :]
        normal = np.linalg.svd(relative, full_matrices=False)[2][:, -1]      # (m, 3)
        distance = np.abs(np.einsum("mkj,mj->mk", relative, normal)).max(axis=1)
        n0, n1, n2 = normal.T
        flat = n1 * n1 + n2 * n2 < 0.01                                     # as _plane_coordinates
        u = np.where(flat[:, None], np.stack([-n2, np.zeros_like(n0), n0], axis=1),
                     np.stack([np.zeros_like(n0), n2, -n1], axis=1))
        u /= np.sqrt(np.einsum("mj,mj->m", u, u))[:, None]
        v = np.cross(normal, u)
        local = np.stack([np.einsum("mkj,mj->mk", relative, u), np.einsum("mkj,mj->mk", relative, v)], axis=2)
        following = np.roll(local, -1, axis=1)
        edge = following - local
        next_edge = np.roll(edge, -1, axis=1)
        turn = edge[..., 0] * next_edge[..., 1] - edge[..., 1] * next_edge[..., 0]
        area = 0.5 * np.sum(local[..., 0] * following[..., 1] - following[..., 0] * local[..., 1], axis=1)
        scale = np.einsum("mkj,mkj->m", edge, edge) / k
        convex = np.all(turn * np.sign(area)[:, None] >= -1e-9 * scale[:, None], axis=1)
        for i, d, c in zip(members, distance.tolist(), convex.tolist()):
            out[i] = (d, c, False)
    return out


def planar_pieces(nodes: np.ndarray, loop: np.ndarray, tolerance: float) -> list[np.ndarray]:
    """Node loops (sub-loops of ``loop``) that are each planar within ``tolerance`` (m) and convex,
    the fewest the recursive diagonal split finds; ``[loop]`` when the cell already is."""
    loop = np.asarray(loop, dtype=np.int64)
    if len(loop) == 3:
        return [loop]
    distance, convex, local = _flatness(nodes[loop])
    if distance <= tolerance and convex:
        return [loop]
    k = len(loop)
    best = None
    cell = Polygon(local)
    if not cell.is_valid:  # a self-intersecting outline in its plane: no diagonal is safe
        cell = None
    candidates = []
    for i in range(k):
        for j in range(i + 2, k):
            if i == 0 and j == k - 1:
                continue
            # the diagonal runs inside the cell (in its best-fit plane)
            if cell is None or not cell.contains(LineString([local[i], local[j]])):
                continue
            candidates.append((loop[i:j + 1], np.r_[loop[j:], loop[:i + 1]]))
    measured = _flatness_of_loops(nodes, [part for parts in candidates for part in parts])
    for n, parts in enumerate(candidates):
        figures = measured[2 * n:2 * n + 2]
        bad = sum(1 for d, c, _ in figures if not (d <= tolerance and c))
        worst = max(d if c else np.inf for d, c, _ in figures)
        slivers = sum(thin for _, _, thin in figures)
        key = (slivers, bad, worst, abs(len(parts[0]) - len(parts[1])))
        if best is None or key < best[0]:
            best = (key, parts)
    if best is None:  # no diagonal inside (a degenerate cell): a fan of triangles from its first node
        return [np.array([loop[0], loop[i], loop[i + 1]]) for i in range(1, k - 1)]
    out: list[np.ndarray] = []
    for part in best[1]:
        out += planar_pieces(nodes, part, tolerance)
    return out


def panel_pieces(polymesh: PolyMesh, tolerance: float) -> list[PanelPiece]:
    """Every cell's panels, in cell order: the cell itself when planar within ``tolerance`` (m) and
    convex, else its planar convex pieces."""
    out: list[PanelPiece] = []
    for cell, loop in enumerate(polymesh.faces):
        pieces = planar_pieces(polymesh.nodes, loop, tolerance)
        out += [PanelPiece(cell=cell, piece=0 if len(pieces) == 1 else k + 1, loop=p) for k, p in enumerate(pieces)]
    return out
