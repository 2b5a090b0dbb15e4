"""Triangle and polygon meshes: the two geometric types every stage passes on.

``TriMesh`` is the input surface (metres), ``PolyMesh`` the grid-shell (nodes, beams
as edges, cells as node loops). Both are frozen values: derived data are cached
properties and stored arrays are read-only.

Glossary: n_vertices / n_nodes (rows of the coordinate array), n_faces, edges (e, 2)
with the smaller node id first.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

__all__ = ["TriMesh", "PolyMesh", "unique_edges", "boundary_loops", "chain_loops", "best_fit_plane", "node_adjacency",
           "neighbour_lists"]


def _readonly(array: np.ndarray) -> np.ndarray:
    array = np.ascontiguousarray(array)
    array.flags.writeable = False
    return array


def unique_rows(rows: np.ndarray, **options):
    """``np.unique(rows, axis=0, **options)`` for rows of non-negative integers, on one int64 key per
    row where the keys fit (a row-wise unique sorts structured rows, several times slower: 27 s of
    a 1.28 million-triangle surface's cleaning went there)."""
    rows = np.asarray(rows)
    if rows.ndim != 2 or not len(rows) or not np.issubdtype(rows.dtype, np.integer) or rows.min() < 0:
        return np.unique(rows, axis=0, **options)
    base = int(rows.max()) + 1
    if base ** rows.shape[1] >= 2**63:
        return np.unique(rows, axis=0, **options)
    key = np.zeros(len(rows), dtype=np.int64)
    for column in rows.T.astype(np.int64):
        key = key * base + column
    found = np.unique(key, **options)
    keys = found[0] if isinstance(found, tuple) else found
    unique = np.empty((len(keys), rows.shape[1]), dtype=rows.dtype)
    for j in range(rows.shape[1] - 1, -1, -1):
        unique[:, j] = keys % base
        keys = keys // base
    return (unique, *found[1:]) if isinstance(found, tuple) else unique


def unique_edges(faces: list[np.ndarray] | np.ndarray) -> np.ndarray:
    """Unique undirected edges of triangles (m, 3) or of polygon loops, as (e, 2) int64, sorted."""
    if isinstance(faces, np.ndarray) and faces.ndim == 2:
        directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=-1).reshape(-1, 2)
    else:
        loops = [np.asarray(f) for f in faces if len(f)]
        if loops:  # every node to the next of its loop, all loops at once
            flat = np.concatenate(loops)
            sizes = np.array([len(f) for f in loops])
            following = np.arange(len(flat)) + 1
            following[np.cumsum(sizes) - 1] -= sizes
            directed = np.column_stack([flat, flat[following]])
        else:
            directed = np.zeros((0, 2), dtype=np.int64)
    edges = np.sort(directed.astype(np.int64), axis=1)
    return unique_rows(edges) if len(edges) else edges


def node_adjacency(edges: np.ndarray, n: int):
    """(n, n) symmetric node adjacency (scipy CSR, 1 per edge) of the undirected ``edges`` (e, 2),
    each listed once."""
    import scipy.sparse as sp

    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    return sp.csr_matrix((np.ones(2 * len(edges)), (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]])),
                         shape=(n, n))


def neighbour_lists(edges: np.ndarray, n: int) -> list[list[int]]:
    """Each of the n nodes' neighbours along the undirected ``edges`` (e, 2), in the edges' order."""
    out: list[list[int]] = [[] for _ in range(n)]
    for a, b in np.asarray(edges, dtype=np.int64).reshape(-1, 2).tolist():
        out[a].append(b)
        out[b].append(a)
    return out


def _used_once(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """(k,) bool: which of the directed edges start[i] -> end[i] no other edge shares, either way
    round (the boundary edges of faces given by their edges in turn)."""
    key = np.sort(np.stack([start, end], axis=1), axis=1)
    _, inverse, counts = unique_rows(key, return_inverse=True, return_counts=True)
    return counts[inverse.ravel()] == 1


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """Closed boundary loops of a manifold triangle mesh, each an ordered vertex array.

    A boundary edge is used by one face; loops follow the faces' orientation.
    Returned longest first.
    """
    directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=-1).reshape(-1, 2)
    border = directed[_used_once(directed[:, 0], directed[:, 1])]
    return chain_loops(border[:, 0], border[:, 1])


