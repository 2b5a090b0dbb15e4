"""Reference grids for the same-length comparison (METHOD.md section 5): a regular triangular
and a regular square grid over the surface's plan, clipped to its outline (holes too), lifted
onto the surface, with the spacing found so that the total beam length matches a target within
1 % (the lattice is aligned with the plan's principal axes, shifted or turned when an alignment
cannot reach 1 %). Where lattice lines meet the outline, nodes closer than a tenth of the spacing
(``MIN_BEAM_FRACTION``) are merged, onto the outline, so that no beam is near zero long. Surfaces
must be height fields over their plan (a surface that folds over itself in plan is refused with a
clear error).

The grids a project can ask for are the ``GridKind``s: the statics-aware Voronoi grid, its
isotropic control (the same remesher under a uniform field, ``isotropic_field``), and the
lattices: squares along the plan's principal axes (``quad_grid``), squares turned 45 degrees to
them (``quad45_grid``), triangles (``triangular_grid``) and the statics-aware quad grid
(``statics_quad_grid``): squares turned to the guiding field's dominant direction in plan, whose
lines along each lattice axis are graded by the field's size. A tensor-product lattice can only
grade along its two axes, so the size used is the field's, averaged (1/size, area-weighted)
across each axis: a grading that varies along a diagonal, or one stress direction that turns over
the roof, is followed only on average; the field's anisotropy is not used (the cells stay about
square)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np

from ..errors import ConvergenceError, InputError
from ..mesh import PolyMesh, TriMesh, unique_edges
from .field import GuidingField

#: cell edges shorter than this fraction of the lattice spacing (in plan) are merged away
MIN_BEAM_FRACTION = 0.1

__all__ = ["GridKind", "LATTICES", "AxisGrading", "is_height_field", "triangular_grid", "quad_grid", "quad45_grid",
           "statics_quad_grid", "lattice_grid", "lattice_total_length", "principal_angle", "field_angle",
           "field_gradings", "isotropic_field"]


class GridKind(str, Enum):
    """The grids a project can be remeshed into (``[remesh] grid``)."""

    VORONOI = "voronoi"            # statics-aware Voronoi, under the guiding field
    ISOTROPIC = "isotropic"        # the same remesher under a uniform field: the control
    QUAD = "quad"                  # squares along the plan's principal axes
    QUAD45 = "quad45"              # squares at 45 degrees to them
    TRIANGULAR = "triangular"      # equilateral triangles, one side along the major axis
    STATICS_QUAD = "statics_quad"  # squares along the field's direction, lines graded by its size


#: the kinds built as lattices clipped to the plan (not Voronoi cells)
LATTICES = frozenset({GridKind.QUAD, GridKind.QUAD45, GridKind.TRIANGULAR, GridKind.STATICS_QUAD})


@dataclass(frozen=True, kw_only=True)
class AxisGrading:
    """A graded coordinate along one lattice axis: ``t`` (k,) increasing positions along the axis
    (m, the plan point's dot product with the axis' unit vector) and ``graded`` (k,) the graded
    coordinate there (m, increasing); lattice lines sit at equal steps of the graded coordinate.
    Beyond ``t`` it goes on with the slope of the end intervals."""

    t: np.ndarray
    graded: np.ndarray

    def stretched(self, factor: float) -> "AxisGrading":
        """The same grading with ``factor`` times as many lines (lines ``factor`` times closer)."""
        return AxisGrading(t=self.t, graded=self.graded * factor)

    def _forward(self, x: np.ndarray) -> np.ndarray:
        return _extended_interp(x, self.t, self.graded)

    def lines(self, lo: float, hi: float, spacing: float, offset: float = 0.0) -> np.ndarray:
        """Positions (m, along the axis) of the lines at graded steps of ``spacing`` shifted by
        ``offset`` (a fraction of it), from one line below ``lo`` to one above ``hi``."""
        g_lo, g_hi = self._forward(np.array([lo, hi]))
        k = np.arange(int(np.floor(g_lo / spacing - offset)) - 1, int(np.ceil(g_hi / spacing - offset)) + 2)
        return _extended_interp((k + offset) * spacing, self.graded, self.t)


#: equal steps: the graded coordinate is the position along the axis
_UNIFORM = AxisGrading(t=np.array([0.0, 1.0]), graded=np.array([0.0, 1.0]))


def _extended_interp(x: np.ndarray, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """np.interp, continued linearly beyond ``xp`` with the slopes of its end intervals."""
    x = np.asarray(x, dtype=float)
    out = np.interp(x, xp, fp)
    low, high = x < xp[0], x > xp[-1]
    out[low] = fp[0] + (x[low] - xp[0]) * (fp[1] - fp[0]) / (xp[1] - xp[0])
    out[high] = fp[-1] + (x[high] - xp[-1]) * (fp[-1] - fp[-2]) / (xp[-1] - xp[-2])
    return out


def is_height_field(mesh: TriMesh) -> bool:
    """True when every facet faces up (so the plan projection is one-to-one)."""
    return bool(np.all(mesh.face_normals[:, 2] > 1e-6))


def _outline(mesh: TriMesh):
    from shapely.geometry import Polygon

    loops = [mesh.vertices[loop, :2] for loop in mesh.boundary_loops]
    areas = [Polygon(loop).area for loop in loops]
    outer = int(np.argmax(areas))
    polygon = Polygon(loops[outer], [loop for i, loop in enumerate(loops) if i != outer])
    return polygon if polygon.is_valid else polygon.buffer(0)


def _tiles(kind: str, spacing: float, bounds, centre, lines=None) -> list[np.ndarray]:
    x0, y0, x1, y1 = bounds
    tiles = []
    if lines is not None:  # graded squares: rectangles between the given lines (xs, ys)
        xs, ys = lines
        return [np.array([[xa, ya], [xb, ya], [xb, yb], [xa, yb]])
                for xa, xb in zip(xs[:-1], xs[1:]) for ya, yb in zip(ys[:-1], ys[1:])]
    if kind == "quad":
        nx0, nx1 = int(np.floor((x0 - centre[0]) / spacing)) - 1, int(np.ceil((x1 - centre[0]) / spacing)) + 1
        ny0, ny1 = int(np.floor((y0 - centre[1]) / spacing)) - 1, int(np.ceil((y1 - centre[1]) / spacing)) + 1
        for i in range(nx0, nx1):
            for j in range(ny0, ny1):
                x, y = centre[0] + i * spacing, centre[1] + j * spacing
                tiles.append(np.array([[x, y], [x + spacing, y], [x + spacing, y + spacing], [x, y + spacing]]))
        return tiles
    height = spacing * np.sqrt(3) / 2
    ny0, ny1 = int(np.floor((y0 - centre[1]) / height)) - 1, int(np.ceil((y1 - centre[1]) / height)) + 1
    nx0, nx1 = int(np.floor((x0 - centre[0]) / spacing)) - 2, int(np.ceil((x1 - centre[0]) / spacing)) + 2
    for j in range(ny0, ny1):
        y = centre[1] + j * height
        shift = 0.5 * spacing * (j % 2)
        for i in range(nx0, nx1):
            x = centre[0] + i * spacing + shift
            tiles.append(np.array([[x, y], [x + spacing, y], [x + 0.5 * spacing, y + height]]))
            tiles.append(np.array([[x + spacing, y], [x + 1.5 * spacing, y + height], [x + 0.5 * spacing, y + height]]))
    return tiles


def _clipped(kind: str, spacing: float, polygon, centre, lines=None) -> tuple[np.ndarray, list[np.ndarray]]:
    """Plan nodes (n,2) and faces (node loops) of the lattice clipped to the polygon."""
    from shapely.geometry import Polygon
    from shapely.geometry.polygon import orient

    key_scale = 1e-7 * max(polygon.bounds[2] - polygon.bounds[0], polygon.bounds[3] - polygon.bounds[1])
    index: dict[tuple[int, int], int] = {}
    points: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    prepared = polygon.buffer(0)
    for tile in _tiles(kind, spacing, polygon.bounds, centre, lines):
        shape = Polygon(tile)
        if not prepared.intersects(shape):
            continue
        cut = prepared.intersection(shape)
        parts = ([cut] if cut.geom_type == "Polygon"
                 else [g for g in getattr(cut, "geoms", []) if g.geom_type == "Polygon"])
        for part in parts:
            if part.area < 1e-3 * shape.area:
                continue
            ring = np.array(orient(part, 1.0).exterior.coords)[:-1]
            loop: list[int] = []
            for p in ring:
                key = (int(round(p[0] / key_scale)), int(round(p[1] / key_scale)))
                if key not in index:
                    index[key] = len(points)
                    points.append(p)
                if not loop or loop[-1] != index[key]:
                    loop.append(index[key])
            if len(loop) >= 3 and loop[0] == loop[-1]:
                loop.pop()
            if len(loop) >= 3:
                faces.append(np.array(loop))
    return np.array(points, dtype=np.float64).reshape(-1, 2), faces


def _insert_hanging_nodes(points: np.ndarray, faces: list[np.ndarray]) -> list[np.ndarray]:
    """Add nodes lying on a face's edge (from a neighbouring clipped tile) into that face's loop."""
    from scipy.spatial import cKDTree

    tree = cKDTree(points)
    out = []
    for face in faces:
        loop = []
        for a, b in zip(face, np.roll(face, -1)):
            loop.append(int(a))
            pa, pb = points[a], points[b]
            length = np.linalg.norm(pb - pa)
            candidates = tree.query_ball_point(0.5 * (pa + pb), 0.5 * length + 1e-12)
            inside = []
            for c in candidates:
                if c in (a, b):
                    continue
                t = np.dot(points[c] - pa, pb - pa) / length**2
                off = np.linalg.norm(points[c] - (pa + t * (pb - pa)))
                if 1e-9 < t < 1 - 1e-9 and off < 1e-9 * max(float(length), 1e-300):
                    inside.append((t, c))
            loop.extend(c for _, c in sorted(inside))
        out.append(np.array(loop))
    return out


def _merge_short_beams(points: np.ndarray, faces: list[np.ndarray], rank: np.ndarray,
                       min_length: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """Merge the end nodes of cell edges shorter than ``min_length`` in plan (m).

    Clipping the lattice to the outline puts nodes wherever a lattice line crosses the outline,
    as close as round-off to a lattice node or an outline vertex: beams a thousand times shorter
    than the spacing, which make the frame's stiffness numerically singular. Each short edge,
    shortest first, is collapsed into the end node of higher ``rank`` (n,) int (3 a surface corner,
    2 an outline vertex, 1 another boundary node, 0 an inner lattice node; between equals, the one
    that moves the merged nodes least), so the outline keeps its corners and boundary nodes stay
    on it; a merge that would move a node by twice ``min_length`` or more, or join two surface
    corners, is left out (a chain of short edges is not collapsed into one point). Cells left with
    fewer than three nodes go; a cell that meets itself at a merged node is split there.

    Returns the surviving node ids (old ids, ascending) and the cells renumbered to them.
    """
    n = len(points)
    target = np.arange(n)
    for _ in range(8):                       # new short edges can appear after a merge
        edges = unique_edges([target[f] for f in faces])
        lengths = np.linalg.norm(points[edges[:, 1]] - points[edges[:, 0]], axis=1)
        short = np.flatnonzero(lengths < min_length)
        if len(short) == 0:
            break
        merged = False
        for a, b in edges[short[np.argsort(lengths[short], kind="stable")]]:
            a, b = int(target[a]), int(target[b])
            if a == b or (rank[a] == 3 and rank[b] == 3):
                continue
            members = np.flatnonzero((target == a) | (target == b))
            # the higher rank stays; between equals, the one that moves the merged nodes least
            choices = [v for v in sorted((a, b)) if rank[v] == max(rank[a], rank[b])]
            reach = [np.linalg.norm(points[members] - points[v], axis=1).max() for v in choices]
            if min(reach) >= 2 * min_length:
                continue
            keep = choices[int(np.argmin(reach))]
            target[members] = keep
            merged = True
        if not merged:
            break
    out = []
    for face in faces:
        loop = [int(v) for v in target[face]]
        loop = [v for i, v in enumerate(loop) if v != loop[i - 1]]      # cyclic: consecutive repeats
        out.extend(_simple_loops(loop))
    survivors = np.unique(target)
    renumber = np.full(n, -1, dtype=np.int64)
    renumber[survivors] = np.arange(len(survivors))
    return survivors, [renumber[np.array(loop)] for loop in out]


def _simple_loops(loop: list[int]) -> list[list[int]]:
    """A node loop split where it meets itself, keeping the parts with three nodes or more."""
    seen: dict[int, int] = {}
    for i, v in enumerate(loop):
        if v in seen:
            inner, outer = loop[seen[v]:i], loop[:seen[v]] + loop[i:]
            return _simple_loops(inner) + _simple_loops(outer)
        seen[v] = i
    return [loop] if len(loop) >= 3 else []


def lattice_grid(mesh: TriMesh, kind: str, spacing: float, support_vertices: np.ndarray | None = None,
                 angle_deg: float = 0.0, offset: tuple[float, float] = (0.0, 0.0),
                 grading: tuple[AxisGrading, AxisGrading] | None = None) -> PolyMesh:
    """The ``kind`` ("triangle" or "quad") lattice of ``spacing`` (m), turned by ``angle_deg`` in
    plan about the plan's centroid and shifted by ``offset`` (fractions of the spacing along the
    lattice axes), clipped to the plan and lifted. With ``grading`` (quads only; one per lattice
    axis, along (cos, sin) and (-sin, cos) of ``angle_deg``) the lines sit at steps of ``spacing``
    in each axis' graded coordinate instead of at equal steps."""
    from matplotlib.tri import LinearTriInterpolator, Triangulation
    from scipy.spatial import cKDTree

    if support_vertices is None and mesh.flagged is not None:
        support_vertices = mesh.flagged
    if not is_height_field(mesh):
        raise InputError("the reference grids need a surface that is a height field over its plan",
                         hint="compare on a surface without overhangs or vertical parts")
    # collinear boundary vertices would become nodes of the clipped cells: simplify them away
    from shapely import affinity

    polygon = _outline(mesh).simplify(0.01 * spacing, preserve_topology=True)
    centre = np.array(polygon.centroid.coords[0])
    turned = affinity.rotate(polygon, -angle_deg, origin=tuple(centre))
    lines = None
    if grading is not None:
        if kind != "quad":
            raise InputError(f"grid: graded lines are for quad lattices, not {kind!r}")
        lines = _graded_lines(grading, turned.bounds, centre, angle_deg, spacing, offset)
        # the shortest gap between lines sets the tolerances and the merge length below
        spacing = float(min(np.diff(lines[0]).min(), np.diff(lines[1]).min()))
    plan, faces = _clipped(kind, spacing, turned, centre + spacing * np.asarray(offset, dtype=float), lines)
    if not faces:  # a spacing larger than the plan: no cell is left (the caller shrinks it)
        return PolyMesh(nodes=np.zeros((0, 3)), faces=())
    if angle_deg:
        c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
        plan = (plan - centre) @ np.array([[c, s], [-s, c]]) + centre
    faces = _insert_hanging_nodes(plan, faces)
    boundary = polygon.boundary
    from shapely.geometry import Point

    on_boundary = np.array([boundary.distance(Point(p)) < 1e-6 * spacing for p in plan])
    corner_points = np.concatenate([np.array(polygon.exterior.coords)[:-1]] +
                                   [np.array(r.coords)[:-1] for r in polygon.interiors])
    outline_vertex = np.zeros(len(plan), dtype=bool)
    if len(corner_points):
        distance, _ = cKDTree(corner_points).query(plan)
        outline_vertex = distance < 1e-6 * spacing
    from ..geometry.fine_mesh import surface_corners
    from .cell_extraction import support_nodes

    kept = sorted(surface_corners(mesh).tolist())
    corners = np.zeros(len(plan), dtype=bool)
    if kept:
        distance, _ = cKDTree(mesh.vertices[kept, :2]).query(plan)
        corners = outline_vertex & (distance < 1e-3 * spacing)
    rank = on_boundary.astype(np.int64) + outline_vertex + corners
    survivors, faces = _merge_short_beams(plan, faces, rank, MIN_BEAM_FRACTION * spacing)
    plan, on_boundary, corners = plan[survivors], on_boundary[survivors], corners[survivors]
    interpolate = LinearTriInterpolator(Triangulation(mesh.vertices[:, 0], mesh.vertices[:, 1], mesh.faces),
                                        mesh.vertices[:, 2])
    z = np.asarray(interpolate(plan[:, 0], plan[:, 1]).filled(np.nan))
    if np.any(np.isnan(z)):
        _, nearest = cKDTree(mesh.vertices[:, :2]).query(plan[np.isnan(z)])
        z[np.isnan(z)] = mesh.vertices[nearest, 2]
    nodes = np.c_[plan, z]
    supports = support_nodes(mesh, nodes, on_boundary, support_vertices)
    return PolyMesh(nodes=nodes, faces=tuple(faces), boundary=on_boundary, supports=supports, corners=corners)


