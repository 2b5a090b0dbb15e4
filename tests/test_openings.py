"""A grid keeps its surface's openings (engine.remeshing.openings): areas against the shoelace
formula on a 10 m square roof with a 4 m square courtyard, lifted onto a tilted plane."""

from __future__ import annotations

import numpy as np
import pytest

from engine.mesh import PolyMesh, TriMesh
from engine.remeshing.openings import loop_area, openings
from workflow.stages.optimize import openings_finding

TILT = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(0.3), np.sin(0.3)], [0.0, -np.sin(0.3), np.cos(0.3)]])


def _courtyard() -> TriMesh:
    """Unit squares of [0, 10]^2 but those of the courtyard [3, 7]^2, two triangles each."""
    index = np.arange(121).reshape(11, 11)            # vertex (i, j) at x = i, y = j
    faces = [[index[i, j], index[i + 1, j], index[i + 1, j + 1]] for i in range(10) for j in range(10)
             if not (3 <= i < 7 and 3 <= j < 7)]
    faces += [[index[i, j], index[i + 1, j + 1], index[i, j + 1]] for i in range(10) for j in range(10)
              if not (3 <= i < 7 and 3 <= j < 7)]
    i, j = np.meshgrid(np.arange(11.0), np.arange(11.0), indexing="ij")
    return TriMesh(vertices=np.c_[i.ravel(), j.ravel(), np.zeros(121)] @ TILT.T, faces=np.array(faces))


def _frame(hole: list[tuple[float, float]]) -> PolyMesh:
    """Cells between the outline's corners and the ``hole``'s nodes (counter-clockwise), one per
    outline side, the hole's nodes shared out along the sides in turn."""
    outer = [(0.0, 0.0), (10.0, 0.0), (10.0, 10.0), (0.0, 10.0)]
    nodes = np.array([(*p, 0.0) for p in outer + hole]) @ TILT.T
    k = len(hole)
    # the hole's node nearest each outline corner starts that side's cell
    first = [int(np.argmin([np.hypot(h[0] - c[0], h[1] - c[1]) for h in hole])) for c in outer]
    faces = []
    for side in range(4):
        a, b = side, (side + 1) % 4
        run = [first[a]]
        while run[-1] != first[b]:
            run.append((run[-1] + 1) % k)
        faces.append(np.array([a, b] + [4 + h for h in reversed(run)]))
    return PolyMesh(nodes=nodes, faces=tuple(faces))


def test_a_loop_spans_its_shoelace_area_on_any_plane():
    square = np.array([[3.0, 3, 0], [7, 3, 0], [7, 7, 0], [3, 7, 0]])
    assert loop_area(square @ TILT.T) == pytest.approx(16.0)
    assert loop_area(square[:2]) == 0.0


def test_a_grid_that_follows_the_courtyard_keeps_it_open():
    grid = _frame([(3.0, 3.0), (7.0, 3.0), (7.0, 7.0), (3.0, 7.0)])
    assert sorted(len(loop) for loop in grid.boundary_loops) == [4, 4]
    (courtyard,) = openings(_courtyard(), grid)
    assert courtyard.surface_area_m2 == pytest.approx(16.0)
    assert courtyard.grid_area_m2 == pytest.approx(16.0)
    assert courtyard.kept == pytest.approx(1.0) and courtyard.joints == 4
    assert courtyard.centre @ TILT[:, :2] == pytest.approx([5.0, 5.0])   # in the roof's own plane


def test_an_outline_shrunk_to_a_triangle_spans_the_courtyard_and_is_a_finding():
    """Three joints left on the courtyard's outline at (4, 4), (6, 4), (5, 6): 2 of its 16 m^2 open."""
    grid = _frame([(4.0, 4.0), (6.0, 4.0), (5.0, 6.0)])
    (courtyard,) = openings(_courtyard(), grid)
    assert courtyard.grid_area_m2 == pytest.approx(2.0)
    assert courtyard.kept == pytest.approx(2.0 / 16.0) and courtyard.joints == 3
    finding = openings_finding([courtyard])
    assert finding["kind"] == "opening_spanned" and finding["parts"] == ["opening 1"]
    assert finding["measure"] == pytest.approx(12.5) and finding["limit"] == 50
    assert "2.00 of 16.00 m^2 left open, 3 joints" in finding["message"]
    assert "[remesh] n_cells" in finding["fix"]


def test_a_grid_without_the_hole_leaves_nothing_open_and_a_surface_without_one_has_no_opening():
    whole = PolyMesh(nodes=np.array([[0.0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0]]) @ TILT.T,
                     faces=(np.array([0, 1, 2, 3]),))
    (courtyard,) = openings(_courtyard(), whole)
    assert courtyard.grid_area_m2 == 0.0 and courtyard.joints == 0 and courtyard.kept == 0.0
    plain = TriMesh(vertices=np.array([[0.0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0]]),
                    faces=np.array([[0, 1, 2], [0, 2, 3]]))
    assert openings(plain, whole) == []
