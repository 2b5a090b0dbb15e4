"""Issue 13: [field] symmetry_planes give a grid symmetric within 1 % of the mean beam, after the
remesh and after the optimiser; without planes nothing of it runs. Symmetry is measured here with
a KD-tree of the nodes against their mirror images, not with engine.geometry.symmetry."""

from __future__ import annotations

from importlib import resources

import numpy as np
import pytest
from scipy.spatial import cKDTree

from engine.geometry.parametric import grid_triangles
from engine.mesh import TriMesh
from engine.remeshing.field import GuidingField
from engine.remeshing.optimize import OptimizeSettings, optimize
from engine.remeshing.voronoi import RemeshSettings, remesh
from workflow.config import load_project
from workflow.progress import Progress
from workflow.runner import run_project
from workflow.stages import STAGES
from workflow.stages.polymesh_io import read_polymesh_obj

TOLERANCE = 0.01


def _deviation(nodes: np.ndarray, lengths: np.ndarray, normal) -> float:
    """Largest distance from a node's mirror image (plane through the origin) to the nearest node,
    over the mean beam."""
    n = np.asarray(normal, dtype=float)
    mirrored = nodes - 2.0 * np.outer(nodes @ n, n)
    return float(cKDTree(nodes).query(mirrored)[0].max() / lengths.mean())


def _run(template: str, out, n_cells: int | None = None, planes: bool = True):
    project = load_project(resources.files("templates") / f"{template}.toml")
    if n_cells is not None:
        project = project.model_copy(update={"remesh": project.remesh.model_copy(update={"n_cells": n_cells})})
    if not planes:
        project = project.model_copy(update={"field": project.field.model_copy(update={"symmetry_planes": []})})
    summary = run_project(project, out, STAGES, until="optimize", progress=Progress(enabled=False))
    assert summary.message is None, summary.message
    return project


@pytest.mark.parametrize("template, n_cells", [("cap", 60), ("cap", 150), ("mockup", None),
                                               pytest.param("mockup", 300, marks=pytest.mark.slow)])
def test_grid_is_symmetric_after_remesh_and_optimize(tmp_path, template, n_cells):
    """Symmetric at every size: the mock-up at 300 cells clusters a subdivision of its surface mesh,
    whose mirror mismatch is that of the surface, not of the finer mesh (it was not symmetric)."""
    project = _run(template, tmp_path / "out", n_cells)
    normals = [p.normal for p in project.field.symmetry_planes]
    assert len(normals) == 2
    for folder in ("04-remesh", "05-optimize"):
        grid = read_polymesh_obj(tmp_path / "out" / folder / "gridshell.obj")
        for normal in normals:
            assert _deviation(grid.nodes, grid.beam_lengths, normal) <= TOLERANCE, (folder, normal)
    import json

    record = json.loads((tmp_path / "out" / "05-optimize" / "optimize.json").read_text())["symmetry"]
    assert record["symmetric"] and len(record["deviation"]) == 2
    # and still close to the surface (issue 13: 0.5 % of the diagonal), measured by trimesh: made
    # symmetric after being brought to the closeness limit, the mock-up at 300 cells was at 0.507 %
    import trimesh

    surface = trimesh.load(tmp_path / "out" / "01-surface" / "surface.ply", process=False)
    triangles = surface.triangles
    near = cKDTree(triangles.mean(axis=1)).query(grid.nodes, k=16)[1]  # candidate triangles per node
    points = np.repeat(grid.nodes, near.shape[1], axis=0)
    closest = trimesh.triangles.closest_point(triangles[near.ravel()], points)
    distance = np.linalg.norm(closest - points, axis=1).reshape(near.shape).min(axis=1)
    assert distance.max() <= 0.005 * np.linalg.norm(np.ptp(surface.vertices, axis=0))


