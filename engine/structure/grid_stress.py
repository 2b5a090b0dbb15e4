"""Membrane forces of a beam grid: the force flow of its axial forces, smeared over the surface.

At each grid node the membrane force tensor (N/m) is the force flow of the beams that meet there
over the node's tributary area,

    n = sum_b w_b N_b (t_b t_b^T) (L_b / 2) / A_node,

N_b the beam's axial force (N, tension > 0), t_b its unit direction, L_b its length; A_node the
node's share of its cells (each cell's area shared equally by its nodes, as the area loads are);
w_b = (cells along the beam) / 2, so that a boundary beam, which borders half a strip of the
continuum, counts half. A flat lattice of spacing s whose x-beams carry N_x and y-beams N_y gives
n_xx = N_x / s, n_yy = N_y / s, n_xy = 0 at every node, corners and edges included. The tensor is
projected into the tangent plane at each node and carried to the vertices of a surface mesh by
inverse-distance weighting of the nearest nodes, in the form the guiding field takes
(engine.remeshing.field.guiding_field: (n_vertices, 3, 3) in global axes).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..errors import InputError
from ..linalg import in_tangent_planes, tangent_projectors
from ..mesh import PolyMesh, TriMesh

__all__ = ["node_membrane_forces", "surface_membrane_forces", "beam_cell_counts", "node_tributary_areas"]

#: Grid nodes whose tensors are averaged at each surface vertex.
NEAREST_NODES = 4


def beam_cell_counts(polymesh: PolyMesh) -> np.ndarray:
    """(n_beams,) number of cells along each beam (1 on the boundary, 2 inside), in ``polymesh.edges`` order."""
    node, following, _ = polymesh.corner_table
    _, counts = np.unique(np.sort(np.stack([node, following], axis=1), axis=1), axis=0, return_counts=True)
    return counts


def node_tributary_areas(polymesh: PolyMesh) -> np.ndarray:
    """(n_nodes,) each node's share of its cells' areas, m^2 (a cell's area shared equally by its nodes)."""
    owner_area = np.repeat(polymesh.face_areas() / polymesh.face_degrees, polymesh.face_degrees)
    return np.bincount(np.concatenate(polymesh.faces), weights=owner_area, minlength=polymesh.n_nodes)


def node_membrane_forces(polymesh: PolyMesh, axial_forces: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(n_nodes, 3, 3) membrane force tensors, N/m, in global axes and in the tangent plane of
    ``normals`` (n_nodes, 3, unit), from the beams' axial forces (n_beams,), N, tension > 0."""
    axial = np.asarray(axial_forces, dtype=float)
    edges = polymesh.edges
    if axial.shape != (len(edges),) or not np.all(np.isfinite(axial)):
        raise InputError(f"grid stress: need one finite axial force per beam ({len(edges)},), got {axial.shape}")
    normals = np.asarray(normals, dtype=float)
    if normals.shape != (polymesh.n_nodes, 3):
        raise InputError(f"grid stress: need one normal per node ({polymesh.n_nodes}, 3), got {normals.shape}")
    axis = polymesh.nodes[edges[:, 1]] - polymesh.nodes[edges[:, 0]]
    lengths = np.linalg.norm(axis, axis=1)
    t = axis / np.maximum(lengths, 1e-300)[:, None]
    weight = 0.5 * beam_cell_counts(polymesh)
    # each end takes half the beam: (b, 3, 3) N m
    half = np.einsum("b,bi,bj->bij", weight * axial * 0.5 * lengths, t, t)
    flow = np.zeros((polymesh.n_nodes, 3, 3))
    np.add.at(flow, edges[:, 0], half)
    np.add.at(flow, edges[:, 1], half)
    area = node_tributary_areas(polymesh)
    tensors = np.where((area > 0)[:, None, None], flow / np.where(area > 0, area, 1.0)[:, None, None], 0.0)
    return _tangent(tensors, normals)


def _tangent(tensors: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """P T P with P = I - n n^T: (n, 3, 3) tensors projected into the tangent planes."""
    return in_tangent_planes(tensors, tangent_projectors(normals))


def surface_membrane_forces(mesh: TriMesh, polymesh: PolyMesh, axial_forces: np.ndarray,
                            node_normals: np.ndarray) -> np.ndarray:
    """(n_vertices, 3, 3) membrane force tensors, N/m, at the vertices of ``mesh``, in global axes
    and in each vertex's tangent plane: the grid's node tensors (node_membrane_forces) averaged over
    the NEAREST_NODES nearest nodes with weights 1 / distance^2 (a vertex on a node takes its tensor)."""
    nodes = node_membrane_forces(polymesh, axial_forces, node_normals)
    k = min(NEAREST_NODES, polymesh.n_nodes)
    distance, nearest = cKDTree(polymesh.nodes).query(mesh.vertices, k=k)
    distance, nearest = distance.reshape(len(mesh.vertices), k), nearest.reshape(len(mesh.vertices), k)
    scale = max(float(np.median(polymesh.beam_lengths)), 1e-300) if len(polymesh.edges) else 1.0
    weights = 1.0 / np.maximum(distance / scale, 1e-9) ** 2
    weights /= weights.sum(axis=1, keepdims=True)
    # (v vertices, k nodes): T_v = sum_k w_vk T_k
    tensors = np.einsum("vk,vkij->vij", weights, nodes[nearest])
    return _tangent(tensors, mesh.vertex_normals)
