"""Discrete anisotropic centroidal Voronoi clustering of a triangle mesh's vertices (compiled).

The approximated CVD of Valette and Chassery (ACVD), generalised to a metric: every vertex i has
a weight w_i and a metric M_i (3x3, symmetric positive definite); the energy of a cluster k,

    E_k = min over c of  sum_{i in k} w_i (x_i - c)^T M_i (x_i - c)  =  S3 - S2^T S1^-1 S2,

with the running moments S1 = sum w M (3x3), S2 = sum w M x (3), S3 = sum w x^T M x, is reached at
the centroid c_k = S1^-1 S2. Moving a vertex between two clusters changes four moment sums, so its
energy change is O(1). Sweeps over the mesh edges whose ends lie in different clusters move an end
to the other cluster whenever the total energy drops; a move is allowed only if the vertex's
neighbours in the cluster it leaves, and in the cluster it joins, each form one arc of its link
(so clusters stay connected and gain no holes) and the cluster it leaves keeps a vertex.

Moments are stored as 10 numbers per vertex or cluster: the six upper components of w M
(00, 11, 22, 01, 02, 12), the three of w M x and w x^T M x. Kernels are numba-compiled
(``cache=True``: the first call in a fresh checkout compiles them, later processes load them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

__all__ = ["MeshAdjacency", "ClusteringResult", "mesh_adjacency", "vertex_moments", "centred_moments",
           "cluster_vertices",
           "cluster_energy", "centroids_of", "simple_cycles"]

#: Relative energy drop below which a move is not made (round-off guard).
ENERGY_TOLERANCE = 1e-12


@dataclass(frozen=True)
class MeshAdjacency:
    """Vertex-vertex and vertex-face incidence of a triangle mesh as CSR arrays (int64)."""

    vertex_ptr: np.ndarray
    vertex_neighbours: np.ndarray
    face_ptr: np.ndarray
    vertex_faces: np.ndarray


@dataclass(frozen=True)
class ClusteringResult:
    """labels (n_vertices,) cluster of each vertex; centroids (k, 3); energy (k,) per cluster;
    sweeps made; moves (sweeps,) vertices moved in each sweep."""

    labels: np.ndarray
    centroids: np.ndarray
    energy: np.ndarray
    sweeps: int
    moves: np.ndarray


def mesh_adjacency(n_vertices: int, faces: np.ndarray, edges: np.ndarray) -> MeshAdjacency:
    """CSR neighbour lists from the unique edges (e, 2) and incident-face lists from faces (m, 3)."""
    both = np.concatenate([edges, edges[:, ::-1]])
    order = np.argsort(both[:, 0], kind="stable")
    vertex_ptr = np.zeros(n_vertices + 1, dtype=np.int64)
    vertex_ptr[1:] = np.cumsum(np.bincount(both[:, 0], minlength=n_vertices))
    flat = faces.ravel()
    face_order = np.argsort(flat, kind="stable")
    face_ptr = np.zeros(n_vertices + 1, dtype=np.int64)
    face_ptr[1:] = np.cumsum(np.bincount(flat, minlength=n_vertices))
    return MeshAdjacency(vertex_ptr=vertex_ptr, vertex_neighbours=np.ascontiguousarray(both[order, 1], dtype=np.int64),
                         face_ptr=face_ptr, vertex_faces=(face_order // 3).astype(np.int64))


def vertex_moments(vertices: np.ndarray, metric: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(n, 10) moments of single vertices: w M (6 upper components), w M x (3), w x^T M x."""
    wm = metric * weights[:, None, None]
    wmx = np.einsum("nij,nj->ni", wm, vertices)
    out = np.zeros((len(vertices), 10))
    out[:, 0], out[:, 1], out[:, 2] = wm[:, 0, 0], wm[:, 1, 1], wm[:, 2, 2]
    out[:, 3], out[:, 4], out[:, 5] = wm[:, 0, 1], wm[:, 0, 2], wm[:, 1, 2]
    out[:, 6:9] = wmx
    out[:, 9] = np.einsum("ni,ni->n", wmx, vertices)
    return out


