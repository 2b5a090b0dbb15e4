"""Linear static analysis of a triangulated surface as a thin shell (METHOD.md section 1).

Flat facet elements with 6 DOF per node (ux, uy, uz, rx, ry, rz): a constant-strain membrane
with a drilling rotation tied to the membrane's in-plane rotation (Hughes-Brezzi style
penalty, so the six rigid-body modes stay free and flat meshes have no spurious drilling
mode) and the discrete Kirchhoff triangle (DKT, Batoz, Bathe & Ho 1980) for bending. Every
kernel runs over all elements at once; the stiffness is assembled once as a sparse matrix and
factored once. Why our own elements and not pyfe3d's: docs/decisions.md.

Units: any consistent set; SI (m, N, Pa) in the workflow.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..errors import InputError, MechanismError
from ..linalg import (
    assemble_blocks,
    block_diagonal,
    congruent,
    count_free_rigid_modes,
    free_rigid_motions,
    in_tangent_planes,
    node_dofs,
    tangent_projectors,
)
from ..mesh import TriMesh
from .loads import GRAVITY, LoadCase, equilibrium_error, resultant
from .supports import Supports

__all__ = ["ShellMaterial", "ShellResult", "shell_nodal_loads", "analyse_shell", "shell_stiffness"]

#: Drilling penalty: k = DRILLING_FACTOR * G t A per node; small enough not to stiffen bending.
DRILLING_FACTOR = 1e-3



@dataclass(frozen=True, kw_only=True)
class ShellMaterial:
    """Isotropic linear elastic material: E (Pa), Poisson's ratio nu, density (kg/m^3)."""

    E: float
    nu: float
    density: float = 0.0

    def __post_init__(self) -> None:
        if not (self.E > 0 and np.isfinite(self.E)):
            raise InputError(f"shell material: E must be positive, got {self.E}")
        if not (-1.0 < self.nu < 0.5):
            raise InputError(f"shell material: Poisson's ratio must lie in (-1, 0.5), got {self.nu}")


@dataclass(frozen=True, kw_only=True)
class ShellResult:
    """Results of a linear static shell analysis (n vertices, m triangles).

    displacements (n, 6) and reactions (n, 6) in global axes (reactions zero where free);
    face_frames (m, 3, 3): rows e1, e2, normal of each facet; face_membrane_forces (m, 3):
    Nxx, Nyy, Nxy (N/m) and face_moments (m, 3): Mxx, Myy, Mxy (N m/m) in that frame;
    face_principal_forces (m, 2): N1 >= N2; face_principal_directions (m, 3): unit vector of
    N1; vertex_membrane_forces (n, 3, 3): area-weighted averages of the incident facets'
    force tensors, projected onto each vertex's tangent plane, in global axes;
    vertex_principal_forces (n, 2) and vertex_principal_directions (n, 3) of those;
    load_total (6,): resultant force and moment about the origin of the applied loads;
    equilibrium_error: |loads + reactions| (forces and moments) / |loads|; solver: the library
    that factored the stiffness (engine.structure.solvers); analysed_triangles: the triangles of the
    mesh the stiffness was built on (a well-shaped copy's where they differ from the mesh's, see
    ``analyse_shell``).
    """

    displacements: np.ndarray
    reactions: np.ndarray
    face_frames: np.ndarray
    face_membrane_forces: np.ndarray
    face_moments: np.ndarray
    face_principal_forces: np.ndarray
    face_principal_directions: np.ndarray
    vertex_membrane_forces: np.ndarray
    vertex_principal_forces: np.ndarray
    vertex_principal_directions: np.ndarray
    load_total: np.ndarray
    equilibrium_error: float
    solver: str = "superlu"
    analysed_triangles: int = 0


# ----------------------------------------------------------------------------- geometry