def _graded_lines(grading: tuple[AxisGrading, AxisGrading], bounds, centre: np.ndarray, angle_deg: float,
                  spacing: float, offset) -> tuple[np.ndarray, np.ndarray]:
    """The graded lines (xs, ys) in the turned frame of lattice_grid (plan turned by -angle_deg
    about ``centre``), covering ``bounds`` of the turned plan."""
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    out = []
    for k, axis in enumerate((np.array([c, s]), np.array([-s, c]))):
        # turned coordinate x'_k = centre_k + (p - centre) . axis, so p . axis = x'_k - centre_k + centre . axis
        to_axis = float(centre @ axis) - centre[k]
        out.append(grading[k].lines(bounds[k] + to_axis, bounds[k + 2] + to_axis, spacing, offset[k]) - to_axis)
    return out[0], out[1]


def principal_angle(mesh: TriMesh) -> float:
    """Angle (degrees, in [-90, 90)) of the plan's major principal axis of area (second moments of
    the facets' plan areas about the centroid); 0 when the two principal moments are within 5 %
    (square or round plans: no preferred direction, keep the x axis) or the axis is within 1 degree
    of x or y."""
    areas = mesh.face_plan_areas
    centres = mesh.face_centroids[:, :2]
    centre = (areas[:, None] * centres).sum(axis=0) / areas.sum()
    d = centres - centre
    moments = np.einsum("f,fi,fj->ij", areas, d, d)
    values, vectors = np.linalg.eigh(moments)
    if values[1] - values[0] < 0.05 * values[1]:
        return 0.0
    major = vectors[:, 1]
    angle = (float(np.degrees(np.arctan2(major[1], major[0]))) + 90.0) % 180.0 - 90.0
    # within 1 degree of the x or y axis: take the axis (plans drawn on the axes stay exact)
    snapped = 90.0 * round(angle / 90.0)
    return float(((snapped if abs(angle - snapped) < 1.0 else angle) + 90.0) % 180.0 - 90.0)


