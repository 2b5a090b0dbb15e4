"""Statics-aware Voronoi remeshing: anisotropic centroidal Voronoi tessellation on the surface.

(METHOD.md section 3.) The direct discrete route: the surface is refined until a cell spans
some tens of vertices; each fine vertex belongs to the seed nearest in the guiding field's
metric (the mean of the metrics at the vertex and at the seed, among the Euclidean-nearest
seeds), so a cell is an ellipse of semi-axes h sqrt(a) and h / sqrt(a); over-relaxed Lloyd
iterations move each seed to its region's centroid weighted by h^-3 (see _lloyd_step). The
polygon grid-shell is the dual of the regions: a node where three regions meet (a fine
triangle with three labels, placed where the metric distances balance), a beam along each
border between two nodes, boundary nodes where a border meets the surface boundary, the
surface's corners kept as nodes, boundary cells closed along the boundary.
Why this route and not the deform-then-uniform-CVT one: docs/decisions.md.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from .errors import InputError, MeshError
from .field import GuidingField
from .mesh import PolyMesh, TriMesh, best_fit_plane, boundary_loops

__all__ = ["RemeshSettings", "RemeshResult", "remesh", "polymesh_quality", "surface_corners"]

Progress = Callable[[str, "float | None"], None]

#: Fine vertices per cell the refinement aims at.
VERTICES_PER_CELL = 45
#: Largest refined mesh (vertices) the remesher builds.
MAX_FINE_VERTICES = 400_000
#: Boundary turning angle above which a surface vertex is a corner kept as a node, degrees.
CORNER_ANGLE_DEG = 30.0
#: Beams shorter than this fraction of the local cell size are collapsed.
SHORT_BEAM_FRACTION = 0.02


@dataclass(frozen=True, kw_only=True)
class RemeshSettings:
    """Size target: exactly one of n_cells, mean_beam_length (m) or total_length (m, L_tot,
    met within 1 %); lloyd_iterations; seed of the random initial sampling."""

    n_cells: int | None = None
    mean_beam_length: float | None = None
    total_length: float | None = None
    lloyd_iterations: int = 80
    seed: int = 0

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


@dataclass(frozen=True, kw_only=True)
class RemeshResult:
    """The grid-shell and its quality figures (JSON-ready)."""

    polymesh: PolyMesh
    quality: dict


# ----------------------------------------------------------------------------- refinement

def _edges_of(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique sorted edges (e,2) and, per face corner j, the id of edge (j, j+1) (m,3)."""
    directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    key = np.sort(directed, axis=1)
    edges, inverse = np.unique(key, axis=0, return_inverse=True)
    return edges, inverse.reshape(len(faces), 3)


def _subdivide(vertices: np.ndarray, faces: np.ndarray, metric: np.ndarray):
    """One 1-to-4 midpoint subdivision; metric tensors averaged at the new vertices."""
    edges, face_edges = _edges_of(faces)
    n = len(vertices)
    mid = n + face_edges
    new_vertices = np.vstack([vertices, 0.5 * (vertices[edges[:, 0]] + vertices[edges[:, 1]])])
    new_metric = np.concatenate([metric, 0.5 * (metric[edges[:, 0]] + metric[edges[:, 1]])])
    a, b, c = faces[:, 0], faces[:, 1], faces[:, 2]
    ab, bc, ca = mid[:, 0], mid[:, 1], mid[:, 2]
    new_faces = np.concatenate([np.stack([a, ab, ca], 1), np.stack([ab, b, bc], 1), np.stack([ca, bc, c], 1),
                                np.stack([ab, bc, ca], 1)])
    return new_vertices, new_faces, new_metric


