"""``[remesh] grid``: the lattices the study sets against the statics-aware Voronoi grid (quad at 0
and 45 degrees, triangles, the statics-aware quads) meet a total length within 1 %, the isotropic
control does not follow the field, and a project on a lattice runs to its analysis."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from engine.geometry.parametric import cap, courtyard, grid_triangles
from engine.mesh import TriMesh
from engine.remeshing.field import GuidingField
from engine.remeshing.grids import (
    field_angle,
    isotropic_field,
    quad45_grid,
    quad_grid,
    statics_quad_grid,
    triangular_grid,
)


def _rectangle(length: float = 8.0, width: float = 5.0, rise: float = 0.0, nx: int = 32, ny: int = 20) -> TriMesh:
    """A rectangle plan on the axes, flat or with a gentle barrel rise (m)."""
    x, y = np.meshgrid(np.linspace(0, length, nx + 1), np.linspace(0, width, ny + 1), indexing="ij")
    z = rise * np.sin(np.pi * y / width)
    return TriMesh(vertices=np.c_[x.ravel(), y.ravel(), z.ravel()], faces=grid_triangles(nx, ny))


def _graded_field(mesh: TriMesh, angle_deg: float = 30.0, ratio: float = 3.0) -> GuidingField:
    """Sizes from 1 (x = 0) to ``ratio`` (the far end), one direction at ``angle_deg`` in plan."""
    x = mesh.vertices[:, 0]
    size = 1.0 + (ratio - 1.0) * (x - x.min()) / np.ptp(x)
    a = np.radians(angle_deg)
    direction = np.tile([np.cos(a), np.sin(a), 0.0], (mesh.n_vertices, 1))
    return GuidingField(size=size, anisotropy=np.ones(mesh.n_vertices), direction=direction,
                        normals=np.tile([0.0, 0.0, 1.0], (mesh.n_vertices, 1)))


def _supports(mesh: TriMesh) -> np.ndarray:
    support = np.zeros(mesh.n_vertices, dtype=bool)
    support[mesh.boundary_loops[0]] = True
    return support


def _interior_directions(grid) -> tuple[np.ndarray, np.ndarray]:
    """(plan angles (deg, in [0, 180)), midpoints) of the beams with no node on the boundary."""
    interior = ~(grid.boundary[grid.edges[:, 0]] | grid.boundary[grid.edges[:, 1]])
    ends = grid.nodes[grid.edges[interior]]
    d = ends[:, 1] - ends[:, 0]
    return np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 180.0, ends.mean(axis=1)


@pytest.mark.parametrize("kind", ["quad", "quad45", "triangular", "statics_quad"])
@pytest.mark.parametrize("surface", ["cap", "courtyard"])
def test_each_lattice_meets_the_total_length_within_one_percent(kind, surface):
    mesh = cap() if surface == "cap" else courtyard()
    target = 8.0 * np.sqrt(mesh.area) * 3
    support = _supports(mesh)
    if kind == "statics_quad":
        grid = statics_quad_grid(mesh, _graded_field(mesh), total_length=target, support_vertices=support)
    else:
        make = {"quad": quad_grid, "quad45": quad45_grid, "triangular": triangular_grid}[kind]
        grid = make(mesh, total_length=target, support_vertices=support)
    assert grid.total_length == pytest.approx(target, rel=0.01)
    assert grid.supports.any()


def test_quad45_beams_run_at_45_degrees_to_the_quad_beams_on_a_rectangle():
    """An 8 m x 5 m rectangle on the axes, 101 m of beams (squares of 1 m: whole rows on this plan jump by
    5 or 8 m, so squares along its sides reach only some lengths): 0 / 90 degrees, turned 45 / 135."""
    mesh = _rectangle()
    quad = quad_grid(mesh, total_length=101.0)
    turned = quad45_grid(mesh, total_length=101.0)
    assert turned.total_length == pytest.approx(101.0, rel=0.01)
    quad_angles, _ = _interior_directions(quad)
    turned_angles, _ = _interior_directions(turned)
    assert len(turned_angles) > 20
    assert quad.total_length == pytest.approx(101.0, rel=0.01)
    assert np.allclose(quad_angles % 90.0, 0.0, atol=1e-6)
    assert np.allclose(turned_angles % 90.0, 45.0, atol=1e-6)


def test_the_isotropic_control_does_not_follow_the_field_and_the_voronoi_grid_does():
    from engine.remeshing.grid_quality import polymesh_quality
    from engine.remeshing.voronoi import RemeshSettings, remesh

    mesh = _rectangle(rise=1.0, nx=40, ny=25)
    field = _graded_field(mesh, ratio=3.0)
    settings = RemeshSettings(n_cells=80, lloyd_iterations=20, seed=1)
    graded = remesh(mesh, field, settings, support_vertices=_supports(mesh)).polymesh
    control = remesh(mesh, isotropic_field(field), settings, support_vertices=_supports(mesh)).polymesh
    # both measured against the statics field's sizes
    followed = polymesh_quality(graded, mesh=mesh, field=field)["size_rank_correlation"]
    ignored = polymesh_quality(control, mesh=mesh, field=field)["size_rank_correlation"]
    assert followed > 0.7
    assert abs(ignored) < 0.35


def test_statics_quad_follows_the_field_direction_and_is_finer_where_the_field_is_smaller():
    """A rectangle on the axes whose field runs at 30 degrees and is three times finer at x = 0."""
    mesh = _rectangle(rise=1.0)
    field = _graded_field(mesh, angle_deg=30.0, ratio=3.0)
    assert field_angle(mesh, field) == pytest.approx(30.0, abs=1e-6)
    target = 110.0
    statics = statics_quad_grid(mesh, field, total_length=target, support_vertices=_supports(mesh))
    plain = quad_grid(mesh, total_length=target, support_vertices=_supports(mesh))
    assert statics.total_length == pytest.approx(target, rel=0.01)

    def misalignment(grid) -> float:
        """Mean angle (deg) between a beam in plan and the nearer of the field's two directions."""
        angles, _ = _interior_directions(grid)
        off = np.abs((angles - 30.0) % 90.0)
        return float(np.minimum(off, 90.0 - off).mean())

    assert misalignment(statics) < 2.0 < 20.0 < misalignment(plain)
    angles, middles = _interior_directions(statics)
    _, ends = angles, statics.nodes[statics.edges]
    interior = ~(statics.boundary[statics.edges[:, 0]] | statics.boundary[statics.edges[:, 1]])
    plan = np.linalg.norm(np.diff(ends[interior][:, :, :2], axis=1)[:, 0], axis=1)
    x = middles[:, 0]
    fine, coarse = plan[x < 2.5], plan[x > 5.5]
    assert len(fine) > 5 and len(coarse) > 5
    assert np.median(fine) < 0.75 * np.median(coarse)


