"""Beam cut list (CSV and a fabricator's XLSX schedule) and the beams as named solids (STEP).

A beam's cut length is its node-to-node length less what the joint at each end takes (the
joint's set-back, see fabrication.joints). Socket joints take square cuts (end angles 0).
The roll angle turns the section about the beam axis from the vertical plane through the beam
to the plane of the beam and the mean of its end nodes' axes (surface normals). Lengths in mm.
At steel nodes a beam's mass is less what its fin plates' end slots take out (``slot_volumes_mm3``).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from engine.mesh import PolyMesh

from .files import atomic_path, stamp_zip, write_assembly_step
from .ids import beam_id, node_id
from .joints import EndSlots, JointSettings, geometry_setback_mm, joint_geometry
from .settings import BeamSettings

__all__ = ["BeamSettings", "cut_list", "write_cut_list", "RectangularSection", "TubeAsCut", "tube_axes_mm",
           "tube_solids", "write_beams_step", "roll_angles_deg", "slot_volumes_mm3"]


def roll_angles_deg(polymesh: PolyMesh, normals: np.ndarray) -> np.ndarray:
    """(b,) signed angle (degrees) about each beam from the vertical plane to the beam's normal plane."""
    e = polymesh.edges
    axis = polymesh.nodes[e[:, 1]] - polymesh.nodes[e[:, 0]]
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    normal = normals[e[:, 0]] + normals[e[:, 1]]
    normal -= np.einsum("bi,bi->b", normal, axis)[:, None] * axis
    reference = np.tile([0.0, 0.0, 1.0], (len(e), 1))
    vertical = np.abs(axis[:, 2]) > 0.99
    reference[vertical] = [0.0, 1.0, 0.0]
    reference -= np.einsum("bi,bi->b", reference, axis)[:, None] * axis
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
    reference /= np.linalg.norm(reference, axis=1)[:, None]
    sine = np.einsum("bi,bi->b", np.cross(reference, normal), axis)
    cosine = np.einsum("bi,bi->b", reference, normal)
    return np.degrees(np.arctan2(sine, cosine))


def cut_list(polymesh: PolyMesh, normals: np.ndarray, settings: BeamSettings, joint_settings: JointSettings, *,
             profiles: list[str] | None = None, areas_m2: np.ndarray | None = None,
             outer_sizes_mm: np.ndarray | None = None) -> pd.DataFrame:
    """One row per beam: ids, profile, material, node and cut lengths, end angles, roll, mass, label.
    Set-backs are rounded up and cut lengths down to 0.1 mm, so that a tube as cut, placed at its
    set-back, never reaches into the joint at its far end.
    ``profiles``, ``areas_m2`` and ``outer_sizes_mm`` (b,) where the beams' sections differ (sized);
    a joint's set-back then follows the largest tube at it."""
    e = polymesh.edges
    node_length = 1000 * polymesh.beam_lengths
    setback = np.zeros(polymesh.n_nodes)
    sizes = settings.outer_size_mm if outer_sizes_mm is None else np.asarray(outer_sizes_mm, dtype=float)
    for geometry in joint_geometry(polymesh, normals, sizes):
        setback[geometry.node] = geometry_setback_mm(joint_settings, geometry)
    # to the saw's 0.1 mm, never into a joint: set-backs rounded up, the cut length down; a beam
    # shorter than its two joints take keeps a zero cut length (the caller reports it)
    setback = np.ceil(np.round(10 * setback, 6)) / 10
    cut = np.maximum(np.floor(np.round(10 * (node_length - setback[e[:, 0]] - setback[e[:, 1]]), 6)) / 10, 0.0)
    ids = [beam_id(i) for i in range(len(e))]
    return pd.DataFrame({
        "id": ids, "start_node": [node_id(a) for a in e[:, 0]], "end_node": [node_id(b) for b in e[:, 1]],
        "profile": settings.profile_name if profiles is None else list(profiles), "material": settings.material_name,
        "node_length_mm": np.round(node_length, 1), "setback_start_mm": setback[e[:, 0]],
        "setback_end_mm": setback[e[:, 1]], "cut_length_mm": cut,
        "end_angle_start_deg": 0.0, "end_angle_end_deg": 0.0,
        "roll_deg": np.round(roll_angles_deg(polymesh, normals), 2),
        "mass_kg": np.round(cut / 1000 * (settings.area_m2 if areas_m2 is None else np.asarray(areas_m2))
                            * settings.density, 4),
        "label": [f"{i} {a}-{b}" for i, a, b in zip(ids, e[:, 0] + 1, e[:, 1] + 1)],
    })