@njit(cache=True, nogil=True)
def _energy(S, k, P, i, sign):
    """Energy of the moments S[k] + sign * P[i] (sign 0 for S[k] alone): S3 - S2^T S1^-1 S2."""
    m00 = S[k, 0] + sign * P[i, 0]
    m11 = S[k, 1] + sign * P[i, 1]
    m22 = S[k, 2] + sign * P[i, 2]
    m01 = S[k, 3] + sign * P[i, 3]
    m02 = S[k, 4] + sign * P[i, 4]
    m12 = S[k, 5] + sign * P[i, 5]
    b0 = S[k, 6] + sign * P[i, 6]
    b1 = S[k, 7] + sign * P[i, 7]
    b2 = S[k, 8] + sign * P[i, 8]
    c = S[k, 9] + sign * P[i, 9]
    c00 = m11 * m22 - m12 * m12
    c01 = m02 * m12 - m01 * m22
    c02 = m01 * m12 - m02 * m11
    c11 = m00 * m22 - m02 * m02
    c12 = m01 * m02 - m00 * m12
    c22 = m00 * m11 - m01 * m01
    det = m00 * c00 + m01 * c01 + m02 * c02
    if det <= 0.0:
        return c
    q = (b0 * (c00 * b0 + c01 * b1 + c02 * b2) + b1 * (c01 * b0 + c11 * b1 + c12 * b2)
         + b2 * (c02 * b0 + c12 * b1 + c22 * b2))
    return c - q / det


@njit(cache=True, nogil=True)
def _one_arc(v, k, labels, vertex_ptr, vertex_neighbours, face_ptr, vertex_faces, faces):
    """True if v's neighbours in cluster k form one arc of v's link: (neighbours in k) minus
    (link edges with both ends in k) is 1 (a closed ring fully in k gives 0, several arcs more)."""
    nodes = 0
    for p in range(vertex_ptr[v], vertex_ptr[v + 1]):
        if labels[vertex_neighbours[p]] == k:
            nodes += 1
    links = 0
    for p in range(face_ptr[v], face_ptr[v + 1]):
        f = vertex_faces[p]
        inside = 0
        for j in range(3):
            w = faces[f, j]
            if w != v and labels[w] == k:
                inside += 1
        if inside == 2:
            links += 1
    return nodes - links == 1


