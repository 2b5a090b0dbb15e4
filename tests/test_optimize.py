"""Face optimisation (engine.remeshing.optimize, engine.remeshing.planarise,
engine.remeshing.boundary_splits): fixed points of the local steps, the derivatives of the end game,
the splits of boundary cells, the planarity target (0.5 % of the mean beam length with every node
within 0.5 % of the diagonal of the surface) on a dome and on the mock-up, constraints held exactly,
the weights' effects, and the field's grading kept on a graded grid (its cell sizes known in closed
form). Test grids are built here, independent of the remesher: a hexagonal honeycomb (Voronoi cells
of a triangular lattice, scipy) clipped to the surface's plan outline (shapely), lifted onto the
surface by linear interpolation over its own triangles (matplotlib), and jittered in plan. The
outline's own vertices that clipping leaves inside a cell's border (boundary nodes of two beams that
are not corners) are dropped, as the remesher has none: boundary nodes are where cells meet."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from matplotlib.tri import LinearTriInterpolator, Triangulation
from scipy.spatial import Voronoi
from scipy.stats import spearmanr
from shapely.geometry import Point, Polygon
from shapely.geometry.polygon import orient

import engine.remeshing.optimize as optimize_module
import engine.remeshing.planarise as planarise_module
from engine.errors import InputError
from engine.geometry.parametric import cap, grid_triangles, mockup
from engine.geometry.proximity import closest_point_on_triangles
from engine.mesh import PolyMesh, TriMesh
from engine.remeshing.boundary_splits import cut_boundary_triangles, split_boundary_cells
from engine.remeshing.field import GuidingField
from engine.remeshing.optimize import OptimizeSettings, graded_areas, optimize, planar_targets, regular_targets
from engine.remeshing.planarise import cell_planes, planarity_terms

# ----------------------------------------------------------------------------- test grids

def _honeycomb(outline: Polygon, spacing: float, rng: np.random.Generator, jitter: float):
    """Plan nodes (n,2), faces, boundary mask, corner mask (outline vertices turning > 20 deg)."""
    h = spacing * np.sqrt(3) / 2
    x0, y0, x1, y1 = outline.bounds
    i, j = np.meshgrid(np.arange(-3, int((x1 - x0) / spacing) + 4), np.arange(-3, int((y1 - y0) / h) + 4),
                       indexing="ij")
    sites = np.c_[((i + 0.5 * (j % 2)) * spacing).ravel(), (j * h).ravel()] + [x0 + 0.31 * spacing, y0 + 0.23 * spacing]
    xy, faces, boundary, corners = _clipped_voronoi(sites, outline, 1e-6 * spacing**2)
    move = rng.normal(scale=jitter * spacing, size=xy.shape)
    move[boundary] = 0.0
    return xy + move, faces, boundary, corners


def _clipped_voronoi(sites: np.ndarray, outline: Polygon, least_area: float):
    """The Voronoi cells of plan ``sites`` clipped to ``outline`` (cells under ``least_area`` left
    out): plan nodes (n,2), faces, boundary mask, corner mask (outline vertices turning > 20 deg)."""
    voronoi = Voronoi(sites)
    x0, y0, x1, y1 = outline.bounds
    scale = max(x1 - x0, y1 - y0)
    keys, nodes, faces = {}, [], []
    for region_id in voronoi.point_region:
        region = voronoi.regions[region_id]
        if not region or -1 in region:
            continue
        cell = Polygon(voronoi.vertices[region]).intersection(outline)
        if cell.is_empty or cell.geom_type != "Polygon" or cell.area < least_area:
            continue
        face = []
        for p in np.asarray(orient(cell, 1.0).exterior.coords)[:-1]:
            key = tuple(np.round(p / (1e-7 * scale)).astype(np.int64))
            if key not in keys:
                keys[key] = len(nodes)
                nodes.append(p)
            face.append(keys[key])
        faces.append(np.array(face))
    xy = np.array(nodes)
    ring = outline.exterior
    boundary = np.array([ring.distance(Point(p)) < 1e-9 * scale for p in xy])
    vertices = np.asarray(ring.coords)[:-1]
    before, after = vertices - np.roll(vertices, 1, axis=0), np.roll(vertices, -1, axis=0) - vertices
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    turn = np.abs(np.arctan2(cross, np.einsum("ij,ij->i", before, after)))
    sharp = vertices[turn > np.radians(20)]
    corners = np.array([len(sharp) > 0 and np.linalg.norm(sharp - p, axis=1).min() < 1e-9 * scale for p in xy],
                       dtype=bool)
    return xy, faces, boundary, corners


def _lift(xy: np.ndarray, mesh: TriMesh) -> np.ndarray:
    """Heights by linear interpolation over the surface's own triangles (plan-projectable surfaces)."""
    triangulation = Triangulation(mesh.vertices[:, 0], mesh.vertices[:, 1], mesh.faces)
    z = np.asarray(LinearTriInterpolator(triangulation, mesh.vertices[:, 2])(xy[:, 0], xy[:, 1]).filled(np.nan))
    lost = np.isnan(z)  # on the outline, lost to round-off: the nearest boundary vertex's height
    if lost.any():
        b = np.flatnonzero(np.isin(np.arange(mesh.n_vertices), np.concatenate(mesh.boundary_loops)))
        nearest = np.argmin(np.linalg.norm(mesh.vertices[b, None, :2] - xy[None, lost], axis=2), axis=0)
        z[lost] = mesh.vertices[b[nearest], 2]
    return np.c_[xy, z]


