"""Statics-aware Voronoi remeshing: anisotropic centroidal Voronoi tessellation on the surface.

(METHOD.md section 3.) The direct discrete route, as a clustering of the surface's vertices:
the surface is used as it is when it has at least VERTICES_PER_CELL vertices per cell and is
refined (1-to-4) until it has REFINED_VERTICES_PER_CELL otherwise. Every vertex i carries a weight w_i = area_i h_i^-p
(p = DENSITY_POWER) and the field's metric M_i (its tangent part, h sqrt(a) along u and
h / sqrt(a) across, plus a small normal part so that it is invertible). The clusters minimise
sum_k sum_{i in k} w_i (x_i - c_k)^T M_i (x_i - c_k) by boundary-vertex moves that keep every
cluster connected (engine/remeshing/clustering.py: an anisotropic Valette-Chassery approximated CVD).
Seeds start on a hexagonal lattice over the best-fit plane and grow into clusters along metric
edge lengths (multi-source Dijkstra); Lloyd steps (seeds moved to the over-relaxed centroids,
clusters regrown and clustered again) grade the cells, which single-vertex moves cannot; above
about four times COARSEST_CELLS cells a coarse level runs first and its centroids and the
midpoints of neighbouring centroids seed the next. At a few cells across, over-relaxed Lloyd
steps carry the clusters among equally graded local minima whose hexagon shares differ by up to
20 points, so the clusterings met along the finest level's steps are candidates; small meshes also
try several lattice offsets. The grid kept has every interior node of valence 3, its size ratio
and aspect within SHAPE_TOLERANCE of the field's, and the most hexagons. The polygon grid-shell
is the dual of the clusters (engine/remeshing/cell_extraction.py). Why this route and not the
deform-then-uniform-CVT one, and why clustering rather than Lloyd iterations alone:
docs/decisions.md.

This module is the driver: the settings, the clustering (seeds, growth, Lloyd steps, coarse to
fine), the choice among candidate grids and the size targets. The clustered mesh is
engine/geometry/fine_mesh.py's, the symmetric seeds engine/geometry/mirror_seeds.py's, the polygons of a clustering
engine/remeshing/cell_extraction.py's and the quality figures engine/remeshing/grid_quality.py's; none of them
imports this module.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from ..errors import InputError, MeshError
from ..geometry.fine_mesh import MAX_FINE_VERTICES, _Fine, _refine
from ..geometry.mirror_seeds import (
    JUNCTION_ROUNDS,
    _merged_pairs,
    _mirrors,
    _onto_planes,
    _symmetric_clusters,
    _symmetric_seeds,
)
from ..geometry.symmetry import symmetrised_grid, symmetry_record
from ..mesh import PolyMesh, TriMesh, best_fit_plane
from .cell_extraction import _polygons
from .field import GuidingField
from .grid_quality import polymesh_quality, size_and_aspect

# polymesh_quality is engine/remeshing/grid_quality.py's, exported here too for the callers that
# import it from the remesher
__all__ = ["RemeshSettings", "RemeshResult", "DegenerateTessellation", "remesh", "polymesh_quality"]


class DegenerateTessellation(InputError):
    """The remesh left fewer than three cells (too few cells asked for the surface and its field)."""

Progress = Callable[[str, "float | None"], None]
#: The grid as a caller will make it buildable (collapses of the beams its joints cannot take).
Buildable = Callable[[PolyMesh], PolyMesh]

#: Vertex weight w = area * h^-DENSITY_POWER (measured: gives achieved size ~ h, see tests).
DENSITY_POWER = 2.0
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
#: Shares of interior nodes with three beams and of interior hexagons that the choice among
#: candidates asks first (issue 13's targets for the optimised grid).
VALENCE3_TARGET = 0.95
HEXAGON_TARGET = 0.70


@dataclass(frozen=True, kw_only=True)
class RemeshSettings:
    """Size target: exactly one of n_cells, mean_beam_length (m) or total_length (m, L_tot,
    met within 1 %); lloyd_iterations: the most Lloyd steps (seeds moved to the over-relaxed
    cluster centroids, clusters regrown and clustered again) at each level of the clustering; at
    most COARSE_LLOYD_STEPS are taken at the coarsest level and LLOYD_STEPS at the finer ones, so
    values above COARSE_LLOYD_STEPS change nothing and 0 keeps the clustering of the initial
    lattice; seed of the lattice's random offset (small meshes also try the next seeds);
    symmetry_planes: up to two (point, normal) pairs (m) the grid is made symmetric about (the
    field's, engine.remeshing.field.FieldSettings), none by default."""

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
    from .clustering import cluster_vertices

    rng = np.random.default_rng(settings.seed)
    adjacency, weights, moments, tree = _clustering_inputs(fine)
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


def _clustering_inputs(fine: _Fine):
    """(adjacency, vertex weights, centred moments, k-d tree) of the clustering, the ones that are
    kept on ``fine`` made on first use."""
    from .clustering import centred_moments

    adjacency = _adjacency(fine)
    weights = fine.areas * fine.inverse_h2 ** (DENSITY_POWER / 2)
    if fine.moments is None:
        fine.moments = centred_moments(fine.vertices, fine.metric, weights)
    if fine.tree is None:
        fine.tree = cKDTree(fine.vertices)
    return adjacency, weights, fine.moments, fine.tree


def _cluster_start(job: tuple) -> list[_Clusters]:
    """``_cluster(*job)``: one start, as a process pool runs it."""
    return _cluster(*job)


def _candidate_order(clusters: _Clusters) -> tuple[float, float]:
    """Sort key, best first: the larger interior hexagon share, then the lower energy."""
    return -clusters.hexagon_share, clusters.energy


# ----------------------------------------------------------------------------- driver

#: ``map(function, jobs)`` that runs a tessellation's starts: the builtin one after another, or a
#: process pool's (``concurrent.futures.Executor.map``) side by side, with the same results.
StartsMap = Callable[[Callable[[tuple], list], list], Iterable[list]]


@dataclass
class _Tessellations:
    """What the tessellations of one remesh share: their seconds and sweeps, and the map that runs
    their starts."""

    clustering_s: float = 0.0
    extraction_s: float = 0.0
    sweeps: int = 0
    starts_map: StartsMap | None = None


def _tessellate(mesh: TriMesh, field: GuidingField, n_cells: int, settings: RemeshSettings,
                support_vertices: np.ndarray | None, say, timing: _Tessellations | None = None,
                buildable: Buildable | None = None) -> PolyMesh:
    """The grid-shell of ``n_cells`` cells. Where the clustered mesh is small, several lattice
    offsets (seeds settings.seed, +1, ...; the lattice turned by LATTICE_TURNS_DEG in turn) are
    tried, up to START_BUDGET clustered vertices in all and MAX_STARTS starts, each giving its
    CANDIDATES_PER_START best clusterings (a single start gives one); the grid kept is the
    candidate's with the best _grid_score (valence 3, size and aspect within the band, hexagons)
    of the grid as ``buildable`` will make it (the caller's collapses of beams its joints cannot
    take cost hexagons and three-beam nodes; the candidate is returned as extracted), its nodes
    symmetrised where settings.symmetry_planes are given (engine.geometry.symmetry)."""
    from time import perf_counter

    say("refining the surface", 0.0)
    fine = _refine(mesh, field, n_cells)
    starts = int(max(1, min(MAX_STARTS, START_BUDGET // len(fine.vertices))))
    candidates: list[_Clusters] = []
    start = perf_counter()
    turns = LATTICE_TURNS_DEG
    jobs = [(fine, n_cells, replace(settings, seed=settings.seed + index), turns[index % len(turns)],
             CANDIDATES_PER_START if starts > 1 else 1) for index in range(starts)]
    starts_map = timing.starts_map if timing is not None and starts > 1 else None
    if starts_map is not None:  # the starts side by side: the caches they share made once, here
        _clustering_inputs(fine)
        _mirrors(fine, tuple(settings.symmetry_planes))
    say(f"clustering {len(fine.vertices)} vertices into {n_cells} cells"
        + (f" ({starts} starts)" if starts > 1 else ""), 0.1)
    for done, found in enumerate((starts_map or map)(_cluster_start, jobs)):
        candidates += found
        if starts > 1:
            say(f"clustering {len(fine.vertices)} vertices into {n_cells} cells (start {done + 1}/{starts} done)",
                0.1 + 0.8 * (done + 1) / starts)
    middle = perf_counter()
    # polygons of the candidates, best clustering first, until none left could score higher (the
    # clusters' hexagon share is the grid's but where extraction collapses a short beam)
    candidates.sort(key=_candidate_order)
    best: PolyMesh | None = None
    best_score: tuple[float, ...] = (-1.0,)
    for clusters in candidates:
        # the best a candidate can score: its clusters' hexagons (extraction and collapses lower them)
        share = clusters.hexagon_share
        if best_score >= (1.0, 1.0, float(share >= HEXAGON_TARGET), 1.0, share):
            break
        polymesh = _polygons(mesh, fine, clusters.labels, clusters.centroids, support_vertices)
        if len(candidates) > 1:  # (one candidate: nothing to compare, nothing to make buildable)
            score = _grid_score(buildable(polymesh) if buildable is not None else polymesh, mesh, field)
        else:
            score = best_score
        if best is None or score > best_score:
            best, best_score = polymesh, score
    if timing is not None:
        timing.clustering_s += middle - start
        timing.extraction_s += perf_counter() - middle
        timing.sweeps = candidates[0].sweeps
    assert best is not None  # there is at least one candidate
    return symmetrised_grid(best, tuple(settings.symmetry_planes)) if settings.symmetry_planes else best


def _grid_score(polymesh: PolyMesh, mesh: TriMesh, field: GuidingField) -> tuple[float, ...]:
    """What the choice among candidate grids maximises, in turn: whether at least VALENCE3_TARGET of
    the interior nodes have three beams (a short beam collapsed where four cells nearly meet leaves
    a node of four), whether the achieved size ratio and aspect lie within SHAPE_TOLERANCE of the
    field's D' and A', whether at least HEXAGON_TARGET of the interior cells are hexagons, then the
    valence-3 share and the hexagon share (1.0 / 0.0 for the targets)."""
    interior_nodes = ~polymesh.boundary
    valence3 = float(np.mean(polymesh.valence[interior_nodes] == 3)) if interior_nodes.any() else 1.0
    size_ratio, aspect = size_and_aspect(polymesh, mesh, field)
    bounds = float(field.size.max() / field.size.min()), float(field.anisotropy.max())
    shaped = float(abs(size_ratio / bounds[0] - 1) <= SHAPE_TOLERANCE
                   and abs(aspect / bounds[1] - 1) <= SHAPE_TOLERANCE)
    interior = ~polymesh.face_boundary
    hexagons = float(np.mean(polymesh.face_degrees[interior] == 6)) if interior.any() else 0.0
    return float(valence3 >= VALENCE3_TARGET), shaped, float(hexagons >= HEXAGON_TARGET), valence3, hexagons


def _cells_for_length(mesh: TriMesh, field: GuidingField, mean_beam_length: float) -> int:
    """Cell count whose regular hexagons (side l) cover the surface: area / (3 sqrt3 / 2 l^2), with
    the field's size variation (sizes relative) folded in."""
    weights = mesh.vertex_areas / field.size**2
    mean_h2 = mesh.area / max(weights.sum(), 1e-300)
    # cells of relative size h have area ~ h^2 * c; a hexagon of side l has area 3 sqrt3/2 l^2
    scale = mesh.area / (1.5 * np.sqrt(3.0) * mean_beam_length**2)
    return max(4, int(round(scale * mean_h2 / np.mean(mean_h2))))


def remesh(mesh: TriMesh, field: GuidingField, settings: RemeshSettings, *,
           support_vertices: np.ndarray | None = None, progress: Progress | None = None,
           buildable: Buildable | None = None, starts_map: StartsMap | None = None) -> RemeshResult:
    """The statics-aware Voronoi grid-shell of ``mesh`` under ``field`` (see the module docstring).
    ``buildable``: the grid as the caller will make it buildable (collapses of the beams its joints
    cannot take); where several candidate grids are made, they are compared as such.
    ``starts_map``: runs the starts of a tessellation (a process pool's ``map`` puts them on the
    cores; the grid is the same).
    With symmetry planes, a grid that cannot be made symmetric (too few cells for the planes to
    keep seeds on every part, or nodes that do not settle) is remeshed without them, and the
    quality's ``symmetry`` says so (``symmetric`` false, ``reason``)."""
    if not settings.symmetry_planes:
        return _remesh(mesh, field, settings, support_vertices=support_vertices, progress=progress,
                       buildable=buildable, starts_map=starts_map)
    try:
        result = _remesh(mesh, field, settings, support_vertices=support_vertices, progress=progress,
                         buildable=buildable, starts_map=starts_map)
        if np.all(np.isfinite(result.polymesh.nodes)):
            return result
        reason = "its nodes did not settle (non-finite positions)"
    except MeshError as error:
        reason = str(error).splitlines()[0]
    result = _remesh(mesh, field, replace(settings, symmetry_planes=()), support_vertices=support_vertices,
                     progress=progress, buildable=buildable, starts_map=starts_map)
    result.quality["symmetry"] = {"symmetric": False, "reason": f"not made symmetric: {reason}",
                                  "planes": [list(map(list, plane)) for plane in settings.symmetry_planes]}
    return result


def _remesh(mesh: TriMesh, field: GuidingField, settings: RemeshSettings, *,
            support_vertices: np.ndarray | None = None, progress: Progress | None = None,
            buildable: Buildable | None = None, starts_map: StartsMap | None = None) -> RemeshResult:
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
    timing = _Tessellations(starts_map=starts_map)
    polymesh = _tessellate(mesh, field, n_cells, settings, support_vertices, say, timing, buildable)
    if settings.mean_beam_length is not None:
        for _ in range(3):
            achieved = float(polymesh.beam_lengths.mean())
            if abs(achieved / settings.mean_beam_length - 1) < 0.01:
                break
            n_cells = max(4, int(round(n_cells * (achieved / settings.mean_beam_length) ** 2)))
            polymesh = _tessellate(mesh, field, n_cells, settings, support_vertices, say, timing, buildable)
    if settings.n_cells is not None and settings.symmetry_planes:
        polymesh = _symmetric_count(mesh, field, settings, support_vertices, say, polymesh, timing, buildable)
    if settings.total_length is not None:
        polymesh, n_cells = _match_total_length(mesh, field, settings, support_vertices, say, polymesh, n_cells,
                                                timing, buildable)
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
        raise DegenerateTessellation("remesh: the tessellation degenerated", hint="lower D or A, or ask for more cells")
    return RemeshResult(polymesh=polymesh, quality=quality)


#: A symmetric grid's cell count is matched to the count asked for within this share: seeds near a
#: plane merge with their mirrors, and so do consecutive mirrored pairs of clusters along a plane
#: (_merged_pairs), so the same seed count gives fewer cells than without planes.
SYMMETRIC_COUNT_TOLERANCE = 0.03
#: Tessellations after the first that the match of a symmetric grid's cell count may take.
SYMMETRIC_COUNT_TRIES = 4


def _symmetric_count(mesh, field, settings, support_vertices, say, polymesh, timing=None, buildable=None):
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
        polymesh = _tessellate(mesh, field, trial, settings, support_vertices, say, timing, buildable)
        if abs(polymesh.n_faces - asked) < abs(best.n_faces - asked):
            best = polymesh
    return best


def _match_total_length(mesh, field, settings, support_vertices, say, polymesh, n_cells, timing=None,
                        buildable=None):
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
        polymesh = _tessellate(mesh, field, n_cells, settings, support_vertices, say, timing, buildable)
        error = abs(polymesh.total_length / target - 1)
        if error < best[0]:
            best = (error, polymesh, n_cells)
    if best[0] >= 0.01:
        # fine adjustment: other lattice offsets at the best cell count
        error, polymesh, n_cells = best
        for seed in range(1, 12):
            candidate = _tessellate(mesh, field, n_cells, replace(settings, seed=settings.seed + seed),
                                    support_vertices, say, timing, buildable)
            candidate_error = abs(candidate.total_length / target - 1)
            if candidate_error < best[0]:
                best = (candidate_error, candidate, n_cells)
            if best[0] < 0.01:
                break
    return best[1], best[2]
