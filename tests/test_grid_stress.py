"""Membrane forces of a beam grid against closed forms: the force flow of a square lattice."""

from __future__ import annotations

import numpy as np
import pytest

from engine.errors import InputError
from engine.geometry.parametric import grid_triangles
from engine.mesh import PolyMesh, TriMesh
from engine.remeshing.field import FieldSettings, guiding_field
from engine.structure.grid_stress import node_membrane_forces, node_tributary_areas, surface_membrane_forces


def _lattice(n: int, spacing: float, angle_deg: float = 0.0) -> PolyMesh:
    """n x n square cells of side ``spacing``, turned by ``angle_deg`` about z."""
    xs = spacing * np.arange(n + 1)
    x, y = np.meshgrid(xs, xs, indexing="ij")
    nodes = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    turn = np.radians(angle_deg)
    R = np.array([[np.cos(turn), -np.sin(turn), 0.0], [np.sin(turn), np.cos(turn), 0.0], [0.0, 0.0, 1.0]])
    ids = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    faces = [np.array([ids[i, j], ids[i + 1, j], ids[i + 1, j + 1], ids[i, j + 1]]) for i in range(n) for j in range(n)]
    return PolyMesh(nodes=nodes @ R.T, faces=faces)


def _lattice_forces(grid: PolyMesh, N_x: float, N_y: float, angle_deg: float = 0.0) -> np.ndarray:
    """N_x in the beams along the lattice's first axis, N_y in the others."""
    turn = np.radians(angle_deg)
    e = grid.edges
    axis = grid.nodes[e[:, 1]] - grid.nodes[e[:, 0]]
    along_x = np.abs(axis @ [np.cos(turn), np.sin(turn), 0.0]) > 0.5 * np.linalg.norm(axis, axis=1)
    return np.where(along_x, N_x, N_y)


def _up(n: int) -> np.ndarray:
    return np.tile([0.0, 0.0, 1.0], (n, 1))


@pytest.mark.parametrize("spacing", [0.5, 2.0])
def test_a_square_lattice_carries_n_equal_to_the_beam_force_over_the_spacing_at_every_node(spacing):
    grid = _lattice(6, spacing)
    N_x, N_y = -3000.0, 1200.0
    tensors = node_membrane_forces(grid, _lattice_forces(grid, N_x, N_y), _up(grid.n_nodes))
    assert node_tributary_areas(grid).sum() == pytest.approx((6 * spacing) ** 2)
    # the interior by the conservation of the force flow; edges and corners by their half-weight beams
    assert np.allclose(tensors[:, 0, 0], N_x / spacing)
    assert np.allclose(tensors[:, 1, 1], N_y / spacing)
    assert np.allclose(tensors[:, 0, 1], 0.0) and np.allclose(tensors[:, 2], 0.0)


@pytest.mark.parametrize("angle_deg", [30.0, 45.0, 110.0])
def test_a_turned_lattice_turns_the_tensor(angle_deg):
    grid = _lattice(5, 1.0, angle_deg)
    N_x, N_y = -2000.0, -500.0
    tensors = node_membrane_forces(grid, _lattice_forces(grid, N_x, N_y, angle_deg), _up(grid.n_nodes))
    turn = np.radians(angle_deg)
    R = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    expected = R @ np.diag([N_x, N_y]) @ R.T
    assert np.allclose(tensors[:, :2, :2], expected)


def test_a_tilted_beam_is_projected_into_the_tangent_plane():
    grid = _lattice(2, 1.0)
    nodes = np.asarray(grid.nodes).copy()
    nodes[:, 2] = 0.3 * nodes[:, 0]  # a plane rising along x
    grid = grid.replace_nodes(nodes)
    normal = np.array([-0.3, 0.0, 1.0]) / np.hypot(0.3, 1.0)
    tensors = node_membrane_forces(grid, np.full(len(grid.edges), -100.0), np.tile(normal, (grid.n_nodes, 1)))
    assert np.allclose(np.einsum("nij,j->ni", tensors, normal), 0.0)


def test_the_surface_gets_the_lattice_tensor_and_the_field_its_direction():
    grid = _lattice(8, 0.25)  # 2 m x 2 m
    xs = np.linspace(0.0, 2.0, 21)
    x, y = np.meshgrid(xs, xs, indexing="ij")
    mesh = TriMesh(vertices=np.c_[x.ravel(), y.ravel(), np.zeros(x.size)], faces=grid_triangles(20, 20))
    N_x, N_y = -4000.0, -1000.0
    tensors = surface_membrane_forces(mesh, grid, _lattice_forces(grid, N_x, N_y), _up(grid.n_nodes))
    assert tensors.shape == (mesh.n_vertices, 3, 3)
    assert np.allclose(tensors[:, 0, 0], N_x / 0.25) and np.allclose(tensors[:, 1, 1], N_y / 0.25)
    field = guiding_field(mesh, tensors, FieldSettings(max_aspect=3.0))
    assert np.allclose(np.abs(field.direction[:, 0]), 1.0)
    assert np.allclose(field.anisotropy, 2.0)  # sqrt(N1 / N2), same sign


def test_one_force_per_beam():
    grid = _lattice(2, 1.0)
    with pytest.raises(InputError, match="one finite axial force per beam"):
        node_membrane_forces(grid, np.zeros(3), _up(grid.n_nodes))
