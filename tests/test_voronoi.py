"""Statics-aware Voronoi remeshing: hexagon share, valence, size and aspect against D and A,
size targets, several boundary loops, corners, extreme settings; the clustering's closed-form
energy and incremental updates, connectivity of its clusters."""

from __future__ import annotations

import numpy as np
import pytest

from engine.errors import GridshellError, InputError
from engine.geometry.fine_mesh import surface_corners
from engine.geometry.parametric import courtyard, grid_triangles
from engine.mesh import TriMesh
from engine.remeshing.field import GuidingField
from engine.remeshing.voronoi import RemeshSettings, remesh


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
    # no near-zero beams: those under 2 % of the local cell size are collapsed
    assert polymesh.beam_lengths.min() > 0.01 * polymesh.beam_lengths.mean()
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
    assert q["n_faces"] == 150
    assert q["closeness_max_rel"] < 1e-9
    # corners of the square kept as nodes
    corners = result.polymesh.nodes[result.polymesh.corners]
    assert len(corners) == 4 and np.allclose(np.sort(np.abs(corners[:, :2]).ravel()), 1.0)
    # boundary nodes lie on the square's edges, and every node on an edge is a boundary node
    nodes = result.polymesh.nodes
    on_edge = np.isclose(np.abs(nodes[:, :2]).max(axis=1), 1.0)
    assert np.array_equal(on_edge, result.polymesh.boundary)
    assert on_edge.sum() > 4 * np.sqrt(150) / 2, "cell borders meet the boundary at nodes"


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
    assert 0.8 <= q["size_grading_slope"] <= 1.25, "achieved size follows h (log-log slope near 1)"
    # cells are elongated along the field's direction (x)
    elongation = []
    for face in result.polymesh.faces:
        p = result.polymesh.nodes[face, :2]
        spread = np.ptp(p, axis=0)
        elongation.append(spread[0] / spread[1])
    assert np.median(elongation) > 1.2


def test_sixty_cells_follow_a_field_graded_on_their_scale_and_report_the_span_they_see():
    """A 6 m square at 60 cells (as few as issue 13's smallest runs), isotropic field h = 2^(x/6):
    a size gradient over the whole width, so the interior cells (about 4 cells across) see the
    field's sizes at their centroids spread by about 2^(3.5/6) = 1.5 (p95/p5), and cells following
    h give achieved sizes with a correlation over 0.9 and a log-log slope of 1 (0.8-1.25)."""
    mesh = _square(30, side=6.0)
    x = mesh.vertices[:, 0] - mesh.vertices[:, 0].min()
    result = remesh(mesh, _field(mesh, size=2.0 ** (x / 6.0)), RemeshSettings(n_cells=60))
    q = result.quality
    assert 1.3 <= q["field_size_span_cells"] <= 1.8
    assert q["size_correlation"] > 0.9
    assert q["size_rank_correlation"] > 0.9      # issue 13's measure: ranks, on the same cells
    assert 0.8 <= q["size_grading_slope"] <= 1.25


def test_a_field_graded_only_along_the_boundary_shows_no_span_at_the_interior_cells():
    """The real roofs' fields vary most within a cell of their supports: here the size rises from 1
    to 2 within 0.3 m of one edge of a 6 m square cut into 60 cells (cells about 0.8 m across,
    interior centroids over half a cell from the edge). The field spans 2, the interior cells on
    which the correlation is measured see 1: the span reported says no grading can show there."""
    mesh = _square(30, side=6.0)
    x = mesh.vertices[:, 0] - mesh.vertices[:, 0].min()
    result = remesh(mesh, _field(mesh, size=1.0 + np.clip(x / 0.3, 0.0, 1.0)), RemeshSettings(n_cells=60))
    q = result.quality
    assert q["field_size_ratio"] == pytest.approx(2.0)
    assert q["field_size_span_cells"] < 1.05


def test_total_length_target_met_within_one_percent():
    mesh = _square()
    target = 30.0
    result = remesh(mesh, _field(mesh), RemeshSettings(total_length=target, lloyd_iterations=20))
    assert result.polymesh.total_length == pytest.approx(target, rel=0.01)


