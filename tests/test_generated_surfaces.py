"""The seeded roof generator (tests/generated_surfaces.py): valid meshes, supports, determinism, PLY files."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from .generated_surfaces import KINDS, SUPPORT_PATTERNS, generate_surface, surfaces, write_ply

SEEDS = range(25)


@functools.lru_cache(maxsize=None)
def _surface(seed: int):
    return generate_surface(seed)


def _edge_counts(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    return np.unique(edges, axis=0, return_counts=True)


def _boundary_loops(faces: np.ndarray, n_vertices: int) -> list[np.ndarray]:
    """Vertex ids of each boundary loop, found as the components of the boundary-edge graph."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    edges, counts = _edge_counts(faces)
    boundary = edges[counts == 1]
    degree = np.bincount(boundary.ravel(), minlength=n_vertices)
    assert set(np.unique(degree)) <= {0, 2}, "a boundary vertex is not on exactly one simple loop"
    graph = coo_matrix((np.ones(len(boundary)), (boundary[:, 0], boundary[:, 1])), shape=(n_vertices, n_vertices))
    _, labels = connected_components(graph, directed=False)
    on = np.flatnonzero(degree > 0)
    return [on[labels[on] == label] for label in np.unique(labels[on])]


def _plan_area(vertices: np.ndarray, faces: np.ndarray) -> float:
    p = vertices[faces][:, :, :2]
    return float(0.5 * np.abs(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])).sum())


@pytest.mark.parametrize("seed", SEEDS)
def test_manifold_disc_or_annulus(seed):
    import trimesh

    s = _surface(seed)
    assert s.vertices.dtype == np.float64 and s.vertices.shape[1] == 3
    assert s.faces.dtype == np.int64 and s.faces.shape[1] == 3
    assert s.flagged.dtype == bool and s.flagged.shape == (len(s.vertices),)
    assert s.name == f"gen{seed:02d}-{s.kind}" and s.kind in KINDS
    mesh = trimesh.Trimesh(s.vertices, s.faces, process=False)
    assert mesh.is_winding_consistent
    _, counts = _edge_counts(s.faces)
    assert counts.max() <= 2
    components = trimesh.graph.connected_components(mesh.face_adjacency, nodes=np.arange(len(s.faces)), min_len=1)
    assert len(components) == 1
    assert np.array_equal(np.unique(s.faces), np.arange(len(s.vertices))), "unused vertices"
    loops = _boundary_loops(s.faces, len(s.vertices))
    assert (s.n_holes >= 1) == (s.kind == "hole")
    assert len(loops) == 1 + s.n_holes
    euler = len(s.vertices) - len(counts) + len(s.faces)
    assert euler == 1 - s.n_holes          # disc: 1, annulus: 0, two holes: -1


@pytest.mark.parametrize("seed", SEEDS)
def test_triangle_quality_and_orientation(seed):
    import trimesh

    s = _surface(seed)
    mesh = trimesh.Trimesh(s.vertices, s.faces, process=False)
    assert np.degrees(mesh.face_angles.min()) > 15.0
    assert (mesh.face_normals[:, 2] > 0).all(), "normals must point up"
    assert (mesh.area_faces > 0).all()


@pytest.mark.parametrize("seed", SEEDS)
def test_size_span_and_rise(seed):
    s = _surface(seed)
    assert 1350 <= len(s.vertices) <= 1650
    extent = np.ptp(s.vertices[:, :2], axis=0).max()
    assert extent == pytest.approx(s.span_m, rel=0.05)
    assert 4.5 <= extent <= 63.0
    rise = np.ptp(s.vertices[:, 2])
    assert rise == pytest.approx(s.rise_m)
    assert 0.05 - 1e-9 <= rise / s.span_m <= 0.35 + 1e-9


@pytest.mark.parametrize("seed", SEEDS)
def test_supports(seed):
    s = _surface(seed)
    assert s.flagged.sum() > 0
    loops = _boundary_loops(s.faces, len(s.vertices))
    boundary = np.concatenate(loops)
    assert not s.flagged[np.setdiff1d(np.arange(len(s.vertices)), boundary)].any(), "an interior vertex is flagged"
    outer = max(loops, key=lambda ids: np.ptp(s.vertices[ids, :2], axis=0).prod())
    holes = np.setdiff1d(boundary, outer)
    if s.supports == "all_boundary":
        assert s.flagged[boundary].all()
    elif s.supports == "outer_boundary":
        assert s.flagged[outer].all() and not s.flagged[holes].any()
    elif s.supports == "stretches":
        assert s.flagged[outer].mean() >= 0.40
        assert not s.flagged[holes].any()
    else:
        assert s.supports == "points"
        assert 3 * 3 <= s.flagged.sum() <= 0.5 * len(outer)
        flagged_xy = s.vertices[s.flagged, :2]
        assert np.ptp(flagged_xy, axis=0).min() > 0.2 * s.span_m, "point zones must not be collinear"


