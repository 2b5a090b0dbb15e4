"""Seeded free-form roof surfaces for tests and benchmarks: plan outline, triangulation, height field, supports.

``generate_surface(seed)`` builds one roof in metres: a plan outline (ellipse, rounded rectangle, smooth
star or smoothed random polygon, convex or not; with one or two courtyards for the kind "hole"), a fairly
uniform triangulation of the plan region (boundary samples plus a jittered hexagonal lattice, relaxed,
``scipy.spatial.Delaunay``, triangles kept whose centroid is inside the ``shapely`` region), lifted by a
height field of the kind:

    dome    a membrane under a random positive pressure (Poisson, zero height on the outline): synclastic
    saddle  a x'^2 - b y'^2 in a random frame (anticlastic), slightly perturbed
    ridge   one or two rounded ridges or valleys (lines in plan), slightly perturbed
    wave    a sum of random low Fourier modes
    hole    the pressurised membrane over an outline with one or two interior holes (courtyards), the holes'
            edges either free or held at the eaves' height; needs n_vertices of about 400 or more

The kind follows ``seed % 5`` (so seeds 0..4 cover every kind) and the supports ``(seed // 5) % 4`` (so seeds
0..19 cover every kind with every support pattern); everything else is drawn from ``default_rng(seed)``.
Support patterns (``flagged`` vertices): the whole boundary, the outer boundary only (holes free), two to
four stretches of the outer boundary covering 40-75 % of it, or three to six point zones (short boundary
arcs at corners or spread round the outline).

Guarantees (checked before returning; ``GeneratorError`` otherwise): one connected component, a disc or an
annulus (1 + holes boundary loops, every boundary edge in one triangle, every other edge in two),
consistently oriented triangles with normals pointing up (+z), smallest triangle angle above 15 degrees,
at least one flagged vertex. The same seed and arguments give identical arrays.

``drawn_settings(seed, span)`` draws the rest of a project for such a roof (material, section, joints,
D and A, loads, panels, sheets, supports), so that runs meet settings nobody tuned the product on.

``write_ply`` writes the ASCII PLY that ``workflow.surface_io`` writes and reads (red vertices are
the flagged supports); ``surfaces(n)`` is the list for seeds 0..n-1.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from engine.mesh import boundary_loops

__all__ = ["KINDS", "OUTLINES", "SUPPORT_PATTERNS", "GeneratedSurface", "GeneratorError", "drawn_settings",
           "generate_surface", "surfaces", "triangle_angles_deg", "write_ply"]

KINDS = ("dome", "saddle", "ridge", "wave", "hole")
OUTLINES = ("ellipse", "rounded_rectangle", "star", "polygon")
SUPPORT_PATTERNS = ("all_boundary", "outer_boundary", "stretches", "points")

SPAN_RANGE_M = (5.0, 60.0)
RISE_RANGE = (0.05, 0.35)          # rise / span
MAX_SLOPE = 1.3                    # largest surface slope (about 52 degrees); the rise is lowered to keep it
MIN_ANGLE_DEG = 15.0


class GeneratorError(RuntimeError):
    """The generator could not build a valid surface for these arguments (a bug of the generator)."""


@dataclass(frozen=True, kw_only=True)
class GeneratedSurface:
    """A generated roof: vertices (n, 3) float64 m, faces (m, 3) int64 (counter-clockwise seen from +z),
    flagged (n,) bool support vertices; name ("gen03-saddle"), kind, and how it was made."""

    vertices: np.ndarray
    faces: np.ndarray
    flagged: np.ndarray
    name: str
    kind: str
    seed: int
    outline: str
    supports: str
    n_holes: int
    span_m: float
    rise_m: float

    def __post_init__(self) -> None:
        for name in ("vertices", "faces", "flagged"):
            getattr(self, name).setflags(write=False)

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_faces(self) -> int:
        return len(self.faces)


# ---------------------------------------------------------------------------------------------- outlines


def _rotate(points: np.ndarray, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return points @ np.array([[c, s], [-s, c]])


def _unit_outline(rng: np.random.Generator, outline: str):
    """A shapely polygon of about unit size, centred near the origin."""
    from shapely.geometry import Polygon, box

    t = np.linspace(0.0, 2.0 * np.pi, 256, endpoint=False)
    if outline == "ellipse":
        b = rng.uniform(0.45, 1.0)
        points = np.stack([np.cos(t), b * np.sin(t)], axis=1)
        return Polygon(_rotate(points, rng.uniform(0, np.pi)))
    if outline == "rounded_rectangle":
        h = rng.uniform(0.4, 1.0)
        r = rng.uniform(0.05, 0.3) * h
        rect = box(-1.0 + r, -h + r, 1.0 - r, h - r).buffer(r, quad_segs=16)
        return Polygon(_rotate(np.asarray(rect.exterior.coords)[:-1], rng.uniform(0, np.pi)))
    if outline == "star":
        radius = np.ones_like(t)
        for k in range(2, 6):
            radius += rng.uniform(0.0, 0.22 / np.sqrt(k - 1)) * np.cos(k * t + rng.uniform(0, 2 * np.pi))
        radius = np.maximum(radius, 0.35)
        return Polygon(np.stack([radius * np.cos(t), radius * np.sin(t)], axis=1))
    if outline == "polygon":
        m = int(rng.integers(5, 10))
        angles = np.sort(rng.uniform(0, 2 * np.pi, m))
        angles = angles[np.diff(np.r_[angles, angles[0] + 2 * np.pi]) > 0.25] if m > 5 else angles
        if rng.random() < 0.4:       # convex: the hull of points on the unit circle
            radii = np.ones(len(angles))
        else:                        # star-shaped, usually not convex
            radii = rng.uniform(0.45, 1.0, len(angles))
        points = np.stack([radii * np.cos(angles), radii * np.sin(angles)], axis=1)
        polygon = Polygon(points)
        if not polygon.is_valid or polygon.area < 0.3:
            polygon = Polygon(points).convex_hull
        if polygon.area < 0.3:
            polygon = Polygon(np.stack([np.cos(t), 0.7 * np.sin(t)], axis=1))
        return polygon
    raise ValueError(f"unknown outline {outline!r}; outlines: {', '.join(OUTLINES)}")


def _scale_to_span(polygon, span: float):
    from shapely import affinity

    x0, y0, x1, y1 = polygon.bounds
    factor = span / max(x1 - x0, y1 - y0)
    polygon = affinity.scale(polygon, factor, factor, origin=(0, 0))
    c = polygon.centroid
    return affinity.translate(polygon, -c.x, -c.y)


def _largest(geometry):
    if geometry.geom_type == "MultiPolygon":
        return max(geometry.geoms, key=lambda g: g.area)
    return geometry


def _smooth(polygon, radius: float):
    """Round every corner to at least ``radius``: a closing (fills notches) then an opening (cuts spikes)."""
    closed = _largest(polygon.buffer(radius, quad_segs=16).buffer(-radius, quad_segs=16))
    return _largest(closed.buffer(-radius, quad_segs=16).buffer(radius, quad_segs=16))


def _spacing(area: float, n_vertices: int) -> float:
    """Edge length of a triangular lattice with n_vertices points over the area."""
    return float(np.sqrt(area / (n_vertices * np.sqrt(3.0) / 2.0)))


def _add_holes(rng: np.random.Generator, outer, n_holes: int, spacing: float):
    """The outer polygon minus up to n_holes smooth holes (ellipses or rounded rectangles) well inside it,
    and how many holes it has (fewer when the second does not fit)."""
    from shapely import affinity
    from shapely.geometry import Polygon, box

    x0, y0, x1, y1 = outer.bounds
    span = max(x1 - x0, y1 - y0)
    margin = 4.5 * spacing
    holes: list = []
    size = (rng.uniform(0.18, 0.35) if n_holes == 1 else rng.uniform(0.12, 0.24)) * span
    t = np.linspace(0.0, 2.0 * np.pi, 128, endpoint=False)
    for _ in range(n_holes):
        for attempt in range(400):
            if attempt and attempt % 100 == 0:
                size *= 0.8
            a = 0.5 * size
            b = a * rng.uniform(0.5, 1.0)
            b = max(b, 2.5 * spacing)
            a = max(a, b)
            if rng.random() < 0.5:
                shape = Polygon(np.stack([a * np.cos(t), b * np.sin(t)], axis=1))
            else:
                r = rng.uniform(0.3, 0.9) * b
                shape = box(-a + r, -b + r, a - r, b - r).buffer(r, quad_segs=8)
            shape = affinity.rotate(shape, rng.uniform(0, 180), origin=(0, 0))
            shape = affinity.translate(shape, rng.uniform(x0, x1), rng.uniform(y0, y1))
            if not outer.buffer(-margin).contains(shape):
                continue
            if any(shape.distance(other) < margin for other in holes):
                continue
            holes.append(shape)
            break
        else:
            if not holes:
                raise GeneratorError("no room for a hole in the outline at this mesh density (more n_vertices)")
            break                                    # a second hole does not fit: one courtyard
    region = outer
    for shape in holes:
        region = region.difference(shape)
    return region, len(holes)


# ---------------------------------------------------------------------------------------------- triangulation


def _ring_samples(ring, spacing: float) -> np.ndarray:
    import shapely

    length = ring.length
    n = max(8, int(round(length / spacing)))
    distances = np.linspace(0.0, length, n, endpoint=False)
    points = shapely.line_interpolate_point(ring, distances)
    return shapely.get_coordinates(points)


def _lattice(rng: np.random.Generator, region, spacing: float) -> np.ndarray:
    """Jittered hexagonal lattice points at least ~0.6 spacing inside the region."""
    import shapely

    x0, y0, x1, y1 = region.bounds
    reach = 1.5 * max(x1 - x0, y1 - y0)
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    n = int(np.ceil(reach / spacing)) + 2
    i, j = np.meshgrid(np.arange(-n, n + 1), np.arange(-n, n + 1), indexing="ij")
    dy = spacing * np.sqrt(3.0) / 2.0
    points = np.stack([(i + 0.5 * (j % 2)) * spacing, j * dy], axis=-1).reshape(-1, 2)
    points = _rotate(points, rng.uniform(0, np.pi)) + [cx + rng.uniform(0, spacing), cy + rng.uniform(0, spacing)]
    points += rng.uniform(-0.12, 0.12, points.shape) * spacing
    inner = region.buffer(-0.6 * spacing)
    return points[shapely.contains_xy(inner, points[:, 0], points[:, 1])]


def _delaunay_inside(points: np.ndarray, region) -> np.ndarray:
    """Delaunay triangles of the points whose centroid is inside the region, counter-clockwise."""
    import shapely
    from scipy.spatial import Delaunay

    # far ghost points keep the samples off the convex hull, where qhull may join collinear samples
    x0, y0, x1, y1 = region.bounds
    reach = 10.0 * max(x1 - x0, y1 - y0)
    angles = np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False)
    ghosts = np.stack([0.5 * (x0 + x1) + reach * np.cos(angles), 0.5 * (y0 + y1) + reach * np.sin(angles)], axis=1)
    triangles = Delaunay(np.concatenate([points, ghosts])).simplices.astype(np.int64)
    triangles = triangles[(triangles < len(points)).all(axis=1)]
    centroids = points[triangles].mean(axis=1)
    triangles = triangles[shapely.contains_xy(region, centroids[:, 0], centroids[:, 1])]
    a, b, c = (points[triangles[:, k]] for k in range(3))
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    triangles[cross < 0] = triangles[cross < 0][:, [0, 2, 1]]
    return triangles


def _relax(points: np.ndarray, n_fixed: int, region, spacing: float, iterations: int) -> np.ndarray:
    """Umbrella smoothing of the free (lattice) points over re-made Delaunay triangulations."""
    import shapely

    inner = region.buffer(-0.35 * spacing)
    points = points.copy()
    for _ in range(iterations):
        triangles = _delaunay_inside(points, region)
        edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
        edges = np.concatenate([edges, edges[:, ::-1]])
        sums = np.zeros_like(points)
        np.add.at(sums, edges[:, 0], points[edges[:, 1]])
        counts = np.bincount(edges[:, 0], minlength=len(points)).astype(float)
        moved = points.copy()
        used = counts > 0
        moved[used] = sums[used] / counts[used, None]
        free = np.arange(len(points)) >= n_fixed
        ok = free & shapely.contains_xy(inner, moved[:, 0], moved[:, 1])
        points[ok] = moved[ok]
    return points


def _triangulate(rng: np.random.Generator, region, spacing: float) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Plan points (n, 2), triangles (m, 3) and, per boundary ring (outer first), its vertex ids in order."""
    rings = [region.exterior, *region.interiors]
    samples = [_ring_samples(ring, spacing) for ring in rings]
    ring_ids, start = [], 0
    for s in samples:
        ring_ids.append(np.arange(start, start + len(s)))
        start += len(s)
    fixed = np.concatenate(samples)
    points = np.concatenate([fixed, _lattice(rng, region, spacing)])
    points = _relax(points, len(fixed), region, spacing, iterations=8)
    triangles = _delaunay_inside(points, region)
    used = np.zeros(len(points), dtype=bool)
    used[triangles.ravel()] = True
    if not used[: len(fixed)].all():
        raise GeneratorError("a boundary sample is in no triangle")
    remap = np.cumsum(used) - 1
    return points[used], remap[triangles], ring_ids


