"""Statics-aware guiding field: target cell size, anisotropy and direction per vertex.

(METHOD.md section 2.) From the shell's membrane forces N: the size h falls where |N| is
large: energy criterion h ~ n^(-2/3), capped at h_max / h_min = D (or, where n varies by less
than D^(3/2), with the exponent raised to reach D), or a linear map of n onto [D, 1];
the anisotropy a = sqrt(|N1| / |N2|) for principal forces of the same sign (energy criterion)
or a linear remap of |N1| / |N2| over its range to [1, A]; the direction u is that of the larger
|principal force|, or normal to it in the tangent plane for cells elongated across the stress
(Orientation.ACROSS, beyond the thesis). Scalars and the line field are smoothed over the mesh and
symmetrised with up to two planes. Sizes are relative (smallest 1); the remesher scales them to its target.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..errors import InputError
from ..linalg import in_tangent_planes, tangent_projectors
from ..mesh import TriMesh

__all__ = ["GuidingField", "SizeMap", "AnisotropyMap", "Orientation", "FieldSettings", "guiding_field",
           "principal_forces", "smooth_scalar", "smooth_directions", "symmetrise", "tangent_basis"]


@dataclass(frozen=True, kw_only=True)
class GuidingField:
    """Per-vertex guiding field on a TriMesh.

    size: (n_vertices,) target cell size h, m; anisotropy: (n_vertices,) a >= 1;
    direction: (n_vertices, 3) unit tangent u, along which cells are elongated: the direction of
    the larger principal force (or normal to it, FieldSettings.orientation); normals: (n_vertices, 3) unit normals.
    The metric is M = R diag(1/(h^2 a), a/h^2) R^T in the (u, v = n x u) frame: its
    unit ellipse has semi-axes h sqrt(a) along u and h / sqrt(a) along v.
    """

    size: np.ndarray
    anisotropy: np.ndarray
    direction: np.ndarray
    normals: np.ndarray

    def metric(self) -> np.ndarray:
        """(n_vertices, 3, 3) metric tensors in global coordinates (rank 2, tangent)."""
        u = self.direction
        v = np.cross(self.normals, u)
        h2 = self.size**2
        a = self.anisotropy
        return (np.einsum("ni,nj->nij", u, u) / (h2 * a)[:, None, None]
                + np.einsum("ni,nj->nij", v, v) * (a / h2)[:, None, None])

    def scaled(self, factor: float) -> "GuidingField":
        """The same field with every size multiplied by ``factor``."""
        return GuidingField(size=self.size * factor, anisotropy=self.anisotropy, direction=self.direction,
                            normals=self.normals)


class SizeMap(str, Enum):
    """How the force level n = max(|N1|, |N2|) becomes a cell size."""

    ENERGY = "energy"
    LINEAR = "linear"


class AnisotropyMap(str, Enum):
    """How the principal force ratio becomes a cell aspect."""

    ENERGY = "energy"
    LINEAR = "linear"


class Orientation(str, Enum):
    """Which way cells are elongated: along the larger principal force (the thesis) or across it."""

    ALONG = "along"
    ACROSS = "across"


@dataclass(frozen=True, kw_only=True)
class FieldSettings:
    """D = max_size_ratio, A = max_aspect; opposite_sign_anisotropy: a where N1 and N2 differ in
    sign (energy map); clamp_percentiles: of the force level; smoothing iterations of the
    scalars and of the line field; symmetry_planes: up to two (point, normal) pairs;
    orientation: cells elongated along the larger principal force or across it (turned by
    90 degrees in the tangent plane)."""

    max_size_ratio: float = 2.0
    max_aspect: float = 2.0
    size_map: SizeMap = SizeMap.ENERGY
    anisotropy_map: AnisotropyMap = AnisotropyMap.ENERGY
    opposite_sign_anisotropy: float = 1.0
    clamp_percentiles: tuple[float, float] = (1.0, 99.0)
    smoothing_iterations: int = 10
    direction_smoothing_iterations: int = 10
    symmetry_planes: tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...] = ()
    orientation: Orientation = Orientation.ALONG

    def __post_init__(self) -> None:
        if not (np.isfinite(self.max_size_ratio) and self.max_size_ratio >= 1.0):
            raise InputError(f"field: D (max_size_ratio) must be a finite number >= 1, got {self.max_size_ratio}",
                             hint="Voro(D, A): D = 1 gives uniform cells, D = 2 lets them vary by a factor 2")
        if not (np.isfinite(self.max_aspect) and self.max_aspect >= 1.0):
            raise InputError(f"field: A (max_aspect) must be a finite number >= 1, got {self.max_aspect}",
                             hint="Voro(D, A): A = 1 gives isotropic cells, A = 2 lets them stretch by 2")
        for name, enum in (("size_map", SizeMap), ("anisotropy_map", AnisotropyMap), ("orientation", Orientation)):
            try:
                object.__setattr__(self, name, enum(getattr(self, name)))
            except ValueError:
                raise InputError(f"field: {name} must be one of {[m.value for m in enum]}, "
                                 f"got {getattr(self, name)!r}") from None
        if not (np.isfinite(self.opposite_sign_anisotropy) and self.opposite_sign_anisotropy >= 1.0):
            raise InputError(f"field: opposite_sign_anisotropy must be >= 1, got {self.opposite_sign_anisotropy}",
                             hint="1 keeps cells isotropic where the principal forces differ in sign")
        try:
            low, high = (float(p) for p in self.clamp_percentiles)
        except (TypeError, ValueError):
            raise InputError(f"field: clamp_percentiles must be two numbers, got {self.clamp_percentiles!r}") from None
        if not 0.0 <= low < high <= 100.0:
            raise InputError(f"field: clamp_percentiles must satisfy 0 <= low < high <= 100, got {low, high}")
        for name in ("smoothing_iterations", "direction_smoothing_iterations"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
                raise InputError(f"field: {name} must be a whole number >= 0, got {value!r}")
        object.__setattr__(self, "symmetry_planes", _check_planes(self.symmetry_planes))


def _check_planes(planes) -> tuple:
    """Validated ((point, unit normal), ...) with at most two planes."""
    planes = tuple(planes)
    if len(planes) > 2:
        raise InputError(f"field: at most two symmetry planes, got {len(planes)}")
    checked = []
    for plane in planes:
        try:
            point, normal = (np.asarray(part, dtype=float) for part in plane)
        except (TypeError, ValueError):
            raise InputError(f"field: a symmetry plane is a (point, normal) pair, got {plane!r}") from None
        length = float(np.linalg.norm(normal)) if normal.shape == (3,) else 0.0
        if point.shape != (3,) or not np.all(np.isfinite(point)) or not (np.isfinite(length) and length > 0):
            raise InputError(f"field: a symmetry plane needs a 3-D point and a non-zero 3-D normal, got {plane!r}",
                             hint="e.g. ((0, 0, 0), (1, 0, 0)) for the plane x = 0")
        checked.append((tuple(point.tolist()), tuple((normal / length).tolist())))
    return tuple(checked)


def tangent_basis(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (n,3) each, orthogonal to the normals and to each other."""
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(normals, helper)
    u /= np.linalg.norm(u, axis=1)[:, None]
    return u, np.cross(normals, u)