def _matched(mesh: TriMesh, kind: str, total_length: float, support_vertices, *, angle_deg: float | None = None,
             turn: bool = True, grading: tuple[AxisGrading, AxisGrading] | None = None,
             tolerance: float = 0.01) -> PolyMesh:
    """Secant iteration on the spacing for L_tot (the clipped length is a step function of the
    spacing: whole rows enter or leave); when an alignment misses 1 %, the lattice is shifted by
    half and a quarter cell, then turned (45 degrees for squares, 30 for triangles). With ``turn``
    false (grids whose direction is the point) it is shifted more instead, then its squares are
    stretched into rectangles of aspect 1.03, 1.06, then 1.1 at most, then it is turned by 3, then
    6 degrees at most (on a plan whose sides run along the lattice, squares jump by whole rows: an
    8 m x 5 m rectangle by 3 to 5 % of L_tot; a coarse grid on a square plan by more).
    Last, the spacing is scanned +-10 % around the best. The lattice starts at ``angle_deg``
    (default: the plan's principal axes); ``grading`` as for lattice_grid. ConvergenceError when
    nothing is within ``tolerance`` (a fraction of L_tot; 1 %; the loops aim at half of it)."""
    if not total_length > 0:
        raise InputError(f"grid: the total length must be positive, got {total_length}")
    # an infinite lattice has length per area 3 / (sqrt3/2 s) (triangles) or 2 / s (squares)
    per_area = (2 * np.sqrt(3), 2.0)[kind == "quad"]
    plan_area = float(mesh.face_plan_areas.sum())
    spacing = per_area * plan_area / total_length
    base = principal_angle(mesh) if angle_deg is None else angle_deg
    candidates = [(base, (0.0, 0.0), grading), (base, (0.5, 0.5), grading), (base, (0.25, 0.25), grading)]
    if turn:
        turned = base + (45.0 if kind == "quad" else 30.0)
        candidates += [(turned, (0.0, 0.0), grading), (turned, (0.5, 0.5), grading)]
    elif kind == "quad":  # more shifts, then rectangles, instead of the turn
        candidates += [(base, offset, grading) for offset in ((0.5, 0.0), (0.0, 0.5), (0.25, 0.75))]
        along, across = grading if grading is not None else (_UNIFORM, _UNIFORM)
        for aspect in (1.03, 1 / 1.03, 1.06, 1 / 1.06, 1.1, 1 / 1.1):
            candidates += [(base, offset, (along, across.stretched(aspect))) for offset in ((0.0, 0.0), (0.5, 0.5))]
        # last, turned a little: tilted lines leave the plan through its sides, so their length
        # varies with the spacing instead of jumping by whole rows
        for tilt in (3.0, -3.0, 6.0, -6.0):
            candidates += [(base + tilt, offset, grading) for offset in ((0.0, 0.0), (0.5, 0.5))]
    best = None
    for angle, offset, axes in candidates:
        trial_spacing = spacing
        for _ in range(8):
            grid = lattice_grid(mesh, kind, trial_spacing, support_vertices, angle, offset, axes)
            error = grid.total_length / total_length - 1
            if best is None or abs(error) < abs(best[0]):
                best = (error, grid, trial_spacing, angle, offset, axes)
            if abs(error) < 0.5 * tolerance:
                return grid
            trial_spacing *= max(1 + error, 0.5)  # no cell left (error -1): halve the spacing
        assert best is not None  # the first trial sets it
        if abs(best[0]) < tolerance:
            return best[1]
    assert best is not None  # candidates is never empty
    for factor in np.linspace(0.9, 1.1, 41):
        grid = lattice_grid(mesh, kind, best[2] * factor, support_vertices, best[3], best[4], best[5])
        error = grid.total_length / total_length - 1
        if abs(error) < abs(best[0]):
            best = (error, grid, best[2] * factor, *best[3:])
        if abs(best[0]) < tolerance:
            return best[1]
    raise ConvergenceError(f"grid: no {kind} lattice spacing gives the total length {total_length:.2f} m within "
                           f"{100 * tolerance:g} % "
                           f"(best {100 * best[0]:+.1f} %)", hint="the surface may be too small for this length; "
                           "try a longer or shorter target length")