def test_without_planes_no_symmetry_step_runs(tmp_path, monkeypatch):
    """No plane: the remesh and optimiser never call the symmetry steps, and the records are as before."""
    import engine.geometry.symmetry as symmetry

    # imported before the patches: a module first imported under them would keep the refusing
    # stand-ins as its own names after the test (monkeypatch restores what it found)
    import engine.remeshing.optimize
    import engine.remeshing.voronoi
    import workflow.stages.optimize
    import workflow.stages.remesh

    def refuse(*args, **kwargs):
        raise AssertionError("a symmetry step ran without planes")

    for name in ("mirror_partners", "symmetrise_points", "symmetrised_grid", "symmetry_record"):
        monkeypatch.setattr(symmetry, name, refuse)
    for module in (engine.remeshing.voronoi, engine.remeshing.optimize, workflow.stages.remesh,
                   workflow.stages.optimize):
        for name in ("mirror_partners", "symmetrise_points", "symmetrised_grid", "symmetry_record"):
            if hasattr(module, name):
                monkeypatch.setattr(module, name, refuse)
    _run("cap", tmp_path / "out", 60, planes=False)
    import json

    assert "symmetry" not in json.loads((tmp_path / "out" / "04-remesh" / "remesh.json").read_text())
    assert "symmetry" not in json.loads((tmp_path / "out" / "05-optimize" / "optimize.json").read_text())


def _mirrored_height_field() -> tuple[TriMesh, GuidingField]:
    """z = f(x^2, y) on [-4, 4] x [0, 5] m, its triangles mirrored across x = 0 (checkerboard
    diagonals), and a field graded along x^2 and y."""
    nx, ny = 32, 20
    x, y = np.meshgrid(np.linspace(-4.0, 4.0, nx + 1), np.linspace(0.0, 5.0, ny + 1), indexing="ij")
    z = 1.5 - 0.05 * x**2 - 0.04 * (y - 2.0) ** 2 + 0.01 * x**2 * y
    mesh = TriMesh(vertices=np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1), faces=grid_triangles(nx, ny))
    v = mesh.vertices
    normals = mesh.vertex_normals
    direction = np.cross(normals, [0.0, 1.0, 0.0])
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    field = GuidingField(size=1.0 + 0.6 * (v[:, 0] / 4.0) ** 2 + 0.2 * v[:, 1] / 5.0,
                         anisotropy=np.full(len(v), 1.3), direction=direction, normals=normals)
    return mesh, field


def test_generated_symmetric_surface_with_one_plane():
    mesh, field = _mirrored_height_field()
    plane = ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))
    result = remesh(mesh, field, RemeshSettings(n_cells=50, symmetry_planes=(plane,)))
    grid = result.polymesh
    assert _deviation(grid.nodes, grid.beam_lengths, plane[1]) <= TOLERANCE
    assert result.quality["symmetry"]["symmetric"]
    optimised = optimize(grid, mesh, field, OptimizeSettings(iterations=20, symmetry_planes=(plane,))).polymesh
    assert _deviation(optimised.nodes, optimised.beam_lengths, plane[1]) <= TOLERANCE


def _interior_valence3_share(grid) -> float:
    """Share of the interior nodes (on no boundary loop) that end three beams, counted here."""
    degree = np.bincount(grid.edges.ravel(), minlength=len(grid.nodes))
    sides = np.sort(np.concatenate([np.stack([f, np.roll(f, -1)], axis=1) for f in grid.faces]), axis=1)
    keys, counts = np.unique(sides, axis=0, return_counts=True)
    boundary = np.zeros(len(grid.nodes), dtype=bool)
    boundary[keys[counts == 1].ravel()] = True  # ends of the sides of one cell only
    return float(np.mean(degree[~boundary] == 3))


@pytest.mark.parametrize("template, n_cells", [("mockup", None), ("cap", 60)])
def test_symmetric_grid_keeps_valence_three(tmp_path, template, n_cells):
    """Two mirrored pairs of cells in a row along a plane meet at a valence-4 node; the clustering
    puts a cell centred on the plane between them, so the interior nodes keep valence 3."""
    project = _run(template, tmp_path / "out", n_cells)
    normals = [p.normal for p in project.field.symmetry_planes]
    for folder in ("04-remesh", "05-optimize"):
        grid = read_polymesh_obj(tmp_path / "out" / folder / "gridshell.obj")
        assert _interior_valence3_share(grid) >= 0.95, folder
        for normal in normals:
            assert _deviation(grid.nodes, grid.beam_lengths, normal) <= TOLERANCE, (folder, normal)


