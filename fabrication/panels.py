"""Flat cladding panels: one per grid-shell cell, flattened, inset and written as DXF.

Each cell (a node loop of ``engine.mesh.PolyMesh``) is projected onto its least-squares
plane; the outline in that plane (mm) is inset by the clearance (mitred corners) to give
the cut outline. Cells whose nodes lie further than the planarity tolerance from that
plane are flagged ``nonplanar``; with ``split_nonplanar`` they are cut into triangles by
ear clipping (each triangle of three nodes is exactly planar), ids ``P0001a``, ``P0001b``...

Files (lengths in mm, DXF R2010, ``$INSUNITS`` = 4): one DXF per panel with the cut
outline on CUT, the panel id on ENGRAVE (single-stroke text style), hole centres on DRILL
and a note (thickness, material, planarity) on NOTES; a CSV schedule of all panels.
The sheet nesting lives in ``fabrication.nesting_sheets``, which draws its sheets with this
module's ``add_panel`` (the imports go that way only).
"""

from __future__ import annotations

import csv
import io
import itertools
import math
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import shapely
import shapely.ops
from shapely.geometry import Polygon

from engine.errors import InputError
from engine.mesh import PolyMesh
from fabrication.dxf import ENGRAVE_STYLE, SharedDocument, cutting_layers
from fabrication.files import write_text_atomic
from fabrication.settings import GRAIN_DIRECTIONS, PanelSettings

from .ids import node_id, panel_id, sheet_id

if TYPE_CHECKING:  # pragma: no cover
    from fabrication.nesting_sheets import SheetNesting

__all__ = ["PanelSettings", "Panel", "flatten_panels", "grain_angle_deg", "panel_seats", "trim_at_folds",
           "write_panel_dxfs",
           "write_panels_csv", "add_panel", "panel_label"]


@dataclass(frozen=True, kw_only=True)
class Panel:
    """One flat panel.

    outline_mm (k, 2): cut outline (inset), counter-clockwise, in the panel plane, mm;
    face_outline_mm (j, 2): the cell outline before inset; origin_m (3,) and axes (2, 3):
    the plane (point in m, orthonormal in-plane basis) so that a 2D point p (mm) sits at
    origin_m + 1e-3 * p @ axes; planarity_mm: largest distance of the cell's nodes to the
    plane; holes_mm (h, 2): drill centres; outline_3d_m (k, 3): the cut outline in 3D;
    grain_deg: the counter-clockwise turn (degrees) that lays the panel's grain direction
    (PanelSettings.grain) along x, the sheets' grain; None: no grain asked for.
    """

    id: str
    face: int
    outline_mm: np.ndarray
    face_outline_mm: np.ndarray
    origin_m: np.ndarray
    axes: np.ndarray
    planarity_mm: float
    holes_mm: np.ndarray
    area_mm2: float
    perimeter_mm: float
    outline_3d_m: np.ndarray
    nonplanar: bool
    grain_deg: float | None = None

    @property
    def vertex_count(self) -> int:
        return len(self.outline_mm)


# ---------------------------------------------------------------------------- geometry