@njit(cache=True, nogil=True)
def _sweeps(edges, faces, labels, P, S, count, vertex_ptr, vertex_neighbours, face_ptr, vertex_faces,
            max_sweeps, tolerance):
    n_clusters = S.shape[0]
    E = np.zeros(n_clusters)
    for k in range(n_clusters):
        E[k] = _energy(S, k, P, 0, 0.0)
    changed = np.zeros(n_clusters, dtype=np.int64)  # last sweep (1-based) in which a cluster changed
    for k in range(n_clusters):
        changed[k] = 1
    moves = np.zeros(max_sweeps, dtype=np.int64)
    sweeps = 0
    for sweep in range(1, max_sweeps + 1):
        moved = 0
        for e in range(edges.shape[0]):
            i = edges[e, 0]
            j = edges[e, 1]
            a = labels[i]
            b = labels[j]
            if a == b:
                continue
            if changed[a] < sweep - 1 and changed[b] < sweep - 1:
                continue  # neither cluster changed since this edge was last examined
            base = E[a] + E[b]
            best = -tolerance * abs(base)
            choice = 0
            new_a = 0.0
            new_b = 0.0
            # energies first: the arc checks are dearer and most moves do not pay
            if count[a] > 1:
                ea = _energy(S, a, P, i, -1.0)
                eb = _energy(S, b, P, i, 1.0)
                if ea + eb - base < best \
                        and _one_arc(i, a, labels, vertex_ptr, vertex_neighbours, face_ptr, vertex_faces, faces) \
                        and _one_arc(i, b, labels, vertex_ptr, vertex_neighbours, face_ptr, vertex_faces, faces):
                    best = ea + eb - base
                    choice = 1
                    new_a = ea
                    new_b = eb
            if count[b] > 1:
                ea = _energy(S, a, P, j, 1.0)
                eb = _energy(S, b, P, j, -1.0)
                if ea + eb - base < best \
                        and _one_arc(j, b, labels, vertex_ptr, vertex_neighbours, face_ptr, vertex_faces, faces) \
                        and _one_arc(j, a, labels, vertex_ptr, vertex_neighbours, face_ptr, vertex_faces, faces):
                    best = ea + eb - base
                    choice = 2
                    new_a = ea
                    new_b = eb
            if choice == 0:
                continue
            v = i if choice == 1 else j
            source = a if choice == 1 else b
            target = b if choice == 1 else a
            for c in range(10):
                S[source, c] -= P[v, c]
                S[target, c] += P[v, c]
            count[source] -= 1
            count[target] += 1
            labels[v] = target
            E[a] = new_a
            E[b] = new_b
            changed[a] = sweep
            changed[b] = sweep
            moved += 1
        moves[sweep - 1] = moved
        sweeps = sweep
        if moved == 0:
            break
    return sweeps, moves[:sweeps], E


@njit(cache=True, nogil=True)
def _accumulate(labels, P, n_clusters):
    S = np.zeros((n_clusters, 10))
    count = np.zeros(n_clusters, dtype=np.int64)
    for v in range(labels.shape[0]):
        k = labels[v]
        count[k] += 1
        for c in range(10):
            S[k, c] += P[v, c]
    return S, count


@njit(cache=True, nogil=True)
def _pieces(labels, edges):  # pragma: no cover - compiled
    parent = np.arange(labels.shape[0])
    pieces = labels.shape[0]
    for e in range(edges.shape[0]):
        a, b = edges[e, 0], edges[e, 1]
        if labels[a] != labels[b]:
            continue
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        while parent[b] != b:
            parent[b] = parent[parent[b]]
            b = parent[b]
        if a != b:
            parent[max(a, b)] = min(a, b)
            pieces -= 1
    return pieces


def label_pieces(labels: np.ndarray, edges: np.ndarray) -> int:
    """How many connected pieces the clusters of ``labels`` (n,) make over the mesh ``edges`` (e, 2):
    the cluster count when every cluster is connected (union-find over the edges inside clusters)."""
    return int(_pieces(np.ascontiguousarray(labels, dtype=np.int64), np.ascontiguousarray(edges, dtype=np.int64)))


def centroids_of(S: np.ndarray) -> np.ndarray:
    """(k, 3) minimisers c = S1^-1 S2 of the cluster energies from moments (k, 10)."""
    M = np.zeros((len(S), 3, 3))
    M[:, 0, 0], M[:, 1, 1], M[:, 2, 2] = S[:, 0], S[:, 1], S[:, 2]
    M[:, 0, 1] = M[:, 1, 0] = S[:, 3]
    M[:, 0, 2] = M[:, 2, 0] = S[:, 4]
    M[:, 1, 2] = M[:, 2, 1] = S[:, 5]
    return np.linalg.solve(M, S[:, 6:9, None])[:, :, 0]


def cluster_energy(vertices: np.ndarray, metric: np.ndarray, weights: np.ndarray, labels: np.ndarray,
                   n_clusters: int) -> np.ndarray:
    """(k,) cluster energies S3 - S2^T S1^-1 S2 from the vertices (the closed form the sweeps update)."""
    S, _ = _accumulate(np.asarray(labels, dtype=np.int64), vertex_moments(vertices, metric, weights), n_clusters)
    c = centroids_of(S)
    return S[:, 9] - np.einsum("ki,ki->k", S[:, 6:9], c)