@pytest.mark.parametrize("bad_call", [3, 25])
def test_a_step_that_leaves_the_reals_ends_the_optimisation_at_the_last_finite_grid(monkeypatch, bad_call):
    """A symmetrisation that returns NaN (at the 3rd call, in the iterations; at the 25th, past
    them) does not reach the grid: the optimiser keeps the last finite nodes, the quality says it
    stopped, and the optimize stage's test for an unsettled symmetric run sees it."""
    import engine.remeshing.optimize as optimize_module
    from workflow.stages.optimize import _unsettled

    mesh, field = _mirrored_height_field()
    plane = ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))
    grid = remesh(mesh, field, RemeshSettings(n_cells=30, symmetry_planes=(plane,))).polymesh
    real = optimize_module.symmetrise_points
    calls = {"n": 0}

    def failing(*args, **kwargs):
        calls["n"] += 1
        x = real(*args, **kwargs)
        if calls["n"] == bad_call:
            x[0] = np.nan
        return x

    monkeypatch.setattr(optimize_module, "symmetrise_points", failing)
    result = optimize(grid, mesh, field, OptimizeSettings(iterations=20, symmetry_planes=(plane,)))
    assert calls["n"] >= bad_call
    assert np.all(np.isfinite(result.polymesh.nodes))
    assert result.quality["stopped_non_finite"] and _unsettled(result)
    monkeypatch.setattr(optimize_module, "symmetrise_points", real)
    clean = optimize(grid, mesh, field, OptimizeSettings(iterations=20, symmetry_planes=(plane,)))
    assert not clean.quality["stopped_non_finite"] and not _unsettled(clean)


def test_node_normals_of_a_symmetric_grid_are_mirror_images_and_nearer_the_surface():
    """A grid symmetric about x = 0 and y = 0 on the paraboloid z = 1 - x^2 - y^2 / 2, its node
    normals read from a triangulation of the same surface without that symmetry (jittered
    vertices): with the symmetry planes, the normals of mirror-image nodes are mirror images
    (1e-12), those of nodes on a plane lie in it, and they are nearer the exact normal
    (2x, y, 1) / |.| than the nearest vertex's, on average."""
    from engine.mesh import PolyMesh
    from engine.structure.grid_model import node_normals

    surface = lambda x, y: 1.0 - x**2 - 0.5 * y**2  # noqa: E731
    rng = np.random.default_rng(3)
    u = np.linspace(-1.0, 1.0, 41)
    x, y = np.meshgrid(u, u, indexing="ij")
    plan = np.column_stack([x.ravel(), y.ravel()]) + rng.uniform(-0.02, 0.02, (x.size, 2))
    plan = np.clip(plan, -1.0, 1.0)
    reference = TriMesh(vertices=np.column_stack([plan, surface(*plan.T)]), faces=grid_triangles(40, 40))
    g = np.linspace(-0.9, 0.9, 7)                       # quads, symmetric about both planes
    gx, gy = np.meshgrid(g, g, indexing="ij")
    nodes = np.column_stack([gx.ravel(), gy.ravel(), surface(gx.ravel(), gy.ravel())])
    faces = tuple(np.array([i * 7 + j, (i + 1) * 7 + j, (i + 1) * 7 + j + 1, i * 7 + j + 1])
                  for i in range(6) for j in range(6))
    grid = PolyMesh(nodes=nodes, faces=faces)
    planes = (((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)), ((0.0, 0.0, 0.0), (0.0, 1.0, 0.0)))
    raw, symmetric = node_normals(grid, reference), node_normals(grid, reference, symmetry_planes=planes)
    index = {tuple(np.round(p[:2], 6)): k for k, p in enumerate(nodes)}
    for k, p in enumerate(nodes):
        for sx, sy in ((-1, 1), (1, -1), (-1, -1)):
            twin = index[(round(sx * p[0], 6) + 0.0, round(sy * p[1], 6) + 0.0)]
            assert np.allclose(symmetric[twin], symmetric[k] * [sx, sy, 1], atol=1e-12)
    assert np.allclose(symmetric[np.isclose(nodes[:, 0], 0.0), 0], 0.0, atol=1e-12)
    exact = np.column_stack([2 * nodes[:, 0], nodes[:, 1], np.ones(len(nodes))])
    exact /= np.linalg.norm(exact, axis=1)[:, None]
    error = lambda normals: np.degrees(np.arccos(np.clip(np.sum(normals * exact, axis=1), -1, 1))).mean()  # noqa: E731
    assert not np.allclose(raw, symmetric) and error(symmetric) < error(raw)