def _plane(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Best-fit plane of a (k, 3) loop: centroid, normal along the loop's own (Newell)
    normal, and an in-plane basis (2, 3) with the first axis along the longest side."""
    centroid = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centroid, full_matrices=False)
    normal = vt[-1]
    rolled = np.roll(points, -1, axis=0)
    newell = np.cross(points - centroid, rolled - centroid).sum(axis=0)
    if normal @ newell < 0:
        normal = -normal
    sides = rolled - points
    side = sides[np.argmax(np.einsum("ij,ij->i", sides, sides))]
    u = side - (side @ normal) * normal
    norm = np.linalg.norm(u)
    u = vt[0] if norm < 1e-12 else u / norm
    v = np.cross(normal, u)
    return centroid, normal, np.stack([u, v])


def _ear_clip(points2d: np.ndarray) -> list[tuple[int, int, int]]:
    """Triangulate a simple counter-clockwise polygon (k, 2) by ear clipping (k - 2
    triangles), cutting at each step the best-shaped ear."""
    index = list(range(len(points2d)))
    triangles: list[tuple[int, int, int]] = []

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    while len(index) > 3:
        n = len(index)
        best, best_quality = None, -1.0
        for k in range(n):
            i0, i1, i2 = index[k - 1], index[k], index[(k + 1) % n]
            a, b, c = points2d[i0], points2d[i1], points2d[i2]
            area2 = cross(a, b, c)
            if area2 <= 1e-12:
                continue
            inside = any(cross(a, b, points2d[j]) >= 0 and cross(b, c, points2d[j]) >= 0
                         and cross(c, a, points2d[j]) >= 0 for j in index if j not in (i0, i1, i2))
            if inside:
                continue
            perimeter2 = ((a - b) ** 2).sum() + ((b - c) ** 2).sum() + ((c - a) ** 2).sum()
            quality = area2 / perimeter2
            if quality > best_quality:
                best, best_quality = k, quality
        if best is None:  # degenerate polygon: fall back to a fan
            return [(0, i, i + 1) for i in range(1, len(points2d) - 1)]
        triangles.append((index[best - 1], index[best], index[(best + 1) % n]))
        del index[best]
    triangles.append((index[0], index[1], index[2]))
    return triangles


def _suffix(k: int) -> str:
    """0 -> a, 25 -> z, 26 -> aa."""
    letters = ""
    k += 1
    while k > 0:
        k, r = divmod(k - 1, 26)
        letters = chr(ord("a") + r) + letters
    return letters


def _hole_centres(outline: np.ndarray, polygon: Polygon, settings: PanelSettings) -> np.ndarray:
    """One drill centre per convex corner of the cut outline, on the corner bisector, at
    ``hole_inset_mm`` from both adjacent edges; corners where the hole would not fit
    (hole edge closer than its radius to the outline) are skipped."""
    if settings.hole_diameter_mm <= 0:
        return np.zeros((0, 2))
    e1 = np.roll(outline, 1, axis=0) - outline
    e2 = np.roll(outline, -1, axis=0) - outline
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 /= np.linalg.norm(e2, axis=1, keepdims=True)
    bisector = e1 + e2
    half = 0.5 * np.arccos(np.clip(np.einsum("ij,ij->i", e1, e2), -1.0, 1.0))
    convex = (e2[:, 0] * e1[:, 1] - e2[:, 1] * e1[:, 0]) > 0  # CCW outline: e2 x e1 > 0 at convex corners
    ok = convex & (np.linalg.norm(bisector, axis=1) > 1e-9) & (np.sin(half) > 1e-3)
    radius = 0.5 * settings.hole_diameter_mm
    boundary = polygon.exterior
    centres = []
    for i in np.flatnonzero(ok):
        direction = bisector[i] / np.linalg.norm(bisector[i])
        c = outline[i] + direction * settings.hole_inset_mm / np.sin(half[i])
        point = shapely.Point(c)
        if polygon.contains(point) and boundary.distance(point) >= radius + 1e-6:
            centres.append(c)
    return np.array(centres).reshape(-1, 2)


def _make_panel(panel_id: str, face: int, loop_m: np.ndarray, settings: PanelSettings) -> Panel:
    centroid, normal, axes = _plane(loop_m)
    planarity_mm = float(np.abs((loop_m - centroid) @ normal).max() * 1e3)
    face_2d = (loop_m - centroid) @ axes.T * 1e3
    face_polygon = Polygon(face_2d)
    if not face_polygon.is_valid or face_polygon.area <= 0:
        raise InputError(f"panel {panel_id}: cell {face} flattens to a self-intersecting or empty outline",
                         hint="check the grid-shell for folded or degenerate cells")
    cut = face_polygon
    if settings.clearance_mm > 0:
        cut = face_polygon.buffer(-settings.clearance_mm, join_style="mitre", mitre_limit=10.0)
    if cut.is_empty:
        raise InputError(f"panel {panel_id}: the clearance {settings.clearance_mm} mm removes the whole panel",
                         hint="lower [fabrication.panels] clearance")
    if cut.geom_type == "MultiPolygon":
        cut = max(cut.geoms, key=lambda g: g.area)
    cut = shapely.geometry.polygon.orient(cut, 1.0)
    outline = np.asarray(cut.exterior.coords)[:-1]
    holes = _hole_centres(outline, cut, settings)
    return Panel(id=panel_id, face=face, outline_mm=outline, face_outline_mm=face_2d,
                 origin_m=centroid, axes=axes, planarity_mm=planarity_mm, holes_mm=holes,
                 area_mm2=float(cut.area), perimeter_mm=float(cut.length),
                 outline_3d_m=centroid + 1e-3 * outline @ axes,
                 nonplanar=planarity_mm > settings.planarity_tolerance_mm,
                 grain_deg=grain_angle_deg(axes, normal, settings.grain))


def grain_angle_deg(axes: np.ndarray, normal: np.ndarray, grain: str) -> float | None:
    """The counter-clockwise turn (degrees) of a panel's 2D frame (in-plane ``axes`` (2, 3), unit
    ``normal``) that lays its ``grain`` direction along x (PanelSettings.grain): the plan axis "x"
    or "y", or "slope", the fall line (-z in the plane). Where that direction stands square to the
    panel (a flat panel's slope, say), the panel's first axis, its longest side. None for "none"."""
    if GRAIN_DIRECTIONS[grain] is None:
        return None
    direction = np.asarray(GRAIN_DIRECTIONS[grain])
    in_plane = direction - (direction @ normal) * normal
    u, v = float(in_plane @ axes[0]), float(in_plane @ axes[1])
    if math.hypot(u, v) < 1e-6:
        return 0.0
    return -math.degrees(math.atan2(v, u))


def panel_seats(panels: list[Panel], loops: list, geometries: dict, joint_settings, beam_radii_mm: dict,
                cells: list[int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(up (n, 3), shift_mm (n, 3)): where each panel rests. ``up`` is its plane's normal on the side
    of its joints' axes (the outside); ``shift_mm`` moves it from its nodes' best-fit plane to where
    its underside clears the joints at its corners (fabrication.joints.joint_reach_mm) and the
    tubes along its edges. ``loops``: each panel's node loop by its ``face``; ``geometries``: node ->
    JointGeometry; ``beam_radii_mm``: (node, node) sorted -> the tube's outer radius, or a rectangular
    beam's (half height, half width, its up (3,)) (pairs that are no beam, a split cell's diagonals,
    have none); ``cells``: each panel's cell. The pieces of a split
    cell move together, along their mean normal, so that they still meet on their diagonals as
    they are cut (each moved along its own normal, the pieces of a sharp fold ran into each other)."""
    from .beams import SECTION_TURN_STEP_DEG
    from .joints import cylinder_reach_mm, joint_reach_mm

    up = np.zeros((len(panels), 3))
    lift = np.zeros(len(panels))
    corners = [[int(i) for i in loops[panel.face] if int(i) in geometries] for panel in panels]
    for k, panel in enumerate(panels):
        normal = np.cross(panel.axes[0], panel.axes[1])
        if corners[k] and sum(float(geometries[i].axis @ normal) for i in corners[k]) < 0:
            normal = -normal
        up[k] = normal
    # each joint's reach along the normals of all the panels at it, in one call
    at_node: dict[int, list[int]] = {}
    for k, nodes in enumerate(corners):
        for i in nodes:
            at_node.setdefault(i, []).append(k)
    joint_reach: dict[tuple[int, int], float] = {}
    for i, members in at_node.items():
        for k, r in zip(members, np.atleast_1d(joint_reach_mm(geometries[i], joint_settings, up[members]))):
            joint_reach[k, i] = float(r)
    for k, panel in enumerate(panels):
        loop = [int(i) for i in loops[panel.face]]
        normal = up[k]
        base = 1e3 * np.asarray(panel.origin_m) @ normal
        reach = [float(geometries[i].position_mm @ normal) - base + joint_reach[k, i] for i in corners[k]]
        for a, b in zip(loop, loop[1:] + loop[:1]):
            radius = beam_radii_mm.get((min(a, b), max(a, b)))
            if radius is None or a not in geometries or b not in geometries:
                continue
            pa, pb = geometries[a].position_mm, geometries[b].position_mm
            start, end = float(pa @ normal) - base, float(pb @ normal) - base
            if isinstance(radius, tuple):  # a rectangle: its corners reach furthest
                half_height, half_width, beam_up = radius
                across = np.cross(beam_up, (pb - pa) / np.linalg.norm(pb - pa))
                # and a slotted end, turned to the nearest SECTION_TURN_STEP_DEG, by its corner's arc
                turned = math.hypot(half_height, half_width) * math.radians(0.5 * SECTION_TURN_STEP_DEG)
                reach.append(max(start, end) + half_height * abs(float(beam_up @ normal))
                             + half_width * abs(float(across @ normal)) + turned)
            else:
                along = float((pb - pa) @ normal / np.linalg.norm(pb - pa))
                reach.append(cylinder_reach_mm(start, end, along, radius))
        lift[k] = max(reach, default=0.0)
    shift = lift[:, None] * up
    cell = np.arange(len(panels)) if cells is None else np.asarray(cells)
    for c in np.unique(cell):
        members = np.flatnonzero(cell == c)
        if len(members) > 1:
            mean = up[members].sum(axis=0)
            mean /= np.linalg.norm(mean)
            # far enough along the mean normal for each piece to clear what is under it
            shift[members] = max(lift[m] / max(float(up[m] @ mean), 1e-3) for m in members) * mean
    return up, shift


#: What to change where a panel is cut back to nothing at its folds.
FOLD_FIX = ("lower [fabrication.panels] clearance or thickness, or smaller joints ([fabrication.joints] "
            "hub_radius), or more cells ([remesh] n_cells) for gentler folds")


def trim_at_folds(panels: list[Panel], loops: list, nodes_m: np.ndarray, seats: tuple[np.ndarray, np.ndarray],
                  settings: PanelSettings, *,
                  problems: list[tuple[tuple[str, ...], str]] | None = None) -> tuple[list[Panel], np.ndarray]:
    """The panels cut back where, resting on their seats (``panel_seats``), two of them would close
    their joint at a fold: (panels, how far each outline was cut back, mm).

    A panel is inset by the clearance from its cell's edges in its nodes' plane; lifted along its
    own normal onto the joints, two neighbours at a valley fold move towards each other (the lift
    times the sine of half the fold each). Each neighbour must stay ``clearance_mm`` clear, over its
    whole thickness, of a plane through their shared edge's direction and halfway between their
    normals, placed halfway across the gap left between them; each outline is cut by it where it is
    not (both by the same amount). Panels that meet at a node only (round a split cell) and whose
    slabs then come within two clearances of each other (the separating axis test on their convex
    hulls) each lose the same corner at that node, cut square to its bisector, as little as keeps
    them apart (bisection); where no such cut parts them they are left as they are (a problem).
    ``loops``: each panel's node loop (into ``nodes_m``, (n, 3) m) by its ``face``; the neighbours
    are the panels whose loops share an edge or a node.
    Nothing is cut at a ridge or where the lift is small. A panel that nothing would be left of
    raises InputError; with ``problems`` (a list) it is left uncut and ((panel id,), message)
    appended, as is ((panel id, panel id), message) for a pair left too close."""
    up, shift = seats
    by_edge: dict[tuple[int, int], list[int]] = {}
    by_node: dict[int, set[int]] = {}
    for k, panel in enumerate(panels):
        loop = [int(i) for i in loops[panel.face]]
        for a, b in zip(loop, loop[1:] + loop[:1]):
            by_edge.setdefault((min(a, b), max(a, b)), []).append(k)
            by_node.setdefault(a, set()).add(k)
    centres = np.array([1e3 * np.asarray(p.outline_3d_m).mean(axis=0) for p in panels]).reshape(-1, 3)
    polygons = [Polygon(p.outline_mm) for p in panels]
    edge_neighbours: list[set[int]] = [set() for _ in panels]
    seated = [1e3 * np.asarray(p.origin_m) + shift[k] for k, p in enumerate(panels)]

    def nearest(k: int, normal: np.ndarray, at: np.ndarray) -> float:
        """How near panel k as seated (its current outline, both faces) comes to the plane through
        ``at`` square to ``normal``: the least of normal . (x - at) over it."""
        outline = np.asarray(polygons[k].exterior.coords) @ np.asarray(panels[k].axes) + seated[k]
        return float(min((outline - at) @ normal) + min(0.0, settings.thickness_mm * float(up[k] @ normal)))

    for (a, b), sharing in sorted(by_edge.items()):
        if len(sharing) != 2:
            continue
        k, j = sharing
        edge_neighbours[k].add(j)
        edge_neighbours[j].add(k)
        if polygons[k].is_empty or polygons[j].is_empty:
            continue
        pa = 1e3 * nodes_m[a]
        along = 1e3 * nodes_m[b] - pa
        along /= np.linalg.norm(along)
        middle = up[k] + up[j]
        middle -= (middle @ along) * along
        if np.linalg.norm(middle) < 1e-9:
            continue
        normal = np.cross(along, middle)
        normal /= np.linalg.norm(normal)
        if float((centres[k] - pa) @ normal) < float((centres[j] - pa) @ normal):  # towards k
            normal = -normal
        # the plane halfway across the gap left between the two, each kept a clearance from it
        gap_k, gap_j = nearest(k, normal, pa), nearest(j, -normal, pa)
        middle_of_gap = pa + 0.5 * (gap_k - gap_j) * normal
        for m, side in ((k, normal), (j, -normal)):
            alpha, beta = float(side @ panels[m].axes[0]), float(side @ panels[m].axes[1])
            if math.hypot(alpha, beta) < 1e-6:
                continue
            # alpha x + beta y >= gamma over the outline (2D, mm), its top face included
            gamma = (settings.clearance_mm - min(0.0, settings.thickness_mm * float(side @ up[m]))
                     - float(side @ (seated[m] - middle_of_gap)))
            polygons[m] = _cut(polygons[m], alpha, beta, gamma)
    # panels that meet at a node only: their corners there, as little as keeps them apart
    for a, around in sorted(by_node.items()):
        for k, j in itertools.combinations(sorted(around), 2):
            if j in edge_neighbours[k] or polygons[k].is_empty or polygons[j].is_empty:
                continue
            slabs = [(panels[m], up[m], seated[m]) for m in (k, j)]
            if not _slabs_meet(*[(polygons[m], *slab) for m, slab in zip((k, j), slabs)], settings.thickness_mm,
                               settings.clearance_mm):
                continue
            corners = [_corner(panels[m], polygons[m], 1e3 * nodes_m[a]) for m in (k, j)]

            def meet(depth: float) -> bool:
                cut = [_cut_corner(polygons[m], *corner, depth) for m, corner in zip((k, j), corners)]
                return not any(c.is_empty for c in cut) and _slabs_meet(
                    *[(c, *slab) for c, slab in zip(cut, slabs)], settings.thickness_mm, settings.clearance_mm)

            low, high = 0.0, max(math.sqrt(polygons[m].area) for m in (k, j)) + settings.clearance_mm
            if meet(high):  # no corner cut parts them: left as they are, and said so
                if problems is not None:
                    problems.append(((panels[k].id, panels[j].id), _unparted(panels[k], panels[j], a, settings)))
                continue
            while high - low > 0.05:
                low, high = (low, 0.5 * (low + high)) if not meet(0.5 * (low + high)) else (0.5 * (low + high), high)
            cut = [_cut_corner(polygons[m], *corner, high) for m, corner in zip((k, j), corners)]
            if any(c.is_empty for c in cut):  # a panel used up before they part: as no cut parting them
                if problems is not None:
                    problems.append(((panels[k].id, panels[j].id), _unparted(panels[k], panels[j], a, settings)))
                continue
            polygons[k], polygons[j] = cut
    out, cut_back = list(panels), np.zeros(len(panels))
    for k, panel in enumerate(panels):
        polygon = polygons[k]
        if polygon.is_empty or polygon.area <= 0:
            message = f"panel {panel.id}: resting on its joints, nothing of it is left between its folds"
            if problems is None:
                raise InputError(message, hint=FOLD_FIX)
            problems.append(((panel.id,), message))
        elif polygon.area < panel.area_mm2 - 1e-6:
            polygon = shapely.geometry.polygon.orient(shapely.simplify(polygon, 1e-6), 1.0)
            outline = np.asarray(polygon.exterior.coords)[:-1]
            cut_back[k] = float(Polygon(panel.outline_mm).hausdorff_distance(polygon))
            out[k] = replace(panel, outline_mm=outline, holes_mm=_hole_centres(outline, polygon, settings),
                             area_mm2=float(polygon.area), perimeter_mm=float(polygon.length),
                             outline_3d_m=np.asarray(panel.origin_m) + 1e-3 * outline @ np.asarray(panel.axes))
    return out, cut_back


def _unparted(first: Panel, second: Panel, node: int, settings: PanelSettings) -> str:
    return (f"panels {first.id} and {second.id}, which meet at node {node_id(node)} only, come within two "
            f"clearances ({2 * settings.clearance_mm:g} mm) of each other resting on their joints, and no cut "
            "of their corners there parts them without using one of them up")


def _cut(polygon: Polygon, alpha: float, beta: float, gamma: float) -> Polygon:
    """``polygon`` where alpha x + beta y >= gamma (its largest part); empty if nothing is left."""
    points = np.asarray(polygon.exterior.coords)
    if (points @ np.array([alpha, beta])).min() >= gamma - 1e-6:
        return polygon
    kept = polygon.intersection(_half_plane(alpha, beta, gamma, polygon))
    if kept.is_empty or kept.area <= 0:
        return Polygon()
    return kept if kept.geom_type == "Polygon" else max(kept.geoms, key=lambda g: g.area)


def _corner(panel: Panel, polygon: Polygon, node_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(vertex, unit inward bisector) in the panel's plane (mm) of the outline's corner nearest the node."""
    outline = np.asarray(polygon.exterior.coords)[:-1]
    node = (node_mm - 1e3 * np.asarray(panel.origin_m)) @ np.asarray(panel.axes).T
    i = int(np.argmin(np.linalg.norm(outline - node, axis=1)))
    before, after = outline[i - 1] - outline[i], outline[(i + 1) % len(outline)] - outline[i]
    inward = before / np.linalg.norm(before) + after / np.linalg.norm(after)
    if np.linalg.norm(inward) < 1e-9:
        inward = np.array([-before[1], before[0]])
    centre = np.asarray(polygon.centroid.coords[0])
    if float(inward @ (centre - outline[i])) < 0:
        inward = -inward
    return outline[i], inward / np.linalg.norm(inward)


def _cut_corner(polygon: Polygon, vertex: np.ndarray, inward: np.ndarray, depth: float) -> Polygon:
    """``polygon`` less its corner at ``vertex``, cut square to ``inward`` at ``depth`` (mm)."""
    return polygon if depth <= 0 else _cut(polygon, float(inward[0]), float(inward[1]),
                                           float(inward @ vertex) + depth)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross products of (..., 3) arrays (numpy's cross costs more than it computes here)."""
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1], a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def _apart_along(points: list[np.ndarray], candidates: np.ndarray, gap_mm: float) -> bool:
    """Whether the two point sets lie ``gap_mm`` apart along one of the ``candidates`` (k, 3)."""
    lengths = np.linalg.norm(candidates, axis=1)
    keep = lengths > 1e-9 * lengths.max()
    candidates = candidates[keep] / lengths[keep, None]
    a, b = points[0] @ candidates.T, points[1] @ candidates.T
    return bool(np.maximum(b.min(axis=0) - a.max(axis=0), a.min(axis=0) - b.max(axis=0)).max() >= gap_mm)


def _slabs_meet(first: tuple, second: tuple, thickness_mm: float, clearance_mm: float) -> bool:
    """Whether two panels as placed may come within two clearances of each other: each (outline
    polygon in its plane (mm), panel, up, origin (mm) of its seat), a slab ``thickness_mm`` thick
    towards up, taken as its convex hull. The separating axis test: the slabs are apart where
    their corners lie two clearances apart along a face's normal or the cross product of an edge
    of each (for convex solids one of these parts any two that do not touch); the line between
    their centres and their faces' normals are tried first."""
    points, sides, ups = [], [], []
    for polygon, panel, up, origin in (first, second):
        # a polygon's corners project as its convex hull's; its own edges serve as the hull's
        outline = np.asarray(polygon.exterior.coords)
        axes = np.asarray(panel.axes)
        flat = outline[:-1] @ axes + origin
        points.append(np.vstack([flat, flat + thickness_mm * up]))
        sides.append(np.diff(outline, axis=0) @ axes)  # (m, 3) the outline's edges in space
        ups.append(up[None, :])
    between = (points[1].mean(axis=0) - points[0].mean(axis=0))[None, :]
    if _apart_along(points, np.vstack([between, *ups]), 2 * clearance_mm):
        return False
    normals = [_cross(side, up) for side, up in zip(sides, ups)]
    edges = [np.vstack([side, up]) for side, up in zip(sides, ups)]
    crossed = _cross(edges[0][:, None, :], edges[1][None, :, :]).reshape(-1, 3)
    return not _apart_along(points, np.vstack([*normals, crossed]), 2 * clearance_mm)


def _half_plane(alpha: float, beta: float, gamma: float, polygon: Polygon) -> Polygon:
    """The part of the plane where alpha x + beta y >= gamma, as a polygon covering ``polygon``
    (plain floats: numpy's set-up costs more than these few products)."""
    norm = math.hypot(alpha, beta)
    nx, ny, g = alpha / norm, beta / norm, gamma / norm
    x0, y0, x1, y1 = polygon.bounds
    r = 2 * math.hypot(x1 - x0, y1 - y0) + abs(g) + 1.0
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    step = g - (cx * nx + cy * ny)
    fx, fy = cx + step * nx, cy + step * ny  # on the line
    tx, ty = -ny * r, nx * r
    ox, oy = nx * r, ny * r
    return shapely.polygons([(fx - tx, fy - ty), (fx + tx, fy + ty), (fx + tx + ox, fy + ty + oy),
                             (fx - tx + ox, fy - ty + oy)])


def flatten_panels(polymesh: PolyMesh, settings: PanelSettings | None = None, *,
                   problems: list[tuple[str, str]] | None = None) -> list[Panel]:
    """One flat panel per cell of ``polymesh`` (node loops, m), in face order, id P{f+1:04d}.

    Cells further from planar than ``settings.planarity_tolerance_mm`` are flagged
    ``nonplanar``; with ``settings.split_nonplanar`` they are replaced by their ear-clipped
    triangles (ids with a letter suffix), which are exactly planar. Raises ``InputError``
    naming the panel when a cell is degenerate or the clearance leaves nothing; with ``problems``
    (a list) such a cell gets no panel and (panel id, message) is appended instead.
    """
    settings = settings or PanelSettings()
    panels: list[Panel] = []
    nodes = polymesh.nodes
    for f, loop in enumerate(polymesh.faces):
        label = panel_id(f)
        if len(loop) < 3:
            raise InputError(f"cell {f} ({label}) has {len(loop)} nodes; a panel needs at least 3")
        loop_m = nodes[loop]
        try:
            panel = _make_panel(label, f, loop_m, settings)
        except InputError as error:
            if problems is None:
                raise
            problems.append((label, str(error).splitlines()[0]))
            continue
        if not (panel.nonplanar and settings.split_nonplanar):
            panels.append(panel)
            continue
        centroid, _, axes = _plane(loop_m)
        for k, tri in enumerate(_ear_clip((loop_m - centroid) @ axes.T)):
            panels.append(_make_panel(f"{label}{_suffix(k)}", f, loop_m[list(tri)], settings))
    return panels


# ---------------------------------------------------------------------------- DXF

def panel_label(outline_mm: np.ndarray) -> tuple[np.ndarray, float]:
    """Label anchor (2,) at the pole of inaccessibility and a text height (mm) that fits."""
    polygon = Polygon(outline_mm)
    pole = shapely.ops.polylabel(polygon, tolerance=1.0) if polygon.area > 0 else polygon.centroid
    radius = polygon.exterior.distance(pole)
    return np.array([pole.x, pole.y]), float(np.clip(0.3 * radius, 1.0, 10.0))


def add_panel(msp, panel: Panel, offset=(0.0, 0.0), angle_deg: float = 0.0,
              settings: PanelSettings | None = None, note: bool = False) -> None:
    """Draw one panel into an ezdxf modelspace, rotated by ``angle_deg`` about its 2D origin
    then moved by ``offset`` (mm): outline on CUT, id on ENGRAVE, holes on DRILL (with
    ``settings``), optionally the note on NOTES."""
    from ezdxf.enums import TextEntityAlignment

    a = math.radians(angle_deg)
    R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    shift = np.asarray(offset, float)

    def place(points):
        return np.asarray(points, float).reshape(-1, 2) @ R.T + shift

    outline = place(panel.outline_mm)
    msp.add_lwpolyline([tuple(map(float, p)) for p in outline], close=True, dxfattribs={"layer": "CUT"})
    anchor, height = panel_label(panel.outline_mm)
    at = place(anchor)[0]
    text = msp.add_text(panel.id, height=height, rotation=float(angle_deg),
                        dxfattribs={"layer": "ENGRAVE", "style": ENGRAVE_STYLE})
    text.set_placement((float(at[0]), float(at[1])), align=TextEntityAlignment.MIDDLE_CENTER)
    if settings is not None and settings.hole_diameter_mm > 0:
        for c in place(panel.holes_mm):
            msp.add_circle((float(c[0]), float(c[1])), 0.5 * settings.hole_diameter_mm, dxfattribs={"layer": "DRILL"})
    if note and settings is not None:
        lo = outline.min(axis=0)
        line = (f"{panel.id}  t={settings.thickness_mm:g} mm  {settings.material_name}  "
                f"planarity {panel.planarity_mm:.2f} mm" + ("  NON-PLANAR" if panel.nonplanar else ""))
        msp.add_text(line, height=3.0, dxfattribs={"layer": "NOTES", "insert": (float(lo[0]), float(lo[1]) - 8.0)})


def write_panel_dxfs(panels: list[Panel], folder: str | os.PathLike,
                     settings: PanelSettings | None = None) -> list[Path]:
    """Write ``folder/<panel id>.dxf`` for every panel (atomic); returns the paths."""
    settings = settings or PanelSettings()
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    files = SharedDocument(cutting_layers(drill=settings.hole_diameter_mm > 0))
    for panel in panels:
        paths.append(files.save(folder / f"{panel.id}.dxf",
                                lambda msp, panel=panel: add_panel(msp, panel, settings=settings, note=True)))
    return paths


def write_panels_csv(panels: list[Panel], nesting: "SheetNesting | None", settings: PanelSettings | None,
                     path: str | os.PathLike, *, sheet_names: dict[str, str] | None = None,
                     cells: dict[str, tuple[int, int]] | None = None) -> Path:
    """Panel schedule: id, area_mm2, perimeter_mm, vertex_count, planarity_mm, thickness_mm,
    mass_kg (cut area less drill holes x thickness x density), sheet (SHEET01... or empty).
    ``sheet_names`` (panel id -> sheet) replaces the nesting's names (several stock sizes);
    ``cells`` (panel id -> (cell number, piece index; 0 = the whole cell)) adds columns cell, piece."""
    settings = settings or PanelSettings()
    sheet_of: dict[int, str] = {}
    if sheet_names is not None:
        sheet_of = {i: sheet_names[p.id] for i, p in enumerate(panels) if p.id in sheet_names}
    elif nesting is not None:
        for placement in nesting.placements:
            sheet_of[placement.panel] = sheet_id(placement.sheet)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["id", "area_mm2", "perimeter_mm", "vertex_count", "planarity_mm", "thickness_mm",
                     "mass_kg", "sheet"] + (["cell", "piece"] if cells is not None else []))
    hole_area = math.pi * (0.5 * settings.hole_diameter_mm) ** 2
    for i, panel in enumerate(panels):
        net_area = panel.area_mm2 - hole_area * len(panel.holes_mm)
        mass = net_area * 1e-6 * settings.thickness_mm * 1e-3 * settings.density
        writer.writerow([panel.id, f"{panel.area_mm2:.2f}", f"{panel.perimeter_mm:.2f}", panel.vertex_count,
                         f"{panel.planarity_mm:.3f}", f"{settings.thickness_mm:g}", f"{mass:.4f}",
                         sheet_of.get(i, "")] + (list(cells.get(panel.id, ("", ""))) if cells is not None else []))
    return write_text_atomic(path, buffer.getvalue())