# ---------------------------------------------------------------------------------------------- height fields


def _cotangent_laplacian(xy: np.ndarray, faces: np.ndarray):
    """Plan cotangent stiffness matrix (n, n) and lumped vertex areas (n,)."""
    from scipy.sparse import coo_matrix

    n = len(xy)
    rows, cols, vals = [], [], []
    area = np.zeros(n)
    p = xy[faces]
    double_area = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                   - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
    for k in range(3):
        i, j, o = faces[:, (k + 1) % 3], faces[:, (k + 2) % 3], faces[:, k]
        u, v = xy[i] - xy[o], xy[j] - xy[o]
        cot = (u * v).sum(axis=1) / double_area
        w = 0.5 * cot
        rows += [i, j, i, j]
        cols += [j, i, i, j]
        vals += [-w, -w, w, w]
        np.add.at(area, o, double_area / 6.0)
    matrix = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)).tocsr()
    return matrix, area


def _fourier(rng: np.random.Generator, xy: np.ndarray, span: float, n_modes: int,
             cycles: tuple[float, float]) -> np.ndarray:
    z = np.zeros(len(xy))
    for _ in range(n_modes):
        k = rng.uniform(*cycles)
        theta = rng.uniform(0, 2 * np.pi)
        wave = 2 * np.pi * k / span * np.array([np.cos(theta), np.sin(theta)])
        z += rng.normal() / k * np.cos(xy @ wave + rng.uniform(0, 2 * np.pi))
    return z