def triangular_grid(mesh: TriMesh, *, total_length: float, support_vertices: np.ndarray | None = None,
                    tolerance: float = 0.01) -> PolyMesh:
    """Equilateral triangles over the plan (one edge direction along the plan's major principal
    axis), lifted onto the surface, with L_tot (m) matched within 1 %; support_vertices (n,) bool
    of the surface (default: its flagged vertices) mark the grid's boundary nodes near them;
    ``tolerance`` the fraction of L_tot to meet (ConvergenceError when no lattice does)."""
    return _matched(mesh, "triangle", total_length, support_vertices, tolerance=tolerance)


def quad_grid(mesh: TriMesh, *, total_length: float, support_vertices: np.ndarray | None = None,
              tolerance: float = 0.01) -> PolyMesh:
    """Squares over the plan (sides along the plan's principal axes, never turned to 45 degrees to
    meet the length: that is quad45_grid; stretched by up to 10 % or turned by up to 6 degrees
    where whole rows cannot meet it, see _matched), lifted onto the surface, with L_tot (m)
    matched within 1 %; support_vertices and tolerance as for triangular_grid."""
    return _matched(mesh, "quad", total_length, support_vertices, turn=False, tolerance=tolerance)


def quad45_grid(mesh: TriMesh, *, total_length: float, support_vertices: np.ndarray | None = None,
                tolerance: float = 0.01) -> PolyMesh:
    """Squares turned 45 degrees to the plan's principal axes (never turned back to them to meet
    the length), lifted onto the surface, with L_tot (m) matched within 1 %; support_vertices and
    tolerance as for triangular_grid."""
    return _matched(mesh, "quad", total_length, support_vertices, angle_deg=principal_angle(mesh) + 45.0,
                    turn=False, tolerance=tolerance)


