"""Joint solids, one per node, built with build123d and OCP (mm).

Socket joint (3D printing): a cylindrical hub along the node axis (surface normal) with the
node id engraved on its top face, one sleeve per beam (bore = beam size + 2 clearance, a wall
around it, a pin hole across it along the node axis); the bore starts at the set-back where neighbouring bores keep
the least wall. Steel joint (full size): a hub tube along the node axis with one fin plate per
beam, in the plane of the beam and the axis, with a bolt hole. Files: joints/J0001.step (the
exact solid named J0001, without the engraved id, points to 1e-8 mm), joints/J0001.stl (sockets
only, the part to print: engraved, watertight, 0.05 mm chord; a steel node is cut and welded from
its STEP and drawing, so it has none and its report holds its box, ``box_mm``, for the clash
check instead), joints/joints.step (all, named; on request and under 30 MB). Joints that are the
same part but for the id are named by ``same_joints``.

Speed (issue 6): a socket joint is one fuse (hub and sleeves) and one cut (bores and pin holes)
in OCP, one joint per core; the id is written between the sleeves and engraved by building the
pockets' faces into the hub's top face (fabrication.engraving) where the label is clear of bores,
pin holes and the hub's rim by the least wall and no sleeve rises through the face over it, else
by a boolean cut as before. Workers write each joint's files (and its entities for joints.step,
fabrication.step_assembly); the parent streams them into the combined file and is free for other
work meanwhile (JointsInBackground). Joints that are the same part go to one worker, which
builds the first and turns its blank onto the others, each then engraved with its own id and
checked as any joint (``turned_copy``; half the booleans of the symmetric mock-up). Each joint's
report records its seconds (``seconds``).
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal, NamedTuple

import numpy as np

from engine.errors import FabricationError
from engine.mesh import PolyMesh

from .files import atomic_path, compact_step_points, stamp_step
from .ids import joint_id
from .settings import check_ranges
from .step_assembly import StepAssemblyWriter, step_part, write_step_part
from .workers import StepOutcome, exit_with_parent, run_steps

__all__ = ["JointKind", "JointSettings", "JointGeometry", "joint_geometry", "joint_setback_mm", "mirrored_copy",
           "geometry_setback_mm", "joint_hub_radius_mm", "joint_sleeve_mm", "smallest_angle", "build_joint",
           "build_joint_and_blank", "build_joints", "same_joints", "JointsInBackground", "joint_name",
           "copy_placements", "joint_hub_height_mm", "geometry_hub_height_mm", "joint_plate_height_mm",
           "knife_plate_height_mm",
           "joint_reach_mm", "cylinder_reach_mm", "JointParts", "joint_parts", "EndSlots", "fin_plate_slots"]

ENGRAVE_DEPTH_MM = 0.6
#: The printed joint's STL: largest distance between a triangle and the surface (mm) and largest
#: angle between neighbouring triangles (rad); see docs/decisions.md.
STL_CHORD_MM = 0.05
STL_ANGLE_RAD = 0.5
#: Largest relative difference between the STL's volume and the solid's for a joint that is ok.
STL_VOLUME_TOLERANCE = 0.005
#: joints.step (every joint in one file) is kept only under this size, bytes (issue 17).
JOINTS_STEP_LIMIT_BYTES = 30_000_000
LABEL_MARGIN_MM = 0.5  # between the label and a sleeve rising through the hub's top face
#: Steel joint: hub radius and fin plate length inside the slotted tube, per beam outer size.
STEEL_HUB_RADIUS = 0.75
STEEL_PLATE_ENGAGEMENT = 1.0
#: A steel node's hub is this many times its fin plates' height tall.
HUB_PER_PLATE_HEIGHT = 1.25
#: A knife plate slotted into a solid rectangular (timber) beam: its height per the beam's depth,
#: leaving a fifth of the depth of wood above and below it for the dowels' edge distance.
KNIFE_PLATE_DEPTH = 0.6


#: Printed sockets (small tubes) or steel hub nodes with fin plates.
JointKind = Literal["socket", "steel"]


@dataclass(frozen=True, kw_only=True)
class JointSettings:
    """Dimensions in mm, all positive but the clearance (zero or more). hub_radius_mm /
    sleeve_length_mm None: derived from the beam size. plate_height_mm: a steel node's fin plates'
    height along its axis; None: twice the beam size, plates through both walls of a slotted tube;
    a solid rectangular (timber) beam's knife plates stay within its depth (``knife_plate_height_mm``),
    set from the section by the fabrication stage."""

    kind: JointKind = "socket"
    clearance_mm: float = 0.3
    wall_mm: float = 2.0
    min_wall_mm: float = 1.5
    pin_hole_mm: float = 3.0
    engrave: bool = True
    hub_radius_mm: float | None = None
    sleeve_length_mm: float | None = None
    plate_thickness_mm: float = 10.0
    bolt_hole_mm: float = 18.0
    plate_height_mm: float | None = None

    def __post_init__(self) -> None:
        check_ranges(self, "joint", positive=("wall_mm", "min_wall_mm", "pin_hole_mm", "hub_radius_mm",
                                              "sleeve_length_mm", "plate_thickness_mm", "bolt_hole_mm",
                                              "plate_height_mm"),
                     zero_or_positive=("clearance_mm",))


@dataclass(frozen=True, kw_only=True)
class JointGeometry:
    """What a joint needs, in mm and unit vectors: position, beam directions (k,3), axis (3,), the
    largest outer size of its beams (the hub's and the set-back's size), and each beam's own outer
    size (k,) for its socket (None: every beam is beam_size_mm)."""

    node: int
    position_mm: np.ndarray
    directions: np.ndarray
    axis: np.ndarray
    beam_size_mm: float
    beam_sizes_mm: np.ndarray | None = None

    @property
    def sizes_mm(self) -> np.ndarray:
        """(k,) outer size of each beam at this joint."""
        if self.beam_sizes_mm is None:
            return np.full(len(self.directions), float(self.beam_size_mm))
        return np.asarray(self.beam_sizes_mm, dtype=float)


def joint_name(node: int) -> str:
    return joint_id(node)


def smallest_angle(directions: np.ndarray) -> float:
    """Smallest angle (radians) between two of a node's unit beam directions (k,3); pi for one beam."""
    if len(directions) < 2:
        return np.pi
    cosine = np.clip(directions @ directions.T, -1.0, 1.0)
    np.fill_diagonal(cosine, -1.0)
    return float(np.arccos(cosine.max()))


def joint_hub_radius_mm(settings: JointSettings, beam_size_mm: float) -> float:
    """Radius of the joint's hub, mm: the setting, else derived from the beam size."""
    if settings.hub_radius_mm is not None:
        return float(settings.hub_radius_mm)
    if settings.kind == "steel":
        return STEEL_HUB_RADIUS * beam_size_mm
    return 1.5 * (0.5 * beam_size_mm + settings.clearance_mm + settings.wall_mm)


def joint_sleeve_mm(settings: JointSettings, beam_size_mm: float) -> float:
    """How far the joint reaches into a beam past its end, mm: the socket's sleeve, or the steel
    joint's fin plate inside the slotted tube."""
    if settings.sleeve_length_mm is not None:
        return float(settings.sleeve_length_mm)
    return (STEEL_PLATE_ENGAGEMENT if settings.kind == "steel" else 2.0) * beam_size_mm


def joint_setback_mm(settings: JointSettings, beam_size_mm: float,
                     smallest_angle_rad: float | np.ndarray = 2 * np.pi / 3,
                     rise: float | np.ndarray = 0.0) -> float | np.ndarray:
    """Distance from the node to where a beam ends (the socket's bore start, the steel tube's end), mm:
    outside the hub, and far enough that two beams at the smallest angle keep apart (sockets: the
    least wall between two bores; steel: 5 mm between two tubes). Vectorised over the angles and rises.
    ``rise``: the largest |sine| of a beam's angle to the plane square to the node's axis; a steel
    node's tube that rises so clears the hub with the edge of its end that leans towards the axis
    (half the beam size times the rise nearer the axis, the end's centre the cosine as far out)."""
    half = np.maximum(np.sin(0.5 * np.asarray(smallest_angle_rad, dtype=float)), 0.05)
    hub = joint_hub_radius_mm(settings, beam_size_mm)
    if settings.kind == "steel":
        rise = np.minimum(np.abs(np.asarray(rise, dtype=float)), 0.95)
        clear_hub = (hub + 5.0 + 0.5 * beam_size_mm * rise) / np.sqrt(1.0 - rise * rise)
        setback = np.maximum(clear_hub, (0.5 * beam_size_mm + 2.5) / half)
    else:
        bore = 0.5 * beam_size_mm + settings.clearance_mm
        setback = np.maximum((2 * bore + settings.min_wall_mm) / (2 * half), 0.8 * hub)
    return float(setback) if setback.ndim == 0 else setback


def geometry_setback_mm(settings: JointSettings, geometry: JointGeometry) -> float:
    """``joint_setback_mm`` of a joint: at its beams' smallest angle and, for a steel node, clear of
    the hub for its steepest beam (``rise``)."""
    rise = float(np.abs(geometry.directions @ geometry.axis).max()) if len(geometry.directions) else 0.0
    return float(joint_setback_mm(settings, geometry.beam_size_mm, smallest_angle(geometry.directions), rise))


def joint_plate_height_mm(settings: JointSettings, beam_size_mm: float) -> float:
    """A steel node's fin plates' height along its axis, mm: the setting, else twice the beam size
    (through both walls of the slotted tube and standing out of it)."""
    if settings.plate_height_mm is not None:
        return float(settings.plate_height_mm)
    return 2.0 * beam_size_mm


def knife_plate_height_mm(depth_mm: float) -> float:
    """The height of a knife plate slotted into a solid rectangular beam ``depth_mm`` deep, mm."""
    return KNIFE_PLATE_DEPTH * float(depth_mm)


