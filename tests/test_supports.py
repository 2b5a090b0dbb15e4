"""Support selections, restraint codes, load cases and combinations."""

from __future__ import annotations

import numpy as np
import pytest

from engine.errors import InputError, SelectionError
from engine.geometry import parametric
from engine.structure.loads import LimitState, LoadCase, LoadCombination, combine, lump_area_load
from engine.structure.supports import (
    Supports,
    restraint_flags,
    select_boundary,
    select_box,
    select_flagged,
    select_ids,
    select_loop,
    select_nearest,
    select_plane,
)


@pytest.fixture(scope="module")
def courtyard():
    return parametric.courtyard(divisions=12)


def test_boundary_and_loops(courtyard):
    loops = courtyard.boundary_loops
    everything = select_boundary(loops)
    outer, inner = select_loop(loops, 0), select_loop(loops, 1)
    assert len(everything) == len(outer) + len(inner)
    lo, hi = courtyard.bounds
    assert np.allclose(np.abs(courtyard.vertices[inner, 2]), 0)
    on_edge = (np.isclose(courtyard.vertices[outer, 0], [[lo[0]], [hi[0]]]).any(0)
               | np.isclose(courtyard.vertices[outer, 1], [[lo[1]], [hi[1]]]).any(0))
    assert on_edge.all()
    with pytest.raises(SelectionError, match="2 boundary loop"):
        select_loop(loops, 2)


def test_plane_box_nearest_ids(courtyard):
    v = courtyard.vertices
    x_max = v[:, 0].max()
    plane = select_plane(v, [x_max, 0, 0], [1, 0, 0], 1e-6)
    assert np.allclose(v[plane, 0], x_max) and len(plane) == np.isclose(v[:, 0], x_max).sum()
    box = select_box(v, [-1, -1, -1], [1, 11, 10])
    assert ((np.abs(v[box, 0]) <= 1) & (v[box, 1] >= -1)).all()
    nearest = select_nearest(v, [[100, 100, 0]])
    assert nearest.tolist() == [int(np.argmax(v[:, 0] + v[:, 1]))]
    assert select_ids(len(v), [3, 1, 3]).tolist() == [1, 3]


def test_empty_selections_say_which(courtyard):
    v = courtyard.vertices
    with pytest.raises(SelectionError, match="plane through"):
        select_plane(v, [1000, 0, 0], [1, 0, 0], 0.01)
    with pytest.raises(SelectionError, match="box"):
        select_box(v, [500, 500, 500], [600, 600, 600])
    with pytest.raises(SelectionError, match="flagged"):
        select_flagged(np.zeros(len(v), dtype=bool))
    with pytest.raises(SelectionError, match="outside"):
        select_ids(len(v), [len(v)])


@pytest.mark.parametrize("code, flags", [
    ("pinned", [1, 1, 1, 0, 0, 0]), ("fixed", [1] * 6), ("roller_x", [0, 1, 1, 0, 0, 0]),
    ("roller_z", [1, 1, 0, 0, 0, 0]), ([1, 0, 1, 0, 1, 0], [1, 0, 1, 0, 1, 0]),
])
def test_restraint_codes(code, flags):
    assert restraint_flags(code).astype(int).tolist() == flags


def test_bad_restraints():
    with pytest.raises(InputError, match="allowed"):
        restraint_flags("glued")
    with pytest.raises(InputError, match="six"):
        restraint_flags([1, 1, 1])


def test_merged_supports_or_their_flags():
    s = Supports.merge([(np.array([1, 2]), restraint_flags("roller_x")),
                        (np.array([2, 5]), restraint_flags("roller_y"))])
    assert s.nodes.tolist() == [1, 2, 5]
    assert s.restraints[1].astype(int).tolist() == [1, 1, 1, 0, 0, 0]
    assert s.dof_mask(6).sum() == 2 + 3 + 2


def test_area_loads_sum_to_true_and_plan_area(courtyard):
    case = LoadCase(name="x", area_true=[0, 0, -100.0], area_plan=[0, 0, -50.0])
    forces = lump_area_load(courtyard.vertices, courtyard.faces, case)
    plan_area = 30 * 20 - 10 * 6  # the courtyard's plan, opening removed
    assert forces[:, 2].sum() == pytest.approx(-100 * courtyard.area - 50 * plan_area)


def test_combinations_are_factored_sums():
    cases = {"dead": LoadCase(name="dead", self_weight=1.0, area_true=[0, 0, -10]),
             "snow": LoadCase(name="snow", area_plan=[0, 0, -20], point_nodes=[3], point_forces=[[0, 0, -5, 0, 0, 0]])}
    uls = combine(cases, LoadCombination(name="ULS", limit_state=LimitState.ULS, factors={"dead": 1.35, "snow": 1.5}))
    assert uls.self_weight == pytest.approx(1.35)
    assert uls.area_true[2] == pytest.approx(-13.5) and uls.area_plan[2] == pytest.approx(-30)
    assert uls.point_load_array(5)[3, 2] == pytest.approx(-7.5)
    with pytest.raises(InputError, match="wind"):
        combine(cases, LoadCombination(name="x", limit_state=LimitState.SLS, factors={"wind": 1.0}))