def field_angle(mesh: TriMesh, field: GuidingField) -> float:
    """Angle (degrees, in [-90, 90)) of the guiding field's dominant direction in plan: the major
    axis of the area-weighted mean of u u^T over the vertices (u the field's direction projected
    on the plan, unit); the plan's principal angle where that mean has no preferred direction
    (its two eigenvalues within 5 %)."""
    u = field.direction[:, :2]
    length = np.linalg.norm(u, axis=1)
    keep = length > 1e-9
    u = u[keep] / length[keep, None]
    weights = mesh.vertex_areas[keep]
    tensor = np.einsum("v,vi,vj->ij", weights, u, u) / max(weights.sum(), 1e-300)
    values, vectors = np.linalg.eigh(tensor)
    if values[1] - values[0] < 0.05 * values[1]:
        return principal_angle(mesh)
    major = vectors[:, 1]
    return (float(np.degrees(np.arctan2(major[1], major[0]))) + 90.0) % 180.0 - 90.0


def field_gradings(mesh: TriMesh, field: GuidingField, angle_deg: float,
                   bins: int = 48) -> tuple[AxisGrading, AxisGrading]:
    """The graded coordinates along the lattice axes (cos, sin) and (-sin, cos) of ``angle_deg``:
    the cumulative integral of the line density 1/size, the field's 1/size averaged (area-weighted)
    over the vertices in each of ``bins`` strips across the axis, scaled to mean 1 over the surface
    (so a uniform field gives lines at the plain spacing, and lines are denser where the field
    asks for smaller cells)."""
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    weights = mesh.vertex_areas
    density = 1.0 / field.size
    density = density / ((weights * density).sum() / weights.sum())
    out = []
    for axis in (np.array([c, s]), np.array([-s, c])):
        t = mesh.vertices[:, :2] @ axis
        edges = np.linspace(t.min(), t.max(), bins + 1)
        strip = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, bins - 1)
        area = np.bincount(strip, weights, bins)
        mean = np.bincount(strip, weights * density, bins) / np.maximum(area, 1e-300)
        filled = area > 0
        mean = np.interp(np.arange(bins), np.flatnonzero(filled), mean[filled])
        out.append(AxisGrading(t=edges, graded=np.concatenate([[0.0], np.cumsum(mean * np.diff(edges))])))
    return out[0], out[1]


