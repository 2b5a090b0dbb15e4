"""The polygon grid-shell of a clustering of the Voronoi remesher (engine/remeshing/voronoi.py): the dual of
the clusters of the fine mesh (engine/geometry/fine_mesh.py). A node where three clusters meet (a triangle
with three labels; at the anisotropic Voronoi vertex of the three centroids where that stays near
the triangle and turns no beam round, else where the metric distances to the centroids balance
along its edges), a beam along each border between two nodes, boundary nodes where a border meets
the surface boundary, the surface's corners kept as nodes, boundary cells closed along the
boundary. Cells that wrap a boundary loop are cut first; the cells are then oriented, short beams
collapsed and the supported nodes marked (support_nodes, which the lattices of engine/remeshing/grids.py use
too).
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..errors import MeshError
from ..geometry.fine_mesh import _edge_ids, _Fine
from ..mesh import PolyMesh, TriMesh

__all__ = ["SHORT_BEAM_FRACTION", "JUNCTION_REACH", "RING_SPLIT", "support_nodes"]

#: Beams shorter than this fraction of the local cell size are collapsed.
SHORT_BEAM_FRACTION = 0.02


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


def _polygons(mesh: TriMesh, fine: _Fine, labels: np.ndarray, centroids: np.ndarray,
              support_vertices: np.ndarray | None) -> PolyMesh:
    """The polygon grid-shell of a clustering (its labels and centroids): extraction, orientation, short
    beams collapsed, supports."""
    labels, centroids = _split_ring_cells(fine, labels, centroids)
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
    loops = tuple(np.split(flat, offsets[1:-1]))
    if support_vertices is None or not np.any(support_vertices):
        supports = np.zeros(len(nodes), dtype=bool)
    else:
        inside = inside_supports(mesh, np.asarray(support_vertices, dtype=bool), boundary_ids)
        supports = support_nodes(mesh, nodes, boundary, support_vertices, boundary_ids=boundary_ids, inside=inside)
        nodes = onto_columns(nodes, loops, supports & ~boundary, column_points(mesh, inside))
    return PolyMesh(nodes=nodes, faces=loops, boundary=boundary, supports=supports, corners=corners)


def inside_supports(mesh: TriMesh, support_vertices: np.ndarray, boundary_ids: np.ndarray) -> np.ndarray:
    """(n,) bool: the supported vertices inside the surface (columns under the roof), more than
    half a median edge from its boundary (``boundary_ids``): a flag one vertex in from the edge is on
    it (hyperbol2 has six, 1-2 mm in)."""
    on_edge = np.zeros(len(support_vertices), dtype=bool)
    on_edge[boundary_ids] = True
    if len(boundary_ids):
        half_edge = 0.5 * float(np.median(mesh.edge_lengths))
        flagged = np.flatnonzero(support_vertices & ~on_edge)
        distance, _ = cKDTree(mesh.vertices[boundary_ids]).query(mesh.vertices[flagged])
        on_edge[flagged[distance <= half_edge]] = True
    return support_vertices & ~on_edge


def column_points(mesh: TriMesh, inside: np.ndarray) -> np.ndarray:
    """(k, 3) the columns among the supported vertices inside the surface (``inside``, n bool): each
    group of them joined by edges that lies within two median edges of its centre, at its vertex
    nearest that centre. A larger group is a supported region (a box of the surface), not a column."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    ids = np.flatnonzero(inside)
    if not len(ids):
        return np.zeros((0, 3))
    edges = mesh.edges
    both = inside[edges[:, 0]] & inside[edges[:, 1]]
    local = np.full(len(inside), -1)
    local[ids] = np.arange(len(ids))
    a, b = local[edges[both, 0]], local[edges[both, 1]]
    count, label = connected_components(coo_matrix((np.ones(len(a)), (a, b)), shape=(len(ids), len(ids))),
                                        directed=False)
    reach = 2.0 * float(np.median(mesh.edge_lengths))
    points = []
    for group in range(count):
        members = mesh.vertices[ids[label == group]]
        centre = members.mean(axis=0)
        distance = np.linalg.norm(members - centre, axis=1)
        if distance.max() <= reach:
            points.append(members[distance.argmin()])
    return np.array(points).reshape(-1, 3)


