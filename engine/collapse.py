"""Short beams collapsed: the two end nodes of a beam merged into one, the cells kept valid.

A grid-shell's fabrication limits are constraints of its geometry: a beam shorter than its two
joints and the shortest cut take cannot be built, so the remesh and optimize stages merge its end
nodes (the thesis's reference code collapses edges under 5 % of the mean; here the limit is the
buildable length). A collapse is made only where the result stays a valid polygon mesh:

- the link condition: every node next to both ends is the third node of a triangle holding the beam
  (that triangle disappears; its other two beams become one);
- every cell holding both ends has them next to each other (no cell is pinched in two);
- two boundary nodes merge only along a boundary beam (the surface is not pinched);
- two corners never merge, no node loses its last cell, and no node gets more than MAX_VALENCE beams.

The merged node keeps the place of its more constrained end (corner, then support, then boundary),
else takes the midpoint; it keeps the flags of both ends. Collapses of one pass touch disjoint
neighbourhoods; passes repeat until no short beam can be collapsed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .mesh import PolyMesh

__all__ = ["CollapseReport", "collapse_beams", "collapse_short_beams", "MAX_VALENCE"]

#: Most beams a merged node may have (a joint with more is crowded, its angles small).
MAX_VALENCE = 5


@dataclass(frozen=True, kw_only=True)
class CollapseReport:
    """collapsed: beams collapsed; passes made; left: beams still shorter than required (ids of the
    result); skipped: of those, how many no valid collapse could remove."""

    collapsed: int
    passes: int
    left: np.ndarray

    def to_dict(self) -> dict:
        return {"collapsed_beams": int(self.collapsed), "collapse_passes": int(self.passes),
                "short_beams_left": int(len(self.left))}


def _rank(polymesh: PolyMesh) -> np.ndarray:
    """How constrained each node is: corner 3, support 2, boundary 1, interior 0."""
    return np.select([polymesh.corners, polymesh.supports, polymesh.boundary], [3, 2, 1], 0)


def collapse_beams(polymesh: PolyMesh, beams: np.ndarray) -> tuple[PolyMesh, int]:
    """Collapse, in the order given, those of ``beams`` (indices into ``polymesh.edges``) that can be
    collapsed validly and touch no node near an earlier collapse of this call. Returns the new grid
    (unused nodes dropped, the others renumbered in order) and the number collapsed."""
    edges = polymesh.edges
    n = polymesh.n_nodes
    faces = [list(map(int, f)) for f in polymesh.faces]
    node_faces: list[list[int]] = [[] for _ in range(n)]
    for i, f in enumerate(faces):
        for v in f:
            node_faces[v].append(i)
    neighbours: list[set[int]] = [set() for _ in range(n)]
    for a, b in edges:
        neighbours[a].add(int(b))
        neighbours[b].add(int(a))
    # boundary beams: used by one cell
    uses: dict[tuple[int, int], int] = {}
    for f in faces:
        for a, b in zip(f, f[1:] + f[:1]):
            key = (a, b) if a < b else (b, a)
            uses[key] = uses.get(key, 0) + 1
    rank = _rank(polymesh)
    x = np.array(polymesh.nodes, dtype=float)
    target = np.arange(n)
    busy = np.zeros(n, dtype=bool)
    removed_faces: set[int] = set()
    collapsed = 0
    for beam in np.asarray(beams, dtype=int):
        a, b = map(int, edges[beam])
        if busy[a] or busy[b] or (polymesh.corners[a] and polymesh.corners[b]):
            continue
        if polymesh.boundary[a] and polymesh.boundary[b] and uses.get((a, b), 0) != 1:
            continue
        shared = set(node_faces[a]) & set(node_faces[b])
        triangles, valid = [], True
        for i in shared:
            f = faces[i]
            k = len(f)
            ia, ib = f.index(a), f.index(b)
            if (ia - ib) % k not in (1, k - 1):
                valid = False
                break
            if k == 3:
                triangles.append(i)
        if not valid:
            continue
        thirds = {v for i in triangles for v in faces[i] if v not in (a, b)}
        if (neighbours[a] & neighbours[b]) - thirds:
            continue
        if len((neighbours[a] | neighbours[b]) - {a, b}) > MAX_VALENCE:
            continue
        # a triangle's third node must keep a cell; so must a and b
        if any(all(j in triangles for j in node_faces[c]) for c in thirds):
            continue
        if len(set(node_faces[a]) | set(node_faces[b])) == len(triangles):
            continue
        keep, drop = (a, b) if rank[a] >= rank[b] else (b, a)
        if rank[a] == rank[b]:
            x[keep] = 0.5 * (x[a] + x[b])
        target[drop] = keep
        removed_faces.update(triangles)
        for i in node_faces[drop]:
            if i not in triangles:
                node_faces[keep].append(i)
        busy[list(neighbours[a] | neighbours[b] | {a, b})] = True
        collapsed += 1
    if not collapsed:
        return polymesh, 0
    new_faces = []
    for i, f in enumerate(faces):
        if i in removed_faces:
            continue
        loop = [int(target[v]) for v in f]
        loop = [v for j, v in enumerate(loop) if v != loop[j - 1]]
        if len(loop) >= 3:
            new_faces.append(loop)
    flags = {name: np.array(getattr(polymesh, name), dtype=bool) for name in ("boundary", "supports", "corners")}
    for name, mask in flags.items():
        np.logical_or.at(mask, target, mask.copy())
    used = np.zeros(n, dtype=bool)
    for f in new_faces:
        used[f] = True
    number = np.cumsum(used) - 1
    result = PolyMesh(nodes=x[used], faces=tuple(np.asarray(number[f], dtype=np.int64) for f in new_faces),
                      **{name: mask[used] for name, mask in flags.items()})
    return result, collapsed


def collapse_short_beams(polymesh: PolyMesh, required: Callable[[PolyMesh], np.ndarray], *,
                         max_passes: int = 50) -> tuple[PolyMesh, CollapseReport]:
    """Collapse beams shorter than ``required(grid)`` ((n_beams,) m, evaluated on the grid as it is
    at each pass), shortest relative to its requirement first, until none is left or none can go."""
    total, passes, left = 0, 0, None
    for passes in range(1, max_passes + 1):
        ratio = polymesh.beam_lengths / np.maximum(required(polymesh), 1e-300)
        short = np.flatnonzero(ratio < 1.0)
        if not len(short):
            left = short
            break
        polymesh, done = collapse_beams(polymesh, short[np.argsort(ratio[short], kind="stable")])
        total += done
        if not done:  # the grid is unchanged: these are the beams left
            left = short
            break
    if left is None:
        left = np.flatnonzero(polymesh.beam_lengths < required(polymesh))
    return polymesh, CollapseReport(collapsed=total, passes=passes, left=left)
