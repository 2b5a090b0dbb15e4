"""Planar convex panels of cells that are not (engine.remeshing.panel_pieces): closed forms on a saddle, a
flat cell kept whole, pieces that tile the cell exactly."""

from __future__ import annotations

import numpy as np
import pytest

from engine.mesh import PolyMesh
from engine.remeshing.panel_pieces import panel_pieces, piece_flatness, planar_pieces


def _hexagon(z):
    a = np.radians(np.arange(6) * 60.0)
    x, y = np.cos(a), np.sin(a)
    return np.c_[x, y, z(x, y)]


def _area(points):
    return 0.5 * np.linalg.norm(np.cross(points, np.roll(points, -1, axis=0)).sum(axis=0))


def test_a_flat_convex_cell_is_one_panel():
    nodes = _hexagon(lambda x, y: 0.2 * x + 0.1 * y)  # planar, tilted
    assert [p.tolist() for p in planar_pieces(nodes, np.arange(6), 1e-9)] == [list(range(6))]


def test_a_saddle_hexagon_splits_into_planar_convex_pieces_that_tile_it():
    nodes = _hexagon(lambda x, y: x**2 - y**2)
    distance, convex = piece_flatness(nodes)
    assert distance > 0.5  # far from planar
    pieces = planar_pieces(nodes, np.arange(6), 1e-6)
    assert 2 <= len(pieces) <= 4
    for piece in pieces:
        d, c = piece_flatness(nodes[piece])
        assert d <= 1e-6 and c
    # every cell edge is an edge of exactly one piece, every diagonal of exactly two (a tiling)
    edges = {}
    for piece in pieces:
        for a, b in zip(piece, np.roll(piece, -1)):
            key = tuple(sorted((int(a), int(b))))
            edges[key] = edges.get(key, 0) + 1
    cell_edges = {tuple(sorted((i, (i + 1) % 6))) for i in range(6)}
    assert all(edges[e] == 1 for e in cell_edges)
    assert all(n == 2 for e, n in edges.items() if e not in cell_edges)
    # in plan the pieces cover the hexagon: plan areas add up to 3 sqrt(3) / 2
    plan = nodes.copy()
    plan[:, 2] = 0
    assert sum(_area(plan[p]) for p in pieces) == pytest.approx(3 * np.sqrt(3) / 2)


def test_a_non_convex_cell_is_split_inside_itself():
    # an arrow-head: reflex corner at node 3; the split must not use a diagonal outside the cell
    nodes = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [1, 0.8, 0], [0, 2, 0]], dtype=float)
    pieces = planar_pieces(nodes, np.arange(5), 1e-6)
    assert all(piece_flatness(nodes[p])[1] for p in pieces)
    assert sum(_area(nodes[p]) for p in pieces) == pytest.approx(_area(nodes))


def test_panel_pieces_name_their_cells():
    flat, saddle = _hexagon(lambda x, y: 0 * x), _hexagon(lambda x, y: x**2 - y**2) + [3.0, 0.0, 0.0]
    grid = PolyMesh(nodes=np.r_[flat, saddle], faces=(np.arange(6), np.arange(6, 12)))
    pieces = panel_pieces(grid, 1e-6)
    assert [(p.cell, p.piece) for p in pieces][0] == (0, 0)
    assert {p.cell for p in pieces[1:]} == {1} and [p.piece for p in pieces[1:]] == list(range(1, len(pieces)))


def test_no_sliver_is_cut_off_where_another_diagonal_will_do():
    """A pentagon with one node nearly on the line of its neighbours (as at a straight run of a
    boundary), raised off the plane of the other four: the flattest split alone cut off the nearly
    aligned triangle (leaving a planar quad), a panel of no area that the cutting clearance removes
    (the courtyard template at 1500 cells asked); the split now leaves none."""
    nodes = np.array([[0.0, 0.0, 0.0], [1.0, -0.01, 0.05], [2.0, 0.0, 0.0], [2.0, 1.5, 0.0], [0.0, 1.5, 0.0]])
    pieces = planar_pieces(nodes, np.arange(5), 1e-6)
    assert all(piece_flatness(nodes[p])[0] <= 1e-6 and piece_flatness(nodes[p])[1] for p in pieces)
    for p in pieces:
        if len(p) == 3:
            q = nodes[p]
            sides = np.linalg.norm(q - np.roll(q, -1, axis=0), axis=1)
            height = 2 * _area(q) / sides.max()
            assert height > 0.05 * sides.max(), p
    plan = nodes.copy()
    plan[:, 2] = 0
    assert sum(_area(plan[p]) for p in pieces) == pytest.approx(_area(plan))


def test_the_batched_flatness_is_each_loops_own():
    """The flatness of many loops at once (one SVD per loop length) against piece_flatness of each,
    and whether a triangle is a sliver against its height over its longest side (Heron's area):
    triangles, planar convex and non-convex loops, warped ones, and planes facing every way."""
    from engine.remeshing.panel_pieces import SLIVER, _flatness_of_loops

    def sliver(points: np.ndarray) -> bool:
        if len(points) != 3:
            return False
        a, b, c = np.linalg.norm(points - np.roll(points, -1, axis=0), axis=1)
        half = 0.5 * (a + b + c)
        area = np.sqrt(max(half * (half - a) * (half - b) * (half - c), 0.0))
        return bool(2 * area / max(a, b, c) < SLIVER * max(a, b, c))

    rng = np.random.default_rng(4)
    nodes = rng.normal(size=(60, 3))
    angles = np.linspace(0, 2 * np.pi, 7)[:-1]
    for k, normal in enumerate(np.eye(3)):               # planar hexagons in the three planes
        u = np.roll(normal, 1)
        v = np.cross(normal, u)
        nodes[6 * k:6 * k + 6] = np.outer(np.cos(angles), u) + np.outer(np.sin(angles), v)
    nodes[18:24] = nodes[0:6]
    nodes[19] *= 0.2                                     # non-convex, planar
    loops = [np.arange(6 * k, 6 * k + 6) for k in range(4)] + [rng.permutation(59)[:n] for n in (3, 4, 5, 6, 7) * 8]
    nodes[59] = 0.5 * (nodes[57] + nodes[58]) + 1e-3      # a sliver
    loops.append(np.array([57, 58, 59]))
    batched = _flatness_of_loops(nodes, loops)
    for loop, (distance, convex, thin) in zip(loops, batched):
        expected = piece_flatness(nodes[loop])
        assert distance == pytest.approx(expected[0], rel=1e-12, abs=1e-15) and convex == expected[1]
        assert thin == sliver(nodes[loop])
    assert [c for _, c, _ in batched[:4]] == [True, True, True, False] and batched[-1][2]