def _grid_on(surface: TriMesh, spacing: float, jitter: float = 0.1, seed: int = 1, supports=None) -> PolyMesh:
    outline = Polygon(surface.vertices[surface.boundary_loops[0], :2])
    return _lifted(surface, *_honeycomb(outline, spacing, np.random.default_rng(seed), jitter), supports=supports)


def _lifted(surface: TriMesh, xy, faces, boundary, corners, supports=None) -> PolyMesh:
    """The plan cells lifted onto the surface as a grid-shell."""
    valence = np.bincount(np.concatenate(faces), minlength=len(xy))  # cells at a node
    keep = ~(boundary & (valence == 1) & ~corners)  # outline vertices inside one cell's border
    index = np.cumsum(keep) - 1
    faces = [index[f[keep[f]]] for f in faces]
    xy, boundary, corners = xy[keep], boundary[keep], corners[keep]
    support_mask = np.zeros(len(xy), dtype=bool) if supports is None else supports(xy, boundary)
    return PolyMesh(nodes=_lift(xy, surface), faces=tuple(faces), boundary=boundary, corners=corners,
                    supports=support_mask)


def _distance_to_surface(points: np.ndarray, mesh: TriMesh) -> np.ndarray:
    """Brute-force distance of points to every triangle of the surface (independent of the engine's index)."""
    a, b, c = (np.repeat(mesh.vertices[mesh.faces[:, j]][None], len(points), axis=0).reshape(-1, 3) for j in range(3))
    q = closest_point_on_triangles(np.repeat(points, mesh.n_faces, axis=0), a, b, c)
    return np.linalg.norm(q.reshape(len(points), mesh.n_faces, 3) - points[:, None], axis=2).min(axis=1)


def _distance_to_segments(points: np.ndarray, mesh: TriMesh) -> np.ndarray:
    """Brute-force distance of points to the surface's boundary polylines (independent of the engine)."""
    a = np.concatenate([mesh.vertices[loop] for loop in mesh.boundary_loops])
    b = np.concatenate([mesh.vertices[np.roll(loop, -1)] for loop in mesh.boundary_loops])
    d = b - a
    t = np.clip(np.einsum("psi,si->ps", points[:, None] - a[None], d) / np.einsum("si,si->s", d, d), 0, 1)
    return np.linalg.norm(a[None] + t[..., None] * d[None] - points[:, None], axis=2).min(axis=1)


def _relative_planarity(polymesh: PolyMesh) -> np.ndarray:
    return polymesh.face_planarity() / polymesh.beam_lengths.mean()


@pytest.fixture(scope="module")
def dome():
    """Spherical cap, 20 m span, span/rise 5 (R = 29 m): umbilic, so regular planar hexagons with
    their nodes on the surface exist (each is inscribed in a circle of the sphere). Every fifth
    boundary node and the node nearest the crown are supports."""
    surface = cap(span=20.0, span_to_rise=5.0, rings=12)

    def supports(xy, boundary):
        mask = np.zeros(len(xy), dtype=bool)
        mask[np.flatnonzero(boundary)[::5]] = True
        mask[np.argmin(np.linalg.norm(xy, axis=1))] = True
        return mask

    return surface, _grid_on(surface, 2.0, supports=supports)


@pytest.fixture(scope="module")
def shell():
    """The mock-up (2.4 m square, funicular, pinned edges at z = 0) with a 0.3 m honeycomb."""
    surface = mockup(divisions=16).mesh
    return surface, _grid_on(surface, 0.3)


#: The graded grid's pole: its cells' size grows as the plan distance to it.
POLE = np.array([-40.0, 0.0])


def _graded_grid(surface: TriMesh, seed: int, step: float = 0.05, stretch: float = 2.0, jitter: float = 0.15):
    """Cells whose size is known: the Voronoi cells of a triangular lattice of log-polar sites
    (u = ln r, v = the angle about POLE, spacing ``step``, jittered by ``jitter`` steps and
    stretched ``stretch`` times along u), mapped by exp. The map is conformal, so a cell's size is
    step * r and its aspect ``stretch`` (radial) wherever it lies: on the dome, r runs from 30 to
    50 m (a size ratio of 1.7, as the real roofs' interior cells see), with the remesher's kind of
    noise. Independent of the remesher and of the field's code."""
    rng = np.random.default_rng(seed)
    r0, r1 = -POLE[0] - 17.0, -POLE[0] + 20.0
    h = step * np.sqrt(3) / 2
    i, j = np.meshgrid(np.arange(int(np.log(r1 / r0) / step) + 1), np.arange(int(2.0 / h) + 1), indexing="ij")
    u = np.log(r0) + (i + 0.5 * (j % 2)) * step
    v = -1.0 + j * h
    uv = np.c_[u.ravel(), v.ravel()] + rng.normal(scale=jitter * step, size=(u.size, 2))
    middle = np.log(r0 * r1) / 2
    uv = (uv - [middle, 0.0]) * [np.sqrt(stretch), 1 / np.sqrt(stretch)] + [middle, 0.0]
    sites = POLE + np.exp(uv[:, :1]) * np.c_[np.cos(uv[:, 1]), np.sin(uv[:, 1])]
    outline = Polygon(surface.vertices[surface.boundary_loops[0], :2])
    return _lifted(surface, *_clipped_voronoi(sites, outline, 1e-4))