def joint_hub_height_mm(settings: JointSettings, beam_size_mm: float) -> float:
    """Height of the joint's hub along its axis, mm: taller than a printed socket's sleeve (so that
    the hub's top and the sleeves have no tangent faces), HUB_PER_PLATE_HEIGHT times a steel node's
    fin plates' (2.5 beam sizes for plates through a tube)."""
    if settings.kind == "steel":
        return HUB_PER_PLATE_HEIGHT * joint_plate_height_mm(settings, beam_size_mm)
    return 2.0 * (0.5 * beam_size_mm + settings.clearance_mm + settings.wall_mm) + 1.0


#: A printed socket's hub is made taller so that each sleeve rising out of the plane square to its
#: axis by up to SLEEVE_CONTAINED_DEG stays this far (mm) under the hub's top and bottom faces within
#: the hub's radius. A sleeve that met the top face at a grazing angle near the rim (a 30 mm rod's,
#: rising 1.6 degrees, 0.2 mm through a hub 0.5 mm over a flat sleeve) was lost by OCCT's fuse, and
#: the joint came out in four solids. A steeper sleeve crosses the face at an angle the booleans take.
SLEEVE_HUB_CLEARANCE_MM = 0.5
SLEEVE_CONTAINED_DEG = 20.0


def geometry_hub_height_mm(settings: JointSettings, geometry: JointGeometry) -> float:
    """Height of a joint's hub along its axis, mm: ``joint_hub_height_mm``, and for printed sockets
    at least what keeps each sleeve rising up to SLEEVE_CONTAINED_DEG inside the hub, with
    SLEEVE_HUB_CLEARANCE_MM to spare, as far out as the hub's radius."""
    height = joint_hub_height_mm(settings, geometry.beam_size_mm)
    if settings.kind == "steel" or not len(geometry.directions):
        return height
    radius = joint_hub_radius_mm(settings, geometry.beam_size_mm)
    sine = np.abs(geometry.directions @ geometry.axis)
    contained = sine <= np.sin(np.radians(SLEEVE_CONTAINED_DEG))
    if not contained.any():
        return height
    sine = sine[contained]
    cosine = np.sqrt(1.0 - sine * sine)
    outer = 0.5 * geometry.sizes_mm[contained] + settings.clearance_mm + settings.wall_mm
    # the top line of a sleeve leaves the hub's radius (R) where s cos - outer sin = R, at the height
    # s sin + outer cos
    top = (radius + outer * sine) * sine / cosine + outer * cosine
    return float(max(height, 2.0 * (top.max() + SLEEVE_HUB_CLEARANCE_MM)))


def cylinder_reach_mm(start: float, end: float, axis_along: float, radius: float) -> float:
    """How far a cylinder reaches along a unit direction: its end centres at ``start`` and ``end``
    along it, its axis at cosine ``axis_along`` to it."""
    return max(start, end) + radius * math.sqrt(max(0.0, 1.0 - axis_along * axis_along))


def joint_reach_mm(geometry: JointGeometry, settings: JointSettings, direction: np.ndarray) -> float | np.ndarray:
    """How far the joint's solid reaches from its node along the unit ``direction`` (mm): its hub and
    its sleeves (printed sockets) or fin plates (steel), with the dimensions build_joint_and_blank
    gives them. What a panel resting on the joint clears. ``direction`` (3,) gives a float; (m, 3)
    directions give (m,) reaches."""
    n = np.asarray(direction, dtype=float)
    many = n.ndim == 2
    n = np.atleast_2d(n)
    size = geometry.beam_size_mm
    hub_radius, height = joint_hub_radius_mm(settings, size), geometry_hub_height_mm(settings, geometry)
    along = n @ geometry.axis
    # the hub: a cylinder from -height / 2 to height / 2 along the axis (cylinder_reach_mm)
    reach = 0.5 * height * np.abs(along) + hub_radius * np.sqrt(np.maximum(0.0, 1.0 - along * along))
    d = geometry.directions
    if len(d):
        setback = geometry_setback_mm(settings, geometry)
        rise = n @ d.T  # (m, k)
        if settings.kind == "steel":
            side = _perpendiculars(d, geometry.axis)
            up = np.cross(d, side)
            end = setback + joint_sleeve_mm(settings, size)
            plate = joint_plate_height_mm(settings, size)
            # each plate: its end along the beam, half its height across, its thickness either side
            plates = (np.maximum(0.5 * hub_radius * rise, end * rise) + 0.5 * plate * np.abs(n @ up.T)
                      + settings.plate_thickness_mm * np.abs(n @ side.T))
        else:
            own = geometry.sizes_mm
            outer = 0.5 * own + settings.clearance_mm + settings.wall_mm
            ends = np.array([setback + joint_sleeve_mm(settings, float(s)) for s in own]) * rise
            # each sleeve: a cylinder from the node to its end (cylinder_reach_mm)
            plates = np.maximum(0.0, ends) + outer * np.sqrt(np.maximum(0.0, 1.0 - rise * rise))
        reach = np.maximum(reach, plates.max(axis=1))
    return reach if many else float(reach[0])


@dataclass(frozen=True)
class JointParts:
    """A joint's solid as simple parts relative to its node (mm), with the dimensions
    build_joint_and_blank gives them: ``cylinders`` (c, 8) rows of base (3), unit axis (3), length,
    radius (the hub, and a printed socket's sleeves, bores not taken out) and ``boxes`` (q, 12) rows
    of origin (3), unit along (3), unit up (3), length along, height across up, thickness through
    (a steel node's fin plates, centred on the line from ``origin`` along ``along``)."""

    cylinders: np.ndarray
    boxes: np.ndarray


def joint_parts(geometry: JointGeometry, settings: JointSettings) -> JointParts:
    """The joint's hub and its sleeves or fin plates as a JointParts (what a tube must clear)."""
    size = geometry.beam_size_mm
    axis = geometry.axis
    hub_radius = joint_hub_radius_mm(settings, size)
    setback = geometry_setback_mm(settings, geometry)
    cylinders, boxes = [], []
    if settings.kind == "steel":
        height = joint_hub_height_mm(settings, size)
        start, sleeve = 0.5 * hub_radius, joint_sleeve_mm(settings, size)
        for d in geometry.directions:
            up = np.cross(d, _perpendicular(d, axis))
            boxes.append([*(start * d), *d, *up, setback + sleeve - start, joint_plate_height_mm(settings, size),
                          settings.plate_thickness_mm])
    else:
        height = geometry_hub_height_mm(settings, geometry)
        for d, own in zip(geometry.directions, geometry.sizes_mm):
            outer = 0.5 * own + settings.clearance_mm + settings.wall_mm
            cylinders.append([0.0, 0.0, 0.0, *d, setback + joint_sleeve_mm(settings, own), outer])
    cylinders.insert(0, [*(-0.5 * height * axis), *axis, height, hub_radius])
    return JointParts(cylinders=np.array(cylinders, dtype=float).reshape(-1, 8),
                      boxes=np.array(boxes, dtype=float).reshape(-1, 12))


@dataclass(frozen=True)
class EndSlots:
    """The slots a steel node's fin plates need at each end of each beam (mm): ``sides`` (b, 2, 3)
    the unit direction across each slot (the plate's normal), ``lengths`` (b, 2) how far each runs
    into the tube from its end, ``width`` across it; ends [start node, end node] as the beam's.
    ``height``: the slot's height along the beam's up, None through the whole section (a plate
    through a tube), else a knife plate's within a solid beam."""

    sides: np.ndarray
    lengths: np.ndarray
    width: float
    height: float | None = None

    def fit(self, beam: int, cut_length_mm: float) -> bool:
        """Whether beam ``beam``'s two slots fit within its cut length (else it is left square-cut)."""
        return float(self.lengths[beam].sum()) < cut_length_mm


def fin_plate_slots(polymesh: PolyMesh, geometries: list[JointGeometry], settings: JointSettings) -> EndSlots:
    """The end slots of every beam at steel nodes, as build_joint_and_blank places the fin plates:
    each plate runs along its beam, across the node's axis, and reaches its sleeve length into the
    tube; the slot is the plate's thickness and a clearance each side wide, and a clearance longer;
    where the plates' height is set (knife plates) a clearance above and below them high."""
    by_node = {g.node: g for g in geometries}
    e = polymesh.edges
    sides = np.zeros((len(e), 2, 3))
    lengths = np.zeros((len(e), 2))
    for k, (a, b) in enumerate(e):
        for end, (here, there) in enumerate(((a, b), (b, a))):
            g = by_node[int(here)]
            d = polymesh.nodes[there] - polymesh.nodes[here]
            d = d / np.linalg.norm(d)
            sides[k, end] = _perpendicular(d, g.axis)
            lengths[k, end] = joint_sleeve_mm(settings, g.beam_size_mm) + settings.clearance_mm
    height = None if settings.plate_height_mm is None else settings.plate_height_mm + 2 * settings.clearance_mm
    return EndSlots(sides=sides, lengths=lengths, width=settings.plate_thickness_mm + 2 * settings.clearance_mm,
                    height=height)