def _frames(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Facet frames (m,3,3), local 2D corner coordinates (m,3,2) and areas (m,)."""
    p = vertices[triangles]
    e1 = p[:, 1] - p[:, 0]
    normal = np.cross(e1, p[:, 2] - p[:, 0])
    double_area = np.linalg.norm(normal, axis=1)
    if np.any(double_area <= 1e-14 * max(np.ptp(vertices, axis=0).max(), 1e-300) ** 2):
        bad = int(np.argmin(double_area))
        raise InputError(f"triangle {bad} has (almost) zero area", hint="clean the mesh (degenerate faces)")
    normal /= double_area[:, None]
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = np.cross(normal, e1)
    frames = np.stack([e1, e2, normal], axis=1)
    local = np.einsum("mkj,mij->mik", frames[:, :2], p - p[:, :1])
    return frames, local, 0.5 * double_area


def _membrane_b(local: np.ndarray, area: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CST shape-function derivatives dN/dx, dN/dy (m,3) and strain matrix (m,3,6) for (u,v) per corner."""
    x, y = local[..., 0], local[..., 1]
    b = np.stack([y[:, 1] - y[:, 2], y[:, 2] - y[:, 0], y[:, 0] - y[:, 1]], axis=1) / (2 * area)[:, None]
    c = np.stack([x[:, 2] - x[:, 1], x[:, 0] - x[:, 2], x[:, 1] - x[:, 0]], axis=1) / (2 * area)[:, None]
    B = np.zeros((len(area), 3, 6))
    B[:, 0, 0::2] = b
    B[:, 1, 1::2] = c
    B[:, 2, 0::2] = c
    B[:, 2, 1::2] = b
    return b, c, B


def _dkt_b(local: np.ndarray, xi: float, eta: float) -> np.ndarray:
    """DKT curvature matrix (m,3,9) at area coordinates (xi, eta); DOFs (w, rx, ry) per corner."""
    x, y = local[..., 0], local[..., 1]
    x23, y23 = x[:, 1] - x[:, 2], y[:, 1] - y[:, 2]
    x31, y31 = x[:, 2] - x[:, 0], y[:, 2] - y[:, 0]
    x12, y12 = x[:, 0] - x[:, 1], y[:, 0] - y[:, 1]
    l23, l31, l12 = x23**2 + y23**2, x31**2 + y31**2, x12**2 + y12**2
    P4, P5, P6 = -6 * x23 / l23, -6 * x31 / l31, -6 * x12 / l12
    q4, q5, q6 = 3 * x23 * y23 / l23, 3 * x31 * y31 / l31, 3 * x12 * y12 / l12
    r4, r5, r6 = 3 * y23**2 / l23, 3 * y31**2 / l31, 3 * y12**2 / l12
    t4, t5, t6 = -6 * y23 / l23, -6 * y31 / l31, -6 * y12 / l12
    a, e = 1 - 2 * xi, 1 - 2 * eta
    one = np.ones_like(P4)
    hx_xi = np.stack([P6 * a + (P5 - P6) * eta, q6 * a - (q5 + q6) * eta,
                      -4 * one + 6 * (xi + eta) + r6 * a - eta * (r5 + r6),
                      -P6 * a + eta * (P4 + P6), q6 * a - eta * (q6 - q4),
                      -2 * one + 6 * xi + r6 * a + eta * (r4 - r6),
                      -eta * (P5 + P4), eta * (q4 - q5), -eta * (r5 - r4)], axis=1)
    hy_xi = np.stack([t6 * a + eta * (t5 - t6), one + r6 * a - eta * (r5 + r6), -q6 * a + eta * (q5 + q6),
                      -t6 * a + eta * (t4 + t6), -one + r6 * a + eta * (r4 - r6), -q6 * a - eta * (q4 - q6),
                      -eta * (t4 + t5), eta * (r4 - r5), -eta * (q4 - q5)], axis=1)
    hx_eta = np.stack([-P5 * e - xi * (P6 - P5), q5 * e - xi * (q5 + q6),
                       -4 * one + 6 * (xi + eta) + r5 * e - xi * (r5 + r6),
                       xi * (P4 + P6), xi * (q4 - q6), -xi * (r6 - r4),
                       P5 * e - xi * (P4 + P5), q5 * e + xi * (q4 - q5),
                       -2 * one + 6 * eta + r5 * e + xi * (r4 - r5)], axis=1)
    hy_eta = np.stack([-t5 * e - xi * (t6 - t5), one + r5 * e - xi * (r5 + r6), -q5 * e + xi * (q5 + q6),
                       xi * (t4 + t6), xi * (r4 - r6), -xi * (q4 - q6),
                       t5 * e - xi * (t4 + t5), -one + r5 * e + xi * (r4 - r5), -q5 * e - xi * (q4 - q5)], axis=1)
    two_area = (x31 * y12 - x12 * y31)[:, None]
    B = np.stack([y31[:, None] * hx_xi + y12[:, None] * hx_eta,
                  -x31[:, None] * hy_xi - x12[:, None] * hy_eta,
                  -x31[:, None] * hx_xi - x12[:, None] * hx_eta + y31[:, None] * hy_xi + y12[:, None] * hy_eta],
                 axis=1)
    return B / two_area[:, None]


_GAUSS = ((0.5, 0.0), (0.5, 0.5), (0.0, 0.5))
#: Local DOF indices (of 18) of the membrane (u, v per corner), bending (w, rx, ry) and drilling (rz).
_MEMBRANE = np.array([0, 1, 6, 7, 12, 13])
_BENDING = np.array([2, 3, 4, 8, 9, 10, 14, 15, 16])
_DRILL = np.array([5, 11, 17])


def _elasticity(E: float, nu: float) -> np.ndarray:
    return E / (1 - nu**2) * np.array([[1, nu, 0], [nu, 1, 0], [0, 0, (1 - nu) / 2]])


def _local_stiffness(local: np.ndarray, area: np.ndarray, thickness: float, material: ShellMaterial) -> np.ndarray:
    """(m,18,18) facet stiffness in local axes."""
    m = len(area)
    D = _elasticity(material.E, material.nu)
    b, c, Bm = _membrane_b(local, area)
    # membrane and drilling act on (u, v) x 3 and rz x 3: one (m,9,9) block
    in_plane = np.zeros((m, 9, 9))
    in_plane[:, :6, :6] = thickness * area[:, None, None] * np.matmul(np.transpose(Bm, (0, 2, 1)), D @ Bm)
    # drilling: k * sum_i (rz_i - omega)^2 with omega = (dv/dx - du/dy) / 2 of the CST
    G = material.E / (2 * (1 + material.nu))
    k = DRILLING_FACTOR * G * thickness * area
    omega = np.zeros((m, 9))
    omega[:, 0:6:2] = -0.5 * c
    omega[:, 1:6:2] = 0.5 * b
    g = np.repeat(-omega[:, None, :], 3, axis=1)
    g[:, np.arange(3), 6 + np.arange(3)] += 1.0
    in_plane += k[:, None, None] * np.matmul(np.transpose(g, (0, 2, 1)), g)
    Db = D * thickness**3 / 12.0
    bending = np.zeros((m, 9, 9))
    for xi, eta in _GAUSS:
        B = _dkt_b(local, xi, eta)
        bending += np.matmul(np.transpose(B, (0, 2, 1)), Db @ B) * (area / 3.0)[:, None, None]
    K = np.zeros((m, 18, 18))
    plane_dofs = np.r_[_MEMBRANE, _DRILL]
    K[:, plane_dofs[:, None], plane_dofs[None, :]] = in_plane
    K[:, _BENDING[:, None], _BENDING[None, :]] = bending
    return K


def _rotation(frames: np.ndarray) -> np.ndarray:
    """(m,18,18) block-diagonal global-to-local transformation."""
    return block_diagonal(frames, 6)


def _dof_indices(triangles: np.ndarray) -> np.ndarray:
    return node_dofs(triangles)


def shell_stiffness(vertices: np.ndarray, triangles: np.ndarray, thickness: float,
                    material: ShellMaterial) -> tuple[sp.csc_matrix, dict]:
    """Global stiffness (6n x 6n, CSC) and the per-facet data stress recovery needs."""
    frames, local, area = _frames(vertices, triangles)
    T = _rotation(frames)
    K_local = _local_stiffness(local, area, thickness, material)
    K_global = congruent(T, K_local)
    dofs = _dof_indices(triangles)
    K = assemble_blocks(K_global, triangles, len(vertices))
    return K, {"frames": frames, "local": local, "area": area, "T": T, "dofs": dofs}


# ----------------------------------------------------------------------------- loads

def shell_nodal_loads(mesh: TriMesh, case: LoadCase, *, thickness: float, density: float) -> np.ndarray:
    """(n, 6) nodal loads (N, N m) of a load case on the shell, a third of each facet to a corner.

    Self-weight: ``case.self_weight`` x density x g x thickness per true area, downward (-z);
    ``area_true`` per true area and ``area_plan`` per plan area (N/m^2, global vectors); point loads.
    """
    loads = case.point_load_array(mesh.n_vertices)
    resultant = (mesh.face_areas[:, None] * case.area_true + mesh.face_plan_areas[:, None] * case.area_plan)
    if case.self_weight:
        resultant[:, 2] -= case.self_weight * density * GRAVITY * thickness * mesh.face_areas
    for k in range(3):
        np.add.at(loads[:, :3], mesh.faces[:, k], resultant / 3.0)
    return loads


def _factor(K_free: sp.csc_matrix, library: str = "auto"):
    """The factor of the free stiffness (engine.structure.solvers: SuperLU, or PARDISO for large shells when
    it is installed), or MechanismError when it is singular."""
    from .solvers import SingularMatrix, factor_symmetric

    try:
        factor = factor_symmetric(K_free, library=library)
    except SingularMatrix as exc:
        raise MechanismError("the shell is a mechanism: its stiffness matrix is singular", n_modes=1,
                             hint="add supports or check for loose parts of the surface") from exc
    # a positive definite stiffness has neither near-zero nor negative pivots
    n_modes = factor.tiny_pivots + factor.negative_pivots
    if n_modes:
        raise MechanismError(f"the shell is a mechanism with {n_modes} free mode(s) beyond rigid-body motion",
                             n_modes=n_modes, hint="add supports or check for loose parts of the surface")
    return factor


# ----------------------------------------------------------------------------- analysis

def _principal(tensors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Principal values (k,2) descending and the angle (k,) of the first of 2D tensors [xx, yy, xy]."""
    xx, yy, xy = tensors[:, 0], tensors[:, 1], tensors[:, 2]
    centre = 0.5 * (xx + yy)
    radius = np.hypot(0.5 * (xx - yy), xy)
    angle = 0.5 * np.arctan2(2 * xy, xx - yy)
    return np.stack([centre + radius, centre - radius], axis=1), angle


def _global_tensors(frames: np.ndarray, components: np.ndarray) -> np.ndarray:
    """(m,3,3) global tensors of the facets' [xx, yy, xy] components in their frames."""
    e1, e2 = frames[:, 0], frames[:, 1]
    return (components[:, 0, None, None] * np.einsum("mi,mj->mij", e1, e1)
            + components[:, 1, None, None] * np.einsum("mi,mj->mij", e2, e2)
            + components[:, 2, None, None] * (np.einsum("mi,mj->mij", e1, e2) + np.einsum("mi,mj->mij", e2, e1)))


def _local_components(frames: np.ndarray, tensors: np.ndarray) -> np.ndarray:
    """(m,3) [xx, yy, xy] components of global tensors (m,3,3) in the facets' frames."""
    e1, e2 = frames[:, 0], frames[:, 1]
    return np.stack([np.einsum("mi,mij,mj->m", e1, tensors, e1), np.einsum("mi,mij,mj->m", e2, tensors, e2),
                     np.einsum("mi,mij,mj->m", e1, tensors, e2)], axis=1)


def _tangent(tensors: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Tensors (n,3,3) projected onto the tangent planes of the unit normals (n,3)."""
    return in_tangent_planes(tensors, tangent_projectors(normals))


def _vertex_tensors(mesh: TriMesh, frames: np.ndarray, forces: np.ndarray, area: np.ndarray) -> np.ndarray:
    """(n,3,3) area-weighted vertex averages of the facet tensors, in each vertex's tangent plane."""
    tensor = _global_tensors(frames, forces)
    total = np.zeros((mesh.n_vertices, 3, 3))
    weight = np.zeros(mesh.n_vertices)
    for k in range(3):
        np.add.at(total, mesh.faces[:, k], tensor * area[:, None, None])
        np.add.at(weight, mesh.faces[:, k], area)
    total /= np.maximum(weight, 1e-300)[:, None, None]
    return _tangent(total, mesh.vertex_normals)


def _tangent_principal(tensors: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Principal values (n,2) descending and unit direction (n,3) of the first, for tangent tensors."""
    u = np.cross(normals, np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    u /= np.linalg.norm(u, axis=1)[:, None]
    v = np.cross(normals, u)
    local = np.stack([np.einsum("ni,nij,nj->n", u, tensors, u), np.einsum("ni,nij,nj->n", v, tensors, v),
                      np.einsum("ni,nij,nj->n", u, tensors, v)], axis=1)
    values, angle = _principal(local)
    direction = np.cos(angle)[:, None] * u + np.sin(angle)[:, None] * v
    return values, direction


def analyse_shell(mesh: TriMesh, supports: Supports, loads: np.ndarray, *, thickness: float,
                  material: ShellMaterial, max_triangles: int | None = None,
                  distributed: Callable[[TriMesh], np.ndarray] | None = None) -> ShellResult:
    """Linear static analysis of ``mesh`` as a shell of uniform ``thickness`` (m).

    loads: (n, 6) nodal forces and moments in global axes. Raises MechanismError (with the
    number of free rigid-body modes) when the supports do not hold the shell.

    max_triangles: a mesh with more triangles is analysed on a coarser copy of about that many, and one
    whose triangles are mostly slivers on a well-shaped copy (engine.remeshing.analysis_mesh); the
    results are carried back to its own vertices and faces. None: the mesh as it is.
    distributed: the nodal loads of the distributed part of ``loads`` (area loads, self-weight) on
    any mesh of the surface; a copy gets them from its own facets, and the rest of ``loads`` (point
    loads) from the mesh's vertices. Without it, all of ``loads`` is carried from the vertices, which
    on a mesh of slivers puts a whole strip's load on its two ends.
    """
    if not (np.isfinite(thickness) and thickness > 0):
        raise InputError(f"shell thickness must be positive, got {thickness}")
    loads = np.asarray(loads, dtype=float)
    n = mesh.n_vertices
    if loads.shape != (n, 6) or not np.all(np.isfinite(loads)):
        raise InputError(f"shell loads must be a finite ({n}, 6) array, got shape {loads.shape}")
    if len(supports.nodes) and (supports.nodes.max() >= n or supports.nodes.min() < 0):
        raise InputError(f"a support node is out of range 0..{n - 1}")
    if max_triangles is not None:
        from ..remeshing.analysis_mesh import copy_triangles

        triangles = copy_triangles(mesh, max_triangles)
        if triangles is not None:
            return _analyse_on_copy(mesh, supports, loads, thickness=thickness, material=material,
                                    triangles=triangles, distributed=distributed)
    restrained = np.asarray(supports.dof_mask(n), dtype=bool).ravel()
    free_rigid = count_free_rigid_modes(mesh.vertices, restrained)
    if free_rigid:
        raise MechanismError(f"the shell is a mechanism: its supports leave {free_rigid} rigid-body "
                             f"mode(s) free ({', '.join(free_rigid_motions(mesh.vertices, restrained))})",
                             n_modes=free_rigid,
                             hint="support more nodes or restrain more directions (e.g. pinned instead of rollers)")
    K, data = shell_stiffness(mesh.vertices, mesh.faces, thickness, material)
    free = np.flatnonzero(~restrained)
    factor = _factor(K[free][:, free].tocsc())
    solve = factor.solve
    u = np.zeros(6 * n)
    f = loads.ravel()
    u[free] = solve(f[free])
    if not np.all(np.isfinite(u)):
        raise MechanismError("the shell is a mechanism (the solution is not finite)", n_modes=1,
                             hint="add supports")
    reactions = (K @ u - f).reshape(n, 6)
    reactions[~restrained.reshape(n, 6)] = 0.0
    displacements = u.reshape(n, 6)
    # stresses
    element_u = np.einsum("mij,mj->mi", data["T"], u[data["dofs"]])
    _, _, Bm = _membrane_b(data["local"], data["area"])
    D = _elasticity(material.E, material.nu)
    membrane = thickness * np.einsum("kl,mlj,mj->mk", D, Bm, element_u[:, _MEMBRANE])
    moments = (thickness**3 / 12.0) * np.einsum("kl,mlj,mj->mk", D, _dkt_b(data["local"], 1 / 3, 1 / 3),
                                                element_u[:, _BENDING])
    principal, angle = _principal(membrane)
    frames = data["frames"]
    direction = np.cos(angle)[:, None] * frames[:, 0] + np.sin(angle)[:, None] * frames[:, 1]
    vertex_tensors = _vertex_tensors(mesh, frames, membrane, data["area"])
    vertex_values, vertex_directions = _tangent_principal(vertex_tensors, mesh.vertex_normals)
    total = resultant(mesh.vertices, loads)
    error = equilibrium_error(mesh.vertices, loads, reactions, size=mesh.diagonal)
    return ShellResult(displacements=displacements, reactions=reactions, face_frames=frames,
                       face_membrane_forces=membrane, face_moments=moments, face_principal_forces=principal,
                       face_principal_directions=direction, vertex_membrane_forces=vertex_tensors,
                       vertex_principal_forces=vertex_values, vertex_principal_directions=vertex_directions,
                       load_total=total, equilibrium_error=error, solver=factor.library,
                       analysed_triangles=mesh.n_faces)


def _analyse_on_copy(mesh: TriMesh, supports: Supports, loads: np.ndarray, *, thickness: float,
                     material: ShellMaterial, triangles: int,
                     distributed: Callable[[TriMesh], np.ndarray] | None) -> ShellResult:
    """``analyse_shell`` on a well-shaped copy of ``mesh`` (about ``triangles``), carried back to ``mesh``.

    Distributed loads are those of the copy's facets, the rest go to the copy by the interpolation's
    transpose (forces conserved); each support vertex restrains its nearest vertex of the copy;
    displacements and vertex forces are interpolated back, each face takes the forces and moments of
    the copy's facet under its centroid, and the copy's reactions land on the mesh's support
    vertices nearest to them (totals conserved).
    """
    from ..geometry.surface_map import surface_map
    from ..remeshing.analysis_mesh import analysis_mesh

    link = surface_map(mesh, analysis_mesh(mesh, triangles))
    copy = link.coarse
    patterns, which = np.unique(supports.restraints, axis=0, return_inverse=True)
    copy_supports = Supports.merge([(np.unique(link.nearest[supports.nodes[which.ravel() == k]]), flags)
                                    for k, flags in enumerate(patterns)])
    if distributed is None:
        copy_loads = link.to_coarse(loads)
    else:  # the copy's own facets' loads, scaled to the surface's total (their areas differ slightly)
        spread, own = distributed(mesh), distributed(copy)
        total, copy_total = np.linalg.norm(spread[:, :3].sum(axis=0)), np.linalg.norm(own[:, :3].sum(axis=0))
        copy_loads = own * (total / copy_total if copy_total > 0 else 1.0) + link.to_coarse(loads - spread)
    done = analyse_shell(copy, copy_supports, copy_loads, thickness=thickness, material=material)
    reactions = np.zeros((mesh.n_vertices, 6))
    if len(supports.nodes):
        held = done.reactions[copy_supports.nodes]
        _, landing = cKDTree(mesh.vertices[supports.nodes]).query(copy.vertices[copy_supports.nodes])
        np.add.at(reactions, supports.nodes[landing], held)
    frames = _frames(mesh.vertices, mesh.faces)[0]
    under = link.face_faces
    membrane = _local_components(frames, _global_tensors(done.face_frames, done.face_membrane_forces)[under])
    moments = _local_components(frames, _global_tensors(done.face_frames, done.face_moments)[under])
    principal, angle = _principal(membrane)
    direction = np.cos(angle)[:, None] * frames[:, 0] + np.sin(angle)[:, None] * frames[:, 1]
    vertex_tensors = _tangent(link.to_fine(done.vertex_membrane_forces), mesh.vertex_normals)
    vertex_values, vertex_directions = _tangent_principal(vertex_tensors, mesh.vertex_normals)
    return ShellResult(displacements=link.to_fine(done.displacements), reactions=reactions, face_frames=frames,
                       face_membrane_forces=membrane, face_moments=moments, face_principal_forces=principal,
                       face_principal_directions=direction, vertex_membrane_forces=vertex_tensors,
                       vertex_principal_forces=vertex_values, vertex_principal_directions=vertex_directions,
                       load_total=resultant(mesh.vertices, loads), equilibrium_error=done.equilibrium_error,
                       solver=done.solver, analysed_triangles=copy.n_faces)


# ----------------------------------------------------------------------------- JSON interface
