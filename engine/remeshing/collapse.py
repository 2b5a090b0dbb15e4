"""Short beams collapsed: the two end nodes of a beam merged into one, the cells kept valid.

A grid-shell's fabrication limits are constraints of its geometry: a beam shorter than its two
joints and the shortest cut take cannot be built, so the remesh and optimize stages merge its end
nodes (the thesis's reference code collapses edges under 5 % of the mean; here the limit is the
buildable length). A collapse is made only where the result stays a valid polygon mesh:

- the link condition: every node next to both ends is the third node of a triangle holding the beam
  (that triangle disappears; its other two beams become one);
- every cell holding both ends has them next to each other (no cell is pinched in two);
- two boundary nodes merge only along a boundary beam (the surface is not pinched);
- two corners never merge (but as the last resort, a bare corner of the outline into its neighbour
  corner: ``merge_corners``), no node loses its last cell, and no node gets more than MAX_VALENCE
  beams (MAX_BOUNDARY_VALENCE on the boundary).

The merged node keeps the place of its more constrained end (corner, then support, then boundary),
else takes the midpoint, or where that would fold a cell round it the place of either end; a
collapse that folds a cell at each is not made. It keeps the flags of both ends. Collapses of one pass touch disjoint
neighbourhoods; passes repeat until no short beam can be collapsed.

A collapse makes a node of four or five beams, and such a joint has narrower angles (and longer
set-backs) than the three-beam joints of a Voronoi grid. So a short beam between two interior
three-beam nodes whose two cells have six sides or more is *flipped* instead (a T1 transition,
as in foams): its two cells lose a side, the two cells at its ends gain one and share the beam,
which is turned across and given its buildable length. Every node keeps three beams.

A short beam that can be neither flipped nor collapsed (at a crowded boundary support, or where a
collapse would break its cells) is *removed* as the last resort (:func:`remove_short_beams`): its
two cells become one, no node moves, and its end nodes keep at least two beams. A node left with two
beams is a kinked joint; the wider angles at its ends shorten what their other beams need.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..geometry.projections import CellFans
from ..mesh import PolyMesh, neighbour_lists

__all__ = ["CollapseReport", "Normals", "collapse_beams", "flip_beams", "flip_defects", "collapse_short_beams",
           "remove_beams", "remove_short_beams", "open_narrow_joints", "dissolve_kinks", "MAX_VALENCE"]

#: The surface's unit normals (p, 3) at points (p, 3): what a collapse or flip may fold no cell along.
Normals = Callable[[np.ndarray], np.ndarray]
#: Most beams a merged node may have (a joint with more is crowded, its angles small).
MAX_VALENCE = 5
#: Most beams a merged node on the boundary may have: two of them run along the boundary, so the
#: others share half a turn (a five-beam boundary joint on the hypar closed to 3.6 degrees).
MAX_BOUNDARY_VALENCE = 4
#: A flipped beam is given this many times its buildable length.
FLIP_MARGIN = 1.1
#: A beam is flipped only if its two cells have at least FLIP_SIDES[0] sides (they lose one) and the
#: cells at its ends at most FLIP_SIDES[1] (they gain one): hexagons become pentagons and
#: heptagons, never quads or octagons, and flips do not cascade.
FLIP_SIDES = (6, 6)
#: A flipped beam's length as shares of the one asked, tried in turn until its four cells fold
#: nowhere they did not before (small cells round a short beam leave no room for a long one); a
#: flip that folds them at every share is not made.
FLIP_SHARES = (1.0, 0.75, 0.5, 0.3)


@dataclass(frozen=True, kw_only=True)
class CollapseReport:
    """collapsed: beams collapsed; passes made; left: beams still shorter than required (ids of the
    result); skipped: of those, how many no valid collapse could remove."""

    collapsed: int
    passes: int
    left: np.ndarray
    flipped: int = 0

    def to_dict(self) -> dict:
        return {"collapsed_beams": int(self.collapsed), "flipped_beams": int(self.flipped),
                "collapse_passes": int(self.passes), "short_beams_left": int(len(self.left))}


def _cells_at_nodes(polymesh: PolyMesh) -> tuple[list[list[int]], list[list[int]]]:
    """The cells as editable node lists, and per node the ids of its cells."""
    faces = [list(map(int, f)) for f in polymesh.faces]
    node_faces: list[list[int]] = [[] for _ in range(polymesh.n_nodes)]
    for i, f in enumerate(faces):
        for v in f:
            node_faces[v].append(i)
    return faces, node_faces


def _rank(polymesh: PolyMesh) -> np.ndarray:
    """How constrained each node is: corner 3, support 2, boundary 1, interior 0."""
    return np.select([polymesh.corners, polymesh.supports, polymesh.boundary], [3, 2, 1], 0)


def collapse_beams(polymesh: PolyMesh, beams: np.ndarray, *, merge_corners: bool = False,
                   normals: Normals | None = None) -> tuple[PolyMesh, int]:
    """Collapse, in the order given, those of ``beams`` (indices into ``polymesh.edges``) that can be
    collapsed validly and touch no node near an earlier collapse of this call. Returns the new grid
    (unused nodes dropped, the others renumbered in order) and the number collapsed.

    ``merge_corners``: two corners may merge along a boundary beam where one of them holds that
    beam and one other only (a corner of the outline with no inner beam): it goes, and the other
    corner stays where it is. For the last resort, where two corners lie closer than a beam can be
    built: the outline is cut at the corner by less than that beam. ``normals``: the surface's unit
    normals at points, along which a collapse may fold no cell (None: the cells' summed normal)."""
    edges = polymesh.edges
    n = polymesh.n_nodes
    faces, node_faces = _cells_at_nodes(polymesh)
    neighbours = [set(around) for around in neighbour_lists(edges, n)]
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
        if busy[a] or busy[b]:
            continue
        if polymesh.boundary[a] and polymesh.boundary[b] and uses.get((a, b), 0) != 1:
            continue
        corner_pair = bool(polymesh.corners[a] and polymesh.corners[b])
        if corner_pair and not (merge_corners and polymesh.boundary[a] and polymesh.boundary[b]
                                and min(len(neighbours[a]), len(neighbours[b])) == 2):
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
        merged = len((neighbours[a] | neighbours[b]) - {a, b})
        if merged > (MAX_BOUNDARY_VALENCE if polymesh.boundary[a] or polymesh.boundary[b] else MAX_VALENCE):
            continue
        # a triangle's third node must keep a cell; so must a and b
        if any(all(j in triangles for j in node_faces[c]) for c in thirds):
            continue
        if len(set(node_faces[a]) | set(node_faces[b])) == len(triangles):
            continue
        keep, drop = (a, b) if rank[a] >= rank[b] else (b, a)
        if corner_pair:  # the corner with inner beams stays; the bare one goes
            keep, drop = (b, a) if len(neighbours[a]) == 2 else (a, b)
            places = [x[keep]]
        elif rank[a] == rank[b]:  # the midpoint, else where either end is, whichever folds no cell
            places = [0.5 * (x[a] + x[b]), x[keep], x[drop]]
        else:
            places = [x[keep]]
        around = [faces[i] for i in set(node_faces[a]) | set(node_faces[b]) if i not in triangles]
        before = [[int(target[v]) for v in loop] for loop in around]
        after = []
        for loop in before:
            loop = [keep if v == drop else v for v in loop]
            after.append([v for j, v in enumerate(loop) if v != loop[j - 1]])
        chosen = _first_unfolding(x, before, after, [{keep: np.array(p, dtype=float)} for p in places], normals)
        if chosen is None:
            continue
        x[keep] = chosen[keep]
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


def _folded_count(x: np.ndarray, fans: CellFans, up: np.ndarray) -> int:
    """How many of the cells of ``fans`` are folded at x seen along ``up`` ((cells, 3) unit): they do
    not turn once about it, or their vector area turns against it (the optimiser's own test)."""
    return int(np.count_nonzero((fans.windings(x, up) != 1) | (np.einsum("ij,ij->i", fans.normals(x), up) <= 0)))


def _first_unfolding(x: np.ndarray, before: list[list[int]], after: list[list[int]],
                     candidates: list[dict[int, np.ndarray]], normals: Normals | None = None
                     ) -> dict[int, np.ndarray] | None:
    """The first of ``candidates`` (new places of some nodes) at which the cells ``after`` (node
    loops) fold no more than the cells ``before`` did at x, or None. The cells are seen along the
    surface's ``normals`` at their centroids at x, or without them along their summed vector area."""
    before, after = ([loop for loop in loops if len(loop) >= 3] for loops in (before, after))
    fans, after_fans = CellFans(before), CellFans(after)
    if normals is None:
        up = fans.normals(x).sum(axis=0)
        up /= max(float(np.linalg.norm(up)), 1e-300)
        up_before, up_after = (np.broadcast_to(up, (f.n_cells, 3)) for f in (fans, after_fans))
    else:
        up_before, up_after = normals(fans.centroids(x)), normals(after_fans.centroids(x))
        if np.einsum("ij,ij->", fans.normals(x), up_before) < 0:  # the cells turn the other way about them
            up_before, up_after = -up_before, -up_after
    folded_before = _folded_count(x, fans, up_before)
    trial = x.copy()
    for places in candidates:
        for node, place in places.items():
            trial[node] = place
        if _folded_count(trial, after_fans, up_after) <= folded_before:
            return places
    return None


def _cells_around(node_faces: list[list[int]], p: int, q: int) -> tuple[int, int, int, int] | None:
    """(left, right, below, above): the two cells of the beam p-q and the third cell at p and at q,
    where both ends have three cells and the beam two; else None."""
    if len(node_faces[p]) != 3 or len(node_faces[q]) != 3:
        return None
    shared = [i for i in node_faces[p] if i in node_faces[q]]
    if len(shared) != 2:
        return None
    below = next(i for i in node_faces[p] if i not in shared)
    above = next(i for i in node_faces[q] if i not in shared)
    return shared[0], shared[1], below, above


def _other(loop: list[int], node: int, not_this: int) -> int:
    """The neighbour of ``node`` in the cell ``loop`` that is not ``not_this``."""
    k = len(loop)
    i = loop.index(node)
    before, after = loop[i - 1], loop[(i + 1) % k]
    return after if before == not_this else before


def _insert_between(loop: list[int], a: int, b: int, new: int) -> None:
    """Insert ``new`` between the neighbours ``a`` and ``b`` of the cell ``loop`` (in place)."""
    i, j = sorted((loop.index(a), loop.index(b)))
    loop.insert(len(loop) if (i, j) == (0, len(loop) - 1) else j, new)


def flip_beams(polymesh: PolyMesh, beams: np.ndarray, lengths: np.ndarray, *,
               normals: Normals | None = None) -> tuple[PolyMesh, int, np.ndarray]:
    """Flip (T1), in the order given, those of ``beams`` that join two interior three-beam nodes,
    whose two cells and two end cells have the sides of FLIP_SIDES, where the four cells around
    the beam are distinct and the two end cells share no node, touching no node near an earlier
    flip of this call. A flipped beam keeps its node ids, is centred where it was, turned to run
    from one former cell towards the other, and is ``lengths[beam]`` long (m). Returns the grid (same nodes, new cells),
    the number flipped and the ids of the flipped beams in the new grid."""
    edges = polymesh.edges
    n = polymesh.n_nodes
    faces, node_faces = _cells_at_nodes(polymesh)
    valence = np.bincount(edges.ravel(), minlength=n)
    free = ~(polymesh.boundary | polymesh.supports | polymesh.corners) & (valence == 3)
    x = np.array(polymesh.nodes, dtype=float)
    busy = np.zeros(n, dtype=bool)
    flipped: list[tuple[int, int]] = []
    for beam in np.asarray(beams, dtype=int):
        p, q = map(int, edges[beam])
        if not (free[p] and free[q]) or busy[p] or busy[q]:
            continue
        around = _cells_around(node_faces, p, q)
        if around is None:
            continue
        left, right, below, above = around
        if min(len(faces[left]), len(faces[right])) < FLIP_SIDES[0]:
            continue
        if below == above or set(faces[below]) & set(faces[above]):
            continue
        if max(len(faces[below]), len(faces[above])) > FLIP_SIDES[1]:
            continue
        p1, q1 = _other(faces[left], p, q), _other(faces[left], q, p)
        p2, q2 = _other(faces[right], p, q), _other(faces[right], q, p)
        if len({p1, q1, p2, q2}) != 4:
            continue
        # cells: left loses q, right loses p; below gets q between p and p2, above p between q and q1
        loops = [list(faces[i]) for i in around]
        loops[0].remove(q)
        loops[1].remove(p)
        _insert_between(loops[2], p, p2, q)
        _insert_between(loops[3], q, q1, p)
        centre = 0.5 * (x[p] + x[q])
        across = x[loops[1]].mean(axis=0) - x[loops[0]].mean(axis=0)
        axis = x[q] - x[p]
        axis /= max(np.linalg.norm(axis), 1e-300)
        across -= (across @ axis) * axis  # in the plane of the two cells, normal to the old beam
        across /= max(np.linalg.norm(across), 1e-300)
        halves = [0.5 * share * float(lengths[beam]) for share in FLIP_SHARES]
        chosen = _first_unfolding(x, [faces[i] for i in around], loops,
                                  [{p: centre - half * across, q: centre + half * across} for half in halves], normals)
        if chosen is None:  # every share folds the four cells
            continue
        x[p], x[q] = chosen[p], chosen[q]
        for i, loop in zip(around, loops):
            faces[i] = loop
        for v in (p, q):
            node_faces[v] = [i for i in node_faces[v] if i not in ((right,) if v == p else (left,))]
        node_faces[q].append(below)
        node_faces[p].append(above)
        busy[[p, q, p1, q1, p2, q2]] = True
        busy[[v for c in (left, right, below, above) for v in faces[c]]] = True
        flipped.append((min(p, q), max(p, q)))
    if not flipped:
        return polymesh, 0, np.zeros(0, dtype=np.int64)
    result = PolyMesh(nodes=x, faces=tuple(np.asarray(f, dtype=np.int64) for f in faces),
                      boundary=polymesh.boundary, supports=polymesh.supports, corners=polymesh.corners)
    index = {tuple(e): k for k, e in enumerate(np.sort(result.edges, axis=1).tolist())}
    return result, len(flipped), np.array([index[e] for e in flipped], dtype=np.int64)


def flip_defects(polymesh: PolyMesh) -> tuple[PolyMesh, int]:
    """Flip (T1, :func:`flip_beams`, each beam kept at its length) the beams between interior nodes
    whose flip brings the sides of the interior cells among their four closer to six: the beam's
    two cells lose a side and the cells at its ends gain one, so a beam between two heptagons with a
    pentagon at each end makes four hexagons, and a heptagon next to the boundary passes its extra
    side to a boundary cell. A flip is made where it takes at least 2 off the sum of |sides - 6|
    over those interior cells, the largest gains first. The cells keep their count. Returns the grid
    and the number flipped."""
    edges = polymesh.edges
    if not len(edges):
        return polymesh, 0
    _, node_faces = _cells_at_nodes(polymesh)
    sides = polymesh.face_degrees
    inner = ~polymesh.face_boundary
    gains, beams = [], []
    for k, (p, q) in enumerate(edges.tolist()):
        around = _cells_around(node_faces, p, q)
        if around is None:
            continue
        cells = list(around)
        counted = inner[cells]  # a boundary cell is cut by the outline: its sides do not count
        before = np.abs(sides[cells] - 6)[counted].sum()
        after = np.abs(sides[cells] + np.array([-1, -1, 1, 1]) - 6)[counted].sum()
        if before - after >= 2:
            gains.append(before - after)
            beams.append(k)
    if not beams:
        return polymesh, 0
    order = np.argsort(-np.array(gains), kind="stable")
    flipped, count, _ = flip_beams(polymesh, np.array(beams)[order], polymesh.beam_lengths)
    return flipped, count


def collapse_short_beams(polymesh: PolyMesh, required: Callable[[PolyMesh], np.ndarray], *,
                         max_passes: int = 50, flip: bool = True,
                         normals: Normals | None = None) -> tuple[PolyMesh, CollapseReport]:
    """Remove beams shorter than ``required(grid)`` ((n_beams,) m, evaluated on the grid as it is at
    each pass), shortest relative to its requirement first, until none is left or none can go:
    each pass flips those that can be flipped (``flip``, :func:`flip_beams`, at FLIP_MARGIN times
    their requirement), then collapses the others. A beam once flipped is not flipped again.
    ``normals``: the surface's, along which no flip or collapse may fold a cell (None: each one's
    cells' summed normal)."""
    total, flips, passes, left = 0, 0, 0, None
    done_flips: set[tuple[int, int]] = set()
    for passes in range(1, max_passes + 1):
        need = required(polymesh)
        ratio = polymesh.beam_lengths / np.maximum(need, 1e-300)
        short = np.flatnonzero(ratio < 1.0)
        if not len(short):
            left = short
            break
        order = short[np.argsort(ratio[short], kind="stable")]
        done = 0
        if flip:
            pairs = [tuple(sorted(map(int, polymesh.edges[b]))) for b in order]
            candidates = np.array([b for b, e in zip(order, pairs) if e not in done_flips], dtype=np.int64)
            polymesh, done, new = flip_beams(polymesh, candidates, FLIP_MARGIN * need, normals=normals)
            flips += done
            done_flips.update((min(e), max(e)) for e in (tuple(map(int, polymesh.edges[b])) for b in new))
        if done:  # the next pass sees the flipped grid, and collapses what could not be flipped
            continue
        polymesh, done = collapse_beams(polymesh, order, normals=normals)
        total += done
        if not done:  # the grid is unchanged: these are the beams left
            left = short
            break
    if left is None:
        left = np.flatnonzero(polymesh.beam_lengths < required(polymesh))
    return polymesh, CollapseReport(collapsed=total, passes=passes, left=left, flipped=flips)


def _merged(first: list[int], second: list[int], a: int, b: int) -> list[int] | None:
    """The loop of two cells that share only the beam a-b, joined along it; None when the cells do not
    run along it in opposite directions (the grid is not oriented there)."""
    def rotated(loop: list[int], start: int) -> list[int]:
        i = loop.index(start)
        return loop[i:] + loop[:i]

    one = rotated(first, b)   # b ... a when first runs a -> b
    two = rotated(second, a)  # a ... b when second runs b -> a
    if one[-1] != a or two[-1] != b:
        return None
    return one + two[1:-1]


def remove_beams(polymesh: PolyMesh, beams: np.ndarray) -> tuple[PolyMesh, int]:
    """Remove, in the order given, those of ``beams`` (indices into ``polymesh.edges``) that are held
    by two cells sharing no other node, whose two end nodes have three beams or more, touching no cell
    merged earlier in this call: each beam's two cells become one. No node moves. Returns the grid
    (same nodes) and the number removed."""
    faces, node_faces = _cells_at_nodes(polymesh)
    valence = np.bincount(polymesh.edges.ravel(), minlength=polymesh.n_nodes)
    merged_cells: set[int] = set()
    gone: set[int] = set()
    removed = 0
    for beam in np.asarray(beams, dtype=int):
        a, b = map(int, polymesh.edges[beam])
        if valence[a] < 3 or valence[b] < 3:
            continue
        shared = [i for i in node_faces[a] if i in node_faces[b]]
        if len(shared) != 2 or merged_cells & set(shared):
            continue
        first, second = (faces[i] for i in shared)
        if set(first) & set(second) != {a, b}:
            continue
        k = len(first)
        if (first.index(b) - first.index(a)) % k != 1:
            first, second = second, first
        loop = _merged(first, second, a, b)
        if loop is None:
            continue
        keep, drop = shared if shared[0] < shared[1] else shared[::-1]
        faces[keep] = loop
        gone.add(drop)
        merged_cells.update(shared)
        for v in faces[keep]:
            node_faces[v] = [keep if i == drop else i for i in node_faces[v]]
            node_faces[v] = list(dict.fromkeys(node_faces[v]))
        valence[[a, b]] -= 1
        removed += 1
    if not removed:
        return polymesh, 0
    result = PolyMesh(nodes=polymesh.nodes, faces=tuple(np.asarray(f, dtype=np.int64)
                                                        for i, f in enumerate(faces) if i not in gone),
                      boundary=polymesh.boundary, supports=polymesh.supports, corners=polymesh.corners)
    return result, removed


def _narrowest_pairs(polymesh: PolyMesh, nodes) -> list[tuple[float, int, int, int]]:
    """(angle rad, node, beam, beam): the narrowest pair of beams at each of ``nodes`` that has three
    beams or more."""
    edges, x = polymesh.edges, polymesh.nodes
    at: dict[int, list[int]] = {}
    for k, (a, b) in enumerate(edges):
        at.setdefault(int(a), []).append(k)
        at.setdefault(int(b), []).append(k)
    out = []
    for v in map(int, nodes):
        beams = at.get(v, [])
        if len(beams) < 3:
            continue
        ends = np.where(edges[beams, 0] == v, edges[beams, 1], edges[beams, 0])
        d = x[ends] - x[v]
        d /= np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
        cosine = d @ d.T
        np.fill_diagonal(cosine, -2.0)
        i, j = np.unravel_index(np.argmax(cosine), cosine.shape)
        out.append((float(np.arccos(np.clip(cosine[i, j], -1.0, 1.0))), v, beams[i], beams[j]))
    return out


def _narrow_partners(polymesh: PolyMesh, short: np.ndarray) -> np.ndarray:
    """For each of the ``short`` beams, at each end with three beams or more, the beams of the
    narrowest pair of beams there (the pair that sets the end's joint set-back), the short beam itself
    left out; ordered by that angle, narrowest first."""
    ends = np.unique(polymesh.edges[short].ravel())
    mine = set(map(int, short))
    found = sorted((angle, k) for angle, v, *pair in _narrowest_pairs(polymesh, ends) for k in pair if k not in mine)
    return np.array(list(dict.fromkeys(k for _, k in found)), dtype=np.int64)


def open_narrow_joints(polymesh: PolyMesh, min_angle_rad: float, *, max_passes: int = 50
                       ) -> tuple[PolyMesh, int, np.ndarray]:
    """Where two beams at a node meet at less than ``min_angle_rad``, remove (:func:`remove_beams`) one
    of them, the longer first (its cells become one, the angle at the node widens), narrowest first,
    in passes until no angle is too narrow or none can go. Returns the grid, the number removed and
    the nodes with an angle still too narrow."""
    def too_narrow(grid: PolyMesh) -> list[tuple[float, int, int, int]]:
        return sorted(p for p in _narrowest_pairs(grid, range(grid.n_nodes)) if p[0] < min_angle_rad)

    removed, pairs = 0, too_narrow(polymesh)
    for _ in range(max_passes):
        if not pairs:
            break
        lengths = polymesh.beam_lengths
        order = [k for _, _, i, j in pairs for k in sorted((i, j), key=lambda k: -lengths[k])]
        polymesh, done = remove_beams(polymesh, np.array(order, dtype=np.int64))
        if not done:
            break
        removed += done
        pairs = too_narrow(polymesh)
    return polymesh, removed, np.array([v for _, v, *_ in pairs], dtype=np.int64)


def dissolve_kinks(polymesh: PolyMesh) -> tuple[PolyMesh, int]:
    """Drop the interior nodes with two beams (left by :func:`remove_beams`; not supports) from their
    cells where their two neighbours are not joined already and every cell keeps three nodes: the
    two beams become one straight beam, and a kinked joint that carries nothing across goes. Where the
    two neighbours are joined and one of its cells is the triangle of the three (a spike: its two
    beams meet at an angle no joint takes), the node goes with its two beams and that triangle. No
    other node moves. Returns the grid (unused nodes dropped, the others renumbered in order) and the
    number of nodes dropped."""
    edges = polymesh.edges
    valence = np.bincount(edges.ravel(), minlength=polymesh.n_nodes)
    kinks = np.flatnonzero((valence == 2) & ~(polymesh.boundary | polymesh.supports | polymesh.corners))
    if not len(kinks):
        return polymesh, 0
    faces, node_faces = _cells_at_nodes(polymesh)
    joined = {tuple(e) for e in np.sort(edges, axis=1).tolist()}
    neighbours = neighbour_lists(edges, polymesh.n_nodes)
    busy = np.zeros(polymesh.n_nodes, dtype=bool)
    dropped = np.zeros(polymesh.n_nodes, dtype=bool)
    gone: set[int] = set()
    for v in map(int, kinks):
        p, q = neighbours[v]
        if busy[v] or busy[p] or busy[q]:
            continue
        if (min(p, q), max(p, q)) in joined:
            spike = _spike(v, p, q, faces, node_faces)
            if spike is not None:
                triangle, other = spike
                faces[other].remove(v)
                gone.add(triangle)
                busy[[v, p, q]] = True
                dropped[v] = True
            continue
        if any(len(faces[i]) <= 3 for i in node_faces[v]):
            continue
        for i in node_faces[v]:
            faces[i].remove(v)
        joined.add((min(p, q), max(p, q)))
        busy[[v, p, q]] = True
        dropped[v] = True
    if not dropped.any():
        return polymesh, 0
    keep = ~dropped
    number = np.cumsum(keep) - 1
    result = PolyMesh(nodes=polymesh.nodes[keep], faces=tuple(np.asarray(number[f], dtype=np.int64)
                                                              for i, f in enumerate(faces) if i not in gone),
                      boundary=polymesh.boundary[keep], supports=polymesh.supports[keep],
                      corners=polymesh.corners[keep])
    return result, int(dropped.sum())


def _spike(v: int, p: int, q: int, faces: list[list[int]], node_faces: list[list[int]]) -> tuple[int, int] | None:
    """(triangle, other cell) where the two-beam node ``v`` is the tip of the triangle (v, p, q) on
    the beam p-q, and its other cell keeps three nodes and does not lie across p-q as well (p-q would
    then run inside it); else None."""
    cells = node_faces[v]
    if len(cells) != 2:
        return None
    triangles = [i for i in cells if sorted(faces[i]) == sorted((v, p, q))]
    if len(triangles) != 1:
        return None
    triangle = triangles[0]
    other = cells[0] if cells[1] == triangle else cells[1]

    def side(i: int) -> bool:  # p and q are neighbours in cell i's loop: the cell lies along the beam p-q
        f = faces[i]
        k = f.index(p)
        return q in (f[k - 1], f[(k + 1) % len(f)])

    across = [i for i in node_faces[p] if i != triangle and i in node_faces[q] and side(i)]
    if len(faces[other]) <= 3 or other in across or len(across) > 1:
        return None
    return triangle, other


def remove_short_beams(polymesh: PolyMesh, required: Callable[[PolyMesh], np.ndarray], *,
                       max_passes: int = 50) -> tuple[PolyMesh, int, np.ndarray]:
    """Remove (:func:`remove_beams`) beams shorter than ``required(grid)`` ((n_beams,) m, evaluated on
    the grid as it is at each pass), shortest relative to its requirement first. Where none of them
    can go (boundary beams), a beam of the narrowest pair at their ends goes instead: the angle there
    widens, and with it the joint's set-back shrinks. Passes repeat until none is short or none can
    go. Returns the grid, the number removed and the ids of the short beams left."""
    removed = 0
    for _ in range(max_passes):
        ratio = polymesh.beam_lengths / np.maximum(required(polymesh), 1e-300)
        short = np.flatnonzero(ratio < 1.0)
        if not len(short):
            break
        short = short[np.argsort(ratio[short], kind="stable")]
        polymesh, done = remove_beams(polymesh, short)
        if not done:
            polymesh, done = remove_beams(polymesh, _narrow_partners(polymesh, short))
        removed += done
        if not done:
            break
    left = np.flatnonzero(polymesh.beam_lengths < required(polymesh))
    return polymesh, removed, left