def principal_forces(tensors: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Principal values (n,2), the first of larger absolute value, and its unit direction (n,3),
    of tangent tensors (n,3,3) in global axes."""
    u, v = tangent_basis(normals)
    xx = np.einsum("ni,nij,nj->n", u, tensors, u)
    yy = np.einsum("ni,nij,nj->n", v, tensors, v)
    xy = np.einsum("ni,nij,nj->n", u, tensors, v)
    centre, radius = 0.5 * (xx + yy), np.hypot(0.5 * (xx - yy), xy)
    angle = 0.5 * np.arctan2(2 * xy, xx - yy)
    first, second = centre + radius, centre - radius
    swap = np.abs(second) > np.abs(first)
    values = np.stack([np.where(swap, second, first), np.where(swap, first, second)], axis=1)
    angle = angle + swap * (np.pi / 2)
    direction = np.cos(angle)[:, None] * u + np.sin(angle)[:, None] * v
    return values, direction


def _adjacency(mesh: TriMesh) -> sp.csr_matrix:
    edges = mesh.edges
    n = mesh.n_vertices
    data = np.ones(2 * len(edges))
    return sp.csr_matrix((data, (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]])), shape=(n, n))


def _cotangent_adjacency(mesh: TriMesh) -> sp.csr_matrix:
    """Symmetric (n, n) edge weights (cot alpha + cot beta) / 2, clamped at 0 so the smoothing
    stays a convex average (no overshoot next to obtuse triangles)."""
    v, f = mesh.vertices, mesh.faces
    rows, cols, data = [], [], []
    for k in range(3):
        i, j, o = f[:, (k + 1) % 3], f[:, (k + 2) % 3], f[:, k]  # edge (i, j) opposite corner o
        a, b = v[i] - v[o], v[j] - v[o]
        cot = np.einsum("mi,mi->m", a, b) / np.maximum(np.linalg.norm(np.cross(a, b), axis=1), 1e-300)
        rows += [i, j]
        cols += [j, i]
        data += [0.5 * cot, 0.5 * cot]
    n = mesh.n_vertices
    W = sp.csr_matrix((np.concatenate(data), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    W.data = np.maximum(W.data, 0.0)
    return W


def smooth_scalar(mesh: TriMesh, values: np.ndarray, iterations: int, *, laplacian: str = "uniform") -> np.ndarray:
    """Diffuse a vertex scalar (n,): each iteration moves a value halfway to the weighted mean of
    its neighbours. laplacian: "uniform" (every edge weight 1) or "cotangent" (cotangent weights,
    clamped at 0). Constants are kept; the total variation falls."""
    values = np.asarray(values, dtype=float)
    if values.shape != (mesh.n_vertices,):
        raise InputError(f"field: smoothing needs one value per vertex ({mesh.n_vertices},), got {values.shape}")
    if iterations < 0:
        raise InputError(f"field: smoothing iterations must be >= 0, got {iterations}")
    if laplacian == "uniform":
        adjacency = _adjacency(mesh)
    elif laplacian == "cotangent":
        adjacency = _cotangent_adjacency(mesh)
    else:
        raise InputError(f"field: laplacian must be 'uniform' or 'cotangent', got {laplacian!r}")
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    lonely = degree <= 0.0
    degree[lonely] = 1.0
    out = values.copy()
    for _ in range(iterations):
        neighbours = (adjacency @ out) / degree
        out = 0.5 * out + 0.5 * np.where(lonely, out, neighbours)
    return out


def _line_tensor_direction(tensors: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Unit tangent eigenvector of the largest eigenvalue of (n,3,3) line tensors."""
    u, v = tangent_basis(normals)
    xx = np.einsum("ni,nij,nj->n", u, tensors, u)
    yy = np.einsum("ni,nij,nj->n", v, tensors, v)
    xy = np.einsum("ni,nij,nj->n", u, tensors, v)
    angle = 0.5 * np.arctan2(2 * xy, xx - yy)
    return np.cos(angle)[:, None] * u + np.sin(angle)[:, None] * v


def smooth_directions(mesh: TriMesh, directions: np.ndarray, normals: np.ndarray, iterations: int,
                      weights: np.ndarray | None = None) -> np.ndarray:
    """Smooth a line field (u and -u alike) by averaging the outer products u u^T over
    neighbours, projected onto each tangent plane; ``weights`` (n,) favour strongly directed vertices."""
    adjacency = _adjacency(mesh)
    w = np.ones(mesh.n_vertices) if weights is None else np.asarray(weights, dtype=float)
    P = tangent_projectors(normals)
    tensors = np.einsum("ni,nj->nij", directions, directions) * w[:, None, None]
    direction = directions
    for _ in range(iterations):
        flat = tensors.reshape(len(tensors), 9)
        averaged = (0.5 * flat + 0.5 * (adjacency @ flat) / np.maximum(np.asarray(adjacency.sum(axis=1)), 1.0))
        tensors = in_tangent_planes(averaged.reshape(-1, 3, 3), P)
        direction = _line_tensor_direction(tensors, normals)
    return direction


def _reflection(normal) -> np.ndarray:
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    return np.eye(3) - 2 * np.outer(n, n)


def symmetrise(mesh: TriMesh, field: GuidingField, planes) -> GuidingField:
    """Average the field with its mirror images through each plane ((point, normal) pairs);
    each vertex pairs with the vertex nearest to its reflection."""
    planes = _check_planes(planes)
    size, anisotropy, direction = field.size.copy(), field.anisotropy.copy(), field.direction.copy()
    tree = cKDTree(mesh.vertices)
    for point, normal in planes:
        R = _reflection(normal)
        point = np.asarray(point, dtype=float)
        mirrored = (mesh.vertices - point) @ R.T + point
        _, partner = tree.query(mirrored)
        size = 0.5 * (size + size[partner])
        anisotropy = 0.5 * (anisotropy + anisotropy[partner])
        reflected = direction[partner] @ R.T
        tensors = 0.5 * (np.einsum("ni,nj->nij", direction, direction) + np.einsum("ni,nj->nij", reflected, reflected))
        direction = _line_tensor_direction(in_tangent_planes(tensors, tangent_projectors(field.normals)),
                                           field.normals)
    return GuidingField(size=size, anisotropy=anisotropy, direction=direction, normals=field.normals)


def _remap_to_ratio(values: np.ndarray, ratio: float) -> np.ndarray:
    """Positive values rescaled by a power so that max/min = ratio (smallest 1); uniform if flat."""
    low, high = values.min(), values.max()
    if ratio <= 1.0 or high <= low * (1 + 1e-9):
        return np.ones_like(values)
    power = np.log(ratio) / np.log(high / low)
    return (values / low) ** power


def guiding_field(mesh: TriMesh, vertex_membrane_forces: np.ndarray, settings: FieldSettings) -> GuidingField:
    """The guiding field from per-vertex membrane force tensors (n,3,3), N/m, in global axes."""
    tensors = np.asarray(vertex_membrane_forces, dtype=float)
    n = mesh.n_vertices
    if tensors.shape != (n, 3, 3) or not np.all(np.isfinite(tensors)):
        raise InputError(f"field: membrane forces must be a finite ({n}, 3, 3) array, got {tensors.shape}")
    normals = mesh.vertex_normals
    values, direction = principal_forces(tensors, normals)
    larger, smaller = np.abs(values[:, 0]), np.abs(values[:, 1])
    level = larger.copy()
    scale = max(float(level.max()), 1e-300)
    low, high = np.percentile(level, settings.clamp_percentiles)
    level = np.clip(level, max(low, 1e-9 * scale), max(high, 1e-9 * scale))
    level = smooth_scalar(mesh, level, settings.smoothing_iterations)
    D, A = settings.max_size_ratio, settings.max_aspect
    if SizeMap(settings.size_map) is SizeMap.ENERGY:
        # equal strain energy per cell: h ~ n^(-2/3), smallest cell (largest force) = 1. Where the
        # law spans more than D, the low-force side is capped at D (denser than the law there: the
        # safe side); where it spans less, the exponent is raised so that h_max / h_min = D still.
        law = (level / level.max()) ** (-2.0 / 3.0)
        size = np.minimum(law, D) if law.max() >= D else _remap_to_ratio(law, D)
    else:
        span = level.max() - level.min()
        t = (level - level.min()) / span if span > 1e-12 * level.max() else np.zeros_like(level)
        size = D - (D - 1.0) * t if span > 1e-12 * level.max() else np.ones_like(level)
    # N2 = 0 (uniaxial) counts as the limit of the same-sign case: a reaches A there
    same_sign = values[:, 0] * values[:, 1] >= 0
    ratio = larger / np.maximum(smaller, 1e-12 * scale)
    if AnisotropyMap(settings.anisotropy_map) is AnisotropyMap.ENERGY:
        aspect = np.where(same_sign, np.sqrt(ratio), settings.opposite_sign_anisotropy)
    else:
        lo, hi = np.percentile(np.minimum(ratio, 1e6), settings.clamp_percentiles)
        clipped = np.clip(ratio, lo, hi)
        aspect = 1.0 + (A - 1.0) * (clipped - lo) / (hi - lo) if hi > lo * (1 + 1e-9) else np.ones(n)
    # smoothed before the bound (capped at 2A) so that uniaxial regions still reach A
    aspect = np.clip(aspect, 1.0, 2.0 * A)
    aspect = np.where(larger > 1e-9 * scale, aspect, 1.0)  # no force, no direction
    reached = aspect.max() >= A
    aspect = np.clip(smooth_scalar(mesh, aspect, settings.smoothing_iterations), 1.0, A)
    if reached and 1.0 < aspect.max() < A:
        aspect = 1.0 + (aspect - 1.0) * (A - 1.0) / (aspect.max() - 1.0)
    direction = smooth_directions(mesh, direction, normals, settings.direction_smoothing_iterations,
                                  weights=aspect - 1.0 + 1e-3)
    field = GuidingField(size=size, anisotropy=aspect, direction=direction, normals=normals)
    if settings.symmetry_planes:
        ratio_before = float(size.max() / size.min())
        field = symmetrise(mesh, field, settings.symmetry_planes)
        size = _remap_to_ratio(field.size, ratio_before)
        aspect = np.clip(field.anisotropy, 1.0, A)
        if reached and 1.0 < aspect.max() < A:  # averaging lowered the peak: restore a_max = A (affine, symmetric)
            aspect = 1.0 + (aspect - 1.0) * (A - 1.0) / (aspect.max() - 1.0)
        field = GuidingField(size=size, anisotropy=aspect, direction=field.direction, normals=normals)
    if Orientation(settings.orientation) is Orientation.ACROSS:
        field = GuidingField(size=field.size, anisotropy=field.anisotropy,
                             direction=np.cross(normals, field.direction), normals=normals)
    return field
