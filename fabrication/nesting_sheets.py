"""Nesting flat panels on rectangular sheets (irregular 2D bottom-left fill, lengths in mm).

Method: panels are taken by decreasing area. For each panel and each candidate rotation
(0, 90, 180, 270 degrees and the two orientations of its minimum-area rectangle) the set of
feasible positions on a sheet is computed exactly with no-fit polygons: for every part
already on the sheet, the positions where the new part would come closer than the spacing
form the Minkowski sum  B + (-A) + disc(spacing)  of the convex hulls (convex panels are
nested exactly; a non-convex panel is nested by its hull, which is conservative). The
inner-fit rectangle (sheet less margin less part size) minus the union of those regions is
the feasible region, and its left-most, then lowest, vertex is the bottom-left position.
The rotation whose placement reaches least far to the right (then least high) wins. Sheets
are tried first-fit; a new sheet is opened when none takes the panel.

Jobs of up to TIGHT_NESTING_PANELS panels are nested a second time by a tighter rule, and the
nesting of fewer sheets is kept: every vertex of the feasible region is a candidate, and the
panel goes where the sheet's parts keep the smallest envelope (convex hull plus a fifth of the
bounding box), with the rotations that lay each of its sides along x as well (two triangles
then close into a parallelogram). On the mock-up's 158 panels: 14 sheets (70 %) instead of 16
(61 %); it is 3-4 times slower, so large jobs keep the bottom-left fill alone.

Speed on large sheets: each sheet keeps its *free space* for a disc of radius rho (the sheet less
its margins and rho, less every part grown by the spacing and rho). Wherever a panel can go, the
panel less a band of rho lies in one piece of that free space, so only pieces at least as big
count and their left edge bounds the bottom-left position from the left: only the parts to the
right of that bound take part in the no-fit union, and a sheet with no such piece refuses the
panel at once. The bound is exact (the same
placements as without it); on a 6000 x 3210 mm sheet holding 200 panels it leaves a few dozen
parts in the union instead of all of them. rho is 0.9 times the smallest disc of the next 50 panels
(by decreasing area), kept while the panels have a disc at least that large, so the free space is
updated by one difference per placed part and rebuilt now and then.

Placement convention: a panel's sheet outline is  outline_mm @ R(angle).T + (dx, dy),
with R the counter-clockwise rotation by ``angle_deg``.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import shapely
from shapely.geometry import MultiPoint, box

from engine.errors import InputError
from fabrication.dxf import cutting_layers, new_document, save_dxf
from fabrication.files import save_figure_png
from fabrication.settings import SheetSettings

from .ids import sheet_id

if TYPE_CHECKING:  # pragma: no cover
    from fabrication.panels import Panel, PanelSettings

__all__ = ["SheetSettings", "Placement", "SheetNesting", "StockNesting", "nest_sheets", "nest_on_stock",
           "fits_sheet", "sheet_overshoot", "write_sheet_dxfs", "write_sheets_picture",
           "write_contact_sheet", "placed_outline", "rotation"]

#: buffer arcs are drawn with this many segments per quarter circle
_QUAD_SEGS = 4


@dataclass(frozen=True)
class Placement:
    """Panel ``panel`` (index into the panel list) on sheet ``sheet`` (0-based), rotated by
    ``angle_deg`` about the panel's 2D origin, then moved by (dx, dy) mm."""

    panel: int
    sheet: int
    angle_deg: float
    dx: float
    dy: float

    @property
    def offset(self) -> tuple[float, float]:
        return (self.dx, self.dy)


@dataclass(frozen=True, kw_only=True)
class SheetNesting:
    """Result of ``nest_sheets``: one placement per panel (in panel order), the panel
    indices on each sheet, overall and per-sheet utilisation (panel area / sheet area),
    and sheet_of: panel id -> sheet name (SHEET01...)."""

    placements: list[Placement]
    sheets: list[list[int]]
    utilisation: float
    sheet_utilisation: list[float]
    settings: SheetSettings = field(default_factory=SheetSettings)
    sheet_of: dict[str, str] = field(default_factory=dict)

    @property
    def n_sheets(self) -> int:
        return len(self.sheets)

    def placed_outline(self, panel_index: int, outline_mm: np.ndarray) -> np.ndarray:
        """(k, 2) outline of panel ``panel_index`` in its sheet's coordinates, mm."""
        p = self.placements[panel_index]
        return np.asarray(outline_mm) @ rotation(p.angle_deg).T + (p.dx, p.dy)