def surface_corners(mesh: TriMesh, angle_deg: float = CORNER_ANGLE_DEG) -> np.ndarray:
    """Vertex ids of boundary vertices where the boundary turns by more than ``angle_deg``."""
    corners = []
    for loop in mesh.boundary_loops:
        p = mesh.vertices[loop]
        incoming = p - np.roll(p, 1, axis=0)
        outgoing = np.roll(p, -1, axis=0) - p
        cosine = np.einsum("ij,ij->i", incoming, outgoing) / np.maximum(
            np.linalg.norm(incoming, axis=1) * np.linalg.norm(outgoing, axis=1), 1e-300)
        corners.extend(loop[cosine < np.cos(np.radians(angle_deg))].tolist())
    return np.array(sorted(corners), dtype=np.int64)


def _vertex_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    area = 0.5 * np.linalg.norm(np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                                         vertices[faces[:, 2]] - vertices[faces[:, 0]]), axis=1)
    out = np.zeros(len(vertices))
    for k in range(3):
        np.add.at(out, faces[:, k], area / 3.0)
    return out


@dataclass
class _Fine:
    vertices: np.ndarray
    faces: np.ndarray
    metric: np.ndarray
    edges: np.ndarray
    face_edges: np.ndarray
    graph: sp.csr_matrix
    edge_lengths: np.ndarray
    density: np.ndarray
    areas: np.ndarray
    loops: list
    corners: np.ndarray
    normals: np.ndarray
    tree: cKDTree


def _refine(mesh: TriMesh, field: GuidingField, n_cells: int) -> _Fine:
    vertices, faces = mesh.vertices, mesh.faces
    metric = field.metric()
    while len(vertices) < VERTICES_PER_CELL * n_cells and 4 * len(vertices) <= MAX_FINE_VERTICES:
        vertices, faces, metric = _subdivide(vertices, faces, metric)
    edges, face_edges = _edges_of(faces)
    d = vertices[edges[:, 1]] - vertices[edges[:, 0]]
    m = 0.5 * (metric[edges[:, 0]] + metric[edges[:, 1]])
    lengths = np.sqrt(np.maximum(np.einsum("ei,eij,ej->e", d, m, d), 1e-300))
    n = len(vertices)
    graph = sp.csr_matrix((np.r_[lengths, lengths], (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]])),
                          shape=(n, n))
    fine = TriMesh(vertices=vertices, faces=faces)
    # Riemannian area element sqrt(det M) on the tangent plane = 1 / h^2
    trace = np.einsum("nii->n", metric)
    second = 0.5 * (trace**2 - np.einsum("nij,nji->n", metric, metric))
    density = np.sqrt(np.maximum(second, 1e-300))
    return _Fine(vertices=vertices, faces=faces, metric=metric, edges=edges, face_edges=face_edges, graph=graph,
                 edge_lengths=lengths, density=density, areas=_vertex_areas(vertices, faces),
                 loops=boundary_loops(faces), corners=surface_corners(mesh), normals=fine.vertex_normals,
                 tree=cKDTree(vertices))


# ----------------------------------------------------------------------------- CVT

#: Over-relaxation of the Lloyd steps.
LLOYD_RELAXATION = 1.7
#: Centroid density rho = h^-power (see _lloyd_step).
CENTROID_DENSITY_POWER = 3.0
#: Seeds examined per vertex (Euclidean nearest first), enough for aspects up to about 5.
CANDIDATE_SEEDS = 16


_UPPER = (np.array([0, 1, 2, 0, 0, 1]), np.array([0, 1, 2, 1, 2, 2]))
_TWICE = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])


def _quadratic(d: np.ndarray, components: np.ndarray) -> np.ndarray:
    """d^T M d from the six upper components of symmetric M (broadcast over leading axes)."""
    products = np.stack([d[..., 0] ** 2, d[..., 1] ** 2, d[..., 2] ** 2, d[..., 0] * d[..., 1],
                         d[..., 0] * d[..., 2], d[..., 1] * d[..., 2]], axis=-1)
    return np.einsum("...c,...c->...", products, components * _TWICE)


def _metric_distance2(points: np.ndarray, point_metric: np.ndarray, seeds: np.ndarray,
                      seed_metric: np.ndarray) -> np.ndarray:
    """Squared metric distances of points (p,3) to seeds (p,k,3) under the mean of both metrics."""
    d = points[:, None, :] - seeds
    point_components = point_metric[:, _UPPER[0], _UPPER[1]]
    seed_components = seed_metric[..., _UPPER[0], _UPPER[1]]
    return 0.5 * (_quadratic(d, point_components[:, None, :]) + _quadratic(d, seed_components))