def _pole_field(surface: TriMesh) -> GuidingField:
    """The graded grid's field: size proportional to the plan distance to POLE, isotropic."""
    normals = surface.vertex_normals
    direction = np.array([1.0, 0.0, 0.0]) - normals[:, :1] * normals
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    r = np.linalg.norm(surface.vertices[:, :2] - POLE, axis=1)
    return GuidingField(size=0.05 * r, anisotropy=np.ones(surface.n_vertices), direction=direction, normals=normals)


def _grading(grid: PolyMesh) -> tuple[float, float]:
    """(Spearman rank correlation, log-log slope) of the interior cells' sqrt(area) against the
    size their place prescribes (the plan distance of their centroid to POLE): measured here, not
    by the engine."""
    inner = ~grid.face_boundary
    sizes = np.sqrt(grid.face_areas()[inner])
    prescribed = np.array([np.linalg.norm(grid.nodes[f, :2].mean(axis=0) - POLE) for f in grid.faces])[inner]
    return float(spearmanr(prescribed, sizes).statistic), float(np.polyfit(np.log(prescribed), np.log(sizes), 1)[0])


# ----------------------------------------------------------------------------- local steps

def _hexagon(stretch: float = 1.0, angle: float = 0.3) -> np.ndarray:
    t = 2 * np.pi * np.arange(6) / 6 + angle
    p = np.c_[stretch * np.cos(t), np.sin(t), np.zeros(6)]
    rotation = np.array([[np.cos(0.7), -np.sin(0.7), 0], [np.sin(0.7), np.cos(0.7), 0], [0, 0, 1]])
    tilt = np.array([[1, 0, 0], [0, np.cos(0.4), -np.sin(0.4)], [0, np.sin(0.4), np.cos(0.4)]])
    return (p @ rotation.T @ tilt.T + [3.0, -1.0, 2.0])[None]


@pytest.mark.parametrize("stretch", [1.0, 1.8])
def test_regular_and_stretched_hexagons_are_fixed_points_of_the_regularity_step(stretch):
    cell = _hexagon(stretch)
    assert np.allclose(regular_targets(cell), cell, atol=1e-9)
    assert np.allclose(regular_targets(cell[:, ::-1]), cell[:, ::-1], atol=1e-9), "either orientation"


def test_regularity_step_makes_an_irregular_cell_regular_with_equal_area():
    cell = _hexagon(1.0) + np.random.default_rng(3).normal(scale=0.15, size=(1, 6, 3))
    target = regular_targets(cell)[0]
    centred = target - target.mean(axis=0)
    assert np.linalg.svd(centred, compute_uv=False)[2] < 1e-12, "the target is planar"
    # un-stretched by its own PCA axes the target is a regular hexagon: equal sides (affine image)
    axes = np.linalg.svd(centred, full_matrices=False)[2][:2]
    local = centred @ axes.T
    values, vectors = np.linalg.eigh(local.T @ local / 6)
    unstretched = local @ vectors / np.sqrt(values)
    sides = np.linalg.norm(unstretched - np.roll(unstretched, -1, axis=0), axis=1)
    assert sides.std() / sides.mean() < 1e-9
    # equal area with the cell projected onto its best-fit plane (shoelace in the plane)
    def area(points):
        c = points - points.mean(axis=0)
        q = c @ np.linalg.svd(c, full_matrices=False)[2][:2].T
        return 0.5 * abs(np.sum(q[:, 0] * np.roll(q[:, 1], -1) - np.roll(q[:, 0], -1) * q[:, 1]))
    assert area(target) == pytest.approx(area(cell[0]), rel=1e-9)


def test_planar_targets_lie_in_a_plane_and_keep_planar_cells():
    cell = _hexagon()
    assert np.allclose(planar_targets(cell), cell, atol=1e-12)
    bent = cell.copy()
    bent[0, ::2, 2] += 0.2
    target = planar_targets(bent)[0]
    assert np.linalg.svd(target - target.mean(axis=0), compute_uv=False)[2] < 1e-12


# ----------------------------------------------------------------------------- the end game's terms

def test_planarity_gradient_matches_finite_differences():
    """The gradient of half the planarity energy (planes eliminated) against central differences."""
    rng = np.random.default_rng(5)
    x = np.r_[_hexagon()[0], _hexagon(1.4, 0.1)[0] + [2.5, 0.3, 0.4]] + rng.normal(scale=0.05, size=(12, 3))
    groups = {6: np.array([np.arange(6), np.arange(6, 12)])}
    weights = {6: np.array([1.0, 3.0])}
    energy, _, _, _, _, gradient = planarity_terms(groups, x, weights)
    direction = rng.normal(size=x.shape)
    h = 1e-6
    up = planarity_terms(groups, x + h * direction, weights, hessian=False)[0]
    down = planarity_terms(groups, x - h * direction, weights, hessian=False)[0]
    assert (up - down) / (2 * h) == pytest.approx(2 * np.sum(gradient * direction), rel=1e-6)