def centred_moments(vertices: np.ndarray, metric: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The vertex moments cluster_vertices works with: those of the vertices less their mean (less
    round-off in S3 - S2^T S1^-1 S2); computed once, they serve every clustering of the same mesh."""
    return vertex_moments(vertices - vertices.mean(axis=0), metric, weights)


def cluster_vertices(vertices: np.ndarray, faces: np.ndarray, edges: np.ndarray, adjacency: MeshAdjacency,
                     metric: np.ndarray, weights: np.ndarray, labels: np.ndarray, n_clusters: int, *,
                     max_sweeps: int = 200, moments: np.ndarray | None = None) -> ClusteringResult:
    """Minimise the total cluster energy from the initial ``labels`` (each cluster connected) by
    boundary-vertex moves (see the module docstring); stops when a sweep moves nothing.
    ``moments``: centred_moments(vertices, metric, weights), when already at hand."""
    centre = vertices.mean(axis=0)
    P = centred_moments(vertices, metric, weights) if moments is None else moments
    labels = np.array(labels, dtype=np.int64)
    S, count = _accumulate(labels, P, n_clusters)
    if np.any(count == 0):
        raise ValueError("cluster_vertices: every cluster needs at least one vertex")
    sweeps, moves, energy = _sweeps(np.ascontiguousarray(edges, dtype=np.int64),
                                    np.ascontiguousarray(faces, dtype=np.int64),
                                    labels, P, S, count, adjacency.vertex_ptr, adjacency.vertex_neighbours,
                                    adjacency.face_ptr, adjacency.vertex_faces, int(max_sweeps), ENERGY_TOLERANCE)
    return ClusteringResult(labels=labels, centroids=centroids_of(S) + centre, energy=energy, sweeps=int(sweeps),
                            moves=moves)


@njit(cache=True, nogil=True)
def simple_cycles(pointer, half_u, half_v):
    """Close each region's border edges (half_u[p], half_v[p]) for p in pointer[r]:pointer[r+1]
    into one node loop. Returns (flat loops, loop length per region, status per region): status 0
    a simple cycle through every edge, 1 no edge, 2 anything else (a node not of degree 2, a
    repeated edge, several cycles): left to the caller."""
    n_regions = pointer.shape[0] - 1
    flat = np.zeros(half_u.shape[0], dtype=np.int64)
    lengths = np.zeros(n_regions, dtype=np.int64)
    status = np.zeros(n_regions, dtype=np.int64)
    out = 0
    for r in range(n_regions):
        s = pointer[r]
        e = pointer[r + 1]
        k = e - s
        if k == 0:
            status[r] = 1
            continue
        if k < 3:
            status[r] = 2
            continue
        ok = True
        for p in range(s, e):
            du = 0
            dv = 0
            for q in range(s, e):
                if half_u[q] == half_u[p] or half_v[q] == half_u[p]:
                    du += 1
                if half_u[q] == half_v[p] or half_v[q] == half_v[p]:
                    dv += 1
                if q != p and ((half_u[q] == half_u[p] and half_v[q] == half_v[p])
                               or (half_u[q] == half_v[p] and half_v[q] == half_u[p])):
                    ok = False
            if du != 2 or dv != 2 or half_u[p] == half_v[p]:
                ok = False
        if not ok:
            status[r] = 2
            continue
        first = half_u[s]
        current = half_v[s]
        previous = s
        flat[out] = first
        length = 1
        used = 1
        while current != first and used <= k:
            flat[out + length] = current
            length += 1
            for q in range(s, e):
                if q != previous and (half_u[q] == current or half_v[q] == current):
                    previous = q
                    current = half_v[q] if half_u[q] == current else half_u[q]
                    break
            used += 1
        if used != k or current != first:
            status[r] = 2
            continue
        lengths[r] = length
        out += length
    return flat[:out], lengths, status