def _regions(fine: _Fine, seeds: np.ndarray, seed_metric: np.ndarray,
             connected: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Label (n,) of the metric-nearest seed of every fine vertex, each region made connected
    (skipped during Lloyd iterations, where stray vertices hardly move a centroid)."""
    k = min(CANDIDATE_SEEDS, len(seeds))
    _, candidates = cKDTree(seeds).query(fine.vertices, k=k)
    candidates = candidates.reshape(len(fine.vertices), k)
    labels = np.empty(len(candidates), dtype=np.int64)
    nearest = np.empty(len(candidates))
    chunk = 32768
    for start in range(0, len(candidates), chunk):
        part = slice(start, start + chunk)
        distance2 = _metric_distance2(fine.vertices[part], fine.metric[part], seeds[candidates[part]],
                                      seed_metric[candidates[part]])
        best = np.argmin(distance2, axis=1)
        rows = np.arange(len(best))
        labels[part] = candidates[part][rows, best]
        nearest[part] = distance2[rows, best]
    if connected:
        labels = _connected_regions(fine, labels)
    return labels, np.sqrt(nearest)


def _connected_regions(fine: _Fine, labels: np.ndarray) -> np.ndarray:
    """Give stray pieces of a region (not connected to its largest piece) to a neighbouring region."""
    from scipy.sparse.csgraph import connected_components

    E = fine.edges
    for _ in range(5):
        same = labels[E[:, 0]] == labels[E[:, 1]]
        n = len(labels)
        graph = sp.csr_matrix((np.ones(same.sum()), (E[same, 0], E[same, 1])), shape=(n, n))
        _, component = connected_components(graph, directed=False)
        size = np.bincount(component)
        # the main piece of each label: its largest component
        order = np.lexsort((-size[component], labels))
        first = np.ones(n, dtype=bool)
        first[1:] = labels[order[1:]] != labels[order[:-1]]
        main = np.zeros(size.shape, dtype=bool)
        main[component[order[first]]] = True
        stray = ~main[component]
        if not stray.any():
            break
        # stray vertices take the label of a neighbour in a main piece
        a, b = E[:, 0], E[:, 1]
        fix = stray[a] & ~stray[b]
        labels = labels.copy()
        labels[a[fix]] = labels[b[fix]]
        fix = stray[b] & ~stray[a]
        labels[b[fix]] = labels[a[fix]]
    return labels


def _lloyd_step(fine: _Fine, labels: np.ndarray, n_seeds: int, seeds: np.ndarray | None = None,
                relaxation: float = 1.0) -> np.ndarray:
    """Each region's centroid, weighted by rho = h^-CENTROID_DENSITY_POWER, projected onto the surface.

    Regions are assigned by metric distance, which already grades them; a Euclidean CVT with
    density rho grades cells as rho^(-1/4) (Gersho). With both, the power 3 makes the achieved
    size follow h (log-log slope near 1, measured in tests/test_voronoi.py): the metric's own
    area element (power 2) gives a slope of about 0.5 and power 4 about 1.35."""
    from .proximity import closest_points

    weight = fine.areas * fine.density ** (CENTROID_DENSITY_POWER / 2)
    total = np.bincount(labels, weights=weight, minlength=n_seeds)
    centroid = np.stack([np.bincount(labels, weights=weight * fine.vertices[:, k], minlength=n_seeds)
                         for k in range(3)], axis=1) / np.maximum(total, 1e-300)[:, None]
    if seeds is not None and relaxation != 1.0:
        centroid = seeds + relaxation * (centroid - seeds)
    return closest_points(fine.vertices, fine.faces, centroid, k=8)[0]


def _seed_metric(fine: _Fine, seeds: np.ndarray) -> np.ndarray:
    _, nearest = fine.tree.query(seeds)
    return fine.metric[nearest]


def _initial_seeds(fine: _Fine, n_cells: int, rng: np.random.Generator) -> np.ndarray:
    """A hexagonal lattice over the surface's best-fit plane (Lloyd then starts near a honeycomb
    and keeps few defects), thinned or topped up at random to exactly ``n_cells``; random
    sampling by the field's density where the surface is not a height field over that plane."""
    weight = fine.areas * fine.density
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
        return fine.vertices[rng.choice(len(fine.vertices), size=n_cells, replace=False, p=probability)]
    plan_area = 0.5 * np.abs(signed).sum()
    tree = cKDTree(plan)
    offset = rng.uniform(0, 1, 2)

    def lattice(spacing: float) -> np.ndarray:
        lo, hi = plan.min(axis=0) - spacing, plan.max(axis=0) + spacing
        rows = np.arange(lo[1] + offset[1] * spacing, hi[1], spacing * np.sqrt(3) / 2)
        points = []
        for j, y in enumerate(rows):
            xs = np.arange(lo[0] + (offset[0] + 0.5 * (j % 2)) * spacing, hi[0], spacing)
            points.append(np.c_[xs, np.full_like(xs, y)])
        grid = np.concatenate(points)
        distance, nearest = tree.query(grid)
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
        extra = rng.choice(rest, size=n_cells - len(chosen), replace=False, p=probability[rest] / probability[rest].sum())
        chosen = np.concatenate([chosen, extra])
    return fine.vertices[chosen]


