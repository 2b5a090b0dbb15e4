"""Hard limits of the grid's geometry, applied as projections between the optimiser's steps.

A joint takes a beam only so short and two beams only so close in angle (see
``fabrication.limits``). The optimiser's energy does not know either; after each of its global
steps these projections move the nodes back inside the limits: a short beam's ends apart along
it, a narrow cell corner's two far nodes apart about its apex. Both are Jacobi sweeps vectorised
over the beams or corners; a node that may not move (a support, a corner) leaves the move to the
others. A sweep that would not lower the sum of squared deficits (coupled limits can do that:
opening one corner closes its neighbours at the same node), or for corners would narrow the
narrowest, is halved until it does not, so the projections never leave the grid worse than they
found it. Crowded limits can still push a node across its neighbours: :func:`unfolded` puts back
the nodes of every cell that a move folds. Lengths in m, angles in radians.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

#: A sweep is halved at most this many times before the projection stops.
MAX_HALVINGS = 5

__all__ = ["lengthen_short_beams", "open_narrow_corners", "face_corners", "corner_angles", "CellFans", "folded_cells",
           "unfolded"]


def face_corners(faces) -> np.ndarray:
    """(c,3) corners (previous node, node, next node) of every face of ``faces`` (a sequence of
    node loops), in face order."""
    loops = [f for f in map(np.asarray, faces) if len(f) >= 3]
    if not loops:
        return np.zeros((0, 3), dtype=np.int64)
    sides = np.array([len(f) for f in loops])
    node = np.concatenate(loops).astype(np.int64)
    start, size = np.repeat(np.cumsum(sides) - sides, sides), np.repeat(sides, sides)
    at = np.arange(len(node)) - start                   # each corner's place in its face
    return np.stack([node[start + (at - 1) % size], node, node[start + (at + 1) % size]], axis=1)


def corner_angles(x: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(c,) angle at node o of each (a, o, b) row of ``corners`` between o->a and o->b, rad."""
    return _angles(x[corners[:, 0]] - x[corners[:, 1]], x[corners[:, 2]] - x[corners[:, 1]])


