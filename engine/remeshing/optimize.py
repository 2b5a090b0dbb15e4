"""Regular, planar cells that stay on the surface (METHOD.md section 4).

Local/global iterations in the manner of Shape-Up (Bouaziz et al. 2012) and ShapeOp.

Local step, per cell: (regularity) the PCA of its nodes in its best-fit plane, un-stretched by
the square roots of the eigenvalues so that the cell's own anisotropy is kept (up to
``max_cell_stretch``), a regular polygon of the cell's *target* area fitted by a rigid rotation
(2-D Procrustes), stretched back. The target area is regular relative to the field's size: the
field's h^2 at the cell, times the area its neighbourhood of cells has per unit of h^2 in the grid
as given (the remesher's cell count kept, the field followed instead of the remesher's noise),
compressed monotonically over the whole grid only as far as the joints' shortest beam demands
(:func:`graded_areas`). With each cell's given area instead, the regular targets pulled cells
toward their neighbours' sizes in noise, and the joints' projections lengthened the small cells'
beams at their neighbours' expense: both lost grading (issue 13); (planarity)
the nodes projected onto the best-fit plane. Per node: (closeness) the nearest point of the
reference surface, or the node itself within a band of it (planar panels only: the band lets nodes
leave the surface as far as planar cells need, and no farther, :func:`closeness_bounds`);
(fairness) the given position plus the mean of its neighbours' displacements
(interior nodes): the displacement is smoothed, not the grid, so fairness does not even out the
cell sizes either.

Global step: the weighted least-squares fit of all targets,

    S * sum_cells ||C x - ((1 - t) R + t P)||^2 + sum_nodes E * ||x_i - ((1 - f) s_i + f m_i)||^2,

C the translation-free rows (x_j - mean of the cell), R, P the mean-free regular and planar
targets, s_i the closest surface point, m_i = x0_i + mean_j (x_j - x0_j) over the neighbours. The shape weight
S = K (w_regularity + w_planarity) and the node weight E = w_closeness + w_fairness are constant;
only the blends t (planarity share) and f (fairness share) change over the iterations, so the
matrix is the same every iteration and is factored ONCE. The planarity share is ramped from
w_p / (w_r + w_p) up to 1, and the last iterations are pure planarity + closeness (t = 1, f = 0).

Constraints: corners and supports are fixed (their DOFs are eliminated); a free boundary node
moves along the tangent of the surface's boundary polyline at its start position (one DOF) and is
projected back onto the polyline after each step (exact on straight boundary edges). After each
step, too, the fabrication limits are projections (:mod:`engine.geometry.projections`): narrow corners
open to ``min_corner_angle_deg``, short beams lengthen to their buildable length, both moving nodes
along the surface only (its tangent plane at each node).

For planar panels (``planar``) two more steps, both reported in the quality record:

- before the iterations, boundary cells whose plane the boundary itself forces away from the
  surface are split by new beams (:mod:`engine.remeshing.boundary_splits`: cells holding a corner and
  nodes on both of its edges; chains of cells along a straight edge, which must share one plane);
- after them, the end game (:mod:`engine.remeshing.planarise`): Gauss-Newton on nodes and planes with the
  planarity as a growing per-cell penalty, closeness as a band, regularity as in the iterations,
  and guards on corner angles and beam lengths, until every cell is within
  ``planarity_tolerance`` of the mean beam length of its plane. Boundary cells it leaves beyond
  the tolerance lose the triangle at their boundary beam (one new beam each) and the end game
  resumes, at most REPAIR_ROUNDS times.

The local/global iterations alone stall at a few per cent of the mean beam length: they are
block-coordinate descent on the same energy, first order, and the final pull-back onto the
closeness limit undoes part of their planarity.

The pieces of the iterations (the cells' targets and target areas, the closest points on the surface
and its boundary, the global step's operators) are in :mod:`engine.remeshing.local_global`; here are the
settings, the quality figures and the phases of :func:`optimize`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from functools import partial
from typing import Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.spatial import cKDTree

from ..errors import InputError
from ..geometry.projections import (
    CellFans,
    face_corners,
    folded_cells,
    lengthen_short_beams,
    open_narrow_corners,
    unfolded,
)
from ..geometry.symmetry import PARTNER_REACH, mirror_partners, symmetrise_points
from ..mesh import PolyMesh, TriMesh
from .boundary_splits import cut_boundary_triangles, split_boundary_cells
from .field import GuidingField
from .local_global import (
    ClosestBoundaryPoints,
    ClosestSurfacePoints,
    cell_adjacency,
    cell_areas,
    cell_frames,
    cell_ids_by_degree,
    cells_by_degree,
    centering_rows,
    free_dof_basis,
    graded_areas,
    into_band,
    neighbour_mean,
    planar_targets,
    regular_targets,
    stacked_targets,
    unstretched_cells,
)
from .planarise import PlanariseSettings, planarise

log = logging.getLogger(__name__)

__all__ = ["OptimizeSettings", "OptimizeResult", "optimize", "regular_targets", "planar_targets",
           "optimize_quality", "grid_quality", "lengthen_short_beams"]


@dataclass(frozen=True, kw_only=True)
class OptimizeSettings:
    """Weights of the four terms (dimensionless, relative), the number of local/global
    iterations, and whether panels must be planar (planar False: the planarity weight is ignored).

    With ``planar`` (and a planarity weight > 0): planarity_tolerance, the largest wanted node
    distance from its cell's plane relative to the mean beam length; planarity_iterations, the
    largest number of Gauss-Newton steps of the end game (0: none); split_cells, whether boundary
    cells that the boundary holds out of plane are split by new beams first; min_beam_length (m),
    the shortest beam the end game leaves (the shortest buildable beam; 0: none); min_corner_angle_deg,
    the smallest cell corner it closes to (the smallest angle a joint takes); max_cell_stretch, the
    most a cell's regularity target is stretched along its own principal axis (the field's aspect
    bound, with a margin: slivers are made rounder, inf: cells keep any anisotropy); keep_grading,
    whether the regularity targets keep each cell's given area and fairness smooths the
    displacement (the field's grading stays), or take each cell's current area and smooth the grid
    (sizes even out). The local/global iterations, too, hold beams to min_beam_length and corners
    to min_corner_angle_deg. With keep_grading: follow_field, whether a cell's target area follows
    the field's size among its neighbours (else it is the cell's given area); grading_quantile, the
    share of interior cells whose regular side may stay under min_beam_length before the grading
    is compressed (see :func:`graded_areas`; the iterations' projections lengthen those beams).
    symmetry_planes: (point, normal) pairs (m) the nodes are kept symmetric about (engine.geometry.symmetry:
    mirror pairs of the given grid moved to their mirrored mean after every step), none by default.
    """

    regularity_weight: float = 1.0
    planarity_weight: float = 1.0
    closeness_weight: float = 1.0
    fairness_weight: float = 0.1
    iterations: int = 50
    planar: bool = True
    planarity_tolerance: float = 0.005
    planarity_iterations: int = 80
    split_cells: bool = True
    min_beam_length: float = 0.0
    min_corner_angle_deg: float = 20.0
    max_cell_stretch: float = np.inf
    keep_grading: bool = True
    follow_field: bool = True
    grading_quantile: float = 0.2
    symmetry_planes: tuple = ()

    def __post_init__(self) -> None:
        for name in ("regularity_weight", "planarity_weight", "closeness_weight", "fairness_weight"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise InputError(f"optimize: {name} must be a finite number >= 0, got {value}",
                                 hint="weights are relative; use 0 to switch a term off")
        for name in ("iterations", "planarity_iterations"):
            value = getattr(self, name)
            if int(value) != value or value < 0:
                raise InputError(f"optimize: {name} must be a whole number >= 0, got {value}")
        if not (0 <= self.grading_quantile < 1):
            raise InputError(f"optimize: grading_quantile must be in [0, 1), got {self.grading_quantile}",
                             hint="the share of cells whose regular side may stay under the shortest beam: 0.2")
        if not (np.isfinite(self.planarity_tolerance) and 0 < self.planarity_tolerance < 1):
            raise InputError(f"optimize: planarity_tolerance must be in (0, 1), got {self.planarity_tolerance}",
                             hint="relative to the mean beam length: 0.005 is 0.5 %")


@dataclass(frozen=True, kw_only=True)
class OptimizeResult:
    """The optimised grid-shell and the figures before and after (JSON-ready dict)."""

    polymesh: PolyMesh
    quality: dict


#: Shape rows (regularity + planarity) against node rows (closeness + fairness): S = K (w_r + w_p).
SHAPE_SCALE = 4.0
#: Share of the iterations (at least one) at the end that are pure planarity + closeness.
FINAL_SHARE = 0.3
#: Weight of the damping term ||x - x_current||^2 relative to S + E (keeps the system regular).
DAMPING = 1e-6
#: Anderson acceleration (Peng et al. 2018) of the final, pure planarity + closeness iterations:
#: number of previous iterates combined (0: off). Steps that raise the energy are rejected.
ANDERSON_DEPTH = 6
#: Closeness tolerance band, relative to the surface's bounding-box diagonal: a node within the band
#: is its own closeness target (free to leave the surface for planarity), one outside is pulled
#: back to the band's edge.
CLOSENESS_BAND = 0.0025
#: Hard limit of the node distance to the surface after the iterations, relative to the diagonal.
CLOSENESS_LIMIT = 0.0045
#: Rounds of the limit projections (corners, then beams) after the last local/global iteration.
FINAL_HOLD_ROUNDS = 3
#: Planarity share in the final iterations (1: pure planarity + closeness).
FINAL_PLANARITY = 1.0
#: Closeness band of the end game, relative to the diagonal (below the hard limit CLOSENESS_LIMIT).
END_BAND = 0.004
#: The band, the end game's band and the hard limit relative to the grid's mean beam: each bound is
#: the smaller of its share of the diagonal and its share of the mean beam. A planar cell of side r
#: on a surface of radius R stands off it by about r^2 / 2R, some 6 % of r on the 2.4 m mock-up's
#: 60 cells; bounds from the diagonal alone let a grid of small cells crumple in a band several
#: times their depth (Hall at 1500 cells: nodes 148 mm off the surface with 0.39 m beams).
BAND_PER_BEAM = 0.05
END_BAND_PER_BEAM = 0.08
LIMIT_PER_BEAM = 0.09
#: A boundary cell is split where the plane its boundary nodes force on it is farther than this
#: share of the end game's band from one of its inner nodes (engine.remeshing.boundary_splits).
SPLIT_HOLD = 0.5
#: Boundary nodes within this share of the planarity tolerance of a line count as on it.
SPLIT_STRAIGHTNESS = 0.5
#: Rounds in which boundary cells that the end game left beyond the tolerance lose the triangle
#: at their boundary beam (one new beam each) before the end game resumes.
REPAIR_ROUNDS = 2


@dataclass(frozen=True, kw_only=True)
class ClosenessBounds:
    """How far nodes may stand off the surface (m): ``band``, within which a node of the iterations
    is its own closeness target (free to leave the surface for planarity); ``end_band``, the end
    game's band; ``limit``, the hard limit after both."""

    band: float
    end_band: float
    limit: float


def closeness_bounds(diagonal: float, mean_beam: float, *, planar: bool) -> ClosenessBounds:
    """The closeness bounds of a grid of mean beam ``mean_beam`` (m) on a surface of bounding-box
    diagonal ``diagonal`` (m): each the smaller of its share of the diagonal and of the mean beam
    (CLOSENESS_BAND, END_BAND, CLOSENESS_LIMIT; BAND_PER_BEAM, END_BAND_PER_BEAM, LIMIT_PER_BEAM).
    Without planar panels the iterations' band is 0: nothing asks a node to leave the surface."""
    limit = min(CLOSENESS_LIMIT * diagonal, LIMIT_PER_BEAM * mean_beam)
    end_band = min(END_BAND * diagonal, END_BAND_PER_BEAM * mean_beam)
    band = min(CLOSENESS_BAND * diagonal, BAND_PER_BEAM * mean_beam) if planar else 0.0
    return ClosenessBounds(band=band, end_band=end_band, limit=limit)


# ----------------------------------------------------------------------------- quality

def optimize_quality(polymesh: PolyMesh, mesh: TriMesh | None = None, *,
                     surface: ClosestSurfacePoints | None = None) -> dict:
    """Figures of a grid-shell (JSON-ready): planarity_max_m, planarity_p95_m (largest node distance
    from a cell's best-fit plane), planarity_max_rel, planarity_p95_rel (to the mean beam length),
    regularity (mean over cells of std/mean of edge lengths after un-stretching the cell's own
    anisotropy), closeness_max_rel, closeness_mean_rel (node distance to the surface / bounding-box
    diagonal, with a mesh; closeness_max_beam_rel: the largest to the mean beam length),
    shortest_beam_m, mean_beam_length_m, smallest_angle_deg, nonconvex_faces (cells with a reflex
    corner in their best-fit plane); with a surface also
    folded_cells (cells that, seen along the surface's normal, cross themselves or are turned over,
    so that they overlap a neighbour: engine.geometry.projections.folded_cells)."""
    x = np.asarray(polymesh.nodes, dtype=float)
    lengths = polymesh.beam_lengths
    mean_length = float(lengths.mean()) if len(lengths) else 0.0
    planarity, regularity, smallest, nonconvex = [], [], 180.0, 0
    for k, faces in cells_by_degree(polymesh.faces).items():
        points = x[faces]
        centroid, axes, normal = cell_frames(points)
        distance = np.abs(np.einsum("fki,fi->fk", points - centroid[:, None], normal)).max(axis=1)
        planarity.append(distance if k > 3 else np.zeros(len(faces)))
        if k > 3:
            local = np.einsum("fki,fji->fkj", points - centroid[:, None], axes)
            edge = np.roll(local, -1, axis=1) - local
            following = np.roll(edge, -1, axis=1)
            turn = edge[:, :, 0] * following[:, :, 1] - edge[:, :, 1] * following[:, :, 0]
            area = 0.5 * np.sum(local[:, :, 0] * np.roll(local[:, :, 1], -1, axis=1)
                                - np.roll(local[:, :, 0], -1, axis=1) * local[:, :, 1], axis=1)
            size = np.einsum("fki,fki->f", edge, edge) / k
            nonconvex += int(np.sum(np.any(turn * np.sign(area)[:, None] < -1e-9 * size[:, None], axis=1)))
        unstretched = unstretched_cells(points)[0]
        edges = np.linalg.norm(unstretched - np.roll(unstretched, -1, axis=1), axis=2)
        regularity.append(edges.std(axis=1) / np.maximum(edges.mean(axis=1), 1e-300))
        a, b = np.roll(points, 1, axis=1) - points, np.roll(points, -1, axis=1) - points
        cosine = np.einsum("fki,fki->fk", a, b) / np.maximum(
            np.linalg.norm(a, axis=2) * np.linalg.norm(b, axis=2), 1e-300)
        smallest = min(smallest, float(np.degrees(np.arccos(np.clip(cosine, -1, 1))).min()))
    planarity_all = np.concatenate(planarity) if planarity else np.zeros(0)
    regularity_all = np.concatenate(regularity) if regularity else np.zeros(0)
    scale = max(mean_length, 1e-300)
    out = {
        "planarity_max_m": float(planarity_all.max()) if len(planarity_all) else 0.0,
        "planarity_p95_m": float(np.percentile(planarity_all, 95)) if len(planarity_all) else 0.0,
        "planarity_max_rel": float(planarity_all.max() / scale) if len(planarity_all) else 0.0,
        "planarity_p95_rel": float(np.percentile(planarity_all, 95) / scale) if len(planarity_all) else 0.0,
        "regularity": float(regularity_all.mean()) if len(regularity_all) else 0.0,
        "shortest_beam_m": float(lengths.min()) if len(lengths) else 0.0,
        "mean_beam_length_m": mean_length,
        "smallest_angle_deg": smallest,
        "nonconvex_faces": nonconvex,
    }
    if mesh is not None or surface is not None:
        if surface is None:
            assert mesh is not None
            surface = ClosestSurfacePoints(mesh)
        distance = surface.closest(x)[1]
        out["closeness_max_rel"] = float(distance.max() / surface.diagonal)
        out["closeness_mean_rel"] = float(distance.mean() / surface.diagonal)
        out["closeness_max_beam_rel"] = float(distance.max() / scale)
        fans = CellFans(polymesh.faces)
        out["folded_cells"] = int(len(folded_cells(x, fans, surface.closest_normals(fans.centroids(x))[1])))
    return out


def grid_quality(polymesh: PolyMesh, mesh: TriMesh, field: GuidingField | None, *,
                 surface: ClosestSurfacePoints | None = None, figures: dict | None = None) -> dict:
    """:func:`optimize_quality` (or ``figures`` already measured) with the remesher's wider figures
    (cell degrees, sizes against the field: engine.remeshing.voronoi.polymesh_quality) added."""
    from .voronoi import polymesh_quality

    out = dict(figures) if figures is not None else optimize_quality(polymesh, mesh if surface is None else None,
                                                                     surface=surface)
    for key, value in polymesh_quality(polymesh, mesh=mesh, field=field).items():
        out.setdefault(key, value)
    return out


# ----------------------------------------------------------------------------- (a) set-up

def _check(polymesh: PolyMesh, mesh: TriMesh) -> None:
    """Refuses a grid without nodes or cells, with non-finite nodes or cells of fewer than three nodes,
    and a surface without triangles."""
    if polymesh.n_nodes == 0 or polymesh.n_faces == 0:
        raise InputError("optimize: the grid-shell has no nodes or no cells",
                         hint="run the remesh stage first and check that it produced cells")
    if not np.all(np.isfinite(polymesh.nodes)):
        raise InputError("optimize: the grid-shell has non-finite node coordinates")
    degrees = polymesh.face_degrees
    if degrees.min() < 3:
        raise InputError(f"optimize: a cell has {int(degrees.min())} nodes; cells need at least 3")
    if mesh.n_faces == 0:
        raise InputError("optimize: the reference surface has no triangles")


def _schedule(settings: OptimizeSettings) -> tuple[float, list[tuple[float, float]]]:
    """Shape weight S and per iteration (planarity share t, fairness share f of E)."""
    w_r = settings.regularity_weight
    w_p = settings.planarity_weight if settings.planar else 0.0
    w_c, w_f = settings.closeness_weight, settings.fairness_weight
    shape = SHAPE_SCALE * (w_r + w_p)
    fair = w_f / (w_c + w_f) if w_c + w_f > 0 else 0.0
    n = int(settings.iterations)
    if w_p == 0:
        return shape, [(0.0, fair)] * n
    final = min(n, max(1, int(round(FINAL_SHARE * n))))
    main = n - final
    t0 = w_p / (w_r + w_p)
    plan = [(t0 + (1 - t0) * (i / max(main, 1)), fair) for i in range(main)]
    return shape, plan + [(FINAL_PLANARITY, 0.0)] * final


@dataclass(frozen=True, kw_only=True)
class _GlobalStep:
    """The global step's constant system: centering rows C, neighbour mean, shape and node weights,
    damping, the plan of blends (t, f), A (3n x 3n), the basis B of the free DOFs and the factor of
    B^T A B (None: nothing to solve)."""

    C: sp.csr_matrix
    neighbours: sp.csr_matrix
    shape: float
    node_weight: float
    damping: float
    plan: list[tuple[float, float]]
    A3: sp.csr_matrix
    B: sp.csr_matrix
    solve: Callable[[np.ndarray], np.ndarray] | None


@dataclass(frozen=True, kw_only=True)
class _Problem:
    """What the phases share: the grid as split, its constraints, the surface and its boundary, the
    mirror partners, the target areas, the fabrication limits and the global step."""

    settings: OptimizeSettings
    given: PolyMesh  # the grid as given
    polymesh: PolyMesh  # the grid the iterations move: split where the boundary holds cells out of plane
    new_beams: np.ndarray  # (b, 2) node ids of the splits' beams
    corner_splits: int
    edge_splits: int
    with_end_game: bool
    surface: ClosestSurfacePoints
    boundary: ClosestBoundaryPoints
    fixed: np.ndarray
    sliding: np.ndarray
    interior: np.ndarray
    movable: np.ndarray
    local: bool  # only a region of the grid moves: the rest is held, and only its cells and nodes are worked on
    start: np.ndarray  # (n, 3) the first iterate: the nodes, sliding ones on the boundary
    x0: np.ndarray  # a copy of it: what fairness and the target areas refer to
    groups: dict[int, np.ndarray]
    planes: tuple
    partners: np.ndarray | None
    field: GuidingField | None
    nearest_vertex: cKDTree | None
    areas: dict[int, np.ndarray | None]
    grading: dict
    corners: np.ndarray  # (c, 3) the corners the limits may open (local: those with a far node that moves)
    fans: CellFans  # the cells, which no step of the iterations may fold
    moving_cells: np.ndarray | None  # (cells,) bool, those with a node that moves (local problems)
    fan_normals: dict = dataclass_field(default_factory=dict)  # "held": the surface normals at the cells at the start
    min_corner: float  # rad
    beam_length_limits: Callable[[PolyMesh], np.ndarray] | None
    system: _GlobalStep
    mean_length: float  # of the grid as given, m
    closeness: ClosenessBounds


def _target_areas(groups: dict[int, np.ndarray], grid: PolyMesh, x0: np.ndarray, settings: OptimizeSettings,
                  field: GuidingField | None,
                  nearest_vertex: cKDTree | None) -> tuple[dict[int, np.ndarray | None], dict]:
    """(the cells' target areas (None: each cell's current area), the grading's slopes): the grid's grading,
    following the field among neighbouring cells and compressed as far as the joints demand (graded_areas)."""
    grading: dict = {"given_slope": None, "target_slope": None}
    if not settings.keep_grading:
        return {k: None for k in groups}, grading
    ids = cell_ids_by_degree(grid.faces)
    area, centroid = np.zeros(grid.n_faces), np.zeros((grid.n_faces, 3))
    for k, f in groups.items():
        area[ids[k]] = cell_areas(x0[f])
        centroid[ids[k]] = x0[f].mean(axis=1)
    sizes = (field.size[nearest_vertex.query(centroid)[1]]
             if nearest_vertex is not None and field is not None else None)
    target, grading["given_slope"], grading["target_slope"] = graded_areas(
        area, sizes, ~grid.face_boundary, cell_adjacency(grid.faces),
        min_side=settings.min_beam_length, quantile=settings.grading_quantile)
    return {k: target[ids[k]] for k in groups}, grading


def _global_step_system(settings: OptimizeSettings, groups: dict[int, np.ndarray], edges: np.ndarray, n: int,
                        interior: np.ndarray, sliding: np.ndarray, tangents: np.ndarray) -> _GlobalStep:
    """The global step's matrix, the same every iteration, factored once (when the plan has steps)."""
    C = centering_rows(groups, n)
    neighbours = neighbour_mean(edges, n)
    shape, plan = _schedule(settings)
    node_weight = settings.closeness_weight + settings.fairness_weight
    damping = DAMPING * max(shape + node_weight, 1.0)
    A = shape * (C.T @ C) + (node_weight + damping) * sp.eye(n)
    A3 = sp.kron(A, sp.eye(3), format="csr")
    B = free_dof_basis(n, interior, sliding, tangents)
    solve = spla.factorized((B.T @ A3 @ B).tocsc()) if B.shape[1] and plan else None
    return _GlobalStep(C=C, neighbours=neighbours, shape=shape, node_weight=node_weight, damping=damping, plan=plan,
                       A3=A3, B=B, solve=solve)


def _active_cells(groups: dict[int, np.ndarray], areas: dict[int, np.ndarray | None],
                  fixed: np.ndarray) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray | None]]:
    """``groups`` and their target ``areas`` less the cells whose nodes are all fixed (nothing moves them)."""
    kept_groups, kept_areas = {}, {}
    for k, faces in groups.items():
        keep = ~fixed[faces].all(axis=1)
        if keep.any():
            kept_groups[k] = faces[keep]
            area = areas[k]
            kept_areas[k] = None if area is None else area[keep]
    return kept_groups, kept_areas


