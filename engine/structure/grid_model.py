"""From a polygonal grid-shell to a frame model with its loads.

Beams are the PolyMesh edges with one cross-section; each beam's strong axis follows the
surface normal (its ``up`` vector is the mean of its end nodes' normals). Loads of a
``LoadCase`` on the grid-shell: beam self-weight (half of each beam to each end node),
area loads on the cells by tributary area (a cell's load shared equally by its nodes:
true area for cladding, plan area for snow), and point loads at the nodes nearest to
the surface vertices where the project put them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..mesh import PolyMesh, TriMesh
from .loads import GRAVITY, LoadCase

__all__ = ["BeamProperties", "node_normals", "beam_up_vectors", "gridshell_loads", "support_restraints"]


@dataclass(frozen=True, kw_only=True)
class BeamProperties:
    """One cross-section and material for every beam (SI): E, G (Pa), A (m^2), Iy (strong
    axis, m^4), Iz, J (m^4), mass_per_length (kg/m)."""

    E: float
    G: float
    A: float
    Iy: float
    Iz: float
    J: float
    mass_per_length: float


def node_normals(polymesh: PolyMesh, reference: TriMesh | None = None, symmetry_planes: tuple = ()) -> np.ndarray:
    """(n_nodes, 3) unit normals: of the nearest reference-surface vertex where given, else
    the sum of the adjacent cells' vector areas; oriented like the cells (up or out). With
    ``symmetry_planes`` ((point, normal) pairs, m), the normals of mirror-image nodes (within
    SYMMETRY_TOLERANCE of the mean beam) are made mirror images too: a symmetric grid on a surface
    triangulated without its symmetry has symmetric joints and beam axes."""
    normals = _node_normals(polymesh, reference)
    if symmetry_planes and len(polymesh.edges):
        from ..geometry.symmetry import SYMMETRY_TOLERANCE, mirror_partners, symmetrise_directions

        reach = SYMMETRY_TOLERANCE * float(polymesh.beam_lengths.mean())
        planes = list(symmetry_planes)
        normals = symmetrise_directions(normals, planes, mirror_partners(polymesh.nodes, planes, reach))
    return normals


def _node_normals(polymesh: PolyMesh, reference: TriMesh | None) -> np.ndarray:
    areas = polymesh.face_vector_areas()
    node, _, cell = polymesh.corner_table
    acc = np.stack([np.bincount(node, weights=areas[cell, k], minlength=polymesh.n_nodes) for k in range(3)], axis=1)
    if reference is not None:
        _, nearest = cKDTree(reference.vertices).query(polymesh.nodes)
        surface_normals = reference.vertex_normals[nearest]
        flip = np.einsum("ij,ij->i", surface_normals, acc) < 0
        acc = np.where(flip[:, None], -surface_normals, surface_normals)
    norm = np.linalg.norm(acc, axis=1, keepdims=True)
    fallback = np.array([0.0, 0.0, 1.0])
    return np.where(norm > 1e-12, acc / np.where(norm > 0, norm, 1.0), fallback)


def beam_up_vectors(polymesh: PolyMesh, normals: np.ndarray) -> np.ndarray:
    """(n_beams, 3) up vector per beam: its end normals' mean, made normal to the beam axis."""
    e = polymesh.edges
    axis = polymesh.nodes[e[:, 1]] - polymesh.nodes[e[:, 0]]
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    up = normals[e[:, 0]] + normals[e[:, 1]]
    up -= np.einsum("ij,ij->i", up, axis)[:, None] * axis
    norm = np.linalg.norm(up, axis=1)
    degenerate = norm < 1e-9
    if degenerate.any():  # a beam along the normal: any perpendicular will do
        trial = np.where(np.abs(axis[degenerate, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
        up[degenerate] = trial - np.einsum("ij,ij->i", trial, axis[degenerate])[:, None] * axis[degenerate]
        norm = np.linalg.norm(up, axis=1)
    return up / norm[:, None]


def gridshell_loads(polymesh: PolyMesh, case: LoadCase, *, mass_per_length: float,
                    surface_vertices: np.ndarray | None = None) -> np.ndarray:
    """(n_nodes, 6) nodal loads (N, N m) of a load case on the grid-shell.

    Self-weight: ``case.self_weight`` x beam weight, half to each end. Area loads: per cell,
    true area x ``area_true`` + plan area x ``area_plan``, shared equally by the cell's
    nodes. Point loads: ``case.point_nodes`` are surface vertex ids; each goes to the
    grid-shell node nearest to that vertex (``surface_vertices`` (n_v, 3) needed then).
    """
    loads = np.zeros((polymesh.n_nodes, 6))
    if case.self_weight:
        weight = case.self_weight * mass_per_length * GRAVITY * polymesh.beam_lengths
        e = polymesh.edges
        np.add.at(loads[:, 2], e[:, 0], -0.5 * weight)
        np.add.at(loads[:, 2], e[:, 1], -0.5 * weight)
    if np.any(case.area_true) or np.any(case.area_plan):
        vector_areas = polymesh.face_vector_areas()
        true_area = np.linalg.norm(vector_areas, axis=1)
        plan_area = np.abs(vector_areas[:, 2])
        resultants = true_area[:, None] * case.area_true + plan_area[:, None] * case.area_plan
        for face, resultant in zip(polymesh.faces, resultants):
            loads[face, :3] += resultant / len(face)
    if len(case.point_nodes):
        if surface_vertices is None:
            raise ValueError("point loads on a grid-shell need the surface vertices they refer to")
        _, nearest = cKDTree(polymesh.nodes).query(surface_vertices[case.point_nodes])
        np.add.at(loads, nearest, case.point_forces)
    return loads


def support_restraints(polymesh: PolyMesh, surface_supports_nodes: np.ndarray,
                       surface_restraints: np.ndarray, surface_vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(node ids, (k, 6) flags) of the grid-shell's supports.

    Each supported grid-shell node (``polymesh.supports``) takes the restraint of the
    nearest supported surface vertex.
    """
    nodes = np.flatnonzero(polymesh.supports)
    if len(nodes) == 0:
        return nodes, np.zeros((0, 6), dtype=bool)
    _, nearest = cKDTree(surface_vertices[surface_supports_nodes]).query(polymesh.nodes[nodes])
    return nodes, np.asarray(surface_restraints, dtype=bool)[nearest]