def _angles(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(c,) angles between the rows of u and v (c,3), rad."""
    return np.arctan2(np.linalg.norm(np.cross(u, v), axis=1), np.einsum("ij,ij->i", u, v))


class CellFans:
    """The corners of every cell ((c,) cell, (c,3) previous node, node, next node in the cell's
    order): how each cell lies on a surface (its vector area, its turns about the surface's normal),
    vectorised over the cells."""

    def __init__(self, faces) -> None:
        loops = [np.asarray(f, dtype=np.int64) for f in faces]
        self.n_cells = len(loops)
        self.cell = np.repeat(np.arange(self.n_cells), [len(f) for f in loops])
        self.corners = face_corners(loops)
        self.sides = np.bincount(self.cell, minlength=self.n_cells)

    def normals(self, x: np.ndarray) -> np.ndarray:
        """(cells, 3) Newell normals (twice the vector area, m2) of the cells at x."""
        out = np.zeros((self.n_cells, 3))
        np.add.at(out, self.cell, np.cross(x[self.corners[:, 1]], x[self.corners[:, 2]]))
        return out

    def centroids(self, x: np.ndarray) -> np.ndarray:
        """(cells, 3) the mean of each cell's nodes at x."""
        centre = np.zeros((self.n_cells, 3))
        np.add.at(centre, self.cell, x[self.corners[:, 1]])
        return centre / np.maximum(self.sides, 1)[:, None]

    def windings(self, x: np.ndarray, up: np.ndarray) -> np.ndarray:
        """(cells,) how many times each cell's loop at x turns about its ``up`` ((cells, 3) unit),
        seen from above: 1 for a simple cell facing up (convex or not), -1 for one turned over, 0
        for a bow-tie."""
        normal = up[self.cell]
        a, o, b = (x[self.corners[:, k]] for k in range(3))
        into, out = o - a, b - o
        into = into - np.einsum("ij,ij->i", into, normal)[:, None] * normal
        out = out - np.einsum("ij,ij->i", out, normal)[:, None] * normal
        turn = np.arctan2(np.einsum("ij,ij->i", np.cross(into, out), normal), np.einsum("ij,ij->i", into, out))
        return np.rint(np.bincount(self.cell, weights=turn, minlength=self.n_cells) / (2 * np.pi)).astype(int)


def _grid_side(x: np.ndarray, fans: CellFans, up: np.ndarray) -> np.ndarray:
    """``up`` ((cells, 3)) as unit vectors turned to the side of the surface that most cells face at x."""
    up = up / np.maximum(np.linalg.norm(up, axis=1), 1e-300)[:, None]
    facing = np.einsum("ij,ij->i", up, fans.normals(x))
    return -up if np.count_nonzero(facing < 0) > np.count_nonzero(facing > 0) else up


def folded_cells(x: np.ndarray, fans: CellFans, up: np.ndarray) -> np.ndarray:
    """Ids of the cells that, seen along ``up`` ((cells, 3), e.g. the surface's normal at each
    cell; the grid's side is the one most cells face), cross themselves or are turned over at x:
    where two cells overlap on the surface."""
    if not fans.n_cells:
        return np.zeros(0, dtype=np.int64)
    up = _grid_side(x, fans, up)
    return np.flatnonzero((fans.windings(x, up) != 1) | (np.einsum("ij,ij->i", fans.normals(x), up) <= 0))


def unfolded(before: np.ndarray, after: np.ndarray, fans: CellFans, up: np.ndarray) -> np.ndarray:
    """``after`` with the nodes of every cell that the move from ``before`` folds put back where they
    were, repeated until the move folds no cell. Seen along ``up`` ((cells, 3), e.g. the surface's
    normal at each cell, oriented consistently; the grid's side is the one most cells face), a cell
    is folded where its loop no longer turns once (it crosses itself, or it is turned over), or
    where its vector area turns against ``up``. A cell folded already before the move (such as a
    jittered cell, or one turned over across the boundary) is free to unfold."""
    if not fans.n_cells:
        return after
    up = _grid_side(before, fans, up)
    was_simple = fans.windings(before, up) == 1
    was_facing = np.einsum("ij,ij->i", fans.normals(before), up) > 0
    x = np.array(after, dtype=float)
    for _ in range(fans.n_cells + 1):  # each round puts back at least one node
        folded = np.flatnonzero((was_simple & (fans.windings(x, up) != 1))
                                | (was_facing & (np.einsum("ij,ij->i", fans.normals(x), up) <= 0)))
        if not len(folded):
            break
        nodes = np.unique(fans.corners[np.isin(fans.cell, folded), 1])
        nodes = nodes[np.any(x[nodes] != before[nodes], axis=1)]
        if not len(nodes):
            break
        x[nodes] = before[nodes]
    return x


def _guarded(x: np.ndarray, sweeps: int, deficits: Callable[[np.ndarray], np.ndarray],
             move: Callable[[np.ndarray], np.ndarray], keep_largest: bool) -> np.ndarray:
    """Jacobi sweeps x + relax * move(x), each kept only if it lowers the sum of squared deficits
    (and, with ``keep_largest``, does not raise the largest); a sweep that does not is retried at
    half the step (MAX_HALVINGS times at most, then the sweeps stop)."""
    d = deficits(x)
    total, largest = float(np.sum(d**2)), float(d.max(initial=0.0))
    relax = 1.0
    for _ in range(sweeps):
        if largest <= 0:
            break
        step = move(x)
        for _ in range(MAX_HALVINGS + 1):
            trial = x + relax * step
            d = deficits(trial)
            if float(np.sum(d**2)) < total and (not keep_largest or float(d.max(initial=0.0)) <= largest * (1 + 1e-9)):
                x, total, largest = trial, float(np.sum(d**2)), float(d.max(initial=0.0))
                break
            relax *= 0.5
        else:
            break
    return x


def lengthen_short_beams(x: np.ndarray, beams: np.ndarray, minimum: float | np.ndarray, movable: np.ndarray,
                         sweeps: int = 3) -> np.ndarray:
    """(n,3) nodes with every beam shorter than its ``minimum`` (m; one for all, or one per beam)
    pushed back to it: both ends move apart along the beam by half the deficit (a fixed end,
    ``movable`` False, leaves it all to the other). A beam with both ends fixed is left."""
    x = np.array(x, dtype=float)
    minimum = np.broadcast_to(np.asarray(minimum, dtype=float), (len(beams),))
    if not len(beams) or not (minimum > 0).any():
        return x
    a, b = beams[:, 0], beams[:, 1]
    free = movable[a] | movable[b]

    def measure(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        d = x[b] - x[a]
        length = np.linalg.norm(d, axis=1)
        return d, length, np.where(free & (length > 0), np.maximum(minimum - length, 0.0), 0.0)

    def move(x: np.ndarray) -> np.ndarray:
        d, length, deficit = measure(x)
        short = deficit > 0
        unit = d[short] / length[short, None]
        share_a = np.where(movable[a[short]], np.where(movable[b[short]], 0.5, 1.0), 0.0)[:, None]
        out = np.zeros_like(x)
        count = np.zeros(len(x))
        np.add.at(out, a[short], -share_a * deficit[short, None] * unit)
        np.add.at(out, b[short], (1 - share_a) * deficit[short, None] * unit)
        np.add.at(count, a[short], share_a[:, 0] > 0)
        np.add.at(count, b[short], share_a[:, 0] < 1)
        return out / np.maximum(count, 1.0)[:, None]

    return _guarded(x, sweeps, lambda x: measure(x)[2], move, keep_largest=False)


def open_narrow_corners(x: np.ndarray, corners: np.ndarray, minimum: float, movable: np.ndarray,
                        sweeps: int = 3) -> np.ndarray:
    """(n,3) nodes with every corner (a, o, b) narrower than ``minimum`` (rad) opened to it: a and
    b turn apart about o in the corner's plane, each by half the deficit, at their distance from o
    (a fixed node leaves its half to the other; a corner with both far nodes fixed is left)."""
    x = np.array(x, dtype=float)
    if minimum <= 0 or not len(corners):
        return x
    a, o, b = corners.T
    free = movable[a] | movable[b]

    def measure(x: np.ndarray):
        u, v = x[a] - x[o], x[b] - x[o]
        lu, lv = np.linalg.norm(u, axis=1), np.linalg.norm(v, axis=1)
        angle = _angles(u, v)
        return u, v, lu, lv, np.where(free & (lu > 0) & (lv > 0), np.maximum(minimum - angle, 0.0), 0.0)

    def move(x: np.ndarray) -> np.ndarray:
        u, v, lu, lv, deficit = measure(x)
        narrow = deficit > 0
        u, v, lu, lv, deficit = u[narrow], v[narrow], lu[narrow, None], lv[narrow, None], deficit[narrow]
        eu, ev = u / lu, v / lv
        # in the corner's plane, the unit direction away from the other beam, normal to each beam
        cosine = np.einsum("ij,ij->i", eu, ev)[:, None]
        away_u, away_v = eu * cosine - ev, ev * cosine - eu
        away_u /= np.maximum(np.linalg.norm(away_u, axis=1), 1e-300)[:, None]
        away_v /= np.maximum(np.linalg.norm(away_v, axis=1), 1e-300)[:, None]
        ma, mb = movable[a[narrow]], movable[b[narrow]]
        turn_a = np.where(ma, np.where(mb, 0.5, 1.0), 0.0) * deficit
        turn_b = deficit - turn_a
        new_u = lu * (np.cos(turn_a)[:, None] * eu + np.sin(turn_a)[:, None] * away_u)
        new_v = lv * (np.cos(turn_b)[:, None] * ev + np.sin(turn_b)[:, None] * away_v)
        out = np.zeros_like(x)
        count = np.zeros(len(x))
        np.add.at(out, a[narrow], new_u - u)
        np.add.at(out, b[narrow], new_v - v)
        np.add.at(count, a[narrow], turn_a > 0)
        np.add.at(count, b[narrow], turn_b > 0)
        return out / np.maximum(count, 1.0)[:, None]

    return _guarded(x, sweeps, lambda x: measure(x)[4], move, keep_largest=True)