def _graded_square():
    """A 4 m square with a field graded along x (D = 2) and a uniform aspect of 2."""
    mesh = _square(24, side=4.0)
    x = mesh.vertices[:, 0]
    return mesh, _field(mesh, size=1.0 + (x - x.min()) / np.ptp(x), aspect=np.full(mesh.n_vertices, 2.0))


@pytest.mark.parametrize("length", [0.2, 0.35])
def test_mean_beam_length_target_met_within_one_percent(length):
    mesh, field = _graded_square()
    result = remesh(mesh, field, RemeshSettings(mean_beam_length=length))
    assert result.polymesh.beam_lengths.mean() == pytest.approx(length, rel=0.01)


@pytest.mark.parametrize("n_cells", [40, 333])
def test_cell_count_target_met_within_one_percent(n_cells):
    mesh, field = _graded_square()
    result = remesh(mesh, field, RemeshSettings(n_cells=n_cells))
    assert result.quality["n_faces"] == pytest.approx(n_cells, rel=0.01)


def test_fine_surface_is_clustered_as_it_is_and_coarse_one_refined():
    from engine.geometry.fine_mesh import VERTICES_PER_CELL, _refine

    mesh = _square(40)  # 1681 vertices
    field = _field(mesh)
    assert len(_refine(mesh, field, n_cells=1681 // VERTICES_PER_CELL).vertices) == mesh.n_vertices
    assert len(_refine(mesh, field, n_cells=1681 // VERTICES_PER_CELL + 10).vertices) == 6561


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
        q = result.quality
        assert q["valence3_share_interior"] == 1.0
        assert abs(q["achieved_size_ratio"] / 5.0 - 1) <= 0.25
        assert abs(q["achieved_max_aspect"] / 5.0 - 1) <= 0.25


def test_one_size_target_only():
    with pytest.raises(InputError, match="exactly one"):
        RemeshSettings(n_cells=10, total_length=3.0)


def _clustering_problem(seed: int = 3):
    """A curved patch with random positive weights, anisotropic metrics, 12 grown clusters."""
    from engine.geometry.fine_mesh import _edges_of, _refine
    from engine.remeshing.clustering import mesh_adjacency

    rng = np.random.default_rng(seed)
    mesh = _square(16)
    vertices = mesh.vertices + np.c_[np.zeros((mesh.n_vertices, 2)), 0.2 * mesh.vertices[:, 0] ** 2]
    mesh = TriMesh(vertices=vertices, faces=mesh.faces)
    field = _field(mesh, size=rng.uniform(0.5, 1.5, mesh.n_vertices), aspect=rng.uniform(1.0, 3.0, mesh.n_vertices),
                   direction=(0.6, 0.8, 0.0))
    fine = _refine(mesh, field, n_cells=4)
    edges, _, _ = _edges_of(fine.faces, len(fine.vertices))
    seeds = rng.choice(len(fine.vertices), 12, replace=False)
    from engine.remeshing.voronoi import _grow_clusters

    labels = _grow_clusters(fine, seeds)
    weights = fine.areas * rng.uniform(0.5, 2.0, len(fine.vertices))
    return fine, edges, mesh_adjacency(len(fine.vertices), fine.faces, edges), weights, labels


def test_cluster_energy_closed_form_is_the_minimum_over_the_centroid():
    """S3 - S2^T S1^-1 S2 equals sum w (x - c)^T M (x - c) at c = S1^-1 S2, and no other c does better."""
    from engine.remeshing.clustering import _accumulate, centroids_of, cluster_energy, vertex_moments

    fine, _, _, weights, labels = _clustering_problem()
    energy = cluster_energy(fine.vertices, fine.metric, weights, labels, 12)
    S, _ = _accumulate(labels, vertex_moments(fine.vertices, fine.metric, weights), 12)
    centroids = centroids_of(S)
    rng = np.random.default_rng(0)
    for k in range(12):
        members = labels == k
        x, M, w = fine.vertices[members], fine.metric[members], weights[members]

        def direct(c):
            d = x - c
            return float(np.sum(w * np.einsum("ni,nij,nj->n", d, M, d)))

        assert energy[k] == pytest.approx(direct(centroids[k]), rel=1e-9)
        for _ in range(5):
            assert direct(centroids[k] + 1e-3 * rng.normal(size=3)) > energy[k]


def test_label_pieces_counts_what_scipy_finds_in_the_graph_of_edges_inside_clusters():
    """The compiled count of the clusters' connected pieces equals scipy's connected components of
    the graph of mesh edges whose ends share a label: on grown clusters (one piece each), on random
    labels (many pieces) and on clusters with a far vertex relabelled (one cluster split)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from engine.remeshing.clustering import label_pieces

    fine, edges, _, _, grown = _clustering_problem()
    rng = np.random.default_rng(3)
    split = grown.copy()
    split[np.flatnonzero(grown == 0)[-1]] = 1

    def by_scipy(labels):
        same = labels[edges[:, 0]] == labels[edges[:, 1]]
        graph = coo_matrix((np.ones(int(same.sum())), (edges[same, 0], edges[same, 1])), shape=(len(labels),) * 2)
        return connected_components(graph, directed=False)[0]

    for labels in (grown, rng.integers(0, 5, len(fine.vertices)), split):
        assert label_pieces(labels, edges) == by_scipy(labels)
    assert label_pieces(grown, edges) == 12


def test_clustering_lowers_the_energy_keeps_clusters_connected_and_its_running_moments_agree():
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    from engine.remeshing.clustering import cluster_energy, cluster_vertices

    fine, edges, adjacency, weights, labels = _clustering_problem()
    before = cluster_energy(fine.vertices, fine.metric, weights, labels, 12).sum()
    result = cluster_vertices(fine.vertices, fine.faces, edges, adjacency, fine.metric, weights, labels, 12)
    after = cluster_energy(fine.vertices, fine.metric, weights, result.labels, 12)
    assert result.sweeps >= 2 and result.moves[0] > 0 and result.moves[-1] == 0
    assert after.sum() < before
    # the energies the sweeps kept up to date by O(1) moves agree with a recomputation from the labels
    np.testing.assert_allclose(result.energy, after, rtol=1e-7, atol=1e-12 * after.sum())
    for k in range(12):
        members = np.flatnonzero(result.labels == k)
        assert len(members) > 0
        inside = np.isin(edges, members).all(axis=1)
        n = len(fine.vertices)
        graph = csr_matrix((np.ones(inside.sum()), (edges[inside, 0], edges[inside, 1])), shape=(n, n))
        _, component = connected_components(graph, directed=False)
        assert len(np.unique(component[members])) == 1, f"cluster {k} is connected"


def test_vectorised_quality_figures_match_a_per_face_loop():
    from engine.mesh import best_fit_plane
    from engine.remeshing.grid_quality import polymesh_quality

    mesh = _square(24, side=4.0)
    x = mesh.vertices[:, 0]
    field = _field(mesh, size=1.0 + (x - x.min()) / np.ptp(x), aspect=np.full(mesh.n_vertices, 2.0))
    polymesh = remesh(mesh, field, RemeshSettings(n_cells=120)).polymesh
    # lift the nodes off the plane so that planarity is not zero
    nodes = polymesh.nodes.copy()
    nodes[:, 2] = 0.05 * np.sin(3 * nodes[:, 0]) * np.cos(2 * nodes[:, 1])
    polymesh = polymesh.replace_nodes(nodes)
    q = polymesh_quality(polymesh)
    aspects, planarity, angles, regularity = [], [], [], []
    for face in polymesh.faces:
        p = polymesh.nodes[face]
        centred = p - p.mean(axis=0)
        _, s, vt = np.linalg.svd(centred, full_matrices=False)
        aspects.append(s[0] / s[1])
        c, n = best_fit_plane(p)
        planarity.append(np.abs((p - c) @ n).max() if len(face) > 3 else 0.0)
        for i in range(len(face)):
            a, b = p[i - 1] - p[i], p[(i + 1) % len(face)] - p[i]
            angles.append(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))
        local = centred @ vt[:2].T
        spread = np.sqrt(np.linalg.svd(local, compute_uv=False))
        unstretched = local / spread * spread.mean()
        edges = np.linalg.norm(unstretched - np.roll(unstretched, -1, axis=0), axis=1)
        regularity.append(edges.std() / edges.mean())
    interior = ~polymesh.face_boundary
    assert q["achieved_max_aspect"] == pytest.approx(np.percentile(np.array(aspects)[interior], 95), rel=1e-9)
    assert q["planarity_max_m"] == pytest.approx(max(planarity), rel=1e-9)
    assert q["smallest_angle_deg"] == pytest.approx(min(angles), rel=1e-9)
    assert q["regularity"] == pytest.approx(np.mean(regularity), rel=1e-9)


def test_cluster_adjacency_hexagon_share_is_the_grids():
    """The share the choice among candidate clusterings ranks by (interior clusters with six
    neighbouring clusters) equals the extracted grid's hexagon share of interior cells."""
    from dataclasses import replace

    from engine.geometry.fine_mesh import _refine
    from engine.remeshing.cell_extraction import _polygons
    from engine.remeshing.voronoi import _cluster, _interior_hexagon_share

    mesh = _square(20, side=4.0)
    x = mesh.vertices[:, 0]
    field = _field(mesh, size=1.0 + (x - x.min()) / np.ptp(x), aspect=np.full(mesh.n_vertices, 2.0))
    fine = _refine(mesh, field, n_cells=60)
    checked = 0
    for seed in range(3):
        for clusters in _cluster(fine, 60, replace(RemeshSettings(n_cells=60), seed=seed), keep=3):
            polymesh = _polygons(mesh, fine, clusters.labels, clusters.centroids, None)
            interior = ~polymesh.face_boundary
            assert clusters.hexagon_share == _interior_hexagon_share(fine, clusters.labels, 60)
            assert clusters.hexagon_share == pytest.approx(np.mean(polymesh.face_degrees[interior] == 6), abs=1e-12)
            checked += 1
    assert checked == 9


@pytest.fixture(scope="module")
def wave_roof():
    """The Wave roof (real surface, flagged supports) with its guiding field, as the stages make them."""
    from .conftest import SURFACE_FILES

    path = next((p for p in SURFACE_FILES if p.stem == "Wave"), None)
    if path is None:
        pytest.skip("no Wave.ply in the surfaces folder")
    from engine.remeshing.field import guiding_field
    from engine.structure.shell import ShellMaterial, analyse_shell, shell_nodal_loads
    from workflow.config import project_from_surface
    from workflow.stages.shell import notional_thickness, shell_load_case
    from workflow.stages.surface import build_surface, resolve_loads, resolve_supports

    project = project_from_surface(str(path), "flagged")
    mesh, _ = build_surface(project)
    supports = resolve_supports(mesh, project.supports)
    cases, combinations = resolve_loads(mesh, project)
    thickness = notional_thickness(project, mesh)
    loads = shell_nodal_loads(mesh, shell_load_case(project, cases, combinations), thickness=thickness,
                              density=project.shell.density)
    material = ShellMaterial(E=project.shell.E, nu=project.shell.nu, density=project.shell.density)
    shell = analyse_shell(mesh, supports, loads, thickness=thickness, material=material)
    support_vertices = np.zeros(mesh.n_vertices, dtype=bool)
    support_vertices[supports.nodes] = True
    return mesh, guiding_field(mesh, shell.vertex_membrane_forces, project.field.to_settings()), support_vertices, \
        project.remesh.to_settings()


@pytest.mark.parametrize("seed", [0, 1])
def test_default_cell_count_on_a_real_roof_meets_the_targets(wave_roof, seed):
    """Issue 4's targets at the project default (120 cells) on the roof whose seed-0 grid had 65.7 %
    hexagons when only the last Lloyd step of each start was a candidate."""
    from dataclasses import replace

    mesh, field, support_vertices, settings = wave_roof
    assert settings.n_cells == 120
    result = remesh(mesh, field, replace(settings, seed=seed), support_vertices=support_vertices)
    _check_valid(result.polymesh)
    q = result.quality
    assert q["hexagon_share_interior"] >= 0.70
    assert q["valence3_share_interior"] == 1.0
    assert abs(q["achieved_size_ratio"] / q["field_size_ratio"] - 1) <= 0.25
    assert abs(q["achieved_max_aspect"] / q["field_max_aspect"] - 1) <= 0.25


@pytest.mark.parametrize("seed, n_cells", [(4, 6), (4, 14), (14, 12), (39, 14), (29, 6)])
def test_a_hole_smaller_than_the_cells_round_it_is_met_by_several_cells(seed, n_cells):
    """A courtyard that one cell would wrap (a round hole among large cells) is cut into wedges, so
    the grid is still a valid polygon mesh with the surface's topology: V - E + F = 1 - holes."""
    from tests.generated_surfaces import generate_surface

    surface = generate_surface(seed)
    assert surface.kind == "hole" and surface.n_holes >= 1
    mesh = TriMesh(vertices=surface.vertices, faces=surface.faces)
    result = remesh(mesh, _field(mesh), RemeshSettings(n_cells=n_cells, lloyd_iterations=20))
    polymesh = result.polymesh
    _check_valid(polymesh)
    V, E, F = polymesh.n_nodes, len(polymesh.edges), polymesh.n_faces
    assert V - E + F == 1 - surface.n_holes


def test_candidates_are_compared_as_the_caller_will_build_them():
    """Where several candidate grids are made, the remesher ranks them by what ``buildable`` makes
    of each (collapses cost hexagons and three-beam nodes), and returns the winner as extracted."""
    from engine.remeshing.collapse import collapse_short_beams

    mesh = _square(24)
    field = _field(mesh, size=1.0 + mesh.vertices[:, 0] + 1.0)
    settings = RemeshSettings(n_cells=40)
    seen: list = []

    def record(grid):
        seen.append(grid)
        return grid

    plain = remesh(mesh, field, settings).polymesh
    same = remesh(mesh, field, settings, buildable=record).polymesh
    assert np.array_equal(same.nodes, plain.nodes), "a buildable that changes nothing changes no choice"
    assert len(seen) >= 2, "the square at 40 cells makes several candidates"
    favoured = len(seen) // 2 if len(seen) > 2 else 1  # not the one chosen without it, if it was first
    calls: list = []

    def spoil_all_but_one(grid):
        # every other candidate as if half its beams were too short: collapsed into four-beam nodes
        calls.append(grid)
        if len(calls) - 1 == favoured:
            return grid
        long = np.quantile(grid.beam_lengths, 0.5)
        return collapse_short_beams(grid, lambda g: np.full(len(g.edges), long))[0]

    chosen = remesh(mesh, field, settings, buildable=spoil_all_but_one).polymesh
    assert np.array_equal(chosen.nodes, calls[favoured].nodes), "the candidate that builds best is kept, as extracted"


def test_the_starts_side_by_side_in_worker_processes_give_the_grid_made_one_after_another():
    """A small grid is clustered from several starts (lattice offsets); a process pool may run them
    on the cores (``starts_map``, the remesh stage's ``[remesh] workers``). Each start is seeded by
    its own index, so the grid is the same, node for node, as from the starts in turn."""
    from concurrent.futures import ProcessPoolExecutor

    from engine.remeshing.voronoi import MAX_STARTS

    mesh = _square(12)
    size = 0.6 + 0.4 * np.abs(mesh.vertices[:, 0])  # graded: the starts' candidates differ
    settings = RemeshSettings(n_cells=30, lloyd_iterations=6)
    order: list[int] = []

    def in_turn(function, jobs):
        for job in jobs:
            order.append(job[2].seed)
            yield function(job)

    serial = remesh(mesh, _field(mesh, size=size), settings, starts_map=in_turn)
    assert order == list(range(MAX_STARTS)), "a small mesh is clustered from every start"
    with ProcessPoolExecutor(max_workers=2) as pool:
        pooled = remesh(mesh, _field(mesh, size=size), settings, starts_map=pool.map)
    assert np.array_equal(serial.polymesh.nodes, pooled.polymesh.nodes)
    assert [f.tolist() for f in serial.polymesh.faces] == [f.tolist() for f in pooled.polymesh.faces]
    plain = remesh(mesh, _field(mesh, size=size), settings)
    assert np.array_equal(plain.polymesh.nodes, serial.polymesh.nodes)