def test_a_plane_the_surface_is_not_symmetric_about_is_refused_naming_a_plane_that_is(tmp_path, capsys):
    """The cap modelled 5 m off the origin with its planes left through the origin: the field was
    averaged with the mirror images of unrelated points and the grid made without symmetry, without
    a word. validate and run now stop with one message naming [field] symmetry_planes[0], the gap
    measured here by reflecting the vertices, and the plane through the surface's centre, about
    which it is symmetric."""
    from engine.geometry.parametric import cap
    from workflow.cli import main

    mesh = cap(span=20.0, span_to_rise=21.43, rings=12)
    moved = mesh.vertices + [5.0, 0.0, 0.0]
    path = tmp_path / "cap.obj"
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in moved)
                    + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.faces))
    text = (resources.files("templates") / "cap.toml").read_text(encoding="utf-8")
    surface = text[text.index("[surface]"):text.index("[[supports]]")]
    project = tmp_path / "project.toml"
    project.write_text(text.replace(surface, f'[surface]\nfile = "{path}"\n\n'), encoding="utf-8")
    gap = cKDTree(moved).query(moved * [-1.0, 1.0, 1.0])[0].max()
    for command in (["validate", str(project)], ["run", str(project), "--out", str(tmp_path / "out"), "--quiet"]):
        assert main(command) == 2
        err = capsys.readouterr().err
        assert "Traceback" not in err and err.count("error:") == 1, err
        assert "[field] symmetry_planes[0]" in err and f"{gap:.3g} m" in err
        assert "point = [5.000, 0.000," in err


def test_a_symmetric_surface_meshed_otherwise_gets_a_grid_of_its_own_and_a_finding(tmp_path):
    """The cap turned 7 degrees about its axis is still symmetric about both planes, but its mesh
    is not its own mirror image vertex by vertex, which the remesher needs: the run goes on (the
    surface passes the field's check), and the grid, not symmetric (measured here), comes with the
    grid_not_symmetric finding naming the keys."""
    from engine.geometry.parametric import cap

    mesh = cap(span=20.0, span_to_rise=21.43, rings=8)
    a = np.radians(7.0)
    turned = mesh.vertices @ np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]).T
    path = tmp_path / "cap.obj"
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in turned)
                    + "".join(f"f {p + 1} {q + 1} {r + 1}\n" for p, q, r in mesh.faces))
    template = load_project(resources.files("templates") / "cap.toml")
    project = template.model_copy(update={
        "surface": template.surface.model_copy(update={"template": None, "parameters": {}, "file": str(path)}),
        "remesh": template.remesh.model_copy(update={"n_cells": 40})})
    out = tmp_path / "out"
    summary = run_project(project, out, STAGES, until="remesh", progress=Progress(enabled=False))
    assert summary.message is None, summary.message
    grid = read_polymesh_obj(out / "04-remesh" / "gridshell.obj")
    deviations = [_deviation(grid.nodes, grid.beam_lengths, p.normal) for p in project.field.symmetry_planes]
    assert max(deviations) > TOLERANCE
    finding = next(f for f in summary.findings if f["kind"] == "grid_not_symmetric")
    assert finding["measure"] == pytest.approx(max(deviations), rel=1e-6)
    assert "[field] symmetry_planes" in finding["fix"]