def joint_geometry(polymesh: PolyMesh, normals: np.ndarray, beam_size_mm: float | np.ndarray) -> list[JointGeometry]:
    """Per node: its beam directions and axis (mm positions); ``beam_size_mm`` one outer size for
    every beam, or one per beam (b,) where the sections were sized."""
    edges = polymesh.edges
    per_beam = np.ndim(beam_size_mm) > 0
    sizes = np.broadcast_to(np.asarray(beam_size_mm, dtype=float), (len(edges),))
    out = []
    incident: list[list[int]] = [[] for _ in range(polymesh.n_nodes)]
    beams_at: list[list[int]] = [[] for _ in range(polymesh.n_nodes)]
    for b, (i, j) in enumerate(edges):
        incident[i].append(j)
        incident[j].append(i)
        beams_at[i].append(b)
        beams_at[j].append(b)
    for node in range(polymesh.n_nodes):
        if not incident[node]:
            continue
        others = np.array(incident[node], dtype=int)
        d = polymesh.nodes[others] - polymesh.nodes[node]
        d /= np.linalg.norm(d, axis=1)[:, None]
        own = sizes[beams_at[node]]
        out.append(JointGeometry(node=node, position_mm=1000 * polymesh.nodes[node], directions=d,
                                 axis=np.asarray(normals[node], float) / np.linalg.norm(normals[node]),
                                 beam_size_mm=float(own.max()),
                                 beam_sizes_mm=own.copy() if per_beam and np.ptp(own) > 0 else None))
    return out


def _beams_about_axis(geometry: JointGeometry) -> np.ndarray:
    """(k, 3) per beam, in the order of their azimuths about the joint's axis: the beam's
    elevation (its direction's component along the axis), the azimuth on to the next beam (rad)
    and its outer size (mm). Unchanged by rotating the joint."""
    azimuth = _azimuths(geometry)
    order = np.argsort(azimuth, kind="stable")
    gaps = np.mod(np.diff(np.r_[azimuth[order], azimuth[order][0] + 2 * np.pi]), 2 * np.pi)
    return np.column_stack([geometry.directions[order] @ geometry.axis, gaps, geometry.sizes_mm[order]])


def _azimuths(geometry: JointGeometry) -> np.ndarray:
    """(k,) each beam's azimuth about the joint's axis, in [0, 2 pi), from an axis-made frame."""
    axis = geometry.axis
    e1 = np.cross([0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0], axis)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    d = geometry.directions
    return np.mod(np.arctan2(d @ e2, d @ e1), 2 * np.pi)


def _near_joints(described: list[np.ndarray], scale: np.ndarray) -> list[set[int]]:
    """For each joint, the others of as many beams whose columns, each sorted, differ by at most
    ``scale`` (elevation, gap, size): a superset of the joints it can be a turned copy of."""
    from scipy.spatial import cKDTree

    near: list[set[int]] = [set() for _ in described]
    by_count: dict[int, list[int]] = {}
    for k, d in enumerate(described):
        by_count.setdefault(len(d), []).append(k)
    for count, members in by_count.items():
        if count == 0 or len(members) < 2:
            continue
        features = np.array([(np.sort(described[k], axis=0) / scale).ravel() for k in members])
        for i, j in cKDTree(features).query_pairs(r=1.0 + 1e-6, p=np.inf):
            near[members[i]].add(members[j])
            near[members[j]].add(members[i])
    return near


#: Two joints are the same part where their beams' angles agree within SAME_RAD (0.05 mm at a
#: sleeve's end) and their sizes within SAME_MM (same_joints; the mirror families likewise).
SAME_RAD, SAME_MM = 1e-3, 1e-3


def _groups_of_same(geometries: list[JointGeometry], tolerance_rad: float = SAME_RAD,
                    tolerance_mm: float = SAME_MM) -> list[list[tuple[int, int]]]:
    """Every joint in a group of the joints that are the same part (see ``same_joints``), in the
    order the groups were opened: (index, shift) pairs, shift 0 for the first, else the turn of the
    member's beams (in azimuth order) that matches the first's."""
    described = [_beams_about_axis(g) for g in geometries]
    scale = np.array([tolerance_rad, tolerance_rad, tolerance_mm])

    def shift_onto(a: np.ndarray, b: np.ndarray) -> int | None:
        if len(a) != len(b):
            return None
        return next((shift for shift in range(len(b)) if np.all(np.abs(a - np.roll(b, shift, axis=0)) <= scale)),
                    None)

    # Only joints whose sorted columns agree within the tolerances can be the same (sorting moves no
    # value further than the turn that matches them did), so each joint is compared with those
    # neighbours only, found in a k-d tree; the groups are those of comparing every pair in order.
    near = _near_joints(described, scale)
    groups: list[list[tuple[int, int]]] = []
    group_of: dict[int, int] = {}  # first member -> its group
    for k, d in enumerate(described):
        for first in sorted(j for j in near[k] if j in group_of):  # groups in the order they were opened
            shift = shift_onto(described[first], d)
            if shift is not None:
                groups[group_of[first]].append((k, shift))
                break
        else:
            group_of[k] = len(groups)
            groups.append([(k, 0)])
    return groups


def same_joints(geometries: list[JointGeometry], tolerance_rad: float = SAME_RAD,
                tolerance_mm: float = SAME_MM) -> list[list[str]]:
    """Groups (two or more ids) of joints that are the same part but for the engraved id: the same
    beams (sizes within ``tolerance_mm``) at the same angles about the axis and to it (within
    ``tolerance_rad``; 1e-3 rad is 0.05 mm at a sleeve's end), one turned onto the other. A
    mirror image is not the same part. The hub, set-back, bores and pin holes follow from these."""
    return [[joint_name(geometries[k].node) for k, _ in group]
            for group in _groups_of_same(geometries, tolerance_rad, tolerance_mm) if len(group) > 1]


def copy_placements(geometries: list[JointGeometry], reports: list[dict],
                    groups: list | None = None) -> dict[str, tuple[str, np.ndarray]]:
    """joint id -> (the id of the joint whose solid it is a copy of, the 4 x 4 transform in mm taking
    that joint's placed solid onto this one's) for every joint that the workers built as a turned
    copy (``copy_of`` in its report); the rotation is ``turned_copy``'s, found again here.
    ``groups``: the groups of equal joints the workers were given (JointsInBackground.groups),
    else found again."""
    copies = {r["id"]: r["copy_of"] for r in reports if r.get("copy_of")}
    by_name = {joint_name(g.node): g for g in geometries}
    placements: dict[str, tuple[str, np.ndarray]] = {}
    for group in _groups_of_same(geometries) if groups is None else groups:
        first = geometries[group[0][0]]
        for k, shift in group[1:]:
            name = joint_name(geometries[k].node)
            if copies.get(name) != joint_name(first.node):
                continue
            turned = turned_copy(first, by_name[name], shift)
            if turned is None:
                continue
            rotation = turned[1]
            transform = np.eye(4)
            transform[:3, :3] = rotation
            transform[:3, 3] = np.asarray(geometries[k].position_mm) - rotation @ np.asarray(first.position_mm)
            placements[name] = (joint_name(first.node), transform)
    return placements


def _azimuth_order(geometry: JointGeometry) -> np.ndarray:
    """The beams in the order of their azimuths about the joint's axis (as _beams_about_axis)."""
    return np.argsort(_azimuths(geometry), kind="stable")


def turned_copy(first: JointGeometry, other: JointGeometry, shift: int,
                tolerance_rad: float = 2e-3) -> tuple[JointGeometry, np.ndarray] | None:
    """(``first`` turned onto ``other``, the rotation): ``first``'s beams and axis turned by the
    rotation that best maps them onto ``other``'s (its beams matched in azimuth order rolled by
    ``shift``, as ``same_joints`` found them), at ``other``'s node and position. None where no
    rotation brings every beam and the axis within ``tolerance_rad`` (a mirror image, say)."""
    k = len(first.directions)
    a_order, b_order = _azimuth_order(first), _azimuth_order(other)
    matched = b_order[(np.arange(k) - shift) % k]
    source = np.vstack([first.directions[a_order], first.axis])
    target = np.vstack([other.directions[matched], other.axis])
    rotation = _orthogonal_fit(source, target, reflection=False)
    turned = source @ rotation.T
    if np.max(np.linalg.norm(turned - target, axis=1)) > tolerance_rad:  # a mirror image, say
        return None
    return _carried(first, other, a_order, matched, turned), rotation


def _orthogonal_fit(source: np.ndarray, target: np.ndarray, *, reflection: bool) -> np.ndarray:
    """(3, 3) the rotation (with ``reflection``, the reflection) that best maps the rows of
    ``source`` onto those of ``target`` (Kabsch's least squares)."""
    u, _, vt = np.linalg.svd(target.T @ source)
    sign = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1.0, 1.0, -sign if reflection else sign]) @ vt


def _carried(first: JointGeometry, other: JointGeometry, a_order: np.ndarray, matched: np.ndarray,
             mapped: np.ndarray) -> JointGeometry:
    """``first`` at ``other``'s node and position, its beams (in ``a_order``) and axis now ``mapped``
    ((k + 1, 3), the axis last), beam ``a_order[i]`` taking the place of ``other``'s ``matched[i]``."""
    k = len(first.directions)
    directions = np.empty_like(first.directions)
    directions[matched] = mapped[:k]
    sizes = None
    if first.beam_sizes_mm is not None:
        sizes = np.empty(k)
        sizes[matched] = np.asarray(first.beam_sizes_mm, dtype=float)[a_order]
    return JointGeometry(node=other.node, position_mm=other.position_mm, directions=directions, axis=mapped[k],
                         beam_size_mm=first.beam_size_mm, beam_sizes_mm=sizes)