def test_every_kind_and_support_pattern_is_covered():
    assert {_surface(seed).kind for seed in range(5)} == set(KINDS)
    assert {(_surface(seed).kind, _surface(seed).supports) for seed in range(20)} == {
        (kind, pattern) for kind in KINDS for pattern in SUPPORT_PATTERNS}
    assert any(_surface(seed).n_holes == 2 for seed in SEEDS) and any(_surface(seed).n_holes == 1 for seed in SEEDS)
    assert len({_surface(seed).outline for seed in SEEDS}) == 4
    assert [s.name for s in surfaces(3)] == [_surface(seed).name for seed in range(3)]


def _quadratic_fit(s):
    x, y, z = s.vertices.T
    x, y = x - x.mean(), y - y.mean()
    a, b, c, *_ = np.linalg.lstsq(np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=1), z, rcond=None)[0]
    return a, b, c


@pytest.mark.parametrize("seed", [0, 5, 10, 15, 20])
def test_dome_is_synclastic(seed):
    s = _surface(seed)
    assert s.kind == "dome"
    a, b, c = _quadratic_fit(s)
    assert a < 0 and c < 0 and 4 * a * c - b * b > 0
    outer = max(_boundary_loops(s.faces, len(s.vertices)), key=len)
    assert np.allclose(s.vertices[outer, 2], 0.0)


@pytest.mark.parametrize("seed", [1, 6, 11, 16, 21])
def test_saddle_is_anticlastic(seed):
    s = _surface(seed)
    assert s.kind == "saddle"
    a, b, c = _quadratic_fit(s)
    assert 4 * a * c - b * b < 0


def test_deterministic_and_options():
    first, again = generate_surface(7), generate_surface(7)
    for name in ("vertices", "faces", "flagged"):
        assert np.array_equal(getattr(first, name), getattr(again, name))
        assert not getattr(first, name).flags.writeable
    assert ((first.name, first.kind, first.supports, first.span_m)
            == (again.name, again.kind, again.supports, again.span_m))
    assert not np.array_equal(generate_surface(8).vertices[:10], first.vertices[:10])
    chosen = generate_surface(3, kind="hole", span_m=12.0, n_vertices=600)
    assert chosen.kind == "hole" and chosen.name == "gen03-hole" and chosen.n_holes >= 1
    assert np.ptp(chosen.vertices[:, :2], axis=0).max() == pytest.approx(12.0, rel=0.05)
    assert 500 <= len(chosen.vertices) <= 700
    with pytest.raises(ValueError):
        generate_surface(0, kind="pyramid")


@pytest.mark.parametrize("seed", [0, 4, 9, 14, 18])
def test_ply_round_trip(seed, tmp_path):
    import trimesh

    from workflow.surface_io import read_surface

    s = _surface(seed)
    path = write_ply(s, tmp_path / f"{s.name}.ply")
    vertices, faces, flagged = read_surface(path)
    assert np.allclose(vertices, s.vertices, rtol=0, atol=1e-6 * s.span_m)
    assert np.array_equal(faces, s.faces)
    assert np.array_equal(flagged, s.flagged)
    loaded = trimesh.load(path, process=False)
    assert isinstance(loaded, trimesh.Trimesh)
    assert loaded.vertices.shape == s.vertices.shape and np.array_equal(loaded.faces, s.faces)
    red = (loaded.visual.vertex_colors[:, :3] == [255, 0, 0]).all(axis=1)
    assert np.array_equal(red, s.flagged)
    assert trimesh.load(path).is_winding_consistent


@pytest.mark.parametrize("seed", [4, 9])
def test_product_cleaning_changes_nothing(seed):
    """The product's mesh cleaning finds nothing to merge, drop or flip, and the loops of a courtyard roof."""
    from engine.geometry.surfaces import clean_mesh

    s = _surface(seed)
    mesh, report = clean_mesh(s.vertices, s.faces, s.flagged)
    assert (report.merged_vertices, report.degenerate_faces, report.duplicate_faces, report.unused_vertices,
            report.flipped_faces) == (0, 0, 0, 0, 0)
    assert report.patches == 1 and report.boundary_loops == 1 + s.n_holes
    assert mesh.n_vertices == len(s.vertices) and mesh.n_faces == len(s.faces)
    assert np.array_equal(np.asarray(mesh.flagged), s.flagged)