def _set_up(polymesh: PolyMesh, mesh: TriMesh, field: GuidingField | None, settings: OptimizeSettings,
            surface: ClosestSurfacePoints, before: dict,
            beam_length_limits: Callable[[PolyMesh], np.ndarray] | None,
            held: np.ndarray | None = None) -> _Problem:
    """The problem: boundary cells split (planar panels), corners, supports and the ``held`` nodes
    fixed, boundary nodes sliding, the rest interior; the mirror partners, the target areas and the
    global step (over the cells that have a node to move only, where nodes are held)."""
    planar_panels = settings.planar and settings.planarity_weight > 0 and settings.iterations > 0
    given = polymesh
    mean_length = max(before["mean_beam_length_m"], 1e-300)
    closeness = closeness_bounds(surface.diagonal, mean_length, planar=planar_panels)
    new_beams = np.zeros((0, 2), dtype=np.int64)
    corner_splits = edge_splits = 0
    if planar_panels and settings.split_cells:
        tolerance = settings.planarity_tolerance * before["mean_beam_length_m"]
        splits = split_boundary_cells(polymesh, hold=SPLIT_HOLD * closeness.end_band,
                                      straightness=SPLIT_STRAIGHTNESS * tolerance)
        polymesh, new_beams = splits.polymesh, splits.new_beams
        corner_splits, edge_splits = splits.corner_splits, splits.edge_splits
    n = polymesh.n_nodes
    fixed = polymesh.corners | polymesh.supports
    local = held is not None
    if held is not None:
        fixed = fixed | np.r_[np.asarray(held, dtype=bool), np.zeros(n - len(held), dtype=bool)]
    boundary = ClosestBoundaryPoints(mesh)
    sliding = polymesh.boundary & ~fixed
    if sliding.any() and not len(boundary.segments):
        raise InputError("optimize: the grid-shell has boundary nodes but the surface has no boundary",
                         hint="closed surfaces: clear the boundary flags of the grid-shell")
    interior = ~polymesh.boundary & ~fixed
    x = np.array(polymesh.nodes, dtype=float)
    tangents = np.zeros((n, 3))
    if sliding.any() and settings.iterations > 0:
        x[sliding], tangents[sliding] = boundary.closest(x[sliding])
    groups = cells_by_degree(polymesh.faces)
    x0 = x.copy()
    planes = tuple(settings.symmetry_planes)
    partners = mirror_partners(x, planes, PARTNER_REACH * float(polymesh.beam_lengths.mean())) if planes else None
    nearest_vertex = cKDTree(mesh.vertices) if field is not None and settings.follow_field else None
    areas, grading = _target_areas(groups, polymesh, x0, settings, field, nearest_vertex)
    movable = interior | sliding
    fans = CellFans(polymesh.faces)
    corners = face_corners(polymesh.faces)
    moving_cells = None
    if local:
        groups, areas = _active_cells(groups, areas, fixed)
        moving_cells = np.zeros(fans.n_cells, dtype=bool)
        np.logical_or.at(moving_cells, fans.cell, movable[fans.corners[:, 1]])
        corners = corners[movable[corners[:, 0]] | movable[corners[:, 2]]]  # the others cannot be opened
    return _Problem(settings=settings, given=given, polymesh=polymesh, new_beams=new_beams,
                    corner_splits=corner_splits, edge_splits=edge_splits,
                    with_end_game=planar_panels and settings.planarity_iterations > 0,
                    surface=surface, boundary=boundary, fixed=fixed, sliding=sliding, interior=interior,
                    movable=movable, local=local, start=x, x0=x0, groups=groups, planes=planes,
                    partners=partners,
                    field=field, nearest_vertex=nearest_vertex, areas=areas, grading=grading,
                    corners=corners, fans=fans, moving_cells=moving_cells,
                    min_corner=float(np.radians(settings.min_corner_angle_deg)),
                    beam_length_limits=beam_length_limits,
                    system=_global_step_system(settings, groups, polymesh.edges, n, interior, sliding, tangents),
                    mean_length=mean_length, closeness=closeness)


