"""Statics-aware Voronoi remeshing: hexagon share, valence, size and aspect against D and A,
size targets, several boundary loops, corners, extreme settings."""

from __future__ import annotations

import numpy as np
import pytest

from engine.errors import GridshellError, InputError
from engine.field import GuidingField
from engine.mesh import TriMesh
from engine.parametric import courtyard, grid_triangles
from engine.voronoi import RemeshSettings, remesh, surface_corners


def _square(n: int = 20, side: float = 2.0) -> TriMesh:
    xs = np.linspace(-side / 2, side / 2, n + 1)
    x, y = np.meshgrid(xs, xs, indexing="ij")
    return TriMesh(vertices=np.c_[x.ravel(), y.ravel(), np.zeros(x.size)], faces=grid_triangles(n, n))


def _field(mesh: TriMesh, size=None, aspect=None, direction=(1.0, 0.0, 0.0)) -> GuidingField:
    n = mesh.n_vertices
    return GuidingField(size=np.ones(n) if size is None else size, anisotropy=np.ones(n) if aspect is None else aspect,
                        direction=np.tile(direction, (n, 1)), normals=mesh.vertex_normals)


def _check_valid(polymesh) -> None:
    for face in polymesh.faces:
        assert len(face) >= 3 and len(set(face.tolist())) == len(face), "every face is a simple node loop"
    edges = polymesh.edges
    assert len(np.unique(edges, axis=0)) == len(edges)
    assert polymesh.beam_lengths.min() > 0
    # every beam is used by one or two cells and consistently oriented (opposite directions)
    directed = np.concatenate([np.stack([f, np.roll(f, -1)], axis=1) for f in polymesh.faces])
    as_set = {tuple(d) for d in directed.tolist()}
    assert len(as_set) == len(directed), "no directed edge appears twice: faces are consistently oriented"


def test_voro_1_1_on_a_flat_square_is_hexagonal():
    mesh = _square()
    result = remesh(mesh, _field(mesh), RemeshSettings(n_cells=150, lloyd_iterations=80))
    _check_valid(result.polymesh)
    q = result.quality
    assert q["hexagon_share_interior"] >= 0.85
    assert q["valence3_share_interior"] == 1.0
    assert q["n_faces"] == pytest.approx(150, abs=3)
    assert q["closeness_max_rel"] < 1e-9
    # corners of the square kept as nodes
    corners = result.polymesh.nodes[result.polymesh.corners]
    assert len(corners) == 4 and np.allclose(np.sort(np.abs(corners[:, :2]).ravel()), 1.0)


def test_graded_anisotropic_field_reaches_D_and_A():
    """Size rising 1 -> D across x, aspect A along x everywhere: achieved within 25 % of both."""
    mesh = _square(24, side=4.0)
    D, A = 2.0, 2.0
    x = mesh.vertices[:, 0]
    size = 1.0 + (D - 1.0) * (x - x.min()) / np.ptp(x)
    field = _field(mesh, size=size, aspect=np.full(mesh.n_vertices, A))
    result = remesh(mesh, field, RemeshSettings(n_cells=220, lloyd_iterations=80))
    _check_valid(result.polymesh)
    q = result.quality
    assert q["hexagon_share_interior"] >= 0.70
    assert q["valence3_share_interior"] == 1.0
    assert abs(q["achieved_size_ratio"] / D - 1) <= 0.25
    assert abs(q["achieved_max_aspect"] / A - 1) <= 0.25
    assert q["size_correlation"] > 0.8
    # cells are elongated along the field's direction (x)
    elongation = []
    for face in result.polymesh.faces:
        p = result.polymesh.nodes[face, :2]
        spread = np.ptp(p, axis=0)
        elongation.append(spread[0] / spread[1])
    assert np.median(elongation) > 1.2


def test_total_length_target_met_within_one_percent():
    mesh = _square()
    target = 30.0
    result = remesh(mesh, _field(mesh), RemeshSettings(total_length=target, lloyd_iterations=20))
    assert result.polymesh.total_length == pytest.approx(target, rel=0.01)


def test_courtyard_with_two_boundary_loops():
    mesh = courtyard()
    result = remesh(mesh, _field(mesh), RemeshSettings(n_cells=120, lloyd_iterations=20))
    polymesh = result.polymesh
    _check_valid(polymesh)
    V, E, F = polymesh.n_nodes, len(polymesh.edges), polymesh.n_faces
    assert V - E + F == 0, "Euler characteristic of an annulus (two boundary loops)"
    assert np.sum(polymesh.corners) == len(surface_corners(mesh)) == 8


def test_extreme_settings_give_a_valid_mesh_or_a_clear_error():
    mesh = _square(24, side=4.0)
    x = mesh.vertices[:, 0]
    field = _field(mesh, size=1.0 + 4.0 * (x - x.min()) / np.ptp(x), aspect=np.full(mesh.n_vertices, 5.0),
                   direction=(0.6, 0.8, 0.0))
    try:
        result = remesh(mesh, field, RemeshSettings(n_cells=120, lloyd_iterations=20))
    except GridshellError as exc:
        assert "lower" in (exc.hint or str(exc))
    else:
        _check_valid(result.polymesh)


def test_one_size_target_only():
    with pytest.raises(InputError, match="exactly one"):
        RemeshSettings(n_cells=10, total_length=3.0)