def test_eliminated_planes_leave_planar_motions_free():
    """On a planar cell the Gauss-Newton Hessian vanishes on every motion that keeps it planar
    (in-plane moves, a tilt or a shift of its plane: the plane follows) and not on a bump."""
    cell = _hexagon(1.3)[0]
    groups = {6: np.arange(6)[None]}
    _, _, rows, cols, vals, _ = planarity_terms(groups, cell)
    hessian = np.zeros((18, 18))
    np.add.at(hessian, (rows, cols), vals)
    centroid, axes, normal, offsets = cell_planes(cell[None])
    assert np.abs(offsets).max() < 1e-12
    u, v = ((cell - centroid) @ axes[0].T).T
    rng = np.random.default_rng(2)
    planar_move = (rng.normal(size=(6, 2)) @ axes[0]) + np.outer(0.3 + 0.7 * u - 0.4 * v, normal[0])
    assert planar_move.ravel() @ hessian @ planar_move.ravel() < 1e-12
    bump = np.zeros((6, 3))
    bump[2] = normal[0]
    assert bump.ravel() @ hessian @ bump.ravel() > 0.1


# ----------------------------------------------------------------------------- boundary splits

def _vector_area(polymesh: PolyMesh) -> np.ndarray:
    return sum(0.5 * np.cross(polymesh.nodes[f], polymesh.nodes[np.roll(f, -1)]).sum(axis=0) for f in polymesh.faces)


def test_boundary_splits_on_the_mockup_cut_corners_and_straight_edge_chains(shell):
    surface, grid = shell
    band = 0.004 * surface.diagonal
    split = split_boundary_cells(grid, hold=0.5 * band, straightness=1e-3 * grid.beam_lengths.mean())
    out = split.polymesh
    new = split.new_beams
    assert split.corner_splits >= 3 and split.edge_splits > 4
    assert len(new) == split.corner_splits + split.edge_splits == out.n_faces - grid.n_faces
    assert len(out.edges) == len(grid.edges) + len(new), "each split adds one beam"
    assert np.allclose(_vector_area(out), _vector_area(grid), atol=1e-12), "a chord splits a loop's vector area"
    assert np.array_equal(out.nodes, grid.nodes)
    assert np.all(out.boundary[new].sum(axis=1) == 1), "a new beam joins a boundary node to an inner one"
    # a cell holding a corner and nodes of both its edges lies in z = 0 (the edges' plane): it is
    # split unless its inner nodes stand within the hold of that plane
    for face in out.faces:
        ring = np.r_[face, face[:2]]
        for a, b, c in zip(ring, ring[1:], ring[2:]):
            if grid.corners[b] and grid.boundary[a] and grid.boundary[c] and len(face) > 3:
                assert np.abs(grid.nodes[face, 2]).max() <= 0.5 * band
    held = sum(1 for f in grid.faces if grid.corners[f].any() and np.abs(grid.nodes[f, 2]).max() > 0.5 * band)
    assert split.corner_splits == held


def test_a_cut_boundary_triangle_leaves_the_rest_of_the_cell_one_node_of_the_edge(shell):
    surface, grid = shell
    cells = np.flatnonzero(grid.face_boundary & (grid.face_degrees > 4))[:6]
    out, new = cut_boundary_triangles(grid, cells)
    assert len(new) == len(cells) and out.n_faces == grid.n_faces + len(cells)
    assert np.allclose(_vector_area(out), _vector_area(grid), atol=1e-12)
    before = {tuple(sorted(f.tolist())) for f in grid.faces}
    pieces = [f for f in out.faces if tuple(sorted(f.tolist())) not in before]
    triangles = [f for f in pieces if len(f) == 3]
    rests = [f for f in pieces if len(f) > 3]
    assert len(triangles) == len(rests) == len(cells)
    for cell in cells:
        original = set(grid.faces[cell].tolist())
        rest = next(f for f in rests if set(f.tolist()) <= original)
        triangle = next(f for f in triangles if set(f.tolist()) <= original)
        assert set(rest.tolist()) | set(triangle.tolist()) == original and len(set(rest) & set(triangle)) == 2
        assert grid.boundary[triangle].sum() == 2, "a boundary beam and an inner node"
        assert grid.boundary[rest].sum() == grid.boundary[list(original)].sum() - 1, "the rest keeps one of them"
    untouched, none = cut_boundary_triangles(grid, np.flatnonzero(~grid.face_boundary)[:3])
    assert untouched is grid and len(none) == 0, "cells without a boundary beam stay"


def test_flat_boundaries_keep_their_cells():
    """On a plane every forced plane is the surface's own: nothing to split."""
    surface = _flat_square()
    grid = _grid_on(surface, 0.4, jitter=0.12)
    split = split_boundary_cells(grid, hold=1e-4, straightness=1e-6)
    assert len(split.new_beams) == 0 and split.polymesh is grid


# ----------------------------------------------------------------------------- the iterations