def test_the_free_rigid_motions_of_a_plane_held_in_its_plane_are_named():
    """Nodes in the plane z = 0 held in x and y only (rollers along z) can still slide along z and
    turn about x and y, which move them along z alone; held in z as well at three nodes not on a
    line, nothing is free."""
    from engine.linalg import count_free_rigid_modes, free_rigid_motions

    rng = np.random.default_rng(3)
    nodes = np.c_[rng.uniform(-5, 5, (20, 2)), np.zeros(20)]
    held = np.zeros((20, 6), dtype=bool)
    held[:, :2] = True
    assert free_rigid_motions(nodes, held.ravel()) == ["sliding along z", "turning about x", "turning about y"]
    assert count_free_rigid_modes(nodes, held.ravel()) == 3
    held[:3, 2] = True
    assert free_rigid_motions(nodes, held.ravel()) == [] and count_free_rigid_modes(nodes, held.ravel()) == 0


def test_a_column_inside_the_roof_holds_the_grid_node_nearest_it():
    """A cap on its edge and on a column under its crown: the remeshed grid is held at its edge
    and at the node nearest the crown, inside the grid (the crown's support used to go to the
    nearest edge node, and the grid to the analysis without its column); at 80 cells that node was
    within COLUMN_SNAP of its shortest beam of the crown, and is moved onto it."""
    from engine.remeshing.field import GuidingField
    from engine.remeshing.voronoi import RemeshSettings, remesh

    mesh = parametric.cap(span=10.0, span_to_rise=5.0, rings=10)
    crown = int(np.argmax(mesh.vertices[:, 2]))
    held = mesh.boundary_vertices.copy()
    held[crown] = True
    n = mesh.n_vertices
    field = GuidingField(size=np.ones(n), anisotropy=np.ones(n), direction=np.tile([1.0, 0, 0], (n, 1)),
                         normals=mesh.vertex_normals)
    for cells in (40, 80):
        grid = remesh(mesh, field, RemeshSettings(n_cells=cells), support_vertices=held).polymesh
        inside = np.flatnonzero(grid.supports & ~grid.boundary)
        assert len(inside) == 1
        nearest = np.linalg.norm(grid.nodes - mesh.vertices[crown], axis=1).argmin()
        assert inside[0] == nearest
        assert np.linalg.norm(grid.nodes[nearest] - mesh.vertices[crown]) < grid.beam_lengths.mean()
        assert np.all(grid.supports[grid.boundary])
    assert np.linalg.norm(grid.nodes[nearest] - mesh.vertices[crown]) < 1e-9


def test_a_nearest_point_far_off_the_roof_is_refused_and_a_column_foot_under_it_is_not():
    """Points given in millimetres and read as metres (6000, 4000) are kilometres off a 24 m roof:
    they used to snap to its corners without a word. A column's foot 4 m under the roof still
    selects the vertex above it, and a point far out towards a corner, that corner."""
    from engine.structure.supports import NEAREST_REACH

    x, y = np.meshgrid(np.linspace(-12, 12, 25), np.linspace(-8, 8, 17), indexing="ij")
    roof = np.c_[x.ravel(), y.ravel(), np.full(x.size, 4.0)]
    assert roof[select_nearest(roof, [[6.0, 4.0, 0.0]])[0]] == pytest.approx([6.0, 4.0, 4.0])
    with pytest.raises(SelectionError, match=r"'nearest' point 1 \[6000.0, 4000.0, 0.0\] lies 7\d{3} m") as error:
        select_nearest(roof, [[6.0, 4.0, 0.0], [6000.0, 4000.0, 0.0]])
    assert "in metres" in error.value.hint
    across = np.linalg.norm(np.ptp(roof, axis=0))
    select_nearest(roof, [[0.0, 0.0, 4.0 + 0.99 * NEAREST_REACH * across]])  # within reach
    with pytest.raises(SelectionError):
        select_nearest(roof, [[0.0, 0.0, 4.0 + 1.01 * NEAREST_REACH * across]])


def test_remesh_json_says_how_far_each_column_is_from_its_node(tmp_path):
    """A cap held on its edge and a column under its crown, run to the remesh from a PLY whose red
    vertices are the supports: remesh.json's ``columns`` has the crown and the offset of the
    interior supported node written in the grid's OBJ and node flags, measured here."""
    import json

    from engine.mesh import TriMesh
    from workflow.config import project_from_surface
    from workflow.progress import Progress
    from workflow.runner import run_project
    from workflow.stages import STAGES
    from workflow.surface_io import write_surface_ply

    mesh = parametric.cap(span=10.0, span_to_rise=5.0, rings=10)
    crown = int(np.argmax(mesh.vertices[:, 2]))
    held = mesh.boundary_vertices.copy()
    held[crown] = True
    path = write_surface_ply(TriMesh(vertices=mesh.vertices, faces=mesh.faces, flagged=held), tmp_path / "cap.ply")
    project = project_from_surface(str(path), "flagged")
    project = project.model_copy(update={"remesh": project.remesh.model_copy(update={"n_cells": 40})})
    out = tmp_path / "out"
    assert run_project(project, out, STAGES, until="remesh", progress=Progress(enabled=False)).message is None
    (column,) = json.loads((out / "04-remesh" / "remesh.json").read_text())["columns"]
    assert column["column_m"] == pytest.approx(mesh.vertices[crown].tolist())
    nodes = np.array([line.split()[1:4] for line in (out / "04-remesh" / "gridshell.obj").read_text().splitlines()
                      if line.startswith("v ")], dtype=float)
    flags = json.loads((out / "04-remesh" / "gridshell.nodes.json").read_text())
    supports, boundary = np.zeros(len(nodes), bool), np.zeros(len(nodes), bool)
    supports[flags["supports"]] = True
    boundary[flags["boundary"]] = True
    (inside,) = np.flatnonzero(supports & ~boundary)
    assert column["node"] == f"N{inside + 1:04d}"
    assert column["offset_m"] == pytest.approx(np.linalg.norm(nodes[inside] - mesh.vertices[crown]), abs=1e-9)
