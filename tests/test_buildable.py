"""Fabrication limits as constraints of the geometry: the shortest buildable beam, the smallest
angle at a joint, short beams collapsed with the cells kept valid, and findings in place of failures."""

from __future__ import annotations

import json

import numpy as np
import pytest

from engine.findings import Finding, findings_table
from engine.mesh import PolyMesh
from engine.remeshing.collapse import (
    MAX_VALENCE,
    collapse_beams,
    collapse_short_beams,
    dissolve_kinks,
    flip_beams,
    open_narrow_joints,
    remove_beams,
    remove_short_beams,
)
from fabrication.joints import JointSettings, build_joint, joint_setback_mm
from fabrication.limits import BuildLimits, node_smallest_angles, required_beam_lengths_m


def _honeycomb(rows: int = 6, cols: int = 6, side: float = 1.0, squeeze: dict | None = None) -> PolyMesh:
    """A patch of regular hexagons (side ``side``, pointy-top) with shared nodes; ``squeeze``
    maps (row, col) of a cell to the factor its first edge is shortened by (moving both ends)."""
    points: dict[tuple, int] = {}
    nodes, faces = [], []
    w = np.sqrt(3) * side
    for r in range(rows):
        for c in range(cols):
            cx, cy = c * w + (r % 2) * w / 2, r * 1.5 * side
            loop = []
            for k in range(6):
                a = np.radians(90 + 60 * k)
                p = (round(cx + side * np.cos(a), 6), round(cy + side * np.sin(a), 6))
                if p not in points:
                    points[p] = len(nodes)
                    nodes.append([p[0], p[1], 0.0])
                loop.append(points[p])
            faces.append(loop)
    nodes = np.array(nodes)
    grid = PolyMesh(nodes=nodes, faces=tuple(np.array(f) for f in faces))
    boundary = np.zeros(len(nodes), dtype=bool)
    key = np.sort(np.concatenate([np.stack([f, np.roll(f, -1)], 1) for f in grid.faces]), axis=1)
    edges, counts = np.unique(key, axis=0, return_counts=True)
    boundary[edges[counts == 1].ravel()] = True
    return PolyMesh(nodes=nodes, faces=grid.faces, boundary=boundary)


def _check_valid(grid: PolyMesh) -> None:
    for face in grid.faces:
        assert len(face) >= 3 and len(set(face.tolist())) == len(face)
    directed = np.concatenate([np.stack([f, np.roll(f, -1)], axis=1) for f in grid.faces])
    assert len({tuple(d) for d in directed.tolist()}) == len(directed), "consistently oriented, manifold"
    assert np.all(np.bincount(np.concatenate(grid.faces), minlength=grid.n_nodes) > 0), "no orphan node"


def test_setback_grows_as_the_angle_closes_and_limits_add_up():
    s = JointSettings()
    wide, narrow = joint_setback_mm(s, 12.0, np.radians(120)), joint_setback_mm(s, 12.0, np.radians(30))
    # two bores of radius 6.3 mm at 30 degrees keep the least wall 1.5 mm: (2 x 6.3 + 1.5) / (2 sin 15 deg)
    assert narrow == pytest.approx((2 * 6.3 + 1.5) / (2 * np.sin(np.radians(15))))
    assert narrow > wide
    limits = BuildLimits.of(s, 12.0)
    assert limits.min_cut_length_mm >= 12.0  # at least one tube diameter
    assert limits.min_cut_length_mm == pytest.approx(2 * 24.0 + 6.0)  # two 24 mm sleeves + half a diameter
    assert limits.shortest_beam_mm() == pytest.approx(2 * wide + limits.min_cut_length_mm)
    steel = BuildLimits.of(JointSettings(kind="steel"), 114.3, min_cut_length_mm=400.0)
    # fin plates 10 mm thick meet at the face of the 0.75 D hub at 2 asin(t / 2r); the joint takes 5 degrees more
    assert steel.min_cut_length_mm == 400.0
    assert steel.min_angle_deg == round(2 * np.degrees(np.arcsin(10.0 / (2 * 0.75 * 114.3))) + 5.0)
    # steel tubes of radius 57.15 mm at 30 degrees stay 5 mm apart at their ends
    assert steel.setback_mm(np.radians(30)) == pytest.approx((57.15 + 2.5) / np.sin(np.radians(15)))