def _target_met(out: PolyMesh, surface: TriMesh) -> tuple[float, float]:
    planarity = _relative_planarity(out).max()
    closeness = _distance_to_surface(out.nodes, surface).max() / surface.diagonal
    return planarity, closeness


def test_planarity_target_on_the_dome_with_closeness_held_and_constraints_exact(dome):
    surface, grid = dome
    result = optimize(grid, surface, None, OptimizeSettings(iterations=50))
    q, out = result.quality, result.polymesh
    # target (issue): planarity <= 0.5 % of the mean beam length with closeness < 0.5 % of the diagonal
    planarity, closeness = _target_met(out, surface)
    assert planarity <= 0.005 and closeness < 0.005
    assert _relative_planarity(grid).max() > 0.03, "the start is far from planar"
    assert q["after"]["planarity_max_rel"] == pytest.approx(planarity, rel=1e-9)
    assert q["planarity_reached"] and q["end_game"]["reached"] and q["converged"]
    assert q["after"]["regularity"] < q["before"]["regularity"]
    assert q["after"]["nonconvex_faces"] == 0, "a sphere has convex planar hexagons"
    fixed = grid.supports | grid.corners
    assert fixed.sum() > 5 and np.array_equal(out.nodes[fixed], grid.nodes[fixed]), "supports exactly in place"
    sliding = grid.boundary & ~fixed
    assert np.abs(out.nodes[sliding] - grid.nodes[sliding]).max() > 1e-3, "boundary nodes do slide"
    assert _distance_to_segments(out.nodes[sliding], surface).max() < 1e-9, "and stay on the boundary"
    assert q["iterations"] == 50 and q["factorisations"] == 1 + q["end_game"]["factorisations"]


def test_mockup_meets_the_planarity_target_with_split_boundary_cells(shell):
    """The mock-up's edges are straight and pinned at z = 0 on a surface that twists along them:
    without the splits the end game stops above the target, with them it meets it."""
    surface, grid = shell
    result = optimize(grid, surface, None, OptimizeSettings(iterations=50))
    q, out = result.quality, result.polymesh
    planarity, closeness = _target_met(out, surface)
    assert planarity <= 0.005 and closeness < 0.005
    assert q["corner_splits"] >= 3 and q["edge_splits"] > 0
    new = np.array(q["split_beams"])
    assert len(out.edges) == len(grid.edges) + len(new)
    assert {tuple(b) for b in np.sort(new, axis=1)} <= {tuple(b) for b in out.edges}
    lengths = np.linalg.norm(out.nodes[new[:, 0]] - out.nodes[new[:, 1]], axis=1)
    assert q["split_length_m"] == pytest.approx(lengths.sum())
    assert q["after"]["smallest_angle_deg"] > 10.0, "the guards keep the corners open"
    assert grid.corners.sum() == 4 and np.array_equal(out.nodes[grid.corners], grid.nodes[grid.corners])
    sliding = grid.boundary & ~grid.corners
    on_edge = np.abs(np.abs(out.nodes[sliding, :2]).max(axis=1) - 1.2)
    assert on_edge.max() < 1e-12 and np.abs(out.nodes[sliding, 2]).max() < 1e-12, "on the square's edges, z = 0"
    unsplit = optimize(grid, surface, None, OptimizeSettings(iterations=50, split_cells=False))
    assert unsplit.polymesh.n_faces == grid.n_faces and not unsplit.quality["planarity_reached"]
    assert _target_met(unsplit.polymesh, surface)[0] > 0.0075


def test_local_global_alone_gains_but_stays_off_target(shell):
    surface, grid = shell
    result = optimize(grid, surface, None, OptimizeSettings(iterations=50, planarity_iterations=0, split_cells=False))
    q = result.quality
    assert q["end_game"] is None and q["corner_splits"] == 0
    assert q["after"]["planarity_max_rel"] < 0.4 * q["before"]["planarity_max_rel"]
    assert q["after"]["planarity_max_rel"] > 0.005
    assert q["after"]["closeness_max_rel"] < 0.005


def test_the_local_global_matrix_is_factored_once_and_the_end_game_counts_its_own(dome, monkeypatch):
    surface, grid = dome
    calls, solves = [], []
    original = optimize_module.spla.factorized

    def counting(matrix):
        calls.append(matrix.shape)
        return original(matrix)

    solve = planarise_module.spla.spsolve
    monkeypatch.setattr(optimize_module.spla, "factorized", counting)
    monkeypatch.setattr(optimize_module.spla, "splu", lambda *a, **k: pytest.fail("splu called"))
    result = optimize(grid, surface, None, OptimizeSettings(iterations=12, planarity_iterations=0))
    assert len(calls) == 1 and result.quality["iterations"] == 12 and result.quality["factorisations"] == 1
    monkeypatch.setattr(planarise_module.spla, "spsolve", lambda *a: solves.append(1) or solve(*a))
    calls.clear()
    result = optimize(grid, surface, None, OptimizeSettings(iterations=12))
    assert len(calls) == 1 and len(solves) == result.quality["end_game"]["factorisations"] > 0
    assert result.quality["factorisations"] == 1 + len(solves)