# ----------------------------------------------------------------------------- extraction

def _extract(fine: _Fine, labels: np.ndarray, seeds: np.ndarray, seed_metric: np.ndarray):
    """Polygon mesh from the region labels: (nodes, cell loops, boundary mask, corner mask, cell labels)."""
    E, F, FE = fine.edges, fine.faces, fine.face_edges
    la, lb = labels[E[:, 0]], labels[E[:, 1]]
    mixed = la != lb
    counts = np.bincount(FE.ravel(), minlength=len(E))
    on_boundary = counts == 1
    # point on each mixed edge where the metric distances to the two seeds balance (linear in between)
    t = np.zeros(len(E))
    ids = np.flatnonzero(mixed)
    ends = [E[ids, 0], E[ids, 1]]
    gap = []
    for end in ends:
        pair = np.stack([la[ids], lb[ids]], axis=1)
        d2 = _metric_distance2(fine.vertices[end], fine.metric[end], seeds[pair], seed_metric[pair])
        gap.append(np.sqrt(d2[:, 0]) - np.sqrt(d2[:, 1]))
    denominator = gap[0] - gap[1]
    t[ids] = np.clip(np.where(np.abs(denominator) > 1e-300, gap[0] / np.where(denominator == 0, 1, denominator), 0.5),
                     0.0, 1.0)
    edge_points = fine.vertices[E[:, 0]] + t[:, None] * (fine.vertices[E[:, 1]] - fine.vertices[E[:, 0]])
    face_labels = labels[F]
    three = (face_labels[:, 0] != face_labels[:, 1]) & (face_labels[:, 1] != face_labels[:, 2]) \
        & (face_labels[:, 0] != face_labels[:, 2])
    # graph over points: edge points are ids 0..len(E)-1, face points len(E)+face
    neighbours: dict[int, list[int]] = defaultdict(list)
    n_edges = len(E)
    for k in np.flatnonzero(three):
        for j in range(3):
            e = int(FE[k, j])
            neighbours[n_edges + int(k)].append(e)
            neighbours[e].append(n_edges + int(k))
    two = ~three & (mixed[FE].sum(axis=1) == 2)
    for k in np.flatnonzero(two):
        e1, e2 = [int(e) for e in FE[k][mixed[FE[k]]]]
        neighbours[e1].append(e2)
        neighbours[e2].append(e1)
    face_points = {n_edges + int(k): edge_points[FE[k]].mean(axis=0) for k in np.flatnonzero(three)}

    def position(point: int) -> np.ndarray:
        return face_points[point] if point >= n_edges else edge_points[point]

    node_of: dict[tuple, int] = {}
    positions: list[np.ndarray] = []
    boundary_flags: list[bool] = []
    corner_flags: list[bool] = []

    def node(key: tuple, where: np.ndarray, boundary: bool, corner: bool = False) -> int:
        if key not in node_of:
            node_of[key] = len(positions)
            positions.append(where)
            boundary_flags.append(boundary)
            corner_flags.append(corner)
        return node_of[key]

    for point in face_points:
        node(("p", point), face_points[point], False)
    for e in np.flatnonzero(mixed & on_boundary):
        node(("p", int(e)), edge_points[e], True)
    # chains between nodes: each separates two regions
    cell_edges: dict[int, list[tuple[int, int]]] = defaultdict(list)
    seen: set[tuple[int, int]] = set()
    for key, start in list(node_of.items()):
        first_point = key[1]
        for step in neighbours[first_point]:
            previous, current = first_point, step
            while ("p", current) not in node_of:
                options = [q for q in neighbours[current] if q != previous]
                if not options:
                    break
                previous, current = current, options[0]
            if ("p", current) not in node_of:
                continue
            end = node_of[("p", current)]
            marker = (min(first_point, step), max(first_point, step))
            edge_id = step if step < n_edges else first_point
            pair = (int(la[edge_id]), int(lb[edge_id]))
            closing = (min(current, previous), max(current, previous))
            if marker in seen or closing in seen:
                continue
            seen.add(marker)
            seen.add(closing)
            if end == start:
                continue
            for region in pair:
                cell_edges[region].append((start, end))
    # boundary beams, through the surface corners
    corner_set = set(fine.corners.tolist())
    for loop in fine.loops:
        sequence: list[tuple[int, int]] = []  # (node, label of the boundary part after it)
        for i, v in enumerate(loop):
            w = loop[(i + 1) % len(loop)]
            if int(v) in corner_set:
                sequence.append((node(("c", int(v)), fine.vertices[v], True, True), int(labels[v])))
            if labels[v] != labels[w]:
                e = _edge_id(E, int(v), int(w))
                sequence.append((node_of[("p", e)], int(labels[w])))
        if len(sequence) < 2:
            raise MeshError("a boundary loop of the surface lies inside a single cell",
                            hint="ask for more cells (or a smaller mean beam length) so that cells resolve "
                                 "every hole and boundary of the surface")
        for i, (a, region) in enumerate(sequence):
            b = sequence[(i + 1) % len(sequence)][0]
            if a != b:
                cell_edges[region].append((a, b))
    nodes = np.array(positions)
    loops, cell_labels = [], []
    for region, edges in cell_edges.items():
        loop = _cycle(edges)
        if loop is None or len(loop) < 3:
            continue
        loops.append(np.array(loop, dtype=np.int64))
        cell_labels.append(region)
    return nodes, loops, np.array(boundary_flags), np.array(corner_flags), np.array(cell_labels)