# ----------------------------------------------------------------------------- (b) local/global iterations

def _symmetric(p: _Problem, x: np.ndarray) -> np.ndarray:
    """x with mirror pairs at their mirrored mean, boundary nodes back on the boundary."""
    if p.partners is None:
        return x
    x = symmetrise_points(x, p.planes, p.partners, p.fixed)
    if p.sliding.any():
        x[p.sliding] = p.boundary.closest(x[p.sliding])[0]
    return x


def _hold_limits(p: _Problem, x: np.ndarray, sweeps: int = 3) -> np.ndarray:
    """x with narrow corners opened and short beams lengthened along the surface, boundary nodes back
    on the boundary. The moves keep only their part along the surface's tangent plane at each node:
    where the surface has no room for the beams the joints take, a move out of it would lengthen
    them by crumpling the grid, and the regularity targets, taken in each cell's own plane, keep a
    crumple once made."""
    given = x
    if p.min_corner > 0:
        x = open_narrow_corners(x, p.corners, p.min_corner, p.movable, sweeps=sweeps)
    minimum = p.settings.min_beam_length
    if p.beam_length_limits is not None:
        minimum = np.maximum(minimum, p.beam_length_limits(p.polymesh.replace_nodes(x)))
    if np.any(np.asarray(minimum) > 0):
        x = lengthen_short_beams(x, p.polymesh.edges, minimum, p.movable, sweeps=sweeps)
    moved = np.flatnonzero(np.any(x != given, axis=1))
    if len(moved):
        normal = p.surface.closest_normals(given[moved])[1]
        step = x[moved] - given[moved]
        x[moved] = given[moved] + step - np.einsum("ij,ij->i", step, normal)[:, None] * normal
    if p.sliding.any():
        x[p.sliding] = p.boundary.closest(x[p.sliding])[0]
    return x