def _flat_square() -> TriMesh:
    n = 12
    x, y = np.meshgrid(np.linspace(-1, 1, n + 1), np.linspace(-1, 1, n + 1), indexing="ij")
    return TriMesh(vertices=np.c_[x.ravel(), y.ravel(), np.zeros(x.size)], faces=grid_triangles(n, n))


def test_zero_regularity_weight_gives_no_regularity_change_beyond_planarity():
    """On a plane the jittered honeycomb is already planar and on the surface: without regularity
    (and fairness) nothing moves; with regularity the cells become more regular."""
    surface = _flat_square()
    grid = _grid_on(surface, 0.4, jitter=0.12)
    # the corner limit off: the jittered honeycomb has corners under its default 20 degrees
    still = optimize(grid, surface, None, OptimizeSettings(regularity_weight=0.0, fairness_weight=0.0, iterations=20,
                                                           min_corner_angle_deg=0.0))
    assert np.abs(still.polymesh.nodes - grid.nodes).max() < 1e-9
    assert still.quality["after"]["regularity"] == pytest.approx(still.quality["before"]["regularity"], abs=1e-9)
    assert still.quality["end_game"]["steps"] == 0 and still.quality["corner_splits"] == 0
    regular = optimize(grid, surface, None, OptimizeSettings(fairness_weight=0.0, iterations=20))
    assert regular.quality["after"]["regularity"] < 0.7 * regular.quality["before"]["regularity"]
    assert np.abs(regular.polymesh.nodes[:, 2]).max() < 1e-12, "a plane stays a plane"


def test_planar_false_ignores_the_planarity_weight_and_trades_planarity_for_regularity(dome):
    surface, grid = dome
    a = optimize(grid, surface, None, OptimizeSettings(iterations=20, planar=False))
    b = optimize(grid, surface, None, OptimizeSettings(iterations=20, planar=False, planarity_weight=7.0))
    assert np.array_equal(a.polymesh.nodes, b.polymesh.nodes)
    assert a.quality["end_game"] is None and a.polymesh.n_faces == grid.n_faces
    planar = optimize(grid, surface, None, OptimizeSettings(iterations=20))
    assert planar.quality["planarity_reached"] and a.quality["after"]["planarity_max_rel"] > 0.01
    assert a.quality["after"]["regularity"] < planar.quality["after"]["regularity"]


def test_a_stronger_regularity_weight_keeps_the_cells_more_regular_at_the_same_planarity(dome):
    surface, grid = dome
    light = optimize(grid, surface, None, OptimizeSettings(iterations=20, regularity_weight=0.2))
    heavy = optimize(grid, surface, None, OptimizeSettings(iterations=20, regularity_weight=5.0))
    for result in (light, heavy):
        assert result.quality["planarity_reached"]
    assert heavy.quality["after"]["regularity"] < light.quality["after"]["regularity"]


def test_progress_is_reported_and_zero_iterations_change_nothing(dome):
    surface, grid = dome
    seen = []
    result = optimize(grid, surface, None, OptimizeSettings(iterations=3),
                      progress=lambda text, f: seen.append((text, f)))
    assert [f for _, f in seen if f is not None] == pytest.approx([1 / 3, 2 / 3, 1.0])
    end = [text for text, f in seen if f is None]
    assert len(end) == result.quality["end_game"]["steps"] > 0 and all("planarity step" in t for t in end)
    none = optimize(grid, surface, None, OptimizeSettings(iterations=0))
    assert np.array_equal(none.polymesh.nodes, grid.nodes) and none.quality["iterations"] == 0
    assert none.polymesh.n_faces == grid.n_faces and none.quality["end_game"] is None


def test_user_mistakes_raise_input_errors(dome):
    surface, grid = dome
    for bad in ({"closeness_weight": -1.0}, {"iterations": -5}, {"planarity_iterations": 2.5},
                {"planarity_tolerance": 0.0}, {"planarity_tolerance": float("nan")}, {"grading_quantile": 1.0},
                {"grading_quantile": -0.1}):
        with pytest.raises(InputError):
            OptimizeSettings(**bad)
    broken = PolyMesh(nodes=np.full((3, 3), np.nan), faces=(np.array([0, 1, 2]),))
    with pytest.raises(InputError):
        optimize(broken, surface, None, OptimizeSettings())


# ----------------------------------------------------------------------------- the field's grading

def _chain(n: int) -> sp.csr_matrix:
    """Adjacency of n cells in a row."""
    a = np.arange(n - 1)
    return sp.csr_matrix((np.ones(2 * (n - 1)), (np.r_[a, a + 1], np.r_[a + 1, a])), shape=(n, n))


