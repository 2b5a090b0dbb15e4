"""Face optimisation (engine.optimize): fixed points of the local steps, the planarity target where
the geometry allows it, constraints held exactly, one factorisation, and the weights' effects.

Test grids are built here, independent of the remesher: a hexagonal honeycomb (Voronoi cells of a
triangular lattice, scipy) clipped to the surface's plan outline (shapely), lifted onto the surface
by linear interpolation over its own triangles (matplotlib), and jittered in plan.
"""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.tri import LinearTriInterpolator, Triangulation
from scipy.spatial import Voronoi
from shapely.geometry import Point, Polygon
from shapely.geometry.polygon import orient

import engine.optimize as optimize_module
from engine.errors import InputError
from engine.mesh import PolyMesh, TriMesh
from engine.optimize import OptimizeSettings, optimize, planar_targets, regular_targets
from engine.parametric import cap, grid_triangles, mockup


# ----------------------------------------------------------------------------- test grids

def _honeycomb(outline: Polygon, spacing: float, rng: np.random.Generator, jitter: float):
    """Plan nodes (n,2), faces, boundary mask, corner mask (outline vertices turning > 20 deg)."""
    h = spacing * np.sqrt(3) / 2
    x0, y0, x1, y1 = outline.bounds
    i, j = np.meshgrid(np.arange(-3, int((x1 - x0) / spacing) + 4), np.arange(-3, int((y1 - y0) / h) + 4),
                       indexing="ij")
    sites = np.c_[((i + 0.5 * (j % 2)) * spacing).ravel(), (j * h).ravel()] + [x0 + 0.31 * spacing, y0 + 0.23 * spacing]
    voronoi = Voronoi(sites)
    scale = max(x1 - x0, y1 - y0)
    keys, nodes, faces = {}, [], []
    for region_id in voronoi.point_region:
        region = voronoi.regions[region_id]
        if not region or -1 in region:
            continue
        cell = Polygon(voronoi.vertices[region]).intersection(outline)
        if cell.is_empty or cell.geom_type != "Polygon" or cell.area < 1e-6 * spacing**2:
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
    move = rng.normal(scale=jitter * spacing, size=xy.shape)
    move[boundary] = 0.0
    return xy + move, faces, boundary, corners


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
    xy, faces, boundary, corners = _honeycomb(outline, spacing, np.random.default_rng(seed), jitter)
    support_mask = np.zeros(len(xy), dtype=bool) if supports is None else supports(xy, boundary)
    return PolyMesh(nodes=_lift(xy, surface), faces=tuple(faces), boundary=boundary, corners=corners,
                    supports=support_mask)


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


# ----------------------------------------------------------------------------- the iterations

def test_planarity_target_on_the_dome_with_closeness_held_and_constraints_exact(dome):
    surface, grid = dome
    result = optimize(grid, surface, None, OptimizeSettings(iterations=50))
    q, out = result.quality, result.polymesh
    interior = ~grid.face_boundary
    # target (issue): planarity <= 0.5 % of the mean beam length with closeness < 0.5 % of the diagonal;
    # cells with >= 3 nodes on the planar boundary circle cannot be planar off z = 0, so interior cells
    assert _relative_planarity(out)[interior].max() <= 0.005
    assert _relative_planarity(grid)[interior].max() > 0.03, "the start is far from planar"
    assert q["after"]["closeness_max_rel"] < 0.005
    assert q["after"]["planarity_max_rel"] < 0.5 * q["before"]["planarity_max_rel"]
    assert q["after"]["regularity"] < q["before"]["regularity"]
    fixed = grid.supports | grid.corners
    assert fixed.sum() > 5 and np.array_equal(out.nodes[fixed], grid.nodes[fixed]), "supports exactly in place"
    sliding = grid.boundary & ~fixed
    assert np.abs(out.nodes[sliding] - grid.nodes[sliding]).max() > 1e-3, "boundary nodes do slide"
    assert _distance_to_segments(out.nodes[sliding], surface).max() < 1e-9, "and stay on the boundary"
    assert q["factorisations"] == 1 and q["iterations"] == 50