def write_cut_list(table: pd.DataFrame, folder: Path) -> tuple[Path, Path]:
    """cutlist.csv and cutlist.xlsx (one sheet per profile with a totals row, and a summary sheet)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    with atomic_path(folder / "cutlist.csv") as tmp:
        table.to_csv(tmp, index=False)
    summary = table.groupby("profile").agg(beams=("id", "count"),
                                           cut_length_m=("cut_length_mm", lambda s: s.sum() / 1000),
                                           mass_kg=("mass_kg", "sum")).reset_index()
    with atomic_path(folder / "cutlist.xlsx") as tmp:
        with pd.ExcelWriter(tmp, engine="openpyxl") as writer:
            summary.to_excel(writer, sheet_name="summary", index=False)
            for number, (profile, rows) in enumerate(table.groupby("profile"), start=1):
                totals = {c: "" for c in rows.columns}
                totals.update({"id": "TOTAL", "cut_length_mm": rows["cut_length_mm"].sum(),
                               "mass_kg": rows["mass_kg"].sum(), "label": f"{len(rows)} beams"})
                sheet = pd.concat([rows, pd.DataFrame([totals])], ignore_index=True)
                name = "".join(ch for ch in str(profile) if ch not in "[]:*?/\\")[:28] or f"profile {number}"
                sheet.to_excel(writer, sheet_name=name, index=False)
        stamp_zip(tmp)
    return folder / "cutlist.csv", folder / "cutlist.xlsx"


def _disc_strip_mm2(radius: float, width: float) -> float:
    """The area of a disc of ``radius`` within a strip ``width`` wide through its centre (mm2)."""
    h = min(0.5 * width, radius)
    return 2.0 * (h * math.sqrt(radius * radius - h * h) + radius * radius * math.asin(h / radius))


def slot_volumes_mm3(slots: EndSlots, cut_lengths_mm: np.ndarray, sizes_mm: np.ndarray,
                     walls_mm: np.ndarray | None, rectangle: "RectangularSection | None" = None) -> np.ndarray:
    """(b,) what the fin plates' end slots take out of each beam as cut (mm3), in closed form: the
    section's area within the slot's strip times the slots' lengths, for beams whose slots fit
    (``EndSlots.fit``): an annulus's or a disc's strip; a rectangle's two walls the slot crosses
    (its full height where solid, or the slot's height where that is less: a knife plate's), the
    section's small turn to the slot neglected."""
    removed = np.zeros(len(cut_lengths_mm))
    for k, cut in enumerate(cut_lengths_mm):
        if cut <= 0 or not slots.fit(k, float(cut)):
            continue
        wall = None if walls_mm is None else float(walls_mm[k])
        if rectangle is None:
            radius = 0.5 * float(sizes_mm[k])
            area = _disc_strip_mm2(radius, slots.width)
            if wall is not None and 0 < wall < radius:
                area -= _disc_strip_mm2(radius - wall, slots.width)
        else:
            depth = rectangle.height_mm if wall is None else 2.0 * wall
            if wall is None and slots.height is not None:
                depth = min(depth, slots.height)
            area = min(slots.width, rectangle.width_mm) * depth
        removed[k] = area * float(slots.lengths[k].sum())
    return removed


#: A rectangular beam's slotted ends are shared between beams whose section turns to the slot by the
#: same angle to this step (degrees); the end then differs from its beam's own turn by half a step.
SECTION_TURN_STEP_DEG = 0.1


@dataclass(frozen=True)
class RectangularSection:
    """A rectangular section as cut (mm): ``height_mm`` along each beam's ``up`` (b, 3) unit vectors
    (the analysis's local z: engine.structure.grid_model.beam_up_vectors), ``width_mm`` across."""

    height_mm: float
    width_mm: float
    up: np.ndarray