def _membrane(rng: np.random.Generator, xy: np.ndarray, faces: np.ndarray, fixed: np.ndarray,
              span: float) -> np.ndarray:
    """Height of a membrane under a random positive pressure, zero at the fixed vertices."""
    from scipy.sparse.linalg import spsolve

    pressure = _fourier(rng, xy, span, 4, (0.4, 1.5))
    pressure = 1.0 + 0.45 * pressure / max(np.abs(pressure).max(), 1e-12)
    matrix, area = _cotangent_laplacian(xy, faces)
    free = np.setdiff1d(np.arange(len(xy)), fixed)
    z = np.zeros(len(xy))
    z[free] = spsolve(matrix[free][:, free].tocsc(), (pressure * area)[free])
    return z


def _height(rng, kind: str, xy: np.ndarray, faces: np.ndarray, rings: list[np.ndarray], span: float) -> np.ndarray:
    x, y = (xy - xy.mean(axis=0)).T
    if kind == "dome":
        return _membrane(rng, xy, faces, rings[0], span)
    if kind == "hole":
        holes_fixed = rng.random() < 0.5          # courtyard edges at the eaves height, or free
        fixed = np.concatenate(rings) if holes_fixed else rings[0]
        return _membrane(rng, xy, faces, fixed, span)
    if kind == "saddle":
        u, v = _rotate(np.stack([x, y], axis=1), rng.uniform(0, np.pi)).T
        z = u ** 2 - rng.uniform(0.4, 1.6) * v ** 2
        perturbation = _fourier(rng, xy, span, 3, (0.5, 1.2))
        return z / np.ptp(z) + 0.08 * perturbation / max(np.ptp(perturbation), 1e-12)
    if kind == "ridge":
        z = np.zeros(len(xy))
        for _ in range(int(rng.integers(1, 3))):
            centre = 0.4 * np.array([x, y])[:, int(rng.integers(len(x)))]     # a point well inside the plan
            theta = rng.uniform(0, np.pi)
            d = (x - centre[0]) * -np.sin(theta) + (y - centre[1]) * np.cos(theta)
            sign = 1.0 if rng.random() < 0.7 else -1.0          # mostly ridges, sometimes valleys
            z += -sign * np.sqrt(d ** 2 + (rng.uniform(0.04, 0.12) * span) ** 2)     # a rounded crest
        z /= np.ptp(z)
        perturbation = _fourier(rng, xy, span, 3, (0.5, 1.2))
        return z + 0.08 * perturbation / max(np.ptp(perturbation), 1e-12)
    if kind == "wave":
        return _fourier(rng, xy, span, int(rng.integers(3, 7)), (0.5, 2.0))
    raise ValueError(f"unknown kind {kind!r}; kinds: {', '.join(KINDS)}")