def test_mockup_honeycomb_planarity_improves_and_edges_and_corners_hold(shell):
    surface, grid = shell
    result = optimize(grid, surface, None, OptimizeSettings(iterations=50))
    q, out = result.quality, result.polymesh
    # the mock-up's saddle corners and strongly anisotropic curvature along the edges keep the
    # target out of reach here; the gain is still large and closeness is held
    assert q["after"]["planarity_max_rel"] < 0.4 * q["before"]["planarity_max_rel"]
    assert q["after"]["closeness_max_rel"] < 0.005
    assert grid.corners.sum() == 4 and np.array_equal(out.nodes[grid.corners], grid.nodes[grid.corners])
    sliding = grid.boundary & ~grid.corners
    on_edge = np.abs(np.abs(out.nodes[sliding, :2]).max(axis=1) - 1.2)
    assert on_edge.max() < 1e-12 and np.abs(out.nodes[sliding, 2]).max() < 1e-12, "on the square's edges, z = 0"


def test_the_matrix_is_factored_once(dome, monkeypatch):
    surface, grid = dome
    calls = []
    original = optimize_module.spla.factorized

    def counting(matrix):
        calls.append(matrix.shape)
        return original(matrix)

    monkeypatch.setattr(optimize_module.spla, "factorized", counting)
    monkeypatch.setattr(optimize_module.spla, "splu", lambda *a, **k: pytest.fail("splu called"))
    result = optimize(grid, surface, None, OptimizeSettings(iterations=12))
    assert len(calls) == 1 and result.quality["iterations"] == 12


def _flat_square() -> TriMesh:
    n = 12
    x, y = np.meshgrid(np.linspace(-1, 1, n + 1), np.linspace(-1, 1, n + 1), indexing="ij")
    return TriMesh(vertices=np.c_[x.ravel(), y.ravel(), np.zeros(x.size)], faces=grid_triangles(n, n))


def test_zero_regularity_weight_gives_no_regularity_change_beyond_planarity():
    """On a plane the jittered honeycomb is already planar and on the surface: without regularity
    (and fairness) nothing moves; with regularity the cells become more regular."""
    surface = _flat_square()
    grid = _grid_on(surface, 0.4, jitter=0.12)
    still = optimize(grid, surface, None, OptimizeSettings(regularity_weight=0.0, fairness_weight=0.0, iterations=20))
    assert np.abs(still.polymesh.nodes - grid.nodes).max() < 1e-9
    assert still.quality["after"]["regularity"] == pytest.approx(still.quality["before"]["regularity"], abs=1e-9)
    regular = optimize(grid, surface, None, OptimizeSettings(fairness_weight=0.0, iterations=20))
    assert regular.quality["after"]["regularity"] < 0.7 * regular.quality["before"]["regularity"]
    assert np.abs(regular.polymesh.nodes[:, 2]).max() < 1e-12, "a plane stays a plane"


def test_planar_false_ignores_the_planarity_weight_and_trades_planarity_for_regularity(dome):
    surface, grid = dome
    a = optimize(grid, surface, None, OptimizeSettings(iterations=20, planar=False))
    b = optimize(grid, surface, None, OptimizeSettings(iterations=20, planar=False, planarity_weight=7.0))
    assert np.array_equal(a.polymesh.nodes, b.polymesh.nodes)
    planar = optimize(grid, surface, None, OptimizeSettings(iterations=20))
    interior = ~grid.face_boundary
    assert _relative_planarity(planar.polymesh)[interior].max() < _relative_planarity(a.polymesh)[interior].max()
    assert a.quality["after"]["regularity"] < planar.quality["after"]["regularity"]


def test_progress_is_reported_and_zero_iterations_change_nothing(dome):
    surface, grid = dome
    seen = []
    optimize(grid, surface, None, OptimizeSettings(iterations=3), progress=lambda text, f: seen.append(f))
    assert seen == pytest.approx([1 / 3, 2 / 3, 1.0])
    none = optimize(grid, surface, None, OptimizeSettings(iterations=0))
    assert np.array_equal(none.polymesh.nodes, grid.nodes) and none.quality["iterations"] == 0


def test_user_mistakes_raise_input_errors(dome):
    surface, grid = dome
    with pytest.raises(InputError):
        OptimizeSettings(closeness_weight=-1.0)
    with pytest.raises(InputError):
        OptimizeSettings(iterations=-5)
    broken = PolyMesh(nodes=np.full((3, 3), np.nan), faces=(np.array([0, 1, 2]),))
    with pytest.raises(InputError):
        optimize(broken, surface, None, OptimizeSettings())