def _unfolded(p: _Problem, x: np.ndarray, new: np.ndarray) -> np.ndarray:
    """The step from x to ``new`` but for the nodes of the cells it would fold, which stay at x
    (crowded limits and the targets of the cells that collapses and flips left can turn a cell over
    on the surface: engine.geometry.projections.unfolded). In a local problem the surface's normals
    at the cells of held nodes only are kept from the first step: those cells do not move."""
    centroids = p.fans.centroids(x)
    if p.moving_cells is None:
        return unfolded(x, new, p.fans, p.surface.closest_normals(centroids)[1])
    up = p.fan_normals.get("held")
    if up is None:
        up = p.fan_normals["held"] = p.surface.closest_normals(centroids)[1]
    else:
        up = up.copy()
        up[p.moving_cells] = p.surface.closest_normals(centroids[p.moving_cells])[1]
    return unfolded(x, new, p.fans, up)


def _local_step(p: _Problem, x: np.ndarray, t: float, f: float) -> tuple[np.ndarray, float]:
    """Right-hand side of the global step at x and the energy of the current phase at x
    (planarity share t, fairness share f)."""
    s, settings = p.system, p.settings
    points = {k: x[faces] for k, faces in p.groups.items()}
    target = np.zeros((s.C.shape[0], 3))
    if s.shape > 0:
        if t < 1.0:
            target += (1 - t) * stacked_targets(p.groups, {
                k: regular_targets(cells, settings.max_cell_stretch, p.areas[k]) for k, cells in points.items()})
        if t > 0.0:
            target += t * stacked_targets(p.groups, {k: planar_targets(cells) for k, cells in points.items()})
    if p.local:  # the held nodes' targets do not count: their DOFs are not solved for
        node_target = x.copy()
        node_target[p.movable] = into_band(x[p.movable], *p.surface.closest(x[p.movable]), p.closeness.band)
    else:
        node_target = into_band(x, *p.surface.closest(x), p.closeness.band)
    if f > 0:
        # keep_grading: a smooth displacement, so that sizes keep their grading; else the grid
        smooth = p.x0 + s.neighbours @ (x - p.x0) if settings.keep_grading else s.neighbours @ x
        node_target[p.interior] = (1 - f) * node_target[p.interior] + f * smooth[p.interior]
    energy = s.shape * float(np.sum((s.C @ x - target) ** 2)) + s.node_weight * float(np.sum((x - node_target) ** 2))
    return s.shape * (s.C.T @ target) + s.node_weight * node_target + s.damping * x, energy


