"""Regular, planar cells that stay on the surface (METHOD.md section 4).

Local/global iterations in the manner of Shape-Up (Bouaziz et al. 2012). Local step, per
cell: (regularity) the PCA of its nodes, un-stretched by the square roots of the eigenvalues
so that the cell's own anisotropy is kept, a regular polygon of equal area fitted by a rigid
rotation, stretched back; (planarity) the nodes projected onto the best-fit plane. Per node:
(closeness) the nearest point of the reference surface; (fairness) the mean of its
neighbours. Global step: the weighted least-squares fit of all targets, with each cell's
targets compared after removing their mean (translation-free), so the system matrix is the
same every iteration and is factored once. Corners and supports are fixed; boundary nodes are
pulled back onto the surface's boundary after each step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .errors import InputError
from .field import GuidingField
from .mesh import PolyMesh, TriMesh
from .proximity import closest_points

__all__ = ["OptimizeSettings", "OptimizeResult", "optimize", "regular_targets", "planar_targets"]


@dataclass(frozen=True, kw_only=True)
class OptimizeSettings:
    """Weights of the four terms, the number of iterations, and whether panels must be planar
    (planar False: the planarity weight is ignored)."""

    regularity_weight: float = 1.0
    planarity_weight: float = 1.0
    closeness_weight: float = 1.0
    fairness_weight: float = 0.1
    iterations: int = 50
    planar: bool = True

    def __post_init__(self) -> None:
        for name in ("regularity_weight", "planarity_weight", "closeness_weight", "fairness_weight"):
            if not getattr(self, name) >= 0:
                raise InputError(f"optimize: {name} must be zero or positive, got {getattr(self, name)}")
        if self.iterations < 0:
            raise InputError(f"optimize: iterations must be zero or positive, got {self.iterations}")


@dataclass(frozen=True, kw_only=True)
class OptimizeResult:
    """The optimised grid-shell and the figures before and after (JSON-ready)."""

    polymesh: PolyMesh
    quality: dict


#: Internal scale of the planarity weight: planar panels need it to dominate at the end.
PLANARITY_SCALE = 20.0


def _groups(faces: tuple[np.ndarray, ...]) -> dict[int, np.ndarray]:
    """Faces grouped by degree: {k: (f_k, k) node ids}."""
    groups: dict[int, list[np.ndarray]] = {}
    for face in faces:
        groups.setdefault(len(face), []).append(face)
    return {k: np.array(v, dtype=np.int64) for k, v in groups.items()}


def _frames(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centroids (f,3), in-plane axes (f,2,3) and normals (f,3) of (f,k,3) point sets (PCA)."""
    centroid = points.mean(axis=1)
    _, _, vt = np.linalg.svd(points - centroid[:, None], full_matrices=False)
    return centroid, vt[:, :2], vt[:, 2]


def planar_targets(points: np.ndarray) -> np.ndarray:
    """(f,k,3) nodes projected onto each cell's best-fit plane."""
    centroid, _, normal = _frames(points)
    offset = np.einsum("fki,fi->fk", points - centroid[:, None], normal)
    return points - offset[..., None] * normal[:, None]


def regular_targets(points: np.ndarray) -> np.ndarray:
    """(f,k,3) the regular k-gon of equal area best fitting each cell after un-stretching it
    by its PCA axes, stretched back (a regular or affinely stretched regular cell is its own target)."""
    f, k, _ = points.shape
    centroid, axes, _ = _frames(points)
    local = np.einsum("fki,fji->fkj", points - centroid[:, None], axes)
    covariance = np.einsum("fki,fkj->fij", local, local) / k
    values, vectors = np.linalg.eigh(covariance)
    spread = np.sqrt(np.maximum(values, 1e-300))
    principal = np.einsum("fki,fij->fkj", local, vectors)
    unstretched = principal / spread[:, None, :]
    angle = 2 * np.pi * np.arange(k) / k
    template = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    signed = 0.5 * np.sum(unstretched[:, :, 0] * np.roll(unstretched[:, :, 1], -1, axis=1)
                          - np.roll(unstretched[:, :, 0], -1, axis=1) * unstretched[:, :, 1], axis=1)
    template = np.where((signed < 0)[:, None, None], template * [1.0, -1.0], template[None])
    unit_area = 0.5 * k * np.sin(2 * np.pi / k)
    scale = np.sqrt(np.abs(signed) / unit_area)
    # best rotation (2D Procrustes) of the template onto the cell
    dot = np.einsum("fki,fki->f", template, unstretched)
    cross = np.einsum("fk,fk->f", template[:, :, 0], unstretched[:, :, 1]) - np.einsum(
        "fk,fk->f", template[:, :, 1], unstretched[:, :, 0])
    phi = np.arctan2(cross, dot)
    c, s = np.cos(phi), np.sin(phi)
    rotated = np.stack([c[:, None] * template[:, :, 0] - s[:, None] * template[:, :, 1],
                        s[:, None] * template[:, :, 0] + c[:, None] * template[:, :, 1]], axis=2)
    fitted = rotated * scale[:, None, None]
    back = np.einsum("fkj,fij->fki", fitted * spread[:, None, :], vectors)
    return centroid[:, None] + np.einsum("fkj,fji->fki", back, axes)


def _centering_blocks(groups: dict[int, np.ndarray], n: int) -> sp.csr_matrix:
    """Rows (x_i - mean of its cell) for every cell corner, stacked over the degree groups."""
    rows, cols, vals, offset = [], [], [], 0
    for k, faces in groups.items():
        f = len(faces)
        row = offset + np.arange(f * k).reshape(f, k)
        for j in range(k):
            rows.append(np.repeat(row[:, j], k))
            cols.append(faces.ravel())
            vals.append(np.tile(np.where(np.arange(k) == j, 1.0 - 1.0 / k, -1.0 / k), f))
        offset += f * k
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(offset, n))