#: A node is moved onto the column nearest it while the move is under this share of its shortest
#: beam and leaves every corner of its cells turning as before (_keeps_corners).
COLUMN_SNAP = 1.0


def _corner_turns(points: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(k,) the sign of each corner's turn of the polygon ``points`` (k, 3) about ``normal``."""
    before, after = points - np.roll(points, 1, axis=0), np.roll(points, -1, axis=0) - points
    return np.sign(np.cross(before, after) @ normal)


def _keeps_corners(nodes: np.ndarray, loops: tuple, node: int, target: np.ndarray) -> bool:
    """Whether moving ``node`` to ``target`` leaves every corner of its cells turning the way it did
    (about each cell's normal before the move): no cell folds or turns over."""
    for loop in loops:
        if node not in loop:
            continue
        points = nodes[loop]
        normal = np.cross(points - points.mean(axis=0), np.roll(points, -1, axis=0) - points.mean(axis=0)).sum(axis=0)
        moved = points.copy()
        moved[np.flatnonzero(loop == node)] = target
        if not np.array_equal(_corner_turns(points, normal), _corner_turns(moved, normal)):
            return False
    return True


def onto_columns(nodes: np.ndarray, loops: tuple, supports: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """``nodes`` with the supported node nearest each of the ``columns`` (k, 3) moved onto it, where
    that move is under COLUMN_SNAP of the node's shortest beam and no cell round it folds (a column
    stands where it was modelled, not half a cell off)."""
    nodes = np.array(nodes, dtype=float)
    held = np.flatnonzero(supports)
    if not len(columns) or not len(held):
        return nodes
    shortest = np.full(len(nodes), np.inf)
    for loop in loops:
        lengths = np.linalg.norm(nodes[np.roll(loop, -1)] - nodes[loop], axis=1)
        np.minimum.at(shortest, loop, lengths)
        np.minimum.at(shortest, np.roll(loop, -1), lengths)
    distance, nearest = cKDTree(nodes[held]).query(columns)
    for column, node, move in zip(columns, held[nearest], distance):
        if move < COLUMN_SNAP * shortest[node] and _keeps_corners(nodes, loops, node, column):
            nodes[node] = column
    return nodes


def support_nodes(mesh: TriMesh, nodes: np.ndarray, boundary: np.ndarray, support_vertices: np.ndarray | None,
                  *, boundary_ids: np.ndarray | None = None, inside: np.ndarray | None = None) -> np.ndarray:
    """Boundary nodes whose nearest boundary vertex of the surface is supported, the boundary node
    nearest to each supported boundary vertex, and the node nearest to each supported vertex inside
    the surface (a column under the roof: held at its nearest node, not moved to the edge;
    inside_supports) (``boundary_ids``: the surface's boundary vertices, and ``inside``: inside_supports,
    when known)."""
    supports = np.zeros(len(nodes), dtype=bool)
    if support_vertices is None or not np.any(support_vertices):
        return supports
    support_vertices = np.asarray(support_vertices, dtype=bool)
    if boundary_ids is None:
        boundary_ids = np.flatnonzero(mesh.boundary_vertices)
    if len(boundary_ids) and np.any(boundary):
        _, nearest = cKDTree(mesh.vertices[boundary_ids]).query(nodes[boundary])
        supports[np.flatnonzero(boundary)[support_vertices[boundary_ids[nearest]]]] = True
    if inside is None:
        inside = inside_supports(mesh, support_vertices, boundary_ids)
    on_edge = support_vertices & ~inside
    candidates = np.flatnonzero(boundary) if np.any(boundary) else np.arange(len(nodes))
    _, nearest_node = cKDTree(nodes[candidates]).query(mesh.vertices[on_edge])
    supports[candidates[nearest_node]] = True
    if inside.any():
        _, nearest_node = cKDTree(nodes).query(mesh.vertices[inside])
        supports[nearest_node] = True
    return supports