def chain_loops(start: np.ndarray, end: np.ndarray) -> list[np.ndarray]:
    """Closed loops of the directed edges start[i] -> end[i] (each vertex starting one edge), each
    an ordered vertex array, longest first."""
    successor = dict(zip(np.asarray(start).tolist(), np.asarray(end).tolist()))
    loops: list[np.ndarray] = []
    seen: set[int] = set()
    for first in successor:
        if first in seen:
            continue
        loop = [first]
        seen.add(first)
        following = successor[first]
        while following != first and following not in seen:
            loop.append(following)
            seen.add(following)
            following = successor.get(following, first)
        loops.append(np.array(loop, dtype=np.int64))
    loops.sort(key=len, reverse=True)
    return loops


def best_fit_plane(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares plane of (k, 3) points: (centroid (3,), unit normal (3,))."""
    centroid = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centroid, full_matrices=False)
    return centroid, vt[-1]


@dataclass(frozen=True, kw_only=True)
class TriMesh:
    """A triangulated surface in metres.

    vertices: (n_vertices, 3) float64; faces: (n_faces, 3) int64, consistently oriented
    (normals up or outward after ``engine.geometry.surfaces.clean_mesh``); flagged: (n_vertices,)
    bool, vertices marked as supports in the input file (red in a PLY), all False if none.
    """

    vertices: np.ndarray
    faces: np.ndarray
    # None (no vertex flagged) or a sequence is welcome too: __post_init__ makes it a read-only bool
    # array, and mypy has no field converters to say so
    flagged: np.ndarray = field(default=None)  # type: ignore[arg-type]
    name: str = "surface"

    def __post_init__(self) -> None:
        vertices = np.asarray(self.vertices, dtype=np.float64)
        faces = np.asarray(self.faces, dtype=np.int64)
        if vertices.ndim != 2 or vertices.shape[1] != 3:
            raise ValueError(f"vertices must be (n, 3), got {vertices.shape}")
        if faces.ndim != 2 or faces.shape[1] != 3:
            raise ValueError(f"faces must be (m, 3), got {faces.shape}")
        flagged = (np.zeros(len(vertices), dtype=bool) if self.flagged is None
                   else np.asarray(self.flagged, dtype=bool))
        object.__setattr__(self, "vertices", _readonly(vertices))
        object.__setattr__(self, "faces", _readonly(faces))
        object.__setattr__(self, "flagged", _readonly(flagged))

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_faces(self) -> int:
        return len(self.faces)

    @cached_property
    def triangles(self) -> np.ndarray:
        """(n_faces, 3, 3) corner coordinates."""
        return _readonly(self.vertices[self.faces])

    @cached_property
    def _face_cross(self) -> np.ndarray:
        t = self.triangles
        return np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])

    @cached_property
    def face_areas(self) -> np.ndarray:
        """(n_faces,) true areas in m^2."""
        return _readonly(0.5 * np.linalg.norm(self._face_cross, axis=1))

    @cached_property
    def face_plan_areas(self) -> np.ndarray:
        """(n_faces,) areas projected on the horizontal plane, m^2."""
        return _readonly(0.5 * np.abs(self._face_cross[:, 2]))

    @cached_property
    def face_normals(self) -> np.ndarray:
        """(n_faces, 3) unit normals following the face orientation."""
        cross = self._face_cross
        norm = np.linalg.norm(cross, axis=1, keepdims=True)
        return _readonly(cross / np.where(norm > 0, norm, 1.0))

    @cached_property
    def face_centroids(self) -> np.ndarray:
        return _readonly(self.triangles.mean(axis=1))

    @cached_property
    def vertex_normals(self) -> np.ndarray:
        """(n_vertices, 3) area-weighted unit normals."""
        acc = np.zeros((self.n_vertices, 3))
        for k in range(3):
            np.add.at(acc, self.faces[:, k], self._face_cross)
        norm = np.linalg.norm(acc, axis=1, keepdims=True)
        return _readonly(acc / np.where(norm > 0, norm, 1.0))

    @cached_property
    def vertex_areas(self) -> np.ndarray:
        """(n_vertices,) barycentric (one third of each adjacent face) areas, m^2."""
        acc = np.zeros(self.n_vertices)
        for k in range(3):
            np.add.at(acc, self.faces[:, k], self.face_areas / 3.0)
        return _readonly(acc)

    @cached_property
    def edges(self) -> np.ndarray:
        """(n_edges, 2) unique undirected edges."""
        return _readonly(unique_edges(self.faces))

    @cached_property
    def edge_lengths(self) -> np.ndarray:
        """(n_edges,) lengths of ``edges``, m."""
        return _readonly(np.linalg.norm(self.vertices[self.edges[:, 1]] - self.vertices[self.edges[:, 0]], axis=1))

    @cached_property
    def boundary_loops(self) -> list[np.ndarray]:
        """Ordered vertex loops of the boundary, longest (outer) first."""
        return boundary_loops(self.faces)

    @cached_property
    def boundary_vertices(self) -> np.ndarray:
        """(n_vertices,) bool, True on any boundary loop."""
        mask = np.zeros(self.n_vertices, dtype=bool)
        for loop in self.boundary_loops:
            mask[loop] = True
        return _readonly(mask)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) lower and upper corners of the bounding box."""
        return np.array([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    @property
    def diagonal(self) -> float:
        """Length of the bounding-box diagonal, m."""
        lo, hi = self.bounds
        return float(np.linalg.norm(hi - lo))

    @property
    def area(self) -> float:
        return float(self.face_areas.sum())

    def to_trimesh(self):  # -> trimesh.Trimesh
        """A ``trimesh.Trimesh`` view (no processing) for I/O and queries."""
        import trimesh

        return trimesh.Trimesh(self.vertices.copy(), self.faces.copy(), process=False)


@dataclass(frozen=True, kw_only=True)
class PolyMesh:
    """A polygonal grid-shell: nodes (joints), faces (cells as node loops), beams = edges.

    nodes: (n_nodes, 3) float64 m; faces: tuple of int64 node loops, each a simple
    polygon, consistently oriented; boundary: (n_nodes,) bool on the surface boundary;
    supports: (n_nodes,) bool, supported nodes; corners: (n_nodes,) bool, surface
    corners kept as nodes (fixed during optimisation).
    """

    nodes: np.ndarray
    faces: tuple[np.ndarray, ...]
    # None (all False) or a sequence is welcome too: __post_init__ makes each a read-only (n_nodes,) bool
    # array, and mypy has no field converters to say so
    boundary: np.ndarray = field(default=None)  # type: ignore[arg-type]
    supports: np.ndarray = field(default=None)  # type: ignore[arg-type]
    corners: np.ndarray = field(default=None)  # type: ignore[arg-type]

    def __post_init__(self) -> None:
        nodes = np.asarray(self.nodes, dtype=np.float64)
        n = len(nodes)
        faces = tuple(_readonly(np.asarray(f, dtype=np.int64)) for f in self.faces)
        object.__setattr__(self, "nodes", _readonly(nodes))
        object.__setattr__(self, "faces", faces)
        for name in ("boundary", "supports", "corners"):
            value = getattr(self, name)
            mask = np.zeros(n, dtype=bool) if value is None else np.asarray(value, dtype=bool)
            if mask.shape != (n,):
                raise ValueError(f"{name} must be ({n},) bool, got {mask.shape}")
            object.__setattr__(self, name, _readonly(mask))

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    @property
    def n_faces(self) -> int:
        return len(self.faces)

    @cached_property
    def edges(self) -> np.ndarray:
        """(n_beams, 2) unique beams, smaller node id first."""
        return _readonly(unique_edges(list(self.faces)))

    @property
    def beams(self) -> np.ndarray:
        """Alias of ``edges``: a grid-shell's edges are its beams."""
        return self.edges

    @cached_property
    def beam_lengths(self) -> np.ndarray:
        """(n_beams,) node-to-node lengths, m."""
        e = self.edges
        return _readonly(np.linalg.norm(self.nodes[e[:, 1]] - self.nodes[e[:, 0]], axis=1))

    @property
    def total_length(self) -> float:
        """Total beam length L_tot, m."""
        return float(self.beam_lengths.sum())

    @cached_property
    def face_degrees(self) -> np.ndarray:
        """(n_faces,) number of nodes of each cell."""
        return _readonly(np.array([len(f) for f in self.faces], dtype=np.int64))

    @cached_property
    def valence(self) -> np.ndarray:
        """(n_nodes,) number of beams at each node."""
        return _readonly(np.bincount(self.edges.ravel(), minlength=self.n_nodes))

    @cached_property
    def corner_table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every cell's corners in one array: (node of each corner, node of the next corner round
        its cell, the cell of each corner), each (sum of the degrees,), cell by cell."""
        degrees = self.face_degrees
        node = np.concatenate(self.faces) if self.faces else np.zeros(0, dtype=np.int64)
        start = np.repeat(np.cumsum(degrees) - degrees, degrees)
        position = np.arange(len(node)) - start
        following = node[start + (position + 1) % np.repeat(degrees, degrees)]
        cell = np.repeat(np.arange(self.n_faces), degrees)
        return _readonly(node), _readonly(following), _readonly(cell)

    def face_vector_areas(self) -> np.ndarray:
        """(n_faces, 3) vector areas (1/2 sum p_i x p_i+1) of the node loops: norm = area (m^2),
        direction = normal."""
        node, following, cell = self.corner_table
        p, q = self.nodes[node], self.nodes[following]
        crossed = np.stack([p[:, 1] * q[:, 2] - p[:, 2] * q[:, 1], p[:, 2] * q[:, 0] - p[:, 0] * q[:, 2],
                            p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0]], axis=1)
        return 0.5 * np.stack([np.bincount(cell, weights=crossed[:, k], minlength=self.n_faces)
                               for k in range(3)], axis=1)

    @cached_property
    def face_boundary(self) -> np.ndarray:
        """(n_faces,) bool: the cell has an edge on the surface boundary (used by one face)."""
        node, following, owner = self.corner_table
        out = np.zeros(self.n_faces, dtype=bool)
        out[owner[_used_once(node, following)]] = True
        return _readonly(out)

    @cached_property
    def boundary_loops(self) -> list[np.ndarray]:
        """Node loops of the grid's boundary (its beams used by one cell), in the cells'
        orientation, longest first."""
        node, following, _ = self.corner_table
        once = _used_once(node, following)
        return chain_loops(node[once], following[once])

    def face_planarity(self) -> np.ndarray:
        """(n_faces,) largest distance of a face's nodes from its best-fit plane, m."""
        out = np.zeros(self.n_faces)
        for i, f in enumerate(self.faces):
            if len(f) > 3:
                c, n = best_fit_plane(self.nodes[f])
                out[i] = np.abs((self.nodes[f] - c) @ n).max()
        return out

    def face_areas(self) -> np.ndarray:
        """(n_faces,) vector areas' norms of the (possibly non-planar) node loops, m^2."""
        return np.linalg.norm(self.face_vector_areas(), axis=1)

    def replace_nodes(self, nodes: np.ndarray) -> "PolyMesh":
        """A copy with moved nodes and the same topology and flags (and the topology already
        worked out: beams, degrees, valences, boundary cells). The faces and flags are this
        grid's read-only arrays, not checked again (a 1500-cell optimiser spent 1 s re-wrapping
        its faces)."""
        nodes = _readonly(np.asarray(nodes, dtype=np.float64))
        if nodes.shape != self.nodes.shape:
            raise ValueError(f"replace_nodes: nodes must be {self.nodes.shape}, got {nodes.shape}")
        moved = object.__new__(PolyMesh)
        for name, value in (("nodes", nodes), ("faces", self.faces), ("boundary", self.boundary),
                            ("supports", self.supports), ("corners", self.corners)):
            object.__setattr__(moved, name, value)
        for name in _TOPOLOGY:
            if name in self.__dict__:
                moved.__dict__[name] = self.__dict__[name]
        return moved


#: PolyMesh's cached properties that depend on its faces only (kept by replace_nodes)
_TOPOLOGY = ("edges", "face_degrees", "valence", "face_boundary", "boundary_loops", "corner_table")