def mirrored_copy(first: JointGeometry, other: JointGeometry,
                  tolerance_rad: float = 2e-3) -> tuple[JointGeometry, np.ndarray] | None:
    """(``first`` mirrored onto ``other``, the reflection (3, 3), determinant -1): as
    ``turned_copy``, where ``other`` is a mirror image of ``first`` (a symmetric grid's joints on
    either side of a symmetry plane), its beams matched in reverse azimuth order and every size
    the same. None where no reflection brings every beam and the axis within ``tolerance_rad``."""
    k = len(first.directions)
    if len(other.directions) != k or k == 0:
        return None
    a_order = _azimuth_order(first)
    reverse = _azimuth_order(other)[::-1]
    source = np.vstack([first.directions[a_order], first.axis])
    best = None
    for shift in range(k):
        matched = reverse[(np.arange(k) + shift) % k]
        if np.abs(other.sizes_mm[matched] - first.sizes_mm[a_order]).max() > 1e-3:
            continue
        target = np.vstack([other.directions[matched], other.axis])
        reflection = _orthogonal_fit(source, target, reflection=True)
        mapped = source @ reflection.T
        error = float(np.max(np.linalg.norm(mapped - target, axis=1)))
        if error <= tolerance_rad and (best is None or error < best[0]):
            best = (error, matched, reflection, mapped)
    if best is None:
        return None
    _, matched, reflection, mapped = best
    return _carried(first, other, a_order, matched, mapped), reflection


def _mirror_families(geometries: list[JointGeometry], groups: list[list[tuple[int, int]]]) -> list[list[int]]:
    """The groups of equal joints (``_groups_of_same``) gathered in families, as indices into
    ``groups``: each family's first group, then the groups whose first joints are mirror images of
    its first joint (``mirrored_copy``). A mirror image is another part (``same_joints``), but its
    blank need not be built again: the first's, mirrored, is the same solid."""
    firsts = [geometries[group[0][0]] for group in groups]
    near = _near_joints([_beams_about_axis(g) for g in firsts], np.array([SAME_RAD, SAME_RAD, SAME_MM]))
    families: list[list[int]] = []
    taken: set[int] = set()
    for i in range(len(groups)):
        if i in taken:
            continue
        families.append([i])
        for j in sorted(near[i]):  # a mirror image has the same sorted elevations, gaps and sizes
            if j > i and j not in taken and mirrored_copy(firsts[i], firsts[j]) is not None:
                families[-1].append(j)
                taken.add(j)
    return families


def _turned_shape(shape, rotation: np.ndarray):
    """A copy of the OCP ``shape`` turned by ``rotation`` (3, 3) about the origin (a reflection
    too: OCCT then reverses the faces' orientations, so the copy stays a solid)."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
    from OCP.gp import gp_Trsf

    trsf = gp_Trsf()
    r = rotation
    trsf.SetValues(*map(float, (r[0, 0], r[0, 1], r[0, 2], 0.0, r[1, 0], r[1, 1], r[1, 2], 0.0,
                                r[2, 0], r[2, 1], r[2, 2], 0.0)))
    return BRepBuilderAPI_Transform(shape, trsf, True).Shape()


def _perpendicular(direction: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The unit normal of a steel joint's fin plate along ``direction``: square to it and to the
    node's ``axis`` (square to a fixed axis where the two are parallel)."""
    return _perpendiculars(np.asarray(direction, dtype=float)[None, :], axis)[0]