def test_graded_areas_follow_the_field_and_compress_it_in_order():
    """Cells in a row whose field size grows 3 times along it (boundary cells at both ends): a grid
    that follows the field is its own target; a noisy one is taken to the field's sizes; joints
    larger than the smallest cells compress the grading with the order of the sizes kept and the
    total area the same; joints that no grading could take leave it."""
    n = 40
    h = np.linspace(1.0, 3.0, n)
    interior = np.ones(n, dtype=bool)
    interior[[0, -1]] = False
    adjacency = _chain(n)
    exact = 0.8 * h**2
    target, given_slope, slope = graded_areas(exact, h, interior, adjacency)
    assert np.allclose(target, exact, rtol=1e-9) and given_slope == pytest.approx(1.0) and slope == given_slope
    noisy = exact * np.exp(np.random.default_rng(2).normal(scale=0.2, size=n))
    target = graded_areas(noisy, h, interior, adjacency)[0]
    assert spearmanr(h[interior], target[interior]).statistic > spearmanr(h[interior], noisy[interior]).statistic + 0.03
    spread = [np.std(np.log(a[interior] / h[interior] ** 2)) for a in (noisy, target)]
    assert spread[1] < 0.7 * spread[0], "nearer the field's sizes"
    assert target.sum() == pytest.approx(noisy.sum(), rel=1e-9)
    assert np.allclose(target[~interior], noisy[~interior], rtol=1e-12), "cut cells keep their area"
    side = np.sqrt(2 / (3 * np.sqrt(3)))  # a regular hexagon's side per sqrt(area)
    for quantile in (0.0, 0.2):
        joint = 1.2 * side * np.sqrt(np.quantile(exact[interior], quantile))  # the joints' shortest beam
        target, _, slope = graded_areas(exact, h, interior, adjacency, min_side=joint, quantile=quantile)
        assert 0.2 < slope < 0.95
        assert target.sum() == pytest.approx(exact.sum(), rel=1e-9)
        assert np.all(np.diff(target) > 0), "the order of the sizes stays"
        assert np.quantile(side * np.sqrt(target[interior]), quantile) == pytest.approx(joint, rel=1e-6)
        log_h = np.log(h[interior])
        assert np.polyfit(log_h, 0.5 * np.log(target[interior]), 1)[0] == pytest.approx(slope, abs=1e-6)
    target, _, slope = graded_areas(exact, h, interior, adjacency, min_side=10 * side * np.sqrt(exact.max()))
    assert slope == 1.0 and np.allclose(target, exact), "a grid too fine for its joints at any grading"


@pytest.mark.parametrize("seed", [2, 5])
def test_the_optimiser_keeps_the_grading_of_a_graded_grid(dome, seed):
    """On a dome, a grid graded 1.7 times across its interior cells with the remesher's kind of
    noise and of anisotropy, beams held to 0.7 m (a quarter of them shorter as given): the cells
    stay as graded as given, by the rank correlation of their size with the size their place
    prescribes and by its log-log slope, both measured here. The regularity targets of the cells'
    own areas (the code before issue 13's fix) lost 0.02-0.09 of the rank correlation here and the
    joints' projections more on the real roofs (the mock-up at 300 cells 0.93 -> 0.80)."""
    surface = dome[0]
    grid = _graded_grid(surface, seed)
    rank, slope = _grading(grid)
    assert 0.6 < rank < 0.9 and slope > 0.8, "a graded, noisy grid"
    assert np.mean(grid.beam_lengths < 0.7) > 0.2, "the joints bite"
    result = optimize(grid, surface, _pole_field(surface), OptimizeSettings(planar=False, min_beam_length=0.7))
    rank_after, slope_after = _grading(result.polymesh)
    assert rank_after >= rank + 0.03, "the sizes follow the field better than given (its noise)"
    assert slope_after >= 0.9 * slope, "the grading is not evened out"
    assert np.mean(result.polymesh.beam_lengths < 0.7 * (1 - 1e-6)) < 0.1
    assert result.quality["grading"]["target_slope"] == result.quality["grading"]["given_slope"]
    assert result.quality["after"]["regularity"] < result.quality["before"]["regularity"]


def test_a_grading_compressed_for_the_joints_is_a_finding():
    from workflow.stages.optimize import compressed_finding, compressed_grading

    kept = {"grading": {"given_slope": 0.98, "target_slope": 0.98}, "before": {}, "after": {}}
    assert not compressed_grading(kept) and not compressed_grading({"grading": None})
    assert not compressed_grading({"grading": {"given_slope": None, "target_slope": None}}), "sizes evened"
    quality = {"grading": {"given_slope": 0.98, "target_slope": 0.44},
               "before": {"size_rank_correlation": 0.96}, "after": {"size_rank_correlation": 0.76}}
    assert compressed_grading(quality)
    finding = compressed_finding(quality)
    assert finding["kind"] == "grading_compressed" and finding["stage"] == "optimize"
    assert "0.44" in finding["message"] and "0.76" in finding["message"] and "n_cells" in finding["fix"]
    # the fix names the section's own keys: a rectangle has no diameter
    from workflow.config import parse_project

    glulam = parse_project({"surface": {"template": "hypar"}, "material": {"name": "glulam_gl24h"},
                            "section": {"kind": "solid_rectangle", "height": "200 mm", "width": "100 mm"}})
    fix = compressed_finding(quality, glulam.section.size_key())["fix"]
    assert "[section] height, width" in fix and "diameter" not in fix


