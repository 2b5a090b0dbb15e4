"""Splitting long edges: no edge left too long, the surface and its area unchanged, the mesh still
conforming and oriented."""

from __future__ import annotations

import numpy as np
import pytest

from engine.geometry.edge_split import split_long_edges
from engine.geometry.parametric import grid_triangles
from engine.mesh import boundary_loops


def _vault_strips(across: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """A 16 x 12 m vault meshed 200 facets along its curve and ``across`` over its straight 12 m."""
    x, y = np.meshgrid(np.linspace(-8, 8, 201), np.linspace(-6, 6, across + 1), indexing="ij")
    vertices = np.c_[x.ravel(), y.ravel(), (3 * (1 - (x / 8) ** 2)).ravel()]
    return vertices, grid_triangles(200, across)


def _edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    directed = np.sort(np.stack([faces, np.roll(faces, -1, axis=1)], axis=-1).reshape(-1, 2), axis=1)
    return np.unique(directed, axis=0, return_counts=True)


def _areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    corners = vertices[faces]
    return np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])


@pytest.mark.parametrize("longest", [2.0, 0.5, 0.13])
def test_long_edges_are_split_conformingly_on_the_surface(longest):
    vertices, faces = _vault_strips(across=3)
    out, out_faces = split_long_edges(vertices, faces, longest)
    edges, counts = _edges(out_faces)
    assert np.linalg.norm(out[edges[:, 1]] - out[edges[:, 0]], axis=1).max() <= longest
    assert counts.max() == 2 and len(boundary_loops(out_faces)) == 1  # no crack, no overlap
    n_vertices, n_edges, n_faces = len(out), len(edges), len(out_faces)
    assert n_vertices - n_edges + n_faces == 1  # still a disc
    assert np.array_equal(out[: len(vertices)], vertices)  # the first vertices keep their ids
    # each new facet lies in its parent's plane: total vector area unchanged, so the area and orientation
    assert _areas(out, out_faces).sum(axis=0) == pytest.approx(_areas(vertices, faces).sum(axis=0), rel=1e-10)
    assert np.abs(_areas(out, out_faces)).sum() == pytest.approx(np.abs(_areas(vertices, faces)).sum(), rel=1e-10)