def _max_slope(xy: np.ndarray, faces: np.ndarray, z: np.ndarray) -> float:
    p = xy[faces]
    dz = z[faces]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    d1, d2 = dz[:, 1] - dz[:, 0], dz[:, 2] - dz[:, 0]
    gx = (d1 * e2[:, 1] - d2 * e1[:, 1]) / det
    gy = (d2 * e1[:, 0] - d1 * e2[:, 0]) / det
    return float(np.hypot(gx, gy).max())


# ---------------------------------------------------------------------------------------------- supports


def _arc(n: int, start: int, length: int) -> np.ndarray:
    return (start + np.arange(length)) % n


def _supports(rng: np.random.Generator, pattern: str, rings: list[np.ndarray], xy: np.ndarray,
              outline: str, n_vertices: int) -> np.ndarray:
    flagged = np.zeros(n_vertices, dtype=bool)
    outer = rings[0]
    n = len(outer)
    if pattern == "all_boundary":
        flagged[np.concatenate(rings)] = True
    elif pattern == "outer_boundary":
        flagged[outer] = True
    elif pattern == "stretches":
        k = int(rng.integers(2, 5))
        total = int(np.ceil(rng.uniform(0.42, 0.75) * n))
        shares = rng.dirichlet(np.full(k, 3.0))
        lengths = np.maximum(3, np.floor(shares * total).astype(int))
        lengths[0] += max(0, total - lengths.sum())
        gaps = rng.dirichlet(np.full(k, 3.0)) * (n - lengths.sum())
        gaps = np.maximum(1, np.floor(gaps).astype(int))
        start = int(rng.integers(n))
        for length, gap in zip(lengths, gaps):
            flagged[outer[_arc(n, start, length)]] = True
            start += length + gap
    elif pattern == "points":
        if outline == "rounded_rectangle":          # the four corners: furthest from the centre per quadrant
            centre = xy[outer].mean(axis=0)
            d = xy[outer] - centre
            axes = np.linalg.svd(d, full_matrices=False)[2]
            local = d @ axes.T
            quadrant = (local[:, 0] > 0).astype(int) * 2 + (local[:, 1] > 0)
            radius = np.hypot(local[:, 0], local[:, 1])
            centres = [int(np.flatnonzero(quadrant == q)[radius[quadrant == q].argmax()])
                       for q in range(4) if np.any(quadrant == q)]
        else:                                        # three to six zones spread round the outline
            k = int(rng.integers(3, 7))
            phase = rng.uniform(0, n / k)
            centres = [int(phase + i * n / k + rng.uniform(-0.15, 0.15) * n / k) % n for i in range(k)]
        half = max(1, int(round(rng.uniform(0.015, 0.03) * n)))
        for c in centres:
            flagged[outer[_arc(n, c - half, 2 * half + 1)]] = True
    else:
        raise ValueError(f"unknown support pattern {pattern!r}; patterns: {', '.join(SUPPORT_PATTERNS)}")
    return flagged