def _tiny_project(folder: Path, grid: str) -> Path:
    sys.path.insert(0, str(Path(__file__).parent))
    from test_compare import _tiny_mockup

    path = _tiny_mockup(folder)
    path.write_text(path.read_text(encoding="utf-8").replace("[remesh]\n", f'[remesh]\ngrid = "{grid}"\n', 1),
                    encoding="utf-8")
    return path


def test_a_project_on_a_quad_grid_runs_to_its_analysis(tmp_path):
    import json

    from workflow.config import load_project
    from workflow.progress import Progress
    from workflow.runner import run_project
    from workflow.stages import STAGES

    project = load_project(_tiny_project(tmp_path, "quad"))
    summary = run_project(project, tmp_path / "out", STAGES, until="analysis", progress=Progress(enabled=False))
    assert summary.message is None, summary.message
    remeshed = json.loads((tmp_path / "out/04-remesh/remesh.json").read_text())
    assert remeshed["grid"] == "quad" and remeshed["face_degree_histogram"].get("4", 0) > 4
    assert abs(remeshed["total_length_error"]) < 0.1, "n_cells gives a guide length, met within 10 %"
    optimised = json.loads((tmp_path / "out/05-optimize/optimize.json").read_text())
    assert optimised["grid"] == "quad" and optimised["optimised"] is False
    assert (tmp_path / "out/04-remesh/gridshell.obj").read_text().split("\n", 1)[1] == \
        (tmp_path / "out/05-optimize/gridshell.obj").read_text().split("\n", 1)[1], "the lattice goes through as built"
    assert (tmp_path / "out/06-analysis").is_dir()