def _profile_face(size: float, wall: float | None, rectangle: tuple[float, float, float] | None):
    """The section as a face on local xy (mm): a disc or annulus of outer ``size``, or where
    ``rectangle`` (height, width, turn in degrees from local y) is given a rectangle, hollow by
    ``wall`` where given."""
    from build123d import Circle, Rectangle

    if rectangle is None:
        outer, inner = Circle(0.5 * size), None if wall is None else Circle(0.5 * size - wall)
    else:
        height, width, turn = rectangle
        outer = Rectangle(width, height, rotation=turn)
        inner = None if wall is None else Rectangle(width - 2 * wall, height - 2 * wall, rotation=turn)
    return (outer if inner is None else outer - inner).faces()[0]


def _slotted_end(size: float, wall: float | None, width: float, length: float,
                 rectangle: tuple[float, float, float] | None = None, height: float | None = None):
    """A beam's end of ``length`` (mm) with a slot ``width`` wide, along local z from the origin, the
    slot across local x: through both walls, or ``height`` high along local y about the axis (a
    knife plate's in a solid beam). The section's prism (``_profile_face``) less the slot, once per
    size (the beams place it again)."""
    from build123d import Align, Box, Solid, Vector

    prism = Solid.extrude(_profile_face(size, wall, rectangle), Vector(0, 0, length))
    slot = Box(width, 2 * size if height is None else height, 2 * length,
               align=(Align.CENTER, Align.CENTER, Align.CENTER))
    return prism - slot


@dataclass(frozen=True)
class TubeAsCut:
    """One beam as cut (mm): ``body``, its prism placed between its joints (build123d), and its
    slotted ``ends`` for steel fin plates as (name, shape, location): one shape per tube size and
    slot, shared by every end that has it, so that a STEP file writes it once and places it."""

    id: str
    body: object
    ends: tuple = ()

    def add_to(self, assembly, color=None) -> None:
        """Add the beam to a cadquery Assembly: one named part, or where it has slotted ends a named
        sub-assembly of its prism and its ends (the ends placed copies of their shared shape)."""
        import cadquery as cq

        body = cq.Shape.cast(self.body.wrapped)
        if not self.ends:
            assembly.add(body, name=self.id, color=color)
            return
        beam = cq.Assembly(name=self.id, color=color)
        beam.add(body, name=f"{self.id} tube", color=color)
        for name, shape, location in self.ends:
            beam.add(shape, name=f"{self.id} {name}", loc=cq.Location(location.wrapped), color=color)
        assembly.add(beam)