def test_a_grading_lost_to_the_joints_collapses_is_a_finding():
    """Where the field is graded and the collapses and removals for the joints cost the grid more
    than 0.1 of its size rank correlation (issue 13's bound), a finding says so with both figures;
    a loss within the bound, or an even field (whose correlation measures noise), is none."""
    from workflow.stages.optimize import lost_finding, lost_grading

    def quality(r0: float, r1: float, span: float) -> dict:
        return {"before": {"size_rank_correlation": r0, "field_size_span_cells": span},
                "after": {"size_rank_correlation": r1}}

    assert lost_grading(quality(0.81, 0.65, 1.85))
    assert not lost_grading(quality(0.81, 0.72, 1.85)), "within 0.1"
    assert not lost_grading(quality(0.81, 0.40, 1.1)), "an even field"
    assert not lost_grading({"before": {}, "after": {}})
    finding = lost_finding(quality(0.81, 0.65, 1.85), collapsed=68, removed=27)
    assert finding["kind"] == "grading_lost" and finding["stage"] == "optimize"
    assert "0.81" in finding["message"] and "0.65" in finding["message"] and "68" in finding["message"]
    assert "n_cells" in finding["fix"] and "[fabrication.joints]" in finding["fix"]


def test_a_local_optimisation_keeps_the_held_cells_normals_and_gives_the_same_grid(dome, monkeypatch):
    """The fold check of a local optimisation finds the surface's normals at the cells that move
    only (the others' are kept from the first step): the same nodes as finding them all at every
    step."""
    from engine.geometry.projections import unfolded
    from engine.remeshing import optimize as optimize_module

    surface, grid = dome
    settings = OptimizeSettings(iterations=20, planar=False)
    centre = np.argmin(np.linalg.norm(grid.nodes[:, :2] - [3.0, 2.0], axis=1))
    held = np.linalg.norm(grid.nodes[:, :2] - grid.nodes[centre, :2], axis=1) >= 4.0
    kept = optimize(grid, surface, None, settings, held=held).polymesh.nodes
    moving = []

    def every_normal(p, x, new):
        moving.append(int(p.moving_cells.sum()))
        return unfolded(x, new, p.fans, p.surface.closest_normals(p.fans.centroids(x))[1])

    monkeypatch.setattr(optimize_module, "_unfolded", every_normal)
    assert np.array_equal(kept, optimize(grid, surface, None, settings, held=held).polymesh.nodes)
    assert 0 < moving[0] < grid.n_faces


def test_held_nodes_stay_exactly_and_the_region_left_free_is_optimised(dome):
    """Optimising again round a local change: the held nodes do not move at all, the free region
    gains regularity as a whole optimisation would, and only the cells with a free node are worked
    on (the global system is the free region's)."""
    surface, grid = dome
    settings = OptimizeSettings(iterations=30, planar=False)
    centre = np.argmin(np.linalg.norm(grid.nodes[:, :2] - [3.0, 2.0], axis=1))
    free = np.linalg.norm(grid.nodes[:, :2] - grid.nodes[centre, :2], axis=1) < 4.0
    held = ~free
    local = optimize(grid, surface, None, settings, held=held)
    whole = optimize(grid, surface, None, settings)
    out = local.polymesh.nodes
    assert np.array_equal(out[held], grid.nodes[held])
    moving = free & ~(grid.supports | grid.corners)
    assert np.abs(out[moving] - grid.nodes[moving]).max() > 1e-3
    # the free region's cells: about as regular as the whole optimisation makes them
    inside = np.array([free[f].all() for f in grid.faces])

    def irregularity(nodes: np.ndarray) -> float:
        lengths = [np.linalg.norm(nodes[f] - nodes[np.roll(f, -1)], axis=1) for f, i in zip(grid.faces, inside) if i]
        return float(np.mean([side.std() / side.mean() for side in lengths]))

    assert irregularity(out) < 0.5 * irregularity(grid.nodes)
    assert irregularity(out) < 1.15 * irregularity(whole.polymesh.nodes)
    assert _distance_to_surface(out[moving], surface).max() < 0.005 * surface.diagonal


def test_a_grid_of_small_cells_whose_joints_want_longer_beams_stays_on_the_surface():
    """A 0.4 m honeycomb on a 10 m spherical cap (R = 6.25 m), every beam held to 1.2 times the
    honeycomb's side: the surface has no room for those beams. Lengthening them along the beams
    and keeping closeness only within a band of the diagonal (0.45 % of it: 64 mm, a quarter of a
    beam) crumpled such grids out of the surface (Hall at 1500 cells: nodes 148 mm off with 0.39 m
    beams). The nodes now stand off by at most 9 % of the mean beam, the bound on grids of small
    cells, and most lie on the surface; measured by brute force over the surface's triangles."""
    surface = cap(span=10.0, span_to_rise=4.0, rings=16)
    grid = _grid_on(surface, 0.4, jitter=0.15, seed=3)
    side = 0.4 / np.sqrt(3)
    result = optimize(grid, surface, None, OptimizeSettings(planar=False, min_beam_length=1.2 * side))
    x = result.polymesh.nodes
    distance = _distance_to_surface(x, surface) / result.polymesh.beam_lengths.mean()
    assert distance.max() <= optimize_module.LIMIT_PER_BEAM * (1 + 1e-6)
    assert np.percentile(distance, 95) < 0.04  # a regular planar cell of this size sags 2 % of its side
    assert result.quality["after"]["closeness_max_beam_rel"] == pytest.approx(distance.max(), abs=0.01)
    assert result.quality["after"]["folded_cells"] == 0
