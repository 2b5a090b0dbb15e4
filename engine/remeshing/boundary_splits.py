"""Splits of boundary cells that cannot be planar and stay on the surface (for planar panels).

Two configurations tie a cell's plane to the boundary, whatever the optimiser does with the
free nodes (boundary nodes stay on the boundary curve, supports and corners do not move):

1. A cell that holds a run of three or more boundary nodes that are not on one line: its plane
   is the plane of those nodes. At a corner of the mock-up (edges in z = 0) that is z = 0 while
   the cell's inner nodes stand 90 mm above it. Such a cell is split by a new beam from the
   run's kink (the node farthest from the run's chord, the corner) to an inner node of the cell,
   the one whose two parts have the largest smallest corner angle; each part then touches one
   side of the kink.
2. Cells along a straight stretch of the boundary: each holds two nodes of the stretch, so its
   plane contains the stretch's line; two such cells also share the spoke beam at their common
   boundary node, so both planes contain that line and the spoke's inner node: they are the same
   plane. A chain of such cells must lie in one plane through the line, which on a doubly curved
   surface soon leaves the surface. Walking along the stretch, a cell joins the current chain
   while one plane through the line stays within ``hold`` of every inner node of the chain;
   otherwise a triangle (the boundary beam and one spoke) is cut off it by a new beam, which
   leaves the rest of the cell touching the stretch at one node: the chain is broken there.

A cell is split only where the plane forced on it is farther than ``hold`` from one of its (or
its chain's) inner nodes, so flat or gently curved boundaries keep their cells. Positions are
not changed here. The new beams are returned so that the optimiser can report them.
:func:`cut_boundary_triangles` applies the second rule's cut to given cells (the optimiser's
repair of boundary cells its end game could not make planar).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..mesh import PolyMesh

__all__ = ["BoundarySplits", "split_boundary_cells", "cut_boundary_triangles"]


@dataclass(frozen=True, kw_only=True)
class BoundarySplits:
    """The split grid-shell, the new beams (b,2) node ids, and how many came from each rule."""

    polymesh: PolyMesh
    new_beams: np.ndarray
    corner_splits: int
    edge_splits: int


def _boundary_beams(faces: list[np.ndarray]) -> set[tuple[int, int]]:
    """Beams (smaller id first) used by one cell only."""
    keys = np.sort(np.concatenate([np.stack([f, np.roll(f, -1)], axis=1) for f in faces]), axis=1)
    unique, counts = np.unique(keys, axis=0, return_counts=True)
    return {(int(a), int(b)) for a, b in unique[counts == 1]}


def _key(a: int, b: int) -> tuple[int, int]:
    return (a, b) if a < b else (b, a)


def _line_deviation(points: np.ndarray) -> float:
    """Largest distance of (p,3) points from the line through the first and the last, m."""
    d = points[-1] - points[0]
    d = d / max(float(np.linalg.norm(d)), 1e-300)
    off = points - points[0]
    return float(np.linalg.norm(off - np.outer(off @ d, d), axis=1).max())


def _smallest_angle(x: np.ndarray, loop: np.ndarray) -> float:
    """Smallest corner angle of a node loop, rad."""
    p = x[loop]
    u, v = np.roll(p, 1, axis=0) - p, np.roll(p, -1, axis=0) - p
    return float(np.arctan2(np.linalg.norm(np.cross(u, v), axis=1), np.einsum("ij,ij->i", u, v)).min())


def _forced_plane_gap(x: np.ndarray, held: np.ndarray, inner: np.ndarray, straightness: float) -> float:
    """Largest distance of the ``inner`` nodes from the plane their cells are held in by the
    ``held`` boundary nodes: the plane through the held nodes when they span one, else the
    best plane through their line (least squares over the inner nodes), m."""
    if len(inner) == 0 or len(held) < 2:
        return 0.0
    p = x[held]
    centroid = p.mean(axis=0)
    _, s, vt = np.linalg.svd(p - centroid, full_matrices=False)
    if len(held) >= 3 and s[1] > straightness * np.sqrt(len(held)):
        normal = vt[-1] if len(s) == 3 else np.cross(vt[0], vt[1])
    else:
        direction = vt[0]
        w = x[inner] - centroid
        w = w - np.outer(w @ direction, direction)
        if np.allclose(w, 0):
            return 0.0
        _, _, vw = np.linalg.svd(w, full_matrices=False)
        # w lies in the plane normal to the line: its weaker axis there is the plane's normal
        normal = vw[1] if len(vw) >= 2 else np.cross(direction, vw[0])
        normal = normal - (normal @ direction) * direction
    normal = normal / max(float(np.linalg.norm(normal)), 1e-300)
    return float(np.abs((x[inner] - centroid) @ normal).max())


def _split_at(face: np.ndarray, p: int, q: int) -> tuple[np.ndarray, np.ndarray]:
    """The two loops of ``face`` cut by a beam between positions p and q (orientation kept)."""
    k = len(face)
    return face[np.arange(p, p + (q - p) % k + 1) % k], face[np.arange(q, q + (p - q) % k + 1) % k]


def _corner_pass(x: np.ndarray, faces: list[np.ndarray], boundary: np.ndarray, beams: set, hold: float,
                 straightness: float) -> tuple[list[np.ndarray], list[tuple[int, int]]]:
    out, new = [], []
    work = list(faces[::-1])
    while work:
        face = work.pop()
        k = len(face)
        on = boundary[face]
        cut = None
        if k > 3 and on.any() and not on.all():
            # runs of boundary nodes joined by boundary beams, starting after an inner node
            start = int(np.flatnonzero(~on)[0])
            runs: list[list[int]] = []
            run: list[int] = []
            for s in range(1, k + 1):
                p = (start + s) % k
                joined = run and _key(int(face[run[-1]]), int(face[p])) in beams
                if on[p] and (not run or joined):
                    run.append(p)
                else:
                    if len(run) >= 3:
                        runs.append(run)
                    run = [p] if on[p] else []
            if len(run) >= 3:
                runs.append(run)
            inner = face[~on]
            for run in runs:
                held = face[run]
                if _line_deviation(x[held]) <= straightness:
                    continue
                if _forced_plane_gap(x, held, inner, straightness) <= hold:
                    continue
                chord = x[held[[0, -1]]]
                d = (chord[1] - chord[0]) / max(float(np.linalg.norm(chord[1] - chord[0])), 1e-300)
                off = x[held[1:-1]] - chord[0]
                kink = run[1 + int(np.argmax(np.linalg.norm(off - np.outer(off @ d, d), axis=1)))]
                candidates = [q for q in range(k) if not on[q] and (q - kink) % k not in (1, k - 1)]
                if not candidates:
                    continue
                q = max(candidates, key=lambda q: min(_smallest_angle(x, part)
                                                      for part in _split_at(face, kink, q)))
                cut = (kink, q)
                break
        if cut is None:
            out.append(face)
            continue
        first, second = _split_at(face, *cut)
        new.append((int(face[cut[0]]), int(face[cut[1]])))
        work += [second, first]
    return out, new


def _boundary_loops(beams: set[tuple[int, int]]) -> list[list[int]]:
    """Closed node sequences along the boundary beams (nodes with two boundary beams)."""
    neighbours: dict[int, list[int]] = {}
    for a, b in beams:
        neighbours.setdefault(a, []).append(b)
        neighbours.setdefault(b, []).append(a)
    seen: set[tuple[int, int]] = set()
    loops = []
    for start in sorted(neighbours):
        for first in neighbours[start]:
            if _key(start, first) in seen:
                continue
            loop, previous, current = [start], start, first
            seen.add(_key(start, first))
            while current != start:
                loop.append(current)
                following = [b for b in neighbours[current] if b != previous and _key(current, b) not in seen]
                if not following:
                    break
                seen.add(_key(current, following[0]))
                previous, current = current, following[0]
            loops.append(loop)
    return loops


def _edge_pass(x: np.ndarray, faces: list[np.ndarray], boundary: np.ndarray, corners: np.ndarray,
               hold: float, straightness: float) -> tuple[list[np.ndarray], list[tuple[int, int]]]:
    beams = _boundary_beams(faces)
    owner: dict[tuple[int, int], int] = {}
    for i, cell in enumerate(faces):
        for a, b in zip(cell, np.roll(cell, -1)):
            if _key(int(a), int(b)) in beams:
                owner[_key(int(a), int(b))] = i
    to_cut: dict[int, set[tuple[int, int]]] = {}
    for loop in _boundary_loops(beams):
        m = len(loop)
        if m < 3:
            continue
        straight = np.array([not corners[loop[j]] and _line_deviation(
            x[[loop[j - 1], loop[j], loop[(j + 1) % m]]][[0, 1, 2]]) <= straightness for j in range(m)])
        if straight.all():
            continue
        shift = int(np.flatnonzero(~straight)[0])
        loop, straight = loop[shift:] + loop[:shift], np.roll(straight, -shift)
        chain: list[int] = []
        previous = None
        for j in range(m):
            beam = _key(loop[j], loop[(j + 1) % m])
            face = owner.get(beam)
            if face is None:
                chain, previous = [], None
                continue
            if face == previous:
                continue
            if straight[j] and previous is not None and chain:
                candidate = chain + [face]
                nodes = np.unique(np.concatenate([faces[i] for i in candidate]))
                held, inner = nodes[boundary[nodes]], nodes[~boundary[nodes]]
                if _forced_plane_gap(x, held, inner, straightness) <= hold:
                    chain = candidate
                else:
                    to_cut.setdefault(face, set()).add(beam)
                    chain = []
            else:
                chain = [face]
            previous = face
    return _cut_triangles(x, faces, boundary, to_cut)


def _cut_triangles(x: np.ndarray, faces: list[np.ndarray], boundary: np.ndarray,
                   to_cut: dict[int, set[tuple[int, int]]]) -> tuple[list[np.ndarray], list[tuple[int, int]]]:
    """Cut off each listed cell the triangle of each listed boundary beam (u, v) and one spoke:
    [u, v, next] (new beam u-next) or [previous, u, v] (new beam previous-v), the third node
    an inner one, of the two the cut whose parts have the larger smallest corner angle; the rest
    keeps one of u, v."""
    out, new = [], []
    for i, face in enumerate(faces):
        pieces = [face]
        for beam in sorted(to_cut.get(i, ())):
            rest = pieces.pop()
            k = len(rest)
            position = {int(v): p for p, v in enumerate(rest)}
            if k <= 3 or beam[0] not in position or beam[1] not in position:
                pieces.append(rest)
                continue
            u, v = position[beam[0]], position[beam[1]]
            if (v - u) % k != 1:
                u, v = v, u
            options = []
            if not boundary[rest[(v + 1) % k]]:
                options.append((u, (v + 1) % k))
            if not boundary[rest[(u - 1) % k]]:
                options.append(((u - 1) % k, v))
            if not options:
                pieces.append(rest)
                continue
            a, b = max(options, key=lambda o: min(_smallest_angle(x, part) for part in _split_at(rest, *o)))
            first, second = _split_at(rest, a, b)
            triangle, remainder = (first, second) if len(first) == 3 else (second, first)
            new.append((int(rest[a]), int(rest[b])))
            pieces += [triangle, remainder]
        out += pieces
    return out, new


def cut_boundary_triangles(polymesh: PolyMesh, cells: np.ndarray) -> tuple[PolyMesh, np.ndarray]:
    """Cut from each of ``cells`` (ids) that holds a boundary beam the triangle of its longest
    one (rule of :func:`_cut_triangles`): the rest of the cell keeps one node of that beam.
    Returns the grid-shell and the new beams (b,2); cells without a boundary beam stay."""
    x = np.asarray(polymesh.nodes, dtype=float)
    faces = [np.asarray(f, dtype=np.int64) for f in polymesh.faces]
    beams = _boundary_beams(faces)
    to_cut = {}
    for i in np.asarray(cells, dtype=np.int64):
        face = faces[int(i)]
        held = [_key(int(a), int(b)) for a, b in zip(face, np.roll(face, -1)) if _key(int(a), int(b)) in beams]
        if held and len(face) > 3:
            to_cut[int(i)] = {max(held, key=lambda e: float(np.linalg.norm(x[e[0]] - x[e[1]])))}
    faces, new = _cut_triangles(x, faces, polymesh.boundary, to_cut)
    if not new:
        return polymesh, np.zeros((0, 2), dtype=np.int64)
    return (PolyMesh(nodes=x, faces=tuple(faces), boundary=polymesh.boundary, supports=polymesh.supports,
                     corners=polymesh.corners), np.array(new, dtype=np.int64))


def split_boundary_cells(polymesh: PolyMesh, *, hold: float, straightness: float) -> BoundarySplits:
    """Split the boundary cells whose plane the boundary forces farther than ``hold`` (m) from
    one of their inner nodes (module docstring); boundary nodes within ``straightness`` (m) of a
    line count as on it. Node positions, flags and the other cells are kept."""
    x = np.asarray(polymesh.nodes, dtype=float)
    faces = [np.asarray(f, dtype=np.int64) for f in polymesh.faces]
    faces, corner_beams = _corner_pass(x, faces, polymesh.boundary, _boundary_beams(faces), hold, straightness)
    faces, edge_beams = _edge_pass(x, faces, polymesh.boundary, polymesh.corners, hold, straightness)
    new = np.array(corner_beams + edge_beams, dtype=np.int64).reshape(-1, 2)
    result = PolyMesh(nodes=x, faces=tuple(faces), boundary=polymesh.boundary, supports=polymesh.supports,
                      corners=polymesh.corners) if len(new) else polymesh
    return BoundarySplits(polymesh=result, new_beams=new, corner_splits=len(corner_beams), edge_splits=len(edge_beams))