def test_socket_min_angle_is_where_its_sleeves_start_to_overlap():
    """Below the angle, two sleeves of radius R overlap farther than the set-back plus half a
    sleeve from the node (the joint's own sleeve-clash check); above it they do not."""
    from fabrication.joints import _clashes

    s = JointSettings()
    limits = BuildLimits.of(s, 12.0)
    outer, sleeve = 6.0 + 0.3 + 2.0, 24.0

    def overlap(angle_deg):
        a = np.radians(angle_deg)
        d = np.array([[1.0, 0.0, 0.0], [np.cos(a), np.sin(a), 0.0]])
        return bool(_clashes(d, outer, joint_setback_mm(s, 12.0, a), sleeve))

    assert not overlap(limits.min_angle_deg) and not overlap(limits.min_angle_deg - 4.5)
    assert overlap(limits.min_angle_deg - 6.0)


def test_smallest_angles_of_a_honeycomb_are_120_degrees_inside():
    grid = _honeycomb()
    angles = np.degrees(node_smallest_angles(grid))
    inner = grid.valence == 3
    assert np.allclose(angles[inner], 120.0)
    assert np.allclose(angles[grid.valence == 2], 120.0)  # boundary nodes with two beams


def test_collapse_keeps_a_valid_mesh_and_merges_to_the_midpoint():
    grid = _honeycomb()
    lengths = grid.beam_lengths
    interior = np.flatnonzero(~grid.boundary[grid.edges].any(axis=1))
    beam = int(interior[0])
    a, b = grid.edges[beam]
    midpoint = 0.5 * (grid.nodes[a] + grid.nodes[b])
    result, done = collapse_beams(grid, np.array([beam]))
    assert done == 1
    _check_valid(result)
    assert result.n_nodes == grid.n_nodes - 1
    assert len(result.edges) == len(grid.edges) - 1  # the beam is gone, the others kept
    assert result.n_faces == grid.n_faces
    assert np.min(np.linalg.norm(result.nodes - midpoint, axis=1)) < 1e-12
    # two cells lose a side (hexagons -> pentagons), the beam's end nodes merge into valence 4
    assert np.sort(result.face_degrees)[:2].tolist() == [5, 5]
    assert result.valence.max() == 4
    # the beam's length is gone and its four neighbours now start at the midpoint
    others = [(int(u), int(v)) for u, v in grid.edges if (u in (a, b)) != (v in (a, b))]
    old = sum(np.linalg.norm(grid.nodes[u] - grid.nodes[v]) for u, v in others)
    new = sum(np.linalg.norm(midpoint - grid.nodes[v if u in (a, b) else u]) for u, v in others)
    assert len(others) == 4
    assert np.isclose(result.total_length, grid.total_length - lengths[beam] - old + new)


def _shortened_honeycomb() -> PolyMesh:
    """An 8 x 8 honeycomb with a dozen interior beams shortened to a tenth (one end moved towards
    the other)."""
    grid = _honeycomb(8, 8)
    rng = np.random.default_rng(3)
    x = grid.nodes.copy()
    interior = np.flatnonzero(~grid.boundary[grid.edges].any(axis=1))
    moved = set()
    for beam in rng.choice(interior, 12, replace=False):
        a, b = grid.edges[beam]
        if a in moved or b in moved:
            continue
        x[b] = x[a] + 0.1 * (x[b] - x[a])
        moved.update((a, b))
    return grid.replace_nodes(x)


def test_short_beams_collapse_until_none_is_shorter_than_required():
    grid = _shortened_honeycomb()
    required = lambda g: np.full(len(g.edges), 0.5)  # noqa: E731
    result, report = collapse_short_beams(grid, required)
    _check_valid(result)
    assert report.flipped >= 1 and len(report.left) == 0
    assert result.beam_lengths.min() >= 0.5
    assert result.valence.max() <= MAX_VALENCE
    # without flips every short beam is collapsed
    collapsed, report = collapse_short_beams(grid, required, flip=False)
    _check_valid(collapsed)
    assert report.collapsed >= 1 and report.flipped == 0 and len(report.left) == 0
    assert collapsed.n_nodes < result.n_nodes <= grid.n_nodes


def _euler(grid: PolyMesh) -> int:
    return grid.n_nodes - len(grid.edges) + grid.n_faces


def _area(grid: PolyMesh) -> float:
    """Sum of the cells' plan areas (shoelace), m2: the same whatever beams inside are removed."""
    return sum(0.5 * abs(np.dot(grid.nodes[f, 0], np.roll(grid.nodes[f, 1], -1))
                         - np.dot(grid.nodes[f, 1], np.roll(grid.nodes[f, 0], -1))) for f in grid.faces)