def statics_quad_grid(mesh: TriMesh, field: GuidingField, *, total_length: float,
                      support_vertices: np.ndarray | None = None, tolerance: float = 0.01) -> PolyMesh:
    """The statics-aware quad grid: squares turned to the field's dominant direction in plan
    (field_angle) whose lines are graded by the field's size along each lattice axis
    (field_gradings), lifted onto the surface, with L_tot (m) matched within 1 % by scaling the
    graded spacing; support_vertices and tolerance as for triangular_grid."""
    if len(field.size) != mesh.n_vertices:
        raise InputError(f"grid: the field has {len(field.size)} values for {mesh.n_vertices} vertices")
    angle = field_angle(mesh, field)
    return _matched(mesh, "quad", total_length, support_vertices, angle_deg=angle, turn=False,
                    grading=field_gradings(mesh, field, angle), tolerance=tolerance)


def lattice_total_length(mesh: TriMesh, kind: GridKind | str, *, n_cells: int | None = None,
                         mean_beam_length: float | None = None) -> float:
    """The total beam length (m) of a ``kind`` lattice of about ``n_cells`` cells, or of beams
    ``mean_beam_length`` (m) long, over the surface: an infinite lattice of spacing s has
    2 / s (squares) or 2 sqrt3 / s (triangles) of beams per unit area, and cells of s^2 or
    sqrt3 / 4 s^2; the surface's area stands for the plan's, so that the length is the lifted one
    (about: the clipped border and the lift make it a guide, matched within 1 % afterwards)."""
    triangles = GridKind(kind) == GridKind.TRIANGULAR
    per_area = 2.0 * np.sqrt(3.0) if triangles else 2.0
    if n_cells is not None and mean_beam_length is None:
        spacing = np.sqrt(mesh.area / n_cells / (np.sqrt(3.0) / 4.0 if triangles else 1.0))
    elif mean_beam_length is not None and n_cells is None:
        spacing = mean_beam_length
    else:
        raise InputError("grid: give the cell count or the mean beam length, one of them")
    return float(per_area * mesh.area / spacing)


def isotropic_field(field: GuidingField) -> GuidingField:
    """The isotropic control of ``field``: every size 1 and every anisotropy 1 (Voro(1,1): uniform
    cells, no direction), on the same vertices and normals."""
    ones = np.ones_like(field.size)
    return GuidingField(size=ones, anisotropy=ones.copy(), direction=field.direction, normals=field.normals)