def _perpendiculars(directions: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """``_perpendicular`` of each of the (k, 3) ``directions``."""
    d = np.asarray(directions, dtype=float)
    side = np.cross(axis, d)
    parallel = np.linalg.norm(side, axis=1) < 1e-6
    if parallel.any():
        fixed = np.where(np.abs(d[parallel, :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        side[parallel] = np.cross(fixed, d[parallel])
    return side / np.linalg.norm(side, axis=1)[:, None]


def _upright(direction: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The node axis made perpendicular to a beam: the direction of the sleeve's pin hole, so the
    hole runs through the sleeve's top and bottom (clear of the neighbouring sleeves, which lie
    about the tangent plane, drilled or screwed from above, printed without overhang)."""
    upright = axis - (axis @ direction) * direction
    if np.linalg.norm(upright) < 1e-6:
        return _perpendicular(direction, axis)
    return upright / np.linalg.norm(upright)


def _cylinder(base: np.ndarray, direction: np.ndarray, radius: float, length: float):
    """OCP solid cylinder from ``base`` along ``direction`` (unit), as build123d's Cylinder placed on
    a plane with that normal (same seam)."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    frame = gp_Ax2(gp_Pnt(*map(float, base)), gp_Dir(*map(float, direction)))
    return BRepPrimAPI_MakeCylinder(frame, float(radius), float(length)).Shape()


def _holed_plate(origin: np.ndarray, along: np.ndarray, up: np.ndarray, length: float, height: float,
                 thickness: float, hole_at: float, hole_radius: float):
    """(solid, holed) an OCP plate from ``origin`` along ``along`` (unit) for ``length``, ``height``
    across ``up`` (unit, perpendicular) and ``thickness`` through, both centred, with a round hole
    through it ``hole_at`` along, made as the prism of a face with a hole: no boolean. Where the hole
    would not lie inside the face with a millimetre to spare the plate is plain (``holed`` False)."""
    from OCP.BRepBuilderAPI import (
        BRepBuilderAPI_MakeEdge,
        BRepBuilderAPI_MakeFace,
        BRepBuilderAPI_MakePolygon,
        BRepBuilderAPI_MakeWire,
    )
    from OCP.BRepPrimAPI import BRepPrimAPI_MakePrism
    from OCP.gp import gp_Ax2, gp_Circ, gp_Dir, gp_Vec
    from OCP.TopoDS import TopoDS

    through = np.cross(along, up)
    base = np.asarray(origin, dtype=float) - 0.5 * thickness * through
    corners = [base + a * along + b * height * up for a, b in ((0, -0.5), (length, -0.5), (length, 0.5), (0, 0.5))]
    face = BRepBuilderAPI_MakeFace(BRepBuilderAPI_MakePolygon(*map(_gp_point, corners), True).Wire(), True)
    holed = hole_radius + 1.0 < min(hole_at, length - hole_at, 0.5 * height)
    if holed:
        circle = gp_Circ(gp_Ax2(_gp_point(base + hole_at * along), gp_Dir(*map(float, through))), float(hole_radius))
        wire = BRepBuilderAPI_MakeWire(BRepBuilderAPI_MakeEdge(circle).Edge()).Wire()
        face.Add(TopoDS.Wire_s(wire.Reversed()))
    # canonized: the hole's wall is a cylinder (for CAM and the checks), not an extruded circle
    return BRepPrimAPI_MakePrism(face.Face(), gp_Vec(*map(float, thickness * through)), False, True).Shape(), holed


def _boolean(kind: str, arguments: list, tools: list):
    """One OCP boolean ("fuse" or "cut") of all ``tools`` with the ``arguments``, on this core
    only (the workers use the others). Unlike build123d's, the result is not passed through
    ShapeUpgrade_UnifySameDomain: on socket joints that merges nothing (same faces, edges and
    vertices on 51 joints of a 500-node grid-shell), and where two beams are collinear (coaxial
    bores) it ran out of memory after 15 s."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut, BRepAlgoAPI_Fuse
    from OCP.TopTools import TopTools_ListOfShape

    operation = BRepAlgoAPI_Fuse() if kind == "fuse" else BRepAlgoAPI_Cut()
    for shapes, setter in ((arguments, operation.SetArguments), (tools, operation.SetTools)):
        listed = TopTools_ListOfShape()
        for shape in shapes:
            listed.Append(shape)
        setter(listed)
    operation.SetRunParallel(False)
    operation.Build()
    if not operation.IsDone():
        raise FabricationError(f"the {kind} of a joint failed")
    return operation.Shape()


#: A surface that a tool leaves on the result of a boolean: ("cylinder", point on the axis, axis
#: direction, radius) or ("plane", normal, offset along it), mm.
Mark = tuple


def _surfaces(shape) -> tuple[list, list]:
    """The cylinders (point on the axis, direction, radius) and planes (normal, offset) of the
    faces of ``shape``, mm."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.GeomAbs import GeomAbs_Cylinder, GeomAbs_Plane
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    cylinders, planes = [], []
    explorer = TopExp_Explorer(shape, TopAbs_FACE)
    while explorer.More():
        surface = BRepAdaptor_Surface(TopoDS.Face_s(explorer.Current()))
        kind = surface.GetType()
        if kind == GeomAbs_Cylinder:
            cylinder = surface.Cylinder()
            axis = cylinder.Axis()
            p, d = axis.Location(), axis.Direction()
            cylinders.append((np.array([p.X(), p.Y(), p.Z()]), np.array([d.X(), d.Y(), d.Z()]), cylinder.Radius()))
        elif kind == GeomAbs_Plane:
            axis = surface.Plane().Axis()
            p, d = axis.Location(), axis.Direction()
            normal = np.array([d.X(), d.Y(), d.Z()])
            planes.append((normal, float(normal @ [p.X(), p.Y(), p.Z()])))
        explorer.Next()
    return cylinders, planes


def _marked(shape, marks: list[Mark], tolerance_mm: float = 1e-4) -> np.ndarray:
    """(k,) whether ``shape`` has a face on each mark's surface."""
    cylinders, planes = _surfaces(shape)
    found = []
    for mark in marks:
        if mark[0] == "cylinder":
            base, direction, radius = mark[1], mark[2] / np.linalg.norm(mark[2]), mark[3]
            found.append(any(abs(r - radius) < tolerance_mm and abs(abs(d @ direction) - 1) < 1e-9
                             and np.linalg.norm(np.cross(base - p, direction)) < tolerance_mm
                             for p, d, r in cylinders))
        else:
            normal, offset = mark[1] / np.linalg.norm(mark[1]), mark[2]
            found.append(any(abs(abs(n @ normal) - 1) < 1e-9 and abs(o - np.sign(n @ normal) * offset) < tolerance_mm
                             for n, o in planes))
    return np.array(found, dtype=bool)


def _checked_boolean(kind: str, shape, tools: list, marks: list[Mark]):
    """``_boolean(kind, [shape], tools)``, checked by one surface per tool (``marks``) that its
    faces must leave on the result. OCCT's boolean of many tools at once can leave some out where
    they meet near one point (three flat sleeves of a socket joint fused into a hub of their own
    height lost two); then the tools are applied one at a time. (Reading the faces' surfaces takes
    a few milliseconds; classifying a point in each tool took 0.28 s of a 0.63 s socket.)"""
    result = _boolean(kind, [shape], tools)
    if _marked(result, marks).all():
        return result
    for tool in tools:
        shape = _boolean(kind, [shape], [tool])
    return shape


def _solids(shape) -> list:
    from .engraving import subshapes

    return subshapes(shape, "solid")


def _is_valid(shape) -> bool:
    from OCP.BRepCheck import BRepCheck_Analyzer

    return bool(BRepCheck_Analyzer(shape).IsValid())


def _segment_box_distances(a: np.ndarray, b: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """(k,) least distances between segments a[i]-b[i] and boxes [low[i], high[i]] (all (k, 3)).
    The distance is convex along a segment, so a golden-section search finds its minimum."""
    def distance(t: np.ndarray) -> np.ndarray:
        p = a + t[:, None] * (b - a)
        return np.linalg.norm(p - np.clip(p, low, high), axis=1)

    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    lo, hi = np.zeros(len(a)), np.ones(len(a))
    x1, x2 = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
    f1, f2 = distance(x1), distance(x2)
    for _ in range(60):
        left = f1 <= f2  # the minimum lies in [lo, x2]
        hi, lo = np.where(left, x2, hi), np.where(left, lo, x1)
        x1, x2 = np.where(left, hi - ratio * (hi - lo), x2), np.where(left, x1, lo + ratio * (hi - lo))
        f1, f2 = np.where(left, distance(x1), f2), np.where(left, f1, distance(x2))
    return np.minimum.reduce([f1, f2, distance(np.zeros(len(a))), distance(np.ones(len(a)))])


def _label_directions(directions: np.ndarray, axis: np.ndarray) -> list[np.ndarray]:
    """Directions on the hub's top face to write the id along, best first: the middles of the gaps
    between the sleeves seen from above, as lines through the axis (the label reaches both ways
    from the centre), widest gap first."""
    e1 = np.cross([0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0], axis)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    flat = directions - np.outer(directions @ axis, axis)
    flat = flat[np.linalg.norm(flat, axis=1) > 1e-6]
    if not len(flat):
        return [e1, e2]
    angles = np.sort(np.mod(np.arctan2(flat @ e2, flat @ e1), np.pi))
    gaps = np.diff(np.r_[angles, angles[0] + np.pi])
    middles = [angles[k] + 0.5 * gaps[k] for k in np.argsort(-gaps, kind="stable")]
    return [math.cos(m) * e1 + math.sin(m) * e2 for m in middles]


def _label_is_clear(bounds, origin, axis, x_dir, features, hub_radius: float, clearance: float) -> bool:
    """True when the label's pockets (its bounding rectangle ``bounds`` on the top face, sunk the
    engraving depth) keep ``clearance`` from the hub's rim and from every bore and pin hole, and
    no sleeve rises through the top face within LABEL_MARGIN_MM of it: then the pockets lie inside
    the top face and every other face is at least ``clearance`` away (a sleeve rising beside the
    label is more material, not a wall). ``features``: (kind, start, end, radius), kind "sleeve"
    or "hole", segments in the joint's frame; sleeves and holes are tested as capsules (the
    segment swept by a ball of the radius), which hold the cylinders."""
    y_dir = np.cross(axis, x_dir)
    x0, y0, x1, y1 = bounds
    corners = [(x, y) for x in (x0 - clearance, x1 + clearance) for y in (y0 - clearance, y1 + clearance)]
    if max(math.hypot(x, y) for x, y in corners) > hub_radius:
        return False
    frame = np.array([x_dir, y_dir, axis])
    reach = max(np.linalg.norm(end) for _, _, end, _ in features) + hub_radius
    a = np.array([frame @ (start - origin) for _, start, _, _ in features])
    b = np.array([frame @ (end - origin) for _, _, end, _ in features])
    sleeve = np.array([kind == "sleeve" for kind, _, _, _ in features])[:, None]
    m, c = LABEL_MARGIN_MM, clearance
    # holes: the pockets with the least wall around and below them; sleeves: the space above the label
    low = np.where(sleeve, [x0 - m, y0 - m, 0.0], [x0 - c, y0 - c, -ENGRAVE_DEPTH_MM - c])
    high = np.where(sleeve, [x1 + m, y1 + m, reach], [x1 + c, y1 + c, 0.0])
    radius = np.array([r for _, _, _, r in features])
    near = np.flatnonzero(_segment_box_distances(a, b, low, high) < radius)
    # a capsule reaches a radius beyond the cylinder's flat ends: decide those with the cylinders
    return all(_box_cylinder_distance(low[k], high[k], a[k], b[k], radius[k]) > 1e-6 for k in near)


def _box_cylinder_distance(low: np.ndarray, high: np.ndarray, start: np.ndarray, end: np.ndarray,
                           radius: float) -> float:
    """Least distance (OCP BRepExtrema) between the box [low, high] and the solid cylinder of
    ``radius`` from ``start`` to ``end``; 0 where they meet."""
    from OCP.BRepExtrema import BRepExtrema_DistShapeShape
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox

    size = np.maximum(high - low, 1e-6)
    box = BRepPrimAPI_MakeBox(_gp_point(low), *map(float, size)).Shape()
    length = float(np.linalg.norm(end - start))
    cylinder = _cylinder(start, (end - start) / length, radius, length)
    distance = BRepExtrema_DistShapeShape(box, cylinder)
    return float(distance.Value()) if distance.IsDone() else 0.0


def _gp_point(p: np.ndarray):
    from OCP.gp import gp_Pnt

    return gp_Pnt(*map(float, p))


def _engrave_id(solid, name: str, geometry: JointGeometry, settings: JointSettings, *, top_mm: float,
                hub_radius: float, features: list, report: dict):
    """The socket joint with its id engraved on the hub's top face (see the module docstring)."""
    from OCP.BRep import BRep_Builder
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
    from OCP.BRepClass import BRepClass_FaceClassifier
    from OCP.BRepPrimAPI import BRepPrimAPI_MakePrism
    from OCP.gp import gp_Pnt, gp_Vec
    from OCP.TopAbs import TopAbs_IN
    from OCP.TopoDS import TopoDS_Compound

    from .engraving import engrave_planar_face, glyph_bounds, planar_faces, pocket_volume, text_faces, text_placement

    axis = geometry.axis
    try:
        glyphs = text_faces(name, 0.45 * hub_radius)
    except Exception:  # noqa: BLE001 - a font problem must not stop the joints
        report["engraved"], report["engraving"] = False, "none"
        return solid
    report["engraved"] = True
    origin = axis * top_mm
    bounds = glyph_bounds(glyphs)
    solids = _solids(solid)
    candidates = planar_faces(solids[0], origin, axis) if len(solids) == 1 else []
    directions = _label_directions(geometry.directions, axis)
    clear = [x for x in directions if candidates and _label_is_clear(bounds, origin, axis, x, features, hub_radius,
                                                                     settings.min_wall_mm)]
    x_dir = (clear or directions)[0]
    if clear:
        centre = gp_Pnt(0.5 * (bounds[0] + bounds[2]), 0.5 * (bounds[1] + bounds[3]), 0.0).Transformed(
            text_placement(origin, axis, x_dir))
        for face in candidates:
            if BRepClass_FaceClassifier(face, centre, 1e-7).State() == TopAbs_IN:
                engraved = engrave_planar_face(solids[0], face, glyphs, origin, axis, x_dir, ENGRAVE_DEPTH_MM)
                if _is_valid(engraved):
                    report["engraving"], report["valid"] = "faces", True
                    report["_pocket_mm3"] = pocket_volume(glyphs, ENGRAVE_DEPTH_MM)  # the blank's less this
                    return engraved
                break
    # otherwise as before: a boolean cut of the glyphs swept the engraving depth
    report["engraving"] = "boolean"
    placement = text_placement(origin - ENGRAVE_DEPTH_MM * axis, axis, x_dir)
    tool = TopoDS_Compound()
    builder = BRep_Builder()
    builder.MakeCompound(tool)
    for glyph in glyphs:
        placed = BRepBuilderAPI_Transform(glyph, placement, True).Shape()
        builder.Add(tool, BRepPrimAPI_MakePrism(placed, gp_Vec(*map(float, ENGRAVE_DEPTH_MM * axis))).Shape())
    return _boolean("cut", [solid], [tool])


def build_joint(geometry: JointGeometry, settings: JointSettings):
    """(solid, report) of one joint, built at the origin (mm); the caller places it. The report
    carries ``valid`` (BRepCheck) when the engraving already checked the solid."""
    _, solid, report = build_joint_and_blank(geometry, settings)
    return solid, report


def build_joint_and_blank(geometry: JointGeometry, settings: JointSettings, *, blank_shape=None):
    """(blank, solid, report): the joint as ``build_joint`` gives it, and its blank, the same solid
    before the id is engraved (the solid itself where nothing is engraved), both at the origin (mm).
    ``blank_shape``: the blank already made (an OCP shape: an equal joint's, turned onto this one
    by ``turned_copy``), which then takes the place of the booleans."""
    name = joint_name(geometry.node)
    directions, axis = geometry.directions, geometry.axis
    size = geometry.beam_size_mm
    bore = 0.5 * size + settings.clearance_mm
    outer = bore + settings.wall_mm
    angle = smallest_angle(directions)
    setback = geometry_setback_mm(settings, geometry)
    sleeve = joint_sleeve_mm(settings, size)
    report = {"id": name, "node": geometry.node, "beams": int(len(directions)), "setback_mm": setback,
              "smallest_angle_deg": float(np.degrees(angle))}
    if settings.kind == "steel":
        hub_radius = joint_hub_radius_mm(settings, size)
        height = joint_hub_height_mm(settings, size)
        hub = _cylinder(-0.5 * height * axis, axis, hub_radius, height)
        plates, holes = [], []  # holes: those that could not be made with their plate
        plate_ends, bolt_holes = [], []  # the end face of each plate, the wall of each bolt hole
        # each plate starts halfway into the hub, not at its centre: there plates met one another
        # as well as the hub, and OCCT's fuse of them all at once left some plate a solid apart
        start = 0.5 * hub_radius
        for d in directions:
            side = _perpendicular(d, axis)  # the plate's normal
            centre = setback + 0.5 * sleeve
            plate, made = _holed_plate(start * d, d, np.cross(d, side), setback + sleeve - start,
                                       joint_plate_height_mm(settings, size),
                                       settings.plate_thickness_mm, centre - start, 0.5 * settings.bolt_hole_mm)
            plates.append(plate)
            if not made:
                holes.append(_cylinder(d * centre - 1.5 * settings.plate_thickness_mm * side, side,
                                       0.5 * settings.bolt_hole_mm, 3 * settings.plate_thickness_mm))
            plate_ends.append(("plane", d, setback + sleeve))
            bolt_holes.append(("cylinder", d * centre, side, 0.5 * settings.bolt_hole_mm))
        # one fuse of the holed plates with the hub, checked by a face of each plate end and hole
        # (a cut of the holes after the fuse took 40 % of the node's booleans); a hole that does
        # not fit inside its plate is cut afterwards
        if blank_shape is not None:
            shape = blank_shape
        else:
            shape = _checked_boolean("fuse", hub, plates, plate_ends + ([] if holes else bolt_holes))
            if holes:
                shape = _checked_boolean("cut", shape, holes, bolt_holes)
        solid = _as_build123d(shape)
        blank = solid
        report["min_wall_mm"] = float(settings.plate_thickness_mm)
    else:
        hub_radius = joint_hub_radius_mm(settings, size)
        hub_height = geometry_hub_height_mm(settings, geometry)  # 2 outer + 1, more for rising sleeves
        hub = _cylinder(-0.5 * hub_height * axis, axis, hub_radius, hub_height)
        sleeves, tools, features = [], [], []
        # each socket fits its own tube; the hub and the set-back take the largest
        for d, own in zip(directions, geometry.sizes_mm):
            bore_k = 0.5 * own + settings.clearance_mm
            outer_k, sleeve_k = bore_k + settings.wall_mm, joint_sleeve_mm(settings, own)
            side = _upright(d, axis)
            sleeves.append(_cylinder(np.zeros(3), d, outer_k, setback + sleeve_k))
            features.append(("sleeve", np.zeros(3), d * (setback + sleeve_k), outer_k))
            tools.append(_cylinder(d * setback, d, bore_k, sleeve_k + 1.0))
            features.append(("hole", d * setback, d * (setback + sleeve_k + 1.0), bore_k))
            pin_centre = d * (setback + 0.6 * sleeve_k)
            tools.append(_cylinder(pin_centre - 2 * outer_k * side, side, 0.5 * settings.pin_hole_mm, 4 * outer_k))
            features.append(("hole", pin_centre - 2 * outer_k * side, pin_centre + 2 * outer_k * side,
                             0.5 * settings.pin_hole_mm))
        # one fuse and one cut with all tools (faster than a boolean per feature), each checked by
        # the wall its features' cylinders leave (the sleeves' outsides, the bores and pin holes)
        walls = {kind: [("cylinder", a, b - a, r) for k, a, b, r in features if k == kind]
                 for kind in ("sleeve", "hole")}
        shape = blank_shape if blank_shape is not None else _checked_boolean(
            "cut", _checked_boolean("fuse", hub, sleeves, walls["sleeve"]), tools, walls["hole"])
        blank = solid = _as_build123d(shape)
        if settings.engrave:
            solid = _as_build123d(_engrave_id(shape, name, geometry, settings, top_mm=0.5 * hub_height,
                                              hub_radius=hub_radius, features=features, report=report))
        # wall left between neighbouring bores at their start
        wall_between = 2 * setback * np.sin(0.5 * angle) - 2 * bore if len(directions) > 1 else settings.wall_mm
        report["min_wall_mm"] = float(min(settings.wall_mm, wall_between))
    report["clashes"] = _clashes(directions, outer, setback, sleeve)
    return blank, solid, report


def _as_build123d(shape):
    from build123d import Compound, Solid

    solids = _solids(shape)
    return Solid(solids[0]) if len(solids) == 1 else Compound(shape)


def _clashes(directions: np.ndarray, outer: float, setback: float, sleeve: float) -> list[list]:
    """Pairs of sleeves that overlap beyond their bores' start (the angle is too small for the sleeve)."""
    out = []
    for i in range(len(directions)):
        for j in range(i + 1, len(directions)):
            angle = float(np.arccos(np.clip(directions[i] @ directions[j], -1, 1)))
            # two sleeves of radius R overlap up to a distance R / tan(angle / 2) from the node
            reach = outer / max(np.tan(0.5 * angle), 1e-9)
            if reach > setback + 0.5 * sleeve:
                out.append([i, j, float(np.degrees(angle))])
    return out


def _axis_errors_deg(solid, directions: np.ndarray, bore_radius: float | np.ndarray) -> float:
    """Largest angle (degrees) between each bore's cylinder axis in the solid and its beam (one
    bore radius, or one per beam)."""
    radii = np.atleast_1d(np.asarray(bore_radius, dtype=float))
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.GeomAbs import GeomAbs_Cylinder

    axes = []
    for face in solid.faces():
        surface = BRepAdaptor_Surface(face.wrapped)
        if surface.GetType() == GeomAbs_Cylinder:
            cylinder = surface.Cylinder()
            if np.abs(radii - cylinder.Radius()).min() < 1e-6:
                d = cylinder.Axis().Direction()
                axes.append([d.X(), d.Y(), d.Z()])
    if not axes:
        return float("nan")
    axes = np.array(axes)
    worst = 0.0
    for d in directions:
        cosine = np.abs(axes @ d).max()
        worst = max(worst, float(np.degrees(np.arccos(np.clip(cosine, -1, 1)))))
    return worst


def _meshed(shape, tolerance: float, angular_tolerance: float, relative: bool) -> None:
    """Triangulate ``shape``'s faces with OCCT's mesher (kept on the shape), unless it holds a
    triangulation as fine already: what ``_tessellate`` and ``_stl_triangles`` read."""
    from OCP.BRepMesh import BRepMesh_IncrementalMesh
    from OCP.BRepTools import BRepTools

    if not BRepTools.Triangulation_s(shape, tolerance):
        BRepMesh_IncrementalMesh(shape, tolerance, relative, angular_tolerance, False)


def _tessellate(shape, tolerance: float, angular_tolerance: float, *,
                relative: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (n, 3), triangles (m, 3)) of an OCP shape's triangulation, as build123d's
    ``tessellate(tolerance, angular_tolerance)`` gives them (same mesher settings, same order),
    read into numpy without a Python object per vertex. ``relative`` False: ``tolerance`` is the
    chord deviation in mm, not a fraction of each edge's size (build123d's)."""
    from OCP.BRep import BRep_Tool
    from OCP.TopAbs import TopAbs_FACE, TopAbs_REVERSED
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopLoc import TopLoc_Location
    from OCP.TopoDS import TopoDS

    _meshed(shape, tolerance, angular_tolerance, relative)
    vertices, triangles, offset = [], [], 0
    explorer = TopExp_Explorer(shape, TopAbs_FACE)
    while explorer.More():
        face = TopoDS.Face_s(explorer.Current())
        explorer.Next()
        location = TopLoc_Location()
        poly = BRep_Tool.Triangulation_s(face, location)
        if poly is None:
            continue
        nodes = np.array([poly.Node(i).Coord() for i in range(1, poly.NbNodes() + 1)])
        trsf = location.Transformation()
        matrix = np.array([[trsf.Value(r, c) for c in range(1, 5)] for r in range(1, 4)])
        vertices.append(nodes @ matrix[:, :3].T + matrix[:, 3])
        t = np.array([poly.Triangle(i).Get() for i in range(1, poly.NbTriangles() + 1)], dtype=np.int64) - 1 + offset
        triangles.append(t[:, [0, 2, 1]] if face.Orientation() == TopAbs_REVERSED else t)
        offset += poly.NbNodes()
    if not vertices:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    return np.vstack(vertices), np.vstack(triangles)


def _stl_triangles(shape, tolerance: float, angular_tolerance: float, *,
                   relative: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (3m, 3), triangles (m, 3)) of ``_tessellate``'s triangulation as OCCT's STL writer
    gives it: three vertices per triangle (float32, as an STL holds them), oriented with their
    faces, read into numpy at once. Reading the triangulation through the bindings took 4 s of the
    default job's 109 printed sockets; this, some 1 ms a socket."""
    from OCP.StlAPI import StlAPI_Writer

    _meshed(shape, tolerance, angular_tolerance, relative)
    writer = StlAPI_Writer()
    writer.ASCIIMode = False
    handle, name = tempfile.mkstemp(suffix=".stl")
    os.close(handle)
    try:
        if not writer.Write(shape, name):
            raise FabricationError("OCCT's STL writer could not write the joint's triangulation")
        record = np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("attribute", "<u2")])
        triangles = np.fromfile(name, dtype=record, offset=84)
    finally:
        os.unlink(name)
    vertices = triangles["vertices"].reshape(-1, 3).astype(float)
    return vertices, np.arange(len(vertices), dtype=np.int64).reshape(-1, 3)


def _volume_mm3(shape) -> float:
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, props)
    return float(props.Mass())


def _watertight_stl(solid, path: Path, report: dict, volume_mm3: float) -> bool:
    """Tessellate (STL_CHORD_MM, STL_ANGLE_RAD), weld and write an STL; True when trimesh finds it
    watertight. ``report`` gets ``stl_triangles`` and ``stl_volume_error``, the mesh's volume over
    the solid's ``volume_mm3``, less 1."""
    import trimesh

    vertices, triangles = _stl_triangles(solid.wrapped, STL_CHORD_MM, STL_ANGLE_RAD, relative=False)
    if not len(triangles):
        raise FabricationError("the joint solid has no faces to tessellate (the booleans left nothing)")
    mesh = trimesh.Trimesh(vertices, triangles, process=True)
    mesh.merge_vertices(digits_vertex=5)
    mesh.update_faces(mesh.nondegenerate_faces())
    if not mesh.is_watertight:
        trimesh.repair.fill_holes(mesh)
    trimesh.repair.fix_normals(mesh)
    with atomic_path(path) as tmp:
        mesh.export(tmp, file_type="stl")
    report["stl_triangles"] = int(len(mesh.faces))
    report["stl_volume_error"] = float(mesh.volume / volume_mm3 - 1.0)
    return bool(mesh.is_watertight)


def _build_and_write_group(jobs: tuple) -> list[dict]:
    """``_build_and_write`` of each joint of a group of equal joints (``_groups_of_same``): the first
    is built; the blank of each other one is the first's turned onto it (``turned_copy``), then
    engraved with its own id, checked and written like any joint. Where the turn is not found, or a
    copy fails a check, that joint is built by itself."""
    return _group_reports(jobs)[0]


def _build_and_write_family(family: tuple) -> list[dict]:
    """``_build_and_write_group`` of each group of a family (``_mirror_families``): the first group
    as it is; the first joint of each other group has for its blank the family's first blank
    mirrored onto it (``mirrored_copy``), then is engraved, checked and written like any joint
    (``mirror_of`` in its report), and the rest of its group are turned copies of it. Where the
    reflection is not found, or the copy fails a check, that joint is built by itself."""
    reports: list[dict] = []
    source = None
    for index, group in enumerate(family):
        group_reports, blank = _group_reports(group, source if index else None)
        if index == 0 and blank is not None:
            source = (group[0][0][0], blank)
        reports += group_reports
    return reports


def _group_reports(jobs: tuple, mirror_source: tuple | None = None) -> tuple[list[dict], object]:
    """(the reports of ``_build_and_write_group``, the group's first blank or None); with
    ``mirror_source`` (a joint's geometry and blank), the first joint's blank is that one mirrored
    where it is a mirror image of it."""
    reports: list[dict] = []
    first_blank = None
    for index, (job, shift) in enumerate(jobs):
        report = None
        if index == 0 and mirror_source is not None:
            copy = mirrored_copy(mirror_source[0], job[0])
            if copy is not None:
                source = mirror_source[1]
                report, blank = _build_and_write_one(
                    job, turned=(copy[0], _turned_shape(source.shape, copy[1]), source.volume_mm3))
                if report.get("ok"):
                    report["mirror_of"] = joint_name(mirror_source[0].node)  # its blank is that one's, mirrored
                    first_blank = blank
                else:
                    report = None
        if index > 0 and first_blank is not None:
            copy = turned_copy(jobs[0][0][0], job[0], shift)
            if copy is not None:
                report, _ = _build_and_write_one(job, turned=(copy[0], _turned_shape(first_blank.shape, copy[1]),
                                                              first_blank.volume_mm3))
                if report.get("ok"):
                    report["copy_of"] = joint_name(jobs[0][0][0].node)  # its solid is the first's, turned
                else:
                    report = None
        if report is None:
            report, blank = _build_and_write_one(job)
            if index == 0 and report.get("ok"):
                first_blank = blank
        reports.append(report)
    return reports, first_blank


def _build_and_write(job: tuple) -> dict:
    """Build, check and write one joint (J0001.step, J0001.stl) and its entities for joints.step.
    A joint the modeller cannot build is a report with ``ok`` False and its ``error``, no files."""
    return _build_and_write_one(job)[0]


class _Blank(NamedTuple):
    """A built joint's blank (an OCP shape at the origin, mm) and its volume (mm^3) where known: a
    printed socket's engraved volume plus its pockets'."""

    shape: object
    volume_mm3: float | None = None


def _build_and_write_one(job: tuple, turned: tuple | None = None) -> tuple[dict, _Blank | None]:
    """(report, the blank or None) of ``_build_and_write``; ``turned``: (the joint's geometry as an
    equal joint's turned onto it, that joint's blank turned likewise, its volume in mm^3 or None)."""
    geometry = job[0]
    started = time.perf_counter()
    try:
        return _build_and_write_checked(job, turned)
    except Exception as error:  # noqa: BLE001 - the OCP kernel's failures are many; the joint is reported
        name = joint_name(geometry.node)
        for suffix in (".step", ".stl"):
            (Path(job[2]) / f"{name}{suffix}").unlink(missing_ok=True)
        return {"id": name, "node": geometry.node, "beams": int(len(geometry.directions)), "ok": False,
                "built": False, "error": f"{type(error).__name__}: {error}".splitlines()[0],
                "smallest_angle_deg": float(np.degrees(smallest_angle(geometry.directions))), "_part": False,
                "seconds": {"build": round(time.perf_counter() - started, 4)}}, None


def _build_and_write_checked(job: tuple, turned: tuple | None = None) -> tuple[dict, _Blank]:
    geometry, settings, folder, parts_folder, first_id, last_id, *more = job
    breps = more[0] if more else None  # a folder for each joint's .brep too (JointsInBackground's breps)
    from build123d import export_step

    started = time.perf_counter()
    if turned is None:
        blank, solid, report = build_joint_and_blank(geometry, settings)
    else:  # the checks below measure the copy against this joint's own beams
        blank, solid, report = build_joint_and_blank(turned[0], settings, blank_shape=turned[1])
    built = time.perf_counter()
    # the pockets engraved by faces remove their glyphs' area times the depth: a copy's solid is its
    # source's blank less them, without OCCT's volume integral (0.05 s of a printed socket)
    pocket_mm3 = report.pop("_pocket_mm3", None)
    blank_mm3 = turned[2] if turned is not None else None
    solid_mm3 = blank_mm3 - pocket_mm3 if blank_mm3 is not None and pocket_mm3 is not None else None
    bores = 0.5 * geometry.sizes_mm + settings.clearance_mm
    report["max_axis_error_deg"] = (_axis_errors_deg(solid, geometry.directions, bores) if settings.kind == "socket"
                                    else 0.0)
    report["single_solid"] = len(solid.solids()) == 1
    # a copy's blank is a valid joint's blank turned or mirrored (a rigid map keeps it valid): only
    # what was made here, the engraved solid, is checked again (0.05 s of a printed socket)
    copied = turned is not None
    report["valid"] = (bool(report["valid"]) if "valid" in report
                       else copied and blank is solid or _is_valid(solid.wrapped))
    if blank is not solid and not copied:
        report["valid"] = report["valid"] and _is_valid(blank.wrapped)
    placed = _placed(solid, geometry.position_mm)
    exact = _placed(blank, geometry.position_mm)  # the STEP: the exact solid without the engraved id (the STL has it)
    exact.label = report["id"]
    folder = Path(folder)
    step_path = folder / f"{report['id']}.step"
    with atomic_path(step_path) as tmp:
        # no p-curves: the 2D copies of each edge on its faces, which readers rebuild, were 58 % of a
        # printed socket's bytes (its engraved id's splines); the solid reads back the same
        export_step(exact, str(tmp), write_pcurves=False)
        stamp_step(tmp)
        compact_step_points(tmp)
    if breps is not None:  # the same solid in OCCT's own format, quick to read for gridshell.step
        from OCP.BRepTools import BRepTools

        BRepTools.Write_s(exact.wrapped, str(Path(breps) / f"{report['id']}.brep"))
    report["_part"] = False  # nothing for joints.step (not asked for)
    if parts_folder is not None:
        part = step_part(step_path.read_text(encoding="utf-8"), first_id)
        # a part too big for its id range is renumbered by the parent, above every range
        report["_part"] = str(write_step_part(part, Path(parts_folder) / f"{report['id']}.part")) \
            if part.last_id <= last_id else None
    written = time.perf_counter()
    printed = settings.kind == "socket"
    if printed:
        if solid_mm3 is None:
            solid_mm3 = _volume_mm3(placed.wrapped)
        report["watertight"] = _watertight_stl(placed, folder / f"{report['id']}.stl", report, solid_mm3)
        report["stl_volume_ok"] = abs(report["stl_volume_error"]) <= STL_VOLUME_TOLERANCE
    else:  # no STL: the clash check's broad phase takes the solid's own box
        box = placed.bounding_box()
        report["box_mm"] = [float(v) for v in (box.min.X, box.min.Y, box.min.Z, box.max.X, box.max.Y, box.max.Z)]
    error = report["max_axis_error_deg"]
    report["wall_ok"] = report["min_wall_mm"] >= settings.min_wall_mm - 1e-9
    report["ok"] = bool(report["valid"] and report["single_solid"] and report["wall_ok"]
                        and (not printed or (report["watertight"] and report["stl_volume_ok"]))
                        and not report["clashes"] and (np.isnan(error) or error <= 0.1))
    finished = time.perf_counter()
    report["seconds"] = {"build": round(built - started, 4), "check_and_step": round(written - built, 4),
                         "stl": round(finished - written, 4)}
    known = solid_mm3 is not None and pocket_mm3 is not None
    return report, _Blank(blank.wrapped, solid_mm3 + pocket_mm3 if known else None)


def _placed(shape, position_mm: np.ndarray):
    """``shape`` (build123d) moved to ``position_mm``, sharing its geometry: build123d's ``moved``
    copies the whole B-rep first (2 ms of a steel node's 50-80 ms), for nothing, since the joint's
    solid at the origin is not used again."""
    from OCP.gp import gp_Trsf, gp_Vec
    from OCP.TopLoc import TopLoc_Location

    shift = gp_Trsf()
    shift.SetTranslation(gp_Vec(*map(float, position_mm)))
    return type(shape)(shape.wrapped.Moved(TopLoc_Location(shift)))


def _id_ranges(n_joints: int) -> list[tuple[int, int]]:
    """Disjoint STEP entity id ranges, one per joint (a socket joint has some 10 000 entities),
    leaving room above them below 2**30 (readers keep ids in 32 bits)."""
    stride = max(1000, min(100_000, 2**29 // max(n_joints, 1)))
    first = StepAssemblyWriter.FIRST_ID
    return [(first + k * stride, first + (k + 1) * stride - 1) for k in range(n_joints)]


class JointsInBackground:
    """Builds, checks and writes every joint in worker processes while the caller does other work
    (the parent is otherwise idle while the joints take both cores)::

        with JointsInBackground(polymesh, normals, beam_size_mm, settings, folder) as joints:
            ...                    # the workers build (a thread streams their parts into joints.step)
            joints.wait(progress)  # optional: wait here, passing on the joints' progress
        joints.reports             # one report per joint, in node order

    The workers fork when the block is entered, before the caller's work starts. With one worker
    (or a handful of joints) everything is built in this process when the block ends. Joints
    with most beams go first, so that both cores stay busy to the end; ``seconds`` is the time
    from entering the block to the last joint written. ``combined_step``: write joints.step too,
    where it comes under JOINTS_STEP_LIMIT_BYTES (``combined_bytes`` is its size either way).
    ``breps``: a folder (outside the stage's) for each joint's solid in OCCT's own format as
    well, which gridshell.step reads some 30 times faster than the STEP file; with
    ``breps_limit``, only while there are at most that many distinct joints (``breps`` is None
    otherwise: the model then draws spheres, and the files would be written for nothing)."""

    def __init__(self, polymesh: PolyMesh, normals: np.ndarray, beam_size_mm: float, settings: JointSettings,
                 folder: Path, *, workers: int | None = None, progress=None, combined_step: bool = False,
                 breps: Path | None = None, breps_limit: int | None = None) -> None:
        self.folder = Path(folder)
        self.geometries = joint_geometry(polymesh, normals, beam_size_mm)
        self.settings = settings
        self.workers = workers or os.cpu_count() or 1
        self.progress = progress
        self.reports: list[dict] = []
        self.seconds = 0.0
        self.combined_step = combined_step
        self.combined_bytes = 0  # joints.step's size, written or not (0: not asked for)
        self.breps = None if breps is None else str(breps)
        self.breps_limit = breps_limit
        self.groups: list = []  # _groups_of_same's groups of equal joints, (index, shift) each
        self._groups: list = []
        self._families: list = []  # the groups' jobs in families of mirror images (_mirror_families)
        self._writer: StepAssemblyWriter | None = None
        self._ranges = _id_ranges(len(self.geometries))
        self._latest: tuple[str, float] | None = None
        self._error: BaseException | None = None
        self._thread = None
        self._pool = None
        self._futures: list = []

    def __enter__(self) -> JointsInBackground:
        import contextlib
        import threading

        import build123d  # noqa: F401 - imported once here, before the workers fork, not once per worker
        import trimesh  # noqa: F401 - likewise

        self._started = time.perf_counter()
        self.folder.mkdir(parents=True, exist_ok=True)
        self._stack = contextlib.ExitStack()
        try:
            parts = None
            if self.combined_step:
                parts = self._stack.enter_context(tempfile.TemporaryDirectory(dir=self.folder.parent))
                # written beside the parts, moved into joints/ when done and under JOINTS_STEP_LIMIT_BYTES
                self._combined = Path(parts) / "joints.step"
                self._file = self._stack.enter_context(open(self._combined, "w", encoding="utf-8"))
                self._writer = StepAssemblyWriter(self._file, "joints")
            # equal joints go to one worker, which builds the first and turns its blank onto the
            # others (their booleans were two thirds of a printed socket's time); most beams first
            groups = _groups_of_same(self.geometries)
            groups.sort(key=lambda group: -len(self.geometries[group[0][0]].directions))
            self.groups = groups
            if self.breps_limit is not None and len(groups) > self.breps_limit:
                self.breps = None
            self._jobs = [(g, self.settings, str(self.folder), parts, *self._ranges[k], self.breps)
                          for k, g in enumerate(self.geometries)]
            self._groups = [tuple((self._jobs[k], shift) for k, shift in group) for group in groups]
            # printed sockets: a mirror image's blank is mirrored from its twin's, checked by its bores
            # against its own beams (a steel node's fin plates lie on one side of their beam's plane)
            families = (_mirror_families(self.geometries, groups) if self.settings.kind == "socket"
                        else [[i] for i in range(len(groups))])
            self._families = [tuple(self._groups[i] for i in family) for family in families]
            if self.workers > 1 and len(self._jobs) > 4:
                self._pool = self._stack.enter_context(ProcessPoolExecutor(
                    max_workers=self.workers, initializer=exit_with_parent, initargs=(os.getpid(),)))
                self._futures = [self._pool.submit(_build_and_write_family, family) for family in self._families]
                self._thread = threading.Thread(target=self._collect_all, name="joints", daemon=True)
                self._thread.start()
        except BaseException:
            self._stack.close()
            raise
        return self

    @property
    def distinct(self) -> int:
        """How many distinct joints there are to build (groups of equal joints count once)."""
        return len(self._groups)

    def _collect(self, report: dict) -> None:
        part = report.pop("_part")
        if part is False or self._writer is None:  # not built, or no joints.step: nothing to add
            pass
        elif part is None:
            text = (self.folder / f"{report['id']}.step").read_text(encoding="utf-8")
            self._writer.add(step_part(text, max(self._writer.next_free_id, self._ranges[-1][1] + 1)))
        else:
            self._writer.add_file(Path(part))
            Path(part).unlink()
        self.reports.append(report)
        n, total = len(self.reports), len(self._jobs)
        if n % 10 == 0 or n == total:
            self._latest = (f"joints {n}/{total}", n / total)
            if self.progress is not None:
                self.progress(*self._latest)

    def _collect_all(self) -> None:
        try:
            for future in self._futures:  # in the order given, so that joints.step is the same bytes
                for report in future.result():
                    self._collect(report)
        except BaseException as error:  # noqa: BLE001 - raised again in the caller's thread
            self._error = error
            for future in self._futures:
                future.cancel()

    def run_steps(self, steps: dict, starting=None) -> dict[str, StepOutcome]:
        """Run independent ``steps`` (name -> a picklable function of a module, no arguments) in this
        thread, and in other processes as soon as a joint worker has no joint left to take
        (fabrication.workers.run_steps); each step's result, seconds and where it ran.

        Those processes are started fresh ("spawn"), when the first step goes, not forked: a forked
        child inherits the parent's thread pools without their threads (OCCT's parallel booleans,
        OpenMP), and a step that uses one there waits for ever."""
        if self._pool is None:
            return run_steps(steps, starting=starting)
        import multiprocessing

        with ProcessPoolExecutor(max_workers=self.workers, mp_context=multiprocessing.get_context("spawn"),
                                 initializer=exit_with_parent, initargs=(os.getpid(),)) as fresh:
            return run_steps(steps, fresh, lambda: self.workers - sum(not f.done() for f in self._futures),
                             starting=starting)

    def wait(self, progress=None, poll_s: float = 0.5) -> None:
        """Wait for the workers, passing the latest progress message to ``progress`` meanwhile."""
        while self._thread is not None and self._thread.is_alive():
            self._thread.join(poll_s)
            if progress is not None and self._latest is not None:
                progress(*self._latest)

    def __exit__(self, kind, value, traceback) -> bool:
        error = value
        if error is None:
            try:
                if self._thread is None:
                    for family in self._families:
                        for report in _build_and_write_family(family):
                            self._collect(report)
                self.wait()
                if self._error is not None:
                    raise self._error
                if self._writer is not None:
                    built = {r["id"] for r in self.reports if r.get("built", True)}
                    self._writer.finish([joint_name(g.node) for g in self.geometries if joint_name(g.node) in built])
                    self._file.close()
                    self.combined_bytes = self._combined.stat().st_size
                    if self.combined_bytes < JOINTS_STEP_LIMIT_BYTES:
                        os.replace(self._combined, self.folder / "joints.step")
                self.seconds = time.perf_counter() - self._started
            except BaseException as failure:  # noqa: BLE001 - raised below, after the clean-up
                error = failure
        else:
            for future in self._futures:
                future.cancel()
            self.wait()
        if error is None:
            self._stack.close()  # part files (and a joints.step over the limit) removed, workers ended
        else:
            for future in self._futures:
                future.cancel()
            self._stack.__exit__(type(error), error, error.__traceback__)  # no joints.step written
            if value is None:
                raise error
        self.reports.sort(key=lambda r: r["node"])
        return False


def build_joints(polymesh: PolyMesh, normals: np.ndarray, beam_size_mm: float, settings: JointSettings, folder: Path,
                 *, workers: int | None = None, progress=None, combined_step: bool = False) -> list[dict]:
    """Build, check and write every joint (see the module docstring and JointsInBackground);
    returns one report per joint, in node order."""
    with JointsInBackground(polymesh, normals, beam_size_mm, settings, folder, workers=workers,
                            progress=progress, combined_step=combined_step) as joints:
        pass
    return joints.reports


def settings_dict(settings: JointSettings) -> dict:
    return asdict(settings)