def test_removing_a_beam_merges_its_two_cells_and_moves_no_node():
    grid = _honeycomb()
    interior = np.flatnonzero(~grid.boundary[grid.edges].any(axis=1))
    beam = int(interior[5])
    a, b = grid.edges[beam]
    result, done = remove_beams(grid, np.array([beam]))
    assert done == 1
    _check_valid(result)
    assert np.array_equal(result.nodes, grid.nodes)
    assert len(result.edges) == len(grid.edges) - 1 and result.n_faces == grid.n_faces - 1
    assert _euler(result) == _euler(grid)  # the surface's topology is the same
    assert np.isclose(_area(result), _area(grid))
    assert np.isclose(result.total_length, grid.total_length - grid.beam_lengths[beam])
    assert sorted(result.face_degrees.tolist())[-1] == 10  # two hexagons sharing a beam: a decagon
    assert result.valence[a] == result.valence[b] == 2
    # its two straight-through nodes then go: the decagon is an octagon, two beams fewer again
    straight, dropped = dissolve_kinks(result)
    assert dropped == 2
    _check_valid(straight)
    assert straight.n_nodes == grid.n_nodes - 2 and len(straight.edges) == len(grid.edges) - 3
    assert _euler(straight) == _euler(grid) and np.isclose(_area(straight), _area(grid))
    assert straight.valence.min() >= 2 and np.all(straight.valence[~straight.boundary] == 3)



def test_a_spike_goes_with_its_triangle():
    """A two-beam node at the tip of a thin triangle standing on a beam (its beams meet at 19 deg, no
    joint takes that; its neighbours are joined, so it cannot be straightened) goes with its two
    beams and the triangle; the cell around it closes over the beam; area and topology are kept."""
    p, q, v, a, b, c, d, e, f = range(9)
    nodes = np.array([[0, 0, 0], [1, 0, 0], [0.5, 3, 0], [2, 0, 0], [2, 4, 0], [-1, 4, 0], [-1, 0, 0],
                      [2, -1, 0], [-1, -1, 0]], dtype=float)
    faces = (np.array([p, q, v]), np.array([q, a, b, c, d, p, v]), np.array([d, f, e, a, q, p]))
    boundary = np.zeros(9, dtype=bool)
    boundary[[a, b, c, d, e, f]] = True
    grid = PolyMesh(nodes=nodes, faces=faces, boundary=boundary)
    _check_valid(grid)
    result, dropped = dissolve_kinks(grid)
    assert dropped == 1
    _check_valid(result)
    assert result.n_nodes == 8 and len(result.edges) == len(grid.edges) - 2 and result.n_faces == 2
    assert not any(np.allclose(x, nodes[v]) for x in result.nodes)
    assert _euler(result) == _euler(grid) and np.isclose(_area(result), _area(grid))
    # p and q are then straight-through two-beam nodes: the next passes drop them (one per pass: neighbours)
    straight, first = dissolve_kinks(result)
    straight, second = dissolve_kinks(straight)
    assert first + second == 2 and straight.n_nodes == 6 and straight.n_faces == 2
    assert _euler(straight) == _euler(grid) and np.isclose(_area(straight), _area(grid))


def test_boundary_beams_and_beams_at_two_beam_nodes_are_not_removed():
    grid = _honeycomb(3, 3)
    sides = np.sort(np.concatenate([np.stack([f, np.roll(f, -1)], 1) for f in grid.faces]), axis=1)
    pairs, uses = np.unique(sides, axis=0, return_counts=True)
    index = {tuple(e): k for k, e in enumerate(np.sort(grid.edges, axis=1).tolist())}
    one_cell = np.array([index[tuple(e)] for e in pairs[uses == 1].tolist()])
    result, done = remove_beams(grid, one_cell)
    assert done == 0 and result is grid
    at_two = np.flatnonzero((grid.valence[grid.edges] == 2).any(axis=1))
    assert len(at_two) and remove_beams(grid, at_two)[1] == 0


def test_short_beams_that_cannot_collapse_are_removed_until_none_is_short():
    grid = _honeycomb(6, 6)
    required = lambda g: np.full(len(g.edges), 0.9 * 1.0)  # noqa: E731
    x = grid.nodes.copy()
    interior = np.flatnonzero(~grid.boundary[grid.edges].any(axis=1))
    shortened = []
    for beam in interior[::7]:
        a, b = grid.edges[beam]
        if any(v in np.asarray(shortened).ravel() for v in (a, b)):
            continue
        x[b] = x[a] + 0.5 * (x[b] - x[a])
        shortened.append((a, b))
    grid = grid.replace_nodes(x)
    short_before = int(np.sum(grid.beam_lengths < 0.9))
    assert short_before >= 3
    result, removed, left = remove_short_beams(grid, required)
    _check_valid(result)
    assert len(left) == 0 and result.beam_lengths.min() >= 0.9
    assert removed <= short_before + 6  # the short beams, and only beams next to them
    assert _euler(result) == _euler(grid)