def test_the_default_grid_leaves_the_cache_keys_as_they_were():
    from workflow.config import parse_project
    from workflow.runner import _stage_key
    from workflow.stages import STAGES

    data = {"project": {"name": "keys"}, "surface": {"template": "mockup"}}
    remesh = next(s for s in STAGES if s.name == "remesh")
    keys = {"surface": "s", "field": "f"}
    plain = _stage_key(remesh, parse_project(data), keys, "1")
    voronoi = _stage_key(remesh, parse_project({**data, "remesh": {"grid": "voronoi"}}), keys, "1")
    quad = _stage_key(remesh, parse_project({**data, "remesh": {"grid": "quad"}}), keys, "1")
    assert plain == voronoi != quad


def test_a_sweep_over_the_grid_is_accepted(tmp_path):
    from workflow.cli import main
    from workflow.sweep import load_sweep, sweep_points

    assert main(["init", str(tmp_path / "proj"), "--template", "mockup"]) == 0
    path = tmp_path / "sweep.toml"
    path.write_text('project = "proj/project.toml"\nuntil = "analysis"\n[parameters]\n'
                    '"remesh.grid" = ["voronoi", "quad"]\n')
    spec = load_sweep(path)
    points = sweep_points(spec, tmp_path / "out")
    assert [p.project.remesh.grid for p in points] == ["voronoi", "quad"]
    bad = tmp_path / "bad.toml"
    bad.write_text(path.read_text().replace('"quad"]', '"hexagons"]'))
    with pytest.raises(Exception, match="remesh.grid"):
        sweep_points(load_sweep(bad), tmp_path / "out2")


@pytest.mark.parametrize("grid", ["quad", "triangular"])
def test_a_lattice_is_made_buildable_for_its_joints(tmp_path, grid):
    """A 5 m dome's lattice of 80 cells on steel nodes: the lines its outline cuts short are a
    quarter of the beams, each shorter than its two joints take (they were written as laid out, 40
    short beams and 49 joint clashes in the fabrication). The remesh stage collapses them as it does
    a Voronoi grid's (all but 3 % at most), without coarsening the lattice, whose own beams are long
    enough; the cells left are polygons of 3 to 5 sides covering the same surface, measured from the
    OBJ read back here."""
    import json

    from fabrication.limits import required_beam_lengths_m
    from workflow.config import project_from_surface
    from workflow.progress import Progress
    from workflow.runner import run_project
    from workflow.stages import STAGES
    from workflow.stages.build_limits import build_limits_of
    from workflow.stages.lattice import build_lattice
    from workflow.stages.polymesh_io import read_polymesh_obj
    from workflow.stages.surface import load as load_surface

    sys.path.insert(0, str(Path(__file__).parent))
    from generated_surfaces import generate_surface, write_ply

    path = write_ply(generate_surface(460), tmp_path / "dome.ply")
    project = project_from_surface(str(path), "flagged")
    project = project.model_copy(update={"remesh": project.remesh.model_copy(update={"n_cells": 80, "grid": grid})})
    out = tmp_path / "out"
    assert run_project(project, out, STAGES, until="remesh", progress=Progress(enabled=False)).message is None
    limits = build_limits_of(project)
    surface = load_surface(out / "01-surface", project)
    laid_out = build_lattice(surface, None, project)
    assert np.mean(laid_out.beam_lengths < required_beam_lengths_m(laid_out, limits)) > 0.15
    record = json.loads((out / "04-remesh" / "remesh.json").read_text())
    assert record["coarsened"]["remeshes"] == 0 and record["buildable"]["collapsed_beams"] > 0
    written = read_polymesh_obj(out / "04-remesh" / "gridshell.obj")
    short = written.beam_lengths < required_beam_lengths_m(written, limits)
    assert short.sum() <= 0.03 * len(short)  # the triangles': 3 of 126 no valid collapse removes (findings)
    nodes, faces = [], []
    for line in (out / "04-remesh" / "gridshell.obj").read_text().splitlines():
        parts = line.split()
        if parts and parts[0] == "v":
            nodes.append([float(c) for c in parts[1:4]])
        elif parts and parts[0] == "f":
            faces.append([int(p.split("/")[0]) - 1 for p in parts[1:]])
    nodes = np.array(nodes)
    assert {len(f) for f in faces} <= {3, 4, 5}

    def area(points: np.ndarray, polygons: list) -> float:  # fan areas of planar-ish polygons
        total = 0.0
        for f in polygons:
            p = points[f]
            total += 0.5 * np.linalg.norm(np.cross(p[1:-1] - p[0], p[2:] - p[0]).sum(axis=0))
        return total

    assert area(nodes, faces) == pytest.approx(area(laid_out.nodes, [list(f) for f in laid_out.faces]), rel=0.05)
