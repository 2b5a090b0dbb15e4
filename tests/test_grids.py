"""Same-length reference grids: L_tot matched, nodes on the surface, regular cells inside."""

from __future__ import annotations

import numpy as np
import pytest

from engine.errors import InputError
from engine.grids import is_height_field, quad_grid, triangular_grid
from engine.mesh import TriMesh
from engine.parametric import cap, courtyard, mockup
from engine.proximity import closest_points


@pytest.mark.parametrize("make", [triangular_grid, quad_grid])
@pytest.mark.parametrize("surface", ["cap", "courtyard"])
def test_total_length_is_matched_within_one_percent(make, surface):
    mesh = cap() if surface == "cap" else courtyard()
    support = np.zeros(mesh.n_vertices, dtype=bool)
    support[mesh.boundary_loops[0]] = True
    target = 8.0 * np.sqrt(mesh.area) * 3
    grid = make(mesh, total_length=target, support_vertices=support)
    assert grid.total_length == pytest.approx(target, rel=0.01)
    assert closest_points(mesh.vertices, mesh.faces, grid.nodes)[1].max() < 1e-6 * mesh.diagonal
    sides = 3 if make is triangular_grid else 4
    inner = ~grid.face_boundary
    assert np.all(grid.face_degrees[inner] == sides), "cells away from the boundary are regular"
    lengths = grid.beam_lengths
    interior_beams = ~(grid.boundary[grid.edges[:, 0]] | grid.boundary[grid.edges[:, 1]])
    spread = np.ptp(lengths[interior_beams]) / lengths[interior_beams].mean()
    assert spread < 0.35, "lifted regular grid: interior beams of nearly one length"
    assert grid.supports.any() and np.all(grid.boundary[grid.supports])
    holes = len(mesh.boundary_loops) - 1
    assert grid.n_nodes - len(grid.edges) + grid.n_faces == 1 - holes


def test_square_mock_up_quad_grid_keeps_its_corners():
    mesh = mockup().mesh
    grid = quad_grid(mesh, total_length=55.0)
    assert grid.corners.sum() == 4


def test_surfaces_that_fold_over_are_refused():
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, 1.0]], float)
    mesh = TriMesh(vertices=vertices, faces=np.array([[0, 1, 2], [0, 3, 1]]))
    assert not is_height_field(mesh)
    with pytest.raises(InputError, match="height field"):
        triangular_grid(mesh, total_length=5.0)