def _laplacian(edges: np.ndarray, n: int, active: np.ndarray) -> sp.csr_matrix:
    """Rows x_i - mean of neighbours for the ``active`` nodes."""
    adjacency = sp.csr_matrix((np.ones(2 * len(edges)), (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]])),
                              shape=(n, n))
    degree = np.maximum(np.asarray(adjacency.sum(axis=1)).ravel(), 1.0)
    L = sp.eye(n, format="csr") - sp.diags(1.0 / degree) @ adjacency
    return L[np.flatnonzero(active)]


def _stack_targets(groups: dict[int, np.ndarray], targets: dict[int, np.ndarray]) -> np.ndarray:
    """Mean-free targets of every cell corner, in the row order of _centering_blocks."""
    out = []
    for k in groups:
        t = targets[k]
        out.append((t - t.mean(axis=1, keepdims=True)).reshape(-1, 3))
    return np.concatenate(out)


def _boundary_polylines(mesh: TriMesh) -> np.ndarray:
    """(s,2,3) segments of the surface's boundary loops."""
    segments = []
    for loop in mesh.boundary_loops:
        p = mesh.vertices[loop]
        segments.append(np.stack([p, np.roll(p, -1, axis=0)], axis=1))
    return np.concatenate(segments) if segments else np.zeros((0, 2, 3))


def _onto_segments(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Closest points of ``points`` on a set of segments (brute force over segments, chunked)."""
    out = np.empty_like(points)
    a, b = segments[:, 0], segments[:, 1]
    d = b - a
    length2 = np.maximum(np.einsum("si,si->s", d, d), 1e-300)
    for start in range(0, len(points), 256):
        p = points[start:start + 256]
        t = np.clip(np.einsum("psi,si->ps", p[:, None] - a[None], d) / length2, 0.0, 1.0)
        q = a[None] + t[..., None] * d[None]
        nearest = np.argmin(np.einsum("psi,psi->ps", q - p[:, None], q - p[:, None]), axis=1)
        out[start:start + 256] = q[np.arange(len(p)), nearest]
    return out


def optimize(polymesh: PolyMesh, mesh: TriMesh, field: GuidingField | None, settings: OptimizeSettings, *,
             progress=None) -> OptimizeResult:
    """Regularise and planarise the cells of ``polymesh`` on the reference surface ``mesh``."""
    from .voronoi import polymesh_quality

    def say(text: str, fraction: float | None = None) -> None:
        if progress is not None:
            progress(text, fraction)

    n = polymesh.n_nodes
    before = polymesh_quality(polymesh, mesh=mesh)
    fixed = polymesh.corners | polymesh.supports
    free = np.flatnonzero(~fixed)
    groups = _groups(polymesh.faces)
    C = _centering_blocks(groups, n)
    w_reg = settings.regularity_weight
    w_plan = PLANARITY_SCALE * settings.planarity_weight if settings.planar else 0.0
    w_close, w_fair = settings.closeness_weight, settings.fairness_weight
    L = _laplacian(polymesh.edges, n, ~polymesh.boundary)
    # system: (w_reg + w_plan) C^T C + w_close I + w_fair L^T L  (a fixed matrix), in the free nodes
    A = (w_reg + w_plan) * (C.T @ C) + w_close * sp.eye(n) + w_fair * (L.T @ L)
    A = A.tocsc()
    A_free = A[free][:, free].tocsc()
    coupling = A[free][:, np.flatnonzero(fixed)]
    if len(free):
        solve = spla.factorized(A_free + 1e-12 * sp.eye(len(free), format="csc"))
    factorisations = 1
    x = polymesh.nodes.copy()
    segments = _boundary_polylines(mesh)
    moving_boundary = polymesh.boundary & ~fixed
    for iteration in range(settings.iterations):
        points = {k: x[faces] for k, faces in groups.items()}
        regular = _stack_targets(groups, {k: regular_targets(p) for k, p in points.items()}) if w_reg else 0.0
        planar = _stack_targets(groups, {k: planar_targets(p) for k, p in points.items()}) if w_plan else 0.0
        surface_points = closest_points(mesh.vertices, mesh.faces, x)[0]
        rhs = C.T @ (w_reg * regular + w_plan * planar) + w_close * surface_points
        if len(free):
            rhs_free = rhs[free] - coupling @ x[fixed]
            x[free] = np.column_stack([solve(rhs_free[:, k]) for k in range(3)])
        if moving_boundary.any():
            x[moving_boundary] = _onto_segments(x[moving_boundary], segments)
        say(f"iteration {iteration + 1}/{settings.iterations}", (iteration + 1) / max(settings.iterations, 1))
    # the nodes end on the surface; a last planarity projection follows only if it keeps them close
    result = polymesh.replace_nodes(x)
    after = polymesh_quality(result, mesh=mesh)
    keys = ("planarity_max_m", "planarity_p95_m", "planarity_max_rel", "planarity_p95_rel", "regularity",
            "closeness_max_rel", "closeness_mean_rel", "shortest_beam_m", "smallest_angle_deg", "hexagon_share_interior",
            "valence3_share_interior", "mean_beam_length_m", "total_length_m")
    quality = {"before": {k: before.get(k) for k in keys}, "after": {k: after.get(k) for k in keys},
               "iterations": settings.iterations, "factorisations": factorisations,
               "planar": settings.planar}
    quality.update({k: v for k, v in after.items() if k not in quality})
    return OptimizeResult(polymesh=result, quality=quality)
