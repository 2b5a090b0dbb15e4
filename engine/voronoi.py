"""Statics-aware Voronoi remeshing: anisotropic centroidal Voronoi tessellation on the surface.

(METHOD.md section 3.) The direct discrete route, as a clustering of the surface's vertices:
the surface is used as it is when it has at least VERTICES_PER_CELL vertices per cell and is
refined (1-to-4) until it has REFINED_VERTICES_PER_CELL otherwise. Every vertex i carries a weight w_i = area_i h_i^-p
(p = DENSITY_POWER) and the field's metric M_i (its tangent part, h sqrt(a) along u and
h / sqrt(a) across, plus a small normal part so that it is invertible). The clusters minimise
sum_k sum_{i in k} w_i (x_i - c_k)^T M_i (x_i - c_k) by boundary-vertex moves that keep every
cluster connected (engine/clustering.py: an anisotropic Valette-Chassery approximated CVD).
Seeds start on a hexagonal lattice over the best-fit plane and grow into clusters along metric
edge lengths (multi-source Dijkstra); Lloyd steps (seeds moved to the over-relaxed centroids,
clusters regrown and clustered again) grade the cells, which single-vertex moves cannot; above
about four times COARSEST_CELLS cells a coarse level runs first and its centroids and the
midpoints of neighbouring centroids seed the next. At a few cells across, over-relaxed Lloyd
steps carry the clusters among equally graded local minima whose hexagon shares differ by up to
20 points, so the clusterings met along the finest level's steps are candidates; small meshes also
try several lattice offsets. The grid kept has every interior node of valence 3, its size ratio
and aspect within SHAPE_TOLERANCE of the field's, and the most hexagons. The polygon grid-shell
is the dual of the clusters: a node where three clusters meet (a triangle with three labels; at
the anisotropic Voronoi vertex of the three centroids where that stays near the triangle and
turns no beam round, else where the metric distances to the centroids balance along its edges),
a beam along each border between two nodes, boundary nodes where a border meets the surface
boundary, the surface's corners kept as nodes, boundary cells closed along the boundary. Why this route and not the
deform-then-uniform-CVT one, and why clustering rather than Lloyd iterations alone:
docs/decisions.md.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from .errors import InputError, MeshError
from .field import GuidingField
from .mesh import PolyMesh, TriMesh, best_fit_plane, chain_loops
from .symmetry import reflect, symmetrised_grid, symmetry_record

__all__ = ["RemeshSettings", "RemeshResult", "remesh", "polymesh_quality", "surface_corners"]

Progress = Callable[[str, "float | None"], None]

#: Fewest surface vertices per cell the clustering works with; a surface with fewer is refined
#: until it has REFINED_VERTICES_PER_CELL (node positions are then finer; refining is cheap there).
VERTICES_PER_CELL = 24
REFINED_VERTICES_PER_CELL = 48
#: Largest refined mesh (vertices) the remesher builds.
MAX_FINE_VERTICES = 400_000
#: Boundary turning angle above which a surface vertex is a corner kept as a node, degrees.
CORNER_ANGLE_DEG = 30.0
#: Beams shorter than this fraction of the local cell size are collapsed.
SHORT_BEAM_FRACTION = 0.02
#: Vertex weight w = area * h^-DENSITY_POWER (measured: gives achieved size ~ h, see tests).
DENSITY_POWER = 2.0
#: Normal part of the vertex metric, relative to its tangent part's mean (keeps S1 invertible).
NORMAL_REGULARISATION = 0.1
#: Largest number of sweeps of one clustering.
MAX_SWEEPS = 200
#: Lloyd steps between clusterings (re-seeding at the centroids), over-relaxed by LLOYD_RELAXATION
#: but for the last LLOYD_PLAIN_STEPS.
LLOYD_STEPS = 3
LLOYD_RELAXATION = 1.7
LLOYD_PLAIN_STEPS = 1
#: Lloyd steps at the coarsest level.
COARSE_LLOYD_STEPS = 20
#: Starts (lattice offsets) tried where the clustered mesh is small: at most MAX_STARTS, and at most
#: START_BUDGET clustered vertices in all.
MAX_STARTS = 8
START_BUDGET = 100_000
#: Turns of the initial lattice against the plan's axes, taken by the starts in turn, degrees.
LATTICE_TURNS_DEG = (0.0, 30.0)
#: Fewest cells of the coarsest level.
COARSEST_CELLS = 250
#: Lloyd steps of the finest level after which its clusterings are candidates for the grid (the
#: cells are graded from the second step on), and candidates per start whose polygons are made.
FIRST_CANDIDATE_STEP = 2
CANDIDATES_PER_START = 3
#: Largest relative gap between a candidate grid's achieved size ratio (aspect) and the field's
#: D' (A') that the choice among candidates accepts before looking at hexagons (issue 4's band).
SHAPE_TOLERANCE = 0.25


@dataclass(frozen=True, kw_only=True)
class RemeshSettings:
    """Size target: exactly one of n_cells, mean_beam_length (m) or total_length (m, L_tot,
    met within 1 %); lloyd_iterations: the most Lloyd steps (seeds moved to the over-relaxed
    cluster centroids, clusters regrown and clustered again) at each level of the clustering; at
    most COARSE_LLOYD_STEPS are taken at the coarsest level and LLOYD_STEPS at the finer ones, so
    values above COARSE_LLOYD_STEPS change nothing and 0 keeps the clustering of the initial
    lattice; seed of the lattice's random offset (small meshes also try the next seeds);
    symmetry_planes: up to two (point, normal) pairs (m) the grid is made symmetric about (the
    field's, engine.field.FieldSettings), none by default."""

    n_cells: int | None = None
    mean_beam_length: float | None = None
    total_length: float | None = None
    lloyd_iterations: int = 80
    seed: int = 0
    symmetry_planes: tuple = ()

    def __post_init__(self) -> None:
        given = [k for k in ("n_cells", "mean_beam_length", "total_length") if getattr(self, k) is not None]
        if len(given) != 1:
            raise InputError(f"remesh: give exactly one size target (n_cells, mean_beam_length or total_length), "
                             f"got {given or 'none'}")
        if self.n_cells is not None and self.n_cells < 4:
            raise InputError(f"remesh: n_cells must be at least 4, got {self.n_cells}")
        for key in ("mean_beam_length", "total_length"):
            value = getattr(self, key)
            if value is not None and not value > 0:
                raise InputError(f"remesh: {key} must be positive, got {value}")
        if self.lloyd_iterations < 0:
            raise InputError(f"remesh: lloyd_iterations (clustering sweeps) must be >= 0, got {self.lloyd_iterations}")


@dataclass(frozen=True, kw_only=True)
class RemeshResult:
    """The grid-shell and its quality figures (JSON-ready)."""

    polymesh: PolyMesh
    quality: dict


# ----------------------------------------------------------------------------- surface topology

def _edges_of(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unique sorted edges (e, 2), per face corner j the id of edge (j, j+1) (m, 3), and the
    number of faces of each edge (e,)."""
    following = np.roll(faces, -1, axis=1)
    key = (np.minimum(faces, following) * n_vertices + np.maximum(faces, following)).ravel()
    unique, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    edges = np.stack([unique // n_vertices, unique % n_vertices], axis=1)
    return edges, inverse.reshape(faces.shape), counts


def _edge_ids(edges: np.ndarray, n_vertices: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Ids of the edges (a_i, b_i) in the sorted edge list."""
    keys = edges[:, 0] * n_vertices + edges[:, 1]
    return np.searchsorted(keys, np.minimum(a, b) * n_vertices + np.maximum(a, b))


def _boundary_loops(faces: np.ndarray, face_edges: np.ndarray, counts: np.ndarray) -> list[np.ndarray]:
    """Boundary loops following the faces' orientation, longest first."""
    border = counts[face_edges] == 1
    start = faces[border]
    end = np.roll(faces, -1, axis=1)[border]
    return chain_loops(start, end)


def _loop_corners(vertices: np.ndarray, loops: list[np.ndarray], angle_deg: float) -> np.ndarray:
    corners = []
    for loop in loops:
        p = vertices[loop]
        incoming = p - np.roll(p, 1, axis=0)
        outgoing = np.roll(p, -1, axis=0) - p
        cosine = np.einsum("ij,ij->i", incoming, outgoing) / np.maximum(
            np.linalg.norm(incoming, axis=1) * np.linalg.norm(outgoing, axis=1), 1e-300)
        corners.extend(loop[cosine < np.cos(np.radians(angle_deg))].tolist())
    return np.array(sorted(corners), dtype=np.int64)


def surface_corners(mesh: TriMesh, angle_deg: float = CORNER_ANGLE_DEG) -> np.ndarray:
    """Vertex ids of boundary vertices where the boundary turns by more than ``angle_deg``."""
    return _loop_corners(mesh.vertices, mesh.boundary_loops, angle_deg)


def _subdivide(vertices: np.ndarray, faces: np.ndarray, per_vertex: list[np.ndarray]):
    """One 1-to-4 midpoint subdivision; per-vertex arrays averaged at the new vertices (the old
    vertices keep their ids)."""
    edges, face_edges, _ = _edges_of(faces, len(vertices))
    mid = len(vertices) + face_edges
    new_vertices = np.vstack([vertices, 0.5 * (vertices[edges[:, 0]] + vertices[edges[:, 1]])])
    new_arrays = [np.concatenate([a, 0.5 * (a[edges[:, 0]] + a[edges[:, 1]])]) for a in per_vertex]
    a, b, c = faces[:, 0], faces[:, 1], faces[:, 2]
    ab, bc, ca = mid[:, 0], mid[:, 1], mid[:, 2]
    new_faces = np.concatenate([np.stack([a, ab, ca], 1), np.stack([ab, b, bc], 1), np.stack([ca, bc, c], 1),
                                np.stack([ab, bc, ca], 1)])
    return new_vertices, new_faces, new_arrays


@dataclass
class _Fine:
    """The clustered mesh: the surface, refined where needed (its first vertices are the surface's)."""

    vertices: np.ndarray
    faces: np.ndarray
    metric: np.ndarray       # (n, 3, 3) tangent metric + normal regularisation
    normals: np.ndarray
    inverse_h2: np.ndarray   # 1 / h^2 = sqrt(det) of the tangent metric
    areas: np.ndarray
    edges: np.ndarray
    face_edges: np.ndarray
    on_boundary: np.ndarray  # (e,) edge used by one face
    loops: list
    corners: np.ndarray      # vertex ids (of the surface, kept in the fine mesh)
    n_surface_vertices: int
    boundary_vertices: np.ndarray            # ids of the vertices on the boundary loops
    adjacency: object = None                 # engine.clustering.MeshAdjacency, built on first use
    graph: sp.csr_matrix | None = None       # metric edge lengths, same order as the adjacency
    moments: np.ndarray | None = None        # centred vertex moments of the clustering, on first use
    tree: cKDTree | None = None              # of the vertices, on first use


def _refine(mesh: TriMesh, field: GuidingField, n_cells: int) -> _Fine:
    """The mesh to cluster: the surface when it has VERTICES_PER_CELL vertices per cell, else
    subdivided until it has REFINED_VERTICES_PER_CELL (within MAX_FINE_VERTICES); vertex metrics
    (tangent + normal regularisation), 1 / h^2, areas, edges, boundary loops and corners."""
    vertices, faces = mesh.vertices, mesh.faces
    tangent = field.metric()
    normals = np.asarray(field.normals, dtype=float)
    if len(vertices) < VERTICES_PER_CELL * n_cells:
        while len(vertices) < REFINED_VERTICES_PER_CELL * n_cells and 4 * len(vertices) <= MAX_FINE_VERTICES:
            vertices, faces, (tangent, normals) = _subdivide(vertices, faces, [tangent, normals])
    normals = normals / np.maximum(np.linalg.norm(normals, axis=1), 1e-300)[:, None]
    # sqrt(det) of the rank-2 tangent metric (its second invariant) = 1 / h^2
    trace = np.einsum("nii->n", tangent)
    second = 0.5 * (trace**2 - np.einsum("nij,nji->n", tangent, tangent))
    inverse_h2 = np.sqrt(np.maximum(second, 1e-300))
    metric = tangent + (NORMAL_REGULARISATION * 0.5 * trace)[:, None, None] * np.einsum("ni,nj->nij", normals, normals)
    edges, face_edges, counts = _edges_of(faces, len(vertices))
    cross = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    face_area = 0.5 * np.linalg.norm(cross, axis=1)
    areas = np.bincount(faces.ravel(), weights=np.repeat(face_area / 3.0, 3), minlength=len(vertices))
    loops = _boundary_loops(faces, face_edges, counts)
    corners = _loop_corners(vertices, loops, CORNER_ANGLE_DEG)
    corners = corners[corners < mesh.n_vertices]
    return _Fine(vertices=vertices, faces=faces, metric=metric, normals=normals, inverse_h2=inverse_h2, areas=areas,
                 edges=edges, face_edges=face_edges, on_boundary=counts == 1, loops=loops, corners=corners,
                 n_surface_vertices=mesh.n_vertices,
                 boundary_vertices=np.unique(np.concatenate(loops)) if loops else np.zeros(0, dtype=np.int64))


# ----------------------------------------------------------------------------- clustering

def _initial_seeds(fine: _Fine, n_cells: int, rng: np.random.Generator, turn_deg: float = 0.0) -> np.ndarray:
    """Vertex ids of ``n_cells`` seeds: a hexagonal lattice over the surface's best-fit plane
    (the clustering then starts near a honeycomb and keeps few defects), thinned or topped up at
    random; random sampling by the field's density where the surface is not a height field over
    that plane."""
    weight = fine.areas * fine.inverse_h2
    probability = weight / weight.sum()
    centre, normal = best_fit_plane(fine.vertices)
    u = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    plan = np.stack([(fine.vertices - centre) @ u, (fine.vertices - centre) @ v], axis=1)
    corners = plan[fine.faces]
    edge1, edge2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    signed = edge1[:, 0] * edge2[:, 1] - edge1[:, 1] * edge2[:, 0]
    if not (np.all(signed > 0) or np.all(signed < 0)):
        return rng.choice(len(fine.vertices), size=n_cells, replace=False, p=probability)
    plan_area = 0.5 * np.abs(signed).sum()
    turn = np.radians(turn_deg)
    plan = plan @ np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    tree = cKDTree(plan)
    offset = rng.uniform(0, 1, 2)
    lo_plan, hi_plan = plan.min(axis=0), plan.max(axis=0)

    def lattice(spacing: float) -> np.ndarray:
        lo, hi = lo_plan - spacing, hi_plan + spacing
        rows = np.arange(int((hi[1] - lo[1]) / (spacing * np.sqrt(3) / 2)) + 1)
        columns = np.arange(int((hi[0] - lo[0]) / spacing) + 2)
        j, i = np.meshgrid(rows, columns, indexing="ij")
        x = lo[0] + (offset[0] + 0.5 * (j % 2) + i) * spacing
        y = lo[1] + (offset[1] + j * np.sqrt(3) / 2) * spacing
        grid = np.c_[x.ravel(), y.ravel()]
        distance, nearest = tree.query(grid, distance_upper_bound=0.5 * spacing)
        return np.unique(nearest[distance < 0.5 * spacing])

    spacing = np.sqrt(2.0 * plan_area / (np.sqrt(3.0) * n_cells))
    best = lattice(spacing)
    low, high = 0.7 * spacing, 1.4 * spacing
    for _ in range(25):
        if len(best) == n_cells:
            break
        middle = 0.5 * (low + high)
        chosen = lattice(middle)
        if abs(len(chosen) - n_cells) < abs(len(best) - n_cells):
            best = chosen
        low, high = (middle, high) if len(chosen) > n_cells else (low, middle)
    chosen = best
    if len(chosen) > n_cells:
        # drop the points nearest the boundary, where cells are cut anyway
        boundary = np.concatenate(fine.loops)
        gap, _ = cKDTree(plan[boundary]).query(plan[chosen])
        chosen = chosen[np.argsort(gap)[len(chosen) - n_cells:]]
    elif len(chosen) < n_cells:
        rest = np.setdiff1d(np.arange(len(fine.vertices)), chosen)
        extra = rng.choice(rest, size=n_cells - len(chosen), replace=False,
                           p=probability[rest] / probability[rest].sum())
        chosen = np.concatenate([chosen, extra])
    return chosen


def _adjacency(fine: _Fine):
    """The fine mesh's vertex adjacency and its graph of metric edge lengths (built on first use)."""
    from .clustering import mesh_adjacency

    if fine.adjacency is None:
        n = len(fine.vertices)
        adjacency = mesh_adjacency(n, fine.faces, fine.edges)
        origin = np.repeat(np.arange(n), np.diff(adjacency.vertex_ptr))
        other = adjacency.vertex_neighbours
        d = fine.vertices[other] - fine.vertices[origin]
        m = 0.5 * (fine.metric[origin] + fine.metric[other])
        lengths = np.sqrt(np.maximum(np.einsum("ei,eij,ej->e", d, m, d), 1e-300))
        fine.adjacency = adjacency
        fine.graph = sp.csr_matrix((lengths, other, adjacency.vertex_ptr), shape=(n, n))
    return fine.adjacency


def _grow_clusters(fine: _Fine, seeds: np.ndarray) -> np.ndarray:
    """Labels of the seed nearest along metric edge lengths (multi-source Dijkstra: each vertex
    takes its predecessor's label, so every cluster is connected)."""
    _adjacency(fine)
    _, _, sources = dijkstra(fine.graph, directed=True, indices=seeds, min_only=True, return_predecessors=True)
    if np.any(sources < 0):
        raise MeshError("remesh: the surface has parts that no seed reaches (it is not connected)",
                        hint="remesh each connected part of the surface on its own, or ask for more cells")
    index = np.full(len(fine.vertices), -1, dtype=np.int64)
    index[seeds] = np.arange(len(seeds))
    return index[sources]


@dataclass
class _Clusters:
    labels: np.ndarray
    centroids: np.ndarray
    sweeps: int
    moves: np.ndarray
    hexagon_share: float = 0.0   # of interior clusters (_interior_hexagon_share)
    energy: float = 0.0


def _level_counts(n_cells: int) -> list[int]:
    """Cell counts of the levels, coarsest first: each level's seeds are the centroids of the one
    before and the midpoints of its neighbouring centroids, about four times as many (a hexagonal
    lattice of N points has about 3N - 4 sqrt(N) neighbour pairs)."""
    counts = [n_cells]
    while True:
        coarse = int(np.ceil(counts[-1] / 4 + np.sqrt(counts[-1]) / 2))
        if coarse < COARSEST_CELLS or coarse >= counts[-1]:
            break
        counts.append(coarse)
    return counts[::-1]


def _refined_seeds(fine: _Fine, tree: cKDTree, labels: np.ndarray, centroids: np.ndarray, count: int,
                   rng: np.random.Generator) -> np.ndarray:
    """``count`` seed vertices: the centroids and the midpoints of neighbouring centroids, those
    nearest the boundary dropped (boundary cells are cut anyway), random vertices added if short."""
    E = fine.edges
    la, lb = labels[E[:, 0]], labels[E[:, 1]]
    mixed = la != lb
    k = len(centroids)
    pairs = np.unique(np.minimum(la[mixed], lb[mixed]) * k + np.maximum(la[mixed], lb[mixed]))
    points = np.concatenate([centroids, 0.5 * (centroids[pairs // k] + centroids[pairs % k])])
    seeds = np.unique(tree.query(points)[1])
    if len(seeds) > count:
        boundary = np.concatenate(fine.loops) if fine.loops else np.zeros(0, dtype=np.int64)
        if len(boundary):
            gap, _ = cKDTree(fine.vertices[boundary]).query(fine.vertices[seeds])
            seeds = seeds[np.sort(np.argsort(gap, kind="stable")[len(seeds) - count:])]
        else:
            seeds = np.sort(rng.choice(seeds, size=count, replace=False))
    elif len(seeds) < count:
        rest = np.setdiff1d(np.arange(len(fine.vertices)), seeds)
        weight = (fine.areas * fine.inverse_h2)[rest]
        extra = rng.choice(rest, size=count - len(seeds), replace=False, p=weight / weight.sum())
        seeds = np.concatenate([seeds, extra])
    return seeds


def _snap(tree: cKDTree, target: np.ndarray, previous: np.ndarray) -> np.ndarray:
    """The vertex nearest each target point, all different: where two targets share a vertex, the
    later one takes the nearest vertex not yet taken (its previous seed among the candidates)."""
    seeds = tree.query(target)[1]
    if len(np.unique(seeds)) == len(seeds):
        return seeds
    taken = set()
    out = seeds.copy()
    first = np.zeros(len(seeds), dtype=bool)
    first[np.unique(seeds, return_index=True)[1]] = True
    taken.update(seeds[first].tolist())
    for i in np.flatnonzero(~first):
        _, candidates = tree.query(target[i], k=min(16, tree.n))
        free = [int(c) for c in np.atleast_1d(candidates) if int(c) not in taken]
        out[i] = free[0] if free else int(previous[i])
        taken.add(int(out[i]))
    if len(np.unique(out)) != len(out):
        return previous
    return out


def _interior_hexagon_share(fine: _Fine, labels: np.ndarray, n_clusters: int) -> float:
    """Share of interior clusters (no vertex on the boundary) with six neighbouring clusters: the
    grid's hexagon share of interior cells, but where extraction collapses a short beam."""
    E = fine.edges
    la, lb = labels[E[:, 0]], labels[E[:, 1]]
    mixed = la != lb
    pairs = np.unique(np.minimum(la[mixed], lb[mixed]) * n_clusters + np.maximum(la[mixed], lb[mixed]))
    degree = np.bincount(pairs // n_clusters, minlength=n_clusters) + np.bincount(pairs % n_clusters,
                                                                                 minlength=n_clusters)
    interior = np.ones(n_clusters, dtype=bool)
    interior[labels[fine.boundary_vertices]] = False
    return float(np.mean(degree[interior] == 6)) if interior.any() else 0.0


def _cluster(fine: _Fine, n_cells: int, settings: RemeshSettings, turn_deg: float = 0.0,
             keep: int = 1) -> list[_Clusters]:
    """Coarse to fine: at each level, seeds grown into clusters, the clustering, then Lloyd steps
    (seeds moved to the over-relaxed centroids, clusters regrown and clustered again). Returns the
    ``keep`` clusterings of the finest level with the largest interior hexagon share
    (ties: the lower energy), from FIRST_CANDIDATE_STEP Lloyd steps on, best first: at a few cells
    across, over-relaxed Lloyd steps move the clusters among equally graded local minima of the
    energy whose hexagon shares differ by up to 20 points. With symmetry planes (and a symmetric
    mesh) seeds and clusters are made symmetric at every step, and only symmetric clusterings are
    candidates while there are any."""
    from .clustering import centred_moments, cluster_vertices

    rng = np.random.default_rng(settings.seed)
    adjacency = _adjacency(fine)
    weights = fine.areas * fine.inverse_h2 ** (DENSITY_POWER / 2)
    if fine.moments is None:
        fine.moments = centred_moments(fine.vertices, fine.metric, weights)
    moments = fine.moments
    if fine.tree is None:
        fine.tree = cKDTree(fine.vertices)
    tree = fine.tree
    counts = _level_counts(n_cells)
    sweeps = 0
    result = None
    candidates: list[_Clusters] = []
    spares: list[_Clusters] = []  # clusterings that could not be made symmetric
    mirrors = _mirrors(fine, tuple(settings.symmetry_planes))
    centred: list = [None]  # sigma of the last symmetric clustering (its clusters centred on a plane)

    def clustered(seeds: np.ndarray, lloyd: bool = False):
        """(seeds, clustering, symmetric): seeds grown into clusters and clustered; with symmetry planes
        the seeds made symmetric first (_symmetric_seeds, ``lloyd``: of a Lloyd step) and the clusters
        after (_symmetric_seeds, _symmetric_clusters)."""
        sigma = None
        if mirrors is not None:
            if lloyd and centred[0] is not None:
                seeds = _onto_planes(fine, mirrors, seeds, centred[0])
            centred[0] = None
            seeds, sigma = _symmetric_seeds(fine, mirrors, seeds, lloyd)
        labels = _grow_clusters(fine, seeds)
        result = cluster_vertices(fine.vertices, fine.faces, fine.edges, adjacency, fine.metric, weights, labels,
                                  len(seeds), max_sweeps=MAX_SWEEPS, moments=moments)
        if sigma is None or mirrors is None:
            return seeds, result, True
        symmetric = _symmetric_clusters(fine, mirrors, seeds, sigma, result, moments)
        if symmetric is None:
            return seeds, result, False
        centred[0] = sigma
        for _ in range(JUNCTION_ROUNDS):
            merged = _merged_pairs(fine, mirrors, seeds, sigma, symmetric)
            if merged is None:
                break
            seeds, sigma = _symmetric_seeds(fine, mirrors, merged, lloyd=True)
            labels = _grow_clusters(fine, seeds)
            again = cluster_vertices(fine.vertices, fine.faces, fine.edges, adjacency, fine.metric, weights, labels,
                                     len(seeds), max_sweeps=MAX_SWEEPS, moments=moments)
            symmetric = _symmetric_clusters(fine, mirrors, seeds, sigma, again, moments)
            if symmetric is None:
                centred[0] = None
                return seeds, again, False
            centred[0] = sigma
        return seeds, symmetric, True

    for level, count in enumerate(counts):
        if result is None:
            seeds = _initial_seeds(fine, count, rng, turn_deg)
        else:
            seeds = _refined_seeds(fine, tree, result.labels, result.centroids, count, rng)
        seeds, result, symmetric = clustered(seeds)
        sweeps += result.sweeps
        steps = min(settings.lloyd_iterations, COARSE_LLOYD_STEPS if level == 0 else LLOYD_STEPS)
        last = level == len(counts) - 1
        for step in range(0, steps + 1):
            if step > 0:
                relaxation = LLOYD_RELAXATION if step <= steps - LLOYD_PLAIN_STEPS else 1.0
                target = fine.vertices[seeds] + relaxation * (result.centroids - fine.vertices[seeds])
                seeds, result, symmetric = clustered(_snap(tree, target, seeds), lloyd=True)
                sweeps += result.sweeps
            if last and step >= min(FIRST_CANDIDATE_STEP, steps):
                pool = candidates if symmetric else spares  # with symmetry planes: symmetric ones first
                pool.append(_Clusters(labels=result.labels, centroids=result.centroids, sweeps=sweeps,
                                            moves=result.moves, energy=float(result.energy.sum()),
                                            hexagon_share=_interior_hexagon_share(fine, result.labels,
                                                                                  len(result.centroids))))
                pool.sort(key=_candidate_order)
                del pool[keep:]
    candidates = candidates or spares
    for clusters in candidates:
        clusters.sweeps = sweeps
    return candidates


# ----------------------------------------------------------------------------- symmetry

#: Two vertices are mirrors of each other when one's image lies within this share of the mean
#: edge length of the other: the clustered mesh must be symmetric for its clusters to be.
MIRROR_MATCH = 0.5
#: A vertex within this share of the mean edge length of a plane is on it.
ON_PLANE = 0.01
#: A seed within this share of the seed spacing of a symmetry plane is moved onto it.
SEED_SNAP = 0.25
#: Rounds of merging consecutive mirrored pairs of clusters along a plane (_merged_pairs) and
#: clustering again, per clustering.
JUNCTION_ROUNDS = 3


@dataclass
class _Mirrors:
    """The clustered mesh's mirror maps through the symmetry planes (perpendicular, one or two):
    per plane each vertex's mirror and whether it is its own (on the plane); for each vertex its
    image in the fundamental region (on the positive side of every plane, a plane's vertices
    included) and through which planes it gets there."""

    planes: tuple
    maps: list
    fixed: list
    sides: list
    flips: list
    image: np.ndarray


def _on_planes(mirrors: _Mirrors, combination: tuple) -> np.ndarray:
    """(n,) bool: the clustered mesh's vertices on every plane whose flag is set in ``combination``."""
    on = np.ones(len(mirrors.image), dtype=bool)
    for plane, wanted in enumerate(combination):
        if wanted:
            on &= mirrors.fixed[plane]
    return on


def _mirrors(fine: _Fine, planes: tuple) -> _Mirrors | None:
    """The mirror maps of ``fine`` through ``planes``, or None without planes, for planes that are
    not perpendicular, or where the clustered mesh's vertices are not symmetric (MIRROR_MATCH)."""
    if not planes:
        return None
    normals = [np.asarray(n, dtype=float) / np.linalg.norm(n) for _, n in planes]
    if len(normals) == 2 and abs(float(normals[0] @ normals[1])) > 1e-6:
        return None
    if fine.tree is None:
        fine.tree = cKDTree(fine.vertices)
    x = fine.vertices
    edge = float(np.linalg.norm(x[fine.edges[:, 1]] - x[fine.edges[:, 0]], axis=1).mean())
    tolerance = MIRROR_MATCH * edge
    every = np.arange(len(x))
    maps, sides = [], []
    for plane, normal in zip(planes, normals):
        distance, mirror = fine.tree.query(reflect(x, plane))
        if distance.max() > tolerance or not np.array_equal(mirror[mirror], every):
            return None
        maps.append(mirror)
        sides.append((x - np.asarray(plane[0], dtype=float)) @ normal)
    image, flips = every, []
    for mirror, side in zip(maps, sides):
        flip = side[image] < -ON_PLANE * edge
        image = np.where(flip, mirror[image], image)
        flips.append(flip)
    return _Mirrors(planes=planes, maps=maps, fixed=[m == every for m in maps], sides=sides, flips=flips,
                    image=image)


def _symmetric_seeds(fine: _Fine, mirrors: _Mirrors, seeds: np.ndarray, lloyd: bool = False
                     ) -> tuple[np.ndarray, list]:
    """(seeds, sigma): the seeds in the fundamental region, those within SEED_SNAP of the seed
    spacing of a plane moved to the nearest vertex on it, and their mirror images; sigma per plane
    maps each seed's index to its mirror's. ``lloyd``: the seeds of a Lloyd step (from symmetric
    centroids), none moved."""
    reps = np.unique(seeds[mirrors.image[seeds] == seeds])
    reach = 0.0 if lloyd else SEED_SNAP * np.sqrt(fine.areas.sum() / max(len(seeds), 1))
    near = np.array([np.abs(side[reps]) < reach for side in mirrors.sides])
    for combination in sorted({tuple(column) for column in near.T if any(column)}):
        chosen = np.flatnonzero(np.all(near.T == combination, axis=1))
        on = _on_planes(mirrors, combination)
        on &= mirrors.image == np.arange(len(fine.vertices))
        if on.any():
            candidates = np.flatnonzero(on)
            reps[chosen] = candidates[cKDTree(fine.vertices[candidates]).query(fine.vertices[reps[chosen]])[1]]
    orbit = [np.unique(reps)]
    for mirror in mirrors.maps:
        orbit = orbit + [mirror[o] for o in orbit]
    seeds = np.unique(np.concatenate(orbit))
    return seeds, [np.searchsorted(seeds, mirror[seeds]) for mirror in mirrors.maps]


def _symmetric_clusters(fine: _Fine, mirrors: _Mirrors, seeds: np.ndarray, sigma: list, result,
                        moments: np.ndarray):
    """``result`` (engine.clustering.ClusteringResult) with the labels of the fundamental region
    mirrored onto the rest, centroids and energies of the mirrored labels; None where that leaves a
    cluster empty or in pieces. In the region, a cluster whose seed lies outside it gives its
    vertices to its mirror image's (the border of the two is the plane; the vertices on a plane go
    to the region's side)."""
    from .clustering import ClusteringResult, _accumulate, centroids_of

    inside = np.searchsorted(seeds, mirrors.image[seeds])
    labels = inside[result.labels][mirrors.image]
    for p in reversed(range(len(mirrors.maps))):
        labels = np.where(mirrors.flips[p], sigma[p][labels], labels)
    count = len(result.centroids)
    if len(np.unique(labels)) != count:
        return None
    E = fine.edges
    same = labels[E[:, 0]] == labels[E[:, 1]]
    graph = sp.coo_matrix((np.ones(int(same.sum())), (E[same, 0], E[same, 1])), shape=(len(labels),) * 2)
    if connected_components(graph, directed=False)[0] != count:
        return None
    S, _ = _accumulate(labels, moments, count)
    centred = centroids_of(S)
    return ClusteringResult(labels=labels, centroids=centred + fine.vertices.mean(axis=0),
                            energy=S[:, 9] - np.einsum("ki,ki->k", S[:, 6:9], centred), sweeps=result.sweeps,
                            moves=result.moves)


def _onto_planes(fine: _Fine, mirrors: _Mirrors, seeds: np.ndarray, sigma: list) -> np.ndarray:
    """``seeds`` (of a Lloyd step, in the order of the clusters of the last symmetric clustering)
    with those of the clusters that are their own mirror through some planes (sigma) moved to the
    nearest vertex on those planes: snapped off the plane, such a cluster would split into a mirrored
    pair (or vanish) at the next clustering."""
    seeds = seeds.copy()
    own = np.array([mirror == np.arange(len(seeds)) for mirror in sigma])
    for combination in sorted({tuple(column) for column in own.T if any(column)}):
        chosen = np.flatnonzero(np.all(own.T == combination, axis=1))
        on = _on_planes(mirrors, combination)
        if on.any():
            candidates = np.flatnonzero(on)
            seeds[chosen] = candidates[cKDTree(fine.vertices[candidates]).query(fine.vertices[seeds[chosen]])[1]]
    return seeds


def _merged_pairs(fine: _Fine, mirrors: _Mirrors, seeds: np.ndarray, sigma: list, result) -> np.ndarray | None:
    """The seeds with mirrored pairs of clusters merged where two such pairs follow each other along
    a plane, or None where none do. The four clusters of two consecutive pairs meet at one point of
    the plane, which no symmetric grid splits into valence-3 nodes (an extra beam there would part
    clusters that are not mirrors), so the extraction collapses it into a valence-4 node; a
    honeycomb symmetric about a line has a cluster centred on it between any two pairs. Two pairs
    are consecutive where a mesh edge within one mean edge length of the plane (an end in the
    fundamental region) joins clusters of both; of the two, the pair of the smaller weight becomes
    one cluster, its seed the vertex on the plane (in the fundamental region) nearest the pair's
    mean centroid. One junction per orbit under the mirrors, taken in order of the mesh edges."""
    x = fine.vertices
    E = fine.edges
    labels = result.labels
    n = len(seeds)
    edge = float(np.linalg.norm(x[E[:, 1]] - x[E[:, 0]], axis=1).mean())
    weight = np.bincount(labels, weights=fine.areas * fine.inverse_h2, minlength=n)
    region = mirrors.image == np.arange(len(x))
    orbit = np.searchsorted(seeds, mirrors.image[seeds])  # each cluster's representative in the region
    taken = set(seeds.tolist())

    def into_region(point: np.ndarray) -> np.ndarray:
        for plane in mirrors.planes:
            if (point - np.asarray(plane[0], dtype=float)) @ np.asarray(plane[1], dtype=float) < 0:
                point = reflect(point[None, :], plane)[0]
        return point

    merged: dict[int, int] = {}  # representative replaced -> its new seed on the plane
    la, lb = labels[E[:, 0]], labels[E[:, 1]]
    for p, (side, flip_map) in enumerate(zip(mirrors.sides, sigma)):
        on = np.flatnonzero(mirrors.fixed[p] & region)
        if not len(on):
            continue
        on_tree = cKDTree(x[on])
        near = (np.abs(side[E[:, 0]]) <= edge) & (np.abs(side[E[:, 1]]) <= edge)
        straddle = flip_map != np.arange(n)
        touching = np.zeros(n, dtype=bool)
        across = near & (la != lb) & (flip_map[la] == lb)
        touching[la[across]] = True
        touching[lb[across]] = True
        junction = (near & (la != lb) & (flip_map[la] != lb) & straddle[la] & straddle[lb] & touching[la]
                    & touching[lb] & (region[E[:, 0]] | region[E[:, 1]]))
        for e in np.flatnonzero(junction):
            a, b = int(la[e]), int(lb[e])
            if orbit[a] in merged or orbit[b] in merged:
                continue
            wa, wb = weight[a] + weight[flip_map[a]], weight[b] + weight[flip_map[b]]
            chosen = a if (wa, a) <= (wb, b) else b
            centre = into_region(0.5 * (result.centroids[chosen] + result.centroids[flip_map[chosen]]))
            vertex = int(on[on_tree.query(centre)[1]])
            if vertex in taken:
                continue
            taken.add(vertex)
            merged[int(orbit[chosen])] = vertex
    if not merged:
        return None
    kept = [int(s) for i, s in enumerate(seeds) if orbit[i] == i and i not in merged] + list(merged.values())
    return np.unique(np.asarray(kept, dtype=np.int64))


def _candidate_order(clusters: _Clusters) -> tuple[float, float]:
    """Sort key, best first: the larger interior hexagon share, then the lower energy."""
    return -clusters.hexagon_share, clusters.energy


# ----------------------------------------------------------------------------- extraction

def _edge_points(fine: _Fine, labels: np.ndarray, centroids: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The point (k, 3) on each fine edge (a, b) between two clusters where the metric distances to
    their centroids balance (linear in between, clipped to the edge): a node of the grid there."""
    la, lb = labels[a], labels[b]
    gaps = []
    for end in (a, b):
        x, M = fine.vertices[end], fine.metric[end]
        to_a, to_b = x - centroids[la], x - centroids[lb]
        gaps.append(np.sqrt(np.maximum(np.einsum("ei,eij,ej->e", to_a, M, to_a), 0.0))
                    - np.sqrt(np.maximum(np.einsum("ei,eij,ej->e", to_b, M, to_b), 0.0)))
    denominator = gaps[0] - gaps[1]
    safe = np.abs(denominator) > 1e-300
    t = np.clip(np.where(safe, gaps[0] / np.where(safe, denominator, 1.0), 0.5), 0.0, 1.0)
    x0, x1 = fine.vertices[a], fine.vertices[b]
    return x0 + t[:, None] * (x1 - x0)


def _extract(fine: _Fine, labels: np.ndarray, centroids: np.ndarray):
    """Polygon mesh from the cluster labels: (nodes, flat cell loops, loop offsets, cell labels,
    boundary mask, corner mask)."""
    E, F, FE = fine.edges, fine.faces, fine.face_edges
    n_edges = len(E)
    la, lb = labels[E[:, 0]], labels[E[:, 1]]
    mixed = la != lb
    ids = np.flatnonzero(mixed)
    edge_points = np.zeros((n_edges, 3))
    edge_points[ids] = _edge_points(fine, labels, centroids, E[ids, 0], E[ids, 1])
    FL = labels[F]
    three = (FL[:, 0] != FL[:, 1]) & (FL[:, 1] != FL[:, 2]) & (FL[:, 0] != FL[:, 2])
    two = ~three & (mixed[FE].sum(axis=1) == 2)
    # nodes: triple triangles, then boundary crossings, then the surface's corners
    triple = np.flatnonzero(three)
    crossing = np.flatnonzero(mixed & fine.on_boundary)
    n_triple, n_crossing = len(triple), len(crossing)
    node_of_edge = np.full(n_edges, -1, dtype=np.int64)
    node_of_edge[crossing] = n_triple + np.arange(n_crossing)
    corner_node = np.full(len(fine.vertices), -1, dtype=np.int64)
    corner_node[fine.corners] = n_triple + n_crossing + np.arange(len(fine.corners))
    nodes = np.concatenate([edge_points[FE[triple]].mean(axis=1), edge_points[crossing], fine.vertices[fine.corners]])
    boundary = np.r_[np.zeros(n_triple, dtype=bool), np.ones(n_crossing + len(fine.corners), dtype=bool)]
    corner = np.r_[np.zeros(n_triple + n_crossing, dtype=bool), np.ones(len(fine.corners), dtype=bool)]
    # chains of mixed edges through two-label triangles, each a beam between two nodes
    links = FE[two][mixed[FE[two]]].reshape(-1, 2)
    chain_graph = sp.csr_matrix((np.ones(len(links)), (links[:, 0], links[:, 1])), shape=(n_edges, n_edges))
    _, chain = connected_components(chain_graph, directed=False)
    attached_chain = np.concatenate([chain[FE[triple]].ravel(), chain[crossing]])
    attached_node = np.concatenate([np.repeat(np.arange(n_triple), 3), node_of_edge[crossing]])
    order = np.argsort(attached_chain, kind="stable")
    attached_chain, attached_node = attached_chain[order], attached_node[order]
    per_chain = np.bincount(attached_chain, minlength=chain.max() + 1)
    first = np.r_[0, np.cumsum(per_chain)[:-1]]
    pairs = np.flatnonzero(per_chain == 2)
    u, v = attached_node[first[pairs]], attached_node[first[pairs] + 1]
    representative = np.zeros(chain.max() + 1, dtype=np.int64)
    representative[chain[ids]] = ids
    region_a, region_b = la[representative[pairs]], lb[representative[pairs]]
    keep = u != v
    u, v, region_a, region_b = u[keep], v[keep], region_a[keep], region_b[keep]
    if JUNCTION_REACH > 0:
        nodes[:n_triple] = _junctions(fine, triple, labels, centroids, nodes, u, v)
    half_u, half_v, half_region = [u, u], [v, v], [region_a, region_b]
    # boundary beams, through the surface corners
    is_corner = corner_node >= 0
    for loop in fine.loops:
        following = np.roll(loop, -1)
        at_corner = np.flatnonzero(is_corner[loop])
        change = np.flatnonzero(labels[loop] != labels[following])
        events = np.concatenate([corner_node[loop[at_corner]],
                                 node_of_edge[_edge_ids(E, len(fine.vertices), loop[change], following[change])]])
        after = np.concatenate([labels[loop[at_corner]], labels[following[change]]])
        sequence = np.argsort(np.concatenate([2 * at_corner, 2 * change + 1]), kind="stable")
        events, after = events[sequence], after[sequence]
        if len(events) < 2:
            raise MeshError("a boundary loop of the surface lies inside a single cell",
                            hint="ask for more cells (or a smaller mean beam length) so that cells resolve "
                                 "every hole and boundary of the surface")
        nxt = np.roll(events, -1)
        keep = events != nxt
        half_u.append(events[keep])
        half_v.append(nxt[keep])
        half_region.append(after[keep])
    flat, offsets, cell_labels = _cells(np.concatenate(half_u), np.concatenate(half_v), np.concatenate(half_region),
                                        len(centroids))
    return nodes, flat, offsets, cell_labels, boundary, corner


#: How far (in triangle sizes) a junction node may lie from its three-label triangle.
JUNCTION_REACH = 1.5


def _junctions(fine: _Fine, triple: np.ndarray, labels: np.ndarray, centroids: np.ndarray, nodes: np.ndarray,
               u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Node of each three-label triangle: the point of its plane at equal metric distance from the
    three clusters' centroids (the anisotropic Voronoi vertex), where it lies within JUNCTION_REACH
    triangle sizes of the triangle and turns no beam (u, v) around or shrinks it below half its
    length; else the node as it was (the mean of the triangle's edge points)."""
    corners = fine.faces[triple]
    x = fine.vertices[corners]
    M = fine.metric[corners].mean(axis=1)
    c = centroids[labels[corners]]
    normal = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
    A = np.zeros((len(triple), 3, 3))
    rhs = np.zeros((len(triple), 3))
    for row, (i, j) in enumerate(((1, 0), (2, 0))):
        A[:, row] = 2 * np.einsum("mij,mj->mi", M, c[:, i] - c[:, j])
        rhs[:, row] = np.einsum("mi,mij,mj->m", c[:, i], M, c[:, i]) - np.einsum("mi,mij,mj->m", c[:, j], M, c[:, j])
    A[:, 2] = normal
    rhs[:, 2] = np.einsum("mi,mi->m", normal, x.mean(axis=1))
    det = np.linalg.det(A)
    scale = np.einsum("mi,mi->m", A[:, 0], A[:, 0]) * np.einsum("mi,mi->m", A[:, 1], A[:, 1])
    ok = np.abs(det) > 1e-9 * np.sqrt(np.maximum(scale, 1e-300))
    fallback = nodes[:len(triple)]
    point = fallback.copy()
    if np.any(ok):
        point[ok] = np.linalg.solve(A[ok], rhs[ok][:, :, None])[:, :, 0]
    size = np.linalg.norm(x - x.mean(axis=1)[:, None], axis=2).max(axis=1)
    near = ok & (np.linalg.norm(point - x.mean(axis=1), axis=1) <= JUNCTION_REACH * size)
    placed = nodes.copy()
    placed[:len(triple)][near] = point[near]
    for _ in range(5):
        old, new = nodes[v] - nodes[u], placed[v] - placed[u]
        bad = np.einsum("ei,ei->e", old, new) < 0.5 * np.einsum("ei,ei->e", old, old)
        if not np.any(bad):
            break
        back = np.concatenate([u[bad], v[bad]])
        placed[back] = nodes[back]
    return placed[:len(triple)]


def _cells(half_u: np.ndarray, half_v: np.ndarray, half_region: np.ndarray, n_regions: int):
    """Each region's border edges closed into one loop: (flat loops, offsets, region of each loop).
    Compiled for regions whose border is one simple cycle, the Python walk for the others."""
    from .clustering import simple_cycles

    order = np.argsort(half_region, kind="stable")
    half_u, half_v, half_region = half_u[order], half_v[order], half_region[order]
    pointer = np.r_[0, np.cumsum(np.bincount(half_region, minlength=n_regions))]
    flat, lengths, status = simple_cycles(pointer, half_u.astype(np.int64), half_v.astype(np.int64))
    loops, regions = [], []
    starts = np.r_[0, np.cumsum(lengths)[:-1]]
    for region in range(n_regions):
        if status[region] == 0:
            loops.append(flat[starts[region]:starts[region] + lengths[region]])
        elif status[region] == 2:
            span = slice(pointer[region], pointer[region + 1])
            loop = _cycle(list(zip(half_u[span].tolist(), half_v[span].tolist())))
            if loop is None or len(loop) < 3:
                continue
            loops.append(np.array(loop, dtype=np.int64))
        else:
            continue
        regions.append(region)
    offsets = np.r_[0, np.cumsum([len(loop) for loop in loops])].astype(np.int64)
    flat = np.concatenate(loops) if loops else np.zeros(0, dtype=np.int64)
    return flat, offsets, np.array(regions, dtype=np.int64)


def _cycle(edges: list[tuple[int, int]]) -> list[int] | None:
    """The longest simple cycle walk through an undirected edge list (None if there is none)."""
    adjacency: dict[int, list[int]] = defaultdict(list)
    for a, b in set((min(a, b), max(a, b)) for a, b in edges):
        adjacency[a].append(b)
        adjacency[b].append(a)
    best: list[int] | None = None
    visited: set[int] = set()
    for start in adjacency:
        if start in visited or len(adjacency[start]) != 2:
            continue
        loop, previous, current = [start], start, adjacency[start][0]
        ok = True
        while current != start:
            if current in loop or len(adjacency[current]) != 2:
                ok = False
                break
            loop.append(current)
            nxt = [q for q in adjacency[current] if q != previous]
            previous, current = current, nxt[0]
        visited.update(loop)
        if ok and (best is None or len(loop) > len(best)):
            best = loop
    if best is None:
        best = _cycle_with_branches(adjacency)
    return best


def _cycle_with_branches(adjacency: dict[int, list[int]]) -> list[int] | None:
    """A cycle in a graph whose nodes may have degree > 2 (depth-first search)."""
    import networkx as nx

    graph = nx.Graph()
    for a, neighbours in adjacency.items():
        for b in neighbours:
            graph.add_edge(a, b)
    try:
        cycles = nx.cycle_basis(graph)
    except nx.NetworkXException:
        return None
    return max(cycles, key=len) if cycles else None


def _loop_ids(offsets: np.ndarray) -> np.ndarray:
    return np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))


def _following(offsets: np.ndarray) -> np.ndarray:
    """Index of the next entry of the same loop, for every entry of flat loops."""
    nxt = np.arange(1, offsets[-1] + 1)
    nxt[offsets[1:] - 1] = offsets[:-1]
    return nxt


def _orient(nodes: np.ndarray, flat: np.ndarray, offsets: np.ndarray, fine: _Fine, labels: np.ndarray,
            cell_labels: np.ndarray) -> np.ndarray:
    """Flat loops turned so that each cell's vector area agrees with its cluster's mean normal."""
    p, q = nodes[flat], nodes[flat[_following(offsets)]]
    vector_area = np.add.reduceat(np.cross(p, q), offsets[:-1], axis=0)
    weighted = fine.normals * fine.areas[:, None]
    normal = np.stack([np.bincount(labels, weights=weighted[:, k], minlength=labels.max() + 1) for k in range(3)], 1)
    flip = np.einsum("ij,ij->i", vector_area, normal[cell_labels]) < 0
    out = flat.copy()
    for i in np.flatnonzero(flip):
        out[offsets[i]:offsets[i + 1]] = flat[offsets[i]:offsets[i + 1]][::-1]
    return out


def _collapse_short_beams(nodes: np.ndarray, flat: np.ndarray, offsets: np.ndarray, boundary: np.ndarray,
                          corners: np.ndarray, local_size: np.ndarray):
    """Merge the ends of beams shorter than SHORT_BEAM_FRACTION of the local size (the larger of the
    two ends' sizes); drop cells that are no longer simple polygons of three or more nodes and
    nodes no cell uses."""
    a, b = flat, flat[_following(offsets)]
    length = np.linalg.norm(nodes[a] - nodes[b], axis=1)
    short = np.flatnonzero(length < SHORT_BEAM_FRACTION * np.maximum(local_size[a], local_size[b]))
    parent = np.arange(len(nodes))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for k in short[np.argsort(length[short], kind="stable")]:
        ra, rb = find(int(a[k])), find(int(b[k]))
        if ra == rb:
            continue
        limit = SHORT_BEAM_FRACTION * max(local_size[a[k]], local_size[b[k]])
        if np.linalg.norm(nodes[ra] - nodes[rb]) >= limit or (corners[ra] and corners[rb]):
            continue
        keep, drop = (ra, rb) if (corners[ra] or (boundary[ra] and not corners[rb])) else (rb, ra)
        if boundary[drop] and not boundary[keep]:
            keep, drop = drop, keep
        parent[drop] = keep
    roots = np.array([find(i) for i in range(len(nodes))]) if len(short) else np.arange(len(nodes))
    mapped = roots[flat]
    loop_of = _loop_ids(offsets)
    kept = mapped != mapped[_following(offsets)]
    mapped, loop_of = mapped[kept], loop_of[kept]
    lengths = np.bincount(loop_of, minlength=len(offsets) - 1)
    # a simple polygon: three or more nodes, none repeated
    order = np.lexsort((mapped, loop_of))
    repeated = np.zeros(len(offsets) - 1, dtype=bool)
    same = (loop_of[order][1:] == loop_of[order][:-1]) & (mapped[order][1:] == mapped[order][:-1])
    repeated[loop_of[order][1:][same]] = True
    good = (lengths >= 3) & ~repeated
    mapped = mapped[good[loop_of]]
    offsets = np.r_[0, np.cumsum(lengths[good])].astype(np.int64)
    used = np.unique(mapped)
    index = np.full(len(nodes), -1, dtype=np.int64)
    index[used] = np.arange(len(used))
    return nodes[used], index[mapped], offsets, boundary[used], corners[used], good


# ----------------------------------------------------------------------------- driver

@dataclass
class _Timing:
    clustering_s: float = 0.0
    extraction_s: float = 0.0
    sweeps: int = 0


def _tessellate(mesh: TriMesh, field: GuidingField, n_cells: int, settings: RemeshSettings,
                support_vertices: np.ndarray | None, say, timing: _Timing | None = None) -> PolyMesh:
    """The grid-shell of ``n_cells`` cells. Where the clustered mesh is small, several lattice
    offsets (seeds settings.seed, +1, ...; the lattice turned by LATTICE_TURNS_DEG in turn) are
    tried, up to START_BUDGET clustered vertices in all and MAX_STARTS starts, each giving its
    CANDIDATES_PER_START best clusterings (a single start gives one); the grid kept is the
    candidate's with the best _grid_score (valence 3, size and aspect within the band, hexagons),
    its nodes symmetrised where settings.symmetry_planes are given (engine.symmetry)."""
    from time import perf_counter

    say("refining the surface", 0.0)
    fine = _refine(mesh, field, n_cells)
    starts = int(max(1, min(MAX_STARTS, START_BUDGET // len(fine.vertices))))
    candidates: list[_Clusters] = []
    start = perf_counter()
    for start_index in range(starts):
        say(f"clustering {len(fine.vertices)} vertices into {n_cells} cells"
            + (f" (start {start_index + 1}/{starts})" if starts > 1 else ""), 0.1 + 0.8 * start_index / starts)
        candidates += _cluster(fine, n_cells, replace(settings, seed=settings.seed + start_index),
                               LATTICE_TURNS_DEG[start_index % len(LATTICE_TURNS_DEG)],
                               keep=CANDIDATES_PER_START if starts > 1 else 1)
    middle = perf_counter()
    # polygons of the candidates, best clustering first, until none left could score higher (the
    # clusters' hexagon share is the grid's but where extraction collapses a short beam)
    candidates.sort(key=_candidate_order)
    best, best_score = None, (-1.0, -1.0, -1.0)
    for clusters in candidates:
        if best_score >= (1.0, 1.0, clusters.hexagon_share):
            break
        polymesh = _polygons(mesh, fine, clusters, support_vertices)
        score = _grid_score(polymesh, mesh, field) if len(candidates) > 1 else best_score
        if best is None or score > best_score:
            best, best_score = polymesh, score
    if timing is not None:
        timing.clustering_s += middle - start
        timing.extraction_s += perf_counter() - middle
        timing.sweeps = candidates[0].sweeps
    assert best is not None  # there is at least one candidate
    return symmetrised_grid(best, tuple(settings.symmetry_planes)) if settings.symmetry_planes else best


def _grid_score(polymesh: PolyMesh, mesh: TriMesh, field: GuidingField) -> tuple[float, float, float]:
    """What the choice among candidate grids maximises: the share of interior nodes of valence 3
    (a short beam collapsed where four cells nearly meet leaves a valence-4 node), then 1 if the
    achieved size ratio and aspect lie within SHAPE_TOLERANCE of the field's D' and A' (0 if not),
    then the hexagon share of interior cells."""
    interior_nodes = ~polymesh.boundary
    valence3 = float(np.mean(polymesh.valence[interior_nodes] == 3)) if interior_nodes.any() else 1.0
    size_ratio, aspect = _size_and_aspect(polymesh, mesh, field)
    bounds = float(field.size.max() / field.size.min()), float(field.anisotropy.max())
    shaped = float(abs(size_ratio / bounds[0] - 1) <= SHAPE_TOLERANCE
                   and abs(aspect / bounds[1] - 1) <= SHAPE_TOLERANCE)
    interior = ~polymesh.face_boundary
    return valence3, shaped, float(np.mean(polymesh.face_degrees[interior] == 6)) if interior.any() else 0.0


#: Cells a boundary loop that lies inside one cell (a small courtyard among large cells) is split into.
RING_SPLIT = 3


def _split_ring_cells(fine: _Fine, labels: np.ndarray, centroids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Labels and centroids where every boundary loop meets its cells at three nodes or more, so
    that every cell is a disc and every hole stays a polygon: a cell that wraps a whole loop (a hole
    smaller than the cells round it, or a tiny roof) is cut into RING_SPLIT wedges round the loop's
    centre, and where two cells share a loop without a corner on it, the one with the longer arc
    of it is cut in two through its arc's middle (cuts in the plane of the cell, from the centre).
    A cell that would meet a loop, once cut, along a beam short enough to be collapsed
    (SHORT_BEAM_FRACTION of the largest cell at the loop) leaves the loop to its neighbour first,
    so that the loop keeps three nodes once short beams are collapsed."""
    is_corner = np.zeros(len(fine.vertices), dtype=bool)
    is_corner[fine.corners] = True
    labels, centres = labels.copy(), [c for c in centroids]

    def cut(owner: int, centre: np.ndarray, start: np.ndarray, pieces: int) -> None:
        members = np.flatnonzero(labels == owner)
        points = fine.vertices[members]
        _, _, axes = np.linalg.svd(points - points.mean(axis=0), full_matrices=False)
        local = (points - centre) @ axes[:2].T
        zero = np.arctan2(*((start - centre) @ axes[:2].T)[::-1])
        piece = (np.floor(((np.arctan2(local[:, 1], local[:, 0]) - zero) % (2 * np.pi)) / (2 * np.pi / pieces))
                 .astype(np.int64) % pieces)
        for k in range(pieces):
            part = members[piece == k]
            if len(part) == 0:
                continue
            centroid = np.average(fine.vertices[part], axis=0, weights=fine.areas[part])
            if k == 0:
                centres[owner] = centroid
            else:
                labels[part] = len(centres)
                centres.append(centroid)

    def split(loop: np.ndarray) -> None:
        around = labels[loop]
        change = np.flatnonzero(around != np.roll(around, 1))
        centre = fine.vertices[loop].mean(axis=0)
        if len(change) == 0:
            cut(int(around[0]), centre, fine.vertices[loop[0]], RING_SPLIT)
        elif len(change) == 2 and not is_corner[loop].any():
            runs = np.diff(np.r_[change, change[0] + len(loop)])
            longest = int(np.argmax(runs))
            middle = loop[(change[longest] + runs[longest] // 2) % len(loop)]
            # the arc's middle is the cut: a piece each side of it (half-turns from the opposite ray)
            cut(int(around[change[longest]]), centre, 2 * centre - fine.vertices[middle], 2)

    for loop in fine.loops:
        before = labels.copy(), list(centres)
        split(loop)
        around = labels[loop]
        change = np.flatnonzero(around != np.roll(around, 1))
        if is_corner[loop].any() or len(change) == 0:
            continue
        # a run whose beam is short enough to be collapsed (its two nodes become one) does not count
        node = _edge_points(fine, labels, np.asarray(centres), loop[change - 1], loop[change])
        area = np.bincount(labels, weights=fine.areas, minlength=len(centres))
        short = (np.linalg.norm(np.roll(node, -1, axis=0) - node, axis=1)
                 < SHORT_BEAM_FRACTION * np.sqrt(area[around[change]].max()))
        if (~short).sum() >= 3:
            continue
        # else its cell leaves the loop to the cell before it, and the loop's cells are cut again
        labels, centres = before[0], before[1]
        ends = np.r_[change[1:], change[0] + len(loop)]
        for first, last in zip(change[short], ends[short]):
            labels[loop[np.arange(first, last) % len(loop)]] = labels[loop[first - 1]]
        split(loop)
    return labels, np.asarray(centres)


def _polygons(mesh: TriMesh, fine: _Fine, clusters: _Clusters, support_vertices: np.ndarray | None) -> PolyMesh:
    """The polygon grid-shell of a clustering: extraction, orientation, short beams collapsed, supports."""
    labels, centroids = _split_ring_cells(fine, clusters.labels, clusters.centroids)
    nodes, flat, offsets, cell_labels, boundary, corners = _extract(fine, labels, centroids)
    flat = _orient(nodes, flat, offsets, fine, labels, cell_labels)
    region_area = np.bincount(labels, weights=fine.areas, minlength=len(centroids))
    # a node's size: its largest cell's (cut cells at corners are small, their neighbours are not)
    local_size = np.zeros(len(nodes))
    np.maximum.at(local_size, flat, np.sqrt(region_area)[np.repeat(cell_labels, np.diff(offsets))])
    nodes, flat, offsets, boundary, corners, _ = _collapse_short_beams(nodes, flat, offsets, boundary, corners,
                                                                       local_size)
    boundary_ids = np.unique(np.concatenate(fine.loops)) if fine.loops else np.zeros(0, dtype=np.int64)
    boundary_ids = boundary_ids[boundary_ids < fine.n_surface_vertices]
    supports = _support_nodes(mesh, nodes, boundary, support_vertices, boundary_ids=boundary_ids)
    loops = tuple(np.split(flat, offsets[1:-1]))
    return PolyMesh(nodes=nodes, faces=loops, boundary=boundary, supports=supports, corners=corners)


def _support_nodes(mesh: TriMesh, nodes: np.ndarray, boundary: np.ndarray, support_vertices: np.ndarray | None,
                   *, boundary_ids: np.ndarray | None = None) -> np.ndarray:
    """Boundary nodes whose nearest boundary vertex of the surface is supported, and the node
    nearest to each supported vertex (``boundary_ids``: the surface's boundary vertices, when known)."""
    supports = np.zeros(len(nodes), dtype=bool)
    if support_vertices is None or not np.any(support_vertices):
        return supports
    support_vertices = np.asarray(support_vertices, dtype=bool)
    if boundary_ids is None:
        boundary_ids = np.flatnonzero(mesh.boundary_vertices)
    if len(boundary_ids) and np.any(boundary):
        _, nearest = cKDTree(mesh.vertices[boundary_ids]).query(nodes[boundary])
        supports[np.flatnonzero(boundary)[support_vertices[boundary_ids[nearest]]]] = True
    candidates = np.flatnonzero(boundary) if np.any(boundary) else np.arange(len(nodes))
    _, nearest_node = cKDTree(nodes[candidates]).query(mesh.vertices[support_vertices])
    supports[candidates[nearest_node]] = True
    return supports


def _cells_for_length(mesh: TriMesh, field: GuidingField, mean_beam_length: float) -> int:
    """Cell count whose regular hexagons (side l) cover the surface: area / (3 sqrt3 / 2 l^2), with
    the field's size variation (sizes relative) folded in."""
    weights = mesh.vertex_areas / field.size**2
    mean_h2 = mesh.area / max(weights.sum(), 1e-300)
    # cells of relative size h have area ~ h^2 * c; a hexagon of side l has area 3 sqrt3/2 l^2
    scale = mesh.area / (1.5 * np.sqrt(3.0) * mean_beam_length**2)
    return max(4, int(round(scale * mean_h2 / np.mean(mean_h2))))


def remesh(mesh: TriMesh, field: GuidingField, settings: RemeshSettings, *,
           support_vertices: np.ndarray | None = None, progress: Progress | None = None) -> RemeshResult:
    """The statics-aware Voronoi grid-shell of ``mesh`` under ``field`` (see the module docstring).
    With symmetry planes, a grid that cannot be made symmetric (too few cells for the planes to
    keep seeds on every part, or nodes that do not settle) is remeshed without them, and the
    quality's ``symmetry`` says so (``symmetric`` false, ``reason``)."""
    if not settings.symmetry_planes:
        return _remesh(mesh, field, settings, support_vertices=support_vertices, progress=progress)
    try:
        result = _remesh(mesh, field, settings, support_vertices=support_vertices, progress=progress)
        if np.all(np.isfinite(result.polymesh.nodes)):
            return result
        reason = "its nodes did not settle (non-finite positions)"
    except MeshError as error:
        reason = str(error).splitlines()[0]
    result = _remesh(mesh, field, replace(settings, symmetry_planes=()), support_vertices=support_vertices,
                     progress=progress)
    result.quality["symmetry"] = {"symmetric": False, "reason": f"not made symmetric: {reason}",
                                  "planes": [list(map(list, plane)) for plane in settings.symmetry_planes]}
    return result


def _remesh(mesh: TriMesh, field: GuidingField, settings: RemeshSettings, *,
            support_vertices: np.ndarray | None = None, progress: Progress | None = None) -> RemeshResult:
    """The grid of ``remesh`` with the settings as given.

    The quality dict also holds ``clustering_s`` and ``extraction_s`` (seconds spent in the
    clustering, including refinement and seeding, and in the polygon extraction, over all
    tessellations the size target needed; the extraction includes choosing among candidate grids)
    and ``clustering_sweeps`` (those of the start whose grid was kept, in the last tessellation)."""
    def say(text: str, fraction: float | None = None) -> None:
        if progress is not None:
            progress(text, fraction)

    if len(field.size) != mesh.n_vertices:
        raise InputError(f"remesh: the field has {len(field.size)} values for {mesh.n_vertices} vertices")
    aspect = float(field.anisotropy.max())
    ratio = float(field.size.max() / field.size.min())
    if settings.n_cells is not None:
        n_cells = settings.n_cells
    else:
        length = settings.mean_beam_length
        if length is None:
            # first guess of the mean beam length for L_tot: a hexagonal grid has ~1.5 beams per cell
            length = np.sqrt(mesh.area) / 10.0
        n_cells = _cells_for_length(mesh, field, length)
    max_cells = MAX_FINE_VERTICES // 12
    if n_cells > max_cells:
        raise InputError(f"remesh: {n_cells} cells is more than this remesher handles ({max_cells})",
                         hint="ask for fewer cells or a longer mean beam length")
    timing = _Timing()
    polymesh = _tessellate(mesh, field, n_cells, settings, support_vertices, say, timing)
    if settings.mean_beam_length is not None:
        for _ in range(3):
            achieved = float(polymesh.beam_lengths.mean())
            if abs(achieved / settings.mean_beam_length - 1) < 0.01:
                break
            n_cells = max(4, int(round(n_cells * (achieved / settings.mean_beam_length) ** 2)))
            polymesh = _tessellate(mesh, field, n_cells, settings, support_vertices, say, timing)
    if settings.n_cells is not None and settings.symmetry_planes:
        polymesh = _symmetric_count(mesh, field, settings, support_vertices, say, polymesh, timing)
    if settings.total_length is not None:
        polymesh, n_cells = _match_total_length(mesh, field, settings, support_vertices, say, polymesh, n_cells,
                                                timing)
    quality = polymesh_quality(polymesh, mesh=mesh, field=field)
    quality.update({"n_cells_requested": int(n_cells), "field_size_ratio": ratio, "field_max_aspect": aspect,
                    "clustering_s": timing.clustering_s, "extraction_s": timing.extraction_s,
                    "clustering_sweeps": timing.sweeps})
    if settings.symmetry_planes:
        quality["symmetry"] = symmetry_record(polymesh.nodes, settings.symmetry_planes,
                                              float(polymesh.beam_lengths.mean()))
    if settings.total_length is not None:
        quality["total_length_target_m"] = settings.total_length
        quality["total_length_error"] = polymesh.total_length / settings.total_length - 1.0
    if quality["n_faces"] < 3:
        raise InputError("remesh: the tessellation degenerated", hint="lower D or A, or ask for more cells")
    return RemeshResult(polymesh=polymesh, quality=quality)


#: A symmetric grid's cell count is matched to the count asked for within this share: seeds near a
#: plane merge with their mirrors, and so do consecutive mirrored pairs of clusters along a plane
#: (_merged_pairs), so the same seed count gives fewer cells than without planes.
SYMMETRIC_COUNT_TOLERANCE = 0.03
#: Tessellations after the first that the match of a symmetric grid's cell count may take.
SYMMETRIC_COUNT_TRIES = 4


def _symmetric_count(mesh, field, settings, support_vertices, say, polymesh, timing=None):
    """The symmetric grid with the cell count nearest ``settings.n_cells``: up to
    SYMMETRIC_COUNT_TRIES more tessellations with the seed count scaled by asked / built (a seed
    count tried before moved by one towards the count asked)."""
    asked = settings.n_cells
    best = polymesh
    trial = asked
    tried = {asked}
    for _ in range(SYMMETRIC_COUNT_TRIES):
        if abs(best.n_faces / asked - 1) <= SYMMETRIC_COUNT_TOLERANCE:
            break
        step = 1 if polymesh.n_faces < asked else -1
        trial = max(4, int(round(trial * asked / max(polymesh.n_faces, 1))))
        while trial in tried:
            trial = max(4, trial + step)
        tried.add(trial)
        say(f"symmetric grid: {polymesh.n_faces} cells for {asked} asked, seeding {trial}")
        polymesh = _tessellate(mesh, field, trial, settings, support_vertices, say, timing)
        if abs(polymesh.n_faces - asked) < abs(best.n_faces - asked):
            best = polymesh
    return best


def _match_total_length(mesh, field, settings, support_vertices, say, polymesh, n_cells, timing=None):
    """Secant iteration on the cell count (L_tot ~ sqrt(cells)) to meet L_tot within 1 %."""
    target = settings.total_length
    best = (abs(polymesh.total_length / target - 1), polymesh, n_cells)
    tried = {n_cells}
    for _ in range(10):
        if best[0] < 0.01:
            break
        ratio = target / polymesh.total_length
        proposal = max(4, int(round(n_cells * ratio**2)))
        if proposal in tried:
            proposal = proposal + (1 if ratio > 1 else -1)
        if proposal in tried:
            break
        n_cells = proposal
        tried.add(n_cells)
        polymesh = _tessellate(mesh, field, n_cells, settings, support_vertices, say, timing)
        error = abs(polymesh.total_length / target - 1)
        if error < best[0]:
            best = (error, polymesh, n_cells)
    if best[0] >= 0.01:
        # fine adjustment: other lattice offsets at the best cell count
        error, polymesh, n_cells = best
        for seed in range(1, 12):
            candidate = _tessellate(mesh, field, n_cells, replace(settings, seed=settings.seed + seed),
                                    support_vertices, say, timing)
            candidate_error = abs(candidate.total_length / target - 1)
            if candidate_error < best[0]:
                best = (candidate_error, candidate, n_cells)
            if best[0] < 0.01:
                break
    return best[1], best[2]


# ----------------------------------------------------------------------------- quality

def _face_groups(polymesh: PolyMesh):
    """(face ids, (m, d, 3) node coordinates) for each face degree d."""
    degrees = polymesh.face_degrees
    for d in np.unique(degrees):
        ids = np.flatnonzero(degrees == d)
        loops = np.stack([polymesh.faces[i] for i in ids])
        yield ids, polymesh.nodes[loops]


def polymesh_quality(polymesh: PolyMesh, *, mesh: TriMesh | None = None, field: GuidingField | None = None) -> dict:
    """Quality figures of a grid-shell (JSON-ready), see docs/formats.md.

    Achieved size per cell: sqrt(area); aspect: sqrt of the ratio of the PCA eigenvalues of
    its nodes (a regular polygon, and a regular one stretched by a, give 1 and a); interior
    cells only. With a field, the achieved size ratio is the field's ratio D' to the power of
    the log-log slope of achieved against prescribed size (1 when cells follow the field
    exactly), so it compares with D even where the extremes of the field lie on the boundary;
    without one it is the 95th over the 5th percentile of the sizes (kept as size_ratio_p5_p95).
    The achieved aspect is the 95th percentile.
    """
    degrees = polymesh.face_degrees
    interior = ~polymesh.face_boundary
    interior_nodes = ~polymesh.boundary
    lengths = polymesh.beam_lengths
    mean_length = float(lengths.mean()) if len(lengths) else 0.0
    histogram = {int(d): int(c) for d, c in zip(*np.unique(degrees, return_counts=True))}
    n = polymesh.n_faces
    sizes, aspects, regularity = np.zeros(n), np.zeros(n), np.zeros(n)
    planarity, centroids = np.zeros(n), np.zeros((n, 3))
    smallest = 180.0
    for ids, p in _face_groups(polymesh):
        # (m faces, d nodes, 3)
        following = np.roll(p, -1, axis=1)
        sizes[ids], centroids[ids], centred, aspects[ids], vt = _cell_shapes(p)
        if p.shape[1] > 3:
            planarity[ids] = np.abs(np.einsum("mdi,mi->md", centred, vt[:, -1])).max(axis=1)
        # regularity: edge-length spread after un-stretching the cell's own anisotropy
        local = np.einsum("mdi,mki->mdk", centred, vt[:, :2])
        spread = np.sqrt(np.maximum(np.linalg.svd(local, compute_uv=False), 1e-300))
        unstretched = local / spread[:, None, :] * spread.mean(axis=1)[:, None, None]
        edges = np.linalg.norm(unstretched - np.roll(unstretched, -1, axis=1), axis=2)
        regularity[ids] = edges.std(axis=1) / np.maximum(edges.mean(axis=1), 1e-300)
        to_previous, to_next = np.roll(p, 1, axis=1) - p, following - p
        cosine = np.einsum("mdi,mdi->md", to_previous, to_next) / np.maximum(
            np.linalg.norm(to_previous, axis=2) * np.linalg.norm(to_next, axis=2), 1e-300)
        smallest = min(smallest, float(np.degrees(np.arccos(np.clip(cosine, -1, 1))).min()))
    pick = interior if interior.sum() >= 4 else np.ones(n, dtype=bool)
    lo, hi = np.percentile(sizes[pick], [5, 95])
    quality = {
        "n_nodes": int(polymesh.n_nodes), "n_beams": int(len(polymesh.edges)), "n_faces": int(polymesh.n_faces),
        "hexagon_share_interior": float(np.mean(degrees[interior] == 6)) if interior.any() else 0.0,
        "face_degree_histogram": histogram,
        "valence3_share_interior": (float(np.mean(polymesh.valence[interior_nodes] == 3))
                                    if interior_nodes.any() else 0.0),
        "achieved_size_ratio": float(hi / max(lo, 1e-300)),
        "achieved_max_aspect": float(np.percentile(aspects[pick], 95)),
        "regularity": float(np.mean(regularity)),
        "planarity_max_m": float(planarity.max()) if n else 0.0,
        "planarity_p95_m": float(np.percentile(planarity, 95)) if n else 0.0,
        "planarity_max_mm": float(1000 * planarity.max()) if n else 0.0,
        "planarity_max_rel": float(planarity.max() / max(mean_length, 1e-300)) if n else 0.0,
        "planarity_p95_rel": float(np.percentile(planarity, 95) / max(mean_length, 1e-300)) if n else 0.0,
        "shortest_beam_m": float(lengths.min()) if len(lengths) else 0.0,
        "mean_beam_length_m": mean_length, "total_length_m": float(lengths.sum()),
        "smallest_angle_deg": smallest,
    }
    if mesh is not None:
        distance = _distance_to_surface(mesh, polymesh.nodes)
        quality["closeness_max_rel"] = float(distance.max() / mesh.diagonal)
        quality["closeness_mean_rel"] = float(distance.mean() / mesh.diagonal)
    if mesh is not None and field is not None:
        quality["size_ratio_p5_p95"] = quality["achieved_size_ratio"]
        prescribed = _prescribed_sizes(centroids[pick], mesh, field)
        quality["field_size_span_cells"] = _span(prescribed)
        graded = _size_grading(sizes[pick], prescribed, field)
        if graded is not None:
            quality["size_correlation"], quality["size_grading_slope"], quality["achieved_size_ratio"] = graded
            from scipy.stats import spearmanr

            quality["size_rank_correlation"] = float(spearmanr(prescribed, sizes[pick]).statistic)
        else:
            quality["size_correlation"] = quality["size_rank_correlation"] = None
    return quality


def _cell_shapes(p: np.ndarray):
    """Cells of one degree, nodes p (m, d, 3): sizes sqrt(area) (m,), centroids (m, 3), centred
    nodes (m, d, 3), aspects (m,: sqrt of the ratio of the two largest PCA eigenvalues) and the
    PCA axes (m, 3, 3)."""
    following = np.roll(p, -1, axis=1)
    sizes = np.sqrt(0.5 * np.linalg.norm(np.cross(p, following).sum(axis=1), axis=1))
    centroids = p.mean(axis=1)
    centred = p - centroids[:, None, :]
    _, s, vt = np.linalg.svd(centred, full_matrices=False)
    s2 = np.maximum(s[:, :2], 1e-300)
    return sizes, centroids, centred, s2[:, 0] / s2[:, 1], vt


def _prescribed_sizes(centroids: np.ndarray, mesh: TriMesh, field: GuidingField) -> np.ndarray:
    """The field's size at the surface vertex nearest each cell centroid (m,)."""
    _, nearest = cKDTree(mesh.vertices).query(centroids)
    return field.size[nearest]


def _span(sizes: np.ndarray) -> float:
    """95th over 5th percentile of sizes: the grading the measured cells can show. It can be far
    below the field's max/min where the field varies only within a cell of the boundary, whose cut
    cells the figures leave out (the real roofs' fields vary most next to their supports)."""
    lo, hi = np.percentile(sizes, [5, 95])
    return float(hi / max(lo, 1e-300))


def _size_grading(sizes: np.ndarray, prescribed: np.ndarray, field: GuidingField):
    """(correlation of achieved and prescribed size, log-log slope, achieved size ratio D'^slope)
    of cells, or None where the field's size (or the cells') does not vary."""
    if not (np.std(prescribed) > 1e-9 * prescribed.mean() and np.std(sizes) > 0):
        return None
    correlation = float(np.corrcoef(prescribed, sizes)[0, 1])
    # grading actually achieved: the field's ratio to the power of the log-log slope
    slope = np.polyfit(np.log(prescribed), np.log(sizes), 1)[0]
    return correlation, float(slope), float((field.size.max() / field.size.min()) ** slope)


def _size_and_aspect(polymesh: PolyMesh, mesh: TriMesh, field: GuidingField) -> tuple[float, float]:
    """The grid's achieved size ratio and aspect, as polymesh_quality reports them."""
    n = polymesh.n_faces
    sizes, aspects, centroids = np.zeros(n), np.zeros(n), np.zeros((n, 3))
    for ids, p in _face_groups(polymesh):
        sizes[ids], centroids[ids], _, aspects[ids], _ = _cell_shapes(p)
    interior = ~polymesh.face_boundary
    pick = interior if interior.sum() >= 4 else np.ones(n, dtype=bool)
    lo, hi = np.percentile(sizes[pick], [5, 95])
    graded = _size_grading(sizes[pick], _prescribed_sizes(centroids[pick], mesh, field), field)
    size_ratio = graded[2] if graded is not None else float(hi / max(lo, 1e-300))
    return size_ratio, float(np.percentile(aspects[pick], 95))


def _distance_to_surface(mesh: TriMesh, points: np.ndarray) -> np.ndarray:
    from .proximity import closest_points

    return closest_points(mesh.vertices, mesh.faces, points)[1]
