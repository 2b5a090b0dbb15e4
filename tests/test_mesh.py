"""The grid's topology: beams of polygon loops, and moved copies that keep it."""

from __future__ import annotations

import numpy as np
import pytest

from engine.mesh import PolyMesh, unique_edges, unique_rows


def _loops(seed: int) -> list[np.ndarray]:
    """Random polygon loops of 3-9 nodes over 40 nodes (any topology: only the edges count here)."""
    rng = np.random.default_rng(seed)
    return [rng.choice(40, size=rng.integers(3, 10), replace=False) for _ in range(30)]


def test_the_beams_of_polygon_loops_are_each_pair_of_consecutive_nodes_once():
    for seed in range(5):
        loops = _loops(seed)
        expected = sorted({tuple(sorted((int(f[i]), int(f[(i + 1) % len(f)])))) for f in loops for i in range(len(f))})
        edges = unique_edges(loops)
        assert edges.dtype == np.int64
        assert [tuple(e) for e in edges.tolist()] == expected
    assert unique_edges([]).shape == (0, 2)


def test_moved_nodes_keep_the_topology_and_measure_their_own_lengths():
    hexagon = np.array([[np.cos(t), np.sin(t), 0.0] for t in np.arange(6) * np.pi / 3])
    grid = PolyMesh(nodes=np.vstack([hexagon, [[0.0, 0.0, 0.0]]]), faces=([0, 1, 2, 6], [2, 3, 4, 5, 0, 6]))
    edges, valence = grid.edges, grid.valence
    assert grid.beam_lengths.min() > 0.99
    moved = grid.replace_nodes(2.0 * grid.nodes)
    assert moved.edges is edges and moved.valence is valence
    chords = moved.nodes[edges[:, 1]] - moved.nodes[edges[:, 0]]
    assert np.array_equal(moved.beam_lengths, np.linalg.norm(chords, axis=1))
    np.testing.assert_allclose(moved.beam_lengths, 2.0 * grid.beam_lengths)
    assert np.array_equal(moved.face_boundary, grid.face_boundary)
    fresh = PolyMesh(nodes=2.0 * grid.nodes, faces=grid.faces)             # as if built afresh
    for name in ("nodes", "boundary", "supports", "corners"):
        assert np.array_equal(getattr(moved, name), getattr(fresh, name))
    assert not moved.nodes.flags.writeable and moved.faces is grid.faces
    with pytest.raises(ValueError, match="nodes must be"):
        grid.replace_nodes(grid.nodes[:-1])


def test_node_adjacency_and_neighbour_lists_name_each_beams_two_ends():
    """The one node adjacency that the optimiser, the collapses and the re-optimised region share:
    symmetric, a row per node as long as its valence, each beam seen from both ends."""
    from scipy.sparse.csgraph import breadth_first_order

    from engine.mesh import neighbour_lists, node_adjacency

    for seed in range(3):
        loops = _loops(seed)
        grid = PolyMesh(nodes=np.random.default_rng(seed).normal(size=(40, 3)), faces=tuple(loops))
        adjacency = node_adjacency(grid.edges, grid.n_nodes)
        lists = neighbour_lists(grid.edges, grid.n_nodes)
        assert (adjacency != adjacency.T).nnz == 0
        assert np.array_equal(np.asarray(adjacency.sum(axis=1)).ravel(), grid.valence)
        assert [len(around) for around in lists] == grid.valence.tolist()
        beams = {tuple(e) for e in grid.edges.tolist()}
        assert {(min(a, b), max(a, b)) for a, around in enumerate(lists) for b in around} == beams
        start = int(grid.edges[0, 0])
        reached = breadth_first_order(adjacency, start, directed=False, return_predecessors=False)
        linked = {start}
        while True:
            grown = linked | {b for a in linked for b in lists[a]}
            if grown == linked:
                break
            linked = grown
        assert set(reached.tolist()) == linked


def test_vector_areas_and_node_normals_over_all_corners_at_once():
    """The cells' vector areas (1/2 sum p_i x p_i+1) and the nodes' normals summed from them,
    taken over every corner at once, against a loop over the cells; kept by replace_nodes."""
    from engine.structure.grid_model import node_normals

    rng = np.random.default_rng(1)
    nodes = rng.normal(size=(400, 3))
    faces = tuple(rng.choice(400, size=rng.integers(3, 9), replace=False) for _ in range(150))
    grid = PolyMesh(nodes=nodes, faces=faces)
    looped = np.array([0.5 * np.cross(nodes[f], np.roll(nodes[f], -1, axis=0)).sum(axis=0) for f in faces])
    assert np.allclose(grid.face_vector_areas(), looped, rtol=0, atol=1e-14)
    assert np.allclose(grid.face_areas(), np.linalg.norm(looped, axis=1), rtol=0, atol=1e-14)
    summed = np.zeros((400, 3))
    for f, a in zip(faces, looped):
        summed[f] += a
    used = np.linalg.norm(summed, axis=1) > 1e-12
    unit = summed[used] / np.linalg.norm(summed[used], axis=1)[:, None]
    assert np.allclose(node_normals(grid)[used], unit, atol=1e-12)
    assert np.allclose(node_normals(grid)[~used], [0.0, 0.0, 1.0])
    assert np.allclose(grid.replace_nodes(2 * nodes).face_vector_areas(), 4 * looped, rtol=0, atol=1e-13)


@pytest.mark.parametrize("shape, largest", [((1000, 2), 50), ((4000, 3), 30), ((2000, 3), 3_000_000), ((7, 2), 2)])
def test_unique_rows_are_numpys_row_wise_unique(shape, largest):
    """Rows keyed as one integer (or, past int64, numpy's own row-wise unique): the same rows, first
    indices, inverse and counts as np.unique(axis=0)."""
    rows = np.random.default_rng(largest).integers(0, largest, size=shape)
    ours = unique_rows(rows, return_index=True, return_inverse=True, return_counts=True)
    numpys = np.unique(rows, axis=0, return_index=True, return_inverse=True, return_counts=True)
    for mine, theirs in zip(ours, numpys):
        assert np.array_equal(np.ravel(mine), np.ravel(theirs))
    assert np.array_equal(unique_rows(rows), np.unique(rows, axis=0))