def _global_step(p: _Problem, x: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """The least-squares fit of the targets ``rhs`` from x over the free DOFs, boundary nodes back on the boundary."""
    s = p.system
    assert s.solve is not None  # factored whenever the plan has steps to solve
    residual = rhs.ravel() - s.A3 @ x.ravel()
    new = x + (s.B @ s.solve(s.B.T @ residual)).reshape(p.polymesh.n_nodes, 3)
    if p.sliding.any():
        new[p.sliding] = p.boundary.closest(new[p.sliding])[0]
    return new


def _anderson(p: _Problem, x: np.ndarray, plain: np.ndarray, history_g: list[np.ndarray],
              history_f: list[np.ndarray]) -> np.ndarray | None:
    """Anderson's extrapolation of the plain step from x over the last ANDERSON_DEPTH + 1 iterates
    (the histories are extended and trimmed); None while they hold a single one."""
    g, r = plain.ravel(), (plain - x).ravel()
    history_g.append(g)
    history_f.append(r)
    new = None
    if len(history_f) > 1:
        dF = np.diff(np.array(history_f[-ANDERSON_DEPTH - 1:]), axis=0).T
        dG = np.diff(np.array(history_g[-ANDERSON_DEPTH - 1:]), axis=0).T
        theta = np.linalg.lstsq(dF, r, rcond=None)[0]
        new = (g - dG @ theta).reshape(p.polymesh.n_nodes, 3)
        if p.sliding.any():
            new[p.sliding] = p.boundary.closest(new[p.sliding])[0]
    del history_g[:-ANDERSON_DEPTH - 1], history_f[:-ANDERSON_DEPTH - 1]
    return new


@dataclass(frozen=True, kw_only=True)
class _Iterated:
    """The nodes after the local/global iterations; how many were done, the last one's largest node
    move (m), the Anderson steps taken and rejected, and whether a step left the reals."""

    x: np.ndarray
    done: int
    step: float
    accepted: int
    rejected: int
    stopped_non_finite: bool


def _iterate(p: _Problem, progress: Callable[[str, float | None], None] | None) -> _Iterated:
    """The local/global iterations along the plan, the final ones Anderson-accelerated (a point that
    raises the energy falls back to the plain step), the fabrication limits held after each step."""
    plan = p.system.plan
    x = p.start
    step, done, accepted, rejected = 0.0, 0, 0, 0
    stopped_non_finite = False
    first_final = next((i for i, (t, f) in enumerate(plan) if f == 0.0 and t == FINAL_PLANARITY), len(plan))
    history_g: list[np.ndarray] = []
    history_f: list[np.ndarray] = []
    previous_energy, previous_plain = np.inf, None
    for iteration, (t, f) in enumerate(plan if p.system.solve is not None else []):
        accelerate = ANDERSON_DEPTH > 0 and iteration >= first_final
        rhs, energy = _local_step(p, x, t, f)
        if accelerate and previous_plain is not None and energy > previous_energy:
            # the accelerated point raised the energy: fall back to the plain step, restart the history
            rejected += 1
            x = previous_plain
            history_g.clear()
            history_f.clear()
            rhs, energy = _local_step(p, x, t, f)
        plain = _global_step(p, x, rhs)
        new = plain
        if accelerate:
            extrapolated = _anderson(p, x, plain, history_g, history_f)
            if extrapolated is not None:
                new, accepted = extrapolated, accepted + 1
            previous_energy, previous_plain = energy, plain
        new = _symmetric(p, _hold_limits(p, new))
        if np.all(np.isfinite(new)):
            new = _unfolded(p, x, new)
        else:
            # a step that left the reals (a guard: the one CI failure that led to it was the plot of
            # workflow/plots/remesh.py, reading matplotlib's uninitialised padding): the
            # iterations end at the last finite grid, and the quality says so
            log.warning("optimize: iteration %d gave non-finite nodes; kept the grid of iteration %d",
                        iteration + 1, done)
            stopped_non_finite = True
            break
        step = float(np.linalg.norm(new - x, axis=1).max())
        x = new
        done = iteration + 1
        if progress is not None:
            progress(f"optimize: iteration {done}/{len(plan)}", done / len(plan))
    if previous_plain is not None and _local_step(p, x, *plan[-1])[1] > previous_energy:
        x = _unfolded(p, x, previous_plain)  # never end on an accelerated point that raised the energy
    if done:
        for _ in range(FINAL_HOLD_ROUNDS):  # the limits once more, to convergence of the sweeps
            held = _symmetric(p, _hold_limits(p, x, sweeps=10))
            if not np.all(np.isfinite(held)):
                stopped_non_finite = True
                break
            x = _unfolded(p, x, held)
    return _Iterated(x=x, done=done, step=step, accepted=accepted, rejected=rejected,
                     stopped_non_finite=stopped_non_finite)


# ----------------------------------------------------------------------------- (c) planarity end game

@dataclass(frozen=True, kw_only=True)
class _EndGame:
    """The nodes and the grid after the end game and its repair rounds, the new beams in all, the
    repairs' share of them, the end game's record (steps, rejected_steps, factorisations,
    planarity_weight, reached) and whether it left the reals."""

    x: np.ndarray
    polymesh: PolyMesh
    new_beams: np.ndarray
    repair_splits: int
    record: dict
    stopped_non_finite: bool


def _regular_rows(x: np.ndarray, *, groups: dict[int, np.ndarray], areas: dict[int, np.ndarray | None],
                  max_stretch: float) -> np.ndarray:
    """(rows, 3) mean-free regular targets of the cells ``groups`` at x, in the row order of centering_rows."""
    return stacked_targets(groups, {k: regular_targets(x[faces], max_stretch, areas[k]) for k, faces in groups.items()})


def _said_step(progress: Callable[[str, float | None], None] | None, base: int, steps: int) -> None:
    """Reports planarity step ``base + steps``."""
    if progress is not None:
        progress(f"optimize: planarity step {base + steps}", None)


def _end_game(p: _Problem, x: np.ndarray, progress: Callable[[str, float | None], None] | None) -> _EndGame:
    """The planarity end game (engine.remeshing.planarise) from x; boundary cells it leaves beyond the tolerance
    lose their boundary triangle and it resumes, at most REPAIR_ROUNDS times."""
    settings, surface = p.settings, p.surface
    polymesh, new_beams, groups, C = p.polymesh, p.new_beams, p.groups, p.system.C
    end = {"steps": 0, "rejected_steps": 0, "factorisations": 0, "planarity_weight": 0.0, "reached": False}
    repair_splits = 0
    stopped_non_finite = False
    for attempt in range(REPAIR_ROUNDS + 1 if p.with_end_game else 0):
        # the tolerance on the grid as split (new beams change the mean beam length)
        tolerance = settings.planarity_tolerance * float(polymesh.beam_lengths.mean())
        end_settings = PlanariseSettings(tolerance=tolerance, band=p.closeness.end_band,
                                         limit=p.closeness.limit,
                                         regularity_weight=SHAPE_SCALE * settings.regularity_weight,
                                         closeness_weight=settings.closeness_weight,
                                         iterations=settings.planarity_iterations,
                                         min_beam_length=settings.min_beam_length,
                                         min_angle_deg=settings.min_corner_angle_deg)
        if attempt == 0:  # the set-up's: the same call on the same grid
            areas = p.areas
        else:
            areas = _target_areas(groups, polymesh, p.x0, settings, p.field, p.nearest_vertex)[0]
            if p.local:
                groups, areas = _active_cells(groups, areas, p.fixed)
                C = centering_rows(groups, polymesh.n_nodes)
        regular = partial(_regular_rows, groups=groups, areas=areas, max_stretch=settings.max_cell_stretch)
        said = partial(_said_step, progress, int(end["steps"]))
        planarised, report = planarise(x, groups, interior=p.interior, sliding=p.sliding,
                                       closest=surface.closest_normals, slide=p.boundary.closest, centering=C,
                                       regular=regular, beams=polymesh.edges, settings=end_settings,
                                       reference=p.given.nodes, progress=said)
        planarised = _symmetric(p, planarised)
        if not np.all(np.isfinite(planarised)):
            log.warning("optimize: the planarity end game gave non-finite nodes; kept the grid before it")
            stopped_non_finite = True
            break
        x = planarised
        for key, value in (("steps", report.iterations), ("rejected_steps", report.rejected_steps),
                           ("factorisations", report.factorisations)):
            end[key] += value
        end["planarity_weight"], end["reached"] = max(end["planarity_weight"], report.planarity_weight), report.reached
        if report.reached or not settings.split_cells or attempt == REPAIR_ROUNDS:
            break
        # boundary cells the end game could not make planar lose their boundary triangle
        current = polymesh.replace_nodes(x.copy())
        failing = np.flatnonzero(current.face_boundary & (current.face_planarity() > tolerance))
        current, cut = cut_boundary_triangles(current, failing)
        if not len(cut):
            break
        polymesh, new_beams, repair_splits = current, np.r_[new_beams, cut], repair_splits + len(cut)
        groups = cells_by_degree(polymesh.faces)
        C = centering_rows(groups, polymesh.n_nodes)
    return _EndGame(x=x, polymesh=polymesh, new_beams=new_beams, repair_splits=repair_splits, record=end,
                    stopped_non_finite=stopped_non_finite)


# ----------------------------------------------------------------------------- (d) closeness band, (e) record

#: Rounds of "into the closeness limit, then symmetric" at most: the mirrored mean of two nodes
#: brought to the limit on a surface meshed a little unsymmetrically can lie beyond it again.
CLOSENESS_ROUNDS = 10


def _within_closeness_limit(p: _Problem, x: np.ndarray) -> tuple[np.ndarray, bool]:
    """(x with the nodes beyond the hard closeness limit brought back to it: the band is a soft
    constraint, whether that left the reals: then x as it was). With symmetry planes the nodes are
    made symmetric after, and the two are repeated (CLOSENESS_ROUNDS at most) until both hold."""
    limit = p.closeness.limit
    banded = x.copy()
    for _ in range(CLOSENESS_ROUNDS if p.partners is not None else 1):
        banded[p.movable] = into_band(banded[p.movable], *p.surface.closest(banded[p.movable]), limit)
        banded = _symmetric(p, banded)
        if not np.all(np.isfinite(banded)):
            return x, True
        if p.partners is None or p.surface.closest(banded[p.movable])[1].max(initial=0.0) <= limit * (1 + 1e-6):
            break
    return banded, False


def _quality_record(p: _Problem, mesh: TriMesh, field: GuidingField | None, before: dict, result: PolyMesh,
                    iterated: _Iterated, end: _EndGame, stopped_non_finite: bool) -> dict:
    """The quality dict of :func:`optimize` (its docstring lists the keys)."""
    before = grid_quality(p.given, mesh, field, figures=before)
    after = grid_quality(result, mesh, field, surface=p.surface)
    x, new_beams = result.nodes, end.new_beams
    split_length = float(np.linalg.norm(x[new_beams[:, 1]] - x[new_beams[:, 0]], axis=1).sum())
    converged = end.record["reached"] if p.with_end_game else bool(iterated.step <= 1e-4 * p.mean_length)
    settings = p.settings
    return {"before": before, "after": after, "iterations": iterated.done,
            "converged": bool(converged), "final_step_rel": iterated.step / p.mean_length,
            "factorisations": int(p.system.solve is not None) + end.record["factorisations"],
            "planar": bool(settings.planar),
            "accelerated_steps": iterated.accepted, "rejected_steps": iterated.rejected,
            "planarity_tolerance_rel": settings.planarity_tolerance,
            "planarity_reached": bool(after["planarity_max_rel"] <= settings.planarity_tolerance),
            "corner_splits": p.corner_splits, "edge_splits": p.edge_splits, "repair_splits": end.repair_splits,
            "split_beams": new_beams.tolist(), "split_length_m": split_length, "grading": p.grading,
            "stopped_non_finite": stopped_non_finite,
            "end_game": end.record if p.with_end_game else None}


# ----------------------------------------------------------------------------- driver

def optimize(polymesh: PolyMesh, mesh: TriMesh, field: GuidingField | None, settings: OptimizeSettings, *,
             progress: Callable[[str, float | None], None] | None = None,
             beam_length_limits: Callable[[PolyMesh], np.ndarray] | None = None,
             held: np.ndarray | None = None) -> OptimizeResult:
    """Regularise and (with ``settings.planar``) planarise the cells of ``polymesh`` on the
    reference surface ``mesh``; corners and supports stay put, boundary nodes on the boundary.

    ``field`` (or None) gives each cell's target size: the regularity targets' areas follow it among
    neighbouring cells (``settings.follow_field``; cells keep their own anisotropy).
    ``progress(text, fraction)`` is called once per iteration (fraction None in the end game).
    ``beam_length_limits(grid)`` gives each beam's shortest length (m) on the grid as it stands
    (the joints' set-backs grow as their angles close); the iterations hold every beam to the larger
    of it and ``settings.min_beam_length``.
    ``held`` (n_nodes,) bool: nodes held where they are, as supports are (None: none); only the
    cells with a node free to move are worked on, so optimising a grid again round a few local
    changes costs in proportion to the region let free.
    With ``settings.iterations == 0`` the grid passes unchanged.

    quality: "before" (the grid as given) and "after" figures (see :func:`optimize_quality`),
    "iterations" (local/global), "converged" (the end game reached the tolerance, or without it
    the last local/global step moved no node more than 1e-4 of the mean beam length),
    "final_step_rel", "factorisations" (one for the local/global iterations plus one per trial
    step of the end game), "planar", "accelerated_steps", "rejected_steps" (Anderson),
    "planarity_tolerance_rel", "planarity_reached" (largest planarity error within the tolerance),
    "corner_splits", "edge_splits", "repair_splits" (new beams by each rule), "split_beams" (node
    pairs of the new beams, ids of the result), "split_length_m" (their total length), "grading"
    (given_slope: the given grid's log-log slope of cell area against the field's h^2, target_slope:
    the regularity targets', lower where the joints compressed the grading; None without
    keep_grading), and
    "end_game" (steps, rejected_steps, factorisations, the largest relative planarity weight,
    reached; see :mod:`engine.remeshing.planarise`), None without it.
    """
    _check(polymesh, mesh)
    surface = ClosestSurfacePoints(mesh)
    before = optimize_quality(polymesh, surface=surface)
    problem = _set_up(polymesh, mesh, field, settings, surface, before, beam_length_limits, held)
    iterated = _iterate(problem, progress)
    end = _end_game(problem, iterated.x, progress)
    x, stopped_in_band = end.x, False
    if iterated.done:
        x, stopped_in_band = _within_closeness_limit(problem, x)
    result = end.polymesh.replace_nodes(x)
    stopped = iterated.stopped_non_finite or end.stopped_non_finite or stopped_in_band
    quality = _quality_record(problem, mesh, field, before, result, iterated, end, stopped)
    return OptimizeResult(polymesh=result, quality=quality)