def rotation(angle_deg: float) -> np.ndarray:
    """2x2 counter-clockwise rotation matrix."""
    a = math.radians(angle_deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def placed_outline(panel: "Panel", placement: Placement) -> np.ndarray:
    """(k, 2) cut outline of ``panel`` where ``placement`` puts it on its sheet, mm."""
    return np.asarray(panel.outline_mm) @ rotation(placement.angle_deg).T + (placement.dx, placement.dy)


@dataclass
class _Orientation:
    angle: float
    hull: np.ndarray  # (k, 2) rotated convex hull, shifted so the outline's bbox starts at 0
    shift: np.ndarray  # (2,) added to R @ outline to reach that normalised frame
    width: float
    height: float
    eroded: dict = field(default_factory=dict)  # disc radius -> bounds of the hull eroded by it, or None

    def eroded_bounds(self, radius: float) -> np.ndarray | None:
        """(4,) bounds of the hull less a band of ``radius`` (where a disc of that radius inside the
        panel can have its centre), in the orientation's frame; None when nothing is left."""
        if radius not in self.eroded:
            core = shapely.buffer(shapely.Polygon(self.hull), -radius, quad_segs=_QUAD_SEGS)
            self.eroded[radius] = None if core.is_empty else np.asarray(core.bounds)
        return self.eroded[radius]


#: The free space of a sheet is rebuilt for discs of this share of the smallest disc radius among
#: the next FREE_RADIUS_LOOKAHEAD panels, so that they all reuse it.
FREE_RADIUS_SHARE = 0.9
FREE_RADIUS_LOOKAHEAD = 50


@dataclass
class _Sheet:
    hulls: list[np.ndarray] = field(default_factory=list)
    bounds: list[np.ndarray] = field(default_factory=list)  # (4,) xmin, ymin, xmax, ymax per part
    area: float = 0.0
    failed_area: float = math.inf  # smallest panel area that did not fit since the last change
    free: object = None  # where the centre of a disc of radius free_radius can go (shapely), or None
    free_radius: float = 0.0
    envelope: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # convex hull of the parts

    def free_parts(self, radius: float, rebuild: float, settings: SheetSettings) -> np.ndarray | None:
        """(k, 4) bounds of the pieces of the free space: where the centre of a disc of radius
        ``free_radius`` (at most ``radius``) can go, inside the margins and at least the spacing from
        every part; None when there is no such place. When the free space kept is for a larger disc,
        it is rebuilt for ``rebuild`` (mm, at most ``radius``)."""
        if self.free is None or self.free_radius > radius:
            rho = min(rebuild, radius)
            m, grow = settings.margin_mm + rho, settings.spacing_mm + rho
            if settings.width_mm - 2 * m <= 0 or settings.height_mm - 2 * m <= 0:
                return None
            room = box(m, m, settings.width_mm - m, settings.height_mm - m)
            grown = shapely.buffer([shapely.Polygon(h) for h in self.hulls], grow, quad_segs=_QUAD_SEGS)
            self.free = room.difference(shapely.union_all(grown)) if self.hulls else room
            self.free_radius = rho
        if self.free.is_empty:
            return None
        return shapely.bounds(shapely.get_parts(self.free))

    def add(self, hull: np.ndarray, settings: SheetSettings, *, envelope: bool = False) -> None:
        """Put the part of convex outline ``hull`` (mm, sheet frame) on the sheet; with ``envelope``
        (the tight rule reads it) the parts' convex envelope grows with it."""
        self.hulls.append(hull)
        if envelope:
            together = shapely.convex_hull(shapely.multipoints(np.concatenate([self.envelope, hull])))
            self.envelope = shapely.get_coordinates(together)[:-1] if together.geom_type == "Polygon" \
                else np.concatenate([self.envelope, hull])
        self.bounds.append(np.concatenate([hull.min(axis=0), hull.max(axis=0)]))
        if self.free is not None:
            grown = shapely.buffer(shapely.Polygon(hull), settings.spacing_mm + self.free_radius, quad_segs=_QUAD_SEGS)
            self.free = self.free.difference(grown)


def _inscribed_radius(hull: np.ndarray) -> float:
    """Radius (mm) of a disc inside the convex polygon ``hull`` ((k, 2), mm): centred at its vertex
    centroid, as large as the nearest edge line allows."""
    centre = hull.mean(axis=0)
    edge = np.roll(hull, -1, axis=0) - hull
    normal = np.column_stack([edge[:, 1], -edge[:, 0]]) / np.maximum(np.linalg.norm(edge, axis=1), 1e-300)[:, None]
    return float(np.min(np.abs(np.einsum("ki,ki->k", centre - hull, normal))))


def _angles(outline: np.ndarray, rotations: bool, sides: bool = False, grain_deg: float | None = None
            ) -> list[float]:
    """The rotations tried (degrees): the quarter turns and the minimum-area rectangle's two, and
    with ``sides`` each side of the hull laid along x, below the part and above it. With a
    ``grain_deg`` (Panel.grain_deg), that turn and the half turn from it only."""
    if grain_deg is not None:
        return [grain_deg % 360.0, (grain_deg + 180.0) % 360.0] if rotations else [grain_deg % 360.0]
    if not rotations:
        return [0.0]
    angles = [0.0, 90.0, 180.0, 270.0]
    rect = np.asarray(MultiPoint(outline).minimum_rotated_rectangle.exterior.coords)[:4]
    edges = np.diff(np.vstack([rect, rect[:1]]), axis=0)
    longest = edges[np.argmax(np.linalg.norm(edges, axis=1))]
    theta = -math.degrees(math.atan2(longest[1], longest[0]))  # turn the long side onto x
    extras = [theta, theta + 90.0]
    if sides:  # sides laid on the sheet's edges and on each other's (two triangles make a parallelogram)
        hull = np.asarray(MultiPoint(outline).convex_hull.exterior.coords)
        for side in np.diff(hull, axis=0):
            along = -math.degrees(math.atan2(side[1], side[0]))
            extras += [along, along + 180.0]
    apart = 0.5 if sides else 0.01  # degrees between two rotations tried
    for extra in extras:
        a = extra % 360.0
        if all(min(abs(a - b) % 360.0, 360.0 - abs(a - b) % 360.0) > apart for b in angles):
            angles.append(a)
    return angles


def _orientations(outline: np.ndarray, rotations: bool, sides: bool = False,
                  grain_deg: float | None = None) -> list[_Orientation]:
    hull = np.asarray(MultiPoint(outline).convex_hull.exterior.coords)[:-1]
    result = []
    for angle in _angles(outline, rotations, sides, grain_deg):
        R = rotation(angle)
        rotated = outline @ R.T
        lo, hi = rotated.min(axis=0), rotated.max(axis=0)
        result.append(_Orientation(angle=angle, hull=hull @ R.T - lo, shift=-lo,
                                   width=float(hi[0] - lo[0]), height=float(hi[1] - lo[1])))
    return result


def _best_position(sheet: _Sheet, o: _Orientation, settings: SheetSettings,
                   reach: float, free: np.ndarray | None = None) -> tuple[float, float] | None:
    """Bottom-left feasible reference point (x, y) of orientation ``o`` on ``sheet``, or None
    (no room, or no position whose right edge stays within ``reach``); ``free`` as for
    ``_feasible_positions``."""
    xy = _feasible_positions(sheet, o, settings, free)
    if xy is None:
        return None
    best = xy[np.argmin(xy[:, 0] + 1e-3 * xy[:, 1])]  # left-most, then lowest
    if best[0] + o.width > reach:
        return None
    return float(best[0]), float(best[1])


def _feasible_positions(sheet: _Sheet, o: _Orientation, settings: SheetSettings,
                        free: np.ndarray | None = None) -> np.ndarray | None:
    """(k, 2) the vertices of the region where orientation ``o``'s reference point can go on
    ``sheet`` (the candidate positions), or None (no room). ``free``: the bounds of the sheet's
    free-space pieces (:meth:`_Sheet.free_parts`). The panel less a band of the free space's disc
    radius lies in one piece wherever the panel can go, so only pieces at least that big count,
    and no feasible point lies outside them."""
    m, s = settings.margin_mm, settings.spacing_mm
    x0, y0 = m, m
    x1, y1 = settings.width_mm - m - o.width, settings.height_mm - m - o.height
    if x1 < x0 - 1e-9 or y1 < y0 - 1e-9:
        return None
    x1, y1 = max(x1, x0), max(y1, y0)
    if not sheet.hulls:
        return np.array([[x0, y0]])
    # where the reference point can be: the inner-fit rectangle, or with the free space only the
    # rectangles that keep the eroded panel inside a piece big enough for it (a degenerate one a
    # hair wider; the parts near them all enter the union, so the result stays exact)
    windows = np.array([[x0, y0, x1, y1]])
    core = o.eroded_bounds(sheet.free_radius) if free is not None else None
    if core is not None:
        big = ((free[:, 2] - free[:, 0] >= core[2] - core[0] - 1e-6)
               & (free[:, 3] - free[:, 1] >= core[3] - core[1] - 1e-6))
        pieces = free[big]
        windows = np.column_stack([np.maximum(pieces[:, 0] - core[0], x0), np.maximum(pieces[:, 1] - core[1], y0),
                                   np.minimum(pieces[:, 2] - core[2], x1), np.minimum(pieces[:, 3] - core[3], y1)])
        windows = windows[(windows[:, 0] <= windows[:, 2] + 1e-6) & (windows[:, 1] <= windows[:, 3] + 1e-6)]
        if not len(windows):
            return None
    wide = windows + np.array([-1e-9, -1e-9, 1e-9, 1e-9])
    inside = np.column_stack([np.maximum(wide[:, :2], (x0, y0)), np.minimum(wide[:, 2:], (x1, y1))])
    solid = (inside[:, 2] > inside[:, 0]) & (inside[:, 3] > inside[:, 1])
    windows = np.where(solid[:, None], inside, wide)
    # GEOS draws buffer arcs with chords of up to pi / (2 quad_segs): grow the radius so the
    # polygonal buffer contains the true rounded one (checked against exact distances in tests)
    radius = s / math.cos(math.pi / (2 * _QUAD_SEGS)) + 1e-6 if s > 0 else 0.0
    a_lo, a_hi = o.hull.min(axis=0), o.hull.max(axis=0)
    bounds = np.array(sheet.bounds)[:, None, :]
    near = ((bounds[..., 0] - a_hi[0] - radius <= windows[:, 2]) & (bounds[..., 2] - a_lo[0] + radius >= windows[:, 0])
            & (bounds[..., 1] - a_hi[1] - radius <= windows[:, 3])
            & (bounds[..., 3] - a_lo[1] + radius >= windows[:, 1])).any(axis=1)
    inner = shapely.union_all(shapely.box(*windows.T)) if len(windows) > 1 else box(*windows[0])
    if near.any():
        # no-fit region of each nearby part B for reference points t: hull(B - A) grown by the spacing
        sums = [(sheet.hulls[j][:, None, :] - o.hull[None, :, :]).reshape(-1, 2) for j in np.flatnonzero(near)]
        counts = [len(c) for c in sums]
        points = shapely.multipoints(np.vstack(sums), indices=np.repeat(np.arange(len(sums)), counts))
        regions = shapely.convex_hull(points)
        if radius > 0:
            regions = shapely.buffer(regions, radius, quad_segs=_QUAD_SEGS)
        feasible = inner.difference(shapely.union_all(regions))
    else:
        feasible = inner
    if feasible.is_empty:
        return None
    return shapely.get_coordinates(feasible)


def _place(sheet: _Sheet, k: int, i: int, options: list[_Orientation], settings: SheetSettings,
           placements: list, radius: float, rebuild: float, tight: bool = False) -> bool:
    """Put panel ``i`` on ``sheet`` (number ``k``) in its best orientation; False when none fits.
    ``radius``: its inscribed disc's (mm); ``rebuild``: see :meth:`_Sheet.free_parts`. The best:
    the bottom-left position of the rotation that reaches least far right, or with ``tight`` the
    position and rotation that leave the sheet's parts the tightest envelope (``_tightest``)."""
    best = None
    reach = math.inf
    free = None
    if sheet.hulls:
        free = sheet.free_parts(radius, rebuild, settings)
        if free is None:
            return False
    for o in options:
        if tight:
            xy = _feasible_positions(sheet, o, settings, free)
            if xy is None:
                continue
            key, position = _tightest(sheet.envelope, o.hull, xy)
        else:
            position = _best_position(sheet, o, settings, reach, free)
            if position is None:
                continue
            key = ((position[0] + o.width) + 1e-3 * (position[1] + o.height),)
        if best is None or key < best[0]:
            best = (key, o, position)
            if not tight:
                reach = position[0] + o.width  # later orientations must not reach further right
    if best is None:
        return False
    _, o, (x, y) = best
    sheet.add(o.hull + (x, y), settings, envelope=tight)
    dx, dy = o.shift + (x, y)
    placements[i] = Placement(panel=int(i), sheet=k, angle_deg=float(o.angle), dx=float(dx), dy=float(dy))
    return True


#: Candidate positions per rotation whose envelope is measured exactly (those of least bounding box).
ENVELOPE_CANDIDATES = 8
#: Weight of the bounding box beside the convex hull in a placement's envelope.
ENVELOPE_BOX_WEIGHT = 0.2


def _tightest(envelope: np.ndarray, hull: np.ndarray, xy: np.ndarray) -> tuple[tuple[float, float], np.ndarray]:
    """The candidate position (one of ``xy``) where the part of convex outline ``hull`` leaves the
    parts on the sheet (their convex envelope ``envelope``, (k, 2), maybe empty) the tightest: the
    least area of the convex hull of all of them plus ENVELOPE_BOX_WEIGHT times their bounding
    box's, then the left-most, lowest. Its (key, position)."""
    xy = np.unique(np.round(xy, 6), axis=0)
    lo = hull.min(axis=0)[None] + xy
    hi = hull.max(axis=0)[None] + xy
    if len(envelope):
        lo, hi = np.minimum(lo, envelope.min(axis=0)), np.maximum(hi, envelope.max(axis=0))
    boxes = np.prod(hi - lo, axis=1)
    keep = np.argsort(boxes, kind="stable")[:ENVELOPE_CANDIDATES]
    points = np.concatenate([np.concatenate([envelope, hull + p]) for p in xy[keep]])
    groups = np.repeat(np.arange(len(keep)), len(envelope) + len(hull))
    hulls = shapely.convex_hull(shapely.multipoints(points, indices=groups))
    score = shapely.area(hulls) + ENVELOPE_BOX_WEIGHT * boxes[keep]
    order = np.lexsort((xy[keep, 1], xy[keep, 0], np.round(score, 3)))
    j = keep[order[0]]
    return (float(np.round(score[order[0]], 3)), float(xy[j, 0] + 1e-3 * xy[j, 1])), xy[j]


def _closest_fit(options: list[_Orientation], settings: SheetSettings) -> tuple[bool, float, _Orientation]:
    """(whether one of the rotations fits the sheet less its margins, how many times the usable size
    the rotation closest to fitting needs (the larger of width and height over the usable ones), that rotation)."""
    usable_w = settings.width_mm - 2 * settings.margin_mm
    usable_h = settings.height_mm - 2 * settings.margin_mm
    fits = any(o.width <= usable_w + 1e-9 and o.height <= usable_h + 1e-9 for o in options)
    closest = min(options, key=lambda o: max(o.width / usable_w, o.height / usable_h))
    return fits, max(closest.width / usable_w, closest.height / usable_h), closest


def fits_sheet(panel: "Panel", settings: SheetSettings) -> bool:
    """Whether the panel's cut outline fits the sheet less its margins in one of its rotations."""
    return _closest_fit(_orientations(np.asarray(panel.outline_mm, float), settings.rotations,
                                      grain_deg=getattr(panel, "grain_deg", None)), settings)[0]


def sheet_overshoot(panel: "Panel", stocks: list[SheetSettings]) -> tuple[float, float, float]:
    """(width, height) in mm of the panel's rotation that comes closest to fitting one of the stock
    sheets, and how many times that sheet's usable size it needs (over 1: it fits none)."""
    best = None
    for stock in stocks:
        _, over, o = _closest_fit(_orientations(np.asarray(panel.outline_mm, float), stock.rotations,
                                                grain_deg=getattr(panel, "grain_deg", None)), stock)
        if best is None or over < best[2]:
            best = (o.width, o.height, over)
    return float(best[0]), float(best[1]), float(best[2])


@dataclass(frozen=True, kw_only=True)
class StockNesting:
    """Panels nested on several stock sheet sizes: ``groups`` holds, per size used, its settings,
    the indices of its panels (into the full list) and their nesting; ``unfit`` the panels larger
    than every size. Sheets are numbered SHEET01... across the sizes in order."""

    groups: list[tuple[SheetSettings, list[int], SheetNesting]]
    unfit: list[int]

    @property
    def n_sheets(self) -> int:
        return sum(n.n_sheets for _, _, n in self.groups)

    @property
    def utilisation(self) -> float:
        """Panel area over sheet area, all sizes."""
        used = sum(n.utilisation * n.n_sheets * s.width_mm * s.height_mm for s, _, n in self.groups)
        total = sum(n.n_sheets * s.width_mm * s.height_mm for s, _, n in self.groups)
        return float(used / total) if total else 0.0

    def first_numbers(self) -> list[int]:
        """Number of each group's first sheet (1-based)."""
        out, number = [], 1
        for _, _, nesting in self.groups:
            out.append(number)
            number += nesting.n_sheets
        return out

    def sheet_of(self, panels: list["Panel"]) -> dict[str, str]:
        """Panel id -> sheet name (SHEET01...), for the panels placed."""
        out = {}
        for first, (_, members, nesting) in zip(self.first_numbers(), self.groups):
            for p in nesting.placements:
                out[panels[members[p.panel]].id] = sheet_id(first - 1 + p.sheet)
        return out


def nest_on_stock(panels: list["Panel"], stocks: list[SheetSettings]) -> StockNesting:
    """Each panel on the first stock size it fits, each size nested with :func:`nest_sheets`;
    panels that fit none are left out (``unfit``) for the caller to report."""
    if not stocks:
        raise InputError("sheet nesting needs at least one stock sheet size")
    members: list[list[int]] = [[] for _ in stocks]
    unfit = []
    for i, panel in enumerate(panels):
        k = next((k for k, stock in enumerate(stocks) if fits_sheet(panel, stock)), None)
        (unfit if k is None else members[k]).append(i)
    groups = [(stock, group, nest_sheets([panels[i] for i in group], stock))
              for stock, group in zip(stocks, members) if group]
    return StockNesting(groups=groups, unfit=unfit)


#: Jobs of at most this many panels per stock size are nested twice, by the bottom-left rule and by
#: the tight one (3-4 times slower), and the better nesting is kept.
TIGHT_NESTING_PANELS = 400


def nest_sheets(panels: list["Panel"], settings: SheetSettings | None = None) -> SheetNesting:
    """Place every panel's cut outline (``Panel.outline_mm``) once on as few sheets as the fill
    finds, parts at least ``spacing_mm`` apart and ``margin_mm`` inside the sheet edge. Raises
    ``InputError`` naming a panel that fits no sheet in any rotation.

    Up to TIGHT_NESTING_PANELS panels, the bottom-left fill and the tight one (each part where
    the sheet's parts keep the smallest envelope, sides laid along each other) both run, and the
    nesting of fewer sheets (then the emptier last sheet, to keep for offcuts) is kept."""
    settings = settings or SheetSettings()
    nesting = _nest(panels, settings, tight=False)
    if 0 < len(panels) <= TIGHT_NESTING_PANELS and settings.rotations:
        tight = _nest(panels, settings, tight=True)
        if (tight.n_sheets, tight.sheet_utilisation[-1]) < (nesting.n_sheets, nesting.sheet_utilisation[-1]):
            return tight
    return nesting


def _nest(panels: list["Panel"], settings: SheetSettings, tight: bool) -> SheetNesting:
    n = len(panels)
    orientations = [_orientations(np.asarray(p.outline_mm, float), settings.rotations, sides=tight,
                                  grain_deg=getattr(p, "grain_deg", None)) for p in panels]
    for p, options in zip(panels, orientations):
        fits, _, o = _closest_fit(options, settings)
        if not fits:
            raise InputError(
                f"panel {p.id} ({o.width:.0f} x {o.height:.0f} mm) does not fit on a "
                f"{settings.width_mm:g} x {settings.height_mm:g} mm sheet with {settings.margin_mm:g} mm margin",
                hint="add a larger size to [fabrication.sheets] sizes, or set [fabrication.sheets] rotations = true")
    areas = np.array([float(p.area_mm2) for p in panels])
    order = np.argsort(-areas, kind="stable")
    radii = np.array([_inscribed_radius(options[0].hull) for options in orientations])
    ahead = radii[order]
    ahead = np.array([ahead[j:j + FREE_RADIUS_LOOKAHEAD].min() for j in range(n)]) if n else ahead
    rebuild = np.empty(n)
    rebuild[order] = FREE_RADIUS_SHARE * ahead
    sheets: list[_Sheet] = []
    members: list[list[int]] = []
    placements: list[Placement | None] = [None] * n
    sheet_area = settings.width_mm * settings.height_mm
    for i in order:
        placed = False
        for k, sheet in enumerate(sheets):
            # skip sheets that just refused a panel of (about) this size or have no area left
            if areas[i] >= 0.98 * sheet.failed_area or sheet.area + areas[i] > sheet_area:
                continue
            if _place(sheet, k, i, orientations[i], settings, placements, radii[i], rebuild[i], tight):
                members[k].append(int(i))
                sheet.area += areas[i]
                sheet.failed_area = math.inf
                placed = True
                break
            sheet.failed_area = min(sheet.failed_area, areas[i])
        if not placed:
            sheets.append(_Sheet())
            members.append([int(i)])
            k = len(sheets) - 1
            if not _place(sheets[k], k, i, orientations[i], settings, placements,  # pragma: no cover
                          radii[i], rebuild[i], tight):
                raise InputError(f"panel {panels[i].id} does not fit on an empty sheet")
            sheets[k].area += areas[i]
    per_sheet = [sheet.area / sheet_area for sheet in sheets]
    utilisation = float(areas.sum() / (len(sheets) * sheet_area)) if sheets else 0.0
    sheet_of = {panels[p.panel].id: sheet_id(p.sheet) for p in placements}
    return SheetNesting(placements=list(placements), sheets=members, utilisation=utilisation,
                        sheet_utilisation=per_sheet, settings=settings, sheet_of=sheet_of)


def _with_grain(panels: list, members: list[int]) -> bool:
    """Whether any of the panels ``members`` on a sheet keeps a grain (Panel.grain_deg)."""
    return any(getattr(panels[i], "grain_deg", None) is not None for i in members)


def write_sheet_dxfs(nesting: SheetNesting, panels: list["Panel"], folder: str | os.PathLike,
                     settings: "PanelSettings | None" = None, *, first_number: int = 1) -> list[Path]:
    """Write ``folder/SHEET01.dxf``... : sheet outline on NOTES, parts on CUT, panel ids on
    ENGRAVE, drill holes on DRILL (mm, $INSUNITS 4). ``settings``: PanelSettings for the
    hole diameter (default: PanelSettings()); ``first_number``: the first sheet's number."""
    from fabrication.panels import PanelSettings, add_panel

    settings = settings or PanelSettings()
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    sheet = nesting.settings
    paths = []
    for k, members in enumerate(nesting.sheets):
        doc = new_document(cutting_layers(drill=settings.hole_diameter_mm > 0))
        msp = doc.modelspace()
        msp.add_lwpolyline([(0, 0), (sheet.width_mm, 0), (sheet.width_mm, sheet.height_mm), (0, sheet.height_mm)],
                           close=True, dxfattribs={"layer": "NOTES"})
        name = sheet_id(first_number - 1 + k)
        grain = "  grain along x" if _with_grain(panels, members) else ""
        msp.add_text(f"{name}  {sheet.width_mm:g} x {sheet.height_mm:g} mm  {len(members)} parts  "
                     f"utilisation {100 * nesting.sheet_utilisation[k]:.1f} %{grain}",
                     height=5.0, dxfattribs={"layer": "NOTES", "insert": (0.0, -10.0)})
        for i in members:
            p = nesting.placements[i]
            add_panel(msp, panels[i], offset=(p.dx, p.dy), angle_deg=p.angle_deg, settings=settings)
        target = folder / f"{name}.dxf"
        save_dxf(doc, target)
        paths.append(target)
    return paths


def write_sheets_picture(nesting: SheetNesting, panels: list["Panel"], path: str | os.PathLike,
                         max_sheets: int | None = None, *, first_number: int = 1) -> Path:
    """A PNG contact sheet of the sheets (all, or the first ``max_sheets``) with their parts and ids."""
    return write_contact_sheet([(nesting, panels, first_number)], path, max_sheets=max_sheets)


#: The contact sheet's resolution (dots per inch).
CONTACT_SHEET_DPI = 110


def label_place(outline: np.ndarray, size_pt: tuple[float, float], px_per_mm: float,
                dpi: float) -> tuple[float, float, float] | None:
    """(x, y, turn): where a label of ``size_pt`` (width, height in points) drawn at ``px_per_mm``
    pixels per mm goes on the part of ``outline`` ((k, 2) mm): centred on the part's centroid,
    level where its box lies inside the part, else upright (turn 90 degrees, a slender part) where
    that does; None where neither does."""
    part = shapely.Polygon(outline)
    centre = part.centroid
    half_w, half_h = 0.5 * size_pt[0] * dpi / 72.0 / px_per_mm, 0.5 * size_pt[1] * dpi / 72.0 / px_per_mm
    for turn, (dx, dy) in ((0.0, (half_w, half_h)), (90.0, (half_h, half_w))):
        if part.contains(box(centre.x - dx, centre.y - dy, centre.x + dx, centre.y + dy)):
            return float(centre.x), float(centre.y), turn
    return None


def write_contact_sheet(groups: list[tuple[SheetNesting, list["Panel"], int]], path: str | os.PathLike, *,
                        max_sheets: int | None = None, columns: int = 4) -> Path:
    """A PNG contact sheet of every sheet of every stock size (``groups``: nesting, its panels and
    the number of its first sheet), ``columns`` sheets a row, each with its parts, its use and the
    ids of the parts large enough on the picture to hold theirs (``label_place``; the title says
    how many are only in the sheet's DXF)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import PolyCollection
    from matplotlib.figure import Figure
    from matplotlib.font_manager import FontProperties
    from matplotlib.patches import Rectangle
    from matplotlib.textpath import TextToPath

    sheets = [(nesting, panels, first + k, k) for nesting, panels, first in groups for k in range(nesting.n_sheets)]
    sheets = sheets[:max_sheets] if max_sheets is not None else sheets
    count = max(len(sheets), 1)
    cols = min(columns, count)
    rows = -(-count // cols)
    aspect = max((n.settings.height_mm / n.settings.width_mm for n, *_ in sheets), default=0.5)
    cell = 13.0 / cols
    fig = Figure(figsize=(cell * cols, rows * (cell * aspect + 0.45) + 0.3), dpi=CONTACT_SHEET_DPI)
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    label_size = max(3.0, min(6.0, 24.0 / cols))
    font, measure = FontProperties(size=label_size), TextToPath()
    for ax in axes:
        ax.set_axis_off()
    for ax, (nesting, panels, number, k) in zip(axes, sheets):
        s = nesting.settings
        ax.add_patch(Rectangle((0, 0), s.width_mm, s.height_mm, fill=False, color="k", lw=0.6))
        outlines = [nesting.placed_outline(i, panels[i].outline_mm) for i in nesting.sheets[k]]
        # one collection for the sheet's parts (a patch per part took most of a large roof's picture)
        ax.add_collection(PolyCollection(outlines, facecolors="#9ecae1", edgecolors="#08519c", linewidths=0.4))
        ax.set_xlim(-10, s.width_mm + 10)
        ax.set_ylim(-10, s.height_mm + 10)
        ax.set_aspect("equal")
        # the scale before the layout, which only enlarges the axes: a label that fits now fits then
        ax.apply_aspect()
        px_per_mm = ax.get_window_extent().width / np.ptp(ax.get_xlim())
        hidden = 0
        for i, outline in zip(nesting.sheets[k], outlines):
            width, height, _ = measure.get_text_width_height_descent(panels[i].id, font, ismath=False)
            place = label_place(outline, (width, height), px_per_mm, CONTACT_SHEET_DPI)
            if place is not None:
                ax.text(place[0], place[1], panels[i].id, fontsize=label_size, ha="center", va="center",
                        rotation=place[2], rotation_mode="anchor", in_layout=False)
            else:
                hidden += 1
        grain = ", grain \u2192" if _with_grain(panels, nesting.sheets[k]) else ""
        small = f"\n{hidden} of its ids too small to show here: see its DXF" if hidden else ""
        ax.set_title(f"{sheet_id(number - 1)} ({s.width_mm:g} x {s.height_mm:g} mm): {len(nesting.sheets[k])} parts, "
                     f"{100 * nesting.sheet_utilisation[k]:.0f} % used{grain}{small}",
                     fontsize=max(5.0, min(9.0, 30.0 / cols)))
    fig.tight_layout()
    return save_figure_png(fig, path, dpi=CONTACT_SHEET_DPI)