def tube_axes_mm(polymesh: PolyMesh, setback_start_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(starts (b, 3), directions (b, 3)): where each beam's tube as cut begins, at its start
    joint's set-back from the node (mm), and its unit direction from start node to end node."""
    starts, directions = np.empty((len(polymesh.edges), 3)), np.empty((len(polymesh.edges), 3))
    for k, ((a, b), setback) in enumerate(zip(polymesh.edges, np.asarray(setback_start_mm, dtype=float))):
        start, end = 1000 * polymesh.nodes[a], 1000 * polymesh.nodes[b]
        directions[k] = (end - start) / np.linalg.norm(end - start)
        starts[k] = start + directions[k] * setback
    return starts, directions


def tube_solids(polymesh: PolyMesh, table: pd.DataFrame, *, outer_size_mm: float | np.ndarray,
                wall_mm: float | np.ndarray | None = None, profile_per_tube: bool = True,
                slots: EndSlots | None = None, rectangle: RectangularSection | None = None) -> list[TubeAsCut]:
    """Every beam as cut (mm): its section (a tube of outer size and ``wall_mm``, a rod where no
    wall is given, or ``rectangle`` turned to each beam's up, hollow by ``wall_mm`` where given)
    extruded to its cut length, no boolean, placed between its joints; a beam of zero cut length
    (shorter than its joints take, reported by the caller) has none.
    ``slots``: steel fin plates' end slots (fabrication.joints.fin_plate_slots): such a beam is its
    middle prism and its two slotted ends, each a placed copy of one slotted end per size (no
    boolean per beam; a rectangle's ends per turn of its section to the slot, to 0.1 degree).
    ``profile_per_tube`` False extrudes every tube from one shared profile face (the scheme before,
    kept for benchmarks/fabrication_speed.py: the same file, built in time growing as the square of
    the tubes)."""
    from build123d import Location, Plane, Solid, Vector

    e = polymesh.edges
    tubes = []
    sizes = np.broadcast_to(np.asarray(outer_size_mm, dtype=float), (len(e),))
    walls = None if wall_mm is None else np.broadcast_to(np.asarray(wall_mm, dtype=float), (len(e),))
    faces: dict[tuple, object] = {}
    shared: dict[tuple, object] = {}
    if slots is not None:
        import cadquery as cq
    origins, directions = tube_axes_mm(polymesh, table["setback_start_mm"].to_numpy())
    for k, (row, origin, direction, size) in enumerate(zip(table.itertuples(index=False), origins, directions, sizes)):
        if row.cut_length_mm <= 0:
            continue
        least = size if rectangle is None else min(rectangle.height_mm, rectangle.width_mm)
        wall = None if walls is None or not 0 < walls[k] < 0.5 * least else float(walls[k])
        section = None if rectangle is None else (float(rectangle.height_mm), float(rectangle.width_mm), 0.0)
        # the section's local x: across a rectangle's height (its up), any square to a round one
        across = None if rectangle is None else np.cross(rectangle.up[k], direction)
        slotted = slots is not None and slots.fit(k, row.cut_length_mm)
        ends_mm = slots.lengths[k] if slots is not None and slotted else np.zeros(2)
        length = float(row.cut_length_mm - ends_mm.sum())
        key = (float(size), wall, section)
        if key not in faces:
            faces[key] = _profile_face(float(size), wall, section)
        # a copy of the profile per tube: prisms of one shared face made the build and the
        # STEP export grow as the square of the tubes (4500 tubes: 75 s, with copies 12 s)
        profile = copy.deepcopy(faces[key]) if profile_per_tube else faces[key]
        solid = Solid.extrude(profile, Vector(0, 0, length))
        at = tuple(map(float, origin + ends_mm[0] * direction))
        plane = (Plane(origin=at, z_dir=tuple(map(float, direction))) if across is None else
                 Plane(origin=at, x_dir=tuple(map(float, across)), z_dir=tuple(map(float, direction))))
        # placed, not moved: build123d's moved copies the fresh prism first (some 0.2 ms a tube)
        solid = Solid(solid.wrapped.Moved(Location(plane).wrapped))
        solid.label = row.id
        ends = []
        if slots is not None and slotted:
            for i, (at_end, inward) in enumerate(((origin, direction),
                                                  (origin + row.cut_length_mm * direction, -direction))):
                side = slots.sides[k, i]
                shape = section
                if rectangle is not None:  # the rectangle's turn in the slot's axes: its height along up
                    y = np.cross(inward, side)
                    turn = np.degrees(np.arctan2(np.cross(y, rectangle.up[k]) @ inward, y @ rectangle.up[k]))
                    step = SECTION_TURN_STEP_DEG
                    shape = (section[0], section[1], round(round(float(turn) / step) * step, 6) % 360.0)
                key2 = (float(size), wall, float(slots.width), float(slots.lengths[k, i]), shape, slots.height)
                if key2 not in shared:
                    shared[key2] = cq.Shape.cast(_slotted_end(*key2).wrapped)
                place = Plane(origin=tuple(map(float, at_end)), x_dir=tuple(map(float, side)),
                              z_dir=tuple(map(float, inward)))
                ends.append(("start slot" if i == 0 else "end slot", shared[key2], Location(place)))
        tubes.append(TubeAsCut(id=row.id, body=solid, ends=tuple(ends)))
    return tubes


def write_beams_step(polymesh: PolyMesh, table: pd.DataFrame, path: Path, *, outer_size_mm: float | np.ndarray,
                     wall_mm: float | np.ndarray | None = None, profile_per_tube: bool = True,
                     slots: EndSlots | None = None, rectangle: RectangularSection | None = None) -> Path:
    """beams.step: the assembly "beams" of every beam as cut (``tube_solids``): one named part per
    beam, or a named sub-assembly of its prism and its slotted ends (steel fin plates)."""
    import cadquery as cq

    tubes = tube_solids(polymesh, table, outer_size_mm=outer_size_mm, wall_mm=wall_mm,
                        profile_per_tube=profile_per_tube, slots=slots, rectangle=rectangle)
    assembly = cq.Assembly(name="beams")
    for tube in tubes:
        tube.add_to(assembly)
    return write_assembly_step(assembly, path)