def _edge_id(edges: np.ndarray, a: int, b: int) -> int:
    key = (min(a, b), max(a, b))
    lo = np.searchsorted(edges[:, 0], key[0], side="left")
    hi = np.searchsorted(edges[:, 0], key[0], side="right")
    return int(lo + np.searchsorted(edges[lo:hi, 1], key[1]))


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


def _orient(nodes: np.ndarray, loops: list[np.ndarray], fine: _Fine, labels_of_cells: np.ndarray,
            seeds: np.ndarray) -> list[np.ndarray]:
    out = []
    for loop, region in zip(loops, labels_of_cells):
        p = nodes[loop]
        vector_area = 0.5 * np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0)
        normal = fine.normals[fine.tree.query(seeds[region])[1]]
        out.append(loop if vector_area @ normal >= 0 else loop[::-1])
    return out


def _collapse_short_beams(nodes: np.ndarray, loops: list[np.ndarray], boundary: np.ndarray, corners: np.ndarray,
                          local_size: np.ndarray) -> tuple[np.ndarray, list[np.ndarray], np.ndarray, np.ndarray]:
    """Merge the ends of beams shorter than SHORT_BEAM_FRACTION of the local size."""
    parent = np.arange(len(nodes))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    edges = {(min(a, b), max(a, b)) for loop in loops for a, b in zip(loop, np.roll(loop, -1))}
    for a, b in sorted(edges, key=lambda e: np.linalg.norm(nodes[e[0]] - nodes[e[1]])):
        ra, rb = find(a), find(b)
        if ra == rb:
            continue
        limit = SHORT_BEAM_FRACTION * min(local_size[a], local_size[b])
        if np.linalg.norm(nodes[ra] - nodes[rb]) >= limit:
            continue
        if corners[ra] and corners[rb]:
            continue
        keep, drop = (ra, rb) if (corners[ra] or (boundary[ra] and not corners[rb])) else (rb, ra)
        if boundary[drop] and not boundary[keep]:
            keep, drop = drop, keep
        parent[drop] = keep
    roots = np.array([find(i) for i in range(len(nodes))])
    new_loops = []
    for loop in loops:
        mapped = roots[loop]
        keep = np.r_[mapped[1:] != mapped[:-1], mapped[0] != mapped[-1]]
        mapped = mapped[keep] if keep.any() else mapped[:1]
        if len(mapped) >= 3 and len(set(mapped.tolist())) == len(mapped):
            new_loops.append(mapped)
    used = np.unique(np.concatenate(new_loops))
    index = np.full(len(nodes), -1)
    index[used] = np.arange(len(used))
    return nodes[used], [index[loop] for loop in new_loops], boundary[used], corners[used]


