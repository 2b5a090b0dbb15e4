"""Face optimisation: fixed points of the local steps, planarity and regularity gains, constraints."""

from __future__ import annotations

import numpy as np
import pytest

from engine.field import GuidingField
from engine.optimize import OptimizeSettings, optimize, planar_targets, regular_targets
from engine.parametric import mockup
from engine.proximity import closest_points
from engine.voronoi import RemeshSettings, remesh


def _hexagon(stretch: float = 1.0, angle: float = 0.3) -> np.ndarray:
    t = 2 * np.pi * np.arange(6) / 6 + angle
    p = np.c_[stretch * np.cos(t), np.sin(t), np.zeros(6)]
    rotation = np.array([[np.cos(0.7), -np.sin(0.7), 0], [np.sin(0.7), np.cos(0.7), 0], [0, 0, 1]])
    tilt = np.array([[1, 0, 0], [0, np.cos(0.4), -np.sin(0.4)], [0, np.sin(0.4), np.cos(0.4)]])
    return (p @ rotation.T @ tilt.T + [3.0, -1.0, 2.0])[None]


@pytest.mark.parametrize("stretch", [1.0, 1.8])
def test_regular_and_stretched_hexagons_are_fixed_points(stretch):
    cell = _hexagon(stretch)
    assert np.allclose(regular_targets(cell), cell, atol=1e-9)
    assert np.allclose(regular_targets(cell[:, ::-1]), cell[:, ::-1], atol=1e-9), "either orientation"


def test_planar_targets_lie_in_a_plane_and_keep_planar_cells():
    cell = _hexagon()
    assert np.allclose(planar_targets(cell), cell, atol=1e-12)
    bent = cell.copy()
    bent[0, ::2, 2] += 0.2
    target = planar_targets(bent)[0]
    centred = target - target.mean(axis=0)
    assert np.linalg.svd(centred, compute_uv=False)[2] < 1e-12


@pytest.fixture(scope="module")
def mockup_grid():
    surface = mockup(divisions=16).mesh
    n = surface.n_vertices
    field = GuidingField(size=np.ones(n), anisotropy=np.ones(n), direction=np.tile([1.0, 0, 0], (n, 1)),
                         normals=surface.vertex_normals)
    support = np.zeros(n, dtype=bool)
    support[surface.boundary_loops[0]] = True
    grid = remesh(surface, field, RemeshSettings(n_cells=60, lloyd_iterations=40), support_vertices=support).polymesh
    return surface, field, grid


def test_optimisation_improves_planarity_and_regularity_and_keeps_constraints(mockup_grid):
    surface, field, grid = mockup_grid
    result = optimize(grid, surface, field, OptimizeSettings(iterations=60))
    before, after = result.quality["before"], result.quality["after"]
    assert after["planarity_max_rel"] < 0.6 * before["planarity_max_rel"]
    assert after["regularity"] < before["regularity"]
    assert after["closeness_max_rel"] < 0.03
    assert result.quality["factorisations"] == 1
    fixed = grid.corners | grid.supports
    assert np.array_equal(result.polymesh.nodes[fixed], grid.nodes[fixed])
    moved_boundary = grid.boundary & ~fixed
    if moved_boundary.any():
        segments = [surface.vertices[loop] for loop in surface.boundary_loops]
        on_edge = np.abs(np.abs(result.polymesh.nodes[moved_boundary, :2]).max(axis=1) - 1.2)
        assert on_edge.max() < 1e-9, "boundary nodes stay on the square's edge"
        del segments


def test_planarity_weight_trades_regularity(mockup_grid):
    surface, field, grid = mockup_grid
    planar = optimize(grid, surface, field, OptimizeSettings(iterations=40, regularity_weight=0.1)).quality["after"]
    regular = optimize(grid, surface, field, OptimizeSettings(iterations=40, planar=False)).quality["after"]
    assert planar["planarity_max_rel"] < regular["planarity_max_rel"]
    assert regular["regularity"] < planar["regularity"]
    nodes = optimize(grid, surface, field, OptimizeSettings(iterations=10, planar=False)).polymesh.nodes
    assert closest_points(surface.vertices, surface.faces, nodes)[1].max() < 0.05 * surface.diagonal