def test_a_narrow_joint_opens_by_removing_one_of_its_two_beams():
    grid = _honeycomb(5, 5)
    x = grid.nodes.copy()
    # pull one interior node's neighbour round until two of its beams meet at 12 degrees
    node = int(np.flatnonzero((grid.valence == 3) & ~grid.boundary)[len(grid.nodes) // 3])
    ends = [int(b if a == node else a) for a, b in grid.edges if node in (a, b)]
    d0 = x[ends[0]] - x[node]
    turn = np.radians(12.0)
    rotation = np.array([[np.cos(turn), -np.sin(turn), 0], [np.sin(turn), np.cos(turn), 0], [0, 0, 1]])
    x[ends[1]] = x[node] + rotation @ d0
    grid = grid.replace_nodes(x)
    assert np.degrees(node_smallest_angles(grid)[node]) < 12.5
    result, removed, left = open_narrow_joints(grid, np.radians(21.0))
    assert removed >= 1
    _check_valid(result)
    assert _euler(result) == _euler(grid)
    assert np.degrees(node_smallest_angles(result)[node]) > 21.0 or result.valence[node] == 2


def test_a_flip_keeps_three_beams_at_every_node_and_turns_the_beam_across():
    """T1 on an interior beam of a regular honeycomb: the same nodes and beam count, Euler's
    characteristic kept, the two cells of the beam lose a side and the two at its ends gain one,
    the beam keeps its midpoint, turns 90 degrees and takes the given length."""
    grid = _honeycomb()
    interior = np.flatnonzero(~grid.boundary[grid.edges].any(axis=1))
    beam = int(interior[len(interior) // 2])
    a, b = grid.edges[beam]
    midpoint = 0.5 * (grid.nodes[a] + grid.nodes[b])
    axis = grid.nodes[b] - grid.nodes[a]
    result, done, new = flip_beams(grid, np.array([beam]), np.full(len(grid.edges), 1.3))
    assert done == 1
    _check_valid(result)
    assert result.n_nodes == grid.n_nodes and len(result.edges) == len(grid.edges)
    assert result.n_faces == grid.n_faces
    assert np.all(result.valence == grid.valence)
    change = np.sort(result.face_degrees - grid.face_degrees)
    assert change.tolist() == [-1, -1] + [0] * (grid.n_faces - 4) + [1, 1]
    p, q = result.edges[new[0]]
    assert {int(p), int(q)} == {int(a), int(b)}
    turned = result.nodes[q] - result.nodes[p]
    assert np.linalg.norm(turned) == pytest.approx(1.3)
    assert np.allclose(0.5 * (result.nodes[p] + result.nodes[q]), midpoint)
    assert abs(turned @ axis) < 1e-9
    # a beam on the boundary is not flipped; the flipped beam flips back to the honeycomb's cells
    edge = int(np.flatnonzero(grid.boundary[grid.edges].all(axis=1))[0])
    assert flip_beams(grid, np.array([edge]), np.full(len(grid.edges), 1.3))[1] == 0
    back, done, _ = flip_beams(result, np.array([new[0]]), np.full(len(grid.edges), 1.0))
    assert done == 1

    def segments(g: PolyMesh) -> list:  # the beams as sorted pairs of rounded end points (ids aside)
        ends = np.round(g.nodes[g.edges], 5).tolist()
        return sorted(tuple(sorted(map(tuple, pair))) for pair in ends)

    assert segments(back) == segments(grid), "two flips, at the side's length, give the honeycomb"


def test_corners_stay_put_and_two_corners_never_merge():
    grid = _honeycomb(3, 3)
    corners = np.zeros(grid.n_nodes, dtype=bool)
    corners[grid.edges[0]] = True  # both ends of beam 0 are corners
    boundary_beam = grid.edges[0]
    pinned = PolyMesh(nodes=grid.nodes, faces=grid.faces, boundary=grid.boundary, corners=corners)
    result, done = collapse_beams(pinned, np.array([0]))
    assert done == 0 and result is pinned
    # one corner: the merged node is at the corner
    one = corners.copy()
    one[boundary_beam[1]] = False
    pinned = PolyMesh(nodes=grid.nodes, faces=grid.faces, boundary=grid.boundary, corners=one)
    result, done = collapse_beams(pinned, np.array([0]))
    corner_at = grid.nodes[boundary_beam[0]]
    assert done == 1 and np.allclose(result.nodes[result.corners], corner_at)


def test_as_the_last_resort_a_bare_corner_merges_into_the_next_corner():
    """Two corners of the outline 0.1 m apart (gen44-hole-v at 60 cells had two 145 mm apart under
    steel joints that take 222 mm, and their joints clashed): with ``merge_corners`` the corner that
    holds only its two boundary beams goes into the other, which stays where it was; two corners
    that both hold an inner beam still never merge. Counted with V - E + F, the plate stays a disc."""
    nodes = np.array([[0.0, 0, 0], [0.1, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0], [1, 1, 0]])
    faces = (np.array([0, 1, 5, 4]), np.array([1, 2, 3, 5]))
    corners = np.array([True, True, True, True, True, False])
    grid = PolyMesh(nodes=nodes, faces=faces, boundary=np.ones(6, bool), corners=corners)
    short = np.flatnonzero(grid.beam_lengths < 0.5)
    assert len(short) == 1 and set(grid.edges[short[0]]) == {0, 1}
    assert collapse_beams(grid, short)[1] == 0, "corners never merge by default"
    merged, done = collapse_beams(grid, short, merge_corners=True)
    assert done == 1 and merged.n_nodes == 5
    assert np.allclose(merged.nodes[merged.corners], nodes[[1, 2, 3, 4]])   # node 0 gone, node 1 in place
    assert merged.beam_lengths.min() >= 0.9
    assert merged.n_nodes - len(merged.edges) + merged.n_faces == 1
    # a strip of three cells whose bottom beam 1-2 is short between two corners of three beams each
    strip = np.array([[0.0, 0, 0], [1, 0, 0], [1.1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [1.1, 1, 0], [2, 1, 0]])
    both = PolyMesh(nodes=strip, faces=(np.array([0, 1, 5, 4]), np.array([1, 2, 6, 5]), np.array([2, 3, 7, 6])),
                    boundary=np.ones(8, bool), corners=np.ones(8, bool))
    pair = np.flatnonzero([set(e) == {1, 2} for e in both.edges])
    assert collapse_beams(both, pair, merge_corners=True)[1] == 0


def test_the_mockups_required_lengths_follow_its_joints():
    """Beams between 120-degree joints need 2 set-backs + the cut; at a narrow node more."""
    grid = _honeycomb(4, 4, side=0.05)  # 50 mm beams: shorter than sockets of 12 mm tubes take
    limits = BuildLimits.of(JointSettings(), 12.0)
    required = required_beam_lengths_m(grid, limits)
    assert np.allclose(required[~grid.boundary[grid.edges].any(axis=1)], limits.shortest_beam_mm() / 1000)
    assert np.all(grid.beam_lengths < required)


def test_two_joints_closer_than_the_shortest_beam_clash_and_farther_do_not():
    """The shortest buildable beam is what keeps two socket joints' solids apart (checked on the solids)."""
    from build123d import Location

    from fabrication.clearance import joint_clashes

    settings = JointSettings(engrave=False)
    limits = BuildLimits.of(settings, 12.0)
    axis = np.array([0.0, 0.0, 1.0])

    def joint(node, position, towards):
        d = [towards] + [np.array([np.cos(a), np.sin(a), 0.0]) for a in
                         (np.arctan2(towards[1], towards[0]) + np.radians([120, -120]))]
        from fabrication.joints import JointGeometry

        g = JointGeometry(node=node, position_mm=position, directions=np.array(d), axis=axis, beam_size_mm=12.0)
        solid, _ = build_joint(g, settings)
        return solid.moved(Location(tuple(map(float, position))))

    def clashes(length_mm):
        a = joint(0, np.zeros(3), np.array([1.0, 0.0, 0.0]))
        b = joint(1, np.array([length_mm, 0.0, 0.0]), np.array([-1.0, 0.0, 0.0]))
        return joint_clashes({"J0001": a, "J0002": b})

    shortest = limits.shortest_beam_mm()
    assert clashes(shortest) == []
    # the two 24 mm sleeves reach 10 mm into each other
    reach = limits.setback_mm(np.radians(120)) + 24.0
    assert clashes(2 * reach - 10.0)


def test_findings_are_grouped_by_kind_with_the_worst_first():
    findings = [Finding(kind="cut_length", parts=[f"B{i:04d}"], measure=m, limit=54.0, unit="mm").to_dict()
                for i, m in enumerate([40.0, 10.0, 50.0])]
    findings.append(Finding(kind="sheet_size", parts=["P0001"], measure=2036.0, limit=1180.0, unit="mm").to_dict())
    rows = findings_table(findings)
    assert [r["kind"] for r in rows] == ["cut_length", "sheet_size"]
    assert rows[0]["count"] == 3 and rows[0]["worst"] == 10.0 and rows[0]["worst_parts"] == ["B0001"]
    json.dumps(findings)  # JSON-ready


@pytest.mark.parametrize("rings", [1, 3])
def test_the_region_optimised_again_is_within_its_rings_of_a_collapse(rings):
    """After a collapse the grid is optimised again only near it: the nodes within ``rings`` beams
    (graph distance, scipy's shortest paths) of the nodes it changed, the merged node (moved) and
    its neighbours (joined to it), so within ``rings + 1`` of the merged node."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import shortest_path

    from workflow.stages.optimize import changed_region

    grid = _honeycomb(8, 8)
    interior = np.flatnonzero(~grid.boundary[grid.edges].any(axis=1))
    beam = int(interior[len(interior) // 2])
    after, done = collapse_beams(grid, np.array([beam]))
    assert done == 1
    merged = int(np.argmin(np.linalg.norm(after.nodes - grid.nodes[grid.edges[beam]].mean(axis=0), axis=1)))
    edges = after.edges
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(after.n_nodes,) * 2)
    hops = shortest_path(graph, directed=False, unweighted=True, indices=merged)
    region = changed_region(grid, after, rings=rings)
    assert np.array_equal(region, hops <= rings + 1)
    assert 0 < region.sum() < after.n_nodes / 2
    assert not changed_region(grid, grid, rings=rings).any(), "nothing changed, nothing optimised again"


def test_a_defect_made_by_a_flip_is_flipped_back_to_hexagons():
    """Issue 13: a T1 flip of a honeycomb's central beam leaves its two cells pentagons and the cells
    at its ends heptagons; flip_defects finds that beam (two heptagons, a pentagon at each end),
    flips it back and gives every cell its six sides and the honeycomb's own nodes again."""
    from engine.remeshing.collapse import flip_beams, flip_defects
    from tests.test_panels import hex_polymesh

    honeycomb = hex_polymesh(rows=6, cols=6)
    centre = honeycomb.nodes[:, :2].mean(axis=0)
    middle = np.linalg.norm(honeycomb.nodes[honeycomb.edges].mean(axis=1)[:, :2] - centre, axis=1)
    beam = int(np.argmin(middle))
    defect, count, _ = flip_beams(honeycomb, np.array([beam]), honeycomb.beam_lengths)
    assert count == 1
    assert sorted(defect.face_degrees.tolist()).count(6) == sorted(honeycomb.face_degrees.tolist()).count(6) - 4
    healed, flipped = flip_defects(defect)
    assert flipped == 1
    assert np.array_equal(healed.face_degrees, honeycomb.face_degrees)
    assert [sorted(f.tolist()) for f in healed.faces] == [sorted(f.tolist()) for f in honeycomb.faces]
    assert flip_defects(honeycomb)[1] == 0


def test_a_flip_is_shortened_or_not_made_where_its_length_would_fold_the_cells():
    """A beam of a unit honeycomb flipped at 4 m would reach past the far sides of the cells it
    enters: it is given a shorter share of that length, and no cell crosses itself or turns over
    (their turns about +z, independently of the flip's own check); at 20 m no share fits and the
    grid is left as it was."""
    from engine.geometry.projections import CellFans

    grid = _honeycomb()
    interior = np.flatnonzero(~grid.boundary[grid.edges].any(axis=1))
    beam = int(interior[len(interior) // 2])
    result, done, new = flip_beams(grid, np.array([beam]), np.full(len(grid.edges), 4.0))
    assert done == 1
    length = float(result.beam_lengths[new[0]])
    assert 0.3 * 4.0 - 1e-9 <= length < 4.0
    fans = CellFans(result.faces)
    assert np.all(fans.windings(result.nodes, np.tile([0.0, 0.0, 1.0], (result.n_faces, 1))) == 1)
    same, done, _ = flip_beams(grid, np.array([beam]), np.full(len(grid.edges), 20.0))
    assert done == 0 and same is grid


def test_a_defect_beside_the_boundary_is_flipped_back_counting_interior_cells_only():
    """Issue 13: the same 5-7 defect made at a beam one of whose four cells is a boundary cell:
    only the interior cells' sides count, and they gain 3, so flip_defects flips it back to the
    honeycomb's cells (it had looked for four interior cells, and left it)."""
    from engine.remeshing.collapse import _cells_around, _cells_at_nodes, flip_beams, flip_defects
    from tests.test_panels import hex_polymesh

    honeycomb = hex_polymesh(rows=6, cols=6)
    _, node_faces = _cells_at_nodes(honeycomb)
    boundary_cell = honeycomb.face_boundary
    candidates = []
    for k, (p, q) in enumerate(honeycomb.edges.tolist()):
        around = _cells_around(node_faces, p, q)
        if around is not None and not honeycomb.boundary[[p, q]].any() and boundary_cell[list(around)].sum() == 1:
            candidates.append(k)
    assert candidates, "the patch has a beam between interior nodes with one boundary cell round it"
    defect, count, _ = flip_beams(honeycomb, np.array(candidates[:1]), honeycomb.beam_lengths)
    assert count == 1
    healed, flipped = flip_defects(defect)
    assert flipped == 1
    assert [sorted(f.tolist()) for f in healed.faces] == [sorted(f.tolist()) for f in honeycomb.faces]


def test_a_collapse_moves_its_node_where_no_cell_folds():
    """Two boundary nodes on an arc collapse; a thin triangle beside them has its inner node just
    under the chord to the next boundary node. At the midpoint of the collapsed beam (inside the
    arc) that triangle turns over, and so it does at the first end's place; at the second end's
    place it does not, so the merged node goes there. Judged independently by each cell's turns
    about +z."""
    from engine.geometry.projections import CellFans

    arc = [np.radians(100), np.radians(90), np.radians(60)]
    nodes = np.array([[np.cos(t), np.sin(t), 0.0] for t in arc] + [[0.25, 0.925, 0.0], [0.0, 0.5, 0.0]])
    faces = (np.array([0, 4, 3, 1]), np.array([3, 2, 1]), np.array([4, 2, 3]))
    boundary = np.array([True, True, True, False, True])
    grid = PolyMesh(nodes=nodes, faces=faces, boundary=boundary)

    def turns(g: PolyMesh) -> list[int]:
        fans = CellFans(g.faces)
        return fans.windings(g.nodes, np.tile([0.0, 0.0, 1.0], (g.n_faces, 1))).tolist()

    assert turns(grid) == [1, 1, 1]
    beam = int(np.flatnonzero((np.sort(grid.edges, axis=1) == [0, 1]).all(axis=1))[0])
    merged, count = collapse_beams(grid, np.array([beam]))
    assert count == 1 and merged.n_faces == 3
    assert turns(merged) == [1, 1, 1]
    assert np.any(np.all(np.isclose(merged.nodes, nodes[1]), axis=1)), "the merged node is where the second end was"
    at_midpoint = nodes.copy()
    at_midpoint[0] = 0.5 * (nodes[0] + nodes[1])  # node 0 standing for the merged node, node 1 unused
    assert -1 in turns(PolyMesh(nodes=at_midpoint, faces=(np.array([0, 4, 3]), np.array([3, 2, 0]),
                                                          np.array([4, 2, 3])))), "the midpoint folds"


def test_when_the_last_resorts_rounds_run_out_the_short_beams_are_removed_once_more(monkeypatch):
    """The last resort's rounds straighten kinks, which can leave a beam short at its ends' narrower
    angles; when its rounds run out, the short beams are removed once more, so none that a removal
    can take is left short of what its joints need (here: no rounds at all)."""
    from importlib import resources
    from types import SimpleNamespace

    from engine.geometry.parametric import grid_triangles
    from engine.mesh import TriMesh
    from engine.remeshing.field import GuidingField
    from engine.remeshing.optimize import OptimizeResult
    from workflow.config import load_project
    from workflow.stages import optimize as stage
    from workflow.stages.build_limits import build_limits_of

    project = load_project(resources.files("templates") / "mockup.toml")
    limits = build_limits_of(project)
    side = 2 * limits.shortest_beam_mm() / 1000
    grid = _honeycomb(5, 5, side=side)
    x = grid.nodes.copy()
    interior = np.flatnonzero(~grid.boundary[grid.edges].any(axis=1))
    moved: set[int] = set()
    for beam in interior[::5]:
        a, b = map(int, grid.edges[beam])
        if {a, b} & moved:
            continue
        x[b] = x[a] + 0.2 * (x[b] - x[a])  # 0.4 of the shortest buildable beam
        moved |= {a, b}
    grid = grid.replace_nodes(x)
    short_before = int(np.sum(grid.beam_lengths < required_beam_lengths_m(grid, limits)))
    assert short_before >= 3
    low, high = grid.nodes.min(axis=0) - side, grid.nodes.max(axis=0) + side
    u, v = np.meshgrid(np.linspace(low[0], high[0], 11), np.linspace(low[1], high[1], 11), indexing="ij")
    plane = TriMesh(vertices=np.c_[u.ravel(), v.ravel(), np.zeros(u.size)], faces=grid_triangles(10, 10))
    n = plane.n_vertices
    field = GuidingField(size=np.ones(n), anisotropy=np.ones(n), direction=np.tile([1.0, 0, 0], (n, 1)),
                         normals=np.tile([0, 0, 1.0], (n, 1)))
    monkeypatch.setattr(stage, "LAST_RESORT_ROUNDS", 0)
    result, removed = stage.without_unbuildable_beams(OptimizeResult(polymesh=grid, quality={}), project,
                                                      SimpleNamespace(mesh=plane), field)
    after = result.polymesh
    _check_valid(after)
    assert removed >= short_before
    assert np.all(after.beam_lengths >= required_beam_lengths_m(after, limits) - 1e-9)
    assert np.allclose(_area(after), _area(grid)), "a removal merges two cells and moves no node"


def test_nodes_that_collapses_and_flips_moved_go_back_onto_the_surface():
    """A flip turns its beam across in the plane of its cells, and a collapse merges at the
    midpoint: on a curved surface both leave nodes off it, and the local re-optimisation pulled them
    back only as strongly as its closeness weight (a 1500-cell roof kept nodes 116 mm off after its
    flips). onto_surface puts the nodes it is given at their closest surface points, here a plane at
    z = 0; boundary nodes, supports and the nodes not given stay where they are."""
    from engine.mesh import TriMesh
    from engine.remeshing.local_global import ClosestSurfacePoints
    from workflow.stages.optimize import onto_surface

    grid = _honeycomb(6, 6)
    lo, hi = grid.nodes.min(axis=0) - 1.0, grid.nodes.max(axis=0) + 1.0
    plane = TriMesh(vertices=np.array([[lo[0], lo[1], 0.0], [hi[0], lo[1], 0.0], [hi[0], hi[1], 0.0],
                                       [lo[0], hi[1], 0.0]]), faces=np.array([[0, 1, 2], [0, 2, 3]]))
    interior = np.flatnonzero(~grid.boundary)
    lifted = grid.nodes.copy()
    moved = np.zeros(grid.n_nodes, dtype=bool)
    moved[interior[:5]] = True
    moved[np.flatnonzero(grid.boundary)[0]] = True
    lifted[moved, 2] = 0.3
    lifted[interior[5], 2] = 0.2  # off the surface, but not given
    off = grid.replace_nodes(lifted)
    snapped = onto_surface(off, moved, ClosestSurfacePoints(plane))
    assert np.allclose(snapped.nodes[interior[:5]], grid.nodes[interior[:5]], atol=1e-12)
    kept = ~moved | grid.boundary
    assert np.array_equal(snapped.nodes[kept], lifted[kept])


def test_collapses_and_flips_judged_along_the_surfaces_normals_either_way_round():
    """With the surface's normals given (engine.remeshing.collapse.Normals), a collapse or flip is
    judged against them at each cell instead of the cells' summed normal: on a flat honeycomb, whose
    surface normal is the summed one, the dozen short beams go the same way, and the same again with
    the normals turned over (the cells then turn the other way about them, which the judgement
    allows for). The arc's thin triangle of the test above still takes the second end's place."""
    grid = _shortened_honeycomb()
    required = lambda g: np.full(len(g.edges), 0.5)  # noqa: E731
    plain, report = collapse_short_beams(grid, required)
    for sign in (1.0, -1.0):
        along, report_along = collapse_short_beams(grid, required,
                                                   normals=lambda p, s=sign: np.tile([0.0, 0.0, s], (len(p), 1)))
        assert np.array_equal(along.nodes, plain.nodes) and [f.tolist() for f in along.faces] == [
            f.tolist() for f in plain.faces]
        assert report_along.to_dict() == report.to_dict()
    arc = [np.radians(100), np.radians(90), np.radians(60)]
    nodes = np.array([[np.cos(t), np.sin(t), 0.0] for t in arc] + [[0.25, 0.925, 0.0], [0.0, 0.5, 0.0]])
    thin = PolyMesh(nodes=nodes, faces=(np.array([0, 4, 3, 1]), np.array([3, 2, 1]), np.array([4, 2, 3])),
                    boundary=np.array([True, True, True, False, True]))
    beam = int(np.flatnonzero((np.sort(thin.edges, axis=1) == [0, 1]).all(axis=1))[0])
    for sign in (1.0, -1.0):
        merged, count = collapse_beams(thin, np.array([beam]),
                                       normals=lambda p, s=sign: np.tile([0.0, 0.0, s], (len(p), 1)))
        assert count == 1 and np.any(np.all(np.isclose(merged.nodes, nodes[1]), axis=1)), "not at the midpoint"