# ----------------------------------------------------------------------------- driver

def _tessellate(mesh: TriMesh, field: GuidingField, n_cells: int, settings: RemeshSettings,
                support_vertices: np.ndarray | None, say) -> PolyMesh:
    say("refining the surface", 0.0)
    fine = _refine(mesh, field, n_cells)
    rng = np.random.default_rng(settings.seed)
    seeds = _initial_seeds(fine, n_cells, rng)
    typical = np.sqrt(fine.areas.sum() / n_cells)
    for iteration in range(settings.lloyd_iterations):
        labels, _ = _regions(fine, seeds, _seed_metric(fine, seeds), connected=False)
        # over-relaxed Lloyd: converges several times faster; plain steps at the end settle it
        relaxation = LLOYD_RELAXATION if iteration < 0.8 * settings.lloyd_iterations else 1.0
        new_seeds = _lloyd_step(fine, labels, len(seeds), seeds, relaxation)
        say(f"Lloyd iteration {iteration + 1}/{settings.lloyd_iterations}", (iteration + 1) / max(settings.lloyd_iterations, 1))
        moved = np.linalg.norm(new_seeds - seeds, axis=1).max()
        seeds = new_seeds
        if moved < 1e-4 * typical:
            break
    seed_metric = _seed_metric(fine, seeds)
    labels, distance = _regions(fine, seeds, seed_metric)
    say("extracting the polygon mesh", None)
    nodes, loops, boundary, corners, cell_labels = _extract(fine, labels, seeds, seed_metric)
    loops = _orient(nodes, loops, fine, cell_labels, seeds)
    region_area = np.bincount(labels, weights=fine.areas, minlength=len(seeds))
    size_at = np.sqrt(region_area)
    local_size = np.full(len(nodes), np.inf)
    for loop, region in zip(loops, cell_labels):
        local_size[loop] = np.minimum(local_size[loop], size_at[region])
    nodes, loops, boundary, corners = _collapse_short_beams(nodes, loops, boundary, corners, local_size)
    supports = _support_nodes(mesh, nodes, boundary, support_vertices)
    return PolyMesh(nodes=nodes, faces=tuple(loops), boundary=boundary, supports=supports, corners=corners)