# ---------------------------------------------------------------------------------------------- checks


def triangle_angles_deg(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(m, 3) interior angles of each triangle in degrees."""
    p = vertices[faces]
    angles = np.zeros((len(faces), 3))
    for k in range(3):
        u = p[:, (k + 1) % 3] - p[:, k]
        v = p[:, (k + 2) % 3] - p[:, k]
        cos = (u * v).sum(axis=1) / (np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1))
        angles[:, k] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return angles


def _check(vertices: np.ndarray, faces: np.ndarray, n_holes: int) -> None:
    """Raise GeneratorError unless the mesh is a valid up-facing disc or annulus with good angles."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    if len(np.unique(edges, axis=0)) != len(edges):
        raise GeneratorError("a directed edge is repeated: inconsistent orientation or non-manifold edge")
    _, counts = np.unique(np.sort(edges, axis=1), axis=0, return_counts=True)
    if counts.max() > 2:
        raise GeneratorError("an edge is shared by more than two triangles")
    n = len(vertices)
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    if connected_components(graph, directed=False)[0] != 1:
        raise GeneratorError("the mesh has more than one connected component")
    loops = boundary_loops(faces)
    if len(loops) != 1 + n_holes:
        raise GeneratorError(f"{len(loops)} boundary loops, expected {1 + n_holes}")
    if sum(len(loop) for loop in loops) != int((counts == 1).sum()):
        raise GeneratorError("a boundary vertex is on two boundary loops (pinched)")
    p = vertices[faces]
    normals = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    if not (normals[:, 2] > 0).all():
        raise GeneratorError("a triangle faces down")
    smallest = triangle_angles_deg(vertices, faces).min()
    if smallest <= MIN_ANGLE_DEG:
        raise GeneratorError(f"smallest triangle angle {smallest:.1f} deg <= {MIN_ANGLE_DEG} deg")


# ---------------------------------------------------------------------------------------------- public


def generate_surface(seed: int, *, kind: str | None = None, span_m: float | None = None,
                     n_vertices: int = 1500) -> GeneratedSurface:
    """The roof surface of a seed: kind from ``seed % 5`` unless given, span (longest plan extent) in
    metres random in 5..60 m unless given, about ``n_vertices`` vertices."""
    from shapely.geometry import Polygon

    seed = int(seed)
    kind = KINDS[seed % len(KINDS)] if kind is None else kind
    if kind not in KINDS:
        raise ValueError(f"unknown kind {kind!r}; kinds: {', '.join(KINDS)}")
    if n_vertices < 50:
        raise ValueError(f"n_vertices = {n_vertices}: at least 50")
    rng = np.random.default_rng(seed)
    span = float(np.exp(rng.uniform(*np.log(SPAN_RANGE_M)))) if span_m is None else float(span_m)
    if not span > 0:
        raise ValueError(f"span_m = {span_m}: must be positive")
    rise_ratio = rng.uniform(*RISE_RANGE)
    pattern = SUPPORT_PATTERNS[(seed // len(KINDS)) % len(SUPPORT_PATTERNS)]
    n_holes_wanted = int(rng.integers(1, 3)) if kind == "hole" else 0
    outlines = OUTLINES if kind != "hole" else ("ellipse", "rounded_rectangle", "star")
    outline = outlines[int(rng.integers(len(outlines)))]

    last_error: Exception | None = None
    for _attempt in range(6):
        outer = _scale_to_span(_unit_outline(rng, outline), span)
        spacing = _spacing(outer.area, n_vertices)
        try:
            region, n_holes = _add_holes(rng, outer, n_holes_wanted, spacing) if n_holes_wanted else (outer, 0)
            spacing = _spacing(region.area, n_vertices)
            region = _smooth(region, 2.0 * spacing)
            if not isinstance(region, Polygon) or len(region.interiors) != n_holes:
                raise GeneratorError("smoothing changed the outline's topology")
            region = region.simplify(0.02 * spacing)
            # the lattice plus the boundary samples overshoot n_vertices a little: one correction
            for _ in range(2):
                xy, faces, rings = _triangulate(rng, region, spacing)
                spacing *= float(np.sqrt(len(xy) / n_vertices))
            z = _height(rng, kind, xy, faces, rings, span)
            z = z - z.min()
            rise = rise_ratio * span
            slope = _max_slope(xy, faces, z * rise / max(z.max(), 1e-12))
            if slope > MAX_SLOPE:
                rise = max(RISE_RANGE[0] * span, rise * MAX_SLOPE / slope)
            z *= rise / max(z.max(), 1e-12)
            vertices = np.column_stack([xy, z]).astype(np.float64)
            faces = faces.astype(np.int64)
            _check(vertices, faces, n_holes)
            flagged = _supports(rng, pattern, rings, xy, outline, len(vertices))
            if not flagged.any():
                raise GeneratorError("no flagged vertex")
            return GeneratedSurface(vertices=vertices, faces=faces, flagged=flagged, name=f"gen{seed:02d}-{kind}",
                                    kind=kind, seed=seed, outline=outline, supports=pattern, n_holes=n_holes,
                                    span_m=span, rise_m=float(z.max()))
        except GeneratorError as exc:
            last_error = exc
    raise GeneratorError(f"seed {seed} ({kind}, {outline}): no valid surface in 6 attempts: {last_error}")


def surfaces(n: int = 20) -> list[GeneratedSurface]:
    """The surfaces of seeds 0..n-1 (every kind from n = 5, every kind x support pattern from n = 20)."""
    return [generate_surface(seed) for seed in range(n)]


def write_ply(surface: GeneratedSurface, path: str | Path) -> Path:
    """ASCII PLY in metres, flagged vertices pure red (255, 0, 0), others white, written by the
    product's ``workflow.surface_io.write_surface_ply`` (which ``read_surface`` reads)."""
    from engine.mesh import TriMesh
    from workflow.surface_io import write_surface_ply

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh = TriMesh(vertices=surface.vertices, faces=surface.faces, flagged=surface.flagged, name=surface.name)
    return write_surface_ply(mesh, path)


# materials with the sections, joints and panels a designer would pair them with
_KITS = (
    ("steel_s355", "circular_hollow", (0.0483, 0.0889, 0.1143, 0.1683), "steel", "glass"),
    ("steel_s235", "rectangular_hollow", (0.06, 0.08, 0.12, 0.16), "steel", "glass"),
    ("aluminium_6061", "circular_hollow", (0.012, 0.03, 0.05, 0.08), "socket", "acrylic"),
    ("aluminium_6063", "solid_round", (0.01, 0.02, 0.03), "socket", "acrylic"),
    ("glulam_gl24h", "solid_rectangle", (0.12, 0.16, 0.2, 0.24), "steel", "glass"),
)


def drawn_settings(seed: int, span_m: float) -> tuple[str, str]:
    """Supports ("flagged" or "boundary") and the TOML text of project settings drawn from a seed: a
    material with a section of its kind and a size that grows with the span, the joint kind, D and A,
    the loads, panels or none, stock sheets. Valid, and not tuned to pass: many designs fail their
    checks, which the run reports as findings."""
    rng = np.random.default_rng(10_000 + seed)
    material, kind, sizes, joints, panels = _KITS[rng.integers(len(_KITS))]
    size = sizes[min(len(sizes) - 1, int(rng.integers(0, 2)) + int(np.searchsorted((10, 25, 45), span_m)))]
    if kind == "circular_hollow":
        section = (f'kind = "{kind}"\ndiameter = "{size * 1000:.1f} mm"\n'
                   f'thickness = "{max(1.0, size * 1000 / 20):.1f} mm"')
    elif kind == "rectangular_hollow":
        section = (f'kind = "{kind}"\nheight = "{size * 1000:.0f} mm"\nwidth = "{size * 600:.0f} mm"\n'
                   f'thickness = "{max(2.0, size * 1000 / 25):.1f} mm"')
    elif kind == "solid_round":
        section = f'kind = "{kind}"\ndiameter = "{size * 1000:.0f} mm"'
    else:
        section = f'kind = "{kind}"\nheight = "{size * 1000:.0f} mm"\nwidth = "{size * 500:.0f} mm"'
    lines = [f'[material]\nname = "{material}"', f"[section]\n{section}",
             f"[field]\nmax_size_ratio = {rng.choice([1.0, 1.5, 2.0, 3.0])}\n"
             f"max_aspect = {rng.choice([1.0, 2.0, 3.0])}",
             f'[loads.cases.dead]\nself_weight = 1.0\narea_true = "{rng.choice([0.2, 0.5, 1.0])} kN/m^2"',
             f'[loads.cases.snow]\narea_plan = "{rng.choice([0.5, 1.0, 2.0])} kN/m^2"',
             "[loads.combinations.ULS]\nlimit_state = \"ULS\"\nfactors = { dead = 1.35, snow = 1.5 }",
             "[loads.combinations.SLS]\nlimit_state = \"SLS\"\nfactors = { dead = 1.0, snow = 1.0 }",
             f'[fabrication.joints]\nkind = "{joints}"']
    if rng.random() < 0.2:
        lines.append("[fabrication.panels]\nenabled = false")
    elif panels == "acrylic":
        lines.append('[fabrication.panels]\nmaterial = "acrylic"\nthickness = "3 mm"\n'
                     '[fabrication.sheets]\nwidth = "1200 mm"\nheight = "600 mm"')
    else:
        lines.append('[fabrication.panels]\nmaterial = "glass"\nthickness = "10 mm"\n'
                     '[fabrication.sheets]\nwidth = "6000 mm"\nheight = "3210 mm"\nsizes = [["3210 mm", "2250 mm"]]')
    supports = str(rng.choice(["flagged", "flagged", "boundary"]))
    return supports, "\n\n".join(lines) + "\n"