def _support_nodes(mesh: TriMesh, nodes: np.ndarray, boundary: np.ndarray, support_vertices: np.ndarray | None) -> np.ndarray:
    """Boundary nodes whose nearest boundary vertex of the surface is supported, and the node
    nearest to each supported vertex."""
    supports = np.zeros(len(nodes), dtype=bool)
    if support_vertices is None or not np.any(support_vertices):
        return supports
    support_vertices = np.asarray(support_vertices, dtype=bool)
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
    """The statics-aware Voronoi grid-shell of ``mesh`` under ``field`` (see the module docstring)."""
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
            guess = _cells_for_length(mesh, field, np.sqrt(mesh.area) / 10.0)
            length = np.sqrt(mesh.area) / 10.0
            n_cells = guess
        else:
            n_cells = _cells_for_length(mesh, field, length)
    max_cells = MAX_FINE_VERTICES // 12
    if n_cells > max_cells:
        raise InputError(f"remesh: {n_cells} cells is more than this remesher handles ({max_cells})",
                         hint="ask for fewer cells or a longer mean beam length")
    polymesh = _tessellate(mesh, field, n_cells, settings, support_vertices, say)
    if settings.mean_beam_length is not None:
        for _ in range(3):
            achieved = float(polymesh.beam_lengths.mean())
            if abs(achieved / settings.mean_beam_length - 1) < 0.02:
                break
            n_cells = max(4, int(round(n_cells * (achieved / settings.mean_beam_length) ** 2)))
            polymesh = _tessellate(mesh, field, n_cells, settings, support_vertices, say)
    if settings.total_length is not None:
        polymesh, n_cells = _match_total_length(mesh, field, settings, support_vertices, say, polymesh, n_cells)
    quality = polymesh_quality(polymesh, mesh=mesh, field=field)
    quality.update({"n_cells_requested": int(n_cells), "field_size_ratio": ratio, "field_max_aspect": aspect})
    if settings.total_length is not None:
        quality["total_length_target_m"] = settings.total_length
        quality["total_length_error"] = polymesh.total_length / settings.total_length - 1.0
    interior_faces = ~polymesh.face_boundary
    if quality["n_faces"] < 3 or not np.any(interior_faces) and quality["n_faces"] > 12:
        raise InputError("remesh: the tessellation degenerated", hint="lower D or A, or ask for more cells")
    return RemeshResult(polymesh=polymesh, quality=quality)


def _match_total_length(mesh, field, settings, support_vertices, say, polymesh, n_cells):
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
        polymesh = _tessellate(mesh, field, n_cells, settings, support_vertices, say)
        error = abs(polymesh.total_length / target - 1)
        if error < best[0]:
            best = (error, polymesh, n_cells)
    if best[0] >= 0.01:
        # fine adjustment: other random starts at the best cell count
        error, polymesh, n_cells = best
        for seed in range(1, 12):
            from dataclasses import replace

            candidate = _tessellate(mesh, field, n_cells, replace(settings, seed=settings.seed + seed),
                                    support_vertices, say)
            candidate_error = abs(candidate.total_length / target - 1)
            if candidate_error < best[0]:
                best = (candidate_error, candidate, n_cells)
            if best[0] < 0.01:
                break
    return best[1], best[2]


# ----------------------------------------------------------------------------- quality

def _cell_pca(points: np.ndarray) -> tuple[float, float, np.ndarray]:
    """(size = sqrt(area of the PCA ellipse-equivalent), aspect, in-plane axes (2,3))."""
    centred = points - points.mean(axis=0)
    _, s, vt = np.linalg.svd(centred, full_matrices=False)
    s = np.maximum(s[:2], 1e-300)
    return float(s[0] * s[1]), float(s[0] / s[1]), vt[:2]


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
    sizes, aspects, regularity = [], [], []
    for face in polymesh.faces:
        p = polymesh.nodes[face]
        area = 0.5 * np.linalg.norm(np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0))
        sizes.append(np.sqrt(area))
        _, aspect, axes = _cell_pca(p)
        aspects.append(aspect)
        # regularity: edge-length spread after un-stretching the cell's own anisotropy
        local = (p - p.mean(axis=0)) @ axes.T
        spread = np.sqrt(np.maximum(np.linalg.svd(local, compute_uv=False), 1e-300))
        unstretched = local / spread * spread.mean()
        edges = np.linalg.norm(unstretched - np.roll(unstretched, -1, axis=0), axis=1)
        regularity.append(float(edges.std() / max(edges.mean(), 1e-300)))
    sizes, aspects = np.array(sizes), np.array(aspects)
    pick = interior if interior.sum() >= 4 else np.ones(len(sizes), dtype=bool)
    lo, hi = np.percentile(sizes[pick], [5, 95])
    planarity = polymesh.face_planarity()
    angles = _smallest_angles(polymesh)
    quality = {
        "n_nodes": int(polymesh.n_nodes), "n_beams": int(len(polymesh.edges)), "n_faces": int(polymesh.n_faces),
        "hexagon_share_interior": float(np.mean(degrees[interior] == 6)) if interior.any() else 0.0,
        "face_degree_histogram": histogram,
        "valence3_share_interior": float(np.mean(polymesh.valence[interior_nodes] == 3)) if interior_nodes.any() else 0.0,
        "achieved_size_ratio": float(hi / max(lo, 1e-300)),
        "achieved_max_aspect": float(np.percentile(aspects[pick], 95)),
        "regularity": float(np.mean(regularity)),
        "planarity_max_m": float(planarity.max()) if len(planarity) else 0.0,
        "planarity_p95_m": float(np.percentile(planarity, 95)) if len(planarity) else 0.0,
        "planarity_max_mm": float(1000 * planarity.max()) if len(planarity) else 0.0,
        "planarity_max_rel": float(planarity.max() / max(mean_length, 1e-300)) if len(planarity) else 0.0,
        "planarity_p95_rel": float(np.percentile(planarity, 95) / max(mean_length, 1e-300)) if len(planarity) else 0.0,
        "shortest_beam_m": float(lengths.min()) if len(lengths) else 0.0,
        "mean_beam_length_m": mean_length, "total_length_m": float(lengths.sum()),
        "smallest_angle_deg": float(angles),
    }
    if mesh is not None:
        distance = _distance_to_surface(mesh, polymesh.nodes)
        quality["closeness_max_rel"] = float(distance.max() / mesh.diagonal)
        quality["closeness_mean_rel"] = float(distance.mean() / mesh.diagonal)
    if mesh is not None and field is not None:
        centroids = np.array([polymesh.nodes[f].mean(axis=0) for f in polymesh.faces])
        _, nearest = cKDTree(mesh.vertices).query(centroids)
        prescribed = field.size[nearest]
        quality["size_ratio_p5_p95"] = quality["achieved_size_ratio"]
        if np.std(prescribed[pick]) > 1e-9 * prescribed.mean() and np.std(sizes[pick]) > 0:
            quality["size_correlation"] = float(np.corrcoef(prescribed[pick], sizes[pick])[0, 1])
            # grading actually achieved: the field's ratio to the power of the log-log slope
            slope = np.polyfit(np.log(prescribed[pick]), np.log(sizes[pick]), 1)[0]
            quality["size_grading_slope"] = float(slope)
            quality["achieved_size_ratio"] = float((field.size.max() / field.size.min()) ** slope)
        else:
            quality["size_correlation"] = None
    return quality


def _smallest_angles(polymesh: PolyMesh) -> float:
    smallest = 180.0
    for face in polymesh.faces:
        p = polymesh.nodes[face]
        a = np.roll(p, 1, axis=0) - p
        b = np.roll(p, -1, axis=0) - p
        cosine = np.einsum("ij,ij->i", a, b) / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300)
        smallest = min(smallest, float(np.degrees(np.arccos(np.clip(cosine, -1, 1))).min()))
    return smallest


def _distance_to_surface(mesh: TriMesh, points: np.ndarray) -> np.ndarray:
    from .proximity import closest_points

    return closest_points(mesh.vertices, mesh.faces, points)[1]
